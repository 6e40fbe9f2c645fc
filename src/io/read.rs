//! Opening a file a user gave: it must be a regular file (links followed) no larger than a
//! limit, so that a pipe, a device such as /dev/zero or a huge file is refused before anything
//! is read or allocated. The limit is `JAWTRACK_MAX_FILE_MB` (MiB) when set, else
//! [`DEFAULT_MAX_FILE_MB`].

use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};

/// The environment variable that sets the size limit, in MiB.
pub const MAX_FILE_ENV: &str = "JAWTRACK_MAX_FILE_MB";
/// The default limit: 4 GiB, above any scan, mask or journal a capture holds.
pub const DEFAULT_MAX_FILE_MB: u64 = 4096;

/// The size limit in bytes.
pub fn max_file_bytes() -> u64 {
    std::env::var(MAX_FILE_ENV)
        .ok()
        .and_then(|v| v.trim().parse::<u64>().ok())
        .unwrap_or(DEFAULT_MAX_FILE_MB)
        .saturating_mul(1 << 20)
}

/// Open `path` (a `what`, for errors) for reading, with its size.
pub fn open_input(path: &Path, what: &str) -> Result<(File, u64)> {
    let meta = std::fs::metadata(path).map_err(|e| Error::read(path, what, e))?;
    if !meta.is_file() {
        return Err(Error::invalid(
            path,
            "file",
            format!("the {what} is not a regular file (a folder, pipe or device)"),
        ));
    }
    let limit = max_file_bytes();
    if meta.len() > limit {
        return Err(Error::invalid(
            path,
            "file",
            format!(
                "the {what} has {} bytes, more than the limit of {} MiB ({MAX_FILE_ENV} raises it)",
                meta.len(),
                limit >> 20
            ),
        ));
    }
    let file = File::open(path).map_err(|e| Error::read(path, what, e))?;
    Ok((file, meta.len()))
}

/// The whole of `path` as text.
pub fn read_text(path: &Path, what: &str) -> Result<String> {
    let (file, len) = open_input(path, what)?;
    let mut text = String::with_capacity(len as usize);
    // `take`: a file that grows while it is read stops at the size checked.
    file.take(len)
        .read_to_string(&mut text)
        .map_err(|e| Error::read(path, what, e))?;
    Ok(text)
}

/// A short, printable token of a file's text for an error message: a file pointed at by
/// mistake (or on purpose) is not echoed whole.
pub fn quote(text: &str) -> String {
    const MAX: usize = 60;
    let mut out: String = text
        .chars()
        .take(MAX)
        .map(|c| {
            if c.is_ascii_graphic() || c == ' ' {
                c
            } else {
                '?'
            }
        })
        .collect();
    if text.chars().count() > MAX {
        out.push('…');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quotes_are_short_and_printable() {
        assert_eq!(quote("1.5e"), "1.5e");
        assert_eq!(quote("a\u{0}b\nc"), "a?b?c");
        let long = "root:x:0:0:root:/root:/bin/bash daemon:x:1:1";
        assert_eq!(quote(&long.repeat(2)).chars().count(), 61);
    }

    #[cfg(unix)]
    #[test]
    fn a_device_is_not_read() {
        let e = read_text(Path::new("/dev/zero"), "capture file").unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
    }

    #[test]
    fn a_folder_is_not_read_and_a_file_is() {
        let t = tempfile::tempdir().unwrap();
        let e = read_text(t.path(), "mesh").unwrap_err().to_string();
        assert!(e.contains("mesh is not a regular file"), "{e}");
        let f = t.path().join("a.json");
        std::fs::write(&f, "{}").unwrap();
        assert_eq!(read_text(&f, "x").unwrap(), "{}");
    }
}
