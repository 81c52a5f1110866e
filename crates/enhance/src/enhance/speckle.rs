//! The removal of the Gaussians that stage 1 fitted to noise (spec §7.2.5), before
//! anything else of stage 2 touches the colours.
//!
//! A dark capture's noise is a few 8-bit steps, and stage 1 spends Gaussians on its
//! peaks as on anything else: small dots and sub-pixel needles whose colour is a
//! dip or a bump of two or three steps. Lifted ×10 to ×16 by the curve, they are the
//! black dots and bright streaks that cover a dark, flat surface (a black bag, a wall
//! in shadow). Neither the mixture (which maps colours, not places) nor the denoising of
//! §7.2.1 (which averages a Gaussian with neighbours of its own size, and a needle has
//! none) removes them.
//!
//! In `sum` blending a Gaussian's colour is the amplitude it adds, and its footprint
//! says how precisely a fit can know that amplitude: against noise `σ` per pixel, to
//! `σ / sqrt(F)` with `F` the footprint's squared sum over the pixels (`π·sqrt(det)` of
//! its covariance widened by a pixel's own area). Each colour is shrunk by the
//! non-negative garrote `1 − (λσ)² / (a²F)` of its mean-square amplitude `a²`, and
//! removed where that is not positive: a Gaussian that stands within [`LAMBDA`] noise
//! levels of what its footprint can know is taken for noise. Large Gaussians (the
//! image's shading) and strong small ones (edges, texture of a lit region) keep their
//! colour; in a bright photograph almost nothing changes.

use super::denoise::{det, pixel_cov};
use gsi_format::format::Speckle;
use gsi_format::model::{Blend, Scene};

/// A pixel's own variance (a unit box, `1/12` per axis), added to each footprint: a
/// Gaussian narrower than a pixel still covers one when sampled.
pub const PIXEL_VARIANCE: f32 = 1.0 / 12.0;

