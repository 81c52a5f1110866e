//! The tiled CPU rasterizer.
//!
//! Work is split into bands of [`BAND`] pixel rows. Each band owns a contiguous slice of
//! the output, so bands can be rendered on different threads without sharing or
//! `unsafe`. Inside a band, a Gaussian's box is cut to the columns that its ellipse
//! reaches over the band's rows ([`band_columns`]) and the Gaussian binned to the tiles
//! of [`TILE`] columns that they cross; a tile visits its list in stored order and
//! evaluates only the pixels inside both the tile and the cut box. Which thread renders a
//! band never changes the arithmetic, so the parallel and sequential builds give
//! identical bits.

use super::lanes::{Acc, Kernel, TILE_W};
use super::project::{Projected, Rect};
use super::tiles::{band_columns, runs, Bins};
use super::{BAND, TILE};
use gsi_format::model::{Blend, ToneCurve, WeightRule};
use std::sync::Mutex;

/// Most entries of the per-band lists binned at once (64 MiB of indices).
const BAND_BUDGET: u64 = 1 << 24;
/// Most entries of one band's per-tile lists binned at once, per thread (4 MiB).
const TILE_BUDGET: u64 = 1 << 20;
/// What the renderer writes a band of pixels into. Blending happens tile by tile in an
/// `f32` [`Acc`]; each finished tile is stored straight into the output's layout, so that
/// no `f32` copy of a band (nor of the image) is made for an 8-bit output, and no band is
/// cleared, interleaved and converted in passes of its own.
pub trait Output: Sync {
    type Elem: Copy + Send + Sync;
    /// Elements per pixel.
    const PER_PIXEL: usize;
    /// Store the pixels of `rect` (rows from the band's first) from `acc` into `band`, a
    /// band of rows `width` pixels wide.
    fn store(acc: &Acc, band: &mut [Self::Elem], width: u32, rect: Rect);
}

/// `f32` RGB.
pub struct RgbF32;
/// 8-bit RGB by [`super::to_u8`].
pub struct Rgb8;
/// 8-bit RGBA by [`super::to_u8`], alpha 255.
pub struct Rgba8;
/// `f32` RGB as native-endian bytes (12 per pixel), for byte buffers such as `image`'s.
pub struct RgbF32Bytes;

/// Hand each row of `rect` in `acc` to `put`, with the elements of `band` (rows `width`
/// pixels wide, `P` elements a pixel) that its pixels go to.
#[inline(always)]
fn each_row<E, const P: usize>(
    acc: &Acc,
    band: &mut [E],
    width: u32,
    rect: Rect,
    mut put: impl FnMut(&mut [E], [&[f32; TILE_W]; 3]),
) {
    let n = (rect.x1 - rect.x0) as usize;
    for j in 0..(rect.y1 - rect.y0) as usize {
        let at = (j * width as usize + rect.x0 as usize) * P;
        put(&mut band[at..at + n * P], acc.row(j));
    }
}

/// [`each_row`], a pixel at a time: `put` gets the pixel's `P` elements, its column in
/// the tile and the tile's row.
#[inline(always)]
fn each_pixel<E, const P: usize>(
    acc: &Acc,
    band: &mut [E],
    width: u32,
    rect: Rect,
    put: impl Fn(&mut [E; P], usize, [&[f32; TILE_W]; 3]),
) {
    each_row::<E, P>(acc, band, width, rect, |out, row| {
        for (k, px) in out.chunks_exact_mut(P).enumerate() {
            put(px.try_into().expect("P elements"), k, row);
        }
    });
}

impl Output for RgbF32 {
    type Elem = f32;
    const PER_PIXEL: usize = 3;
    #[inline(always)]
    fn store(acc: &Acc, band: &mut [f32], width: u32, rect: Rect) {
        each_pixel::<_, 3>(acc, band, width, rect, |px, k, [r, g, b]| {
            *px = [r[k], g[k], b[k]];
        });
    }
}

