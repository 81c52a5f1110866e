//! Binning Gaussians into tiles by their pixel boxes: the crate's one binner.
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

#[cfg(any(test, feature = "encode", feature = "gpu"))]
use super::{project::Projected, TILE};
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
        let covered = projected.iter().enumerate().map(|(k, g)| {
            let b = g.bbox;
            let ys = (b.y0 / TILE).max(rows.start)..(b.y1 / TILE + 1).min(rows.end);
            let xs = b.x0 / TILE..(b.x1 / TILE + 1).min(tiles_x);
            let r0 = rows.start;
            let tiles = ys.flat_map(move |ty| {
                xs.clone()
                    .map(move |tx| ((ty - r0) * tiles_x + tx) as usize)
            });
            (k as u32, tiles)
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

    /// The lists of a naive push per covered tile, which [`TileLists`] must reproduce.
    fn naive(proj: &[Projected], tiles_x: u32, rows: Range<u32>) -> Vec<Vec<u32>> {
        let mut lists = vec![Vec::new(); tiles_x as usize * rows.len()];
        for (k, g) in proj.iter().enumerate() {
            for ty in g.bbox.y0 / TILE..=g.bbox.y1 / TILE {
                for tx in g.bbox.x0 / TILE..=g.bbox.x1 / TILE {
                    if rows.contains(&ty) && tx < tiles_x {
                        lists[((ty - rows.start) * tiles_x + tx) as usize].push(k as u32);
                    }
                }
            }
        }
        lists
    }

    #[test]
    fn tile_lists_match_a_naive_binning_in_stored_order() {
        use gsi_format::model::{Blend, CovParam, GaussianSet, Scene};
        let (w, h) = (70, 45);
        let mut g = GaussianSet::default();
        for k in 0..40 {
            let t = k as f32 / 40.0;
            g.positions.push([(t * 7.3) % 1.0, (t * 3.1) % 1.0]);
            g.cov.push([-3.0 - 2.0 * t, -2.5 - t, t * 6.0]);
            g.colors.push([t, 1.0 - t, 0.5]);
        }
        let scene = Scene {
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
