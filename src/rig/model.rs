//! The three-parameter jaw rig: the paper's Eq. 5, Φ(d1, d2, d3) = Φ1(d1) + Φ2(d2) + Φ3(d3) in
//! se(3), mapped back with exp, by default with the modes' pairwise couplings added
//! (coupled.rs), which vanish wherever either of their parameters is zero.
//!
//! Learning: PCA of the jaw vectors, then the three modes Φi fitted together as one additive
//! model (additive.rs), from straight starting modes: opening along the first principal
//! direction, lateral excursion and protrusion in the plane of the next two; then, coupled,
//! the couplings with them. With `paper` set, the paper's first step is learned as well, for
//! the figures: the five-component hierarchical NLPCA and the paper's own construction of Φ2
//! and Φ3 (one-component NLPCAs of D23 = {Φgen(0, c2, c3, 0, 0)} and
//! D45 = {Φgen(0, 0, 0, c4, c5)}, the base point Φgen(0) counted once), kept as
//! [`PaperModes`]. That construction assumes components 2-3 are lateral excursion and 4-5
//! protrusion, which fails on motion whose remainder after opening is two-dimensional.
//!
//! Parameters: each d_i is the mode's own parameter times a gain that makes it an arc length
//! along the mode in the rig's input units (where the widest coordinate has a standard
//! deviation of 0.1, as in Scholz's NLPCA; the paper's d1 runs over about −0.2..0.33 in such
//! units) and points the intuitive way: d1 up opens the mouth, d2 up moves the chin to the
//! subject's left (+x), d3 up moves it forward (+z).

use nalgebra::{Vector3, Vector6};
use serde::{Deserialize, Serialize};

use super::Progress;
use super::additive::{self, AdditiveModes, AdditiveReport, AdditiveSettings};
use super::coupled::{self, Couplings};
use super::nlpca::{Nlpca, NlpcaError, NlpcaSettings, TrainReport};
use super::ranges::{RangeError, Ranges};
use crate::anatomy::Coordinates;
use crate::anatomy::MeshMetric;
use crate::anatomy::Pca;
use crate::error::Result;
use crate::geometry::Pose;
use crate::geometry::least_squares::levenberg_marquardt;
use crate::settings::Rules;

pub const RIG_FORMAT: &str = "jawtrack-rig/1";

/// The components of the first network: opening, two of lateral excursion, two of
/// protrusion (the paper's finding; its sixth adds only noise).
pub const NETWORK_COMPONENTS: usize = 5;

