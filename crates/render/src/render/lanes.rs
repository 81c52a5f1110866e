//! The per-pixel rule of spec §6.3–6.4, eight pixels of a tile row at a time.
//!
//! A render evaluates `alpha = o·exp(power)` for every pixel a Gaussian's box holds. One
//! pixel at a time, with a branch per pixel and a call to the platform's `expf`, that was
//! most of a decode. Here a tile row is cut into chunks of [`LANES`] pixels, branches
//! become masks, and `exp` is the polynomial of spec §6.3.1 ([`gsi_format::contract::exp`]),
//! built from `+ − ×` and exponent bits, which the compiler puts in SIMD registers.
//!
//! Every operation is one IEEE 754 binary32 operation in the order the spec writes, never
//! fused (Rust does not contract `a·b + c`), so a lane computes what a scalar decoder
//! computes, bit for bit: the portable build (SSE2 on x86-64, NEON on aarch64, whatever
//! the target has elsewhere) and the AVX2 and AVX-512 builds picked at run time
//! ([`Kernel`]) give the same image, and so does [`Projected::alpha_at`], the rule in its
//! plainest form. (`std::arch` detection and `#[target_feature]` on the same generic code,
//! rather than a SIMD crate: the loops are plain arrays that LLVM vectorizes for whatever
//! the function is compiled for, which keeps one copy of the arithmetic and adds no
//! dependency. AVX-512 is a build of its own because its 32 registers hold the
//! polynomial's constants: 10.9 ms against 9.7 ms for kodim23 at 768×512 here; its
//! 16-lane registers also take a tile row of `sum` at once (`Blender::BY_CHUNK`).)
//!
//! Files with `GCRW` or `GCRT` (spec §6.3.2) take the column rule instead: down each
//! chunk column a lane's weight is the row above's times a ratio, and the ratio the row
//! above's times `E(−C)`, so that a chunk-row costs two products where the rule of §6.3
//! costs the power and `E`. A lane evaluates `E` where it starts (its first row in the
//! rule's band, or the row where a dark lane's power reaches the start level): in tiles
//! and bands of 16 rows, kodim23 at 1 bpp started lanes on 0.10 M of its 1.11 M
//! chunk-rows, and its decode (parse and render, in process) took 15.8 ms against 20.7 ms
//! by §6.3. Tiles are [`BAND`] (32) rows, the bands of the rule in files written now
//! (`GCRT`), so no weight is carried from one tile to the next; in a `GCRW` file's bands
//! of 16 rows a column starts again at the tile's row 16. (The blending is a trait with
//! inlined methods, not a closure: as a closure with two callers it was compiled apart from the
//! `#[target_feature]` function, without AVX, and the loop called it for every chunk-row
//! at half the speed. LLVM inlines some closures and not others; the hot ones here are
//! functions.)
//!
//! The encoder's loops (`gsi_fit::fit`) share [`Footprint`] and the polynomial. Their
//! forward pass takes the row-independent part of a chunk's powers once per chunk
//! ([`Footprint::column`]) and gives this rule's bits; their backward pass may fuse
//! multiply-adds (`F`), since a gradient needs the decoder's values, not its bits.

use super::project::{offset, Projected, Rect};
use super::{BAND, TILE};
use gsi_format::contract::exp_in_range;
pub use gsi_format::contract::mla;
use gsi_format::contract::{
    exp, ALPHA_MAX, ALPHA_MIN, COLUMN_DARK, COLUMN_START, COLUMN_STEEP, TRANSMITTANCE_MIN,
};
use gsi_format::model::{Blend, ToneCurve, WeightRule};

/// Pixels per chunk: one AVX register of `f32`, two SSE or NEON ones.
pub const LANES: usize = 8;
pub(crate) const TILE_W: usize = TILE as usize;
const TILE_H: usize = BAND as usize;

/// One value per lane.
pub type V = [f32; LANES];

/// One Gaussian over the part of a tile it touches.
pub struct Footprint<'g> {
    pub g: &'g Projected,
    /// Tile-local columns `lx0..lx1` and pixel rows `ys` of its box in the tile.
    pub lx0: usize,
    pub lx1: usize,
    pub ys: std::ops::Range<u32>,
    /// Pixel column of the tile's first column.
    pub x0: u32,
}

