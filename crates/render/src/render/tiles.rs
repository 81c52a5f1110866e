//! Binning Gaussians into tiles: the crate's one binner.
//!
//! A Gaussian goes to the tiles of its pixel box that its ellipse can reach, decided per
//! tile row in closed form ([`band_tiles`]): a rotated, elongated Gaussian's box holds
//! tiles it never touches.
//!
//! A list only restricts which Gaussians a pixel visits; it keeps them in stored order,
//! which `alpha` blending needs and which makes `sum` blending bit-reproducible. Every
//! binning goes through [`bin`], a counting sort into compressed lists:
//! - [`Bins`] over runs of slots (tile rows, then tile columns), for the CPU renderer;
//! - [`TileLists`] over whole tile rows, for the differentiable rasterizer, the
//!   enhancer's render matrix and the GPU renderer's upload.
//!
//! Memory is bounded: a Gaussian covering the whole image appears in every tile, so a
//! flat per-tile list over a large output could take `count × tiles` entries. Slots are
//! therefore binned in consecutive [`runs`] whose lists hold at most a budget of entries
//! (a run has at least one slot; a single list never exceeds the number of Gaussians).

use super::project::{offset, term_bound, Projected};
use super::rounding::{ceil, floor};
use super::TILE;
use gsi_format::contract::EXTENT_SIGMAS;
use std::ops::Range;

/// Counting sort of items into `slots` lists, each list in the order `items` visits them.
///
/// `items` yields `(item, slots it covers)` and is walked twice (count, then place). On
/// return the list of slot `k` is `out[offsets[k]..offsets[k + 1]]`; `cursor` is scratch.
/// The buffers are the caller's so that repeated binnings reuse them.
pub fn bin<I, S>(
    items: I,
    slots: usize,
    offsets: &mut Vec<usize>,
    cursor: &mut Vec<usize>,
    out: &mut Vec<u32>,
) where
    I: Iterator<Item = (u32, S)> + Clone,
    S: Iterator<Item = usize>,
{
    offsets.clear();
    offsets.resize(slots + 1, 0);
    for (_, covered) in items.clone() {
        for k in covered {
            offsets[k + 1] += 1;
        }
    }
    for k in 0..slots {
        offsets[k + 1] += offsets[k];
    }
    out.clear();
    out.resize(offsets[slots], 0);
    cursor.clear();
    cursor.extend_from_slice(&offsets[..slots]);
    for (item, covered) in items {
        for k in covered {
            out[cursor[k]] = item;
            cursor[k] += 1;
        }
    }
}

/// The largest `Q = -2·power` (exactly) at which a pixel may still reach the cut-off
/// `cut`, where `s` bounds the magnitude of `Q`'s terms ([`term_bound`]). A margin of
/// 2e-4·s + 1e-3 in `Q`, over twice [`log_weight_error`](super::project::log_weight_error)
/// (which covers a pixel's power by the rule of §6.3 too), leaves out no pixel that
/// reaches the cut by any rule.
fn reach(cut: f32, s: f64) -> f64 {
    -2.0 * f64::from(cut) + 1e-3 + 2e-4 * s
}

/// [`band_columns`] as tile columns `(lo, hi)` (inclusive): the tiles of the band that
/// `g` may reach, for the tile lists of the fit and of the GPU.
#[cfg(any(test, feature = "encode", feature = "gpu"))]
pub fn band_tiles(g: &Projected, rows: Range<u32>) -> Option<(u32, u32)> {
    band_columns(g, rows).map(|(first, last)| (first / TILE, last / TILE))
}