/// Which three-parameter model the rig is.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
pub enum RigModel {
    /// The modes and their pairwise couplings (coupled.rs): each parameter alone still moves
    /// the jaw along its own mode.
    #[default]
    Coupled,
    /// The paper's sum of the three modes (Eq. 5).
    Additive,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct RigSettings {
    pub model: RigModel,
    /// Also learn the paper's five-component NLPCA and its D23/D45 construction: for the
    /// figures (`rig eval`, `bench rig`); the rig itself does not need them.
    pub paper: bool,
    /// The five-component network.
    pub network: NlpcaSettings,
    /// The one-component networks of the paper's D23 and D45.
    pub mode: NlpcaSettings,
    /// The rig's three modes, fitted together.
    pub modes: AdditiveSettings,
    /// Their couplings (the coupled model).
    pub couplings: AdditiveSettings,
    /// Alpha radius of the range shapes, in parameter units (the paper: 0.12).
    pub alpha: f64,
    /// Gauss-Newton steps when encoding a pose (0: the extraction functions alone).
    pub encode_steps: usize,
}

impl Default for RigSettings {
    fn default() -> Self {
        RigSettings {
            model: RigModel::default(),
            paper: false,
            network: NlpcaSettings {
                hidden: 16,
                max_iterations: 6000,
                ..Default::default()
            },
            mode: NlpcaSettings {
                hidden: 6,
                max_iterations: 1500,
                ..Default::default()
            },
            modes: AdditiveSettings::default(),
            couplings: coupled::default_settings(),
            alpha: 0.12,
            encode_steps: 8,
        }
    }
}

impl RigSettings {
    /// Every field in its range (see [`crate::settings`]), errors naming `source`.
    pub fn validate(&self, source: &std::path::Path) -> crate::error::Result<()> {
        let rules = Rules::new(source);
        self.network.validate(&rules.within("network"))?;
        self.mode.validate(&rules.within("mode"))?;
        self.modes.validate(&rules.within("modes"))?;
        self.couplings.validate(&rules.within("couplings"))?;
        rules.above("alpha", self.alpha, 0.0, 100.0)?;
        rules.count("encode_steps", self.encode_steps as u64, 0, 1000)?;
        Ok(())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RigError {
    #[error("learning the rig needs at least {need} jaw poses, got {got}")]
    TooFewPoses { need: usize, got: usize },
    #[error("the {stage} network: {error}")]
    Nlpca {
        stage: &'static str,
        error: NlpcaError,
    },
    #[error("the jaw poses do not move: every pose is the same")]
    NoMotion,
    // Not a `#[source]`: the message already says it, and anyhow would print it twice.
    #[error("valid ranges: {0}")]
    Ranges(RangeError),
}

impl From<RangeError> for RigError {
    fn from(e: RangeError) -> Self {
        RigError::Ranges(e)
    }
}

/// How learning went.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Training {
    pub poses: usize,
    pub seconds: f64,
    /// The paper's networks, where they were learned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network: Option<TrainReport>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateral: Option<TrainReport>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub protrusion: Option<TrainReport>,
    pub modes: AdditiveReport,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub couplings: Option<AdditiveReport>,
}

/// The rig's input scaling: `x_n = (x − mean) · scale` takes the jaw vectors to the units the
/// modes work in (the widest coordinate with a standard deviation of 0.1, as Scholz's NLPCA).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct InputScaling {
    pub mean: [f64; 6],
    pub scale: f64,
}

impl InputScaling {
    const STD: f64 = 0.1;

