//! Frames tracked again from a corrected one, in the background: forward as a resumed run of
//! a scratch file beside tracks.json, backward from the corrected poses.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::{Frames, TrackedFrame, Workbench, beside, lock, shown};
use crate::arch::ArchPoses;
use crate::capture::{Capture, FrameMasks};
use crate::energy::{Scene, open_engine};
use crate::error::{Error, Result};
use crate::formats::{FrameRecordJson, Status, TRACKS_FORMAT, TracksJson};
use crate::io::write_json_atomic;
use crate::track::output::{SettledFrames, TracksWriter, as_tracked, journal_path, record};
use crate::track::window::Window;
use crate::track::{FrameResult, MaskSource, Session, SessionOptions, TrackState, track_frames};

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

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RetrackQuery {
    pub frame: u32,
    /// Track the frames before it instead, nearest first (where the run was lost before it).
    #[serde(default)]
    pub backward: bool,
}

impl Workbench {
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

    pub fn job(&self) -> JobReply {
        let mut j = lock(&self.job).clone();
        j.version = lock(&self.frames).version;
        j
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
                    &Window::new(&self.retracking.settings.window, &self.capture),
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
        let mut settled = SettledFrames::new(&Window::new(&settings.window, &self.capture));
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
                status: r.written_status(),
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

/// The re-track's own run.
fn scratch_path(tracks: &Path) -> PathBuf {
    beside(tracks, "retrack")
}