impl Footprint<'_> {
    /// The part of `g`'s box in tile `rect`; `None` where they do not meet. (Which tiles
    /// a Gaussian can reach at all was decided when it was binned, [`super::tiles::band_tiles`].)
    #[inline]
    pub fn of(g: &Projected, rect: Rect) -> Option<Footprint<'_>> {
        let (xs, ys) = g.bbox.clip(rect)?;
        Some(Footprint {
            g,
            lx0: (xs.start - rect.x0) as usize,
            lx1: (xs.end - rect.x0) as usize,
            ys,
            x0: rect.x0,
        })
    }

    /// The chunks of a tile row that the box meets, aligned to multiples of [`LANES`]
    /// (the fit's loops, whose planes are [`TILE`] wide). (Narrowing them row by row to
    /// where the ellipse reaches the cut-off was tried for fitting: a square root and two
    /// divisions per row cost more than the lanes they saved.)
    #[cfg(feature = "encode")]
    #[inline(always)]
    pub fn chunks(&self) -> std::ops::RangeInclusive<usize> {
        self.lx0 / LANES..=(self.lx1 - 1) / LANES
    }

    /// The first columns of the chunks that cover the box's columns from its first one
    /// on: `ceil(width / LANES)` chunks, where aligned ones can take one more (a box of 3
    /// columns from column 6 takes two). For accumulators [`LANES`] wider than a tile.
    #[inline(always)]
    pub fn starts(&self) -> std::iter::StepBy<std::ops::Range<usize>> {
        (self.lx0..self.lx1).step_by(LANES)
    }

    /// `(alpha, dx)` on the [`LANES`] columns from tile-local column `start` of the row
    /// at `dy` from the centre: `alpha` 0 where the Gaussian does not touch the pixel
    /// (outside the box's columns, `power` out of `[cut, 0]`, `alpha < ALPHA_MIN`). With
    /// `CAP`, alpha is capped at `ALPHA_MAX` before the threshold, as `alpha` blending does.
    #[inline(always)]
    pub fn alphas<const F: bool, const CAP: bool>(&self, start: usize, dy: f32) -> (V, V) {
        self.alphas_with::<F, CAP, false>(start, dy)
    }

    /// The powers on the [`LANES`] columns from tile-local column `start` of the row at
    /// `dy` from the centre, and their offsets `dx`: the first half of
    /// [`Footprint::alphas_with`], which [`Footprint::alphas_of`] completes.
    #[inline(always)]
    pub(crate) fn powers<const F: bool>(&self, start: usize, dy: f32) -> (V, V) {
        let g = self.g;
        let [ca, cb, cc] = g.conic;
        let cdy = cc * dy * dy;
        let first = self.x0 + start as u32;
        let mut power = [0f32; LANES];
        let mut dxs = [0f32; LANES];
        for l in 0..LANES {
            let dx = offset(first.wrapping_add(l as u32), g.mean[0]);
            // -0.5·(A dx² + C dy²) − B dx dy
            power[l] = mla::<F>(-0.5, mla::<F>(ca * dx, dx, cdy), -(cb * dx * dy));
            dxs[l] = dx;
        }
        (power, dxs)
    }

    /// Whether every lane of `power` is below the cut-off, where every alpha is 0: a
    /// decoder may skip the chunk, since adding 0 (colours are finite) and multiplying a
    /// transmittance by 1 change nothing. Of the chunk-rows a decode walks at 768×512,
    /// 16.5 % on kodim23 and 25.8 % on kodim13 have no lane that takes light (mostly the
    /// corners of rotated boxes); for a compare and a branch on every chunk-row the tile
    /// loop came out 1–3 % (kodim23) and 7–14 % (kodim13) faster. (Counting the lanes
    /// outside the box's columns as dark too skipped more and measured no faster.)
    #[inline(always)]
    pub(crate) fn dark(&self, power: &V) -> bool {
        let cut = self.g.cutoff();
        // A NaN is not below the cut: such a chunk is evaluated, as the rule says.
        power.iter().fold(true, |dark, &p| dark & (p < cut))
    }

    /// The alphas of `power` (from [`Footprint::powers`] at `start`): 0 where the
    /// Gaussian does not touch the pixel, as [`Footprint::alphas_with`] gives them.
    #[inline(always)]
    pub(crate) fn alphas_of<const F: bool, const CAP: bool, const JOIN: bool>(
        &self,
        start: usize,
        power: &V,
    ) -> V {
        let g = self.g;
        let cut = g.cutoff();
        let (lx0, lx1) = self.box_lanes(start);
        let mut alpha = [0f32; LANES];
        for l in 0..LANES {
            let power = power[l];
            // Every lane with `power` outside `[cut, 0]` is set to 0 below.
            let mut a = g.opacity * exp_in_range::<F>(power);
            if CAP {
                a = a.min(ALPHA_MAX);
            }
            // NaN fails every test.
            let inside = (l as i32 >= lx0) & ((l as i32) < lx1);
            if JOIN {
                let keep = inside & (power >= cut) & (power <= 0.0) & (a >= ALPHA_MIN);
                alpha[l] = if keep { a } else { 0.0 };
            } else {
                // One select per test, each a compare and a mask on a whole register.
                a = if power >= cut { a } else { 0.0 };
                a = if power <= 0.0 { a } else { 0.0 };
                a = if a >= ALPHA_MIN { a } else { 0.0 };
                alpha[l] = if inside { a } else { 0.0 };
            }
        }
        alpha
    }

    /// [`Footprint::alphas`], with the four tests joined into one mask where `JOIN`. With
    /// AVX-512's mask registers each compare then works under the previous one's mask
    /// (kodim23's decode 6 % faster here); on AVX2 a joined boolean is packed to bytes
    /// and back, and a select per test is 3 % faster. The bits are the same either way.
    #[inline(always)]
    pub fn alphas_with<const F: bool, const CAP: bool, const JOIN: bool>(
        &self,
        start: usize,
        dy: f32,
    ) -> (V, V) {
        let (power, dxs) = self.powers::<F>(start, dy);
        (self.alphas_of::<F, CAP, JOIN>(start, &power), dxs)
    }

    /// The offsets from the centre of the columns of chunk `c`, as [`Footprint::alphas`]
    /// computes them.
    #[cfg(feature = "encode")]
    #[inline(always)]
    pub fn dxs(&self, c: usize) -> V {
        let first = self.x0 + (c * LANES) as u32;
        std::array::from_fn(|l| offset(first.wrapping_add(l as u32), self.g.mean[0]))
    }

    /// What [`Footprint::alphas`] computes on chunk `c` that is the same on every row:
    /// for loops that walk a chunk's rows one after another (the fit's), which then
    /// compute per row only what depends on `dy` ([`Footprint::column_alphas`]).
    #[cfg(feature = "encode")]
    #[inline(always)]
    pub fn column(&self, c: usize) -> Column {
        let [ca, cb, _] = self.g.conic;
        let dx = self.dxs(c);
        let (lx0, lx1) = self.box_lanes(c * LANES);
        Column {
            dx,
            a_dx: dx.map(|x| ca * x),
            b_dx: dx.map(|x| cb * x),
            inside: std::array::from_fn(|l| (l as i32 >= lx0) & ((l as i32) < lx1)),
        }
    }

    /// [`Footprint::alphas`] (unfused, uncapped) on the chunk of `col` at the row `dy`
    /// from the centre, bit for bit: the same operations, the row-independent ones taken
    /// from `col`; `None` where every lane's power is below the cut-off, so that every
    /// alpha is 0. Of the chunk-rows a fit's forward pass walks, those are the corners of
    /// rotated and elongated boxes, which then cost a compare instead of an `exp`.
    #[cfg(feature = "encode")]
    #[inline(always)]
    pub fn column_alphas(&self, col: &Column, dy: f32) -> Option<V> {
        let cdy = self.g.conic[2] * dy * dy;
        // -0.5·(A dx² + C dy²) − B dx dy, as in `powers`.
        let power: V = std::array::from_fn(|l| {
            mla::<false>(
                -0.5,
                mla::<false>(col.a_dx[l], col.dx[l], cdy),
                -(col.b_dx[l] * dy),
            )
        });
        if self.dark(&power) {
            return None;
        }
        // `alphas_of`'s tests, with the box's lanes taken from `col`: computed again on
        // every row there, they cost the fit's encodes 2-4 % more time. A loop, not
        // `from_fn`: as a closure the tests were not vectorized (kodim23 and kodim13
        // encodes +43-52 %).
        let cut = self.g.cutoff();
        let mut alpha = [0f32; LANES];
        for l in 0..LANES {
            let p = power[l];
            let mut a = self.g.opacity * exp_in_range::<false>(p);
            a = if p >= cut { a } else { 0.0 };
            a = if p <= 0.0 { a } else { 0.0 };
            a = if a >= ALPHA_MIN { a } else { 0.0 };
            alpha[l] = if col.inside[l] { a } else { 0.0 };
        }
        Some(alpha)
    }
}

