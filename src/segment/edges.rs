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

/// `classes` (row-major, `w` x `h`; 0 teeth, 1 mouth interior, 2 lips and skin) with each
/// pixel that touches another class moved to the class whose colour its own is nearer along
/// the line between the two sides' local mean colours. The means are over `inner` pixels
/// (each class's pixels away from its edges) within [`WINDOW`]; a side without any keeps the
/// pixel as it is.
///
/// Between teeth and the interior the cut lies half way between the two sides' *rims* (the
/// pixel behind the edge pixel and the one beyond its neighbour, read as mixes of the means),
/// not half way between the means: a crown darkens towards its silhouette as it turns from
/// the light, and read against the bright middle of the crown its edge pixels hold too little
/// of it, so the crown shrank by a part of a pixel all along its incisal edge.
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
            let Some(((dx, dy), b)) = across(classes, w, h, x, y) else {
                continue;
            };
            let (Some(ma), Some(mb)) = (
                local_mean(&colours, inner, w, h, x, y, a),
                local_mean(&colours, inner, w, h, x, y, b),
            ) else {
                continue;
            };
            let Some((share, _)) = mix(colours[i], ma, mb) else {
                continue;
            };
            let cut = if a.max(b) == 1 {
                rims_midpoint(&colours, classes, w, h, (x, y), (dx, dy), (ma, mb))
            } else {
                None
            };
            if share < cut.unwrap_or(0.5) {
                out[i] = b;
            }
        }
    }
    out
}

/// How much of the teeth's colour (as a share of the two sides' means) the teeth's rim must
/// hold at least, and the other side's at most, for their midpoint to say where the edge is:
/// a rim inside a blur's ramp is itself a mix, and the midpoint of a rim in the ramp and
/// one past it lies off the ramp's middle.
const RIM_TEETH: f32 = 0.6;
const RIM_OTHER: f32 = 0.25;

/// Where between the two sides' means `means` (as the share of the first) the edge between
/// pixel (x, y) and its neighbour one step `d` away lies: half way between the rim behind the
/// pixel and the rim beyond its neighbour. `None` where a rim is missing or not nearly pure,
/// or either is no mix of the two sides (another colour, such as the tongue's). Class 0 is
/// the teeth.
fn rims_midpoint(
    colours: &[[f32; 3]],
    classes: &[u8],
    w: usize,
    h: usize,
    (x, y): (usize, usize),
    (dx, dy): (isize, isize),
    (ma, mb): ([f32; 3], [f32; 3]),
) -> Option<f32> {
    let (x, y) = (x as isize, y as isize);
    let (a, b) = (
        classes[y as usize * w + x as usize],
        classes[(y + dy) as usize * w + (x + dx) as usize],
    );
    let ra = rim(colours, classes, w, h, (x - dx, y - dy), (dx, dy), a)?;
    let rb = rim(
        colours,
        classes,
        w,
        h,
        (x + 2 * dx, y + 2 * dy),
        (dx, dy),
        b,
    )?;
    let (sa, oa) = mix(ra, ma, mb)?;
    let (sb, ob) = mix(rb, ma, mb)?;
    // The rims' shares of the teeth's colour.
    let (teeth, other) = if a == 0 {
        (sa, sb)
    } else {
        (1.0 - sb, 1.0 - sa)
    };
    (teeth >= RIM_TEETH && other <= RIM_OTHER && oa.max(ob) <= MIX_TOLERANCE)
        .then_some(0.5 * (sa + sb))
}

