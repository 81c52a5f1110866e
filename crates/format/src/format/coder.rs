//! The binary adaptive range coder of compression methods 2 and 3 (spec §5.4.1), the raw
//! bits that method 3 keeps beside it (§5.4.4), and the ways integers are turned into
//! decisions and raw bits (§5.4.2, §5.4.4).
//!
//! Written here rather than taken from a crate because the spec must fix every bit of it:
//! an independent decoder reproduces the stream from the spec's few lines, and no crate's
//! internal conventions (state width, renormalization, flush) can change under the format.
//! The arithmetic is the classic carry-less binary range coder (as in LZMA): 32-bit range,
//! 12-bit probabilities that move 1/32 of the way towards each decision they code.

use super::error::{Error, ErrorKind, Result};

/// Probabilities are `p / 4096` that the next decision is 0.
const PROB_BITS: u32 = 12;
const PROB_ONE: u16 = 1 << PROB_BITS;
/// How fast a probability adapts: it moves `1/2^ADAPT` of the way per decision.
const ADAPT: u32 = 5;
/// Below this the range is renormalized by one byte.
const TOP: u32 = 1 << 24;

/// One adaptive probability (a context), starting at one half.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Prob(u16);

impl Default for Prob {
    fn default() -> Self {
        Prob(PROB_ONE / 2)
    }
}

impl Prob {
    #[inline]
    fn update(&mut self, bit: bool) {
        if bit {
            self.0 -= self.0 >> ADAPT;
        } else {
            self.0 += (PROB_ONE - self.0) >> ADAPT;
        }
    }
}

/// Where decisions go: the range encoder, or a meter that only adds up their cost (so an
/// encoder can compare ways of coding a component without producing bytes).
pub trait Sink {
    fn bit(&mut self, p: &mut Prob, bit: bool);
    /// The `n` low bits of `v` (`n ≤ 56`), most significant first, as raw bits (§5.4.4).
    fn raw(&mut self, v: u64, n: u32);
}

/// Raw bits, most significant first, filled from the most significant bit of each byte
/// and padded with zeros to a whole byte (§5.4.4).
#[derive(Default)]
struct RawWriter {
    out: Vec<u8>,
    /// Bits not yet a whole byte, in the low `pending` bits.
    acc: u64,
    pending: u32,
}

impl RawWriter {
    fn put(&mut self, v: u64, n: u32) {
        debug_assert!(n <= 56 && v >> n == 0);
        self.acc = (self.acc << n) | v;
        self.pending += n;
        while self.pending >= 8 {
            self.pending -= 8;
            self.out.push((self.acc >> self.pending) as u8);
        }
        self.acc &= (1 << self.pending) - 1;
    }

    fn finish(mut self) -> Vec<u8> {
        if self.pending > 0 {
            self.out.push((self.acc << (8 - self.pending)) as u8);
        }
        self.out
    }
}

/// The range encoder.
pub struct Encoder {
    low: u64,
    range: u32,
    cache: u8,
    cache_size: u64,
    out: Vec<u8>,
    raw: RawWriter,
}

impl Encoder {
    pub fn new() -> Self {
        Encoder {
            low: 0,
            range: u32::MAX,
            cache: 0,
            cache_size: 1,
            out: Vec::new(),
            raw: RawWriter::default(),
        }
    }

    fn shift_low(&mut self) {
        if (self.low as u32) < 0xFF00_0000 || (self.low >> 32) != 0 {
            let carry = (self.low >> 32) as u8;
            let mut byte = self.cache;
            while self.cache_size > 0 {
                self.out.push(byte.wrapping_add(carry));
                byte = 0xFF;
                self.cache_size -= 1;
            }
            self.cache = (self.low >> 24) as u8;
        }
        self.cache_size += 1;
        self.low = (self.low & 0x00FF_FFFF) << 8;
    }

    /// The coded bytes, where no raw bits were written (method 2's tests).
    #[cfg(test)]
    pub fn finish(self) -> Vec<u8> {
        let (stream, raw) = self.finish_with_raw();
        debug_assert!(raw.is_empty(), "method 2 has no raw bits");
        stream
    }

