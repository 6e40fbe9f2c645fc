//! What several commands share: how a capture is loaded and energies are evaluated, the
//! synthetic camera rig, settings, mesh landmarks, and the choices the library's enums offer
//! on the command line (clap stays out of the library).

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use jawtrack::anatomy::MeshMetric;
use jawtrack::capture::{Capture, OpenOptions};
use jawtrack::envelope::JawFrame;
use jawtrack::mesh::{BoiSource, Mesh};

/// A command-line mirror of a library enum: the variants' `///` lines are the help, and the
/// two `From`s fail to compile when either side gains a variant the other lacks.
macro_rules! choice {
    ($(#[$meta:meta])* $name:ident => $lib:path { $($(#[doc = $doc:literal])* $variant:ident),+ $(,)? }) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
        pub enum $name {
            $($(#[doc = $doc])* $variant),+
        }
        impl From<$name> for $lib {
            fn from(c: $name) -> $lib {
                match c { $($name::$variant => <$lib>::$variant),+ }
            }
        }
        impl From<$lib> for $name {
            fn from(c: $lib) -> $name {
                match c { $(<$lib>::$variant => $name::$variant),+ }
            }
        }
    };
}

choice!(BackendArg => jawtrack::energy::Backend {
    /// A hardware GPU adapter when there is one; the CPU reference otherwise, and also when
    /// the only adapter is a software rasteriser (slower than the CPU reference).
    Auto,
    /// The GPU engine (any adapter, software ones included; `JAWTRACK_ADAPTER` picks one).
    Gpu,
    /// The CPU reference.
    Cpu,
    /// The paper's architecture on the GPU: colour image read back and counted on the CPU.
    Readback,
});

choice!(RegionArg => jawtrack::energy::Region {
    /// Only the pixels the arch (and, in combined mode, the other arch) can cover.
    Footprint,
    /// Every pixel of the mask (for comparison).
    FullFrame,
    /// The footprint, drawing only the faces that can change the energy (CPU reference).
    Relevant,
});

choice!(PresetArg => jawtrack::synth::Preset {
    /// Perfect masks of the whole crowns.
    Clean,
    /// Lips hide the gum side of the crowns; boundaries wander by a pixel or two; gums
    /// between teeth filled; a few specular holes.
    Realistic,
    /// Faster motion, more noise, and frames where the lips close.
    Hard,
});

choice!(PhotosArg => jawtrack::synth::Photos {
    /// Teeth, the dark mouth interior, lips and skin; a little lens blur and sensor noise.
    Clean,
    /// What a real mouth shows besides teeth: gums, the tongue, wet highlights, lips shading
    /// the crowns, motion blur, drifting exposure and white balance.
    Hard,
});

choice!(JointArg => jawtrack::synth::Joint {
    /// An average adult joint.
    Average,
    /// A second subject: condyles placed differently, a steeper eminence, less opening.
    Variant,
});

choice!(SearchArg => jawtrack::track::Solver {
    /// gauss-newton where the masks label the mouth interior or are combined, paper on per-arch
    /// teeth masks alone
    Auto,
    /// The paper's derivative-free search of its energy, per arch (finite differences, golden
    /// section, local sampling)
    Paper,
    /// Gauss-Newton over both arches at once on the energy's terms along the silhouettes,
    /// falling back to the paper's search on a lost frame
    GaussNewton,
    /// Gauss-Newton per arch on its teeth outline (experimental)
    Contour,
});

choice!(MaskKindArg => jawtrack::synth::MaskKind {
    /// One label per arch.
    PerArch,
    /// One teeth mask for both arches.
    Combined,
});

choice!(AdaptationArg => jawtrack::envelope::adapt::Adaptation {
    /// Only the reference point of each measured pose is used.
    Reduced,
    /// The whole measured poses.
    Full,
});

/// How a capture is loaded: the arches' simplification and the masks' resolution (shared by
/// the commands that evaluate energies).
#[derive(clap::Args, Clone, Copy)]
pub struct LoadArgs {
    /// Simplify each arch to at most this many triangles at load (instead of --simplify-mm).
    #[arg(long, value_parser = count_in(4, 100_000_000))]
    pub max_triangles: Option<usize>,
    /// Simplify each arch as far as its surface stays within this distance (mm) of the
    /// scan's; 0 keeps every triangle (a silhouette needs far fewer than a scan has). Default:
    /// a tenth of a mask pixel where the cameras look (0.04 mm for half-resolution GoPro
    /// masks at 20 cm).
    #[arg(long, value_parser = non_negative_mm)]
    pub simplify_mm: Option<f64>,
    /// Read the masks at 1/K of their resolution (each K x K block's most common label; K
    /// must divide the masks' sides): for masks larger than the time per frame allows, e.g.
    /// 4K video's. Drawing and counting cost about K² times less (setting up each triangle
    /// costs the same), and the pixels are K times coarser.
    #[arg(long, default_value_t = 1, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=16))]
    pub mask_reduce: u32,
    /// Let capture.json name files outside the capture folder (absolute paths, `..`, links
    /// out); refused by default.
    #[arg(long)]
    pub allow_outside: bool,
}

impl LoadArgs {
    pub fn open_options(&self) -> OpenOptions {
        OpenOptions {
            max_triangles: self.max_triangles,
            simplify_mm: self.simplify_mm,
            mask_reduce: self.mask_reduce,
            allow_outside: self.allow_outside,
            masks_to_come: false,
        }
    }
}

/// A distance in mm that must be finite and not negative (`--simplify-mm`).
pub fn non_negative_mm(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..=100.0).contains(&v) => Ok(v),
        Ok(v) => Err(format!("must be a distance from 0 to 100 mm, found {v}")),
        Err(e) => Err(format!("{s:?}: {e}")),
    }
}

/// A flag's number: finite and from `lo` to `hi` (NaN and infinities are refused where they
/// enter, not found later as a NaN energy or a pose that never converges).
pub fn number_in(lo: f64, hi: f64) -> impl Fn(&str) -> Result<f64, String> + Clone {
    move |s| match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (lo..=hi).contains(&v) => Ok(v),
        Ok(v) => Err(format!("must be a number from {lo} to {hi}, found {v:e}")),
        Err(e) => Err(format!("{s:?}: {e}")),
    }
}

