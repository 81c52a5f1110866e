//! The GPU figures of BENCHMARKS.md (issue 4), for a machine with a GPU:
//!
//! ```sh
//! cargo run --release --example gpu_bench -- [--kodak DIR] [--limit N] [--quick] [--out FILE]
//! ```
//!
//! 1. Draw rate: Kodak images of 768×512 fitted on the GPU with 10k and 70k Gaussians,
//!    then drawn resident ([`gsi::gpu::GpuScene`]: projection, binning and render on the
//!    GPU per frame, nothing read back), frames per second: the median of seven runs of
//!    500 frames (one run of 0.1 s moved by a third between runs on a shared machine),
//!    with the submitting thread's CPU time per frame and the rate of the scene's first
//!    64 Gaussians alone (the floor a frame has whatever it draws: submission and a
//!    chain of dependent dispatches); beside it, `Gpu::render` per call (CPU projection,
//!    upload, render, read-back), which is what `gsi decode --device gpu` does once.
//! 2. Time to quality: every Kodak image (or `--limit N`) encoded on the GPU with 9000
//!    Gaussians at increasing iteration counts; wall time and the PSNR of the stored
//!    (quantized) file, so the first count whose mean reaches 32 dB gives the time to
//!    32 dB.
//!
//! On a software adapter (lavapipe) it still runs, and says that its timings are not GPU
//! figures. `--quick` shrinks everything to check that the tool works.

use gsi::fit::{encode, Budget, EncodeOptions, Target};
use gsi::gpu::{Gpu, GpuScene};
use gsi::Device;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn main() {
    let shared = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).join("../shared/data/kodak");
    let (mut kodak, mut limit, mut quick, mut out) =
        (shared, usize::MAX, false, PathBuf::from("bench/gpu.json"));
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let mut value = || {
            args.next()
                .unwrap_or_else(|| panic!("{flag} needs a value"))
        };
        match flag.as_str() {
            "--kodak" => kodak = value().into(),
            "--limit" => limit = value().parse().expect("--limit takes a number"),
            "--out" => out = value().into(),
            "--quick" => quick = true,
            other => panic!("unknown argument {other}"),
        }
    }
    let gpu = Gpu::new().unwrap_or_else(|e| panic!("no GPU: {e}"));
    let adapter = gpu.adapter();
    let software = adapter.contains("Cpu");
    println!("adapter: {adapter}");
    if software {
        println!("(a software adapter: these timings are not GPU figures)");
    }
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&kodak)
        .unwrap_or_else(|e| panic!("{}: {e}", kodak.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    paths.sort();
    paths.truncate(if quick { 1 } else { limit });

    // 1. Draw rate at 768×512.
    let landscape = paths
        .iter()
        .map(|p| load(p))
        .find(|t| (t.width, t.height) == (768, 512))
        .expect("a 768×512 image");
    let sizes: &[usize] = if quick { &[2_000] } else { &[10_000, 70_000] };
    let (frames, runs) = if quick { (5, 1) } else { (500, 7) };
    let mut draw = Vec::new();
    for &n in sizes {
        let opts = EncodeOptions {
            budget: Budget::Gaussians(n),
            iterations: if quick { 20 } else { 300 },
            ..EncodeOptions::default()
        };
        let encoded = encode(&landscape, &opts, Device::Gpu(&gpu), &mut |_| {}).expect("fit");
        let scene = encoded.records.to_scene();
        let resident = GpuScene::new(&gpu, &scene, 768, 512).expect("upload");
        resident.draw(frames / 10 + 1).expect("GPU");
        resident.wait().expect("GPU");
        let (fps, submit_us, spread) = draw_rate(&resident, frames, runs);
        // The same frames with the first 64 Gaussians alone: what a frame costs whatever
        // the scene (submission, a dozen dispatches and their barriers).
        let floor = GpuScene::new(&gpu, &first(&scene, 64), 768, 512).expect("upload");
        floor.draw(frames / 10 + 1).expect("GPU");
        floor.wait().expect("GPU");
        let (floor_fps, _, _) = draw_rate(&floor, frames, runs);
        let calls = if quick { 2 } else { 50 };
        let t = Instant::now();
        for _ in 0..calls {
            std::hint::black_box(gpu.render(&scene, 768, 512).expect("render"));
        }
        let per_call = t.elapsed().as_secs_f64() / f64::from(calls);
        println!(
            "{} Gaussians at 768x512: {fps:.0} frames/s resident (runs {:.0}-{:.0}; {submit_us:.0} us of CPU to submit a frame; 64 Gaussians: {floor_fps:.0} frames/s); Gpu::render {:.2} ms per call ({:.1} dB file)",
            scene.gaussians.len(),
            spread.0,
            spread.1,
            per_call * 1e3,
            encoded.psnr
        );
        draw.push(json!({
            "gaussians": scene.gaussians.len(),
            "resident_fps": fps,
            "resident_fps_runs_min_max": [spread.0, spread.1],
            "submit_cpu_us_per_frame": submit_us,
            "fps_first_64_gaussians": floor_fps,
            "render_call_ms": per_call * 1e3,
            "frames": frames,
            "runs": runs,
        }));
    }

    // 2. Time to quality at N = 9000.
    let counts: &[u32] = if quick {
        &[10, 20]
    } else {
        &[100, 200, 400, 800, 1600]
    };
    let n = if quick { 500 } else { 9000 };
    let targets: Vec<Target> = paths.iter().map(|p| load(p)).collect();
    let mut curve = Vec::new();
    for &iterations in counts {
        let opts = EncodeOptions {
            budget: Budget::Gaussians(n),
            iterations,
            ..EncodeOptions::default()
        };
        let (mut seconds, mut psnr) = (Vec::new(), Vec::new());
        for t in &targets {
            let start = Instant::now();
            let e = encode(t, &opts, Device::Gpu(&gpu), &mut |_| {}).expect("fit");
            seconds.push(start.elapsed().as_secs_f64());
            psnr.push(e.psnr);
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let mut sorted = seconds.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        println!(
            "N {n}, {iterations} iterations: mean {:.2} dB, mean {:.2} s, median {median:.2} s ({} images)",
            mean(&psnr),
            mean(&seconds),
            targets.len()
        );
        curve.push(json!({
            "iterations": iterations,
            "mean_psnr": mean(&psnr),
            "mean_seconds": mean(&seconds),
            "median_seconds": median,
            "psnr": psnr,
            "seconds": seconds,
        }));
    }
    let report = json!({
        "adapter": adapter,
        "software_adapter": software,
        "commit": commit(),
        "draw_768x512": draw,
        "time_to_quality": { "gaussians": n, "images": targets.len(), "runs": curve },
    });
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).expect("output folder");
    }
    std::fs::write(&out, serde_json::to_string_pretty(&report).unwrap()).expect("write");
    println!("wrote {}", out.display());
}

