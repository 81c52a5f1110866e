//! SSIM and MS-SSIM: the per-scale statistics, their gradient, and the 8-bit metrics.
//!
//! One plane (one colour channel) at a time. At each position `p` of the valid region,
//! with `μ`, `σ²`, `σxy` the window-weighted means, (population) variances and covariance:
//!
//! ```text
//! A1 = 2 μx μy + C1    A2 = 2 σxy + C2    B1 = μx² + μy² + C1    B2 = σx² + σy² + C2
//! SSIM(p) = A1 A2 / (B1 B2)               cs(p) = A2 / B2   (contrast-structure)
//! ```
//!
//! `C1 = (0.01 L)²`, `C2 = (0.03 L)²` for data range `L`. The metric is the mean of the
//! map over the valid region (see `filter.rs` for why that is scikit-image's crop).

use super::filter::{
    adjoint3, correlate_row, correlate_rows, pool2, pool2_adjoint_add, ring_rows, taps, Pool, Real,
    RADIUS, TAPS,
};
use super::{check_pair, MetricError, Rgb8, WINDOW};

/// Wang, Simoncelli & Bovik (2003), exponents of scales 1 (finest) to 5.
pub const MS_SSIM_WEIGHTS: [f64; 5] = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333];

/// The window statistics of one plane pair at one scale, kept for the backward pass.
pub struct Stats<T> {
    w: usize,
    h: usize,
    mu_x: Vec<T>,
    mu_y: Vec<T>,
    var_x: Vec<T>,
    var_y: Vec<T>,
    cov: Vec<T>,
    /// Mean of the SSIM map.
    pub ssim: f64,
    /// Mean of the contrast-structure map.
    pub cs: f64,
}

impl<T: Real> Stats<T> {
    /// Hand the maps back to the pool.
    pub fn recycle(self, pool: &mut Pool<T>) {
        for v in [self.mu_x, self.mu_y, self.var_x, self.var_y, self.cov] {
            pool.put(v);
        }
    }
}

/// The SSIM constants for data range `range`.
pub fn constants(range: f64) -> (f64, f64) {
    ((0.01 * range).powi(2), (0.03 * range).powi(2))
}

/// Window statistics of `x` against `y` (`w × h`, both at least 11×11) and the means of
/// the SSIM and cs maps (accumulated in `f64`).
///
/// Streamed: each input row is filtered horizontally (for `x`, `y`, `x²`, `y²`, `xy`)
/// into a ring of the last 11 rows, and each output row is filtered vertically from the
/// ring as soon as its 11 rows are there, so the working set stays in cache.
pub fn stats<T: Real>(
    x: &[T],
    y: &[T],
    w: usize,
    h: usize,
    range: f64,
    pool: &mut Pool<T>,
) -> Stats<T> {
    let g = taps::<T>();
    let (wo, ho) = (w - 2 * RADIUS, h - 2 * RADIUS);
    let (c1, c2) = constants(range);
    let (c1, c2) = (T::from_f64(c1), T::from_f64(c2));
    let two = T::from_f64(2.0);
    let mut maps: [Vec<T>; 5] = std::array::from_fn(|_| pool.take(wo * ho));
    let mut ring: [Vec<T>; 5] = std::array::from_fn(|_| pool.take(TAPS * wo));
    let mut prod: [Vec<T>; 3] = std::array::from_fn(|_| pool.take(w));
    let mut scratch = pool.take(2 * wo);
    let (mut sum_ssim, mut sum_cs) = (0.0f64, 0.0f64);
    for i in 0..h {
        let (xr, yr) = (&x[i * w..(i + 1) * w], &y[i * w..(i + 1) * w]);
        let [xx, yy, xy] = &mut prod;
        for (((&a, &b), xx), (yy, xy)) in xr.iter().zip(yr).zip(xx).zip(yy.iter_mut().zip(xy)) {
            *xx = a * a;
            *yy = b * b;
            *xy = a * b;
        }
        let slot = i % TAPS;
        let src: [&[T]; 5] = [xr, yr, &prod[0], &prod[1], &prod[2]];
        for (q, s) in src.into_iter().enumerate() {
            correlate_row(&g, s, &mut ring[q][slot * wo..(slot + 1) * wo]);
        }
        if i < 2 * RADIUS {
            continue;
        }
        let r = i - 2 * RADIUS;
        let span = r * wo..(r + 1) * wo;
        for q in 0..5 {
            correlate_rows(&g, ring_rows(&ring[q], wo, r), &mut maps[q][span.clone()]);
        }
        // maps: μx, μy, E[x²] → σx², E[y²] → σy², E[xy] → σxy.
        let [mu_x, mu_y, var_x, var_y, cov] = &mut maps;
        let (row_ssim, row_cs) = stats_row(
            &mu_x[span.clone()],
            &mu_y[span.clone()],
            &mut var_x[span.clone()],
            &mut var_y[span.clone()],
            &mut cov[span.clone()],
            &mut scratch,
            c1,
            c2,
            two,
        );
        sum_ssim += row_ssim;
        sum_cs += row_cs;
    }
    for v in ring.into_iter().chain(prod) {
        pool.put(v);
    }
    pool.put(scratch);
    let n = (wo * ho) as f64;
    let [mu_x, mu_y, var_x, var_y, cov] = maps;
    Stats {
        w,
        h,
        mu_x,
        mu_y,
        var_x,
        var_y,
        cov,
        ssim: sum_ssim / n,
        cs: sum_cs / n,
    }
}