/// The row-independent part of [`Footprint::alphas`] on one chunk ([`Footprint::column`]).
#[cfg(feature = "encode")]
#[derive(Clone, Copy, Debug)]
pub struct Column {
    /// Each column's offset from the centre.
    pub dx: V,
    /// `A·dx` and `B·dx` of the power.
    a_dx: V,
    b_dx: V,
    /// Whether the column lies in the box.
    inside: [bool; LANES],
}

/// Which build of the loops runs: the portable one, or one for a CPU feature detected at
/// run time. Each gives the same bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    Portable,
    /// x86-64 with AVX2: eight lanes in one register.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// x86-64 with AVX-512 (F and VL): the same eight lanes, with 32 registers, so that
    /// the polynomial's constants stay in registers.
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Kernel {
    /// The fastest build this CPU runs.
    pub fn detect() -> Kernel {
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl")
            {
                return Kernel::Avx512;
            }
            if std::is_x86_feature_detected!("avx2") {
                return Kernel::Avx2;
            }
        }
        Kernel::Portable
    }

    /// Every build this CPU runs, for tests.
    #[cfg(test)]
    pub fn all() -> Vec<Kernel> {
        let mut all = vec![Kernel::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                all.push(Kernel::Avx2);
            }
            if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl")
            {
                all.push(Kernel::Avx512);
            }
        }
        all
    }

    /// Blend the Gaussians `list` (indices into `proj`, stored order) over tile `rect`
    /// (at most [`BAND`] rows, from a multiple of them) into `acc`, which holds zeros,
    /// with their weights by `rule`.
    pub fn tile(
        self,
        (blend, rule): (Blend, WeightRule),
        list: &[u32],
        proj: &[Projected],
        rect: Rect,
        acc: &mut Acc,
    ) {
        let columns = rule.band_rows();
        match self {
            Kernel::Portable => tile::<false>(blend, columns, list, proj, rect, acc),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Avx2` and `Avx512` are only made where the CPU has the features
            // (`detect`), and a CPU with AVX-512 has AVX2.
            Kernel::Avx2 => unsafe { x86::tile_avx2(blend, columns, list, proj, rect, acc) },
            // `alpha` blending by the column rule runs the AVX2 build on an AVX-512 CPU
            // too: on an AMD EPYC with AVX-512 (Zen 4), one thread, kodim23 fitted in
            // `alpha` mode at 1 bpp rendered in 16.7 ms by the AVX2 build against 23.1 ms
            // by the AVX-512 one (`sum` by columns 6.4 against 6.1 ms, `alpha` per pixel
            // 2.8 against 2.5 ms for a corpus file: those keep AVX-512). Why the AVX-512
            // code of this loop is slower was not looked into. The bits are the same
            // either way.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 if blend == Blend::Alpha && columns.is_some() => unsafe {
                x86::tile_avx2(blend, columns, list, proj, rect, acc)
            },
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => unsafe { x86::tile_avx512(blend, columns, list, proj, rect, acc) },
        }
    }
}

/// Row stride of [`Acc`]: a chunk may start at any column of a tile row.
const ACC_W: usize = TILE_W + LANES;

/// A tile in three planes (R, G, B) whose rows are [`LANES`] wider than a tile, so that a
/// chunk starting at the box's first column never reaches the next row; the padding is
/// only ever given zeros.
pub struct Acc(pub [[f32; ACC_W * TILE_H]; 3]);

impl Acc {
    pub fn zero() -> Acc {
        Acc([[0.0; ACC_W * TILE_H]; 3])
    }

    /// Back to zeros, for the next tile.
    #[inline]
    pub fn clear(&mut self) {
        self.0.iter_mut().for_each(|p| p.fill(0.0));
    }

    /// Row `j` of the three planes: the tile's [`TILE`] columns.
    #[inline(always)]
    pub fn row(&self, j: usize) -> [&[f32; TILE_W]; 3] {
        let at = j * ACC_W;
        fn row(p: &[f32], at: usize) -> &[f32; TILE_W] {
            p[at..at + TILE_W].try_into().expect("a tile row")
        }
        [
            row(&self.0[0], at),
            row(&self.0[1], at),
            row(&self.0[2], at),
        ]
    }

    /// Every blended value of the tile `rect` through the tone curve `t` (spec §6.6),
    /// channel by channel.
    pub fn tone(&mut self, t: &ToneCurve, rect: Rect) {
        let n = (rect.x1 - rect.x0) as usize;
        for (channel, plane) in self.0.iter_mut().enumerate() {
            for j in 0..(rect.y1 - rect.y0) as usize {
                for v in &mut plane[j * ACC_W..][..n] {
                    *v = t.eval(channel, *v);
                }
            }
        }
    }
}

/// One build of the loops: the blend mode and the weight rule picked once per tile, so
/// that each combination is a loop of its own. `columns`: the rows of the column rule's
/// bands, `None` for the per-pixel rule. `WIDE`: the AVX-512 build, whose mask registers
/// join the per-pixel rule's tests into one mask (`JOIN` of [`Footprint::alphas_with`])
/// and whose 16-lane registers take a tile row's two chunks at once (`sum` blending).
#[inline(always)]
fn tile<const WIDE: bool>(
    blend: Blend,
    columns: Option<u32>,
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    acc: &mut Acc,
) {
    let band = columns.unwrap_or(BAND);
    match (blend, columns.is_some()) {
        (Blend::Sum, false) => tile_sum::<WIDE, false>(list, proj, (rect, band), acc),
        (Blend::Sum, true) => tile_sum::<WIDE, true>(list, proj, (rect, band), acc),
        (Blend::Alpha, false) => tile_alpha::<WIDE, false>(list, proj, (rect, band), acc),
        (Blend::Alpha, true) => tile_alpha::<WIDE, true>(list, proj, (rect, band), acc),
    }
}

/// Blend `into` the alphas of footprint `f` row by row (the index of the first pixel in
/// [`Acc`] and the alphas of [`LANES`] pixels or of a tile row, 0 where the Gaussian does
/// not touch the pixel), down each chunk column in turn or down the tile's two together;
/// chunk-rows that take no light may be skipped. With `COLUMNS`, by the column rule of
/// spec §6.3.2 in bands of `band` rows (per pixel for a Gaussian steeper than
/// [`COLUMN_STEEP`]), else by §6.3's per-pixel rule. With `CAP`, alphas are capped at
/// [`ALPHA_MAX`] before the threshold, as `alpha` blending does.
#[inline(always)]
fn chunk_rows<const JOIN: bool, const CAP: bool, const COLUMNS: bool>(
    f: &Footprint,
    (rect, band): (Rect, u32),
    into: &mut impl Blender,
) {
    let g = f.g;
    let at = |start: usize, j: u32| (j - rect.y0) as usize * ACC_W + start;
    let dy = |j: u32| offset(j, g.mean[1]);
    // (A projected conic is finite: `project` drops any other.)
    if !COLUMNS || g.conic[2] > COLUMN_STEEP {
        for start in f.starts() {
            for j in f.ys.clone() {
                let (power, _) = f.powers::<false>(start, dy(j));
                if f.dark(&power) {
                    continue;
                }
                let alpha = f.alphas_of::<false, CAP, JOIN>(start, &power);
                into.blend(g, at(start, j), &[alpha]);
            }
        }
        return;
    }
    // The column rule, on the tile's aligned chunks that the box meets: both of them at
    // once where it meets both (see `column_rows`), from the first row of each of the
    // rule's bands that the box's rows in the tile meet (one, unless the rule's bands
    // are shorter than the tile).
    debug_assert_eq!(rect.y0 % band, 0, "a tile starts a band of the rule");
    let k = g.column_k();
    let first = f.lx0 / LANES;
    let mut y = f.ys.start;
    while y < f.ys.end {
        let end = ((y / band + 1) * band).min(f.ys.end);
        let part = Footprint { ys: y..end, ..*f };
        if (f.lx1 - 1) / LANES == first {
            column_rows::<1, CAP, _>(&part, first * LANES, k, rect, into);
        } else {
            column_rows::<2, CAP, _>(&part, 0, k, rect, into);
        }
        y = end;
    }
}

/// All ones where `b`, else 0: a lane mask for selecting bits.
#[inline(always)]
fn lanes_mask(b: bool) -> u32 {
    u32::from(b).wrapping_neg()
}

// A tile row is two chunks, so that a box meets one chunk or both.
const _: () = assert!(TILE_W == 2 * LANES);
// A tile's rows are whole bands of every column rule (§6.3.2: 16 or 32 rows, and 32 is a
// multiple of 16), so that a rule's band never runs from one tile into the next.
const _: () = assert!(BAND % 32 == 0);

/// The column rule of spec §6.3.2 for footprint `f` on the `M` chunks of a tile row
/// from tile-local column `start` (a multiple of [`LANES`]), `k = E(−C)`.
///
/// The chunks are the tile's own, not ones from the box's first column: a box then meets
/// at most two, and where it meets both they go down the rows together, which halves the
/// loop's steps and gives the processor two independent chains of products (each row's
/// weight waits on the row above's). Every lane computes what it would alone, so the
/// image is the same bits. (The state is held chunk by chunk, `[V; M]`, not as one array
/// of `M·LANES` lanes: LLVM split such an array at odd lanes when it left the registers,
/// and each Gaussian's next row then waited on a store it could not forward, 4 % of a
/// single-thread render of kodim23 on one load.)
#[inline(always)]
fn column_rows<const M: usize, const CAP: bool, B: Blender>(
    f: &Footprint,
    start: usize,
    k: f32,
    rect: Rect,
    into: &mut B,
) {
    let g = f.g;
    let dy = |j: u32| offset(j, g.mean[1]);
    let mask: [V; M] = std::array::from_fn(|c| f.inside_lanes(start + c * LANES));
    // `w` the weight, `r` its ratio to the next row's, `k` the ratio of successive `r`
    // (the power is a parabola down a column, its second difference −C). Every lane
    // starts dark (w = 0). A lane outside the box's columns, no pixel of the rule, counts
    // as carried, so that it never asks for a power or an `E`: it carries its 0, and its
    // factor of 0 keeps it out of every alpha.
    let (mut w, mut r) = ([[0f32; LANES]; M], [[0f32; LANES]; M]);
    // (Conditions are folded and tested lane by lane where they are used rather than
    // kept in arrays of booleans, which LLVM packs to bytes and back, splitting the
    // lanes of `w` and `r` across registers.)
    let carried = |w: f32, m: f32| (w >= COLUMN_DARK) | (m == 0.0);
    // (Plain loops, not `Iterator::fold`: LLVM left the fold over a row's lanes out of
    // line, a call compiled without AVX on every row that starts a lane.)
    let all_carried = |w: &[V; M]| {
        let mut all = true;
        for c in 0..M {
            for l in 0..LANES {
                all &= carried(w[c][l], mask[c][l]);
            }
        }
        all
    };
    let blend_row = |into: &mut B, j: u32, w: &[V; M]| {
        blend_chunks::<M, CAP, B>(into, g, (j - rect.y0) as usize * ACC_W + start, w, &mask)
    };
    let mut j = f.ys.start;
    while j < f.ys.end {
        // The rows where every lane is carried: two products per lane, in a loop of its
        // own so that `w` and `r` stay in registers (in one loop with the start below,
        // LLVM kept them on the stack, and each row waited for a store and a load).
        while j < f.ys.end && all_carried(&w) {
            step(&mut w, &mut r, k);
            blend_row(into, j, &w);
            j += 1;
        }
        if j == f.ys.end {
            break;
        }
        // A row with a lane not carried: that lane starts where its power reaches the
        // start level, with `E`; below it, it stays dark.
        let (mut wn, mut rn) = (w, r);
        step(&mut wn, &mut rn, k);
        let (dy0, dy1) = (dy(j), dy(j + 1));
        for c in 0..M {
            let (power, dxs) = f.powers::<false>(start + c * LANES, dy0);
            let mut any = false;
            for l in 0..LANES {
                any |= !carried(w[c][l], mask[c][l]) & (power[l] >= COLUMN_START);
            }
            // (Where no lane of the chunk starts, a lane neither carried nor started
            // takes `r = 0` beside its `w = 0`; that ratio is never used, since a lane
            // below the dark level is not carried and takes both anew at its start.)
            let (w1, r1) = if any {
                f.column_start(&power, &dxs, dy0, dy1)
            } else {
                ([0f32; LANES], [0f32; LANES])
            };
            // The selects as masks on the bits: as `if`s, LLVM took the packed bytes of
            // the test above apart and branched lane by lane.
            for l in 0..LANES {
                let keep = lanes_mask(carried(w[c][l], mask[c][l]));
                let go = lanes_mask(power[l] >= COLUMN_START);
                let started = w1[l].to_bits() & go;
                w[c][l] = f32::from_bits((wn[c][l].to_bits() & keep) | (started & !keep));
                r[c][l] = f32::from_bits((rn[c][l].to_bits() & keep) | (r1[l].to_bits() & !keep));
            }
        }
        blend_row(into, j, &w);
        j += 1;
        if g.carried_throughout() {
            // Every lane of the box started on this row and none can fall below the dark
            // level anywhere in the box: the rows left are carried, without the test
            // (a tenth of the loop's time where it ran on every row). A loop of its own:
            // as a flag or'd into the loop above's test, the render measured 8–10 %
            // slower than this (single thread, kodim23, kodim13, a random scene).
            debug_assert!(all_carried(&w));
            while j < f.ys.end {
                step(&mut w, &mut r, k);
                blend_row(into, j, &w);
                j += 1;
            }
            return;
        }
    }
}

/// One row down the column rule: each weight times its ratio, each ratio times `k`.
/// (A function rather than a closure, as is [`blend_chunks`]: written as closures of
/// `column_rows`, the two were compiled apart from the `#[target_feature]` function,
/// without AVX, and called on every row; kodim23's single-thread render took 20 ms
/// instead of 13.)
#[inline(always)]
fn step<const M: usize>(w: &mut [V; M], r: &mut [V; M], k: f32) {
    for c in 0..M {
        for l in 0..LANES {
            (w[c][l], r[c][l]) = (w[c][l] * r[c][l], r[c][l] * k);
        }
    }
}

/// Blend the alphas of weights `w` (opacity times weight, capped with `CAP`, times the
/// lane's `mask` of 1 or 0, 0 under [`ALPHA_MIN`]) into the `M` chunks from `at`: a
/// chunk at a time or all at once, as [`Blender::BY_CHUNK`] says. `mask` is 1 or 0, and
/// `a·1` is `a`. Every chunk-row is blended, lit or not: adding 0 changes no sum and
/// multiplies no transmittance, and a branch on "lit" measured no faster.
#[inline(always)]
fn blend_chunks<const M: usize, const CAP: bool, B: Blender>(
    into: &mut B,
    g: &Projected,
    at: usize,
    w: &[V; M],
    mask: &[V; M],
) {
    let alpha_of = |c: usize| {
        let mut alpha = [0f32; LANES];
        for l in 0..LANES {
            let a = g.opacity * w[c][l];
            let a = (if CAP { a.min(ALPHA_MAX) } else { a }) * mask[c][l];
            alpha[l] = if a >= ALPHA_MIN { a } else { 0.0 };
        }
        alpha
    };
    if B::BY_CHUNK {
        for c in 0..M {
            into.blend(g, at + c * LANES, &[alpha_of(c)]);
        }
    } else {
        let mut alpha = [[0f32; LANES]; M];
        for (c, alpha) in alpha.iter_mut().enumerate() {
            *alpha = alpha_of(c);
        }
        into.blend(g, at, &alpha);
    }
}

impl Footprint<'_> {
    /// The box's columns `lx0..lx1` relative to the first of the chunk from tile-local
    /// column `start` (negative where the box starts before it): lane `l` lies in the
    /// box where `lx0 <= l < lx1`.
    #[inline(always)]
    fn box_lanes(&self, start: usize) -> (i32, i32) {
        let at = start as i32;
        (self.lx0 as i32 - at, self.lx1 as i32 - at)
    }

    /// 1 in the lanes of the chunk from tile-local column `start` that lie in the box's
    /// columns, 0 in the others: a factor of the alpha, so that its one test also turns
    /// away the lanes outside the box.
    #[inline(always)]
    fn inside_lanes(&self, start: usize) -> V {
        let (lx0, lx1) = self.box_lanes(start);
        std::array::from_fn(|l| f32::from(u8::from((l as i32 >= lx0) & ((l as i32) < lx1))))
    }

    /// The column rule's start at a row whose centre is `dy` from the Gaussian's and
    /// whose next row's is `dy1` (spec §6.3.2), from the row's `power` and the columns'
    /// offsets `dxs`: `w = E(power)` and `r = E(step)`, the step `−0.5·(C·(dy + dy1)) −
    /// B·dx` of the power to the next row.
    #[inline(always)]
    fn column_start(&self, power: &V, dxs: &V, dy: f32, dy1: f32) -> (V, V) {
        let [_, cb, cc] = self.g.conic;
        let half = -0.5 * (cc * (dy + dy1));
        let (mut w, mut r) = ([0f32; LANES], [0f32; LANES]);
        for l in 0..LANES {
            w[l] = exp(power[l]);
            r[l] = exp(half - cb * dxs[l]);
        }
        (w, r)
    }
}

/// Where a chunk-row of alphas goes (a trait rather than a closure: see the module's doc).
trait Blender {
    /// Whether the column rule blends a row of several chunks a chunk at a time, each
    /// chunk's alphas as soon as they are made, rather than all at once (the per-pixel
    /// rule blends one chunk at a time anyway). `sum` blending measured 4–5 % faster a
    /// chunk at a time on the AVX2 build (kodim23 and a random scene, single thread;
    /// kodim23 and kodim13 again on an AMD EPYC with AVX-512, 0.14–0.46 ms of 6–7.6 ms
    /// of parse and render)
    /// but slower on the AVX-512 one, where the two chunks' sums go through one 16-lane
    /// register (0.3 ms, the same renders); `alpha` blending 9–11 % slower, its
    /// count of the pixels that stop then taken twice a row.
    const BY_CHUNK: bool;

    /// Blend Gaussian `g`'s `alpha` into the `M` chunks of [`LANES`] pixels from `at` of
    /// the tile, which lie side by side.
    fn blend<const M: usize>(&mut self, g: &Projected, at: usize, alpha: &[V; M]);
}

/// `sum` blending: `acc += c·alpha`, a chunk at a time unless `WIDE` (see
/// [`Blender::BY_CHUNK`]).
struct Sum<'a, const WIDE: bool>(&'a mut Acc);

