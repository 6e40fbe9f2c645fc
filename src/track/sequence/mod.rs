//! Tracking a capture frame by frame (the driver around `search`): each frame starts from the
//! previous one, extrapolated at constant velocity when that fits the new masks better; masks
//! are read on a thread one frame ahead; every finished frame goes to an observer (the output
//! writer and the progress bar), so memory does not grow with the masks of past frames.

mod relocated;

use std::sync::mpsc::sync_channel;
use std::time::Instant;

use nalgebra::Vector3;

use self::relocated::{relocated, window_information};
use super::align::{ArchAlign, align_arch};
use super::contact::{Contact, ContactSettings};
use super::edge_offsets::{EdgeOffsets, corrected};
use super::joint_frame::{JointFound, JointFrame};
use super::manifold::JawManifold;
use super::mask_source::{MaskSource, with_second_look};
use super::penalties::Penalties;
use super::prior::{JawPrior, centre};
use super::search::{ArchSearch, Found, RADIUS_MM, Solver, search};
use super::settings::TrackSettings;
use super::state::{Caution, FrameResult, TrackState, as_written};
use crate::arch::{Arch, ArchPoses};
use crate::capture::{Capture, FrameMasks, MaskMode};
use crate::energy::contour::ContourEdges;
use crate::energy::{Energy, EnergyEngine};
use crate::error::Result;
pub use crate::formats::Status;
use crate::geometry::Pose;

/// Constant-velocity prediction: the last motion applied once more.
fn extrapolate(last: &Pose, before: &Pose) -> Pose {
    last.compose(&before.inverse()).compose(last)
}

/// The poses a frame's search starts from: the last good pose, its constant-velocity
/// extrapolation, the latest low-confidence estimate since and that estimate moved on as far
/// again from the last good pose (a fast motion blurs the frames it is fastest in, and such a
/// frame, well placed but flagged, is where the motion went on from).
pub fn starts(state: &TrackState) -> Vec<ArchPoses> {
    let on = |last: &ArchPoses, before: &ArchPoses| ArchPoses {
        upper: extrapolate(&last.upper, &before.upper),
        lower: extrapolate(&last.lower, &before.lower),
    };
    let mut starts = vec![state.last];
    if let Some(before) = &state.before {
        starts.push(on(&state.last, before));
    }
    if let Some(since) = &state.since_good {
        starts.push(*since);
        starts.push(on(since, &state.last));
    }
    starts
}

/// The jaw prior and the penalties of a run over `capture` (its `settings` made for it,
/// `TrackSettings::for_capture`), fitted around `start`, the poses tracking starts from.
pub fn prior_and_penalties(
    capture: &Capture,
    settings: &TrackSettings,
    start: &ArchPoses,
) -> (JawPrior, Penalties) {
    // The prior serves both mask modes: with combined masks a lower-arch start could win by
    // covering the upper arch's pixels, which the contact penalty forbids (docs/tracking.md).
    // Which side of each arch the other is on comes from the poses tracking starts from.
    let prior = match &settings.jaw_space {
        Some(space) => JawPrior::of_poses(
            &space.poses,
            settings.jaw_prior_grid.iter().product(),
            settings.jaw_prior_nearest,
            centre(capture, Arch::Lower),
        ),
        None => JawPrior::new(
            capture.upper(),
            capture.lower(),
            &start.jaw(),
            settings.jaw_prior_grid,
            settings.jaw_prior_fine_grid,
            settings.jaw_prior_nearest,
            centre(capture, Arch::Lower),
        ),
    };
    let contact = (settings.contact_weight > 0.0).then(|| {
        Contact::new(
            capture.upper(),
            capture.lower(),
            &start.jaw(),
            ContactSettings {
                weight: settings.contact_weight,
                tolerance_mm: settings.contact_tolerance_mm,
            },
        )
    });
    let per_arch = matches!(capture.mask_mode(), MaskMode::PerArch { .. });
    let manifold =
        (per_arch && settings.jaw_manifold_weight > 0.0 && prior.fine.len() >= 4).then(|| {
            let new = match settings.jaw_space {
                Some(_) => JawManifold::sampled,
                None => JawManifold::new,
            };
            new(
                &prior.fine,
                capture.lower(),
                settings.jaw_manifold_weight,
                settings.jaw_manifold_tolerance_mm,
            )
        });
    (prior, Penalties { contact, manifold })
}

