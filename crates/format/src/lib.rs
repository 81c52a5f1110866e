//! The `.gsi` container and the model it holds: the bottom layer of gsi.
//!
//! [`format`](mod@format) turns bytes into records and back (framing, CRC, [`format::Limits`],
//! quantizers, bit-packed and range-coded attributes, the stage-2 chunks), [`model`] is the
//! float Gaussian set every other layer works on, and [`contract`] holds the constants of
//! the spec's pixel contract (`format-spec.md` §6) that encoder and decoders share. The
//! `gsi` crate re-exports all three; depend on it unless you need this layer alone.

pub mod contract;
pub mod format;
pub mod model;
