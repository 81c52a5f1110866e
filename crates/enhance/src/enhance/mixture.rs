//! The enhancer as stored: a weight map over the image and a mixture of colour operators
//! (paper Eq. 13–15). Applying it needs no rendering and no features, only each
//! Gaussian's centre and colour, which is what makes in-container enhancement cheap.

use gsi_format::format::{tensor_sizes, Attribute, EnhancerRecord, FitSettings, TENSORS};
use gsi_format::model::Blend;

/// Most bits of each stored weight-map logit.
pub const MAP_BITS: u8 = 10;
/// The step a stored logit is kept to: a change of 1/64 moves a mixing weight by under
/// 1.6 % of itself. The bits follow the map's range (at most [`MAP_BITS`]), so that a
/// map that varies little costs little.
pub const MAP_STEP: f32 = 1.0 / 64.0;
/// Bits of each stored operator parameter.
pub const PARAM_BITS: u8 = 12;
/// Largest log-gain of an operator (a gain of e^8 ≈ 3000 takes any visible colour past
/// the clamp); keeps `exp` finite for any stored parameters.
pub const GAIN_LOG_MAX: f32 = 8.0;

/// A fitted (or loaded) enhancer in the numbers it computes with.
#[derive(Clone, Debug, PartialEq)]
pub struct Enhancer {
    /// K: operator 0 is the identity, operators 1..K are residual MLPs.
    pub experts: usize,
    /// Width of both hidden layers of each MLP.
    pub hidden: usize,
    /// Every MLP operator's output is clamped to this range (paper Eq. 14).
    pub clamp: [f32; 2],
    pub map_width: usize,
    pub map_height: usize,
    /// Mixing logits, `map_height × map_width × K`, K innermost.
    pub map: Vec<f32>,
    /// Parameters of operators 1..K, [`Enhancer::params_per_operator`] each, laid out
    /// `W1 (hidden×3), b1, W2 (hidden×hidden), b2, W3 (1×hidden), b3 (1)`.
    pub params: Vec<f32>,
}

/// Where each Gaussian reads the weight map: four cells and their bilinear weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapTap {
    pub cells: [u32; 4],
    pub weights: [f32; 4],
}

/// The operator clamp for a blend mode. In `alpha` blending a colour record is a
/// displayable colour, so the paper's `[0, 1]` applies. In `sum` blending records are
/// coefficients that overlapping Gaussians add up, negative ones included (they carve
/// detail), so clamping them to `[0, 1]` would erase detail: the range is widened by the
/// margin a brightened coefficient needs.
pub fn clamp_for(blend: Blend) -> [f32; 2] {
    match blend {
        Blend::Alpha => [0.0, 1.0],
        Blend::Sum => [-2.0, 3.0],
    }
}

impl Enhancer {
    pub fn params_per_operator(hidden: usize) -> usize {
        tensor_sizes(hidden).iter().sum()
    }

    /// The bilinear tap of the weight map at a normalized position. Cell `(x, y)` covers
    /// `[x/W', (x+1)/W') × [y/H', (y+1)/H')` and holds the value at its centre; outside
    /// the centres the map is extended flat.
    pub fn tap(&self, pos: [f32; 2]) -> MapTap {
        tap(self.map_width, self.map_height, pos)
    }

    /// Mixing weights `w` (K values summing to 1) at a tap: softmax of the interpolated logits.
    pub fn weights_at(&self, t: &MapTap, w: &mut [f32]) {
        let k = self.experts;
        w.fill(0.0);
        for (&cell, &b) in t.cells.iter().zip(&t.weights) {
            let logits = &self.map[cell as usize * k..][..k];
            for (o, &l) in w.iter_mut().zip(logits) {
                *o += b * l;
            }
        }
        softmax_in_place(w);
    }

