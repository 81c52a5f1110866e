//! Denoising across neighbouring Gaussians, before the mixture (spec §7.2.1).
//!
//! Brightening a dark photograph multiplies its sensor noise, and a Gaussian fit of a
//! noisy image spends Gaussians on it: blotches a few Gaussians wide. The mixture maps
//! every colour on its own, so it cannot tell a blotch from detail. This step can: it
//! compares each Gaussian with the Gaussians of about its own size and place, and pulls
//! it towards those whose colour is within the noise of its own (an edge-preserving,
//! bilateral average, over Gaussians rather than pixels).
//!
//! In `sum` blending a colour record is a coefficient, not a colour: overlapping
//! Gaussians add up, and a large one and the small ones over it carry very different
//! numbers for the same shade. Averaging records would blotch flat areas (measured:
//! LOL eval15 lost 0.7 dB). So what is averaged is the value the render takes at each
//! centre, and the change is carried back to the record divided by how many footprints
//! overlap there. In `alpha` blending records are displayable colours and are averaged
//! as they are.
//!
//! The operator depends only on the geometry and the three numbers of [`Denoise`], so
//! `--apply-from` reproduces it exactly, like the mixture.

use gsi_format::format::{Denoise, Error, ErrorKind, Limits, Result};
use gsi_format::model::{Blend, Scene};

/// Least affinity (Bhattacharyya coefficient) of two neighbours (spec §7.2.1). Weaker
/// pairs add little each, but a large, dense scene has thousands of them per Gaussian:
/// at 1/256 a 10.7-megapixel file of 278 000 Gaussians passed the search's memory
/// budget, while LOL eval15 and the synthetic Kodak set scored the same at either
/// threshold (BENCHMARKS.md, the denoising threshold).
pub const NEAR_MIN: f32 = 1.0 / 16.0;

/// Least value of a footprint at a centre for it to count in the value there (spec
/// §7.2.1). Lower than [`NEAR_MIN`]: the value at a centre is a sum of many footprints,
/// and the weak ones together are not negligible.
pub const REACH_MIN: f32 = 1.0 / 256.0;

/// Half-side of the box a Gaussian is binned with, in standard deviations along its
/// major axis. Two Gaussians whose boxes do not meet are more than `2·BOX_SIGMAS`
/// major-axis deviations apart, which bounds their affinity by `exp(−BOX_SIGMAS²/4)`
/// (0.047 < [`NEAR_MIN`]), and a footprint outside its box by `exp(−BOX_SIGMAS²/2)`
/// (0.0022 < [`REACH_MIN`]): the boxes find every pair the spec counts.
const BOX_SIGMAS: f32 = 3.5;

/// Each Gaussian's neighbours (by affinity) and the footprints that reach its centre,
/// in compressed-row form, indices increasing within a row.
pub struct Neighbours {
    blend: Blend,
    near_start: Vec<u32>,
    near: Vec<u32>,
    affinity: Vec<f32>,
    reach_start: Vec<u32>,
    reach: Vec<u32>,
    footprint: Vec<f32>,
}

/// Covariance in pixels of the reference size: `[σuu·W·W, σuv·W·H, σvv·H·H]` (spec
/// §7.2.1 step 1, which §7.2.5 reads too).
pub(crate) fn pixel_cov(scene: &Scene, i: usize) -> [f32; 3] {
    let [a, b, c] = scene.cov_param.covariance(scene.gaussians.cov[i]);
    let (w, h) = (scene.width as f32, scene.height as f32);
    [a * w * w, b * w * h, c * h * h]
}

/// `max(S0·S2 − S1·S1, 1e-12)`, spec §7.2.1 step 1.
pub(crate) fn det(s: [f32; 3]) -> f32 {
    (s[0] * s[2] - s[1] * s[1]).max(1e-12)
}

/// `dᵀ S⁻¹ d`.
fn mahalanobis(d: [f32; 2], s: [f32; 3]) -> f32 {
    (s[2] * d[0] * d[0] - 2.0 * s[1] * d[0] * d[1] + s[0] * d[1] * d[1]) / det(s)
}

/// The Bhattacharyya coefficient of two Gaussians `d` apart: 1 for two alike, falling
/// with distance and with any difference of size or shape.
fn affinity(d: [f32; 2], s: [f32; 3], t: [f32; 3]) -> f32 {
    let m = [
        (s[0] + t[0]) * 0.5,
        (s[1] + t[1]) * 0.5,
        (s[2] + t[2]) * 0.5,
    ];
    let shape = ((det(s) * det(t)).sqrt().sqrt() / det(m).sqrt()).min(1.0);
    shape * (-0.125 * mahalanobis(d, m)).exp()
}

