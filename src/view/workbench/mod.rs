//! The page as the tracker's workbench: a tracked capture's frames, a frame's poses moved by
//! hand (a draft, with its energy's terms), saved as hand-set, and the frames after it tracked
//! again in the background from there.
//!
//! The capture's tracks.json is only ever replaced whole and atomically, and the first time
//! the page changes it the file as it was is kept beside it (`NAME.before-view.json`). A
//! re-track runs as a resumed `track` of a scratch file beside it (`NAME.retrack.json`) that
//! holds the frames up to the corrected one; when it ends, or is stopped, its frames and the
//! old ones after them become the new tracks.json, so nothing after the last frame it reached
//! is lost.

mod moves;
mod retrack;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, MutexGuard};

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

pub use moves::EditOp;
pub use retrack::{JobReply, RetrackQuery};

use crate::arch::{Arch, ArchPoses};
use crate::capture::{Capture, FrameMasks};
use crate::energy::cpu::CpuEnergy;
use crate::energy::{Backend, Energy, EnergyEngine, Region, Scene};
use crate::error::{Error, Result};
use crate::formats::{FrameRecordJson, PerArchJson, PoseJson, Status, TRACKS_FORMAT, TracksJson};
use crate::geometry::Camera;
use crate::io::write_json_atomic;
use crate::track::TrackSettings;
use crate::track::output::energy_json;
use crate::track::session::fingerprint;
use moves::moved;

/// How frames are tracked again: what `track` would be given.
#[derive(Debug, Clone)]
pub struct Retracking {
    pub settings: TrackSettings,
    pub backend: Backend,
    pub region: Region,
}

/// One frame as the page shows it.
#[derive(Debug, Clone, Copy)]
pub struct TrackedFrame {
    pub frame: u32,
    pub status: Status,
    pub hand_set: bool,
    /// Moved by hand and not saved: the overlays draw the draft.
    pub drafted: bool,
    pub poses: ArchPoses,
}

/// A tracked capture on the page, shared by the server's threads and a re-track's.
pub struct Workbench {
    pub capture: Arc<Capture>,
    tracks: PathBuf,
    retracking: Retracking,
    /// The fingerprint a re-track's output carries: this capture with these settings.
    fingerprint: String,
    /// Whether tracks.json was written with other settings than [`Retracking`]'s.
    pub other_settings: bool,
    frames: Mutex<Frames>,
    /// The draft's energies (CPU reference: one evaluation per arch at a time) and the frame
    /// whose masks it holds.
    preview: Mutex<(CpuEnergy, Option<u32>)>,
    job: Mutex<JobReply>,
    stop: AtomicBool,
    /// Each arch's centre in its own frame (its bounding box's): moves turn about it.
    centres: [Vector3<f64>; 2],
}

