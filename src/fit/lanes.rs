//! The `sum` rasterizer's inner loops for fitting, eight pixels of a tile row at a time.
//!
//! A fitting step evaluates `alpha = o·exp(power)` for every pixel a Gaussian touches,
//! and that was three quarters of its time: the decoder's
//! loops ([`crate::render`]) follow spec §6 one pixel at a time, branch per pixel and call
//! the platform's `exp`, which keeps them scalar. A fit does not need the decoder's bits,
//! only its values (the stored file is measured with the decoder at the end), so here a
//! row of a tile is cut into chunks of [`LANES`] pixels, branches become masks, and `exp`
//! is a polynomial ([`exp`]) that the compiler can put in SIMD registers.
//!
//! On x86-64 the loops are compiled a second time, for AVX2 with fused multiply-adds
//! ([`mla`]), picked at run time where the CPU has both (Intel since 2013, AMD since
//! 2015); a kodim05 encode ran 1.35× faster than with unfused AVX2. A fused
//! multiply-add is one correctly rounded operation, so the portable loops with `F` give
//! its bits on any CPU (the test checks it), and a fit is the same on every CPU that
//! runs the same build; between the fused and the unfused build, files differ by
//! rounding (the PSNR by hundredths of a dB). An encoder promises no more: the decoder's
//! loops, which define the pixels, stay unfused (spec §6).
//!
//! The backward pass can read the alphas its forward pass kept ([`forward_tile`]'s
//! `kept`, used by [`super::raster::step_l2_sum`]) instead of evaluating them again.
//!
//! The masks keep the rule of [`Projected::alpha_at`]: inside the pixel box,
//! `power <= 0` and above the cut-off, `alpha >= ALPHA_MIN`. Only `exp` differs (by
//! less than 2e-7 relative), which can move a pixel across `ALPHA_MIN` where the decoder
//! is exactly on it.

use crate::contract::ALPHA_MIN;
use crate::render::{Projected, Rect, TILE};

/// Pixels per chunk: one AVX register of `f32`, two SSE ones.
const LANES: usize = 8;
const TILE_W: usize = TILE as usize;
/// Pixels of a tile.
pub(super) const TILE_PIXELS: usize = TILE_W * TILE_W;

type V = [f32; LANES];

/// One tile in three planes (R, G, B), row-major, [`TILE`] pixels a row whatever the
/// tile's real width.
#[derive(Clone)]
pub(super) struct Planes(pub [[f32; TILE_PIXELS]; 3]);

impl Planes {
    pub fn zero() -> Planes {
        Planes([[0.0; TILE_PIXELS]; 3])
    }

    pub fn ones() -> Planes {
        Planes([[1.0; TILE_PIXELS]; 3])
    }

    /// The tile `rect` of an interleaved RGB image `width` pixels wide.
    pub fn gather(image: &[f32], width: u32, rect: Rect) -> Planes {
        let mut p = Planes::zero();
        for j in rect.y0..rect.y1 {
            let row = (j * width) as usize;
            let l0 = ((j - rect.y0) * TILE) as usize;
            for (n, i) in (rect.x0..rect.x1).enumerate() {
                for ch in 0..3 {
                    p.0[ch][l0 + n] = image[(row + i as usize) * 3 + ch];
                }
            }
        }
        p
    }

    /// Write the tile into `rows`, the interleaved RGB pixel rows of an image `width`
    /// pixels wide from row `rect.y0` on.
    pub fn scatter(&self, rows: &mut [f32], width: u32, rect: Rect) {
        for j in rect.y0..rect.y1 {
            let row = ((j - rect.y0) * width) as usize;
            let l0 = ((j - rect.y0) * TILE) as usize;
            for (n, i) in (rect.x0..rect.x1).enumerate() {
                for ch in 0..3 {
                    rows[(row + i as usize) * 3 + ch] = self.0[ch][l0 + n];
                }
            }
        }
    }
}

