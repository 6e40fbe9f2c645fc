//! Camera sync from a light switched off and on (the paper's Section 5): every camera sees
//! the room darken in some frame; the frames where it does give each camera's offset.
//!
//! A frame's mean brightness is a mix of the light before and after the switch, in
//! proportion to how much of its exposure each covers: the light, decoded from the values the
//! camera wrote ([`crate::capture::light`]), not the values, which the transfer curve bends. Summing the bright share of the frames
//! around the step gives the switch time within a frame, so cameras are placed to a fraction
//! of a frame apart; the whole-frame part becomes `frames.offsets`. The fraction assumes an
//! exposure as long as the frame period; a shorter shutter shows a steeper step, read as the
//! nearest frame boundary.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::capture::light::linear_table;
use crate::error::{Error, Result};

/// The image files of one camera's folder (images/<camera>/<frame:06>.png|jpg), by number.
pub fn frame_files(dir: &Path) -> Result<Vec<(u32, PathBuf)>> {
    let rd = std::fs::read_dir(dir).map_err(|error| Error::Read {
        path: dir.to_path_buf(),
        error,
    })?;
    let mut out = Vec::new();
    for entry in rd.flatten() {
        let p = entry.path();
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
        if !["png", "jpg", "jpeg"].contains(&ext.to_ascii_lowercase().as_str()) {
            continue;
        }
        if let Some(n) = p
            .file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| s.parse().ok())
        {
            out.push((n, p));
        }
    }
    out.sort();
    if out.is_empty() {
        return Err(Error::invalid(
            dir,
            "frames",
            "holds no numbered .png or .jpg frames",
        ));
    }
    Ok(out)
}

/// Mean brightness (linear light, 255 the brightest) of every frame, in the files' order;
/// `done` is called after each frame.
pub fn brightness(files: &[(u32, PathBuf)], done: &(dyn Fn() + Sync)) -> Result<Vec<f64>> {
    let light = linear_table();
    files
        .par_iter()
        .map(|(_, path)| {
            let img = image::open(path).map_err(|e| Error::Image {
                path: path.clone(),
                problem: e.to_string(),
            })?;
            let rgb = img.into_rgb8();
            let sum: f64 = rgb
                .pixels()
                .map(|p| {
                    let [r, g, b] = p.0.map(|v| light[v as usize] as f64);
                    0.2126 * r + 0.7152 * g + 0.0722 * b
                })
                .sum();
            done();
            Ok(255.0 * sum / (rgb.width() as f64 * rgb.height() as f64).max(1.0))
        })
        .collect()
}

/// A light switched off and on, as one camera saw it: times in that camera's file frames
/// (frame k's exposure spans [k, k + 1)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Event {
    pub off: f64,
    pub on: Option<f64>,
    /// Brightness before the switch and while dark.
    pub bright: f64,
    pub dark: f64,
}

/// Frames on each side of a step used to read its levels.
const LEVEL_FRAMES: usize = 5;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The light-off (and light-on) event in a brightness series whose first value is file frame
/// `first`; `None` when no step stands out from the frame-to-frame noise.
pub fn detect(first: u32, b: &[f64]) -> Option<Event> {
    let n = b.len();
    if n < 4 {
        return None;
    }
    // Two-frame differences: a switch inside a frame splits its step over two frames.
    let step = |i: usize| b[(i + 1).min(n - 1)] - b[i.saturating_sub(1)];
    let off = (1..n - 1).min_by(|&i, &j| step(i).total_cmp(&step(j)))?;
    let mut diffs: Vec<f64> = b.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let noise = 1.4826 * median(&mut diffs);
    let on = (off + 2..n.saturating_sub(1)).max_by(|&i, &j| step(i).total_cmp(&step(j)));

    let before = off.saturating_sub(1 + LEVEL_FRAMES)..off.saturating_sub(1);
    let dark_end = on.map(|j| j.saturating_sub(1)).unwrap_or(n).max(off + 2);
    let dark_range = (off + 2).min(n)..dark_end.min(off + 2 + LEVEL_FRAMES).min(n);
    if before.is_empty() {
        return None;
    }
    let bright = median(&mut b[before].to_vec());
    let dark = if dark_range.is_empty() {
        b[(off + 1).min(n - 1)]
    } else {
        median(&mut b[dark_range].to_vec())
    };
    let drop = bright - dark;
    if !(drop > 8.0 * noise && drop > 0.1 * bright) {
        return None;
    }
    // Sum the bright share over the frames around the step.
    let share = |k: usize| ((b[k] - dark) / drop).clamp(0.0, 1.0);
    let lo = off.saturating_sub(2);
    let hi_off = (off + 2).min(dark_end.saturating_sub(1)).min(n - 1);
    let off_time = lo as f64 + (lo..=hi_off).map(share).sum::<f64>();

    let on_time = on.and_then(|j| {
        let after = (j + 2).min(n)..(j + 2 + LEVEL_FRAMES).min(n);
        if after.is_empty() || step(j) < 0.5 * drop {
            return None;
        }
        let bright_after = median(&mut b[after].to_vec());
        let rise = bright_after - dark;
        if rise <= 8.0 * noise {
            return None;
        }
        let lo = j.saturating_sub(2).max(off + 2);
        let hi = (j + 2).min(n - 1);
        let dark_share = |k: usize| (1.0 - (b[k] - dark) / rise).clamp(0.0, 1.0);
        Some(lo as f64 + (lo..=hi).map(dark_share).sum::<f64>())
    });
    Some(Event {
        off: first as f64 + off_time,
        on: on_time.map(|t| first as f64 + t),
        bright,
        dark,
    })
}

