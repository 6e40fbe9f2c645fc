//! What the page shows and asks: the rig with the meshes it moves, optionally a tracked
//! capture, and the answers to the page's questions (a pose for slider values, IK for a
//! dragged vertex, an animation as glTF, a camera's overlay) in the animator's units.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::anatomy::motion::{Anatomical, MotionFrame};
use crate::arch::ArchPoses;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::export::gltf::{self, write_gltf};
use crate::geometry::jaw_pose;
use crate::mesh::{Mesh, Simplify};
use crate::rig::ThreeParameterRig;
use crate::rig::animate::{Key, animate_animator};
use crate::rig::three::{nearest_animator, solve_animator};

use super::workbench::{Draft, EditQuery, FrameQuery, JobReply, RetrackQuery, Workbench};

/// The meshes the page draws: the upper arch fixed (upper frame), the lower arch and the
/// mandible moved by the jaw pose (lower frame), all in mm.
pub struct Meshes {
    pub upper: Option<Mesh>,
    pub lower: Mesh,
    pub mandible: Option<Mesh>,
}

/// Triangles of a mesh drawn while a slider, a drag or the orbit moves: software WebGL's
/// vertex work is most of a frame, and the full mesh is drawn once the motion rests.
pub const COARSE_TRIANGLES: usize = 2500;

/// The page's questions are answered here.
pub struct Viewer {
    /// The rig the sliders, IK and keys drive; `None`: the page shows the capture alone.
    posing: Option<Posing>,
    /// Animator units for the timeline: the rig's, or without one the tracked motion's.
    motion: Option<MotionFrame>,
    pub meshes: Meshes,
    /// Each mesh with fewer triangles over the same vertices, drawn while anything moves.
    coarse: Meshes,
    /// The capture given, for its pictures and the first pose picked on them.
    pub(super) capture: Option<Arc<Capture>>,
    /// The first pose last fitted from picked points, drawn over the pictures.
    pub(super) fitted: Mutex<Option<ArchPoses>>,
    tracked: Option<Arc<Workbench>>,
}

/// A rig with what the page needs of it.
struct Posing {
    rig: Box<dyn ThreeParameterRig + Send + Sync>,
    motion: MotionFrame,
    extent: Extent,
    rest: [f64; 3],
    /// The largest |parameter| a query may start from: the training poses' span, widened.
    param_bound: f64,
}

/// A point to move or a target farther than this from the jaw (mm) is no question the page asks.
const MAX_TARGET_MM: f64 = 1e4;

/// IK's answer counts as reached when the vertex ends this close to where it was dragged (mm):
/// about what a drag on the page can place.
const IK_REACHED_MM: f64 = 1.0;

/// Frames one animation request may solve (an hour at 24 fps); each costs a rig solve.
const MAX_ANIMATION_FRAMES: f64 = 86_400.0;

/// The sliders' full travel: the training poses' span in animator units, widened by a
/// quarter so poses beyond it can be tried (and shown out of range).
#[derive(Debug, Clone, Serialize)]
pub struct Extent {
    pub opening_deg: [f64; 2],
    pub lateral_mm: [f64; 2],
    pub protrusion_mm: [f64; 2],
}

