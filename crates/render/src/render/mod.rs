//! Gaussians to pixels.
//!
//! Rendering is defined per pixel by `format-spec.md` §6, in `f32` and in a fixed order,
//! so that every renderer of this crate (this CPU one, a GPU one, a differentiable one)
//! agrees on what a file *means*. The pieces are kept apart for that reason:
//!
//! * [`project`]: per-Gaussian preprocessing into pixel space ([`Projected`]). It is the
//!   only place where a covariance becomes a conic and a pixel box, so other renderers
//!   reuse it rather than re-deriving the clamps.
//! * [`Projected::alpha_at`]: the per-pixel rule, written once, readably, and
//!   [`Projected::weight_at`]: the column rule of files with `GCRW` or `GCRT` (§6.3.2),
//!   as plainly.
//! * `tiles`, `cpu` and `lanes`: the CPU renderer. Tiles only decide *which* Gaussians a
//!   pixel visits (those whose pixel box holds it), never in what order, and `lanes`
//!   evaluates eight pixels at once with the same binary32 operations, so the tiled result
//!   is bit-identical to a naive loop over all Gaussians for every pixel, by either rule.
//!
//! Without a tone curve the output is linear in the stored (sRGB-encoded) colour values
//! and is not clamped: `sum` blending may overshoot `[0, 1]`, and a caller that
//! post-processes (enhancement, metrics) wants to see that. [`RgbImage::to_rgb8`] is
//! where clamping happens. A scene with a tone curve (spec §6.6, written by stage 2)
//! shows every blended value through it, in `[0, 1]`.

mod cpu;
#[doc(hidden)]
pub mod lanes;
mod project;
mod rounding;
mod tiles;

/// The output layouts [`render_as`] writes, for the decoder API's own limits.
#[doc(hidden)]
pub use cpu::{Rgb8 as Rgb8Out, RgbF32Bytes as RgbF32BytesOut, Rgba8 as Rgba8Out};

#[cfg(feature = "encode")]
#[doc(hidden)]
pub use project::Rect;
pub use project::{project, project_scene, PixelBox, Projected};
#[cfg(any(feature = "encode", feature = "gpu"))]
#[doc(hidden)]
pub use tiles::TileLists;

use gsi_format::format::{Error, ErrorKind, Limits, Result};
use gsi_format::model::Scene;
use std::borrow::Borrow;

/// Side of a square tile, in pixels.
pub const TILE: u32 = 16;
/// Pixel rows of a band of the CPU renderer, whose tiles are [`TILE`] columns by `BAND`
/// rows: the column rule's bands in files written now (`GCRT`, spec §6.3.2), so that
/// each column of a tile starts from `E` once; a `GCRW` file's columns start again at
/// the tile's row 16. (Bands and rule of 64 rows decoded kodim23 0.13 ms faster and
/// kodim13 0.17 ms slower than 32, for weights carried twice as far.)
pub const BAND: u32 = 32;

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
    /// An image from 8-bit RGB samples (`width·height·3` of them, rows top to bottom),
    /// each `v / 255` in `f32`: how every front end (the command-line tool, the Python
    /// package) hands an 8-bit image to the encoder, so that the same pixels give the same
    /// file. `None` where the count does not match the size.
    pub fn from_rgb8(width: u32, height: u32, samples: &[u8]) -> Option<RgbImage> {
        Self::from_samples(width, height, samples, |v| f32::from(v) / 255.0)
    }

    /// An image from 16-bit RGB samples, each `v / 65535` in `f32` (as [`Self::from_rgb8`]).
    pub fn from_rgb16(width: u32, height: u32, samples: &[u16]) -> Option<RgbImage> {
        Self::from_samples(width, height, samples, |v| f32::from(v) / 65535.0)
    }

    fn from_samples<T: Copy>(
        width: u32,
        height: u32,
        samples: &[T],
        to_f32: impl Fn(T) -> f32,
    ) -> Option<RgbImage> {
        let n = (width as usize)
            .checked_mul(height as usize)?
            .checked_mul(3)?;
        (samples.len() == n).then(|| RgbImage {
            width,
            height,
            data: samples.iter().map(|&v| to_f32(v)).collect(),
        })
    }

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

