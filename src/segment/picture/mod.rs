//! One camera's picture segmented into teeth (per arch), visible mouth interior and the rest,
//! from where the models project (the spatial prior) and the capture's colour models, made
//! spatially coherent by graph cuts with a contrast-sensitive smoothness term as in GrabCut
//! (teeth against the rest, then mouth interior against lips and skin), the edges decided
//! again by colour (`edges`), and the teeth split between the arches by a third cut
//! (`arches`).

use super::arches::split_arches;
use super::colour_model::{ColourModel, luma};
use super::distance::{distance_transform, mouth_span_distance};
use super::edges::{neighbours4, refine_edges, settle_gaps};
use super::evidence::teeth_shares;
use super::graph_cut::GridCut;
use super::opening::inside_the_lips;
use super::seeds::{initial_classes, learn_interior};
use super::settings::SegmentSettings;
use super::shaded_crowns::shaded_crowns;
use super::smear::decide_ramps;
use super::smoothness::{contrast, set_pairs};
use crate::capture::masks::MOUTH_BIT;
use crate::capture::{LOWER_BIT, UPPER_BIT};
pub use lesson::Lesson;

/// How the teeth's colour model falls off a luma level into shade
/// ([`ColourModel::shaded`]): the side teeth deep in an open mouth are in its shadow.
const TEETH_SHADE_FALLOFF: f32 = 0.7;

/// The colour models of one camera: teeth, mouth interior, lips and skin.
#[derive(Debug, Clone)]
pub struct Models {
    pub teeth: ColourModel,
    /// `None` until a picture shows the mouth's dark interior (a closed mouth shows none, and
    /// a model learned there would learn the lips).
    pub mouth: Option<ColourModel>,
    pub other: ColourModel,
    /// Mean luma of the region they were learned in: a picture much darker than this was
    /// taken with the lights off.
    pub lit_luma: f32,
}

/// How far from the models' projection lips and skin are learned from, in reaches.
const OTHER_REACH: f32 = 3.0;

/// What one picture came out as.
pub enum Outcome {
    /// Label bits per pixel (UPPER_BIT, LOWER_BIT, MOUTH_BIT), the whole picture, and what
    /// the picture has to teach the models once the frame is tracked (none on the picture
    /// they were first learned from).
    Labels {
        labels: Vec<u8>,
        /// Per pixel, how much of it each arch's teeth hold (upper, lower; 0-255): the
        /// labels, but along the teeth's edges the share the pixel's colour gives them
        /// ([`super::evidence`]); only where the settings ask for soft evidence.
        soft: Option<Vec<[u8; 2]>>,
        lesson: Option<Lesson>,
    },
    /// The models project nowhere into the picture.
    OutOfView,
    /// Much darker than the colour models were learned in (the lights were off).
    Dark,
}

/// A rectangle of the picture, where the work is done.
#[derive(Debug, Clone, Copy)]
struct Roi {
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
}

impl Roi {
    /// The picture's pixel (x, y) at index `i` of the ROI's local, row-major order.
    fn at(&self, i: usize) -> (usize, usize) {
        (self.x0 + i % self.w, self.y0 + i / self.w)
    }
}

/// Where tracking expects the arches in a picture.
#[derive(Debug, Clone, Copy)]
pub struct Expected<'a> {
    /// The label bits of the models drawn at the expected poses (UPPER_BIT / LOWER_BIT per
    /// pixel, 0 elsewhere).
    pub prior: &'a [u8],
    /// Each arch's smear (upper, lower): how far, in pixels, it moves while the shutter is
    /// open ([`super::smear`]).
    pub smear: [[f32; 2]; 2],
}

