//! How far a mapping is carried to a new subject, beyond the paper's one way: every rung of a
//! ladder from none to the paper's per-feature transforms, each scored on the calibration
//! poses left out, and the model's prediction the blend of every rung of every mapping it
//! holds (a multi-subject model holds the pooled mapping and each source's own), weighed by
//! those scores.

use rayon::prelude::*;

use super::model::{BlendTerm, SkinModel, SubjectFit};
use super::regress::Regressor;
use super::retarget::{
    CandidateScore, FeatureTransform, RetargetReport, RetargetSettings, align_globally, apply,
    data_cost, retarget,
};
use super::subject::Subject;
use crate::error::Result;

/// How far a mapping is carried to a new subject.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Carry {
    /// The source's mapping as it is (the uncalibrated mapping).
    None,
    /// One rigid transform of every skin feature's displacement (6 numbers).
    Global,
    /// The global transform, then one per feature, regularised by Eq. 3's λ times this
    /// multiple.
    PerFeature(f64),
    /// The paper's: one transform per feature from the identity, with Eq. 3's λ.
    Paper,
}

/// Calibration poses are left out in at most this many groups when a rung is scored.
pub const MAX_FOLDS: usize = 5;

/// The ways a mapping is carried, simplest first.
pub const LADDER: [Carry; 5] = [
    Carry::None,
    Carry::Global,
    Carry::PerFeature(1e4),
    Carry::PerFeature(1e2),
    Carry::Paper,
];

impl std::fmt::Display for Carry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Carry::None => write!(f, "none"),
            Carry::Global => write!(f, "global"),
            Carry::PerFeature(k) => write!(f, "global, then per-feature λ×{k}"),
            Carry::Paper => write!(f, "per-feature"),
        }
    }
}

/// Fit one rung of the ladder on `pairs`.
fn fit(
    phi: &Regressor,
    pairs: &[(Vec<f64>, Vec<f64>)],
    s: &RetargetSettings,
    carry: Carry,
) -> (Vec<FeatureTransform>, RetargetReport) {
    let mut out = match carry {
        Carry::None => {
            let c = data_cost(phi, pairs, &[]);
            (
                Vec::new(),
                RetargetReport {
                    cost_before: c,
                    cost_after: c,
                    ..Default::default()
                },
            )
        }
        Carry::Global => {
            let (t, r) = align_globally(phi, pairs, s);
            (vec![t], r)
        }
        Carry::Paper => retarget(phi, pairs, s),
        Carry::PerFeature(k) => {
            let scaled = RetargetSettings {
                lambda_rotation: s.lambda_rotation * k,
                lambda_translation: s.lambda_translation * k,
                ..*s
            };
            // Per-feature transforms on top of the global one: the regulariser then shrinks
            // each toward the subject's overall change, which five poses determine well.
            let (g, first) = align_globally(phi, pairs, s);
            let moved: Vec<(Vec<f64>, Vec<f64>)> = pairs
                .iter()
                .map(|(f, b)| (apply(&[g], f), b.clone()))
                .collect();
            let (each, mut r) = retarget(phi, &moved, &scaled);
            r.cost_before = first.cost_before;
            r.iterations += first.iterations;
            (each.iter().map(|t| t.after(&g)).collect(), r)
        }
    };
    out.1.carried = carry.to_string();
    out
}

/// One rung of the ladder fitted on every calibration pose, and its score on the poses left
/// out.
#[derive(Debug, Clone)]
pub struct Rung {
    pub transforms: Vec<FeatureTransform>,
    pub score: CandidateScore,
}