    fn of(samples: &[Vec<f64>]) -> Result<InputScaling, RigError> {
        let (mean, max_std) = super::nlpca::mean_and_widest_std(samples);
        if max_std.is_nan() || max_std <= 1e-12 {
            return Err(RigError::NoMotion);
        }
        Ok(InputScaling {
            mean: std::array::from_fn(|q| mean[q]),
            scale: Self::STD / max_std,
        })
    }
}

/// The paper's construction of Φ2 and Φ3 (one-component NLPCAs of D23 and D45), kept for
/// comparison: it assumes components 2-3 are lateral excursion and 4-5 protrusion, which holds
/// for the paper's data but not for motion whose remainder after opening is two-dimensional
/// (then D23 holds both modes and D45 almost nothing). `rig eval` reports its error.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PaperModes {
    pub lateral: Nlpca,
    pub protrusion: Nlpca,
    /// Φgen(0), in the vector units of [`Coordinates`].
    pub base: [f64; 6],
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct JawRig {
    pub format: String,
    pub coords: Coordinates,
    /// Linear PCA of the same vectors, for comparison and its singular values.
    pub pca: Pca,
    /// The five-component hierarchical NLPCA and the paper's D23/D45 construction, where they
    /// were learned (`paper` in the settings): for the figures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network: Option<Nlpca>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub paper: Option<PaperModes>,
    /// Absent in rig files written before it: then the network's (the same scaling).
    #[serde(default)]
    pub input: InputScaling,
    /// The rig: Φ(d) = mean + (Σ_i g_i(r_i) + Σ_{i<j} G_ij(r_i, r_j) + bias) / scale with
    /// r_i = d_i / gain_i, in normalised units; the couplings G only in the coupled model.
    pub modes: AdditiveModes,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub couplings: Option<Couplings>,
    /// d_i = gain_i · (the mode's own parameter): sign and arc-length scale.
    pub gain: [f64; 3],
    /// The parameters of the training poses (encoding starts from the nearest one).
    pub training_params: Vec<[f64; 3]>,
    pub ranges: Ranges,
    /// Extreme vertices of the mesh the rig was learned with (lower frame, mm): encoding
    /// fits these, so the rig file needs no mesh.
    pub probes_mm: Vec<[f64; 3]>,
    pub settings: RigSettings,
    pub training: Training,
    /// The jaw frame and rest bite, for animator units ([`super::units`]); absent in rig
    /// files written before them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anatomy: Option<super::units::RigAnatomy>,
}

/// The smallest training set: enough for the five-component network to be determined at all.
pub const MIN_POSES: usize = 12;

/// Sign and arc-length gain of each mode: `speed(k, raw)` is |dΦ_k/draw| in normalised units;
/// the sign makes d_k move the front of the mesh along `direction[k]`.
fn gains(raw: &[[f64; 3]], moved: &[Vector3<f64>], speed: impl Fn(usize, f64) -> f64) -> [f64; 3] {
    let direction = [-Vector3::y(), Vector3::x(), Vector3::z()];
    let n = raw.len().max(1) as f64;
    std::array::from_fn(|k| {
        let mean_speed = raw.iter().map(|r| speed(k, r[k])).sum::<f64>() / n;
        let mean_c = raw.iter().map(|r| r[k]).sum::<f64>() / n;
        let mean_m = moved.iter().map(|m| m.dot(&direction[k])).sum::<f64>() / n;
        let cov: f64 = raw
            .iter()
            .zip(moved)
            .map(|(r, m)| (r[k] - mean_c) * (m.dot(&direction[k]) - mean_m))
            .sum();
        let g = mean_speed.max(1e-12);
        if cov < 0.0 { -g } else { g }
    })
}

/// |d f / dc| by central differences.
fn speed_of(f: impl Fn(f64) -> Vec<f64>, c: f64) -> f64 {
    let h = 1e-4;
    let (a, b) = (f(c + h), f(c - h));
    a.iter()
        .zip(&b)
        .map(|(p, q)| (p - q).powi(2))
        .sum::<f64>()
        .sqrt()
        / (2.0 * h)
}

impl JawRig {
    /// Learn the rig from `poses`, telling `progress` how far it is.
    pub fn learn(
        poses: &[Pose],
        metric: &MeshMetric,
        settings: &RigSettings,
        progress: &Progress,
    ) -> Result<JawRig, RigError> {
        let started = std::time::Instant::now();
        if poses.len() < MIN_POSES {
            return Err(RigError::TooFewPoses {
                need: MIN_POSES,
                got: poses.len(),
            });
        }
        let coords = Coordinates::for_mesh(metric);
        let vectors: Vec<Vector6<f64>> = poses.iter().map(|p| coords.vector(p)).collect();
        let pca = Pca::fit(&vectors);
        let samples: Vec<Vec<f64>> = vectors.iter().map(|v| v.as_slice().to_vec()).collect();
        let input = InputScaling::of(&samples)?;

        // The rig's modes, fitted in normalised units: their sum, then (coupled) their
        // couplings from it.
        let front = metric
            .probes()
            .iter()
            .copied()
            .max_by(|a, b| a.z.total_cmp(&b.z))
            .unwrap_or_default();
        let moved: Vec<Vector3<f64>> = poses.iter().map(|p| p.transform_point(&front)).collect();
        let directions = mode_directions(&pca, &vectors, &moved);
        let normalised: Vec<f64> = samples
            .iter()
            .flat_map(|s| {
                s.iter()
                    .zip(&input.mean)
                    .map(|(v, m)| (v - m) * input.scale)
            })
            .collect();
        let (base, theta, modes_report) =
            additive::fit_vector(&normalised, 6, &directions, &settings.modes, progress);
        let (modes, couplings, raw, couplings_report) = match settings.model {
            RigModel::Additive => (base.unpack(&theta), None, base.params(&theta), None),
            RigModel::Coupled => {
                let (m, c, raw, report) =
                    coupled::fit(&normalised, base, theta, &settings.couplings, progress);
                (m, Some(c), raw, Some(report))
            }
        };
        let gain = gains(&raw, &moved, |k, c| speed_of(|c| modes.mode(k, c), c));
        let training_params: Vec<[f64; 3]> = raw
            .iter()
            .map(|r| std::array::from_fn(|k| r[k] * gain[k]))
            .collect();
        let ranges = Ranges::build(&training_params, settings.alpha)?;
        let (network, paper, reports) = if settings.paper {
            let (network, paper, reports) = learn_paper(&samples, settings, progress)?;
            (Some(network), Some(paper), Some(reports))
        } else {
            (None, None, None)
        };
        let [network_report, lateral_report, protrusion_report] =
            reports.map_or([None, None, None], |r| r.map(Some));
        Ok(JawRig {
            format: RIG_FORMAT.into(),
            coords,
            pca,
            network,
            paper,
            input,
            modes,
            couplings,
            gain,
            training_params,
            ranges,
            probes_mm: metric.probes().iter().map(|p| [p.x, p.y, p.z]).collect(),
            settings: settings.clone(),
            training: Training {
                poses: poses.len(),
                seconds: started.elapsed().as_secs_f64(),
                network: network_report,
                lateral: lateral_report,
                protrusion: protrusion_report,
                modes: modes_report,
                couplings: couplings_report,
            },
            anatomy: None,
        })
    }

