//! How brightly each part of an image is lit: the illumination estimate that stage 2's
//! low-light decision ([`super::assess`]) and its local exposure ([`super::curve`]) read.
//!
//! As in Retinex methods and LIME, the illumination of a region is taken from the
//! brightest of its three channels (a red lamp lights a scene as much as a white one),
//! smoothed over a large neighbourhood so that texture and noise do not count as light:
//! a Gaussian of [`SIGMA_FRACTION`] of the image's long side.

/// Standard deviation of the smoothing, as a fraction of the long side: 8 pixels of the
/// 256-pixel working image, a few Gaussians of a typical file across.
pub const SIGMA_FRACTION: f32 = 1.0 / 32.0;

/// The illumination of a `width × height` image of interleaved RGB values: the largest
/// channel of each pixel (display-clamped to `[0, 1]`, NaN as 0), blurred by a Gaussian
/// of [`SIGMA_FRACTION`] of the long side, with the borders mirrored.
pub fn illumination(rgb: &[f32], width: usize, height: usize) -> Vec<f32> {
    let max: Vec<f32> = rgb
        .chunks_exact(3)
        .map(|p| {
            // `max` skips NaN channels; an all-NaN pixel fails the comparison, as 0.
            let m = p[0].max(p[1]).max(p[2]);
            if m >= 0.0 {
                m.min(1.0)
            } else {
                0.0
            }
        })
        .collect();
    let sigma = SIGMA_FRACTION * width.max(height) as f32;
    blur(&max, width, height, sigma)
}

/// A separable Gaussian blur of `src` (`width × height`), radius `3σ`, borders mirrored.
pub fn blur(src: &[f32], width: usize, height: usize, sigma: f32) -> Vec<f32> {
    assert_eq!(src.len(), width * height);
    if src.is_empty() || sigma <= 0.0 || !sigma.is_finite() {
        return src.to_vec();
    }
    let radius = (3.0 * sigma).ceil() as usize;
    let taps: Vec<f32> = (0..=radius)
        .map(|d| (-0.5 * (d as f32 / sigma).powi(2)).exp())
        .collect();
    let norm = taps[0] + 2.0 * taps[1..].iter().sum::<f32>();
    let taps: Vec<f32> = taps.iter().map(|t| t / norm).collect();
    // Mirror an index into 0..n (edges repeated once, as `reflect` padding).
    let mirror = |i: isize, n: usize| -> usize {
        let n = n as isize;
        let period = 2 * n;
        let mut i = i.rem_euclid(period);
        if i >= n {
            i = period - 1 - i;
        }
        i as usize
    };
    let mut rows = vec![0.0f32; src.len()];
    for y in 0..height {
        let row = &src[y * width..][..width];
        for x in 0..width {
            let mut acc = taps[0] * row[x];
            for (d, &t) in taps.iter().enumerate().skip(1) {
                let (l, r) = (x as isize - d as isize, x as isize + d as isize);
                acc += t * (row[mirror(l, width)] + row[mirror(r, width)]);
            }
            rows[y * width + x] = acc;
        }
    }
    let mut out = vec![0.0f32; src.len()];
    for y in 0..height {
        for x in 0..width {
            let mut acc = taps[0] * rows[y * width + x];
            for (d, &t) in taps.iter().enumerate().skip(1) {
                let (u, v) = (y as isize - d as isize, y as isize + d as isize);
                acc +=
                    t * (rows[mirror(u, height) * width + x] + rows[mirror(v, height) * width + x]);
            }
            out[y * width + x] = acc;
        }
    }
    out
}

/// The value below which a share `q` (in `[0, 1]`) of `values` lies (nearest rank); 0 for
/// none.
pub fn quantile(values: &[f32], q: f32) -> f32 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v: Vec<f32> = values
        .iter()
        .map(|x| if x.is_nan() { 0.0 } else { *x })
        .collect();
    let k = ((v.len() - 1) as f32 * q.clamp(0.0, 1.0)).round() as usize;
    *v.select_nth_unstable_by(k, f32::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flat_image_is_lit_by_its_brightest_channel() {
        let img: Vec<f32> = [0.1, 0.3, 0.2].repeat(40 * 30);
        for l in illumination(&img, 40, 30) {
            assert!((l - 0.3).abs() < 1e-5, "{l}");
        }
    }

    #[test]
    fn the_blur_keeps_the_mean_and_spreads_a_spot() {
        let (w, h) = (33, 21);
        let mut img = vec![0.0f32; w * h];
        img[10 * w + 16] = 1.0;
        let b = blur(&img, w, h, 2.0);
        let sum: f32 = b.iter().sum();
        assert!((sum - 1.0).abs() < 1e-4, "{sum}");
        assert!(b[10 * w + 16] > b[10 * w + 18] && b[10 * w + 18] > b[10 * w + 20]);
    }

    #[test]
    fn black_white_nan_and_tiny_images_stay_finite() {
        for (img, w, h) in [
            (vec![0.0; 3], 1, 1),
            (vec![1.0; 12], 2, 2),
            (vec![f32::NAN, f32::INFINITY, -1.0], 1, 1),
            (Vec::new(), 0, 0),
        ] {
            let l = illumination(&img, w, h);
            assert_eq!(l.len(), w * h);
            assert!(
                l.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)),
                "{l:?}"
            );
        }
        assert_eq!(quantile(&[], 0.5), 0.0);
        assert_eq!(quantile(&[3.0, 1.0, 2.0], 1.0), 3.0);
    }
}
