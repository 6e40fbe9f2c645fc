//! Opening a capture: capture.json checked field by field, then the cameras and the masks
//! present, the frames they cover, the meshes, init.json and the ground truth; every path kept
//! inside the folder unless the user allows otherwise.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::json::{self, BoiJson, CaptureJson};
use super::paths::{self, Folder};
use super::{Capture, CaptureCamera, MaskMode, OpenOptions, masks, read_camera, resolution};
use crate::error::{Error, Result};
use crate::formats::read_poses;
use crate::mesh::{BoiSource, Mesh, Simplify};

/// A capture being opened: its folder, capture.json's path and the options.
pub(super) struct Opening<'a> {
    dir: &'a Path,
    capture_path: PathBuf,
    options: OpenOptions,
}

enum BoiRef {
    Group(String),
    List(PathBuf),
}

impl<'a> Opening<'a> {
    pub(super) fn new(dir: &'a Path, options: OpenOptions) -> Opening<'a> {
        Opening {
            dir,
            capture_path: dir.join("capture.json"),
            options,
        }
    }

    fn invalid(&self, field: impl Into<String>, problem: impl Into<String>) -> Error {
        Error::invalid(&self.capture_path, field, problem)
    }

    /// `rel` (the field `field` of capture.json) in the capture folder.
    fn inside(&self, field: &str, rel: &str) -> Result<PathBuf> {
        if self.options.allow_outside {
            Ok(self.dir.join(rel))
        } else {
            paths::path_inside(Folder::Capture, self.dir, &self.capture_path, field, rel)
        }
    }

    pub(super) fn open(&self) -> Result<Capture> {
        let (cj, unknown): (CaptureJson, _) =
            crate::io::read_json_noting_unknown(&self.capture_path, "capture.json")?;
        let notes = unknown
            .iter()
            .map(|field| {
                format!(
                    "{}: `{field}` is not a field of the capture format; ignored",
                    self.capture_path.display()
                )
            })
            .collect();
        self.check_header(&cj)?;
        let mask_mode = self.mask_mode(&cj)?;
        let offsets = self.offsets(&cj)?;
        let mouth = mask_mode.mouth_label(cj.masks.mouth, &self.capture_path)?;
        let mask_dir = self.inside("masks.dir", &cj.masks.dir)?;
        let cameras = cj
            .cameras
            .iter()
            .enumerate()
            .map(|(i, name)| self.camera(&cj, i, name, mask_mode, &offsets))
            .collect::<Result<Vec<_>>>()?;
        self.check_frames(&cj, &cameras, &mask_dir)?;
        // Where no bound is given, the cameras say how fine a silhouette they can see.
        let simplified_mm = match self.options.max_triangles {
            Some(_) => None,
            None => Some(
                self.options
                    .simplify_mm
                    .unwrap_or_else(|| resolution::simplify_mm(&cameras)),
            ),
        };
        let (upper, lower, mandible) = self.meshes(&cj, simplified_mm)?;
        let mut capture = Capture {
            dir: self.dir.to_path_buf(),
            cameras,
            first_frame: cj.frames.first,
            frame_count: cj.frames.count,
            upper,
            lower,
            mandible,
            mask_dir,
            mask_mode,
            mouth,
            notes,
            mask_reduce: self.options.mask_reduce.max(1),
            simplified_mm,
            init: None,
            gt: None,
        };
        let allow = self.options.allow_outside;
        let init_path = paths::own_file(self.dir, "init.json", allow)?;
        if init_path.exists() {
            capture.init = Some(capture.read_init(&init_path)?);
        }
        let gt_path = paths::own_file(self.dir, "gt/poses.json", allow)?;
        if gt_path.exists() {
            capture.gt = Some(read_poses(&gt_path)?);
        }
        Ok(capture)
    }

    /// The format, the cameras' names and the frame count.
    fn check_header(&self, cj: &CaptureJson) -> Result<()> {
        if cj.format != json::CAPTURE_FORMAT {
            return Err(self.invalid(
                "format",
                format!(
                    "expected \"{}\", found \"{}\"",
                    json::CAPTURE_FORMAT,
                    cj.format
                ),
            ));
        }
        if cj.cameras.is_empty() {
            return Err(self.invalid("cameras", "no cameras are named"));
        }
        for (i, name) in cj.cameras.iter().enumerate() {
            if name.is_empty() || name.contains(['/', '\\']) || name == "." || name == ".." {
                return Err(self.invalid(
                    format!("cameras[{i}]"),
                    format!("`{name}` is not a valid camera name"),
                ));
            }
            if cj.cameras[..i].contains(name) {
                return Err(self.invalid(
                    format!("cameras[{i}]"),
                    format!("camera `{name}` is named twice"),
                ));
            }
        }
        if cj.frames.count == 0 {
            return Err(self.invalid("frames.count", "must be at least 1"));
        }
        Ok(())
    }

    fn mask_mode(&self, cj: &CaptureJson) -> Result<MaskMode> {
        match cj.masks.mode.as_str() {
            "per-arch" => {
                let label =
                    |v: Option<i64>, default: u8, field: &str| -> Result<u8> {
                        match v {
                            None => Ok(default),
                            Some(x) if (0..=255).contains(&x) => Ok(x as u8),
                            Some(x) => Err(self
                                .invalid(field, format!("a mask label must be 0..255, found {x}"))),
                        }
                    };
                let upper = label(cj.masks.upper, 1, "masks.upper")?;
                let lower = label(cj.masks.lower, 2, "masks.lower")?;
                if upper == lower {
                    return Err(self.invalid(
                        "masks.lower",
                        format!("the upper and lower labels are both {upper}"),
                    ));
                }
                Ok(MaskMode::PerArch { upper, lower })
            }
            "combined" => Ok(MaskMode::Combined),
            other => Err(self.invalid(
                "masks.mode",
                format!("expected \"per-arch\" or \"combined\", found \"{other}\""),
            )),
        }
    }

    /// `frames.offsets`: by how many frames each camera's files run ahead.
    fn offsets(&self, cj: &CaptureJson) -> Result<BTreeMap<String, i64>> {
        let offsets = cj.frames.offsets.clone().unwrap_or_default();
        for (name, &offset) in &offsets {
            let field = format!("frames.offsets.{name}");
            if !cj.cameras.contains(name) {
                return Err(self.invalid(field, "no camera of that name"));
            }
            if offset.abs() > 1_000_000 {
                return Err(self.invalid(
                    field,
                    format!("an offset of {offset} frames is beyond 1000000"),
                ));
            }
        }
        Ok(offsets)
    }

    /// Camera `i` (`name`): its calibration and the masks present for it.
    fn camera(
        &self,
        cj: &CaptureJson,
        i: usize,
        name: &str,
        mask_mode: MaskMode,
        offsets: &BTreeMap<String, i64>,
    ) -> Result<CaptureCamera> {
        let camera_file = self.inside(&format!("cameras[{i}]"), &format!("cameras/{name}.json"))?;
        let calibrated = read_camera(&camera_file, name)?;
        let cam_masks = self.inside(
            &format!("masks.dir ({name}/)"),
            &format!("{}/{name}", cj.masks.dir),
        )?;
        let root = (!self.options.allow_outside).then_some(self.dir);
        let (mask_size, files_present) = masks::scan_masks(&cam_masks, mask_mode, root)?;
        let offset = offsets.get(name).copied().unwrap_or(0);
        let frames_present = files_present
            .into_iter()
            .filter_map(|f| u32::try_from(f as i64 - offset).ok())
            .collect();
        let mask_size = mask_size
            .map(|size| masks::reduced_size(size, self.options.mask_reduce, &cam_masks))
            .transpose()?;
        Ok(CaptureCamera {
            calibrated,
            mask_size,
            frames_present,
            offset,
        })
    }

    /// The frames capture.json names have masks up to the last (unless they are to come).
    fn check_frames(
        &self,
        cj: &CaptureJson,
        cameras: &[CaptureCamera],
        mask_dir: &Path,
    ) -> Result<()> {
        let first = cj.frames.first;
        let last = first as u64 + cj.frames.count as u64 - 1;
        let last_present = cameras.iter().filter_map(|c| c.frames_present.last()).max();
        match last_present {
            _ if self.options.masks_to_come => Ok(()),
            None => Err(Error::Missing {
                path: mask_dir.to_path_buf(),
                what: "mask files (<camera>/<frame:06>.png)".into(),
            }),
            Some(&lp) if last > lp as u64 => Err(self.invalid(
                "frames",
                format!(
                    "frames {first}..={last} go beyond the last mask file present (frame {lp})"
                ),
            )),
            _ => Ok(()),
        }
    }

    /// Both arches (simplified as the options say) with their boundary of interest, and the
    /// mandible if named.
    fn meshes(
        &self,
        cj: &CaptureJson,
        simplified_mm: Option<f64>,
    ) -> Result<(Mesh, Mesh, Option<Mesh>)> {
        let (upper_boi, lower_boi) = match &cj.boi {
            BoiJson::Group { group } => {
                (BoiRef::Group(group.clone()), BoiRef::Group(group.clone()))
            }
            BoiJson::FaceLists { upper, lower } => (
                BoiRef::List(self.inside("boi.upper", upper)?),
                BoiRef::List(self.inside("boi.lower", lower)?),
            ),
        };
        let load_mesh = |field: &str, rel: &str, boi: &BoiRef| -> Result<Mesh> {
            let path = self.inside(field, rel)?;
            let source = match boi {
                BoiRef::Group(g) => BoiSource::Group(g),
                BoiRef::List(p) => BoiSource::FaceList(p),
            };
            let mesh = Mesh::load(&path, source)?;
            Ok(match (self.options.max_triangles, simplified_mm) {
                (Some(n), _) => mesh.simplified(Simplify::MaxTriangles(n)),
                (None, bound) => mesh.simplified(Simplify::MaxErrorMm(bound.unwrap_or(0.0))),
            })
        };
        let upper = load_mesh("meshes.upper", &cj.meshes.upper, &upper_boi)?;
        let lower = load_mesh("meshes.lower", &cj.meshes.lower, &lower_boi)?;
        let mandible = cj
            .meshes
            .mandible
            .as_ref()
            .map(|rel| Mesh::load(&self.inside("meshes.mandible", rel)?, BoiSource::None))
            .transpose()?;
        Ok((upper, lower, mandible))
    }
}
