//! Scoring the jaw from the skin on subjects with ground truth, as the paper's Section 7 does:
//! one subject trained on its first frames and tested on its later ones (Fig. 7), and
//! leave-one-subject-out retargeting from the calibration poses, from every single subject
//! and from the multi-subject mapping, against the Procrustes baseline (Table 1, Fig. 8).

use std::time::Instant;

use serde::Serialize;

use super::baseline::baseline_jaw;
use super::carry::{Carried, blended, carry_mappings, retarget_on};
use super::features::SkinPoint;
use super::model::{SkinModel, SkinSettings, learn_multi, learn_single, skin_points, spaced};
use super::retarget::{CandidateScore, RetargetSettings};
use super::subject::{Subject, bone_point_error};
use crate::error::{Error, Result};
use crate::geometry::Pose;

/// The share of a subject's frames (the first ones) its single-subject mapping learns from.
pub const SINGLE_TRAIN_SHARE: f64 = 0.6;

#[derive(Debug, Clone, Serialize)]
pub struct Evaluation {
    pub subjects: Vec<SubjectScore>,
    /// Mean time to predict one frame's jaw (features, Φ, rigid fit), ms.
    pub predict_ms: f64,
    /// Mean time to learn one single-subject mapping, s, and the frames it learned from.
    pub learn_s: f64,
    pub learn_frames: usize,
    pub seconds: f64,
}

