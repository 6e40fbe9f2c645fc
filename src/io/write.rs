//! Atomic output: write to a temporary file beside the target, then rename over it, so a
//! reader (or an interrupted run) never sees a half-written file.

use std::io::Write;
use std::path::Path;

use crate::error::{Error, Result};

/// Write `bytes` to `path` atomically. A `path` that exists and is not a regular file (a
/// device, a pipe, a folder, a link) is refused: renaming over it would replace the node
/// itself, e.g. /dev/full with an ordinary file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    check_replaceable(path)?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let werr = |error| Error::Write {
        path: path.to_path_buf(),
        error,
    };
    std::fs::create_dir_all(dir).map_err(werr)?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(werr)?;
    tmp.write_all(bytes).map_err(werr)?;
    tmp.as_file().sync_data().map_err(werr)?;
    // Temporary files are private (0600); the result is an ordinary file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))
            .map_err(werr)?;
    }
    tmp.persist(path).map_err(|e| werr(e.error))?;
    Ok(())
}

/// `Ok` when `path` is absent or a regular file (not a link to one).
pub fn check_replaceable(path: &Path) -> Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if !m.file_type().is_file() => Err(Error::invalid(
            path,
            "output",
            "exists and is not a regular file (a device, pipe, folder or link): refusing to replace it",
        )),
        _ => Ok(()),
    }
}

pub fn write_json_atomic<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut text = serde_json::to_vec_pretty(value).expect("serialising plain data cannot fail");
    text.push(b'\n');
    write_atomic(path, &text)
}

/// An 8-bit grey (`L8`) or RGB (`Rgb8`) picture as PNG bytes, fast compression: masks and
/// pictures the program writes.
pub fn encode_png(
    pixels: &[u8],
    width: u32,
    height: u32,
    kind: image::ExtendedColorType,
) -> Vec<u8> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(pixels, width, height, kind)
    .expect("a buffer of the stated size encodes into memory");
    out
}

/// Where `path` points: its canonical form, or, where it does not exist yet, its parent's
/// with its name (so that `a/../b.json` and `b.json` are one file).
pub fn resolved(path: &Path) -> std::path::PathBuf {
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    let parent = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match (std::fs::canonicalize(parent), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf()),
    }
}

/// What a command reads, for [`check_outputs`]: files, and folders whose every file it reads.
#[derive(Debug, Default)]
pub struct Reads<'a> {
    pub files: Vec<&'a Path>,
    pub folders: Vec<&'a Path>,
}

/// Refuse an output that is a file the command reads, lies in a folder it reads, or is another
/// of its outputs: writing it would destroy what the user made.
pub fn check_outputs(reads: &Reads, outputs: &[&Path]) -> Result<()> {
    let files: Vec<_> = reads.files.iter().map(|p| (resolved(p), *p)).collect();
    let folders: Vec<_> = reads.folders.iter().map(|p| (resolved(p), *p)).collect();
    for (i, out) in outputs.iter().enumerate() {
        let at = resolved(out);
        if let Some((_, input)) = files.iter().find(|(f, _)| *f == at) {
            return Err(Error::invalid(
                out,
                "output",
                format!(
                    "is {}, which this command reads: write the output elsewhere",
                    input.display()
                ),
            ));
        }
        if let Some((_, dir)) = folders.iter().find(|(d, _)| at.starts_with(d)) {
            return Err(Error::invalid(
                out,
                "output",
                format!(
                    "lies in {}, whose files this command reads: write the output elsewhere",
                    dir.display()
                ),
            ));
        }
        if outputs[..i].iter().any(|o| resolved(o) == at) {
            return Err(Error::invalid(
                out,
                "output",
                "is given twice: each output needs its own file",
            ));
        }
    }
    Ok(())
}