impl Output for Rgb8 {
    type Elem = u8;
    const PER_PIXEL: usize = 3;
    #[inline(always)]
    fn store(acc: &Acc, band: &mut [u8], width: u32, rect: Rect) {
        #[cfg(target_arch = "x86_64")]
        let ssse3 = std::is_x86_feature_detected!("ssse3");
        each_row::<_, 3>(acc, band, width, rect, |out, row| {
            #[cfg(target_arch = "x86_64")]
            if let (true, Ok(out)) = (ssse3, <&mut [u8; 3 * TILE_W]>::try_from(&mut *out)) {
                // SAFETY: the CPU has SSSE3 (checked above).
                unsafe { x86::rgb8_row(row, out) };
                return;
            }
            for (k, px) in out.chunks_exact_mut(3).enumerate() {
                px.copy_from_slice(&row.map(|p| super::to_u8(p[k])));
            }
        });
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::TILE_W;
    use std::arch::x86_64::*;

    /// For output byte `p` of 16-byte block `b` of an interleaved RGB row of [`TILE_W`]
    /// pixels, the byte of plane `c` it takes: `[b][c][p]`, −128 (a zero) where it takes
    /// another plane's.
    const INTERLEAVE: [[[i8; 16]; 3]; 3] = {
        let mut m = [[[-128i8; 16]; 3]; 3];
        let mut i = 0;
        while i < 3 * TILE_W {
            m[i / 16][i % 3][i % 16] = (i / 3) as i8;
            i += 1;
        }
        m
    };

    /// A full tile row of the three planes as 8-bit RGB: [`super::super::to_u8`]'s
    /// operations (max with 0 first, so that NaN gives 0; min with 1; ×255; +0.5;
    /// truncation), four values at a time, then the planes interleaved by byte
    /// shuffles. (Left to the compiler, the conversion or the interleaving came out a
    /// value at a time: 7–10 % of a single-thread render of kodim23, against 3.9 % here.)
    /// No closures: they would be compiled without SSSE3, a call per intrinsic.
    #[target_feature(enable = "ssse3")]
    pub fn rgb8_row(planes: [&[f32; TILE_W]; 3], out: &mut [u8; 3 * TILE_W]) {
        const _: () = assert!(TILE_W == 16);
        // SAFETY: every load and store is of 16 bytes within its array.
        unsafe {
            let (zero, one) = (_mm_setzero_ps(), _mm_set1_ps(1.0));
            let (scale, half) = (_mm_set1_ps(255.0), _mm_set1_ps(0.5));
            let mut bytes = [_mm_setzero_si128(); 3];
            for (b, p) in bytes.iter_mut().zip(planes) {
                let mut ints = [_mm_setzero_si128(); 4];
                for (k, i) in ints.iter_mut().enumerate() {
                    let v = _mm_loadu_ps(p[4 * k..].as_ptr());
                    let v = _mm_min_ps(_mm_max_ps(v, zero), one);
                    *i = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(v, scale), half));
                }
                let lo = _mm_packs_epi32(ints[0], ints[1]);
                let hi = _mm_packs_epi32(ints[2], ints[3]);
                *b = _mm_packus_epi16(lo, hi);
            }
            for (k, [mr, mg, mb]) in INTERLEAVE.iter().enumerate() {
                let mr = _mm_loadu_si128(mr.as_ptr().cast::<__m128i>());
                let mg = _mm_loadu_si128(mg.as_ptr().cast::<__m128i>());
                let mb = _mm_loadu_si128(mb.as_ptr().cast::<__m128i>());
                let rg = _mm_or_si128(
                    _mm_shuffle_epi8(bytes[0], mr),
                    _mm_shuffle_epi8(bytes[1], mg),
                );
                let rgb = _mm_or_si128(rg, _mm_shuffle_epi8(bytes[2], mb));
                _mm_storeu_si128(out[16 * k..].as_mut_ptr().cast::<__m128i>(), rgb);
            }
        }
    }
}

impl Output for Rgba8 {
    type Elem = u8;
    const PER_PIXEL: usize = 4;
    #[inline(always)]
    fn store(acc: &Acc, band: &mut [u8], width: u32, rect: Rect) {
        let to_u8 = super::to_u8;
        each_pixel::<_, 4>(acc, band, width, rect, |px, k, [r, g, b]| {
            *px = [to_u8(r[k]), to_u8(g[k]), to_u8(b[k]), 255];
        });
    }
}

