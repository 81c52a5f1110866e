//! Stage 1's error.

use std::fmt;

/// Why an encode failed. GPU failures are not among them: a fit given a GPU that fails
/// finishes on the CPU and says so in [`super::Encoded::fallback`].
#[non_exhaustive]
#[derive(Debug)]
pub enum Error {
    /// The image to fit is unusable: empty, mis-sized, or holding non-finite values.
    InvalidTarget(String),
    /// The fit went non-finite (which the stability tests guard against).
    NonFinite(&'static str),
    /// Writing the file, or reading back what was written, failed in the container layer.
    Format(gsi_format::format::Error),
    /// The byte budget (`--bpp`) is below the smallest file that can be written for this
    /// image: one Gaussian and the fixed chunks. Refused rather than written over budget.
    BudgetUnreachable { asked_bpp: f32, smallest_bpp: f32 },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::InvalidTarget(why) => write!(f, "cannot fit this image: {why}"),
            Error::NonFinite(what) => f.write_str(what),
            Error::Format(e) => e.fmt(f),
            Error::BudgetUnreachable {
                asked_bpp,
                smallest_bpp,
            } => write!(
                f,
                "a budget of {asked_bpp} bpp cannot be met: the smallest file for this image \
                 is {smallest_bpp:.4} bpp"
            ),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Format(e) => Some(e),
            _ => None,
        }
    }
}

impl From<gsi_format::format::Error> for Error {
    fn from(e: gsi_format::format::Error) -> Error {
        Error::Format(e)
    }
}
