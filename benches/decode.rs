//! Decoding benchmarks: bytes to model, and model to pixels on the CPU and (when wgpu
//! finds an adapter) the GPU.
//!
//! Scenes come from `gsi::synth::random_scene` at 768×512 with standard deviations of
//! 0.5 to 8 px, which is what fitted sets of that size look like.

use criterion::{criterion_group, criterion_main, Criterion, SamplingMode};
use gsi::format::{read_file, to_bytes, BitDepths, Limits, Records, WriteOptions};
use gsi::model::{Blend, WeightRule};
use gsi::render::{render_into, render_rgb8_into};
use gsi::synth::{random_scene, SceneSpec};
use std::hint::black_box;
use std::time::Duration;

const WIDTH: u32 = 768;
const HEIGHT: u32 = 512;
const COUNTS: [(&str, usize); 2] = [("10k", 10_000), ("100k", 100_000)];

fn parse_dequantize(c: &mut Criterion) {
    let mut group = c.benchmark_group("parse_dequantize");
    group.sample_size(20).warm_up_time(Duration::from_secs(1));
    for (name, n) in COUNTS {
        let scene = random_scene(1, SceneSpec::new(WIDTH, HEIGHT, n, Blend::Sum));
        let records = Records::from_scene(&scene, BitDepths::default());
        let bytes = to_bytes(&records, &WriteOptions::default()).expect("in-memory write");
        group.bench_function(name, |b| {
            b.iter(|| {
                let file = read_file(black_box(&bytes[..]), Limits::default()).expect("valid file");
                file.records.to_scene()
            })
        });
    }
    group.finish();
}

fn render_cpu(c: &mut Criterion) {
    let mut group = c.benchmark_group("render_cpu");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5))
        // One render is milliseconds to a fraction of a second: equal-sized samples
        // keep the total time bounded where linear sampling would not.
        .sampling_mode(SamplingMode::Flat);
    let mut out = vec![0.0f32; (WIDTH * HEIGHT * 3) as usize];
    for blend in [Blend::Sum, Blend::Alpha] {
        for rule in RULES {
            for (name, n) in COUNTS {
                let scene = scene(n, blend, rule);
                group.bench_function(format!("{}/{}/{name}", blend.name(), rule.name()), |b| {
                    b.iter(|| {
                        render_into(black_box(&scene), WIDTH, HEIGHT, &mut out).expect("valid size")
                    })
                });
            }
        }
    }
    group.finish();
}

/// Two weight rules of spec §6.3: files an encoder writes now weigh by columns in bands of
/// 32 rows (`GCRT`), files before 1.4 per pixel.
const RULES: [WeightRule; 2] = [WeightRule::Columns32, WeightRule::PerPixel];

/// A random scene of `n` Gaussians at 768×512 (σ 0.5–8 px) weighed by `rule`.
fn scene(n: usize, blend: Blend, rule: WeightRule) -> gsi::Scene {
    let mut spec = SceneSpec::new(WIDTH, HEIGHT, n, blend);
    spec.weights = rule;
    random_scene(2, spec)
}

/// A 12-MP decode into 8-bit RGB (4240×2832, the size of a phone's photograph) of a
/// 10k-Gaussian scene fitted at 768×512: every Gaussian covers 31 times the pixels.
fn render_cpu_12mp(c: &mut Criterion) {
    let mut group = c.benchmark_group("render_cpu_12mp");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(8))
        .sampling_mode(SamplingMode::Flat);
    let (w, h) = (4240, 2832);
    let mut out = vec![0u8; (w * h * 3) as usize];
    for blend in [Blend::Sum, Blend::Alpha] {
        for rule in RULES {
            let scene = scene(10_000, blend, rule);
            group.bench_function(format!("{}/{}/10k", blend.name(), rule.name()), |b| {
                b.iter(|| render_rgb8_into(black_box(&scene), w, h, &mut out).expect("valid size"))
            });
        }
    }
    group.finish();
}

/// The wgpu renderer, end to end (projection and binning on the CPU, upload, dispatch,
/// read-back), when wgpu finds an adapter. On lavapipe this measures an emulated GPU,
/// not a GPU.
#[cfg(feature = "gpu")]
fn render_gpu(c: &mut Criterion) {
    let gpu = match gsi::gpu::Gpu::new() {
        Ok(g) => g,
        Err(e) => {
            eprintln!("render_gpu skipped: {e}");
            return;
        }
    };
    eprintln!("render_gpu on {}", gpu.adapter());
    let mut group = c.benchmark_group("render_gpu");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5))
        .sampling_mode(SamplingMode::Flat);
    for blend in [Blend::Sum, Blend::Alpha] {
        for (name, n) in [("10k", 10_000), ("70k", 70_000)] {
            let scene = random_scene(2, SceneSpec::new(WIDTH, HEIGHT, n, blend));
            group.bench_function(format!("{}/{name}", blend.name()), |b| {
                b.iter(|| {
                    gpu.render(black_box(&scene), WIDTH, HEIGHT)
                        .expect("renders")
                })
            });
        }
    }
    group.finish();
}

#[cfg(not(feature = "gpu"))]
fn render_gpu(_: &mut Criterion) {}

/// Whole decodes (parse, dequantize, CPU render at the file's size) of the files named in
/// `GSI_BENCH_FILES` (comma-separated; skipped when unset): real fitted files, for
/// instance one written with method 3 and the same codes rewritten in the 1.0 codings by
/// `cargo run --release --example recode`, measured in the same run. Beside them, the
/// same files parsed and dequantized alone (`parse_file`): a random scene's codes are
/// not what a fitted file's range coder reads.
fn decode_files(c: &mut Criterion) {
    let Ok(list) = std::env::var("GSI_BENCH_FILES") else {
        return;
    };
    // Numbered, so that a file may be named twice to alternate runs.
    let files: Vec<(String, Vec<u8>)> = list
        .split(',')
        .enumerate()
        .map(|(i, path)| {
            let bytes = std::fs::read(path).expect("GSI_BENCH_FILES names readable files");
            let name = std::path::Path::new(path).file_name().unwrap_or_default();
            (format!("{i}-{}", name.to_string_lossy()), bytes)
        })
        .collect();
    let mut group = c.benchmark_group("parse_file");
    group.sample_size(30).warm_up_time(Duration::from_secs(1));
    for (name, bytes) in &files {
        group.bench_function(name, |b| {
            b.iter(|| {
                let file = read_file(black_box(&bytes[..]), Limits::default()).expect("valid");
                file.records.to_scene()
            })
        });
    }
    group.finish();
    let mut group = c.benchmark_group("decode_file");
    group
        .sample_size(30)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5))
        .sampling_mode(SamplingMode::Flat);
    for (name, bytes) in &files {
        let h = read_file(&bytes[..], Limits::default())
            .expect("a valid file")
            .records
            .header;
        let mut out = vec![0.0f32; (h.width * h.height * 3) as usize];
        group.bench_function(name, |b| {
            b.iter(|| {
                let file = read_file(black_box(&bytes[..]), Limits::default()).expect("valid");
                render_into(&file.records.to_scene(), h.width, h.height, &mut out).expect("size")
            })
        });
    }
    group.finish();
}

criterion_group!(
    benches,
    parse_dequantize,
    render_cpu,
    render_cpu_12mp,
    render_gpu,
    decode_files
);
criterion_main!(benches);