impl Output for RgbF32Bytes {
    type Elem = u8;
    const PER_PIXEL: usize = 12;
    #[inline(always)]
    fn store(acc: &Acc, band: &mut [u8], width: u32, rect: Rect) {
        each_pixel::<_, 12>(acc, band, width, rect, |px, k, [r, g, b]| {
            for (o, c) in px.chunks_exact_mut(4).zip([r[k], g[k], b[k]]) {
                o.copy_from_slice(&c.to_ne_bytes());
            }
        });
    }
}

/// Render projected Gaussians (in stored order) into `out`, `width * height` pixels of
/// `O`'s layout, weighed and blended as `blend` (the blend mode, the weight rule) says,
/// every blended value through `tone` where there is one (spec §6.6).
pub fn render_projected<O: Output>(
    proj: &[Projected],
    blend: (Blend, WeightRule),
    tone: Option<&ToneCurve>,
    (width, height): (u32, u32),
    out: &mut [O::Elem],
    parallel: bool,
) {
    let how = (parallel, Kernel::detect(), (BAND_BUDGET, TILE_BUDGET));
    let whole = render_with::<O>(proj, blend, tone, (width, height), out, None, how);
    debug_assert!(whole.is_ok(), "no sink, no error");
}

/// Where the rows of a render go when they are not left in one whole-image buffer.
pub type Sink<'a, T> = &'a mut dyn FnMut(&[T]) -> std::io::Result<()>;

/// [`render_projected`] a few bands at a time: `window` holds a whole number of bands
/// (at least one) of `O`'s layout, and `sink` gets its rows, top to bottom, after each
/// step; the first error from `sink` stops the render and is returned. Memory then
/// follows the window, not the output: a 12 MP decode written as it is rendered never
/// holds its 36 MB, nor faults their pages in.
pub fn render_projected_rows<O: Output>(
    proj: &[Projected],
    blend: (Blend, WeightRule),
    tone: Option<&ToneCurve>,
    (width, height): (u32, u32),
    window: &mut [O::Elem],
    parallel: bool,
    sink: Sink<'_, O::Elem>,
) -> std::io::Result<()> {
    let how = (parallel, Kernel::detect(), (BAND_BUDGET, TILE_BUDGET));
    render_with::<O>(proj, blend, tone, (width, height), window, Some(sink), how)
}

/// [`render_projected`] (without `sink`, `out` the whole image) or
/// [`render_projected_rows`] (with it, `out` the window), with the build of the inner
/// loops and the binning budgets `(bands, tiles)` given, so that tests can force each
/// build and many small runs.
fn render_with<O: Output>(
    proj: &[Projected],
    blend: (Blend, WeightRule),
    tone: Option<&ToneCurve>,
    (width, height): (u32, u32),
    out: &mut [O::Elem],
    mut sink: Option<Sink<'_, O::Elem>>,
    (parallel, kernel, (band_budget, tile_budget)): (bool, Kernel, (u64, u64)),
) -> std::io::Result<()> {
    let row_len = width as usize * O::PER_PIXEL;
    let band_len = BAND.min(height) as usize * row_len;
    let band_count = height.div_ceil(BAND);
    // Bands per step: all of a run into the whole image, or a window's worth.
    let per_step = match sink {
        None => {
            debug_assert_eq!(out.len(), height as usize * row_len);
            band_count
        }
        Some(_) => {
            assert!(out.len() >= band_len && out.len() % band_len == 0);
            (out.len() / band_len) as u32
        }
    };
    let spans = proj
        .iter()
        .enumerate()
        .map(|(k, p)| (k as u32, p.bbox.y0 / BAND, p.bbox.y1 / BAND));

    // Through a window, each thread keeps its scratch from step to step (into a whole
    // image, one is made per run and thread).
    let kept: Vec<Mutex<Bins>> = match sink {
        None => Vec::new(),
        Some(_) => (0..threads(parallel)).map(|_| Mutex::default()).collect(),
    };
    let mut bands = Bins::default();
    for run in runs(spans.clone(), band_count, band_budget) {
        bands.fill(spans.clone(), run.clone());
        let mut first = run.start;
        while first < run.end {
            let end = run.end.min(first.saturating_add(per_step));
            let rows = (end * BAND).min(height) as usize - (first * BAND) as usize;
            let step = match sink {
                None => &mut out[first as usize * band_len..][..rows * row_len],
                Some(_) => &mut out[..rows * row_len],
            };
            let ctx = (proj, blend, tone, width, kernel, tile_budget);
            let kept = (!kept.is_empty()).then_some(&kept[..]);
            render_bands::<O>(ctx, &bands, first, (step, band_len), kept, parallel);
            if let Some(sink) = sink.as_mut() {
                sink(step)?;
            }
            first = end;
        }
    }
    Ok(())
}

