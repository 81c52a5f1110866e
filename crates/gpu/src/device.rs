//! Where a stage runs: the seam between each stage and its GPU twin.
//!
//! Each stage has one entry point that takes a [`Device`] (`fit::encode`,
//! `enhance::enhance`); the stage's CPU kernels and their GPU twins live side by side in
//! the stage's folder (`fit::raster`/`fit::resident`, `enhance::mixture`/`enhance::gpu`).
//! A GPU that fails part-way is left for the CPU, and the reason comes back in the stage's
//! result (its `fallback` field) for the caller to show or log: the library writes nothing
//! to stderr.

/// Where a stage's kernels run.
#[non_exhaustive]
#[derive(Clone, Copy, Default)]
pub enum Device<'a> {
    /// Every kernel on the CPU (on all cores with the `parallel` feature).
    #[default]
    Cpu,
    /// The kernels that have a GPU twin on this device; the rest on the CPU.
    #[cfg(feature = "gpu")]
    Gpu(&'a crate::gpu::Gpu),
    #[doc(hidden)]
    #[cfg(not(feature = "gpu"))]
    _Lifetime(std::marker::PhantomData<&'a ()>),
}
