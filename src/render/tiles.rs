//! Binning Gaussians into runs of slots (tile rows, then tile columns) by their pixel boxes.
//!
//! A list only restricts which Gaussians a pixel visits; it keeps them in stored order,
//! which `alpha` blending needs and which makes `sum` blending bit-reproducible.
//!
//! Memory is bounded: a Gaussian covering the whole image appears in every tile, so a
//! flat per-tile list over a large output could take `count × tiles` entries. Slots are
//! therefore binned in consecutive [`runs`] whose lists hold at most a budget of entries
//! (a run has at least one slot; a single list never exceeds the number of Gaussians).

use std::ops::Range;

/// One item to bin: its index and the inclusive range of slots it covers.
pub(crate) type Span = (u32, u32, u32);

/// Split slots `0..n` into consecutive runs whose lists together hold at most `budget`
/// entries (or a single slot, if that alone exceeds it).
pub(crate) fn runs<I>(spans: I, n: u32, budget: u64) -> Vec<Range<u32>>
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
pub(crate) struct Bins {
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
        self.offsets.clear();
        self.offsets.resize(m + 1, 0);
        if m == 0 {
            self.items.clear();
            return;
        }
        let clip = |lo: u32, hi: u32| -> Range<usize> {
            let lo = lo.max(run.start);
            let hi = hi.min(run.end - 1);
            if lo > hi {
                0..0
            } else {
                (lo - run.start) as usize..(hi - run.start) as usize + 1
            }
        };
        for (_, lo, hi) in spans.clone() {
            for k in clip(lo, hi) {
                self.offsets[k + 1] += 1;
            }
        }
        for k in 0..m {
            self.offsets[k + 1] += self.offsets[k];
        }
        self.items.clear();
        self.items.resize(self.offsets[m], 0);
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.offsets[..m]);
        for (item, lo, hi) in spans {
            for k in clip(lo, hi) {
                self.items[self.cursor[k]] = item;
                self.cursor[k] += 1;
            }
        }
    }

    /// The list of `slot`, which must lie in the run last filled.
    pub fn slot(&self, slot: u32) -> &[u32] {
        let k = (slot - self.first) as usize;
        &self.items[self.offsets[k]..self.offsets[k + 1]]
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
}
