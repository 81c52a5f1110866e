//! The render as a matrix: with geometry frozen, every pixel is a fixed linear
//! combination of the Gaussians' colours (`C = A·c`, in both blend modes, since `alpha`
//! blending's transmittance depends on opacities only). Building `A` once costs about
//! one render; afterwards an enhancement iteration renders with a sparse product and
//! back-propagates with its transpose, never touching a Gaussian's shape again.

use gsi_format::contract::{COLOR_MAX, TRANSMITTANCE_MIN};
use gsi_format::model::{Blend, Scene};
use gsi_render::render::{project_scene, TileLists};

/// `A` in compressed-row form: row `p` (pixel `p`, row-major) holds the Gaussians that
/// reach it and their weights, in blending order.
pub struct ColorOperator {
    pub width: u32,
    pub height: u32,
    row_start: Vec<u32>,
    gaussian: Vec<u32>,
    weight: Vec<f32>,
}

impl ColorOperator {
    /// `A` of `scene` rendered at `width × height`, following the pixel contract of
    /// spec §6 exactly (same boxes, thresholds, alpha cap and transmittance stop as the
    /// decoder), so `A·c` is what `gsi decode` would show at that size.
    pub fn new(scene: &Scene, width: u32, height: u32) -> ColorOperator {
        let proj = project_scene(scene, width, height);
        let tiles = TileLists::bin(&proj, width, height);
        let tile = gsi_render::render::TILE;
        let mut row_start = Vec::with_capacity((width * height) as usize + 1);
        let (mut gaussian, mut weight) = (Vec::new(), Vec::new());
        row_start.push(0);
        for j in 0..height {
            for i in 0..width {
                let list = tiles.list(((j / tile) * tiles.tiles_x + i / tile) as usize);
                let mut t = 1.0f32;
                for &k in list {
                    let g = &proj[k as usize];
                    let Some(alpha) = g.alpha_at(i, j, scene.blend) else {
                        continue;
                    };
                    let w = match scene.blend {
                        Blend::Sum => alpha,
                        Blend::Alpha => {
                            if t < TRANSMITTANCE_MIN {
                                break;
                            }
                            let w = alpha * t;
                            t *= 1.0 - alpha;
                            w
                        }
                    };
                    gaussian.push(g.index as u32);
                    weight.push(w);
                }
                row_start.push(gaussian.len() as u32);
            }
        }
        ColorOperator {
            width,
            height,
            row_start,
            gaussian,
            weight,
        }
    }

    /// Stored weights: the cost of one product.
    pub fn nonzeros(&self) -> usize {
        self.weight.len()
    }

    fn row(&self, p: usize) -> (&[u32], &[f32]) {
        let r = self.row_start[p] as usize..self.row_start[p + 1] as usize;
        (&self.gaussian[r.clone()], &self.weight[r])
    }

    /// `out = A·c`: `width·height·3` floats. Colours are clamped to `±COLOR_MAX` as the
    /// decoder clamps them.
    pub fn render(&self, colors: &[[f32; 3]], out: &mut [f32]) {
        let fill = |(p, px): (usize, &mut [f32])| {
            let (g, w) = self.row(p);
            let mut acc = [0.0f32; 3];
            for (&k, &w) in g.iter().zip(w) {
                let c = colors[k as usize];
                for (a, c) in acc.iter_mut().zip(c) {
                    *a += c.clamp(-COLOR_MAX, COLOR_MAX) * w;
                }
            }
            px.copy_from_slice(&acc);
        };
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            out.par_chunks_exact_mut(3)
                .with_min_len(1024)
                .enumerate()
                .for_each(fill);
        }
        #[cfg(not(feature = "parallel"))]
        out.chunks_exact_mut(3).enumerate().for_each(fill);
    }

    /// `grad_colors = Aᵀ·grad_image` (overwritten). Sequential: a scatter, and cheap.
    pub fn transpose(&self, grad_image: &[f32], grad_colors: &mut [[f32; 3]]) {
        grad_colors.fill([0.0; 3]);
        for (p, g) in grad_image.chunks_exact(3).enumerate() {
            if g == [0.0; 3] {
                continue;
            }
            let (idx, w) = self.row(p);
            for (&k, &w) in idx.iter().zip(w) {
                let o = &mut grad_colors[k as usize];
                o[0] += w * g[0];
                o[1] += w * g[1];
                o[2] += w * g[2];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_synth::{random_scene, SceneSpec};

    #[test]
    fn the_matrix_renders_what_the_decoder_renders() {
        for blend in [Blend::Sum, Blend::Alpha] {
            let scene = random_scene(7, SceneSpec::new(37, 29, 60, blend));
            for (w, h) in [(37, 29), (20, 15), (64, 50)] {
                let a = ColorOperator::new(&scene, w, h);
                let mut out = vec![0.0; (w * h * 3) as usize];
                a.render(&scene.gaussians.colors, &mut out);
                let want = gsi_render::render::render(&scene, w, h).unwrap();
                for (x, y) in out.iter().zip(&want.data) {
                    assert!(
                        (x - y).abs() <= 1e-5 * (1.0 + y.abs()),
                        "{blend:?} {w}x{h}: {x} vs {y}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_transpose_is_the_adjoint() {
        let scene = random_scene(8, SceneSpec::new(30, 20, 40, Blend::Alpha));
        let a = ColorOperator::new(&scene, 30, 20);
        let mut rng = gsi_optim::rng::SplitMix64::new(1);
        let c: Vec<[f32; 3]> = (0..40)
            .map(|_| [rng.unit(), rng.unit(), rng.unit()])
            .collect();
        let y: Vec<f32> = (0..30 * 20 * 3).map(|_| rng.range(-1.0, 1.0)).collect();
        let mut ac = vec![0.0; y.len()];
        a.render(&c, &mut ac);
        let mut aty = vec![[0.0; 3]; 40];
        a.transpose(&y, &mut aty);
        let lhs: f64 = ac.iter().zip(&y).map(|(a, b)| f64::from(a * b)).sum();
        let rhs: f64 = aty
            .iter()
            .flatten()
            .zip(c.iter().flatten())
            .map(|(a, b)| f64::from(a * b))
            .sum();
        assert!(
            (lhs - rhs).abs() < 1e-3 * lhs.abs().max(1.0),
            "{lhs} vs {rhs}"
        );
    }
}
