//! Crowns shaded by the lips. Where a crown meets a lip, the lip shades it: the crown's last
//! pixels are as dark as the lip, and the colour models and the edges' pass (which read a pixel
//! against the two sides' light) give them to the lip, so every crown lost a pixel or more
//! along the lips. Shade dims a colour but keeps its chromaticity (the share of each
//! channel in linear light), and a crown's is a lip's no more in shade than in light: here a
//! lip pixel beside the teeth whose chromaticity is mostly the crowns' goes to the teeth.
//! A mix of crown and lip (a blurred edge) holds the two chromaticities in proportion to
//! their light, so it goes where the crown holds most of it; the tongue and the gums are as
//! red as the lips and stay.

use super::distance::distance_transform;
use super::edges::{linear_colours, neighbours4};

/// The classes read here: teeth, the mouth interior, lips and skin.
const TEETH: u8 = 0;
const INTERIOR: u8 = 1;
const LIPS: u8 = 2;

/// How far past the cut (pixels) a shaded crown is followed.
const REACH_PX: usize = 4;

/// The ring around the teeth (pixels from them) whose lip pixels give the lips' chromaticity:
/// past a shaded or blurred edge, within the lips.
const LIP_RING_PX: (f32, f32) = (6.0, 14.0);

/// How far inside the teeth (pixels from any other class) their pixels give the crowns'
/// chromaticity.
const CROWN_DEPTH_PX: f32 = 3.0;

/// How far (pixels) a lip pixel taken must lie from the mouth interior. A crown's edge
/// blurred into the dark interior holds the crown's chromaticity too (the dark adds little
/// light), and where the opening's margin leaves it lips it is no crown in a lip's shade.
const INTERIOR_CLEARANCE_PX: f32 = 3.0;

/// The least light (linear, the three channels summed) whose chromaticity is read: a darker
/// pixel's is mostly the sensor's noise.
const MIN_LIGHT: f32 = 0.02;

/// The least distance between the crowns' and the lips' chromaticities for either to be told
/// apart from the other.
const MIN_CONTRAST: f32 = 0.02;

/// The fewest pixels the crowns' and the lips' chromaticities are each read from.
const MIN_PIXELS: usize = 20;

/// `classes` (0 teeth, 1 mouth interior, 2 lips and skin) and `arches` (the arch's bit per
/// tooth pixel) of a `w` x `h` region, with the lip pixels that lie within [`REACH_PX`] of the
/// teeth (through pixels taken so) and hold at least `least_share` of the crowns'
/// chromaticity (along the line from the lips' to the crowns') given to the teeth of the arch
/// beside them. Above half: a mix of crown and lip holds the two in proportion to their light,
/// and a lip's own chromaticity varies.
pub(super) fn shaded_crowns(
    colours: &[[u8; 3]],
    classes: &mut [u8],
    arches: &mut [u8],
    w: usize,
    h: usize,
    least_share: f32,
) {
    let lin = linear_colours(colours);
    let chroma: Vec<Option<[f32; 2]>> = lin
        .iter()
        .map(|c| {
            let s = c[0] + c[1] + c[2];
            (s > MIN_LIGHT).then(|| [c[0] / s, c[1] / s])
        })
        .collect();
    let teeth: Vec<u8> = classes.iter().map(|&c| (c == TEETH) as u8).collect();
    let others: Vec<u8> = teeth.iter().map(|&t| 1 - t).collect();
    let (from_teeth, _) = distance_transform(&teeth, w, h);
    let (from_others, _) = distance_transform(&others, w, h);
    let interior: Vec<u8> = classes.iter().map(|&c| (c == INTERIOR) as u8).collect();
    let (from_interior, _) = distance_transform(&interior, w, h);
    let crown = median_chroma(&chroma, |i| {
        classes[i] == TEETH && from_others[i] >= CROWN_DEPTH_PX
    });
    let lip = median_chroma(&chroma, |i| {
        classes[i] == LIPS && (LIP_RING_PX.0..=LIP_RING_PX.1).contains(&from_teeth[i])
    });
    let (Some(crown), Some(lip)) = (crown, lip) else {
        return;
    };
    let line = [crown[0] - lip[0], crown[1] - lip[1]];
    let length = line[0] * line[0] + line[1] * line[1];
    if length < MIN_CONTRAST * MIN_CONTRAST {
        return;
    }
    let crown_like = |i: usize| {
        chroma[i].is_some_and(|c| {
            ((c[0] - lip[0]) * line[0] + (c[1] - lip[1]) * line[1]) / length >= least_share
        })
    };
    // Grown a pixel a round from the teeth as they stood at its start, so the order the
    // pixels are visited in does not matter.
    for _ in 0..REACH_PX {
        let mut taken = Vec::new();
        for i in 0..w * h {
            if classes[i] != LIPS || from_interior[i] <= INTERIOR_CLEARANCE_PX || !crown_like(i) {
                continue;
            }
            let beside = neighbours4(w, h, i % w, i / w).find(|&j| classes[j] == TEETH);
            if let Some(j) = beside {
                taken.push((i, arches[j]));
            }
        }
        if taken.is_empty() {
            break;
        }
        for (i, arch) in taken {
            (classes[i], arches[i]) = (TEETH, arch);
        }
    }
}

