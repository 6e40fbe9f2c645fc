//! GrabCut's contrast-sensitive smoothness, shared by every cut of a picture: telling two
//! neighbours apart costs `λ·exp(−|c_p − c_q|² / 2β)`, little across an edge in the picture
//! and the most inside a region of one colour, with β the picture's mean squared difference
//! between neighbours.

use super::graph_cut::GridCut;

/// GrabCut's β: the mean squared colour difference between neighbours (at least 1).
pub(super) fn contrast(colours: &[[u8; 3]], w: usize, h: usize) -> f32 {
    let (mut sum, mut count) = (0f64, 0usize);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w {
                sum += difference(colours[i], colours[i + 1]) as f64;
                count += 1;
            }
            if y + 1 < h {
                sum += difference(colours[i], colours[i + w]) as f64;
                count += 1;
            }
        }
    }
    ((sum / count.max(1) as f64) as f32).max(1.0)
}

/// Every pair of neighbours in `cut` (`w` x `h`, `colours` row-major) weighted with
/// `lambda` as above; pairs with a pixel that `skip` leaves out of the cut cost nothing.
pub(super) fn set_pairs(
    cut: &mut GridCut,
    colours: &[[u8; 3]],
    (w, h): (usize, usize),
    beta: f32,
    lambda: f32,
    skip: &dyn Fn(usize) -> bool,
) {
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if skip(i) {
                continue;
            }
            let weight = |j: usize| {
                if skip(j) {
                    0.0
                } else {
                    lambda * (-difference(colours[i], colours[j]) / (2.0 * beta)).exp()
                }
            };
            if x + 1 < w {
                cut.set_pair(i, false, weight(i + 1));
            }
            if y + 1 < h {
                cut.set_pair(i, true, weight(i + w));
            }
        }
    }
}

fn difference(a: [u8; 3], b: [u8; 3]) -> f32 {
    (0..3)
        .map(|k| (a[k] as f32 - b[k] as f32).powi(2))
        .sum::<f32>()
}
