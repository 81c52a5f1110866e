//! The SSIM window: an 11-tap Gaussian (σ = 1.5) applied separably, in "valid" mode, and
//! its adjoint. Generic over [`Real`] so one code path serves the `f64` metrics and the
//! `f32` loss (and the `f64` loss that tests check against finite differences).
//!
//! Why "valid" (no padding, output smaller by 10 on each axis): scikit-image filters with
//! `mode='reflect'` and then crops `(11 - 1) / 2 = 5` pixels from every side before taking
//! the mean. A radius-5 window centred 5 or more pixels from the border never reads a
//! reflected sample, so the cropped values *are* the valid correlation; computing only
//! those is exact, cheaper, and has a simple adjoint for the gradient.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

/// Window radius: `int(truncate · σ + 0.5)` with scikit-image's `truncate = 3.5`.
pub const RADIUS: usize = 5;
/// Window side.
pub const TAPS: usize = 2 * RADIUS + 1;
/// Window standard deviation, pixels.
pub const SIGMA: f64 = 1.5;

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// The float types the loss is computed in: `f32` (fast, for the encoder) and `f64`
/// (for checking gradients against finite differences). Sealed: implemented for those two.
pub trait Real:
    sealed::Sealed
    + Copy
    + Default
    + Debug
    + PartialOrd
    + Send
    + Sync
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + 'static
{
    fn from_f64(v: f64) -> Self;
    fn to_f64(self) -> f64;
}

impl Real for f32 {
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
}

impl Real for f64 {
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
}

/// scipy's `_gaussian_kernel1d(1.5, 0, 5)`: `exp(-x²/(2σ²))` normalised to sum 1.
pub fn taps<T: Real>() -> [T; TAPS] {
    let raw: [f64; TAPS] = std::array::from_fn(|i| {
        let x = i as f64 - RADIUS as f64;
        (-0.5 / (SIGMA * SIGMA) * x * x).exp()
    });
    let sum: f64 = raw.iter().sum();
    raw.map(|v| T::from_f64(v / sum))
}

/// `dst[i] = Σ_k g[k] · src[i + k]` for `i < dst.len()`, `src.len() = dst.len() + 10`:
/// one row of the horizontal pass. The window is symmetric, so taps `k` and `10 - k`
/// share a multiplication.
#[inline]
pub fn correlate_row<T: Real>(g: &[T; TAPS], src: &[T], dst: &mut [T]) {
    let n = dst.len();
    let src = &src[..n + 2 * RADIUS];
    for (i, d) in dst.iter_mut().enumerate() {
        let s = &src[i..i + TAPS];
        *d = g[5] * s[5]
            + g[0] * (s[0] + s[10])
            + g[1] * (s[1] + s[9])
            + g[2] * (s[2] + s[8])
            + g[3] * (s[3] + s[7])
            + g[4] * (s[4] + s[6]);
    }
}

/// `dst[i] = Σ_k g[k] · rows[k][i]`: one row of the vertical pass, from the 11 input rows
/// it covers, in order.
#[inline]
pub fn correlate_rows<T: Real>(g: &[T; TAPS], rows: [&[T]; TAPS], dst: &mut [T]) {
    let n = dst.len();
    let r: [&[T]; TAPS] = rows.map(|r| &r[..n]);
    for (i, d) in dst.iter_mut().enumerate() {
        *d = g[5] * r[5][i]
            + g[0] * (r[0][i] + r[10][i])
            + g[1] * (r[1][i] + r[9][i])
            + g[2] * (r[2][i] + r[8][i])
            + g[3] * (r[3][i] + r[7][i])
            + g[4] * (r[4][i] + r[6][i]);
    }
}

/// The 11 rows of a ring buffer of `TAPS` rows of length `n` that start at row `first`
/// (row `j` lives in slot `j % TAPS`).
#[inline]
pub fn ring_rows<T>(ring: &[T], n: usize, first: usize) -> [&[T]; TAPS] {
    std::array::from_fn(|k| {
        let slot = (first + k) % TAPS;
        &ring[slot * n..(slot + 1) * n]
    })
}

