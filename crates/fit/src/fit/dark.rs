//! A dark image is fitted at the level of a well-exposed one.
//!
//! The fit's fixed quantities are set for images that span the display range: Adam moves
//! a colour by up to its learning rate per step, a Gaussian whose whole contribution is
//! under one 8-bit step is dropped, re-placement samples where the squared error is
//! largest. A low-light photograph uses a fraction of that range (LOL's low images reach
//! 0.10–0.59 at their 99.9th percentile), so every colour step is several times too
//! coarse and much of its shadows falls under the pruning threshold: the Gaussians go
//! where the brighter pixels are, and the shadows get few. That costs the file some
//! fidelity, and stage 2 much more: brightening makes the shadows the larger part of
//! what is seen, and stage 2 cannot move a Gaussian.
//!
//! Both blend modes render a linear function of the colours, so a fit of the image
//! multiplied by a gain `k` is a fit of the image itself with every colour multiplied
//! by `k`, its thresholds taken at `1/k` of their value. [`super::encode`] therefore
//! fits the brightened copy, divides the colours by `k` before storing them, and solves
//! them once more against the image as it is. The gain brings the image's bright end
//! (its [`HIGH_QUANTILE`] of channel values) to full scale, as a levels tool stretches a
//! histogram. Nothing is clipped: the values above that quantile go above 1 in the copy,
//! and the fit still sees them.
//!
//! Measured on LOL eval15 and the synthetic low-light Kodak set (BENCHMARKS.md, session
//! 17): the stored file's PSNR against the dark image rose by 0.75 and 0.66 dB, and the
//! enhanced file's SSIM against the references by 0.038 and 0.048. A gain that brings
//! the mean to Kodak's instead did as well on LOL and less well on the synthetic set.

use super::Target;

/// The share of an image's channel values at or below its bright end. Not the maximum:
/// a lit lamp or a few hot pixels would keep the gain at 1 for the whole image.
pub const HIGH_QUANTILE: f64 = 0.999;

/// The least gain that is applied: one stop, the rule by which stage 2 calls an image
/// low-light. An image whose bright end reaches half of full scale is fitted as it is,
/// so every normally exposed photograph keeps its bytes (Kodak's 99.9th percentiles are
/// 0.96 and above).
pub const MIN_GAIN: f32 = 2.0;

/// The largest gain: four stops, which brings LOL's darkest low image (99.9th percentile
/// 0.098) to full scale. A black image stays black at any gain.
pub const MAX_GAIN: f32 = 16.0;

/// The gain at which `target` is fitted: 1 where its bright end reaches half of full
/// scale, else the gain that brings it to full scale, at most [`MAX_GAIN`]. Values that
/// are negative or not finite count as 0.
pub fn gain(target: &Target) -> f32 {
    let value = |x: &f32| if x.is_finite() { x.max(0.0) } else { 0.0 };
    let n = target.data.len();
    if n == 0 {
        return 1.0;
    }
    let rank = ((n - 1) as f64 * HIGH_QUANTILE).round() as usize;
    // The bright end reaches 1/MIN_GAIN exactly when at most `rank` values lie below it:
    // a count, with no copy, settles every normally exposed image.
    let below = target
        .data
        .iter()
        .filter(|x| value(x) * MIN_GAIN < 1.0)
        .count();
    if below <= rank {
        return 1.0;
    }
    let mut v: Vec<f32> = target.data.iter().map(value).collect();
    let (_, &mut high, _) = v.select_nth_unstable_by(rank, f32::total_cmp);
    (1.0 / high).min(MAX_GAIN)
}

/// `target` with every value multiplied by `k`.
pub fn brightened(target: &Target, k: f32) -> Target {
    Target {
        width: target.width,
        height: target.height,
        data: target.data.iter().map(|x| x * k).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(v: f32, n: usize) -> Target {
        Target {
            width: n as u32,
            height: 1,
            data: vec![v; 3 * n],
        }
    }

    #[test]
    fn the_gain_brings_the_bright_end_to_full_scale() {
        assert_eq!(gain(&flat(0.6, 100)), 1.0);
        assert_eq!(gain(&flat(0.5, 100)), 1.0);
        assert_eq!(gain(&flat(0.25, 100)), 4.0);
        // Black, nearly black, empty and broken images: finite, within bounds.
        assert_eq!(gain(&flat(0.0, 100)), MAX_GAIN);
        assert_eq!(gain(&flat(1e-9, 100)), MAX_GAIN);
        assert_eq!(gain(&flat(0.0, 0)), 1.0);
        assert_eq!(gain(&flat(f32::NAN, 10)), MAX_GAIN);
        assert_eq!(gain(&flat(f32::INFINITY, 10)), MAX_GAIN);
        assert_eq!(gain(&flat(-1.0, 10)), MAX_GAIN);
    }

    #[test]
    fn a_few_bright_pixels_do_not_hold_the_gain_back() {
        // One hot pixel in a thousand: the bright end is the scene's.
        let mut t = flat(0.1, 1000);
        t.data[..3].fill(1.0);
        assert!((gain(&t) - 10.0).abs() < 1e-5, "{}", gain(&t));
        // A lit window of 1 % holds it.
        t.data[..30].fill(1.0);
        assert_eq!(gain(&t), 1.0);
    }
}
