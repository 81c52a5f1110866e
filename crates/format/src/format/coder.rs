//! The binary adaptive range coder of compression method 2 (spec §5.4.1) and the ways
//! integers are turned into its binary decisions (§5.4.2).
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
}

/// The range encoder.
pub struct Encoder {
    low: u64,
    range: u32,
    cache: u8,
    cache_size: u64,
    out: Vec<u8>,
}

impl Encoder {
    pub fn new() -> Self {
        Encoder {
            low: 0,
            range: u32::MAX,
            cache: 0,
            cache_size: 1,
            out: Vec::new(),
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

    /// The coded bytes. The classic coder's first byte is always 0 (nothing can carry
    /// into it), so it is not stored.
    pub fn finish(mut self) -> Vec<u8> {
        for _ in 0..5 {
            self.shift_low();
        }
        debug_assert_eq!(self.out.first(), Some(&0));
        self.out.remove(0);
        self.out
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
}

/// All ones where `b`, else 0: a mask for selecting bits without a branch.
#[inline(always)]
fn all_ones(b: bool) -> u32 {
    u32::from(b).wrapping_neg()
}

/// The range decoder over one payload's coded bytes.
pub struct Decoder<'a> {
    data: &'a [u8],
    at: usize,
    range: u32,
    code: u32,
}

fn corrupt(detail: impl Into<String>) -> Error {
    Error::new(ErrorKind::Decompression, detail)
}

impl<'a> Decoder<'a> {
    pub fn new(data: &'a [u8]) -> Result<Self> {
        let mut d = Decoder {
            data,
            at: 0,
            range: u32::MAX,
            code: 0,
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

    /// Whether every byte read so far lies in the stream: past its end, [`Decoder::decide`]
    /// reads zeros, so that a value's decisions need no test each, only the value.
    #[inline(always)]
    fn in_time(&self) -> Result<()> {
        if self.at > self.data.len() {
            return Err(corrupt("coded stream ends before its last code"));
        }
        Ok(())
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

    /// Every byte must have been read: an encoder writes no more than it needs.
    pub fn finish(self) -> Result<()> {
        self.in_time()?;
        match self.data.len() - self.at {
            0 => Ok(()),
            left => Err(corrupt(format!(
                "{left} bytes left after the last code of the coded stream"
            ))),
        }
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

impl Magnitude {
    /// Code `m`; `m + 1` must be below `2^max_bits` for the decoder's bound.
    pub fn put<S: Sink>(&mut self, s: &mut S, m: u64) {
        let v = m + 1;
        let e = 63 - v.leading_zeros() as usize;
        debug_assert!(e < MAX_MAGNITUDE_BITS);
        for j in 0..e {
            s.bit(&mut self.unary[j], true);
        }
        s.bit(&mut self.unary[e], false);
        for j in (0..e).rev() {
            s.bit(
                &mut self.mantissa[e * MAX_MAGNITUDE_BITS + j],
                (v >> j) & 1 == 1,
            );
        }
    }

    /// Decode a magnitude `m`; one with `m + 1 ≥ 2^max_bits` is refused as out of range
    /// as soon as its unary prefix says so (`max_bits` ≤ [`MAX_MAGNITUDE_BITS`]).
    #[inline(always)]
    pub fn get(&mut self, d: &mut Decoder, max_bits: usize) -> Result<u64> {
        let max_bits = max_bits.min(MAX_MAGNITUDE_BITS);
        let mut e = 0;
        while d.decide(&mut self.unary[e]) {
            e += 1;
            if e >= max_bits {
                d.in_time()?;
                return Err(corrupt(format!(
                    "coded magnitude of more than {max_bits} bits"
                )));
            }
        }
        let mut v = 1u64;
        for j in (0..e).rev() {
            let b = d.decide(&mut self.mantissa[e * MAX_MAGNITUDE_BITS + j]);
            v = (v << 1) | u64::from(b);
        }
        d.in_time()?;
        Ok(v - 1)
    }
}

/// A signed value: its magnitude ([`Magnitude`]), then, if not 0, a sign decision
/// (1 = negative) in one context.
#[derive(Clone, Default)]
pub struct Signed {
    magnitude: Magnitude,
    sign: Prob,
}

impl Signed {
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
    // A fixed array, so that an index masked to it needs no bounds check in the decoder's
    // loop.
    nodes: Box<[Prob; TREE_NODES]>,
    low: Vec<Prob>,
}

impl Tree {
    pub fn new(bits: u8) -> Self {
        let top = bits.min(TREE_BITS);
        Tree {
            bits,
            nodes: Box::new([Prob::default(); TREE_NODES]),
            low: vec![Prob::default(); usize::from(bits - top)],
        }
    }

    fn top(&self) -> u8 {
        self.bits.min(TREE_BITS)
    }

    pub fn put<S: Sink>(&mut self, s: &mut S, q: u32) {
        let (top, rest) = (self.top(), self.bits - self.top());
        let mut node = 1usize;
        for j in (0..top).rev() {
            let b = (q >> (rest + j)) & 1 == 1;
            s.bit(&mut self.nodes[node], b);
            node = 2 * node + usize::from(b);
        }
        for j in (0..rest).rev() {
            s.bit(&mut self.low[usize::from(j)], (q >> j) & 1 == 1);
        }
    }

    #[inline(always)]
    pub fn get(&mut self, d: &mut Decoder) -> Result<u32> {
        let (top, rest) = (self.top(), self.bits - self.top());
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
        for j in (0..rest).rev() {
            q = (q << 1) | u32::from(d.decide(&mut self.low[usize::from(j)]));
        }
        d.in_time()?;
        Ok(q)
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
        let (mut m, mut s, mut t) = (Magnitude::default(), Signed::default(), Tree::new(12));
        for (i, (&v, &q)) in mags.iter().zip(&codes).enumerate() {
            m.put(&mut e, v);
            s.put(&mut e, if i % 2 == 0 { v as i64 } else { -(v as i64) });
            t.put(&mut e, q);
        }
        let bytes = e.finish();
        let mut d = Decoder::new(&bytes).unwrap();
        let (mut m, mut s, mut t) = (Magnitude::default(), Signed::default(), Tree::new(12));
        for (i, (&v, &q)) in mags.iter().zip(&codes).enumerate() {
            assert_eq!(m.get(&mut d, 49).unwrap(), v);
            let r = s.get(&mut d, 49).unwrap();
            assert_eq!(r, if i % 2 == 0 { v as i64 } else { -(v as i64) });
            assert_eq!(t.get(&mut d).unwrap(), q);
        }
        d.finish().unwrap();
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