struct Frames {
    /// tracks.json's records, by frame.
    records: Vec<FrameRecordJson>,
    /// What the page shows: the records' poses, a running re-track's as it goes.
    shown: Vec<TrackedFrame>,
    /// Poses being moved by hand, per frame, not yet saved.
    drafts: HashMap<u32, ArchPoses>,
    /// Each camera's crop of a frame's overlay, found at the frame's own poses, so that the
    /// picture stays put while a draft moves.
    crops: HashMap<(usize, u32), [u32; 4]>,
    /// Bumped by every change, for the page to know when to ask again.
    version: u64,
    /// Whether tracks.json as first read has been kept.
    backed_up: bool,
    /// The fingerprint tracks.json carries.
    fingerprint: Option<String>,
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(rename_all = "lowercase")]
pub enum ArchName {
    Upper,
    Lower,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EditQuery {
    pub frame: u32,
    pub arch: ArchName,
    pub op: EditOp,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameQuery {
    pub frame: u32,
}

/// An arch's energy terms at a pose, for the page.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Terms {
    pub uncovered: u64,
    pub boi_outside: u64,
    pub cross: u64,
    pub over_mouth: u64,
    /// The paper's E (uncovered + 0.4 · boi_outside).
    pub paper: f64,
    /// What the search minimises, at the run's weights.
    pub objective: f64,
    /// |model − mask| / mask area, in %.
    pub area_error_percent: f64,
}

/// A frame's poses as moved, with their terms and the saved poses'.
#[derive(Debug, Clone, Serialize)]
pub struct Draft {
    pub frame: u32,
    /// The arches' poses (world from arch) and the jaw's (upper from lower), column-major 4x4.
    pub upper: [f64; 16],
    pub lower: [f64; 16],
    pub jaw: [f64; 16],
    #[serde(skip)]
    pub poses: ArchPoses,
    pub terms: PerArchJson<Terms>,
    pub saved: PerArchJson<Terms>,
    pub hand_set: bool,
    /// Whether the frame now has unsaved moves.
    pub drafted: bool,
    pub version: u64,
}

impl Workbench {
    /// `capture`'s frames as `tracks` holds them; re-tracked with `retracking`.
    pub fn open(capture: Arc<Capture>, tracks: &Path, retracking: Retracking) -> Result<Workbench> {
        let json: TracksJson = crate::io::read_json(tracks, "tracks file")?;
        let mut records = json.frames;
        records.sort_by_key(|r| r.frame);
        records.dedup_by_key(|r| r.frame);
        if records.is_empty() {
            return Err(Error::invalid(tracks, "frames", "no frame to show"));
        }
        let shown = records
            .iter()
            .map(|r| shown(tracks, r))
            .collect::<Result<Vec<_>>>()?;
        let fingerprint = fingerprint(&capture, &retracking.settings, false);
        let other_settings = json.fingerprint.as_deref() != Some(fingerprint.as_str());
        let centre = |mesh: &crate::mesh::Mesh| {
            let (lo, hi) = mesh.bounds();
            Vector3::from_fn(|i, _| 0.5 * (lo[i] as f64 + hi[i] as f64))
        };
        let centres = [centre(capture.upper()), centre(capture.lower())];
        let preview = CpuEnergy::with_region(Scene::from_capture(&capture), Region::Relevant);
        Ok(Workbench {
            tracks: tracks.to_path_buf(),
            retracking,
            fingerprint,
            other_settings,
            frames: Mutex::new(Frames {
                records,
                shown,
                drafts: HashMap::new(),
                crops: HashMap::new(),
                version: 0,
                backed_up: false,
                fingerprint: json.fingerprint.clone(),
            }),
            preview: Mutex::new((preview, None)),
            job: Mutex::new(JobReply::default()),
            stop: AtomicBool::new(false),
            centres,
            capture,
        })
    }

    /// The frames as the page shows them (a draft in place of its frame's poses) and the
    /// version they are at.
    pub fn frames(&self) -> (Vec<TrackedFrame>, u64) {
        let f = lock(&self.frames);
        let mut shown = f.shown.clone();
        for s in &mut shown {
            s.drafted = f.drafts.contains_key(&s.frame);
        }
        (shown, f.version)
    }

    /// What the overlay of `frame` draws: the draft, else the frame's poses; and the crop
    /// kept for camera `k`, if any.
    pub fn overlay_poses(&self, k: usize, frame: u32) -> Option<(ArchPoses, Option<[u32; 4]>)> {
        let f = lock(&self.frames);
        let i = f.index(frame)?;
        let poses = f.drafts.get(&frame).copied().unwrap_or(f.shown[i].poses);
        Some((poses, f.crops.get(&(k, frame)).copied()))
    }

    /// Keep camera `k`'s crop of `frame` (found at the frame's saved poses).
    pub fn keep_crop(&self, k: usize, frame: u32, crop: [u32; 4]) {
        lock(&self.frames).crops.insert((k, frame), crop);
    }

