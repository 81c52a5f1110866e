//! The colour depth of a `sum` file, chosen from the fit that it stores.
//!
//! Within a byte budget a colour bit is paid for in Gaussians: one bit fewer on each of
//! the three channels buys about 3/β more of them (β bits per Gaussian), and more
//! Gaussians lower the fit's error. One bit fewer also quadruples the quantization noise.
//! The two balance where the noise is a fixed share of the fit's error: with the fit's
//! mean squared error falling as `N^−γ` and the noise as `Δ²`, the total is least where
//!
//! ```text
//! noise = 3·γ / (2·β·ln 2) · fit error
//! ```
//!
//! (differentiate `D(N(Δ)) + noise(Δ)` with `N = budget / β(Δ)` and `dβ/dΔ = −3/(Δ ln 2)`).
//! With γ = 0.9 (doubling the Gaussians buys about 2.7 dB at 1 bpp) and β ≈ 45, the noise
//! should be about 4 % of the error: a photograph fitted to 23 dB (texture the Gaussians
//! cannot follow) wants steps four times coarser than one fitted to 35 dB, where a single
//! depth for every image would spend the same bits on both. The rule is a slope and a
//! ratio, not a table fitted to a set of images.
//!
//! The noise of `sum` blending is the colour error of each Gaussian spread by its weights:
//! a pixel's error is `Σ_i w_i(p)·e_i`, the `e_i` independent and uniform over a step, so
//! its mean square is `Δ²/12 · Σ_i w_i(p)²`, and over the image
//! `mean_p Σ_i w_i(p)² = π · Σ_i s1_i·s2_i` for the normalized scales `s1`, `s2`
//! (`∫ w² = π σ1 σ2` for a Gaussian of peak 1; the image's area is 1 in normalized units).
//! Colours stored by footprint (spec §5.4.6) have the step `Δ·2^−k` of their class `k`
//! over the range of the colours times `2^k`: each term `s1·s2` then takes `4^−k`.

use gsi_format::format::{footprint, Quantizer};

/// The fit error's fall with the count: `MSE ∝ N^−γ`, from the 2.7 dB a doubling of the
/// Gaussians buys at 1 bpp (γ = 2.7 / (10·log10 2)).
pub(crate) const GAMMA: f64 = 0.9;

/// The depths the rule may choose: under 5 bits (31 steps over the colour range) a step
/// is too coarse for the noise to behave as the rule assumes (uniform, independent of
/// the image); at 10 bits a step over a typical range of ±1.1 is half an 8-bit level.
pub const COLOR_BITS: std::ops::RangeInclusive<u8> = 5..=10;

/// The depths for colours stored by footprint: their grid spans the colours times up to
/// `2^7`, so the same steps take more bits over it.
pub const FOOTPRINT_COLOR_BITS: std::ops::RangeInclusive<u8> = 5..=14;

