use super::*;
use crate::arch::{LOWER_BIT, UPPER_BIT};

/// A surface's colour at (x, y), with a little texture.
fn textured(c: [u8; 3], x: usize, y: usize) -> [u8; 3] {
    c.map(|v| v.saturating_add(((x * 7 + y * 13) % 9) as u8))
}

/// One picture segmented with the arches expected still at `prior`, its posteriors unwritten.
fn segment_still(
    rgb: &[u8],
    (w, h): (usize, usize),
    prior: &[u8],
    models: &mut Option<Models>,
    settings: &SegmentSettings,
) -> Outcome {
    segment_picture(rgb, w, h, Expected::still(prior), models, settings, None)
}

/// A picture of a white band (teeth) over a dark gap, inside red lips, on skin; the
/// prior is the band shifted by two pixels and a little too wide, as a pose a frame
/// old would draw it.
#[test]
fn teeth_and_mouth_come_out_where_the_colours_are_despite_an_offset_prior() {
    let (w, h) = (120, 80);
    let mut rgb = vec![0u8; w * h * 3];
    let mut truth = vec![0u8; w * h];
    let mut prior = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (c, t): ([u8; 3], u8) = if (30..90).contains(&x) && (30..40).contains(&y) {
                ([230, 220, 195], UPPER_BIT)
            } else if (30..90).contains(&x) && (40..48).contains(&y) {
                ([60, 20, 25], MOUTH_BIT)
            } else if (30..90).contains(&x) && (20..58).contains(&y) {
                ([170, 80, 85], 0)
            } else {
                ([210, 160, 135], 0)
            };
            rgb[i * 3..i * 3 + 3].copy_from_slice(&textured(c, x, y));
            truth[i] = t;
            if (28..92).contains(&x) && (25..44).contains(&y) {
                prior[i] = UPPER_BIT;
            }
        }
    }
    // A 120-pixel picture: the reach of a 960-pixel one.
    let settings = SegmentSettings {
        reach: 0.06,
        ..SegmentSettings::default()
    };
    let mut models = None;
    let Outcome::Labels { labels, .. } =
        segment_still(&rgb, (w, h), &prior, &mut models, &settings)
    else {
        panic!("the prior is in view and the picture is lit");
    };
    let iou = |bit: u8| {
        let (mut inter, mut union) = (0, 0);
        for (l, t) in labels.iter().zip(&truth) {
            let (a, b) = (l & bit != 0, t & bit != 0);
            inter += (a && b) as u32;
            union += (a || b) as u32;
        }
        inter as f64 / union as f64
    };
    assert!(iou(UPPER_BIT) > 0.95, "teeth IoU {}", iou(UPPER_BIT));
    // The mouth interior is the known weak point (docs/footage.md): found, not yet whole.
    assert!(iou(MOUTH_BIT) > 0.4, "mouth IoU {}", iou(MOUTH_BIT));
    // The same picture in the dark is refused once the models know the light.
    let dark: Vec<u8> = rgb.iter().map(|&v| v / 10).collect();
    assert!(matches!(
        segment_still(&dark, (w, h), &prior, &mut models, &settings),
        Outcome::Dark
    ));
}

/// Upper teeth over lower teeth `gap` rows apart (the dark interior between), inside
/// lips, on skin; the prior draws both arches where they are. The picture and its true
/// labels.
fn mouth_picture(gap: usize) -> (Vec<u8>, Vec<u8>, Vec<u8>) {
    let (w, h) = (120, 80);
    let (mut rgb, mut truth, mut prior) =
        (vec![0u8; w * h * 3], vec![0u8; w * h], vec![0u8; w * h]);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let across = (30..90).contains(&x);
            let (c, t): ([u8; 3], u8) = if across && (30..38).contains(&y) {
                ([230, 220, 195], UPPER_BIT)
            } else if across && (38..38 + gap).contains(&y) {
                ([60, 20, 25], MOUTH_BIT)
            } else if across && (38 + gap..46 + gap).contains(&y) {
                ([225, 214, 190], LOWER_BIT)
            } else if across && (20..56 + gap).contains(&y) {
                ([170, 80, 85], 0)
            } else {
                ([210, 160, 135], 0)
            };
            rgb[i * 3..i * 3 + 3].copy_from_slice(&textured(c, x, y));
            truth[i] = t;
            if across && (26..38).contains(&y) {
                prior[i] = UPPER_BIT;
            } else if across && (38 + gap..50 + gap).contains(&y) {
                prior[i] = LOWER_BIT;
            }
        }
    }
    (rgb, truth, prior)
}

fn iou(labels: &[u8], truth: &[u8], bit: u8) -> f64 {
    let (mut inter, mut union) = (0, 0);
    for (l, t) in labels.iter().zip(truth) {
        let (a, b) = (l & bit != 0, t & bit != 0);
        inter += (a && b) as u32;
        union += (a || b) as u32;
    }
    inter as f64 / union.max(1) as f64
}

