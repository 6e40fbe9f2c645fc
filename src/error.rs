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
    #[error("{}: cannot decode the image: {problem}", path.display())]
    Image { path: PathBuf, problem: String },
    /// The GPU energy engine could not start or run. (Part of the message, not a `#[source]`,
    /// so anyhow does not print it twice.)
    #[error("GPU: {0}")]
    Gpu(crate::energy::gpu::GpuError),
}

impl From<crate::energy::gpu::GpuError> for Error {
    fn from(e: crate::energy::gpu::GpuError) -> Self {
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