/// Track `frames` in the order given (backwards too, from a frame set by hand), starting from
/// `state`, with the masks of the capture's files or, given a `source`, its; `on_frame`
/// receives every frame with its masks (for overlays, without reading them again).
pub fn track_frames(
    capture: &Capture,
    engine: &mut dyn EnergyEngine,
    settings: &TrackSettings,
    frames: &[u32],
    state: &mut TrackState,
    source: Option<&mut dyn MaskSource>,
    on_frame: &mut dyn FnMut(&FrameResult, &FrameMasks) -> Result<()>,
) -> Result<()> {
    let settings = settings.for_capture(capture);
    let centres = [centre(capture, Arch::Upper), centre(capture, Arch::Lower)];
    let (prior, penalties) = prior_and_penalties(capture, &settings, &state.start);
    // The solvers that align outlines, the window (which weighs each frame by what its edges
    // say) and the fresh look for a lost frame all read the arches' contour edges.
    let edges = [
        ContourEdges::of(capture.upper()),
        ContourEdges::of(capture.lower()),
    ];
    let mut run = Run {
        capture,
        settings,
        centres,
        prior,
        penalties,
        edges,
    };
    let mut done = |result: FrameResult, started: Instant, masks: &FrameMasks| {
        let seconds = started.elapsed().as_secs_f64();
        on_frame(&FrameResult { seconds, ..result }, masks)
    };
    if let Some(source) = source {
        for &frame in frames {
            run.let_go_of_manifold(state);
            let started = Instant::now();
            let expected = starts(state);
            let coarse = &run.prior.coarse;
            let mut track = |masks: &FrameMasks, state: &mut TrackState| {
                track_frame(&run, engine, frame, masks, state)
            };
            let (result, masks) =
                with_second_look(capture, coarse, source, frame, &expected, state, &mut track)?;
            source.tracked(frame, &result.poses, result.status)?;
            done(result, started, &masks)?;
        }
        return Ok(());
    }
    std::thread::scope(|scope| {
        let (tx, rx) = sync_channel::<(u32, Result<FrameMasks>)>(2);
        scope.spawn(move || {
            for &f in frames {
                if tx.send((f, capture.load_masks(f))).is_err() {
                    break; // the tracker stopped
                }
            }
        });
        for (frame, masks) in rx {
            let started = Instant::now();
            run.let_go_of_manifold(state);
            let masks = masks?;
            done(
                track_frame(&run, engine, frame, &masks, state)?,
                started,
                &masks,
            )?;
        }
        Ok(())
    })
}

/// The first pass's starts for `arch` (the other arch at `poses`): each of the frame's starts,
/// and for the lower arch the jaw prior's candidates placed on the upper arch as just found.
fn first_pass_options(
    prior: &JawPrior,
    starts: &[ArchPoses],
    poses: &ArchPoses,
    arch: Arch,
) -> Vec<ArchPoses> {
    let mut options: Vec<ArchPoses> = starts
        .iter()
        .map(|s| poses.with(arch, *s.get(arch)))
        .collect();
    if arch == Arch::Lower {
        let jaws: Vec<Pose> = starts.iter().map(ArchPoses::jaw).collect();
        options.extend(
            prior
                .candidates(&jaws)
                .iter()
                .map(|j| poses.with(arch, poses.upper.compose(j))),
        );
    }
    options
}

/// What stays the same over a run: the capture, its settings, the arches' centres (in their
/// model frames), the jaw prior and the penalties.
struct Run<'a> {
    capture: &'a Capture,
    settings: TrackSettings,
    centres: [Vector3<f64>; 2],
    prior: JawPrior,
    penalties: Penalties,
    /// Each arch's contour edges.
    edges: [ContourEdges; 2],
}

