//! Paths a capture names stay inside its folder: capture.json's paths, the mask files, init.json
//! and the ground truth may not climb out, be absolute, or be links that resolve elsewhere,
//! unless the user says so (`--allow-outside`).

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// `rel` (capture.json's `field`) joined to the capture folder `dir`, refused when it leaves the
/// folder: an absolute path, a `..` that climbs out, or a link that resolves outside.
pub fn path_inside(dir: &Path, capture_path: &Path, field: &str, rel: &str) -> Result<PathBuf> {
    use std::path::Component;
    let outside = |why: &str| {
        Error::invalid(
            capture_path,
            field,
            format!(
                "{why}: a capture reads only its own folder (`--allow-outside` lets it read elsewhere)"
            ),
        )
    };
    let rel_path = Path::new(rel);
    let mut depth = 0i64;
    for c in rel_path.components() {
        match c {
            Component::Prefix(_) | Component::RootDir => {
                return Err(outside("an absolute path"));
            }
            Component::ParentDir => depth -= 1,
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
        }
        if depth < 0 {
            return Err(outside("the path climbs out of the capture folder"));
        }
    }
    let path = dir.join(rel_path);
    // Links are followed where the file exists; a missing file is reported by its reader.
    if let (Ok(real), Ok(root)) = (path.canonicalize(), dir.canonicalize())
        && !real.starts_with(&root)
    {
        return Err(outside(
            "the path resolves (through a link) outside the capture folder",
        ));
    }
    Ok(path)
}

/// Where a file of the capture that no field names (init.json, gt/poses.json) lies: refused
/// when it is a link out of the folder.
pub fn own_file(dir: &Path, rel: &str, allow_outside: bool) -> Result<PathBuf> {
    if allow_outside {
        return Ok(dir.join(rel));
    }
    path_inside(dir, &dir.join(rel), "file", rel)
}

/// A file found in one of the capture's folders (a mask): refused when it is a link that
/// resolves outside `root`, the capture folder; `None` when links out are allowed.
pub fn listed_file_inside(path: &Path, root: Option<&Path>) -> Result<()> {
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
            "a link that resolves outside the capture folder: a capture reads only its own folder (`--allow-outside` lets it read elsewhere)",
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
                .is_some_and(|e| super::mesh::EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        }));
    }
    let mut folders: Vec<PathBuf> = ["cameras", "meshes", "masks", "images", "gt"]
        .iter()
        .map(|d| capture.dir.join(d))
        .collect();
    folders.push(capture.mask_dir.clone());
    (files, folders)
}
