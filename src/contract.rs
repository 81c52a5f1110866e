//! The constants of the pixel contract, `format-spec.md` §6: the one home of every number
//! that decides what a file's pixels are.
//!
//! The CPU renderer, the differentiable rasterizer, the enhancer and the GPU shaders (which
//! get them written in as WGSL by `gpu::contract`) all read these, so that no renderer can
//! drift from another. Changing one changes what existing files mean: it is a format change.

/// Largest magnitude of a Cholesky entry, in normalized units (16 image widths), §6.1.
pub const CHOLESKY_MAX: f32 = 16.0;
/// Range of `ln σ` in normalized units, §6.1: `e^-30` is far below any pixel, `e^3` is 20
/// images.
pub const LN_SIGMA_MIN: f32 = -30.0;
/// See [`LN_SIGMA_MIN`].
pub const LN_SIGMA_MAX: f32 = 3.0;

/// Floor of a pixel-space variance (px²), §6.2. Keeps a Gaussian far below a pixel from
/// having an infinite conic, and its determinant a normal float.
pub const VAR_MIN: f32 = 1e-4;
/// Ceiling of a pixel-space variance (px²); with [`VAR_MIN`] it keeps `a·c` finite.
pub const VAR_MAX: f32 = 1e12;
/// The covariance term is clamped to this fraction of `√(a·c)`, so the determinant stays
/// positive however the parameters were rounded.
pub const CORRELATION_MAX: f32 = 0.999;
/// Half-extent of a Gaussian's pixel box, in standard deviations along x and y.
pub const EXTENT_SIGMAS: f32 = 3.0;
/// Contributions with `alpha` below this are skipped (they are invisible in 8 bits), §6.3.
pub const ALPHA_MIN: f32 = 1.0 / 255.0;
/// In `alpha` blending one Gaussian lets at least 1 % of the light through, §6.4.
pub const ALPHA_MAX: f32 = 0.99;
/// In `alpha` blending a pixel stops once its transmittance falls below this, §6.4.
pub const TRANSMITTANCE_MIN: f32 = 1e-4;
/// Colours are clamped to `±COLOR_MAX` before blending. A `sum` of fewer than 2^32
/// Gaussians with alpha ≤ 1 then stays below 2^38, so no file can make a pixel infinite;
/// displayable colours are in `[0, 1]` and fitted ones stay within a few units.
pub const COLOR_MAX: f32 = 64.0;
