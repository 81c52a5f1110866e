//! Where a stage runs: the [`Device`] each stage's entry point takes, and (feature `gpu`)
//! the wgpu device under it: adapter choice, buffers, read-back, kernels, the stable radix
//! sort and the scene renderer. It knows no stage: stage 1's and stage 2's GPU twins live
//! in their own crates and build on it.

pub mod device;
#[cfg(feature = "gpu")]
pub mod gpu;

pub use device::Device;