/// `e^x` for `x` in `[-87, 0]` (larger arguments are clamped into it), within 2e-7
/// relative: `x = n·ln 2 + r` with `|r| <= ln 2 / 2`, a degree-7 polynomial for `e^r`
/// (Cephes' `expf` coefficients, S. L. Moshier), and `2^n` built in the exponent bits.
/// Branch-free and without calls, so a loop over lanes vectorizes. With `F`, the
/// products and sums are fused ([`mla`]).
#[inline(always)]
pub(super) fn exp<const F: bool>(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5·2^23: adding it rounds to an integer and leaves that integer in the low
    // mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 0.0);
    let k = mla::<F>(x, LOG2E, ROUND);
    let n = k - ROUND;
    let r = mla::<F>(-n, LN2_LO, mla::<F>(-n, LN2_HI, x));
    let p = 1.987_569_1e-4;
    let p = mla::<F>(p, r, 1.398_199_9e-3);
    let p = mla::<F>(p, r, 8.333_452e-3);
    let p = mla::<F>(p, r, 4.166_579_6e-2);
    let p = mla::<F>(p, r, 1.666_666_5e-1);
    let p = mla::<F>(p, r, 5e-1);
    let er = mla::<F>(p * r, r, r) + 1.0;
    let shift = (k.to_bits() as i32).wrapping_sub(ROUND.to_bits() as i32);
    let scale = f32::from_bits(((shift + 127) as u32) << 23);
    er * scale
}

/// `a·b + c`: with `F` in one rounding (a fused multiply-add, for builds where the CPU
/// has one), else in two. Every product-and-sum of the loops goes through here, so the
/// build without `F` does the operations of the plain expressions, in the same order.
#[inline(always)]
fn mla<const F: bool>(a: f32, b: f32, c: f32) -> f32 {
    if F {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// One Gaussian over the part of a tile it touches.
struct Footprint<'g> {
    g: &'g Projected,
    cut: f32,
    /// Tile-local columns `lx0..lx1` and pixel rows `ys` of its box in the tile.
    lx0: usize,
    lx1: usize,
    ys: std::ops::Range<u32>,
    /// Pixel column of the tile's first column.
    x0: u32,
}

impl Footprint<'_> {
    /// `None` where the box misses the tile, or where the ellipse in which `power`
    /// reaches the cut-off misses the tile's part of the box: the box is square to the
    /// axes, and a rotated, elongated Gaussian leaves whole tiles of it untouched.
    fn of<'g>(g: &'g Projected, rect: Rect) -> Option<Footprint<'g>> {
        let (xs, ys) = g.bbox.clip(rect)?;
        let cut = g.cutoff();
        // Offsets from the centre of the first and last pixel centres.
        let dxs = [
            xs.start as f32 + 0.5 - g.mean[0],
            (xs.end - 1) as f32 + 0.5 - g.mean[0],
        ];
        let dys = [
            ys.start as f32 + 0.5 - g.mean[1],
            (ys.end - 1) as f32 + 0.5 - g.mean[1],
        ];
        // `-2·power`'s least value over those pixels, as a continuous rectangle (1e-3
        // looser than the cut-off against rounding).
        if q_min(g.conic, dxs, dys) > -2.0 * cut + 1e-3 {
            return None;
        }
        Some(Footprint {
            g,
            cut,
            lx0: (xs.start - rect.x0) as usize,
            lx1: (xs.end - rect.x0) as usize,
            ys,
            x0: rect.x0,
        })
    }

    /// The chunks of a tile row that the box meets, each with the mask of its columns
    /// inside the box. (Narrowing them row by row to where the ellipse reaches the
    /// cut-off was tried: a square root and two divisions per row cost more than the
    /// lanes they saved.)
    #[inline(always)]
    fn chunks(&self) -> impl Iterator<Item = (usize, [bool; LANES])> + '_ {
        (self.lx0 / LANES..=(self.lx1 - 1) / LANES).map(|c| {
            let mut inside = [false; LANES];
            for (l, m) in inside.iter_mut().enumerate() {
                let col = c * LANES + l;
                *m = (col >= self.lx0) & (col < self.lx1);
            }
            (c, inside)
        })
    }

    /// `(alpha, dx)` on chunk `c` of the row at `dy` from the centre: `alpha` 0 where
    /// the Gaussian does not touch.
    #[inline(always)]
    fn alphas<const F: bool>(&self, (c, inside): (usize, [bool; LANES]), dy: f32) -> (V, V) {
        let g = self.g;
        let [ca, cb, cc] = g.conic;
        let cdy = cc * dy * dy;
        let x0 = (self.x0 as usize + c * LANES) as f32 + 0.5;
        let mut alpha = [0f32; LANES];
        let mut dxs = [0f32; LANES];
        for l in 0..LANES {
            let dx = (x0 + l as f32) - g.mean[0];
            // -0.5·(A dx² + C dy²) − B dx dy
            let power = mla::<F>(-0.5, mla::<F>(ca * dx, dx, cdy), -(cb * dx * dy));
            let a = g.opacity * exp::<F>(power);
            // `&`, not `&&`: every lane evaluates every test, without branches.
            let keep = inside[l] & (power >= self.cut) & (power <= 0.0) & (a >= ALPHA_MIN);
            alpha[l] = if keep { a } else { 0.0 };
            dxs[l] = dx;
        }
        (alpha, dxs)
    }

    /// The offsets from the centre of the columns of chunk `c`, as [`Footprint::alphas`]
    /// computes them.
    #[inline(always)]
    fn dxs(&self, c: usize) -> V {
        let x0 = (self.x0 as usize + c * LANES) as f32 + 0.5;
        std::array::from_fn(|l| (x0 + l as f32) - self.g.mean[0])
    }
}

