//! Motion blur read where the teeth meet the mouth's dark interior. While the shutter is open
//! a moving arch sweeps its *smear* (the shutter's share of its motion over a frame) across
//! the picture, so each of its edges across the motion becomes a ramp as long as the smear,
//! from the crown's colour to the colour beyond, and the frame's pose (the arch at
//! mid-shutter) puts the edge half way along it. The colour models cannot read a ramp: its mix
//! of pale crown and dark interior is a colour of a crown in shade, so the cut grows the
//! crowns over the interior by up to half the smear, and the tracker reads that as the arch's
//! pose. Here the crown's pixels of such a ramp that hold less than half its colour go to the
//! interior, the sides' colours read beyond the ramp's ends.
//!
//! Only where the interior lies beyond the ramp: towards the lips a crown is shaded by them,
//! and its own colour there already lies between the crown's and the lip's, so a mix of the
//! two says little about where the edge is (read so, the crowns lost pixels along the lips
//! and the teeth IoU fell on every blurred set; docs/footage.md). The lips' edges still tell
//! whether the picture is smeared at all.

use super::edges::{linear_colours, mix};
use crate::arch::{LOWER_BIT, UPPER_BIT};

/// The classes read here: teeth, and the mouth interior (lips and skin are 2).
const TEETH: u8 = 0;
const INTERIOR: u8 = 1;

/// The shortest smear (pixels) read as a ramp: below it the edges' own pass
/// ([`super::edges::refine_edges`]) decides the pixels.
const MIN_SMEAR: f32 = 1.5;

/// The least share of the crown's colour that an arch's edges must hold, in the median, a
/// quarter of the smear past where they are half way, for the picture to be read as smeared:
/// a ramp as long as the smear holds a quarter there, a sharp edge none.
const SMEARED_TAIL: f32 = 0.1;

/// `classes` (0 teeth, 1 mouth interior, 2 lips and skin) and `arches` (UPPER_BIT or
/// LOWER_BIT per tooth pixel) of a `w` x `h` region, with each arch's ramps into the interior
/// decided again: `smear` holds each arch's smear (upper, lower) in pixels, as a vector along
/// its motion. Along each line through an edge of the arch's teeth in the direction of its
/// smear, the pixels within the smear's length of the edge are read as mixes of the crown's
/// colour and the colour beyond, each taken just beyond where the ramp can reach; where the
/// interior lies beyond, the edge is put where the fewest of them hold less than half of the
/// side they are given to, and the crown's pixels past it go to the class beside the crown.
/// Lines that run into the other arch, or whose sides' colours are alike, stay as they are;
/// so does an arch whose edges show no smear (the shutter was shorter than the settings
/// say).
pub(super) fn decide_ramps(
    colours: &[[u8; 3]],
    classes: &mut [u8],
    arches: &mut [u8],
    w: usize,
    h: usize,
    smear: [[f32; 2]; 2],
) {
    let lin = linear_colours(colours);
    for (bit, v) in [(UPPER_BIT, smear[0]), (LOWER_BIT, smear[1])] {
        let length = v[0].hypot(v[1]);
        if length.is_nan() || length < MIN_SMEAR {
            continue;
        }
        let d = [v[0] / length, v[1] / length];
        let reading = Reading {
            lin: &lin,
            classes,
            arches,
            w,
            h,
            bit,
        };
        let mut ramps = Vec::new();
        for sign in [1.0f32, -1.0] {
            let u = [sign * d[0], sign * d[1]];
            let step = (u[0].round(), u[1].round());
            for i in 0..w * h {
                if !reading.is_arch(i) {
                    continue;
                }
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let Some(n) = reading.at(x + step.0, y + step.1) else {
                    continue;
                };
                if classes[n] == TEETH {
                    continue;
                }
                if let Some(ramp) = reading.ramp((x, y), u, length, classes[n]) {
                    ramps.push(ramp);
                }
            }
        }
        // The picture shows the smear where the other side of the arch's edges holds crown
        // light past where they are half way. Read over all its edges: against the interior a
        // crown darkening towards a sharp edge can hold some there too, against the lips not.
        let past = (length / 4.0).round().max(1.0) as usize;
        let mut tails: Vec<f32> = ramps.iter().filter_map(|r| r.tail(past)).collect();
        if tails.is_empty() {
            continue;
        }
        let middle = tails.len() / 2;
        let (_, &mut tail, _) = tails.select_nth_unstable_by(middle, f32::total_cmp);
        if tail < SMEARED_TAIL {
            continue;
        }
        // Only the crowns' growth into the interior is undone: the cut gives a ramp's pale
        // half to the teeth anyway, and what it gives the interior of the crowns there is a
        // crown's edge shaded as it turns from the light, which the ramp's colours misread as
        // the interior's (docs/footage.md, "Which label errors move which arch").
        for ramp in ramps.iter().filter(|r| r.far == INTERIOR) {
            for &(k, _) in &ramp.line[ramp.cut..] {
                if classes[k] == TEETH {
                    (classes[k], arches[k]) = (ramp.beside, 0);
                }
            }
        }
    }
}