    /// The coded bytes and the raw bits' bytes (none in method 2). The classic coder's
    /// first byte is always 0 (nothing can carry into it), so it is not stored.
    pub fn finish_with_raw(mut self) -> (Vec<u8>, Vec<u8>) {
        for _ in 0..5 {
            self.shift_low();
        }
        debug_assert_eq!(self.out.first(), Some(&0));
        self.out.remove(0);
        (self.out, self.raw.finish())
    }
}

impl Sink for Encoder {
    #[inline]
    fn bit(&mut self, p: &mut Prob, bit: bool) {
        let bound = (self.range >> PROB_BITS) * u32::from(p.0);
        if bit {
            self.low += u64::from(bound);
            self.range -= bound;
        } else {
            self.range = bound;
        }
        p.update(bit);
        while self.range < TOP {
            self.range <<= 8;
            self.shift_low();
        }
    }

    fn raw(&mut self, v: u64, n: u32) {
        self.raw.put(v, n);
    }
}

/// Adds up `-log2` of the probability of every decision: the bits a range coder spends,
/// to within its few bytes of flush.
#[derive(Default)]
pub struct Meter(pub f64);

impl Sink for Meter {
    #[inline]
    fn bit(&mut self, p: &mut Prob, bit: bool) {
        let p0 = f64::from(p.0) / f64::from(PROB_ONE);
        self.0 -= if bit { (1.0 - p0).log2() } else { p0.log2() };
        p.update(bit);
    }

    fn raw(&mut self, _v: u64, n: u32) {
        self.0 += f64::from(n);
    }
}

/// All ones where `b`, else 0: a mask for selecting bits without a branch.
#[inline(always)]
fn all_ones(b: bool) -> u32 {
    u32::from(b).wrapping_neg()
}

/// The range decoder over one payload's coded bytes, and the reader of its raw bits.
pub struct Decoder<'a> {
    data: &'a [u8],
    at: usize,
    range: u32,
    code: u32,
    raw: &'a [u8],
    /// Raw bits read so far.
    raw_at: usize,
}

fn corrupt(detail: impl Into<String>) -> Error {
    Error::new(ErrorKind::Decompression, detail)
}

impl<'a> Decoder<'a> {
    /// A decoder of `data`'s decisions, with no raw bits (method 2's tests).
    #[cfg(test)]
    pub fn new(data: &'a [u8]) -> Result<Self> {
        Self::with_raw(data, &[])
    }

    /// A decoder of `data`'s decisions and of the raw bits in `raw` (method 3).
    pub fn with_raw(data: &'a [u8], raw: &'a [u8]) -> Result<Self> {
        let mut d = Decoder {
            data,
            at: 0,
            range: u32::MAX,
            code: 0,
            raw,
            raw_at: 0,
        };
        for _ in 0..4 {
            d.code = (d.code << 8) | u32::from(d.next()?);
        }
        // `code < range` holds from here on for every stream; one that starts at the top
        // of the range could not have been written by an encoder.
        if d.code == u32::MAX {
            return Err(corrupt("coded stream starts with FF FF FF FF"));
        }
        Ok(d)
    }

    fn next(&mut self) -> Result<u8> {
        let b = *self
            .data
            .get(self.at)
            .ok_or_else(|| corrupt("coded stream ends before its last code"))?;
        self.at += 1;
        Ok(b)
    }

    /// One decision, or an error where the stream has ended before it.
    #[inline(always)]
    pub fn bit(&mut self, p: &mut Prob) -> Result<bool> {
        let bit = self.decide(p);
        self.in_time()?;
        Ok(bit)
    }

    /// Whether every byte and raw bit read so far lies in the payload: past their ends,
    /// [`Decoder::decide`] and [`Decoder::raw_bits`] read zeros, so that a value's
    /// decisions and bits need no test each, only the value.
    #[inline(always)]
    fn in_time(&self) -> Result<()> {
        if self.at > self.data.len() {
            return Err(corrupt("coded stream ends before its last code"));
        }
        if self.raw_at > 8 * self.raw.len() {
            return Err(corrupt("raw bits end before the last code"));
        }
        Ok(())
    }