/// The mean linear colour of class `class` at pixel (x, y) and its two neighbours along an
/// edge that runs across `(dx, dy)`, where they hold it; `None` unless (x, y) holds it.
pub(super) fn rim(
    colours: &[[f32; 3]],
    classes: &[u8],
    w: usize,
    h: usize,
    (x, y): (isize, isize),
    (dx, dy): (isize, isize),
    class: u8,
) -> Option<[f32; 3]> {
    let pixel = |x: isize, y: isize| {
        (x >= 0 && y >= 0 && x < w as isize && y < h as isize).then(|| y as usize * w + x as usize)
    };
    if pixel(x, y).is_none_or(|k| classes[k] != class) {
        return None;
    }
    let (mut sum, mut n) = ([0f32; 3], 0.0f32);
    for t in -1..=1 {
        if let Some(k) = pixel(x + t * dy, y + t * dx)
            && classes[k] == class
        {
            for (s, v) in sum.iter_mut().zip(colours[k]) {
                *s += v;
            }
            n += 1.0;
        }
    }
    Some(sum.map(|s| s / n))
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

/// The first 4-neighbour of (x, y) of another class than its own: the step towards it, and
/// its class.
fn across(classes: &[u8], w: usize, h: usize, x: usize, y: usize) -> Option<((isize, isize), u8)> {
    let here = classes[y * w + x];
    [(-1, 0), (1, 0), (0, -1), (0, 1)]
        .into_iter()
        .find_map(|(dx, dy): (isize, isize)| {
            let (nx, ny) = (x as isize + dx, y as isize + dy);
            if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                return None;
            }
            let c = classes[ny as usize * w + nx as usize];
            (c != here).then_some(((dx, dy), c))
        })
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

    /// Pale linear light `t` mixed with dark, encoded as a camera writes it.
    fn pale_over_dark(t: f32) -> [u8; 3] {
        let pale = [230u8, 220, 200].map(linear);
        let dark = [60u8, 20, 25].map(linear);
        std::array::from_fn(|k| byte(t * pale[k] + (1.0 - t) * dark[k]))
    }

    /// A 12 x 12 picture whose row `y` has the colour `row(y)`, teeth above row `teeth_rows`
    /// and interior below, each side's inner pixels two rows or more from that edge: the
    /// class of each row after the refinement (every row comes out uniform).
    fn refined_rows(row: impl Fn(usize) -> [u8; 3], teeth_rows: usize) -> Vec<u8> {
        let (w, h) = (12, 12);
        let colours: Vec<[u8; 3]> = (0..w * h).map(|i| row(i / w)).collect();
        let classes: Vec<u8> = (0..w * h).map(|i| u8::from(i / w >= teeth_rows)).collect();
        let inner: Vec<u8> = (0..w * h)
            .map(|i| match i / w {
                y if y + 1 < teeth_rows => 0,
                y if y >= teeth_rows + 2 => 1,
                _ => 3,
            })
            .collect();
        let out = refine_edges(&colours, &classes, &inner, w, h);
        (0..h)
            .map(|y| {
                assert!((0..w).all(|x| out[y * w + x] == out[y * w]), "row {y}");
                out[y * w]
            })
            .collect()
    }

    /// Rows 0-5 pale, rows 8- dark, rows 6 and 7 covered by the pale side `t6` and `t7`
    /// (the light mixed, then encoded as a camera writes it); the cut's answer has both mixed
    /// rows dark. What the refinement makes of rows 6 and 7.
    fn refined(t6: f32, t7: f32) -> (u8, u8) {
        let rows = refined_rows(
            |y| match y {
                0..6 => pale_over_dark(1.0),
                6 => pale_over_dark(t6),
                7 => pale_over_dark(t7),
                _ => pale_over_dark(0.0),
            },
            6,
        );
        assert_eq!(rows[5], 0);
        (rows[6], rows[7])
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

    /// A crown darkening towards its edge (rows 4 and 5 at 0.8 and 0.6 of its light) over the
    /// dark interior, its edge pixel (row 6) 60 % covered: against the crown's mean nearby
    /// (0.8) it holds 0.45 of the crown and went to the interior; against the rims either side
    /// (0.75 and 0) it holds more than their midpoint, and stays teeth. A pixel 30 % covered
    /// still goes.
    #[test]
    fn an_edge_is_read_against_the_rims_either_side_of_it() {
        let decided = |cover: f32| {
            let rows = refined_rows(
                |y| match y {
                    0..4 => pale_over_dark(1.0),
                    4 => pale_over_dark(0.8),
                    5 => pale_over_dark(0.6),
                    6 => pale_over_dark(0.6 * cover),
                    _ => pale_over_dark(0.0),
                },
                7,
            );
            assert_eq!((rows[5], rows[7]), (0, 1));
            rows[6]
        };
        assert_eq!(decided(0.6), 0);
        assert_eq!(decided(0.3), 1);
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