/// Most Gaussians in a tile list whose alphas a fused step keeps ([`forward_tile`]'s
/// `kept`): each keeps at most a tile's worth (1 KiB), so a thread holds at most 16 MiB;
/// a longer list (Gaussians far larger than tiles) is evaluated again instead.
pub(super) const KEPT_LIST_MAX: usize = 16 * 1024;

/// The least value of `Q = A dx² + 2B dx dy + C dy²` (`-2·power`, a positive definite
/// form) over the rectangle `dx ∈ [dxs[0], dxs[1]]`, `dy ∈ [dys[0], dys[1]]`: 0 when it
/// holds the centre, else on an edge, where `Q` is a parabola minimized in closed form.
fn q_min([a, b, c]: [f32; 3], dxs: [f32; 2], dys: [f32; 2]) -> f32 {
    let holds = |r: [f32; 2]| r[0] <= 0.0 && 0.0 <= r[1];
    if holds(dxs) && holds(dys) {
        return 0.0;
    }
    let q = |x: f32, y: f32| a * x * x + 2.0 * b * x * y + c * y * y;
    let mut least = f32::INFINITY;
    for x in dxs {
        let y = (-b * x / c).clamp(dys[0], dys[1]);
        least = least.min(q(x, y));
    }
    for y in dys {
        let x = (-b * y / a).clamp(dxs[0], dxs[1]);
        least = least.min(q(x, y));
    }
    least
}

/// Σ of the lanes, in lane order.
#[inline(always)]
fn total(v: &V) -> f32 {
    v.iter().fold(0.0, |s, x| s + x)
}

/// With `KEEP`, the alphas are appended to `kept` as they are computed.
#[inline(always)]
fn forward_generic<const KEEP: bool, const F: bool>(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    acc: &mut Planes,
    kept: &mut Vec<f32>,
) {
    for &k in list {
        let g = &proj[k as usize];
        let Some(f) = Footprint::of(g, rect) else {
            continue;
        };
        for chunk in f.chunks() {
            for j in f.ys.clone() {
                let dy = (j as f32 + 0.5) - g.mean[1];
                let (alpha, _) = f.alphas::<F>(chunk, dy);
                if KEEP {
                    kept.extend_from_slice(&alpha);
                }
                let at = (j - rect.y0) as usize * TILE_W + chunk.0 * LANES;
                for (ch, plane) in acc.0.iter_mut().enumerate() {
                    let px = &mut plane[at..at + LANES];
                    for l in 0..LANES {
                        px[l] = mla::<F>(g.color[ch], alpha[l], px[l]);
                    }
                }
            }
        }
    }
}