/// A flag's count: from `lo` to `hi`.
pub fn count_in(lo: usize, hi: usize) -> impl Fn(&str) -> Result<usize, String> + Clone {
    move |s| match s.trim().parse::<usize>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        Ok(v) => Err(format!("must be from {lo} to {hi}, found {v}")),
        Err(e) => Err(format!("{s:?}: {e}")),
    }
}

impl Default for LoadArgs {
    fn default() -> Self {
        let o = OpenOptions::default();
        LoadArgs {
            max_triangles: o.max_triangles,
            simplify_mm: o.simplify_mm,
            mask_reduce: o.mask_reduce,
            allow_outside: o.allow_outside,
        }
    }
}

/// How energies are evaluated (shared by every command that evaluates them).
#[derive(clap::Args, Clone, Copy)]
pub struct EngineArgs {
    /// Energy backend: `auto` takes a hardware GPU adapter when there is one and the CPU
    /// reference otherwise; `JAWTRACK_ADAPTER=substring` picks an adapter by name.
    #[arg(long, value_enum, default_value_t = BackendArg::Auto)]
    pub backend: BackendArg,
    /// What to render and count: only where the arch can be (`footprint`), every pixel
    /// (`full-frame`), or only the faces that can change the energy (`relevant`: the CPU
    /// reference skips body faces off the mask; the other counts are then low). Default: `relevant` where
    /// only the energy is read (track, bench track), `footprint` for the energy command.
    #[arg(long, value_enum)]
    pub region: Option<RegionArg>,
}

/// The cameras a synthetic capture is filmed with (`synth`, `bench track`).
#[derive(clap::Args, Clone, Debug)]
pub struct CameraRigArgs {
    /// A folder of camera files (`<name>.json`, as in a capture's cameras/) to film with
    /// instead of the rig of calib/ (three cameras); masks are written at half each camera's
    /// resolution.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Lens distortion for every camera, OpenCV's k1,k2,p1,p2[,k3[,k4,k5,k6[,s1,s2,s3,s4]]]
    /// (e.g. -0.25,0.08,0,0, a moderate barrel), replacing the camera files': written to the
    /// capture's camera files, and the masks are drawn through it. Default: the cameras' own
    /// (calib/ has none).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub distortion: Option<Vec<f64>>,
    /// `--distortion` gives cv::fisheye's k1,k2,k3,k4 (Kannala-Brandt).
    #[arg(long, requires = "distortion")]
    pub fisheye: bool,
}

