//! Beyond the paper: a capture with both the teeth and the face. The frames the teeth tracker
//! is confident in (`ok` in tracks.json) supply the calibration poses by themselves, chosen to
//! span the motion; the model, retargeted on them, predicts the jaw where the lips hide the
//! teeth (`low-confidence`, `no-data`). Each record says where its jaw came from
//! (`jaw_source`: `teeth` or `skin`).

use std::path::Path;

use nalgebra::Vector3;
use serde::Serialize;

use super::model::{SkinModel, retarget_on};
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
    let (rest, ..) = subject.rest()?;
    // Spread the calibration over the motion: farthest-point sampling of the menton's travel.
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
    let (mut m, mut report) = retarget_on(model, &subject, &chosen, settings)?;
    // A confident frame the tracker got wrong would pull the whole retargeting toward it (and
    // the farthest-point choice favours such outliers): frames whose teeth pose the
    // retargeted mapping cannot explain, far beyond the others' misfit, are left out once.
    let misfit: Vec<f64> = chosen
        .iter()
        .map(|&i| {
            let predicted = m.predict(&subject.skin_features(&m.skin_points, i));
            let teeth = subject.jaw[i].expect("a chosen frame has a jaw");
            bone_point_error(&subject.bone, &predicted, &teeth)
        })
        .collect();
    let typical = crate::stats::Stats::of(&misfit).median;
    let kept: Vec<usize> = chosen
        .iter()
        .zip(&misfit)
        .filter(|&(_, &e)| e <= OUTLIER_MM.max(OUTLIER_FACTOR * typical))
        .map(|(&i, _)| i)
        .collect();
    let mut left_out = Vec::new();
    if kept.len() < chosen.len() && kept.len() >= 2 {
        left_out = chosen
            .iter()
            .filter(|i| !kept.contains(i))
            .map(|&i| subject.frames[i])
            .collect();
        (m, report) = retarget_on(model, &subject, &kept, settings)?;
        chosen = kept;
    }
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
    Ok((
        out,
        FillReport {
            teeth_frames: teeth,
            skin_frames: skin,
            calibration_frames: chosen.iter().map(|&i| subject.frames[i]).collect(),
            left_out,
            retarget: report,
        },
    ))
}