/// The pixel columns `(first, last)` (inclusive, within the box) of a band of pixel rows
/// `rows` where `g` may reach its cut-off ([`Projected::cutoff`]) by either weight rule:
/// those that the ellipse `Q = −2·power ≤ t` meets within the rows of the box in the band
/// (`t` the cut-off with the margin for rounding), widened by a pixel each way; the box's
/// own columns where the box lies within two tile columns. `None` where it meets none.
///
/// A rotated, elongated Gaussian's box holds whole tiles, and corners of tiles, that the
/// ellipse never reaches; deciding that once per band, in closed form, costs less than a
/// test per tile in the tile loops, and keeps those tiles' lists shorter. Only a
/// shortcut: every pixel of the columns kept is evaluated by the rule.
pub fn band_columns(g: &Projected, rows: Range<u32>) -> Option<(u32, u32)> {
    let b = &g.bbox;
    let ys = b.y0.max(rows.start)..(b.y1 + 1).min(rows.end);
    if ys.is_empty() {
        return None;
    }
    let whole = Some((b.x0, b.x1));
    if b.x1 / TILE - b.x0 / TILE < 2 {
        // A box within two tile columns: the ellipse reaches both nearly always, and the
        // test would cost more than the tile it rarely saves.
        return whole;
    }
    // The offsets of the box's first and last pixel centres (columns) and of the band's
    // rows in the box, as the pixels compute them; rounding is monotonic, so every
    // pixel's offset lies between them.
    let dxs = [offset(b.x0, g.mean[0]), offset(b.x1, g.mean[0])].map(f64::from);
    let dys = [offset(ys.start, g.mean[1]), offset(ys.end - 1, g.mean[1])].map(f64::from);
    let [a, bb, c] = g.conic.map(f64::from);
    let (mx, my) = (
        dxs[0].abs().max(dxs[1].abs()),
        dys[0].abs().max(dys[1].abs()),
    );
    let t = reach(g.cutoff(), term_bound([a, bb, c], mx, my));
    let det = a * c - bb * bb;
    if !(det > 0.0 && a > 0.0 && c > 0.0 && t.is_finite()) {
        return whole;
    }
    // Where the band's rows hold the two rows at which the ellipse reaches furthest left
    // and right (`y = ±ytop`, below), and it reaches past the box there (its half-width
    // `√(t·C/det)` is `√t` standard deviations, the box's [`EXTENT_SIGMAS`]), it keeps
    // the whole box: so said without the square roots, as for a Gaussian whose middle
    // rows the band holds. (Keeping columns is always exact.)
    let (up, down) = (-dys[0], dys[1]);
    let reach_sq = f64::from(EXTENT_SIGMAS * EXTENT_SIGMAS);
    if up >= 0.0 && down >= 0.0 && t >= reach_sq {
        let m = up.min(down);
        if bb * bb * t <= det * c * (m * m) {
            return whole;
        }
    }
    // The ellipse `Q ≤ t` spans rows `|y| ≤ ymax`; at row `y` its columns run from
    // `(−B·y − w)/A` to `(−B·y + w)/A`, `w = sqrt(A·t − det·y²)`. Its right end is
    // concave in `y`, greatest at `y = −B·x/C` with `x = sqrt(t·C/det)` (where
    // `∂Q/∂y = 0`); the left end mirrors it. Over the band's rows each is at its
    // extreme row clamped into them. (Written as `ymax = √A·s` and `ytop = −B·s/√C` with
    // `s = √(t/det)`, so that the divisions and the square roots run side by side rather
    // than one after another: the band loop calls this for every Gaussian of every band.
    // Rounding moves these ends by ulps, far inside the pixel of slack below.)
    let s = (t / det).sqrt();
    let ymax = a.sqrt() * s;
    let (lo, hi) = (dys[0].max(-ymax), dys[1].min(ymax));
    if lo > hi {
        return None;
    }
    let inv_a = 1.0 / a;
    let ytop = -bb * s / c.sqrt();
    let (y_right, y_left) = (ytop.clamp(lo, hi), (-ytop).clamp(lo, hi));
    let half_width = |y: f64| (a * t - det * y * y).max(0.0).sqrt();
    let right = (-bb * y_right + half_width(y_right)) * inv_a;
    let left = (-bb * y_left - half_width(y_left)) * inv_a;
    // Pixel `i` has its centre at offset `i + 0.5 − mx`; a pixel of slack each way covers
    // the rounding of the offsets the pixels compute. (`max` and `min` take a NaN to the
    // box's edge.)
    let first = floor(f64::from(g.mean[0]) + left - 1.5).max(f64::from(b.x0));
    let last = ceil(f64::from(g.mean[0]) + right + 0.5).min(f64::from(b.x1));
    if first > last {
        return None;
    }
    Some((first as u32, last as u32))
}

