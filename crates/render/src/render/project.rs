//! Per-Gaussian preprocessing: from the normalized model to pixel space (spec §6).
//!
//! Every renderer starts here, so that the clamps, the conic and the pixel box, which
//! decide which pixels a Gaussian may touch, are computed once and the same way.

use super::rounding::{ceil, floor};
use super::TILE;
use gsi_format::contract::{
    exp, ALPHA_MAX, ALPHA_MIN, COLOR_MAX, COLUMN_DARK, COLUMN_START, COLUMN_STEEP, CORRELATION_MAX,
    EXTENT_SIGMAS, VAR_MAX, VAR_MIN,
};
use gsi_format::model::{Blend, Scene, WeightRule};

/// Inclusive range of pixel columns `x0..=x1` and rows `y0..=y1`; never empty.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PixelBox {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

/// Pixels `x0..x1` × `y0..y1`, exclusive ends: a tile, or the part of one that a band
/// of rows holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub x0: u32,
    pub x1: u32,
    pub y0: u32,
    pub y1: u32,
}

impl Rect {
    /// Tile `t` of a `width × height` output, tiles `tiles_x` to a row, cut to the output.
    pub fn of_tile(t: usize, tiles_x: u32, width: u32, height: u32) -> Rect {
        let (tx, ty) = (t as u32 % tiles_x, t as u32 / tiles_x);
        Rect {
            x0: tx * TILE,
            x1: ((tx + 1) * TILE).min(width),
            y0: ty * TILE,
            y1: ((ty + 1) * TILE).min(height),
        }
    }

    /// Index of pixel `(i, j)` in a tile-local buffer of `TILE × TILE`.
    #[inline(always)]
    pub fn local(&self, i: u32, j: u32) -> usize {
        ((j - self.y0) * TILE + (i - self.x0)) as usize
    }
}

impl PixelBox {
    /// Columns and rows of `rect` inside the box; `None` when they do not meet.
    #[inline]
    pub fn clip(&self, rect: Rect) -> Option<(std::ops::Range<u32>, std::ops::Range<u32>)> {
        let xs = self.x0.max(rect.x0)..(self.x1 + 1).min(rect.x1);
        let ys = self.y0.max(rect.y0)..(self.y1 + 1).min(rect.y1);
        (!xs.is_empty() && !ys.is_empty()).then_some((xs, ys))
    }

    /// Whether pixel `(i, j)` lies in the box.
    #[inline]
    pub fn contains(&self, i: u32, j: u32) -> bool {
        (self.x0..=self.x1).contains(&i) && (self.y0..=self.y1).contains(&j)
    }
}

/// `(i + 0.5) − m` for pixel column or row `i`, as spec §6.3 computes it.
#[inline(always)]
pub(crate) fn offset(i: u32, m: f32) -> f32 {
    (i as f32 + 0.5) - m
}

/// One Gaussian in the pixel space of a given output size, ready to be evaluated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected {
    /// Index of the Gaussian in the scene (stored order).
    pub index: usize,
    /// Centre `(mx, my)` in pixels; pixel `(i, j)` has its centre at `(i + 0.5, j + 0.5)`.
    pub mean: [f32; 2],
    /// Inverse pixel covariance `(A, B, C)`: `power = -0.5(A dx² + C dy²) - B dx dy`.
    pub conic: [f32; 3],
    /// Opacity in `[ALPHA_MIN, 1]` (a Gaussian below `ALPHA_MIN` is never projected).
    pub opacity: f32,
    /// Colour as stored, clamped to `±COLOR_MAX`, non-finite components replaced by 0.
    pub color: [f32; 3],
    /// Pixels whose centre lies within `EXTENT_SIGMAS` standard deviations along x and y,
    /// clipped to the image. No pixel outside it is ever touched.
    pub bbox: PixelBox,
    /// [`Projected::cutoff`], computed once here: every tile a Gaussian visits asks for it.
    cut: f32,
    /// [`Projected::column_k`], computed once here for the same reason.
    column_k: f32,
    /// [`Projected::carried_throughout`].
    carried: bool,
}