/// `colors` with the Gaussians fitted to noise removed, exactly as spec §7.2.5: per
/// Gaussian of a `sum` scene, `k = 1 − t² / (e·F)` where `e·F > t²` (else 0), and
/// `k·c`. An `alpha` scene's colours are returned as they are.
pub fn apply(scene: &Scene, colors: &[[f32; 3]], speckle: &Speckle) -> Vec<[f32; 3]> {
    if scene.blend != Blend::Sum {
        return colors.to_vec();
    }
    let t = speckle.threshold;
    let tt = t * t;
    colors
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let [s0, s1, s2] = pixel_cov(scene, i);
            let d = det([s0 + PIXEL_VARIANCE, s1, s2 + PIXEL_VARIANCE]);
            let f = std::f32::consts::PI * d.sqrt();
            let e = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) / 3.0;
            let z = e * f;
            if z > tt {
                let k = 1.0 - tt / z;
                c.map(|x| k * x)
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

#[cfg(feature = "encode")]
pub use plan::{plan, LAMBDA};

#[cfg(feature = "encode")]
mod plan {
    use super::*;

    /// How many noise levels a Gaussian's amplitude must stand above what its
    /// footprint can know: three, the usual bound for "not noise" of one estimate. On
    /// the validation pairs (a probe before this record was written: LOL `val30`,
    /// the synthetic dark Kodak set, PSNR / SSIM) none scored 20.51 / 0.795 and 21.95 /
    /// 0.792, λ = 2 20.51 / 0.807 and 21.97 / 0.797, λ = 3 20.56 / 0.814 and 21.98 /
    /// 0.799, λ = 5 (the universal threshold of 240,000 pixels) 20.57 / 0.821 and
    /// 21.96 / 0.797.
    pub const LAMBDA: f32 = 3.0;

    /// The record stage 2 writes for `scene`: for `sum` blending, `t = λ·σ` with `σ`
    /// the noise of a dark photograph ([`crate::enhance::chroma::NOISE`], in colour
    /// units); none for `alpha`, where the step does nothing.
    pub fn plan(scene: &Scene) -> Option<Speckle> {
        (scene.blend == Blend::Sum).then(|| Speckle {
            threshold: (f64::from(LAMBDA) * f64::from(crate::enhance::chroma::NOISE) / 255.0)
                as f32,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::model::{CovParam, GaussianSet};

    fn scene(blend: Blend, cov: Vec<[f32; 3]>, colors: Vec<[f32; 3]>) -> Scene {
        Scene {
            weights: gsi_format::model::WeightRule::PerPixel,
            width: 64,
            height: 32,
            blend,
            cov_param: CovParam::Cholesky,
            gaussians: GaussianSet {
                positions: vec![[0.5, 0.5]; cov.len()],
                cov,
                colors,
                opacity: None,
            },
            tone: None,
        }
    }

    /// Spec §7.2.5's worked example, bit for bit.
    #[test]
    fn speckle_worked_example() {
        let t = f32::from_bits(0x3C7A_942D);
        assert_eq!(t, 0.015_294_117);
        assert_eq!(PIXEL_VARIANCE.to_bits(), 0x3DAA_AAAB);
        assert_eq!(std::f32::consts::PI.to_bits(), 0x4049_0FDB);
        let s = scene(
            Blend::Sum,
            vec![[0.03125, 0.0, 0.0625], [0.0078125, 0.0, 0.015625]],
            vec![[0.02; 3], [-0.01; 3]],
        );
        let out = apply(&s, &s.gaussians.colors, &Speckle { threshold: t });
        assert_eq!(out[0].map(f32::to_bits), [0x3C9C_5F0E; 3]);
        assert_eq!(out[1], [0.0; 3]);
    }

    #[cfg(feature = "encode")]
    #[test]
    fn the_encoder_writes_the_threshold_of_the_worked_example() {
        let s = scene(Blend::Sum, vec![[0.1, 0.0, 0.1]], vec![[0.5; 3]]);
        assert_eq!(plan(&s).unwrap().threshold.to_bits(), 0x3C7A_942D);
        let a = scene(Blend::Alpha, vec![[0.1, 0.0, 0.1]], vec![[0.5; 3]]);
        assert!(plan(&a).is_none());
    }

    /// Large or strong Gaussians keep nearly all their colour, weak small ones go, none
    /// grows or changes sign, and alpha scenes are left alone.
    #[test]
    fn shrinks_only_what_the_noise_explains() {
        let t = Speckle {
            threshold: 0.015_294_118,
        };
        // A broad shading Gaussian (σ 8 px), a strong dot, a weak dot, a weak needle.
        let cov = vec![
            [0.125, 0.0, 0.25],
            [0.0078125, 0.0, 0.015625],
            [0.0078125, 0.0, 0.015625],
            [0.001, 0.05, 0.001],
        ];
        let colors = vec![
            [0.05, 0.04, 0.03],
            [0.4, 0.3, 0.2],
            [0.008, -0.01, 0.004],
            [-0.01; 3],
        ];
        let s = scene(Blend::Sum, cov.clone(), colors.clone());
        let out = apply(&s, &colors, &t);
        let kept = |i: usize| out[i][0] / colors[i][0];
        assert!(kept(0) > 0.99, "{out:?}");
        assert!(kept(1) > 0.98, "{out:?}");
        assert_eq!(out[2], [0.0; 3]);
        assert_eq!(out[3], [0.0; 3]);
        for (o, c) in out.iter().zip(&colors) {
            for k in 0..3 {
                assert!(o[k].abs() <= c[k].abs() && o[k] * c[k] >= 0.0);
            }
        }
        let a = scene(Blend::Alpha, cov, colors.clone());
        assert_eq!(apply(&a, &colors, &t), colors);
    }

    #[test]
    fn degenerate_input_stays_finite() {
        let t = Speckle { threshold: 1.0 };
        let cov = vec![[0.0; 3], [1e30, 1e30, 1e30], [f32::NAN, 0.0, f32::INFINITY]];
        let colors = vec![[64.0; 3], [-64.0, 0.0, 64.0], [0.0; 3]];
        let s = scene(Blend::Sum, cov, colors.clone());
        for c in apply(&s, &colors, &t) {
            assert!(c.iter().all(|x| x.is_finite()), "{c:?}");
        }
    }
}