/// Turn one row of second moments into (co)variances in place; return the row's sums of
/// SSIM and cs. `scratch` holds two rows.
#[allow(clippy::too_many_arguments)]
#[inline]
fn stats_row<T: Real>(
    mu_x: &[T],
    mu_y: &[T],
    var_x: &mut [T],
    var_y: &mut [T],
    cov: &mut [T],
    scratch: &mut [T],
    c1: T,
    c2: T,
    two: T,
) -> (f64, f64) {
    let n = mu_x.len();
    let (mu_y, var_x, var_y, cov) = (&mu_y[..n], &mut var_x[..n], &mut var_y[..n], &mut cov[..n]);
    let (ssim, cs) = scratch[..2 * n].split_at_mut(n);
    for i in 0..n {
        let (mx, my) = (mu_x[i], mu_y[i]);
        var_x[i] = var_x[i] - mx * mx;
        var_y[i] = var_y[i] - my * my;
        cov[i] = cov[i] - mx * my;
        let c = (two * cov[i] + c2) / (var_x[i] + var_y[i] + c2);
        cs[i] = c;
        ssim[i] = (two * mx * my + c1) * c / (mx * mx + my * my + c1);
    }
    (lane_sum(ssim), lane_sum(cs))
}

/// Sum in eight independent lanes (so that it vectorises; strict float order forbids the
/// compiler from reassociating a single running sum), then in `f64`.
#[inline]
fn lane_sum<T: Real>(v: &[T]) -> f64 {
    let mut lanes = [T::default(); 8];
    let chunks = v.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (l, &x) in lanes.iter_mut().zip(c) {
            *l += x;
        }
    }
    lanes.iter().chain(rest).map(|x| x.to_f64()).sum()
}

/// Accumulate into `grad` (`w × h`) the gradient with respect to `x` of
/// `k_ssim · mean(SSIM map) + k_cs · mean(cs map)`.
///
/// Each map value depends on `x` through `μx = G*x`, `E[x²] = G*x²` and `E[xy] = G*(xy)`,
/// so the gradient is `Gᵀa + 2x·Gᵀb + y·Gᵀc` with `a, b, c` the map's partial
/// derivatives with respect to those three filtered quantities.
#[allow(clippy::too_many_arguments)]
pub fn backward<T: Real>(
    st: &Stats<T>,
    x: &[T],
    y: &[T],
    range: f64,
    k_ssim: f64,
    k_cs: f64,
    grad: &mut [T],
    pool: &mut Pool<T>,
) {
    let (w, h) = (st.w, st.h);
    let wo = w - 2 * RADIUS;
    let n = st.mu_x.len() as f64;
    let (ks, kc) = (T::from_f64(k_ssim / n), T::from_f64(k_cs / n));
    let (c1, c2) = constants(range);
    let (c1, c2) = (T::from_f64(c1), T::from_f64(c2));
    let two = T::from_f64(2.0);
    let fill = |r: usize, [da, db, dc]: [&mut [T]; 3]| {
        let span = r * wo..(r + 1) * wo;
        let (mu_x, mu_y) = (&st.mu_x[span.clone()], &st.mu_y[span.clone()]);
        let (var_x, var_y, cov) = (
            &st.var_x[span.clone()],
            &st.var_y[span.clone()],
            &st.cov[span],
        );
        let (da, db, dc) = (&mut da[..wo], &mut db[..wo], &mut dc[..wo]);
        for i in 0..wo {
            let (mx, my) = (mu_x[i], mu_y[i]);
            let a1 = two * mx * my + c1;
            let a2 = two * cov[i] + c2;
            let b1 = mx * mx + my * my + c1;
            let b2 = var_x[i] + var_y[i] + c2;
            let d = b1 * b2;
            let s = a1 * a2 / d;
            let cs = a2 / b2;
            // ∂/∂μx, ∂/∂E[x²], ∂/∂E[xy] of SSIM and of cs, weighted.
            da[i] = ks * two * (my * (a2 - a1) - mx * s * (b2 - b1)) / d
                + kc * two * (mx * cs - my) / b2;
            db[i] = -(ks * s + kc * cs) / b2;
            dc[i] = ks * two * a1 / d + kc * two / b2;
        }
    };
    let emit = |j: usize, [ga, gb, gc]: [&[T]; 3]| {
        let span = j * w..(j + 1) * w;
        let (xr, yr) = (&x[span.clone()], &y[span.clone()]);
        let (ga, gb, gc) = (&ga[..w], &gb[..w], &gc[..w]);
        for (i, g) in grad[span].iter_mut().enumerate() {
            *g += ga[i] + two * xr[i] * gb[i] + yr[i] * gc[i];
        }
    };
    adjoint3(&taps::<T>(), w, h, pool, fill, emit);
}

