//! The zero-shot low-light enhancement loss (paper §III-B, Eq. 16–22) and its gradient,
//! written out by hand.
//!
//! An enhanced image `I_e` is scored against the low-light image `I_low` it came from,
//! with no reference: five image terms (exposure, hue, spatial consistency, colour
//! richness and contrast, Eq. 16–21, in [`ImageLoss`]) and two regularizers of the
//! weight map that mixes the colour operators (total variation and entropy, Eq. 22, in
//! [`map_regularizers`]). The encoder minimizes them by gradient descent and the crate
//! carries no automatic differentiation, so every term comes with its exact gradient,
//! which the tests check against finite differences.
//!
//! ```
//! use gsi_enhance::enhance::loss::{ImageLoss, LossParams, LossWeights};
//! let (w, h) = (4, 3);
//! let low = vec![0.05f32; w * h * 3];
//! let loss = ImageLoss::new(&low, w, h, LossWeights::default(), LossParams::default());
//! let brighter: Vec<f32> = low.iter().map(|v| v * 8.0).collect();
//! let mut grad = vec![0f32; brighter.len()];
//! let terms = loss.eval(&brighter, &mut grad);
//! // Too dark for the exposure target: raising any pixel lowers the loss.
//! assert!(terms.exposure > 0.0 && grad.iter().all(|&g| g < 0.0));
//! ```
//!
//! # Conventions
//!
//! The paper leaves these open; they are fixed here so that values are comparable between
//! image sizes and runs.
//!
//! * Images are `width × height × 3` `f32`, interleaved RGB, row-major, nominally in
//!   `[0, 1]`. `I_e` is used as it is, even outside that range, so that the gradient
//!   always describes the function evaluated.
//! * Every "mean" is the arithmetic mean over the items named, and every standard
//!   deviation is the population one (divided by the count, not the count minus one).
//! * Sums and means are accumulated in `f64`, so a term does not drift with image size;
//!   inputs, values and gradients are `f32`.
//! * Where a term has a kink (`|x|` at 0, a hinge at 0, the two branches of a `min`
//!   equal) the gradient is the subgradient 0, and discrete choices (which channel of a
//!   pixel is largest, which branch of a `min` is taken) are held fixed when
//!   differentiating.
//! * The spatial term (Eq. 21) compares the Sobel responses of `I_e` with those of
//!   `I_low` *scaled by the ratio of their mean lumas*, `s = Ȳ(I_e) / Ȳ(I_low)`, and
//!   differentiates through `s`. Compared unscaled, as Eq. 21 is written, brightening
//!   by a gain `g` multiplies every edge by `g`, so the spatial term fights the
//!   exposure term and the brightness a fit settles at is set by how textured the image
//!   is rather than by `E` (measured on LOL: half the images stayed near-black while
//!   flat ones reached the target). Scaled, it keeps its purpose (no new edges, no
//!   noise, no lost ones) without taxing brightness.
//! * Nothing returned is NaN or infinite for finite input: every division and square
//!   root is guarded by an epsilon, and values beyond the `f32` range saturate at
//!   `±f32::MAX`.

use gsi_metrics::metrics::sobel_row;
use std::fmt;

/// Below this mean luma the low image counts as black, and the spatial term compares
/// against its gradients unscaled.
const LOW_LUMA_MIN: f64 = 1e-6;

/// ITU-R BT.601 luma weights of the exposure term (Eq. 17).
const LUMA: [f64; 3] = gsi_metrics::metrics::BT601;

/// Rec. 601 luma of a pixel as an 8-bit display shows it (each channel clamped to
/// `[0, 1]`, NaN shown as 0): what the low-light test, the features and the reports call
/// brightness. Evaluated in `f32`, channel by channel, so that it is cheap per pixel.
pub fn display_luma(p: &[f32]) -> f32 {
    const W: [f32; 3] = gsi_metrics::metrics::BT601_F32;
    let shown = |x: f32| if x >= 0.0 { x.min(1.0) } else { 0.0 };
    W[0] * shown(p[0]) + W[1] * shown(p[1]) + W[2] * shown(p[2])
}

/// Chroma (`max − min`) at or below which a pixel's hue is taken as 0 with a zero
/// gradient: the hue of a near-grey pixel is undefined and its gradient would explode.
const HUE_EPS: f64 = 1e-6;
/// Added to `max` in the saturation `(max − min) / (max + ε)`, so black has S = 0.
const SAT_EPS: f64 = 1e-6;
/// Added to the number of saturated pixels, so an image with none has a hue term of 0.
const MASK_EPS: f64 = 1e-6;
/// Inside the square root of the colour richness, so a grey image has a finite gradient.
const COLOUR_EPS: f64 = 1e-8;
/// Added to a variance of `I_e` before its square root, so σ is smooth at a flat channel.
const STD_EPS: f64 = 1e-12;
/// Inside the logarithm of the entropy, so a vanishing weight contributes `0 · ln ε = 0`.
const LOG_EPS: f64 = 1e-8;

/// λ1..λ7 of paper Eq. 16 and 22: how much each term counts in the objective.
///
/// The defaults are the paper's. A weight of 0 removes a term from the gradient and the
/// total, but its value is still reported.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossWeights {
    /// Exposure control (Eq. 17).
    pub exposure: f32,
    /// Hue consistency (Eq. 18).
    pub hue: f32,
    /// Spatial (gradient) consistency (Eq. 21).
    pub spatial: f32,
    /// Colour richness (Eq. 19).
    pub colour: f32,
    /// Contrast preservation (Eq. 20).
    pub contrast: f32,
    /// Total variation of the weight map (Eq. 22).
    pub tv: f32,
    /// Entropy of the weight map (Eq. 22).
    pub entropy: f32,
}

impl LossWeights {
    /// λ1..λ7 in the paper's order (exposure, hue, spatial, colour, contrast, TV,
    /// entropy): the order of the command line's `--weights` and of `gENH`.
    pub fn from_array(w: [f32; 7]) -> LossWeights {
        LossWeights {
            exposure: w[0],
            hue: w[1],
            spatial: w[2],
            colour: w[3],
            contrast: w[4],
            tv: w[5],
            entropy: w[6],
        }
    }

    /// The inverse of [`LossWeights::from_array`].
    pub fn to_array(&self) -> [f32; 7] {
        [
            self.exposure,
            self.hue,
            self.spatial,
            self.colour,
            self.contrast,
            self.tv,
            self.entropy,
        ]
    }
}

impl Default for LossWeights {
    fn default() -> Self {
        LossWeights {
            exposure: 50.0,
            hue: 25.0,
            spatial: 32.5,
            colour: 2.91,
            contrast: 0.44,
            tv: 500.0,
            entropy: 0.01,
        }
    }
}

