//! `GTRC` (spec §6.6): the tone curve a decoder applies to every blended value. Only
//! bytes live here; what the knots mean is [`crate::model::ToneCurve`].

use super::error::{Error, ErrorKind, Result};
use crate::model::{ToneCurve, TONE_KNOTS_MAX};
use byteorder::{BigEndian, ByteOrder};

/// Bytes before the knot values.
pub const TRC_FIXED_LEN: usize = 4;
/// Shortest `GTRC` payload: one curve of two knots.
pub const MIN_TRC_LEN: usize = TRC_FIXED_LEN + 2 * 2;
/// Longest `GTRC` payload: three curves of [`TONE_KNOTS_MAX`] knots.
pub const MAX_TRC_LEN: usize = TRC_FIXED_LEN + 2 * 3 * TONE_KNOTS_MAX;

/// Parse a `GTRC` payload. Every way it can break spec §6.6 is refused with the reason.
pub fn parse(p: &[u8]) -> Result<ToneCurve> {
    let bad = |what: String| Error::new(ErrorKind::InvalidValue, what);
    if p.len() < TRC_FIXED_LEN {
        return Err(Error::new(
            ErrorKind::BadChunkLength,
            format!("{} bytes, shorter than the 4-byte GTRC preamble", p.len()),
        ));
    }
    let (curves, reserved, knots) = (p[0], p[1], usize::from(BigEndian::read_u16(&p[2..4])));
    if curves != 1 && curves != 3 {
        return Err(bad(format!("GTRC with {curves} curves, 1 or 3 allowed")));
    }
    if reserved != 0 {
        return Err(bad(format!("GTRC reserved byte is {reserved:#04x}, not 0")));
    }
    if !(2..=TONE_KNOTS_MAX).contains(&knots) {
        return Err(bad(format!(
            "GTRC with {knots} knots, 2..={TONE_KNOTS_MAX} allowed"
        )));
    }
    let want = TRC_FIXED_LEN + 2 * usize::from(curves) * knots;
    if p.len() != want {
        return Err(Error::new(
            ErrorKind::BadChunkLength,
            format!(
                "GTRC of {} bytes, {curves} curve(s) of {knots} knots take {want}",
                p.len()
            ),
        ));
    }
    let values = p[TRC_FIXED_LEN..]
        .chunks_exact(2)
        .map(BigEndian::read_u16)
        .collect();
    Ok(ToneCurve::new(curves, values).expect("counts checked above"))
}

/// The `GTRC` payload of `curve`.
pub fn to_payload(curve: &ToneCurve) -> Vec<u8> {
    let mut out = Vec::with_capacity(TRC_FIXED_LEN + 2 * curve.values().len());
    out.push(curve.curves());
    out.push(0);
    out.extend_from_slice(&curve.knots().to_be_bytes());
    for v in curve.values() {
        out.extend_from_slice(&v.to_be_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payloads_round_trip() {
        for curve in [
            ToneCurve::new(1, vec![0, 65535]).unwrap(),
            ToneCurve::new(3, (0..3 * 17).map(|i| i * 1000).collect()).unwrap(),
        ] {
            assert_eq!(parse(&to_payload(&curve)).unwrap(), curve);
        }
    }

    #[test]
    fn malformed_payloads_are_refused_with_the_reason() {
        let ok = to_payload(&ToneCurve::new(1, vec![0, 7, 65535]).unwrap());
        let cases: [(Vec<u8>, &str); 6] = [
            (ok[..3].to_vec(), "preamble"),
            (
                {
                    let mut p = ok.clone();
                    p[0] = 2;
                    p
                },
                "curves",
            ),
            (
                {
                    let mut p = ok.clone();
                    p[1] = 1;
                    p
                },
                "reserved",
            ),
            (
                {
                    let mut p = ok.clone();
                    p[2..4].copy_from_slice(&1u16.to_be_bytes());
                    p
                },
                "knots",
            ),
            (
                {
                    let mut p = ok.clone();
                    p.push(0);
                    p
                },
                "take",
            ),
            (ok[..ok.len() - 2].to_vec(), "take"),
        ];
        for (p, why) in cases {
            let e = parse(&p).unwrap_err();
            assert!(e.to_string().contains(why), "{why}: {e}");
        }
    }
}