impl Projected {
    /// The weight `alpha` of this Gaussian at pixel `(i, j)`, or `None` where the rules of
    /// spec §6 skip it (outside the box, `power > 0`, `alpha < ALPHA_MIN`). In `alpha`
    /// blending the result is capped at `ALPHA_MAX`.
    ///
    /// This is the per-pixel contract in its plainest form; the CPU renderer's inner
    /// loops are specialized copies of it, and tests hold them to it bit for bit.
    #[inline]
    pub fn alpha_at(&self, i: u32, j: u32, blend: Blend) -> Option<f32> {
        if !self.bbox.contains(i, j) {
            return None;
        }
        let power = self.power(offset(i, self.mean[0]), offset(j, self.mean[1]));
        if power > 0.0 {
            return None;
        }
        self.alpha_of(exp(power), blend)
    }

    /// `power = −0.5·(A·dx·dx + C·dy·dy) − B·dx·dy` at offsets `(dx, dy)` from the centre
    /// (spec §6.3).
    #[inline]
    fn power(&self, dx: f32, dy: f32) -> f32 {
        let [a, b, c] = self.conic;
        -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
    }

    /// The alpha of a weight `w` (`E(power)` or the column rule's): `o·w`, capped at
    /// `ALPHA_MAX` in `alpha` blending, `None` below `ALPHA_MIN`.
    #[inline]
    fn alpha_of(&self, w: f32, blend: Blend) -> Option<f32> {
        let mut alpha = self.opacity * w;
        if blend == Blend::Alpha {
            alpha = alpha.min(ALPHA_MAX);
        }
        (alpha >= ALPHA_MIN).then_some(alpha)
    }

    /// The weight at pixel `(i, j)` under `rule`: [`Projected::alpha_at`] for
    /// [`WeightRule::PerPixel`] and for a Gaussian steeper than [`COLUMN_STEEP`]; else
    /// spec §6.3.2 in its plainest form, walking down column `i` from the first row of the
    /// box in `j`'s band of the rule's rows ([`WeightRule::band_rows`]).
    pub fn weight_at(&self, i: u32, j: u32, blend: Blend, rule: WeightRule) -> Option<f32> {
        let [_, b, c] = self.conic;
        let band = match rule.band_rows() {
            Some(band) if c <= COLUMN_STEEP => band,
            _ => return self.alpha_at(i, j, blend),
        };
        if !self.bbox.contains(i, j) {
            return None;
        }
        let dx = offset(i, self.mean[0]);
        let power = |row: u32| self.power(dx, offset(row, self.mean[1]));
        // The power's step from `row` to the next: its first difference, written out so
        // that `A·dx·dx`, the same in both rows, does not round into it.
        let step = |row: u32| {
            let (dy0, dy1) = (offset(row, self.mean[1]), offset(row + 1, self.mean[1]));
            -0.5 * (c * (dy0 + dy1)) - b * dx
        };
        let first = self.bbox.y0.max(j - j % band);
        let k = exp(-c);
        // Dark (w = 0) until the power reaches the start level, then carried while the
        // weight stays at or above the dark level.
        let (mut w, mut r) = (0f32, 0f32);
        for row in first..=j {
            if w >= COLUMN_DARK {
                (w, r) = (w * r, r * k);
            } else if power(row) >= COLUMN_START {
                (w, r) = (exp(power(row)), exp(step(row)));
            } else {
                w = 0.0;
            }
        }
        self.alpha_of(w, blend)
    }
}

impl Projected {
    /// A `power` below which `opacity · exp(power) < ALPHA_MIN` for certain, whatever the
    /// rounding of `exp` and of the product: `ln(ALPHA_MIN / opacity)` less a margin of
    /// 1e-3, thousands of ulps of `exp`. Only a shortcut: every pixel above it is
    /// evaluated exactly as the contract says.
    #[inline]
    pub fn cutoff(&self) -> f32 {
        self.cut
    }

    /// `k = E(−C)` of the column rule (spec §6.3.2): the ratio of successive ratios `r`
    /// down a column.
    #[inline]
    pub fn column_k(&self) -> f32 {
        self.column_k
    }

