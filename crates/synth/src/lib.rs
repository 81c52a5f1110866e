//! Deterministic random Gaussian sets, for the corpus, benchmarks, fuzzing and every
//! crate's tests; never used by the library itself.
//!
//! The generator is the project's own `SplitMix64` (`gsi_optim::rng`), so that the
//! checked-in corpus and its golden hashes never change with a dependency upgrade.

use gsi_format::model::{Blend, CovParam, GaussianSet, Scene, WeightRule};
pub use gsi_optim::rng::SplitMix64;

/// Shape of a random scene.
#[derive(Clone, Copy, Debug)]
pub struct SceneSpec {
    pub width: u32,
    pub height: u32,
    pub count: usize,
    pub blend: Blend,
    pub cov_param: CovParam,
    pub with_opacity: bool,
    /// Standard deviations are log-uniform in this range, in pixels of the reference size.
    pub sigma_px: (f32, f32),
    /// The weight rule of the scene (per pixel by default, as the corpus's older files).
    pub weights: WeightRule,
}

impl SceneSpec {
    pub fn new(width: u32, height: u32, count: usize, blend: Blend) -> Self {
        SceneSpec {
            width,
            height,
            count,
            blend,
            cov_param: CovParam::LogScaleRotation,
            with_opacity: blend == Blend::Alpha,
            sigma_px: (0.5, 8.0),
            weights: WeightRule::PerPixel,
        }
    }
}

/// A random scene: positions uniform over the image, anisotropic Gaussians with
/// log-uniform standard deviations and uniform orientation, colours uniform in `[0, 1]`
/// (scaled down for `sum` so that overlaps stay near the displayable range).
pub fn random_scene(seed: u64, spec: SceneSpec) -> Scene {
    let mut rng = SplitMix64::new(seed);
    let (w, h) = (spec.width as f32, spec.height as f32);
    let (lo, hi) = (spec.sigma_px.0.ln(), spec.sigma_px.1.ln());
    let color_scale = match spec.blend {
        Blend::Sum => 0.35,
        Blend::Alpha => 1.0,
    };
    let mut g = GaussianSet::default();
    for _ in 0..spec.count {
        g.positions.push([rng.unit(), rng.unit()]);
        // Standard deviations along the principal axes, in pixels, and an angle.
        let (s1, s2) = (rng.range(lo, hi).exp(), rng.range(lo, hi).exp());
        let th = rng.range(0.0, std::f32::consts::PI);
        g.cov.push(match spec.cov_param {
            // Normalized axes: a pixel-space rotation does not survive the anisotropic
            // normalization exactly, which does not matter for a random set.
            CovParam::LogScaleRotation => [(s1 / w).ln(), (s2 / h).ln(), th],
            CovParam::Cholesky => {
                let cov = CovParam::LogScaleRotation.covariance([(s1 / w).ln(), (s2 / h).ln(), th]);
                let l11 = cov[0].sqrt();
                let l21 = cov[1] / l11;
                [l11, l21, (cov[2] - l21 * l21).max(0.0).sqrt()]
            }
        });
        g.colors.push([0; 3].map(|_| rng.unit() * color_scale));
    }
    if spec.with_opacity {
        g.opacity = Some((0..spec.count).map(|_| rng.range(0.05, 1.0)).collect());
    }
    Scene {
        tone: None,
        width: spec.width,
        height: spec.height,
        blend: spec.blend,
        cov_param: spec.cov_param,
        gaussians: g,
        weights: spec.weights,
    }
}
