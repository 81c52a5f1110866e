//! The float Gaussian set that rendering, fitting and enhancement work on.
//!
//! Everything here lives in *normalized image coordinates*: `u = x / W`, `v = y / H`,
//! both in `[0, 1]` across the image, x right and y down. Storing geometry this way
//! makes rendering at any output size a matter of sampling at other pixel centres.
//!
//! The covariance is kept in the parameterization the file declares ([`CovParam`]) so
//! that converting records to the model and back is lossless; [`CovParam::covariance`]
//! turns parameters into a covariance matrix under the clamps of `format-spec.md` §6,
//! which guarantee a finite, positive-definite result for *any* finite input.

use crate::contract::{CHOLESKY_MAX, LN_SIGMA_MAX, LN_SIGMA_MIN};

/// How overlapping Gaussians combine into a pixel colour.
// Not `#[non_exhaustive]`: the set is the file format's (spec §4), and a new mode would be
// a new major version, which callers should have to handle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Blend {
    /// `C(p) = Σ c_i α_i(p)`, order-free (GaussianImage's accumulated summation).
    Sum,
    /// Front-to-back compositing in stored order with transmittance (paper Eq. 6–8).
    Alpha,
}

impl Blend {
    pub fn name(self) -> &'static str {
        match self {
            Blend::Sum => "sum",
            Blend::Alpha => "alpha",
        }
    }
}

/// How the three covariance parameters of a Gaussian are to be read.
// Closed by the format's major version, like [`Blend`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CovParam {
    /// `(l11, l21, l22)`: `Σ = L Lᵀ` with `L = [[l11, 0], [l21, l22]]`.
    /// GaussianImage's choice: unconstrained for the optimizer, linear to quantize.
    Cholesky,
    /// `(ln σ1, ln σ2, θ)`: `Σ = R(θ) diag(σ1², σ2²) R(θ)ᵀ`, the paper's Eq. 3.
    /// Uniform steps in `ln σ` give every scale the same relative precision.
    LogScaleRotation,
}

impl CovParam {
    pub fn name(self) -> &'static str {
        match self {
            CovParam::Cholesky => "cholesky",
            CovParam::LogScaleRotation => "log-scale-rotation",
        }
    }

    /// Normalized covariance `[σ_uu, σ_uv, σ_vv]` of one Gaussian, finite for any finite input.
    ///
    /// Parameters are clamped before they are combined (spec §6.1) so that no product
    /// can overflow to infinity or form `0 · ∞`. Non-finite parameters (which no valid
    /// file can hold, but a caller's model might) are treated as 0.
    pub fn covariance(self, p: [f32; 3]) -> [f32; 3] {
        let p = p.map(|x| if x.is_finite() { x } else { 0.0 });
        match self {
            CovParam::Cholesky => {
                let [a, b, c] = p.map(|x| x.clamp(-CHOLESKY_MAX, CHOLESKY_MAX));
                [a * a, a * b, b * b + c * c]
            }
            CovParam::LogScaleRotation => {
                let s1 = p[0].clamp(LN_SIGMA_MIN, LN_SIGMA_MAX).exp();
                let s2 = p[1].clamp(LN_SIGMA_MIN, LN_SIGMA_MAX).exp();
                let (sin, cos) = p[2].sin_cos();
                let (v1, v2) = (s1 * s1, s2 * s2);
                [
                    cos * cos * v1 + sin * sin * v2,
                    sin * cos * (v1 - v2),
                    sin * sin * v1 + cos * cos * v2,
                ]
            }
        }
    }
}

/// A set of 2D Gaussians, structure of arrays. All vectors have the same length.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianSet {
    /// Centres `(u, v)`, normalized.
    pub positions: Vec<[f32; 2]>,
    /// Covariance parameters, read under the scene's [`CovParam`].
    pub cov: Vec<[f32; 3]>,
    /// sRGB-encoded colour. `[0, 1]` is the displayable range; `sum` blending may
    /// store values outside it, since overlapping Gaussians add up.
    pub colors: Vec<[f32; 3]>,
    /// Per-Gaussian opacity in `[0, 1]`; `None` means every opacity is 1.
    pub opacity: Option<Vec<f32>>,
}

impl GaussianSet {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Opacity of Gaussian `i` (1 when the set carries none).
    #[inline]
    pub fn opacity_of(&self, i: usize) -> f32 {
        self.opacity.as_ref().map_or(1.0, |o| o[i])
    }

