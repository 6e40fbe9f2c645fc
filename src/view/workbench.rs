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

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use nalgebra::{Rotation3, Unit, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::arch::{Arch, ArchPoses};
use crate::capture::{Capture, FrameMasks};
use crate::energy::cpu::CpuEnergy;
use crate::energy::open_engine;
use crate::energy::{Backend, Energy, EnergyEngine, Region, Scene};
use crate::error::{Error, Result};
use crate::formats::{FrameRecordJson, PerArchJson, PoseJson, Status, TRACKS_FORMAT, TracksJson};
use crate::geometry::{Camera, Pose};
use crate::io::write_json_atomic;
use crate::track::output::{
    SettledFrames, TracksWriter, as_tracked, energy_json, journal_path, record,
};
use crate::track::session::fingerprint;
use crate::track::{
    FrameResult, MaskSource, Session, SessionOptions, TrackSettings, TrackState, track_frames,
};

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
}

/// A re-track's progress, as the page polls it.
#[derive(Debug, Clone, Default, Serialize)]
pub struct JobReply {
    pub running: bool,
    pub backward: bool,
    /// The corrected frame it went on from, and the frame it goes to: the first it leaves as
    /// it was going forward, the last it tracks going back.
    pub from: Option<u32>,
    pub until: Option<u32>,
    pub done: usize,
    pub last: Option<u32>,
    /// Seconds from the request to its first tracked frame.
    pub first_frame_seconds: Option<f64>,
    pub message: String,
    pub version: u64,
}

