//! Each camera's offset of its masks' edges, estimated beside the poses.
//!
//! A segmentation tool (a threshold, a network, an exposure) may draw every tooth a pixel too
//! wide in one camera and a pixel too narrow in another, for the whole take. The arches then
//! move towards the cameras whose teeth look bigger and the three views pull them apart: a
//! pixel of such a bias costs the jaw most of a millimetre (docs/tracking.md, "A segmentation
//! tool's bias"). An offset per camera is what such a bias is, and the poses do not explain
//! it: a pose moves a silhouette's edges by different amounts along it, an offset moves them
//! all alike. So Gauss-Newton takes one unknown per view beside the two arches' increments,
//! its samples drawn that much wider ([`super::joint::align_both`]), and a take's offsets are
//! carried from frame to frame with what the frames have learned of them (their information,
//! partly forgotten at each frame, so that an exposure that drifts is followed).
//!
//! Every frame measures the offsets ([`step`]); one is applied, the samples drawn wider by it,
//! only once learned and clear of a segmentation's own noise ([`EdgeOffsets::applied`]). The
//! pixel counts read the masks corrected by its whole pixels ([`corrected`]), so that they
//! weigh poses as the solver does.

use std::borrow::Cow;

use nalgebra::{DMatrix, DVector};

use crate::arch::{LOWER_BIT, UPPER_BIT};
use crate::capture::masks::MOUTH_BIT;
use crate::capture::{FrameMasks, LabelMask};
use crate::energy::edge_terms::EdgeSample;
use crate::energy::smooth::{Matrix12, Vector12, ViewSums};
use crate::formats::EdgeOffsetsJson;

/// What an offset of a pixel costs with nothing learned of it, in the residuals' unit (pixels
/// of contour times pixels of offset): a few samples' worth, against a frame's hundreds.
const ZERO_PRIOR: f64 = 10.0;
/// The share of a frame's information about the offsets the next frame keeps.
const MEMORY: f64 = 0.8;
/// An offset is applied once the frames put it at least this far from zero (pixels of the
/// masks); below, it is only measured. Below it lies what a segmentation's own noise moves its
/// edges by, and where the lips hide the gum side of the crowns an offset is half a translation:
/// drawing the samples wider by such an offset moves the arches by more than it corrects
/// (docs/tracking.md, "A segmentation tool's bias").
pub const LEAST_PX: f64 = 0.3;
/// What the frames must have learned of an offset before it is applied (its information, in
/// the residuals' unit per pixel²): about a frame's worth with both arches' outlines in view. A
/// frame that shows little measures an offset from little, and applied, it moves the arches by
/// what it measured and measures more of it in turn.
pub const LEAST_INFORMATION: f64 = 300.0;
/// No offset beyond this many pixels (of the masks) is estimated: a segmentation that far off
/// is wrong, not biased.
const MOST_PX: f64 = 3.0;

/// The offsets (pixels of the masks, outwards: the masks' teeth wider than the model's) of a
/// set of cameras, and their information.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeOffsets {
    pub px: DVector<f64>,
    pub information: DMatrix<f64>,
}

impl EdgeOffsets {
    /// Nothing known of `cameras` cameras' offsets.
    pub fn unknown(cameras: usize) -> EdgeOffsets {
        EdgeOffsets {
            px: DVector::zeros(cameras),
            information: DMatrix::zeros(cameras, cameras),
        }
    }

    /// The offsets of the cameras `indices` (those with masks this frame), with what is known
    /// of them.
    pub fn of(&self, indices: &[usize]) -> EdgeOffsets {
        let n = indices.len();
        EdgeOffsets {
            px: DVector::from_fn(n, |i, _| self.px[indices[i]]),
            information: DMatrix::from_fn(n, n, |i, j| self.information[(indices[i], indices[j])]),
        }
    }