/// Retarget from calibration pairs (the last one the rest pose, which always stays in): with
/// [`RetargetSettings::blend`] and at least three poses, every rung of [`LADDER`], each scored
/// on the poses left out (to be weighed by [`blend_weights`]); otherwise the paper's
/// per-feature transforms alone (scored where three poses allow). The report's `carried` is
/// the rung of the lowest score.
pub fn retarget_rungs(
    phi: &Regressor,
    pairs: &[(Vec<f64>, Vec<f64>)],
    s: &RetargetSettings,
) -> (Vec<Rung>, RetargetReport) {
    let unscored = |carry: Carry| {
        let (transforms, report) = fit(phi, pairs, s, carry);
        let score = CandidateScore {
            carry: carry.to_string(),
            mm: f64::NAN,
            standard_error_mm: f64::NAN,
            held_out: Vec::new(),
        };
        (vec![Rung { transforms, score }], report)
    };
    if s.iterations == 0 {
        return unscored(Carry::None);
    }
    let held = pairs.len().saturating_sub(1);
    if held < 3 {
        return unscored(Carry::Paper);
    }
    let ladder: &[Carry] = if s.blend { &LADDER } else { &[Carry::Paper] };
    // Each pose is left out once; beyond MAX_FOLDS poses, in MAX_FOLDS interleaved groups.
    let folds = held.min(MAX_FOLDS);
    let scores: Vec<CandidateScore> = ladder
        .iter()
        .map(|&carry| {
            let fitted: Vec<Vec<FeatureTransform>> = (0..folds)
                .into_par_iter()
                .map(|k| {
                    let rest: Vec<(Vec<f64>, Vec<f64>)> = pairs
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| *i >= held || i % folds != k)
                        .map(|(_, p)| p.clone())
                        .collect();
                    fit(phi, &rest, s, carry).0
                })
                .collect();
            let held_out: Vec<Vec<f64>> = (0..held)
                .map(|i| phi.predict(&apply(&fitted[i % folds], &pairs[i].0)))
                .collect();
            let e: Vec<f64> = (0..held)
                .map(|i| super::regress::point_errors(&held_out[i], &pairs[i].1))
                .collect();
            let mm = e.iter().sum::<f64>() / held as f64;
            let var = e.iter().map(|v| (v - mm).powi(2)).sum::<f64>() / (held - 1) as f64;
            CandidateScore {
                carry: carry.to_string(),
                mm,
                standard_error_mm: (var / held as f64).sqrt(),
                held_out,
            }
        })
        .collect();
    let fitted: Vec<(Vec<FeatureTransform>, RetargetReport)> = ladder
        .par_iter()
        .map(|&carry| fit(phi, pairs, s, carry))
        .collect();
    let best = (0..scores.len())
        .min_by(|&a, &b| scores[a].mm.total_cmp(&scores[b].mm))
        .expect("candidates");
    let mut report = fitted[best].1.clone();
    report.candidates = scores.clone();
    let rungs = fitted
        .into_iter()
        .zip(scores)
        .map(|((transforms, _), score)| Rung { transforms, score })
        .collect();
    (rungs, report)
}

/// The weights of several carried mappings from their scores on the calibration poses left
/// out (mm): each score to the power −[`BLEND_EXPONENT`], normalised, so that a mapping twice
/// as far off counts an eighth as much. A mapping that could not be scored gets none, unless
/// none could be (then all count alike). Weights under [`MIN_WEIGHT`] are dropped, the rest
/// normalised again.
pub fn blend_weights(scores_mm: &[f64]) -> Vec<f64> {
    let raw: Vec<f64> = scores_mm
        .iter()
        .map(|&e| {
            if e.is_finite() && e > 0.0 {
                e.powf(-BLEND_EXPONENT)
            } else {
                0.0
            }
        })
        .collect();
    let normalised = |w: Vec<f64>| {
        let sum: f64 = w.iter().sum();
        if sum > 0.0 {
            w.iter().map(|v| v / sum).collect()
        } else {
            vec![1.0 / w.len().max(1) as f64; w.len()]
        }
    };
    let w: Vec<f64> = normalised(raw);
    normalised(
        w.iter()
            .map(|&v| if v < MIN_WEIGHT { 0.0 } else { v })
            .collect(),
    )
}

/// A carried mapping weighed below this is left out of a blend (each term costs a prediction).
pub const MIN_WEIGHT: f64 = 0.01;

/// How sharply a blend favours the better-scored: 1/e³. Scores from five poses left out one at
/// a time are noisy, so the blend hedges; 1/e² (inverse variance) hedged too much and the
/// best score alone too little on the sets docs/skin.md measures.
pub const BLEND_EXPONENT: f64 = 3.0;

/// The model carried to `target` from its calibration poses (and its rest, where the skin is
/// the neutral's and the bone at rest: a sixth calibration pose for free).
pub fn retarget_to(
    m: &SkinModel,
    target: &Subject,
    settings: &RetargetSettings,
) -> Result<(SkinModel, RetargetReport)> {
    let frames: Vec<usize> = target
        .calibration_indices()?
        .into_iter()
        .map(|(_, i)| i)
        .collect();
    retarget_on(m, target, &frames, settings)
}

/// The model carried to `target` from the jaw poses of frame indices `frames` (and its rest):
/// each of its mappings by every rung of the ladder, all blended (see [`blended`]).
pub fn retarget_on(
    m: &SkinModel,
    target: &Subject,
    frames: &[usize],
    settings: &RetargetSettings,
) -> Result<(SkinModel, RetargetReport)> {
    let carried = carry_mappings(m, target, frames, settings)?;
    blended(m, target, carried)
}

/// One of a model's mappings carried to a subject: every rung tried, and the report of the
/// best scored.
#[derive(Debug, Clone)]
pub struct Carried {
    pub rungs: Vec<Rung>,
    pub report: RetargetReport,
}