/// What every band of a render shares: the Gaussians, how they blend, the tone curve,
/// the output's width, the build of the inner loops and the tile lists' budget.
type Shared<'a> = (
    &'a [Projected],
    (Blend, WeightRule),
    Option<&'a ToneCurve>,
    u32,
    Kernel,
    u64,
);

/// Render the bands from `first` on into `rows` (`band_len` values a band, the last
/// one possibly shorter), their lists in `bands`, with the scratch of the thread's slot
/// in `kept` where given (else one made per thread); on rayon's pool where `parallel`.
fn render_bands<O: Output>(
    (proj, blend, tone, width, kernel, tile_budget): Shared<'_>,
    bands: &Bins,
    first: u32,
    (rows, band_len): (&mut [O::Elem], usize),
    kept: Option<&[Mutex<Bins>]>,
    parallel: bool,
) {
    let job = |tiles: &mut Bins, (k, rows): (usize, &mut [O::Elem])| {
        let band = first + k as u32;
        let ctx = Band {
            proj,
            blend,
            tone,
            kernel,
            width,
            y0: band * BAND,
            tile_budget,
        };
        ctx.render::<O>(bands.slot(band), rows, tiles);
    };
    // A slot per thread, so that no lock is ever waited for (a poisoned one only means
    // another band panicked; its scratch is still only scratch).
    let with_kept = |kept: &[Mutex<Bins>], item| {
        let slot = thread_slot() % kept.len();
        let mut tiles = kept[slot].lock().unwrap_or_else(|e| e.into_inner());
        job(&mut tiles, item)
    };
    #[cfg(feature = "parallel")]
    if parallel {
        use rayon::prelude::*;
        let bands = rows.par_chunks_mut(band_len).enumerate();
        match kept {
            Some(kept) => bands.for_each(|item| with_kept(kept, item)),
            None => bands.for_each_init(Bins::default, job),
        }
        return;
    }
    let _ = parallel;
    let mut own = Bins::default();
    for item in rows.chunks_mut(band_len).enumerate() {
        match kept {
            Some(kept) => with_kept(kept, item),
            None => job(&mut own, item),
        }
    }
}

/// Threads that may render bands at once.
fn threads(parallel: bool) -> usize {
    #[cfg(feature = "parallel")]
    if parallel {
        return rayon::current_num_threads();
    }
    let _ = parallel;
    1
}

/// This thread's index among [`threads`] (0 outside a pool).
fn thread_slot() -> usize {
    #[cfg(feature = "parallel")]
    if let Some(k) = rayon::current_thread_index() {
        return k;
    }
    0
}

