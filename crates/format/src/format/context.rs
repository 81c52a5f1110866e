//! Compression methods 2, 3 and 4 (spec §5.4): each component's codes predicted from what
//! is already decoded and range-coded with adaptive contexts; method 3 keeps the bits that
//! contexts do not help with raw, beside the range-coded stream (§5.4.4); method 4 adds
//! angles that keep only the bits their Gaussian's shape needs (§5.4.5).
//!
//! Where the bits go, measured on Kodak at 1 bpp: positions are the largest field, and
//! in curve order (the encoder writes `sum` files along a Morton curve, where the order of
//! the Gaussians carries no information) a centre is a short step from the previous one,
//! so the pair is coded as the step between Morton keys. Colours of one Gaussian are
//! strongly correlated (G from R, B from G); covariance parameters less so, and for some
//! images not at all. So each component carries a mode, chosen by the encoder as the one
//! that codes it in fewest bits: its codes alone, its residual from the previous component
//! of the same Gaussian, or its residual from the previous Gaussian.

use super::angle;
use super::coder::{
    Decoder, Encoder, Magnitude, MagnitudeCode, Meter, Signed, Sink, SplitMagnitude, Tree,
};
use super::error::{invalid, Error, ErrorKind, Result};
use super::footprint;
use super::quant::Quantizer;

/// Which of the two coded methods (the payload's method byte, §5.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coding {
    /// Method 2 (§5.4): every bit a decision.
    Method2,
    /// Method 3 (§5.4.4, version 1.6): method 2's modes and predictions, the low bits of
    /// trees and magnitudes raw, a Morton step's `e` through a tree, and mode 4.
    Method3,
    /// Method 4 (§5.4.5, version 1.7): method 3 and mode 5, an angle at the precision of
    /// its Gaussian's shape.
    Method4,
    /// Method 5 (§5.4.6, version 1.8): method 3's modes 0, 1, 2 and 4 with their contexts
    /// kept per footprint class, for colours stored at the precision of their footprint
    /// ([`crate::format::footprint`]).
    Method5,
}

/// The code itself, through a `Tree`.
pub const MODE_DIRECT: u8 = 0;
/// Residual from the previous component of the same Gaussian, requantized (§5.4.3).
pub const MODE_ACROSS: u8 = 1;
/// Residual from the same component of the previous Gaussian (0 before the first).
pub const MODE_ALONG: u8 = 2;
/// Components 0 and 1 of a two-component attribute as one Morton key, coded as the
/// signed step from the previous Gaussian's key.
pub const MODE_MORTON: u8 = 3;
/// Method 3 only: the code's bits, raw (a component with no structure to model).
pub const MODE_RAW: u8 = 4;
/// Method 4 only, component 2 of three: as many of the code's leading bits, raw, as the
/// Gaussian's log-scales (components 0 and 1) say its angle needs ([`angle::shape_bits`]).
pub const MODE_SHAPED: u8 = 5;

/// How a method turns codes into decisions and raw bits: the binarizations of §5.4.2
/// (method 2) or §5.4.4 (method 3), as types, so that one loop serves both and each
/// method's loop is compiled for its own.
trait Binarization {
    /// The magnitude of a residual of modes 1 and 2.
    type Residual: MagnitudeCode;
    /// The magnitude of a step of mode 3.
    type Step: MagnitudeCode;
    /// The method whose binarization this is.
    const CODING: Coding;
    /// Methods 3 to 5: the data holds the length of its raw bits, and mode 4 is allowed.
    const RAW: bool = !matches!(Self::CODING, Coding::Method2);
    /// The tree of mode 0 for codes of `bits` bits.
    fn tree(bits: u8) -> Tree;
}

/// §5.4.2: trees and signed values, every bit a decision.
struct Method2;

impl Binarization for Method2 {
    type Residual = Magnitude;
    type Step = Magnitude;
    const CODING: Coding = Coding::Method2;
    fn tree(bits: u8) -> Tree {
        Tree::new(bits)
    }
}

/// §5.4.4's binarizations (split trees and magnitudes, a step's `e` through a tree),
/// which methods 3, 4 (§5.4.5: and mode 5) and 5 (§5.4.6: contexts per footprint class)
/// share: they differ in their modes and contexts, not in how a code becomes decisions.
/// `M` is the method's number.
struct RawBits<const M: u8>;

type Method3 = RawBits<3>;
type Method4 = RawBits<4>;
type Method5 = RawBits<5>;

impl<const M: u8> Binarization for RawBits<M> {
    type Residual = SplitMagnitude<false>;
    type Step = SplitMagnitude<true>;
    const CODING: Coding = match M {
        3 => Coding::Method3,
        4 => Coding::Method4,
        _ => Coding::Method5,
    };
    fn tree(bits: u8) -> Tree {
        Tree::split(bits)
    }
}

/// The footprint classes of method 5 (§5.4.6): the file's base and each Gaussian's class.
#[derive(Clone, Copy, Debug)]
pub struct Footprint<'a> {
    pub base: i8,
    pub classes: &'a [u8],
}

/// Contexts per class: one set where a payload has no classes, [`footprint::CLASSES`]
/// where it has.
struct PerClass<'a, T> {
    sets: Vec<T>,
    classes: Option<&'a [u8]>,
}