/// A uniform grid of square cells over the image, each listing the Gaussians whose box
/// meets it (compressed rows).
struct Grid {
    cell: f32,
    nx: usize,
    ny: usize,
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Grid {
    /// Cells of the box `centre ± r`, clipped to the grid (a box far outside lands on
    /// the border cells, which keeps every meeting pair meeting).
    fn span(
        &self,
        centre: [f32; 2],
        r: f32,
    ) -> (
        std::ops::RangeInclusive<usize>,
        std::ops::RangeInclusive<usize>,
    ) {
        let axis = |m: f32, n: usize| {
            let last = (n - 1) as f32;
            let lo = ((m - r) / self.cell).floor().clamp(0.0, last);
            let hi = ((m + r) / self.cell).floor().clamp(0.0, last);
            // Clamped in float: NaN becomes 0 through the cast.
            lo as usize..=hi as usize
        };
        (axis(centre[0], self.nx), axis(centre[1], self.ny))
    }

    fn cell_of(&self, p: [f32; 2]) -> usize {
        let (xs, ys) = self.span(p, 0.0);
        ys.start() * self.nx + xs.start()
    }

    fn items(&self, c: usize) -> &[u32] {
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }
}

impl Neighbours {
    /// The neighbour lists of `scene`. Refuses (rather than spends without bound) a
    /// scene whose footprints overlap so much that the search would visit more than
    /// `limits.max_alloc / 8` pairs: the lists (8 bytes a pair, and no more pairs than
    /// visits) then stay within the limit, and the time with them.
    pub fn new(scene: &Scene, limits: &Limits) -> Result<Neighbours> {
        let n = scene.gaussians.len();
        let (w, h) = (scene.width as f32, scene.height as f32);
        let cov: Vec<[f32; 3]> = (0..n).map(|i| pixel_cov(scene, i)).collect();
        let centre: Vec<[f32; 2]> = scene
            .gaussians
            .positions
            .iter()
            .map(|p| [p[0] * w, p[1] * h])
            .collect();
        let radius: Vec<f32> = cov
            .iter()
            .map(|c| {
                let mean = 0.5 * (c[0] + c[2]);
                let major = mean + (0.25 * (c[0] - c[2]) * (c[0] - c[2]) + c[1] * c[1]).sqrt();
                BOX_SIGMAS * major.max(0.0).sqrt()
            })
            .collect();
        // About four centres per cell on average, and never more cells than that needs.
        let cell = ((w * h) / (n as f32 / 4.0).max(1.0)).sqrt().max(4.0);
        let nx = ((w / cell).ceil() as usize).max(1);
        let ny = ((h / cell).ceil() as usize).max(1);
        let mut grid = Grid {
            cell,
            nx,
            ny,
            start: vec![0; nx * ny + 1],
            items: Vec::new(),
        };
        let budget = limits.max_alloc / 8;
        let mut spent = 0u64;
        let mut spend = |k: u64| -> Result<()> {
            spent += k;
            if spent > budget {
                return Err(Error::new(
                    ErrorKind::LimitExceeded,
                    "the Gaussians overlap too much to find their neighbours within the memory limit",
                ));
            }
            Ok(())
        };
        for i in 0..n {
            let (xs, ys) = grid.span(centre[i], radius[i]);
            spend((xs.end() - xs.start() + 1) as u64 * (ys.end() - ys.start() + 1) as u64)?;
            for y in ys {
                for x in xs.clone() {
                    grid.start[y * nx + x + 1] += 1;
                }
            }
        }
        for c in 0..nx * ny {
            grid.start[c + 1] += grid.start[c];
        }
        grid.items = vec![0; grid.start[nx * ny] as usize];
        let mut fill = grid.start.clone();
        for i in 0..n {
            let (xs, ys) = grid.span(centre[i], radius[i]);
            for y in ys {
                for x in xs.clone() {
                    let f = &mut fill[y * nx + x];
                    grid.items[*f as usize] = i as u32;
                    *f += 1;
                }
            }
        }

        let mut out = Neighbours {
            blend: scene.blend,
            near_start: Vec::with_capacity(n + 1),
            near: Vec::new(),
            affinity: Vec::new(),
            reach_start: Vec::with_capacity(n + 1),
            reach: Vec::new(),
            footprint: Vec::new(),
        };
        out.near_start.push(0);
        out.reach_start.push(0);
        let mut cand = Vec::new();
        for i in 0..n {
            cand.clear();
            let (xs, ys) = grid.span(centre[i], radius[i]);
            for y in ys {
                for x in xs.clone() {
                    cand.extend_from_slice(grid.items(y * nx + x));
                }
            }
            spend(cand.len() as u64)?;
            cand.sort_unstable();
            cand.dedup();
            for &j in &cand {
                let j = j as usize;
                let d = [centre[j][0] - centre[i][0], centre[j][1] - centre[i][1]];
                if j != i {
                    let a = affinity(d, cov[i], cov[j]);
                    if a >= NEAR_MIN {
                        out.near.push(j as u32);
                        out.affinity.push(a);
                    }
                }
            }
            out.near_start.push(out.near.len() as u32);
            if scene.blend == Blend::Sum {
                // Every box that reaches i's centre lists itself in i's cell.
                let here = grid.items(grid.cell_of(centre[i]));
                spend(here.len() as u64)?;
                for &j in here {
                    let j = j as usize;
                    let d = [centre[i][0] - centre[j][0], centre[i][1] - centre[j][1]];
                    let g = (-0.5 * mahalanobis(d, cov[j])).exp();
                    if g >= REACH_MIN {
                        out.reach.push(j as u32);
                        out.footprint.push(g);
                    }
                }
            }
            out.reach_start.push(out.reach.len() as u32);
        }
        Ok(out)
    }

