//! Container tests: the spec's worked example, roundtrips, streaming, corruption.

use gsi::format::{self, BitDepths, ChunkType, ErrorKind, Limits, Records, WriteOptions};
use gsi::model::{Blend, CovParam};
use gsi::synth::{random_scene, SceneSpec};
use std::io::Read;

/// Bytes of the hex dump in format-spec.md §9: on each line of the code block, the
/// two-digit hex tokens after the offset, up to the first word that is not one.
fn spec_hexdump() -> Vec<u8> {
    spec_block("## 9. Worked example", 1)
}

/// The bytes of the `nth` code block (1 for the first) after `heading` in format-spec.md.
fn spec_block(heading: &str, nth: usize) -> Vec<u8> {
    let spec =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/format-spec.md")).unwrap();
    let section = spec.split(heading).nth(1).expect("spec has the section");
    let block = section
        .split("```")
        .nth(2 * nth - 1)
        .expect("the section has the code block");
    let mut bytes = Vec::new();
    for line in block.lines().skip(2) {
        for tok in line.split_whitespace().skip(1) {
            match u8::from_str_radix(tok, 16) {
                Ok(b) if tok.len() == 2 => bytes.push(b),
                _ => break,
            }
        }
    }
    bytes
}

#[test]
fn spec_worked_example_matches_the_encoder() {
    assert_eq!(spec_hexdump(), format::tests_support::tiny_file());
}

/// §9.1 and §9.2: each coded payload of the spec decodes to its codes, and the encoder
/// writes exactly those bytes in the same method and modes.
#[test]
fn spec_method_2_3_and_4_examples_decode() {
    let q = |bits| format::Quantizer {
        bits,
        min: 0.0,
        max: 1.0,
    };
    let pos = format::Attribute {
        quantizers: vec![q(4), q(4)],
        codes: vec![1, 3, 12, 2, 2, 9],
        shape: None,
        footprint: None,
    };
    let col = format::Attribute {
        quantizers: vec![q(3), q(3), q(3)],
        codes: vec![7, 1, 4, 6, 1, 5, 6, 0, 5],
        shape: None,
        footprint: None,
    };
    let cov = format::Attribute {
        quantizers: vec![q(7), q(7), q(7)],
        codes: vec![100, 37, 64, 101, 36, 70, 5, 127, 64],
        shape: None,
        footprint: None,
    };
    // Log-scales of 3 bits over [−8, −1] (values −8 + q) and a 4-bit angle, shaped.
    let scale = format::Quantizer {
        bits: 3,
        min: -8.0,
        max: -1.0,
    };
    let angle = format::Quantizer {
        bits: 4,
        min: -std::f32::consts::FRAC_PI_4,
        max: std::f32::consts::FRAC_PI_4,
    };
    let shaped = format::Attribute {
        quantizers: vec![scale, scale, angle],
        codes: vec![4, 5, 6, 4, 3, 0, 8, 11, 2],
        shape: Some(7.0),
        footprint: None,
    };
    let examples = [
        ("### 9.1 Method 2 payloads", 2, 1, &pos, &[3u8, 3][..]),
        ("### 9.1 Method 2 payloads", 2, 2, &col, &[0, 1, 2][..]),
        ("### 9.2 Method 3 payloads", 3, 1, &pos, &[3, 3][..]),
        ("### 9.2 Method 3 payloads", 3, 2, &cov, &[0, 1, 4][..]),
        ("### 9.3 A method 4 payload", 4, 1, &shaped, &[4, 4, 5][..]),
    ];
    for (section, method, nth, attribute, modes) in examples {
        let bytes = spec_block(section, nth);
        let decoded = format::Attribute::from_payload(&bytes, attribute.components(), 3).unwrap();
        assert_eq!(&decoded, attribute, "{section}, example {nth}");
        assert_eq!(
            attribute.to_coded_payload(modes, method, None).unwrap(),
            bytes
        );
    }
}

/// §9.4: the method-5 payload decodes, with the sizes of its Gaussians' log-scales, to its
/// codes and base; the encoder writes exactly those bytes; and the colours are the
/// values divided by `2^k`.
#[test]
fn spec_method_5_example_decodes() {
    use gsi::format::footprint::{class, size_of, step};
    let scales = [(-8.0f32, -8.0f32), (-4.0, -4.0), (-1.0, -1.0)];
    let sizes: Vec<i32> = scales.iter().map(|&(a, b)| size_of(a, b)).collect();
    assert_eq!(sizes, [-9, -5, -2]);
    let q = format::Quantizer {
        bits: 3,
        min: 0.0,
        max: 7.0,
    };
    let colors = format::Attribute {
        quantizers: vec![q; 3],
        codes: vec![7, 2, 5, 1, 6, 0, 4, 3, 7],
        shape: None,
        footprint: Some(-9),
    };
    let bytes = spec_block("### 9.4 A method 5 payload", 1);
    let payload = colors
        .to_coded_payload(&[0, 1, 4], format::METHOD_FOOTPRINT, Some(&sizes))
        .unwrap();
    assert_eq!(payload, bytes, "{payload:02x?}");
    let decoded = format::Attribute::from_colour_payload(&bytes, 3, &sizes).unwrap();
    assert_eq!(decoded, colors);
    let values: Vec<[f32; 3]> = decoded.values();
    let got: Vec<[f32; 3]> = values
        .iter()
        .zip(&sizes)
        .map(|(v, &s)| v.map(|x| x * step(class(s, -9))))
        .collect();
    assert_eq!(
        got,
        [
            [7.0, 1.0, 4.0],
            [0.125, 0.375, 0.1875],
            [0.0390625, 0.0, 0.0546875]
        ]
    );
    // Read without the sizes (no log-scale GCOV before it), it is refused.
    assert!(format::Attribute::from_payload(&bytes, 3, 3).is_err());
}