impl<'a, T> PerClass<'a, T> {
    fn new(classes: Option<&'a [u8]>, make: impl Fn() -> T) -> Self {
        let n = if classes.is_some() {
            footprint::CLASSES
        } else {
            1
        };
        PerClass {
            sets: (0..n).map(|_| make()).collect(),
            classes,
        }
    }

    /// The contexts of Gaussian `i`.
    #[inline]
    fn of(&mut self, i: usize) -> &mut T {
        let k = self.classes.map_or(0, |c| usize::from(c[i]));
        &mut self.sets[k]
    }
}

/// Interleave two codes into a Morton key: bit `j` of `u` becomes bit `2j`, bit `j` of
/// `v` bit `2j + 1`.
pub fn morton(u: u32, v: u32) -> u64 {
    let spread = |x: u32| {
        let mut x = u64::from(x);
        x = (x | (x << 16)) & 0x0000_FFFF_0000_FFFF;
        x = (x | (x << 8)) & 0x00FF_00FF_00FF_00FF;
        x = (x | (x << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
        x = (x | (x << 2)) & 0x3333_3333_3333_3333;
        (x | (x << 1)) & 0x5555_5555_5555_5555
    };
    spread(u) | (spread(v) << 1)
}

/// Inverse of [`morton`].
pub fn demorton(key: u64) -> (u32, u32) {
    let gather = |x: u64| {
        let mut x = x & 0x5555_5555_5555_5555;
        x = (x | (x >> 1)) & 0x3333_3333_3333_3333;
        x = (x | (x >> 2)) & 0x0F0F_0F0F_0F0F_0F0F;
        x = (x | (x >> 4)) & 0x00FF_00FF_00FF_00FF;
        x = (x | (x >> 8)) & 0x0000_FFFF_0000_FFFF;
        ((x | (x >> 16)) & 0xFFFF_FFFF) as u32
    };
    (gather(key), gather(key >> 1))
}

/// The prediction of [`MODE_ACROSS`]: the previous component's value, quantized with
/// this component's quantizer.
fn across(from: &Quantizer, to: &Quantizer, q: u32) -> u32 {
    to.quantize(from.dequantize(q))
}

/// Code `count` planar codes (component 0 of every Gaussian, then component 1, …) by
/// `coding`: the mode bytes, then the coded data, each component in the mode that codes
/// it in fewest bits. `shape` is the offset of §5.4.5 that component 2's codes follow
/// (see [`shaped`]); method 4 may then code them in mode 5.
///
/// Method 5 takes the footprint classes `fp` of every Gaussian (and writes their base);
/// the other methods ignore them.
pub fn encode(
    codes: &[u32],
    count: usize,
    qs: &[Quantizer],
    shape: Option<f32>,
    fp: Option<Footprint>,
    coding: Coding,
) -> Vec<u8> {
    match coding {
        Coding::Method2 => encode_by::<Method2>(codes, count, qs, None, None),
        Coding::Method3 => encode_by::<Method3>(codes, count, qs, None, None),
        Coding::Method4 => encode_by::<Method4>(codes, count, qs, shape, None),
        Coding::Method5 => encode_by::<Method5>(codes, count, qs, None, fp),
    }
}

fn encode_by<B: Binarization>(
    codes: &[u32],
    count: usize,
    qs: &[Quantizer],
    shape: Option<f32>,
    fp: Option<Footprint>,
) -> Vec<u8> {
    debug_assert_eq!(codes.len(), count * qs.len());
    let plane = |k: usize| &codes[k * count..(k + 1) * count];
    // Mode 5 is a candidate only where every code of component 2 is its bucket's middle.
    let shape = shape.filter(|&o| qs.len() == 3 && shaped(codes, count, qs, o));
    let classes = fp.map(|f| f.classes);
    let cost = |k: usize, mode: u8| {
        let mut m = Meter::default();
        put_component::<B, _>(&mut m, mode, k, qs, shape, classes, &plane);
        m.0
    };
    let best: Vec<(f64, u8)> = (0..qs.len())
        .map(|k| {
            [MODE_DIRECT, MODE_ACROSS, MODE_ALONG, MODE_RAW, MODE_SHAPED]
                .into_iter()
                .filter(|&m| single_mode_allowed(m, k, qs.len(), B::CODING))
                .filter(|&m| m != MODE_SHAPED || shape.is_some())
                .map(|m| (cost(k, m), m))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .expect("candidates")
        })
        .collect();
    let mut modes: Vec<u8> = best.iter().map(|b| b.1).collect();
    if qs.len() == 2
        && single_mode_allowed(MODE_MORTON, 0, 2, B::CODING)
        && cost(0, MODE_MORTON) < best[0].0 + best[1].0
    {
        modes = vec![MODE_MORTON; 2];
    }
    encode_with_modes_by::<B>(codes, count, qs, &modes, shape, fp)
}

/// Whether component 2 of `codes` (three components) holds, for every Gaussian, the
/// middle of the bucket that §5.4.5 gives it under `offset`: what mode 5 can code.
pub fn shaped(codes: &[u32], count: usize, qs: &[Quantizer], offset: f32) -> bool {
    if qs.len() != 3 || codes.len() != 3 * count || !offset.is_finite() {
        return false;
    }
    let keeps = keep_bits(&codes[..count], &codes[count..2 * count], qs, offset);
    let bits = qs[2].bits;
    (0..count).all(|i| {
        codes[2 * count + i] <= qs[2].max_code()
            && angle::coarse_code(codes[2 * count + i], keeps(i), bits).is_some()
    })
}

/// The bits that Gaussian `i`'s angle keeps (§5.4.5), from its codes of components 0
/// and 1 (`first`, `second`), dequantized through tables where they pay.
fn keep_bits<'a>(
    first: &'a [u32],
    second: &'a [u32],
    qs: &'a [Quantizer],
    offset: f32,
) -> impl Fn(usize) -> u8 + 'a {
    let count = first.len();
    let v0 = qs[0].lookup(count, move |c| qs[0].dequantize(c));
    let v1 = qs[1].lookup(count, move |c| qs[1].dequantize(c));
    let bits = qs[2].bits;
    move |i| angle::shape_bits(v0.get(first[i]), v1.get(second[i]), offset, bits)
}

