//! One error type for the whole library. Each variant says *where* the problem is, so a
//! user reading a CLI message knows which file, section or field to look at.

use std::path::PathBuf;

/// Errors returned by every fallible scode function. Untrusted input never panics: it ends
/// up here.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A `.scode` bitstream is malformed: names the section and the field that failed
    /// validation, plus a human-readable detail.
    #[error("invalid .scode data in section `{section}`, field `{field}`: {detail}")]
    Format {
        section: &'static str,
        field: &'static str,
        detail: String,
    },
    /// An input model (mesh file, STEP file) is malformed or unsupported.
    #[error("{path}: {detail}")]
    Input { path: PathBuf, detail: String },
    /// A mesh violates an invariant an operation needs (non-manifold, NaN, ...).
    #[error("invalid mesh: {0}")]
    Mesh(String),
    /// A caller-supplied parameter is out of range (quantisation bits, tolerance, level...).
    #[error("invalid parameter: {0}")]
    Parameter(String),
    /// Decoding would exceed a configured resource limit (see `codec::Limits`).
    #[error("limit exceeded: {what} = {value} exceeds the limit {limit}")]
    LimitsExceeded {
        what: &'static str,
        value: u64,
        limit: u64,
    },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Shorthand for a bitstream format error.
    pub fn format(section: &'static str, field: &'static str, detail: impl Into<String>) -> Self {
        Error::Format {
            section,
            field,
            detail: detail.into(),
        }
    }

    /// Shorthand for an I/O error on a path.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// Shorthand for an input-model error on a path.
    pub fn input(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        Error::Input {
            path: path.into(),
            detail: detail.into(),
        }
    }
}
