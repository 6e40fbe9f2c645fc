//! Beyond the paper: a capture with both the teeth and the face. The frames the teeth tracker
//! is confident in (`ok` in tracks.json) supply the calibration poses by themselves, chosen to
//! span the motion; the model, retargeted on them, predicts the jaw where the lips hide the
//! teeth (`low-confidence`, `no-data`). Each record says where its jaw came from
//! (`jaw_source`: `teeth` or `skin`).

use std::path::Path;

use nalgebra::Vector3;
use serde::Serialize;

use super::carry::retarget_on;
use super::model::SkinModel;
use super::retarget::{RetargetReport, RetargetSettings};
use super::subject::{Subject, bone_point_error};
use crate::error::{Error, Result};
use crate::formats::{JawSource, PoseJson, Status, TracksJson};

/// Calibration frames chosen from the confident ones, at most.
pub const MAX_CALIBRATION: usize = 24;

/// A calibration frame whose bone points the retargeted mapping misses by more than this
/// (mm) and by more than [`OUTLIER_FACTOR`] times the median miss is left out. Honest poses
/// are missed by a few millimetres at most, even at the extremes of the motion and across
/// subjects; a frame the tracker got wrong by a centimetre or more is not.
pub const OUTLIER_MM: f64 = 10.0;
pub const OUTLIER_FACTOR: f64 = 4.0;

#[derive(Debug, Clone, Serialize)]
pub struct FillReport {
    pub teeth_frames: usize,
    pub skin_frames: usize,
    pub calibration_frames: Vec<u32>,
    /// Confident frames left out of the calibration: the retargeted mapping could not explain
    /// their teeth pose (a tracking error the tracker did not flag).
    pub left_out: Vec<u32>,
    pub retarget: RetargetReport,
}

/// tracks.json with the jaw of its unconfident frames predicted from the skin of `face` (whose
/// frame numbers are the capture's). `face`'s own jaw poses, if any, are not used.
pub fn fill(
    model: &SkinModel,
    face: &Subject,
    tracks: &TracksJson,
    tracks_path: &Path,
    settings: &RetargetSettings,
) -> Result<(TracksJson, FillReport)> {
    let (m, subject, mut report) = carried(model, face, tracks, tracks_path, settings)?;
    let (out, skin) = fill_from_skin(&m, &subject, tracks, tracks_path)?;
    report.skin_frames = skin;
    Ok((out, report))
}

/// The model carried to `face` from the confident frames of `tracks` (`skin retarget
/// --tracks`): up to [`MAX_CALIBRATION`] of them, spread over the motion, outliers left out.
/// The report's `skin_frames` is 0: nothing is filled.
pub fn retarget_from_tracks(
    model: &SkinModel,
    face: &Subject,
    tracks: &TracksJson,
    tracks_path: &Path,
    settings: &RetargetSettings,
) -> Result<(SkinModel, FillReport)> {
    let (m, _, report) = carried(model, face, tracks, tracks_path, settings)?;
    Ok((m, report))
}

fn carried(
    model: &SkinModel,
    face: &Subject,
    tracks: &TracksJson,
    tracks_path: &Path,
    settings: &RetargetSettings,
) -> Result<(SkinModel, Subject, FillReport)> {
    let (subject, teeth) = teeth_subject(face, tracks, tracks_path)?;
    let chosen = spread_calibration(&subject)?;
    let Calibration {
        model: m,
        report,
        chosen,
        left_out,
    } = calibrate(model, &subject, chosen, settings)?;
    let report = FillReport {
        teeth_frames: teeth,
        skin_frames: 0,
        calibration_frames: chosen.iter().map(|&i| subject.frames[i]).collect(),
        left_out,
        retarget: report,
    };
    Ok((m, subject, report))
}

/// The mapping retargeted on the calibration frames it could explain.
struct Calibration {
    model: SkinModel,
    report: RetargetReport,
    /// The calibration frames, as indices of the subject's frames.
    chosen: Vec<usize>,
    /// The frame numbers of the calibration frames left out as outliers.
    left_out: Vec<u32>,
}

/// `face` with the jaw poses of the confident frames of `tracks` (and no others), and how many
/// frames got one.
fn teeth_subject(
    face: &Subject,
    tracks: &TracksJson,
    tracks_path: &Path,
) -> Result<(Subject, usize)> {
    let mut subject = face.clone();
    subject.jaw = vec![None; subject.frames.len()];
    let mut teeth = 0;
    for r in &tracks.frames {
        if r.status() != Status::Ok {
            continue;
        }
        let Some(i) = subject.index_of(r.frame) else {
            continue;
        };
        subject.jaw[i] = Some(r.checked_jaw(tracks_path)?);
        teeth += 1;
    }
    if teeth == 0 {
        return Err(Error::invalid(
            tracks_path,
            "frames",
            "no `ok` frame of the tracks is a frame of the face sequence (their frame numbers must be the capture's)",
        ));
    }
    Ok((subject, teeth))
}

