//! The pixels along a boundary between two classes, decided again by their colour alone: a
//! lens, motion and the sensor blur every edge, so a pixel there mixes the colours either
//! side, and it belongs to the side whose colour it mostly holds. The graph cut cannot tell:
//! a mixed colour is rare in both classes' models, so its side follows the priors and the
//! smoothness, which shrinks pale teeth against the dark mouth by a fraction of a pixel all
//! along the edge; the tracker reads such a bias as a pose.
//!
//! The mix is measured in linear light ([`crate::capture::light`]): on the encoded values, a
//! half-dark mix lies well past the middle of the two sides', and pale teeth grew into the
//! dark mouth by a fraction of a pixel all along the edge instead.

use crate::capture::light::linear_table;

/// How far (pixels) around an edge pixel the two sides' colours are taken from.
const WINDOW: usize = 3;

/// How far apart (linear light, 1 the brightest) two sides' mean colours must lie for a mix
/// of them to say which it mostly holds.
const MIN_CONTRAST: f32 = 0.03;

/// Each colour as linear light.
pub(super) fn linear_colours(colours: &[[u8; 3]]) -> Vec<[f32; 3]> {
    let lut = linear_table();
    colours.iter().map(|c| c.map(|v| lut[v as usize])).collect()
}

/// `classes` (row-major, `w` x `h`) with each pixel that touches another class moved to the
/// class whose local mean colour its own is nearer along the line between the two means. The
/// means are over `inner` pixels (each class's pixels away from its edges) within [`WINDOW`];
/// a side without any keeps the pixel as it is.
pub(super) fn refine_edges(
    colours: &[[u8; 3]],
    classes: &[u8],
    inner: &[u8],
    w: usize,
    h: usize,
) -> Vec<u8> {
    let colours = linear_colours(colours);
    let mut out = classes.to_vec();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let a = classes[i];
            let Some(b) = other_side(classes, w, h, x, y) else {
                continue;
            };
            let (Some(ma), Some(mb)) = (
                local_mean(&colours, inner, w, h, x, y, a),
                local_mean(&colours, inner, w, h, x, y, b),
            ) else {
                continue;
            };
            if mix(colours[i], ma, mb).is_some_and(|(share, _)| share < 0.5) {
                out[i] = b;
            }
        }
    }
    out
}

/// How far (as a share of the distance between the two sides' colours) a pixel's colour may
/// lie off the line between them and still be read as their mix.
const MIX_TOLERANCE: f32 = 0.15;

/// Colour `c` read as a mix of `a` and `b`: the share of `a` along the line from `b` to `a`,
/// and how far off that line `c` lies (as a share of the line's length). `None` where the
/// two are about the same colour: then they say nothing about the mix.
pub(super) fn mix(c: [f32; 3], a: [f32; 3], b: [f32; 3]) -> Option<(f32, f32)> {
    let line: [f32; 3] = std::array::from_fn(|k| a[k] - b[k]);
    let length = line.iter().map(|v| v * v).sum::<f32>();
    if length < MIN_CONTRAST * MIN_CONTRAST {
        return None;
    }
    let share = (0..3).map(|k| (c[k] - b[k]) * line[k]).sum::<f32>() / length;
    let off = (0..3)
        .map(|k| (c[k] - b[k] - share * line[k]).powi(2))
        .sum::<f32>();
    Some((share, (off / length).sqrt()))
}

/// `classes` (0 teeth, 1 mouth interior, 2 lips and skin) with each lips-and-skin pixel that
/// lies between teeth and the interior (a 4-neighbour of one, the other within two pixels) and
/// is coloured as their mix given to the side whose colour it mostly holds. Inside the lips'
/// opening nothing lies between a crown and the interior; a blurred edge's mix of pale and
/// dark is a colour of neither model, likeliest lip, and a line of lip there is a gap that a
/// model drawn over it pays nothing for (the paper's energy lets the lips hide teeth).
/// Colours off the line (gums and tongue, pink) stay as they are.
///
/// The two sides' colours are the means of their `inner` pixels nearby, as in
/// [`refine_edges`].
pub(super) fn settle_gaps(
    colours: &[[u8; 3]],
    classes: &[u8],
    inner: &[u8],
    w: usize,
    h: usize,
) -> Vec<u8> {
    let lin = linear_colours(colours);
    let mut out = classes.to_vec();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if classes[i] != 2 {
                continue;
            }
            let touches = |k: u8| neighbours4(w, h, x, y).any(|j| classes[j] == k);
            let within2 = |k: u8| {
                (y.saturating_sub(2)..(y + 3).min(h)).any(|yy| {
                    (x.saturating_sub(2)..(x + 3).min(w)).any(|xx| classes[yy * w + xx] == k)
                })
            };
            if !((touches(0) && within2(1)) || (touches(1) && within2(0))) {
                continue;
            }
            let (Some(teeth), Some(mouth)) = (
                local_mean(&lin, inner, w, h, x, y, 0),
                local_mean(&lin, inner, w, h, x, y, 1),
            ) else {
                continue;
            };
            let Some((t, off)) = mix(lin[i], teeth, mouth) else {
                continue;
            };
            // Off the line, or well beyond either end of it: no mix of the two.
            if off > MIX_TOLERANCE || !(-0.25..=1.25).contains(&t) {
                continue;
            }
            out[i] = if t >= 0.5 { 0 } else { 1 };
        }
    }
    out
}