    fn near(&self, i: usize) -> (&[u32], &[f32]) {
        let r = self.near_start[i] as usize..self.near_start[i + 1] as usize;
        (&self.near[r.clone()], &self.affinity[r])
    }

    /// The value of the render at every centre (`v`) and how many footprints overlap
    /// there (`D ≥ 1`). In `alpha` blending, the records themselves and 1. Shared with
    /// the tone curve (spec §7.2.2), which reaches its values through the same density.
    pub fn values(&self, colors: &[[f32; 3]]) -> (Vec<[f32; 3]>, Vec<f32>) {
        if self.blend == Blend::Alpha {
            return (colors.to_vec(), vec![1.0; colors.len()]);
        }
        (0..colors.len())
            .map(|i| {
                let r = self.reach_start[i] as usize..self.reach_start[i + 1] as usize;
                let mut v = [0.0f32; 3];
                let mut d = 0.0f32;
                for (&j, &g) in self.reach[r.clone()].iter().zip(&self.footprint[r]) {
                    let c = colors[j as usize];
                    for k in 0..3 {
                        v[k] += g * c[k];
                    }
                    d += g;
                }
                (v, d.max(1.0))
            })
            .unzip()
    }

    /// One pass of spec §7.2.1.
    fn pass(&self, colors: &[[f32; 3]], d: &Denoise) -> Vec<[f32; 3]> {
        let (v, dens) = self.values(colors);
        let h = 0.5 / (d.range * d.range);
        (0..colors.len())
            .map(|i| {
                let (idx, aff) = self.near(i);
                let mut t = [0.0f32; 3];
                let mut s = 1.0f32;
                for (&j, &a) in idx.iter().zip(aff) {
                    let vj = v[j as usize];
                    let dv = [vj[0] - v[i][0], vj[1] - v[i][1], vj[2] - v[i][2]];
                    let dist = dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2];
                    let w = a * (-(dist * h)).exp();
                    s += w;
                    for k in 0..3 {
                        t[k] += w * dv[k];
                    }
                }
                std::array::from_fn(|k| colors[i][k] + d.strength * t[k] / (s * dens[i]))
            })
            .collect()
    }

    /// `colors` after the passes of `d`.
    pub fn denoise(&self, colors: &[[f32; 3]], d: &Denoise) -> Vec<[f32; 3]> {
        let mut c = colors.to_vec();
        for _ in 0..d.passes {
            c = self.pass(&c, d);
        }
        c
    }

    /// How far a centre's value typically strays from its neighbours' (affinity-weighted
    /// mean, over every channel): 1.4826 × the median absolute difference, which is the
    /// standard deviation were the strays Gaussian noise. Texture counts too, so it
    /// over-states the noise of a detailed image; the range is set from it with that in
    /// mind. 0 where no Gaussian has a neighbour.
    #[cfg(feature = "encode")]
    pub fn spread(&self, colors: &[[f32; 3]]) -> f32 {
        let (v, _) = self.values(colors);
        let mut dev = Vec::with_capacity(3 * v.len());
        for (i, vi) in v.iter().enumerate() {
            let (idx, aff) = self.near(i);
            let total: f32 = aff.iter().sum();
            if total <= 0.0 {
                continue;
            }
            for k in 0..3 {
                let m: f32 = idx
                    .iter()
                    .zip(aff)
                    .map(|(&j, &a)| a * v[j as usize][k])
                    .sum();
                dev.push((vi[k] - m / total).abs());
            }
        }
        if dev.is_empty() {
            return 0.0;
        }
        let mid = dev.len() / 2;
        let (_, m, _) = dev.select_nth_unstable_by(mid, f32::total_cmp);
        1.4826 * *m
    }
}