/// One line across an edge along the arch's smear, from the crown's side: each pixel with the
/// share of the crown's colour it holds, and where the edge goes (the pixels before `cut`
/// are teeth).
struct Ramp {
    line: Vec<(usize, f32)>,
    cut: usize,
    /// The class just beyond the edge as cut: what the crown's pixels past `cut` become.
    beside: u8,
    /// The class beyond the ramp's reach: the colour the crown's is mixed with.
    far: u8,
}

impl Ramp {
    /// The crown's share held `past` pixels beyond the first pixel given to the other side.
    fn tail(&self, past: usize) -> Option<f32> {
        self.line.get(self.cut + past).map(|&(_, s)| s)
    }
}

/// The labels of a region as they were before any ramp was decided again, and the arch
/// whose ramps are read.
struct Reading<'a> {
    lin: &'a [[f32; 3]],
    classes: &'a [u8],
    arches: &'a [u8],
    w: usize,
    h: usize,
    bit: u8,
}

impl Reading<'_> {
    /// The index of the pixel nearest (x, y), if in the region.
    fn at(&self, x: f32, y: f32) -> Option<usize> {
        let (x, y) = (x.round(), y.round());
        (x >= 0.0 && y >= 0.0 && (x as usize) < self.w && (y as usize) < self.h)
            .then(|| y as usize * self.w + x as usize)
    }

    fn is_arch(&self, i: usize) -> bool {
        self.classes[i] == TEETH && self.arches[i] == self.bit
    }

    /// The mean colour at `p` and its two neighbours across the line along `u`, over those
    /// of the side wanted (the arch's teeth when `class` is 0); `None` unless two are.
    fn side_colour(&self, p: [f32; 2], u: [f32; 2], class: u8) -> Option<[f32; 3]> {
        let (mut sum, mut n) = ([0f32; 3], 0);
        for t in [-1.0f32, 0.0, 1.0] {
            let Some(k) = self.at(p[0] - t * u[1], p[1] + t * u[0]) else {
                continue;
            };
            let wanted = if class == TEETH {
                self.is_arch(k)
            } else {
                self.classes[k] == class
            };
            if wanted {
                for (s, c) in sum.iter_mut().zip(self.lin[k]) {
                    *s += c;
                }
                n += 1;
            }
        }
        (n >= 2).then(|| sum.map(|s| s / n as f32))
    }

    /// The line through edge pixel `b` (the arch's last along `u`; the next is of class
    /// `beside`) within the smear's `length` of it, and the edge at the cut that the fewest of
    /// its pixels disagree with. The colour beyond is read where the ramp cannot reach, of
    /// whatever class is there but teeth: next to the crowns the opening leaves a margin of
    /// the tongue and the gums labelled lips (`super::opening`).
    fn ramp(&self, b: (f32, f32), u: [f32; 2], length: f32, beside: u8) -> Option<Ramp> {
        let point = |t: f32| [b.0 + t * u[0], b.1 + t * u[1]];
        // The ramp may lie wholly on either side of the edge the cut drew.
        let beyond = length.ceil() + 1.0;
        let teeth = self.side_colour(point(-beyond), u, TEETH)?;
        let p = point(beyond + 1.0);
        let far = self.classes[self.at(p[0], p[1])?];
        if far == TEETH {
            return None;
        }
        let rest = self.side_colour(p, u, far)?;
        let reach = length.ceil() as i32;
        let mut line = Vec::with_capacity(2 * reach as usize + 2);
        for t in -reach..=reach + 1 {
            let p = point(t as f32);
            let k = self.at(p[0], p[1])?;
            if !(self.is_arch(k) || self.classes[k] != TEETH) {
                return None;
            }
            if line.last().is_some_and(|&(j, _)| j == k) {
                continue;
            }
            let (share, _) = mix(self.lin[k], teeth, rest)?;
            line.push((k, share));
        }
        // The cut after `c` pixels: those before go to the teeth, the rest beyond.
        let wrong = |c: usize| {
            line[..c].iter().filter(|(_, s)| *s < 0.5).count()
                + line[c..].iter().filter(|(_, s)| *s >= 0.5).count()
        };
        let cut = (0..=line.len()).min_by_key(|&c| wrong(c))?;
        Some(Ramp {
            line,
            cut,
            beside,
            far,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::capture::light::encoded;

    const W: usize = 5;
    const H: usize = 48;
    /// Where the crown meets the interior above it and the lip below it at mid-shutter.
    const TOP: f32 = 14.0;
    const BOTTOM: f32 = 34.0;

    /// A lower arch's crown, `W` columns wide, between the dark interior and a lip, shaded
    /// towards both its edges, moving down by `smear` pixels while the shutter is open (the
    /// lip with it); its labels (the cut's) put the edge with the interior `grown` pixels
    /// above where it is at mid-shutter, as the colour models grow crowns into the dark.
    fn picture(smear: f32, grown: i32) -> (Vec<[u8; 3]>, Vec<u8>, Vec<u8>) {
        let (crown, dark, lip) = (
            [0.80f32, 0.78, 0.70],
            [0.03f32, 0.01, 0.01],
            [0.30, 0.08, 0.09],
        );
        let light = |y: f32, shift: f32| -> [f32; 3] {
            let (top, bottom) = (TOP + shift, BOTTOM + shift);
            if y < top {
                dark
            } else if y >= bottom {
                lip
            } else {
                let shade = 1.0 - 0.5 * (-(y - top).min(bottom - y) / 1.5).exp();
                crown.map(|c| c * shade)
            }
        };
        let (mut colours, mut classes, mut arches) = (Vec::new(), Vec::new(), Vec::new());
        for y in 0..H {
            // The pixel's light: its area over the shutter's time.
            let (steps, rows) = (32, 8);
            let mut sum = [0f32; 3];
            for s in 0..steps {
                let shift = smear * ((s as f32 + 0.5) / steps as f32 - 0.5);
                for r in 0..rows {
                    let c = light(y as f32 + (r as f32 + 0.5) / rows as f32, shift);
                    for k in 0..3 {
                        sum[k] += c[k] / (steps * rows) as f32;
                    }
                }
            }
            let class = if (y as i32) < TOP as i32 - grown {
                INTERIOR
            } else if (y as f32) < BOTTOM {
                TEETH
            } else {
                2
            };
            for _ in 0..W {
                colours.push(sum.map(|v| encoded(v as f64).round() as u8));
                classes.push(class);
                arches.push(if class == TEETH { LOWER_BIT } else { 0 });
            }
        }
        (colours, classes, arches)
    }

    /// The first row of teeth in the middle column.
    fn top_row(classes: &[u8]) -> i32 {
        classes
            .chunks(W)
            .position(|row| row[W / 2] == TEETH)
            .unwrap() as i32
    }

    #[test]
    fn a_smeared_edge_goes_where_the_ramp_is_half_way() {
        for grown in [0, 1, 3] {
            for down in [8.0, -8.0] {
                let (colours, mut classes, mut arches) = picture(8.0, grown);
                let smear = [[0.0; 2], [0.0, down]];
                decide_ramps(&colours, &mut classes, &mut arches, W, H, smear);
                let row = top_row(&classes);
                // Within a pixel: the crown's shade at its edge reads as a little less crown.
                assert!(
                    (row - TOP as i32).abs() <= 1,
                    "grown {grown}, smear {down}: row {row}"
                );
            }
        }
    }

    #[test]
    fn a_sharp_edge_a_still_arch_the_other_arch_and_a_shrunk_crown_are_left_alone() {
        // The settings' shutter says 8 pixels, the picture shows none.
        let cases = [
            (picture(0.0, 1), [[0.0, 0.0], [0.0, 8.0]]),
            (picture(8.0, 3), [[0.0, 0.0], [0.0, 1.0]]),
            (picture(8.0, 3), [[0.0, 8.0], [0.0, 0.0]]),
            // Crowns the cut gave to the interior stay there (the module's comment says why).
            (picture(8.0, -2), [[0.0, 0.0], [0.0, 8.0]]),
        ];
        for ((colours, classes, arches), smear) in cases {
            let (mut c, mut a) = (classes.clone(), arches.clone());
            decide_ramps(&colours, &mut c, &mut a, W, H, smear);
            assert!(c == classes && a == arches, "{smear:?}: moved");
        }
    }
}
