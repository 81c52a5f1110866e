//! Angle precision by shape (spec §5.4.5): how many of a `log-scale-rotation` angle's
//! bits a Gaussian keeps, from its own two log-scales.
//!
//! Turning a Gaussian of scales `s1, s2` by a small `δ` moves
//! `δ²·(π/4)·s1·s2·(r − 1/r)²` of squared footprint (`r = s1/s2`, integrated over the
//! plane), so a round Gaussian's angle changes no pixel and a long thin one's changes many.
//! A uniform angle depth spends the bits the thinnest need on every Gaussian. Here a
//! Gaussian keeps `log2(r − 1/r) + ½·log2(s1·s2)` bits plus a per-file offset: the
//! high-rate allocation in which each angle adds the same noise, for a depth that
//! only the thinnest Gaussians use whole.
//!
//! Everything here is exact binary64 arithmetic on the dequantized scales (§5.2), with
//! fixed thresholds rather than `exp` or `log`, so that every decoder keeps the same bits:
//! a different count would misread every code after it.

use super::quant::Quantizer;
use crate::contract::{COLOR_MAX, LN_SIGMA_MAX, LN_SIGMA_MIN};

/// `asinh(2^(j − 7))` for `j = 0..=16`: where `2·sinh(e) = r − 1/r` reaches `2^(j − 6)`.
/// [`shape_bits`] counts the thresholds at or below `e = |ln r|` (spec §5.4.5 lists them).
pub const THRESHOLDS: [f64; 17] = [
    0.007812420529323008,
    0.01562436428696144,
    0.031244915970854933,
    0.06245938125554031,
    0.12467674692144273,
    0.24746646154726346,
    0.48121182505960347,
    0.881373587019543,
    1.4436354751788103,
    2.0947125472611012,
    2.7764722807237177,
    3.466711037884725,
    4.15912713462618,
    4.85209129348869,
    5.545192702919391,
    6.238328439714945,
    6.931472759272405,
];

/// `1 / (2·ln 2)`: `½·log2` of `s1·s2` per unit of `ln s1 + ln s2`.
pub const HALF_LOG2_E: f64 = 0.7213475204444817;

/// The angle bits a Gaussian of log-scales `p0`, `p1` keeps, of `bits`, under a file's
/// `offset`: `clamp(κ + floor((p0 + p1)·HALF_LOG2_E + offset), 0, bits)` with
/// `κ = floor(log2(r − 1/r))` clamped to `[−6, 10]`, read from [`THRESHOLDS`]; none
/// where `r − 1/r < 2^−6`, a Gaussian round to its last bit.
pub fn shape_bits(p0: f32, p1: f32, offset: f32, bits: u8) -> u8 {
    Shape::of(p0, p1).bits(offset, bits)
}

/// The part of [`shape_bits`] that does not depend on the offset, for trying many.
#[derive(Clone, Copy, Debug)]
pub struct Shape {
    /// `κ`, or `None` where `r − 1/r < 2^−6`.
    kappa: Option<f64>,
    /// `(p0 + p1)·HALF_LOG2_E`.
    size: f64,
}

impl Shape {
    pub fn of(p0: f32, p1: f32) -> Shape {
        let (p0, p1) = (f64::from(p0), f64::from(p1));
        let e = (p0 - p1).abs();
        let above = THRESHOLDS.iter().filter(|&&t| t <= e).count();
        Shape {
            kappa: (above > 0).then_some(above as f64 - 7.0),
            size: (p0 + p1) * HALF_LOG2_E,
        }
    }

    /// The bits kept of `bits` under `offset`.
    #[inline]
    pub fn bits(&self, offset: f32, bits: u8) -> u8 {
        match self.kappa {
            None => 0,
            Some(kappa) => {
                let size = (self.size + f64::from(offset)).floor();
                (kappa + size).clamp(0.0, f64::from(bits)) as u8
            }
        }
    }
}

/// The full code of a Gaussian that keeps `keep` of `bits` bits and holds `coarse`: the
/// middle of the `2^(bits − keep)` codes that share those leading bits.
#[inline]
pub fn full_code(coarse: u32, keep: u8, bits: u8) -> u32 {
    let drop = bits - keep;
    let mid = if drop == 0 { 0 } else { 1u32 << (drop - 1) };
    (coarse << drop) | mid
}