/// Valid Gaussian correlation of a `w × h` plane into `(w - 10) × (h - 10)`, rows first
/// then columns. Requires `w, h ≥ 11`. (The SSIM statistics stream the same two passes
/// row by row; this whole-plane form is the reference the tests check the adjoint of.)
#[cfg(test)]
pub fn filter_valid<T: Real>(g: &[T; TAPS], src: &[T], w: usize, h: usize) -> Vec<T> {
    let (wo, ho) = (w - 2 * RADIUS, h - 2 * RADIUS);
    let mut tmp = vec![T::default(); wo * h];
    for (row_in, row_out) in src.chunks_exact(w).zip(tmp.chunks_exact_mut(wo)) {
        correlate_row(g, row_in, row_out);
    }
    let mut dst = vec![T::default(); wo * ho];
    for (r, row_out) in dst.chunks_exact_mut(wo).enumerate() {
        let rows = std::array::from_fn(|k| &tmp[(r + k) * wo..(r + k + 1) * wo]);
        correlate_rows(g, rows, row_out);
    }
    dst
}

/// Buffers kept for reuse, so that a loss evaluated every iteration of a fit does not
/// allocate (and have the system zero fresh pages for) megabytes each time.
pub struct Pool<T>(Vec<Vec<T>>);

impl<T: Real> Pool<T> {
    pub fn new() -> Self {
        Pool(Vec::new())
    }

    /// A buffer of `len` values with unspecified contents (the caller overwrites them):
    /// the smallest kept buffer that is large enough, else the largest one grown.
    pub fn take(&mut self, len: usize) -> Vec<T> {
        let fits = (0..self.0.len())
            .filter(|&i| self.0[i].capacity() >= len)
            .min_by_key(|&i| self.0[i].capacity());
        let best = fits.or_else(|| (0..self.0.len()).max_by_key(|&i| self.0[i].capacity()));
        let mut v = best.map(|i| self.0.swap_remove(i)).unwrap_or_default();
        v.resize(len, T::default());
        v
    }

    /// A buffer of `len` zeros.
    pub fn take_zeroed(&mut self, len: usize) -> Vec<T> {
        let mut v = self.take(len);
        v.fill(T::default());
        v
    }

    pub fn put(&mut self, v: Vec<T>) {
        self.0.push(v);
    }
}

/// Streams the adjoint (transpose) of the valid filter: a "full" convolution with the
/// symmetric window of a `(w - 10) × (h - 10)` map, zero outside it, onto `w × h`.
///
/// The map arrives a row at a time: `fill(r, rows)` writes row `r` of three maps at once
/// (the SSIM gradient needs three) and `emit(j, rows)` receives row `j` of the three
/// results. Rows are gathered, not scattered: output row `j` is the vertical correlation
/// of map rows `j - 10 ..= j` (zero outside), held in a ring of 11 rows, then the
/// horizontal one of that row padded with 10 zeros on each side.
pub fn adjoint3<T: Real>(
    g: &[T; TAPS],
    w: usize,
    h: usize,
    pool: &mut Pool<T>,
    mut fill: impl FnMut(usize, [&mut [T]; 3]),
    mut emit: impl FnMut(usize, [&[T]; 3]),
) {
    let (wo, ho) = (w - 2 * RADIUS, h - 2 * RADIUS);
    let mut ring: [Vec<T>; 3] = std::array::from_fn(|_| pool.take_zeroed(TAPS * wo));
    let mut padded: [Vec<T>; 3] = std::array::from_fn(|_| pool.take_zeroed(wo + 4 * RADIUS));
    let mut out: [Vec<T>; 3] = std::array::from_fn(|_| pool.take(w));
    for j in 0..h {
        let slot = j % TAPS;
        let [a, b, c] = &mut ring;
        let rows = [a, b, c].map(|r| &mut r[slot * wo..(slot + 1) * wo]);
        if j < ho {
            fill(j, rows);
        } else {
            for r in rows {
                r.fill(T::default());
            }
        }
        // Map rows j-10 ..= j: slots of rows < 0 are still zero from the start.
        let first = (j + 1) % TAPS; // = (j - 10) mod 11
        for q in 0..3 {
            let rows = ring_rows(&ring[q], wo, first);
            correlate_rows(g, rows, &mut padded[q][2 * RADIUS..2 * RADIUS + wo]);
            correlate_row(g, &padded[q], &mut out[q]);
        }
        emit(j, [&out[0][..], &out[1][..], &out[2][..]]);
    }
    for v in ring.into_iter().chain(padded).chain(out) {
        pool.put(v);
    }
}