/// The indices of (x, y)'s 4-neighbours within the picture.
pub(super) fn neighbours4(w: usize, h: usize, x: usize, y: usize) -> impl Iterator<Item = usize> {
    let i = y * w + x;
    [
        (x > 0).then(|| i - 1),
        (x + 1 < w).then(|| i + 1),
        (y > 0).then(|| i - w),
        (y + 1 < h).then(|| i + w),
    ]
    .into_iter()
    .flatten()
}

/// The class of the first 4-neighbour of another class than (x, y)'s.
fn other_side(classes: &[u8], w: usize, h: usize, x: usize, y: usize) -> Option<u8> {
    let here = classes[y * w + x];
    neighbours4(w, h, x, y)
        .map(|j| classes[j])
        .find(|&c| c != here)
}

/// The mean linear colour of the `inner` pixels of class `k` within [`WINDOW`] of (x, y).
pub(super) fn local_mean(
    colours: &[[f32; 3]],
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
                    *s += v;
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

    use crate::capture::light::{encoded, linear};

    /// The 8-bit value that encodes linear light `l`.
    fn byte(l: f32) -> u8 {
        encoded(l as f64).round() as u8
    }

    /// Rows 0-5 pale, rows 8- dark, rows 6 and 7 covered by the pale side `t6` and `t7` (the
    /// light mixed, then encoded as a camera writes it); the cut's answer has both mixed rows
    /// dark. What the refinement makes of rows 6 and 7.
    fn refined(t6: f32, t7: f32) -> (u8, u8) {
        let (w, h) = (12, 12);
        let pale = [230u8, 220, 200].map(linear);
        let dark = [60u8, 20, 25].map(linear);
        let mix = |t: f32| -> [u8; 3] {
            std::array::from_fn(|k| byte(t * pale[k] + (1.0 - t) * dark[k]))
        };
        let colours: Vec<[u8; 3]> = (0..w * h)
            .map(|i| match i / w {
                0..6 => mix(1.0),
                6 => mix(t6),
                7 => mix(t7),
                _ => mix(0.0),
            })
            .collect();
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
            assert_eq!(out[5 * w + x], 0);
            assert_eq!((out[6 * w + x], out[7 * w + x]), (out[6 * w], out[7 * w]));
        }
        (out[6 * w], out[7 * w])
    }

    /// A blurred edge: one row 70 % pale goes back to the pale side, one 30 % pale stays.
    #[test]
    fn a_mixed_pixel_goes_to_the_side_whose_colour_it_mostly_holds() {
        assert_eq!(refined(0.7, 0.3), (0, 1));
    }

    /// A pixel 40 % pale encodes nearer the pale side's value than the dark's (the transfer
    /// curve lifts the dark): measured on encoded values it went to the teeth.
    #[test]
    fn the_mix_is_measured_in_linear_light() {
        let mixed = byte(0.4 * linear(230) + 0.6 * linear(60));
        assert!(mixed as f32 > 0.5 * (230.0 + 60.0), "{mixed}");
        assert_eq!(refined(0.6, 0.4), (0, 1));
    }

    /// Teeth over the interior with one row between that the cut called lip: a mix of the two
    /// goes to the side it mostly holds; a pink row (gum) stays.
    #[test]
    fn a_gap_between_teeth_and_interior_is_settled_by_its_mix() {
        let (w, h) = (12, 12);
        let pale = [230u8, 220, 200].map(linear);
        let dark = [60u8, 20, 25].map(linear);
        let mix = |t: f32| -> [u8; 3] {
            std::array::from_fn(|k| byte(t * pale[k] + (1.0 - t) * dark[k]))
        };
        let settled = |between: [u8; 3]| {
            let colours: Vec<[u8; 3]> = (0..w * h)
                .map(|i| match i / w {
                    0..6 => mix(1.0),
                    6 => between,
                    _ => mix(0.0),
                })
                .collect();
            let classes: Vec<u8> = (0..w * h)
                .map(|i| match i / w {
                    0..6 => 0,
                    6 => 2,
                    _ => 1,
                })
                .collect();
            let inner: Vec<u8> = (0..w * h)
                .map(|i| match i / w {
                    0..5 => 0,
                    8.. => 1,
                    _ => 3,
                })
                .collect();
            let out = settle_gaps(&colours, &classes, &inner, w, h);
            assert!((0..w).all(|x| out[6 * w + x] == out[6 * w]));
            out[6 * w]
        };
        assert_eq!(settled(mix(0.6)), 0);
        assert_eq!(settled(mix(0.3)), 1);
        assert_eq!(settled([196, 96, 108]), 2, "gum");
    }
}