/// The gradient sums of one Gaussian over a tile, before the chain rule's constants:
/// `color[ch] = Σ alpha·d[ch]` and, with `q = alpha·(colour · d)`, `mean` and `conic`
/// as in [`super::raster::ProjGrad`], `opacity = Σ q / o`. With `KEPT`, the alphas are
/// read from `kept`, the stream the forward pass over this tile kept.
#[inline(always)]
fn backward_generic<const ALL: bool, const KEPT: bool, const F: bool>(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    d: &Planes,
    out: &mut [super::raster::ProjGrad],
    kept: &[f32],
) {
    let [dr, dg, db] = &d.0;
    let mut kept = kept.chunks_exact(LANES);
    for (slot, &k) in out.iter_mut().zip(list) {
        let g = &proj[k as usize];
        let Some(f) = Footprint::of(g, rect) else {
            continue;
        };
        let [ca, cb, cc] = g.conic;
        let col = g.color;
        let z = [0f32; LANES];
        let (mut c0, mut c1, mut c2) = (z, z, z);
        let (mut gx, mut gy, mut ga, mut gb, mut gc, mut go) = (z, z, z, z, z, z);
        for chunk in f.chunks() {
            let dx_kept = f.dxs(chunk.0);
            for j in f.ys.clone() {
                let dy = (j as f32 + 0.5) - g.mean[1];
                let (alpha, dx) = if KEPT {
                    // The forward pass kept a chunk for every chunk and row walked here.
                    let a = kept.next().unwrap_or(&[0.0; LANES][..]);
                    (std::array::from_fn(|l| a[l]), dx_kept)
                } else {
                    f.alphas::<F>(chunk, dy)
                };
                let at = (j - rect.y0) as usize * TILE_W + chunk.0 * LANES;
                let (r, gg, b) = (
                    &dr[at..at + LANES],
                    &dg[at..at + LANES],
                    &db[at..at + LANES],
                );
                for l in 0..LANES {
                    c0[l] = mla::<F>(alpha[l], r[l], c0[l]);
                    c1[l] = mla::<F>(alpha[l], gg[l], c1[l]);
                    c2[l] = mla::<F>(alpha[l], b[l], c2[l]);
                    if ALL {
                        let dot = mla::<F>(col[2], b[l], mla::<F>(col[1], gg[l], col[0] * r[l]));
                        let q = alpha[l] * dot;
                        let x = dx[l];
                        gx[l] = mla::<F>(q, mla::<F>(ca, x, cb * dy), gx[l]);
                        gy[l] = mla::<F>(q, mla::<F>(cb, x, cc * dy), gy[l]);
                        ga[l] = mla::<F>(q * x, x, ga[l]);
                        gb[l] = mla::<F>(q * x, dy, gb[l]);
                        gc[l] = mla::<F>(q * dy, dy, gc[l]);
                        go[l] += q;
                    }
                }
            }
        }
        *slot = super::raster::ProjGrad {
            mean: [total(&gx), total(&gy)],
            conic: [-0.5 * total(&ga), -total(&gb), -0.5 * total(&gc)],
            // d alpha / d o = alpha / o.
            opacity: total(&go) / g.opacity,
            color: [total(&c0), total(&c1), total(&c2)],
        };
    }
}

/// Add the `sum` render of the Gaussians `list` (indices into `proj`, in order) over
/// tile `rect` to `acc`; with `kept`, append the alphas to it for the backward pass.
pub(super) fn forward_tile(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    acc: &mut Planes,
    kept: Option<&mut Vec<f32>>,
) {
    #[cfg(target_arch = "x86_64")]
    if simd::available() {
        // SAFETY: the CPU has the features, checked just above.
        return unsafe { simd::forward(list, proj, rect, acc, kept) };
    }
    forward_any::<false>(list, proj, rect, acc, kept)
}

