//! Differentiable rasterizer: the renderer of spec §6 with a backward pass.
//!
//! The forward pass evaluates exactly the per-pixel rule of [`Projected::alpha_at`] over
//! the same projection ([`crate::render::project`]), so an image rendered while fitting
//! is the image a decoder will produce from the same parameters. Tiles only choose which
//! Gaussians a pixel visits, in stored order, as in the CPU renderer.
//!
//! The backward pass returns, for each projected Gaussian, the gradient with respect to
//! its pixel-space mean, conic, opacity and colour; [`super::params`] chains those to the
//! stored parameters. Parallel work is split by bands of tile rows; each tile keeps its
//! own gradient slots and they are summed in a fixed order afterwards, so results do not
//! depend on the number of threads.

use crate::model::Blend;
use crate::render::{Projected, ALPHA_MAX, ALPHA_MIN, TILE, TRANSMITTANCE_MIN};

#[cfg(feature = "parallel")]
use rayon::prelude::*;

/// Gradient of the loss with respect to one projected Gaussian.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProjGrad {
    pub mean: [f32; 2],
    /// With respect to `(A, B, C)` of `power = -0.5(A dx² + C dy²) - B dx dy`.
    pub conic: [f32; 3],
    pub opacity: f32,
    pub color: [f32; 3],
}

impl ProjGrad {
    fn add(&mut self, o: &ProjGrad) {
        for k in 0..2 {
            self.mean[k] += o.mean[k];
        }
        for k in 0..3 {
            self.conic[k] += o.conic[k];
            self.color[k] += o.color[k];
        }
        self.opacity += o.opacity;
    }
}

/// Per-tile lists of projected-Gaussian indices, in stored order.
pub struct Tiles {
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// `lists[t]` for tile `t = ty * tiles_x + tx`.
    pub lists: Vec<Vec<u32>>,
}

impl Tiles {
    pub fn bin(projected: &[Projected], width: u32, height: u32) -> Tiles {
        let tiles_x = width.div_ceil(TILE);
        let tiles_y = height.div_ceil(TILE);
        let mut lists = vec![Vec::new(); (tiles_x * tiles_y) as usize];
        for (k, g) in projected.iter().enumerate() {
            let b = g.bbox;
            for ty in b.y0 / TILE..=b.y1 / TILE {
                for tx in b.x0 / TILE..=b.x1 / TILE {
                    lists[(ty * tiles_x + tx) as usize].push(k as u32);
                }
            }
        }
        Tiles {
            tiles_x,
            tiles_y,
            lists,
        }
    }
}

/// What the backward pass needs from the forward pass.
pub struct Forward {
    pub width: u32,
    pub height: u32,
    pub blend: Blend,
    /// Interleaved RGB, not clamped.
    pub image: Vec<f32>,
    pub tiles: Tiles,
    /// `alpha` blending: final transmittance of each pixel.
    final_t: Vec<f32>,
    /// `alpha` blending: one past the last position in its tile's list that contributed.
    n_visited: Vec<u32>,
}

/// Pixels of one tile: columns `x0..x1`, rows `y0..y1`, exclusive ends.
#[derive(Clone, Copy)]
struct Rect {
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
}

impl Rect {
    fn of_tile(t: usize, tiles_x: u32, width: u32, height: u32) -> Rect {
        let (tx, ty) = (t as u32 % tiles_x, t as u32 / tiles_x);
        Rect {
            x0: tx * TILE,
            x1: ((tx + 1) * TILE).min(width),
            y0: ty * TILE,
            y1: ((ty + 1) * TILE).min(height),
        }
    }

    /// Index of pixel `(i, j)` in a tile-local buffer of `TILE × TILE`.
    #[inline(always)]
    fn local(&self, i: u32, j: u32) -> usize {
        ((j - self.y0) * TILE + (i - self.x0)) as usize
    }
}