/// A jaw pose as the page shows it.
#[derive(Debug, Clone, Serialize)]
pub struct PoseReply {
    /// The network's parameters: internal, handed back as the next query's start.
    pub params: [f64; 3],
    /// Whether the rig reached the animator values asked for (else `params` are the start's);
    /// for IK, whether the vertex came within [`IK_REACHED_MM`] of its target.
    pub reached: bool,
    /// Inside the alpha-shape ranges learned from the training poses.
    pub valid: bool,
    pub animator: AnimatorJson,
    /// The valid lateral and protrusion at this opening (mm); `None` where the opening itself
    /// is outside the learned ranges.
    pub lateral_range_mm: Option<[f64; 2]>,
    pub protrusion_range_mm: Option<[f64; 2]>,
    /// upper_from_lower as a column-major 4x4 (mm), as WebGL takes it.
    pub jaw: [f64; 16],
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct AnimatorJson {
    pub opening_deg: f64,
    pub incisal_opening_mm: f64,
    pub lateral_mm: f64,
    pub protrusion_mm: f64,
}

impl From<Anatomical> for AnimatorJson {
    fn from(a: Anatomical) -> Self {
        AnimatorJson {
            opening_deg: a.opening_deg,
            incisal_opening_mm: a.incisal_opening_mm,
            lateral_mm: a.lateral_mm,
            protrusion_mm: a.protrusion_mm,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseQuery {
    /// Opening (degrees), lateral (mm), protrusion (mm).
    pub target: [f64; 3],
    pub from: Option<[f64; 3]>,
}

/// Which moving mesh a dragged vertex belongs to.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(rename_all = "lowercase")]
pub enum Part {
    Lower,
    Mandible,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IkQuery {
    pub part: Part,
    pub vertex: usize,
    /// Where the vertex should go, upper frame (mm).
    pub target: [f64; 3],
    pub from: [f64; 3],
}

#[derive(Debug, Clone, Serialize)]
pub struct IkReply {
    #[serde(flatten)]
    pub pose: PoseReply,
    pub residual_mm: f64,
    pub evaluations: usize,
    pub milliseconds: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnimationQuery {
    /// Keys in animator units: `params` = opening (°), lateral (mm), protrusion (mm).
    pub keys: Vec<Key>,
    pub fps: f64,
}

/// What the page loads first.
#[derive(Debug, Clone, Serialize)]
pub struct SceneReply {
    /// The kind of rig ("NLPCA rig", "envelope rig"); `None` without one (no sliders).
    pub rig: Option<&'static str>,
    pub extent: Option<Extent>,
    pub rest: Option<PoseReply>,
    pub meshes: Vec<&'static str>,
    /// The capture's cameras and first frame, when one was given (the first pose is picked
    /// on its pictures).
    pub capture: Option<CaptureInfo>,
    pub timeline: Option<Timeline>,
}

#[derive(Debug, Clone, Serialize)]
pub struct CaptureInfo {
    pub cameras: Vec<String>,
    pub first_frame: u32,
    /// Whether the capture has an init.json.
    pub has_init: bool,
    /// Per camera, the part of the first frame's picture shown (x, y, width, height in the
    /// masks' pixels: around what its mask labels), `None` for the whole.
    pub crops: Vec<Option<[u32; 4]>>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Timeline {
    pub cameras: Vec<String>,
    pub frames: Vec<TimelineFrame>,
    /// Changes whenever a frame does (a correction, a re-track's frame).
    pub version: u64,
    pub job: JobReply,
    /// Where tracks.json as the page first read it is kept once the page changes it.
    pub backup: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct TimelineFrame {
    pub frame: u32,
    pub status: &'static str,
    pub hand_set: bool,
    /// Moved by hand on the page and not saved.
    pub drafted: bool,
    pub animator: AnimatorJson,
    pub jaw: [f64; 16],
}

/// A frame moved by hand, with the jaw's animator values.
#[derive(Debug, Clone, Serialize)]
pub struct DraftReply {
    #[serde(flatten)]
    pub draft: Draft,
    pub animator: Option<AnimatorJson>,
}

/// A question the page asked that has no answer: its message goes back as the reply.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{0}")]
pub struct Refused(pub String);

impl Viewer {
    /// A rig (with its path, which names it in errors; it must carry its jaw frame, the
    /// animator units), or without one `motion`, the units of the timeline.
    pub fn new(
        rig: Option<(Box<dyn ThreeParameterRig + Send + Sync>, &Path)>,
        motion: Option<MotionFrame>,
        meshes: Meshes,
        capture: Option<Arc<Capture>>,
        tracked: Option<Arc<Workbench>>,
    ) -> Result<Viewer> {
        let posing = rig.map(|(rig, path)| Posing::new(rig, path)).transpose()?;
        let coarse = |m: &Mesh| m.simplified(Simplify::MaxTriangles(COARSE_TRIANGLES));
        let coarse = Meshes {
            upper: meshes.upper.as_ref().map(coarse),
            lower: coarse(&meshes.lower),
            mandible: meshes.mandible.as_ref().map(coarse),
        };
        Ok(Viewer {
            motion: posing.as_ref().map(|p| p.motion.clone()).or(motion),
            posing,
            meshes,
            coarse,
            capture,
            fitted: Mutex::new(None),
            tracked,
        })
    }

    fn posing(&self) -> std::result::Result<&Posing, Refused> {
        self.posing
            .as_ref()
            .ok_or_else(|| Refused("no rig was given (`jawtrack view RIG.json ...`)".into()))
    }
}

impl Posing {
    fn new(rig: Box<dyn ThreeParameterRig + Send + Sync>, rig_path: &Path) -> Result<Posing> {
        let motion = rig.motion_frame().ok_or_else(|| {
            Error::invalid(
                rig_path,
                "anatomy",
                "the rig has no jaw frame (learned before animator units): learn it again",
            )
        })?;
        // The rest bite exactly (the rig's nearest parameters land a little off).
        let rest = solve_animator(&*rig, &motion, &[0.0; 3], rig.rest_params())
            .unwrap_or_else(|| rig.rest_params());
        let measured: Vec<Anatomical> = rig
            .spread()
            .iter()
            .map(|d| motion.measure(&rig.pose(d)))
            .collect();
        let span = |f: &dyn Fn(&Anatomical) -> f64| {
            let lo = measured.iter().map(f).fold(0.0f64, f64::min);
            let hi = measured.iter().map(f).fold(0.0f64, f64::max);
            let pad = 0.25 * (hi - lo).max(1.0);
            [lo - pad, hi + pad]
        };
        let extent = Extent {
            opening_deg: span(&|a| a.opening_deg),
            lateral_mm: span(&|a| a.lateral_mm),
            protrusion_mm: span(&|a| a.protrusion_mm),
        };
        let param_bound = 4.0
            * rig
                .spread()
                .iter()
                .chain([&rest])
                .flatten()
                .fold(1.0f64, |m, v| m.max(v.abs()));
        Ok(Posing {
            rig,
            motion,
            extent,
            rest,
            param_bound,
        })
    }

    fn reply(&self, params: [f64; 3], reached: bool) -> PoseReply {
        let pose = self.rig.pose(&params);
        // A band's ends, parameter k moved with the others kept, measured in mm.
        let span = |k: usize, measure: fn(&Anatomical) -> f64| {
            let [lo, hi] = self.rig.band(&params, k)?;
            let at = |v: f64| {
                let mut d = params;
                d[k] = v;
                measure(&self.motion.measure(&self.rig.pose(&d)))
            };
            let (a, b) = (at(lo), at(hi));
            Some([a.min(b), a.max(b)])
        };
        PoseReply {
            params,
            reached,
            valid: self.rig.is_valid(&params),
            animator: self.motion.measure(&pose).into(),
            lateral_range_mm: span(1, |a| a.lateral_mm),
            protrusion_range_mm: span(2, |a| a.protrusion_mm),
            jaw: pose.column_major(),
        }
    }

    /// A query's starting parameters, checked: finite and within the rig's reach.
    fn start(&self, from: Option<&[f64; 3]>) -> std::result::Result<Option<[f64; 3]>, Refused> {
        match from {
            Some(d)
                if d.iter()
                    .any(|v| !v.is_finite() || v.abs() > self.param_bound) =>
            {
                Err(Refused(format!(
                    "from: three finite parameters within ±{:.3} (the rig's own, as a reply gave them)",
                    self.param_bound
                )))
            }
            other => Ok(other.copied()),
        }
    }
}

impl Viewer {
    pub fn scene(&self) -> SceneReply {
        let mut meshes = vec!["lower"];
        if self.meshes.upper.is_some() {
            meshes.insert(0, "upper");
        }
        if self.meshes.mandible.is_some() {
            meshes.push("mandible");
        }
        SceneReply {
            rig: self.posing.as_ref().map(|p| p.rig.kind()),
            extent: self.posing.as_ref().map(|p| p.extent.clone()),
            rest: self.posing.as_ref().map(|p| p.reply(p.rest, true)),
            meshes,
            capture: self.capture_info(),
            timeline: self.timeline(),
        }
    }

    /// The pose with these animator values, solved from `from` (or the rest bite).
    pub fn pose(&self, q: &PoseQuery) -> std::result::Result<PoseReply, Refused> {
        if q.target.iter().any(|v| !v.is_finite() || v.abs() > 1e3) {
            return Err(Refused("target: three finite numbers, |v| ≤ 1000".into()));
        }
        let p = self.posing()?;
        let from = p.start(q.from.as_ref())?.unwrap_or(p.rest);
        // Where the rig cannot reach the values, the pose it comes nearest to is shown.
        Ok(
            match nearest_animator(&*p.rig, &p.motion, &q.target, from) {
                Some((d, miss)) if d.iter().all(|v| v.is_finite()) => p.reply(d, miss < 1e-3),
                _ => p.reply(from, false),
            },
        )
    }

    /// IK (Eq. 10): the valid parameters that bring the vertex closest to the target.
    pub fn ik(&self, q: &IkQuery) -> std::result::Result<IkReply, Refused> {
        let mesh = match q.part {
            Part::Lower => &self.meshes.lower,
            Part::Mandible => self
                .meshes
                .mandible
                .as_ref()
                .ok_or_else(|| Refused("there is no mandible mesh".into()))?,
        };
        let p = mesh.positions.get(q.vertex).ok_or_else(|| {
            Refused(format!(
                "vertex {}: the mesh has {} vertices",
                q.vertex,
                mesh.positions.len()
            ))
        })?;
        if q.target
            .iter()
            .any(|v| !v.is_finite() || v.abs() > MAX_TARGET_MM)
        {
            return Err(Refused(format!(
                "target: three finite numbers, |v| ≤ {MAX_TARGET_MM} mm"
            )));
        }
        let posing = self.posing()?;
        let from = posing.start(Some(&q.from))?.unwrap_or(posing.rest);
        let point = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        let started = Instant::now();
        let r = crate::rig::ik::solve(
            &*posing.rig,
            &point,
            &Vector3::from(q.target),
            &from,
            &Default::default(),
        )
        .map_err(|e| Refused(e.to_string()))?;
        let milliseconds = started.elapsed().as_secs_f64() * 1e3;
        Ok(IkReply {
            pose: posing.reply(r.params, r.residual_mm <= IK_REACHED_MM),
            residual_mm: r.residual_mm,
            evaluations: r.evaluations,
            milliseconds,
        })
    }

    /// The keyed animation as glTF 2.0 (upper fixed, lower arch and mandible animated).
    pub fn animation(&self, q: &AnimationQuery) -> std::result::Result<Vec<u8>, Refused> {
        if !(q.fps.is_finite() && q.fps > 0.0 && q.fps <= 1000.0) {
            return Err(Refused("fps: above 0, at most 1000".into()));
        }
        let span = q.keys.last().map_or(0.0, |k| k.time) - q.keys.first().map_or(0.0, |k| k.time);
        if span > 3600.0 {
            return Err(Refused("keys: at most an hour of animation".into()));
        }
        if span * q.fps > MAX_ANIMATION_FRAMES {
            return Err(Refused(format!(
                "keys and fps: {:.0} frames; at most {MAX_ANIMATION_FRAMES} a request",
                span * q.fps
            )));
        }
        let frames = animate_animator(&*self.posing()?.rig, &q.keys, q.fps)
            .map_err(|e| Refused(e.to_string()))?;
        let keys = gltf::keys_of(&frames, q.fps);
        let m = &self.meshes;
        let upper = m.upper.as_ref().map(|u| gltf::Part {
            name: "upper",
            mesh: u,
            colour: gltf::UPPER_COLOUR,
        });
        let mandible = m.mandible.as_ref().map(|u| gltf::Part {
            name: "mandible",
            mesh: u,
            colour: gltf::MANDIBLE_COLOUR,
        });
        let lower = gltf::Part {
            name: "lower",
            mesh: &m.lower,
            colour: gltf::LOWER_COLOUR,
        };
        Ok(write_gltf(
            upper.as_ref(),
            &lower,
            mandible.as_ref(),
            &keys,
            "keyframed jaw",
        ))
    }

    pub(super) fn workbench(&self) -> std::result::Result<&Arc<Workbench>, Refused> {
        self.tracked
            .as_ref()
            .ok_or_else(|| Refused("no capture was given".into()))
    }

    /// The tracked frames as they now are.
    pub fn timeline(&self) -> Option<Timeline> {
        let t = self.tracked.as_ref()?;
        let motion = self.motion.as_ref()?;
        let (frames, version) = t.frames();
        Some(Timeline {
            cameras: t
                .capture
                .camera_names()
                .into_iter()
                .map(String::from)
                .collect(),
            frames: frames
                .iter()
                .map(|f| {
                    let jaw = jaw_pose(&f.poses.upper, &f.poses.lower);
                    TimelineFrame {
                        frame: f.frame,
                        status: f.status.as_str(),
                        hand_set: f.hand_set,
                        drafted: f.drafted,
                        animator: motion.measure(&jaw).into(),
                        jaw: jaw.column_major(),
                    }
                })
                .collect(),
            version,
            job: t.job(),
            backup: t.backup().display().to_string(),
        })
    }

    fn draft(
        &self,
        d: std::result::Result<Draft, String>,
    ) -> std::result::Result<DraftReply, Refused> {
        let draft = d.map_err(Refused)?;
        let jaw = draft.poses.jaw();
        Ok(DraftReply {
            animator: self.motion.as_ref().map(|m| m.measure(&jaw).into()),
            draft,
        })
    }

    /// Move an arch of a frame by hand.
    pub fn edit(&self, q: &EditQuery) -> std::result::Result<DraftReply, Refused> {
        self.draft(self.workbench()?.edit(q))
    }

    /// Save a frame's poses as hand-set.
    pub fn correct(&self, q: &FrameQuery) -> std::result::Result<DraftReply, Refused> {
        self.draft(self.workbench()?.correct(q.frame))
    }

    /// Track again after a frame, in the background.
    pub fn retrack(&self, q: &RetrackQuery) -> std::result::Result<JobReply, Refused> {
        self.workbench()?.retrack(q).map_err(Refused)
    }

    pub fn job(&self) -> std::result::Result<JobReply, Refused> {
        Ok(self.workbench()?.job())
    }

    pub fn stop(&self) -> std::result::Result<JobReply, Refused> {
        Ok(self.workbench()?.stop())
    }

    /// A mesh for WebGL: vertex and triangle counts (u32), positions (f32, mm), indices (u32),
    /// little-endian. `NAME.coarse`: the same vertices, the triangles drawn while anything
    /// moves.
    pub fn mesh_bytes(&self, name: &str) -> Option<Vec<u8>> {
        let (name, meshes) = match name.strip_suffix(".coarse") {
            Some(name) => (name, &self.coarse),
            None => (name, &self.meshes),
        };
        let m = match name {
            "upper" => meshes.upper.as_ref()?,
            "lower" => &meshes.lower,
            "mandible" => meshes.mandible.as_ref()?,
            _ => return None,
        };
        let mut out = Vec::with_capacity(8 + 12 * m.positions.len() + 12 * m.triangles.len());
        out.extend((m.positions.len() as u32).to_le_bytes());
        out.extend((m.triangles.len() as u32).to_le_bytes());
        for p in &m.positions {
            out.extend(bytemuck::cast_slice(p));
        }
        for t in &m.triangles {
            out.extend(bytemuck::cast_slice(t));
        }
        Some(out)
    }
}