/// One camera's place in the sync.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraSync {
    pub name: String,
    pub event: Event,
    /// How many frames this camera's files run ahead of the capture's frame numbers.
    pub offset: i64,
    /// What is left within a frame (frames, −0.5 to 0.5): this camera's exposure starts this
    /// much of a frame after the reference camera's.
    pub within: f64,
}

/// Offsets from each camera's event: the camera that saw the switch at the lowest file frame
/// (the one started last) has offset 0, the others count forward from it. Errs, naming the
/// camera, when the light-on event gives another whole-frame offset than the light-off one.
pub fn offsets(events: &[(String, Event)]) -> Result<Vec<CameraSync>> {
    let Some(reference) = events
        .iter()
        .min_by(|a, b| a.1.off.total_cmp(&b.1.off))
        .map(|(_, e)| *e)
    else {
        return Ok(Vec::new());
    };
    events
        .iter()
        .map(|(name, e)| {
            let d = e.off - reference.off;
            let offset = d.round() as i64;
            if let (Some(on), Some(ref_on)) = (e.on, reference.on)
                && ((on - ref_on).round() as i64) != offset
            {
                return Err(Error::invalid(
                    Path::new(name),
                    "sync",
                    format!(
                        "camera `{name}`: the light goes off {d:.2} frames after the first camera's \
                         but comes on {:.2} frames after: two different events, or dropped frames",
                        on - ref_on
                    ),
                ));
            }
            Ok(CameraSync {
                name: name.clone(),
                event: *e,
                offset,
                within: d - offset as f64,
            })
        })
        .collect()
}

/// Set `frames.offsets` in a capture.json to these offsets (every other field kept; the
/// file is replaced atomically).
pub fn write_offsets(capture_json: &Path, syncs: &[CameraSync]) -> Result<()> {
    let text = crate::io::read::read_text(capture_json, "capture file")?;
    let mut doc: serde_json::Value = serde_json::from_str(&text).map_err(|error| Error::Json {
        path: capture_json.to_path_buf(),
        field: ".".into(),
        error,
    })?;
    let frames = doc
        .get_mut("frames")
        .and_then(|f| f.as_object_mut())
        .ok_or_else(|| Error::invalid(capture_json, "frames", "missing or not an object"))?;
    let offsets: serde_json::Map<String, serde_json::Value> = syncs
        .iter()
        .map(|c| (c.name.clone(), c.offset.into()))
        .collect();
    frames.insert("offsets".into(), offsets.into());
    crate::io::write_json_atomic(capture_json, &doc)
}

/// The cameras to sync: capture.json's when there is one, else every folder in images/.
pub fn camera_names(capture: &Path) -> Result<Vec<String>> {
    let cj = capture.join("capture.json");
    if cj.is_file() {
        let c: crate::capture::json::CaptureJson = crate::io::read_json(&cj, "capture file")?;
        return Ok(c.cameras);
    }
    let images = capture.join("images");
    let rd = std::fs::read_dir(&images).map_err(|error| Error::Read {
        path: images.clone(),
        error,
    })?;
    let mut names: Vec<String> = rd
        .flatten()
        .filter(|e| e.path().is_dir())
        .filter_map(|e| e.file_name().to_str().map(str::to_string))
        .filter(|n| !n.starts_with('.'))
        .collect();
    names.sort();
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera whose light goes off at `off` and on at `on` (frame units), exposure = frame.
    fn series(n: usize, off: f64, on: f64) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let (a, b) = (k as f64, k as f64 + 1.0);
                let dark = (b.min(on) - a.max(off)).clamp(0.0, 1.0);
                200.0 - 180.0 * dark + 0.3 * ((k * 7919) % 13) as f64 / 13.0
            })
            .collect()
    }

    #[test]
    fn sub_frame_switch_times_and_offsets() {
        let cams = [("a", 30.25, 52.25), ("b", 33.6, 55.6), ("c", 27.9, 49.9)];
        let events: Vec<(String, Event)> = cams
            .iter()
            .map(|&(n, off, on)| (n.to_string(), detect(100, &series(90, off, on)).unwrap()))
            .collect();
        for ((_, e), &(_, off, on)) in events.iter().zip(&cams) {
            assert!((e.off - 100.0 - off).abs() < 0.02, "{e:?}");
            assert!((e.on.unwrap() - 100.0 - on).abs() < 0.02, "{e:?}");
        }
        let s = offsets(&events).unwrap();
        let got: Vec<i64> = s.iter().map(|c| c.offset).collect();
        assert_eq!(got, vec![2, 6, 0]);
        assert!((s[0].within - 0.35).abs() < 0.03, "{:?}", s[0]);
        assert!((s[1].within - (-0.3)).abs() < 0.03, "{:?}", s[1]);
    }

    #[test]
    fn no_event_in_a_steady_room() {
        let b: Vec<f64> = (0..60).map(|k| 120.0 + (k % 3) as f64).collect();
        assert_eq!(detect(0, &b), None);
    }

    #[test]
    fn two_different_events_are_an_error() {
        let a = detect(0, &series(90, 30.0, 50.0)).unwrap();
        let b = detect(0, &series(90, 32.0, 60.0)).unwrap();
        let e = offsets(&[("a".into(), a), ("b".into(), b)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("camera `b`") && e.contains("different events"),
            "{e}"
        );
    }
}
