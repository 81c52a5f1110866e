//! Differentiable rasterizer: the renderer of spec §6 with a backward pass.
//!
//! Both passes apply the per-pixel rule of [`Projected::alpha_at`] over the same
//! projection ([`gsi_render::render::project`]) and tile lists as the decoder. In `alpha`
//! blending the forward pass gives the decoder's pixels bit for bit; `sum` blending, the
//! default, goes through `fit::lanes`, eight pixels at a time, and gives the decoder's
//! pixels bit for bit too (test `forward_matches_the_decoder`).
//! The file an encode writes is measured with the decoder itself.
//!
//! The backward pass returns, for each projected Gaussian, the gradient with respect to
//! its pixel-space mean, conic, opacity and colour; [`super::params`] chains those to the
//! stored parameters. Parallel work is split by bands of tile rows; each tile keeps its
//! own gradient slots and they are summed in a fixed order afterwards, so results do not
//! depend on the number of threads.

use super::lanes::{self, Planes};
use gsi_format::contract::{ALPHA_MAX, ALPHA_MIN, TRANSMITTANCE_MIN};
use gsi_format::model::Blend;
use gsi_render::render::{Projected, Rect, TileLists, TILE};
use std::ops::Range;

#[cfg(feature = "parallel")]
use rayon::prelude::*;

pub use super::lanes::ProjGrad;

/// What the backward pass needs from the forward pass.
pub struct Forward {
    pub width: u32,
    pub height: u32,
    pub blend: Blend,
    /// Interleaved RGB, not clamped.
    pub image: Vec<f32>,
    pub(crate) tiles: TileLists,
    /// `alpha` blending: final transmittance of each pixel.
    final_t: Vec<f32>,
    /// `alpha` blending: one past the last position in its tile's list that contributed.
    n_visited: Vec<u32>,
}

/// The spec's per-pixel rule (§6.3) at offset `(dx, dy)`, with `cdy = C·dy²` hoisted out
/// of the row: `(alpha, capped)` where the Gaussian touches the pixel. Below `cut`
/// ([`Projected::cutoff`]) alpha is certainly under the threshold and `exp` is spared.
#[inline(always)]
fn touch(g: &Projected, cut: f32, dx: f32, dy: f32, cdy: f32, blend: Blend) -> Option<(f32, bool)> {
    let power = -0.5 * (g.conic[0] * dx * dx + cdy) - g.conic[1] * dx * dy;
    if !(cut..=0.0).contains(&power) {
        return None;
    }
    let raw = g.opacity * gsi_format::contract::exp(power);
    let (alpha, capped) = if blend == Blend::Alpha && raw > ALPHA_MAX {
        (ALPHA_MAX, true)
    } else {
        (raw, false)
    };
    (alpha >= ALPHA_MIN).then_some((alpha, capped))
}

const TILE_PIXELS: usize = (TILE * TILE) as usize;

/// Alphas of `g` along row `j` over columns `xs` (at most a tile wide), 0 where it does
/// not touch. Computed apart from the accumulation that uses them, so that the `exp`
/// call does not force every accumulator out of registers.
#[inline(always)]
fn row_alphas(
    g: &Projected,
    cut: f32,
    j: u32,
    xs: &Range<u32>,
    blend: Blend,
) -> (f32, [f32; TILE as usize]) {
    let dy = (j as f32 + 0.5) - g.mean[1];
    let cdy = g.conic[2] * dy * dy;
    let mut alphas = [0f32; TILE as usize];
    for (a, i) in alphas.iter_mut().zip(xs.clone()) {
        if let Some((alpha, _)) = touch(g, cut, (i as f32 + 0.5) - g.mean[0], dy, cdy, blend) {
            *a = alpha;
        }
    }
    (dy, alphas)
}

