//! Differentiable SSIM and MS-SSIM losses for fitting an image (the encoder's objective).
//!
//! Images are **interleaved RGB**, row-major, three values per pixel in `[0, 1]` (the
//! layout of [`gsi_render::render::render_into`]), so a render can be scored without copying.
//! The data range is 1, so `C1 = 0.01²`, `C2 = 0.03²`.
//!
//! The arithmetic is the metrics' own (`ssim.rs`): the same window, the same "valid"
//! region (no padding: the map covers the pixels at least 5 from every edge, exactly
//! scikit-image's crop), the same MS-SSIM pyramid and weights. A pixel near an edge
//! still receives gradient, through the windows that cover it. The loss is therefore
//! `1 − ssim(..)` of the metric up to 8-bit quantisation and `f32` rounding.
//!
//! Cost: five Gaussian-filtered planes forward and three adjoint filterings backward per
//! channel, each two separable 11-tap passes (`O(pixels · 11)`).

use super::filter::{Pool, Real};
use super::ssim::{backward, ms_ssim_plane, stats};
use super::{MetricError, WINDOW};

/// Check the shapes of both interleaved images.
fn check<T: Real>(img: &[T], reference: &[T], w: u32, h: u32) -> Result<(), MetricError> {
    if w == 0 || h == 0 {
        return Err(MetricError::Empty);
    }
    let expected = w as usize * h as usize * 3;
    for len in [img.len(), reference.len()] {
        if len != expected {
            return Err(MetricError::BufferLength {
                expected,
                actual: len,
            });
        }
    }
    if w < WINDOW || h < WINDOW {
        return Err(MetricError::TooSmall {
            width: w,
            height: h,
            min: WINDOW,
        });
    }
    Ok(())
}

/// Buffers of the SSIM and MS-SSIM losses kept between calls.
///
/// A fit evaluates the loss every iteration on images of one size; keeping the dozen
/// plane-sized buffers the computation needs saves their allocation and, more, the
/// zeroing of fresh pages by the system (about a third of the time at 768×512). The
/// free functions [`ssim_loss_grad`] and [`ms_ssim_loss_grad`] use a fresh workspace.
pub struct LossWorkspace<T> {
    pool: Pool<T>,
}

impl<T: Real> Default for LossWorkspace<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> LossWorkspace<T> {
    pub fn new() -> Self {
        LossWorkspace { pool: Pool::new() }
    }

    /// [`ssim_loss_grad`] writing the gradient into `grad` (same length as `img`,
    /// overwritten) and returning the loss.
    pub fn ssim_loss_grad(
        &mut self,
        img: &[T],
        reference: &[T],
        w: u32,
        h: u32,
        grad: &mut [T],
    ) -> Result<T, MetricError> {
        let (wu, hu) = (w as usize, h as usize);
        self.channel_by_channel(img, reference, w, h, grad, |x, y, g, pool| {
            let st = stats(x, y, wu, hu, 1.0, pool);
            backward(&st, x, y, 1.0, -1.0 / 3.0, 0.0, g, pool);
            let v = st.ssim;
            st.recycle(pool);
            v
        })
    }

    /// [`ms_ssim_loss_grad`] writing the gradient into `grad` (same length as `img`,
    /// overwritten) and returning the loss.
    pub fn ms_ssim_loss_grad(
        &mut self,
        img: &[T],
        reference: &[T],
        w: u32,
        h: u32,
        grad: &mut [T],
    ) -> Result<T, MetricError> {
        let (wu, hu) = (w as usize, h as usize);
        self.channel_by_channel(img, reference, w, h, grad, |x, y, g, pool| {
            ms_ssim_plane(x, y, wu, hu, 1.0, Some((g, -1.0 / 3.0)), pool)
        })
    }

    /// Run `per_channel(x, y, grad, pool)` on each channel in turn (one channel's
    /// planes live at a time) and return `1 − mean` of its values, the gradient
    /// interleaved into `out`.
    fn channel_by_channel(
        &mut self,
        img: &[T],
        reference: &[T],
        w: u32,
        h: u32,
        out: &mut [T],
        per_channel: impl Fn(&[T], &[T], &mut [T], &mut Pool<T>) -> f64,
    ) -> Result<T, MetricError> {
        check(img, reference, w, h)?;
        if out.len() != img.len() {
            return Err(MetricError::BufferLength {
                expected: img.len(),
                actual: out.len(),
            });
        }
        let pool = &mut self.pool;
        let n = w as usize * h as usize;
        let (mut x, mut y, mut grad) = (pool.take(n), pool.take(n), pool.take(n));
        let mut total = 0.0;
        for c in 0..3 {
            for (d, px) in x.iter_mut().zip(img.chunks_exact(3)) {
                *d = px[c];
            }
            for (d, px) in y.iter_mut().zip(reference.chunks_exact(3)) {
                *d = px[c];
            }
            grad.fill(T::default());
            total += per_channel(&x, &y, &mut grad, pool);
            for (px, &g) in out.chunks_exact_mut(3).zip(&grad) {
                px[c] = g;
            }
        }
        for v in [x, y, grad] {
            pool.put(v);
        }
        Ok(T::from_f64(1.0 - total / 3.0))
    }
}

/// `1 − SSIM(img, reference)` (mean over the three channels) and its gradient with
/// respect to `img`, interleaved like `img`.
///
/// Both images are `w × h` interleaved RGB in `[0, 1]`, at least 11×11. Generic over
/// `f32` and `f64`; each row's sums are widened to `f64` for the mean. A fit that calls
/// this every iteration should keep a [`LossWorkspace`] instead.
pub fn ssim_loss_grad<T: Real>(
    img: &[T],
    reference: &[T],
    w: u32,
    h: u32,
) -> Result<(T, Vec<T>), MetricError> {
    let mut grad = vec![T::default(); img.len()];
    let loss = LossWorkspace::new().ssim_loss_grad(img, reference, w, h, &mut grad)?;
    Ok((loss, grad))
}

/// `1 − MS-SSIM(img, reference)` (mean over the three channels) and its gradient, with the
/// conventions of [`ms_ssim`](super::ms_ssim): five scales when the smaller side is at
/// least 176 pixels, otherwise the scales that fit with renormalised weights (under 22
/// pixels this is exactly [`ssim_loss_grad`]). Where a channel's mean cs or SSIM at some
/// scale is ≤ 0 (images anti-correlated at that scale) its MS-SSIM is clamped to 0 and
/// contributes no gradient; mixing in an L1 or L2 term, as encoders usually do, covers it.
pub fn ms_ssim_loss_grad<T: Real>(
    img: &[T],
    reference: &[T],
    w: u32,
    h: u32,
) -> Result<(T, Vec<T>), MetricError> {
    let mut grad = vec![T::default(); img.len()];
    let loss = LossWorkspace::new().ms_ssim_loss_grad(img, reference, w, h, &mut grad)?;
    Ok((loss, grad))
}