/// What a drag, turn or nudge does to one arch of one frame.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum EditOp {
    /// Move parallel to camera `camera`'s picture by `pixels` (the overlay's, which are the
    /// masks').
    Drag { camera: String, pixels: [f64; 2] },
    /// Turn about the arch's centre: about the camera's viewing axis, then its x axis (a nod).
    Turn { camera: String, degrees: [f64; 2] },
    /// Move along the camera's viewing axis (mm, + away from it).
    Depth { camera: String, mm: f64 },
    /// Move and turn in the arch's own axes (x, y, z), about its centre.
    Nudge { mm: [f64; 3], degrees: [f64; 3] },
    /// Back to the frame's saved poses.
    Reset,
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

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RetrackQuery {
    pub frame: u32,
    /// Track the frames before it instead, nearest first (where the run was lost before it).
    #[serde(default)]
    pub backward: bool,
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

/// The largest move one request may make: more is no drag a page sends.
const MAX_PIXELS: f64 = 1e4;
const MAX_DEGREES: f64 = 180.0;
const MAX_MM: f64 = 100.0;

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
        let (arch, a) = match q.arch {
            ArchName::Upper => (Arch::Upper, 0),
            ArchName::Lower => (Arch::Lower, 1),
        };
        let pose = match arch {
            Arch::Upper => &mut poses.upper,
            Arch::Lower => &mut poses.lower,
        };
        let centre = self.centres[a];
        match &q.op {
            EditOp::Reset => {
                f.drafts.remove(&q.frame);
                f.version += 1;
                let hand_set = f.records[i].hand_set;
                drop(f);
                return self.draft_reply(q.frame, saved, saved, hand_set, false);
            }
            EditOp::Drag { camera, pixels } => {
                bounded(pixels, MAX_PIXELS, "pixels")?;
                let cam = self.camera(camera)?;
                let at = cam
                    .camera_from_world
                    .transform_point(&pose.transform_point(&centre));
                let moved = Vector3::new(pixels[0] * at.z / cam.fx, pixels[1] * at.z / cam.fy, 0.0);
                *pose = shifted(&cam, moved).compose(pose);
            }
            EditOp::Depth { camera, mm } => {
                bounded(&[*mm], MAX_MM, "mm")?;
                let cam = self.camera(camera)?;
                *pose = shifted(&cam, Vector3::new(0.0, 0.0, *mm)).compose(pose);
            }
            EditOp::Turn { camera, degrees } => {
                bounded(degrees, MAX_DEGREES, "degrees")?;
                let cam = self.camera(camera)?;
                let to_world = cam.camera_from_world.rotation.inverse();
                let c = pose.transform_point(&centre);
                for (axis, deg) in [(Vector3::z(), degrees[0]), (Vector3::x(), degrees[1])] {
                    let r = Rotation3::from_axis_angle(
                        &Unit::new_normalize(to_world * axis),
                        deg.to_radians(),
                    );
                    *pose = Pose::new(r, c - r * c).compose(pose);
                }
            }
            EditOp::Nudge { mm, degrees } => {
                bounded(mm, MAX_MM, "mm")?;
                bounded(degrees, MAX_DEGREES, "degrees")?;
                let d = degrees.map(f64::to_radians);
                let xi = Vector6::new(d[0], d[1], d[2], mm[0], mm[1], mm[2]);
                let about = Pose::from_translation(centre);
                *pose = pose
                    .compose(&about)
                    .compose(&Pose::exp(&xi))
                    .compose(&about.inverse());
            }
        }
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

    /// Track the frames after `frame` again, from its poses, up to the next hand-set frame
    /// (or the capture's end); or, `backward`, those before it down to the previous hand-set
    /// frame (or the capture's start). In the background.
    pub fn retrack(self: &Arc<Self>, q: &RetrackQuery) -> Result<JobReply, String> {
        let frame = q.frame;
        let mut job = lock(&self.job);
        if job.running {
            return Err("a re-track is running: stop it first".into());
        }
        let f = lock(&self.frames);
        let i = f
            .index(frame)
            .ok_or_else(|| format!("frame {frame} is not on the timeline"))?;
        if f.drafts.contains_key(&frame) {
            return Err(format!(
                "frame {frame} has unsaved moves: save it (or reset it) first"
            ));
        }
        let all = self.capture.frames();
        let (until, todo) = if q.backward {
            let since = f.records[..i]
                .iter()
                .rev()
                .find(|r| r.hand_set)
                .map_or(all.start, |r| r.frame + 1);
            (since, since..frame)
        } else {
            let until = f.records[i + 1..]
                .iter()
                .find(|r| r.hand_set)
                .map_or(all.end, |r| r.frame);
            (until, frame + 1..until)
        };
        if todo.is_empty() {
            return Err(format!(
                "no frame to track {} frame {frame} before the {} hand-set frame or the {}",
                if q.backward { "before" } else { "after" },
                if q.backward { "previous" } else { "next" },
                if q.backward { "start" } else { "end" },
            ));
        }
        let kept = f.records[..=i].to_vec();
        let corrected = f.shown[i].poses;
        drop(f);
        self.stop.store(false, Ordering::SeqCst);
        *job = JobReply {
            running: true,
            backward: q.backward,
            from: Some(frame),
            until: Some(until),
            message: if self.other_settings {
                "tracking again with this page's settings, not those tracks.json was written with"
                    .into()
            } else {
                "tracking again".into()
            },
            ..JobReply::default()
        };
        drop(job);
        let me = Arc::clone(self);
        let backward = q.backward;
        std::thread::spawn(move || {
            let started = Instant::now();
            let outcome = if backward {
                me.run_backward(frame, corrected, todo, started)
            } else {
                me.run_forward(kept, until, started)
            };
            let mut job = lock(&me.job);
            job.running = false;
            job.message = match outcome {
                Ok(None) => format!("tracked {} frames again", job.done),
                Ok(Some(at)) => {
                    format!("stopped at frame {at}; the frames from there are as they were")
                }
                Err(e) => format!("failed: {e}"),
            };
        });
        Ok(self.job())
    }

    /// Ask a running re-track to stop after the frame it is on.
    pub fn stop(&self) -> JobReply {
        self.stop.store(true, Ordering::SeqCst);
        self.job()
    }

    /// Where tracks.json as first read is kept once the page changes it.
    pub fn backup(&self) -> PathBuf {
        backup_path(&self.tracks)
    }

    pub fn job(&self) -> JobReply {
        let mut j = lock(&self.job).clone();
        j.version = lock(&self.frames).version;
        j
    }

    fn idle(&self) -> Result<(), String> {
        if lock(&self.job).running {
            return Err("a re-track is running: wait for it or stop it".into());
        }
        Ok(())
    }

    /// A re-track forward; `Some(frame)` where it was stopped before `frame`.
    fn run_forward(
        &self,
        kept: Vec<FrameRecordJson>,
        until: u32,
        started: Instant,
    ) -> Result<Option<u32>> {
        let scratch = scratch_path(&self.tracks);
        // What a re-track killed with the server left behind is no part of this one.
        self.remove_scratch(&scratch);
        let first = kept[0].frame;
        write_json_atomic(
            &scratch,
            &TracksJson {
                format: TRACKS_FORMAT.to_string(),
                fingerprint: Some(self.fingerprint.clone()),
                frames: kept,
            },
        )?;
        let options = SessionOptions {
            frames: Some(first..until),
            backend: self.retracking.backend,
            region: self.retracking.region,
            resume: true,
            settings: self.retracking.settings.clone(),
            ..SessionOptions::new(&scratch)
        };
        let session = Session::open(&self.capture, options)?;
        let mut source = Stoppable {
            capture: &self.capture,
            stop: &self.stop,
        };
        let outcome = session.run_with(Some(&mut source), &mut |r| self.tracked(r, started));
        let (records, stopped) = match outcome {
            Ok(summary) => (summary.records, None),
            Err(Error::Stopped { frame }) => {
                // The frames it finished are in the scratch run's journal: settle them.
                let (writer, _) = TracksWriter::open(
                    &scratch,
                    true,
                    false,
                    self.capture.frames(),
                    &self.fingerprint,
                    &self.retracking.settings.window,
                )?;
                (writer.finish()?, Some(frame))
            }
            Err(e) => {
                self.remove_scratch(&scratch);
                return Err(e);
            }
        };
        let mut f = lock(&self.frames);
        let last = records.last().map_or(first, |r| r.frame);
        let mut all = records;
        all.extend(f.records.iter().filter(|r| r.frame > last).cloned());
        self.replace(&mut f, all)?;
        drop(f);
        self.remove_scratch(&scratch);
        Ok(stopped)
    }

    /// A re-track backward over `todo` (nearest `frame` first) from its `corrected` poses;
    /// `Some(frame)` where it was stopped before `frame`. Its frames take the old ones' place
    /// and every frame is settled again by the window, as one run's would be.
    fn run_backward(
        &self,
        frame: u32,
        corrected: ArchPoses,
        todo: Range<u32>,
        started: Instant,
    ) -> Result<Option<u32>> {
        let settings = &self.retracking.settings;
        let energies = self.energies(frame, &corrected)?;
        let start = match self.capture.init() {
            Some(_) => self.capture.initial_poses()?,
            None => corrected,
        };
        // The jaw prior is the run's (centred on its first pose); tracking goes on from the
        // corrected frame, with no velocity yet.
        let mut state = TrackState::new(start);
        state.advance(
            Status::Ok,
            corrected,
            energies[0].area_error().max(energies[1].area_error()),
            settings.confidence_window,
        );
        state.before = None;
        let mut engine = open_engine(
            self.retracking.backend,
            Scene::from_capture(&self.capture),
            self.retracking.region,
        )?
        .engine;
        let frames: Vec<u32> = todo.rev().collect();
        let mut source = Stoppable {
            capture: &self.capture,
            stop: &self.stop,
        };
        let mut new = Vec::new();
        let outcome = track_frames(
            &self.capture,
            engine.as_mut(),
            settings,
            &frames,
            &mut state,
            Some(&mut source),
            &mut |r, _| {
                new.push(record(r));
                self.tracked(r, started);
                Ok(())
            },
        );
        let stopped = match outcome {
            Ok(()) => None,
            Err(Error::Stopped { frame }) => Some(frame),
            Err(e) => return Err(e),
        };
        let mut f = lock(&self.frames);
        let replaced: std::collections::HashSet<u32> = new.iter().map(|r| r.frame).collect();
        let mut all: Vec<FrameRecordJson> = f
            .records
            .iter()
            .filter(|r| !replaced.contains(&r.frame))
            .cloned()
            .chain(new)
            .collect();
        all.sort_by_key(|r| r.frame);
        let mut settled = SettledFrames::new(&settings.window);
        for r in all {
            let (r, e) = as_tracked(&self.tracks, r)?;
            settled.push(r, e);
        }
        settled.settle(true);
        self.replace(&mut f, settled.output())?;
        Ok(stopped)
    }

    /// A re-track's outcome becomes tracks.json (with this page's fingerprint) and the frames
    /// shown.
    fn replace(&self, f: &mut Frames, records: Vec<FrameRecordJson>) -> Result<()> {
        self.write(f, records, Some(self.fingerprint.clone()))?;
        f.shown = f
            .records
            .iter()
            .map(|r| shown(&self.tracks, r))
            .collect::<Result<Vec<_>>>()?;
        f.crops.clear();
        f.version += 1;
        Ok(())
    }

    /// A re-track's frame `r` is shown as it comes.
    fn tracked(&self, r: &FrameResult, started: Instant) {
        let mut f = lock(&self.frames);
        if let Some(i) = f.index(r.frame) {
            f.shown[i] = TrackedFrame {
                frame: r.frame,
                status: r.status,
                hand_set: false,
                drafted: false,
                poses: r.poses,
            };
            f.drafts.remove(&r.frame);
            f.crops.retain(|&(_, frame), _| frame != r.frame);
        }
        f.version += 1;
        drop(f);
        let mut job = lock(&self.job);
        job.done += 1;
        job.last = Some(r.frame);
        job.first_frame_seconds
            .get_or_insert(started.elapsed().as_secs_f64());
    }

    fn remove_scratch(&self, scratch: &Path) {
        let _ = std::fs::remove_file(scratch);
        let _ = std::fs::remove_file(journal_path(scratch));
    }

    /// Replace tracks.json with `records` (its fingerprint kept unless `fingerprint` gives
    /// one), keeping the file as first read beside it the first time.
    fn write(
        &self,
        f: &mut Frames,
        records: Vec<FrameRecordJson>,
        fingerprint: Option<String>,
    ) -> Result<()> {
        let before: Option<TracksJson> = if self.tracks.exists() {
            Some(crate::io::read_json(&self.tracks, "tracks file")?)
        } else {
            None
        };
        if !f.backed_up {
            let backup = backup_path(&self.tracks);
            if let Some(b) = &before
                && !backup.exists()
            {
                write_json_atomic(&backup, b)?;
            }
            f.backed_up = true;
        }
        let fingerprint = fingerprint.or_else(|| before.and_then(|b| b.fingerprint));
        write_json_atomic(
            &self.tracks,
            &TracksJson {
                format: TRACKS_FORMAT.to_string(),
                fingerprint,
                frames: records.clone(),
            },
        )?;
        f.records = records;
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

/// The masks from the capture's files, until the page asks the run to stop.
struct Stoppable<'a> {
    capture: &'a Capture,
    stop: &'a AtomicBool,
}

impl MaskSource for Stoppable<'_> {
    fn frame_masks(&mut self, frame: u32, _expected: &[ArchPoses]) -> Result<FrameMasks> {
        if self.stop.load(Ordering::SeqCst) {
            return Err(Error::Stopped { frame });
        }
        self.capture.load_masks(frame)
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

/// A world translation by `moved`, given in camera `cam`'s axes.
fn shifted(cam: &Camera, moved: Vector3<f64>) -> Pose {
    Pose::from_translation(cam.camera_from_world.rotation.inverse() * moved)
}

fn bounded(values: &[f64], limit: f64, what: &str) -> Result<(), String> {
    if values.iter().all(|v| v.is_finite() && v.abs() <= limit) {
        Ok(())
    } else {
        Err(format!("{what}: finite numbers, each within ±{limit}"))
    }
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

/// The re-track's own run.
fn scratch_path(tracks: &Path) -> PathBuf {
    beside(tracks, "retrack")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{SynthOptions, generate};

    fn bench_on(frames: u32) -> (tempfile::TempDir, Workbench) {
        let dir = tempfile::tempdir().unwrap();
        let cap = dir.path().join("cap");
        generate(
            &cap,
            &SynthOptions {
                frames,
                ..SynthOptions::default()
            },
            &|| {},
        )
        .unwrap();
        let capture = Capture::open(&cap).unwrap();
        let w = Workbench::open(
            Arc::new(capture),
            &cap.join("gt/poses.json"),
            Retracking {
                settings: TrackSettings::default(),
                backend: Backend::Cpu,
                region: Region::Relevant,
            },
        )
        .unwrap();
        (dir, w)
    }

    /// The lower arch lost on frames 0..6 (3 mm off, flagged), frame 6 set right by hand and
    /// the frames before it tracked backwards from there: they come back to the truth, and the
    /// frames after it are as they were.
    #[test]
    fn a_run_lost_before_a_corrected_frame_is_tracked_backwards() {
        let dir = tempfile::tempdir().unwrap();
        let cap = dir.path().join("cap");
        generate(
            &cap,
            &SynthOptions {
                frames: 10,
                ..SynthOptions::default()
            },
            &|| {},
        )
        .unwrap();
        let capture = Capture::open(&cap).unwrap();
        let mut settings = TrackSettings::default();
        settings.search.solver = crate::track::Solver::GaussNewton;
        let tracks = dir.path().join("tracks.json");
        let options = SessionOptions {
            backend: Backend::Cpu,
            settings: settings.clone(),
            ..SessionOptions::new(&tracks)
        };
        let mut t = TracksJson {
            format: TRACKS_FORMAT.into(),
            fingerprint: None,
            frames: Session::open(&capture, options)
                .unwrap()
                .run(&mut |_| {})
                .unwrap()
                .records,
        };
        let after = t.frames[7].clone();
        for r in &mut t.frames[..6] {
            let mut lower = r.poses(&tracks).unwrap().lower;
            lower.translation.x += 3.0;
            r.lower = PoseJson::from(&lower);
            r.tracked = None;
            r.status = Some(Status::LowConfidence);
        }
        write_json_atomic(&tracks, &t).unwrap();
        let gt: Vec<ArchPoses> = (0..10).map(|f| capture.gt_poses(f).unwrap()).collect();
        let truth = |frame: u32| gt[frame as usize];
        let w = Arc::new(
            Workbench::open(
                Arc::new(capture),
                &tracks,
                Retracking {
                    settings,
                    backend: Backend::Cpu,
                    region: Region::Relevant,
                },
            )
            .unwrap(),
        );
        lock(&w.frames).drafts.insert(6, truth(6));
        w.correct(6).unwrap();
        let job = w
            .retrack(&RetrackQuery {
                frame: 6,
                backward: true,
            })
            .unwrap();
        assert!(
            job.running && job.backward && job.until == Some(0),
            "{job:?}"
        );
        while w.job().running {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let job = w.job();
        assert_eq!(job.done, 6, "{job:?}");
        let written: TracksJson = crate::io::read_json(&tracks, "tracks").unwrap();
        assert_eq!(written.frames.len(), 10);
        assert!(written.frames[6].hand_set);
        for r in &written.frames[..6] {
            let p = r.poses(&tracks).unwrap();
            let off = (p.lower.translation - truth(r.frame).lower.translation).norm();
            assert!(
                off < 0.5,
                "frame {}: lower {off:.2} mm from the truth",
                r.frame
            );
        }
        // The window settles frame 7 again beside its new neighbours; its tracked poses stay.
        assert_eq!(
            serde_json::to_value(&written.frames[7].tracked).unwrap(),
            serde_json::to_value(&after.tracked).unwrap()
        );
        assert!(!journal_path(&tracks).exists());
    }

    fn edit(w: &Workbench, arch: ArchName, op: EditOp) -> ArchPoses {
        w.edit(&EditQuery { frame: 1, arch, op }).unwrap().poses
    }

    /// A drag moves the arch's centre in that camera's picture by the pixels dragged; a turn
    /// keeps the centre where it was; a nudge and its opposite cancel; reset restores.
    #[test]
    fn moves_by_hand_do_what_the_page_says() {
        let (_dir, w) = bench_on(3);
        let cam = w.camera("cam0").unwrap();
        let saved = w.frames().0[1].poses;
        let at = |p: &ArchPoses| {
            cam.project(&p.lower.transform_point(&w.centres[1]))
                .unwrap()
        };
        let dragged = edit(
            &w,
            ArchName::Lower,
            EditOp::Drag {
                camera: "cam0".into(),
                pixels: [12.0, -7.0],
            },
        );
        let moved = at(&dragged) - at(&saved);
        assert!(
            (moved.x - 12.0).abs() < 0.05 && (moved.y + 7.0).abs() < 0.05,
            "{moved}"
        );
        assert_eq!(dragged.upper, saved.upper);
        let turned = edit(
            &w,
            ArchName::Lower,
            EditOp::Turn {
                camera: "cam1".into(),
                degrees: [5.0, -3.0],
            },
        );
        assert!((at(&turned) - at(&dragged)).norm() < 1e-6);
        let angle = turned
            .lower
            .rotation
            .angle_to(&dragged.lower.rotation)
            .to_degrees();
        assert!((angle - 34f64.sqrt()).abs() < 0.05, "{angle}");
        let there = edit(
            &w,
            ArchName::Upper,
            EditOp::Nudge {
                mm: [0.3, 0.0, -0.2],
                degrees: [0.0, 1.0, 0.0],
            },
        );
        assert!((there.upper.translation - saved.upper.translation).norm() > 0.2);
        let back = edit(
            &w,
            ArchName::Upper,
            EditOp::Nudge {
                mm: [-0.3, 0.0, 0.2],
                degrees: [0.0, -1.0, 0.0],
            },
        );
        assert!((back.upper.translation - saved.upper.translation).norm() < 1e-9);
        assert_eq!(edit(&w, ArchName::Lower, EditOp::Reset), saved);
        let far = w.edit(&EditQuery {
            frame: 1,
            arch: ArchName::Lower,
            op: EditOp::Drag {
                camera: "cam0".into(),
                pixels: [f64::NAN, 0.0],
            },
        });
        assert!(far.unwrap_err().contains("pixels"));
        let nowhere = w.edit(&EditQuery {
            frame: 1,
            arch: ArchName::Lower,
            op: EditOp::Depth {
                camera: "cam9".into(),
                mm: 1.0,
            },
        });
        assert!(nowhere.unwrap_err().contains("cam9"));
    }
}
