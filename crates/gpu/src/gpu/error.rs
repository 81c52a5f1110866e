//! The GPU layer's error: why no device could be had, or why a GPU call failed.
//!
//! Its kinds say what a caller can do about it: `Unavailable`, `Device` and `TimedOut`
//! call for the CPU, `LimitExceeded` for the CPU or a smaller job, `InvalidValue` for
//! other input.

use std::fmt;

/// Why a GPU call failed.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// No adapter, or not the kind asked for (only a software one where hardware was
    /// required), or no device could be opened on it.
    Unavailable,
    /// The work does not fit this adapter: a buffer over its binding limit, a dispatch over
    /// its workgroup limit, or its memory.
    LimitExceeded,
    /// The caller's input is malformed (an empty size, inconsistent lengths).
    InvalidValue,
    /// The device refused the work (a validation error, a shader its compiler rejects),
    /// lost it, or could not hand the results back.
    Device,
    /// The device did not finish within [`super::Gpu::set_wait_timeout`]: hung or lost.
    TimedOut,
}

/// A GPU error: its kind and what happened, in words.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Error {
    kind: ErrorKind,
    message: String,
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Error {
        Error {
            kind,
            message: message.into(),
        }
    }

    pub fn kind(&self) -> ErrorKind {
        self.kind
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Error {}

/// The container layer's refusals that GPU entry points pass on (output sizes over
/// [`gsi_format::format::Limits`], invalid values).
impl From<gsi_format::format::Error> for Error {
    fn from(e: gsi_format::format::Error) -> Error {
        let kind = match e.kind() {
            gsi_format::format::ErrorKind::LimitExceeded => ErrorKind::LimitExceeded,
            _ => ErrorKind::InvalidValue,
        };
        Error::new(kind, e.to_string())
    }
}