    /// The offsets after a frame that estimated `found` for the cameras `indices`: the next
    /// frame's prior, that frame's information partly forgotten.
    pub fn after(&self, indices: &[usize], found: &EdgeOffsets) -> EdgeOffsets {
        let mut next = self.clone();
        for (i, &a) in indices.iter().enumerate() {
            next.px[a] = found.px[i];
            for k in 0..next.px.len() {
                next.information[(a, k)] = 0.0;
                next.information[(k, a)] = 0.0;
            }
        }
        for (i, &a) in indices.iter().enumerate() {
            for (j, &b) in indices.iter().enumerate() {
                next.information[(a, b)] = MEMORY * found.information[(i, j)];
            }
        }
        next
    }

    /// Whether each camera's offset is applied: once the frames have learned enough of it
    /// ([`LEAST_INFORMATION`]) and put it at least [`LEAST_PX`] from zero.
    pub fn applied(&self) -> Vec<bool> {
        let known = |k: usize| self.information[(k, k)] >= LEAST_INFORMATION;
        (0..self.px.len())
            .map(|k| known(k) && self.px[k].abs() >= LEAST_PX)
            .collect()
    }

    /// The whole pixels by which each camera's masks are corrected ([`corrected`]): the
    /// offsets rounded.
    pub fn whole_px(&self) -> Vec<i32> {
        self.px.iter().map(|p| p.round() as i32).collect()
    }

    pub fn to_json(&self) -> EdgeOffsetsJson {
        let n = self.px.len();
        EdgeOffsetsJson {
            px: self.px.iter().copied().collect(),
            information: (0..n)
                .map(|i| (0..n).map(|j| self.information[(i, j)]).collect())
                .collect(),
        }
    }

    /// The offsets a record wrote; `None` where the information is not a square of their
    /// number.
    pub fn from_json(j: &EdgeOffsetsJson) -> Option<EdgeOffsets> {
        let cameras = j.px.len();
        let square =
            j.information.len() == cameras && j.information.iter().all(|r| r.len() == cameras);
        square.then(|| EdgeOffsets {
            px: DVector::from_column_slice(&j.px),
            information: DMatrix::from_fn(cameras, cameras, |i, k| j.information[i][k]),
        })
    }
}

/// Each view's offsets as a frame's Gauss-Newton takes them.
#[derive(Debug, Clone)]
pub struct ViewOffsets {
    /// What earlier frames know of them (pixels beyond the whole ones the masks were corrected
    /// by, [`corrected`]).
    pub prior: EdgeOffsets,
    /// Whether each is applied: the samples drawn wider by it, and it estimated with the poses.
    /// Where it is not, it is only measured, the poses' step as without it.
    pub applied: Vec<bool>,
}

impl ViewOffsets {
    /// Each view's offset the samples are drawn wider by: the applied ones'.
    pub fn drawn_px(&self) -> DVector<f64> {
        let px = |k: usize| {
            if self.applied[k] {
                self.prior.px[k]
            } else {
                0.0
            }
        };
        DVector::from_fn(self.applied.len(), |k, _| px(k))
    }
}

/// `samples` drawn wider by their view's offset `drawn_px` (pixels of the masks; `scale` of
/// them to the samples' level), those beside the other arch's model excepted.
pub fn widened(samples: &[EdgeSample], drawn_px: &DVector<f64>, scale: f64) -> Vec<EdgeSample> {
    let mut widened = samples.to_vec();
    for w in widened.iter_mut().filter(|w| !w.beside_other) {
        w.point.pixel += drawn_px[w.view] / scale * w.point.normal;
    }
    widened
}

/// What [`step`] gives.
pub struct Stepped {
    /// The poses' increments ξ.
    pub xi: Vector12,
    /// Each view's offset the samples are drawn wider by after the step (0 where not applied).
    pub drawn_px: DVector<f64>,
    /// The offsets the step measures, and their information given the poses' (the Schur
    /// complement).
    pub measured: EdgeOffsets,
}

