//! Compression method 2 (spec §5.4): each component's codes predicted from what is
//! already decoded and range-coded with adaptive contexts.
//!
//! Where the bits go, measured on Kodak at 1 bpp: positions are the largest field, and
//! in curve order (the encoder writes `sum` files along a Morton curve, where the order of
//! the Gaussians carries no information) a centre is a short step from the previous one,
//! so the pair is coded as the step between Morton keys. Colours of one Gaussian are
//! strongly correlated (G from R, B from G); covariance parameters less so, and for some
//! images not at all. So each component carries a mode, chosen by the encoder as the one
//! that codes it in fewest bits: its codes alone, its residual from the previous component
//! of the same Gaussian, or its residual from the previous Gaussian.

use super::coder::{Decoder, Encoder, Meter, Signed, Sink, Tree};
use super::error::{invalid, Error, ErrorKind, Result};
use super::quant::Quantizer;

/// The code itself, through a `Tree`.
pub const MODE_DIRECT: u8 = 0;
/// Residual from the previous component of the same Gaussian, requantized (§5.4.3).
pub const MODE_ACROSS: u8 = 1;
/// Residual from the same component of the previous Gaussian (0 before the first).
pub const MODE_ALONG: u8 = 2;
/// Components 0 and 1 of a two-component attribute as one Morton key, coded as the
/// signed step from the previous Gaussian's key.
pub const MODE_MORTON: u8 = 3;

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

/// Code `count` planar codes (component 0 of every Gaussian, then component 1, …):
/// the mode bytes, then the range-coded stream, each component in the mode that codes it
/// in fewest bits.
pub fn encode(codes: &[u32], count: usize, qs: &[Quantizer]) -> Vec<u8> {
    debug_assert_eq!(codes.len(), count * qs.len());
    let plane = |k: usize| &codes[k * count..(k + 1) * count];
    let cost = |k: usize, mode: u8| {
        let mut m = Meter::default();
        put_component(&mut m, mode, k, qs, &plane);
        m.0
    };
    let best: Vec<(f64, u8)> = (0..qs.len())
        .map(|k| {
            let candidates: &[u8] = if k == 0 {
                &[MODE_DIRECT, MODE_ALONG]
            } else {
                &[MODE_DIRECT, MODE_ACROSS, MODE_ALONG]
            };
            candidates
                .iter()
                .map(|&m| (cost(k, m), m))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .expect("candidates")
        })
        .collect();
    let mut modes: Vec<u8> = best.iter().map(|b| b.1).collect();
    if qs.len() == 2 && cost(0, MODE_MORTON) < best[0].0 + best[1].0 {
        modes = vec![MODE_MORTON; 2];
    }
    encode_with_modes(codes, count, qs, &modes)
}

/// [`encode`] in the given modes (which must be valid for `qs`, as [`decode`] checks).
pub fn encode_with_modes(codes: &[u32], count: usize, qs: &[Quantizer], modes: &[u8]) -> Vec<u8> {
    let plane = |k: usize| &codes[k * count..(k + 1) * count];
    let mut e = Encoder::new();
    for (k, &mode) in modes.iter().enumerate() {
        if mode == MODE_MORTON && k == 1 {
            break;
        }
        put_component(&mut e, mode, k, qs, &plane);
    }
    let mut out = modes.to_vec();
    out.extend(e.finish());
    out
}