/// Visit the pixels of `rect` that Gaussian `g` may touch, as the CPU renderer does: the
/// rows of its box, on each row the columns of its analytic span. `f(i, j, alpha, dx,
/// dy, capped)` is called where the spec's rule lets the Gaussian touch the pixel.
#[inline(always)]
fn for_each_pixel(
    g: &Projected,
    rect: Rect,
    blend: Blend,
    mut f: impl FnMut(u32, u32, f32, f32, f32, bool),
) {
    let b = &g.bbox;
    let xs = b.x0.max(rect.x0)..(b.x1 + 1).min(rect.x1);
    let ys = b.y0.max(rect.y0)..(b.y1 + 1).min(rect.y1);
    if xs.is_empty() {
        return;
    }
    let [ca, cb, cc] = g.conic;
    let [mx, my] = g.mean;
    let cut = g.cutoff();
    for j in ys {
        let dy = (j as f32 + 0.5) - my;
        let cdy = cc * dy * dy;
        for i in g.row_span(dy, cut, &xs) {
            let dx = (i as f32 + 0.5) - mx;
            let power = -0.5 * (ca * dx * dx + cdy) - cb * dx * dy;
            if !(cut..=0.0).contains(&power) {
                continue;
            }
            let raw = g.opacity * power.exp();
            let (alpha, capped) = if blend == Blend::Alpha && raw > ALPHA_MAX {
                (ALPHA_MAX, true)
            } else {
                (raw, false)
            };
            if alpha >= ALPHA_MIN {
                f(i, j, alpha, dx, dy, capped);
            }
        }
    }
}

const TILE_PIXELS: usize = (TILE * TILE) as usize;

/// Render `projected` and keep what the backward pass needs.
pub fn forward(projected: &[Projected], blend: Blend, width: u32, height: u32) -> Forward {
    let tiles = Tiles::bin(projected, width, height);
    let alpha_mode = blend == Blend::Alpha;
    let per_tile = |t: usize| -> (
        [f32; TILE_PIXELS * 3],
        [f32; TILE_PIXELS],
        [u32; TILE_PIXELS],
    ) {
        let rect = Rect::of_tile(t, tiles.tiles_x, width, height);
        let mut acc = [0f32; TILE_PIXELS * 3];
        let mut trans = [1f32; TILE_PIXELS];
        let mut last = [0u32; TILE_PIXELS];
        for (pos, &k) in tiles.lists[t].iter().enumerate() {
            let g = &projected[k as usize];
            for_each_pixel(g, rect, blend, |i, j, alpha, _, _, _| {
                let p = rect.local(i, j);
                if alpha_mode {
                    let t = trans[p];
                    if t < TRANSMITTANCE_MIN {
                        return;
                    }
                    for ch in 0..3 {
                        acc[p * 3 + ch] += g.color[ch] * alpha * t;
                    }
                    trans[p] = t * (1.0 - alpha);
                    last[p] = pos as u32 + 1;
                } else {
                    for ch in 0..3 {
                        acc[p * 3 + ch] += g.color[ch] * alpha;
                    }
                }
            });
        }
        (acc, trans, last)
    };
    let n_tiles = tiles.lists.len();
    #[cfg(feature = "parallel")]
    let done: Vec<_> = (0..n_tiles).into_par_iter().map(per_tile).collect();
    #[cfg(not(feature = "parallel"))]
    let done: Vec<_> = (0..n_tiles).map(per_tile).collect();
    let px = (width * height) as usize;
    let mut image = vec![0f32; px * 3];
    let mut final_t = vec![1f32; if alpha_mode { px } else { 0 }];
    let mut n_visited = vec![0u32; if alpha_mode { px } else { 0 }];
    for (t, (acc, trans, last)) in done.iter().enumerate() {
        let rect = Rect::of_tile(t, tiles.tiles_x, width, height);
        for j in rect.y0..rect.y1 {
            for i in rect.x0..rect.x1 {
                let (p, l) = ((j * width + i) as usize, rect.local(i, j));
                image[p * 3..p * 3 + 3].copy_from_slice(&acc[l * 3..l * 3 + 3]);
                if alpha_mode {
                    final_t[p] = trans[l];
                    n_visited[p] = last[l];
                }
            }
        }
    }
    Forward {
        width,
        height,
        blend,
        image,
        tiles,
        final_t,
        n_visited,
    }
}

/// Which gradients to compute: all, or colours only (the least-squares colour solve).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Need {
    All,
    ColorOnly,
}

