//! Where the Gaussians start.
//!
//! The paper starts cold: uniform random centres, isotropic covariances, zero colour, and
//! lets 30k iterations organise them. Most of that work is predictable from the image:
//! detail needs small Gaussians where the gradient is strong, edges want ellipses along
//! them, flat areas want a few large ones. The adaptive start places them so from the
//! first iteration, and [`super::lsq`] then solves their colours exactly.

use super::Target;
use gsi_format::format::context::morton;
use gsi_format::model::{Blend, GaussianSet};
use gsi_optim::rng::SplitMix64;

/// How the Gaussians are initialized.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Init {
    /// Content-adaptive: density from gradient magnitude, scale from local density,
    /// orientation from the structure tensor, colour from the image.
    Adaptive,
    /// The paper's cold start: uniform positions, isotropic, colour 0, small opacity.
    Random,
}

/// Luminance of the target, row-major.
fn luminance(t: &Target) -> Vec<f32> {
    t.data
        .chunks_exact(3)
        .map(|p| {
            let [r, g, b] = gsi_metrics::metrics::BT601_F32;
            r * p[0] + g * p[1] + b * p[2]
        })
        .collect()
}

/// Sobel gradients `(gx, gy)` of `l` with replicated borders, a row at a time through
/// the filter stage 2 uses too ([`gsi_metrics::metrics::sobel_row`]).
fn sobel(l: &[f32], w: usize, h: usize) -> (Vec<f32>, Vec<f32>) {
    let mut gx = vec![0f32; w * h];
    let mut gy = vec![0f32; w * h];
    let row = |y: usize| &l[y * w..(y + 1) * w];
    for y in 0..h {
        let (up, dn) = (row(y.saturating_sub(1)), row((y + 1).min(h - 1)));
        let out = y * w..(y + 1) * w;
        gsi_metrics::metrics::sobel_row::<1>(up, row(y), dn, &mut gx[out.clone()], &mut gy[out]);
    }
    (gx, gy)
}

/// Separable box blur of radius `r` (clamped borders), for the structure tensor.
fn box_blur(v: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let pass = |src: &[f32], len: usize, stride: usize, lines: usize, line_stride: usize| {
        let mut out = vec![0f32; src.len()];
        for l in 0..lines {
            let base = l * line_stride;
            let mut acc = 0f32;
            let get = |k: isize| src[base + k.clamp(0, len as isize - 1) as usize * stride];
            for k in -(r as isize)..=r as isize {
                acc += get(k);
            }
            for k in 0..len {
                out[base + k * stride] = acc / (2 * r + 1) as f32;
                acc += get(k as isize + r as isize + 1) - get(k as isize - r as isize);
            }
        }
        out
    };
    let horiz = pass(v, w, 1, h, w);
    pass(&horiz, h, w, w, 1)
}

/// Initial parameters for `n` Gaussians on `target`.
pub fn initialize(target: &Target, n: usize, init: Init, blend: Blend, seed: u64) -> GaussianSet {
    let (w, h) = (target.width as usize, target.height as usize);
    let mut rng = SplitMix64::new(seed);
    let mut g = GaussianSet::default();
    let (fw, fh) = (w as f32, h as f32);
    let n = n.max(1);
    let spacing = (fw * fh / n as f32).sqrt();
    match init {
        Init::Random => {
            let ln = |s: f32, dim: f32| (s / dim).ln();
            let sigma = (0.5 * spacing).max(0.5);
            for _ in 0..n {
                g.positions.push([rng.unit(), rng.unit()]);
                g.cov.push([ln(sigma, fw), ln(sigma, fh), 0.0]);
                g.colors.push([0.0; 3]);
            }
            if blend == Blend::Alpha {
                g.opacity = Some(vec![0.1; n]);
            }
        }
        Init::Adaptive => {
            let l = luminance(target);
            let (gx, gy) = sobel(&l, w, h);
            let mag: Vec<f32> = gx
                .iter()
                .zip(&gy)
                .map(|(x, y)| (x * x + y * y).sqrt())
                .collect();
            let mean = mag.iter().sum::<f32>() / mag.len() as f32;
            // Half the Gaussians follow detail, half cover the image evenly.
            let floor = mean.max(1e-3);
            let density: Vec<f32> = mag.iter().map(|m| m + floor).collect();
            let total: f32 = density.iter().sum();
            // Structure tensor, smoothed over about one spacing.
            let r = ((spacing * 0.5) as usize).clamp(1, 8);
            let jxx = box_blur(&gx.iter().map(|x| x * x).collect::<Vec<_>>(), w, h, r);
            let jxy = box_blur(
                &gx.iter().zip(&gy).map(|(x, y)| x * y).collect::<Vec<_>>(),
                w,
                h,
                r,
            );
            let jyy = box_blur(&gy.iter().map(|y| y * y).collect::<Vec<_>>(), w, h, r);
            for p in stratified(&density, w, h, n, &mut rng) {
                let d = density[p];
                {
                    let (x, y) = (p % w, p / w);
                    let (px, py) = (x as f32 + rng.unit(), y as f32 + rng.unit());
                    g.positions.push([px / fw, py / fh]);
                    // Gaussians per pixel here is n·d/total: spacing 1/sqrt of that.
                    let local = (total / (n as f32 * d)).sqrt();
                    let sigma = (0.7 * local).clamp(0.5, (0.25 * fw.max(fh)).max(0.5));
                    // Elongate along the edge (the eigenvector of the smaller eigenvalue).
                    let (a, b, c) = (jxx[p], jxy[p], jyy[p]);
                    let tr = a + c;
                    let disc = (((a - c) * 0.5).powi(2) + b * b).sqrt();
                    let (l1, l2) = (tr * 0.5 + disc, (tr * 0.5 - disc).max(0.0));
                    let eps = 1e-4 + 0.01 * tr;
                    let ratio = ((l1 + eps) / (l2 + eps)).sqrt().clamp(1.0, 3.0);
                    let theta = 0.5 * (2.0 * b).atan2(a - c) + std::f32::consts::FRAC_PI_2;
                    let (s_along, s_across) = (sigma * ratio.sqrt(), sigma / ratio.sqrt());
                    g.cov.push(pixel_lsr(s_along, s_across, theta, fw, fh));
                    let c = &target.data[p * 3..p * 3 + 3];
                    g.colors.push([c[0], c[1], c[2]]);
                }
            }
            if blend == Blend::Alpha {
                g.opacity = Some(vec![0.8; g.positions.len()]);
            }
        }
    }
    g
}