/// The neighbours of `scene` for a step (`what`, for the error) over `colors`, which
/// must be one per Gaussian.
pub(crate) fn neighbours_for(
    scene: &Scene,
    colors: &[[f32; 3]],
    limits: &Limits,
    what: &str,
) -> Result<Neighbours> {
    if colors.len() != scene.gaussians.len() {
        return Err(Error::new(
            ErrorKind::InvalidValue,
            format!("{what}: not one colour per Gaussian"),
        ));
    }
    Neighbours::new(scene, limits)
}

/// `colors` of `scene` denoised by `d` (spec §7.2.1).
pub fn denoise(
    scene: &Scene,
    colors: &[[f32; 3]],
    d: &Denoise,
    limits: &Limits,
) -> Result<Vec<[f32; 3]>> {
    Ok(neighbours_for(scene, colors, limits, "denoise")?.denoise(colors, d))
}

/// How stage 2 chooses the denoising it stores: the range as a multiple of the scene's
/// [`Neighbours::spread`], and the strength and passes as they are.
#[cfg(feature = "encode")]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DenoiseOptions {
    pub range_spreads: f32,
    pub strength: f32,
    pub passes: u8,
}

/// One pass, because the tone curve follows: with it, a second pass cost the synthetic
/// Kodak set 0.21 dB and 0.007 SSIM and eval15 0.02 dB, flattening dark texture that the
/// curve then lifts into view (BENCHMARKS.md); 2 passes were chosen without it.
#[cfg(feature = "encode")]
impl Default for DenoiseOptions {
    fn default() -> Self {
        DenoiseOptions {
            range_spreads: 2.0,
            strength: 1.0,
            passes: 1,
        }
    }
}