    /// True when every stored number (positions, covariance parameters, colours,
    /// opacities) is finite: what every stage guarantees of what it hands on.
    pub fn all_finite(&self) -> bool {
        self.positions.iter().flatten().all(|x| x.is_finite())
            && self.cov.iter().flatten().all(|x| x.is_finite())
            && self.colors.iter().flatten().all(|x| x.is_finite())
            && self.opacity.iter().flatten().all(|x| x.is_finite())
    }

    /// True when every attribute vector has the same length.
    pub fn is_consistent(&self) -> bool {
        let n = self.len();
        self.cov.len() == n
            && self.colors.len() == n
            && self.opacity.as_ref().is_none_or(|o| o.len() == n)
    }
}

/// A Gaussian image: the set plus what it takes to turn it into pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// Reference size in pixels (the size the image was fitted at).
    pub width: u32,
    pub height: u32,
    pub blend: Blend,
    pub cov_param: CovParam,
    pub gaussians: GaussianSet,
    /// The tone curve every blended value goes through before it is shown (spec §6.6,
    /// `GTRC`); `None` shows the blended values as they are.
    pub tone: Option<ToneCurve>,
    /// How a Gaussian's weight at a pixel is computed (a file with `GCRW` says
    /// [`WeightRule::Columns`], one with `GCRT` [`WeightRule::Columns32`]).
    pub weights: WeightRule,
}

/// How a Gaussian's weight at each pixel is computed: the rules of spec §6.3, which
/// differ in the last bits of a weight and so, rarely, by one step of an 8-bit value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum WeightRule {
    /// `E(power)` at every pixel (§6.3): files with neither `GCRW` nor `GCRT`.
    PerPixel,
    /// Down each pixel column by two products a row from an `E` at the first row of each
    /// band of 16 rows (§6.3.2): files with a `GCRW` chunk, which encoders of version 1.4
    /// wrote: two products a pixel where §6.3 takes the power and `E`.
    Columns,
    /// The column rule in bands of 32 rows (§6.3.2): files with a `GCRT` chunk, which
    /// every encoder of version 1.5 writes. A column starts from `E` half as often, and a
    /// renderer bins each Gaussian to half as many bands.
    Columns32,
}

impl WeightRule {
    /// `"per-pixel"`, `"columns"` or `"columns-32"`, as `gsi info --json` and the Python
    /// package say it.
    pub fn name(self) -> &'static str {
        match self {
            WeightRule::PerPixel => "per-pixel",
            WeightRule::Columns => "columns",
            WeightRule::Columns32 => "columns-32",
        }
    }

    /// Rows of the column rule's bands (spec §6.3.2), `None` for the per-pixel rule: in
    /// every band of this many output rows, from row 0, a Gaussian's weights down a pixel
    /// column start again from `E` at the first row of its box, so that no weight is more
    /// than `band − 1` steps from an `E`, and a decoder that renders tiles of that many
    /// rows never carries a weight from one tile to the next.
    pub fn band_rows(self) -> Option<u32> {
        match self {
            WeightRule::PerPixel => None,
            WeightRule::Columns => Some(16),
            WeightRule::Columns32 => Some(32),
        }
    }
}

/// Most knots a [`ToneCurve`] may have (spec §6.6).
pub const TONE_KNOTS_MAX: usize = 1024;

/// A curve applied to every blended channel value (spec §6.6): knots evenly spaced in the
/// square root of the value, as 16-bit fractions of 1, linearly interpolated.
///
/// Stage 2 stores its tone curve this way because a curve of the blended value cannot be
/// moved into the colour records: a power of a sum of Gaussians is not a sum of the same
/// Gaussians. Evaluating it takes `sqrt`, `+`, `−`, `×` and `÷` only, so every decoder
/// gets the same bits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ToneCurve {
    /// 1 (one curve for R, G and B) or 3 (one per channel).
    curves: u8,
    /// Knots per curve, `2..=TONE_KNOTS_MAX`.
    knots: u16,
    /// `curves · knots` values, curve after curve; knot `i` is the curve at `(i/(n−1))²`.
    values: Vec<u16>,
}