/// Bands [`render_projected_rows`] takes a step at a time: three per thread (96 rows), so
/// that the threads share a step's uneven bands, and the window stays small (a
/// 768-pixel-wide output on two threads: 192 rows, 432 KiB). Each step ends with the
/// threads waiting while the rows are written, so fewer steps cost less, until the window
/// outgrows the memory a decode has freed by then (its codes and dequantized attributes)
/// and faults in fresh pages. On two cores, `gsi decode` to PPM (61–101 paired
/// processes), in bands of 16 rows: 96 rows a thread against 64, 0.6–0.7 ms less CPU for
/// kodim23, kodim13 and Barbara (768×512 and 720×576), 0.7–1.1 ms for a 1024×768
/// photograph, the same at 12 MP; 128 against 64, 0.1–0.25 ms less for kodim23 (108 more
/// page faults), 0.7 ms for the 1024×768 one. (32 against 64 cost 1.0 ms more, measured
/// before the freed memory was reused.)
pub fn window_bands(parallel: bool) -> usize {
    const ROWS_PER_THREAD: usize = 96;
    const MAX_ROWS: usize = 512;
    let band = BAND as usize;
    (ROWS_PER_THREAD / band * threads(parallel)).min(MAX_ROWS / band)
}

/// What every tile of one band needs to know.
struct Band<'a> {
    proj: &'a [Projected],
    blend: (Blend, WeightRule),
    tone: Option<&'a ToneCurve>,
    kernel: Kernel,
    width: u32,
    /// First pixel row of the band.
    y0: u32,
    tile_budget: u64,
}