    /// Operator `op` (1..K) applied to colour `c`, with the pre-activations the fitter
    /// needs (each `hidden` long) written to `h1`, `h2`. Returns `(output, unclamped)`.
    ///
    /// The residual is a gain shared by the three channels, `Φ(c) = clamp(c·exp(η(c)))`
    /// with `η: R³ → R` (the identity at `η = 0`), rather than the offset `c + η(c)` of
    /// the paper's Eq. 14. With an offset, the exposure and spatial losses
    /// are both satisfied by adding a constant (the Sobel gradients do not change), and
    /// the fit drifts to a flat, washed-out image tinted green (the channel with the
    /// largest luma weight grows fastest). A gain keeps black black and edges in place,
    /// as every tone curve of low-light enhancement does, so brightening must be paid for
    /// in the spatial term and the fit settles on a real compromise. The gain is an
    /// exponential so that it stays positive: a linear gain `1 + η` can pass through
    /// zero, and the fit then found it cheaper to zero two channels than to brighten
    /// three (a saturated green image). The gain is shared by the channels because
    /// per-channel gains drift the same way: the exposure term pulls hardest on green
    /// (the largest luma weight) and the hue term, saturated once a hue has turned,
    /// cannot pull it back. A shared gain preserves hue by construction; the operator
    /// still decides it from the whole colour, and the mixture varies it over the image.
    pub fn operator(
        &self,
        op: usize,
        c: [f32; 3],
        h1: &mut [f32],
        h2: &mut [f32],
    ) -> ([f32; 3], [f32; 3]) {
        let h = self.hidden;
        let p =
            &self.params[(op - 1) * Self::params_per_operator(h)..][..Self::params_per_operator(h)];
        let (w1, p) = p.split_at(3 * h);
        let (b1, p) = p.split_at(h);
        let (w2, p) = p.split_at(h * h);
        let (b2, p) = p.split_at(h);
        let (w3, b3) = p.split_at(h);
        for j in 0..h {
            let r = &w1[3 * j..3 * j + 3];
            h1[j] = b1[j] + r[0] * c[0] + r[1] * c[1] + r[2] * c[2];
        }
        for j in 0..h {
            let r = &w2[h * j..h * (j + 1)];
            h2[j] = b2[j]
                + r.iter()
                    .zip(&*h1)
                    .map(|(a, &x)| a * x.max(0.0))
                    .sum::<f32>();
        }
        let eta = b3[0]
            + w3.iter()
                .zip(&*h2)
                .map(|(a, &x)| a * x.max(0.0))
                .sum::<f32>();
        // exp(η) > 0: a gain that can darken but never flip a colour's sign.
        let gain = eta.min(GAIN_LOG_MAX).exp();
        let raw = c.map(|x| x * gain);
        let [lo, hi] = self.clamp;
        // `max` then `min` also maps NaN to `lo`, so no operator output is ever NaN.
        (raw.map(|x| x.max(lo).min(hi)), raw)
    }

    /// The enhanced colour of one Gaussian (paper Eq. 15).
    pub fn apply_one(&self, pos: [f32; 2], c: [f32; 3], scratch: &mut Scratch) -> [f32; 3] {
        let t = self.tap(pos);
        scratch.resize(self.experts, self.hidden);
        self.weights_at(&t, &mut scratch.w);
        let mut out = c.map(|x| x * scratch.w[0]);
        for op in 1..self.experts {
            let (y, _) = self.operator(op, c, &mut scratch.h1, &mut scratch.h2);
            for (o, y) in out.iter_mut().zip(y) {
                *o += scratch.w[op] * y;
            }
        }
        out
    }

