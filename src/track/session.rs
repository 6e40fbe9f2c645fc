//! A tracking run from a capture to tracks.json, as `track`, `demo` and `bench track` do it:
//! the frames to do (after those a resumed run already has), the energy engine, the journal
//! and tracks.json, overlays. [`Session::open`] settles all of that before any frame is
//! tracked, so a caller can say what was chosen; [`Session::run`] then tracks.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::locate::locate;
use super::mask_source::MaskSource;
use super::output::TracksWriter;
use super::overlay;
use super::score::{ScoreReport, score};
use super::search::Solver;
use super::sequence::{Status, prior_and_penalties, track_frames};
use super::settings::TrackSettings;
use super::state::{FrameResult, TrackState};
use super::window::Window;
use crate::arch::ArchPoses;
use crate::capture::Capture;
use crate::energy::contour::ContourEdges;
use crate::energy::{Backend, EnergyEngine, Region, Scene, open_engine};
use crate::error::{Error, Result};
use crate::formats::FrameRecordJson;
use crate::io::Fnv;

/// What a run is asked to do.
#[derive(Debug, Clone)]
pub struct SessionOptions {
    /// Where tracks.json goes (its journal beside it).
    pub output: PathBuf,
    /// The frames to track; `None`: all of the capture's.
    pub frames: Option<Range<u32>>,
    pub backend: Backend,
    /// What the engine renders; tracking reads only the energy, so the default draws only
    /// what can change it.
    pub region: Region,
    /// Write the paper's overlay pictures per camera and frame into this folder.
    pub overlays: Option<PathBuf>,
    /// Continue after the last complete frame of an earlier run of the same output.
    pub resume: bool,
    /// Start over when the output exists.
    pub force: bool,
    /// Find the first frame's poses from its masks even where init.json gives them: for a run
    /// that starts later in a take (`frames`), where init.json's first-frame poses do not hold.
    pub locate: bool,
    pub settings: TrackSettings,
}

impl SessionOptions {
    /// Every frame, the default engine and settings, into `output`.
    pub fn new(output: impl Into<PathBuf>) -> SessionOptions {
        SessionOptions {
            output: output.into(),
            frames: None,
            backend: Backend::Auto,
            region: Region::Relevant,
            overlays: None,
            resume: false,
            force: false,
            locate: false,
            settings: TrackSettings::default(),
        }
    }
}

/// What a finished run did.
#[derive(Debug, Clone)]
pub struct Summary {
    /// Every record of tracks.json, those of an earlier run included.
    pub records: Vec<FrameRecordJson>,
    /// Frames tracked by this run.
    pub tracked_now: usize,
    pub seconds: f64,
    pub evaluations: usize,
    /// Gauss-Newton steps ([`super::FrameResult::steps`]).
    pub steps: usize,
    /// The engine and why it was chosen.
    pub backend: String,
    /// The search that ran (`auto` resolved for the capture).
    pub solver: Solver,
    /// The frames said the jaw's manifold does not fit the subject, and it was let go
    /// (`TrackState::manifold_fit`).
    pub manifold_released: bool,
}

impl Summary {
    /// How many of the records have this status.
    pub fn count(&self, status: Status) -> usize {
        self.records.iter().filter(|r| r.status() == status).count()
    }
}

/// An opened run: frames to do, engine, writer.
pub struct Session<'c> {
    capture: &'c Capture,
    options: SessionOptions,
    writer: TracksWriter,
    state: TrackState,
    todo: Range<u32>,
    engine: Box<dyn EnergyEngine>,
    backend: String,
}