impl<const WIDE: bool> Blender for Sum<'_, WIDE> {
    const BY_CHUNK: bool = !WIDE;

    #[inline(always)]
    fn blend<const M: usize>(&mut self, g: &Projected, at: usize, alpha: &[V; M]) {
        let color = g.color;
        for (plane, c) in self.0 .0.iter_mut().zip(color) {
            for (chunk, alpha) in alpha.iter().enumerate() {
                let px = &mut plane[at + chunk * LANES..][..LANES];
                // Where alpha is 0 this adds ±0, which leaves every sum as it is: a sum
                // that starts at +0 is never −0.
                for l in 0..LANES {
                    px[l] += c * alpha[l];
                }
            }
        }
    }
}

/// `alpha` blending: front to back, with per-pixel transmittance, counting the pixels
/// that still take light.
struct Over<'a> {
    acc: &'a mut Acc,
    trans: [f32; ACC_W * TILE_H],
    live: usize,
}

impl Blender for Over<'_> {
    const BY_CHUNK: bool = false;

    #[inline(always)]
    fn blend<const M: usize>(&mut self, g: &Projected, at: usize, alpha: &[V; M]) {
        let mut died = 0;
        for (chunk, alpha) in alpha.iter().enumerate() {
            let at = at + chunk * LANES;
            let t = &mut self.trans[at..at + LANES];
            let mut a = [0f32; LANES];
            for l in 0..LANES {
                // A pixel that stopped takes nothing more; alpha 0 leaves `t` as it is.
                a[l] = if t[l] < TRANSMITTANCE_MIN {
                    0.0
                } else {
                    alpha[l]
                };
            }
            for (ch, plane) in self.acc.0.iter_mut().enumerate() {
                let px = &mut plane[at..at + LANES];
                for l in 0..LANES {
                    px[l] += g.color[ch] * a[l] * t[l];
                }
            }
            for l in 0..LANES {
                let before = t[l];
                t[l] = before * (1.0 - a[l]);
                died += usize::from((before >= TRANSMITTANCE_MIN) & (t[l] < TRANSMITTANCE_MIN));
            }
        }
        self.live -= died;
    }
}