/// `floor(clamp(c, 0, 1) · 255 + 0.5)`, NaN to 0.
#[inline]
#[doc(hidden)]
// `clamp` keeps NaN, which the conversion below must not see.
#[allow(clippy::manual_clamp)]
pub fn to_u8(c: f32) -> u8 {
    // `max` and `min` take NaN to 0, so the value lies in `[0.5, 255.5]`, where
    // truncation is `floor`. A plain conversion without the checks of a saturating cast
    // (which the range makes moot) is what lets a loop over a band use SIMD: a 12-MP
    // decode spent a tenth of its time here, one value at a time.
    let v = c.max(0.0).min(1.0) * 255.0 + 0.5;
    // SAFETY: `v` is finite and in `[0.5, 255.5]`, inside `i32`'s range.
    unsafe { v.to_int_unchecked::<i32>() as u8 }
}

/// Render `scene` at `width × height` on the CPU.
///
/// Any output size is allowed: geometry is normalized, so another size samples the same
/// continuous image at other pixel centres. Refused: an empty size
/// ([`ErrorKind::InvalidValue`]), or one over the default [`Limits`]' `max_output_pixels`,
/// `max_alloc` for the `width·height·12` bytes this allocates, or `max_render_work`
/// for the Gaussian–pixel pairs it would evaluate ([`ErrorKind::LimitExceeded`]) — the
/// bounds the GPU renderer applies too. To render with other limits, or into 8 bits
/// without the `f32` image, use [`crate::decode::Reader`] or the `render_*_into` functions with a
/// buffer of your own (which apply the default limits' work bound).
///
/// With the `parallel` feature, tile rows are spread over rayon's pool; the result is
/// bit-identical to the sequential build.
pub fn render(scene: &Scene, width: u32, height: u32) -> Result<RgbImage> {
    let limits = Limits::default();
    let mut data = allocate(width, height, 3, 4, &limits)?;
    render_as::<cpu::RgbF32>(scene, width, height, &mut data, &limits)?;
    Ok(RgbImage {
        width,
        height,
        data,
    })
}

/// 8-bit RGB of `scene` at `width × height` in a new buffer (the values
/// [`RgbImage::to_rgb8`] gives, with no `f32` image made), refused over `limits`: the
/// output's pixels, and its `width·height·3` bytes against `max_alloc`.
pub fn render_rgb8(scene: &Scene, width: u32, height: u32, limits: &Limits) -> Result<Vec<u8>> {
    let mut rgb = allocate(width, height, 3, 1, limits)?;
    render_as::<cpu::Rgb8>(scene, width, height, &mut rgb, limits)?;
    Ok(rgb)
}

/// A zeroed buffer of `per_pixel` values of `bytes` bytes each for a `width × height`
/// output, after checking its size and its allocation against `limits`.
fn allocate<T: Clone + Default>(
    width: u32,
    height: u32,
    per_pixel: usize,
    bytes: u64,
    limits: &Limits,
) -> Result<Vec<T>> {
    let len = buffer_len(width, height, per_pixel, limits)?;
    limits.check_alloc(len as u64 * bytes, "the rendered image")?;
    Ok(vec![T::default(); len])
}

/// Render into a caller-provided buffer of exactly `width * height * 3` floats
/// (overwritten, not accumulated into), so that repeated renders reuse one allocation.
pub fn render_into(scene: &Scene, width: u32, height: u32, out: &mut [f32]) -> Result<()> {
    render_as::<cpu::RgbF32>(scene, width, height, out, &Limits::default())
}

/// Render into a caller's buffer of exactly `width * height * 3` bytes of 8-bit RGB, the
/// values [`RgbImage::to_rgb8`] gives. Tiles are blended in a band-sized scratch buffer
/// and written straight into `out`: no whole-image `f32` copy is made.
pub fn render_rgb8_into(scene: &Scene, width: u32, height: u32, out: &mut [u8]) -> Result<()> {
    render_as::<cpu::Rgb8>(scene, width, height, out, &Limits::default())
}

/// As [`render_rgb8_into`], in 8-bit RGBA (`width * height * 4` bytes, alpha 255).
pub fn render_rgba8_into(scene: &Scene, width: u32, height: u32, out: &mut [u8]) -> Result<()> {
    render_as::<cpu::Rgba8>(scene, width, height, out, &Limits::default())
}