/// Calibration frames spread over the motion: farthest-point sampling of the menton's travel
/// among the frames with a jaw pose.
fn spread_calibration(subject: &Subject) -> Result<Vec<usize>> {
    let (rest, ..) = subject.rest()?;
    let known: Vec<usize> = (0..subject.frames.len())
        .filter(|&i| subject.jaw[i].is_some())
        .collect();
    let menton = |i: usize| -> Vector3<f64> {
        let b = subject.bone_features(&rest, i).expect("a known frame");
        Vector3::new(b[0], b[1], b[2])
    };
    let mut chosen = vec![known[0]];
    let mut dist: Vec<f64> = known
        .iter()
        .map(|&i| (menton(i) - menton(known[0])).norm())
        .collect();
    while chosen.len() < MAX_CALIBRATION.min(known.len()) {
        let (j, d) = dist
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(j, d)| (j, *d))
            .expect("non-empty");
        if d < 0.5 {
            break;
        }
        chosen.push(known[j]);
        for (k, &i) in known.iter().enumerate() {
            dist[k] = dist[k].min((menton(i) - menton(known[j])).norm());
        }
    }
    Ok(chosen)
}

/// Retarget `model` on the `chosen` frames, then once more without those it cannot explain.
///
/// A confident frame the tracker got wrong would pull the whole retargeting toward it (and
/// the farthest-point choice favours such outliers): frames whose teeth pose the retargeted
/// mapping cannot explain, far beyond the others' misfit, are left out once.
fn calibrate(
    model: &SkinModel,
    subject: &Subject,
    mut chosen: Vec<usize>,
    settings: &RetargetSettings,
) -> Result<Calibration> {
    let (mut m, mut report) = retarget_on(model, subject, &chosen, settings)?;
    let kept = explained_frames(&m, subject, &chosen);
    let mut left_out = Vec::new();
    if kept.len() < chosen.len() && kept.len() >= 2 {
        left_out = chosen
            .iter()
            .filter(|i| !kept.contains(i))
            .map(|&i| subject.frames[i])
            .collect();
        (m, report) = retarget_on(model, subject, &kept, settings)?;
        chosen = kept;
    }
    Ok(Calibration {
        model: m,
        report,
        chosen,
        left_out,
    })
}

/// The `chosen` frames whose teeth pose `m` misses by no more than [`OUTLIER_MM`] or
/// [`OUTLIER_FACTOR`] times the median miss, whichever is larger.
fn explained_frames(m: &SkinModel, subject: &Subject, chosen: &[usize]) -> Vec<usize> {
    let misfit: Vec<f64> = chosen
        .iter()
        .map(|&i| {
            let predicted = m.predict(&subject.skin_features(&m.skin_points, i));
            let teeth = subject.jaw[i].expect("a chosen frame has a jaw");
            bone_point_error(&subject.bone, &predicted, &teeth)
        })
        .collect();
    let typical = crate::stats::Stats::of(&misfit).median;
    chosen
        .iter()
        .zip(&misfit)
        .filter(|&(_, &e)| e <= OUTLIER_MM.max(OUTLIER_FACTOR * typical))
        .map(|(&i, _)| i)
        .collect()
}

/// `tracks` with the jaw of every unconfident frame predicted by `m` from the skin, each frame
/// marked with its jaw's source; and how many frames got a jaw from the skin.
fn fill_from_skin(
    m: &SkinModel,
    subject: &Subject,
    tracks: &TracksJson,
    tracks_path: &Path,
) -> Result<(TracksJson, usize)> {
    let mut out = tracks.clone();
    let mut skin = 0;
    for r in &mut out.frames {
        if r.status() == Status::Ok {
            r.jaw_source = Some(JawSource::Teeth);
            continue;
        }
        let Some(i) = subject.index_of(r.frame) else {
            continue;
        };
        let jaw = m.predict(&subject.skin_features(&m.skin_points, i));
        let upper = r
            .upper
            .to_pose(tracks_path, &format!("frames[{}].upper", r.frame))?;
        r.lower = PoseJson::from(&upper.compose(&jaw));
        r.jaw = Some(PoseJson::from(&jaw));
        r.jaw_source = Some(JawSource::Skin);
        skin += 1;
    }
    Ok((out, skin))
}