/// The corpus file of §5.4.6's edges: every pair of 4-bit log-scale codes over [−15, 0]
/// under β = −12 reaches both clamps of the class and `floor` below zero (truncation
/// would put `s` = −8.66 in class 4, not 3), and its colours are the stored values
/// divided by `2^k`.
#[test]
fn spec_colour_classes_at_their_edges() {
    use gsi::format::footprint::{class, size_of, step};
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/corpus/valid/coded5-sum-lsr-256-classes.gsi"
    );
    let file = format::read_file(&std::fs::read(path).unwrap()[..], Limits::default()).unwrap();
    let r = &file.records;
    assert_eq!(r.colors.footprint, Some(-12));
    let s = r.covariance.quantizers[0];
    let n = 256;
    let sizes: Vec<i32> = (0..n)
        .map(|i| {
            let (a, b) = (r.covariance.codes[i], r.covariance.codes[n + i]);
            size_of(s.dequantize(a), s.dequantize(b))
        })
        .collect();
    assert_eq!(sizes.iter().min(), Some(&-17));
    assert_eq!(sizes.iter().max(), Some(&0));
    // −16 · 0.541… = −8.656…: floor −9, class 3.
    assert_eq!(size_of(-8.0, -8.0), -9);
    assert_eq!(class(-9, -12), 3);
    let classes: Vec<u8> = sizes.iter().map(|&z| class(z, -12)).collect();
    assert!(classes.contains(&0) && classes.contains(&7));
    assert!(sizes.iter().any(|&z| z < -12) && sizes.iter().any(|&z| z > -5));
    let stored: Vec<[f32; 3]> = r.colors.values();
    let want: Vec<[f32; 3]> = stored
        .iter()
        .zip(&classes)
        .map(|(v, &k)| v.map(|x| x * step(k)))
        .collect();
    assert_eq!(r.to_scene().gaussians.colors, want);
}

/// The corpus file of §5.4.5's edges holds what fitted files rarely reach: a sum just below
/// an integer (`floor`, not truncation), round Gaussians whose `floor(...)` would keep
/// bits (they keep none), and the depth reached.
#[test]
fn spec_shaped_angles_at_their_edges() {
    use gsi::format::angle::{coarse_code, shape_bits};
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/corpus/valid/coded4-sum-lsr-64-edges.gsi"
    );
    let file = format::read_file(&std::fs::read(path).unwrap()[..], Limits::default()).unwrap();
    let cov = &file.records.covariance;
    let offset = cov.shape.expect("method 4, mode 5");
    assert_eq!(offset, -1.0 / (1u32 << 20) as f32);
    let [s, _, a] = [cov.quantizers[0], cov.quantizers[1], cov.quantizers[2]];
    let keep = |q0: u32, q1: u32| shape_bits(s.dequantize(q0), s.dequantize(q1), offset, a.bits);
    assert_eq!(
        (a.bits, keep(0, 7), keep(7, 0)),
        (10, 9, 9),
        "floor below 0, not 0"
    );
    assert_eq!(
        (keep(7, 7), keep(6, 6)),
        (0, 0),
        "round Gaussians keep nothing"
    );
    assert_eq!(keep(3, 4), 1);
    assert_eq!(keep(1, 7), 10);
    for i in 0..64usize {
        let k = keep(cov.codes[i], cov.codes[64 + i]);
        assert!(
            coarse_code(cov.codes[128 + i], k, a.bits).is_some(),
            "Gaussian {i}"
        );
    }
}

fn sample_files() -> Vec<(Records, Vec<u8>)> {
    let mut out = Vec::new();
    for (seed, blend, cov, n) in [
        (1, Blend::Sum, CovParam::Cholesky, 0),
        (2, Blend::Sum, CovParam::LogScaleRotation, 1),
        (3, Blend::Alpha, CovParam::LogScaleRotation, 50),
        (4, Blend::Alpha, CovParam::Cholesky, 700),
    ] {
        let scene = random_scene(
            seed,
            SceneSpec {
                cov_param: cov,
                ..SceneSpec::new(64, 40, n, blend)
            },
        );
        let records = Records::from_scene(&scene, BitDepths::default());
        let opts = WriteOptions {
            psnr: Some(31.5),
            settings: Some("seed=1".into()),
            ..Default::default()
        };
        let bytes = format::to_bytes(&records, &opts).unwrap();
        out.push((records, bytes));
    }
    out
}

#[test]
fn records_roundtrip_exactly() {
    for (records, bytes) in sample_files() {
        let f = format::read_file(&bytes[..], Limits::default()).unwrap();
        assert_eq!(f.records, records);
        assert_eq!(f.file_bytes, bytes.len() as u64);
        let meta = f.metadata.expect("gCRM written");
        assert_eq!(meta.file_bytes, bytes.len() as u64);
        assert_eq!(meta.psnr, Some(31.5));
        assert_eq!(meta.settings, "seed=1");
        // Writing what was read gives the same bytes.
        let opts = WriteOptions {
            psnr: meta.psnr,
            settings: Some(meta.settings),
            ..Default::default()
        };
        assert_eq!(format::to_bytes(&f.records, &opts).unwrap(), bytes);
    }
}

#[test]
fn model_roundtrip_is_lossless_through_records() {
    for (records, _) in sample_files() {
        let scene = records.to_scene();
        let again = Records {
            positions: gsi::format::Attribute::quantize(
                &scene.gaussians.positions,
                records.positions.quantizers.clone().try_into().unwrap(),
            ),
            covariance: gsi::format::Attribute::quantize(
                &scene.gaussians.cov,
                records.covariance.quantizers.clone().try_into().unwrap(),
            ),
            colors: gsi::format::Attribute::quantize(
                &scene.gaussians.colors,
                records.colors.quantizers.clone().try_into().unwrap(),
            ),
            ..records.clone()
        };
        assert_eq!(again, records);
    }
}

/// Yields one byte per `read` call: the decoder must not depend on read sizes.
struct OneByte<'a>(&'a [u8]);
impl Read for OneByte<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.0.is_empty() || buf.is_empty() {
            return Ok(0);
        }
        buf[0] = self.0[0];
        self.0 = &self.0[1..];
        Ok(1)
    }
}

#[test]
fn streaming_is_independent_of_read_sizes() {
    for (_, bytes) in sample_files() {
        let whole = format::read_file(&bytes[..], Limits::default()).unwrap();
        let trickled = format::read_file(OneByte(&bytes), Limits::default()).unwrap();
        assert_eq!(whole, trickled);
    }
}

#[test]
fn header_is_available_before_attributes() {
    let (_, bytes) = sample_files().pop().unwrap();
    // Only the signature and GHDR are present: the header still reads.
    let mut dec = format::Decoder::new(&bytes[..8 + 12 + 18]);
    let h = dec.read_header().unwrap();
    assert_eq!((h.width, h.height, h.count), (64, 40, 700));
    assert_eq!(dec.finish().unwrap_err().kind(), ErrorKind::Truncated);
}

#[test]
fn every_truncation_is_refused() {
    for (_, bytes) in sample_files() {
        for len in 0..bytes.len() {
            let e = format::read_file(&bytes[..len], Limits::default()).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::Truncated, "len {len}: {e}");
        }
    }
}

#[test]
fn every_bit_flip_is_refused() {
    // Every byte is signature, framing, or covered by a CRC: no flip may go unnoticed.
    let (_, bytes) = &sample_files()[2];
    for at in 0..bytes.len() {
        for bit in 0..8 {
            let mut b = bytes.clone();
            b[at] ^= 1 << bit;
            assert!(
                format::read_file(&b[..], Limits::default()).is_err(),
                "flip of bit {bit} at byte {at} accepted"
            );
        }
    }
}

