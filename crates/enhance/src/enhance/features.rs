//! Guidance features for the weight-map head (paper Eq. 12).
//!
//! The paper extracts them with the first seven layers of an ImageNet-trained
//! MobileNetV2. Those weights are not ours to ship, so the default [`Backbone`] is a
//! fixed, training-free bank of the cues such a network's early layers respond to:
//! brightness, opponent colour, saturation, edges and local contrast, each at four
//! spatial scales. A learned extractor can implement the same trait.

/// Something that turns an image into a grid of feature vectors.
pub trait Backbone {
    /// Short name, recorded in the file's settings.
    fn name(&self) -> &'static str;
    /// D, the length of each feature vector.
    fn dim(&self) -> usize;
    /// Features of `img` (`width·height·3` floats, RGB in `[0, 1]`) on a
    /// `map_width × map_height` grid whose cells split the image evenly; returns
    /// `map_width·map_height·D` floats, D innermost. Every value is finite.
    fn extract(
        &self,
        img: &[f32],
        width: usize,
        height: usize,
        map_width: usize,
        map_height: usize,
    ) -> Vec<f32>;
}

/// Base cues per cell before the multi-scale pyramid.
const CUES: usize = 8;
/// Box radii, in cells, of the four scales.
const RADII: [usize; 4] = [0, 1, 3, 7];

/// The built-in training-free backbone, D = 32: eight cues (mean luma, log luma,
/// red–green, yellow–blue, saturation, gradient magnitude, local luma contrast, darkest
/// channel) averaged over each cell, then box-filtered at radii 0, 1, 3 and 7 cells, and
/// each of the 32 channels standardized over the image, so the head sees comparable
/// scales whatever the exposure.
#[derive(Clone, Copy, Debug, Default)]
pub struct FeatureBank;

impl Backbone for FeatureBank {
    fn name(&self) -> &'static str {
        "feature-bank-v1"
    }

    fn dim(&self) -> usize {
        CUES * RADII.len()
    }

    fn extract(&self, img: &[f32], width: usize, height: usize, mw: usize, mh: usize) -> Vec<f32> {
        assert_eq!(img.len(), width * height * 3);
        let cells = mw * mh;
        let luma: Vec<f32> = img.chunks_exact(3).map(super::loss::display_luma).collect();
        // Each cell averages the pixels of its share of the image; a cell smaller than
        // a pixel (a map finer than the image) takes the pixel under its centre.
        let span = |c: usize, n: usize, px: usize| {
            let lo = (c * px / n).min(px - 1);
            lo..((c + 1) * px / n).clamp(lo + 1, px)
        };
        let mut base = vec![0.0f64; cells * CUES];
        for cy in 0..mh {
            for cx in 0..mw {
                let (xs, ys) = (span(cx, mw, width), span(cy, mh, height));
                let n = (xs.len() * ys.len()) as f64;
                let sums = &mut base[(cy * mw + cx) * CUES..][..CUES];
                for y in ys {
                    for x in xs.clone() {
                        for (s, v) in sums.iter_mut().zip(cues(img, &luma, width, height, x, y)) {
                            *s += f64::from(v);
                        }
                    }
                }
                for s in sums.iter_mut() {
                    *s /= n;
                }
            }
        }
        let mut out = vec![0.0f32; cells * self.dim()];
        for (s, &r) in RADII.iter().enumerate() {
            let blurred = box_filter(&base, mw, mh, CUES, r);
            for cell in 0..cells {
                let b = &blurred[cell * CUES..][..CUES];
                let o = &mut out[cell * self.dim() + s * CUES..][..CUES];
                for (o, v) in o.iter_mut().zip(b) {
                    *o = *v as f32;
                }
                // Local contrast: E[l²] − E[l]² over the window.
                o[6] = (b[6] - b[0] * b[0]).max(0.0).sqrt() as f32;
            }
        }
        standardize(&mut out, self.dim());
        out
    }
}