    /// The next `n ≤ 56` raw bits, most significant first, without the test that they lie
    /// in the payload ([`Decoder::in_time`]), which the caller makes once a value.
    #[inline(always)]
    fn raw_bits(&mut self, n: u32) -> u64 {
        debug_assert!(n <= 56);
        let (byte, skip) = (self.raw_at / 8, (self.raw_at % 8) as u32);
        // Eight bytes from the one holding the next bit (zeros past the end): with at most
        // 7 bits skipped, they hold the next 57 bits.
        let window = match self.raw.get(byte..byte + 8) {
            Some(b) => u64::from_be_bytes(b.try_into().expect("8 bytes")),
            None => {
                let mut b = [0u8; 8];
                let rest = self.raw.get(byte..).unwrap_or(&[]);
                b[..rest.len()].copy_from_slice(rest);
                u64::from_be_bytes(b)
            }
        };
        self.raw_at += n as usize;
        // Two shifts, so that n = 0 shifts by 64 in neither.
        (window << skip) >> 1 >> (63 - n)
    }

    /// One decision, without the test that the stream has not ended ([`Decoder::in_time`]),
    /// which the caller makes once a value.
    #[inline(always)]
    fn decide(&mut self, p: &mut Prob) -> bool {
        let bound = (self.range >> PROB_BITS) * u32::from(p.0);
        let bit = self.code >= bound;
        // Without branches: the decision is as unpredictable as the data, and a
        // mispredicted branch per decision cost more than the arithmetic (a third of the
        // decode time on a fitted Kodak file).
        let ones = all_ones(bit);
        self.code -= bound & ones;
        self.range = (bound & !ones) | (self.range.wrapping_sub(bound) & ones);
        let (up, down) = (p.0 + ((PROB_ONE - p.0) >> ADAPT), p.0 - (p.0 >> ADAPT));
        p.0 = if bit { down } else { up };
        // One byte at most: the range was at least 2^24 and keeps at least 31/4096 of
        // itself (a probability stays within 31..=4065), so one shift restores 2^24. As
        // selects rather than a branch, which went one way or the other as the data did.
        let shift = self.range < TOP;
        let byte = self.data.get(self.at).copied().unwrap_or(0);
        let n = 8 * u32::from(shift);
        self.range <<= n;
        self.code = (self.code << n) | (u32::from(byte) & all_ones(shift));
        self.at += usize::from(shift);
        debug_assert!(self.range >= TOP);
        bit
    }

    /// A code of `bits` raw bits (mode 4).
    #[inline(always)]
    pub fn raw_code(&mut self, bits: u8) -> Result<u32> {
        let q = self.raw_bits(u32::from(bits)) as u32;
        self.in_time()?;
        Ok(q)
    }

    /// Every byte must have been read, and every raw bit but the last byte's padding,
    /// which must be zeros: an encoder writes no more than it needs.
    pub fn finish(self) -> Result<()> {
        self.in_time()?;
        match self.data.len() - self.at {
            0 => {}
            left => {
                return Err(corrupt(format!(
                    "{left} bytes left after the last code of the coded stream"
                )))
            }
        }
        let padding = 8 * self.raw.len() - self.raw_at;
        if padding >= 8 {
            return Err(corrupt(format!(
                "{} raw bytes left after the last code",
                padding / 8
            )));
        }
        if padding > 0 && self.raw[self.raw.len() - 1] & ((1u8 << padding) - 1) != 0 {
            return Err(corrupt("raw bits padded with ones"));
        }
        Ok(())
    }
}

/// Widest magnitude [`Magnitude`] codes: 2^49 − 1 covers any Morton step of two 24-bit
/// components.
pub const MAX_MAGNITUDE_BITS: usize = 49;

/// Contexts of an unsigned magnitude coded as an adaptive Exp-Golomb code (§5.4.2):
/// `e`, the bit length of `m + 1` minus one, in unary (a context per position), then the
/// `e` bits below the leading one, most significant first, a context per `(e, bit)`.
#[derive(Clone)]
pub struct Magnitude {
    unary: [Prob; MAX_MAGNITUDE_BITS],
    // A fixed array, so that the decoder's indices need no bounds check.
    mantissa: Box<[Prob; MAX_MAGNITUDE_BITS * MAX_MAGNITUDE_BITS]>,
}