/// [`encode`] in the given modes (which must be valid for `qs` and `coding`, as
/// [`check_modes`] says; mode 5 with `shape` such that [`shaped`] holds; method 5 with
/// the classes `fp`).
pub fn encode_with_modes(
    codes: &[u32],
    count: usize,
    qs: &[Quantizer],
    modes: &[u8],
    shape: Option<f32>,
    fp: Option<Footprint>,
    coding: Coding,
) -> Vec<u8> {
    match coding {
        Coding::Method2 => encode_with_modes_by::<Method2>(codes, count, qs, modes, None, None),
        Coding::Method3 => encode_with_modes_by::<Method3>(codes, count, qs, modes, None, None),
        Coding::Method4 => encode_with_modes_by::<Method4>(codes, count, qs, modes, shape, None),
        Coding::Method5 => encode_with_modes_by::<Method5>(codes, count, qs, modes, None, fp),
    }
}

fn encode_with_modes_by<B: Binarization>(
    codes: &[u32],
    count: usize,
    qs: &[Quantizer],
    modes: &[u8],
    shape: Option<f32>,
    fp: Option<Footprint>,
) -> Vec<u8> {
    let plane = |k: usize| &codes[k * count..(k + 1) * count];
    let fp = fp.filter(|_| B::CODING == Coding::Method5);
    assert!(
        (B::CODING == Coding::Method5) == fp.is_some(),
        "method 5 takes its classes, and only it"
    );
    let classes = fp.map(|f| f.classes);
    let mut e = Encoder::new();
    for (k, &mode) in modes.iter().enumerate() {
        if mode == MODE_MORTON && k == 1 {
            break;
        }
        put_component::<B, _>(&mut e, mode, k, qs, shape, classes, &plane);
    }
    let mut out = Vec::with_capacity(modes.len() + 9);
    if let Some(f) = fp {
        out.push(f.base as u8);
    }
    out.extend_from_slice(modes);
    if modes.contains(&MODE_SHAPED) {
        out.extend(shape.expect("mode 5 with its offset").to_be_bytes());
    }
    let (stream, raw) = e.finish_with_raw();
    if B::RAW {
        out.extend((raw.len() as u32).to_be_bytes());
    }
    out.extend(stream);
    out.extend(raw);
    out
}

/// Code component `k` (for [`MODE_MORTON`], components 0 and 1) into `s`.
fn put_component<'c, B: Binarization, S: Sink>(
    s: &mut S,
    mode: u8,
    k: usize,
    qs: &[Quantizer],
    shape: Option<f32>,
    classes: Option<&[u8]>,
    plane: &impl Fn(usize) -> &'c [u32],
) {
    let q = &qs[k];
    match mode {
        MODE_MORTON => {
            let mut ctx = Signed::<B::Step>::default();
            let mut prev = 0u64;
            for (&u, &v) in plane(0).iter().zip(plane(1)) {
                let key = morton(u, v);
                ctx.put(s, key as i64 - prev as i64);
                prev = key;
            }
        }
        _ if q.bits == 0 => {}
        MODE_DIRECT => {
            let mut ctx = PerClass::new(classes, || B::tree(q.bits));
            for (i, &c) in plane(k).iter().enumerate() {
                ctx.of(i).put(s, c);
            }
        }
        MODE_RAW => {
            for &c in plane(k) {
                s.raw(u64::from(c), u32::from(q.bits));
            }
        }
        MODE_SHAPED => {
            let keeps = keep_bits(
                plane(0),
                plane(1),
                qs,
                shape.expect("mode 5 with its offset"),
            );
            for (i, &c) in plane(k).iter().enumerate() {
                let keep = keeps(i);
                s.raw(u64::from(c >> (q.bits - keep)), u32::from(keep));
            }
        }
        MODE_ACROSS => {
            let mut ctx = PerClass::new(classes, Signed::<B::Residual>::default);
            for (i, (&c, &p)) in plane(k).iter().zip(plane(k - 1)).enumerate() {
                ctx.of(i)
                    .put(s, i64::from(c) - i64::from(across(&qs[k - 1], q, p)));
            }
        }
        _ => {
            let mut ctx = PerClass::new(classes, Signed::<B::Residual>::default);
            let mut prev = 0u32;
            for (i, &c) in plane(k).iter().enumerate() {
                ctx.of(i).put(s, i64::from(c) - i64::from(prev));
                prev = c;
            }
        }
    }
}