impl ToneCurve {
    /// A curve from its knot values (`curves` of `values.len() / curves` knots each);
    /// `None` where the counts break spec §6.6.
    pub fn new(curves: u8, values: Vec<u16>) -> Option<ToneCurve> {
        if curves != 1 && curves != 3 || values.len() % usize::from(curves) != 0 {
            return None;
        }
        let knots = values.len() / usize::from(curves);
        if !(2..=TONE_KNOTS_MAX).contains(&knots) {
            return None;
        }
        Some(ToneCurve {
            curves,
            knots: knots as u16,
            values,
        })
    }

    /// One curve for all three channels, sampling `f` (a function of the blended value,
    /// with results in `[0, 1]`) at `knots` knots, each rounded to the nearest 16-bit
    /// step. `None` where `knots` is out of range.
    pub fn sample(knots: usize, f: impl Fn(f64) -> f64) -> Option<ToneCurve> {
        if !(2..=TONE_KNOTS_MAX).contains(&knots) {
            return None;
        }
        let last = (knots - 1) as f64;
        let values = (0..knots)
            .map(|i| {
                let s = i as f64 / last;
                let y = f(s * s);
                let y = if y.is_nan() { 0.0 } else { y.clamp(0.0, 1.0) };
                (y * 65535.0).round() as u16
            })
            .collect();
        ToneCurve::new(1, values)
    }

    /// 1 or 3.
    pub fn curves(&self) -> u8 {
        self.curves
    }

    /// Knots per curve.
    pub fn knots(&self) -> u16 {
        self.knots
    }

    /// Every knot value, curve after curve.
    pub fn values(&self) -> &[u16] {
        &self.values
    }

    /// The curve of `channel` (0, 1, 2) at the blended value `c`, exactly as spec §6.6.
    #[inline]
    pub fn eval(&self, channel: usize, c: f32) -> f32 {
        let n = usize::from(self.knots);
        let curve = if self.curves == 1 { 0 } else { channel };
        let l = &self.values[curve * n..][..n];
        // NaN fails the comparison and is shown as 0.
        let x = if c >= 0.0 { c.min(1.0) } else { 0.0 };
        let u = x.sqrt() * (n - 1) as f32;
        let i = (u as usize).min(n - 2);
        let t = u - i as f32;
        let (a, b) = (f32::from(l[i]), f32::from(l[i + 1]));
        (a + t * (b - a)) / 65535.0
    }

    /// Apply the curve to interleaved RGB values in place.
    pub fn apply(&self, rgb: &mut [f32]) {
        for px in rgb.chunks_exact_mut(3) {
            for (k, v) in px.iter_mut().enumerate() {
                *v = self.eval(k, *v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn is_pos_def(s: [f32; 3]) -> bool {
        s.iter().all(|x| x.is_finite()) && s[0] >= 0.0 && s[2] >= 0.0
    }

    #[test]
    fn covariance_is_finite_for_extreme_parameters() {
        let extremes = [
            0.0,
            -0.0,
            1e-30,
            f32::MIN_POSITIVE,
            1e30,
            -1e30,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NAN,
        ];
        for param in [CovParam::Cholesky, CovParam::LogScaleRotation] {
            for &a in &extremes {
                for &b in &extremes {
                    for &c in &extremes {
                        let s = param.covariance([a, b, c]);
                        assert!(is_pos_def(s), "{param:?} {a} {b} {c} -> {s:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn log_scale_rotation_matches_eq3() {
        // σ1 = 0.1, σ2 = 0.02, θ = 30°: Σ = R diag(σ1², σ2²) Rᵀ
        let th = 30f32.to_radians();
        let s = CovParam::LogScaleRotation.covariance([0.1f32.ln(), 0.02f32.ln(), th]);
        let (c, sn) = (th.cos(), th.sin());
        let want = [
            c * c * 0.01 + sn * sn * 0.0004,
            c * sn * (0.01 - 0.0004),
            sn * sn * 0.01 + c * c * 0.0004,
        ];
        for k in 0..3 {
            assert!((s[k] - want[k]).abs() < 1e-7, "{s:?} vs {want:?}");
        }
    }

    #[test]
    fn cholesky_is_l_lt() {
        let s = CovParam::Cholesky.covariance([0.3, -0.1, 0.2]);
        let want = [0.09, -0.03, 0.05];
        for k in 0..3 {
            assert!((s[k] - want[k]).abs() < 1e-7, "{s:?} vs {want:?}");
        }
    }
}
