//! The `sum` rasterizer's inner loops for fitting, eight pixels of a tile row at a time.
//!
//! They walk tiles as the decoder's loops do ([`gsi_render::render::lanes`]: the same
//! [`Footprint`] and masks, the same polynomial `exp` of spec §6.3), and add the
//! fit's own needs: the alphas a forward pass keeps for its backward pass ([`forward_tile`]'s
//! `kept`, used by [`super::raster::step_l2_sum`]), and the backward pass itself.
//!
//! On x86-64 the loops are compiled a second time, for AVX2 with fused multiply-adds
//! ([`mla`]), picked at run time where the CPU has both (Intel since 2013, AMD since
//! 2015). The backward pass fuses its sums: a fused multiply-add is one correctly
//! rounded operation, so the portable loops with `F` give its bits on any CPU (the test
//! checks it), and a fit is the same on every CPU that runs the same build. The forward
//! pass does not fuse: it does the decoder's operations in the decoder's order (spec §6),
//! so the fit renders the pixels the per-pixel rule decodes, bit for bit, and LLVM
//! vectorizes it whole, where with `mul_add` in the polynomial of `exp` it left most lanes
//! scalar (kodim23 at 1 bpp, whole encode: 11.8 → 9.3 s of CPU with the chunk-rows below
//! the cut-off skipped as well). Between the portable and the AVX2 build, files differ
//! by the backward pass's rounding (the PSNR by hundredths of a dB). An encoder promises
//! no more.

use gsi_render::render::lanes::{mla, Footprint, LANES, V};
use gsi_render::render::{Projected, Rect, TILE};

const TILE_W: usize = TILE as usize;
/// Gradient of the loss with respect to one projected Gaussian.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProjGrad {
    pub mean: [f32; 2],
    /// With respect to `(A, B, C)` of `power = -0.5(A dx² + C dy²) - B dx dy`.
    pub conic: [f32; 3],
    pub opacity: f32,
    pub color: [f32; 3],
}

impl ProjGrad {
    /// From the flat layout of a GPU gradient slot (`gsi::gpu::Gpu::backward`): d mean (2),
    /// d conic (3), d opacity, d colour (3).
    pub fn from_slot(g: &[f32; 9]) -> ProjGrad {
        ProjGrad {
            mean: [g[0], g[1]],
            conic: [g[2], g[3], g[4]],
            opacity: g[5],
            color: [g[6], g[7], g[8]],
        }
    }

    /// The flat layout of [`ProjGrad::from_slot`].
    pub fn to_slot(&self) -> [f32; 9] {
        let [mx, my] = self.mean;
        let [a, b, c] = self.conic;
        let [r, g, bl] = self.color;
        [mx, my, a, b, c, self.opacity, r, g, bl]
    }

    pub(super) fn add(&mut self, o: &ProjGrad) {
        for k in 0..2 {
            self.mean[k] += o.mean[k];
        }
        for k in 0..3 {
            self.conic[k] += o.conic[k];
            self.color[k] += o.color[k];
        }
        self.opacity += o.opacity;
    }
}

/// Pixels of a tile.
const TILE_PIXELS: usize = TILE_W * TILE_W;

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
        let n = (rect.x1 - rect.x0) as usize;
        for j in rect.y0..rect.y1 {
            let at = ((j - rect.y0) as usize * width as usize + rect.x0 as usize) * 3;
            let l0 = (j - rect.y0) as usize * TILE_W;
            let [r, g, b] = [&self.0[0], &self.0[1], &self.0[2]].map(|p| &p[l0..l0 + n]);
            for (k, px) in rows[at..at + n * 3].chunks_exact_mut(3).enumerate() {
                px.copy_from_slice(&[r[k], g[k], b[k]]);
            }
        }
    }
}

/// Most Gaussians in a tile list whose alphas a fused step keeps ([`forward_tile`]'s
/// `kept`): each keeps at most a tile's worth (1 KiB), so a thread holds at most 16 MiB;
/// a longer list (Gaussians far larger than tiles) is evaluated again instead.
pub(super) const KEPT_LIST_MAX: usize = 16 * 1024;

/// Σ of the lanes, in lane order.
#[inline(always)]
fn total(v: &V) -> f32 {
    v.iter().fold(0.0, |s, x| s + x)
}

/// With `KEEP`, the alphas are appended to `kept` as they are computed.
#[inline(always)]
fn forward_generic<const KEEP: bool>(
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
            let column = f.column(chunk);
            for j in f.ys.clone() {
                let dy = (j as f32 + 0.5) - g.mean[1];
                let Some(alpha) = f.column_alphas(&column, dy) else {
                    // Every alpha is 0: adding nothing leaves the sums as they are.
                    if KEEP {
                        kept.extend_from_slice(&[0.0; LANES]);
                    }
                    continue;
                };
                if KEEP {
                    kept.extend_from_slice(&alpha);
                }
                let at = (j - rect.y0) as usize * TILE_W + chunk * LANES;
                for (ch, plane) in acc.0.iter_mut().enumerate() {
                    let px = &mut plane[at..at + LANES];
                    for l in 0..LANES {
                        px[l] = mla::<false>(g.color[ch], alpha[l], px[l]);
                    }
                }
            }
        }
    }
}

