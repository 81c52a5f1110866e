//! The tiled CPU rasterizer.
//!
//! Work is split into bands of [`TILE`] pixel rows. Each band owns a contiguous slice of
//! the output, so bands can be rendered on different threads without sharing or
//! `unsafe`. Inside a band, Gaussians are binned per 16×16 tile; a tile visits its list
//! in stored order and evaluates only the pixels inside both the tile and the
//! Gaussian's box. Which thread renders a band never changes the arithmetic, so the
//! parallel and sequential builds give identical bits.

use super::project::{Projected, Rect};
use super::tiles::{runs, Bins, Span};
use super::TILE;
use crate::contract::{ALPHA_MAX, ALPHA_MIN, TRANSMITTANCE_MIN};
use crate::model::{Blend, ToneCurve};
use std::ops::Range;

/// Most entries of the per-band lists binned at once (64 MiB of indices).
const BAND_BUDGET: u64 = 1 << 24;
/// Most entries of one band's per-tile lists binned at once, per thread (4 MiB).
const TILE_BUDGET: u64 = 1 << 20;
/// Tile area in pixels.
const TILE_PIXELS: usize = (TILE * TILE) as usize;

/// What the renderer writes a band of pixels into. Blending happens in `f32` RGB; an
/// output of another layout gets each band converted from a per-thread scratch band, so
/// that a whole-image `f32` copy is never made.
pub(crate) trait Output: Sync {
    type Elem: Copy + Send + Sync;
    /// Elements per pixel.
    const PER_PIXEL: usize;
    /// Have `draw` blend a band into `f32` RGB (zeroed by `draw`), stored into `out`.
    fn band(out: &mut [Self::Elem], scratch: &mut Vec<f32>, draw: impl FnOnce(&mut [f32]));
}

/// `f32` RGB, blended in place.
pub(crate) struct RgbF32;
/// 8-bit RGB by [`super::to_u8`].
pub(crate) struct Rgb8;
/// 8-bit RGBA by [`super::to_u8`], alpha 255.
pub(crate) struct Rgba8;
/// `f32` RGB as native-endian bytes (12 per pixel), for byte buffers such as `image`'s.
pub(crate) struct RgbF32Bytes;

impl Output for RgbF32 {
    type Elem = f32;
    const PER_PIXEL: usize = 3;
    fn band(out: &mut [f32], _: &mut Vec<f32>, draw: impl FnOnce(&mut [f32])) {
        draw(out)
    }
}

/// Blend a band of `pixels` pixels into `scratch` and hand it to `store`.
fn via_scratch(scratch: &mut Vec<f32>, pixels: usize, draw: impl FnOnce(&mut [f32])) -> &[f32] {
    scratch.clear();
    scratch.resize(pixels * 3, 0.0);
    draw(scratch);
    scratch
}

impl Output for Rgb8 {
    type Elem = u8;
    const PER_PIXEL: usize = 3;
    fn band(out: &mut [u8], scratch: &mut Vec<f32>, draw: impl FnOnce(&mut [f32])) {
        let rgb = via_scratch(scratch, out.len() / 3, draw);
        for (o, &c) in out.iter_mut().zip(rgb) {
            *o = super::to_u8(c);
        }
    }
}

impl Output for Rgba8 {
    type Elem = u8;
    const PER_PIXEL: usize = 4;
    fn band(out: &mut [u8], scratch: &mut Vec<f32>, draw: impl FnOnce(&mut [f32])) {
        let rgb = via_scratch(scratch, out.len() / 4, draw);
        for (o, c) in out.chunks_exact_mut(4).zip(rgb.chunks_exact(3)) {
            o[..3].copy_from_slice(&[super::to_u8(c[0]), super::to_u8(c[1]), super::to_u8(c[2])]);
            o[3] = 255;
        }
    }
}