/// 2×2 average pooling, `w × h → ⌊w/2⌋ × ⌊h/2⌋` into `out`; an odd last row or column
/// is dropped.
pub fn pool2<T: Real>(src: &[T], w: usize, h: usize, out: &mut Vec<T>) {
    let (w2, h2) = (w / 2, h / 2);
    let q = T::from_f64(0.25);
    out.clear();
    for r in 0..h2 {
        let (a, b) = (&src[2 * r * w..], &src[(2 * r + 1) * w..]);
        out.extend((0..w2).map(|c| q * (a[2 * c] + a[2 * c + 1] + b[2 * c] + b[2 * c + 1])));
    }
}

/// The adjoint of [`pool2`], accumulated: `dst` (`w × h`) += each pooled value's
/// gradient spread as a quarter over its four source pixels.
pub fn pool2_adjoint_add<T: Real>(src: &[T], w: usize, h: usize, dst: &mut [T]) {
    let (w2, h2) = (w / 2, h / 2);
    let q = T::from_f64(0.25);
    for r in 0..h2 {
        for c in 0..w2 {
            let v = q * src[r * w2 + c];
            for (dr, dc) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                dst[(2 * r + dr) * w + 2 * c + dc] += v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taps_are_scipys() {
        // scipy.ndimage._filters._gaussian_kernel1d(1.5, 0, 5)
        let g = taps::<f64>();
        assert!((g[5] - 0.266_011_724_861_794_4).abs() < 1e-12, "{}", g[5]);
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }

    /// `<F x, y> = <x, Fᵀ y>` for random planes: the adjoint really is the transpose.
    #[test]
    fn adjoints_are_transposes() {
        let (w, h) = (17, 13);
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let x: Vec<f64> = (0..w * h).map(|_| rnd()).collect();
        let y: Vec<f64> = (0..(w - 10) * (h - 10)).map(|_| rnd()).collect();
        let g = taps::<f64>();
        let fx = filter_valid(&g, &x, w, h);
        let mut fty = vec![0.0; w * h];
        let wo = w - 10;
        adjoint3(
            &g,
            w,
            h,
            &mut Pool::new(),
            |r, [a, b, c]| {
                a.copy_from_slice(&y[r * wo..(r + 1) * wo]);
                b.fill(0.0);
                c.fill(0.0);
            },
            |j, [a, _, _]| fty[j * w..(j + 1) * w].copy_from_slice(a),
        );
        let lhs: f64 = fx.iter().zip(&y).map(|(a, b)| a * b).sum();
        let rhs: f64 = x.iter().zip(&fty).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() < 1e-12, "{lhs} {rhs}");

        let p: Vec<f64> = (0..(w / 2) * (h / 2)).map(|_| rnd()).collect();
        let mut px = Vec::new();
        pool2(&x, w, h, &mut px);
        let mut ptp = vec![0.0; w * h];
        pool2_adjoint_add(&p, w, h, &mut ptp);
        let lhs: f64 = px.iter().zip(&p).map(|(a, b)| a * b).sum();
        let rhs: f64 = x.iter().zip(&ptp).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() < 1e-12, "{lhs} {rhs}");
    }
}