    /// Whether the power at every pixel of the box is far above the column rule's start
    /// and dark levels (spec §6.3.2), so that down any column of a band every lane of the
    /// box starts on its first row and stays carried to its last: a renderer may then
    /// skip testing for lanes that go dark. Only a shortcut: the weights are the rule's.
    #[inline]
    pub fn carried_throughout(&self) -> bool {
        self.carried
    }
}

/// A bound on the power's terms `A·dx²`, `C·dy²` and `2·B·dx·dy` for offsets of at most
/// `mx` and `my` from the centre: what the rounding of the power scales with.
pub(crate) fn term_bound([a, b, c]: [f64; 3], mx: f64, my: f64) -> f64 {
    a.abs() * mx * mx + c.abs() * my * my + 2.0 * b.abs() * mx * my
}

/// How far, in its logarithm, a weight is from `e^power` where the power's terms are
/// bounded by `s` ([`term_bound`]). A pixel's binary32 power is off by less than 1e-6·s;
/// a weight of the column rule (spec §6.3.2) in bands of up to 32 rows by less than 63
/// such errors (its first power, and 31 times a step, whose terms are bounded as the
/// power's) and 1e-4: in units `u = 2⁻²⁴`, the first `E(P)` and `E(D)` (2u each, with
/// their products) and `E(D)` taken 31 times, `E(−C)` raised to up to the 465th power
/// (2u each), and the rounding of each ratio `r·k`, carried into every later weight (465
/// times), and of each weight's product (31): about 1,490u, 8.9e-5.
pub(crate) fn log_weight_error(s: f64) -> f64 {
    63e-6 * s + 1e-4
}

/// [`Projected::carried_throughout`] for a Gaussian centred at `mean` with `conic`, over
/// the pixels of `bbox`. The power is concave, so its least value over the box is at a
/// corner pixel. Asking for a least power of −50 (the start level is −55, the dark level
/// −55.45) with [`log_weight_error`] under 1 leaves a margin of over 4.
fn carried_in(mean: [f32; 2], conic: [f32; 3], bbox: &PixelBox) -> bool {
    let dxs = [offset(bbox.x0, mean[0]), offset(bbox.x1, mean[0])].map(f64::from);
    let dys = [offset(bbox.y0, mean[1]), offset(bbox.y1, mean[1])].map(f64::from);
    let [a, b, c] = conic.map(f64::from);
    let mut least = f64::INFINITY;
    for dx in dxs {
        for dy in dys {
            least = least.min(-0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy);
        }
    }
    let (mx, my) = (
        dxs[0].abs().max(dxs[1].abs()),
        dys[0].abs().max(dys[1].abs()),
    );
    // (`min` and `max` pass over a NaN: a non-finite offset or conic is refused here.)
    let finite = dxs
        .iter()
        .chain(&dys)
        .chain(&[a, b, c])
        .all(|x| x.is_finite());
    finite && least > -50.0 && log_weight_error(term_bound([a, b, c], mx, my)) < 1.0
}

/// [`Projected::cutoff`] for an opacity.
#[inline]
fn cutoff_of(opacity: f32) -> f32 {
    // Every Gaussian of a `sum` file has opacity 1: its cut-off is a constant, and the
    // logarithm a call into libm per Gaussian.
    if opacity == 1.0 {
        return CUTOFF_AT_ONE;
    }
    cutoff_by_log(opacity)
}

/// `ln(ALPHA_MIN / opacity) − 10⁻³`, in `f64`, rounded to `f32`.
fn cutoff_by_log(opacity: f32) -> f32 {
    ((f64::from(ALPHA_MIN) / f64::from(opacity)).ln() - 1e-3) as f32
}

/// [`cutoff_by_log`] of 1 (checked by a test).
const CUTOFF_AT_ONE: f32 = -5.542_263_5;