    /// Enhance every Gaussian's colour. Each result depends only on that Gaussian, so the
    /// parallel build gives the same bits as the sequential one.
    pub fn apply(&self, positions: &[[f32; 2]], colors: &[[f32; 3]]) -> Vec<[f32; 3]> {
        let one = |s: &mut Scratch, (p, c): (&[f32; 2], &[f32; 3])| self.apply_one(*p, *c, s);
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            positions
                .par_iter()
                .zip(colors)
                .map_init(Scratch::default, one)
                .collect()
        }
        #[cfg(not(feature = "parallel"))]
        {
            let mut s = Scratch::default();
            positions
                .iter()
                .zip(colors)
                .map(|pc| one(&mut s, pc))
                .collect()
        }
    }

    /// The stored form, quantized. [`Enhancer::from_record`] of the result is the
    /// enhancer that must be applied, so that the file can reproduce its own colours.
    pub fn to_record(&self, fit: FitSettings) -> EnhancerRecord {
        let h = self.hidden;
        let sizes = tensor_sizes(h);
        let per = Self::params_per_operator(h);
        let tensors: [Attribute; TENSORS] = std::array::from_fn(|t| {
            let start: usize = sizes[..t].iter().sum();
            let vals: Vec<[f32; 1]> = self
                .params
                .chunks_exact(per)
                .flat_map(|p| p[start..start + sizes[t]].iter().map(|&x| [x]))
                .collect();
            Attribute::fit(&vals, [PARAM_BITS])
        });
        let map: Vec<[f32; 1]> = self.map.iter().map(|&x| [x]).collect();
        EnhancerRecord {
            gain: None,
            chroma: None,
            speckle: None,
            experts: self.experts as u8,
            hidden: h as u8,
            clamp: self.clamp,
            map_width: self.map_width as u16,
            map_height: self.map_height as u16,
            map: Attribute::fit(&map, [map_bits(&self.map)]),
            tensors,
            fit,
            denoise: None,
            tone: None,
        }
    }

    /// The enhancer a stored record describes.
    pub fn from_record(r: &EnhancerRecord) -> Enhancer {
        let h = usize::from(r.hidden);
        let sizes = tensor_sizes(h);
        let per = Self::params_per_operator(h);
        let ops = usize::from(r.experts) - 1;
        let mut params = vec![0.0f32; ops * per];
        for (t, a) in r.tensors.iter().enumerate() {
            let start: usize = sizes[..t].iter().sum();
            let vals = a.values::<1>();
            for (op, chunk) in vals.chunks_exact(sizes[t].max(1)).enumerate().take(ops) {
                for (j, v) in chunk.iter().enumerate() {
                    params[op * per + start + j] = v[0];
                }
            }
        }
        Enhancer {
            experts: usize::from(r.experts),
            hidden: h,
            clamp: r.clamp,
            map_width: usize::from(r.map_width),
            map_height: usize::from(r.map_height),
            map: r.map.values::<1>().into_iter().map(|v| v[0]).collect(),
            params,
        }
    }
}