    /// Move one arch of a frame's draft.
    pub fn edit(&self, q: &EditQuery) -> Result<Draft, String> {
        let mut f = lock(&self.frames);
        let i = f
            .index(q.frame)
            .ok_or_else(|| format!("frame {} is not on the timeline", q.frame))?;
        let saved = f.shown[i].poses;
        let mut poses = f.drafts.get(&q.frame).copied().unwrap_or(saved);
        let (pose, centre) = match q.arch {
            ArchName::Upper => (&mut poses.upper, self.centres[0]),
            ArchName::Lower => (&mut poses.lower, self.centres[1]),
        };
        if let EditOp::Reset = q.op {
            f.drafts.remove(&q.frame);
            f.version += 1;
            let hand_set = f.records[i].hand_set;
            drop(f);
            return self.draft_reply(q.frame, saved, saved, hand_set, false);
        }
        *pose = moved(*pose, &centre, &q.op, |name| self.camera(name))?;
        f.drafts.insert(q.frame, poses);
        f.version += 1;
        let hand_set = f.records[i].hand_set;
        drop(f);
        self.draft_reply(q.frame, poses, saved, hand_set, true)
    }

    /// Save a frame's draft (or its poses as they are) as hand-set: tracks.json is rewritten
    /// with it.
    pub fn correct(&self, frame: u32) -> Result<Draft, String> {
        self.idle()?;
        let mut f = lock(&self.frames);
        let i = f
            .index(frame)
            .ok_or_else(|| format!("frame {frame} is not on the timeline"))?;
        let poses = f.drafts.get(&frame).copied().unwrap_or(f.shown[i].poses);
        let energies = self.energies(frame, &poses).map_err(|e| e.to_string())?;
        f.records[i] = hand_set_record(frame, &poses, &energies);
        f.shown[i] = TrackedFrame {
            frame,
            status: Status::Ok,
            hand_set: true,
            drafted: false,
            poses,
        };
        f.drafts.remove(&frame);
        let records = f.records.clone();
        self.write(&mut f, records, None)
            .map_err(|e| e.to_string())?;
        f.version += 1;
        drop(f);
        self.draft_reply(frame, poses, poses, true, false)
    }

    /// Where tracks.json as first read is kept once the page changes it.
    pub fn backup(&self) -> PathBuf {
        backup_path(&self.tracks)
    }

    fn idle(&self) -> Result<(), String> {
        if lock(&self.job).running {
            return Err("a re-track is running: wait for it or stop it".into());
        }
        Ok(())
    }

    /// Replace tracks.json with `records` (its fingerprint kept unless `fingerprint` gives
    /// one), keeping the file as first read beside it the first time.
    fn write(
        &self,
        f: &mut Frames,
        records: Vec<FrameRecordJson>,
        fingerprint: Option<String>,
    ) -> Result<()> {
        if !f.backed_up {
            let backup = backup_path(&self.tracks);
            if self.tracks.exists() && !backup.exists() {
                std::fs::copy(&self.tracks, &backup).map_err(|error| Error::Write {
                    path: backup.clone(),
                    error,
                })?;
            }
            f.backed_up = true;
        }
        let fingerprint = fingerprint.or_else(|| f.fingerprint.clone());
        write_json_atomic(
            &self.tracks,
            &TracksJson {
                format: TRACKS_FORMAT.to_string(),
                fingerprint: fingerprint.clone(),
                frames: records.clone(),
            },
        )?;
        f.records = records;
        f.fingerprint = fingerprint;
        Ok(())
    }

    fn camera(&self, name: &str) -> Result<Camera, String> {
        let k = self
            .capture
            .camera_names()
            .iter()
            .position(|c| *c == name)
            .ok_or_else(|| format!("no camera {name:?}"))?;
        let c = &self.capture.cameras()[k];
        Ok(c.mask_camera().unwrap_or_else(|| c.calibrated.clone()))
    }