impl Default for Magnitude {
    fn default() -> Self {
        Magnitude {
            unary: [Prob::default(); MAX_MAGNITUDE_BITS],
            mantissa: Box::new([Prob::default(); MAX_MAGNITUDE_BITS * MAX_MAGNITUDE_BITS]),
        }
    }
}

/// `e` in unary, a context per position: the prefix of §5.4.2's magnitude(L), which
/// method 3 keeps for residuals.
fn put_unary<S: Sink>(unary: &mut [Prob; MAX_MAGNITUDE_BITS], s: &mut S, e: usize) {
    for p in &mut unary[..e] {
        s.bit(p, true);
    }
    s.bit(&mut unary[e], false);
}

/// The unary prefix `e` of [`put_unary`], refused as soon as it reaches `max_bits`
/// (≤ [`MAX_MAGNITUDE_BITS`]).
#[inline(always)]
fn get_unary(
    unary: &mut [Prob; MAX_MAGNITUDE_BITS],
    d: &mut Decoder,
    max_bits: usize,
) -> Result<usize> {
    let mut e = 0;
    while d.decide(&mut unary[e]) {
        e += 1;
        if e >= max_bits {
            d.in_time()?;
            return Err(too_wide(max_bits));
        }
    }
    Ok(e)
}

fn too_wide(max_bits: usize) -> Error {
    corrupt(format!("coded magnitude of more than {max_bits} bits"))
}

impl MagnitudeCode for Magnitude {
    fn put<S: Sink>(&mut self, s: &mut S, m: u64) {
        let v = m + 1;
        let e = 63 - v.leading_zeros() as usize;
        debug_assert!(e < MAX_MAGNITUDE_BITS);
        put_unary(&mut self.unary, s, e);
        for j in (0..e).rev() {
            s.bit(
                &mut self.mantissa[e * MAX_MAGNITUDE_BITS + j],
                (v >> j) & 1 == 1,
            );
        }
    }

    #[inline(always)]
    fn get(&mut self, d: &mut Decoder, max_bits: usize) -> Result<u64> {
        let e = get_unary(&mut self.unary, d, max_bits.min(MAX_MAGNITUDE_BITS))?;
        let mut v = 1u64;
        for j in (0..e).rev() {
            let b = d.decide(&mut self.mantissa[e * MAX_MAGNITUDE_BITS + j]);
            v = (v << 1) | u64::from(b);
        }
        d.in_time()?;
        Ok(v - 1)
    }
}

/// An unsigned magnitude's binarization and its contexts: method 2's [`Magnitude`] or
/// method 3's [`SplitMagnitude`], so that one [`Signed`] and one loop code either.
pub trait MagnitudeCode: Default {
    /// Code `m`; `m + 1` must be below `2^max_bits` for the decoder's bound.
    fn put<S: Sink>(&mut self, s: &mut S, m: u64);
    /// Decode a magnitude `m`; one with `m + 1 ≥ 2^max_bits` is refused
    /// (`max_bits` ≤ [`MAX_MAGNITUDE_BITS`]).
    fn get(&mut self, d: &mut Decoder, max_bits: usize) -> Result<u64>;
}

/// A signed value: its magnitude (method 2's [`Magnitude`] unless `M` says otherwise),
/// then, if not 0, a sign decision (1 = negative) in one context.
#[derive(Clone, Default)]
pub struct Signed<M = Magnitude> {
    magnitude: M,
    sign: Prob,
}

impl<M: MagnitudeCode> Signed<M> {
    pub fn put<S: Sink>(&mut self, s: &mut S, r: i64) {
        self.magnitude.put(s, r.unsigned_abs());
        if r != 0 {
            s.bit(&mut self.sign, r < 0);
        }
    }

    #[inline(always)]
    pub fn get(&mut self, d: &mut Decoder, max_bits: usize) -> Result<i64> {
        let m = self.magnitude.get(d, max_bits)? as i64;
        if m != 0 && d.bit(&mut self.sign)? {
            return Ok(-m);
        }
        Ok(m)
    }
}