impl Band<'_> {
    /// Render the Gaussians of `list` (indices into `proj`, stored order) into `rows`,
    /// the band's pixel rows in `O`'s layout, binned to tiles in `tiles`.
    fn render<O: Output>(&self, list: &[u32], rows: &mut [O::Elem], tiles: &mut Bins) {
        let row_len = self.width as usize * O::PER_PIXEL;
        let y1 = self.y0 + (rows.len() / row_len) as u32;
        let tiles_x = self.width.div_ceil(TILE);
        // The band's Gaussians, each with its box cut to the columns it may reach over
        // the band's rows: the pixels cut away take no light by either weight rule, so
        // the image is the same, and a tile spends no chunk, nor a start of the column
        // rule, on a box's corner that the ellipse does not reach. (A copy per Gaussian
        // and band: kodim13 and kodim23 at 1 bpp decode in 2.1 % and 1.5 % less CPU.
        // The cut columns carried beside the Gaussians' indices instead were 10 % slower
        // in the tile loops, whose registers then spilled.)
        let mut local: Vec<Projected> = Vec::with_capacity(list.len());
        local.extend(list.iter().filter_map(|&k| {
            let g = &self.proj[k as usize];
            let (first, last) = band_columns(g, self.y0..y1)?;
            let mut cut = *g;
            (cut.bbox.x0, cut.bbox.x1) = (first, last);
            Some(cut)
        }));
        let spans = (0..)
            .zip(&local)
            .map(|(i, g)| (i, g.bbox.x0 / TILE, g.bbox.x1 / TILE));
        let mut acc = Acc::zero();
        for run in runs(spans.clone(), tiles_x, self.tile_budget) {
            tiles.fill(spans.clone(), run.clone());
            for tx in run {
                let x0 = tx * TILE;
                let rect = Rect {
                    x0,
                    x1: x0.saturating_add(TILE).min(self.width),
                    y0: self.y0,
                    y1,
                };
                // Every tile is stored, an empty one as blended from nothing (through
                // the tone curve, which need not take 0 to 0).
                acc.clear();
                let tile = tiles.slot(tx);
                if !tile.is_empty() {
                    self.kernel.tile(self.blend, tile, &local, rect, &mut acc);
                }
                if let Some(t) = self.tone {
                    acc.tone(t, rect);
                }
                O::store(&acc, rows, self.width, rect);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::project_scene;
    use super::*;
    use gsi_format::model::CovParam;
    use gsi_synth::{random_scene, SceneSpec};

    const RULES: [WeightRule; 3] = [
        WeightRule::PerPixel,
        WeightRule::Columns,
        WeightRule::Columns32,
    ];

    /// Each blend mode with each column rule.
    fn blends_by_columns() -> impl Iterator<Item = (Blend, WeightRule)> {
        [Blend::Sum, Blend::Alpha]
            .into_iter()
            .flat_map(|b| RULES[1..].iter().map(move |&r| (b, r)))
    }

    fn render_both(blend: (Blend, WeightRule), w: u32, h: u32) -> (Vec<f32>, Vec<f32>) {
        let mut spec = SceneSpec::new(64, 48, 400, blend.0);
        spec.sigma_px = (0.3, 30.0);
        spec.cov_param = CovParam::Cholesky;
        let scene = random_scene(11, spec);
        let proj = project_scene(&scene, w, h);
        let mut seq = vec![f32::NAN; (w * h * 3) as usize];
        let mut par = vec![f32::NAN; (w * h * 3) as usize];
        render_projected::<RgbF32>(&proj, blend, None, (w, h), &mut seq, false);
        render_projected::<RgbF32>(&proj, blend, None, (w, h), &mut par, true);
        (seq, par)
    }

    #[test]
    fn parallel_and_sequential_are_identical() {
        for blend in [Blend::Sum, Blend::Alpha] {
            for rule in RULES {
                for (w, h) in [(64, 48), (131, 97), (5, 200), (1, 1)] {
                    let (seq, par) = render_both((blend, rule), w, h);
                    assert!(seq.iter().all(|x| x.is_finite()));
                    let same = seq
                        .iter()
                        .zip(&par)
                        .all(|(a, b)| a.to_bits() == b.to_bits());
                    assert!(same, "{blend:?} {rule:?} {w}x{h}");
                }
            }
        }
    }

    /// The rules of spec §6.3–6.4 over every Gaussian, one pixel at a time, with no tile,
    /// no binning and no shortcut.
    fn by_the_rule(
        proj: &[Projected],
        (blend, rule): (Blend, WeightRule),
        w: u32,
        h: u32,
    ) -> Vec<f32> {
        let mut out = vec![0.0; (w * h * 3) as usize];
        for j in 0..h {
            for i in 0..w {
                let px = &mut out[((j * w + i) * 3) as usize..][..3];
                let mut t = 1.0f32;
                for g in proj {
                    let Some(alpha) = g.weight_at(i, j, blend, rule) else {
                        continue;
                    };
                    match blend {
                        Blend::Sum => (0..3).for_each(|c| px[c] += g.color[c] * alpha),
                        Blend::Alpha => {
                            (0..3).for_each(|c| px[c] += g.color[c] * alpha * t);
                            t *= 1.0 - alpha;
                            if t < gsi_format::contract::TRANSMITTANCE_MIN {
                                break;
                            }
                        }
                    }
                }
            }
        }
        out
    }

    /// The first value where `kernel`'s render of `proj` differs from [`by_the_rule`]'s,
    /// bit for bit; the rule's image must not be black.
    fn unlike_the_rule(
        proj: &[Projected],
        blend: (Blend, WeightRule),
        (w, h): (u32, u32),
        kernel: Kernel,
    ) -> Option<usize> {
        let want = by_the_rule(proj, blend, w, h);
        assert!(want.iter().any(|&x| x != 0.0));
        let mut got = vec![f32::NAN; want.len()];
        let how = (false, kernel, (BAND_BUDGET, TILE_BUDGET));
        render_with::<RgbF32>(proj, blend, None, (w, h), &mut got, None, how).unwrap();
        want.iter()
            .zip(&got)
            .position(|(a, b)| a.to_bits() != b.to_bits())
    }

    /// Each build of the inner loops (the portable one, and AVX2 where the CPU has it)
    /// gives the bits of each rule: elongated, rotated Gaussians (whose boxes hold tiles
    /// the ellipse misses, and columns whose lanes go dark and start again), Gaussians steeper
    /// than the column rule takes, partial tiles and chunks, opaque stacks that stop early.
    #[test]
    fn every_build_gives_the_bits_of_the_rule() {
        for blend in [Blend::Sum, Blend::Alpha] {
            for rule in RULES {
                for (seed, cov_param, sigma) in [
                    (3, CovParam::LogScaleRotation, (0.2, 25.0)),
                    (4, CovParam::Cholesky, (0.2, 25.0)),
                    (5, CovParam::LogScaleRotation, (0.05, 60.0)),
                ] {
                    let mut spec = SceneSpec::new(50, 40, 500, blend);
                    spec.sigma_px = sigma;
                    spec.cov_param = cov_param;
                    let scene = random_scene(seed, spec);
                    for (w, h) in [(50, 40), (37, 23), (3, 70), (160, 128)] {
                        let proj = project_scene(&scene, w, h);
                        for kernel in Kernel::all() {
                            let diff = unlike_the_rule(&proj, (blend, rule), (w, h), kernel);
                            assert!(
                                diff.is_none(),
                                "{blend:?} {rule:?} {cov_param:?} {w}x{h} {kernel:?} at {diff:?}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// Needles: Gaussians whose covariance is nearly singular, along every direction,
    /// thin to a hundredth of a pixel, at opacities from 1/255 up: the powers of their
    /// boxes cancel most, so the column rule's weights are furthest from `E(power)`, and
    /// the binning must still keep every tile where they reach the cut.
    #[test]
    fn needles_give_the_bits_of_the_rule() {
        use gsi_format::model::{GaussianSet, Scene};
        for seed in 0..6u64 {
            let mut rng = gsi_synth::SplitMix64::new(seed);
            let mut g = GaussianSet::default();
            for _ in 0..200 {
                g.positions.push([rng.unit(), rng.unit()]);
                let l = 0.001 + 0.3 * rng.unit().powi(3);
                let t = 1e-6 + 0.01 * rng.unit().powi(4);
                let sign = if rng.unit() < 0.5 { -1.0 } else { 1.0 };
                g.cov.push([l, sign * l * rng.range(0.5, 1.0), t]);
                g.colors.push([rng.unit(), rng.unit() - 0.5, 1.0]);
            }
            g.opacity = Some((0..200).map(|_| rng.range(0.004, 1.0)).collect());
            for (blend, rule) in blends_by_columns() {
                let scene = Scene {
                    width: 64,
                    height: 48,
                    blend,
                    cov_param: CovParam::Cholesky,
                    gaussians: g.clone(),
                    tone: None,
                    weights: rule,
                };
                for (w, h) in [(64, 48), (150, 110)] {
                    let proj = project_scene(&scene, w, h);
                    let how = (blend, rule);
                    let diff = unlike_the_rule(&proj, how, (w, h), Kernel::detect());
                    assert!(diff.is_none(), "seed {seed} {blend:?} {w}x{h} at {diff:?}");
                }
            }
        }
    }

    /// The column rule moves a blended value by a few millionths of the per-pixel rule's
    /// (a weight is at most 31 rounded steps from an `E`, and each ratio `r` carries the
    /// rounding of a difference of two powers), far below an 8-bit step.
    #[test]
    fn the_column_rule_stays_near_the_per_pixel_rule() {
        for (blend, columns) in blends_by_columns() {
            let mut spec = SceneSpec::new(96, 64, 800, blend);
            spec.sigma_px = (0.3, 20.0);
            let scene = random_scene(9, spec);
            let (w, h) = (96, 64);
            let proj = project_scene(&scene, w, h);
            let [a, b] = [WeightRule::PerPixel, columns].map(|rule| {
                let mut out = vec![0.0; (w * h * 3) as usize];
                render_projected::<RgbF32>(&proj, (blend, rule), None, (w, h), &mut out, false);
                out
            });
            let worst = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).abs())
                .fold(0f32, f32::max);
            // A flipped 1/255 cut moves a value by up to |colour|/255; elsewhere 1e-5.
            assert!(worst < 5e-3, "{blend:?} {columns:?}: {worst}");
            // Measured: median 1.2e-6, 99.9th percentile 5.6e-5 (sum; values up to a few units).
            let near = a
                .iter()
                .zip(&b)
                .filter(|(x, y)| (*x - *y).abs() < 1e-4)
                .count();
            assert!(
                near as f64 > 0.999 * a.len() as f64,
                "{blend:?} {columns:?}: {near}"
            );
        }
    }

    /// Rows handed out through windows of one band or several, with runs of one band
    /// (the tiniest budgets) or of all, on one thread or the pool, are the whole image.
    /// The shuffled 8-bit row gives [`super::super::to_u8`]'s bytes, in its pixel order,
    /// for the values where rounding or clamping decide (NaN, infinities, the halves).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn rgb8_rows_by_shuffles_are_to_u8() {
        if !std::is_x86_feature_detected!("ssse3") {
            return;
        }
        let mut values = vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0, 1.0, 2.0];
        for k in 0..=255u16 {
            // Each step's half, and the values either side of it.
            let h = (f32::from(k) + 0.5) / 255.0;
            values.extend([
                h,
                f32::from_bits(h.to_bits() - 1),
                f32::from_bits(h.to_bits() + 1),
            ]);
        }
        values.extend((0..3001).map(|i| -0.2 + 1.4 * i as f32 / 3000.0));
        for chunk in values.chunks(48) {
            let mut planes = [[0f32; TILE_W]; 3];
            for (i, &v) in chunk.iter().enumerate() {
                planes[i % 3][i / 3] = v;
            }
            let mut out = [0u8; 3 * TILE_W];
            // SAFETY: the CPU has SSSE3 (checked above).
            unsafe { x86::rgb8_row([&planes[0], &planes[1], &planes[2]], &mut out) };
            for (i, &v) in chunk.iter().enumerate() {
                assert_eq!(out[i], super::super::to_u8(v), "{v:e} at {i}");
            }
        }
    }

    #[test]
    fn windows_give_the_whole_image() {
        for blend in [Blend::Sum, Blend::Alpha] {
            let mut spec = SceneSpec::new(40, 40, 300, blend);
            spec.sigma_px = (0.3, 40.0);
            let scene = random_scene(6, spec);
            let (w, h) = (45, 83);
            let proj = project_scene(&scene, w, h);
            let rule = (blend, WeightRule::Columns32);
            let mut whole = vec![0.0; (w * h * 3) as usize];
            render_projected::<RgbF32>(&proj, rule, None, (w, h), &mut whole, false);
            let band_len = (BAND * w * 3) as usize;
            for budgets in [(BAND_BUDGET, TILE_BUDGET), (0, 0)] {
                for bands in [1, 2, 5, 6] {
                    for parallel in [false, true] {
                        let mut window = vec![f32::NAN; bands * band_len];
                        let mut rows = Vec::new();
                        let how = (parallel, Kernel::detect(), budgets);
                        let mut sink = |r: &[f32]| {
                            rows.extend_from_slice(r);
                            Ok(())
                        };
                        let size = (w, h);
                        render_with::<RgbF32>(
                            &proj,
                            rule,
                            None,
                            size,
                            &mut window,
                            Some(&mut sink),
                            how,
                        )
                        .unwrap();
                        let same = rows.len() == whole.len()
                            && rows
                                .iter()
                                .zip(&whole)
                                .all(|(a, b)| a.to_bits() == b.to_bits());
                        assert!(
                            same,
                            "{blend:?} {budgets:?} {bands} bands, parallel {parallel}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn tiny_budgets_give_the_same_image() {
        // Binning in runs of one band and one tile must not change what a pixel visits.
        for blend in [Blend::Sum, Blend::Alpha] {
            for rule in RULES {
                let mut spec = SceneSpec::new(40, 40, 300, blend);
                spec.sigma_px = (0.3, 40.0);
                let scene = random_scene(5, spec);
                let (w, h) = (75, 50);
                let proj = project_scene(&scene, w, h);
                let mut a = vec![0.0; (w * h * 3) as usize];
                let mut b = a.clone();
                let kernel = Kernel::detect();
                let how = (false, kernel, (BAND_BUDGET, TILE_BUDGET));
                render_with::<RgbF32>(&proj, (blend, rule), None, (w, h), &mut a, None, how)
                    .unwrap();
                let tiny = (false, kernel, (0, 0));
                render_with::<RgbF32>(&proj, (blend, rule), None, (w, h), &mut b, None, tiny)
                    .unwrap();
                assert!(a.iter().any(|&x| x != 0.0));
                assert!(
                    a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
                    "{blend:?} {rule:?}"
                );
            }
        }
    }
}