    /// "coupled" or "additive": which model the rig is.
    pub fn model_name(&self) -> &'static str {
        if self.couplings.is_some() {
            "coupled"
        } else {
            "additive"
        }
    }

    /// Φ(d) in the vector units of [`Coordinates`].
    pub fn vector(&self, d: &[f64; 3]) -> Vector6<f64> {
        let raw: [f64; 3] = std::array::from_fn(|k| d[k] / self.gain[k]);
        let mut x = self.modes.generate(&raw);
        if let Some(c) = &self.couplings {
            c.add_to(&raw, &mut x);
        }
        Vector6::from_fn(|q, _| self.input.mean[q] + x[q] / self.input.scale)
    }

    /// The jaw pose `upper_from_lower` for parameters `d`.
    pub fn pose(&self, d: &[f64; 3]) -> Pose {
        self.coords.pose(&self.vector(d))
    }

    /// The paper's rig, Φ1(c1) + Φ2(e2) + Φ3(e3) (base counted once), through its extraction
    /// functions: `pose` rebuilt, where the paper's networks were learned.
    pub fn paper_reconstruct(&self, pose: &Pose) -> Option<Pose> {
        let (network, paper) = (self.network.as_ref()?, self.paper.as_ref()?);
        let c = network.extract(self.coords.vector(pose).as_slice());
        let part = |keep: [usize; 2]| {
            let mut z = [0.0; NETWORK_COMPONENTS];
            for k in keep {
                z[k] = c[k];
            }
            network.generate(&z)
        };
        let raw = [
            c[0],
            paper.lateral.extract(&part([1, 2]))[0],
            paper.protrusion.extract(&part([3, 4]))[0],
        ];
        let parts = [
            network.generate(&[raw[0]]),
            paper.lateral.generate(&[raw[1]]),
            paper.protrusion.generate(&[raw[2]]),
        ];
        let v =
            Vector6::from_fn(|q, _| parts[0][q] + parts[1][q] + parts[2][q] - 2.0 * paper.base[q]);
        Some(self.coords.pose(&v))
    }

