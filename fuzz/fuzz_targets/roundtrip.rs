//! Arbitrary Gaussian sets, non-finite floats included, through quantization, the
//! encoder and the decoder, with the 1.0 codings and with methods 3 and 4 after the
//! encoder's curve order (colours by footprint in method 5 either way): the records read
//! back are exactly the records written.

#![no_main]

use arbitrary::Arbitrary;
use gsi::format::{read_file, to_bytes, write_file, BitDepths, Limits, Records, WriteOptions};
use gsi::model::{Blend, CovParam, GaussianSet, Scene};
use libfuzzer_sys::fuzz_target;

const MAX_GAUSSIANS: usize = 512;
const MAX_SIDE: u32 = 4096;

#[derive(Arbitrary, Clone, Copy, Debug)]
struct Gaussian {
    position: [f32; 2],
    cov: [f32; 3],
    color: [f32; 3],
    opacity: f32,
}

#[derive(Arbitrary, Debug)]
struct Input {
    width: u16,
    height: u16,
    alpha: bool,
    log_scale_rotation: bool,
    /// Angles at the precision of their shape (§5.4.5), where the covariance is
    /// `log-scale-rotation`.
    angle_by_shape: bool,
    /// Colours at the precision of their footprint (§5.4.6), where the covariance is
    /// `log-scale-rotation`.
    color_by_footprint: bool,
    with_opacity: bool,
    /// Taken modulo 25: 0..=24 bits for position, covariance, colour and opacity.
    bits: [u8; 4],
    /// Further Gaussians cycled from `gaussians`, their positions shifted by multiples
    /// of `step`: reaches hundreds of records (and compressible payloads) from short inputs.
    extra: u16,
    step: f32,
    gaussians: Vec<Gaussian>,
}

fuzz_target!(|input: Input| {
    let side = |v: u16| u32::from(v) % MAX_SIDE + 1;
    let given = &input.gaussians[..input.gaussians.len().min(MAX_GAUSSIANS)];
    let n = if given.is_empty() {
        0
    } else {
        (given.len() + usize::from(input.extra)).min(MAX_GAUSSIANS)
    };
    let gs: Vec<Gaussian> = (0..n)
        .map(|k| {
            let g = &given[k % given.len()];
            let shift = (k / given.len()) as f32 * input.step;
            Gaussian {
                position: g.position.map(|p| p + shift),
                ..*g
            }
        })
        .collect();
    let scene = Scene {
        weights: gsi::model::WeightRule::PerPixel,
        tone: None,
        width: side(input.width),
        height: side(input.height),
        blend: if input.alpha {
            Blend::Alpha
        } else {
            Blend::Sum
        },
        cov_param: if input.log_scale_rotation {
            CovParam::LogScaleRotation
        } else {
            CovParam::Cholesky
        },
        gaussians: GaussianSet {
            positions: gs.iter().map(|g| g.position).collect(),
            cov: gs.iter().map(|g| g.cov).collect(),
            colors: gs.iter().map(|g| g.color).collect(),
            opacity: input
                .with_opacity
                .then(|| gs.iter().map(|g| g.opacity).collect()),
        },
    };
    let [position, covariance, color, opacity] = input.bits.map(|b| b % 25);
    let records = Records::from_scene(
        &scene,
        BitDepths {
            position,
            covariance,
            angle: covariance,
            angle_by_shape: input.angle_by_shape,
            color_by_footprint: input.color_by_footprint,
            color,
            opacity,
        },
    );
    assert!(records.is_consistent());

    let opts = WriteOptions::default();
    let bytes = to_bytes(&records, &opts).expect("in-memory write of valid records");
    let mut sink = Vec::new();
    let reported = write_file(&mut sink, &records, &opts).expect("second write");
    assert_eq!(sink, bytes, "writing is not deterministic");
    assert_eq!(
        reported,
        bytes.len() as u64,
        "write_file reports a size other than what it wrote"
    );

    let file =
        read_file(&bytes[..], Limits::default()).expect("reading back a freshly written file");
    // The 1.0 codings keep the codes, not the shape offset that method 4 would code them by;
    // colours by footprint are written in method 5 whatever the options, as version 1.8.
    let mut plain = records.clone();
    plain.covariance.shape = None;
    if plain.colors.footprint.is_some() {
        plain.header.version_minor = plain
            .header
            .version_minor
            .max(gsi::format::VERSION_MINOR_FOOTPRINT);
    }
    assert_eq!(file.records, plain, "records change through write and read");
    assert_eq!(
        file.file_bytes,
        bytes.len() as u64,
        "decoder counts a different file size"
    );
    let meta = file.metadata.expect("default options write gCRM");
    assert_eq!(
        meta.file_bytes,
        bytes.len() as u64,
        "gCRM states a different file size"
    );

    // Dequantized values are finite whatever went in (NaN and ±inf included).
    let back = file.records.to_scene();
    assert!(back.gaussians.all_finite());
    // Colours by footprint exactly where asked for and possible, in method 5 (1.8).
    let by_footprint = input.color_by_footprint && input.log_scale_rotation;
    assert_eq!(file.records.colors.footprint.is_some(), by_footprint);
    if by_footprint {
        assert!(file.records.header.version_minor >= gsi::format::VERSION_MINOR_FOOTPRINT);
    }

    // The encoder's way: curve order (for `sum`), method 3 where it is smaller (4 where the
    // angles are shaped and that is smaller), version 1.6 (1.7) exactly when some payload
    // uses it; the same codes come back, and the shape offset where method 4 coded them.
    let mut sorted = records.clone();
    sorted.sort_spatially();
    let coded = WriteOptions {
        context_coding: true,
        ..WriteOptions::default()
    };
    let bytes = to_bytes(&sorted, &coded).expect("in-memory write with method 3");
    let file = read_file(&bytes[..], Limits::default()).expect("reading back method 3");
    // The minor the payloads' methods need (§2.5): each payload as the writer makes it.
    let level = coded.zstd_level;
    let minor = [&sorted.positions, &sorted.covariance, &sorted.colors]
        .into_iter()
        .chain(sorted.opacity.as_ref())
        .map(|a| {
            let p = sorted
                .attribute_payload(a, level, true)
                .expect("in-memory payload");
            gsi::format::minor_for_method(p[1 + 9 * a.components()])
        })
        .max()
        .unwrap_or(0)
        .max(sorted.header.version_minor);
    assert_eq!(
        file.records.header.version_minor, minor,
        "the minor version against the payloads' methods"
    );
    let cov = sorted
        .covariance
        .to_payload_with(level, true)
        .expect("in-memory payload");
    let mut expected = sorted;
    expected.header.version_minor = minor;
    if cov[1 + 9 * 3] != gsi::format::METHOD_SHAPED {
        expected.covariance.shape = None;
    }
    assert_eq!(file.records, expected, "records change through method 3");
});