/// How many MS-SSIM scales fit: the most, up to 5, whose coarsest level
/// (`⌊side / 2^(m-1)⌋`) still holds an 11×11 window. Zero if the image itself does not.
pub fn scale_count(w: usize, h: usize) -> usize {
    let side = w.min(h);
    (0..MS_SSIM_WEIGHTS.len())
        .take_while(|&j| side >> j >= TAPS)
        .count()
}

/// MS-SSIM of one plane pair, and (when `grad` is given) `upstream ·` its gradient with
/// respect to `x`, accumulated into `grad`.
///
/// Scales `1..m` contribute their mean cs, scale `m` its mean SSIM, with the weights of
/// [`MS_SSIM_WEIGHTS`] cut to the `m` scales that fit and renormalised to sum 1 (so one
/// scale is plain SSIM). Factors are clamped at 0 before the fractional powers, as in
/// common implementations (a negative mean cs would otherwise give NaN); where a factor
/// is clamped the value is 0 and the gradient is taken as 0.
pub fn ms_ssim_plane<T: Real>(
    x: &[T],
    y: &[T],
    w: usize,
    h: usize,
    range: f64,
    grad: Option<(&mut [T], f64)>,
    pool: &mut Pool<T>,
) -> f64 {
    let m = scale_count(w, h);
    debug_assert!(m >= 1);
    let total: f64 = MS_SSIM_WEIGHTS[..m].iter().sum();
    // The pyramid below the image: coarse[j - 1] = (x, y) at scale j, sizes[j] = (w, h).
    let sizes: Vec<(usize, usize)> = (0..m).map(|j| (w >> j, h >> j)).collect();
    let mut coarse: Vec<(Vec<T>, Vec<T>)> = Vec::with_capacity(m - 1);
    for j in 1..m {
        let (pw, ph) = sizes[j - 1];
        let (mut cx, mut cy) = (pool.take(0), pool.take(0));
        let (fx, fy) = coarse.last().map_or((x, y), |(a, b)| (&a[..], &b[..]));
        pool2(fx, pw, ph, &mut cx);
        pool2(fy, pw, ph, &mut cy);
        coarse.push((cx, cy));
    }
    let level = |j: usize| -> (&[T], &[T]) {
        if j == 0 {
            (x, y)
        } else {
            (&coarse[j - 1].0, &coarse[j - 1].1)
        }
    };
    let mut st = Vec::with_capacity(m);
    for (j, &(lw, lh)) in sizes.iter().enumerate() {
        let (lx, ly) = level(j);
        st.push(stats(lx, ly, lw, lh, range, pool));
    }
    let factor = |j: usize| if j + 1 == m { st[j].ssim } else { st[j].cs };
    let value: f64 = (0..m)
        .map(|j| factor(j).max(0.0).powf(MS_SSIM_WEIGHTS[j] / total))
        .product();
    if let Some((grad, upstream)) = grad {
        if (0..m).all(|j| factor(j) > 0.0) {
            // Coarsest first: each level's gradient flows down through the pooling.
            let mut below: Option<Vec<T>> = None;
            for j in (0..m).rev() {
                let ((lx, ly), (lw, lh)) = (level(j), sizes[j]);
                let mut g = pool.take_zeroed(lw * lh);
                if let Some(b) = below.take() {
                    pool2_adjoint_add(&b, lw, lh, &mut g);
                    pool.put(b);
                }
                let k = upstream * value * (MS_SSIM_WEIGHTS[j] / total) / factor(j);
                let (ks, kc) = if j + 1 == m { (k, 0.0) } else { (0.0, k) };
                backward(&st[j], lx, ly, range, ks, kc, &mut g, pool);
                below = Some(g);
            }
            if let Some(b) = below {
                for (d, &s) in grad.iter_mut().zip(&b) {
                    *d += s;
                }
                pool.put(b);
            }
        }
    }
    for s in st {
        s.recycle(pool);
    }
    for (a, b) in coarse {
        pool.put(a);
        pool.put(b);
    }
    value
}