/// Render `projected` and keep what the backward pass needs.
pub fn forward(projected: &[Projected], blend: Blend, width: u32, height: u32) -> Forward {
    let tiles = TileLists::bin(projected, width, height);
    let alpha_mode = blend == Blend::Alpha;
    if !alpha_mode {
        // `sum` needs nothing but the image, rendered a row of tiles at a time.
        let mut image = vec![0f32; (width * height * 3) as usize];
        let band_len = (TILE * width * 3) as usize;
        let tiles_x = tiles.tiles_x as usize;
        let per_band = |acc: &mut Planes, (ty, rows): (usize, &mut [f32])| {
            for t in ty * tiles_x..(ty + 1) * tiles_x {
                let rect = Rect::of_tile(t, tiles.tiles_x, width, height);
                *acc = Planes::zero();
                lanes::forward_tile(tiles.list(t), projected, rect, acc, None);
                acc.scatter(rows, width, rect);
            }
        };
        #[cfg(feature = "parallel")]
        image
            .par_chunks_mut(band_len)
            .enumerate()
            .for_each_init(Planes::zero, per_band);
        #[cfg(not(feature = "parallel"))]
        {
            let mut acc = Planes::zero();
            image
                .chunks_mut(band_len)
                .enumerate()
                .for_each(|item| per_band(&mut acc, item));
        }
        return Forward {
            width,
            height,
            blend,
            image,
            tiles,
            final_t: Vec::new(),
            n_visited: Vec::new(),
        };
    }
    let per_tile = |t: usize| -> (
        [f32; TILE_PIXELS * 3],
        [f32; TILE_PIXELS],
        [u32; TILE_PIXELS],
    ) {
        let rect = Rect::of_tile(t, tiles.tiles_x, width, height);
        let mut acc = [0f32; TILE_PIXELS * 3];
        let mut trans = [1f32; TILE_PIXELS];
        let mut last = [0u32; TILE_PIXELS];
        for (pos, &k) in tiles.list(t).iter().enumerate() {
            let g = &projected[k as usize];
            let Some((xs, ys)) = g.bbox.clip(rect) else {
                continue;
            };
            let cut = g.cutoff();
            let col = g.color;
            for j in ys {
                let (_, alphas) = row_alphas(g, cut, j, &xs, blend);
                let l0 = rect.local(xs.start, j);
                let px_row = acc[l0 * 3..(l0 + xs.len()) * 3].chunks_exact_mut(3);
                let t_row = &mut trans[l0..l0 + xs.len()];
                let n_row = &mut last[l0..l0 + xs.len()];
                for (((px, t), n), &alpha) in px_row.zip(t_row).zip(n_row).zip(&alphas) {
                    if alpha == 0.0 || *t < TRANSMITTANCE_MIN {
                        continue;
                    }
                    px[0] += col[0] * alpha * *t;
                    px[1] += col[1] * alpha * *t;
                    px[2] += col[2] * alpha * *t;
                    *t *= 1.0 - alpha;
                    *n = pos as u32 + 1;
                }
            }
        }
        (acc, trans, last)
    };
    let n_tiles = tiles.len();
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
        let w = (rect.x1 - rect.x0) as usize;
        for j in rect.y0..rect.y1 {
            let (p, l) = ((j * width + rect.x0) as usize, rect.local(rect.x0, j));
            image[p * 3..(p + w) * 3].copy_from_slice(&acc[l * 3..(l + w) * 3]);
            if alpha_mode {
                final_t[p..p + w].copy_from_slice(&trans[l..l + w]);
                n_visited[p..p + w].copy_from_slice(&last[l..l + w]);
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
        let list = tiles.list(t);
        let mut out = vec![ProjGrad::default(); list.len()];
        if list.is_empty() {
            return out;
        }
        let rect = Rect::of_tile(t, tiles.tiles_x, width, height);
        if blend == Blend::Sum {
            let d = Planes::gather(dl_dimage, width, rect);
            lanes::backward_tile(list, projected, rect, &d, &mut out, all, None);
            return out;
        }
        let mut d = [0f32; TILE_PIXELS * 3];
        for j in rect.y0..rect.y1 {
            for i in rect.x0..rect.x1 {
                let (p, l) = ((j * width + i) as usize, rect.local(i, j));
                d[l * 3..l * 3 + 3].copy_from_slice(&dl_dimage[p * 3..p * 3 + 3]);
            }
        }
        // `alpha`: walk the list back to front, recovering each pixel's transmittance
        // before every Gaussian from the final one.
        let mut trans = [1f32; TILE_PIXELS];
        let mut last = [0u32; TILE_PIXELS];
        for j in rect.y0..rect.y1 {
            let w = (rect.x1 - rect.x0) as usize;
            let (p, l) = ((j * width + rect.x0) as usize, rect.local(rect.x0, j));
            trans[l..l + w].copy_from_slice(&fwd.final_t[p..p + w]);
            last[l..l + w].copy_from_slice(&fwd.n_visited[p..p + w]);
        }
        let mut behind = [0f32; TILE_PIXELS * 3]; // colour composited behind, per unit T
        let mut prev_alpha = [0f32; TILE_PIXELS];
        let mut prev_color = [0f32; TILE_PIXELS * 3];
        let end = last.iter().copied().max().unwrap_or(0) as usize;
        for pos in (0..end).rev() {
            let g = &projected[list[pos] as usize];
            let Some((xs, ys)) = g.bbox.clip(rect) else {
                continue;
            };
            let cut = g.cutoff();
            let mx = g.mean[0];
            let mut s = ProjGrad::default();
            for j in ys {
                let (dy, alphas) = row_alphas(g, cut, j, &xs, blend);
                for (&alpha, i) in alphas.iter().zip(xs.clone()) {
                    let l = rect.local(i, j);
                    if alpha == 0.0 || pos as u32 >= last[l] {
                        continue;
                    }
                    // A capped alpha does not move with the geometry.
                    let capped = alpha >= ALPHA_MAX;
                    let dx = (i as f32 + 0.5) - mx;
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
                }
            }
            out[pos] = s;
        }
        out
    };
    let n_tiles = tiles.len();
    #[cfg(feature = "parallel")]
    let slots: Vec<Vec<ProjGrad>> = (0..n_tiles).into_par_iter().map(per_tile).collect();
    #[cfg(not(feature = "parallel"))]
    let slots: Vec<Vec<ProjGrad>> = (0..n_tiles).map(per_tile).collect();
    let mut grads = vec![ProjGrad::default(); projected.len()];
    for (list, slot) in tiles.iter().zip(&slots) {
        for (&k, g) in list.iter().zip(slot) {
            grads[k as usize].add(g);
        }
    }
    grads
}

/// What [`step_l2_sum`] returns: the render, the loss and the gradients of one step.
pub struct Step {
    /// Interleaved RGB, not clamped; empty unless asked for.
    pub image: Vec<f32>,
    /// Mean squared error over the image's values.
    pub loss: f32,
    pub grads: Vec<ProjGrad>,
}

/// One fitting step of `sum` blending under the L2 loss, tile by tile: render a tile,
/// take the loss's gradient on its pixels, and run the tile's backward pass while the
/// alphas its forward pass kept are still in cache. The L2 gradient of a pixel depends
/// on that pixel alone, which is what lets the passes meet per tile; the gradients have
/// the bits of [`forward`], [`super::loss::LossFn`] and [`backward`] run one after the
/// other (test `fused_step_gives_the_gradients_of_the_passes`), and the backward pass no
/// longer evaluates the Gaussians (about half of its work).
///
/// The render is kept only `with_image` (a measured step): otherwise [`Step::image`] is
/// empty, and a 12 MP step allocates and writes 144 MB less.
pub fn step_l2_sum(
    projected: &[Projected],
    target: &[f32],
    width: u32,
    height: u32,
    with_image: bool,
) -> Step {
    let tiles = TileLists::bin(projected, width, height);
    let mut image = vec![
        0f32;
        if with_image {
            (width * height * 3) as usize
        } else {
            0
        }
    ];
    let n = (width * height * 3) as f32;
    let (grads, sum) = sum_tiles(
        projected,
        &tiles,
        width,
        height,
        true,
        with_image.then_some(&mut image[..]),
        |acc, rect| {
            // `d` = dL/dimage over the tile, as `LossFn::eval` computes it.
            let mut d = Planes::gather(target, width, rect);
            let mut sum = 0f64;
            for j in rect.y0..rect.y1 {
                for i in rect.x0..rect.x1 {
                    let l = rect.local(i, j);
                    for ch in 0..3 {
                        let diff = acc.0[ch][l] - d.0[ch][l];
                        sum += f64::from(diff * diff);
                        d.0[ch][l] = 2.0 * diff / n;
                    }
                }
            }
            (d, sum)
        },
    );
    Step {
        image,
        loss: (sum / f64::from(n)) as f32,
        grads,
    }
}

/// `Aᵀ d(A c)` of `sum` blending, where `A c` renders the colours of `projected` over
/// `tiles` (into `image`, when given) and `d` maps a rendered tile to the tile of values
/// the adjoint takes: the colour part of [`backward`] after [`forward`], a tile at a time
/// on the alphas the forward pass kept, with the same bits (the least-squares colour
/// solve, where the geometry and so the binning stay fixed across its iterations, and
/// the contributions that pruning ranks).
pub(super) fn sum_adjoint(
    projected: &[Projected],
    tiles: &TileLists,
    width: u32,
    height: u32,
    image: Option<&mut [f32]>,
    d: impl Fn(&Planes, Rect) -> Planes + Sync,
) -> Vec<[f32; 3]> {
    let (grads, _) = sum_tiles(
        projected,
        tiles,
        width,
        height,
        false,
        image,
        |acc, rect| (d(acc, rect), 0.0),
    );
    grads.into_iter().map(|g| g.color).collect()
}

/// The tile loop of [`step_l2_sum`] and [`sum_adjoint`]: per tile, render it (into
/// `image`, when given), let `d` turn the render into the values the backward pass takes
/// (and a sum it adds up), and run the backward pass for every gradient (`all`) or the
/// colours only. Bands of tile rows run in parallel; each tile's slots are summed per
/// Gaussian in tile order afterwards, so the results do not depend on the threads.
fn sum_tiles(
    projected: &[Projected],
    tiles: &TileLists,
    width: u32,
    height: u32,
    all: bool,
    image: Option<&mut [f32]>,
    d: impl Fn(&Planes, Rect) -> (Planes, f64) + Sync,
) -> (Vec<ProjGrad>, f64) {
    let tiles_x = tiles.tiles_x as usize;
    // Per thread: the tile's render and the kept alphas.
    let scratch = || (Planes::zero(), Vec::new());
    let per_band =
        |(acc, kept): &mut (Planes, Vec<f32>), ty: usize, mut rows: Option<&mut [f32]>| {
            let mut slots = Vec::with_capacity(tiles_x);
            let mut sum = 0f64;
            for t in ty * tiles_x..(ty + 1) * tiles_x {
                let list = tiles.list(t);
                let rect = Rect::of_tile(t, tiles.tiles_x, width, height);
                *acc = Planes::zero();
                kept.clear();
                let keep = list.len() <= lanes::KEPT_LIST_MAX;
                lanes::forward_tile(list, projected, rect, acc, keep.then_some(&mut *kept));
                if let Some(rows) = rows.as_deref_mut() {
                    acc.scatter(rows, width, rect);
                }
                let (dt, s) = d(acc, rect);
                sum += s;
                let mut out = vec![ProjGrad::default(); list.len()];
                let kept = keep.then_some(&kept[..]);
                lanes::backward_tile(list, projected, rect, &dt, &mut out, all, kept);
                slots.push(out);
            }
            (slots, sum)
        };
    let band_len = (TILE * width * 3) as usize;
    let bands_n = height.div_ceil(TILE) as usize;
    #[cfg(feature = "parallel")]
    let bands: Vec<_> = match image {
        Some(image) => image
            .par_chunks_mut(band_len)
            .enumerate()
            .map_init(scratch, |s, (ty, rows)| per_band(s, ty, Some(rows)))
            .collect(),
        None => (0..bands_n)
            .into_par_iter()
            .map_init(scratch, |s, ty| per_band(s, ty, None))
            .collect(),
    };
    #[cfg(not(feature = "parallel"))]
    let bands: Vec<_> = {
        let mut s = scratch();
        match image {
            Some(image) => image
                .chunks_mut(band_len)
                .enumerate()
                .map(|(ty, rows)| per_band(&mut s, ty, Some(rows)))
                .collect(),
            None => (0..bands_n).map(|ty| per_band(&mut s, ty, None)).collect(),
        }
    };
    let mut grads = vec![ProjGrad::default(); projected.len()];
    let mut sum = 0f64;
    let slots = bands.iter().flat_map(|(slots, s)| {
        sum += s;
        slots
    });
    for (list, slot) in tiles.iter().zip(slots) {
        for (&k, g) in list.iter().zip(slot) {
            grads[k as usize].add(g);
        }
    }
    (grads, sum)
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