impl CameraRigArgs {
    pub fn distortion(&self) -> anyhow::Result<Option<jawtrack::geometry::Distortion>> {
        let Some(d) = &self.distortion else {
            return Ok(None);
        };
        anyhow::ensure!(
            d.iter().all(|x| x.is_finite()),
            "--distortion: every coefficient must be a finite number, found {d:?}"
        );
        jawtrack::geometry::Distortion::from_coefficients(d, self.fisheye)
            .map(Some)
            .map_err(|e| anyhow::anyhow!("--distortion: {e}"))
    }
}

/// Settings from the argument of option `flag` (`--settings`): a JSON file, or the JSON itself
/// when the argument starts with `{` (errors then name `flag` where they would name the file);
/// with the name its errors go by.
pub fn read_settings<'a, T: serde::de::DeserializeOwned>(
    arg: &'a Path,
    what: &str,
    flag: &'static str,
) -> anyhow::Result<(T, &'a Path)> {
    match arg.to_str().map(str::trim_start) {
        Some(text) if text.starts_with('{') => {
            let source = Path::new(flag);
            Ok((jawtrack::io::parse_json(text, source)?, source))
        }
        _ => Ok((jawtrack::io::read_json(arg, what)?, arg)),
    }
}

/// Tracking settings from `--settings` (defaults without it), checked field by field.
pub fn track_settings(
    arg: Option<&Path>,
    energy: EnergyArg,
    search: Option<SearchArg>,
) -> anyhow::Result<jawtrack::track::TrackSettings> {
    let mut settings = match arg {
        None => jawtrack::track::TrackSettings::default(),
        Some(arg) => {
            let (settings, source): (jawtrack::track::TrackSettings, _) =
                read_settings(arg, "settings file", "--settings")?;
            settings.validate_from(source)?;
            settings
        }
    };
    if energy == EnergyArg::Paper {
        settings.search.cross_weight = 0.0;
        settings.search.mouth_weight = 0.0;
    }
    if let Some(search) = search {
        settings.search.solver = search.into();
    }
    Ok(settings)
}

/// The objective the search minimises (`--energy`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum EnergyArg {
    /// The paper's E plus the terms of our own at the settings' weights: cross-label (per-arch
    /// masks) and over-mouth (masks that label the mouth interior).
    #[default]
    Full,
    /// The paper's E alone (`cross_weight` and `mouth_weight` 0, whatever the settings say).
    Paper,
}

/// Rig settings from `--settings` (defaults without it), checked field by field.
pub fn rig_settings(arg: Option<&Path>) -> anyhow::Result<jawtrack::rig::RigSettings> {
    let Some(arg) = arg else {
        return Ok(Default::default());
    };
    let (settings, source): (jawtrack::rig::RigSettings, _) =
        read_settings(arg, "rig settings", "--settings")?;
    settings.validate(source)?;
    Ok(settings)
}

/// `--frames A..B` (B excluded) or `A..=B`, either end optional, within the capture's frames.
pub fn parse_frames(s: &str, capture: &Capture) -> anyhow::Result<Range<u32>> {
    let all = capture.frames();
    let (a, b, inclusive) = if let Some((a, b)) = s.split_once("..=") {
        (a, b, true)
    } else if let Some((a, b)) = s.split_once("..") {
        (a, b, false)
    } else {
        bail!("--frames {s:?}: expected A..B or A..=B");
    };
    let num = |x: &str, default: u32| -> anyhow::Result<u32> {
        if x.is_empty() {
            Ok(default)
        } else {
            x.trim()
                .parse()
                .with_context(|| format!("--frames {s:?}: `{x}` is not a frame number"))
        }
    };
    let start = num(a, all.start)?;
    let end = num(b, all.end)?.saturating_add(u32::from(inclusive));
    if start < all.start || end > all.end || start >= end {
        bail!(
            "--frames {s:?}: the capture has frames {}..{}",
            all.start,
            all.end
        );
    }
    Ok(start..end)
}

/// A window of file frames, `A..B` (B excluded), for commands that run before a capture.json.
pub fn frame_window(s: &str) -> Result<Range<u32>, String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("{s:?}: expected A..B"))?;
    let num = |x: &str| x.trim().parse::<u32>().map_err(|e| format!("{x:?}: {e}"));
    let (a, b) = (num(a)?, num(b)?);
    if a >= b {
        return Err(format!("{s:?}: the window is empty"));
    }
    Ok(a..b)
}

