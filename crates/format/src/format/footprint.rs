//! Colour precision by footprint (spec §5.4.6): how finely a Gaussian's colour is stored,
//! from its own two log-scales.
//!
//! In `sum` blending a colour error `δ` on a Gaussian of peak weight 1 adds `δ²·π·s1·s2`
//! of squared error over the plane: a Gaussian four times the area spreads its rounding
//! over four times the pixels. One step for every colour gives the large Gaussians most
//! of the noise and the small ones more precision than they can show. Method 5 stores
//! `c·2^k` on one uniform grid, with the class `k = clamp(floor(⅜·log2(s1·s2)) − base, 0,
//! 7)`, so that a Gaussian's step falls as `(s1·s2)^(−3/8)`; and it keeps the coder's
//! adaptive contexts per class, because the stored values of small and large Gaussians
//! spread differently.
//!
//! Why ⅜ and not the ½ at which every colour would add the same noise: the encoder rounds
//! the colours largest first and solves the smaller ones again for what the rounding left
//! (`gsi_fit`'s compensated rounding), so the large Gaussians' rounding already costs less
//! than their footprint says, and the small ones', rounded last, the most. On the
//! validation images at 1 bpp (photos12 and LOL eval15's normal-light images, against
//! colours on one grid): ½ gained +0.05 dB, ⅜ +0.09, ¼ +0.03 (BENCHMARKS.md).
//!
//! The class is exact binary64 arithmetic on the dequantized scales (§5.2), one product
//! and a `floor`, and the scaling is by a power of two, exact in binary32: every decoder
//! gets the same colours.

use super::error::{invalid, Result};
use super::quant::Quantizer;

/// Classes of §5.4.6: `k` in `0..CLASSES`, a step `2^−k` of the stored grid's.
pub const CLASSES: usize = 8;

/// `3 / (8·ln 2)`, rounded to binary64: `⅜·log2` of `s1·s2` per unit of `ln s1 + ln s2`.
pub const SIZE_PER_LOG_SCALE: f64 = 0.5410106403333613;

/// `floor((p0 + p1)·SIZE_PER_LOG_SCALE)`, `floor(⅜·log2(s1·s2))`, of each Gaussian of a
/// `log-scale-rotation` covariance, clamped to `±256` (where every base gives the same
/// class); an error for an attribute that is not of three components.
/// `qs` and `codes` are the covariance attribute's quantizers and planar codes.
pub fn sizes(qs: &[Quantizer], codes: &[u32]) -> Result<Vec<i32>> {
    if qs.len() != 3 || codes.len() % 3 != 0 {
        return Err(invalid(format!(
            "colours by footprint need a covariance of 3 components, not {}",
            qs.len()
        )));
    }
    let n = codes.len() / 3;
    let v0 = qs[0].lookup(n, |c| qs[0].dequantize(c));
    let v1 = qs[1].lookup(n, |c| qs[1].dequantize(c));
    Ok((0..n)
        .map(|i| size_of(v0.get(codes[i]), v1.get(codes[n + i])))
        .collect())
}

/// [`sizes`] of one Gaussian from its (dequantized) log-scales.
#[inline]
pub fn size_of(p0: f32, p1: f32) -> i32 {
    ((f64::from(p0) + f64::from(p1)) * SIZE_PER_LOG_SCALE)
        .clamp(-256.0, 256.0)
        .floor() as i32
}

/// The class of a Gaussian of `size` ([`sizes`]) under a file's `base`.
#[inline]
pub fn class(size: i32, base: i8) -> u8 {
    (size - i32::from(base)).clamp(0, CLASSES as i32 - 1) as u8
}

/// The classes of Gaussians of `sizes` under `base`.
pub fn classes(sizes: &[i32], base: i8) -> Vec<u8> {
    sizes.iter().map(|&s| class(s, base)).collect()
}

/// `2^k`: what the stored value of a colour of class `k` is, times the colour.
#[inline]
pub fn gain(class: u8) -> f32 {
    f32::from(1u8 << class.min(CLASSES as u8 - 1))
}

/// `2^−k`, exact: the colour of a stored value of class `k`, per unit.
#[inline]
pub fn step(class: u8) -> f32 {
    1.0 / gain(class)
}

/// The base the reference encoder writes: three classes below the median size, so that
/// the median Gaussian takes class 3 and the classes reach from an eighth of its side
/// to sixteen times it.
pub fn base_for(sizes: &[i32]) -> i8 {
    if sizes.is_empty() {
        return 0;
    }
    let mut s = sizes.to_vec();
    let mid = s.len() / 2;
    let (_, median, _) = s.select_nth_unstable(mid);
    (*median - 3).clamp(i32::from(i8::MIN), i32::from(i8::MAX)) as i8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_three_eighths_log2_of_the_area_floored() {
        let exact = 3.0 / (8.0 * std::f64::consts::LN_2);
        assert!((SIZE_PER_LOG_SCALE / exact - 1.0).abs() < 1e-16);
        // The worked example of §9.4: log-scales −8 and −8, −4 and −4, −1 and −1.
        assert_eq!(
            [
                size_of(-8.0, -8.0),
                size_of(-4.0, -4.0),
                size_of(-1.0, -1.0)
            ],
            [-9, -5, -2]
        );
        // `floor`, not truncation: just below −3 is −4.
        let p = -2.7725887f32;
        assert!((f64::from(p) * 2.0 * SIZE_PER_LOG_SCALE) < -3.0);
        assert_eq!(size_of(p, p), -4);
        assert_eq!(size_of(-2.772588, -2.772588), -3);
        assert_eq!(size_of(f32::MAX, f32::MAX), 256);
        assert_eq!(size_of(f32::MIN, 0.0), -256);
        assert_eq!(class(-5, -9), 4);
        assert_eq!(class(-50, -9), 0);
        assert_eq!(class(50, -9), 7);
        assert_eq!(gain(3) * step(3), 1.0);
    }

    #[test]
    fn the_base_puts_the_median_in_class_3() {
        assert_eq!(base_for(&[-9, -7, -6, -5, -2]), -9);
        assert_eq!(base_for(&[]), 0);
        assert_eq!(base_for(&[-256, -256]), i8::MIN);
    }

    #[test]
    fn sizes_need_three_components() {
        let q = Quantizer::fit(4, [0.0f32, 1.0]);
        assert!(sizes(&[q, q], &[0, 15]).is_err());
        assert_eq!(sizes(&[q, q, q], &[0, 15, 3]).unwrap().len(), 1);
    }
}