/// The gradient sums of one Gaussian over a tile, before the chain rule's constants:
/// `color[ch] = Σ alpha·d[ch]` and, with `q = alpha·(colour · d)`, `mean` and `conic`
/// as in [`ProjGrad`], `opacity = Σ q / o`. With `KEPT`, the alphas are
/// read from `kept`, the stream the forward pass over this tile kept.
#[inline(always)]
fn backward_generic<const ALL: bool, const KEPT: bool, const F: bool>(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    d: &Planes,
    out: &mut [ProjGrad],
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
            let column = f.column(chunk);
            let dx = column.dx;
            for j in f.ys.clone() {
                let dy = (j as f32 + 0.5) - g.mean[1];
                let alpha: V = if KEPT {
                    // The forward pass kept a chunk for every chunk and row walked here.
                    let a = kept.next().unwrap_or(&[0.0; LANES][..]);
                    std::array::from_fn(|l| a[l])
                } else {
                    match f.column_alphas(&column, dy) {
                        Some(alpha) => alpha,
                        None => continue,
                    }
                };
                let at = (j - rect.y0) as usize * TILE_W + chunk * LANES;
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
        *slot = ProjGrad {
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
    forward_any(list, proj, rect, acc, kept)
}

/// The gradient of each Gaussian of `list` over tile `rect` (`out[i]` for `list[i]`),
/// given `d`, the loss's gradient with respect to the tile's pixels; colours only unless
/// `all`. `kept`: the alphas the forward pass over this tile kept, if it did.
pub(super) fn backward_tile(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    d: &Planes,
    out: &mut [ProjGrad],
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
fn forward_any(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    acc: &mut Planes,
    kept: Option<&mut Vec<f32>>,
) {
    match kept {
        Some(kept) => forward_generic::<true>(list, proj, rect, acc, kept),
        None => forward_generic::<false>(list, proj, rect, acc, &mut Vec::new()),
    }
}

/// [`backward_generic`] with its switches picked at run time.
#[inline(always)]
fn backward_any<const F: bool>(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    d: &Planes,
    out: &mut [ProjGrad],
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
    use crate::fit::lanes::ProjGrad;

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
        forward_any(list, proj, rect, acc, kept)
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
    use crate::fit::lanes::ProjGrad;

    /// A tile's forward pass (image and kept alphas) and its backward passes (all
    /// gradients and colours only) for `d`, the backward in the build `F`; `keep` decides
    /// whether the backward passes read the kept alphas.
    fn tile_passes<const F: bool>(
        list: &[u32],
        proj: &[Projected],
        rect: Rect,
        d: &Planes,
        keep: bool,
    ) -> (Planes, Vec<f32>, [Vec<ProjGrad>; 2]) {
        let mut acc = Planes::zero();
        let mut kept = Vec::new();
        forward_any(list, proj, rect, &mut acc, Some(&mut kept));
        let grads = [true, false].map(|all| {
            let mut out = vec![ProjGrad::default(); list.len()];
            let k = keep.then_some(&kept[..]);
            backward_any::<F>(list, proj, rect, d, &mut out, all, k);
            out
        });
        (acc, kept, grads)
    }

    /// The module's promises: the forward pass gives the decoder's pixels (the per-pixel
    /// rule in its plainest form, [`Projected::alpha_at`], summed in list order) bit for
    /// bit, in the portable build and the SIMD one; the alphas kept by a forward pass give
    /// the backward pass the bits of a fresh evaluation; the SIMD backward pass gives the
    /// bits of the portable loops with fused multiply-adds (each is one correctly rounded
    /// operation whoever computes it); and fusing moves the gradients by rounding alone.
    #[test]
    fn the_builds_and_the_kept_alphas_agree() {
        use gsi_format::model::Blend;
        use gsi_render::render::{project_scene, TileLists};
        use gsi_synth::{random_scene, SceneSpec, SplitMix64};
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
        let mut lit = 0;
        for t in 0..tiles.len() {
            let rect = Rect::of_tile(t, tiles.tiles_x, w, h);
            let list = tiles.list(t);
            let mut d = Planes::zero();
            d.0.iter_mut()
                .flatten()
                .for_each(|v| *v = rng.range(-1.0, 1.0));
            let plain = tile_passes::<false>(list, &proj, rect, &d, false);
            for j in rect.y0..rect.y1 {
                for i in rect.x0..rect.x1 {
                    let mut want = [0f32; 3];
                    for &k in list {
                        let g = &proj[k as usize];
                        if let Some(a) = g.alpha_at(i, j, Blend::Sum) {
                            for (w, c) in want.iter_mut().zip(g.color) {
                                *w += c * a;
                            }
                        }
                    }
                    let at = ((j - rect.y0) * TILE + i - rect.x0) as usize;
                    let got = [0, 1, 2].map(|ch| plain.0 .0[ch][at]);
                    assert!(got == want, "tile {t}, pixel ({i}, {j}): {got:?} {want:?}");
                    lit += usize::from(want != [0.0; 3]);
                }
            }
            let plain_kept = tile_passes::<false>(list, &proj, rect, &d, true);
            assert!(plain.2 == plain_kept.2, "tile {t}: kept alphas, unfused");
            let fused = tile_passes::<true>(list, &proj, rect, &d, false);
            let fused_kept = tile_passes::<true>(list, &proj, rect, &d, true);
            assert!(fused.2 == fused_kept.2, "tile {t}: kept alphas, fused");
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
                    acc.0 == plain.0 .0 && kept == plain.1,
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
        assert!(lit > (w * h) as usize / 2, "the scene lights {lit} pixels");
    }
}