/// `k` pixel indices drawn in proportion to `weight`, spread evenly over the image.
///
/// Systematic sampling (evenly spaced quantiles of the cumulative weight, one random
/// phase) along a Z-order curve: along raster order the samples of a flat image would
/// fall in the same few columns, along the curve they are stratified in both directions.
/// Returns fewer than `k` only when the total weight is zero.
pub fn stratified(
    weight: &[f32],
    w: usize,
    h: usize,
    k: usize,
    rng: &mut SplitMix64,
) -> Vec<usize> {
    let total: f64 = weight.iter().map(|&v| f64::from(v.max(0.0))).sum();
    if total.is_nan() || total <= 0.0 || k == 0 {
        return Vec::new();
    }
    let mut order: Vec<u32> = (0..(w * h) as u32).collect();
    order.sort_unstable_by_key(|&p| morton(p % w as u32, p / w as u32));
    let step = total / k as f64;
    let mut next = f64::from(rng.unit()) * step;
    let (mut acc, mut out) = (0f64, Vec::with_capacity(k));
    for &p in &order {
        acc += f64::from(weight[p as usize].max(0.0));
        while next < acc && out.len() < k {
            next += step;
            out.push(p as usize);
        }
    }
    // Rounding can leave the last quantile just past the end.
    while out.len() < k {
        out.push(*order.last().expect("non-empty image") as usize);
    }
    out
}

/// `log-scale-rotation` parameters (normalized) of the pixel-space Gaussian with standard
/// deviations `s1` along angle `theta` and `s2` across it.
pub fn pixel_lsr(s1: f32, s2: f32, theta: f32, fw: f32, fh: f32) -> [f32; 3] {
    // Pixel covariance, then normalized, then its eigen-decomposition.
    let (sin, cos) = theta.sin_cos();
    let (v1, v2) = (s1 * s1, s2 * s2);
    let a = (cos * cos * v1 + sin * sin * v2) / (fw * fw);
    let b = (sin * cos * (v1 - v2)) / (fw * fh);
    let c = (sin * sin * v1 + cos * cos * v2) / (fh * fh);
    lsr_of(a, b, c)
}

/// Eigen-decomposition of a normalized covariance into `(ln σ1, ln σ2, θ)`.
pub fn lsr_of(a: f32, b: f32, c: f32) -> [f32; 3] {
    let theta = 0.5 * (2.0 * b).atan2(a - c);
    let mid = 0.5 * (a + c);
    let disc = ((0.5 * (a - c)).powi(2) + b * b).sqrt();
    let (l1, l2) = ((mid + disc).max(1e-20), (mid - disc).max(1e-20));
    [0.5 * l1.ln(), 0.5 * l2.ln(), theta]
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::model::CovParam;

    #[test]
    fn lsr_of_inverts_covariance() {
        for p in [[-3.0f32, -4.0, 0.3], [-2.0, -2.0, 0.0], [-5.0, -3.5, -1.2]] {
            let s = CovParam::LogScaleRotation.covariance(p);
            let q = CovParam::LogScaleRotation.covariance(lsr_of(s[0], s[1], s[2]));
            for k in 0..3 {
                assert!(
                    (s[k] - q[k]).abs() <= 1e-5 * s[0].abs().max(s[2].abs()),
                    "{p:?}: {s:?} vs {q:?}"
                );
            }
        }
    }

    #[test]
    fn adaptive_init_is_finite_on_flat_and_busy_images() {
        for fill in [0.0f32, 1.0, 0.5] {
            let t = Target {
                width: 9,
                height: 5,
                data: vec![fill; 9 * 5 * 3],
            };
            for init in [Init::Adaptive, Init::Random] {
                let g = initialize(&t, 12, init, Blend::Alpha, 1);
                assert_eq!(g.len(), 12);
                assert!(g.all_finite());
            }
        }
    }
}