impl Output for RgbF32Bytes {
    type Elem = u8;
    const PER_PIXEL: usize = 12;
    fn band(out: &mut [u8], scratch: &mut Vec<f32>, draw: impl FnOnce(&mut [f32])) {
        let rgb = via_scratch(scratch, out.len() / 12, draw);
        for (o, c) in out.chunks_exact_mut(4).zip(rgb) {
            o.copy_from_slice(&c.to_ne_bytes());
        }
    }
}

/// Render projected Gaussians (in stored order) into `out`, `width * height` pixels of
/// `O`'s layout, every blended value through `tone` where there is one (spec §6.6).
pub(crate) fn render_projected<O: Output>(
    proj: &[Projected],
    blend: Blend,
    tone: Option<&ToneCurve>,
    (width, height): (u32, u32),
    out: &mut [O::Elem],
    parallel: bool,
) {
    let budgets = (BAND_BUDGET, TILE_BUDGET);
    render_budgeted::<O>(proj, blend, tone, (width, height), out, parallel, budgets);
}

/// [`render_projected`] with explicit binning budgets `(bands, tiles)`, so that tests can
/// force many small runs.
fn render_budgeted<O: Output>(
    proj: &[Projected],
    blend: Blend,
    tone: Option<&ToneCurve>,
    (width, height): (u32, u32),
    out: &mut [O::Elem],
    parallel: bool,
    (band_budget, tile_budget): (u64, u64),
) {
    debug_assert_eq!(out.len(), width as usize * height as usize * O::PER_PIXEL);
    let row_len = width as usize * O::PER_PIXEL;
    let band_len = TILE.min(height) as usize * row_len;
    let band_count = height.div_ceil(TILE);
    let spans = proj
        .iter()
        .enumerate()
        .map(|(k, p)| (k as u32, p.bbox.y0 / TILE, p.bbox.y1 / TILE));

    let cuts: Vec<f32> = proj.iter().map(Projected::cutoff).collect();
    let mut bands = Bins::default();
    for run in runs(spans.clone(), band_count, band_budget) {
        bands.fill(spans.clone(), run.clone());
        let start = run.start as usize * band_len;
        let end = (run.end as usize * band_len).min(out.len());
        let rows = &mut out[start..end];
        let job = |scratch: &mut Scratch, (k, rows): (usize, &mut [O::Elem])| {
            let band = run.start + k as u32;
            let ctx = Band {
                proj,
                cuts: &cuts,
                blend,
                width,
                y0: band * TILE,
                tile_budget,
            };
            let Scratch { tiles, band: rgb } = scratch;
            O::band(rows, rgb, |px| {
                ctx.render(bands.slot(band), px, tiles);
                if let Some(t) = tone {
                    t.apply(px);
                }
            });
        };
        #[cfg(feature = "parallel")]
        if parallel {
            use rayon::prelude::*;
            rows.par_chunks_mut(band_len)
                .enumerate()
                .for_each_init(Scratch::default, job);
            continue;
        }
        let _ = parallel;
        let mut scratch = Scratch::default();
        rows.chunks_mut(band_len)
            .enumerate()
            .for_each(|item| job(&mut scratch, item));
    }
}

/// Per-thread buffers, reused from band to band.
#[derive(Default)]
struct Scratch {
    tiles: Bins,
    /// One band in `f32` RGB, for outputs not blended in place.
    band: Vec<f32>,
}

/// What every tile of one band needs to know.
struct Band<'a> {
    proj: &'a [Projected],
    /// [`cutoff`] of each Gaussian's opacity.
    cuts: &'a [f32],
    blend: Blend,
    width: u32,
    /// First pixel row of the band.
    y0: u32,
    tile_budget: u64,
}