/// The colour depth for Gaussians of `colors` and log-scale covariances `cov`
/// (`[ln s1, ln s2, θ]`, normalized), fitted to a mean squared error `mse` (per value, on
/// `[0, 1]`), at `bits_per_gaussian` bits each as coded. `None` when the error is not a
/// number to go by. `by_footprint`: the colours are stored by footprint (§5.4.6).
pub fn color_bits(
    colors: &[[f32; 3]],
    cov: &[[f32; 3]],
    mse: f64,
    bits_per_gaussian: f64,
    by_footprint: bool,
) -> Option<u8> {
    // Written so that a NaN fails it.
    let usable =
        mse >= 0.0 && bits_per_gaussian > 0.0 && !colors.is_empty() && colors.len() == cov.len();
    if !usable {
        return None;
    }
    // Each Gaussian's class where the colours are stored by footprint (from the float
    // scales: the stored ones differ by a rounding).
    let classes: Vec<u8> = if by_footprint {
        let sizes: Vec<i32> = cov.iter().map(|c| footprint::size_of(c[0], c[1])).collect();
        footprint::classes(&sizes, footprint::base_for(&sizes))
    } else {
        vec![0; cov.len()]
    };
    // mean_p Σ_i w_i(p)² (times the squared step of each class); the log-scales are
    // clamped as the renderer clamps them (§6.1).
    let spread: f64 = std::f64::consts::PI
        * cov
            .iter()
            .zip(&classes)
            .map(|(c, &k)| {
                let area =
                    (f64::from(c[0]).clamp(-30.0, 3.0) + f64::from(c[1]).clamp(-30.0, 3.0)).exp();
                area * f64::from(footprint::step(k)).powi(2)
            })
            .sum::<f64>();
    let ranges: [f64; 3] = std::array::from_fn(|ch| {
        let stored = colors
            .iter()
            .zip(&classes)
            .map(|(c, &k)| c[ch] * footprint::gain(k));
        let q = Quantizer::fit(8, stored);
        f64::from(q.max) - f64::from(q.min)
    });
    let noise = |bits: u8| {
        let steps = f64::from((1u32 << bits) - 1);
        spread / 12.0 * ranges.iter().map(|r| (r / steps).powi(2)).sum::<f64>() / 3.0
    };
    let wanted = 3.0 * GAMMA / (2.0 * bits_per_gaussian * std::f64::consts::LN_2) * mse;
    // Nearest in the log domain: the total cost is about symmetric in log Δ around its least.
    let off = |bits: u8| {
        (noise(bits).max(f64::MIN_POSITIVE) / wanted.max(f64::MIN_POSITIVE))
            .ln()
            .abs()
    };
    let depths = if by_footprint {
        FOOTPRINT_COLOR_BITS
    } else {
        COLOR_BITS
    };
    depths.min_by(|&a, &b| off(a).total_cmp(&off(b)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` Gaussians of scales `minor` and `major` (normalized), colours spread over ±1.1.
    fn gaussians(n: usize, minor: f32, major: f32) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let colors = (0..n)
            .map(|i| {
                [
                    -1.1 + 2.2 * (i % 7) as f32 / 6.0,
                    1.1 - 2.2 * (i % 5) as f32 / 4.0,
                    0.0,
                ]
            })
            .map(|[r, g, _]| [r, g, (r + g) / 2.0])
            .collect();
        (colors, vec![[minor.ln(), major.ln(), 0.3]; n])
    }

    #[test]
    fn a_worse_fit_takes_coarser_colour() {
        // 8,500 Gaussians of σ 3 × 8.7 px on a 768-pixel-wide image, colours over ±1.1:
        // the medians of kodim23 at 1 bpp.
        let (colors, cov) = gaussians(8500, 3.0 / 768.0, 8.7 / 768.0);
        let at = |db: f64| color_bits(&colors, &cov, 10f64.powf(-db / 10.0), 45.0, false).unwrap();
        let (fine, coarse) = (at(40.0), at(23.0));
        assert!(fine >= 8, "a 40 dB fit took {fine} bits");
        assert!(coarse <= 6, "a 23 dB fit took {coarse} bits");
        // A bit is 6.02 dB of noise: 7 dB more error is one or two bits coarser.
        let (a, b) = (at(32.0), at(25.0));
        assert!((1..=2).contains(&(a - b)), "32 dB: {a}, 25 dB: {b}");
    }

    #[test]
    fn bounds_and_degenerate_input() {
        let (colors, cov) = gaussians(100, 0.02, 0.02);
        assert_eq!(
            color_bits(&colors, &cov, 0.0, 45.0, false),
            Some(*COLOR_BITS.end())
        );
        assert_eq!(
            color_bits(&colors, &cov, 1.0, 45.0, false),
            Some(*COLOR_BITS.start())
        );
        assert_eq!(color_bits(&colors, &cov, f64::NAN, 45.0, false), None);
        assert_eq!(color_bits(&colors, &cov, 1e-4, 0.0, false), None);
        assert_eq!(color_bits(&[], &[], 1e-4, 45.0, false), None);
        // Constant colours (a zero range) and huge scales stay finite and in range.
        let flat = vec![[0.5f32; 3]; 10];
        let big = vec![[f32::MAX, f32::INFINITY, 0.0]; 10];
        let b = color_bits(&flat, &big, 1e-4, 45.0, false).unwrap();
        assert!(COLOR_BITS.contains(&b));
    }
}