/// One Gauss-Newton step over the increments ξ (normal equations `h`, `g`, everything of the
/// poses' already in) and the offsets' changes: `sums`, each view's samples' sums at a pyramid
/// level of `scale` mask pixels to its own; `drawn_px`, the offsets the samples were drawn
/// with; `offsets`, what earlier frames know and which are applied. `None` where the system is
/// singular.
pub fn step(
    (h, g): (&Matrix12, &Vector12),
    sums: &[ViewSums],
    scale: f64,
    drawn_px: &DVector<f64>,
    offsets: &ViewOffsets,
) -> Option<Stepped> {
    let (prior, v) = (&offsets.prior, sums.len());
    let n = 12 + v;
    let mut a = DMatrix::zeros(n, n);
    let mut b = DVector::zeros(n);
    a.view_mut((0, 0), (12, 12)).copy_from(h);
    b.rows_mut(0, 12).copy_from(g);
    // An offset moves every sample of its view outwards by 1/scale of the level's pixels.
    let e = 1.0 / scale;
    for (k, s) in sums.iter().enumerate() {
        a[(12 + k, 12 + k)] += s.weight * e * e;
        for i in 0..12 {
            a[(i, 12 + k)] += s.weighted_row[i] * e;
            a[(12 + k, i)] += s.weighted_row[i] * e;
        }
        b[12 + k] += s.weighted_offset * e;
    }
    let info = &prior.information + DMatrix::identity(v, v) * ZERO_PRIOR;
    let pull = &prior.information * (&prior.px - drawn_px) - drawn_px * ZERO_PRIOR;
    let mut block = a.view_mut((12, 12), (v, v));
    block += &info;
    let mut rows = b.rows_mut(12, v);
    rows += &pull;
    // The measurement: every offset free.
    let all = a.clone().cholesky()?.solve(&b);
    let px = DVector::from_fn(v, |k, _| {
        (drawn_px[k] + all[12 + k]).clamp(-MOST_PX, MOST_PX)
    });
    let poses_block = a.view((0, 0), (12, 12)).into_owned();
    let cross = a.view((0, 12), (12, v)).into_owned();
    let inverse = poses_block.clone().cholesky()?.inverse();
    let schur = a.view((12, 12), (v, v)).into_owned() - cross.transpose() * inverse * cross;
    let measured = EdgeOffsets {
        px,
        information: schur - DMatrix::identity(v, v) * ZERO_PRIOR,
    };
    // The step: the applied offsets free beside the poses, the others held.
    let keep: Vec<usize> = (0..12)
        .chain((0..v).filter(|&k| offsets.applied[k]).map(|k| 12 + k))
        .collect();
    let reduced = DMatrix::from_fn(keep.len(), keep.len(), |i, j| a[(keep[i], keep[j])]);
    let rhs = DVector::from_fn(keep.len(), |i, _| b[keep[i]]);
    let x = reduced.cholesky()?.solve(&rhs);
    let mut drawn = drawn_px.clone();
    for (i, &k) in keep.iter().enumerate().skip(12) {
        drawn[k - 12] = (drawn[k - 12] + x[i]).clamp(-MOST_PX, MOST_PX);
    }
    Some(Stepped {
        xi: Vector12::from_fn(|i, _| x[i]),
        drawn_px: drawn,
        measured,
    })
}

/// The frame's `masks` with each camera's teeth moved in by its whole pixels of offset
/// (`whole`, [`EdgeOffsets::whole_px`]; out where negative), against what is not teeth: what
/// the pixel counts (the confidence, the choice between candidates, the paper's search) read,
/// so that they weigh poses as the offsets' Gauss-Newton does. The edges between the arches
/// stay.
pub fn corrected<'m>(masks: &'m FrameMasks, whole: &[i32]) -> Cow<'m, FrameMasks> {
    if whole.iter().all(|&k| k == 0) {
        return Cow::Borrowed(masks);
    }
    let mut out = masks.clone();
    for (m, &k) in out.masks.iter_mut().zip(whole) {
        if let Some(m) = m {
            for _ in 0..k.unsigned_abs() {
                *m = moved_one_pixel(m, k > 0);
            }
        }
    }
    Cow::Owned(out)
}