#[test]
fn crc_errors_name_chunk_and_offset() {
    let (_, mut bytes) = sample_files().remove(2);
    let f = format::read_file(&bytes[..], Limits::default()).unwrap();
    let col = f.chunks.iter().find(|c| c.ty == ChunkType::COLORS).unwrap();
    bytes[col.offset as usize + 8 + 3] ^= 0x40;
    let e = format::read_file(&bytes[..], Limits::default()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::CrcMismatch);
    assert_eq!(e.chunk(), Some(ChunkType::COLORS));
    assert_eq!(e.offset(), Some(col.offset));
    assert!(
        e.to_string().starts_with(&format!(
            "CRC mismatch in chunk GCOL at byte {}",
            col.offset
        )),
        "{e}"
    );
}

#[test]
fn huge_length_field_is_refused_without_allocating() {
    let (_, bytes) = sample_files().remove(3);
    let f = format::read_file(&bytes[..], Limits::default()).unwrap();
    let gpos = f
        .chunks
        .iter()
        .find(|c| c.ty == ChunkType::POSITIONS)
        .unwrap();
    // Everything before GPOS, then a GPOS head claiming ~4 GiB, then a few bytes.
    let mut b = bytes[..gpos.offset as usize].to_vec();
    b.extend_from_slice(&0xFFFF_FFF0u32.to_be_bytes());
    b.extend_from_slice(b"GPOS");
    b.extend_from_slice(&[0u8; 100]);
    // Too long for the chunk limit:
    let e = format::read_file(&b[..], Limits::default()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::LimitExceeded, "{e}");
    // Within the limit but the stream is short: only the present bytes are read.
    let unlimited = Limits::unlimited();
    let e = format::read_file(&b[..], unlimited).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Truncated, "{e}");
}

#[test]
fn limits_are_enforced_before_allocation() {
    let (_, bytes) = sample_files().remove(3);
    let tight = |f: &dyn Fn(&mut Limits)| {
        let mut l = Limits::default();
        f(&mut l);
        format::read_file(&bytes[..], l).unwrap_err().kind()
    };
    assert_eq!(tight(&|l| l.max_gaussians = 699), ErrorKind::LimitExceeded);
    assert_eq!(tight(&|l| l.max_dimension = 63), ErrorKind::LimitExceeded);
    assert_eq!(tight(&|l| l.max_chunk_len = 100), ErrorKind::LimitExceeded);
    assert_eq!(tight(&|l| l.max_alloc = 1000), ErrorKind::LimitExceeded);
    assert_eq!(
        tight(&|l| l.max_decompressed = 100),
        ErrorKind::LimitExceeded
    );
}

#[test]
fn unknown_chunks_follow_their_criticality() {
    let records = Records::from_scene(&format::tests_support::tiny_scene(), BitDepths::default());
    let extra = |ty: &[u8; 4]| {
        let opts = WriteOptions {
            ancillary: vec![format::RawChunk {
                ty: ChunkType(*ty),
                data: vec![1, 2, 3],
            }],
            ..Default::default()
        };
        format::to_bytes(&records, &opts)
    };
    // Ancillary: kept, file reads.
    let f = format::read_file(&extra(b"zzZz").unwrap()[..], Limits::default()).unwrap();
    assert_eq!(f.ancillary.len(), 1);
    // The writer refuses to emit an unknown critical chunk…
    assert!(extra(b"ZZzz").is_err());
    // …and the reader refuses one that is spliced in.
    let mut b = format::tests_support::tiny_file();
    let end = b.len() - 12;
    let mut chunk = Vec::new();
    chunk.extend_from_slice(&0u32.to_be_bytes());
    chunk.extend_from_slice(b"ZZzz");
    chunk.extend_from_slice(&format::chunk_crc(ChunkType(*b"ZZzz"), &[]).to_be_bytes());
    b.splice(end..end, chunk);
    let e = format::read_file(&b[..], Limits::default()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::UnknownCriticalChunk);
}

/// `bytes` with the payload of every chunk of type `ty` replaced by `f(payload)` (CRC
/// recomputed), and `extra` chunks inserted before `GEND`.
fn rewrite(
    bytes: &[u8],
    ty: ChunkType,
    f: impl Fn(&[u8]) -> Vec<u8>,
    extra: &[(ChunkType, Vec<u8>)],
) -> Vec<u8> {
    let file = format::ChunkedFile::parse(bytes, Limits::default()).unwrap();
    let mut out = bytes[..8].to_vec();
    for c in &file.chunks {
        if c.ty == ChunkType::END {
            for (t, d) in extra {
                put_chunk(&mut out, *t, d);
            }
        }
        let data = if c.ty == ty {
            f(&c.data)
        } else {
            c.data.clone()
        };
        put_chunk(&mut out, c.ty, &data);
    }
    out
}

/// Append one framed chunk (§2.2).
fn put_chunk(out: &mut Vec<u8>, ty: ChunkType, data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    out.extend_from_slice(&ty.0);
    out.extend_from_slice(data);
    out.extend_from_slice(&format::chunk_crc(ty, data).to_be_bytes());
}

/// §2.5, §7.4: a stage-2 rewrite keeps `GHDR` byte for byte, so its colours take only a
/// coded method that the file's minor version allows: none before 1.1, method 2 in
/// 1.1–1.5, method 3 from 1.6 (method 4 of 1.7 is for shaped angles, never colours).
#[test]
fn a_stage_2_rewrite_codes_colours_only_in_a_method_its_minor_allows() {
    let corpus = concat!(env!("CARGO_MANIFEST_DIR"), "/corpus/valid/");
    // An enhancer record from a small enhanced file, put on a larger one (3,000
    // Gaussians), with colours whose green and blue differ from red in the lowest bit
    // only: coded `across`, they take far fewer bytes than the 1.0 codings do.
    let enhanced = std::fs::read(format!("{corpus}enhanced-sum-160.gsi")).unwrap();
    let enhanced = format::ChunkedFile::parse(&enhanced, Limits::default()).unwrap();
    let record = enhanced.enhancer(&Limits::default()).unwrap().unwrap();
    let bytes = std::fs::read(format!("{corpus}coded3-sum-lsr-3000-morton.gsi")).unwrap();
    for (minor, methods) in [
        (0u8, &[0u8, 1][..]),
        (1, &[2]),
        (5, &[2]),
        (6, &[3]),
        (7, &[3]),
    ] {
        let patched = rewrite(
            &bytes,
            ChunkType::HEADER,
            |p| {
                let mut p = p.to_vec();
                p[1] = minor;
                p
            },
            &[],
        );
        let file = format::ChunkedFile::parse(&patched, Limits::default()).unwrap();
        let mut colors = file.file.records.colors.clone();
        let n = colors.count();
        let red = colors.codes[..n].to_vec();
        for k in 1..3 {
            colors.quantizers[k] = colors.quantizers[0];
            for (i, &r) in red.iter().enumerate() {
                colors.codes[k * n + i] = r ^ (i as u32 >> (k - 1) & 1);
            }
        }
        let out = file.with_colors(&colors, &record, None, true, 19).unwrap();
        let again = format::ChunkedFile::parse(&out, Limits::default()).unwrap();
        assert_eq!(again.file.records.header.version_minor, minor);
        assert_eq!(again.file.records.colors, colors);
        let gcol = again
            .chunks
            .iter()
            .find(|c| c.ty == ChunkType::COLORS)
            .unwrap();
        // §5.1: the method byte follows the count of components and their 9-byte
        // quantizers.
        let method = gcol.data[1 + 9 * 3];
        assert!(methods.contains(&method), "minor {minor}: method {method}");
    }
}