pub fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("{p:?}: {e}")))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [a, b, c] if v.iter().all(|x| x.is_finite()) => Ok([*a, *b, *c]),
        _ => Err(format!("expected three finite numbers X,Y,Z, found {s:?}")),
    }
}

pub fn load_mesh(path: &Path) -> anyhow::Result<(Mesh, MeshMetric)> {
    let mesh = Mesh::load(path, BoiSource::None)
        .with_context(|| format!("reading the mesh {}", path.display()))?;
    let metric = MeshMetric::new(&mesh);
    Ok((mesh, metric))
}

/// The jaw frame's landmarks on the mandible, given or found.
#[derive(clap::Args, Default)]
pub struct Landmarks {
    /// Vertex indices of the left and right condyles: L,R (default: found on the mesh).
    #[arg(long, value_delimiter = ',')]
    pub condyles: Option<Vec<usize>>,
    /// Vertex index of the reference point, the lower incisal midpoint (default: found).
    #[arg(long)]
    pub reference: Option<usize>,
}

impl Landmarks {
    /// The jaw frame of a mandible mesh.
    pub fn frame(
        &self,
        mesh_path: &std::path::Path,
        mesh: &jawtrack::mesh::Mesh,
    ) -> anyhow::Result<JawFrame> {
        let condyles = match self.condyles.as_deref() {
            None => None,
            Some(&[l, r]) => Some([l, r]),
            Some(other) => anyhow::bail!(
                "--condyles: expected two vertex indices L,R, found {}",
                other.len()
            ),
        };
        JawFrame::from_mesh(mesh, condyles, self.reference)
            .with_context(|| format!("{}: the jaw frame's landmarks", mesh_path.display()))
    }
}

/// A choice's command-line name (`per-arch`), for output in plain words.
pub fn name_of<T: clap::ValueEnum>(value: &T) -> String {
    value
        .to_possible_value()
        .map(|p| p.get_name().to_string())
        .unwrap_or_default()
}

/// A three-parameter rig file of either kind (`rig learn`'s or `envelope learn`'s): the file
/// says which.
pub fn load_rig(
    path: &Path,
) -> anyhow::Result<Box<dyn jawtrack::rig::ThreeParameterRig + Send + Sync>> {
    let head: serde_json::Value = jawtrack::io::read_json(path, "rig file")?;
    Ok(
        if head["format"].as_str() == Some(jawtrack::envelope::model::ENVELOPE_FORMAT) {
            Box::new(jawtrack::envelope::EnvelopeRig::load(path)?)
        } else {
            Box::new(jawtrack::rig::JawRig::load(path)?)
        },
    )
}

/// Per parameter, how many values the rig's range is sampled at for tracking.
const RIG_SAMPLES: [usize; 3] = [25, 9, 7];

/// A rig's jaw poses over its valid range (a grid over the span of the poses it was learned
/// from, the valid points kept): what `track --rig` holds the jaw to.
pub fn rig_space(
    rig: &(dyn jawtrack::rig::ThreeParameterRig + Send + Sync),
    source: &str,
) -> anyhow::Result<jawtrack::track::JawSpace> {
    let spread = rig.spread();
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for d in &spread {
        for k in 0..3 {
            lo[k] = lo[k].min(d[k]);
            hi[k] = hi[k].max(d[k]);
        }
    }
    let at = |k: usize, i: usize| {
        let n = RIG_SAMPLES[k];
        lo[k] + (hi[k] - lo[k]) * i as f64 / (n - 1) as f64
    };
    let mut poses = Vec::new();
    for i in 0..RIG_SAMPLES[0] {
        for j in 0..RIG_SAMPLES[1] {
            for k in 0..RIG_SAMPLES[2] {
                let d = [at(0, i), at(1, j), at(2, k)];
                if rig.is_valid(&d) {
                    poses.push(rig.pose(&d));
                }
            }
        }
    }
    if poses.len() < 16 {
        anyhow::bail!(
            "{source}: only {} of the rig's sampled parameters are valid; too few to track with",
            poses.len()
        );
    }
    Ok(jawtrack::track::JawSpace::new(poses, source))
}