impl Band<'_> {
    /// Render the Gaussians of `list` (indices into `proj`, stored order) into `rows`,
    /// the band's pixel rows.
    fn render(&self, list: &[u32], rows: &mut [f32], tiles: &mut Bins) {
        rows.fill(0.0);
        if list.is_empty() {
            return;
        }
        let row_len = self.width as usize * 3;
        let y1 = self.y0 + (rows.len() / row_len) as u32;
        let tiles_x = self.width.div_ceil(TILE);
        let spans = list.iter().map(|&k| -> Span {
            let b = &self.proj[k as usize].bbox;
            (k, b.x0 / TILE, b.x1 / TILE)
        });
        for run in runs(spans.clone(), tiles_x, self.tile_budget) {
            tiles.fill(spans.clone(), run.clone());
            for tx in run {
                let tile = tiles.slot(tx);
                if tile.is_empty() {
                    continue;
                }
                let x0 = tx * TILE;
                let rect = Rect {
                    x0,
                    x1: x0.saturating_add(TILE).min(self.width),
                    y0: self.y0,
                    y1,
                };
                match self.blend {
                    Blend::Sum => self.tile_sum(tile, rect, rows),
                    Blend::Alpha => self.tile_alpha(tile, rect, rows),
                }
            }
        }
    }

    /// `sum` blending: `acc += c · alpha` for every Gaussian of the tile, in list order.
    fn tile_sum(&self, list: &[u32], rect: Rect, rows: &mut [f32]) {
        let row_len = self.width as usize * 3;
        let centres = Centres::new(rect);
        let mut power = [0.0f32; TILE as usize];
        for &k in list {
            let g = &self.proj[k as usize];
            let Some((xs, ys)) = g.bbox.clip(rect) else {
                continue;
            };
            let (o, col) = (g.opacity, g.color);
            let cut = self.cuts[k as usize];
            for j in ys {
                let dy = (j as f32 + 0.5) - g.mean[1];
                let power = &mut power[..xs.len()];
                powers(g, centres.of(&xs, rect), dy, power);
                let base = (j - self.y0) as usize * row_len;
                let row = &mut rows[base + xs.start as usize * 3..base + xs.end as usize * 3];
                for (px, &power) in row.chunks_exact_mut(3).zip(power.iter()) {
                    // `power > 0` is skipped by the contract; below `cut`, alpha is
                    // certainly under ALPHA_MIN, so the exponential can be spared.
                    if !(cut..=0.0).contains(&power) {
                        continue;
                    }
                    let alpha = o * power.exp();
                    if alpha < ALPHA_MIN {
                        continue;
                    }
                    px[0] += col[0] * alpha;
                    px[1] += col[1] * alpha;
                    px[2] += col[2] * alpha;
                }
            }
        }
    }

    /// `alpha` blending: front to back in list order, with per-pixel transmittance.
    fn tile_alpha(&self, list: &[u32], rect: Rect, rows: &mut [f32]) {
        let row_len = self.width as usize * 3;
        let centres = Centres::new(rect);
        let mut power = [0.0f32; TILE as usize];
        let mut trans = [1.0f32; TILE_PIXELS];
        // Pixels of the tile still taking light; the tile is done when none is.
        let mut live = ((rect.x1 - rect.x0) * (rect.y1 - rect.y0)) as usize;
        for &k in list {
            let g = &self.proj[k as usize];
            let Some((xs, ys)) = g.bbox.clip(rect) else {
                continue;
            };
            let (o, col) = (g.opacity, g.color);
            let cut = self.cuts[k as usize];
            for j in ys {
                let dy = (j as f32 + 0.5) - g.mean[1];
                let power = &mut power[..xs.len()];
                powers(g, centres.of(&xs, rect), dy, power);
                let base = (j - self.y0) as usize * row_len;
                let row = &mut rows[base + xs.start as usize * 3..base + xs.end as usize * 3];
                let t0 = (j - rect.y0) as usize * TILE as usize + (xs.start - rect.x0) as usize;
                let trow = &mut trans[t0..t0 + xs.len()];
                for ((px, t), &power) in row.chunks_exact_mut(3).zip(trow).zip(power.iter()) {
                    if *t < TRANSMITTANCE_MIN || !(cut..=0.0).contains(&power) {
                        continue;
                    }
                    let alpha = (o * power.exp()).min(ALPHA_MAX);
                    if alpha < ALPHA_MIN {
                        continue;
                    }
                    px[0] += col[0] * alpha * *t;
                    px[1] += col[1] * alpha * *t;
                    px[2] += col[2] * alpha * *t;
                    *t *= 1.0 - alpha;
                    if *t < TRANSMITTANCE_MIN {
                        live -= 1;
                    }
                }
            }
            if live == 0 {
                break;
            }
        }
    }
}