/// `m` with its teeth shrunk (`inwards`) or grown by one pixel (4-neighbours) against what is
/// not teeth: a tooth pixel beside something else takes its label (the mouth's where one is
/// beside), and the other way round.
fn moved_one_pixel(m: &LabelMask, inwards: bool) -> LabelMask {
    let (w, h) = (m.width as usize, m.height as usize);
    let teeth = |v: u8| v & (UPPER_BIT | LOWER_BIT) != 0;
    let mut data = m.data.clone();
    for y in 0..h {
        for x in 0..w {
            let here = m.data[y * w + x];
            if teeth(here) != inwards {
                continue;
            }
            let beside = [
                (x > 0).then(|| m.data[y * w + x - 1]),
                (x + 1 < w).then(|| m.data[y * w + x + 1]),
                (y > 0).then(|| m.data[(y - 1) * w + x]),
                (y + 1 < h).then(|| m.data[(y + 1) * w + x]),
            ];
            let mut other = beside
                .into_iter()
                .flatten()
                .filter(|&v| teeth(v) != inwards);
            let first = other.next();
            data[y * w + x] = match (first, inwards) {
                (None, _) => here,
                // The mouth interior over the background, where the tooth had both beside it.
                (Some(v), true) => std::iter::once(v)
                    .chain(other)
                    .max_by_key(|&v| v & MOUTH_BIT)
                    .unwrap_or(v),
                (Some(v), false) => v,
            };
        }
    }
    LabelMask {
        soft: None,
        width: m.width,
        height: m.height,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row of pixels: background, the upper arch's label (1) three wide, the lower's (2)
    /// two wide, the mouth interior.
    fn row() -> FrameMasks {
        let data = vec![0, 1, 1, 1, 2, 2, MOUTH_BIT, MOUTH_BIT];
        FrameMasks {
            frame: 0,
            masks: vec![Some(LabelMask {
                soft: None,
                width: data.len() as u32,
                height: 1,
                data,
            })],
        }
    }

    fn data(m: &FrameMasks) -> Vec<u8> {
        m.masks[0].as_ref().unwrap().data.clone()
    }

    #[test]
    fn masks_are_corrected_against_what_is_not_teeth_only() {
        let m = row();
        assert!(matches!(corrected(&m, &[0]), Cow::Borrowed(_)));
        // In by a pixel: each label gives its outer pixel to what lies beside it; the edge
        // between the arches stays.
        assert_eq!(data(&corrected(&m, &[1])), [0, 0, 1, 1, 2, 4, 4, 4]);
        assert_eq!(data(&corrected(&m, &[2])), [0, 0, 0, 1, 4, 4, 4, 4]);
        // Out by a pixel: the teeth take the pixels beside them.
        assert_eq!(data(&corrected(&m, &[-1])), [1, 1, 1, 1, 2, 2, 2, 4]);
    }

    #[test]
    fn offsets_of_some_cameras_are_carried_into_the_takes() {
        let mut take = EdgeOffsets::unknown(3);
        take.information[(0, 0)] = 5.0;
        let found = EdgeOffsets {
            px: DVector::from_vec(vec![0.4, -1.2]),
            information: DMatrix::from_row_slice(2, 2, &[100.0, 10.0, 10.0, 50.0]),
        };
        let next = take.after(&[1, 2], &found);
        assert_eq!(next.px.as_slice(), [0.0, 0.4, -1.2]);
        assert_eq!(next.information[(0, 0)], 5.0);
        assert_eq!(next.information[(1, 2)], MEMORY * 10.0);
        assert_eq!(next.of(&[2]).px.as_slice(), [-1.2]);
        assert_eq!(next.whole_px(), [0, 0, -1]);
        let back = EdgeOffsets::from_json(&next.to_json()).expect("square");
        assert_eq!(back, next);
    }
}