impl Run<'_> {
    /// The jaw's manifold left out from here on where the frames so far say it does not fit
    /// the subject (`TrackState::manifold_fit`).
    fn let_go_of_manifold(&mut self, state: &TrackState) {
        if state.manifold_fit.released {
            self.penalties.manifold = None;
        }
    }

    /// The Gauss-Newton solver over both arches with this run's prior and penalties.
    fn joint_frame(&self) -> JointFrame<'_> {
        JointFrame {
            capture: self.capture,
            search: &self.settings.search,
            prior: &self.prior,
            penalties: &self.penalties,
            edges: &self.edges,
        }
    }

    /// `arch`'s pose from the start `from` (both arches), by the run's solver.
    fn find(
        &self,
        engine: &dyn EnergyEngine,
        masks: &FrameMasks,
        arch: Arch,
        from: ArchPoses,
        seed: u64,
    ) -> Result<Found> {
        let search_settings = &self.settings.search;
        match search_settings.solver {
            Solver::Contour => align_arch(
                engine,
                &ArchAlign {
                    capture: self.capture,
                    masks,
                    edges: &self.edges[arch.index()],
                    arch,
                    from,
                    penalties: &self.penalties,
                    weights: search_settings.weights(),
                },
            ),
            // Gauss-Newton's fallback, and the paper's search itself.
            _ => search(
                engine,
                &ArchSearch {
                    arch,
                    from,
                    centre: &self.centres[arch.index()],
                    penalties: &self.penalties,
                    settings: search_settings,
                    seed,
                },
            ),
        }
    }
}

/// [`track_over`] the frame's masks corrected by each camera's whole pixels of edge offset
/// ([`corrected`]); a frame after which an offset rounds to another whole pixel or comes to be
/// applied (the take's first, where they are learned) is tracked again with them.
fn track_frame(
    run: &Run,
    engine: &mut dyn EnergyEngine,
    frame: u32,
    masks: &FrameMasks,
    state: &mut TrackState,
) -> Result<FrameResult> {
    let unknown = EdgeOffsets::unknown(run.capture.cameras().len());
    let corrections = |s: &TrackState| {
        let o = s.edge_offsets.as_ref().unwrap_or(&unknown);
        (o.whole_px(), o.applied())
    };
    let (before, saved) = (corrections(state), state.clone());
    let first = track_over(run, engine, frame, &corrected(masks, &before.0), state)?;
    if corrections(state) == before {
        return Ok(first);
    }
    *state = TrackState {
        edge_offsets: state.edge_offsets.take(),
        ..saved
    };
    let again = track_over(
        run,
        engine,
        frame,
        &corrected(masks, &corrections(state).0),
        state,
    )?;
    Ok(FrameResult {
        evaluations: first.evaluations + again.evaluations,
        steps: first.steps + again.steps,
        ..again
    })
}