fn out_of_range(what: &str, i: usize, k: usize) -> Error {
    Error::new(
        ErrorKind::Decompression,
        format!("{what} of Gaussian {i}, component {k} leaves the quantizer's range"),
    )
}

/// Refuse modes that §5.4.3–§5.4.5 do not allow in `coding`: an unknown byte,
/// [`MODE_ACROSS`] on the first component, [`MODE_MORTON`] other than on both components
/// of a pair, [`MODE_RAW`] in method 2, [`MODE_SHAPED`] other than on component 2 of
/// three in method 4.
pub fn check_modes(modes: &[u8], coding: Coding) -> Result<()> {
    for (k, &m) in modes.iter().enumerate() {
        let ok = match m {
            MODE_MORTON => {
                modes == [MODE_MORTON; 2] && single_mode_allowed(m, k, modes.len(), coding)
            }
            _ => single_mode_allowed(m, k, modes.len(), coding),
        };
        if !ok {
            return Err(invalid(format!("coding mode {m} for component {k}")));
        }
    }
    Ok(())
}

/// Whether component `k` of `components` may be coded alone in `mode` under `coding`
/// (every mode but [`MODE_MORTON`], which takes a pair).
fn single_mode_allowed(mode: u8, k: usize, components: usize, coding: Coding) -> bool {
    match mode {
        MODE_DIRECT | MODE_ALONG => true,
        MODE_ACROSS => k > 0,
        MODE_RAW => coding != Coding::Method2,
        MODE_SHAPED => coding == Coding::Method4 && k == 2 && components == 3,
        MODE_MORTON => coding != Coding::Method5,
        _ => false,
    }
}

/// A decoded coded payload: the planar codes, and the offset of §5.4.5 where a component
/// was shaped.
#[derive(Debug)]
pub struct Decoded {
    pub codes: Vec<u32>,
    pub shape: Option<f32>,
    /// The base of §5.4.6 of a method-5 payload.
    pub footprint: Option<i8>,
}

/// Decode a method-2, 3 or 4 payload's data into `count` planar codes. `data` is the
/// mode bytes and the coded data (§5.4, §5.4.4, §5.4.5); every byte of it must be used.
///
/// Method 5 needs `sizes`, the footprint size of every Gaussian
/// ([`footprint::sizes`] of the file's covariance), and refuses a payload without them.
pub fn decode(
    data: &[u8],
    count: usize,
    qs: &[Quantizer],
    coding: Coding,
    sizes: Option<&[i32]>,
) -> Result<Decoded> {
    match coding {
        Coding::Method2 => decode_by::<Method2>(data, count, qs, None),
        Coding::Method3 => decode_by::<Method3>(data, count, qs, None),
        Coding::Method4 => decode_by::<Method4>(data, count, qs, None),
        Coding::Method5 => {
            let sizes = sizes.ok_or_else(|| {
                invalid("compression method 5 (colours by footprint) outside a GCOL read after a log-scale GCOV")
            })?;
            if sizes.len() != count {
                return Err(invalid(format!(
                    "method 5 with {} footprint sizes for {count} Gaussians",
                    sizes.len()
                )));
            }
            decode_by::<Method5>(data, count, qs, Some(sizes))
        }
    }
}

