//! Exact least-squares colours for fixed geometry.
//!
//! With positions, covariances and opacities frozen, both blend modes are linear in the
//! colours: the image is `A c` for a sparse matrix `A` of per-pixel weights
//! (`alpha_i` for `sum`, `alpha_i T_i` for `alpha`). The best colours in the L2 sense
//! solve `(AᵀA + εI) c = Aᵀ y`. `A` is never formed: the forward pass applies it and the
//! colour part of the backward pass applies `Aᵀ`, so conjugate gradients (on the normal
//! equations) needs only renders.

use super::lanes::Planes;
use super::raster::{self, Need};
use gsi_format::format::Quantizer;
use gsi_format::model::Blend;
use gsi_render::render::{Projected, TileLists};

/// Ridge term: keeps Gaussians that touch almost nothing from taking huge colours.
const RIDGE: f32 = 1e-3;

/// The normal equations' product `Aᵀ d(A c)` for one geometry, binned once.
struct Normal<'t> {
    blend: Blend,
    width: u32,
    height: u32,
    target: &'t [f32],
    /// `sum` blending: the tile lists every product walks (the geometry does not move).
    tiles: Option<TileLists>,
}

impl<'t> Normal<'t> {
    fn new(
        projected: &[Projected],
        blend: Blend,
        width: u32,
        height: u32,
        target: &'t [f32],
    ) -> Self {
        // `sum` blending: each product a tile at a time ([`raster::sum_adjoint`]), over one
        // binning. `alpha`: a forward pass, then the colour part of the backward pass on
        // the binning it made.
        let tiles = (blend == Blend::Sum).then(|| TileLists::bin(projected, width, height));
        Normal {
            blend,
            width,
            height,
            target,
            tiles,
        }
    }

    /// `Aᵀ(y − A c)` with `subtract`, else `AᵀA c`, for the colours `c` of `proj`.
    fn product(&self, proj: &mut [Projected], c: &[[f32; 3]], subtract: bool) -> Vec<[f32; 3]> {
        for (g, c) in proj.iter_mut().zip(c) {
            g.color = *c;
        }
        let (width, height, target) = (self.width, self.height, self.target);
        match &self.tiles {
            Some(tiles) => raster::sum_adjoint(proj, tiles, width, height, None, |acc, rect| {
                if !subtract {
                    return acc.clone();
                }
                let mut d = Planes::gather(target, width, rect);
                for (dc, ac) in d.0.iter_mut().zip(&acc.0) {
                    dc.iter_mut().zip(ac).for_each(|(y, a)| *y -= a);
                }
                d
            }),
            None => {
                let f = raster::forward(proj, self.blend, width, height);
                let d = if subtract {
                    target.iter().zip(&f.image).map(|(y, a)| y - a).collect()
                } else {
                    f.image.clone()
                };
                raster::backward(&f, proj, &d, Need::ColorOnly)
                    .into_iter()
                    .map(|g| g.color)
                    .collect()
            }
        }
    }

    /// `iterations` CG steps on `(AᵀA + ε) x = Aᵀ y` from `x`, moving only the colours
    /// that `free` marks (all where `None`): the others stay as they are and are part of
    /// what the free ones are solved against.
    fn solve(
        &self,
        projected: &mut [Projected],
        x: &mut [[f32; 3]],
        free: Option<&[bool]>,
        iterations: usize,
    ) {
        let restrict = |v: &mut [[f32; 3]]| {
            if let Some(free) = free {
                for (v, &f) in v.iter_mut().zip(free) {
                    if !f {
                        *v = [0.0; 3];
                    }
                }
            }
        };
        // r = Aᵀ(y − A x) − ε x, on the free colours.
        let mut r = self.product(projected, x, true);
        for (ri, xi) in r.iter_mut().zip(x.iter()) {
            for ch in 0..3 {
                ri[ch] -= RIDGE * xi[ch];
            }
        }
        restrict(&mut r);
        let mut p = r.clone();
        let dot = |a: &[[f32; 3]], b: &[[f32; 3]]| -> [f64; 3] {
            let mut s = [0f64; 3];
            for (u, v) in a.iter().zip(b) {
                for ch in 0..3 {
                    s[ch] += f64::from(u[ch]) * f64::from(v[ch]);
                }
            }
            s
        };
        let mut rr = dot(&r, &r);
        for _ in 0..iterations {
            if rr.iter().all(|&v| v <= 1e-20) {
                break;
            }
            // q = (AᵀA + ε) p, per channel (p is 0 on every fixed colour).
            let mut q = self.product(projected, &p, false);
            for (qi, pi) in q.iter_mut().zip(&p) {
                for ch in 0..3 {
                    qi[ch] += RIDGE * pi[ch];
                }
            }
            restrict(&mut q);
            let pq = dot(&p, &q);
            let alpha = ratio(rr, pq);
            for ((xk, rk), (pk, qk)) in x.iter_mut().zip(r.iter_mut()).zip(p.iter().zip(&q)) {
                for ch in 0..3 {
                    xk[ch] += alpha[ch] * pk[ch];
                    rk[ch] -= alpha[ch] * qk[ch];
                }
            }
            let rr_new = dot(&r, &r);
            let beta = ratio(rr_new, rr);
            for (pk, rk) in p.iter_mut().zip(&r) {
                for ch in 0..3 {
                    pk[ch] = rk[ch] + beta[ch] * pk[ch];
                }
            }
            rr = rr_new;
        }
    }
}