/// Each of `m`'s mappings (see [`SkinModel::mappings`]) carried to `target` from the jaw poses
/// of frame indices `frames` and its rest; without [`RetargetSettings::blend`], the paper's:
/// its own mapping (the pooled one of a multi-subject model) alone.
pub fn carry_mappings(
    m: &SkinModel,
    target: &Subject,
    frames: &[usize],
    settings: &RetargetSettings,
) -> Result<Vec<Carried>> {
    let (rest, ..) = target.rest()?;
    let mut pairs: Vec<(Vec<f64>, Vec<f64>)> = frames
        .iter()
        .filter_map(|&i| {
            Some((
                target.skin_features(&m.skin_points, i),
                target.bone_features(&rest, i)?,
            ))
        })
        .collect();
    pairs.push((vec![0.0; m.skin_points.len() * 3], vec![0.0; 15]));
    let count = if settings.blend { usize::MAX } else { 1 };
    Ok(m.mappings()
        .into_iter()
        .take(count)
        .map(|(_, r)| {
            let (rungs, report) = retarget_rungs(r, &pairs, settings);
            Carried { rungs, report }
        })
        .collect())
}

/// `m` for `target`, every rung of every mapping in `carried` (one per mapping of `m`, in
/// order) weighed by [`blend_weights`] on its score. The report is the best-scored mapping's,
/// its candidates every term's score and `blend` the weights kept.
pub fn blended(
    m: &SkinModel,
    target: &Subject,
    carried: Vec<Carried>,
) -> Result<(SkinModel, RetargetReport)> {
    let (rest, ..) = target.rest()?;
    let names: Vec<String> = m.mappings().into_iter().map(|(n, _)| n).collect();
    let several = names.len() > 1;
    let term_name = |k: usize, carry: &str| {
        if several {
            format!("{}: {carry}", names[k])
        } else {
            carry.to_string()
        }
    };
    let scores: Vec<f64> = carried
        .iter()
        .flat_map(|c| c.rungs.iter().map(|r| r.score.mm))
        .collect();
    let weights = blend_weights(&scores);
    let best = (0..carried.len())
        .min_by(|&a, &b| {
            let low = |k: usize| {
                carried[k]
                    .rungs
                    .iter()
                    .map(|r| r.score.mm)
                    .fold(f64::INFINITY, f64::min)
            };
            low(a).total_cmp(&low(b))
        })
        .unwrap_or(0);
    let mut report = carried[best].report.clone();
    if several {
        report.carried = term_name(best, &report.carried);
    }
    report.candidates.clear();
    let mut blend = Vec::new();
    let mut w = weights.into_iter();
    for (k, c) in carried.into_iter().enumerate() {
        for rung in c.rungs {
            let weight = w.next().expect("a weight per rung");
            let mut score = rung.score;
            score.carry = term_name(k, &score.carry);
            if weight > 0.0 {
                report.blend.push((score.carry.clone(), weight));
                blend.push(BlendTerm {
                    mapping: k,
                    carry: score.carry.clone(),
                    weight,
                    transforms: rung.transforms,
                });
            }
            report.candidates.push(score);
        }
    }
    let mut out = m.clone();
    out.subject = SubjectFit {
        blend,
        ..SubjectFit::of(target, &rest)
    };
    Ok((out, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skin::retarget::tests::turned_pairs;

    #[test]
    fn every_rung_is_scored_and_the_one_the_poses_call_for_weighs_most() {
        let (phi, pairs) = turned_pairs(6);
        // Five poses: every rung is scored and blended; the global rung, which is what the
        // turn is, predicts the poses left out far better than none, and weighs far more.
        let (rungs, report) = retarget_rungs(&phi, &pairs, &RetargetSettings::default());
        assert_eq!(rungs.len(), LADDER.len());
        assert!(report.carried != "none", "{report:?}");
        let scores: Vec<f64> = rungs.iter().map(|r| r.score.mm).collect();
        assert!(scores[1] < 0.5 * scores[0], "{report:?}");
        let w = blend_weights(&scores);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(w[1] > 8.0 * w[0], "{w:?}");
        // Off: the paper's rung alone, scored.
        let paper = RetargetSettings {
            blend: false,
            ..Default::default()
        };
        let (rungs, report) = retarget_rungs(&phi, &pairs, &paper);
        assert_eq!(rungs.len(), 1);
        assert_eq!(report.carried, "per-feature");
        assert!(rungs[0].score.mm.is_finite());
    }

    #[test]
    fn blend_weights_favour_the_better_scored_and_drop_the_rest() {
        // Twice as far off counts an eighth as much.
        let w = blend_weights(&[1.0, 2.0]);
        assert!(
            (w[0] - 8.0 / 9.0).abs() < 1e-12 && (w[1] - 1.0 / 9.0).abs() < 1e-12,
            "{w:?}"
        );
        // Unscored ones get nothing; a weight under MIN_WEIGHT is dropped, the rest normalised.
        let w = blend_weights(&[0.1, f64::NAN, 5.0]);
        assert_eq!(w, vec![1.0, 0.0, 0.0]);
        // None scored: all alike.
        assert_eq!(blend_weights(&[f64::NAN, f64::NAN]), vec![0.5, 0.5]);
    }
}