/// As [`render_into`], with the floats written as native-endian bytes
/// (`width * height * 12`), for byte-typed buffers.
pub fn render_f32_bytes_into(scene: &Scene, width: u32, height: u32, out: &mut [u8]) -> Result<()> {
    render_as::<cpu::RgbF32Bytes>(scene, width, height, out, &Limits::default())
}

/// The Gaussian–pixel pairs a render of `proj` evaluates at most: the pixels of every
/// Gaussian's box (already cut to the output), summed, saturating.
pub fn render_work(proj: &[Projected]) -> u64 {
    proj.iter()
        .map(|p| {
            let b = &p.bbox;
            u64::from(b.x1 - b.x0 + 1) * u64::from(b.y1 - b.y0 + 1)
        })
        .fold(0u64, u64::saturating_add)
}

/// Check `scene` and `out`, project, check the work against `limits`, and render in
/// `O`'s layout.
#[doc(hidden)]
pub fn render_as<O: cpu::Output>(
    scene: &Scene,
    width: u32,
    height: u32,
    out: &mut [O::Elem],
    limits: &Limits,
) -> Result<()> {
    let len = buffer_len(width, height, O::PER_PIXEL, &Limits::unlimited())?;
    if out.len() != len {
        return Err(Error::new(
            ErrorKind::InvalidValue,
            format!(
                "output buffer holds {} values, {width}x{height} needs {len}",
                out.len()
            ),
        ));
    }
    let projected = checked_projection(scene, width, height, limits)?;
    let parallel = cfg!(feature = "parallel");
    cpu::render_projected::<O>(
        &projected,
        (scene.blend, scene.weights),
        scene.tone.as_ref(),
        (width, height),
        out,
        parallel,
    );
    Ok(())
}

/// 8-bit RGB of `scene` at `width × height`, handed to `sink` in steps of whole rows, top
/// to bottom (three bands of [`BAND`] rows a step per thread, at most 512 rows): the bytes
/// [`render_rgb8`] gives, in memory that does not grow with the output, so that a decode
/// written out as it is rendered (a PPM, say) never holds the whole image. Refused over
/// `limits` as [`render_rgb8`] is; the first error `sink` returns stops the render and
/// comes back as an [`ErrorKind::Io`] error.
///
/// `scene` may be given by value (or as `&Scene`): owned, it is freed once projected, so
/// that the rows rendered at a time reuse its memory rather than fault in fresh pages
/// (a decode's dequantized attributes are about as large as its window).
///
/// ```
/// # use gsi_format::model::Blend;
/// # let scene = gsi_synth::random_scene(1, gsi_synth::SceneSpec::new(64, 48, 50, Blend::Sum));
/// // A binary PPM is its header and then its rows: write them as they come.
/// let mut ppm = b"P6\n640 480\n255\n".to_vec();
/// gsi_render::render::render_rgb8_rows(&scene, 640, 480, &Default::default(), |rows| {
///     ppm.extend_from_slice(rows); // or `file.write_all(rows)`
///     Ok(())
/// })?;
/// assert_eq!(ppm.len(), 15 + 640 * 480 * 3);
/// # Ok::<(), gsi_format::format::Error>(())
/// ```
pub fn render_rgb8_rows(
    scene: impl Borrow<Scene>,
    width: u32,
    height: u32,
    limits: &Limits,
    mut sink: impl FnMut(&[u8]) -> std::io::Result<()>,
) -> Result<()> {
    let row = buffer_len(width, 1, 3, &Limits::unlimited())?;
    limits.check_output(width, height)?;
    let parallel = cfg!(feature = "parallel");
    let bands = cpu::window_bands(parallel).min(height.div_ceil(BAND) as usize);
    let window_len = row * BAND.min(height) as usize * bands;
    limits.check_alloc(window_len as u64, "the rows rendered at a time")?;
    let s = scene.borrow();
    let projected = checked_projection(s, width, height, limits)?;
    let (blend, weights, tone) = (s.blend, s.weights, s.tone.clone());
    drop(scene);
    let mut window = vec![0u8; window_len];
    cpu::render_projected_rows::<cpu::Rgb8>(
        &projected,
        (blend, weights),
        tone.as_ref(),
        (width, height),
        &mut window,
        parallel,
        &mut sink,
    )?;
    Ok(())
}

/// The Gaussians of `scene` projected for a `width × height` output, after checking the
/// scene and the render's work against `limits`.
fn checked_projection(
    scene: &Scene,
    width: u32,
    height: u32,
    limits: &Limits,
) -> Result<Vec<Projected>> {
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
    limits.check_render_work(render_work(&projected), width, height)?;
    Ok(projected)
}