/// The constants inside the image terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossParams {
    /// `E` of Eq. 17: the mean luma the enhanced image should reach. Default 0.5, mid
    /// grey, not the paper's 0.7: see [`ImageLoss::eval_display`] and BENCHMARKS.md.
    /// Scored on the whole image's mean (not per patch, as Zero-DCE does), 0.7 lifts a
    /// scene with a bright window until everything else is washed out, and on LOL
    /// eval15 it scores 1.1 dB lower (16.40 against 17.52 dB, the stage-2 table of
    /// BENCHMARKS.md).
    pub exposure_target: f32,
    /// τ of Eq. 18: only pixels of `I_low` more saturated than this constrain the hue,
    /// since the hue of a near-grey pixel is mostly noise. Default 0.1.
    pub saturation_tau: f32,
    /// γ of Eq. 20: each channel of `I_e` should vary at least γ times as much as in
    /// `I_low`. Default 1.05.
    pub contrast_gamma: f32,
}

impl Default for LossParams {
    fn default() -> Self {
        LossParams {
            exposure_target: 0.5,
            saturation_tau: 0.1,
            contrast_gamma: 1.05,
        }
    }
}

/// Unweighted values of each image term, plus the weighted total (Eq. 16).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImageTerms {
    /// `(mean_p Y_p − E)²` (Eq. 17).
    pub exposure: f32,
    /// Mean circular hue distance over the saturated pixels of `I_low` (Eq. 18), in
    /// `[0, 0.5]` (hue is measured in turns).
    pub hue: f32,
    /// Mean absolute difference of horizontal plus vertical Sobel responses (Eq. 21),
    /// against those of the low image scaled by the brightness ratio (see the module
    /// conventions).
    pub spatial: f32,
    /// Minus the opponent-colour spread `√(σ_rg² + σ_yb² + ε)` (Eq. 19): at most −1e-4.
    pub colour: f32,
    /// Mean over channels of the standard deviation missing to reach γ·σ_low (Eq. 20).
    pub contrast: f32,
    /// `Σ λ · term` over the five terms above.
    pub total: f32,
}

/// The five image terms of Eq. 16–21, with everything that depends only on `I_low`
/// (its hue, saturation mask, Sobel responses and channel deviations) computed once,
/// since the encoder evaluates the loss many times against the same `I_low`.
///
/// Memory: about 28 bytes per pixel (`I_low` itself is not kept).
#[derive(Clone)]
pub struct ImageLoss {
    width: usize,
    height: usize,
    weights: LossWeights,
    params: LossParams,
    /// Hue of each pixel of the clamped `I_low`, in `[0, 1]`, or −1 where the pixel's
    /// saturation is not above τ (outside the mask of Eq. 18).
    low_hue: Vec<f32>,
    /// Number of pixels in the mask.
    masked: f64,
    /// Horizontal and vertical Sobel responses of `I_low`, per pixel and channel.
    low_gx: Vec<f32>,
    low_gy: Vec<f32>,
    /// Population standard deviation of each channel of `I_low`.
    low_std: [f64; 3],
    /// Mean luma of the low image: the spatial term compares against its gradients
    /// scaled by the brightness ratio.
    low_luma: f64,
}

impl fmt::Debug for ImageLoss {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ImageLoss")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("weights", &self.weights)
            .field("params", &self.params)
            .field("masked", &self.masked)
            .field("low_std", &self.low_std)
            .finish_non_exhaustive()
    }
}

/// The five terms in `f64`, before they are reported as `f32`.
#[derive(Clone, Copy, Debug)]
struct Terms64 {
    /// `d total / d x` of every value of the exposure image's channel `c` is
    /// `exposure_slope · LUMA[c]`.
    exposure_slope: f64,
    exposure: f64,
    hue: f64,
    spatial: f64,
    colour: f64,
    contrast: f64,
    total: f64,
}

impl From<Terms64> for ImageTerms {
    fn from(t: Terms64) -> ImageTerms {
        ImageTerms {
            exposure: sat(t.exposure),
            hue: sat(t.hue),
            spatial: sat(t.spatial),
            colour: sat(t.colour),
            contrast: sat(t.contrast),
            total: sat(t.total),
        }
    }
}

/// The luma of channel means (the mean luma of their image).
fn luma_of(mean: [f64; 3]) -> f64 {
    LUMA[0] * mean[0] + LUMA[1] * mean[1] + LUMA[2] * mean[2]
}

impl ImageLoss {
    /// Prepares the loss against `low` (`width × height × 3` floats, interleaved RGB,
    /// row-major).
    ///
    /// `low` is clamped to `[0, 1]` for its hue and saturation only, as they are
    /// meaningless outside; its Sobel responses and deviations use it as it is, so that
    /// `I_e = I_low` scores 0 on the spatial term whatever the values.
    ///
    /// # Panics
    ///
    /// If `width` or `height` is 0, or `low.len() != width * height * 3`.
    pub fn new(
        low: &[f32],
        width: usize,
        height: usize,
        weights: LossWeights,
        params: LossParams,
    ) -> ImageLoss {
        assert!(
            width > 0 && height > 0,
            "ImageLoss: empty image ({width}×{height})"
        );
        let len = image_len(width, height);
        assert_eq!(
            low.len(),
            len,
            "ImageLoss: low has {} floats, {width}×{height}×3 needs {len}",
            low.len()
        );

        let tau = params.saturation_tau as f64;
        let mut masked = 0usize;
        let low_hue = low
            .chunks_exact(3)
            .map(|p| {
                let c = [p[0], p[1], p[2]].map(|v| (v as f64).clamp(0.0, 1.0));
                let mx = c[0].max(c[1]).max(c[2]);
                let mn = c[0].min(c[1]).min(c[2]);
                if (mx - mn) / (mx + SAT_EPS) > tau {
                    masked += 1;
                    hue_and_grad(c).0 as f32
                } else {
                    -1.0
                }
            })
            .collect();

        let row = 3 * width;
        let mut low_gx = vec![0f32; len];
        let mut low_gy = vec![0f32; len];
        for (y, (gx, gy)) in low_gx
            .chunks_exact_mut(row)
            .zip(low_gy.chunks_exact_mut(row))
            .enumerate()
        {
            let [up, mid, dn] = neighbours(y, height).map(|r| &low[r * row..(r + 1) * row]);
            sobel_row::<3>(up, mid, dn, gx, gy);
        }

        let n = (width * height) as f64;
        let mean = channel_sums(low).map(|s| s / n);
        let mut ss = [0f64; 3];
        for p in low.chunks_exact(3) {
            for c in 0..3 {
                let d = p[c] as f64 - mean[c];
                ss[c] += d * d;
            }
        }
        let low_std = ss.map(|s| (s / n).sqrt());

        ImageLoss {
            width,
            height,
            weights,
            params,
            low_hue,
            masked: masked as f64,
            low_gx,
            low_gy,
            low_std,
            low_luma: luma_of(mean),
        }
    }