/// The gradient of each Gaussian of `list` over tile `rect` (`out[i]` for `list[i]`),
/// given `d`, the loss's gradient with respect to the tile's pixels; colours only unless
/// `all`. `kept`: the alphas the forward pass over this tile kept, if it did.
pub(super) fn backward_tile(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    d: &Planes,
    out: &mut [super::raster::ProjGrad],
    all: bool,
    kept: Option<&[f32]>,
) {
    #[cfg(target_arch = "x86_64")]
    if simd::available() {
        // SAFETY: the CPU has the features, checked just above.
        return unsafe { simd::backward(list, proj, rect, d, out, all, kept) };
    }
    backward_any::<false>(list, proj, rect, d, out, all, kept)
}

/// [`forward_generic`] with its switch picked at run time.
#[inline(always)]
fn forward_any<const F: bool>(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    acc: &mut Planes,
    kept: Option<&mut Vec<f32>>,
) {
    match kept {
        Some(kept) => forward_generic::<true, F>(list, proj, rect, acc, kept),
        None => forward_generic::<false, F>(list, proj, rect, acc, &mut Vec::new()),
    }
}

/// [`backward_generic`] with its switches picked at run time.
#[inline(always)]
fn backward_any<const F: bool>(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    d: &Planes,
    out: &mut [super::raster::ProjGrad],
    all: bool,
    kept: Option<&[f32]>,
) {
    match (all, kept) {
        (true, Some(k)) => backward_generic::<true, true, F>(list, proj, rect, d, out, k),
        (false, Some(k)) => backward_generic::<false, true, F>(list, proj, rect, d, out, k),
        (true, None) => backward_generic::<true, false, F>(list, proj, rect, d, out, &[]),
        (false, None) => backward_generic::<false, false, F>(list, proj, rect, d, out, &[]),
    }
}

/// The same loops compiled for AVX2 with fused multiply-adds (see the module's doc).
#[cfg(target_arch = "x86_64")]
mod simd {
    use super::*;
    use crate::fit::raster::ProjGrad;