/// Bits of a code coded through a binary tree: the top `TREE_BITS` bits with one context
/// per node (an adaptive model of their whole distribution), the bits below with one
/// context per bit position.
pub const TREE_BITS: u8 = 8;

/// Nodes of the deepest [`Tree`], and room for its last level's children (see `get`).
const TREE_NODES: usize = 2 << TREE_BITS;

#[derive(Clone)]
pub struct Tree {
    bits: u8,
    /// Levels of the tree: `bits`, at most [`TREE_BITS`] (`new`) or [`SPLIT_TREE_BITS`]
    /// (`split`).
    top: u8,
    /// The bits below the tree raw (method 3) rather than in `low`'s contexts.
    raw_low: bool,
    // A fixed array, so that an index masked to it needs no bounds check in the decoder's
    // loop.
    nodes: Box<[Prob; TREE_NODES]>,
    low: Vec<Prob>,
}

/// Levels of method 3's trees (§5.4.4): below them, the bits of a quantized attribute's
/// code are close to uniform, and adaptive contexts spend time and, while they adapt, a
/// few bits more than raw bits. The twelve `photos12` files at 1 bpp, recoded with 4, 5,
/// 6 and 8 levels: 717,571, 716,655, 716,925 and 717,106 bytes, 5 the smallest in 11
/// files (the twelfth 3 bytes larger than with 6).
pub const SPLIT_TREE_BITS: u8 = 5;

impl Tree {
    /// `tree(bits)` of §5.4.2 (method 2).
    pub fn new(bits: u8) -> Self {
        Self::with_top(bits, bits.min(TREE_BITS), false)
    }

    /// `tree3(bits)` of §5.4.4 (method 3): [`SPLIT_TREE_BITS`] levels, the bits below
    /// them raw.
    pub fn split(bits: u8) -> Self {
        Self::with_top(bits, bits.min(SPLIT_TREE_BITS), true)
    }

    fn with_top(bits: u8, top: u8, raw_low: bool) -> Self {
        let low = if raw_low { 0 } else { bits - top };
        Tree {
            bits,
            top,
            raw_low,
            nodes: Box::new([Prob::default(); TREE_NODES]),
            low: vec![Prob::default(); usize::from(low)],
        }
    }

    pub fn put<S: Sink>(&mut self, s: &mut S, q: u32) {
        let (top, rest) = (self.top, self.bits - self.top);
        let mut node = 1usize;
        for j in (0..top).rev() {
            let b = (q >> (rest + j)) & 1 == 1;
            s.bit(&mut self.nodes[node], b);
            node = 2 * node + usize::from(b);
        }
        if self.raw_low {
            s.raw(u64::from(q) & ((1 << rest) - 1), u32::from(rest));
            return;
        }
        for j in (0..rest).rev() {
            s.bit(&mut self.low[usize::from(j)], (q >> j) & 1 == 1);
        }
    }

    #[inline(always)]
    pub fn get(&mut self, d: &mut Decoder) -> Result<u32> {
        let (top, rest) = (self.top, self.bits - self.top);
        let mut node = 1usize;
        let mut p = self.nodes[1];
        for _ in 0..top {
            // Both children's contexts are read while this node's decision is made, so
            // that the next decision waits for a select, not a load. (The last level's
            // children are the padding past the tree, never decided.)
            // (`node` stays below 2^top ≤ TREE_NODES / 2: the masks only tell the compiler.)
            let children = [
                self.nodes[(2 * node) % TREE_NODES],
                self.nodes[(2 * node + 1) % TREE_NODES],
            ];
            let bit = d.decide(&mut p);
            self.nodes[node % TREE_NODES] = p;
            node = 2 * node + usize::from(bit);
            p = children[usize::from(bit)];
        }
        let mut q = (node - (1 << top)) as u32;
        if self.raw_low {
            q = (q << rest) | d.raw_bits(u32::from(rest)) as u32;
        } else {
            for j in (0..rest).rev() {
                q = (q << 1) | u32::from(d.decide(&mut self.low[usize::from(j)]));
            }
        }
        d.in_time()?;
        Ok(q)
    }
}

