//! Writes the seed inputs under `fuzz/seeds/`: a handful of small valid files covering
//! both blend modes, both covariance parameterizations, opacity or none, 0..=24-bit
//! quantizers, stored and zstd payloads, `gCRM` or none, and an unknown ancillary chunk.
//!
//! `cargo run --manifest-path fuzz/Cargo.toml --features seeds --example gen_seeds [OUT_DIR]`
//!
//! `parse/` gets the files as they are; `decode/` gets each with a two-byte prefix that
//! the `decode` target reads as its output size. `coded/` gets method-2, 3 and 4 payloads
//! in the `coded` target's input layout: positions in Morton mode, covariance and colours
//! in mixed modes, shaped angles, at several depths.

use gsi::format::{to_bytes, BitDepths, ChunkType, RawChunk, Records, WriteOptions};
use gsi::model::{Blend, CovParam, GaussianSet, Scene};
use gsi::synth::{random_scene, SceneSpec};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("seeds"));
    let (parse_dir, decode_dir) = (out.join("parse"), out.join("decode"));
    std::fs::create_dir_all(&parse_dir)?;
    std::fs::create_dir_all(&decode_dir)?;

    let mut seeds: Vec<(String, Vec<u8>)> =
        vec![("tiny".into(), gsi::format::tests_support::tiny_file())];
    const DEFAULT: BitDepths = BitDepths {
        position: 16,
        covariance: 12,
        angle: 12,
        angle_by_shape: false,
        color_by_footprint: false,
        color: 8,
        opacity: 8,
    };
    const ODD: BitDepths = BitDepths {
        position: 3,
        covariance: 5,
        angle: 5,
        angle_by_shape: false,
        color_by_footprint: false,
        color: 7,
        opacity: 1,
    };
    const WIDE: BitDepths = BitDepths {
        position: 24,
        covariance: 24,
        angle: 24,
        angle_by_shape: false,
        color_by_footprint: false,
        color: 24,
        opacity: 24,
    };
    // The encoder's `sum` depths: angles shaped (§5.4.5), colours by footprint (§5.4.6).
    const ENCODER: BitDepths = BitDepths {
        position: 12,
        covariance: 6,
        angle: 8,
        angle_by_shape: true,
        color_by_footprint: true,
        color: 9,
        opacity: 6,
    };
    const NONE: BitDepths = BitDepths {
        position: 0,
        covariance: 0,
        angle: 0,
        angle_by_shape: false,
        color_by_footprint: false,
        color: 0,
        opacity: 0,
    };
    use Blend::{Alpha, Sum};
    use CovParam::{Cholesky as Chol, LogScaleRotation as Lsr};
    // name, width, height, count, blend, covariance, opacity, bits
    type Case = (
        &'static str,
        u32,
        u32,
        usize,
        Blend,
        CovParam,
        bool,
        BitDepths,
    );
    #[rustfmt::skip]
    let cases: &[Case] = &[
        ("empty",       8,  8,  0, Sum,   Chol, false, DEFAULT),
        ("one",         1,  1,  1, Alpha, Lsr,  true,  DEFAULT),
        ("sum-chol",   32, 24, 12, Sum,   Chol, false, DEFAULT),
        ("sum-lsr",    24, 32, 12, Sum,   Lsr,  false, DEFAULT),
        ("alpha-lsr",  48, 48, 30, Alpha, Lsr,  true,  DEFAULT),
        ("alpha-chol", 40, 30, 20, Alpha, Chol, true,  DEFAULT),
        ("bits-odd",   16, 16,  9, Alpha, Chol, true,  ODD),
        ("bits-24",    16, 16,  6, Sum,   Lsr,  false, WIDE),
        ("bits-0",     16, 16,  6, Alpha, Lsr,  true,  NONE),
        ("footprint",  40, 30, 50, Sum,   Lsr,  false, ENCODER),
    ];
    for (i, &(name, w, h, n, blend, cov_param, with_opacity, bits)) in cases.iter().enumerate() {
        let mut spec = SceneSpec::new(w, h, n, blend);
        spec.cov_param = cov_param;
        spec.with_opacity = with_opacity;
        let records = Records::from_scene(&random_scene(0x5eed + i as u64, spec), bits);
        let mut opts = WriteOptions {
            zstd_level: 3,
            ..WriteOptions::default()
        };
        match i % 3 {
            0 => opts.settings = None,
            1 => {
                opts.settings = Some(format!("seed={i}\nbits={bits:?}"));
                opts.psnr = Some(31.5);
            }
            _ => opts.ancillary.push(RawChunk {
                ty: ChunkType(*b"gTST"),
                data: b"unknown ancillary".to_vec(),
            }),
        }
        seeds.push((name.into(), to_bytes(&records, &opts)?));
    }

    // A regular grid of near-identical Gaussians compresses, so its payloads are zstd.
    let n = 16;
    let grid = Scene {
        weights: gsi::model::WeightRule::PerPixel,
        tone: None,
        width: 64,
        height: 64,
        blend: Blend::Alpha,
        cov_param: CovParam::LogScaleRotation,
        gaussians: GaussianSet {
            positions: (0..n * n)
                .map(|i| [(i % n) as f32 / n as f32, (i / n) as f32 / n as f32])
                .collect(),
            cov: (0..n * n)
                .map(|i| [-4.0, -4.0 - (i % 2) as f32, 0.0])
                .collect(),
            colors: (0..n * n)
                .map(|i| [(i % 4) as f32 / 3.0, 0.5, 1.0 - (i % 2) as f32])
                .collect(),
            opacity: Some(
                (0..n * n)
                    .map(|i| if i % 3 == 0 { 0.5 } else { 1.0 })
                    .collect(),
            ),
        },
    };
    let opts = WriteOptions {
        zstd_level: 3,
        ..WriteOptions::default()
    };
    seeds.push((
        "zstd".into(),
        to_bytes(&Records::from_scene(&grid, BitDepths::default()), &opts)?,
    ));
    // Weights by the column rule (spec §6.3.2) in bands of 32 rows (GCRT), as the encoder
    // writes files now, and of 16 (GCRW), as version 1.4 wrote them: thin Gaussians (σ
    // from 0.05 px) over more than one band of rows.
    use gsi::model::WeightRule::{Columns, Columns32};
    for (name, blend, seed, weights, (h, n)) in [
        ("columns-sum", Sum, 0x5eed_c0, Columns, (36, 40)),
        ("columns-alpha", Alpha, 0x5eed_c1, Columns, (36, 40)),
        ("columns32-sum", Sum, 0x5eed_c2, Columns32, (70, 60)),
        ("columns32-alpha", Alpha, 0x5eed_c3, Columns32, (70, 60)),
    ] {
        let mut spec = SceneSpec::new(40, h, n, blend);
        spec.sigma_px = (0.05, 10.0);
        spec.weights = weights;
        let records = Records::from_scene(&random_scene(seed, spec), DEFAULT);
        seeds.push((name.into(), to_bytes(&records, &WriteOptions::default())?));
    }

    for (i, (name, bytes)) in seeds.iter().enumerate() {
        std::fs::write(parse_dir.join(format!("{name}.gsi")), bytes)?;
        // Output sizes from 1x1 up to 64x64, varied across seeds.
        let size = [(i * 7 % 64) as u8, (i * 13 % 64) as u8];
        std::fs::write(
            decode_dir.join(format!("{name}.bin")),
            [&size[..], bytes].concat(),
        )?;
    }
    let coded_dir = out.join("coded");
    std::fs::create_dir_all(&coded_dir)?;
    for (name, bits) in [("default", DEFAULT), ("odd", ODD), ("wide", WIDE)] {
        let scene = random_scene(
            5,
            SceneSpec {
                cov_param: CovParam::LogScaleRotation,
                ..SceneSpec::new(40, 30, 60, Blend::Sum)
            },
        );
        let mut records = Records::from_scene(&scene, bits);
        records.sort_spatially();
        // The angles shaped as the encoder shapes them (§5.4.5), for method 4's mode 5.
        let shaped = Records::from_scene(
            &scene,
            BitDepths {
                angle_by_shape: true,
                color_by_footprint: false,
                ..bits
            },
        );
        // The colours by footprint (§5.4.6), for method 5, under the sizes the fuzz target
        // draws from the count.
        let sizes: Vec<i32> = (0..records.header.count as i32)
            .map(|i| (i * 7) % 23 - 15)
            .collect();
        let colors = records.to_scene().gaussians.colors;
        let by_footprint = gsi::format::Attribute::footprint_colors(&colors, &sizes, bits.color);
        for (method, attr, a, modes) in [
            (2, "pos", &records.positions, &[3u8, 3][..]),
            (2, "cov", &records.covariance, &[0, 1, 2][..]),
            (2, "col", &records.colors, &[2, 1, 1][..]),
            (3, "pos3", &records.positions, &[3u8, 3][..]),
            (3, "cov3", &records.covariance, &[0, 1, 4][..]),
            (3, "col3", &records.colors, &[2, 1, 1][..]),
            (4, "cov4", &shaped.covariance, &[0, 1, 5][..]),
            (5, "col5", &by_footprint, &[0, 1, 1][..]),
        ] {
            let payload = a
                .to_coded_payload(modes, method, Some(&sizes))
                .expect("valid modes");
            let k = a.components();
            // The top bit chooses method 3, both top bits method 4, and bit 5 with them
            // method 5 (whose low bits 0x23 give three components).
            let top = match method {
                2 => 0,
                3 => 0x80,
                4 => 0xC0,
                _ => 0xE0,
            };
            let low = if method == 5 { 0x23 } else { (k - 1) as u8 };
            let mut input = vec![low | top];
            input.extend((a.count() as u16).to_be_bytes());
            input.extend(a.quantizers.iter().map(|q| q.bits));
            // Modes and stream follow the preamble unchanged.
            input.extend_from_slice(&payload[6 + 9 * k..]);
            std::fs::write(coded_dir.join(format!("{name}-{attr}.bin")), input)?;
        }
    }
    println!("{} seeds in {}", seeds.len(), out.display());
    Ok(())
}