/// `num / den` per channel, 0 where `den` is not positive (a direction the CG step
/// cannot move along).
fn ratio(num: [f64; 3], den: [f64; 3]) -> [f32; 3] {
    std::array::from_fn(|ch| {
        if den[ch] > 0.0 {
            (num[ch] / den[ch]) as f32
        } else {
            0.0
        }
    })
}

/// Solve for the colours of `projected` (written into their `color`) that best
/// reproduce `target` (interleaved RGB), running `iterations` CG steps from the
/// current colours. Returns the solved colour of each projected Gaussian.
pub fn solve_colors(
    projected: &mut [Projected],
    blend: Blend,
    width: u32,
    height: u32,
    target: &[f32],
    iterations: usize,
) -> Vec<[f32; 3]> {
    let normal = Normal::new(projected, blend, width, height, target);
    let mut x: Vec<[f32; 3]> = projected.iter().map(|g| g.color).collect();
    normal.solve(projected, &mut x, None, iterations);
    let x: Vec<[f32; 3]> = x
        .into_iter()
        .map(|c| c.map(|v| if v.is_finite() { v } else { 0.0 }))
        .collect();
    for (g, c) in projected.iter_mut().zip(&x) {
        g.color = *c;
    }
    x
}

/// Codes of the colours of `projected` (solved, as [`solve_colors`] leaves them) under
/// the quantizers `qs`, each colour's rounding error compensated by the colours not yet
/// rounded.
///
/// Rounding every colour to its nearest code alone leaves an error the colour solve had
/// removed: a Gaussian's quantization step times its footprint, summed where footprints
/// overlap. Here the colours are rounded a batch at a time, largest footprints first
/// (whose error reaches the most pixels), and after each batch the colours still free
/// are solved again (`iterations` CG steps) against what the rounded ones left, so that
/// they absorb it; the last batch, the smallest Gaussians, is rounded as it stands. This
/// is the rounding of weights in the GPTQ quantizer (Frantar et al., 2023) with the
/// image's own normal equations in place of a layer's Hessian.
pub fn quantize_colors(
    projected: &mut [Projected],
    blend: Blend,
    (width, height): (u32, u32),
    target: &[f32],
    qs: &[Quantizer; 3],
    steps: Option<&[f32]>,
    (batches, iterations): (usize, usize),
) -> Vec<[u32; 3]> {
    let n = projected.len();
    // Colours stored by footprint (spec §5.4.6): the code of `c` is that of `c / step`,
    // and a code's colour its value times `step` (powers of two: exact both ways).
    let step: Vec<f32> = projected
        .iter()
        .map(|g| steps.and_then(|s| s.get(g.index)).copied().unwrap_or(1.0))
        .collect();
    let round =
        |c: [f32; 3], s: f32| -> [u32; 3] { std::array::from_fn(|ch| qs[ch].quantize(c[ch] / s)) };
    let value = |q: [u32; 3], s: f32| -> [f32; 3] {
        std::array::from_fn(|ch| qs[ch].dequantize(q[ch]) * s)
    };
    let mut x: Vec<[f32; 3]> = projected.iter().map(|g| g.color).collect();
    let mut codes: Vec<[u32; 3]> = x.iter().zip(&step).map(|(&c, &s)| round(c, s)).collect();
    if batches <= 1 || iterations == 0 || n < 2 {
        return codes;
    }
    let normal = Normal::new(projected, blend, width, height, target);
    let mut order: Vec<usize> = (0..n).collect();
    let energy: Vec<f32> = projected.iter().map(footprint_energy).collect();
    order.sort_by(|&a, &b| energy[b].total_cmp(&energy[a]));
    let mut free = vec![true; n];
    for b in 0..batches {
        for &i in &order[n * b / batches..n * (b + 1) / batches] {
            codes[i] = round(x[i], step[i]);
            x[i] = value(codes[i], step[i]);
            free[i] = false;
        }
        if b + 1 < batches {
            normal.solve(projected, &mut x, Some(&free), iterations);
            // A colour the solve cannot make finite is rounded from 0, as the plain
            // solve gives it.
            for (c, &f) in x.iter_mut().zip(&free) {
                if f {
                    *c = c.map(|v| if v.is_finite() { v } else { 0.0 });
                }
            }
        }
    }
    codes
}

/// `Σ w²` over the pixels of a Gaussian of unit colour, as an integral (`π·o²·sqrt(det Σ)`,
/// the covariance widened by a pixel's own variance, 1/12 per axis, so that a Gaussian
/// narrower than a pixel still covers one): how far its rounding error reaches.
fn footprint_energy(g: &Projected) -> f32 {
    let [a, b, c] = g.conic;
    let det_conic = a * c - b * b;
    // (Also a NaN conic, which has no footprint to order by.)
    if det_conic.is_nan() || det_conic <= 0.0 {
        return 0.0;
    }
    // Σ is the conic's inverse: [[C, −B], [−B, A]] / det.
    let pixel = 1.0 / 12.0;
    let (sxx, sxy, syy) = (c / det_conic + pixel, -b / det_conic, a / det_conic + pixel);
    let det = sxx * syy - sxy * sxy;
    std::f32::consts::PI * g.opacity * g.opacity * det.max(0.0).sqrt()
}