impl<'a> Expected<'a> {
    /// Arches expected at `prior`, not moving.
    pub fn still(prior: &'a [u8]) -> Expected<'a> {
        Expected {
            prior,
            smear: [[0.0; 2]; 2],
        }
    }
}

/// Segment `rgb` (`width` x `height`, 3 bytes a pixel) given where the arches are `expected`.
/// `models` are learned here when `None`; afterwards they follow the pictures once tracking
/// has placed the arches in them (the outcome's [`Lesson`]). `posteriors`, when given, gets
/// the picture of what the colour models and the prior made of each pixel before the cuts
/// ([`posterior_picture`]).
pub fn segment_picture(
    rgb: &[u8],
    width: usize,
    height: usize,
    expected: Expected,
    models: &mut Option<Models>,
    settings: &SegmentSettings,
    posteriors: Option<&mut Vec<u8>>,
) -> Outcome {
    let prior = expected.prior;
    let Some(roi) = roi(prior, width, height) else {
        return Outcome::OutOfView;
    };
    let colour = |x: usize, y: usize| -> [u8; 3] {
        let i = (y * width + x) * 3;
        [rgb[i], rgb[i + 1], rgb[i + 2]]
    };
    let reach = (settings.reach * width as f64).max(1.5) as f32;
    let n = roi.w * roi.h;
    // Local coordinates inside the ROI from here on.
    let at = |i: usize| roi.at(i);
    let colours: Vec<[u8; 3]> = (0..n).map(at).map(|(x, y)| colour(x, y)).collect();
    let projected: Vec<u8> = (0..n).map(at).map(|(x, y)| prior[y * width + x]).collect();
    let (distance, _) = distance_transform(&projected, roi.w, roi.h);
    let span_distance = mouth_span_distance(&projected, roi.w, roi.h, reach as usize);
    let priors = spatial_priors(&projected, &distance, &span_distance, reach);
    let mean_luma = (colours.iter().map(|&c| luma(c) as f64).sum::<f64>() / n as f64) as f32;
    if let Some(m) = models
        && (mean_luma as f64) < settings.dark_ratio * m.lit_luma as f64
    {
        return Outcome::Dark;
    }
    let learning = models.is_none();
    if let Some(m) = models.as_mut()
        && m.mouth.is_none()
    {
        m.mouth = learn_interior(&colours, &priors, &m.teeth, &m.other, settings.min_pixels);
    }
    let first: Vec<u8> = if learning {
        initial_classes(
            &colours,
            &projected,
            &distance,
            &span_distance,
            reach,
            settings.min_pixels,
        )
    } else {
        Vec::new()
    };
    // Lips and skin are learned from around the mouth alone: skin far from it, shaded as
    // teeth can be, would teach the model teeth's colours, and there the prior decides.
    let far: Vec<bool> = distance.iter().map(|&d| d > OTHER_REACH * reach).collect();
    let beta = contrast(&colours, roi.w, roi.h);
    let classes = cut_rounds(
        &colours, &priors, beta, &far, first, models, mean_luma, roi, settings,
    );
    let Some(classes) = classes else {
        return Outcome::OutOfView;
    };
    // A pass over the classes' edges by colour, each side's colour read from its pixels away
    // from its edges.
    type ByColour = fn(&[[u8; 3]], &[u8], &[u8], usize, usize) -> Vec<u8>;
    let by_colour =
        |pass: ByColour, c: &[u8]| pass(&colours, c, &eroded(c, roi.w, roi.h), roi.w, roi.h);
    let classes = by_colour(settle_gaps, &classes);
    let classes = by_colour(refine_edges, &classes);
    if let (Some(out), Some(m)) = (posteriors, models.as_ref()) {
        *out = posterior_picture(&likelihoods(&colours, &priors, m), roi, width, height);
    }
    // The gums and tongue are labelled interior, but the lesson keeps the classes as cut:
    // they are not the interior's colours (they would teach it the lips').
    let mut opened = inside_the_lips(&classes, roi.w, roi.h);
    let teeth: Vec<bool> = opened.iter().map(|&c| c == 0).collect();
    let mut arches = split_arches(
        &colours,
        &teeth,
        &projected,
        roi.w,
        roi.h,
        beta,
        settings.smoothness as f32,
        reach,
    );
    decide_ramps(
        &colours,
        &mut opened,
        &mut arches,
        roi.w,
        roi.h,
        expected.smear,
    );
    if let Some(share) = settings.shaded_crowns {
        shaded_crowns(&colours, &mut opened, &mut arches, roi.w, roi.h, share);
    }
    let labels = picture_labels(&opened, &arches, roi, width, height);
    let soft = settings.soft_evidence.then(|| {
        let shares = by_colour(teeth_shares, &opened);
        picture_shares(&shares, &arches, roi, width, height)
    });
    let lesson = (!learning).then_some(Lesson {
        colours,
        classes,
        far,
        roi,
        mean_luma,
    });
    Outcome::Labels {
        labels,
        soft,
        lesson,
    }
}

/// Spatial priors per ROI pixel (teeth, mouth interior, the rest): teeth only near the models'
/// projection, mouth interior between the arches' outlines, lips and skin anywhere.
fn spatial_priors(
    projected: &[u8],
    distance: &[f32],
    span_distance: &[f32],
    reach: f32,
) -> Vec<[f32; 3]> {
    (0..projected.len())
        .map(|i| {
            let teeth = 0.45 * (-distance[i] / reach).exp();
            let mouth = if projected[i] != 0 {
                0.2
            } else {
                0.45 * (-span_distance[i] / reach).exp()
            };
            let other = (1.0 - teeth - mouth).max(0.1);
            [teeth, mouth, other]
        })
        .collect()
}

/// The classes after the graph cuts: when `models` is `None`, learned from `classes` (the
/// first guess) and re-cut for the settings' learning rounds, else one cut with `models`.
/// `None` when the teeth's colours cannot be learned.
#[allow(clippy::too_many_arguments)]
fn cut_rounds(
    colours: &[[u8; 3]],
    priors: &[[f32; 3]],
    beta: f32,
    far: &[bool],
    mut classes: Vec<u8>,
    models: &mut Option<Models>,
    mean_luma: f32,
    roi: Roi,
    settings: &SegmentSettings,
) -> Option<Vec<u8>> {
    let learning = models.is_none();
    let rounds = if learning {
        settings.learning_rounds
    } else {
        1
    };
    for round in 0..rounds.max(1) {
        if learning {
            // The first guess is made of whole pixels of each colour, not of a cut's edges.
            let cut_edges = round > 0;
            let fresh = learn(colours, &classes, cut_edges, far, roi, settings.min_pixels)?;
            *models = Some(Models {
                lit_luma: mean_luma,
                ..fresh
            });
        }
        let m = models.as_ref().expect("learned above or before");
        classes = cut(colours, priors, m, roi, beta, settings);
    }
    Some(classes)
}

/// The whole picture's label bits from the ROI's classes: teeth take their arch's bit
/// (`arches`), the mouth interior MOUTH_BIT, the rest 0.
fn picture_labels(classes: &[u8], arches: &[u8], roi: Roi, width: usize, height: usize) -> Vec<u8> {
    let mut labels = vec![0u8; width * height];
    for (i, &class) in classes.iter().enumerate() {
        let (x, y) = roi.at(i);
        labels[y * width + x] = match class {
            0 => arches[i],
            1 => MOUTH_BIT,
            _ => 0,
        };
    }
    labels
}

/// The whole picture's soft evidence from the ROI's teeth shares: a tooth's share goes to its
/// arch (`arches`), a share beside teeth to the arch of the teeth beside it.
fn picture_shares(
    shares: &[u8],
    arches: &[u8],
    roi: Roi,
    width: usize,
    height: usize,
) -> Vec<[u8; 2]> {
    let mut soft = vec![[0u8; 2]; width * height];
    for (i, &share) in shares.iter().enumerate() {
        if share == 0 {
            continue;
        }
        let arch = if arches[i] != 0 {
            arches[i]
        } else {
            let (x, y) = (i % roi.w, i / roi.w);
            let Some(j) = neighbours4(roi.w, roi.h, x, y).find(|&j| arches[j] != 0) else {
                continue;
            };
            arches[j]
        };
        let (x, y) = roi.at(i);
        let slot = &mut soft[y * width + x];
        if arch & UPPER_BIT != 0 {
            slot[0] = share;
        } else if arch & LOWER_BIT != 0 {
            slot[1] = share;
        }
    }
    soft
}

/// The prior's bounding box, widened by a third of its height and a sixth of its width.
fn roi(prior: &[u8], width: usize, height: usize) -> Option<Roi> {
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (i, &p) in prior.iter().enumerate() {
        if p != 0 {
            let (x, y) = (i % width, i / width);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x);
            y1 = y1.max(y);
        }
    }
    if x0 == usize::MAX {
        return None;
    }
    let (mx, my) = ((x1 - x0) / 6 + 8, (y1 - y0) / 3 + 8);
    let (x0, y0) = (x0.saturating_sub(mx), y0.saturating_sub(my));
    let (x1, y1) = ((x1 + mx).min(width - 1), (y1 + my).min(height - 1));
    Some(Roi {
        x0,
        y0,
        w: x1 - x0 + 1,
        h: y1 - y0 + 1,
    })
}