fn load(path: &Path) -> Target {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    let (width, height) = img.dimensions();
    Target {
        width,
        height,
        data: img
            .into_raw()
            .iter()
            .map(|&v| f32::from(v) / 255.0)
            .collect(),
    }
}

/// `GSI_COMMIT` where the kit set it (the commit it was built from: a device machine's
/// copy of the tree may carry an older `.git`), else what git says here.
fn commit() -> String {
    if let Ok(c) = std::env::var("GSI_COMMIT") {
        return c;
    }
    std::process::Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

/// Frames per second drawing `frames` frames resident, the median of `runs` runs, with
/// the CPU time the submitting thread spent per frame in microseconds (median; Linux's
/// per-thread accounting, 0 elsewhere) and the slowest and fastest run's rate.
fn draw_rate(scene: &GpuScene, frames: u32, runs: usize) -> (f64, f64, (f64, f64)) {
    let (mut fps, mut cpu_us) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let cpu = thread_cpu_ns();
        let t = Instant::now();
        scene.draw(frames).expect("GPU");
        let submitted = thread_cpu_ns();
        scene.wait().expect("GPU");
        fps.push(f64::from(frames) / t.elapsed().as_secs_f64());
        cpu_us.push((submitted - cpu) as f64 / 1e3 / f64::from(frames));
    }
    let spread = (
        fps.iter().copied().fold(f64::INFINITY, f64::min),
        fps.iter().copied().fold(0.0, f64::max),
    );
    (median(&mut fps), median(&mut cpu_us), spread)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Nanoseconds this thread has run, from `/proc/thread-self/schedstat`.
fn thread_cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

/// The scene with its first `n` Gaussians alone.
fn first(scene: &gsi::model::Scene, n: usize) -> gsi::model::Scene {
    let mut s = scene.clone();
    let g = &mut s.gaussians;
    g.positions.truncate(n);
    g.cov.truncate(n);
    g.colors.truncate(n);
    if let Some(o) = &mut g.opacity {
        o.truncate(n);
    }
    s
}
