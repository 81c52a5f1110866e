//! Any bytes as the coded data of a method-2, 3, 4 or 5 attribute payload (format-spec.md
//! §5.4, §5.4.4, §5.4.5, §5.4.6), behind a preamble the input chooses: `Ok` or `Err`,
//! never a panic, a hang or an allocation beyond the codes the count declares. Input: a
//! byte whose top bit chooses method 3, both top bits method 4 (method 5 where bit 5 is
//! set too), and whose low bits the components (1 + (byte & 0x3F) % 3),
//! count (u16, big-endian, at most 4096), one byte per component for its width (% 25), one
//! mode byte per component (any value, so invalid modes are met too), then the rest of the
//! data (method 2: the stream; method 3: the raw bits' length, the stream, the raw bits;
//! method 4: the shape offset where a mode is 5, then as method 3; method 5: the base,
//! then as method 3). Method 5's footprint sizes are drawn from the count, spread over
//! more than its eight classes, so that every class and both clamps are met.
//!
//! An accepted payload must hold codes within each quantizer's range, and coding those
//! codes again in the same modes must give a payload that decodes to the same codes.

#![no_main]

use gsi::format::{Attribute, Limits, Quantizer};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let [k, c0, c1, rest @ ..] = data else {
        return;
    };
    let method = match (*k >> 6, *k & 0x20) {
        (0 | 1, _) => 2,
        (2, _) => 3,
        (_, 0) => 4,
        _ => 5,
    };
    let k = 1 + usize::from((*k & 0x3F) % 3);
    let count = u32::from(u16::from_be_bytes([*c0, *c1])).min(4096);
    if rest.len() < 2 * k {
        return;
    }
    let (bits, rest) = rest.split_at(k);
    let (modes, stream) = rest.split_at(k);
    let quantizers: Vec<Quantizer> = bits
        .iter()
        .map(|b| match b % 25 {
            0 => Quantizer {
                bits: 0,
                min: 0.5,
                max: 0.5,
            },
            b => Quantizer {
                bits: b,
                min: -1.0,
                max: 2.0,
            },
        })
        .collect();
    let bits_total: u64 = quantizers.iter().map(|q| u64::from(q.bits)).sum();
    let mut payload = vec![k as u8];
    for q in &quantizers {
        payload.push(q.bits);
        payload.extend(q.min.to_be_bytes());
        payload.extend(q.max.to_be_bytes());
    }
    payload.push(method);
    payload.extend(((u64::from(count) * bits_total).div_ceil(8) as u32).to_be_bytes());
    // Method 5's base comes before its modes: the stream's first byte.
    let (base, stream) = match (method, stream.split_first()) {
        (5, Some((b, rest))) => (Some(*b), rest),
        (5, None) => return,
        _ => (None, stream),
    };
    payload.extend(base);
    payload.extend_from_slice(modes);
    payload.extend_from_slice(stream);

    let sizes: Vec<i32> = (0..count as i32).map(|i| (i * 7) % 23 - 15).collect();
    let read = |p: &[u8]| match method {
        5 => Attribute::parse_standalone(p, k, count, &Limits::default(), Some(&sizes)),
        _ => Attribute::from_payload(p, k, count),
    };
    let Ok(a) = read(&payload) else {
        return;
    };
    assert_eq!(
        a.footprint.map(|b| b as u8),
        base,
        "the base is the payload's"
    );
    let n = count as usize;
    assert_eq!(a.codes.len(), n * k);
    for (plane, q) in a.codes.chunks(n.max(1)).zip(&a.quantizers) {
        assert!(plane.iter().all(|&c| c <= q.max_code()), "code past {q:?}");
    }
    let again = a
        .to_coded_payload(modes, method, Some(&sizes))
        .expect("accepted modes are valid");
    let back = read(&again).expect("re-coded payload decodes");
    assert_eq!(back, a, "codes change through a re-code");
});