    /// Both arches' energies at `poses` on `frame`'s masks.
    fn energies(&self, frame: u32, poses: &ArchPoses) -> Result<[Energy; 2]> {
        let mut p = lock(&self.preview);
        if p.1 != Some(frame) {
            let masks: FrameMasks = self.capture.load_masks(frame)?;
            p.1 = None;
            p.0.set_frame(&masks)?;
            p.1 = Some(frame);
        }
        let upper = p.0.evaluate(Arch::Upper, &[*poses])?.remove(0);
        let lower = p.0.evaluate(Arch::Lower, &[*poses])?.remove(0);
        Ok([upper, lower])
    }

    fn terms(&self, e: &Energy) -> Terms {
        let weights = self
            .retracking
            .settings
            .for_capture(&self.capture)
            .search
            .weights();
        Terms {
            uncovered: e.uncovered(),
            boi_outside: e.boi_outside(),
            cross: e.cross(),
            over_mouth: e.over_mouth(),
            paper: e.total(crate::energy::DEFAULT_LAMBDA),
            objective: e.objective(&weights),
            area_error_percent: 100.0 * e.area_error(),
        }
    }

    fn draft_reply(
        &self,
        frame: u32,
        poses: ArchPoses,
        saved: ArchPoses,
        hand_set: bool,
        drafted: bool,
    ) -> Result<Draft, String> {
        let now = self.energies(frame, &poses).map_err(|e| e.to_string())?;
        let before = self.energies(frame, &saved).map_err(|e| e.to_string())?;
        let per = |e: &[Energy; 2]| PerArchJson {
            upper: self.terms(&e[0]),
            lower: self.terms(&e[1]),
        };
        Ok(Draft {
            frame,
            upper: poses.upper.column_major(),
            lower: poses.lower.column_major(),
            jaw: poses.jaw().column_major(),
            poses,
            terms: per(&now),
            saved: per(&before),
            hand_set,
            drafted,
            version: lock(&self.frames).version,
        })
    }
}

impl Frames {
    fn index(&self, frame: u32) -> Option<usize> {
        self.shown.binary_search_by_key(&frame, |f| f.frame).ok()
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic in another request leaves plain data behind: go on with it.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

fn shown(path: &Path, r: &FrameRecordJson) -> Result<TrackedFrame> {
    Ok(TrackedFrame {
        frame: r.frame,
        status: r.status(),
        hand_set: r.hand_set,
        drafted: false,
        poses: r.poses(path)?,
    })
}

/// A frame's record with its poses set by hand: held by the window, started from by a run.
fn hand_set_record(frame: u32, poses: &ArchPoses, e: &[Energy; 2]) -> FrameRecordJson {
    FrameRecordJson {
        frame,
        upper: PoseJson::from(&poses.upper),
        lower: PoseJson::from(&poses.lower),
        jaw: Some(PoseJson::from(&poses.jaw())),
        energy: Some(PerArchJson {
            lower: energy_json(&e[1]),
            upper: energy_json(&e[0]),
        }),
        area_error: Some(PerArchJson {
            lower: Some(e[1].area_error()),
            upper: Some(e[0].area_error()),
        }),
        status: Some(Status::Ok),
        jaw_source: None,
        tracked: None,
        hand_set: true,
        teeth_hidden: false,
        recovered: false,
        edge_offsets: None,
    }
}

/// `NAME.EXT` → `NAME.<tag>.EXT` beside it.
fn beside(path: &Path, tag: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path.extension().map(|s| s.to_string_lossy().into_owned());
    path.with_file_name(match ext {
        Some(ext) => format!("{stem}.{tag}.{ext}"),
        None => format!("{stem}.{tag}"),
    })
}

/// Where tracks.json as first read is kept.
pub fn backup_path(tracks: &Path) -> PathBuf {
    beside(tracks, "before-view")
}

#[cfg(test)]
mod tests;
