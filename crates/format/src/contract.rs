//! The constants of the pixel contract, `format-spec.md` §6: the one home of every number
//! that decides what a file's pixels are.
//!
//! The CPU renderer, the differentiable rasterizer, the enhancer and the GPU shaders (which
//! get them written in as WGSL by `gpu::contract`) all read these, so that no renderer can
//! drift from another. Changing one changes what existing files mean: it is a format change.
//! The exponential of §6.3.1 ([`exp`]) lives here for the same reason: it is made of
//! constants and binary32 operations, and decides pixels as they do.

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

/// `2^-80`: a weight of the column rule below it is no longer carried down its column
/// (§6.3.2); the lane waits, dark, until its power reaches [`COLUMN_START`]. Carried
/// weights stay far above `E`'s floor, and clear of the slow subnormal range.
pub const COLUMN_DARK: f32 = f32::from_bits(0x1780_0000);
/// The power at or above which a dark lane of the column rule starts from `E` (§6.3.2):
/// `e^-55` is above [`COLUMN_DARK`], so a lane started is carried, and its next step
/// is below 55, inside `E`'s range.
pub const COLUMN_START: f32 = -55.0;
/// A Gaussian whose `C` exceeds this is weighed per pixel by §6.3 under the column rule
/// too: `E(−C)` must stay far from `E`'s floor of −87, and so steep a column (a standard
/// deviation under 0.13 px) spans a row or two of a band.
pub const COLUMN_STEEP: f32 = 60.0;

/// The `exp` of spec §6.3, `E` of §6.3.1: `e^x` for `x` clamped to `[-87, 88]`, within
/// one ulp of the true value on `[-87, 0]` (0.98 at worst, test `exp_is_within_1_ulp`).
/// `x = n·ln 2 + r` with `n` the nearest integer (ties to even) and `|r| <= ln 2 / 2`, a
/// degree-7 polynomial for `e^r` (the coefficients of Cephes' `expf`, S. L. Moshier), and
/// `2^n` assembled in the exponent bits. Branch-free and without calls, so a loop over lanes vectorizes.
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    exp_with::<false>(x)
}

/// [`exp`], with its products and sums fused where `F` ([`mla`]): the encoder's variant,
/// within 2e-7 relative of `exp`'s values but not its bits.
#[inline(always)]
pub fn exp_with<const F: bool>(x: f32) -> f32 {
    exp_in_range::<F>(x.clamp(EXP_MIN, EXP_MAX))
}

/// [`exp_with`] without the clamp: its bits for `x` in `[EXP_MIN, EXP_MAX]`, a meaningless
/// (but defined, never a panic) value elsewhere. For loops that mask out every lane whose
/// `x` lies outside `[cut-off, 0]`, where the clamp only costs registers.
#[inline(always)]
pub fn exp_in_range<const F: bool>(x: f32) -> f32 {
    let k = mla::<F>(x, EXP_LOG2E, ROUND);
    let n = k - ROUND;
    let r = mla::<F>(-n, EXP_LN2_LO, mla::<F>(-n, EXP_LN2_HI, x));
    let [p0, p1, p2, p3, p4, p5] = EXP_POLY;
    let p = mla::<F>(p0, r, p1);
    let p = mla::<F>(p, r, p2);
    let p = mla::<F>(p, r, p3);
    let p = mla::<F>(p, r, p4);
    let p = mla::<F>(p, r, p5);
    let er = mla::<F>(p * r, r, r) + 1.0;
    let shift = (k.to_bits() as i32).wrapping_sub(ROUND.to_bits() as i32);
    let scale = f32::from_bits((shift.wrapping_add(127) as u32) << 23);
    er * scale
}

/// [`exp`]'s argument range: `2^n` stays a normal number.
pub const EXP_MIN: f32 = -87.0;
pub const EXP_MAX: f32 = 88.0;
/// log2(e), rounded to binary32.
pub const EXP_LOG2E: f32 = std::f32::consts::LOG2_E;
/// ln 2 in two parts: `n·EXP_LN2_HI` is exact for every `n` used (|n| <= 127, 9 bits).
pub const EXP_LN2_HI: f32 = 0.693_359_4;
pub const EXP_LN2_LO: f32 = -2.121_944_4e-4;
/// `e^r ≈ 1 + r + r²·p(r)`, `p` by Horner from the highest coefficient.
pub const EXP_POLY: [f32; 6] = [
    1.987_569_1e-4,
    1.398_199_9e-3,
    8.333_452e-3,
    4.166_579_6e-2,
    1.666_666_5e-1,
    5e-1,
];
/// 1.5·2^23: adding it to `x·log2 e` (|.| < 2^22) rounds to an integer, ties to even,
/// and leaves that integer in the low mantissa bits.
const ROUND: f32 = 12_582_912.0;

/// `a·b + c`: with `F` in one rounding (a fused multiply-add), else in two. Every
/// product-and-sum of the encoder's loops goes through here, so that without `F` they do
/// the operations of the spec's expressions, in the same order.
#[inline(always)]
pub fn mla<const F: bool>(a: f32, b: f32, c: f32) -> f32 {
    if F {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two positive finite floats.
    fn ulps(a: f32, b: f64) -> f64 {
        let b32 = b as f32;
        let ulp = f64::from(f32::from_bits(b32.to_bits() + 1)) - f64::from(b32);
        (f64::from(a) - b).abs() / ulp
    }

    /// Over every 7th binary32 value of `[-87, 0]` (all exponents, 157 million values).
    #[test]
    fn exp_is_within_1_ulp() {
        let (lo, hi) = ((-0.0f32).to_bits(), (-87.0f32).to_bits());
        let mut worst = (0f64, 0f32);
        let mut bits = lo;
        while bits <= hi {
            let x = f32::from_bits(bits);
            let u = ulps(exp(x), f64::from(x).exp());
            if u > worst.0 {
                worst = (u, x);
            }
            bits += 7;
        }
        assert!(worst.0 < 1.0, "{} ulp at {:e}", worst.0, worst.1);
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-0.0), 1.0);
        // Outside the range: clamped, never NaN, Inf or 0.
        assert_eq!(exp(-1e9), exp(-87.0));
        assert!(exp(-87.0) > 0.0 && exp(1e9).is_finite() && exp(1e9) == exp(88.0));
        assert!(exp(f32::NAN).is_nan());
    }

    #[test]
    fn the_fused_exp_is_close() {
        let mut x = -87.0f32;
        while x <= 0.0 {
            let (a, b) = (f64::from(exp(x)), f64::from(exp_with::<true>(x)));
            assert!(((a - b) / a).abs() < 4e-7, "{x}");
            x += 1e-3;
        }
    }
}