#[cfg(feature = "encode")]
impl DenoiseOptions {
    /// The stored settings for a scene with these neighbours and colours: `None` where
    /// there is nothing to smooth (no Gaussian has a neighbour, or all agree) or the
    /// options ask for nothing.
    pub fn resolve(&self, nb: &Neighbours, colors: &[[f32; 3]]) -> Option<Denoise> {
        let range = self.range_spreads * nb.spread(colors);
        let d = Denoise {
            range: range.min(gsi_format::contract::COLOR_MAX),
            strength: self.strength.min(1.0),
            passes: self.passes.min(gsi_format::format::MAX_DENOISE_PASSES),
        };
        (d.range > 0.0 && d.strength > 0.0 && d.passes > 0).then_some(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::model::{CovParam, GaussianSet};
    use gsi_synth::{random_scene, SceneSpec};

    fn scene(w: u32, h: u32, blend: Blend, g: Vec<([f32; 2], [f32; 3], [f32; 3])>) -> Scene {
        Scene {
            weights: gsi_format::model::WeightRule::PerPixel,
            tone: None,
            width: w,
            height: h,
            blend,
            cov_param: CovParam::Cholesky,
            gaussians: GaussianSet {
                positions: g.iter().map(|x| x.0).collect(),
                cov: g.iter().map(|x| x.1).collect(),
                colors: g.iter().map(|x| x.2).collect(),
                opacity: None,
            },
        }
    }

    fn run(s: &Scene, d: Denoise) -> Vec<[f32; 3]> {
        denoise(s, &s.gaussians.colors, &d, &Limits::default()).unwrap()
    }

    /// The example of spec §7.2.1, to its seven printed digits.
    #[test]
    fn denoise_worked_example() {
        let l = [0.125, 0.0, 0.125];
        let s = scene(
            16,
            16,
            Blend::Sum,
            vec![([0.25, 0.5], l, [0.5; 3]), ([0.375, 0.5], l, [0.3; 3])],
        );
        let out = run(
            &s,
            Denoise {
                range: 0.5,
                strength: 1.0,
                passes: 1,
            },
        );
        for (c, want) in out.iter().zip([0.4774895f32, 0.3225105]) {
            for x in c {
                assert!((x - want).abs() < 2e-7, "{x} vs {want}");
            }
        }
    }

    /// A regular grid of like Gaussians over two flat halves (0.2 and 0.6) with noise:
    /// the noise shrinks, the step between the halves stays.
    #[cfg(feature = "encode")]
    #[test]
    fn noise_shrinks_and_the_edge_stays() {
        for blend in [Blend::Sum, Blend::Alpha] {
            let mut rng = gsi_synth::SplitMix64::new(5);
            let mut g = Vec::new();
            for y in 0..16 {
                for x in 0..16 {
                    let base = if x < 8 { 0.2 } else { 0.6 };
                    let c = base + rng.range(-0.02, 0.02);
                    let pos = [(x as f32 + 0.5) / 16.0, (y as f32 + 0.5) / 16.0];
                    g.push((pos, [2.5 / 64.0, 0.0, 2.5 / 64.0], [c; 3]));
                }
            }
            let s = scene(64, 64, blend, g);
            let nb = Neighbours::new(&s, &Limits::default()).unwrap();
            let before = nb.values(&s.gaussians.colors).0;
            let d = DenoiseOptions::default()
                .resolve(&nb, &s.gaussians.colors)
                .unwrap();
            let after = nb.values(&nb.denoise(&s.gaussians.colors, &d)).0;
            // Spread of the values within each half, away from the border columns.
            let spread = |v: &[[f32; 3]]| {
                let mut dev = 0.0f32;
                let mut means = [0.0f32; 2];
                for (mean, cols) in means.iter_mut().zip([1..6, 10..15]) {
                    let vals: Vec<f32> = (1..15)
                        .flat_map(|y| cols.clone().map(move |x| y * 16 + x))
                        .map(|i| v[i][0])
                        .collect();
                    let m = vals.iter().sum::<f32>() / vals.len() as f32;
                    dev += vals.iter().map(|x| (x - m).abs()).sum::<f32>() / vals.len() as f32;
                    *mean = m;
                }
                (dev, means)
            };
            let (dev0, m0) = spread(&before);
            let (dev1, m1) = spread(&after);
            assert!(dev1 < 0.75 * dev0, "{blend:?}: spread {dev0} -> {dev1}");
            let step = |m: [f32; 2]| m[1] - m[0];
            assert!(
                (step(m1) - step(m0)).abs() < 0.02 * step(m0).abs(),
                "{blend:?}: step {} -> {}",
                step(m0),
                step(m1)
            );
        }
    }

    #[test]
    fn equal_colours_in_alpha_blending_are_left_as_they_are() {
        let s = random_scene(3, SceneSpec::new(40, 30, 80, Blend::Alpha));
        let flat = Scene {
            gaussians: GaussianSet {
                colors: vec![[0.3, 0.1, 0.7]; 80],
                ..s.gaussians.clone()
            },
            ..s
        };
        let d = Denoise {
            range: 0.1,
            strength: 1.0,
            passes: 3,
        };
        assert_eq!(run(&flat, d), flat.gaussians.colors);
    }

    /// Singular, vanishing and enormous covariances, centres far outside, no Gaussians:
    /// finite colours, never a panic.
    #[test]
    fn degenerate_scenes_stay_finite() {
        let cov = [
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [16.0, -16.0, 16.0],
            [1e-20, 0.0, 1e-20],
            [0.3, 0.3, 0.0],
        ];
        let pos = [
            [0.5, 0.5],
            [-40.0, 0.5],
            [0.5, 90.0],
            [0.25, 0.25],
            [0.5, 0.5],
        ];
        for blend in [Blend::Sum, Blend::Alpha] {
            let g = (0..25)
                .map(|i| (pos[i % 5], cov[i / 5], [i as f32 * 0.1 - 1.0, 0.5, 64.0]))
                .collect();
            let s = scene(1, 1, blend, g);
            let d = Denoise {
                range: 64.0,
                strength: 1.0,
                passes: 8,
            };
            assert!(run(&s, d).iter().flatten().all(|x| x.is_finite()));
            assert!(run(&scene(5, 3, blend, Vec::new()), d).is_empty());
        }
    }

    #[test]
    fn a_scene_past_the_memory_limit_is_refused() {
        let s = random_scene(4, SceneSpec::new(64, 64, 400, Blend::Sum));
        let tight = Limits {
            max_alloc: 8 * 1000,
            ..Limits::default()
        };
        let e = Neighbours::new(&s, &tight).err().expect("refused");
        assert_eq!(e.kind(), ErrorKind::LimitExceeded);
        assert!(Neighbours::new(&s, &Limits::default()).is_ok());
    }
}