/// §5.1: with `packed_len` = 0 (no Gaussians, or every component 0 bits wide) there is
/// nothing to compress. Stored, the data is empty; under zstd it is a stream that
/// decompresses to nothing: an empty frame, or no frame at all (empty data). Both read
/// as the stored form does; any byte of data beyond that is refused.
#[test]
fn an_empty_attribute_under_zstd() {
    let mut scene = format::tests_support::tiny_scene();
    scene.gaussians = gsi::model::GaussianSet::default();
    let records = Records::from_scene(&scene, BitDepths::default());
    let stored = format::to_bytes(&records, &WriteOptions::default()).unwrap();
    let reference = format::read_file(&stored[..], Limits::default())
        .unwrap()
        .records;
    let pre = 6 + 9 * 2;
    fn zstd_with(data: &[u8], pre: usize) -> impl Fn(&[u8]) -> Vec<u8> + '_ {
        move |p: &[u8]| {
            assert_eq!(p.len(), pre, "stored empty GPOS");
            let mut q = p.to_vec();
            q[pre - 5] = 1;
            q.extend_from_slice(data);
            q
        }
    }
    let empty_frame = zstd::bulk::compress(&[], 3).unwrap();
    for (what, data) in [("no frame", &[][..]), ("an empty frame", &empty_frame[..])] {
        let b = rewrite(&stored, ChunkType::POSITIONS, zstd_with(data, pre), &[]);
        let f = format::read_file(&b[..], Limits::default());
        assert_eq!(f.map(|f| f.records).ok(), Some(reference.clone()), "{what}");
    }
    let b = rewrite(
        &stored,
        ChunkType::POSITIONS,
        zstd_with(&[0x28, 0xb5], pre),
        &[],
    );
    assert!(
        format::read_file(&b[..], Limits::default()).is_err(),
        "a broken frame was read"
    );
}

/// §2.3: every decoder checks an ancillary chunk's framing, count and length range; its
/// contents bind only the decoders that use it. A `gENH` of a valid length whose contents
/// are not an enhancer still renders, and is refused where it is interpreted; a second
/// `gENH` is refused by every decoder.
#[test]
fn stage_two_chunks_are_checked_where_used() {
    let plain = format::tests_support::tiny_file();
    let junk = vec![9u8; 201]; // the shortest gENH §3 allows
    let b = rewrite(
        &plain,
        ChunkType::END,
        |p| p.to_vec(),
        &[(ChunkType::ENHANCER, junk.clone())],
    );
    let f = format::ChunkedFile::parse(&b, Limits::default()).expect("renders");
    assert!(
        f.enhancer(&Limits::default()).is_err(),
        "junk gENH interpreted"
    );
    let two = rewrite(
        &plain,
        ChunkType::END,
        |p| p.to_vec(),
        &[
            (ChunkType::ENHANCER, junk.clone()),
            (ChunkType::ENHANCER, junk),
        ],
    );
    let e = format::read_file(&two[..], Limits::default()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::ChunkOrder, "{e}");
    // Unknown ancillary chunks may repeat.
    let any = (ChunkType(*b"zzZz"), vec![1, 2]);
    let b = rewrite(&plain, ChunkType::END, |p| p.to_vec(), &[any.clone(), any]);
    assert_eq!(
        format::read_file(&b[..], Limits::default())
            .unwrap()
            .ancillary
            .len(),
        2
    );
}

/// The gENH of the corpus file `name`, parsed, and its payload.
fn corpus_enhancer(name: &str) -> (format::EnhancerRecord, Vec<u8>) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/corpus/valid/").to_owned() + name;
    let f = format::ChunkedFile::parse(&std::fs::read(path).unwrap(), Limits::default()).unwrap();
    let payload = f
        .chunks
        .iter()
        .find(|c| c.ty == ChunkType::ENHANCER)
        .expect("an enhanced file")
        .data
        .to_vec();
    (f.enhancer(&Limits::default()).unwrap().unwrap(), payload)
}

/// How `gENH` bytes with `edit` applied are refused (the edit must make them invalid).
fn genh_refused(bytes: &[u8], edit: &dyn Fn(&mut Vec<u8>)) -> ErrorKind {
    let mut b = bytes.to_vec();
    edit(&mut b);
    format::EnhancerRecord::parse(&b, &Limits::default())
        .expect_err("refused")
        .kind()
}

/// An edit that writes `x` as a big-endian f32 at offset `o`.
fn f32_at(o: usize, x: f32) -> impl Fn(&mut Vec<u8>) {
    move |b: &mut Vec<u8>| b[o..o + 4].copy_from_slice(&x.to_be_bytes())
}