/// The kept bits of `code` where it is the middle of its bucket ([`full_code`]), else
/// `None`.
#[inline]
pub fn coarse_code(code: u32, keep: u8, bits: u8) -> Option<u32> {
    let coarse = code >> (bits - keep);
    (full_code(coarse, keep, bits) == code).then_some(coarse)
}

/// The code of keep bits nearest to the fine position `x` (in units of `bits`-bit codes),
/// as a full code.
#[inline]
pub fn round_to_bucket(x: f64, keep: u8, bits: u8) -> u32 {
    let drop = bits - keep;
    let mid = if drop == 0 {
        0.0
    } else {
        f64::from(1u32 << (drop - 1))
    };
    let top = f64::from(((1u64 << keep) - 1) as u32);
    let coarse = ((x - mid) / f64::from(1u32 << drop))
        .round()
        .clamp(0.0, top);
    full_code(coarse as u32, keep, bits)
}

/// How many bits above the uniform depth whose noise they match shaped angles are stored
/// at: the thinnest Gaussians keep up to four times the uniform step's precision.
pub const EXTRA_BITS: u8 = 2;

/// Shape the angles of `cov` (§5.4.5): `qs` and `codes` are their quantizers and planar
/// codes (three components, the angle at its file depth), `colors` the Gaussians'
/// colours. Finds the least offset (to 2^−16) at which the angles' summed noise, each
/// Gaussian's weighed by `s1·s2·(r − 1/r)²` and its squared colour, is no more than
/// `uniform_bits` uniform bits give, rounds each angle to the nearest middle of its
/// bucket in `codes`, and returns the offset; `None`, with `codes` as they were, where
/// there is no angle to shape (no Gaussian, a constant angle).
pub fn shape(
    cov: &[[f32; 3]],
    colors: &[[f32; 3]],
    qs: &[Quantizer],
    codes: &mut [u32],
    uniform_bits: u8,
) -> Option<f32> {
    let n = cov.len();
    let depth = qs.get(2)?.bits;
    if n == 0 || depth == 0 || colors.len() != n || codes.len() != 3 * n {
        return None;
    }
    let v0 = qs[0].lookup(n, |c| qs[0].dequantize(c));
    let v1 = qs[1].lookup(n, |c| qs[1].dequantize(c));
    let p: Vec<(f32, f32)> = (0..n)
        .map(|i| (v0.get(codes[i]), v1.get(codes[n + i])))
        .collect();
    // Weights relative to the largest size, within §6.1's clamps: finite for any record.
    let log_size = |(p0, p1): (f32, f32)| {
        f64::from(p0.clamp(LN_SIGMA_MIN, LN_SIGMA_MAX) + p1.clamp(LN_SIGMA_MIN, LN_SIGMA_MAX))
    };
    let top = p
        .iter()
        .map(|&x| log_size(x))
        .fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = p
        .iter()
        .zip(colors)
        .map(|(&(p0, p1), c)| {
            let k = 2.0 * f64::from((p0 - p1).abs().min(33.0)).sinh();
            let c2: f64 = c
                .iter()
                .map(|&x| f64::from(x.clamp(-COLOR_MAX, COLOR_MAX)).powi(2))
                .sum();
            let w = (log_size((p0, p1)) - top).exp() * k * k * c2;
            // A colour that is not a number weighs nothing rather than everything.
            if w.is_finite() {
                w
            } else {
                0.0
            }
        })
        .collect();
    // Noise in units of the depth's step squared: a bucket of 2^(depth − keep) codes.
    let step: Vec<f64> = (0..=depth)
        .map(|keep| 4f64.powi(i32::from(depth) - i32::from(keep)))
        .collect();
    let uniform = w.iter().sum::<f64>() * step[usize::from(uniform_bits.min(depth))];
    let shapes: Vec<Shape> = p.iter().map(|&(p0, p1)| Shape::of(p0, p1)).collect();
    let noise = |offset: f32| -> f64 {
        shapes
            .iter()
            .zip(&w)
            .map(|(s, &w)| w * step[usize::from(s.bits(offset, depth))])
            .sum()
    };
    let (mut lo, mut hi) = (-128f32, 128f32);
    while hi - lo > 1.0 / 65536.0 {
        let mid = 0.5 * (lo + hi);
        if noise(mid) <= uniform {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    for (i, (s, c)) in shapes.iter().zip(cov).enumerate() {
        codes[2 * n + i] = round_to_bucket(qs[2].position(c[2]), s.bits(hi, depth), depth);
    }
    Some(hi)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::format::coder::tests::test_rng;
    use crate::format::Attribute;

    /// `n` log-scale pairs, angles within a quarter turn and colours, spread as a fitted
    /// file's are (sizes over six nats, elongations mostly under 3).
    pub(crate) fn fitted_like(n: usize, seed: u64) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let mut rng = test_rng(seed);
        let cov = (0..n)
            .map(|_| {
                let a = -9.0 + 6.0 * rng();
                let b = a - 3.0 * rng() * rng();
                [a, b, (rng() - 0.5) * std::f32::consts::FRAC_PI_2]
            })
            .collect();
        let colors = (0..n).map(|_| [rng(), rng(), rng()]).collect();
        (cov, colors)
    }

    #[test]
    fn thresholds_are_where_r_minus_one_over_r_doubles() {
        for (j, &t) in THRESHOLDS.iter().enumerate() {
            let k = 2.0 * t.sinh();
            let want = 2f64.powi(j as i32 - 6);
            assert!((k / want - 1.0).abs() < 1e-12, "{j}: {k} against {want}");
        }
        assert!((HALF_LOG2_E - 0.5 / std::f64::consts::LN_2).abs() < 1e-16);
    }

    #[test]
    fn round_gaussians_keep_nothing_and_thin_ones_everything() {
        assert_eq!(shape_bits(-5.0, -5.0, 20.0, 9), 0);
        assert_eq!(shape_bits(-3.0, -9.0, 20.0, 9), 9);
        // At one size, each doubling of r − 1/r keeps one bit more.
        let at = |j: usize| {
            let half = (THRESHOLDS[j] + 1e-3) / 2.0;
            shape_bits((-6.0 + half) as f32, (-6.0 - half) as f32, 20.0, 24)
        };
        for j in 1..THRESHOLDS.len() {
            assert_eq!(at(j), at(j - 1) + 1, "threshold {j}");
        }
    }

    #[test]
    fn shaped_angles_add_the_noise_of_the_uniform_depth_in_fewer_bits() {
        let n = 6000;
        let (cov, colors) = fitted_like(n, 1);
        let shaped = Attribute::shaped_angles(&cov, &colors, 6, 7);
        let uniform = Attribute::fit(&cov, [6, 6, 7]);
        assert_eq!(shaped.quantizers[2].bits, 7 + EXTRA_BITS);
        let offset = shaped.shape.expect("shaped");
        // Each angle's squared error, weighed as the rule weighs it.
        let weighed = |a: &Attribute| -> f64 {
            let v: Vec<[f32; 3]> = a.values();
            v.iter()
                .zip(&cov)
                .zip(&colors)
                .map(|((q, c), k)| {
                    let r = 2.0 * f64::from((q[0] - q[1]).abs()).sinh();
                    let c2: f64 = k.iter().map(|&x| f64::from(x).powi(2)).sum();
                    let d = f64::from(q[2] - c[2]);
                    f64::from(q[0] + q[1]).exp() * r * r * c2 * d * d
                })
                .sum()
        };
        let (s, u) = (weighed(&shaped), weighed(&uniform));
        assert!(s < 1.15 * u, "shaped {s:e} against uniform {u:e}");
        let v: Vec<[f32; 3]> = shaped.values();
        let kept: u32 = v
            .iter()
            .map(|q| u32::from(shape_bits(q[0], q[1], offset, 7 + EXTRA_BITS)))
            .sum();
        let mean = f64::from(kept) / n as f64;
        assert!(mean < 6.0, "{mean} bits an angle");
    }

    #[test]
    fn buckets_round_trip() {
        for bits in 1..=12u8 {
            for keep in 0..=bits {
                for coarse in [0, 1, (1u32 << keep) - 1] {
                    let coarse = coarse.min((1u32 << keep) - 1);
                    let code = full_code(coarse, keep, bits);
                    assert!(code < 1 << bits);
                    assert_eq!(coarse_code(code, keep, bits), Some(coarse));
                    let x = f64::from(code);
                    assert_eq!(round_to_bucket(x, keep, bits), code);
                }
            }
        }
        assert_eq!(coarse_code(6, 1, 3), Some(1));
        assert_eq!(coarse_code(4, 1, 3), None);
    }
}
