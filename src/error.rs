//! The library's error type. Every variant names the file; `Invalid` also names the field.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file the capture needs does not exist.
    #[error("{}: {what} not found", path.display())]
    Missing { path: PathBuf, what: String },
    // The underlying errors are part of the messages, not `#[source]`s, so that anyhow's
    // `{:#}` does not print them twice.
    #[error("{}: cannot read: {error}", path.display())]
    Read {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: cannot write: {error}", path.display())]
    Write {
        path: PathBuf,
        error: std::io::Error,
    },
    /// JSON that does not parse or does not fit the schema; `field` is where (`.` for the
    /// document itself).
    #[error("{}: `{field}`: malformed JSON: {error}", path.display())]
    Json {
        path: PathBuf,
        field: String,
        error: serde_json::Error,
    },
    /// A value that parsed but is wrong: the file, the field (a JSON path such as
    /// `rotation[1][2]`, or a mesh element such as `face 12`) and what is wrong.
    #[error("{}: `{field}`: {problem}", path.display())]
    Invalid {
        path: PathBuf,
        field: String,
        problem: String,
    },
    /// A program jawtrack ran (sbatch, a task of a batch) failed; `path` is the script it
    /// ran or the log it wrote.
    #[error("{}: `{program}` failed: {problem}", path.display())]
    Command {
        path: PathBuf,
        program: String,
        problem: String,
    },
    /// A run was asked to stop (the page's Stop button); what it wrote so far is kept.
    #[error("stopped at frame {frame}")]
    Stopped { frame: u32 },
    #[error("{}: cannot decode the image: {problem}", path.display())]
    Image { path: PathBuf, problem: String },
    /// The GPU energy engine could not start or run. (Part of the message, not a `#[source]`,
    /// so anyhow does not print it twice.)
    #[error("GPU: {0}")]
    Gpu(GpuError),
}

/// Why the GPU energy engine could not start or run. It lives here, beside [`Error`], so that
/// the error type depends on nothing above it.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter, or none matching `wanted` (the adapter variable and its value, e.g.
    /// `JAWTRACK_ADAPTER="llvmpipe"`).
    #[error(
        "no GPU adapter{}; available: {}",
        wanted.as_ref().map(|w| format!(" matching {w}")).unwrap_or_default(),
        if available.is_empty() { "none".to_string() } else { available.join(", ") }
    )]
    NoAdapter {
        wanted: Option<String>,
        available: Vec<String>,
    },
    #[error("cannot open a device on {0}")]
    Device(String),
    #[error("reading the counts back failed: {0}")]
    Readback(String),
    #[error(
        "camera `{camera}`: masks of {width}x{height} exceed the GPU atlas page ({page}x{page})"
    )]
    MaskTooLarge {
        camera: String,
        width: u32,
        height: u32,
        page: u32,
    },
}

impl From<GpuError> for Error {
    fn from(e: GpuError) -> Self {
        Error::Gpu(e)
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub fn invalid(
        path: impl Into<PathBuf>,
        field: impl Into<String>,
        problem: impl Into<String>,
    ) -> Self {
        Error::Invalid {
            path: path.into(),
            field: field.into(),
            problem: problem.into(),
        }
    }

    /// An I/O error on reading, with a not-found error turned into [`Error::Missing`].
    pub fn read(path: impl Into<PathBuf>, what: &str, source: std::io::Error) -> Self {
        let path = path.into();
        if source.kind() == std::io::ErrorKind::NotFound {
            Error::Missing {
                path,
                what: what.to_string(),
            }
        } else {
            Error::Read {
                path,
                error: source,
            }
        }
    }
}

/// A number as an error message shows it: as is when it reads well, in exponent form when it
/// would run to hundreds of digits (1e308 is `1e308`, not 309 figures).
pub struct Shown(pub f64);

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a == 0.0 || !a.is_finite() || (1e-4..1e7).contains(&a) {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Shown;

    #[test]
    fn huge_and_tiny_numbers_are_shown_with_an_exponent() {
        assert_eq!(Shown(1e308).to_string(), "1e308");
        assert_eq!(Shown(-2.5e-9).to_string(), "-2.5e-9");
        assert_eq!(Shown(0.25).to_string(), "0.25");
        assert_eq!(Shown(150.0).to_string(), "150");
        assert_eq!(Shown(f64::NAN).to_string(), "NaN");
    }
}