/// §7.2 layout 2: the denoise record sits at offset 68 as the spec's example shows,
/// layout 1 is still what an enhancer without denoising is written as, and every field
/// outside its range is refused where the chunk is read.
#[test]
fn genh_layout_2_reads_writes_and_refuses_as_specified() {
    let (plain, plain_bytes) = corpus_enhancer("enhanced-sum-160.gsi");
    assert_eq!(plain_bytes[0], 1);
    assert_eq!(plain.denoise, None);
    let (record, bytes) = corpus_enhancer("enhanced-denoised-sum-160.gsi");
    assert_eq!(bytes[0], 2);
    assert_eq!(bytes.len(), plain_bytes.len() + 12);
    assert_eq!(record.to_payload(19).unwrap(), bytes);

    // The spec's example record, put in place of this one.
    let example = spec_block("### 7.2.1 Denoising", 1);
    assert_eq!(example.len(), 12);
    let mut b = bytes.clone();
    b[68..80].copy_from_slice(&example);
    let r = format::EnhancerRecord::parse(&b, &Limits::default()).unwrap();
    assert_eq!(
        r.denoise,
        Some(format::Denoise {
            range: 0.5,
            strength: 1.0,
            passes: 1
        })
    );

    let refused = |edit: &dyn Fn(&mut Vec<u8>)| genh_refused(&bytes, edit);
    for (what, kind) in [
        ("range 0", refused(&f32_at(68, 0.0))),
        ("range NaN", refused(&f32_at(68, f32::NAN))),
        ("range 65", refused(&f32_at(68, 65.0))),
        ("strength 0", refused(&f32_at(72, 0.0))),
        ("strength 1.5", refused(&f32_at(72, 1.5))),
        ("0 passes", refused(&|b| b[76] = 0)),
        ("9 passes", refused(&|b| b[76] = 9)),
        ("reserved", refused(&|b| b[79] = 1)),
    ] {
        assert_eq!(kind, ErrorKind::InvalidValue, "{what}");
    }
    assert_eq!(refused(&|b| b[0] = 7), ErrorKind::UnsupportedVersion);
    // Byte 3 is 0 in layouts 1 and 2, and never 0 in layouts 3 to 6.
    assert_eq!(refused(&|b| b[0] = 4), ErrorKind::InvalidValue);
    assert_eq!(refused(&|b| b[0] = 5), ErrorKind::InvalidValue);
    assert_eq!(refused(&|b| b[3] = 1), ErrorKind::InvalidValue);
    assert_eq!(refused(&|b| b[0] = 3), ErrorKind::InvalidValue);
    // A layout-2 chunk too short for its denoise record.
    assert_eq!(refused(&|b| b.truncate(75)), ErrorKind::BadChunkLength);
    // Layout 1 bytes read as layout 2 lose their first block to the record.
    let mut as_two = plain_bytes.clone();
    as_two[0] = 2;
    assert!(format::EnhancerRecord::parse(&as_two, &Limits::default()).is_err());
}

/// §7.2 layout 3: byte 3 says which records follow, the tone record sits after the
/// denoise record (or at 68 alone) as the spec's example shows, and every field outside
/// its range is refused where the chunk is read.
#[test]
fn genh_layout_3_reads_writes_and_refuses_as_specified() {
    let (denoised, denoised_bytes) = corpus_enhancer("enhanced-denoised-sum-160.gsi");
    let (record, bytes) = corpus_enhancer("enhanced-denoised-toned-sum-160.gsi");
    assert_eq!((bytes[0], bytes[3]), (3, 3));
    assert_eq!(bytes.len(), denoised_bytes.len() + 12);
    assert_eq!(record.denoise, denoised.denoise);
    let tone = format::Tone {
        exponent: 0.7,
        scale: 1.3,
        passes: 3,
    };
    assert_eq!(record.tone, Some(tone));
    assert_eq!(record.to_payload(19).unwrap(), bytes);
    let (alone, alone_bytes) = corpus_enhancer("enhanced-toned-alpha-160.gsi");
    assert_eq!((alone_bytes[0], alone_bytes[3]), (3, 2));
    assert_eq!((alone.denoise, alone.tone), (None, Some(tone)));
    assert_eq!(alone.to_payload(19).unwrap(), alone_bytes);

    // The spec's example: a tone record alone, in place of the denoise record of a
    // layout-2 chunk (the blocks stay where they are).
    let example = spec_block("### 7.2.2 A tone curve", 1);
    assert_eq!(example.len(), 12);
    let mut b = denoised_bytes.clone();
    b[0] = 3;
    b[3] = 2;
    b[68..80].copy_from_slice(&example);
    let r = format::EnhancerRecord::parse(&b, &Limits::default()).unwrap();
    assert_eq!(r.denoise, None);
    assert_eq!(
        r.tone,
        Some(format::Tone {
            exponent: 0.5,
            scale: 0.8,
            passes: 1
        })
    );
    assert_eq!(r.to_payload(19).unwrap(), b);

    let refused = |edit: &dyn Fn(&mut Vec<u8>)| genh_refused(&bytes, edit);
    // The tone record of `bytes` sits at 80, after the denoise record.
    for (what, kind) in [
        ("exponent 0", refused(&f32_at(80, 0.0))),
        ("exponent −0.5", refused(&f32_at(80, -0.5))),
        ("exponent NaN", refused(&f32_at(80, f32::NAN))),
        ("exponent 4.5", refused(&f32_at(80, 4.5))),
        ("scale 0", refused(&f32_at(84, 0.0))),
        ("scale 65", refused(&f32_at(84, 65.0))),
        ("scale ∞", refused(&f32_at(84, f32::INFINITY))),
        ("0 passes", refused(&|b| b[88] = 0)),
        ("9 passes", refused(&|b| b[88] = 9)),
        ("reserved", refused(&|b| b[91] = 1)),
        ("records 0", refused(&|b| b[3] = 0)),
        ("denoise record only", refused(&|b| b[3] = 1)),
        ("an unknown record", refused(&|b| b[3] = 7)),
        // The denoise record is still checked in layout 3.
        ("denoise passes 0", refused(&|b| b[76] = 0)),
    ] {
        assert_eq!(kind, ErrorKind::InvalidValue, "{what}");
    }
    // Too short for its records.
    assert_eq!(refused(&|b| b.truncate(87)), ErrorKind::BadChunkLength);
    // Read with one record fewer than written, the blocks start in the wrong place.
    let mut as_one = bytes.clone();
    as_one[3] = 2;
    assert!(format::EnhancerRecord::parse(&as_one, &Limits::default()).is_err());
}

/// How `gENH` bytes `good` are refused once their last map block's range reads
/// `[lo, hi]`: the block's preamble is found by its `max`, `marker`, the last such f32.
fn last_block_range_refused(good: &[u8], marker: f32, lo: f32, hi: f32) -> ErrorKind {
    let at = good
        .windows(4)
        .rposition(|w| w == marker.to_be_bytes())
        .expect("the map block's max");
    let mut bad = good.to_vec();
    bad[at - 4..at].copy_from_slice(&lo.to_be_bytes());
    bad[at..at + 4].copy_from_slice(&hi.to_be_bytes());
    format::EnhancerRecord::parse(&bad, &Limits::default())
        .expect_err("refused")
        .kind()
}