    /// Width of the images, pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height of the images, pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The loss of `img` (same layout as `I_low`). `grad` (same length) is overwritten
    /// with `d total / d img`, so the caller need not clear it between iterations.
    ///
    /// `img` is not clamped, for the hue either: the gradient describes the function of
    /// the values given. Three passes over the image; the only allocation is two rows of
    /// scratch.
    ///
    /// # Panics
    ///
    /// If `img` or `grad` does not hold `width * height * 3` floats.
    pub fn eval(&self, img: &[f32], grad: &mut [f32]) -> ImageTerms {
        self.eval_f64(img, grad).into()
    }

    /// [`ImageLoss::eval`] with the values left in `f64` (the tests difference them).
    fn eval_f64(&self, img: &[f32], grad: &mut [f32]) -> Terms64 {
        self.eval_parts(img, None, grad)
    }

    /// The loss of `raw` as an 8-bit display shows it: every term is scored on `raw`
    /// clamped to `[0, 1]`, which is written to `shown`, except exposure, which is
    /// scored on `raw` itself.
    ///
    /// The gradient is exact for that function: zero through the clamp for the four
    /// terms that see the clamped image. Exposure sees past the clamp so that an
    /// over-exposed image is pulled back: scored on the clamped image, a fit that
    /// overshoots into white has no gradient left to return with.
    ///
    /// # Panics
    ///
    /// If `raw`, `shown` or `grad` does not hold `width * height * 3` floats.
    pub fn eval_display(&self, raw: &[f32], shown: &mut [f32], grad: &mut [f32]) -> ImageTerms {
        assert_eq!(shown.len(), raw.len(), "ImageLoss::eval_display: shown");
        // One pass clamps and sums the unclamped channels, in `channel_sums`' order.
        let mut sums = [0f64; 3];
        for (r, s) in raw.chunks_exact(3).zip(shown.chunks_exact_mut(3)) {
            for c in 0..3 {
                sums[c] += f64::from(r[c]);
                s[c] = r[c].clamp(0.0, 1.0);
            }
        }
        let t = self.eval_parts(shown, Some(sums), grad);
        for (i, (g, (&r, &c))) in grad
            .iter_mut()
            .zip(raw.iter().zip(shown.iter()))
            .enumerate()
        {
            if r != c {
                *g = sat(t.exposure_slope * LUMA[i % 3]);
            }
        }
        t.into()
    }

    /// [`ImageLoss::eval_f64`], with the exposure term scored on the image whose channel
    /// sums are `exposure_sums`, when given.
    fn eval_parts(
        &self,
        img: &[f32],
        exposure_sums: Option<[f64; 3]>,
        grad: &mut [f32],
    ) -> Terms64 {
        let (w, h) = (self.width, self.height);
        let len = w * h * 3;
        assert_eq!(
            img.len(),
            len,
            "ImageLoss::eval: img has {} floats, expected {len}",
            img.len()
        );
        assert_eq!(
            grad.len(),
            len,
            "ImageLoss::eval: grad has {} floats, expected {len}",
            grad.len()
        );
        let wt = &self.weights;
        let n = (w * h) as f64;
        grad.fill(0.0);

        // Pass 1: channel sums, and the hue term (Eq. 18), which needs no mean.
        let mut sum = [0f64; 3];
        let hue_norm = self.masked + MASK_EPS;
        let hue_scale = wt.hue as f64 / hue_norm;
        let mut hue_sum = 0f64;
        for ((p, g), &hl) in img
            .chunks_exact(3)
            .zip(grad.chunks_exact_mut(3))
            .zip(&self.low_hue)
        {
            let v = [p[0] as f64, p[1] as f64, p[2] as f64];
            sum[0] += v[0];
            sum[1] += v[1];
            sum[2] += v[2];
            // Branch-free: on a textured image the branches would be coin flips.
            let inside = flag(hl >= 0.0);
            let (he, dh) = hue_and_grad(v);
            let (dist, slope) = circular_distance(round32(he) - hl as f64);
            hue_sum += inside * dist;
            let k = inside * hue_scale * slope;
            for c in 0..3 {
                g[c] += (k * dh[c]) as f32;
            }
        }
        let mean = sum.map(|s| s / n);
        let hue = hue_sum / hue_norm;

        // Pass 2, a row at a time: the spatial term (Eq. 21), its adjoint added into
        // `grad`, and the centred sums of squares of the channels and of the opponent
        // colours rg = R − G, yb = (R + G)/2 − B.
        let spatial_scale = (wt.spatial as f64 / (3.0 * n)) as f32;
        // The brightness ratio s that the low image's gradients are scaled by, and
        // ds/d x for a value of channel c (LUMA[c] · ds_dmean); 0 for a black low image.
        let (ratio, ds_dmean) = if self.low_luma > LOW_LUMA_MIN {
            let luma = luma_of(mean);
            (luma / self.low_luma, 1.0 / (n * self.low_luma))
        } else {
            (1.0, 0.0)
        };
        let row = 3 * w;
        let mut gx = vec![0f32; row];
        let mut gy = vec![0f32; row];
        let mut ref_x = vec![0f32; row];
        let mut ref_y = vec![0f32; row];
        // Σ sign · low gradient, for the gradient through the ratio.
        let mut through_ratio = 0f64;
        let (mut abs_x, mut abs_y) = (0f64, 0f64);
        let mut ss = [0f64; 5];
        for y in 0..h {
            let rows = neighbours(y, h);
            let [up, mid, dn] = rows.map(|r| &img[r * row..(r + 1) * row]);
            for p in mid.chunks_exact(3) {
                let d = [0, 1, 2].map(|c| p[c] as f64 - mean[c]);
                let rg = d[0] - d[1];
                let yb = 0.5 * (d[0] + d[1]) - d[2];
                ss[0] += d[0] * d[0];
                ss[1] += d[1] * d[1];
                ss[2] += d[2] * d[2];
                ss[3] += rg * rg;
                ss[4] += yb * yb;
            }
            sobel_row::<3>(up, mid, dn, &mut gx, &mut gy);
            let low_gx = &self.low_gx[y * row..(y + 1) * row];
            let low_gy = &self.low_gy[y * row..(y + 1) * row];
            for (r, l) in ref_x
                .iter_mut()
                .zip(low_gx)
                .chain(ref_y.iter_mut().zip(low_gy))
            {
                *r = (ratio * f64::from(*l)) as f32;
            }
            abs_x += sum_abs_diff(&gx, &ref_x);
            abs_y += sum_abs_diff(&gy, &ref_y);
            if spatial_scale == 0.0 {
                continue;
            }
            // From here gx and gy hold the scaled signs of the differences, and the
            // transposed Sobel taps carry them back to the three rows they came from.
            sign_of_difference(&mut gx, &ref_x, spatial_scale);
            sign_of_difference(&mut gy, &ref_y, spatial_scale);
            through_ratio += gx
                .iter()
                .zip(low_gx)
                .chain(gy.iter().zip(low_gy))
                .map(|(s, l)| f64::from(*s) * f64::from(*l))
                .sum::<f64>();
            let (sx, sy) = (&gx[..], &gy[..]);
            let [rm, r0, rp] = rows.map(|r| r * row..(r + 1) * row);
            adjoint_taps(
                &mut grad[rm],
                sx,
                sy,
                [(-1.0, -1.0), (0.0, -2.0), (1.0, -1.0)],
            );
            adjoint_taps(&mut grad[r0], sx, sy, [(-2.0, 0.0), (0.0, 0.0), (2.0, 0.0)]);
            adjoint_taps(&mut grad[rp], sx, sy, [(-1.0, 1.0), (0.0, 2.0), (1.0, 1.0)]);
        }
        let spatial = (abs_x + abs_y) / (3.0 * n);

        // Exposure (Eq. 17): the mean luma is the luma of the channel means.
        let p = &self.params;
        let exposure_mean = exposure_sums.map_or(mean, |s| s.map(|s| s / n));
        let luma = luma_of(exposure_mean);
        let off = luma - p.exposure_target as f64;
        let exposure = off * off;
        let k_exposure = wt.exposure as f64 * 2.0 * off / n;

        // Colour richness (Eq. 19): d/d rg_p of −√(σ_rg² + σ_yb² + ε) is −(rg_p − μ)/(N·S).
        let spread = ((ss[3] + ss[4]) / n + COLOUR_EPS).sqrt();
        let colour = -spread;
        let k_colour = -(wt.colour as f64) / (n * spread);

        // Contrast (Eq. 20): a hinge per channel; dσ/dx_p = (x_p − μ)/(N·σ).
        let gamma = p.contrast_gamma as f64;
        let mut contrast = 0f64;
        let mut k_contrast = [0f64; 3];
        for c in 0..3 {
            let std = (ss[c] / n + STD_EPS).sqrt();
            let gap = gamma * self.low_std[c] - std;
            if gap > 0.0 {
                contrast += gap / 3.0;
                k_contrast[c] = -(wt.contrast as f64) / (3.0 * n * std);
            }
        }

        // Pass 3: the three terms above are linear in the centred pixel.
        let k_ratio = -through_ratio * ds_dmean;
        let base = LUMA.map(|l| (k_exposure + k_ratio) * l);
        for (p, g) in img.chunks_exact(3).zip(grad.chunks_exact_mut(3)) {
            let d = [0, 1, 2].map(|c| p[c] as f64 - mean[c]);
            let rg = k_colour * (d[0] - d[1]);
            let yb = k_colour * (0.5 * (d[0] + d[1]) - d[2]);
            let add = [
                base[0] + rg + 0.5 * yb + k_contrast[0] * d[0],
                base[1] - rg + 0.5 * yb + k_contrast[1] * d[1],
                base[2] - yb + k_contrast[2] * d[2],
            ];
            for c in 0..3 {
                g[c] = sat(g[c] as f64 + add[c]);
            }
        }

        let total = wt.exposure as f64 * exposure
            + wt.hue as f64 * hue
            + wt.spatial as f64 * spatial
            + wt.colour as f64 * colour
            + wt.contrast as f64 * contrast;
        Terms64 {
            exposure_slope: k_exposure,
            exposure,
            hue,
            spatial,
            colour,
            contrast,
            total,
        }
    }
}

