//! gsi: images stored as 2D Gaussians.
//!
//! Four representations, each with one home: bytes ([`format`]), records (quantized
//! attributes, [`format::Records`]), the float model ([`model`]) and pixels ([`render`]).

pub mod format;
pub mod model;
pub mod render;
#[doc(hidden)]
pub mod synth;
