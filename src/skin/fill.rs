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
use super::subject::Subject;
use crate::capture::json::{PoseJson, Status, TracksJson};
use crate::error::{Error, Result};

/// Calibration frames chosen from the confident ones, at most.
pub const MAX_CALIBRATION: usize = 24;

#[derive(Debug, Clone, Serialize)]
pub struct FillReport {
    pub teeth_frames: usize,
    pub skin_frames: usize,
    pub calibration_frames: Vec<u32>,
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
        subject.jaw[i] = Some(r.poses(tracks_path)?.jaw());
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
    let (m, report) = retarget_on(model, &subject, &chosen, settings)?;
    let mut out = tracks.clone();
    let mut skin = 0;
    for r in &mut out.frames {
        if r.status() == Status::Ok {
            r.jaw_source = Some("teeth".into());
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
        r.jaw_source = Some("skin".into());
        skin += 1;
    }
    Ok((
        out,
        FillReport {
            teeth_frames: teeth,
            skin_frames: skin,
            calibration_frames: chosen.iter().map(|&i| subject.frames[i]).collect(),
            retarget: report,
        },
    ))
}
