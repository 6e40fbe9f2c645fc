//! The cameras' pictures the page shows: a tracked frame's overlays (cropped to the teeth), the
//! first frame's pictures for picking the first pose, and that pose fitted from the clicks.

use crate::capture::masks::LabelMask;
use crate::track::overlay::{self, ArchColours};

use super::first_pose::{FirstPoseQuery, FirstPoseReply, first_pose};
use super::scene::{CaptureInfo, Refused, Viewer};

impl Viewer {
    /// The capture's cameras, first frame and the part of each first picture shown.
    pub(super) fn capture_info(&self) -> Option<CaptureInfo> {
        self.capture.as_ref().map(|c| {
            let first = c.frames().start;
            let masks = c.load_masks(first).ok();
            CaptureInfo {
                cameras: c.camera_names().into_iter().map(String::from).collect(),
                first_frame: first,
                has_init: c.init().is_some(),
                crops: (0..c.cameras().len())
                    .map(|k| {
                        let mask = masks.as_ref().and_then(|m| m.masks[k].as_ref());
                        mask.and_then(labelled_crop)
                    })
                    .collect(),
            }
        })
    }

    /// Camera `camera`'s picture of tracked frame `frame` with the models at its poses (a
    /// draft's where the frame is being moved), the arches in distinct colours, as PNG: the
    /// region around the teeth as the frame's own poses place them.
    pub fn overlay(&self, camera: &str, frame: u32) -> std::result::Result<Vec<u8>, Refused> {
        let t = self.workbench()?;
        let k = t
            .capture
            .camera_names()
            .iter()
            .position(|c| *c == camera)
            .ok_or_else(|| Refused(format!("no camera {camera:?}")))?;
        let (poses, kept) = t
            .overlay_poses(k, frame)
            .ok_or_else(|| Refused(format!("frame {frame} was not tracked")))?;
        let masks = t.capture.load_masks(frame).ok();
        let mask = masks.as_ref().and_then(|m| m.masks[k].as_ref());
        let (rgb, models) = overlay::picture(
            &t.capture,
            k,
            frame,
            mask,
            Some(&poses),
            ArchColours::Distinct,
        )
        .map_err(|e| Refused(e.to_string()))?
        .ok_or_else(|| Refused(format!("{camera}: the picture's size is not known")))?;
        let crop = match kept {
            Some(c) => c,
            None => {
                let Some(b) = models else {
                    return Ok(overlay::png(&rgb));
                };
                let (w, h) = rgb.dimensions();
                let crop = around(b, w, h);
                t.keep_crop(k, frame, crop);
                crop
            }
        };
        let [cx, cy, cw, ch] = crop;
        let crop = image::imageops::crop_imm(&rgb, cx, cy, cw, ch).to_image();
        Ok(overlay::png(&crop))
    }

    /// Camera `camera`'s whole picture of `frame` (video frame and mask, at the masks'
    /// resolution), with the first pose last fitted from picked points, as PNG.
    pub fn picture(&self, camera: &str, frame: u32) -> std::result::Result<Vec<u8>, Refused> {
        let c = self
            .capture
            .as_ref()
            .ok_or_else(|| Refused("no capture was given".into()))?;
        let k = c
            .camera_names()
            .iter()
            .position(|n| *n == camera)
            .ok_or_else(|| Refused(format!("no camera {camera:?}")))?;
        if !c.frames().contains(&frame) {
            return Err(Refused(format!("no frame {frame} in the capture")));
        }
        let masks = c.load_masks(frame).ok();
        let mask = masks.as_ref().and_then(|m| m.masks[k].as_ref());
        let fitted = *self.fitted.lock().unwrap_or_else(|e| e.into_inner());
        let (rgb, _) = overlay::picture(c, k, frame, mask, fitted.as_ref(), ArchColours::Distinct)
            .map_err(|e| Refused(e.to_string()))?
            .ok_or_else(|| Refused(format!("{camera}: the picture's size is not known")))?;
        let [cx, cy, cw, ch] =
            mask.and_then(labelled_crop)
                .unwrap_or([0, 0, rgb.width(), rgb.height()]);
        Ok(overlay::png(
            &image::imageops::crop_imm(&rgb, cx, cy, cw, ch).to_image(),
        ))
    }

    /// Fit the first pose from picked points (and write init.json when asked).
    pub fn first_pose(&self, q: &FirstPoseQuery) -> std::result::Result<FirstPoseReply, Refused> {
        let c = self
            .capture
            .as_ref()
            .ok_or_else(|| Refused("no capture was given".into()))?;
        let (poses, reply) = first_pose(c, q).map_err(|e| Refused(e.to_string()))?;
        *self.fitted.lock().unwrap_or_else(|e| e.into_inner()) = Some(poses);
        Ok(reply)
    }
}

/// The region around box `[x0, y0, x1, y1]` of a `w`x`h` picture shown on the page: twice
/// the box, at least a quarter of the picture's width, at the picture's aspect (the teeth fill
/// a small part of the frame).
fn around([x0, y0, x1, y1]: [u32; 4], w: u32, h: u32) -> [u32; 4] {
    let size = (2 * (x1 - x0)).max(2 * (y1 - y0) * w / h).max(w / 4);
    let cw = size.min(w);
    let ch = (cw * h / w).min(h);
    let cx = ((x0 + x1) / 2).saturating_sub(cw / 2).min(w - cw);
    let cy = ((y0 + y1) / 2).saturating_sub(ch / 2).min(h - ch);
    [cx, cy, cw, ch]
}

/// [`around`] what a mask labels (teeth or mouth), `None` where it labels nothing.
fn labelled_crop(mask: &LabelMask) -> Option<[u32; 4]> {
    let w = mask.width as usize;
    let mut b: Option<[u32; 4]> = None;
    for (i, _) in mask.data.iter().enumerate().filter(|(_, v)| **v != 0) {
        let (x, y) = ((i % w) as u32, (i / w) as u32);
        let c = b.get_or_insert([x, y, x + 1, y + 1]);
        *c = [c[0].min(x), c[1].min(y), c[2].max(x + 1), c[3].max(y + 1)];
    }
    b.map(|b| around(b, mask.width, mask.height))
}