/// Gradients of the loss for every projected Gaussian, given `dl_dimage` (same layout as
/// [`Forward::image`]).
pub fn backward(
    fwd: &Forward,
    projected: &[Projected],
    dl_dimage: &[f32],
    need: Need,
) -> Vec<ProjGrad> {
    let (width, height, blend) = (fwd.width, fwd.height, fwd.blend);
    let tiles = &fwd.tiles;
    let all = need == Need::All;
    // One gradient slot per entry of each tile list, summed in a fixed order below.
    let per_tile = |t: usize| -> Vec<ProjGrad> {
        let list = &tiles.lists[t];
        let mut out = vec![ProjGrad::default(); list.len()];
        if list.is_empty() {
            return out;
        }
        let rect = Rect::of_tile(t, tiles.tiles_x, width, height);
        let mut d = [0f32; TILE_PIXELS * 3];
        for j in rect.y0..rect.y1 {
            for i in rect.x0..rect.x1 {
                let (p, l) = ((j * width + i) as usize, rect.local(i, j));
                d[l * 3..l * 3 + 3].copy_from_slice(&dl_dimage[p * 3..p * 3 + 3]);
            }
        }
        if blend == Blend::Sum {
            for (pos, &k) in list.iter().enumerate() {
                let g = &projected[k as usize];
                let mut s = ProjGrad::default();
                for_each_pixel(g, rect, blend, |i, j, alpha, dx, dy, _| {
                    let l = rect.local(i, j);
                    let mut dl_dalpha = 0.0;
                    for ch in 0..3 {
                        s.color[ch] += alpha * d[l * 3 + ch];
                        dl_dalpha += g.color[ch] * d[l * 3 + ch];
                    }
                    if all {
                        geometry(&mut s, g, alpha, dl_dalpha, dx, dy);
                    }
                });
                out[pos] = s;
            }
            return out;
        }
        // `alpha`: walk the list back to front, recovering each pixel's transmittance
        // before every Gaussian from the final one.
        let mut trans = [1f32; TILE_PIXELS];
        let mut last = [0u32; TILE_PIXELS];
        for j in rect.y0..rect.y1 {
            for i in rect.x0..rect.x1 {
                let (p, l) = ((j * width + i) as usize, rect.local(i, j));
                trans[l] = fwd.final_t[p];
                last[l] = fwd.n_visited[p];
            }
        }
        let mut behind = [0f32; TILE_PIXELS * 3]; // colour composited behind, per unit T
        let mut prev_alpha = [0f32; TILE_PIXELS];
        let mut prev_color = [0f32; TILE_PIXELS * 3];
        let end = last.iter().copied().max().unwrap_or(0) as usize;
        for pos in (0..end).rev() {
            let g = &projected[list[pos] as usize];
            let mut s = ProjGrad::default();
            for_each_pixel(g, rect, blend, |i, j, alpha, dx, dy, capped| {
                let l = rect.local(i, j);
                if pos as u32 >= last[l] {
                    return;
                }
                let t = trans[l] / (1.0 - alpha);
                trans[l] = t;
                let mut dl_dalpha = 0.0;
                for ch in 0..3 {
                    let b = prev_alpha[l] * prev_color[l * 3 + ch]
                        + (1.0 - prev_alpha[l]) * behind[l * 3 + ch];
                    behind[l * 3 + ch] = b;
                    let dd = d[l * 3 + ch];
                    s.color[ch] += alpha * t * dd;
                    dl_dalpha += (g.color[ch] - b) * t * dd;
                    prev_color[l * 3 + ch] = g.color[ch];
                }
                prev_alpha[l] = alpha;
                if all && !capped {
                    geometry(&mut s, g, alpha, dl_dalpha, dx, dy);
                }
            });
            out[pos] = s;
        }
        out
    };
    let n_tiles = tiles.lists.len();
    #[cfg(feature = "parallel")]
    let slots: Vec<Vec<ProjGrad>> = (0..n_tiles).into_par_iter().map(per_tile).collect();
    #[cfg(not(feature = "parallel"))]
    let slots: Vec<Vec<ProjGrad>> = (0..n_tiles).map(per_tile).collect();
    let mut grads = vec![ProjGrad::default(); projected.len()];
    for (list, slot) in tiles.lists.iter().zip(&slots) {
        for (&k, g) in list.iter().zip(slot) {
            grads[k as usize].add(g);
        }
    }
    grads
}

/// Chain `dL/dalpha` at one pixel to the mean, conic and opacity of the Gaussian.
#[inline(always)]
fn geometry(s: &mut ProjGrad, g: &Projected, alpha: f32, dl_dalpha: f32, dx: f32, dy: f32) {
    // alpha = o · exp(power): d alpha / d power = alpha, d alpha / d o = alpha / o.
    let dl_dpower = dl_dalpha * alpha;
    let [a, b, c] = g.conic;
    // power = -0.5(A dx² + C dy²) - B dx dy, with dx = px - mx.
    s.mean[0] += dl_dpower * (a * dx + b * dy);
    s.mean[1] += dl_dpower * (c * dy + b * dx);
    s.conic[0] += dl_dpower * -0.5 * dx * dx;
    s.conic[1] += dl_dpower * -dx * dy;
    s.conic[2] += dl_dpower * -0.5 * dy * dy;
    s.opacity += dl_dalpha * alpha / g.opacity;
}