impl<'c> Session<'c> {
    pub fn open(capture: &'c Capture, options: SessionOptions) -> Result<Session<'c>> {
        options.settings.validate()?;
        let all = capture.frames();
        let range = options.frames.clone().unwrap_or(all.clone());
        if range.start < all.start || range.end > all.end || range.start >= range.end {
            return Err(Error::invalid(
                capture.dir(),
                "frames",
                format!(
                    "{}..{} asked for, but the capture has frames {}..{}",
                    range.start, range.end, all.start, all.end
                ),
            ));
        }
        let (writer, done) = TracksWriter::open(
            &options.output,
            options.resume,
            options.force,
            all.clone(),
            &fingerprint(capture, &options.settings, options.locate),
            &Window::new(&options.settings.window, capture),
        )?;
        let next = done
            .last()
            .map_or(range.start, |r| r.frame + 1)
            .max(range.start);
        // A resumed run goes on from the state the earlier one ended in, replayed from its
        // records: the same starts, velocity and recent area errors.
        let opened = open_engine(
            options.backend,
            Scene::from_capture(capture),
            options.region,
        )?;
        let mut engine = opened.engine;
        let start = match capture.init() {
            Some(_) if !options.locate => capture.initial_poses()?,
            // Without init.json (or asked to) the arches are found in the run's first frame (a
            // resumed run finds the same poses again: the search depends on that frame's masks
            // alone).
            _ => {
                let masks = capture.load_masks(range.start)?;
                engine.set_frame(&masks)?;
                let edges = [
                    ContourEdges::of(capture.upper()),
                    ContourEdges::of(capture.lower()),
                ];
                let settings = options.settings.for_capture(capture);
                locate(capture, engine.as_ref(), &masks, &settings, &edges)?.poses
            }
        };
        let state = if options.resume {
            // The manifold the run holds the jaw to, whose fit the frames done have judged.
            let settings = options.settings.for_capture(capture);
            let (_, penalties) = prior_and_penalties(capture, &settings, &start);
            let manifold =
                (penalties.manifold.as_ref()).map(|m| (m, settings.jaw_manifold_release_mm));
            TrackState::replay(
                start,
                &done,
                &options.output,
                options.settings.confidence_window,
                manifold,
            )?
        } else {
            TrackState::new(start)
        };
        Ok(Session {
            capture,
            writer,
            state,
            todo: next..range.end,
            engine,
            backend: opened.choice,
            options,
        })
    }

    /// The frames this run will track.
    pub fn todo(&self) -> Range<u32> {
        self.todo.clone()
    }

    /// The engine and why it was chosen.
    pub fn backend(&self) -> &str {
        &self.backend
    }

    /// Track every frame to do; `on_frame` sees each as it is written (for progress).
    pub fn run(self, on_frame: &mut dyn FnMut(&FrameResult)) -> Result<Summary> {
        self.run_with(None, on_frame)
    }

    /// [`Session::run`] with the masks from `source` instead of the capture's files.
    pub fn run_with(
        mut self,
        source: Option<&mut dyn MaskSource>,
        on_frame: &mut dyn FnMut(&FrameResult),
    ) -> Result<Summary> {
        let started = Instant::now();
        let (mut evaluations, mut steps, mut tracked_now) = (0, 0, 0);
        let (capture, writer, overlays) = (self.capture, &mut self.writer, &self.options.overlays);
        track_frames(
            capture,
            self.engine.as_mut(),
            &self.options.settings,
            &self.todo.clone().collect::<Vec<u32>>(),
            &mut self.state,
            source,
            &mut |r, masks| {
                writer.push(r)?;
                if let Some(dir) = overlays {
                    overlay::write_overlays(dir, capture, masks, &r.poses)?;
                }
                evaluations += r.evaluations;
                steps += r.steps;
                tracked_now += 1;
                on_frame(r);
                Ok(())
            },
        )?;
        Ok(Summary {
            records: self.writer.finish()?,
            tracked_now,
            seconds: started.elapsed().as_secs_f64(),
            evaluations,
            steps,
            backend: self.backend,
            solver: self.options.settings.for_capture(capture).search.solver,
            manifold_released: self.state.manifold_fit.released,
        })
    }
}

/// What a run's result depends on, hashed (FNV-1a, 64 bits): the capture as loaded (cameras,
/// frames, meshes after simplification, mask mode and reduction, the start) and the settings.
/// A resumed run must have the same; the engine is left out, since every engine computes the
/// same energy.
pub fn fingerprint(capture: &Capture, settings: &TrackSettings, locate: bool) -> String {
    let mut hash = Fnv::default();
    if locate {
        // The start found from the masks, not init.json's (left out otherwise, so that runs
        // from before the option resume).
        hash.write(b"locate");
    }
    for cam in capture.cameras() {
        hash.write(format!("{:?} {:?}", cam.calibrated, cam.mask_size).as_bytes());
    }
    hash.write(
        format!(
            "{} {} {:?} {} {:?}",
            capture.first_frame(),
            capture.frame_count(),
            capture.mask_mode(),
            capture.mask_reduce(),
            capture.init()
        )
        .as_bytes(),
    );
    for mesh in [&capture.upper(), &capture.lower()] {
        hash.write(bytemuck::cast_slice(&mesh.positions));
        hash.write(bytemuck::cast_slice(&mesh.triangles));
        hash.write(&mesh.boi.iter().map(|&b| b as u8).collect::<Vec<u8>>());
    }
    hash.write(&serde_json::to_vec(settings).expect("plain data"));
    format!("{:016x}", hash.0)
}

/// Score written records (of tracks.json at `path`) against the capture's ground truth, if it
/// has any.
pub fn score_records(
    capture: &Capture,
    path: &Path,
    records: &[FrameRecordJson],
) -> Result<Option<ScoreReport>> {
    let tracked: Vec<(FrameRecordJson, ArchPoses)> = records
        .iter()
        .map(|r| Ok((r.clone(), r.poses(path)?)))
        .collect::<Result<_>>()?;
    Ok(score(capture, &tracked))
}
