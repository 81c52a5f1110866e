//! Figures of low-light enhancement: the GT-mean rescaling, lightness-order error (LOE),
//! discrete entropy (DE) and the measure of enhancement (EME).
//!
//! Each convention below was chosen by reproducing the reference table of
//! `shared/data/README.md` (rows "input", "gamma 0.4" and "auto-gamma" on LOL eval15);
//! the alternatives tried and what they gave are listed where they matter.

use super::color::BT601;
use super::{check_pair, MetricError, Rgb8};

/// LOE compares lightness order on a block-averaged image about this many pixels on its
/// smaller side.
pub const LOE_ROWS: u32 = 50;
/// EME block side, pixels.
pub const EME_BLOCK: u32 = 8;
/// Added to a block's maximum and minimum gray level (on the 0–255 scale) before their
/// ratio, so that a block whose minimum is 0 stays finite.
pub const EME_EPS: f64 = 1e-4;

/// ITU-R BT.601 luma `0.299 R + 0.587 G + 0.114 B` of every pixel, in `[0, 255]`,
/// unrounded (the README's "gray level"; the plain mean of R, G, B gives 18.75 dB
/// instead of the table's 18.78 for PSNR-gm of the LOL inputs).
pub fn luma(image: Rgb8<'_>) -> Vec<f64> {
    image
        .data
        .chunks_exact(3)
        .map(|p| p[0] as f64 * BT601[0] + p[1] as f64 * BT601[1] + p[2] as f64 * BT601[2])
        .collect()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// The "GT-mean" version of `image`: every channel multiplied by
/// `mean luma(reference) / mean luma(image)`, clipped to `[0, 255]` and rounded to 8 bits
/// (half to even, as numpy). It removes the overall brightness, which the reference of a
/// low-light pair fixes arbitrarily, so that PSNR and SSIM judge the rest. An all-black
/// image cannot be rescaled and is returned unchanged.
pub fn gt_mean(reference: Rgb8<'_>, image: Rgb8<'_>) -> Result<Vec<u8>, MetricError> {
    check_pair(reference, image)?;
    let (target, current) = (mean(&luma(reference)), mean(&luma(image)));
    if current <= 0.0 {
        return Ok(image.data.to_vec());
    }
    Ok(image
        .data
        .iter()
        .map(|&v| {
            (v as f64 * target / current)
                .clamp(0.0, 255.0)
                .round_ties_even() as u8
        })
        .collect())
}

/// Side of the blocks [`flat_noise`] looks at, in pixels.
pub const FLAT_BLOCK: u32 = 16;
/// A block of the reference whose luma varies less than this (standard deviation, 8-bit
/// steps) counts as flat.
pub const FLAT_MAX_STD: f64 = 1.5;
/// Flat blocks darker than this mean luma (8-bit) are left out: in a dark reference
/// a flat block is often flat because it is black.
const FLAT_MIN_MEAN: f64 = 20.0;

/// Noise on flat surfaces: the median, over the `FLAT_BLOCK`-pixel blocks where the
/// reference is flat (luma standard deviation below [`FLAT_MAX_STD`], mean luma at least
/// 20), of the image's luma standard deviation in that block, in 8-bit steps. `None`
/// where the reference has no flat block. A low-light enhancement that lifts sensor
/// noise with the signal shows it here: a wall that is flat in the reference is grainy
/// or blotchy in the output.
pub fn flat_noise(reference: Rgb8<'_>, image: Rgb8<'_>) -> Result<Option<f64>, MetricError> {
    check_pair(reference, image)?;
    let (w, h) = (reference.width as usize, reference.height as usize);
    let (r, o) = (luma(reference), luma(image));
    let b = FLAT_BLOCK as usize;
    let stats = |v: &[f64], x0: usize, y0: usize| {
        let (mut s, mut s2) = (0.0, 0.0);
        for y in y0..y0 + b {
            for x in x0..x0 + b {
                let p = v[y * w + x];
                s += p;
                s2 += p * p;
            }
        }
        let n = (b * b) as f64;
        let m = s / n;
        (m, (s2 / n - m * m).max(0.0).sqrt())
    };
    let mut found = Vec::new();
    for y0 in (0..h.saturating_sub(b - 1)).step_by(b) {
        for x0 in (0..w.saturating_sub(b - 1)).step_by(b) {
            let (m, sd) = stats(&r, x0, y0);
            if sd < FLAT_MAX_STD && m >= FLAT_MIN_MEAN {
                found.push(stats(&o, x0, y0).1);
            }
        }
    }
    if found.is_empty() {
        return Ok(None);
    }
    found.sort_by(f64::total_cmp);
    let k = found.len() / 2;
    Ok(Some(if found.len() % 2 == 1 {
        found[k]
    } else {
        0.5 * (found[k - 1] + found[k])
    }))
}

/// A channel value from which a pixel counts as clipped.
pub const CLIPPED_FROM: u8 = 250;

/// The share of pixels, in `[0, 1]`, with any channel at [`CLIPPED_FROM`] or above:
/// highlights a brightening burnt out.
pub fn clipped_share(image: Rgb8<'_>) -> f64 {
    let n = image.data.len() / 3;
    if n == 0 {
        return 0.0;
    }
    let clipped = image
        .data
        .chunks_exact(3)
        .filter(|p| p.iter().any(|&v| v >= CLIPPED_FROM))
        .count();
    clipped as f64 / n as f64
}

/// Discrete entropy, in bits, of the 256-bin histogram of the luma rounded to 8 bits
/// (half to even). At most 8; 0 for a flat image.
pub fn de(image: Rgb8<'_>) -> f64 {
    let mut hist = [0u64; 256];
    for y in luma(image) {
        hist[y.round_ties_even().clamp(0.0, 255.0) as usize] += 1;
    }
    let n = image.pixels() as f64;
    -hist
        .iter()
        .filter(|&&c| c > 0)
        .map(|&c| {
            let p = c as f64 / n;
            p * p.log2()
        })
        .sum::<f64>()
}

/// Measure of enhancement: over 8×8 blocks of the (unrounded) luma, starting at the top
/// left, the mean of `20 · ln((max + ε) / (min + ε))` with `ε` = [`EME_EPS`] = 1e-4 on the
/// 0–255 scale. Blocks cut by the right or bottom edge count as they are.
///
/// The regularisation decides the figure for dark images, whose blocks often have a
/// minimum of 0: on the 15 LOL inputs `ε = 1e-4` on unrounded luma gives 43.12 (README:
/// 43.1) and on their gamma-0.4 versions 39.31 (README: 39.3), whereas `max(·, 1)` gives
/// 20.8, `+1` 19.2, and `ε = 1e-4` on luma rounded to 8 bits 46.4.
pub fn eme(image: Rgb8<'_>) -> f64 {
    let (w, h) = (image.width as usize, image.height as usize);
    let gray = luma(image);
    let b = EME_BLOCK as usize;
    let (mut sum, mut blocks) = (0.0, 0usize);
    for r0 in (0..h).step_by(b) {
        for c0 in (0..w).step_by(b) {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for r in r0..(r0 + b).min(h) {
                for &v in &gray[r * w + c0..r * w + (c0 + b).min(w)] {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            sum += 20.0 * ((hi + EME_EPS) / (lo + EME_EPS)).ln();
            blocks += 1;
        }
    }
    sum / blocks as f64
}

/// Lightness-order error of an enhancement, `input → output` (Wang et al., NPE, 2013).
///
/// Lightness is `L = max(R, G, B)` at full resolution. Both lightness images are then
/// averaged over `s × s` blocks, `s = max(1, ⌊min(width, height) / 50⌋)` (an odd
/// remainder of rows or columns dropped), giving about 50 pixels on the smaller side
/// (exactly 50×75 for LOL's 600×400). Then
///
/// ```text
/// LOE = (1/n) Σ_x Σ_y [ (L_in(x) ≥ L_in(y)) XOR (L_out(x) ≥ L_out(y)) ]
/// ```
///
/// over the `n` block pixels. 0 means the enhancement kept every lightness order.
/// Block sums are compared as integers, so ties are exact. On LOL this reproduces the
/// README's 50.2 (gamma 0.4) and 68.7 (auto-gamma); downsampling by taking every 8th
/// pixel gives 0.1, and computing `max(R, G, B)` after averaging gives 61.0.
///
/// Counted in `O(n log n)` (sorting and a Fenwick tree), not by the `O(n²)` definition,
/// so that small `s` on a long thin image stays cheap.
pub fn loe(input: Rgb8<'_>, output: Rgb8<'_>) -> Result<f64, MetricError> {
    check_pair(input, output)?;
    let a = lightness_blocks(input);
    let b = lightness_blocks(output);
    Ok(order_disagreements(&a, &b) as f64 / a.len() as f64)
}

/// Block sums of `max(R, G, B)`, row-major (see [`loe`]).
fn lightness_blocks(image: Rgb8<'_>) -> Vec<u64> {
    let (w, h) = (image.width as usize, image.height as usize);
    let s = (w.min(h) / LOE_ROWS as usize).max(1);
    let (ws, hs) = (w / s, h / s);
    let mut out = vec![0u64; ws * hs];
    for r in 0..hs * s {
        let row = &image.data[r * w * 3..(r * w + ws * s) * 3];
        for (c, p) in row.chunks_exact(3).enumerate() {
            out[(r / s) * ws + c / s] += p[0].max(p[1]).max(p[2]) as u64;
        }
    }
    out
}

/// `Σ_x #{y : (a_y ≤ a_x) XOR (b_y ≤ b_x)}`, which is `Σ_x P_x + Q_x − 2 R_x` with
/// `P_x = #{a_y ≤ a_x}`, `Q_x = #{b_y ≤ b_x}` and `R_x = #{a_y ≤ a_x ∧ b_y ≤ b_x}`.
fn order_disagreements(a: &[u64], b: &[u64]) -> u64 {
    let n = a.len();
    // Σ_x #{y : v_y ≤ v_x}: in sorted order every member of a run of equal values
    // counts everything up to the end of its run.
    let at_most = |v: &[u64]| -> u64 {
        let mut s = v.to_vec();
        s.sort_unstable();
        let mut total = 0u64;
        let mut i = 0;
        while i < n {
            let j = i + s[i..].iter().take_while(|&&x| x == s[i]).count();
            total += ((j - i) * j) as u64;
            i = j;
        }
        total
    };
    let (p, q) = (at_most(a), at_most(b));

    // R: sweep x in increasing a; a run of equal a is inserted whole before it is
    // queried, since its members precede each other. The tree counts b ranks.
    let mut bs = b.to_vec();
    bs.sort_unstable();
    bs.dedup();
    let rank = |v: u64| bs.partition_point(|&x| x <= v); // 1-based rank of v
    let mut tree = vec![0u32; bs.len() + 1];
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_unstable_by_key(|&i| a[i]);
    let mut r = 0u64;
    let mut i = 0;
    while i < n {
        let j = i + order[i..]
            .iter()
            .take_while(|&&k| a[k] == a[order[i]])
            .count();
        for &k in &order[i..j] {
            let mut t = rank(b[k]);
            while t < tree.len() {
                tree[t] += 1;
                t += t & t.wrapping_neg();
            }
        }
        for &k in &order[i..j] {
            let mut t = rank(b[k]);
            while t > 0 {
                r += tree[t] as u64;
                t -= t & t.wrapping_neg();
            }
        }
        i = j;
    }
    p + q - 2 * r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(a: &[u64], b: &[u64]) -> u64 {
        let mut n = 0;
        for x in 0..a.len() {
            for y in 0..a.len() {
                n += ((a[x] >= a[y]) != (b[x] >= b[y])) as u64;
            }
        }
        n
    }

    #[test]
    fn fast_count_matches_definition() {
        let mut s = 7u64;
        for len in [1usize, 2, 5, 40, 300] {
            for levels in [2u64, 5, 1000] {
                let mut rnd = || {
                    s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
                    (s >> 33) % levels
                };
                let a: Vec<u64> = (0..len).map(|_| rnd()).collect();
                let b: Vec<u64> = (0..len).map(|_| rnd()).collect();
                assert_eq!(order_disagreements(&a, &b), brute(&a, &b));
                assert_eq!(order_disagreements(&a, &a), 0);
            }
        }
    }

    #[test]
    fn block_sums() {
        // 4x2 image: the smaller side 2 < 50, so s = 1 and L is max(R, G, B) itself.
        let data: Vec<u8> = (0..24).collect();
        let img = Rgb8::new(4, 2, &data).unwrap();
        assert_eq!(lightness_blocks(img), vec![2, 5, 8, 11, 14, 17, 20, 23]);
        // 120x100: s = 2, 60x50 blocks of 4 pixels.
        let data = vec![10u8; 120 * 100 * 3];
        let img = Rgb8::new(120, 100, &data).unwrap();
        let l = lightness_blocks(img);
        assert_eq!(l.len(), 60 * 50);
        assert!(l.iter().all(|&v| v == 40));
    }

    #[test]
    fn entropy_and_eme_of_simple_images() {
        let flat = vec![77u8; 16 * 16 * 3];
        let img = Rgb8::new(16, 16, &flat).unwrap();
        assert_eq!(de(img), 0.0);
        assert!(eme(img).abs() < 1e-12);
        // Two gray levels, half each: 1 bit.
        let halves: Vec<u8> = (0..16 * 16 * 3)
            .map(|i| if i < 16 * 8 * 3 { 0 } else { 200 })
            .collect();
        let img = Rgb8::new(16, 16, &halves).unwrap();
        assert!((de(img) - 1.0).abs() < 1e-12);
    }
}
