//! The pixels along a boundary between two classes, decided again by their colour alone: a
//! lens, motion and the sensor blur every edge, so a pixel there mixes the colours either
//! side, and it belongs to the side whose colour it mostly holds. The graph cut cannot tell:
//! a mixed colour is rare in both classes' models, so its side follows the priors and the
//! smoothness, which shrinks pale teeth against the dark mouth by a fraction of a pixel all
//! along the edge; the tracker reads such a bias as a pose.

/// How far (pixels) around an edge pixel the two sides' colours are taken from.
const WINDOW: usize = 3;

/// `classes` (row-major, `w` x `h`; values below `kinds`) with each pixel that touches another
/// class moved to the class whose local mean colour its own is nearer along the line between
/// the two means. The means are over `inner` pixels (each class's pixels away from its
/// edges) within [`WINDOW`]; a side without any keeps the pixel as it is.
pub(super) fn refine_edges(
    colours: &[[u8; 3]],
    classes: &[u8],
    inner: &[u8],
    w: usize,
    h: usize,
) -> Vec<u8> {
    let mut out = classes.to_vec();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let a = classes[i];
            let Some(b) = other_side(classes, w, h, x, y) else {
                continue;
            };
            let (Some(ma), Some(mb)) = (
                local_mean(colours, inner, w, h, x, y, a),
                local_mean(colours, inner, w, h, x, y, b),
            ) else {
                continue;
            };
            let c = colours[i].map(|v| v as f32);
            let (mut along, mut length) = (0f32, 0f32);
            for k in 0..3 {
                along += (c[k] - mb[k]) * (ma[k] - mb[k]);
                length += (ma[k] - mb[k]).powi(2);
            }
            // Sides of about the same colour say nothing about the mix.
            if length < 400.0 {
                continue;
            }
            if along / length < 0.5 {
                out[i] = b;
            }
        }
    }
    out
}

/// The class of the first 4-neighbour of another class than (x, y)'s.
fn other_side(classes: &[u8], w: usize, h: usize, x: usize, y: usize) -> Option<u8> {
    let here = classes[y * w + x];
    let mut near = Vec::with_capacity(4);
    if x > 0 {
        near.push(y * w + x - 1);
    }
    if x + 1 < w {
        near.push(y * w + x + 1);
    }
    if y > 0 {
        near.push((y - 1) * w + x);
    }
    if y + 1 < h {
        near.push((y + 1) * w + x);
    }
    near.into_iter().map(|j| classes[j]).find(|&c| c != here)
}

/// The mean colour of the `inner` pixels of class `k` within [`WINDOW`] of (x, y).
fn local_mean(
    colours: &[[u8; 3]],
    inner: &[u8],
    w: usize,
    h: usize,
    x: usize,
    y: usize,
    k: u8,
) -> Option<[f32; 3]> {
    let (mut sum, mut n) = ([0f32; 3], 0usize);
    for yy in y.saturating_sub(WINDOW)..(y + WINDOW + 1).min(h) {
        for xx in x.saturating_sub(WINDOW)..(x + WINDOW + 1).min(w) {
            let j = yy * w + xx;
            if inner[j] == k {
                for (s, v) in sum.iter_mut().zip(colours[j]) {
                    *s += v as f32;
                }
                n += 1;
            }
        }
    }
    (n > 0).then(|| sum.map(|s| s / n as f32))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pale band over a dark one, blurred so that one row mixes them 70/30: the cut put
    /// that row on the dark side; it is mostly pale, so it goes back.
    #[test]
    fn a_mixed_pixel_goes_to_the_side_whose_colour_it_mostly_holds() {
        let (w, h) = (12, 12);
        let pale = [230u8, 220, 200];
        let dark = [60u8, 20, 25];
        let mix = |t: f32| -> [u8; 3] {
            std::array::from_fn(|k| (t * pale[k] as f32 + (1.0 - t) * dark[k] as f32) as u8)
        };
        let colours: Vec<[u8; 3]> = (0..w * h)
            .map(|i| match i / w {
                0..6 => pale,
                6 => mix(0.7),
                7 => mix(0.3),
                _ => dark,
            })
            .collect();
        // The cut's answer: both mixed rows dark.
        let classes: Vec<u8> = (0..w * h).map(|i| if i / w < 6 { 0 } else { 1 }).collect();
        let inner: Vec<u8> = (0..w * h)
            .map(|i| match i / w {
                0..5 => 0,
                9.. => 1,
                _ => 3,
            })
            .collect();
        let out = refine_edges(&colours, &classes, &inner, w, h);
        for x in 0..w {
            assert_eq!(out[6 * w + x], 0, "row 6 is 70% pale");
            assert_eq!(out[7 * w + x], 1, "row 7 is 30% pale");
            assert_eq!(out[5 * w + x], 0);
        }
    }
}
