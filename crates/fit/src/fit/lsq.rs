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
use gsi_format::model::Blend;
use gsi_render::render::{Projected, TileLists};

/// Ridge term: keeps Gaussians that touch almost nothing from taking huge colours.
const RIDGE: f32 = 1e-3;

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
    let n = projected.len();
    let mut x: Vec<[f32; 3]> = projected.iter().map(|g| g.color).collect();
    // `sum` blending: each product a tile at a time ([`raster::sum_adjoint`]), over one
    // binning, since the geometry does not move. `alpha`: a forward pass, then the colour
    // part of the backward pass on the binning it made.
    let tiles = (blend == Blend::Sum).then(|| TileLists::bin(projected, width, height));
    let set = |proj: &mut [Projected], c: &[[f32; 3]]| {
        for (g, c) in proj.iter_mut().zip(c) {
            g.color = *c;
        }
    };
    let colors = |grads: Vec<raster::ProjGrad>| grads.into_iter().map(|g| g.color).collect();
    // Aᵀ d(A c), with `d` given the rendered pixels (interleaved RGB) and the target's.
    let product = |proj: &mut [Projected], c: &[[f32; 3]], subtract: bool| -> Vec<[f32; 3]> {
        set(proj, c);
        match &tiles {
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
                let f = raster::forward(proj, blend, width, height);
                let d = if subtract {
                    target.iter().zip(&f.image).map(|(y, a)| y - a).collect()
                } else {
                    f.image.clone()
                };
                colors(raster::backward(&f, proj, &d, Need::ColorOnly))
            }
        }
    };
    // r = Aᵀ(y − A x) − ε x
    let mut r = product(projected, &x, true);
    for (ri, xi) in r.iter_mut().zip(&x) {
        for ch in 0..3 {
            ri[ch] -= RIDGE * xi[ch];
        }
    }
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
        // q = (AᵀA + ε) p, per channel.
        let mut q = product(projected, &p, false);
        for (qi, pi) in q.iter_mut().zip(&p) {
            for ch in 0..3 {
                qi[ch] += RIDGE * pi[ch];
            }
        }
        let pq = dot(&p, &q);
        let alpha: [f32; 3] = std::array::from_fn(|ch| {
            if pq[ch] > 0.0 {
                (rr[ch] / pq[ch]) as f32
            } else {
                0.0
            }
        });
        for k in 0..n {
            for ch in 0..3 {
                x[k][ch] += alpha[ch] * p[k][ch];
                r[k][ch] -= alpha[ch] * q[k][ch];
            }
        }
        let rr_new = dot(&r, &r);
        let beta: [f32; 3] = std::array::from_fn(|ch| {
            if rr[ch] > 0.0 {
                (rr_new[ch] / rr[ch]) as f32
            } else {
                0.0
            }
        });
        for k in 0..n {
            for ch in 0..3 {
                p[k][ch] = r[k][ch] + beta[ch] * p[k][ch];
            }
        }
        rr = rr_new;
    }
    for (g, c) in projected.iter_mut().zip(&x) {
        g.color = c.map(|v| if v.is_finite() { v } else { 0.0 });
    }
    x
}