fn decode_by<B: Binarization>(
    data: &[u8],
    count: usize,
    qs: &[Quantizer],
    sizes: Option<&[i32]>,
) -> Result<Decoded> {
    // Method 5 starts with the base of its classes (§5.4.6).
    let (base, data) = match sizes {
        Some(_) => match data.split_first() {
            Some((&b, rest)) => (Some(b as i8), rest),
            None => {
                return Err(Error::new(
                    ErrorKind::Decompression,
                    "no bytes of coded data: method 5 starts with its base",
                ))
            }
        },
        None => (None, data),
    };
    let classes = match (sizes, base) {
        (Some(s), Some(b)) => Some(footprint::classes(s, b)),
        _ => None,
    };
    let classes = classes.as_deref();
    let k_all = qs.len();
    let short = |head: usize| {
        Error::new(
            ErrorKind::Decompression,
            format!(
                "{} bytes of coded data, fewer than the {head} in front of its stream",
                data.len()
            ),
        )
    };
    if data.len() < k_all {
        return Err(short(k_all));
    }
    let (modes, rest) = data.split_at(k_all);
    check_modes(modes, B::CODING)?;
    let offset_len = if modes.contains(&MODE_SHAPED) { 4 } else { 0 };
    let head = k_all + offset_len + if B::RAW { 4 } else { 0 };
    if data.len() < head {
        return Err(short(head));
    }
    let (offset, rest) = rest.split_at(offset_len);
    let shape = (offset_len > 0).then(|| f32::from_be_bytes(offset.try_into().expect("4 bytes")));
    if let Some(o) = shape.filter(|o| !o.is_finite()) {
        return Err(invalid(format!("shape offset {o} is not finite")));
    }
    let (stream, raw) = if B::RAW {
        let (len, rest) = rest.split_at(4);
        let len = u32::from_be_bytes(len.try_into().expect("4 bytes")) as usize;
        if len > rest.len() {
            return Err(Error::new(
                ErrorKind::Decompression,
                format!(
                    "{len} bytes of raw bits in {} bytes of coded data",
                    rest.len()
                ),
            ));
        }
        rest.split_at(rest.len() - len)
    } else {
        (rest, &[][..])
    };
    let mut d = Decoder::with_raw(stream, raw)?;
    let mut codes = vec![0u32; count * k_all];
    let mut k = 0;
    while k < k_all {
        let q = qs[k];
        let max = q.max_code();
        let (done, rest) = codes.split_at_mut(k * count);
        match modes[k] {
            MODE_MORTON => {
                let (u_bits, v_bits) = (qs[0].bits, qs[1].bits);
                let width = 2 * usize::from(u_bits.max(v_bits));
                let mut ctx = Signed::<B::Step>::default();
                let mut prev = 0i64;
                let (us, vs) = rest.split_at_mut(count);
                for i in 0..count {
                    let key = prev + ctx.get(&mut d, width + 1)?;
                    if key < 0 || key >= 1i64 << width {
                        return Err(out_of_range("Morton key", i, 0));
                    }
                    let (u, v) = demorton(key as u64);
                    if u > qs[0].max_code() || v > qs[1].max_code() {
                        return Err(out_of_range("Morton key", i, 0));
                    }
                    us[i] = u;
                    vs[i] = v;
                    prev = key;
                }
                k += 2;
                continue;
            }
            _ if q.bits == 0 => {}
            MODE_DIRECT => {
                // A tree of `bits` levels yields codes up to `max` and no further.
                let mut ctx = PerClass::new(classes, || B::tree(q.bits));
                for (i, c) in rest[..count].iter_mut().enumerate() {
                    *c = ctx.of(i).get(&mut d)?;
                }
            }
            MODE_RAW => {
                // `bits` raw bits are a code up to `max` and no further.
                for c in rest[..count].iter_mut() {
                    *c = d.raw_code(q.bits)?;
                }
            }
            MODE_SHAPED => {
                // Components 0 and 1 are decoded; the middle of a bucket of `keep`
                // leading bits is a code up to `max` and no further.
                let (first, second) = done.split_at(count);
                let keeps = keep_bits(first, second, qs, shape.expect("read with mode 5"));
                for (i, c) in rest[..count].iter_mut().enumerate() {
                    let keep = keeps(i);
                    *c = angle::full_code(d.raw_code(keep)?, keep, q.bits);
                }
            }
            mode => {
                let mut ctx = PerClass::new(classes, Signed::<B::Residual>::default);
                let prior = &done[(k.max(1) - 1) * count..];
                // The prediction across components depends on the prior code alone: a
                // table of it where there are fewer codes than Gaussians.
                let predict = (mode == MODE_ACROSS)
                    .then(|| qs[k - 1].lookup(count, |c| across(&qs[k - 1], &q, c)));
                let mut prev = 0u32;
                for i in 0..count {
                    let p = match &predict {
                        Some(predict) => predict.get(prior[i]),
                        None => prev,
                    };
                    let c = i64::from(p) + ctx.of(i).get(&mut d, usize::from(q.bits) + 1)?;
                    if c < 0 || c > i64::from(max) {
                        return Err(out_of_range("residual", i, k));
                    }
                    rest[i] = c as u32;
                    prev = c as u32;
                }
            }
        }
        k += 1;
    }
    d.finish()?;
    Ok(Decoded {
        codes,
        shape,
        footprint: base,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::format::coder::tests::test_rng;

    fn q(bits: u8, min: f32, max: f32) -> Quantizer {
        Quantizer { bits, min, max }
    }

    #[test]
    fn morton_interleaves_and_inverts() {
        assert_eq!(morton(0b11, 0), 0b0101);
        assert_eq!(morton(0, 0b11), 0b1010);
        for (u, v) in [
            (0, 0),
            (1, 2),
            (0xFF_FFFF, 0),
            (0xFF_FFFF, 0xFF_FFFF),
            (12345, 678),
        ] {
            assert_eq!(demorton(morton(u, v)), (u, v));
        }
    }

    /// A payload in `modes`, whichever the encoder would have chosen.
    fn forced(codes: &[u32], n: usize, qs: &[Quantizer], modes: &[u8], c: Coding) -> Vec<u8> {
        encode_with_modes(codes, n, qs, modes, None, None, c)
    }

    /// [`super::encode`] of an attribute that is not shaped.
    fn encode(codes: &[u32], n: usize, qs: &[Quantizer], c: Coding) -> Vec<u8> {
        super::encode(codes, n, qs, None, None, c)
    }

    /// The codes of [`super::decode`].
    fn decode(data: &[u8], n: usize, qs: &[Quantizer], c: Coding) -> Result<Vec<u32>> {
        super::decode(data, n, qs, c, None).map(|d| d.codes)
    }

    #[test]
    fn every_mode_roundtrips() {
        for c in [Coding::Method2, Coding::Method3, Coding::Method4] {
            let mut rng = test_rng(11);
            for &(n, bits) in &[
                (0usize, 8u8),
                (1, 8),
                (7, 3),
                (500, 8),
                (500, 13),
                (300, 24),
            ] {
                let qs = [q(bits, 0.0, 1.0), q(bits, -0.5, 0.5), q(0, 0.2, 0.2)];
                let max = qs[0].max_code() as f32;
                let mut codes = Vec::new();
                for k in 0..3 {
                    let mut walk = 0.5f32;
                    for _ in 0..n {
                        walk = (walk + 0.05 * (rng() - 0.5)).clamp(0.0, 1.0);
                        codes.push(if k == 2 { 0 } else { (walk * max) as u32 });
                    }
                }
                let data = encode(&codes, n, &qs, c);
                assert_eq!(
                    decode(&data, n, &qs, c).unwrap(),
                    codes,
                    "n {n} bits {bits}"
                );
                // Forced modes, each of which the encoder may not have chosen.
                let mut all: Vec<[u8; 3]> = vec![[0, 1, 0], [2, 2, 2], [0, 2, 1]];
                if c != Coding::Method2 {
                    all.extend([[4, 4, 4], [4, 1, 0], [2, 4, 1]]);
                }
                for modes in all {
                    let data = forced(&codes, n, &qs, &modes, c);
                    assert_eq!(decode(&data, n, &qs, c).unwrap(), codes, "{c:?} {modes:?}");
                }
                let pair = [qs[0], q(bits.saturating_sub(2), 0.0, 1.0)];
                let codes2: Vec<u32> = codes[..2 * n]
                    .iter()
                    .enumerate()
                    .map(|(i, &c)| if i >= n { c >> 2 } else { c })
                    .collect();
                let data = forced(&codes2, n, &pair, &[MODE_MORTON; 2], c);
                assert_eq!(decode(&data, n, &pair, c).unwrap(), codes2);
            }
        }
    }

    /// Footprint sizes spread over more than the eight classes, and colour codes whose
    /// spread grows with the class, as a fitted file's stored values do (§5.4.6).
    fn by_footprint(n: usize, bits: u8, seed: u64) -> (Vec<i32>, Vec<u32>) {
        let mut rng = test_rng(seed);
        let sizes: Vec<i32> = (0..n).map(|_| (rng() * 12.0) as i32 - 14).collect();
        let mid = 1u32 << (bits - 1);
        let mut codes = vec![0u32; 3 * n];
        for i in 0..n {
            let k = footprint::class(sizes[i], -12);
            let spread = f64::from((1u32 << k).min(mid - 1));
            for ch in 0..3 {
                codes[ch * n + i] = (f64::from(mid) + spread * (rng() - 0.5) as f64) as u32;
            }
        }
        (sizes, codes)
    }

    #[test]
    fn method_5_roundtrips_in_every_mode_and_needs_its_sizes() {
        for &(n, bits) in &[(0usize, 8u8), (1, 8), (9, 3), (600, 9), (300, 14)] {
            let qs = [q(bits, -1.0, 1.0), q(bits, -1.0, 1.0), q(bits, -2.0, 1.0)];
            let (sizes, codes) = by_footprint(n, bits, 17);
            let classes = footprint::classes(&sizes, -12);
            let fp = Some(Footprint {
                base: -12,
                classes: &classes,
            });
            let chosen = super::encode(&codes, n, &qs, None, fp, Coding::Method5);
            assert_eq!(chosen[0], (-12i8) as u8, "the base comes first");
            let mut payloads = vec![chosen];
            for modes in [[0u8, 1, 1], [2, 2, 2], [4, 4, 4], [0, 2, 4], [4, 1, 0]] {
                payloads.push(encode_with_modes(
                    &codes,
                    n,
                    &qs,
                    &modes,
                    None,
                    fp,
                    Coding::Method5,
                ));
            }
            for data in &payloads {
                let d = super::decode(data, n, &qs, Coding::Method5, Some(&sizes)).unwrap();
                assert_eq!((d.codes, d.footprint), (codes.clone(), Some(-12)), "n {n}");
                // Without the sizes, or with another count of them, it is refused.
                assert!(super::decode(data, n, &qs, Coding::Method5, None).is_err());
                let short = &sizes[..n.saturating_sub(1)];
                if n > 0 {
                    assert!(super::decode(data, n, &qs, Coding::Method5, Some(short)).is_err());
                }
            }
        }
    }

    #[test]
    fn method_5_contexts_per_class_pay_where_classes_spread_differently() {
        let (n, bits) = (4000, 10);
        let qs = [q(bits, -1.0, 1.0); 3];
        let (sizes, codes) = by_footprint(n, bits, 3);
        let classes = footprint::classes(&sizes, -12);
        let fp = Footprint {
            base: -12,
            classes: &classes,
        };
        let five = super::encode(&codes, n, &qs, None, Some(fp), Coding::Method5);
        let three = encode(&codes, n, &qs, Coding::Method3);
        assert!(
            five.len() < three.len() * 95 / 100,
            "method 5 {} bytes, method 3 {}",
            five.len(),
            three.len()
        );
    }

    #[test]
    fn method_5_refuses_what_it_does_not_define() {
        let (n, bits) = (40, 6);
        let qs = [q(bits, -1.0, 1.0); 3];
        let (sizes, codes) = by_footprint(n, bits, 8);
        let classes = footprint::classes(&sizes, -12);
        let fp = Some(Footprint {
            base: -12,
            classes: &classes,
        });
        let good = encode_with_modes(&codes, n, &qs, &[0, 1, 1], None, fp, Coding::Method5);
        let five = |d: &[u8]| super::decode(d, n, &qs, Coding::Method5, Some(&sizes));
        assert!(five(&good).is_ok());
        // Modes 3 (Morton) and 5 (shaped) are not method 5's; nor is a byte above 5.
        for (k, bad) in [(1usize, MODE_MORTON), (2, MODE_SHAPED), (0, 6)] {
            let mut d = good.clone();
            d[1 + k] = bad;
            let e = five(&d).unwrap_err().to_string();
            assert!(e.contains(&format!("coding mode {bad}")), "{e}");
        }
        // No byte at all: not even the base.
        assert!(super::decode(&[], 0, &qs, Coding::Method5, Some(&[])).is_err());
        // Truncated anywhere.
        for cut in 0..good.len() {
            assert!(five(&good[..cut]).is_err(), "cut at {cut}");
        }
        // Another base reads other classes: other contexts, other codes or a refusal.
        let mut moved = good.clone();
        moved[0] = moved[0].wrapping_add(2);
        assert!(five(&moved).map_or(true, |d| d.codes != codes));
    }

    #[test]
    fn method_3_keeps_the_codes_of_method_2_in_about_as_many_bytes() {
        // Codes with structure in their top bits and noise below, as a fitted file's are.
        let mut rng = test_rng(5);
        let n = 4000;
        let qs = [q(12, 0.0, 1.0), q(12, 0.0, 1.0)];
        let mut codes: Vec<u32> = (0..2 * n).map(|_| (rng() * 4095.0) as u32).collect();
        codes[..n].sort_unstable();
        let two = encode(&codes, n, &qs, Coding::Method2);
        let three = encode(&codes, n, &qs, Coding::Method3);
        assert_eq!(decode(&three, n, &qs, Coding::Method3).unwrap(), codes);
        assert!(
            (three.len() as f64) < two.len() as f64 * 1.01,
            "method 3 {} bytes, method 2 {}",
            three.len(),
            two.len()
        );
    }

    #[test]
    fn bad_modes_and_ranges_are_refused() {
        for c in [Coding::Method2, Coding::Method3, Coding::Method4] {
            let qs = [q(4, 0.0, 1.0), q(4, 0.0, 1.0)];
            let codes = vec![1, 2, 3, 4];
            let good = encode(&codes, 2, &qs, c);
            let mut bad_modes = vec![[1u8, 0], [3, 0], [0, 3], [5, 0]];
            if c == Coding::Method2 {
                bad_modes.push([4, 0]);
            }
            for modes in bad_modes {
                let mut bad = good.clone();
                bad[..2].copy_from_slice(&modes);
                assert_eq!(
                    decode(&bad, 2, &qs, c).unwrap_err().kind(),
                    ErrorKind::InvalidValue,
                    "{c:?} {modes:?}"
                );
            }
            // A residual of 20 on a 4-bit code.
            let data = forced(&[20], 1, &[q(5, 0.0, 1.0)], &[MODE_ALONG], c);
            assert!(decode(&data, 1, &qs[..1], c).is_err());
            // Truncated and over-long payloads.
            assert!(decode(&good[..good.len() - 1], 2, &qs, c).is_err());
            let mut long = good.clone();
            long.push(7);
            assert!(decode(&long, 2, &qs, c).is_err());
            assert!(decode(&good, 3, &qs, c).is_err());
        }
    }

    #[test]
    fn method_3_raw_bits_are_checked() {
        let c = Coding::Method3;
        let qs = [q(7, 0.0, 1.0)];
        // Raw codes of 7 bits: 3 codes, 21 bits, in 3 bytes with 3 bits of padding.
        let data = forced(&[100, 5, 127], 3, &qs, &[MODE_RAW], c);
        let raw_len = |d: &[u8]| u32::from_be_bytes(d[1..5].try_into().unwrap());
        assert_eq!(raw_len(&data), 3);
        assert_eq!(decode(&data, 3, &qs, c).unwrap(), [100, 5, 127]);
        let err = |d: &[u8], n: usize| decode(d, n, &qs, c).unwrap_err().to_string();
        // More codes than the raw bits hold.
        assert!(err(&data, 4).contains("raw bits end"), "{}", err(&data, 4));
        // A raw byte too many, and padding that is not zeros.
        let mut long = data.clone();
        long.push(0);
        long[1..5].copy_from_slice(&4u32.to_be_bytes());
        assert!(
            err(&long, 3).contains("raw bytes left"),
            "{}",
            err(&long, 3)
        );
        let mut ones = data.clone();
        *ones.last_mut().unwrap() |= 1;
        assert!(
            err(&ones, 3).contains("padded with ones"),
            "{}",
            err(&ones, 3)
        );
        // A raw length past the payload, and a payload too short for its length field.
        let mut past = data.clone();
        past[1..5].copy_from_slice(&u32::MAX.to_be_bytes());
        assert!(
            err(&past, 3).contains("bytes of raw bits"),
            "{}",
            err(&past, 3)
        );
        assert!(decode(&data[..3], 3, &qs, c).is_err());
        // Mantissa bits raw: a magnitude whose raw bits are cut.
        let big = forced(&[0, 120], 2, &qs, &[MODE_ALONG], c);
        assert_eq!(decode(&big, 2, &qs, c).unwrap(), [0, 120]);
        let n = raw_len(&big) as usize;
        assert!(n > 0);
        let mut cut = big[..big.len() - n].to_vec();
        cut[1..5].copy_from_slice(&0u32.to_be_bytes());
        assert!(err(&cut, 2).contains("raw bits end"), "{}", err(&cut, 2));
    }

    /// Log-scales and angles as a fitted file's are, shaped by the encoder's rule.
    fn shaped_attribute(n: usize, seed: u64) -> (crate::format::Attribute, Vec<[f32; 3]>) {
        let (cov, colors) = angle::tests::fitted_like(n, seed);
        (
            crate::format::Attribute::shaped_angles(&cov, &colors, 6, 7),
            cov,
        )
    }

    #[test]
    fn shaped_angles_roundtrip_in_fewer_bits() {
        for n in [2usize, 3, 700] {
            let (a, _) = shaped_attribute(n, 3);
            let o = a.shape.expect("shaped");
            assert!(shaped(&a.codes, n, &a.quantizers, o));
            let four = super::encode(&a.codes, n, &a.quantizers, a.shape, None, Coding::Method4);
            assert_eq!(four[2], MODE_SHAPED, "n {n}");
            let got = super::decode(&four, n, &a.quantizers, Coding::Method4, None).unwrap();
            assert_eq!(got.codes, a.codes);
            assert_eq!(got.shape, Some(o));
            let three = encode(&a.codes, n, &a.quantizers, Coding::Method3);
            assert_eq!(
                decode(&three, n, &a.quantizers, Coding::Method3).unwrap(),
                a.codes
            );
            if n == 700 {
                assert!(
                    four.len() < three.len(),
                    "{} against {}",
                    four.len(),
                    three.len()
                );
            }
        }
        // One Gaussian: a constant angle takes no bits, and nothing is shaped.
        assert_eq!(shaped_attribute(1, 3).0.shape, None);
        // A code off its bucket's middle cannot be shaped: mode 5 is no candidate.
        let (mut a, _) = shaped_attribute(700, 4);
        let o = a.shape.unwrap();
        let depth = a.quantizers[2].bits;
        let i = {
            let keeps = keep_bits(&a.codes[..700], &a.codes[700..1400], &a.quantizers, o);
            (0..700)
                .find(|&i| keeps(i) + 2 <= depth)
                .expect("a coarse angle")
        };
        a.codes[1400 + i] ^= 1;
        assert!(!shaped(&a.codes, 700, &a.quantizers, o));
        let d = super::encode(&a.codes, 700, &a.quantizers, Some(o), None, Coding::Method4);
        assert_ne!(d[2], MODE_SHAPED);
        assert_eq!(
            decode(&d, 700, &a.quantizers, Coding::Method4).unwrap(),
            a.codes
        );
    }

    #[test]
    fn shaped_payloads_are_checked() {
        let c = Coding::Method4;
        let (a, _) = shaped_attribute(50, 9);
        let qs = &a.quantizers;
        let good = encode_with_modes(&a.codes, 50, qs, &[0, 0, MODE_SHAPED], a.shape, None, c);
        assert_eq!(decode(&good, 50, qs, c).unwrap(), a.codes);
        let err = |d: &[u8], qs: &[Quantizer], c: Coding| {
            super::decode(d, 50, qs, c, None)
                .expect_err("refused")
                .to_string()
        };
        // Mode 5 on components 0 and 1, in method 3, on an attribute of two components.
        for modes in [[MODE_SHAPED, 0, 0], [0, MODE_SHAPED, 0]] {
            let mut bad = good.clone();
            bad[..3].copy_from_slice(&modes);
            assert!(
                err(&bad, qs, c).contains("coding mode 5"),
                "{}",
                err(&bad, qs, c)
            );
        }
        assert!(err(&good, qs, Coding::Method3).contains("coding mode 5"));
        let pair = [qs[0], qs[1]];
        let mut two = good[1..].to_vec();
        two[..2].copy_from_slice(&[0, MODE_SHAPED]);
        assert!(err(&two, &pair, c).contains("coding mode 5"));
        // A mode above 5.
        let mut six = good.clone();
        six[2] = 6;
        assert!(err(&six, qs, c).contains("coding mode 6"));
        // An offset that is not finite.
        for o in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut bad = good.clone();
            bad[3..7].copy_from_slice(&o.to_be_bytes());
            assert!(
                err(&bad, qs, c).contains("not finite"),
                "{}",
                err(&bad, qs, c)
            );
        }
        // Cut inside the offset or the raw length; raw bits that end too soon.
        for cut in [4, 8, 10] {
            assert!(
                super::decode(&good[..cut], 50, qs, c, None).is_err(),
                "cut at {cut}"
            );
        }
        assert!(super::decode(&good, 51, qs, c, None).is_err());
        // Another offset keeps other bits: the payload no longer decodes whole.
        let mut moved = good.clone();
        moved[3..7].copy_from_slice(&(a.shape.unwrap() + 3.0).to_be_bytes());
        assert!(super::decode(&moved, 50, qs, c, None).is_err());
    }
}