/// With the mouth closed, what lies between the lips is lip: no interior is learned from
/// it (else every later lip would be labelled interior). The first picture that shows
/// the dark interior teaches it, and its posteriors say so.
#[test]
fn the_mouth_interior_is_learned_once_a_picture_shows_it() {
    let (w, h) = (120, 80);
    let settings = SegmentSettings {
        reach: 0.06,
        ..SegmentSettings::default()
    };
    let mut models = None;
    let (rgb, truth, prior) = mouth_picture(0);
    let Outcome::Labels { labels, .. } =
        segment_still(&rgb, (w, h), &prior, &mut models, &settings)
    else {
        panic!("in view and lit");
    };
    assert!(models.as_ref().unwrap().mouth.is_none());
    assert!(labels.iter().all(|l| l & MOUTH_BIT == 0));
    assert!(iou(&labels, &truth, UPPER_BIT) > 0.8);
    let (rgb, truth, prior) = mouth_picture(8);
    let mut posteriors = Vec::new();
    let Outcome::Labels { labels, .. } = segment_picture(
        &rgb,
        w,
        h,
        Expected::still(&prior),
        &mut models,
        &settings,
        Some(&mut posteriors),
    ) else {
        panic!("in view and lit");
    };
    assert!(models.as_ref().unwrap().mouth.is_some());
    let mouth = iou(&labels, &truth, MOUTH_BIT);
    assert!(mouth > 0.7, "mouth IoU {mouth}");
    for bit in [UPPER_BIT, LOWER_BIT] {
        let teeth = iou(&labels, &truth, bit);
        assert!(teeth > 0.8, "teeth IoU {teeth}");
    }
    // Red where a tooth is, green where the interior is, blue on the skin far away.
    let at = |x: usize, y: usize| &posteriors[(y * w + x) * 3..(y * w + x) * 3 + 3];
    assert!(at(60, 34)[0] > 200, "{:?}", at(60, 34));
    assert!(at(60, 42)[1] > 200, "{:?}", at(60, 42));
    assert_eq!(at(2, 2), [0, 0, 255]);
}

#[test]
fn the_distance_transform_carries_the_nearest_label() {
    let (w, h) = (10, 1);
    let mut l = vec![0u8; w];
    l[0] = UPPER_BIT;
    l[9] = LOWER_BIT;
    let (d, near) = distance_transform(&l, w, h);
    assert_eq!(d[3], 3.0);
    assert_eq!(near[3], UPPER_BIT);
    assert_eq!(near[7], LOWER_BIT);
}

/// Gums the cut labelled teeth, beside real crowns: following that picture teaches the teeth's
/// model pink where the arches are not tracked, and nothing of it where the tracked arches
/// cover only the crowns.
#[test]
fn the_models_learn_teeth_only_where_the_tracked_arches_are() {
    let (w, h) = (40, 30);
    let (white, pink) = ([230u8, 220, 195], [200u8, 90, 100]);
    let colours: Vec<[u8; 3]> = (0..w * h)
        .map(|i| textured(if i % w < w / 2 { white } else { pink }, i % w, i / w))
        .collect();
    let lesson = lesson::Lesson {
        colours: colours.clone(),
        classes: vec![0; w * h],
        far: vec![false; w * h],
        roi: Roi { x0: 0, y0: 0, w, h },
        mean_luma: 150.0,
    };
    let settings = SegmentSettings::default();
    let crowns = || {
        let teeth = ColourModel::learn(colours.iter().copied().filter(|c| c[1] > 150), 10);
        Models {
            teeth: teeth.expect("enough white pixels"),
            mouth: None,
            other: ColourModel::uniform(),
            lit_luma: 150.0,
        }
    };
    let drawn_over = |columns: usize| -> Vec<u8> {
        (0..w * h)
            .map(|i| if i % w < columns { UPPER_BIT } else { 0 })
            .collect()
    };
    let mut everywhere = crowns();
    lesson.follow(&drawn_over(w), w, &mut everywhere, &settings);
    let mut on_the_crowns = crowns();
    lesson.follow(&drawn_over(w / 2), w, &mut on_the_crowns, &settings);
    let before = crowns().teeth.density(textured(pink, 30, 15));
    let taught = everywhere.teeth.density(textured(pink, 30, 15));
    let gated = on_the_crowns.teeth.density(textured(pink, 30, 15));
    assert!(taught > 10.0 * before.max(1e-9), "{taught} vs {before}");
    assert!(gated < 1.01 * before + 1e-9, "{gated} vs {before}");
    let enamel = textured(white, 5, 5);
    assert!(on_the_crowns.teeth.density(enamel) > 0.8 * crowns().teeth.density(enamel));
}
