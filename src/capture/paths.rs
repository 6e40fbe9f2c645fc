//! Paths a capture names stay inside its folder: capture.json's paths, the mask files, init.json
//! and the ground truth may not climb out, be absolute, or be links that resolve elsewhere,
//! unless the user says so (`--allow-outside`).

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The folder a reader keeps to, which its refusals name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Folder {
    Capture,
    FaceSequence,
}

impl Folder {
    fn name(self) -> &'static str {
        match self {
            Folder::Capture => "the capture folder",
            Folder::FaceSequence => "the face sequence's folder",
        }
    }

    fn rule(self) -> &'static str {
        match self {
            Folder::Capture => {
                "a capture reads only its own folder (`--allow-outside` lets it read elsewhere)"
            }
            Folder::FaceSequence => {
                "a face sequence reads only its own folder (copy the file into it)"
            }
        }
    }
}

/// `rel` (the `field` of `described_in`, a file in `dir`) joined to `dir`, refused when it
/// leaves the folder: an absolute path, a `..` that climbs out, or a link that resolves outside.
pub fn path_inside(
    folder: Folder,
    dir: &Path,
    described_in: &Path,
    field: &str,
    rel: &str,
) -> Result<PathBuf> {
    use std::path::Component;
    let outside =
        |why: String| Error::invalid(described_in, field, format!("{why}: {}", folder.rule()));
    let rel_path = Path::new(rel);
    let mut depth = 0i64;
    for c in rel_path.components() {
        match c {
            Component::Prefix(_) | Component::RootDir => {
                return Err(outside("an absolute path".into()));
            }
            Component::ParentDir => depth -= 1,
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
        }
        if depth < 0 {
            return Err(outside(format!("the path climbs out of {}", folder.name())));
        }
    }
    let path = dir.join(rel_path);
    // Links are followed where the file exists; a missing file is reported by its reader.
    if let (Ok(real), Ok(root)) = (path.canonicalize(), dir.canonicalize())
        && !real.starts_with(&root)
    {
        return Err(outside(format!(
            "the path resolves (through a link) outside {}",
            folder.name()
        )));
    }
    Ok(path)
}

/// Where a file of the capture that no field names (init.json, gt/poses.json) lies: refused
/// when it is a link out of the folder.
pub fn own_file(dir: &Path, rel: &str, allow_outside: bool) -> Result<PathBuf> {
    if allow_outside {
        return Ok(dir.join(rel));
    }
    path_inside(Folder::Capture, dir, &dir.join(rel), "file", rel)
}

/// A file found in one of a folder's sub-folders (a mask, a skin frame): refused when it is a
/// link that resolves outside `root`, the folder of `folder`; `None` when links out are allowed.
pub fn listed_file_inside(folder: Folder, path: &Path, root: Option<&Path>) -> Result<()> {
    let Some(root) = root else { return Ok(()) };
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    if !is_link {
        return Ok(());
    }
    if let (Ok(real), Ok(root)) = (path.canonicalize(), root.canonicalize())
        && !real.starts_with(&root)
    {
        return Err(Error::invalid(
            path,
            "file",
            format!(
                "a link that resolves outside {}: {}",
                folder.name(),
                folder.rule()
            ),
        ));
    }
    Ok(())
}

/// What any command that opens this capture reads, for [`super::check_outputs`]: capture.json,
/// init.json, the spec's folders (cameras, meshes, masks, images, gt) and scans kept at
/// the folder's top.
pub fn capture_reads(capture: &super::Capture) -> (Vec<PathBuf>, Vec<PathBuf>) {
    let mut files = vec![
        capture.dir.join("capture.json"),
        capture.dir.join("init.json"),
    ];
    if let Ok(entries) = std::fs::read_dir(&capture.dir) {
        files.extend(entries.flatten().map(|e| e.path()).filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| crate::mesh::EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        }));
    }
    let mut folders: Vec<PathBuf> = ["cameras", "meshes", "masks", "images", "gt"]
        .iter()
        .map(|d| capture.dir.join(d))
        .collect();
    folders.push(capture.mask_dir.clone());
    (files, folders)
}
