//! Where a frame's masks come from when they are made as tracking goes (`jawtrack segment`),
//! and the second look at a frame lost on such masks: made again from wherever the jaw may be.

use super::state::{FrameResult, TrackState};
use crate::arch::{ArchPoses, LOWER_BIT, UPPER_BIT};
use crate::capture::{Capture, FrameMasks};
use crate::energy::raster::render_labels;
use crate::error::Result;
use crate::formats::Status;
use crate::geometry::Pose;

/// Where a frame's masks come from when they are not read from the capture's files: made as
/// tracking goes, from where it expects the arches (`jawtrack segment`).
pub trait MaskSource {
    /// The masks of `frame`; `expected`: the poses tracking will search from (the last good
    /// one first). Asked again for the same frame, the masks replace the earlier ones, made
    /// as if the earlier call had not been.
    fn frame_masks(&mut self, frame: u32, expected: &[ArchPoses]) -> Result<FrameMasks>;

    /// Whether the masks depend on `expected`: a frame tracked `low-confidence` from them is
    /// then looked at again, its masks made from wherever the jaw may be.
    fn follows_expected(&self) -> bool {
        false
    }

    /// `frame` came out at `poses` with `status`, from the masks last made for it: what a
    /// source learns as it goes (colour models) may learn from where the arches are.
    fn tracked(&mut self, _frame: u32, _poses: &ArchPoses, _status: Status) -> Result<()> {
        Ok(())
    }
}

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

/// A frame whose masks `source` makes from where tracking expects the arches (`expected`, the
/// frame's starts), tracked by `track`. Masks made from a lost arch's pose lose it again (a
/// lower arch expected wide open gives the crowns of a closed mouth to the upper arch, or to
/// nothing): a frame tracked `low-confidence` has its masks made again from wherever the jaw
/// may be (`coarse`, the jaw prior's coarse grid, on the upper arch just found, beside the
/// starts) and is tracked from those, kept where it is then `ok` or fits its masks better;
/// unless its masks show hardly any teeth ([`THIN_TEETH`]).
pub fn with_second_look(
    capture: &Capture,
    coarse: &[Pose],
    source: &mut dyn MaskSource,
    frame: u32,
    expected: &[ArchPoses],
    state: &mut TrackState,
    track: &mut dyn FnMut(&FrameMasks, &mut TrackState) -> Result<FrameResult>,
) -> Result<(FrameResult, FrameMasks)> {
    let masks = source.frame_masks(frame, expected)?;
    let before = state.clone();
    let result = track(&masks, state)?;
    if result.status != Status::LowConfidence
        || !source.follows_expected()
        || teeth_shown(capture, &masks, &result.poses) < THIN_TEETH
    {
        return Ok((result, masks));
    }
    let upper = result.poses.upper;
    let wider: Vec<ArchPoses> = expected
        .iter()
        .copied()
        .chain(coarse.iter().map(|jaw| ArchPoses {
            upper,
            lower: upper.compose(jaw),
        }))
        .collect();
    let again = source.frame_masks(frame, &wider)?;
    let mut looked = before;
    let second = track(&again, &mut looked)?;
    // Masks made from more poses may show more, so the area error (a share of the masks'
    // pixels) is what compares the two looks, not the energy.
    let worst = |r: &FrameResult| {
        r.energies
            .as_ref()
            .map_or(f64::INFINITY, |e| e[0].area_error().max(e[1].area_error()))
    };
    let evaluations = result.evaluations + second.evaluations;
    if second.status == Status::Ok || worst(&second) < worst(&result) {
        *state = looked;
        return Ok((
            FrameResult {
                evaluations,
                ..second
            },
            again,
        ));
    }
    // The first look stands, its masks made again (and written) as they were.
    let masks = source.frame_masks(frame, expected)?;
    Ok((
        FrameResult {
            evaluations,
            ..result
        },
        masks,
    ))
}