/// Project Gaussian `index` of `scene` for a `width × height` output.
///
/// `None` when it can touch no pixel: non-finite centre, empty pixel box, or opacity
/// below `ALPHA_MIN` (its `alpha` can never reach the threshold, since `power <= 0`).
///
/// # Panics
/// If `index` is out of range or the scene's attribute vectors are inconsistent.
pub fn project(scene: &Scene, index: usize, width: u32, height: u32) -> Option<Projected> {
    let g = &scene.gaussians;
    let (fw, fh) = (width as f32, height as f32);

    // Steps 1-4: normalized covariance, pixel covariance, clamps, conic.
    let s = scene.cov_param.covariance(g.cov[index]);
    let a = (s[0] * fw * fw).clamp(VAR_MIN, VAR_MAX);
    let c = (s[2] * fh * fh).clamp(VAR_MIN, VAR_MAX);
    let lim = CORRELATION_MAX * (a * c).sqrt();
    // `covariance` is finite, so `lim` is positive; the guard keeps `clamp` panic-free
    // should that ever change.
    if !(lim > 0.0 && lim.is_finite()) {
        return None;
    }
    let b = (s[1] * fw * fh).clamp(-lim, lim);
    let det = a * c - b * b;
    let conic = [c / det, -b / det, a / det];
    if !conic.iter().all(|x| x.is_finite()) {
        return None;
    }

    // Step 5: centre. An infinite centre could only give an empty box anyway.
    let [u, v] = g.positions[index];
    let mean = [u * fw, v * fh];
    if !(mean[0].is_finite() && mean[1].is_finite()) {
        return None;
    }

    // Step 6: pixel box.
    let (x0, x1) = pixel_span(mean[0], EXTENT_SIGMAS * a.sqrt(), width)?;
    let (y0, y1) = pixel_span(mean[1], EXTENT_SIGMAS * c.sqrt(), height)?;

    // Step 7: opacity and colour.
    let o = g.opacity_of(index);
    let opacity = if o.is_finite() {
        o.clamp(0.0, 1.0)
    } else {
        0.0
    };
    if opacity < ALPHA_MIN {
        return None;
    }
    let color = g.colors[index].map(|x| {
        if x.is_finite() {
            x.clamp(-COLOR_MAX, COLOR_MAX)
        } else {
            0.0
        }
    });

    let bbox = PixelBox { x0, y0, x1, y1 };
    Some(Projected {
        index,
        mean,
        conic,
        opacity,
        color,
        bbox,
        cut: cutoff_of(opacity),
        column_k: exp(-conic[2]),
        carried: carried_in(mean, conic, &bbox),
    })
}

/// Every Gaussian of `scene` that can touch a pixel of a `width × height` output, in
/// stored order (which `alpha` blending and bit-exact `sum` accumulation depend on).
///
/// # Panics
/// If the scene's attribute vectors are inconsistent ([`gsi_format::model::GaussianSet::is_consistent`]).
pub fn project_scene(scene: &Scene, width: u32, height: u32) -> Vec<Projected> {
    let n = scene.gaussians.len();
    #[cfg(feature = "parallel")]
    if n >= PARALLEL_PROJECTION && rayon::current_num_threads() > 1 {
        return project_in_parallel(scene, width, height);
    }
    // Room for every Gaussian at once: most of a fitted scene is drawn, and a vector
    // grown by doubling copies itself and faults in fresh pages at each step.
    let mut out = Vec::with_capacity(n);
    out.extend((0..n).filter_map(|i| project(scene, i, width, height)));
    out
}

/// Gaussians from which [`project_scene`] projects on rayon's pool: a projection is about
/// 80 ns (6 % of kodim23's decode for its 8.6k Gaussians: the platform's `exp`, `sin` and
/// `cos` of a `log-scale-rotation` covariance, divisions and square roots), and on the
/// pool a random 10k `sum` render went from 3.1–3.3 ms to 2.5–2.6 ms. The threshold was
/// not tuned: a few thousand Gaussians, where a chunk of work outweighs handing it out.
#[cfg(feature = "parallel")]
const PARALLEL_PROJECTION: usize = 4096;

/// [`project_scene`] by chunks on rayon's pool, in place: every slot of one array is
/// written by the chunk that holds it, and the Gaussians that cannot show are dropped
/// after, so that no second array is made (nor its pages faulted in) to join the chunks.
/// The same Gaussians, in the same order, with the same values.
#[cfg(feature = "parallel")]
fn project_in_parallel(scene: &Scene, width: u32, height: u32) -> Vec<Projected> {
    use rayon::prelude::*;
    const CHUNK: usize = 1024;
    let mut out = vec![DROPPED; scene.gaussians.len()];
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, chunk)| {
            for (k, slot) in chunk.iter_mut().enumerate() {
                if let Some(p) = project(scene, c * CHUNK + k, width, height) {
                    *slot = p;
                }
            }
        });
    // (Nothing moves where nothing was dropped, as for most fitted scenes.)
    out.retain(|p| p.index != DROPPED.index);
    out
}

