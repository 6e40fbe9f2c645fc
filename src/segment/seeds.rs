//! Where each class's colours are first learned from, before any model exists: the first
//! guess of teeth, mouth interior and the rest on a camera's first picture, and the mouth
//! interior on the first picture that shows one (a closed mouth shows none, and what lies
//! between its lips is lip).

use super::colour_model::{ColourModel, luma};

/// A first guess of the classes, to learn the colour models from. The models' projection
/// holds teeth and whatever hides them (lips, gums, the mouth's shadow): teeth are its
/// palest pixels, of colours rare just around it. Of the rest near the arches, the clearly
/// darker part (a two-class split of luma, Otsu's) is the mouth interior when it is also dark
/// beside the teeth; everything else is lips and skin.
pub(super) fn initial_classes(
    colours: &[[u8; 3]],
    projected: &[u8],
    distance: &[f32],
    span_distance: &[f32],
    reach: f32,
    min_pixels: usize,
) -> Vec<u8> {
    let n = colours.len();
    // Enamel is the least red of what the projection holds (lips, gums and the mouth are
    // red), in light and in shadow and under any white balance near daylight's: teeth are the
    // less red side of a two-class split of redness there, when the split is clear. (Not
    // saturation: a yellowish white balance makes shaded enamel as saturated as a lip.)
    let pale: Vec<f32> = (0..n)
        .filter(|&i| projected[i] != 0)
        .map(|i| redness(colours[i]))
        .collect();
    let pale_below = otsu(&pale)
        .filter(|&(_, low, high)| low < 0.7 * high)
        .map_or(f32::INFINITY, |(t, _, _)| t);
    // Skin the projection reaches at the mouth's corners can be as pale: teeth are also the
    // colours commoner inside the projection than in the ring around it.
    let ring = |i: usize| projected[i] == 0 && distance[i] <= 4.0 * reach;
    let learn_where = |inside: &dyn Fn(usize) -> bool| {
        ColourModel::learn(
            (0..n).filter(|&i| inside(i)).map(|i| colours[i]),
            min_pixels,
        )
    };
    let models = (learn_where(&|i| projected[i] != 0), learn_where(&ring));
    let teeth: Vec<bool> = (0..n)
        .map(|i| {
            let c = colours[i];
            projected[i] != 0
                && redness(c) < pale_below
                && match &models {
                    (Some(inside), Some(around)) => inside.density(c) > around.density(c),
                    _ => true,
                }
        })
        .collect();
    let near: Vec<bool> = (0..n)
        .map(|i| span_distance[i] <= reach && !teeth[i])
        .collect();
    let lumas: Vec<f32> = (0..n)
        .filter(|&i| near[i])
        .map(|i| luma(colours[i]))
        .collect();
    // The mouth interior is the clearly darker side of what lies near the arches, and dark
    // beside the teeth themselves: with the mouth closed, that darker side is the lips, and
    // the interior is left to be learned once a later picture shows it.
    let teeth_luma = median((0..n).filter(|&i| teeth[i]).map(|i| luma(colours[i])));
    let dark_below = otsu(&lumas)
        .filter(|&(_, dark, bright)| dark < 0.6 * bright)
        .filter(|&(_, dark, _)| teeth_luma.is_some_and(|t| dark < INTERIOR_SHARE * t))
        .map(|(t, dark, bright)| {
            (
                t.min(INTERIOR_SHARE * teeth_luma.unwrap_or(0.0)),
                dark,
                bright,
            )
        });
    (0..n)
        .map(|i| {
            if teeth[i] {
                0
            } else if near[i] && dark_below.is_some_and(|(t, _, _)| luma(colours[i]) < t) {
                1
            } else {
                2
            }
        })
        .collect()
}

/// The mouth interior is at most this share of the teeth's luma (the median over the first
/// guess of them): a throat in shadow, not a lip.
const INTERIOR_SHARE: f32 = 0.45;

/// The median of some values; `None` of none.
fn median(values: impl Iterator<Item = f32>) -> Option<f32> {
    let mut v: Vec<f32> = values.collect();
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    Some(*v.select_nth_unstable_by(mid, f32::total_cmp).1)
}

/// How much redder than green a colour is, as a share of its brightness, scaled to 0..255.
fn redness(c: [u8; 3]) -> f32 {
    let [r, g, b] = c.map(|v| v as f32);
    255.0 * (r - g).max(0.0) / (r + g + b).max(1.0)
}

/// Otsu's threshold of a set of values (0..255), with the two sides' means.
fn otsu(values: &[f32]) -> Option<(f32, f32, f32)> {
    let mut hist = [0f64; 256];
    for &v in values {
        hist[v.clamp(0.0, 255.0) as usize] += 1.0;
    }
    let total: f64 = hist.iter().sum();
    let sum: f64 = hist.iter().enumerate().map(|(k, h)| k as f64 * h).sum();
    let (mut below, mut below_sum) = (0f64, 0f64);
    let mut best: Option<(f64, f32, f32, f32)> = None;
    for (k, h) in hist.iter().enumerate() {
        below += h;
        below_sum += k as f64 * h;
        let above = total - below;
        if below == 0.0 || above == 0.0 {
            continue;
        }
        let (m0, m1) = (below_sum / below, (sum - below_sum) / above);
        let between = below * above * (m0 - m1).powi(2);
        if best.is_none_or(|b| between > b.0) {
            best = Some((between, k as f32 + 1.0, m0 as f32, m1 as f32));
        }
    }
    best.map(|(_, t, m0, m1)| (t, m0, m1))
}

/// The mouth interior's model, from a picture that shows it: the pixels where the interior
/// may be (between the arches) as dark beside the teeth as an interior is; `None` while too
/// few are.
pub(super) fn learn_interior(
    colours: &[[u8; 3]],
    priors: &[[f32; 3]],
    teeth: &ColourModel,
    other: &ColourModel,
    min_pixels: usize,
) -> Option<ColourModel> {
    let teeth_like = |i: usize| teeth.density(colours[i]) > other.density(colours[i]);
    let teeth_luma = median(
        (0..colours.len())
            .filter(|&i| priors[i][0] > priors[i][2] && teeth_like(i))
            .map(|i| luma(colours[i])),
    )?;
    ColourModel::learn(
        (0..colours.len())
            .filter(|&i| {
                priors[i][1] > priors[i][2] && luma(colours[i]) < INTERIOR_SHARE * teeth_luma
            })
            .map(|i| colours[i]),
        min_pixels,
    )
}