/// Unweighted values of the two weight-map regularizers of Eq. 22.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MapTerms {
    /// Mean `|Δ|` over horizontally adjacent logits plus the same over vertically
    /// adjacent ones.
    pub tv: f32,
    /// Mean over cells of the Shannon entropy (nats) of the cell's softmax weights.
    pub entropy: f32,
}

/// TV and entropy (Eq. 22) of a weight map of logits `m`: `map_h × map_w` cells, row-major,
/// `k` logits per cell, `k` innermost.
///
/// TV is the mean of `|m[y][x+1][j] − m[y][x][j]|` over all horizontal neighbour pairs and
/// all `j`, plus the same mean over vertical pairs; a direction with no pairs (a map one
/// cell wide or tall) contributes 0. It keeps neighbouring cells choosing alike, so the
/// enhancement has no seams. Entropy is the mean over cells of `−Σ_j w_j ln(w_j + ε)`, `w`
/// the softmax of the cell's logits (computed stably); weighted positively it pushes each
/// cell towards one operator.
///
/// Adds `weights.tv · d tv/dm + weights.entropy · d entropy/dm` into `grad`, so the caller
/// can accumulate it onto the gradient of the image terms.
///
/// # Panics
///
/// If `m.len()` or `grad.len()` is not `map_w * map_h * k`.
pub fn map_regularizers(
    m: &[f32],
    map_w: usize,
    map_h: usize,
    k: usize,
    weights: &LossWeights,
    grad: &mut [f32],
) -> MapTerms {
    let (tv, entropy) = map_terms_f64(m, map_w, map_h, k, weights, grad);
    MapTerms {
        tv: sat(tv),
        entropy: sat(entropy),
    }
}

