//! Uniform scalar quantizers and the MSB-first bit packing of their codes.

use super::error::{invalid, Result};
use bitvec::prelude::*;

/// Widest code a quantizer may use. 24 bits already resolve finer than an `f32`
/// mantissa over any range a component needs.
pub const MAX_BITS: u8 = 24;

/// One component's quantizer: `bits`-bit codes spread uniformly over `[min, max]`.
///
/// Dequantization is `min·(1 − t) + max·t` with `t = q / (2^bits − 1)`, clamped to
/// `[min, max]`, evaluated in `f64` and rounded once to `f32`, so every decoder gets the
/// same value bit for bit and no code leaves the range. With
/// `bits = 0` the component is the constant `min` and occupies no bits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantizer {
    pub bits: u8,
    pub min: f32,
    pub max: f32,
}

impl Quantizer {
    /// Check the descriptor against spec §5.2: finite bounds, `min ≤ max`, at most
    /// [`MAX_BITS`] bits, and `min == max` exactly when `bits == 0`.
    pub fn validate(&self) -> Result<()> {
        if self.bits > MAX_BITS {
            return Err(invalid(format!(
                "quantizer of {} bits (at most {MAX_BITS})",
                self.bits
            )));
        }
        if !(self.min.is_finite() && self.max.is_finite()) {
            return Err(invalid(format!(
                "quantizer range [{}, {}] not finite",
                self.min, self.max
            )));
        }
        if self.min > self.max {
            return Err(invalid(format!(
                "quantizer range [{}, {}] reversed",
                self.min, self.max
            )));
        }
        if self.bits == 0 && self.min != self.max {
            return Err(invalid("0-bit quantizer with min != max"));
        }
        Ok(())
    }

    /// The tightest quantizer of `bits` bits over the finite values in `data`.
    /// A constant (or empty) component collapses to 0 bits.
    pub fn fit(bits: u8, data: impl IntoIterator<Item = f32>) -> Quantizer {
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for x in data.into_iter().filter(|x| x.is_finite()) {
            lo = lo.min(x);
            hi = hi.max(x);
        }
        if lo > hi {
            return Quantizer {
                bits: 0,
                min: 0.0,
                max: 0.0,
            };
        }
        if bits == 0 || lo == hi {
            return Quantizer {
                bits: 0,
                min: lo,
                max: lo,
            };
        }
        Quantizer {
            bits: bits.min(MAX_BITS),
            min: lo,
            max: hi,
        }
    }

    /// Largest code, `2^bits − 1`.
    #[inline]
    pub fn max_code(&self) -> u32 {
        ((1u64 << self.bits) - 1) as u32
    }

    #[inline]
    pub fn dequantize(&self, q: u32) -> f32 {
        if self.bits == 0 {
            return self.min;
        }
        // Interpolating between the ends (rather than `lo + (hi − lo)·t`) keeps both ends
        // exact and every value inside the range, even when `hi − lo` dwarfs `hi`.
        let (lo, hi) = (f64::from(self.min), f64::from(self.max));
        let t = f64::from(q) / f64::from(self.max_code());
        (lo * (1.0 - t) + hi * t).clamp(lo, hi) as f32
    }

    /// `f(code)` for every code, where there are fewer codes than half of `uses` (the
    /// number of times the caller needs a value): a table is then cheaper than a division
    /// for each. Else `None`.
    pub fn table<T>(&self, uses: usize, f: impl Fn(u32) -> T) -> Option<Vec<T>> {
        ((self.max_code() as usize) < uses / 2).then(|| (0..=self.max_code()).map(f).collect())
    }

    /// `f` of this quantizer's codes, needed `uses` times: from a [`Quantizer::table`]
    /// where one pays, else computed code by code.
    pub fn lookup<T: Copy, F: Fn(u32) -> T>(&self, uses: usize, f: F) -> Lookup<T, F> {
        Lookup {
            table: self.table(uses, &f),
            f,
        }
    }

    /// Nearest code for `x`; values outside the range clamp to its ends, NaN maps to 0.
    #[inline]
    pub fn quantize(&self, x: f32) -> u32 {
        self.position(x).round() as u32
    }

    /// Where `x` falls on the codes, unrounded: in `[0, max_code]`, values outside the
    /// range at its ends, NaN (and a range of one value) at 0.
    #[inline]
    pub fn position(&self, x: f32) -> f64 {
        if self.bits == 0 || self.max <= self.min || x.is_nan() {
            return 0.0;
        }
        let t = (f64::from(x) - f64::from(self.min)) / (f64::from(self.max) - f64::from(self.min));
        t.clamp(0.0, 1.0) * f64::from(self.max_code())
    }
}

/// [`Quantizer::lookup`]: `f(code)` from the table, or computed where there is none or
/// the code lies past it (an in-memory attribute may hold codes above `max`).
pub struct Lookup<T, F> {
    table: Option<Vec<T>>,
    f: F,
}

impl<T: Copy, F: Fn(u32) -> T> Lookup<T, F> {
    #[inline]
    pub fn get(&self, code: u32) -> T {
        match self.table.as_ref().and_then(|t| t.get(code as usize)) {
            Some(&v) => v,
            None => (self.f)(code),
        }
    }
}

