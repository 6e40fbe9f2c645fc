//! A second look at a frame lost on masks made from where tracking expected the arches
//! (`jawtrack segment`): made again from wherever the jaw may be.

use super::sequence::{FrameResult, MaskSource, Run, Status, starts, track_frame};
use super::state::TrackState;
use crate::arch::{ArchPoses, LOWER_BIT, UPPER_BIT};
use crate::capture::{Capture, FrameMasks};
use crate::energy::EnergyEngine;
use crate::energy::raster::render_labels;
use crate::error::Result;

/// Below this share of the arches' drawn pixels labelled teeth, a frame's masks show no
/// teeth to look for (a closed mouth, whose masks hold specks at most): a second look, drawing
/// the prior over the jaw's whole range, would find such specks there and take them for an
/// arch. Where lips hide most of the crowns, a tenth of them still shows.
const THIN_TEETH: f64 = 0.1;

/// The pixels `masks` label as teeth (either arch) over those of both arches drawn at `poses`,
/// in the cameras that have masks.
fn teeth_shown(capture: &Capture, masks: &FrameMasks, poses: &ArchPoses) -> f64 {
    let (mut drawn, mut labelled) = (0usize, 0usize);
    for (camera, mask) in capture.cameras().iter().zip(&masks.masks) {
        let (Some(cam), Some(mask)) = (camera.mask_camera(), mask) else {
            continue;
        };
        let items = [
            (capture.upper(), &poses.upper, UPPER_BIT, UPPER_BIT),
            (capture.lower(), &poses.lower, LOWER_BIT, LOWER_BIT),
        ];
        drawn += render_labels(&cam, &items)
            .iter()
            .filter(|&&l| l != 0)
            .count();
        let teeth = |v: &&u8| **v & (UPPER_BIT | LOWER_BIT) != 0;
        labelled += mask.data.iter().filter(teeth).count();
    }
    match drawn {
        0 => 0.0,
        _ => labelled as f64 / drawn as f64,
    }
}

/// A frame whose masks `source` makes from where tracking expects the arches. Masks made
/// from a lost arch's pose lose it again (a lower arch expected wide open gives the crowns of a
/// closed mouth to the upper arch, or to nothing): a frame tracked `low-confidence` has its
/// masks made again from wherever the jaw may be (the jaw prior's coarse grid on the upper
/// arch just found, beside the starts) and is tracked from those, kept where it is then `ok`
/// or fits its masks better; unless its masks show hardly any teeth ([`THIN_TEETH`]).
pub(super) fn with_second_look(
    run: &Run,
    engine: &mut dyn EnergyEngine,
    source: &mut dyn MaskSource,
    frame: u32,
    state: &mut TrackState,
) -> Result<(FrameResult, FrameMasks)> {
    let expected = starts(state);
    let masks = source.frame_masks(frame, &expected)?;
    let before = state.clone();
    let result = track_frame(run, engine, frame, &masks, state)?;
    if result.status != Status::LowConfidence
        || !source.follows_expected()
        || teeth_shown(run.capture, &masks, &result.poses) < THIN_TEETH
    {
        return Ok((result, masks));
    }
    let upper = result.poses.upper;
    let wider: Vec<ArchPoses> = expected
        .iter()
        .copied()
        .chain(run.prior.coarse.iter().map(|jaw| ArchPoses {
            upper,
            lower: upper.compose(jaw),
        }))
        .collect();
    let again = source.frame_masks(frame, &wider)?;
    let mut looked = before;
    let second = track_frame(run, engine, frame, &again, &mut looked)?;
    // Masks made from more poses may show more, so the area error (a share of the masks'
    // pixels) is what compares the two looks, not the energy.
    let worst = |r: &FrameResult| {
        r.energies
            .as_ref()
            .map_or(f64::INFINITY, |e| e[0].area_error().max(e[1].area_error()))
    };
    if second.status == Status::Ok || worst(&second) < worst(&result) {
        *state = looked;
        let evaluations = result.evaluations + second.evaluations;
        return Ok((
            FrameResult {
                evaluations,
                ..second
            },
            again,
        ));
    }
    // The first look stands, its masks made again (and written) as they were.
    let masks = source.frame_masks(frame, &expected)?;
    Ok((result, masks))
}

