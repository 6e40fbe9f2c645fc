//! The CPU twin of shaders/histogram.wgsl: the twelve bins (mask state none/own/other/mouth x
//! class none/body/BOI) of a rendered target over its mask, the pixels outside the target
//! added from the mask's totals.

use super::raster::{CLASS_BODY, CLASS_BOI, Target};
use super::{
    BINS, Counts, MASK_MOUTH, MASK_NONE, MASK_OTHER, MASK_OWN, MaskTotals, counts_with_outside,
};
use crate::arch::Arch;
use crate::capture::LabelMask;
use crate::capture::masks::MOUTH_BIT;
use crate::geometry::Camera;

/// The bins over the whole mask: counted inside the target, derived outside it.
pub fn count(
    cam: &Camera,
    target: &Target,
    mask: &LabelMask,
    arch: Arch,
    totals: MaskTotals,
) -> Counts {
    let (own, other) = (arch.mask_bit(), arch.other().mask_bit());
    let mut bins = [0u64; BINS];
    if let Some(r) = target.rect {
        let w = r.width as usize;
        for y in 0..r.height as usize {
            let start = (r.y0 as usize + y) * mask.width as usize + r.x0 as usize;
            let row = count_row(
                &mask.data[start..start + w],
                &target.class[y * w..(y + 1) * w],
                own,
                other,
            );
            for (b, n) in bins.iter_mut().zip(row) {
                *b += n as u64;
            }
        }
    }
    counts_with_outside(bins, cam, totals)
}

/// The bins of one row (mask state own, else other, else mouth, else none; times class),
/// written without branches or indexed stores so that it vectorises: it is most of the CPU
/// energy's time after rasterising.
fn count_row(mask: &[u8], class: &[u8], own: u8, other: u8) -> [u32; BINS] {
    // Per mask state (own, other, mouth) and overall: pixels, body pixels, BOI pixels.
    let [mut own_n, mut own_body, mut own_boi] = [0u32; 3];
    let [mut other_n, mut other_body, mut other_boi] = [0u32; 3];
    let [mut mouth_n, mut mouth_body, mut mouth_boi] = [0u32; 3];
    let [mut body, mut boi] = [0u32; 2];
    for (&m, &c) in mask.iter().zip(class) {
        let o = ((m & own) != 0) as u32;
        let x = ((m & other) != 0) as u32 & (o ^ 1);
        let y = ((m & MOUTH_BIT) != 0) as u32 & ((o | x) ^ 1);
        let b = (c == CLASS_BODY) as u32;
        let i = (c == CLASS_BOI) as u32;
        own_n += o;
        own_body += o & b;
        own_boi += o & i;
        other_n += x;
        other_body += x & b;
        other_boi += x & i;
        mouth_n += y;
        mouth_body += y & b;
        mouth_boi += y & i;
        body += b;
        boi += i;
    }
    let none_n = mask.len() as u32 - own_n - other_n - mouth_n;
    let none_body = body - own_body - other_body - mouth_body;
    let none_boi = boi - own_boi - other_boi - mouth_boi;
    let mut bins = [0u32; BINS];
    for (state, [n, b, i]) in [
        (MASK_OWN, [own_n, own_body, own_boi]),
        (MASK_OTHER, [other_n, other_body, other_boi]),
        (MASK_MOUTH, [mouth_n, mouth_body, mouth_boi]),
        (MASK_NONE, [none_n, none_body, none_boi]),
    ] {
        bins[state * 3] = n - b - i;
        bins[state * 3 + 1] = b;
        bins[state * 3 + 2] = i;
    }
    bins
}