/// Number of bytes that `count` records of the given component widths pack into.
pub fn packed_len(count: u64, quantizers: &[Quantizer]) -> u64 {
    let bits_per_record: u64 = quantizers.iter().map(|q| u64::from(q.bits)).sum();
    (count * bits_per_record).div_ceil(8)
}

/// Pack planar codes (component 0 of every record, then component 1, …), each code
/// MSB first in `bits` bits, the whole stream zero-padded to a byte.
pub fn pack(codes: &[u32], count: usize, quantizers: &[Quantizer]) -> Vec<u8> {
    debug_assert_eq!(codes.len(), count * quantizers.len());
    let mut bits: BitVec<u8, Msb0> =
        BitVec::with_capacity(packed_len(count as u64, quantizers) as usize * 8);
    for (plane, q) in codes.chunks(count.max(1)).zip(quantizers) {
        let w = usize::from(q.bits);
        if w == 0 {
            continue;
        }
        for &code in plane {
            bits.extend_from_bitslice(&code.view_bits::<Msb0>()[32 - w..]);
        }
    }
    bits.into_vec()
}

/// Inverse of [`pack`]. `data` must hold exactly [`packed_len`] bytes; padding bits are
/// ignored.
pub fn unpack(data: &[u8], count: usize, quantizers: &[Quantizer]) -> Vec<u32> {
    debug_assert_eq!(data.len() as u64, packed_len(count as u64, quantizers));
    let bits = data.view_bits::<Msb0>();
    let mut codes = Vec::with_capacity(count * quantizers.len());
    let mut at = 0usize;
    for q in quantizers {
        let w = usize::from(q.bits);
        if w == 0 {
            codes.extend(std::iter::repeat_n(0, count));
            continue;
        }
        codes.extend((0..count).map(|i| bits[at + i * w..at + (i + 1) * w].load_be::<u32>()));
        at += count * w;
    }
    codes
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values looked up in a table are the values computed one by one, codes past the
    /// largest included (an in-memory attribute may hold them; they clamp to `max`).
    #[test]
    fn tabled_values_are_the_computed_ones() {
        use crate::format::records::Attribute;
        let q = Quantizer {
            bits: 5,
            min: -3.7,
            max: 1e3,
        };
        assert!(q.table(10, |c| c).is_none());
        let table = q.table(100, |c| q.dequantize(c)).unwrap();
        assert_eq!(table.len(), 32);
        let codes: Vec<u32> = (0..100).map(|i| (i * 7) % 40).collect();
        let a = Attribute {
            quantizers: vec![q],
            codes: codes.clone(),
            shape: None,
            footprint: None,
        };
        let got: Vec<[f32; 1]> = a.values();
        for (v, &c) in got.iter().zip(&codes) {
            assert_eq!(v[0].to_bits(), q.dequantize(c).to_bits(), "code {c}");
        }
        assert_eq!(q.dequantize(39), q.max);
    }

    #[test]
    fn pack_is_msb_first_and_planar() {
        let qs = [
            Quantizer {
                bits: 3,
                min: 0.0,
                max: 1.0,
            },
            Quantizer {
                bits: 2,
                min: 0.0,
                max: 1.0,
            },
        ];
        // plane 0: 0b101, 0b011; plane 1: 0b10, 0b01  -> 101 011 10 01 -> 0b10101110 0b01000000
        let packed = pack(&[5, 3, 2, 1], 2, &qs);
        assert_eq!(packed, vec![0b1010_1110, 0b0100_0000]);
        assert_eq!(unpack(&packed, 2, &qs), vec![5, 3, 2, 1]);
    }

    #[test]
    fn codes_roundtrip_through_values() {
        let q = Quantizer {
            bits: 16,
            min: -0.25,
            max: 1.5,
        };
        for code in [0, 1, 2, 12345, 65534, 65535] {
            assert_eq!(q.quantize(q.dequantize(code)), code);
        }
        assert_eq!(q.dequantize(0), -0.25);
        assert_eq!(q.dequantize(65535), 1.5);
        assert_eq!(q.quantize(f32::NAN), 0);
        assert_eq!(q.quantize(9.0), 65535);
    }

    #[test]
    fn fit_collapses_constants() {
        assert_eq!(
            Quantizer::fit(8, [0.5, 0.5]),
            Quantizer {
                bits: 0,
                min: 0.5,
                max: 0.5
            }
        );
        assert_eq!(
            Quantizer::fit(8, []),
            Quantizer {
                bits: 0,
                min: 0.0,
                max: 0.0
            }
        );
        assert_eq!(
            Quantizer::fit(8, [1.0, f32::NAN, -1.0]),
            Quantizer {
                bits: 8,
                min: -1.0,
                max: 1.0
            }
        );
    }

    #[test]
    fn validate_rejects_bad_descriptors() {
        assert!(Quantizer {
            bits: 25,
            min: 0.0,
            max: 1.0
        }
        .validate()
        .is_err());
        assert!(Quantizer {
            bits: 8,
            min: 1.0,
            max: 0.0
        }
        .validate()
        .is_err());
        assert!(Quantizer {
            bits: 8,
            min: f32::NAN,
            max: 0.0
        }
        .validate()
        .is_err());
        assert!(Quantizer {
            bits: 0,
            min: 0.0,
            max: 1.0
        }
        .validate()
        .is_err());
        assert!(Quantizer {
            bits: 24,
            min: -1e30,
            max: 1e30
        }
        .validate()
        .is_ok());
    }
}