/// §7.2 layout 4: a gain record (bit 2 of byte 3) after the other records and an eighth
/// block of gains; every field outside its range is refused where the chunk is read.
#[test]
fn genh_layout_4_reads_writes_and_refuses_as_specified() {
    let (record, bytes) = corpus_enhancer("enhanced-gained-alpha-160.gsi");
    assert_eq!((bytes[0], bytes[3]), (4, 4));
    let map = record.gain.as_ref().expect("a gain map");
    assert_eq!((map.width, map.height), (4, 3));
    assert_eq!(&bytes[68..72], &[0, 4, 0, 3]);
    assert_eq!(record.to_payload(19).unwrap(), bytes);
    let (both, both_bytes) = corpus_enhancer("enhanced-denoised-gained-sum-160.gsi");
    assert_eq!((both_bytes[0], both_bytes[3]), (4, 5));
    assert!(both.denoise.is_some() && both.gain.is_some());
    // The gain record follows the denoise record.
    assert_eq!(&both_bytes[80..84], &[0, 4, 0, 3]);
    assert_eq!(both.to_payload(19).unwrap(), both_bytes);

    let refused = |edit: &dyn Fn(&mut Vec<u8>)| genh_refused(&bytes, edit);
    for (what, kind) in [
        ("records without bit 2", refused(&|b| b[3] = 2)),
        ("records bit 3", refused(&|b| b[3] = 12)),
        ("width 0", refused(&|b| b[68..70].copy_from_slice(&[0, 0]))),
        (
            "height 1025",
            refused(&|b| b[70..72].copy_from_slice(&1025u16.to_be_bytes())),
        ),
    ] {
        assert_eq!(kind, ErrorKind::InvalidValue, "{what}");
    }
    // Another map size: the last block no longer holds width·height gains.
    assert!(format::EnhancerRecord::parse(
        &{
            let mut b = bytes.clone();
            b[69] = 5;
            b
        },
        &Limits::default()
    )
    .is_err());
    // Gains outside (0, 64]: the block's range is checked.
    for (lo, hi) in [(0.0f32, 2.0f32), (-1.0, 2.0), (1.0, 65.0)] {
        let mut r = record.clone();
        let g = r.gain.as_mut().unwrap();
        g.gains.quantizers[0].min = lo;
        g.gains.quantizers[0].max = hi;
        assert!(r.to_payload(19).is_err(), "[{lo}, {hi}] written");
        let mut ok = record.clone();
        ok.gain.as_mut().unwrap().gains.quantizers[0].max = 2.0;
        let kind = last_block_range_refused(&ok.to_payload(19).unwrap(), 2.0, lo, hi);
        assert_eq!(kind, ErrorKind::InvalidValue, "[{lo}, {hi}]");
    }
}

/// §7.2 layout 5: a chroma record (bit 3 of byte 3) after the other records and a block
/// of scales after the other blocks, with or without a gain map; every field outside its
/// range is refused where the chunk is read, and a decoder of layouts 1 to 4 would have
/// refused the layout by its number.
#[test]
fn genh_layout_5_reads_writes_and_refuses_as_specified() {
    let (alone, alone_bytes) = corpus_enhancer("enhanced-chroma-alpha-160.gsi");
    assert_eq!((alone_bytes[0], alone_bytes[3]), (5, 8));
    assert!(alone.gain.is_none());
    let map = alone.chroma.as_ref().expect("a chroma map");
    assert_eq!((map.width, map.height), (5, 4));
    assert_eq!(&alone_bytes[68..72], &[0, 5, 0, 4]);
    assert_eq!(alone.to_payload(19).unwrap(), alone_bytes);
    let (both, bytes) = corpus_enhancer("enhanced-gained-chroma-sum-160.gsi");
    assert_eq!((bytes[0], bytes[3]), (5, 12));
    assert!(both.gain.is_some() && both.chroma.is_some());
    // The chroma record follows the gain record.
    assert_eq!(&bytes[68..76], &[0, 4, 0, 3, 0, 5, 0, 4]);
    assert_eq!(both.to_payload(19).unwrap(), bytes);
    // Without its chroma map the same enhancer is written as layout 4.
    let mut four = both.clone();
    four.chroma = None;
    assert_eq!(four.to_payload(19).unwrap()[..4], [4, 4, 3, 4]);

    let refused = |edit: &dyn Fn(&mut Vec<u8>)| genh_refused(&bytes, edit);
    for (what, kind) in [
        ("records without bit 3", refused(&|b| b[3] = 4)),
        ("records bit 4", refused(&|b| b[3] = 28)),
        ("width 0", refused(&|b| b[72..74].copy_from_slice(&[0, 0]))),
        (
            "height 1025",
            refused(&|b| b[74..76].copy_from_slice(&1025u16.to_be_bytes())),
        ),
    ] {
        assert_eq!(kind, ErrorKind::InvalidValue, "{what}");
    }
    assert_eq!(refused(&|b| b[0] = 7), ErrorKind::UnsupportedVersion);
    // Another map size: the last block no longer holds width·height scales.
    assert!(format::EnhancerRecord::parse(
        &{
            let mut b = bytes.clone();
            b[73] = 6;
            b
        },
        &Limits::default()
    )
    .is_err());
    // Scales outside [0, 1]: the block's range is checked, when written and when read.
    for (lo, hi) in [(-0.5f32, 0.5f32), (0.25, 1.5)] {
        let mut r = alone.clone();
        let q = &mut r.chroma.as_mut().unwrap().scales.quantizers[0];
        (q.min, q.max) = (lo, hi);
        assert!(r.to_payload(19).is_err(), "[{lo}, {hi}] written");
        let mut ok = alone.clone();
        ok.chroma.as_mut().unwrap().scales.quantizers[0].max = 0.75;
        let kind = last_block_range_refused(&ok.to_payload(19).unwrap(), 0.75, lo, hi);
        assert_eq!(kind, ErrorKind::InvalidValue, "[{lo}, {hi}]");
    }
}