/// The channels of an 8-bit image as `f64` planes in `[0, 255]`.
fn planes(img: Rgb8<'_>) -> [Vec<f64>; 3] {
    std::array::from_fn(|c| {
        img.data
            .iter()
            .skip(c)
            .step_by(3)
            .map(|&v| v as f64)
            .collect()
    })
}

fn check_window(img: Rgb8<'_>) -> Result<(), MetricError> {
    if img.width < WINDOW || img.height < WINDOW {
        return Err(MetricError::TooSmall {
            width: img.width,
            height: img.height,
            min: WINDOW,
        });
    }
    Ok(())
}

/// Mean SSIM over the three channels, exactly scikit-image's
/// `structural_similarity(a, b, channel_axis=2, data_range=255, gaussian_weights=True,
/// sigma=1.5, use_sample_covariance=False)`: 11×11 Gaussian window (σ = 1.5, truncated
/// at 3.5σ), population statistics, the map averaged over the region 5 pixels in from
/// every edge. Symmetric in its arguments; both images at least 11×11.
pub fn ssim(reference: Rgb8<'_>, image: Rgb8<'_>) -> Result<f64, MetricError> {
    check_pair(reference, image)?;
    check_window(image)?;
    let (w, h) = (image.width as usize, image.height as usize);
    let (pr, pi) = (planes(reference), planes(image));
    Ok((0..3)
        .map(|c| stats(&pi[c], &pr[c], w, h, 255.0, &mut Pool::new()).ssim)
        .sum::<f64>()
        / 3.0)
}

/// Multi-scale SSIM (Wang et al. 2003), per channel, averaged over the three channels.
///
/// Scale 1 is the image; each next scale is a 2×2 average pool of the previous one (an
/// odd last row or column dropped, no rounding). Each scale uses the same window and
/// crop as [`ssim`]. MS-SSIM = Π_{j<m} cs_j^{w_j} · SSIM_m^{w_m} with the weights of
/// [`MS_SSIM_WEIGHTS`]. Five scales need a smaller side of at least 11·2⁴ = 176 pixels;
/// smaller images use the `m` scales that fit (side ≥ 11·2^(m-1)) with the first `m`
/// weights renormalised to sum 1, so an image under 22 pixels gets plain SSIM. A mean
/// cs or SSIM below 0 is clamped to 0.
pub fn ms_ssim(reference: Rgb8<'_>, image: Rgb8<'_>) -> Result<f64, MetricError> {
    check_pair(reference, image)?;
    check_window(image)?;
    let (w, h) = (image.width as usize, image.height as usize);
    let (pr, pi) = (planes(reference), planes(image));
    Ok((0..3)
        .map(|c| ms_ssim_plane(&pi[c], &pr[c], w, h, 255.0, None, &mut Pool::new()))
        .sum::<f64>()
        / 3.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_counts() {
        assert_eq!(scale_count(10, 100), 0);
        assert_eq!(scale_count(11, 11), 1);
        assert_eq!(scale_count(21, 300), 1);
        assert_eq!(scale_count(22, 300), 2);
        assert_eq!(scale_count(175, 300), 4);
        assert_eq!(scale_count(176, 176), 5);
        assert_eq!(scale_count(4000, 3000), 5);
    }

    #[test]
    fn identical_planes_score_one() {
        let (w, h) = (30, 25);
        let x: Vec<f64> = (0..w * h).map(|i| ((i * 37) % 256) as f64).collect();
        let pool = &mut Pool::new();
        let st = stats(&x, &x, w, h, 255.0, pool);
        assert!((st.ssim - 1.0).abs() < 1e-12 && (st.cs - 1.0).abs() < 1e-12);
        assert!((ms_ssim_plane(&x, &x, w, h, 255.0, None, pool) - 1.0).abs() < 1e-12);
    }
}
