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