/// One item to bin: its index and the inclusive range of slots it covers.
pub type Span = (u32, u32, u32);

/// Split slots `0..n` into consecutive runs whose lists together hold at most `budget`
/// entries (or a single slot, if that alone exceeds it).
pub fn runs<I>(spans: I, n: u32, budget: u64) -> Vec<Range<u32>>
where
    I: Iterator<Item = Span>,
{
    // Entries per slot through a difference array: O(items + slots), whatever the spans.
    let mut diff = vec![0i64; n as usize + 1];
    for (_, lo, hi) in spans {
        if lo <= hi && hi < n {
            diff[lo as usize] += 1;
            diff[hi as usize + 1] -= 1;
        }
    }
    let mut out = Vec::new();
    let (mut start, mut total, mut count) = (0u32, 0u64, 0i64);
    for s in 0..n {
        count += diff[s as usize];
        let here = count as u64;
        if s > start && total + here > budget {
            out.push(start..s);
            start = s;
            total = 0;
        }
        total += here;
    }
    if n > 0 {
        out.push(start..n);
    }
    out
}

/// Lists of item indices for a run of consecutive slots, in compressed form: the list of
/// slot `first + k` is `items[offsets[k]..offsets[k + 1]]`. Kept between runs so that
/// its buffers are reused.
#[derive(Debug, Default)]
pub struct Bins {
    first: u32,
    offsets: Vec<usize>,
    cursor: Vec<usize>,
    items: Vec<u32>,
}

impl Bins {
    /// Bin `spans` (visited in the order the lists must keep) over the slots of `run`.
    pub fn fill<I>(&mut self, spans: I, run: Range<u32>)
    where
        I: Iterator<Item = Span> + Clone,
    {
        self.first = run.start;
        let m = run.len();
        let clip = move |(item, lo, hi): Span| -> (u32, Range<usize>) {
            let lo = lo.max(run.start);
            let hi = hi.min(run.end.saturating_sub(1));
            if m == 0 || lo > hi {
                (item, 0..0)
            } else {
                (
                    item,
                    (lo - run.start) as usize..(hi - run.start) as usize + 1,
                )
            }
        };
        bin(
            spans.map(clip),
            m,
            &mut self.offsets,
            &mut self.cursor,
            &mut self.items,
        );
    }

    /// The list of `slot`, which must lie in the run last filled.
    pub fn slot(&self, slot: u32) -> &[u32] {
        let k = (slot - self.first) as usize;
        &self.items[self.offsets[k]..self.offsets[k + 1]]
    }
}

/// Per-tile lists of projected-Gaussian indices, in stored order, over a band of whole tile
/// rows (all of them for [`TileLists::bin`]). Tile `t` of the band is tile row
/// `rows.start + t / tiles_x`, column `t % tiles_x`.
#[cfg(any(test, feature = "encode", feature = "gpu"))]
#[derive(Debug, Default)]
pub struct TileLists {
    #[cfg_attr(not(feature = "encode"), allow(dead_code))]
    pub tiles_x: u32,
    offsets: Vec<usize>,
    items: Vec<u32>,
}

#[cfg(any(test, feature = "encode", feature = "gpu"))]
impl TileLists {
    /// Lists for every tile of a `width × height` output.
    #[cfg_attr(not(feature = "encode"), allow(dead_code))]
    pub fn bin(projected: &[Projected], width: u32, height: u32) -> TileLists {
        TileLists::bin_rows(projected, width.div_ceil(TILE), 0..height.div_ceil(TILE))
    }