/// A slot of [`project_in_parallel`] whose Gaussian cannot show: no scene has
/// `usize::MAX` Gaussians.
#[cfg(feature = "parallel")]
const DROPPED: Projected = Projected {
    index: usize::MAX,
    mean: [0.0; 2],
    conic: [0.0; 3],
    opacity: 0.0,
    color: [0.0; 3],
    bbox: PixelBox {
        x0: 0,
        y0: 0,
        x1: 0,
        y1: 0,
    },
    cut: 0.0,
    column_k: 0.0,
    carried: false,
};

/// Pixels `i` of `0..n` whose centre `i + 0.5` lies in `[m - r, m + r]`, as an inclusive
/// range: `ceil(m - r - 0.5) ..= floor(m + r - 0.5)`, clipped. Computed in `f32` and
/// clamped in float before the cast, so a centre far outside the image cannot overflow.
fn pixel_span(m: f32, r: f32, n: u32) -> Option<(u32, u32)> {
    let lo = ceil(f64::from(m - r - 0.5)) as f32;
    let hi = floor(f64::from(m + r - 0.5)) as f32;
    // Also rejects NaN.
    if !(lo <= hi && hi >= 0.0) {
        return None;
    }
    let last = n.checked_sub(1)?;
    let limit = n as f32;
    let lo = lo.clamp(0.0, limit) as u64;
    let hi = (hi.clamp(0.0, limit) as u64).min(u64::from(last));
    if lo > hi {
        return None;
    }
    // Both are at most `last`, a u32.
    Some((lo as u32, hi as u32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::model::{CovParam, GaussianSet};

    fn one(pos: [f32; 2], cov: [f32; 3], opacity: Option<f32>) -> Scene {
        Scene {
            weights: gsi_format::model::WeightRule::PerPixel,
            tone: None,
            width: 10,
            height: 10,
            blend: Blend::Sum,
            cov_param: CovParam::Cholesky,
            gaussians: GaussianSet {
                positions: vec![pos],
                cov: vec![cov],
                colors: vec![[1.0, f32::NAN, -2.0]],
                opacity: opacity.map(|o| vec![o]),
            },
        }
    }

    /// The projection on rayon's pool gives the one thread's Gaussians, in order, bit for
    /// bit, with Gaussians that cannot show dropped from the first chunk, the last and
    /// between, and with none dropped.
    #[cfg(feature = "parallel")]
    #[test]
    fn projection_in_parallel_is_the_sequential_one() {
        use gsi_synth::{random_scene, SceneSpec};
        for (n, drop_every) in [(5000, 7), (2 * 1024, 0), (3000, 1)] {
            let mut scene = random_scene(5, SceneSpec::new(120, 90, n, Blend::Alpha));
            let g = &mut scene.gaussians;
            for i in (0..n).filter(|i| drop_every > 0 && i % drop_every == 0) {
                match i % 3 {
                    0 => g.positions[i] = [-5.0, 0.5],
                    1 => g.positions[i] = [f32::NAN, 0.5],
                    _ => g.opacity.as_mut().expect("alpha scenes have opacity")[i] = 0.0,
                }
            }
            let one: Vec<Projected> = (0..n).filter_map(|i| project(&scene, i, 120, 90)).collect();
            let pool = project_in_parallel(&scene, 120, 90);
            assert_eq!(one.len(), pool.len(), "{n} {drop_every}");
            let bits = |p: &Projected| {
                let f = [
                    p.mean.as_slice(),
                    &p.conic,
                    &[p.opacity],
                    &p.color,
                    &[p.cut, p.column_k],
                ];
                let f: Vec<u32> = f.concat().iter().map(|x| x.to_bits()).collect();
                (p.index, f, p.bbox, p.carried)
            };
            assert!(
                one.iter().zip(&pool).all(|(a, b)| bits(a) == bits(b)),
                "{n} {drop_every}"
            );
            assert!(drop_every == 0 || one.len() < n);
        }
    }

    #[test]
    fn pixel_span_follows_centres() {
        // Centre 5.0, radius 1: centres 4.5 and 5.5 are inside, 3.5 and 6.5 are not.
        assert_eq!(pixel_span(5.0, 1.0, 10), Some((4, 5)));
        // Exactly on a centre counts.
        assert_eq!(pixel_span(5.5, 1.0, 10), Some((4, 6)));
        assert_eq!(pixel_span(5.0, 0.1, 10), None);
        assert_eq!(pixel_span(-3.0, 1.0, 10), None);
        assert_eq!(pixel_span(12.0, 1.0, 10), None);
        assert_eq!(pixel_span(0.0, 1e30, 10), Some((0, 9)));
        assert_eq!(pixel_span(1e30, 1.0, 10), None);
        assert_eq!(pixel_span(-1e30, 1e12, u32::MAX), None);
        assert_eq!(pixel_span(f32::NAN, 1.0, 10), None);
        assert_eq!(pixel_span(0.5, 1e12, u32::MAX), Some((0, u32::MAX - 1)));
    }

    #[test]
    fn projection_applies_clamps() {
        // 8 px output, Cholesky l11 = 1/8 -> a = 1 px², c = VAR_MIN (clamped from 0).
        let p = project(&one([0.5625, 0.5625], [0.125, 0.0, 0.0], None), 0, 8, 8).unwrap();
        assert_eq!(p.mean, [4.5, 4.5]);
        let det = 1.0 * VAR_MIN;
        assert_eq!(p.conic, [VAR_MIN / det, 0.0, 1.0 / det]);
        // x: 3 px either side of 4.5; y: 0.03 px, only the centre row.
        assert_eq!(
            p.bbox,
            PixelBox {
                x0: 1,
                y0: 4,
                x1: 7,
                y1: 4
            }
        );
        assert_eq!(p.color, [1.0, 0.0, -2.0]);
        assert_eq!(p.opacity, 1.0);
        assert_eq!(p.alpha_at(4, 4, Blend::Sum), Some(1.0));
        assert_eq!(p.alpha_at(4, 4, Blend::Alpha), Some(ALPHA_MAX));
        assert_eq!(
            p.alpha_at(5, 4, Blend::Sum),
            Some(gsi_format::contract::exp(-0.5))
        );
        assert_eq!(p.alpha_at(4, 5, Blend::Sum), None);
        assert_eq!(p.alpha_at(0, 4, Blend::Sum), None);
    }

    #[test]
    fn projection_skips_what_cannot_show() {
        let p = |pos, op| project(&one(pos, [0.1, 0.0, 0.1], op), 0, 10, 10);
        assert!(p([0.5, 0.5], Some(0.0)).is_none());
        assert!(p([0.5, 0.5], Some(f32::NAN)).is_none());
        assert!(p([0.5, 0.5], Some(f32::INFINITY)).is_none());
        assert_eq!(p([0.5, 0.5], Some(7.0)).unwrap().opacity, 1.0);
        assert!(p([f32::NAN, 0.5], None).is_none());
        assert!(p([0.5, f32::INFINITY], None).is_none());
        assert!(p([-5.0, 0.5], None).is_none());
        assert!(p([0.5, 1e30], None).is_none());
    }

    #[test]
    fn cutoff_is_below_the_threshold() {
        for o in [ALPHA_MIN, 0.01, 0.1, 0.5, 0.99, 1.0] {
            let cut = cutoff_of(o);
            // Just below the cut-off, alpha is under the threshold; at the true
            // threshold, it is (about) on it.
            assert!(o * cut.exp() < ALPHA_MIN, "{o}");
            assert!(o * (cut + 2e-3).exp() >= ALPHA_MIN, "{o}");
        }
    }

    #[test]
    fn the_cutoff_at_opacity_one_is_the_logarithms() {
        assert_eq!(CUTOFF_AT_ONE.to_bits(), cutoff_by_log(1.0).to_bits());
        assert_eq!(cutoff_of(1.0).to_bits(), cutoff_by_log(1.0).to_bits());
        assert_eq!(cutoff_of(0.5).to_bits(), cutoff_by_log(0.5).to_bits());
    }

    /// The shortcut is taken only where no pixel of the box is near the dark level:
    /// ordinary footprints take it, a needle whose box runs far out along its thin axis
    /// or a box far off-centre does not.
    #[test]
    fn carried_throughout_only_far_from_dark() {
        let round = [0.25, 0.0, 0.25];
        let box_of = |x0, y0, x1, y1| PixelBox { x0, y0, x1, y1 };
        assert!(carried_in([8.0, 8.0], round, &box_of(2, 2, 13, 13)));
        // 40 px out at 1/0.25 variance: power −200.
        assert!(!carried_in([8.0, 8.0], round, &box_of(0, 0, 48, 8)));
        // A needle: a hundredth of a pixel across, a box spanning 12 px of its thin axis.
        let needle = [1e4, 0.0, 1e-2];
        assert!(!carried_in([8.0, 8.0], needle, &box_of(2, 2, 13, 13)));
        assert!(!carried_in([f32::NAN, 8.0], round, &box_of(2, 2, 13, 13)));
    }

    /// Spec §6.3.2's worked example, and its band rule.
    #[test]
    fn column_rule_worked_example() {
        let p = Projected {
            index: 0,
            mean: [1.25, 0.75],
            conic: [0.5, 0.125, 0.25],
            opacity: 1.0,
            color: [1.0; 3],
            bbox: PixelBox {
                x0: 0,
                y0: 0,
                x1: 3,
                y1: 40,
            },
            cut: cutoff_of(1.0),
            column_k: exp(-0.25),
            carried: false,
        };
        let bits = |row, rule| p.weight_at(1, row, Blend::Sum, rule).map(f32::to_bits);
        let columns = [0x3F7C07F5, 0x3F657A17, 0x3F22B938, 0x3EB3BA9B];
        let per_pixel = [0x3F7C07F5, 0x3F657A17, 0x3F22B937, 0x3EB3BA9A];
        for row in 0..4 {
            assert_eq!(bits(row, WeightRule::Columns), Some(columns[row as usize]));
            assert_eq!(
                bits(row, WeightRule::PerPixel),
                Some(per_pixel[row as usize])
            );
        }
        assert_eq!(exp(-0.25).to_bits(), 0x3F475F7D);
        assert_eq!(exp(-0.09375).to_bits(), 0x3F691735);
        // A band's first row is E(power) itself, the next two products of it, whatever
        // the rows above: the centre moved down by 16 rows.
        let q = Projected {
            mean: [1.25, 16.75],
            ..p
        };
        let at = |row| q.weight_at(1, row, Blend::Sum, WeightRule::Columns);
        assert_eq!(at(16).map(f32::to_bits), Some(columns[0]));
        assert_eq!(at(17).map(f32::to_bits), Some(columns[1]));
        // In bands of 32 rows (`GCRT`) the same rows 0 to 3 give the same weights, rows 16
        // and 17 are carried from the box's first row, and rows 32 and 33 begin a band.
        for row in 0..4 {
            let w = p.weight_at(1, row, Blend::Sum, WeightRule::Columns32);
            assert_eq!(w.map(f32::to_bits), Some(columns[row as usize]));
        }
        let at = |row| q.weight_at(1, row, Blend::Sum, WeightRule::Columns32);
        // (Row 0's power, about −32.5, starts the column there, far below `1/255`.)
        assert_eq!(at(0), None);
        assert_eq!(at(16).map(f32::to_bits), Some(0x3F7C07EF));
        assert_eq!(at(17).map(f32::to_bits), Some(0x3F657A11));
        let r = Projected {
            mean: [1.25, 32.75],
            ..p
        };
        let at = |row| r.weight_at(1, row, Blend::Sum, WeightRule::Columns32);
        assert_eq!(at(32).map(f32::to_bits), Some(columns[0]));
        assert_eq!(at(33).map(f32::to_bits), Some(columns[1]));
    }
}