fn track_over(
    run: &Run,
    engine: &mut dyn EnergyEngine,
    frame: u32,
    masks: &FrameMasks,
    state: &mut TrackState,
) -> Result<FrameResult> {
    let (capture, settings, prior, penalties) =
        (run.capture, &run.settings, &run.prior, &run.penalties);
    if masks.masks.iter().all(Option::is_none) {
        // No camera saw anything: keep the last good pose.
        state.no_data();
        return Ok(FrameResult {
            frame,
            poses: state.last,
            energies: None,
            status: Status::NoData,
            caution: None,
            evaluations: 0,
            steps: 0,
            information: None,
            edge_offsets: state.edge_offsets.clone(),
            seconds: 0.0,
        });
    }
    engine.set_frame(masks)?;
    let weights = settings.search.weights();
    let objective = |e: &Energy| e.objective(&weights);
    let (mut evaluations, mut steps) = (0, 0);
    // Start, per arch, from whichever fits this frame best: the last good pose, its
    // constant-velocity extrapolation, or the latest low-confidence estimate since.
    let starts = starts(state);
    let gn = &settings.search.gauss_newton;
    // Each camera's offset of its masks' edges, estimated beside the poses.
    let offsets = (settings.search.solver == Solver::GaussNewton && gn.edge_offsets).then(|| {
        (state.edge_offsets.clone())
            .unwrap_or_else(|| EdgeOffsets::unknown(capture.cameras().len()))
    });
    let mut second_opinion = None;
    if settings.search.solver == Solver::GaussNewton {
        let found = (run.joint_frame()).solve(&*engine, masks, &starts, offsets.as_ref())?;
        evaluations += found.evaluations;
        steps = found.steps;
        // A frame that fits worse than the recent ones (the confidence rule with the
        // solver's own, stricter ratio), or with an arch drawn over what the masks say is not
        // it, is taken over by the paper's search, with the whole jaw prior: an arch the masks
        // barely show (lips closing) may have slid away.
        let worst = worst_area_error(&found.energies);
        let strict = TrackSettings {
            low_confidence_ratio: gn.fallback_ratio,
            ..settings.clone()
        };
        let misdrawn = found
            .energies
            .iter()
            .map(|e| e.misdrawn_share(&weights))
            .fold(0.0, f64::max);
        let drawn_well = misdrawn <= gn.fallback_misdrawn;
        if state.confidence(&strict, worst) == Status::Ok && drawn_well {
            return accept_solved(
                run,
                engine,
                masks,
                state,
                frame,
                found,
                (evaluations, steps),
            );
        }
        // The paper's search looks for the lower arch among the average joint's poses too (the
        // jaw prior). Once the take has shown that this subject's jaw is not the average one
        // (its manifold let go), the answer it lands is a second opinion that overrules
        // Gauss-Newton's only with a clearly better fit, and only where the fit was what sent
        // the frame there: an arch drawn over the open mouth fits its area as well as the
        // truth does.
        second_opinion = (drawn_well && state.manifold_fit.released).then_some(found);
    }
    let mut poses = state.last;
    let passes = match capture.mask_mode() {
        MaskMode::PerArch { .. } => settings.per_arch_passes,
        MaskMode::Combined => settings.combined_passes,
    };
    for pass in 0..passes.max(1) {
        let mut moved: f64 = 0.0;
        for arch in Arch::BOTH {
            // The first pass picks the starts that fit this frame best (the jaw prior placed
            // on the upper arch as just found); later passes go on from where the last ended.
            let options = if pass == 0 {
                first_pass_options(prior, &starts, &poses, arch)
            } else {
                vec![poses]
            };
            let chosen = if options.len() > 1 {
                let e = engine.evaluate(arch, &options)?;
                evaluations += options.len();
                let scores: Vec<f64> = e
                    .iter()
                    .zip(&options)
                    .map(|(e, o)| objective(e) + penalties.of(o))
                    .collect();
                best_distinct(arch, &options, &scores, settings.restarts)
            } else {
                options
            };
            let mut best: Option<(f64, Pose)> = None;
            for (k, start) in chosen.iter().enumerate() {
                let seed = (frame as u64) << 12
                    | (pass as u64) << 8
                    | (k as u64) << 1
                    | (arch == Arch::Lower) as u64;
                let found = run.find(&*engine, masks, arch, *start, seed)?;
                evaluations += found.evaluations;
                if best.is_none_or(|(e, _)| found.objective < e) {
                    best = Some((found.objective, found.pose));
                }
            }
            let (_, found) = best.expect("a start");
            let (r, t) = poses.get(arch).distance_to(&found);
            moved = moved.max(t + r * RADIUS_MM);
            poses = poses.with(arch, found);
        }
        if moved < settings.settle_mm {
            break;
        }
    }
    // Gauss-Newton settles the second opinion's answer. A mouth opening wide shows more of the
    // masks' errors frame by frame: the paper's search then lands a fit no better, nearer the
    // average joint, and a pose further off; an arch lost on the way fits clearly worse.
    if let Some(found) = second_opinion {
        let settled = (run.joint_frame()).solve(&*engine, masks, &[poses], offsets.as_ref())?;
        evaluations += settled.evaluations;
        steps += settled.steps;
        let chosen = match overrules(&settled.energies, &found.energies, gn.fallback_gain) {
            true => settled,
            false => found,
        };
        return accept_solved(
            run,
            engine,
            masks,
            state,
            frame,
            chosen,
            (evaluations, steps),
        );
    }
    let energies = [
        engine.evaluate(Arch::Upper, &[poses])?.remove(0),
        engine.evaluate(Arch::Lower, &[poses])?.remove(0),
    ];
    evaluations += 2;
    let (poses, energies) = relocated(run, engine, masks, (poses, energies), &mut evaluations)?;
    // What the masks say about the poses found, for the window over frames.
    let information = window_information(run, engine, masks, &poses)?;
    // The edge offsets measured where the paper's search took the frame over from
    // Gauss-Newton: masks a pixel narrower leave a band of each tooth over the mouth interior,
    // which sends a frame there, and it is tracked again once the offsets apply.
    if let Some(before) = offsets {
        let measured = run
            .joint_frame()
            .measure_offsets(engine, masks, &poses, &before)?;
        state.edge_offsets = Some(measured);
    }
    let result = finish(run, state, frame, poses, energies, evaluations);
    Ok(FrameResult {
        steps,
        information,
        ..result
    })
}