/// Errors in mm: mean over the mandible's vertices (and over the five bone points), averaged
/// over frames.
#[derive(Debug, Clone, Serialize)]
pub struct SubjectScore {
    pub name: String,
    pub frames: usize,
    /// Trained on the subject's own first frames, tested on the rest (`single_frames`).
    pub single_mm: f64,
    pub single_bone_mm: f64,
    pub single_frames: usize,
    /// The baseline on the same test frames.
    pub single_baseline_mm: f64,
    /// The best single other subject's mapping, retargeted; every frame.
    pub retargeted_mm: f64,
    pub retargeted_bone_mm: f64,
    pub retargeted_from: String,
    /// The rung of the ladder that scored best for that source, and every rung's score on the
    /// calibration poses left out (its mapping is the blend of them all).
    pub retargeted_carried: String,
    pub retargeted_candidates: Vec<CandidateScore>,
    pub retargeted_each_mm: Vec<(String, f64)>,
    /// The best single other subject's mapping without retargeting.
    pub uncalibrated_mm: f64,
    /// The multi-subject mapping: the paper's pooled mapping of all the others and each
    /// other's own, every one carried by every rung, blended by how well each predicts the
    /// subject's calibration poses when they are left out; every frame.
    pub multi_subject_mm: f64,
    pub multi_subject_bone_mm: f64,
    /// The weight of each mapping ("pooled" and the sources' names), its rungs' summed.
    pub multi_subject_weights: Vec<(String, f64)>,
    /// The paper's pooled mapping alone, its rungs blended, and its best-scored rung.
    pub pooled_mm: f64,
    pub pooled_carried: String,
    /// The multi-subject mapping's error with more calibration poses than the five: the
    /// five, then others spread over the sequence (as the teeth tracker's frames give them);
    /// (poses, mm) on every frame.
    pub calibration_curve: Vec<(usize, f64)>,
    /// The method with the lowest error of those that see only the calibration poses of this
    /// subject: "retargeted", "multi-subject", "uncalibrated" or "baseline".
    pub won: String,
    pub baseline_mm: f64,
    pub baseline_bone_mm: f64,
    /// Per frame (every frame), for the plot: multi-subject, baseline; and the single-subject
    /// error on its test frames (NaN before them).
    pub series: Series,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct Series {
    pub frames: Vec<u32>,
    pub single: Vec<f64>,
    pub multi_subject: Vec<f64>,
    pub baseline: Vec<f64>,
}

struct Scored {
    mm: Vec<f64>,
    bone: Vec<f64>,
}

fn score(s: &Subject, rows: &[usize], predict: &dyn Fn(usize) -> Pose) -> Scored {
    let mut out = Scored {
        mm: Vec::new(),
        bone: Vec::new(),
    };
    for &i in rows {
        let Some(truth) = s.jaw[i] else { continue };
        let p = predict(i);
        out.mm.push(s.metric.mean_distance(&p, &truth));
        out.bone.push(bone_point_error(&s.bone, &p, &truth));
    }
    out
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Evaluate a set (at least two subjects, all with jaw poses and calibration frames), read from
/// the folder `set` (which errors name).
///
/// With `curve`, the multi-subject mapping is also carried with each of
/// [`CALIBRATION_COUNTS`] calibration poses (several times the work).
pub fn evaluate(
    set: &std::path::Path,
    subjects: &[Subject],
    settings: &SkinSettings,
    curve: bool,
    progress: &dyn Fn(&str),
) -> Result<Evaluation> {
    let started = Instant::now();
    if subjects.len() < 2 {
        return Err(Error::invalid(
            set,
            "subjects",
            format!(
                "{} subject(s) (sub-folders with a face.json); leave-one-subject-out needs at least two",
                subjects.len()
            ),
        ));
    }
    // Skin points are chosen on each fold's primary (its first training subject), so that the
    // subject left out has no say; two sets cover every fold.
    let point_sets: Vec<Vec<SkinPoint>> = vec![
        skin_points(&subjects[0], settings)?,
        skin_points(&subjects[1], settings)?,
    ];
    let set_for = |held: usize| if held == 0 { 1 } else { 0 };
    // Every subject's own mapping on all its frames, per point set, for single-source
    // retargeting.
    let mut sources: Vec<Vec<Option<SkinModel>>> = vec![vec![None; subjects.len()]; 2];
    let mut timings = Timings::default();
    let mut scores = Vec::new();
    for (t, target) in subjects.iter().enumerate() {
        progress(&format!(
            "subject {} ({} of {})",
            target.name,
            t + 1,
            subjects.len()
        ));
        let ps = set_for(t);
        let fold = Fold {
            subjects,
            t,
            target,
            points: &point_sets[ps],
            settings,
            curve,
        };
        scores.push(score_subject(&fold, &mut sources[ps], &mut timings)?);
    }
    Ok(Evaluation {
        subjects: scores,
        predict_ms: timings.predict * 1e3 / timings.predicted.max(1) as f64,
        learn_s: mean(&timings.learn),
        learn_frames: timings.learn_frames,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// One leave-one-subject-out fold: the subject held out and what its mappings share.
struct Fold<'a> {
    subjects: &'a [Subject],
    /// The index of `target` in `subjects`.
    t: usize,
    target: &'a Subject,
    points: &'a [SkinPoint],
    settings: &'a SkinSettings,
    /// Measure the calibration curve.
    curve: bool,
}

/// Timings summed over every subject, for the evaluation's averages.
#[derive(Default)]
struct Timings {
    /// Seconds to learn each single-subject mapping.
    learn: Vec<f64>,
    /// The most frames a single-subject mapping learned from.
    learn_frames: usize,
    /// Seconds spent predicting the single-subject test frames, and how many there were.
    predict: f64,
    predicted: usize,
}

/// The best single other subject's mapping, retargeted, and every source's error.
struct SourceScores {
    each: Vec<(String, f64)>,
    mm: f64,
    bone_mm: f64,
    from: String,
    carried: String,
    candidates: Vec<CandidateScore>,
    /// The best source's error without retargeting.
    uncalibrated: f64,
}

/// Score one held-out subject against every mapping and the baseline; `sources` caches each
/// subject's own mapping on the fold's point set.
fn score_subject(
    fold: &Fold,
    sources: &mut [Option<SkinModel>],
    timings: &mut Timings,
) -> Result<SubjectScore> {
    let target = fold.target;
    let points = fold.points;
    let (rest, ..) = target.rest()?;
    let n = target.frames.len();
    let all: Vec<usize> = (0..n).collect();
    // Single subject: first frames learn, the rest test.
    let cut = ((n as f64 * SINGLE_TRAIN_SHARE) as usize).clamp(1, n - 1);
    let (single, features) = score_single(fold, &all, cut, timings)?;
    let base = |i: usize| {
        baseline_jaw(
            points,
            &target.neutral.triangles,
            &target.neutral.positions,
            &target.skin[i],
            &rest,
        )
    };
    let single_base = score(target, &all[cut..], &base);
    let members = retarget_sources(fold, sources, &target.calibration_indices()?)?;
    let retargeted = score_sources(target, &members, &all, &features);
    let pooled_mapping = pooled_mapping(fold, sources)?;
    let calibration: Vec<usize> = target
        .calibration_indices()?
        .into_iter()
        .map(|c| c.1)
        .collect();
    let pooled = member(
        "pooled",
        &pooled_mapping,
        target,
        &calibration,
        fold.settings,
    )?;
    let pooled_sc = score(target, &all, &|i| pooled.model.predict(&features[i]));
    let multi = multi_subject(fold, sources, &pooled_mapping, &pooled, &members)?;
    let multi_sc = score(target, &all, &|i| multi.predict(&features[i]));
    let mut curve = vec![(calibration.len(), mean(&multi_sc.mm))];
    if fold.curve {
        curve.extend(calibration_curve(
            fold,
            sources,
            &pooled_mapping,
            &all,
            &features,
        )?);
    }
    let base_sc = score(target, &all, &base);
    let mut series = Series {
        frames: target.frames.clone(),
        single: vec![f64::NAN; cut],
        multi_subject: multi_sc.mm.clone(),
        baseline: base_sc.mm.clone(),
    };
    series.single.extend(single.mm.iter().copied());
    let across = [
        ("retargeted", retargeted.mm),
        ("multi-subject", mean(&multi_sc.mm)),
        ("uncalibrated", retargeted.uncalibrated),
        ("baseline", mean(&base_sc.mm)),
    ];
    let won = across
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|w| w.0.to_string())
        .unwrap_or_default();
    Ok(SubjectScore {
        name: target.name.clone(),
        frames: n,
        single_mm: mean(&single.mm),
        single_bone_mm: mean(&single.bone),
        single_frames: single.mm.len(),
        single_baseline_mm: mean(&single_base.mm),
        retargeted_mm: retargeted.mm,
        retargeted_bone_mm: retargeted.bone_mm,
        retargeted_from: retargeted.from,
        retargeted_carried: retargeted.carried,
        retargeted_candidates: retargeted.candidates,
        retargeted_each_mm: retargeted.each,
        uncalibrated_mm: retargeted.uncalibrated,
        multi_subject_mm: mean(&multi_sc.mm),
        multi_subject_bone_mm: mean(&multi_sc.bone),
        multi_subject_weights: weights_by_mapping(&multi),
        pooled_mm: mean(&pooled_sc.mm),
        pooled_carried: pooled.carried,
        calibration_curve: curve,
        won,
        baseline_mm: mean(&base_sc.mm),
        baseline_bone_mm: mean(&base_sc.bone),
        series,
    })
}

/// Learn the target's own mapping on its frames before `cut` and score it on the rest; also
/// returns the target's skin features on every frame.
fn score_single(
    fold: &Fold,
    all: &[usize],
    cut: usize,
    timings: &mut Timings,
) -> Result<(Scored, Vec<Vec<f64>>)> {
    let target = fold.target;
    let points = fold.points;
    let clock = Instant::now();
    let own = learn_single(target, Some(points.to_vec()), &all[..cut], fold.settings)?;
    timings.learn.push(clock.elapsed().as_secs_f64());
    timings.learn_frames = timings.learn_frames.max(cut);
    let features: Vec<Vec<f64>> = all
        .iter()
        .map(|&i| target.skin_features(points, i))
        .collect();
    let predict = |i: usize| own.predict(&target.skin_features(points, i));
    let clock = Instant::now();
    let single = score(target, &all[cut..], &predict);
    timings.predict += clock.elapsed().as_secs_f64();
    timings.predicted += all.len() - cut;
    Ok((single, features))
}

/// A mapping carried to the target: retargeted (its rungs blended), uncalibrated, the best
/// rung and every rung's score on the calibration poses left out, and the rungs themselves
/// (for the multi-subject blend).
#[derive(Clone)]
struct Member {
    name: String,
    model: SkinModel,
    plain: SkinModel,
    carried: String,
    candidates: Vec<CandidateScore>,
    rungs: Carried,
}

fn member(
    name: &str,
    m: &SkinModel,
    target: &Subject,
    frames: &[usize],
    s: &SkinSettings,
) -> Result<Member> {
    let (plain, _) = retarget_on(
        m,
        target,
        frames,
        &RetargetSettings {
            iterations: 0,
            ..s.retarget
        },
    )?;
    let carried = carry_mappings(m, target, frames, &s.retarget)?;
    let rungs = carried[0].clone();
    let (model, report) = blended(m, target, carried)?;
    Ok(Member {
        name: name.into(),
        model,
        plain,
        carried: report.carried,
        candidates: report.candidates,
        rungs,
    })
}

/// Every other subject's own mapping (learned once into `sources`) carried to the target from
/// the calibration frames `calibration`.
fn retarget_sources(
    fold: &Fold,
    sources: &mut [Option<SkinModel>],
    calibration: &[(&str, usize)],
) -> Result<Vec<Member>> {
    let frames: Vec<usize> = calibration.iter().map(|c| c.1).collect();
    let mut out = Vec::new();
    for (k, src) in fold.subjects.iter().enumerate() {
        if k == fold.t {
            continue;
        }
        if sources[k].is_none() {
            let rows: Vec<usize> = (0..src.frames.len()).collect();
            sources[k] = Some(learn_single(
                src,
                Some(fold.points.to_vec()),
                &rows,
                fold.settings,
            )?);
        }
        let m = sources[k].as_ref().expect("learned above");
        out.push(member(&src.name, m, fold.target, &frames, fold.settings)?);
    }
    Ok(out)
}

/// The best single source (on the target's every frame: an oracle, as the paper's Table 1
/// compares), with and without retargeting, and every source's error.
fn score_sources(
    target: &Subject,
    members: &[Member],
    all: &[usize],
    features: &[Vec<f64>],
) -> SourceScores {
    let mut each = Vec::new();
    let mut best: Option<(f64, f64, &Member)> = None;
    let mut uncalibrated = f64::INFINITY;
    for m in members {
        let raw = score(target, all, &|i| m.plain.predict(&features[i]));
        uncalibrated = uncalibrated.min(mean(&raw.mm));
        let sc = score(target, all, &|i| m.model.predict(&features[i]));
        let e = mean(&sc.mm);
        each.push((m.name.clone(), e));
        if best.as_ref().is_none_or(|b| e < b.0) {
            best = Some((e, mean(&sc.bone), m));
        }
    }
    let (mm, bone_mm, m) = best.expect("two subjects or more");
    SourceScores {
        each,
        mm,
        bone_mm,
        from: m.name.clone(),
        carried: m.carried.clone(),
        candidates: m.candidates.clone(),
        uncalibrated,
    }
}

/// The paper's multi-subject mapping (Section 6.2) of every subject but the target.
fn pooled_mapping(fold: &Fold, sources: &[Option<SkinModel>]) -> Result<SkinModel> {
    let t = fold.t;
    let others: Vec<&Subject> = fold
        .subjects
        .iter()
        .enumerate()
        .filter(|(k, _)| *k != t)
        .map(|(_, s)| s)
        .collect();
    let primary = if t == 0 { 1 } else { 0 };
    let (multi, _) = learn_multi(
        &others,
        Some(fold.points.to_vec()),
        sources[primary].as_ref(),
        fold.settings,
    )?;
    Ok(multi)
}

/// The multi-subject mapping: the pooled mapping with every source's own beside it, each
/// carried by every rung, all blended by their scores on the calibration poses left out.
fn multi_subject(
    fold: &Fold,
    sources: &[Option<SkinModel>],
    pooled_mapping: &SkinModel,
    pooled: &Member,
    members: &[Member],
) -> Result<SkinModel> {
    let own: Vec<(String, &SkinModel)> = members
        .iter()
        .map(|m| {
            let k = fold
                .subjects
                .iter()
                .position(|s| s.name == m.name)
                .expect("a member is a subject");
            (m.name.clone(), sources[k].as_ref().expect("learned"))
        })
        .collect();
    let model = pooled_mapping.clone().with_sources(own);
    let carried = std::iter::once(pooled.rungs.clone())
        .chain(members.iter().map(|m| m.rungs.clone()))
        .collect();
    Ok(blended(&model, fold.target, carried)?.0)
}

/// The weight of each mapping of a blended model, its rungs' summed.
fn weights_by_mapping(m: &SkinModel) -> Vec<(String, f64)> {
    let mut out: Vec<(String, f64)> = m.mappings().into_iter().map(|(n, _)| (n, 0.0)).collect();
    for t in &m.subject.blend {
        out[t.mapping].1 += t.weight;
    }
    out
}

/// The numbers of calibration poses the curve is measured at, beyond the five.
pub const CALIBRATION_COUNTS: [usize; 2] = [10, 24];

/// The multi-subject mapping's error with each of [`CALIBRATION_COUNTS`] calibration poses:
/// the five named ones, then frames spread over the sequence.
fn calibration_curve(
    fold: &Fold,
    sources: &mut [Option<SkinModel>],
    pooled_mapping: &SkinModel,
    all: &[usize],
    features: &[Vec<f64>],
) -> Result<Vec<(usize, f64)>> {
    let named = fold.target.calibration_indices()?;
    let mut out = Vec::new();
    for &count in &CALIBRATION_COUNTS {
        let mut frames = named.clone();
        for i in spaced(all.len(), count.saturating_sub(named.len())) {
            if frames.len() >= count {
                break;
            }
            if fold.target.jaw[i].is_some() && frames.iter().all(|f| f.1 != i) {
                frames.push(("spread", i));
            }
        }
        let members = retarget_sources(fold, sources, &frames)?;
        let cal: Vec<usize> = frames.iter().map(|f| f.1).collect();
        let pooled = member("pooled", pooled_mapping, fold.target, &cal, fold.settings)?;
        let multi = multi_subject(fold, sources, pooled_mapping, &pooled, &members)?;
        let sc = score(fold.target, all, &|i| multi.predict(&features[i]));
        out.push((frames.len(), mean(&sc.mm)));
    }
    Ok(out)
}