    /// Whether the CPU runs this build.
    #[inline]
    pub(super) fn available() -> bool {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn forward(
        list: &[u32],
        proj: &[Projected],
        rect: Rect,
        acc: &mut Planes,
        kept: Option<&mut Vec<f32>>,
    ) {
        forward_any::<true>(list, proj, rect, acc, kept)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn backward(
        list: &[u32],
        proj: &[Projected],
        rect: Rect,
        d: &Planes,
        out: &mut [ProjGrad],
        all: bool,
        kept: Option<&[f32]>,
    ) {
        backward_any::<true>(list, proj, rect, d, out, all, kept)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::raster::ProjGrad;

    fn exp_worst<const F: bool>() -> f64 {
        let mut worst = 0f64;
        let mut x = -87.0f32;
        while x <= 0.0 {
            let want = f64::from(x).exp();
            let got = f64::from(exp::<F>(x));
            worst = worst.max(((got - want) / want).abs());
            x += 1e-3;
        }
        worst
    }

    #[test]
    fn exp_is_within_2e7_relative_over_its_range() {
        for (worst, fused) in [(exp_worst::<false>(), false), (exp_worst::<true>(), true)] {
            assert!(
                worst < 2e-7,
                "fused {fused}: worst relative error {worst:e}"
            );
        }
        assert_eq!(exp::<false>(0.0), 1.0);
        assert_eq!(exp::<true>(0.0), 1.0);
        // Out of range: clamped, never NaN, Inf or negative.
        assert!(exp::<false>(1.0) == 1.0 && exp::<false>(-1e9) > 0.0);
        assert!(exp::<true>(-1e9) < 1e-37 && exp::<true>(-1e9) > 0.0);
    }

    /// A tile's forward pass (image and kept alphas) and its backward passes (all
    /// gradients and colours only) for `d`, in the build `F`; `keep` decides whether the
    /// backward passes read the kept alphas.
    fn tile_passes<const F: bool>(
        list: &[u32],
        proj: &[Projected],
        rect: Rect,
        d: &Planes,
        keep: bool,
    ) -> (Planes, Vec<f32>, [Vec<ProjGrad>; 2]) {
        let mut acc = Planes::zero();
        let mut kept = Vec::new();
        forward_any::<F>(list, proj, rect, &mut acc, Some(&mut kept));
        let grads = [true, false].map(|all| {
            let mut out = vec![ProjGrad::default(); list.len()];
            let k = keep.then_some(&kept[..]);
            backward_any::<F>(list, proj, rect, d, &mut out, all, k);
            out
        });
        (acc, kept, grads)
    }

    /// The module's promises: the alphas kept by a forward pass give the backward pass
    /// the bits of a fresh evaluation; the SIMD build gives the bits of the portable
    /// loops with fused multiply-adds (each is one correctly rounded operation whoever
    /// computes it); and fusing moves the results by rounding alone.
    #[test]
    fn the_builds_and_the_kept_alphas_agree() {
        use crate::model::Blend;
        use crate::render::{project_scene, TileLists};
        use crate::synth::{random_scene, SceneSpec, SplitMix64};
        let (w, h) = (61, 37);
        let scene = random_scene(
            5,
            SceneSpec {
                sigma_px: (0.3, 9.0),
                ..SceneSpec::new(w, h, 300, Blend::Sum)
            },
        );
        let proj = project_scene(&scene, w, h);
        let tiles = TileLists::bin(&proj, w, h);
        let mut rng = SplitMix64::new(3);
        // Sums with cancellation (`d` has both signs): a bound on rounding, far below
        // what a wrong term would move.
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-3 * (1.0 + a.abs().max(b.abs()));
        for t in 0..tiles.len() {
            let rect = Rect::of_tile(t, tiles.tiles_x, w, h);
            let list = tiles.list(t);
            let mut d = Planes::zero();
            d.0.iter_mut()
                .flatten()
                .for_each(|v| *v = rng.range(-1.0, 1.0));
            let plain = tile_passes::<false>(list, &proj, rect, &d, false);
            let plain_kept = tile_passes::<false>(list, &proj, rect, &d, true);
            assert!(plain.2 == plain_kept.2, "tile {t}: kept alphas, unfused");
            let fused = tile_passes::<true>(list, &proj, rect, &d, false);
            let fused_kept = tile_passes::<true>(list, &proj, rect, &d, true);
            assert!(fused.2 == fused_kept.2, "tile {t}: kept alphas, fused");
            let pixels = plain.0 .0.iter().flatten().zip(fused.0 .0.iter().flatten());
            assert!(
                pixels.clone().all(|(a, b)| close(*a, *b)),
                "tile {t}: fused image"
            );
            for (a, b) in plain.2.iter().flatten().zip(fused.2.iter().flatten()) {
                let (a, b) = (a.to_slot(), b.to_slot());
                assert!(
                    a.iter().zip(&b).all(|(x, y)| close(*x, *y)),
                    "tile {t}: {a:?} {b:?}"
                );
            }
            #[cfg(target_arch = "x86_64")]
            if simd::available() {
                let mut acc = Planes::zero();
                let mut kept = Vec::new();
                // SAFETY: the CPU has the features, checked just above.
                unsafe { simd::forward(list, &proj, rect, &mut acc, Some(&mut kept)) };
                assert!(
                    acc.0 == fused.0 .0 && kept == fused.1,
                    "tile {t}: SIMD forward"
                );
                for (all, want) in [true, false].into_iter().zip(&fused.2) {
                    let mut out = vec![ProjGrad::default(); list.len()];
                    // SAFETY: as above.
                    unsafe { simd::backward(list, &proj, rect, &d, &mut out, all, Some(&kept)) };
                    assert!(out == *want, "tile {t}: SIMD backward, all {all}");
                }
            }
        }
    }
}