/// Bits that keep the logits `map` to [`MAP_STEP`], at most [`MAP_BITS`].
fn map_bits(map: &[f32]) -> u8 {
    let (lo, hi) = map
        .iter()
        .filter(|x| x.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
    if lo >= hi {
        return 0;
    }
    let levels = f64::from((hi - lo) / MAP_STEP) + 1.0;
    (levels.log2().ceil() as u8).clamp(1, MAP_BITS)
}

/// Per-thread buffers of [`Enhancer::apply_one`].
#[derive(Default)]
pub struct Scratch {
    w: Vec<f32>,
    h1: Vec<f32>,
    h2: Vec<f32>,
}

impl Scratch {
    fn resize(&mut self, experts: usize, hidden: usize) {
        self.w.resize(experts, 0.0);
        self.h1.resize(hidden, 0.0);
        self.h2.resize(hidden, 0.0);
    }
}

/// See [`Enhancer::tap`].
pub fn tap(map_width: usize, map_height: usize, pos: [f32; 2]) -> MapTap {
    let axis = |u: f32, n: usize| -> (u32, u32, f32) {
        let x = u * n as f32 - 0.5;
        // NaN and far-away centres land on the border cell.
        let x = if x.is_nan() {
            0.0
        } else {
            x.clamp(0.0, (n - 1) as f32)
        };
        let x0 = (x.floor() as usize).min(n - 1);
        let x1 = (x0 + 1).min(n - 1);
        (x0 as u32, x1 as u32, x - x0 as f32)
    };
    let (x0, x1, fx) = axis(pos[0], map_width);
    let (y0, y1, fy) = axis(pos[1], map_height);
    let w = map_width as u32;
    MapTap {
        cells: [y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1],
        weights: [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ],
    }
}

/// Numerically stable softmax.
pub fn softmax_in_place(w: &mut [f32]) {
    let m = w.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0f32;
    for x in w.iter_mut() {
        *x = (*x - m).exp();
        sum += *x;
    }
    for x in w.iter_mut() {
        *x /= sum;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(experts: usize, hidden: usize) -> Enhancer {
        let mut rng = gsi_synth::SplitMix64::new(3);
        let per = Enhancer::params_per_operator(hidden);
        Enhancer {
            experts,
            hidden,
            clamp: [0.0, 1.0],
            map_width: 3,
            map_height: 2,
            map: (0..6 * experts).map(|_| rng.range(-2.0, 2.0)).collect(),
            params: (0..(experts - 1) * per)
                .map(|_| rng.range(-0.5, 0.5))
                .collect(),
        }
    }

    fn fit() -> FitSettings {
        FitSettings {
            weights: [50.0, 25.0, 32.5, 2.91, 0.44, 500.0, 0.01],
            exposure: 0.7,
            saturation_tau: 0.1,
            contrast_gamma: 1.05,
            iterations: 10,
            seed: 1,
        }
    }

    #[test]
    fn taps_interpolate_between_cell_centres() {
        let t = tap(4, 2, [0.375, 0.25]); // centre of cell (1, 0)
        assert_eq!(t.cells[0], 1);
        assert!((t.weights[0] - 1.0).abs() < 1e-6);
        let t = tap(4, 2, [0.5, 0.25]); // half way between cells 1 and 2
        assert!((t.weights[0] - 0.5).abs() < 1e-6 && (t.weights[1] - 0.5).abs() < 1e-6);
        for p in [[-5.0, 9.0], [f32::NAN, 0.5], [1.0, 1.0], [0.0, 0.0]] {
            let t = tap(4, 2, p);
            assert!(t.cells.iter().all(|&c| c < 8));
            assert!((t.weights.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn zero_residuals_are_the_identity() {
        let mut e = sample(4, 5);
        let per = Enhancer::params_per_operator(5);
        for op in e.params.chunks_exact_mut(per) {
            op[per - 5 - 1..].fill(0.0); // W3 and b3
        }
        let c = [0.2, 0.5, 0.9];
        let out = e.apply(&[[0.3, 0.6]], &[c])[0];
        for (o, c) in out.iter().zip(c) {
            assert!((o - c).abs() < 1e-6);
        }
    }

    #[test]
    fn output_is_a_convex_mix_within_the_clamp() {
        let e = sample(6, 4);
        let pos: Vec<[f32; 2]> = (0..50)
            .map(|i| [i as f32 / 49.0, 1.0 - i as f32 / 49.0])
            .collect();
        let col: Vec<[f32; 3]> = (0..50).map(|i| [i as f32 / 49.0, 0.3, 0.9]).collect();
        for c in e.apply(&pos, &col) {
            assert!(c.iter().all(|x| (0.0..=1.0).contains(x)), "{c:?}");
        }
    }

    #[test]
    fn the_stored_enhancer_round_trips_through_bytes() {
        let e = sample(5, 3);
        let rec = e.to_record(fit());
        let bytes = rec.to_payload(3).unwrap();
        let back = EnhancerRecord::parse(&bytes, &gsi_format::format::Limits::default()).unwrap();
        assert_eq!(back, rec);
        let q = Enhancer::from_record(&back);
        assert_eq!(q.params.len(), e.params.len());
        for (a, b) in q.params.iter().zip(&e.params) {
            assert!((a - b).abs() < 1e-3, "{a} vs {b}");
        }
        // The logits are kept to MAP_STEP, or to 1/1023 of a range too wide for it.
        let (lo, hi) = e
            .map
            .iter()
            .fold((f32::MAX, f32::MIN), |(l, h), &x| (l.min(x), h.max(x)));
        let step = MAP_STEP.max((hi - lo) / 1023.0);
        for (a, b) in q.map.iter().zip(&e.map) {
            assert!((a - b).abs() <= 0.5 * step + 1e-6, "{a} vs {b}");
        }
    }

    #[test]
    fn one_operator_is_just_the_identity() {
        let e = Enhancer {
            experts: 1,
            params: Vec::new(),
            map: vec![0.0; 6],
            ..sample(2, 2)
        };
        assert_eq!(
            e.apply(&[[0.5, 0.5]], &[[0.1, 2.0, -1.0]])[0],
            [0.1, 2.0, -1.0]
        );
        let rec = e.to_record(fit());
        let back = EnhancerRecord::parse(
            &rec.to_payload(3).unwrap(),
            &gsi_format::format::Limits::default(),
        )
        .unwrap();
        assert_eq!(Enhancer::from_record(&back), e);
    }
}