/// Code component `k` (for [`MODE_MORTON`], components 0 and 1) into `s`.
fn put_component<'c, S: Sink>(
    s: &mut S,
    mode: u8,
    k: usize,
    qs: &[Quantizer],
    plane: &impl Fn(usize) -> &'c [u32],
) {
    let q = &qs[k];
    match mode {
        MODE_MORTON => {
            let mut ctx = Signed::default();
            let mut prev = 0u64;
            for (&u, &v) in plane(0).iter().zip(plane(1)) {
                let key = morton(u, v);
                ctx.put(s, key as i64 - prev as i64);
                prev = key;
            }
        }
        _ if q.bits == 0 => {}
        MODE_DIRECT => {
            let mut ctx = Tree::new(q.bits);
            for &c in plane(k) {
                ctx.put(s, c);
            }
        }
        MODE_ACROSS => {
            let mut ctx = Signed::default();
            for (&c, &p) in plane(k).iter().zip(plane(k - 1)) {
                ctx.put(s, i64::from(c) - i64::from(across(&qs[k - 1], q, p)));
            }
        }
        _ => {
            let mut ctx = Signed::default();
            let mut prev = 0u32;
            for &c in plane(k) {
                ctx.put(s, i64::from(c) - i64::from(prev));
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

/// Refuse modes that §5.4.3 does not allow: an unknown byte, [`MODE_ACROSS`] on the first
/// component, [`MODE_MORTON`] other than on both components of a pair.
pub fn check_modes(modes: &[u8]) -> Result<()> {
    for (k, &m) in modes.iter().enumerate() {
        let ok = match m {
            MODE_DIRECT | MODE_ALONG => true,
            MODE_ACROSS => k > 0,
            MODE_MORTON => modes == [MODE_MORTON; 2],
            _ => false,
        };
        if !ok {
            return Err(invalid(format!("coding mode {m} for component {k}")));
        }
    }
    Ok(())
}

/// Decode a method-2 payload's data into `count` planar codes. `data` is the mode bytes
/// and the coded stream; every byte of it must be used.
pub fn decode(data: &[u8], count: usize, qs: &[Quantizer]) -> Result<Vec<u32>> {
    let k_all = qs.len();
    if data.len() < k_all {
        return Err(Error::new(
            ErrorKind::Decompression,
            "coded data shorter than its mode bytes",
        ));
    }
    let (modes, stream) = data.split_at(k_all);
    check_modes(modes)?;
    let mut d = Decoder::new(stream)?;
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
                let mut ctx = Signed::default();
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
                let mut ctx = Tree::new(q.bits);
                for c in rest[..count].iter_mut() {
                    *c = ctx.get(&mut d)?;
                }
            }
            mode => {
                let mut ctx = Signed::default();
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
                    let c = i64::from(p) + ctx.get(&mut d, usize::from(q.bits) + 1)?;
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
    Ok(codes)
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

    #[test]
    fn every_mode_roundtrips() {
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
            let data = encode(&codes, n, &qs);
            assert_eq!(decode(&data, n, &qs).unwrap(), codes, "n {n} bits {bits}");
            // Forced modes, each of which the encoder may not have chosen.
            for modes in [[0u8, 1, 0], [2, 2, 2], [0, 2, 1]] {
                let mut e = Encoder::new();
                let plane = |k: usize| &codes[k * n..(k + 1) * n];
                for (k, &m) in modes.iter().enumerate() {
                    put_component(&mut e, m, k, &qs, &plane);
                }
                let mut data = modes.to_vec();
                data.extend(e.finish());
                assert_eq!(decode(&data, n, &qs).unwrap(), codes);
            }
            let pair = [qs[0], q(bits.saturating_sub(2), 0.0, 1.0)];
            let codes2: Vec<u32> = codes[..2 * n]
                .iter()
                .enumerate()
                .map(|(i, &c)| if i >= n { c >> 2 } else { c })
                .collect();
            let mut e = Encoder::new();
            put_component(&mut e, MODE_MORTON, 0, &pair, &|k| {
                &codes2[k * n..(k + 1) * n]
            });
            let mut data = vec![MODE_MORTON; 2];
            data.extend(e.finish());
            assert_eq!(decode(&data, n, &pair).unwrap(), codes2);
        }
    }

    #[test]
    fn bad_modes_and_ranges_are_refused() {
        let qs = [q(4, 0.0, 1.0), q(4, 0.0, 1.0)];
        let codes = vec![1, 2, 3, 4];
        let good = encode(&codes, 2, &qs);
        for modes in [[1u8, 0], [3, 0], [0, 3], [4, 0]] {
            let mut bad = good.clone();
            bad[..2].copy_from_slice(&modes);
            assert_eq!(
                decode(&bad, 2, &qs).unwrap_err().kind(),
                ErrorKind::InvalidValue,
                "{modes:?}"
            );
        }
        // A residual of 20 on a 4-bit code.
        let mut e = Encoder::new();
        let mut s = Signed::default();
        s.put(&mut e, 20);
        let mut data = vec![MODE_ALONG, MODE_ALONG];
        data.extend(e.finish());
        assert!(decode(&data, 1, &qs[..1]).is_err());
        // Truncated and over-long streams.
        assert!(decode(&good[..good.len() - 1], 2, &qs).is_err());
        let mut long = good.clone();
        long.push(7);
        assert!(decode(&long, 2, &qs).is_err());
        assert!(decode(&good, 3, &qs).is_err());
    }
}
