//! A frame looked at again: one lost (worse than any tracked frame may be) has its arches
//! found afresh from its masks alone, and the masks' information taken where the poses are.

use super::Run;
use crate::arch::ArchPoses;
use crate::capture::FrameMasks;
use crate::energy::smooth::Matrix12;
use crate::energy::{Energy, EnergyEngine};
use crate::error::Result;
use crate::track::locate::{MIN_PIXELS, relocate};
use crate::track::search::Solver;

/// The masks' information about `poses`, where the window over frames takes it.
pub(super) fn window_information(
    run: &Run,
    engine: &dyn EnergyEngine,
    masks: &FrameMasks,
    poses: &ArchPoses,
) -> Result<Option<Matrix12>> {
    (run.settings.window.frames > 0)
        .then(|| run.joint_frame().information(engine, masks, poses))
        .transpose()
}

/// Whether an arch fits its masks worse than any tracked one may (its area error above
/// `area_error`). An arch that leaves fewer of its mask's pixels uncovered than one camera needs
/// to place it is not lost, whatever share of a small mask that is (the lips closing over its
/// teeth), and its masks could not place it afresh.
pub(super) fn lost(energies: &[Energy; 2], area_error: f64) -> bool {
    energies
        .iter()
        .any(|e| e.area_error() > area_error && e.uncovered() >= MIN_PIXELS)
}

/// A frame lost (worse than any tracked frame may be) has its arches looked for afresh, from
/// its masks alone ([`relocate`]); they are taken where they fit better, penalties included.
pub(super) fn relocated(
    run: &Run,
    engine: &dyn EnergyEngine,
    masks: &FrameMasks,
    (poses, energies): (ArchPoses, [Energy; 2]),
    evaluations: &mut usize,
) -> Result<(ArchPoses, [Energy; 2])> {
    let settings = &run.settings;
    if !lost(&energies, settings.relocate_area_error) {
        return Ok((poses, energies));
    }
    let (found, spent) = relocate(run.capture, engine, masks, settings, &run.edges)?;
    *evaluations += spent;
    let Some(mut found) = found else {
        return Ok((poses, energies));
    };
    // Found from the masks alone, then solved as any frame is, with the penalties: the masks
    // of a lost frame may leave the arches a valley the joint's prior closes.
    if settings.search.solver == Solver::GaussNewton {
        let solved = (run.joint_frame()).solve(engine, masks, &[found.poses], None)?;
        *evaluations += solved.evaluations;
        (found.poses, found.energies) = (solved.poses, solved.energies);
    }
    let weights = settings.search.weights();
    let total = |p: &ArchPoses, e: &[Energy; 2]| {
        e[0].objective(&weights) + e[1].objective(&weights) + run.penalties.of(p)
    };
    Ok(
        if total(&found.poses, &found.energies) < total(&poses, &energies) {
            (found.poses, found.energies)
        } else {
            (poses, energies)
        },
    )
}