/// [`map_regularizers`] with the values left in `f64` (the tests difference them).
fn map_terms_f64(
    m: &[f32],
    map_w: usize,
    map_h: usize,
    k: usize,
    weights: &LossWeights,
    grad: &mut [f32],
) -> (f64, f64) {
    let len = map_w
        .checked_mul(map_h)
        .and_then(|c| c.checked_mul(k))
        .expect("map_regularizers: map size overflows usize");
    assert_eq!(
        m.len(),
        len,
        "map_regularizers: m has {} floats, {map_w}×{map_h}×{k} needs {len}",
        m.len()
    );
    assert_eq!(
        grad.len(),
        len,
        "map_regularizers: grad has {} floats, expected {len}",
        grad.len()
    );

    // TV: pairs at a distance of one cell (k floats) within a row, and of one row.
    let mut tv = 0f64;
    let row = map_w * k;
    let horizontal = map_h * map_w.saturating_sub(1) * k;
    if horizontal > 0 {
        let scale = weights.tv as f64 / horizontal as f64;
        let mut sum = 0f64;
        for y in 0..map_h {
            for i in y * row..(y + 1) * row - k {
                sum += tv_pair(m, grad, i, i + k, scale);
            }
        }
        tv += sum / horizontal as f64;
    }
    let vertical = map_h.saturating_sub(1) * row;
    if vertical > 0 {
        let scale = weights.tv as f64 / vertical as f64;
        let mut sum = 0f64;
        for i in 0..vertical {
            sum += tv_pair(m, grad, i, i + row, scale);
        }
        tv += sum / vertical as f64;
    }

    // Entropy, through the softmax: with g_j = dH/dw_j, dH/dm_i = w_i (g_i − Σ_j w_j g_j).
    let cells = map_w * map_h;
    let mut entropy = 0f64;
    if cells > 0 && k > 0 {
        let scale = weights.entropy as f64 / cells as f64;
        let mut w = vec![0f64; k];
        let mut dh = vec![0f64; k];
        let mut sum = 0f64;
        for (logits, g) in m.chunks_exact(k).zip(grad.chunks_exact_mut(k)) {
            let top = logits
                .iter()
                .fold(f64::NEG_INFINITY, |a, &v| a.max(v as f64));
            let mut z = 0f64;
            for (wj, &v) in w.iter_mut().zip(logits) {
                *wj = (v as f64 - top).exp();
                z += *wj;
            }
            let (mut cell, mut mean_dh) = (0f64, 0f64);
            for (wj, dj) in w.iter_mut().zip(dh.iter_mut()) {
                *wj /= z;
                let ln = (*wj + LOG_EPS).ln();
                cell -= *wj * ln;
                *dj = -ln - *wj / (*wj + LOG_EPS);
                mean_dh += *wj * *dj;
            }
            sum += cell;
            for ((gj, &wj), &dj) in g.iter_mut().zip(&w).zip(&dh) {
                *gj += (scale * wj * (dj - mean_dh)) as f32;
            }
        }
        entropy = sum / cells as f64;
    }
    (tv, entropy)
}

/// `|m[b] − m[a]|`, adding `scale · d|·|/dm` into `grad`.
#[inline]
fn tv_pair(m: &[f32], grad: &mut [f32], a: usize, b: usize, scale: f64) -> f64 {
    let d = m[b] as f64 - m[a] as f64;
    let g = (sign(d) * scale) as f32;
    grad[b] += g;
    grad[a] -= g;
    d.abs()
}

/// Floats in a `width × height` RGB image.
fn image_len(width: usize, height: usize) -> usize {
    width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(3))
        .expect("ImageLoss: image size overflows usize")
}

fn channel_sums(img: &[f32]) -> [f64; 3] {
    img.chunks_exact(3).fold([0f64; 3], |mut s, p| {
        s[0] += p[0] as f64;
        s[1] += p[1] as f64;
        s[2] += p[2] as f64;
        s
    })
}

/// The indices before, at and after `i` in `0..n`, the edge replicated.
#[inline]
fn neighbours(i: usize, n: usize) -> [usize; 3] {
    [i.saturating_sub(1), i, (i + 1).min(n - 1)]
}

