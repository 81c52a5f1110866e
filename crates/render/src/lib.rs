//! Rendering Gaussians into pixels on the CPU, and the decoder API: the layer above the
//! container.
//!
//! [`render`] projects a scene at any output size, bins it into tiles and blends eight
//! pixels at a time with the exponential the format defines; [`decode`] is what an embedder
//! calls (`decode`, `Reader`), with `Limits` on the output and the work as well as the
//! file. The `gsi` crate re-exports both.

pub mod decode;
pub mod render;