/// Number of values of a `width × height` buffer of `per_pixel` values, refusing empty
/// sizes, sizes over `limits` and unaddressable ones.
#[doc(hidden)]
pub fn buffer_len(width: u32, height: u32, per_pixel: usize, limits: &Limits) -> Result<usize> {
    limits.check_output(width, height)?;
    usize::try_from(u64::from(width) * u64::from(height))
        .ok()
        .and_then(|px| px.checked_mul(per_pixel))
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

    /// Rows handed out a window at a time are the bytes of the whole-image render, for
    /// heights within one window, over several, and not a multiple of a band, and with
    /// the scene given by value; a sink's error ends the render and comes back.
    #[test]
    fn rows_in_windows_are_the_whole_image() {
        use gsi_format::model::{Blend, WeightRule};
        use gsi_synth::{random_scene, SceneSpec};
        for blend in [Blend::Sum, Blend::Alpha] {
            for rule in [
                WeightRule::PerPixel,
                WeightRule::Columns,
                WeightRule::Columns32,
            ] {
                let mut spec = SceneSpec::new(60, 90, 300, blend);
                spec.sigma_px = (0.3, 30.0);
                spec.weights = rule;
                let scene = random_scene(7, spec);
                for (w, h) in [(1, 1), (60, 90), (37, 300), (5, 129), (90, 16)] {
                    let limits = Limits::default();
                    let whole = render_rgb8(&scene, w, h, &limits).unwrap();
                    let mut rows = Vec::new();
                    let mut steps = 0;
                    render_rgb8_rows(&scene, w, h, &limits, |step| {
                        assert_eq!(step.len() % (w as usize * 3), 0);
                        rows.extend_from_slice(step);
                        steps += 1;
                        Ok(())
                    })
                    .unwrap();
                    assert!(whole.iter().any(|&v| v != 0));
                    assert!(rows == whole, "{blend:?} {rule:?} {w}x{h}");
                    let bands = cpu::window_bands(cfg!(feature = "parallel"));
                    assert_eq!(steps, (h as usize).div_ceil(BAND as usize * bands));
                }
                // Given by value (freed once projected): the same rows.
                let mut owned = Vec::new();
                render_rgb8_rows(scene.clone(), 37, 300, &Limits::default(), |step| {
                    owned.extend_from_slice(step);
                    Ok(())
                })
                .unwrap();
                assert!(owned == render_rgb8(&scene, 37, 300, &Limits::default()).unwrap());
                let mut calls = 0;
                let err = render_rgb8_rows(&scene, 40, 400, &Limits::default(), |_| {
                    calls += 1;
                    Err(std::io::Error::other("disk full"))
                })
                .unwrap_err();
                assert_eq!((err.kind(), calls), (ErrorKind::Io, 1));
            }
        }
    }

    #[test]
    fn rows_are_refused_over_the_limits() {
        use gsi_format::model::Blend;
        use gsi_synth::{random_scene, SceneSpec};
        let scene = random_scene(1, SceneSpec::new(8, 8, 10, Blend::Sum));
        let small = Limits {
            max_output_pixels: 100,
            ..Limits::default()
        };
        let err = render_rgb8_rows(&scene, 20, 20, &small, |_| Ok(())).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::LimitExceeded);
        let err = render_rgb8_rows(&scene, 0, 20, &Limits::default(), |_| Ok(())).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::InvalidValue);
    }

    #[test]
    fn buffer_len_refuses_empty_sizes() {
        let any = Limits::unlimited();
        assert_eq!(
            buffer_len(0, 5, 3, &any).unwrap_err().kind(),
            ErrorKind::InvalidValue
        );
        assert_eq!(
            buffer_len(5, 0, 3, &any).unwrap_err().kind(),
            ErrorKind::InvalidValue
        );
        assert_eq!(buffer_len(2, 3, 3, &any).unwrap(), 18);
        assert_eq!(buffer_len(2, 3, 4, &any).unwrap(), 24);
        let small = Limits {
            max_output_pixels: 5,
            ..Limits::default()
        };
        assert_eq!(
            buffer_len(2, 3, 3, &small).unwrap_err().kind(),
            ErrorKind::LimitExceeded
        );
    }
}