/// Colour models from the pixels of each class (0 teeth, 1 mouth, 2 other; others unused).
/// From a cut (`cut_edges`), teeth and mouth interior learn from inside their regions alone,
/// lips and skin also from the edges, where a blurred picture mixes lip and skin (or lip and
/// tooth): a mixed colour must be likelier lip than tooth. Teeth too thin to have an inside
/// learn from all of theirs. A mouth with too few pixels gets no model (a closed mouth shows
/// none); lips and skin too few get a uniform one.
fn learn(
    colours: &[[u8; 3]],
    classes: &[u8],
    cut_edges: bool,
    far: &[bool],
    roi: Roi,
    min_pixels: usize,
) -> Option<Models> {
    let inner = if cut_edges {
        eroded(classes, roi.w, roi.h)
    } else {
        classes.to_vec()
    };
    Some(Models {
        teeth: learn_class(colours, &inner, 0, min_pixels)
            .or_else(|| learn_class(colours, classes, 0, min_pixels))?
            .shaded(TEETH_SHADE_FALLOFF),
        mouth: learn_class(colours, &inner, 1, min_pixels),
        other: learn_class(colours, &near_only(classes, far), 2, min_pixels)
            .unwrap_or_else(ColourModel::uniform),
        lit_luma: 0.0,
    })
}

