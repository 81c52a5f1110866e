//! The optimizer both stages train with: Adam (Kingma & Ba 2015), in one home.
//!
//! `AdamRule` is the arithmetic of one update, written once. [`Adam`] applies it to a
//! Gaussian set with a learning rate per attribute (stage 1, `fit`); `FlatAdam` to a
//! flat parameter vector (stage 2's enhancer, `enhance::fit`). The GPU twin of [`Adam`]
//! (`shaders/fit/fit_adam.wgsl`) takes its state from [`Adam`]'s fields and its bias
//! corrections from `AdamRule::corrections`, and hands the state back in the same shape.

use gsi_format::contract::{LN_SIGMA_MAX, LN_SIGMA_MIN};
use gsi_format::model::GaussianSet;

/// A step-size factor that decays on a half cosine from 1 at `t = 0` to `floor` at
/// `t = 1`: the schedule of both stages' optimizers (stage 1 to 5 %, stage 2 to 1 %).
pub fn cosine_decay(t: f32, floor: f32) -> f32 {
    floor + (1.0 - floor) * 0.5 * (1.0 + (std::f32::consts::PI * t).cos())
}

/// Adam (Kingma & Ba 2015) with one learning rate per parameter component.
pub struct Adam {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    /// Steps taken so far.
    pub step: i32,
    /// First and second moments, shaped like the parameters.
    pub m: GaussianSet,
    pub v: GaussianSet,
}

/// Learning rates per attribute component (normalized units for positions).
#[derive(Clone, Copy, Debug, PartialEq)]
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
            m: zeros_like(params),
            v: zeros_like(params),
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

/// Adam's update rule at one step: the one home of its arithmetic, shared by [`Adam`]
/// and [`FlatAdam`] (and mirrored by `shaders/fit/fit_adam.wgsl`).
#[derive(Clone, Copy)]
pub struct AdamRule {
    b1: f32,
    b2: f32,
    eps: f32,
    /// Bias corrections `1 − β^t`.
    c1: f32,
    c2: f32,
}

impl AdamRule {
    /// The rule at step `t` (counted from 1).
    pub fn at(b1: f32, b2: f32, eps: f32, t: i32) -> AdamRule {
        AdamRule {
            b1,
            b2,
            eps,
            c1: 1.0 - b1.powi(t),
            c2: 1.0 - b2.powi(t),
        }
    }

    /// The bias corrections `(1 − β1^t, 1 − β2^t)`, for a twin of [`AdamRule::update`]
    /// that runs elsewhere (`shaders/fit/fit_adam.wgsl`).
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pub fn corrections(&self) -> (f32, f32) {
        (self.c1, self.c2)
    }

    /// Move `p` along gradient `g` with moments `m`, `v`; a non-finite gradient counts
    /// as 0.
    #[inline]
    pub fn update(&self, p: &mut f32, g: f32, m: &mut f32, v: &mut f32, lr: f32) {
        let g = if g.is_finite() { g } else { 0.0 };
        *m = self.b1 * *m + (1.0 - self.b1) * g;
        *v = self.b2 * *v + (1.0 - self.b2) * g * g;
        *p -= lr * (*m / self.c1) / ((*v / self.c2).sqrt() + self.eps);
    }
}

/// Adam over a flat vector (non-finite gradients count as 0), with stage 2's constants
/// `β = (0.9, 0.999)`, `ε = 1e-8`.
pub struct FlatAdam {
    m: Vec<f32>,
    v: Vec<f32>,
    step: i32,
}

impl FlatAdam {
    pub fn new(n: usize) -> Self {
        FlatAdam {
            m: vec![0.0; n],
            v: vec![0.0; n],
            step: 0,
        }
    }

    pub fn update(&mut self, p: &mut [f32], g: &[f32], lr: f32) {
        self.step += 1;
        let rule = AdamRule::at(0.9, 0.999, 1e-8, self.step);
        for ((p, &g), (m, v)) in p.iter_mut().zip(g).zip(self.m.iter_mut().zip(&mut self.v)) {
            rule.update(p, g, m, v, lr);
        }
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

/// Zeros shaped like `params` (moments, gradients).
pub fn zeros_like(params: &GaussianSet) -> GaussianSet {
    GaussianSet {
        positions: vec![[0.0; 2]; params.len()],
        cov: vec![[0.0; 3]; params.len()],
        colors: vec![[0.0; 3]; params.len()],
        opacity: params.opacity.as_ref().map(|o| vec![0.0; o.len()]),
    }
}

#[cfg(test)]
mod tests {
    use super::cosine_decay;

    /// The shared schedule gives the bits each stage's own formula gave, at every step of
    /// a long run (the spans `1 − floor` round to the literals 0.95 and 0.99).
    #[test]
    fn the_cosine_is_each_stages_own() {
        let pi = std::f32::consts::PI;
        for i in 0..=4096u32 {
            let t = i as f32 / 4096.0;
            let c = 0.5 * (1.0 + (pi * t).cos());
            assert_eq!(cosine_decay(t, 0.05).to_bits(), (0.05 + 0.95 * c).to_bits());
            assert_eq!(cosine_decay(t, 0.01).to_bits(), (0.01 + 0.99 * c).to_bits());
        }
    }
}