    /// Lists for the tiles of tile rows `rows`, `tiles_x` tiles wide.
    pub fn bin_rows(projected: &[Projected], tiles_x: u32, rows: Range<u32>) -> TileLists {
        let mut lists = TileLists {
            tiles_x,
            ..TileLists::default()
        };
        let slots = tiles_x as usize * rows.len();
        // Each Gaussian's tiles, tile row by tile row: the tile columns its ellipse
        // reaches there ([`band_tiles`]), decided once (the binner walks them twice),
        // in chunks of Gaussians on rayon's pool where there is one: this is the serial
        // part of a fitting pass.
        let reach = |first: usize, chunk: &[Projected]| {
            let mut out = Vec::new();
            for (k, g) in (first..).zip(chunk) {
                let b = g.bbox;
                for ty in (b.y0 / TILE).max(rows.start)..(b.y1 / TILE + 1).min(rows.end) {
                    match band_tiles(g, ty * TILE..(ty + 1) * TILE) {
                        Some((lo, hi)) if lo < tiles_x => {
                            out.push((k as u32, ty - rows.start, lo, hi.min(tiles_x - 1)))
                        }
                        _ => {}
                    }
                }
            }
            out
        };
        #[cfg(feature = "parallel")]
        let reached: Vec<_> = {
            use rayon::prelude::*;
            const CHUNK: usize = 1024;
            let parts: Vec<Vec<_>> = projected
                .par_chunks(CHUNK)
                .enumerate()
                .map(|(c, chunk)| reach(c * CHUNK, chunk))
                .collect();
            parts.concat()
        };
        #[cfg(not(feature = "parallel"))]
        let reached = reach(0, projected);
        let covered = reached.iter().map(|&(k, ty, lo, hi)| {
            let tiles = (lo..=hi).map(move |tx| (ty * tiles_x + tx) as usize);
            (k, tiles)
        });
        let mut cursor = Vec::new();
        bin(
            covered,
            slots,
            &mut lists.offsets,
            &mut cursor,
            &mut lists.items,
        );
        lists
    }

    /// Number of tiles binned.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Whether no tile was binned.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The list of tile `t` of the band.
    #[inline]
    pub fn list(&self, t: usize) -> &[u32] {
        &self.items[self.offsets[t]..self.offsets[t + 1]]
    }

