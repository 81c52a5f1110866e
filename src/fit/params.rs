//! The fitted parameters are a [`GaussianSet`] in the stored parameterization
//! (normalized centres, `log-scale-rotation` covariance, colour, opacity), so that what
//! the optimizer moves is exactly what is quantized and written. This module chains the
//! rasterizer's pixel-space gradients to those parameters and holds the Adam optimizer.

use super::raster::ProjGrad;
use crate::model::{CovParam, GaussianSet, LN_SIGMA_MAX, LN_SIGMA_MIN};
use crate::render::{Projected, CORRELATION_MAX, VAR_MAX, VAR_MIN};

/// Gradients shaped like the parameters (opacity present when the parameters have it).
pub fn zero_grads(p: &GaussianSet) -> GaussianSet {
    GaussianSet {
        positions: vec![[0.0; 2]; p.len()],
        cov: vec![[0.0; 3]; p.len()],
        colors: vec![[0.0; 3]; p.len()],
        opacity: p.opacity.as_ref().map(|o| vec![0.0; o.len()]),
    }
}

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

/// Adam (Kingma & Ba 2015) with one learning rate per parameter component.
pub struct Adam {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    step: i32,
    m: GaussianSet,
    v: GaussianSet,
}

/// Learning rates per attribute component (normalized units for positions).
#[derive(Clone, Copy, Debug)]
pub struct LearningRates {
    pub position: f32,
    pub log_scale: f32,
    pub rotation: f32,
    pub color: f32,
    pub opacity: f32,
}

impl LearningRates {
    pub fn scaled(&self, f: f32) -> LearningRates {
        LearningRates {
            position: self.position * f,
            log_scale: self.log_scale * f,
            rotation: self.rotation * f,
            color: self.color * f,
            opacity: self.opacity * f,
        }
    }
}

impl Adam {
    pub fn new(params: &GaussianSet) -> Adam {
        Adam {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
            step: 0,
            m: zero_grads(params),
            v: zero_grads(params),
        }
    }

    /// Keep the moments of the Gaussians where `keep` is true, then append zeroed
    /// moments for `added` new ones (after pruning and densification).
    pub fn resize(&mut self, keep: &[bool], added: usize) {
        for s in [&mut self.m, &mut self.v] {
            retain(s, keep);
            let n = s.len() + added;
            s.positions.resize(n, [0.0; 2]);
            s.cov.resize(n, [0.0; 3]);
            s.colors.resize(n, [0.0; 3]);
            if let Some(o) = s.opacity.as_mut() {
                o.resize(n, 0.0);
            }
        }
    }

    /// A copy of the state, for an optimizer that continues elsewhere (the GPU fit).
    #[cfg(feature = "gpu")]
    pub(crate) fn state(&self) -> crate::gpu::fit::AdamState {
        crate::gpu::fit::AdamState {
            step: self.step,
            beta1: self.beta1,
            beta2: self.beta2,
            eps: self.eps,
            m: self.m.clone(),
            v: self.v.clone(),
        }
    }

    /// Continue from `state` (as [`Adam::state`] gave it, moved on elsewhere).
    #[cfg(feature = "gpu")]
    pub(crate) fn set_state(&mut self, state: crate::gpu::fit::AdamState) {
        self.step = state.step;
        self.m = state.m;
        self.v = state.v;
    }

    pub fn step(&mut self, params: &mut GaussianSet, grads: &GaussianSet, lr: &LearningRates) {
        self.step += 1;
        let rule = AdamRule::at(self.beta1, self.beta2, self.eps, self.step);
        let update =
            |p: &mut f32, g: f32, m: &mut f32, v: &mut f32, lr: f32| rule.update(p, g, m, v, lr);
        for i in 0..params.len() {
            for k in 0..2 {
                update(
                    &mut params.positions[i][k],
                    grads.positions[i][k],
                    &mut self.m.positions[i][k],
                    &mut self.v.positions[i][k],
                    lr.position,
                );
            }
            for k in 0..3 {
                let rate = if k < 2 { lr.log_scale } else { lr.rotation };
                update(
                    &mut params.cov[i][k],
                    grads.cov[i][k],
                    &mut self.m.cov[i][k],
                    &mut self.v.cov[i][k],
                    rate,
                );
                update(
                    &mut params.colors[i][k],
                    grads.colors[i][k],
                    &mut self.m.colors[i][k],
                    &mut self.v.colors[i][k],
                    lr.color,
                );
            }
            if let (Some(o), Some(go), Some(mo), Some(vo)) = (
                params.opacity.as_mut(),
                grads.opacity.as_ref(),
                self.m.opacity.as_mut(),
                self.v.opacity.as_mut(),
            ) {
                update(&mut o[i], go[i], &mut mo[i], &mut vo[i], lr.opacity);
                o[i] = o[i].clamp(0.0, 1.0);
            }
            // Keep parameters where the spec's clamps leave them a gradient.
            for k in 0..2 {
                params.cov[i][k] = params.cov[i][k].clamp(LN_SIGMA_MIN, LN_SIGMA_MAX);
            }
        }
    }
}

/// Adam's update rule at one step: the one home of its arithmetic, shared by this
/// optimizer and stage 2's (`enhance::fit`).
#[derive(Clone, Copy)]
pub(crate) struct AdamRule {
    b1: f32,
    b2: f32,
    eps: f32,
    /// Bias corrections `1 − β^t`.
    c1: f32,
    c2: f32,
}

impl AdamRule {
    /// The rule at step `t` (counted from 1).
    pub(crate) fn at(b1: f32, b2: f32, eps: f32, t: i32) -> AdamRule {
        AdamRule {
            b1,
            b2,
            eps,
            c1: 1.0 - b1.powi(t),
            c2: 1.0 - b2.powi(t),
        }
    }

    /// Move `p` along gradient `g` with moments `m`, `v`; a non-finite gradient counts
    /// as 0.
    #[inline]
    pub(crate) fn update(&self, p: &mut f32, g: f32, m: &mut f32, v: &mut f32, lr: f32) {
        let g = if g.is_finite() { g } else { 0.0 };
        *m = self.b1 * *m + (1.0 - self.b1) * g;
        *v = self.b2 * *v + (1.0 - self.b2) * g * g;
        *p -= lr * (*m / self.c1) / ((*v / self.c2).sqrt() + self.eps);
    }
}

/// Keep the Gaussians where `keep` is true.
pub fn retain(s: &mut GaussianSet, keep: &[bool]) {
    fn filter<T: Copy>(v: &mut Vec<T>, keep: &[bool]) {
        let mut it = keep.iter();
        v.retain(|_| *it.next().unwrap_or(&true));
    }
    filter(&mut s.positions, keep);
    filter(&mut s.cov, keep);
    filter(&mut s.colors, keep);
    if let Some(o) = s.opacity.as_mut() {
        filter(o, keep);
    }
}
