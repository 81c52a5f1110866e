//! Shared by the `parse` and `decode` targets: tight limits, a one-byte-at-a-time
//! reader, and a parse that checks buffer independence and the dequantized scene.

#![allow(dead_code)]

use gsi::format::{chunk_crc, read_file, ChunkType, ErrorKind, GsiFile, Limits, SIGNATURE};
use gsi::model::Scene;
use std::cell::Cell;
use std::io::Read;
use std::sync::Once;

/// Bounds small enough that no input can make a run slow or large: whatever a file
/// says, the decoder must refuse it before it allocates more than this.
pub fn limits() -> Limits {
    Limits {
        max_dimension: 1 << 16,
        max_gaussians: 1 << 16,
        max_chunk_len: 16 << 20,
        max_decompressed: 16 << 20,
        max_alloc: 64 << 20,
        max_output_pixels: 1 << 20,
        // Far below the default (2^33): every accepted render must finish well within
        // the smoke run's per-input timeout, sanitizers and three renders included.
        max_render_work: 1 << 24,
    }
}

/// A reader that hands out one byte per `read` call, to catch any dependence of the
/// decoder on how its input is buffered.
pub struct OneByte<'a>(pub &'a [u8]);

impl Read for OneByte<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match (self.0.split_first(), buf.first_mut()) {
            (Some((&b, rest)), Some(slot)) => {
                *slot = b;
                self.0 = rest;
                Ok(1)
            }
            _ => Ok(0),
        }
    }
}

/// Every float of the scene is finite, and so is every covariance it implies.
pub fn assert_scene_finite(scene: &Scene) {
    let g = &scene.gaussians;
    assert!(g.is_consistent(), "inconsistent scene from valid records");
    let finite = |xs: &[f32]| xs.iter().all(|x| x.is_finite());
    for (i, p) in g.positions.iter().enumerate() {
        assert!(finite(p), "position {i} not finite: {p:?}");
    }
    for (i, c) in g.cov.iter().enumerate() {
        assert!(finite(c), "covariance parameters {i} not finite: {c:?}");
        let s = scene.cov_param.covariance(*c);
        assert!(finite(&s), "covariance {i} not finite: {c:?} -> {s:?}");
    }
    for (i, c) in g.colors.iter().enumerate() {
        assert!(finite(c), "colour {i} not finite: {c:?}");
    }
    if let Some(o) = &g.opacity {
        assert!(finite(o), "an opacity is not finite");
    }
}

/// [`parse_checked`], and when that fails on a CRC, again with every CRC repaired.
///
/// Random mutations almost never keep a CRC-32 right, so without the repair nearly every
/// mutated payload would stop at the CRC check; with it the fuzzer explores what the
/// payload parsers and the renderer make of them. A panic after a repair says so (see
/// [`note_repairs_on_panic`]): the file that reproduces it outside the fuzzer is then
/// [`repair_crcs`] of the input.
pub fn parse_deep(data: &[u8]) -> Option<GsiFile> {
    note_repairs_on_panic();
    REPAIRED.with(|r| r.set(false));
    match parse_checked(data) {
        Ok(file) => Some(file),
        Err(ErrorKind::CrcMismatch) => {
            REPAIRED.with(|r| r.set(true));
            parse_checked(&repair_crcs(data)).ok()
        }
        Err(_) => None,
    }
}

/// Rewrite the CRC of every complete chunk after the signature (whatever the signature
/// holds) so that it matches its type and payload.
pub fn repair_crcs(data: &[u8]) -> Vec<u8> {
    let mut out = data.to_vec();
    let mut at = SIGNATURE.len();
    while at + 8 <= out.len() {
        let len = u32::from_be_bytes(out[at..at + 4].try_into().unwrap()) as usize;
        let ty = ChunkType(out[at + 4..at + 8].try_into().unwrap());
        let Some(end) = (at + 8).checked_add(len).filter(|&e| e + 4 <= out.len()) else {
            break;
        };
        let crc = chunk_crc(ty, &out[at + 8..end]);
        out[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        at = end + 4;
    }
    out
}

thread_local! {
    static REPAIRED: Cell<bool> = const { Cell::new(false) };
}

/// Chain a panic hook (once) that says when the failing run had its CRCs repaired,
/// then hands over to the hook already installed (libfuzzer-sys's, which aborts).
fn note_repairs_on_panic() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if REPAIRED.with(|r| r.get()) {
                eprintln!("note: this run parsed the input with its CRCs repaired; the file that reproduces it is common::repair_crcs(input)");
            }
            previous(info)
        }));
    });
}

/// Parse `data` from a slice and again one byte per read; both must agree. Returns
/// the file when it is valid, the error kind when it is not.
pub fn parse_checked(data: &[u8]) -> Result<GsiFile, ErrorKind> {
    let whole = read_file(data, limits());
    let trickled = read_file(OneByte(data), limits());
    match (whole, trickled) {
        (Ok(a), Ok(b)) => {
            assert_eq!(a, b, "slice and one-byte reads disagree");
            assert!(a.records.is_consistent(), "parsed records are inconsistent");
            assert!(a.file_bytes <= data.len() as u64);
            assert_scene_finite(&a.records.to_scene());
            Ok(a)
        }
        (Err(a), Err(b)) => {
            assert_eq!(
                (a.kind(), a.chunk(), a.offset()),
                (b.kind(), b.chunk(), b.offset()),
                "slice and one-byte reads fail differently: {a} / {b}"
            );
            Err(a.kind())
        }
        (a, b) => panic!(
            "slice read gives {:?}, one-byte read gives {:?}",
            a.map(|_| "Ok"),
            b.map(|_| "Ok")
        ),
    }
}