    /// The parameters that bring the rig closest to `pose` (the probes' squared distances):
    /// from the nearest training pose's parameters, a few damped Gauss-Newton steps.
    pub fn encode(&self, pose: &Pose) -> [f64; 3] {
        let probes: Vec<Vector3<f64>> = self.probes_mm.iter().map(|p| Vector3::from(*p)).collect();
        let target: Vec<Vector3<f64>> = probes.iter().map(|p| pose.transform_point(p)).collect();
        let residual = |d: &[f64; 3]| -> Vec<f64> {
            let q = self.pose(d);
            probes
                .iter()
                .zip(&target)
                .flat_map(|(p, t)| {
                    let e = q.transform_point(p) - t;
                    [e.x, e.y, e.z]
                })
                .collect()
        };
        let v = self.coords.vector(pose);
        let start = self
            .training_params
            .iter()
            .map(|d| (d, (self.vector(d) - v).norm_squared()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or([0.0; 3], |(d, _)| *d);
        let d = levenberg_marquardt(
            |d| residual(&[d[0], d[1], d[2]]),
            &start,
            self.settings.encode_steps,
            1e-6,
        );
        [d[0], d[1], d[2]]
    }

    pub fn is_valid(&self, d: &[f64; 3]) -> bool {
        self.ranges.is_valid(d)
    }

    pub fn clamp(&self, d: &[f64; 3]) -> [f64; 3] {
        self.ranges.clamp(d)
    }
}

/// The paper's five-component network and its D23/D45 construction, each reduced to one
/// dimension, with their reports.
fn learn_paper(
    samples: &[Vec<f64>],
    settings: &RigSettings,
    progress: &Progress,
) -> Result<(Nlpca, PaperModes, [TrainReport; 3]), RigError> {
    let nl = |stage| move |error| RigError::Nlpca { stage, error };
    progress("the paper's five-component NLPCA");
    let (network, network_report) = Nlpca::train(samples, NETWORK_COMPONENTS, &settings.network)
        .map_err(nl("five-component"))?;
    let codes: Vec<Vec<f64>> = samples.iter().map(|s| network.extract(s)).collect();
    let part = |keep: [usize; 2]| -> Vec<Vec<f64>> {
        codes
            .iter()
            .map(|c| {
                let mut z = vec![0.0; NETWORK_COMPONENTS];
                for k in keep {
                    z[k] = c[k];
                }
                network.generate(&z)
            })
            .collect()
    };
    progress("the paper's D23 and D45");
    let (lateral, lateral_report) =
        Nlpca::train(&part([1, 2]), 1, &settings.mode).map_err(nl("lateral (D23)"))?;
    let (protrusion, protrusion_report) =
        Nlpca::train(&part([3, 4]), 1, &settings.mode).map_err(nl("protrusion (D45)"))?;
    let base = network.generate(&[0.0; NETWORK_COMPONENTS]);
    let paper = PaperModes {
        lateral,
        protrusion,
        base: std::array::from_fn(|k| base[k]),
    };
    Ok((
        network,
        paper,
        [network_report, lateral_report, protrusion_report],
    ))
}

/// Starting directions of the three modes (vector units, orthonormal): the first principal
/// direction (opening); in the plane of the next two, the one along which the front of the
/// mesh moves sideways (lateral excursion, by least squares over the training poses), and the
/// one orthogonal to it (protrusion).
fn mode_directions(pca: &Pca, vectors: &[Vector6<f64>], moved: &[Vector3<f64>]) -> [Vec<f64>; 3] {
    let p: Vec<Vector6<f64>> = pca
        .components
        .iter()
        .take(3)
        .map(|c| Vector6::from(*c))
        .collect();
    let mean = Vector6::from(pca.mean);
    // Regress the front's sideways motion on the scores along p2 and p3.
    let n = vectors.len().max(1) as f64;
    let scores: Vec<[f64; 2]> = vectors
        .iter()
        .map(|v| [p[1].dot(&(v - mean)), p[2].dot(&(v - mean))])
        .collect();
    let mx = moved.iter().map(|m| m.x).sum::<f64>() / n;
    let mut a = nalgebra::Matrix2::<f64>::zeros();
    let mut b = nalgebra::Vector2::<f64>::zeros();
    for (s, m) in scores.iter().zip(moved) {
        let s = nalgebra::Vector2::new(s[0], s[1]);
        a += s * s.transpose();
        b += s * (m.x - mx);
    }
    let coef = a
        .try_inverse()
        .map_or(nalgebra::Vector2::new(1.0, 0.0), |inv| inv * b);
    let coef = if coef.norm() > 0.0 {
        coef.normalize()
    } else {
        nalgebra::Vector2::new(1.0, 0.0)
    };
    let lateral = p[1] * coef[0] + p[2] * coef[1];
    let protrusion = p[2] * coef[0] - p[1] * coef[1];
    [p[0], lateral, protrusion].map(|u| u.as_slice().to_vec())
}