/// §7.2 layout 6: the speckle record follows every other record, the spec's example
/// record reads as written, an enhancer without one keeps its lower layout, and a
/// threshold outside `(0, 1]` or a records byte layout 6 does not allow is refused.
#[test]
fn genh_layout_6_reads_writes_and_refuses_as_specified() {
    let (alone, alone_bytes) = corpus_enhancer("enhanced-speckle-sum-160.gsi");
    assert_eq!((alone_bytes[0], alone_bytes[3]), (6, 16));
    assert_eq!(alone.speckle, Some(format::Speckle { threshold: 0.1 }));
    assert_eq!(&alone_bytes[68..72], &0.1f32.to_be_bytes());
    assert_eq!(alone.to_payload(19).unwrap(), alone_bytes);
    let (all, bytes) = corpus_enhancer("enhanced-speckle-all-sum-160.gsi");
    assert_eq!((bytes[0], bytes[3]), (6, 31));
    // Denoise (12 bytes), tone (12), gain (4), chroma (4), then the speckle record.
    assert_eq!(&bytes[92..100], &[0, 4, 0, 3, 0, 5, 0, 4]);
    assert_eq!(&bytes[100..104], &0.1f32.to_be_bytes());
    assert_eq!(all.to_payload(19).unwrap(), bytes);
    // Without it the same enhancer is written as layout 5.
    let mut five = all.clone();
    five.speckle = None;
    assert_eq!(five.to_payload(19).unwrap()[..4], [5, 4, 3, 15]);

    // The spec's example record, put in place of this one.
    let example = spec_block("### 7.2.5 Removing the Gaussians", 1);
    assert_eq!(example, [0x3c, 0x7a, 0x94, 0x2d]);
    let mut b = alone_bytes.clone();
    b[68..72].copy_from_slice(&example);
    let r = format::EnhancerRecord::parse(&b, &Limits::default()).unwrap();
    assert_eq!(r.speckle.unwrap().threshold, 0.015_294_117);

    let refused = |edit: &dyn Fn(&mut Vec<u8>)| genh_refused(&bytes, edit);
    for (what, kind) in [
        ("threshold 0", refused(&f32_at(100, 0.0))),
        ("threshold -0.1", refused(&f32_at(100, -0.1))),
        ("threshold 1.5", refused(&f32_at(100, 1.5))),
        ("threshold NaN", refused(&f32_at(100, f32::NAN))),
        ("threshold inf", refused(&f32_at(100, f32::INFINITY))),
        ("records without bit 4", refused(&|b| b[3] = 15)),
        ("records bit 5", refused(&|b| b[3] = 63)),
    ] {
        assert_eq!(kind, ErrorKind::InvalidValue, "{what}");
    }
    assert_eq!(refused(&|b| b[0] = 7), ErrorKind::UnsupportedVersion);
    // Layout 5 does not hold the record: bit 4 in a layout-5 chunk is refused.
    assert_eq!(refused(&|b| b[0] = 5), ErrorKind::InvalidValue);
    // The record cut off: the blocks start 4 bytes early and no longer parse.
    let mut short = alone_bytes.clone();
    short.drain(68..72);
    assert!(format::EnhancerRecord::parse(&short, &Limits::default()).is_err());
    // The corpus file takes both branches of step 4: some colours removed, some kept.
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/corpus/valid/enhanced-speckle-sum-160.gsi"
    );
    let file =
        format::ChunkedFile::parse(&std::fs::read(path).unwrap(), Limits::default()).unwrap();
    let scene = gsi::enhance::base_records(&file, &Limits::default())
        .unwrap()
        .to_scene();
    let out =
        gsi::enhance::speckle::apply(&scene, &scene.gaussians.colors, &alone.speckle.unwrap());
    let removed = out.iter().filter(|c| **c == [0.0; 3]).count();
    assert!(
        removed > 0 && removed < out.len(),
        "{removed} of {}",
        out.len()
    );
    // Written from memory, a bad threshold is refused too.
    let mut bad = alone.clone();
    bad.speckle = Some(format::Speckle { threshold: 0.0 });
    assert!(bad.to_payload(19).is_err());
}

/// §6.6's worked example: the chunk as printed, its CRC, and the three values.
#[test]
fn spec_tone_curve_example() {
    let chunk = spec_block("### 6.6 `GTRC`", 2);
    assert_eq!(&chunk[4..8], b"GTRC");
    let len = u32::from_be_bytes(chunk[..4].try_into().unwrap()) as usize;
    let payload = &chunk[8..8 + len];
    let crc = u32::from_be_bytes(chunk[8 + len..].try_into().unwrap());
    assert_eq!(format::chunk_crc(ChunkType::TONE_CURVE, payload), crc);
    let curve = format::trc::parse(payload).unwrap();
    assert_eq!((curve.curves(), curve.knots()), (1, 3));
    assert_eq!(curve.values(), &[0, 40000, 65535]);
    for (c, want, byte) in [
        (0.25f32, 0.610_360_86f32, 156u8),
        (0.09, 0.366_216_54, 93),
        (1.5, 1.0, 255),
    ] {
        let v = curve.eval(0, c);
        assert_eq!(v, want, "{c}");
        let rgb = gsi::RgbImage {
            width: 1,
            height: 1,
            data: vec![v; 3],
        };
        assert_eq!(rgb.to_rgb8()[0], byte, "{c}");
    }
    assert_eq!(format::trc::to_payload(&curve), payload);
}

/// A file with a `GTRC` shows every blended value through it, on the CPU and through
/// every output of the decoder API; without one, as before.
#[test]
fn a_tone_curve_changes_every_output_value_as_specified() {
    let mut records = Records::from_scene(
        &random_scene(31, SceneSpec::new(30, 20, 60, Blend::Sum)),
        BitDepths::default(),
    );
    let plain = records.to_scene();
    let curve = gsi::model::ToneCurve::sample(17, |x| (x * 1.7).sqrt().min(0.9)).unwrap();
    records.tone = Some(curve.clone());
    let bytes = format::to_bytes(&records, &WriteOptions::default()).unwrap();
    let file = format::read_file(&bytes[..], Limits::default()).unwrap();
    assert_eq!(file.records.tone.as_ref(), Some(&curve));
    let toned = file.records.to_scene();
    let (w, h) = (45, 30);
    let raw = gsi::render::render(&plain, w, h).unwrap();
    let out = gsi::render::render(&toned, w, h).unwrap();
    for (i, (o, r)) in out.data.iter().zip(&raw.data).enumerate() {
        assert_eq!(*o, curve.eval(i % 3, *r), "value {i}");
    }
    let image = gsi::decode(&bytes[..], w, h).unwrap();
    assert_eq!(image.data, out.to_rgb8());
}