/// `sum` blending: `acc += c·alpha` for every Gaussian of the tile, in list order.
#[inline(always)]
fn tile_sum<const WIDE: bool, const COLUMNS: bool>(
    list: &[u32],
    proj: &[Projected],
    (rect, band): (Rect, u32),
    acc: &mut Acc,
) {
    let mut into = Sum::<WIDE>(acc);
    for &k in list {
        let g = &proj[k as usize];
        if let Some(f) = Footprint::of(g, rect) {
            chunk_rows::<WIDE, false, COLUMNS>(&f, (rect, band), &mut into);
        }
    }
}

/// `alpha` blending: front to back in list order, with per-pixel transmittance; the tile
/// is done when no pixel of it takes light.
#[inline(always)]
fn tile_alpha<const WIDE: bool, const COLUMNS: bool>(
    list: &[u32],
    proj: &[Projected],
    (rect, band): (Rect, u32),
    acc: &mut Acc,
) {
    let mut into = Over {
        acc,
        trans: [1.0f32; ACC_W * TILE_H],
        live: ((rect.x1 - rect.x0) * (rect.y1 - rect.y0)) as usize,
    };
    for &k in list {
        let g = &proj[k as usize];
        if let Some(f) = Footprint::of(g, rect) {
            chunk_rows::<WIDE, true, COLUMNS>(&f, (rect, band), &mut into);
        }
        if into.live == 0 {
            break;
        }
    }
}

/// The same loops compiled for AVX2, and for AVX-512.
#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::*;

    #[target_feature(enable = "avx2")]
    pub fn tile_avx2(
        blend: Blend,
        columns: Option<u32>,
        list: &[u32],
        proj: &[Projected],
        rect: Rect,
        acc: &mut Acc,
    ) {
        tile::<false>(blend, columns, list, proj, rect, acc)
    }

    #[target_feature(enable = "avx2,avx512f,avx512vl")]
    pub fn tile_avx512(
        blend: Blend,
        columns: Option<u32>,
        list: &[u32],
        proj: &[Projected],
        rect: Rect,
        acc: &mut Acc,
    ) {
        tile::<true>(blend, columns, list, proj, rect, acc)
    }
}