    /// Every tile's list, in tile order.
    #[cfg_attr(not(feature = "encode"), allow(dead_code))]
    pub fn iter(&self) -> impl Iterator<Item = &[u32]> + '_ {
        (0..self.len()).map(|t| self.list(t))
    }

    /// The compressed form: list `t` is `items[offsets[t]..offsets[t + 1]]`.
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pub fn parts(&self) -> (&[usize], &[u32]) {
        (&self.offsets, &self.items)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::model::{Blend, CovParam};
    use gsi_synth::{random_scene, SceneSpec};

    #[test]
    fn runs_respect_budget_and_cover_all_slots() {
        let spans = [(0, 0, 3), (1, 1, 1), (2, 2, 5), (3, 5, 5)];
        // Entries per slot: 1 2 2 2 1 2.
        assert_eq!(runs(spans.into_iter(), 6, 100), vec![0..6]);
        assert_eq!(runs(spans.into_iter(), 6, 3), vec![0..2, 2..3, 3..5, 5..6]);
        assert_eq!(runs(spans.into_iter(), 6, 4), vec![0..2, 2..4, 4..6]);
        // A slot over budget still gets a run of its own.
        assert_eq!(
            runs(spans.into_iter(), 6, 0),
            (0..6).map(|s| s..s + 1).collect::<Vec<_>>()
        );
        // Empty slots cost nothing.
        assert_eq!(runs(std::iter::empty(), 3, 0), vec![0..3]);
        assert!(runs(std::iter::empty(), 0, 10).is_empty());
    }

    #[test]
    fn bins_keep_order_and_clip_to_run() {
        let spans = [(7, 0, 3), (2, 1, 1), (9, 2, 5), (4, 5, 5)];
        let mut b = Bins::default();
        b.fill(spans.into_iter(), 1..4);
        assert_eq!(b.slot(1), &[7, 2]);
        assert_eq!(b.slot(2), &[7, 9]);
        assert_eq!(b.slot(3), &[7, 9]);
        b.fill(spans.into_iter(), 4..6);
        assert_eq!(b.slot(4), &[9]);
        assert_eq!(b.slot(5), &[9, 4]);
    }

    /// Every pixel the rule touches lies in the columns `band_columns` keeps for its band
    /// (within the box) and in a tile `band_tiles` keeps, and the culling does cull:
    /// needle-thin rotated Gaussians, low opacities, sizes that scale the footprints up
    /// and down.
    #[test]
    fn band_culling_keeps_every_touched_tile() {
        for (seed, cov_param, with_opacity) in [
            (3, CovParam::LogScaleRotation, true),
            (4, CovParam::Cholesky, false),
        ] {
            let mut spec = SceneSpec::new(96, 80, 300, Blend::Sum);
            spec.sigma_px = (0.1, 60.0);
            spec.cov_param = cov_param;
            spec.with_opacity = with_opacity;
            let scene = random_scene(seed, spec);
            for (w, h) in [(96, 80), (250, 41), (50, 130)] {
                let (mut kept, mut boxed) = (0u32, 0u32);
                for g in &super::super::project_scene(&scene, w, h) {
                    for band in 0..h.div_ceil(TILE) {
                        let rows = band * TILE..((band + 1) * TILE).min(h);
                        let tiles = band_tiles(g, rows.clone());
                        let columns = band_columns(g, rows.clone());
                        if g.bbox.y0 < rows.end && rows.start <= g.bbox.y1 {
                            boxed += g.bbox.x1 / TILE - g.bbox.x0 / TILE + 1;
                            kept += tiles.map_or(0, |(lo, hi)| hi - lo + 1);
                        }
                        for j in rows {
                            for i in 0..w {
                                if g.alpha_at(i, j, Blend::Sum).is_some() {
                                    let (lo, hi) = tiles.expect("band of a touched pixel");
                                    assert!((lo..=hi).contains(&(i / TILE)), "{g:?} {i} {j}");
                                    let (first, last) = columns.expect("band of a touched pixel");
                                    assert!((first..=last).contains(&i), "{g:?} {i} {j}");
                                    assert!(g.bbox.x0 <= first && last <= g.bbox.x1);
                                }
                            }
                        }
                    }
                }
                assert!(kept < boxed, "{cov_param:?} {w}x{h}: {kept} of {boxed}");
            }
        }
    }

    /// The lists of a naive push per tile of the box that the ellipse reaches
    /// ([`band_tiles`]), which [`TileLists`] must reproduce.
    fn naive(proj: &[Projected], tiles_x: u32, rows: Range<u32>) -> Vec<Vec<u32>> {
        let mut lists = vec![Vec::new(); tiles_x as usize * rows.len()];
        for (k, g) in proj.iter().enumerate() {
            for ty in g.bbox.y0 / TILE..=g.bbox.y1 / TILE {
                let reached = band_tiles(g, ty * TILE..(ty + 1) * TILE);
                for tx in g.bbox.x0 / TILE..=g.bbox.x1 / TILE {
                    let reaches = reached.is_some_and(|(lo, hi)| (lo..=hi).contains(&tx));
                    if rows.contains(&ty) && tx < tiles_x && reaches {
                        lists[((ty - rows.start) * tiles_x + tx) as usize].push(k as u32);
                    }
                }
            }
        }
        lists
    }

    #[test]
    fn tile_lists_match_a_naive_binning_in_stored_order() {
        use gsi_format::model::{GaussianSet, Scene};
        let (w, h) = (70, 45);
        let mut g = GaussianSet::default();
        for k in 0..40 {
            let t = k as f32 / 40.0;
            g.positions.push([(t * 7.3) % 1.0, (t * 3.1) % 1.0]);
            g.cov.push([-3.0 - 2.0 * t, -2.5 - t, t * 6.0]);
            g.colors.push([t, 1.0 - t, 0.5]);
        }
        let scene = Scene {
            weights: gsi_format::model::WeightRule::PerPixel,
            tone: None,
            width: w,
            height: h,
            blend: Blend::Alpha,
            cov_param: CovParam::LogScaleRotation,
            gaussians: g,
        };
        let proj = super::super::project_scene(&scene, w, h);
        let tx = w.div_ceil(TILE);
        for rows in [0..h.div_ceil(TILE), 1..2, 2..3] {
            let got = TileLists::bin_rows(&proj, tx, rows.clone());
            let want = naive(&proj, tx, rows.clone());
            assert_eq!(got.len(), want.len());
            assert!(got.iter().zip(&want).all(|(a, b)| a == &b[..]), "{rows:?}");
        }
        assert!(TileLists::bin(&proj, w, h).iter().any(|l| l.len() > 1));
    }
}