/// §6.3.1's table: `E` at each listed `x`, bit for bit, from the spec's own hex (the rows
/// were computed by a separate binary32 implementation from the spec's text); and the
/// constants of its code block are the decoder's.
#[test]
fn spec_exp_table() {
    let spec =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/format-spec.md")).unwrap();
    let section = spec
        .split("### 6.3.1 The exponential")
        .nth(1)
        .expect("spec has §6.3.1")
        .split("\n### ")
        .next()
        .unwrap();
    let hex =
        |t: &str| u32::from_str_radix(t.trim().trim_matches('`').trim_start_matches("0x"), 16);
    use gsi::contract;
    assert_eq!(contract::EXP_POLY[5], 0.5);
    let mut rows = 0;
    for line in section.lines().filter(|l| l.starts_with("| `0x")) {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let x = f32::from_bits(hex(cells[1]).unwrap());
        let want = hex(cells[3]).unwrap();
        let got = gsi::contract::exp(x).to_bits();
        assert_eq!(
            got, want,
            "E({x}) = {got:#010x}, the spec says {want:#010x}"
        );
        rows += 1;
    }
    assert!(rows >= 7, "{rows} rows");
    // The code block's constants, by their bit patterns, against the ones `exp` uses.
    for (name, value) in [
        ("L  = ", contract::EXP_LOG2E),
        ("H  = ", contract::EXP_LN2_HI),
        ("K  = ", contract::EXP_LN2_LO),
        ("P0 = ", contract::EXP_POLY[0]),
        ("P1 = ", contract::EXP_POLY[1]),
        ("P2 = ", contract::EXP_POLY[2]),
        ("P3 = ", contract::EXP_POLY[3]),
        ("P4 = ", contract::EXP_POLY[4]),
    ] {
        let at = section.find(name).unwrap_or_else(|| panic!("{name}")) + name.len();
        let bits = hex(&section[at..at + 10]).unwrap();
        assert_eq!(f32::from_bits(bits), value, "{name}");
    }
}

/// §7.1.1's worked example reads into every typed field and is written back byte for
/// byte; an encode writes settings of that grammar only (no line left unread), with its
/// options in them.
#[test]
fn spec_settings_example() {
    use gsi::format::settings::{BudgetKind, InitKind, LossKind};
    let spec =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/format-spec.md")).unwrap();
    let section = spec.split("#### 7.1.1").nth(1).expect("spec has §7.1.1");
    let text = section
        .split("```")
        .nth(1)
        .expect("the section has the example");
    let text = text.trim_start_matches('\n').trim_end_matches('\n');
    let s = format::EncoderSettings::parse(text);
    assert!(s.other.is_empty(), "{:?}", s.other);
    assert_eq!(s.encoder.as_deref(), Some("gsi 0.1.0"));
    assert_eq!(s.init, Some(InitKind::Adaptive));
    assert_eq!((s.iterations, s.seed), (Some(600), Some(0)));
    assert_eq!(s.budget, Some(BudgetKind::Bpp(1.0)));
    assert_eq!(s.loss, Some(LossKind::L2));
    assert_eq!(s.bits, Some([12, 6, 8, 6, 7]));
    assert_eq!(s.coarse, Some((2, 0.5)));
    assert_eq!(
        (s.color_solve, s.solve_stored_colors, s.dark_gain),
        (None, None, None)
    );
    assert_eq!(s.to_text(), text);

    let scene = random_scene(3, SceneSpec::new(24, 16, 40, Blend::Sum));
    let target = gsi::render::render(&scene, 24, 16).unwrap();
    let opts = gsi::fit::EncodeOptions {
        budget: gsi::fit::Budget::Gaussians(30),
        iterations: 20,
        seed: 5,
        loss: gsi::fit::Loss::L1MsSsim { lambda: 0.2 },
        ..Default::default()
    };
    let e = gsi::fit::encode(&target, &opts, gsi::Device::Cpu, &mut |_| {}).unwrap();
    let file = format::read_file(&e.bytes[..], Limits::default()).unwrap();
    let written = file.metadata.expect("gCRM").settings;
    let s = format::EncoderSettings::parse(&written);
    assert!(s.other.is_empty(), "{written}");
    assert_eq!(s.budget, Some(BudgetKind::Gaussians(30)));
    assert_eq!(s.loss, Some(LossKind::L1MsSsim { lambda: 0.2 }));
    assert_eq!((s.iterations, s.seed), (Some(20), Some(5)));
    assert_eq!(s.to_text(), written);
}

/// `GCRW` and `GCRT` (spec §6.3.2): written empty right after `GHDR` and `gCRM` where the
/// records weigh by columns (in bands of 16 rows or of 32), read back as the rule; a file
/// without either weighs per pixel, bit for bit as before.
#[test]
fn the_column_rule_chunks_are_written_read_and_render_as_specified() {
    let mut spec = SceneSpec::new(40, 36, 200, Blend::Sum);
    spec.sigma_px = (0.3, 12.0);
    let per_pixel = Records::from_scene(&random_scene(32, spec), BitDepths::default());
    let opts = WriteOptions {
        settings: Some("generator=test".into()),
        ..WriteOptions::default()
    };
    let plain = format::to_bytes(&per_pixel, &opts).unwrap();
    let chunks = |bytes: &[u8]| {
        let file = format::read_file(bytes, Limits::default()).unwrap();
        (file.chunks.iter().map(|c| c.ty).collect::<Vec<_>>(), file)
    };
    let (types, file) = chunks(&plain);
    assert!(!types.contains(&ChunkType::COLUMN_WEIGHTS));
    assert!(!types.contains(&ChunkType::COLUMN_WEIGHTS_32));
    assert_eq!(file.records.weights, gsi::WeightRule::PerPixel);
    let (w, h) = (80, 72);
    let a = gsi::render::render(&per_pixel.to_scene(), w, h).unwrap();
    let mut renders = Vec::new();
    for (rule, ty) in [
        (gsi::WeightRule::Columns, ChunkType::COLUMN_WEIGHTS),
        (gsi::WeightRule::Columns32, ChunkType::COLUMN_WEIGHTS_32),
    ] {
        let columns = Records {
            weights: rule,
            ..per_pixel.clone()
        };
        let marked = format::to_bytes(&columns, &opts).unwrap();
        let (types, file) = chunks(&marked);
        assert_eq!(
            types[..3],
            [ChunkType::HEADER, ChunkType::COMPRESSION_META, ty]
        );
        assert_eq!(types.len(), chunks(&plain).0.len() + 1);
        assert_eq!(file.records.weights, rule);
        assert_eq!(marked.len(), plain.len() + 12);

        // Each rule differs from the per-pixel one in the last bits of some weights only.
        let b = gsi::render::render(&columns.to_scene(), w, h).unwrap();
        assert_ne!(a.data, b.data, "{rule:?}");
        let worst = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0f32, f32::max);
        assert!(worst < 1e-3, "{rule:?}: {worst}");
        let (a8, b8) = (a.to_rgb8(), b.to_rgb8());
        let moved = a8.iter().zip(&b8).filter(|(x, y)| x != y).count();
        assert!(moved * 1000 < a8.len(), "{rule:?}: {moved} of {}", a8.len());
        assert!(a8.iter().zip(&b8).all(|(x, y)| x.abs_diff(*y) <= 1));
        renders.push(b.data);
    }
    // Bands of 32 rows carry weights across row 16, 48, …: other bits than bands of 16.
    assert_ne!(renders[0], renders[1]);
}