/// `Σ |a_i − b_i|`, in `f64`, with four partial sums so the loop vectorizes.
fn sum_abs_diff(a: &[f32], b: &[f32]) -> f64 {
    let mut acc = [0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(&x, &y)| (x as f64 - y as f64).abs())
        .sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..4 {
            acc[l] += (x[l] as f64 - y[l] as f64).abs();
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Replaces each `a_i` by `scale · sign(a_i − b_i)` (0 where equal: the subgradient of
/// `|x|` at 0).
fn sign_of_difference(a: &mut [f32], b: &[f32], scale: f32) {
    for (x, &y) in a.iter_mut().zip(b) {
        *x = if *x > y {
            scale
        } else if *x < y {
            -scale
        } else {
            0.0
        };
    }
}

/// Adds into one row of `grad` what the Sobel responses of one output row owe it:
/// `taps[t] = (kx, ky)` weighs `sx` and `sy` for the column to the left (`t = 0`), the
/// same column (`t = 1`) and the column to the right (`t = 2`) of each output pixel. An
/// edge pixel's missing neighbour is the pixel itself, which therefore receives both its
/// own tap and the missing one.
fn adjoint_taps(grad: &mut [f32], sx: &[f32], sy: &[f32], taps: [(f32, f32); 3]) {
    let n = grad.len();
    let add = |g: &mut [f32], sx: &[f32], sy: &[f32], (kx, ky): (f32, f32)| {
        if kx == 0.0 && ky == 0.0 {
            return;
        }
        for ((g, &x), &y) in g.iter_mut().zip(sx).zip(sy) {
            *g += kx * x + ky * y;
        }
    };
    // Left neighbour: output j reads j − 3, or j itself on the first pixel.
    add(&mut grad[..3], &sx[..3], &sy[..3], taps[0]);
    add(&mut grad[..n - 3], &sx[3..], &sy[3..], taps[0]);
    add(grad, sx, sy, taps[1]);
    // Right neighbour: output j reads j + 3, or j itself on the last pixel.
    add(&mut grad[3..], &sx[..n - 3], &sy[..n - 3], taps[2]);
    add(&mut grad[n - 3..], &sx[n - 3..], &sy[n - 3..], taps[2]);
}

/// HSV hue of `p` in turns, in `[0, 1)`, and its gradient with respect to `p`, the
/// largest channel (ties to R, then G) held fixed; `(0, 0)` where the chroma is at most
/// [`HUE_EPS`].
///
/// With `a` the largest channel and `(x, y)` the other two in the order of the HSV
/// formula, `h = ((x − y)/d + offset)/6` where `d = max − min`. Written without
/// branches (selections are products with 0/1 flags), since on textured images which
/// channel is largest is unpredictable from one pixel to the next.
#[inline]
fn hue_and_grad(p: [f64; 3]) -> (f64, [f64; 3]) {
    let [r, g, b] = p;
    let is_r = (r >= g) & (r >= b);
    let is_g = !is_r & (g >= b);
    let (fr, fg) = (flag(is_r), flag(is_g));
    let fb = 1.0 - fr - fg;
    let top = fr * r + fg * g + fb * b;
    let x = fr * g + fg * b + fb * r;
    let y = fr * b + fg * r + fb * g;
    let offset = 2.0 * fg + 4.0 * fb;
    let d = top - x.min(y);
    let defined = flag(d > HUE_EPS);
    let inv = 1.0 / d.max(HUE_EPS);
    let q = (x - y) * inv;
    let mut h = (q + offset) * (1.0 / 6.0);
    h += flag(h < 0.0);
    h -= flag(h >= 1.0);
    // dq = (dx − dy)/d − q (da − dmin)/d. When x and y tie for the minimum q = 0, so
    // which of them is called the minimum does not matter.
    let s = defined * inv * (1.0 / 6.0);
    let x_min = flag(x <= y);
    let dx = s * (1.0 + q * x_min);
    let dy = s * (-1.0 + q * (1.0 - x_min));
    let da = -q * s;
    let grad = [
        fr * da + fg * dy + fb * dx,
        fr * dx + fg * da + fb * dy,
        fr * dy + fg * dx + fb * da,
    ];
    (defined * h, grad)
}

/// Distance between two hues `Δ` turns apart, the shorter way round the circle, and
/// its derivative with respect to `Δ` (0 where the two ways are equally long).
#[inline]
fn circular_distance(delta: f64) -> (f64, f64) {
    let a = delta.abs();
    let b = 1.0 - a;
    let way = flag(a < b) - flag(a > b);
    (a.min(b), way * sign(delta))
}

/// 1 or 0.
#[inline(always)]
fn flag(b: bool) -> f64 {
    b as u8 as f64
}

/// Sign of `x`, 0 at 0 (the subgradient of `|x|` used throughout).
#[inline]
fn sign(x: f64) -> f64 {
    flag(x > 0.0) - flag(x < 0.0)
}

/// `x` as `f32`, saturating at `±f32::MAX` instead of overflowing to infinity.
#[inline]
fn sat(x: f64) -> f32 {
    x.clamp(-(f32::MAX as f64), f32::MAX as f64) as f32
}

/// `x` rounded to `f32` (saturating) and back. Values of `I_e` compared with stored
/// values of `I_low` go through the same rounding, so `I_e = I_low` compares equal.
#[inline]
fn round32(x: f64) -> f64 {
    sat(x) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SplitMix64: a tiny deterministic generator, so the tests need no crate.
    /// SplitMix64 with the two draws these tests need (53-bit uniforms, indices).
    struct Rng(gsi_optim::rng::SplitMix64);

    impl Rng {
        fn new(seed: u64) -> Rng {
            Rng(gsi_optim::rng::SplitMix64::new(seed))
        }

        fn next(&mut self) -> u64 {
            self.0.next_u64()
        }

        /// Uniform in `[lo, hi)`.
        fn range(&mut self, lo: f64, hi: f64) -> f32 {
            let u = (self.next() >> 11) as f64 / (1u64 << 53) as f64;
            (lo + (hi - lo) * u) as f32
        }

        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }
    }

    const W: usize = 9;
    const H: usize = 7;

    fn zero_weights() -> LossWeights {
        LossWeights {
            exposure: 0.0,
            hue: 0.0,
            spatial: 0.0,
            colour: 0.0,
            contrast: 0.0,
            tv: 0.0,
            entropy: 0.0,
        }
    }

    /// A random `img` in (0.05, 0.95) and `low = 0.2 · img + noise`: the setting of an
    /// enhancement that brightened the input.
    fn brightened(rng: &mut Rng) -> (Vec<f32>, Vec<f32>) {
        let img: Vec<f32> = (0..W * H * 3).map(|_| rng.range(0.05, 0.95)).collect();
        let low = img
            .iter()
            .map(|&v| 0.2 * v + rng.range(0.0, 0.03))
            .collect();
        (img, low)
    }

    /// A high-contrast `low` and a flatter `img`, so the contrast hinge is active in
    /// every channel.
    fn flattened(rng: &mut Rng) -> (Vec<f32>, Vec<f32>) {
        let low = (0..W * H * 3).map(|_| rng.range(0.05, 0.95)).collect();
        let img = (0..W * H * 3).map(|_| rng.range(0.35, 0.65)).collect();
        (img, low)
    }

    /// Whether a term is smooth, or piecewise smooth with kinks a probe may straddle.
    #[derive(Clone, Copy, PartialEq)]
    enum Shape {
        Smooth,
        Kinked,
    }

    /// Checks `grad` of `f` at `x` against central differences (step 1e-3, values in
    /// `f64`) on `probes` random components: `|analytic − fd| ≤ 2e-2 · max(|analytic|,
    /// |fd|) + 1e-3 · max_i |grad_i|`. For a [`Shape::Kinked`] term, a component whose
    /// forward and backward differences disagree beyond that bound has a kink within the
    /// step and is skipped, but at least three quarters must be checked.
    fn check_fd(
        x: &[f32],
        grad: &[f32],
        shape: Shape,
        probes: usize,
        rng: &mut Rng,
        mut f: impl FnMut(&[f32]) -> f64,
    ) {
        const STEP: f32 = 1e-3;
        let largest = grad.iter().fold(0f64, |a, &g| a.max((g as f64).abs()));
        assert!(
            largest > 0.0,
            "the gradient is identically 0: nothing to check"
        );
        let floor = 1e-3 * largest;
        let mut x = x.to_vec();
        let mut checked = 0;
        for _ in 0..probes {
            let i = rng.below(x.len());
            let x0 = x[i];
            let (up, down) = (x0 + STEP, x0 - STEP);
            let l0 = f(&x);
            x[i] = up;
            let lu = f(&x);
            x[i] = down;
            let ld = f(&x);
            x[i] = x0;
            let (hu, hd) = ((up - x0) as f64, (x0 - down) as f64);
            let (fwd, bwd) = ((lu - l0) / hu, (l0 - ld) / hd);
            if shape == Shape::Kinked && (fwd - bwd).abs() > 2e-2 * fwd.abs().max(bwd.abs()) + floor
            {
                continue;
            }
            let fd = (lu - ld) / (hu + hd);
            let a = grad[i] as f64;
            assert!(
                (a - fd).abs() <= 2e-2 * a.abs().max(fd.abs()) + floor,
                "component {i}: analytic {a:e}, finite difference {fd:e}"
            );
            checked += 1;
        }
        assert!(
            checked * 4 >= probes * 3,
            "only {checked} of {probes} components were free of kinks"
        );
    }

    fn check_image_term(
        weights: LossWeights,
        shape: Shape,
        setting: fn(&mut Rng) -> (Vec<f32>, Vec<f32>),
    ) {
        let mut rng = Rng::new(0x5eed);
        for _ in 0..3 {
            let (img, low) = setting(&mut rng);
            let loss = ImageLoss::new(&low, W, H, weights, LossParams::default());
            let mut grad = vec![f32::NAN; img.len()];
            loss.eval(&img, &mut grad);
            let mut scratch = vec![0f32; img.len()];
            check_fd(&img, &grad, shape, 40, &mut rng, |x| {
                loss.eval_f64(x, &mut scratch).total
            });
        }
    }

    #[test]
    fn exposure_gradient_matches_finite_differences() {
        let weights = LossWeights {
            exposure: 50.0,
            ..zero_weights()
        };
        check_image_term(weights, Shape::Smooth, brightened);
    }

    #[test]
    fn hue_gradient_matches_finite_differences() {
        let weights = LossWeights {
            hue: 25.0,
            ..zero_weights()
        };
        check_image_term(weights, Shape::Kinked, brightened);
        // Hues far apart, so some pixels take the way round through 0.
        check_image_term(weights, Shape::Kinked, flattened);
    }

    #[test]
    fn spatial_gradient_matches_finite_differences() {
        let weights = LossWeights {
            spatial: 32.5,
            ..zero_weights()
        };
        check_image_term(weights, Shape::Kinked, brightened);
    }

    #[test]
    fn colour_gradient_matches_finite_differences() {
        let weights = LossWeights {
            colour: 2.91,
            ..zero_weights()
        };
        check_image_term(weights, Shape::Smooth, brightened);
    }

    #[test]
    fn contrast_gradient_matches_finite_differences() {
        let weights = LossWeights {
            contrast: 0.44,
            ..zero_weights()
        };
        check_image_term(weights, Shape::Smooth, flattened);
    }

    #[test]
    fn total_gradient_matches_finite_differences() {
        check_image_term(LossWeights::default(), Shape::Kinked, brightened);
        check_image_term(LossWeights::default(), Shape::Kinked, flattened);
    }

    #[test]
    fn border_pixels_get_every_sobel_tap() {
        // On a 2×2 image every tap of every pixel is clamped: the adjoint must still
        // match finite differences.
        let mut rng = Rng::new(7);
        let weights = LossWeights {
            spatial: 1.0,
            ..zero_weights()
        };
        for (w, h) in [(2, 2), (1, 3), (3, 1)] {
            let img: Vec<f32> = (0..w * h * 3).map(|_| rng.range(0.05, 0.95)).collect();
            let low: Vec<f32> = (0..w * h * 3).map(|_| rng.range(0.0, 0.2)).collect();
            let loss = ImageLoss::new(&low, w, h, weights, LossParams::default());
            let mut grad = vec![0f32; img.len()];
            loss.eval(&img, &mut grad);
            let mut scratch = vec![0f32; img.len()];
            check_fd(&img, &grad, Shape::Kinked, 24, &mut rng, |x| {
                loss.eval_f64(x, &mut scratch).total
            });
        }
    }

    fn random_map(rng: &mut Rng) -> Vec<f32> {
        (0..5 * 4 * 6).map(|_| rng.range(-2.0, 2.0)).collect()
    }

    fn check_map_term(weights: LossWeights, shape: Shape) {
        let mut rng = Rng::new(0xc0ffee);
        for _ in 0..3 {
            let m = random_map(&mut rng);
            let mut grad = vec![0f32; m.len()];
            map_regularizers(&m, 5, 4, 6, &weights, &mut grad);
            let mut scratch = vec![0f32; m.len()];
            check_fd(&m, &grad, shape, 40, &mut rng, |x| {
                let (tv, entropy) = map_terms_f64(x, 5, 4, 6, &weights, &mut scratch);
                weights.tv as f64 * tv + weights.entropy as f64 * entropy
            });
        }
    }

    #[test]
    fn tv_gradient_matches_finite_differences() {
        check_map_term(
            LossWeights {
                tv: 500.0,
                ..zero_weights()
            },
            Shape::Kinked,
        );
    }

    #[test]
    fn entropy_gradient_matches_finite_differences() {
        check_map_term(
            LossWeights {
                entropy: 1.0,
                ..zero_weights()
            },
            Shape::Smooth,
        );
    }

    #[test]
    fn map_regularizers_add_into_grad() {
        let mut rng = Rng::new(3);
        let m = random_map(&mut rng);
        let weights = LossWeights::default();
        let mut fresh = vec![0f32; m.len()];
        map_regularizers(&m, 5, 4, 6, &weights, &mut fresh);
        let mut added = vec![1f32; m.len()];
        map_regularizers(&m, 5, 4, 6, &weights, &mut added);
        for (a, f) in added.iter().zip(&fresh) {
            assert!(
                (a - 1.0 - f).abs() <= 1e-6 * (1.0 + f.abs()),
                "{a} vs 1 + {f}"
            );
        }
    }

    #[test]
    fn eval_overwrites_grad() {
        let mut rng = Rng::new(4);
        let (img, low) = brightened(&mut rng);
        let loss = ImageLoss::new(&low, W, H, LossWeights::default(), LossParams::default());
        let mut clean = vec![0f32; img.len()];
        let mut dirty = vec![123f32; img.len()];
        assert_eq!(loss.eval(&img, &mut clean), loss.eval(&img, &mut dirty));
        assert_eq!(clean, dirty);
    }

    #[test]
    fn exposure_of_a_constant_image_is_exact() {
        let (r, g, b) = (0.3f32, 0.5f32, 0.2f32);
        let img: Vec<f32> = [r, g, b].repeat(4 * 3);
        let low = vec![0.01f32; img.len()];
        let weights = LossWeights::default();
        let loss = ImageLoss::new(&low, 4, 3, weights, LossParams::default());
        let mut grad = vec![0f32; img.len()];
        let terms = loss.eval(&img, &mut grad);
        let luma = LUMA[0] * r as f64 + LUMA[1] * g as f64 + LUMA[2] * b as f64;
        let off = luma - LossParams::default().exposure_target as f64;
        assert_eq!(terms.exposure, (off * off) as f32);
    }

    #[test]
    fn hue_is_standard_hsv() {
        let cases = [
            ([1.0, 0.0, 0.0], 0.0),
            ([1.0, 1.0, 0.0], 1.0 / 6.0),
            ([0.0, 1.0, 0.0], 2.0 / 6.0),
            ([0.0, 1.0, 1.0], 3.0 / 6.0),
            ([0.0, 0.0, 1.0], 4.0 / 6.0),
            ([1.0, 0.0, 1.0], 5.0 / 6.0),
            ([1.0, 0.0, 0.5], 11.0 / 12.0),
            ([0.5, 0.5, 0.5], 0.0),
        ];
        for (p, want) in cases {
            let (h, _) = hue_and_grad(p);
            assert!((h - want).abs() < 1e-12, "{p:?}: {h} instead of {want}");
        }
    }

    #[test]
    fn circular_distance_takes_the_short_way() {
        assert_eq!(circular_distance(0.1), (0.1, 1.0));
        assert_eq!(circular_distance(-0.1), (0.1, -1.0));
        assert_eq!(circular_distance(-0.75), (0.25, 1.0));
        assert_eq!(circular_distance(0.75), (0.25, -1.0));
        assert_eq!(circular_distance(0.5), (0.5, 0.0));
        assert_eq!(circular_distance(0.0), (0.0, 0.0));
    }

    #[test]
    fn low_itself_has_no_hue_or_spatial_loss() {
        let mut rng = Rng::new(5);
        let (_, low) = brightened(&mut rng);
        let loss = ImageLoss::new(&low, W, H, LossWeights::default(), LossParams::default());
        assert!(loss.masked > 0.0);
        let mut grad = vec![0f32; low.len()];
        let terms = loss.eval(&low, &mut grad);
        assert_eq!(terms.hue, 0.0);
        assert_eq!(terms.spatial, 0.0);
        // Also outside [0, 1], where only the hue sees a clamped I_low.
        let wild: Vec<f32> = (0..W * H * 3).map(|_| rng.range(-3.0, 5.0)).collect();
        let loss = ImageLoss::new(&wild, W, H, LossWeights::default(), LossParams::default());
        assert_eq!(loss.eval(&wild, &mut grad).spatial, 0.0);
    }

    #[test]
    fn contrast_vanishes_at_twice_low() {
        let mut rng = Rng::new(6);
        let (_, low) = brightened(&mut rng);
        let img: Vec<f32> = low.iter().map(|v| 2.0 * v).collect();
        let loss = ImageLoss::new(&low, W, H, LossWeights::default(), LossParams::default());
        let mut grad = vec![0f32; img.len()];
        assert_eq!(loss.eval(&img, &mut grad).contrast, 0.0);
        // And is positive at half of it.
        let img: Vec<f32> = low.iter().map(|v| 0.5 * v).collect();
        assert!(loss.eval(&img, &mut grad).contrast > 0.0);
    }

    #[test]
    fn colour_of_a_grey_image_is_minus_sqrt_eps() {
        let mut rng = Rng::new(8);
        let img: Vec<f32> = (0..W * H).flat_map(|_| [rng.range(0.0, 1.0); 3]).collect();
        let loss = ImageLoss::new(&img, W, H, LossWeights::default(), LossParams::default());
        let mut grad = vec![0f32; img.len()];
        let colour = loss.eval(&img, &mut grad).colour;
        assert!((colour + 1e-4).abs() < 1e-9, "{colour}");
    }

    #[test]
    fn entropy_of_a_uniform_map_is_ln_k() {
        let weights = LossWeights::default();
        for k in [1, 2, 6] {
            let m = vec![0.37f32; 5 * 4 * k];
            let mut grad = vec![0f32; m.len()];
            let t = map_regularizers(&m, 5, 4, k, &weights, &mut grad);
            assert!(
                (t.entropy - (k as f32).ln()).abs() < 1e-6,
                "K = {k}: {}",
                t.entropy
            );
            assert_eq!(t.tv, 0.0);
            // The uniform cell is a stationary point of both terms.
            assert!(grad.iter().all(|g| g.abs() < 1e-6), "{grad:?}");
        }
    }

    #[test]
    fn tv_counts_pairs_in_each_direction() {
        // One row of 3 cells, K = 2: horizontal pairs only, mean |Δ| = (1 + 2 + 3 + 4)/4.
        let m = [0.0, 0.0, 1.0, 2.0, 4.0, 6.0];
        let mut grad = [0f32; 6];
        let t = map_regularizers(&m, 3, 1, 2, &zero_weights(), &mut grad);
        assert_eq!(t.tv, 2.5);
        // Transposed: the same pairs, now vertical.
        let t = map_regularizers(&m, 1, 3, 2, &zero_weights(), &mut grad);
        assert_eq!(t.tv, 2.5);
        assert_eq!(grad, [0.0; 6]);
    }

    fn assert_image_finite(img: &[f32], low: &[f32], w: usize, h: usize) {
        let loss = ImageLoss::new(low, w, h, LossWeights::default(), LossParams::default());
        let mut grad = vec![0f32; img.len()];
        let t = loss.eval(img, &mut grad);
        let values = [t.exposure, t.hue, t.spatial, t.colour, t.contrast, t.total];
        assert!(values.iter().all(|v| v.is_finite()), "{w}×{h}: {t:?}");
        assert!(grad.iter().all(|g| g.is_finite()), "{w}×{h}: {grad:?}");
    }

    #[test]
    fn degenerate_images_stay_finite() {
        let mut rng = Rng::new(9);
        for (w, h) in [(1, 1), (2, 1), (1, 2), (1, 5), (5, 1), (3, 3), (W, H)] {
            let n = w * h * 3;
            let random =
                |rng: &mut Rng, lo, hi| -> Vec<f32> { (0..n).map(|_| rng.range(lo, hi)).collect() };
            let black = vec![0f32; n];
            let white = vec![1f32; n];
            let wild: Vec<f32> = (0..n)
                .map(|i| if i % 2 == 0 { -3.0 } else { 5.0 })
                .collect();
            let huge: Vec<f32> = (0..n)
                .map(|i| if i % 3 == 0 { -f32::MAX } else { f32::MAX })
                .collect();
            let tiny = vec![f32::MIN_POSITIVE / 4.0; n];
            let dark = random(&mut rng, 0.0, 0.1);
            let outside = random(&mut rng, -3.0, 5.0);
            let images = [&black, &white, &wild, &huge, &tiny, &dark, &outside];
            for img in images {
                for low in images {
                    assert_image_finite(img, low, w, h);
                }
            }
        }
    }

    #[test]
    fn degenerate_maps_stay_finite() {
        let weights = LossWeights::default();
        let mut rng = Rng::new(10);
        for (w, h, k) in [
            (1, 1, 1),
            (1, 1, 4),
            (1, 5, 3),
            (5, 1, 3),
            (0, 3, 2),
            (2, 2, 0),
        ] {
            let n = w * h * k;
            let maps = [
                vec![0f32; n],
                (0..n).map(|_| rng.range(-50.0, 50.0)).collect(),
                (0..n)
                    .map(|i| if i % 2 == 0 { f32::MAX } else { -f32::MAX })
                    .collect::<Vec<_>>(),
            ];
            for m in maps {
                let mut grad = vec![0f32; n];
                let t = map_regularizers(&m, w, h, k, &weights, &mut grad);
                assert!(
                    t.tv.is_finite() && t.entropy.is_finite(),
                    "{w}×{h}×{k}: {t:?}"
                );
                assert!(grad.iter().all(|g| g.is_finite()), "{w}×{h}×{k}: {grad:?}");
            }
        }
    }

    #[test]
    #[should_panic(expected = "needs")]
    fn new_rejects_a_wrong_length() {
        ImageLoss::new(
            &[0.0; 5],
            1,
            2,
            LossWeights::default(),
            LossParams::default(),
        );
    }

    #[test]
    #[should_panic(expected = "empty")]
    fn new_rejects_an_empty_image() {
        ImageLoss::new(&[], 0, 2, LossWeights::default(), LossParams::default());
    }

    #[test]
    #[should_panic(expected = "grad has")]
    fn eval_rejects_a_wrong_grad() {
        let loss = ImageLoss::new(
            &[0.0; 6],
            2,
            1,
            LossWeights::default(),
            LossParams::default(),
        );
        loss.eval(&[0.0; 6], &mut [0.0; 3]);
    }
}
