//! Gaussians to pixels.
//!
//! Rendering is defined per pixel by `format-spec.md` §6, in `f32` and in a fixed order,
//! so that every renderer of this crate (this CPU one, a GPU one, a differentiable one)
//! agrees on what a file *means*. The pieces are kept apart for that reason:
//!
//! * [`project`]: per-Gaussian preprocessing into pixel space ([`Projected`]). It is the
//!   only place where a covariance becomes a conic and a pixel box, so other renderers
//!   reuse it rather than re-deriving the clamps.
//! * [`Projected::alpha_at`]: the per-pixel rule, written once, readably.
//! * `tiles` and `cpu`: the CPU renderer. Tiles only decide *which* Gaussians a pixel
//!   visits (those whose pixel box holds it), never in what order, so the tiled result
//!   is bit-identical to a naive loop over all Gaussians for every pixel.
//!
//! The output is linear in the stored (sRGB-encoded) colour values and is not clamped:
//! `sum` blending may overshoot `[0, 1]`, and a caller that post-processes (enhancement,
//! metrics) wants to see that. [`RgbImage::to_rgb8`] is where clamping happens.

mod cpu;
mod project;
mod tiles;

#[cfg(feature = "encode")]
pub(crate) use project::Rect;
pub use project::{project, project_scene, PixelBox, Projected};

/// Render already-projected Gaussians into `out` (`width·height·3` floats, overwritten):
/// the differentiable rasterizer shares this path so that fitting sees decoded pixels.
#[cfg_attr(not(feature = "encode"), allow(dead_code))]
pub(crate) fn render_projected(
    proj: &[Projected],
    blend: model::Blend,
    width: u32,
    height: u32,
    out: &mut [f32],
) {
    cpu::render_projected(proj, blend, width, height, out, cfg!(feature = "parallel"));
}

use crate::format::{Error, ErrorKind, Limits, Result};
use crate::model::{self, Scene};

/// Floor of a pixel-space variance (px²). Keeps a Gaussian far below a pixel from
/// having an infinite conic, and its determinant a normal float.
pub const VAR_MIN: f32 = 1e-4;
/// Ceiling of a pixel-space variance (px²); with [`VAR_MIN`] it keeps `a·c` finite.
pub const VAR_MAX: f32 = 1e12;
/// The covariance term is clamped to this fraction of `√(a·c)`, so the determinant stays
/// positive however the parameters were rounded.
pub const CORRELATION_MAX: f32 = 0.999;
/// Half-extent of a Gaussian's pixel box, in standard deviations along x and y.
pub const EXTENT_SIGMAS: f32 = 3.0;
/// Contributions with `alpha` below this are skipped (they are invisible in 8 bits).
pub const ALPHA_MIN: f32 = 1.0 / 255.0;
/// In `alpha` blending one Gaussian lets at least 1 % of the light through.
pub const ALPHA_MAX: f32 = 0.99;
/// In `alpha` blending a pixel stops once its transmittance falls below this.
pub const TRANSMITTANCE_MIN: f32 = 1e-4;
/// Colours are clamped to `±COLOR_MAX` before blending. A `sum` of fewer than 2^32
/// Gaussians with alpha ≤ 1 then stays below 2^38, so no file can make a pixel infinite; displayable
/// colours are in `[0, 1]` and fitted ones stay within a few units.
pub const COLOR_MAX: f32 = 64.0;
/// Side of a square tile, in pixels.
pub const TILE: u32 = 16;

/// A rendered image: row-major, three `f32` per pixel, in the stored colour encoding.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    /// `width * height * 3` values, `[r, g, b]` per pixel, rows top to bottom.
    /// Not clamped: values may lie outside `[0, 1]`.
    pub data: Vec<f32>,
}

impl RgbImage {
    /// 8-bit RGB, three bytes per pixel.
    ///
    /// Each channel is clamped to `[0, 1]`, then mapped to `floor(c·255 + 0.5)`
    /// (round half up, in `f32`); NaN becomes 0. The rule is fixed so that golden hashes
    /// of decoded images do not depend on the platform's rounding mode or on `round()`.
    pub fn to_rgb8(&self) -> Vec<u8> {
        self.data.iter().map(|&c| to_u8(c)).collect()
    }