/// `i as f32 + 0.5` for the columns `i` of a tile, computed once per tile.
struct Centres([f32; TILE as usize]);

impl Centres {
    fn new(rect: Rect) -> Self {
        // Past the image's last column the values are never read.
        Centres(std::array::from_fn(|k| {
            rect.x0.saturating_add(k as u32) as f32 + 0.5
        }))
    }

    /// The centres of columns `xs`, which lie in `rect`.
    #[inline]
    fn of(&self, xs: &Range<u32>, rect: Rect) -> &[f32] {
        &self.0[(xs.start - rect.x0) as usize..(xs.end - rect.x0) as usize]
    }
}

/// The contract's `power = -0.5·(A dx² + C dy²) - B dx dy` of `g` for the pixel centres
/// `cx` of a row at vertical offset `dy`, with `dx = cx - mx`, in exactly this `f32`
/// order. A separate pass without branches or calls, so that it can vectorize.
#[inline]
fn powers(g: &Projected, cx: &[f32], dy: f32, out: &mut [f32]) {
    let [ca, cb, cc] = g.conic;
    let mx = g.mean[0];
    let cdy = cc * dy * dy;
    for (p, &x) in out.iter_mut().zip(cx) {
        let dx = x - mx;
        *p = -0.5 * (ca * dx * dx + cdy) - cb * dx * dy;
    }
}

#[cfg(test)]
mod tests {
    use super::super::project_scene;
    use super::*;
    use crate::model::CovParam;
    use crate::synth::{random_scene, SceneSpec};

    fn render_both(blend: Blend, w: u32, h: u32) -> (Vec<f32>, Vec<f32>) {
        let mut spec = SceneSpec::new(64, 48, 400, blend);
        spec.sigma_px = (0.3, 30.0);
        spec.cov_param = CovParam::Cholesky;
        let scene = random_scene(11, spec);
        let proj = project_scene(&scene, w, h);
        let mut seq = vec![f32::NAN; (w * h * 3) as usize];
        let mut par = vec![f32::NAN; (w * h * 3) as usize];
        render_projected::<RgbF32>(&proj, blend, None, (w, h), &mut seq, false);
        render_projected::<RgbF32>(&proj, blend, None, (w, h), &mut par, true);
        (seq, par)
    }

    #[test]
    fn parallel_and_sequential_are_identical() {
        for blend in [Blend::Sum, Blend::Alpha] {
            for (w, h) in [(64, 48), (131, 97), (5, 200), (1, 1)] {
                let (seq, par) = render_both(blend, w, h);
                assert!(seq.iter().all(|x| x.is_finite()));
                let same = seq
                    .iter()
                    .zip(&par)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "{blend:?} {w}x{h}");
            }
        }
    }

    #[test]
    fn tiny_budgets_give_the_same_image() {
        // Binning in runs of one band and one tile must not change what a pixel visits.
        for blend in [Blend::Sum, Blend::Alpha] {
            let mut spec = SceneSpec::new(40, 40, 300, blend);
            spec.sigma_px = (0.3, 40.0);
            let scene = random_scene(5, spec);
            let (w, h) = (75, 50);
            let proj = project_scene(&scene, w, h);
            let mut a = vec![0.0; (w * h * 3) as usize];
            let mut b = a.clone();
            render_budgeted::<RgbF32>(
                &proj,
                blend,
                None,
                (w, h),
                &mut a,
                false,
                (BAND_BUDGET, TILE_BUDGET),
            );
            render_budgeted::<RgbF32>(&proj, blend, None, (w, h), &mut b, false, (0, 0));
            assert!(a.iter().any(|&x| x != 0.0));
            assert!(
                a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{blend:?}"
            );
        }
    }
}