/// The classes with lips and skin `far` from the mouth left out (3 = unused).
fn near_only(classes: &[u8], far: &[bool]) -> Vec<u8> {
    classes
        .iter()
        .zip(far)
        .map(|(&c, &f)| if c == 2 && f { 3 } else { c })
        .collect()
}

fn learn_class(
    colours: &[[u8; 3]],
    classes: &[u8],
    k: u8,
    min_pixels: usize,
) -> Option<ColourModel> {
    ColourModel::learn(
        colours
            .iter()
            .zip(classes)
            .filter(|&(_, &c)| c == k)
            .map(|(&c, _)| c),
        min_pixels,
    )
}

/// The classes with their boundaries left out (3 = unused), so that mixed pixels at edges
/// do not teach a model the neighbour's colour.
fn eroded(classes: &[u8], w: usize, h: usize) -> Vec<u8> {
    (0..classes.len())
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let c = classes[i];
            let same = |j: usize| classes[j] == c;
            let interior = x > 0
                && y > 0
                && x + 1 < w
                && y + 1 < h
                && same(i - 1)
                && same(i + 1)
                && same(i - w)
                && same(i + w);
            if interior { c } else { 3 }
        })
        .collect()
}

/// Per ROI pixel, prior times colour density of teeth, mouth interior (0 while it has no
/// model), and lips and skin.
fn likelihoods(colours: &[[u8; 3]], priors: &[[f32; 3]], m: &Models) -> Vec<[f32; 3]> {
    colours
        .iter()
        .zip(priors)
        .map(|(&c, p)| {
            [
                p[0] * m.teeth.density(c),
                m.mouth
                    .as_ref()
                    .map_or(0.0, |mouth| p[1] * mouth.density(c)),
                p[2] * m.other.density(c),
            ]
        })
        .collect()
}

/// The whole picture (RGB) of each pixel's posterior: red teeth, green mouth interior, blue
/// lips and skin, each at its probability; outside the region worked on, blue.
fn posterior_picture(likelihood: &[[f32; 3]], roi: Roi, width: usize, height: usize) -> Vec<u8> {
    let mut rgb: Vec<u8> = [0u8, 0, 255].repeat(width * height);
    for (i, l) in likelihood.iter().enumerate() {
        let (x, y) = roi.at(i);
        let total = (l[0] + l[1] + l[2]).max(1e-30);
        for k in 0..3 {
            rgb[(y * width + x) * 3 + k] = (255.0 * l[k] / total).round() as u8;
        }
    }
    rgb
}

/// Teeth against the rest, then, among the rest, mouth interior against lips and skin.
fn cut(
    colours: &[[u8; 3]],
    priors: &[[f32; 3]],
    m: &Models,
    roi: Roi,
    beta: f32,
    settings: &SegmentSettings,
) -> Vec<u8> {
    let (w, h) = (roi.w, roi.h);
    let n = w * h;
    let likelihood = likelihoods(colours, priors, m);
    let cost = |p: f32| -(p.max(1e-12)).ln();
    let lambda = settings.smoothness as f32;
    let mut teeth_cut = GridCut::new(w, h);
    for (i, l) in likelihood.iter().enumerate() {
        let (a, b) = (cost(l[0]), cost(l[1] + l[2]));
        let low = a.min(b);
        teeth_cut.set_costs(i, a - low, b - low);
    }
    set_pairs(&mut teeth_cut, colours, (w, h), beta, lambda, &|_| false);
    let teeth = teeth_cut.solve();
    let mut mouth_cut = GridCut::new(w, h);
    for (i, l) in likelihood.iter().enumerate() {
        if teeth[i] {
            continue;
        }
        let (a, b) = (cost(l[1]), cost(l[2]));
        let low = a.min(b);
        mouth_cut.set_costs(i, a - low, b - low);
    }
    set_pairs(&mut mouth_cut, colours, (w, h), beta, lambda, &|i| teeth[i]);
    let mouth = mouth_cut.solve();
    (0..n)
        .map(|i| {
            if teeth[i] {
                0
            } else if mouth[i] {
                1
            } else {
                2
            }
        })
        .collect()
}

mod lesson;
#[cfg(test)]
mod tests;
