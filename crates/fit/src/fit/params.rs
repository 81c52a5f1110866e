//! The fitted parameters are a [`GaussianSet`] in the stored parameterization
//! (normalized centres, `log-scale-rotation` covariance, colour, opacity), so that what
//! the optimizer moves is exactly what is quantized and written. This module chains the
//! rasterizer's pixel-space gradients to those parameters; the optimizer that moves them
//! is [`gsi_optim::optim::Adam`].

use super::raster::ProjGrad;
use gsi_format::contract::{CORRELATION_MAX, LN_SIGMA_MAX, LN_SIGMA_MIN, VAR_MAX, VAR_MIN};
use gsi_format::model::{CovParam, GaussianSet};
use gsi_render::render::Projected;

/// Accumulate into `grads` the gradient of each projected Gaussian with respect to its
/// stored parameters, for an output of `width × height` pixels.
///
/// Clamps of spec §6 that are active pass no gradient (the value does not move with the
/// parameter there).
pub fn chain(
    params: &GaussianSet,
    projected: &[Projected],
    pg: &[ProjGrad],
    width: u32,
    height: u32,
    grads: &mut GaussianSet,
) {
    let (fw, fh) = (width as f32, height as f32);
    for (g, d) in projected.iter().zip(pg) {
        let i = g.index;
        grads.positions[i][0] += d.mean[0] * fw;
        grads.positions[i][1] += d.mean[1] * fh;
        for ch in 0..3 {
            grads.colors[i][ch] += d.color[ch];
        }
        if let (Some(go), Some(o)) = (grads.opacity.as_mut(), params.opacity.as_ref()) {
            if (0.0..=1.0).contains(&o[i]) {
                go[i] += d.opacity;
            }
        }
        // dL/dΣ = -Q G Q, with G the symmetric gradient of the conic Q = [[A, B], [B, C]]
        // (B enters `power` once, as -B dx dy, i.e. twice in dᵀQd / 2).
        let [qa, qb, qc] = g.conic;
        let [ga, gb, gc] = [d.conic[0], d.conic[1] * 0.5, d.conic[2]];
        // QG = [[qa ga + qb gb, qa gb + qb gc], [qb ga + qc gb, qb gb + qc gc]]
        let (m00, m01) = (qa * ga + qb * gb, qa * gb + qb * gc);
        let (m10, m11) = (qb * ga + qc * gb, qb * gb + qc * gc);
        // (QG)Q
        let d_a = -(m00 * qa + m01 * qb);
        let d_c = -(m10 * qb + m11 * qc);
        let d_b = -2.0 * (m00 * qb + m01 * qc);
        let p = params.cov[i];
        let s = CovParam::LogScaleRotation.covariance(p);
        let (a, b, c) = (s[0] * fw * fw, s[1] * fw * fh, s[2] * fh * fh);
        let live = |x: f32| (VAR_MIN..=VAR_MAX).contains(&x);
        let b_live = b.abs()
            < CORRELATION_MAX * (a.clamp(VAR_MIN, VAR_MAX) * c.clamp(VAR_MIN, VAR_MAX)).sqrt();
        let d_suu = if live(a) { d_a * fw * fw } else { 0.0 };
        let d_svv = if live(c) { d_c * fh * fh } else { 0.0 };
        let d_suv = if b_live { d_b * fw * fh } else { 0.0 };
        // Σ = R diag(v1, v2) Rᵀ with v = exp(2 p), R the rotation by θ = p[2].
        let (sin, cos) = p[2].sin_cos();
        let (v1, v2) = ((2.0 * p[0]).exp(), (2.0 * p[1]).exp());
        let (cc, ss, sc) = (cos * cos, sin * sin, sin * cos);
        let scale_live = |x: f32| (LN_SIGMA_MIN..=LN_SIGMA_MAX).contains(&x);
        if scale_live(p[0]) {
            grads.cov[i][0] += 2.0 * v1 * (d_suu * cc + d_suv * sc + d_svv * ss);
        }
        if scale_live(p[1]) {
            grads.cov[i][1] += 2.0 * v2 * (d_suu * ss - d_suv * sc + d_svv * cc);
        }
        let (s2, c2) = (2.0 * sc, cc - ss);
        grads.cov[i][2] += (v2 - v1) * s2 * d_suu + (v1 - v2) * c2 * d_suv + (v1 - v2) * s2 * d_svv;
    }
}

/// The `log-scale-rotation` parameters `p` rewritten with the angle in `[−π/4, π/4]`,
/// and whether the two scales were swapped to get there.
///
/// `(s1, s2, θ)`, `(s1, s2, θ + π)` and `(s2, s1, θ + π/2)` are one covariance, so every
/// Gaussian has a form whose angle lies in a quarter turn. A file whose angles lie in
/// `[−π/4, π/4]` quantizes them over a quarter of the range a free angle spreads over
/// (2π or more after a fit): the same step takes a code two bits narrower, and about one
/// bit fewer once range-coded, as fitted angles are not spread evenly (LOL eval15 at
/// 1 bpp, BENCHMARKS.md, angles within a quarter turn). The interval is
/// centred on 0 because fitted angles crowd about the axes: an interval with an end at an
/// axis would split that crowd over both ends. Non-finite angles are left alone.
pub fn canonical_rotation(p: [f32; 3]) -> ([f32; 3], bool) {
    let quarter = std::f32::consts::FRAC_PI_2;
    let turns = (p[2] / quarter).round();
    if !turns.is_finite() || turns == 0.0 {
        return (p, false);
    }
    let theta = (f64::from(p[2]) - f64::from(turns) * std::f64::consts::FRAC_PI_2) as f32;
    let theta = theta.clamp(-quarter / 2.0, quarter / 2.0);
    if turns.rem_euclid(2.0) == 1.0 {
        ([p[1], p[0], theta], true)
    } else {
        ([p[0], p[1], theta], false)
    }
}
