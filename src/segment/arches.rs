//! Which arch each tooth pixel belongs to, from the picture as well as from where the arches
//! are expected. Taking the nearest expected arch alone pins the line between the upper and
//! the lower teeth to the expected poses: an arch that moved, or one tracked a little wrong,
//! gets the other's crowns in its mask, and tracking follows the mask. A graph cut among the
//! tooth pixels instead puts that line where the picture has one (the dark gap between the
//! arches, the shadowed incisal edge), near where the arches are expected.

use super::distance::distance_transform;
use super::graph_cut::GridCut;
use super::smoothness::set_pairs;
use crate::arch::{LOWER_BIT, UPPER_BIT};

/// How far (in reaches) the picture may move the line between the arches from where the
/// expected poses draw it: the data term grows by one nat over this distance.
const SPLIT_REACH: f32 = 2.0;
/// The smoothness of this cut as a share of the others'. Where teeth touch without an edge
/// between them, a line across the arch costs its length in smoothness wherever it runs,
/// and giving one arch's crowns to the other costs nothing of it: the line must stay
/// cheaper than what the data term charges for that.
const SPLIT_SMOOTHNESS: f32 = 1.0 / 3.0;

/// Per pixel of a `w` x `h` region, UPPER_BIT or LOWER_BIT where `teeth` is true, else 0.
/// `projected`: the label bits of the arches drawn at the expected poses; `colours`: the
/// region's picture; `beta` and `smoothness`: the contrast-sensitive smoothness of the other
/// cuts (GrabCut's); `reach`: the prior's reach in pixels.
#[allow(clippy::too_many_arguments)]
pub(super) fn split_arches(
    colours: &[[u8; 3]],
    teeth: &[bool],
    projected: &[u8],
    w: usize,
    h: usize,
    beta: f32,
    smoothness: f32,
    reach: f32,
) -> Vec<u8> {
    let only = |bit: u8| -> Vec<u8> { projected.iter().map(|&p| p & bit).collect() };
    let (to_upper, _) = distance_transform(&only(UPPER_BIT), w, h);
    let (to_lower, _) = distance_transform(&only(LOWER_BIT), w, h);
    // An arch not drawn at all (out of view) leaves the other every tooth.
    let scale = SPLIT_REACH * reach;
    let cost = |d: f32| if d.is_finite() { d / scale } else { 1e6 };
    let mut cut = GridCut::new(w, h);
    for i in 0..w * h {
        if teeth[i] {
            let (a, b) = (cost(to_upper[i]), cost(to_lower[i]));
            let low = a.min(b);
            cut.set_costs(i, a - low, b - low);
        }
    }
    set_pairs(
        &mut cut,
        colours,
        (w, h),
        beta,
        SPLIT_SMOOTHNESS * smoothness,
        &|i| !teeth[i],
    );
    let upper = cut.solve();
    (0..w * h)
        .map(|i| match (teeth[i], upper[i]) {
            (false, _) => 0,
            (true, true) => UPPER_BIT,
            (true, false) => LOWER_BIT,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two rows of teeth with a dark line between them at row 10; the arches are expected
    /// three rows lower (the upper drawn down to row 13). The line between the masks is the
    /// picture's, not the expected one.
    #[test]
    fn the_line_between_the_arches_follows_the_picture() {
        let (w, h) = (40, 24);
        let mut colours = vec![[225u8, 215, 190]; w * h];
        // Teeth everywhere but the top two rows; the dark line is a shadowed edge, still tooth.
        let mut teeth = vec![true; w * h];
        for x in 0..w {
            colours[10 * w + x] = [120, 100, 90];
        }
        let projected: Vec<u8> = (0..w * h)
            .map(|i| if i / w < 13 { UPPER_BIT } else { LOWER_BIT })
            .collect();
        for row in teeth.chunks_mut(w).take(2) {
            row.fill(false);
        }
        let beta = 2000.0;
        let labels = split_arches(&colours, &teeth, &projected, w, h, beta, 3.0, 8.0);
        for x in 0..w {
            assert_eq!(labels[9 * w + x], UPPER_BIT, "row 9, column {x}");
            assert_eq!(labels[11 * w + x], LOWER_BIT, "row 11, column {x}");
            assert_eq!(labels[x], 0);
        }
    }
}