/// The per-pixel cues at `(x, y)`; see [`FeatureBank`].
fn cues(img: &[f32], luma: &[f32], width: usize, height: usize, x: usize, y: usize) -> [f32; CUES] {
    let p = y * width + x;
    let [r, g, b] = [0, 1, 2].map(|c| img[3 * p + c].clamp(0.0, 1.0));
    let l = luma[p];
    let at = |dx: isize, dy: isize| {
        let xx = (x as isize + dx).clamp(0, width as isize - 1) as usize;
        let yy = (y as isize + dy).clamp(0, height as isize - 1) as usize;
        luma[yy * width + xx]
    };
    let gx = at(1, 0) - at(-1, 0);
    let gy = at(0, 1) - at(0, -1);
    let mx = r.max(g).max(b);
    let mn = r.min(g).min(b);
    [
        l,
        (l + 1.0 / 64.0).ln(),
        r - g,
        0.5 * (r + g) - b,
        (mx - mn) / (mx + 1e-3),
        (gx * gx + gy * gy).sqrt(),
        l * l, // becomes the local standard deviation of luma
        mn,
    ]
}

/// Mean over a `(2r+1)²` window of cells, clipped at the borders.
fn box_filter(v: &[f64], w: usize, h: usize, ch: usize, r: usize) -> Vec<f64> {
    if r == 0 {
        return v.to_vec();
    }
    let mut out = vec![0.0; v.len()];
    for y in 0..h {
        for x in 0..w {
            let (y0, y1) = (y.saturating_sub(r), (y + r).min(h - 1));
            let (x0, x1) = (x.saturating_sub(r), (x + r).min(w - 1));
            let n = ((y1 - y0 + 1) * (x1 - x0 + 1)) as f64;
            let o = &mut out[(y * w + x) * ch..][..ch];
            for yy in y0..=y1 {
                for xx in x0..=x1 {
                    for (o, s) in o.iter_mut().zip(&v[(yy * w + xx) * ch..][..ch]) {
                        *o += s;
                    }
                }
            }
            for o in o.iter_mut() {
                *o /= n;
            }
        }
    }
    out
}

/// Zero mean and unit variance per channel; a constant channel becomes zeros.
fn standardize(f: &mut [f32], dim: usize) {
    let n = (f.len() / dim) as f64;
    for c in 0..dim {
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for v in f.iter().skip(c).step_by(dim) {
            s += f64::from(*v);
            s2 += f64::from(*v) * f64::from(*v);
        }
        let mean = s / n;
        let sd = (s2 / n - mean * mean).max(0.0).sqrt();
        for v in f.iter_mut().skip(c).step_by(dim) {
            *v = if sd > 1e-6 {
                ((f64::from(*v) - mean) / sd) as f32
            } else {
                0.0
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn features_are_finite_and_standardized() {
        let (w, h) = (40, 30);
        let img: Vec<f32> = (0..w * h * 3)
            .map(|i| ((i * 7919) % 101) as f32 / 100.0)
            .collect();
        let f = FeatureBank.extract(&img, w, h, 5, 4);
        assert_eq!(f.len(), 5 * 4 * 32);
        assert!(f.iter().all(|x| x.is_finite()));
        let mean0: f32 = f.iter().step_by(32).sum::<f32>() / 20.0;
        assert!(mean0.abs() < 1e-4);
    }

    #[test]
    fn flat_black_and_tiny_images_give_zeros() {
        for (w, h, mw, mh) in [(8, 8, 2, 2), (1, 1, 1, 1), (3, 1, 4, 2)] {
            let f = FeatureBank.extract(&vec![0.0; w * h * 3], w, h, mw, mh);
            assert!(f.iter().all(|&x| x == 0.0));
        }
        let f = FeatureBank.extract(&[f32::NAN, 5.0, -1.0], 1, 1, 1, 1);
        assert!(f.iter().all(|x| x.is_finite()));
    }
}