    /// 8-bit RGBA, four bytes per pixel, alpha 255 (the background is opaque black).
    pub fn to_rgba8(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.data.len() / 3 * 4);
        for px in self.data.chunks_exact(3) {
            out.extend(px.iter().map(|&c| to_u8(c)));
            out.push(255);
        }
        out
    }
}

/// `floor(clamp(c, 0, 1) · 255 + 0.5)`; the float-to-int cast maps NaN to 0.
#[inline]
fn to_u8(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0 + 0.5).floor() as u8
}

/// Render `scene` at `width × height` on the CPU.
///
/// Any output size is allowed: geometry is normalized, so another size samples the same
/// continuous image at other pixel centres. The only refusal is an empty size
/// ([`ErrorKind::InvalidValue`]) or one whose buffer cannot be addressed
/// ([`ErrorKind::LimitExceeded`]); a caller rendering untrusted files checks
/// [`Limits::check_output`] first, since this function allocates `width·height·12` bytes.
///
/// With the `parallel` feature, tile rows are spread over rayon's pool; the result is
/// bit-identical to the sequential build.
pub fn render(scene: &Scene, width: u32, height: u32) -> Result<RgbImage> {
    let len = buffer_len(width, height)?;
    let mut data = vec![0.0; len];
    render_into(scene, width, height, &mut data)?;
    Ok(RgbImage {
        width,
        height,
        data,
    })
}

/// Render into a caller-provided buffer of exactly `width * height * 3` floats
/// (overwritten, not accumulated into), so that repeated renders reuse one allocation.
pub fn render_into(scene: &Scene, width: u32, height: u32, out: &mut [f32]) -> Result<()> {
    let len = buffer_len(width, height)?;
    if out.len() != len {
        return Err(Error::new(
            ErrorKind::InvalidValue,
            format!(
                "output buffer holds {} floats, {width}x{height} RGB needs {len}",
                out.len()
            ),
        ));
    }
    if !scene.gaussians.is_consistent() {
        return Err(Error::new(
            ErrorKind::InvalidValue,
            "Gaussian attribute vectors have different lengths",
        ));
    }
    if u32::try_from(scene.gaussians.len()).is_err() {
        // Tile lists hold `u32` indices.
        return Err(Error::new(
            ErrorKind::LimitExceeded,
            "more than 2^32 - 1 Gaussians",
        ));
    }
    let projected = project_scene(scene, width, height);
    cpu::render_projected(
        &projected,
        scene.blend,
        width,
        height,
        out,
        cfg!(feature = "parallel"),
    );
    Ok(())
}

/// Number of floats of a `width × height` RGB buffer, refusing empty or unaddressable sizes.
fn buffer_len(width: u32, height: u32) -> Result<usize> {
    Limits::unlimited().check_output(width, height)?;
    usize::try_from(u64::from(width) * u64::from(height))
        .ok()
        .and_then(|px| px.checked_mul(3))
        .ok_or_else(|| {
            Error::new(
                ErrorKind::LimitExceeded,
                format!("output {width}x{height} does not fit in memory"),
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn to_u8_rounds_half_up_after_clamping() {
        let cases = [
            (-1.0, 0),
            (0.0, 0),
            (0.25, 64),
            (0.5, 128),
            (1.0, 255),
            (7.0, 255),
            (f32::NAN, 0),
            (f32::NEG_INFINITY, 0),
            (f32::INFINITY, 255),
        ];
        for (c, want) in cases {
            assert_eq!(to_u8(c), want, "{c}");
        }
    }

    #[test]
    fn buffer_len_refuses_empty_sizes() {
        assert_eq!(
            buffer_len(0, 5).unwrap_err().kind(),
            ErrorKind::InvalidValue
        );
        assert_eq!(
            buffer_len(5, 0).unwrap_err().kind(),
            ErrorKind::InvalidValue
        );
        assert_eq!(buffer_len(2, 3).unwrap(), 18);
    }
}