/// Levels of the tree of a Morton step's `e` in method 3 (§5.4.4): `e` ≤ 48.
const EXPONENT_BITS: u8 = 6;

/// Method 3's unsigned magnitude (§5.4.4): `e` as in [`Magnitude`], in unary, or with
/// `TREE` through a tree of [`EXPONENT_BITS`] levels; then the bit below the leading one
/// in a context per `e`, and the `e − 1` bits below it raw. Those lower bits gain nothing
/// from contexts (kodim23 at 1 bpp: 19.98 bits a Gaussian in contexts, 19.89 raw), and
/// raw they cost the decoder no decision each. `TREE` is for steps along the Morton
/// curve, whose `e` is about 10: six decisions rather than eleven, and fewer bytes too
/// (`photos12` recoded with unary steps: 717,167 bytes against 716,655).
#[derive(Clone)]
pub struct SplitMagnitude<const TREE: bool> {
    unary: [Prob; MAX_MAGNITUDE_BITS],
    /// `e`'s tree: `Some` exactly with `TREE`.
    exponent: Option<Tree>,
    top: [Prob; MAX_MAGNITUDE_BITS],
}

impl<const TREE: bool> Default for SplitMagnitude<TREE> {
    fn default() -> Self {
        SplitMagnitude {
            unary: [Prob::default(); MAX_MAGNITUDE_BITS],
            exponent: TREE.then(|| Tree::new(EXPONENT_BITS)),
            top: [Prob::default(); MAX_MAGNITUDE_BITS],
        }
    }
}

impl<const TREE: bool> MagnitudeCode for SplitMagnitude<TREE> {
    fn put<S: Sink>(&mut self, s: &mut S, m: u64) {
        let v = m + 1;
        let e = 63 - v.leading_zeros() as usize;
        debug_assert!(e < MAX_MAGNITUDE_BITS);
        match (TREE, &mut self.exponent) {
            (true, Some(tree)) => tree.put(s, e as u32),
            _ => put_unary(&mut self.unary, s, e),
        }
        if e >= 1 {
            s.bit(&mut self.top[e], (v >> (e - 1)) & 1 == 1);
            s.raw(v & ((1 << (e - 1)) - 1), e as u32 - 1);
        }
    }

    #[inline(always)]
    fn get(&mut self, d: &mut Decoder, max_bits: usize) -> Result<u64> {
        let max_bits = max_bits.min(MAX_MAGNITUDE_BITS);
        let e = match (TREE, &mut self.exponent) {
            (true, Some(tree)) => {
                let e = tree.get(d)? as usize;
                if e >= max_bits {
                    return Err(too_wide(max_bits));
                }
                e
            }
            _ => get_unary(&mut self.unary, d, max_bits)?,
        };
        let mut v = 1u64;
        if e >= 1 {
            // (`e` < MAX_MAGNITUDE_BITS: the mask only tells the compiler.)
            v = 2 | u64::from(d.decide(&mut self.top[e % MAX_MAGNITUDE_BITS]));
            v = (v << (e - 1)) | d.raw_bits(e as u32 - 1);
        }
        d.in_time()?;
        Ok(v - 1)
    }
}

#[cfg(test)]
pub mod tests {
    use super::*;

