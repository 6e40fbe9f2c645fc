//! Distance maps of a projected label picture, for the spatial prior: how far each pixel is
//! from the nearest labelled one (and which label that is), and from the span of the mouth.

use crate::arch::{LOWER_BIT, UPPER_BIT};

/// Per pixel, the chamfer distance (3-4, in pixels) to the nearest labelled pixel and that
/// pixel's label.
pub(super) fn distance_transform(labels: &[u8], w: usize, h: usize) -> (Vec<f32>, Vec<u8>) {
    let mut d: Vec<f32> = labels
        .iter()
        .map(|&l| if l != 0 { 0.0 } else { f32::INFINITY })
        .collect();
    let mut near = labels.to_vec();
    let (straight, diagonal) = (1.0f32, std::f32::consts::SQRT_2);
    let relax = |d: &mut [f32], near: &mut [u8], i: usize, j: usize, step: f32| {
        if d[j] + step < d[i] {
            d[i] = d[j] + step;
            near[i] = near[j];
        }
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x > 0 {
                relax(&mut d, &mut near, i, i - 1, straight);
            }
            if y > 0 {
                relax(&mut d, &mut near, i, i - w, straight);
                if x > 0 {
                    relax(&mut d, &mut near, i, i - w - 1, diagonal);
                }
                if x + 1 < w {
                    relax(&mut d, &mut near, i, i - w + 1, diagonal);
                }
            }
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            if x + 1 < w {
                relax(&mut d, &mut near, i, i + 1, straight);
            }
            if y + 1 < h {
                relax(&mut d, &mut near, i, i + w, straight);
                if x + 1 < w {
                    relax(&mut d, &mut near, i, i + w + 1, diagonal);
                }
                if x > 0 {
                    relax(&mut d, &mut near, i, i + w - 1, diagonal);
                }
            }
        }
    }
    for n in &mut near {
        if *n == 0 {
            *n = UPPER_BIT;
        }
        *n &= UPPER_BIT | LOWER_BIT;
    }
    (d, near)
}

/// Per pixel, how far (rows) it lies outside the span between the arches' outlines in its
/// column (the outlines' top and bottom taken over `reach` columns either side, so gaps
/// between crowns do not break it); 0 inside.
pub(super) fn mouth_span_distance(labels: &[u8], w: usize, h: usize, reach: usize) -> Vec<f32> {
    let mut top = vec![usize::MAX; w];
    let mut bottom = vec![0usize; w];
    for y in 0..h {
        for x in 0..w {
            if labels[y * w + x] != 0 {
                top[x] = top[x].min(y);
                bottom[x] = bottom[x].max(y);
            }
        }
    }
    let mut out = vec![f32::INFINITY; w * h];
    for x in 0..w {
        let lo = x.saturating_sub(reach);
        let hi = (x + reach).min(w - 1);
        let t = (lo..=hi).map(|k| top[k]).min().unwrap_or(usize::MAX);
        let b = (lo..=hi).map(|k| bottom[k]).max().unwrap_or(0);
        if t == usize::MAX {
            continue;
        }
        for y in 0..h {
            out[y * w + x] = if y < t {
                (t - y) as f32
            } else if y > b {
                (y - b) as f32
            } else {
                0.0
            };
        }
    }
    out
}