/// The frame's result at `poses` (their energies `[upper, lower]`), its confidence, and the
/// state moved on.
fn finish(
    run: &Run,
    state: &mut TrackState,
    frame: u32,
    poses: ArchPoses,
    energies: [Energy; 2],
    evaluations: usize,
) -> FrameResult {
    let settings = &run.settings;
    let worst = worst_area_error(&energies);
    let status = state.confidence(settings, worst);
    let poses_written = as_written(&poses);
    let teeth_hidden = energies.iter().any(|e| {
        e.boi_shown()
            .is_some_and(|s| s < settings.hidden_teeth_share)
    });
    // Before the state moves on: it still says whether tracking was lost since the last good
    // frame.
    let caution = match (status, teeth_hidden, state.lost) {
        (Status::Ok, true, _) => Some(Caution::TeethHidden),
        (Status::Ok, false, true) => Some(Caution::Recovered),
        _ => None,
    };
    state.advance(status, poses_written, worst, settings.confidence_window);
    if let Some(m) = &run.penalties.manifold {
        let off_mm = m.distance_mm(&poses_written.jaw());
        (state.manifold_fit).note(status, off_mm, settings.jaw_manifold_release_mm);
    }
    FrameResult {
        frame,
        poses,
        energies: Some(energies),
        status,
        caution,
        evaluations,
        steps: 0,
        information: None,
        edge_offsets: state.edge_offsets.clone(),
        seconds: 0.0,
    }
}

/// Gauss-Newton's answer `found` taken as the frame's (looked at again where it is lost),
/// with the edge offsets it estimated; the frame took `evaluations` and `steps` so far.
fn accept_solved(
    run: &Run,
    engine: &mut dyn EnergyEngine,
    masks: &FrameMasks,
    state: &mut TrackState,
    frame: u32,
    found: JointFound,
    (mut evaluations, steps): (usize, usize),
) -> Result<FrameResult> {
    state.edge_offsets = found.offsets;
    let tracked = (found.poses, found.energies);
    let (poses, energies) = relocated(run, engine, masks, tracked, &mut evaluations)?;
    // A frame found afresh has the masks' information at its own poses.
    let information = match poses == found.poses {
        true => Some(found.information),
        false => window_information(run, engine, masks, &poses)?,
    };
    let result = finish(run, state, frame, poses, energies, evaluations);
    Ok(FrameResult {
        steps,
        information,
        ..result
    })
}

/// The worse arch's area error.
fn worst_area_error(energies: &[Energy; 2]) -> f64 {
    energies.iter().map(Energy::area_error).fold(0.0, f64::max)
}

/// Whether a second opinion fitting with `energies` overrules the first, fitting with `first`:
/// where its worse arch's area error is at least a share `gain` lower.
fn overrules(energies: &[Energy; 2], first: &[Energy; 2], gain: f64) -> bool {
    worst_area_error(energies) < (1.0 - gain) * worst_area_error(first)
}

/// The best `k` options for `arch` by objective that lie apart from each other (more than
/// 1 mm at an arch's radius): the starts a search runs from.
fn best_distinct(arch: Arch, options: &[ArchPoses], scores: &[f64], k: usize) -> Vec<ArchPoses> {
    let mut order: Vec<usize> = (0..options.len()).collect();
    order.sort_by(|&i, &j| scores[i].total_cmp(&scores[j]));
    let mut chosen: Vec<ArchPoses> = Vec::new();
    for i in order {
        let p = options[i].get(arch);
        let apart = chosen.iter().all(|c| {
            let (r, t) = c.get(arch).distance_to(p);
            t + r * RADIUS_MM > 1.0
        });
        if apart {
            chosen.push(options[i]);
            if chosen.len() >= k.max(1) {
                break;
            }
        }
    }
    chosen
}

#[cfg(test)]
mod tests;