    /// Uniform values in [0, 1) from a seed (the library's own generator is an encoder
    /// module; the format must test without it).
    pub fn test_rng(mut state: u64) -> impl FnMut() -> f32 {
        move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    #[test]
    fn decisions_roundtrip_and_every_byte_is_read() {
        let mut rng = test_rng(7);
        for n in [0usize, 1, 2, 10, 1000, 100_000] {
            let bits: Vec<bool> = (0..n)
                .map(|i| rng() < 0.1 + 0.8 * ((i / 50) % 2) as f32)
                .collect();
            let mut e = Encoder::new();
            let mut ctx = [Prob::default(); 2];
            for (i, &b) in bits.iter().enumerate() {
                e.bit(&mut ctx[i % 2], b);
            }
            let bytes = e.finish();
            let mut d = Decoder::new(&bytes).unwrap();
            let mut ctx = [Prob::default(); 2];
            for (i, &b) in bits.iter().enumerate() {
                assert_eq!(d.bit(&mut ctx[i % 2]).unwrap(), b, "n {n} at {i}");
            }
            d.finish().unwrap();
        }
    }

    #[test]
    fn long_runs_carry_correctly() {
        // Runs of likely decisions push `low` towards a carry through 0xFF bytes.
        for first in [false, true] {
            let mut e = Encoder::new();
            let mut p = Prob::default();
            let seq: Vec<bool> = (0..50_000).map(|i| (i % 997 == 0) ^ first).collect();
            for &b in &seq {
                e.bit(&mut p, b);
            }
            let bytes = e.finish();
            let mut d = Decoder::new(&bytes).unwrap();
            let mut p = Prob::default();
            for &b in &seq {
                assert_eq!(d.bit(&mut p).unwrap(), b);
            }
            d.finish().unwrap();
        }
    }

    #[test]
    fn integers_roundtrip_through_their_binarizations() {
        let mut rng = test_rng(3);
        let mags: Vec<u64> = (0..3000)
            .map(|i| match i % 4 {
                0 => 0,
                1 => (rng() * 40.0) as u64,
                2 => (1u64 << 48) - 2,
                _ => (rng() as f64 * 1e9) as u64,
            })
            .collect();
        let codes: Vec<u32> = (0..3000).map(|i| (i * 7919 % 4096) as u32).collect();
        let mut e = Encoder::new();
        let (mut m, mut s, mut t) = (
            Magnitude::default(),
            Signed::<Magnitude>::default(),
            Tree::new(12),
        );
        for (i, (&v, &q)) in mags.iter().zip(&codes).enumerate() {
            m.put(&mut e, v);
            s.put(&mut e, if i % 2 == 0 { v as i64 } else { -(v as i64) });
            t.put(&mut e, q);
        }
        let bytes = e.finish();
        let mut d = Decoder::new(&bytes).unwrap();
        let (mut m, mut s, mut t) = (
            Magnitude::default(),
            Signed::<Magnitude>::default(),
            Tree::new(12),
        );
        for (i, (&v, &q)) in mags.iter().zip(&codes).enumerate() {
            assert_eq!(m.get(&mut d, 49).unwrap(), v);
            let r = s.get(&mut d, 49).unwrap();
            assert_eq!(r, if i % 2 == 0 { v as i64 } else { -(v as i64) });
            assert_eq!(t.get(&mut d).unwrap(), q);
        }
        d.finish().unwrap();
    }

    #[test]
    fn split_binarizations_roundtrip_with_their_raw_bits() {
        let mut rng = test_rng(9);
        let mags: Vec<u64> = (0..3000)
            .map(|i| match i % 5 {
                0 => 0,
                1 => 1,
                2 => (rng() * 40.0) as u64,
                3 => (1u64 << 48) - 2,
                _ => (rng() as f64 * 1e9) as u64,
            })
            .collect();
        let codes: Vec<u32> = (0..3000).map(|i| (i * 7919 % 4096) as u32).collect();
        let mut e = Encoder::new();
        let mut m = SplitMagnitude::<false>::default();
        let mut s = Signed::<SplitMagnitude<true>>::default();
        let (mut t, mut small) = (Tree::split(12), Tree::split(3));
        for (i, (&v, &q)) in mags.iter().zip(&codes).enumerate() {
            m.put(&mut e, v);
            s.put(&mut e, if i % 2 == 0 { v as i64 } else { -(v as i64) });
            t.put(&mut e, q);
            small.put(&mut e, q % 8);
            e.raw(q.into(), 12);
        }
        let (bytes, raw) = e.finish_with_raw();
        let mut d = Decoder::with_raw(&bytes, &raw).unwrap();
        let mut m = SplitMagnitude::<false>::default();
        let mut s = Signed::<SplitMagnitude<true>>::default();
        let (mut t, mut small) = (Tree::split(12), Tree::split(3));
        for (i, (&v, &q)) in mags.iter().zip(&codes).enumerate() {
            assert_eq!(m.get(&mut d, 49).unwrap(), v);
            let r = s.get(&mut d, 49).unwrap();
            assert_eq!(r, if i % 2 == 0 { v as i64 } else { -(v as i64) });
            assert_eq!(t.get(&mut d).unwrap(), q);
            assert_eq!(small.get(&mut d).unwrap(), q % 8);
            assert_eq!(d.raw_code(12).unwrap(), q);
        }
        d.finish().unwrap();
        // A magnitude wider than allowed, by the tree of `e` and by its unary prefix.
        let mut e = Encoder::new();
        Signed::<SplitMagnitude<true>>::default().put(&mut e, 1 << 20);
        SplitMagnitude::<false>::default().put(&mut e, 1 << 20);
        let (bytes, raw) = e.finish_with_raw();
        let mut d = Decoder::with_raw(&bytes, &raw).unwrap();
        assert!(Signed::<SplitMagnitude<true>>::default()
            .get(&mut d, 8)
            .is_err());
        let mut d = Decoder::with_raw(&bytes, &raw).unwrap();
        Signed::<SplitMagnitude<true>>::default()
            .get(&mut d, 49)
            .unwrap();
        assert!(SplitMagnitude::<false>::default().get(&mut d, 8).is_err());
    }

    #[test]
    fn raw_bits_are_most_significant_first_and_padded_with_zeros() {
        let mut e = Encoder::new();
        e.raw(0b101, 3);
        e.raw(0, 0);
        e.raw(0b1, 1);
        e.raw(0xABCDE, 20);
        e.raw(1, 1);
        let (_, raw) = e.finish_with_raw();
        // 101, (nothing), 1, 1010 1011 1100 1101 1110, 1, then 7 bits of padding.
        assert_eq!(raw, [0b1011_1010, 0b1011_1100, 0b1101_1110, 0b1000_0000]);
    }

    #[test]
    fn malformed_streams_are_refused_not_panicked_on() {
        assert!(Decoder::new(&[0, 0, 0]).is_err());
        assert!(Decoder::new(&[0xFF; 4]).is_err());
        // A magnitude wider than allowed.
        let mut e = Encoder::new();
        Magnitude::default().put(&mut e, 1 << 20);
        let bytes = e.finish();
        let mut d = Decoder::new(&bytes).unwrap();
        assert!(Magnitude::default().get(&mut d, 8).is_err());
        // Bytes left over.
        let mut e = Encoder::new();
        e.bit(&mut Prob::default(), true);
        let mut bytes = e.finish();
        bytes.push(0);
        let mut d = Decoder::new(&bytes).unwrap();
        d.bit(&mut Prob::default()).unwrap();
        assert!(d.finish().is_err());
        // A stream cut short: the value whose decisions read past its end is refused as
        // cut, not decoded from the zeros read there.
        let mut e = Encoder::new();
        let (mut m, mut t) = (Magnitude::default(), Tree::new(12));
        for v in 0..200u64 {
            m.put(&mut e, v * 977);
            t.put(&mut e, (v * 31) as u32 % 4096);
        }
        let bytes = e.finish();
        for cut in [4, 9, bytes.len() / 2, bytes.len() - 1] {
            let mut d = Decoder::new(&bytes[..cut]).unwrap();
            let (mut m, mut t) = (Magnitude::default(), Tree::new(12));
            let err = (0..200)
                .find_map(|_| m.get(&mut d, 20).and_then(|_| t.get(&mut d)).err())
                .expect("a cut stream is refused");
            assert!(err.to_string().contains("ends before"), "cut {cut}: {err}");
        }
        // Arbitrary bytes decode to something or fail; they never panic.
        let mut rng = test_rng(1);
        for len in 4..64 {
            let junk: Vec<u8> = (0..len).map(|_| (rng() * 256.0) as u8).collect();
            if let Ok(mut d) = Decoder::new(&junk) {
                let mut m = Magnitude::default();
                for _ in 0..100 {
                    if m.get(&mut d, 49).is_err() {
                        break;
                    }
                }
            }
        }
    }
}