/// The per-channel median chromaticity of the pixels `wanted` picks that carry light enough;
/// `None` with fewer than [`MIN_PIXELS`].
fn median_chroma(chroma: &[Option<[f32; 2]>], wanted: impl Fn(usize) -> bool) -> Option<[f32; 2]> {
    let mut picked: [Vec<f32>; 2] = [Vec::new(), Vec::new()];
    for (i, c) in chroma.iter().enumerate() {
        if let Some(c) = c
            && wanted(i)
        {
            picked[0].push(c[0]);
            picked[1].push(c[1]);
        }
    }
    if picked[0].len() < MIN_PIXELS {
        return None;
    }
    Some(picked.map(|mut v| {
        let middle = v.len() / 2;
        *v.select_nth_unstable_by(middle, f32::total_cmp).1
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::LOWER_BIT;
    use crate::capture::light::encoded;

    const W: usize = 6;
    const H: usize = 44;
    /// Rows 0-3 the mouth interior, 4 the crown's edge blurred into it (left lips by the
    /// opening's margin), 5-23 a crown, 24-43 a lip: the crown's last rows shaded (its colour
    /// dimmed), then a blurred row of half crown, half lip.
    fn picture() -> (Vec<[u8; 3]>, Vec<u8>, Vec<u8>) {
        let crown = [0.70f32, 0.66, 0.60];
        let lip = [0.35f32, 0.16, 0.15];
        let dark = [0.01f32, 0.005, 0.005];
        let row_colour = |y: usize| -> [f32; 3] {
            match y {
                0..=3 => dark,
                4 => std::array::from_fn(|k| 0.4 * crown[k] + 0.6 * dark[k]),
                5..=19 => crown,
                20..=23 => crown.map(|c| c * (0.9 - 0.12 * (y - 19) as f32)),
                24 => std::array::from_fn(|k| 0.5 * crown[k] * 0.4 + 0.5 * lip[k]),
                _ => lip,
            }
        };
        let colours = (0..W * H)
            .map(|i| row_colour(i / W).map(|c| encoded(c as f64).round() as u8))
            .collect();
        // The cut gave the shaded rows and the blurred one to the lip.
        let classes: Vec<u8> = (0..W * H)
            .map(|i| match i / W {
                0..=3 => INTERIOR,
                4 => LIPS,
                5..=19 => TEETH,
                _ => LIPS,
            })
            .collect();
        let arches = classes
            .iter()
            .map(|&c| if c == TEETH { LOWER_BIT } else { 0 })
            .collect();
        (colours, classes, arches)
    }

    #[test]
    fn a_crown_shaded_by_the_lip_goes_back_to_the_teeth_and_the_lip_stays() {
        let (colours, mut classes, mut arches) = picture();
        shaded_crowns(&colours, &mut classes, &mut arches, W, H, 0.65);
        let at = |y: usize| (classes[y * W + 2], arches[y * W + 2]);
        for y in 20..=23 {
            assert_eq!(at(y), (TEETH, LOWER_BIT), "shaded crown, row {y}");
        }
        for y in 25..H {
            assert_eq!(at(y), (LIPS, 0), "lip, row {y}");
        }
        assert_eq!(
            at(4),
            (LIPS, 0),
            "the crown's edge blurred into the interior"
        );
    }
}
