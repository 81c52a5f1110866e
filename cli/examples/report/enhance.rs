//! The stage-2 section of BENCHMARKS.md: LOL eval15, each low-light image encoded,
//! enhanced in the container, decoded and scored against its normal-light reference;
//! then the same for the synthetic low-light Kodak set (`lowlight.rs`), the validation
//! set that stage 2's defaults are also judged on.

use crate::{
    auto_gamma_exponent, commit, gamma_curve, images, load, lowlight, machine, mean, median,
    replace_section, README_ROWS,
};
use gsi::enhance::exposure::Aim;
use gsi::enhance::fit::EnhanceOptions;
use gsi::fit::{encode, Budget, EncodeOptions};
use gsi::format::{ChunkedFile, Limits};
use gsi::metrics::{self, Rgb8};
use plotters::prelude::*;
use serde_json::json;
use std::fmt::Write;
use std::path::Path;
use std::time::Instant;

/// Stage-1 size: 1.1 bpp is 21.8× fewer bytes than 8-bit RGB.
pub const BPP: f32 = 1.1;

struct Row {
    image: String,
    gaussians: u32,
    stage1_bytes: usize,
    cr_bytes: f64,
    kept_bytes: usize,
    discarded_bytes: usize,
    encode_s: f64,
    enhance_s: f64,
    /// Mean luma of the working image before and after the enhancement.
    luma: (f32, f32),
    /// The exposure the default fit was pulled towards, as stored in `gENH`.
    target: f32,
    /// With `--exposure auto`: the metered target and the output's mean luma.
    metered_target: f32,
    metered_luma: f32,
    /// The figures with `--exposure auto`.
    metered: [f64; 8],
    /// The figures with `--no-denoise`: the default without its denoising.
    plain: [f64; 8],
    /// The figures with `--tone 1`: the default without its tone curve.
    untoned: [f64; 8],
    /// The figures of the default enhancement of a stage-1 file fitted at the image's own
    /// level (`EncodeOptions::lift_dark` off, as before session 17).
    unlifted: [f64; 8],
    /// PSNR of the stage-1 file against the low image, as stored, and with
    /// `lift_dark` off.
    stage1_psnr: f64,
    unlifted_stage1_psnr: f64,
    /// Mean luma of the reference.
    reference_luma: f64,
    /// psnr, ssim, psnr_gm, ssim_gm, loe, de, eme, niqe
    gsi: [f64; 8],
    /// The same figures with the paper's exposure target, 0.7 (LOL only).
    paper_exposure: Option<[f64; 8]>,
    /// The same figures for auto-gamma on the raw low image (mean grey to 0.5).
    auto_gamma: [f64; 8],
    /// The same figures for the low image itself.
    input: [f64; 8],
}

fn figures(low: &[u8], high: &[u8], out: &[u8], w: u32, h: u32) -> [f64; 8] {
    let rgb = |d| Rgb8::new(w, h, d).expect("sizes match");
    let r = metrics::full_reference(rgb(high), rgb(out)).expect("scores");
    let loe = metrics::loe(rgb(low), rgb(out)).expect("loe");
    let niqe = metrics::niqe(rgb(out)).expect("600x400 holds NIQE patches");
    [r.psnr, r.ssim, r.psnr_gm, r.ssim_gm, loe, r.de, r.eme, niqe]
}

fn auto_gamma(low: &[u8], w: u32, h: u32) -> Vec<u8> {
    gamma_curve(low, auto_gamma_exponent(low, w, h))
}

/// One row of the example figure: input, gsi and reference, RGB8, with their size.
type Example = (Vec<u8>, Vec<u8>, Vec<u8>, u32, u32);

/// Encode, enhance, decode and score every pair of `dir/low` and `dir/high`; with the
/// paper's exposure target too when `paper` is set.
fn run_set(
    dir: &Path,
    opts: &EnhanceOptions,
    paper: bool,
    limit: usize,
) -> (Vec<Row>, Vec<Example>) {
    let mut rows = Vec::new();
    let mut examples = Vec::new();
    for low_path in images(&dir.join("low"), limit) {
        let name = low_path.file_name().unwrap().to_string_lossy().into_owned();
        let (target, low) = load(&low_path);
        let (_, high) = load(&dir.join("high").join(&name));
        let (w, h) = (target.width, target.height);
        let t0 = Instant::now();
        let enc_opts = EncodeOptions {
            budget: Budget::Bpp(BPP),
            ..EncodeOptions::default()
        };
        let e = encode(&target, &enc_opts, gsi::Device::Cpu, &mut |_| {}).expect("encode");
        let encode_s = t0.elapsed().as_secs_f64();
        let unlifted_opts = EncodeOptions {
            lift_dark: false,
            ..enc_opts.clone()
        };
        let unlifted =
            encode(&target, &unlifted_opts, gsi::Device::Cpu, &mut |_| {}).expect("encode");
        let file = ChunkedFile::parse(&e.bytes, Limits::default()).expect("own file parses");
        let t0 = Instant::now();
        let (kept, fitted) = gsi::enhance::enhance(
            &file,
            opts,
            true,
            &Limits::default(),
            gsi::Device::Cpu,
            &mut |_| {},
        )
        .expect("enhance");
        let enhance_s = t0.elapsed().as_secs_f64();
        let discarded = gsi::enhance::apply_from(
            &file,
            &ChunkedFile::parse(&kept, Limits::default()).unwrap(),
            false,
            &Limits::default(),
        )
        .expect("apply");
        let decode = |bytes: &[u8]| {
            let scene = ChunkedFile::parse(bytes, Limits::default())
                .unwrap()
                .file
                .records
                .to_scene();
            gsi::render::render(&scene, w, h).expect("render").to_rgb8()
        };
        let out = decode(&kept);
        // The variants beside the default: the same file, other options, gORC dropped.
        let enhance_quietly = |f: &ChunkedFile, o: &EnhanceOptions| {
            gsi::enhance::enhance(
                f,
                o,
                false,
                &Limits::default(),
                gsi::Device::Cpu,
                &mut |_| {},
            )
            .expect("enhance")
        };
        let variant = |o: &EnhanceOptions| enhance_quietly(&file, o);
        let paper_exposure = paper.then(|| {
            let (bytes, _) = variant(&EnhanceOptions {
                params: gsi::enhance::loss::LossParams {
                    exposure_target: 0.7,
                    ..opts.params
                },
                ..opts.clone()
            });
            figures(&low, &high, &decode(&bytes), w, h)
        });
        let (metered_bytes, metered_fit) = variant(&EnhanceOptions {
            aim: Aim::Metered,
            ..opts.clone()
        });
        let (plain_bytes, _) = variant(&EnhanceOptions {
            denoise: None,
            ..opts.clone()
        });
        let (untoned_bytes, _) = variant(&EnhanceOptions {
            tone: None,
            ..opts.clone()
        });
        let unlifted_file =
            ChunkedFile::parse(&unlifted.bytes, Limits::default()).expect("own file parses");
        let (unlifted_bytes, _) = enhance_quietly(&unlifted_file, opts);
        let px = f64::from(w * h);
        let row = Row {
            plain: figures(&low, &high, &decode(&plain_bytes), w, h),
            untoned: figures(&low, &high, &decode(&untoned_bytes), w, h),
            unlifted: figures(&low, &high, &decode(&unlifted_bytes), w, h),
            stage1_psnr: e.psnr,
            unlifted_stage1_psnr: unlifted.psnr,
            metered_target: metered_fit.record.fit.exposure,
            metered_luma: metered_fit.mean_luma.1,
            metered: figures(&low, &high, &decode(&metered_bytes), w, h),
            image: name.clone(),
            gaussians: e.records.header.count,
            stage1_bytes: e.bytes.len(),
            cr_bytes: 3.0 * px / e.bytes.len() as f64,
            kept_bytes: kept.len(),
            discarded_bytes: discarded.len(),
            encode_s,
            enhance_s,
            luma: fitted.mean_luma,
            target: fitted.record.fit.exposure,
            reference_luma: mean_luma(&high, w, h),
            gsi: figures(&low, &high, &out, w, h),
            paper_exposure,
            auto_gamma: figures(&low, &high, &auto_gamma(&low, w, h), w, h),
            input: figures(&low, &high, &low, w, h),
        };
        eprintln!(
            "{name}: N {} Cr {:.1}x, encode {:.1}s enhance {:.1}s, luma {:.3} -> {:.3}, {:.2} dB SSIM {:.3}; \
             auto {:.3} for {:.3}, {:.2} dB {:.3}; auto-gamma {:.2} dB {:.3}",
            row.gaussians, row.cr_bytes, row.encode_s, row.enhance_s, row.luma.0, row.luma.1,
            row.gsi[0], row.gsi[1], row.metered_luma, row.metered_target, row.metered[0], row.metered[1],
            row.auto_gamma[0], row.auto_gamma[1]
        );
        if examples.len() < 4 {
            examples.push((low.clone(), out, high.clone(), w, h));
        }
        rows.push(row);
    }
    (rows, examples)
}

fn mean_luma(rgb: &[u8], w: u32, h: u32) -> f64 {
    let luma = metrics::luma(Rgb8::new(w, h, rgb).unwrap());
    luma.iter().sum::<f64>() / luma.len() as f64 / 255.0
}

fn rows_json(rows: &[Row]) -> serde_json::Value {
    json!(rows.iter().map(|r| json!({
        "image": r.image, "gaussians": r.gaussians, "stage1_bytes": r.stage1_bytes, "cr_bytes": r.cr_bytes,
        "enhanced_bytes": r.kept_bytes, "enhanced_bytes_discard_original": r.discarded_bytes,
        "encode_s": r.encode_s, "enhance_s": r.enhance_s, "mean_luma": [r.luma.0, r.luma.1],
        "target": r.target, "reference_luma": r.reference_luma,
        "metered_target": r.metered_target, "metered_luma": r.metered_luma, "metered": r.metered,
        "no_denoise": r.plain, "no_tone": r.untoned, "stage1_not_lifted": r.unlifted,
        "stage1_psnr": r.stage1_psnr, "stage1_psnr_not_lifted": r.unlifted_stage1_psnr,
        "psnr": r.gsi[0], "ssim": r.gsi[1], "psnr_gm": r.gsi[2], "ssim_gm": r.gsi[3],
        "loe": r.gsi[4], "de": r.gsi[5], "eme": r.gsi[6], "niqe": r.gsi[7],
        "auto_gamma": r.auto_gamma, "input": r.input, "paper_exposure_0_7": r.paper_exposure,
    })).collect::<Vec<_>>())
}

/// LOL eval15 from `lol` (its `low` and `high`), and, when `kodak` is given, the
/// synthetic low-light set built from it in `target/kodak-lowlight`.
pub fn section(lol: &Path, kodak: Option<&Path>, out_dir: &Path, limit: usize) {
    let stamp = (machine(), commit());
    let opts = EnhanceOptions::default();
    let (rows, examples) = run_set(lol, &opts, true, limit);
    let synthetic = kodak.map(|k| {
        // Derived from Kodak: built where the build goes, never into the repository.
        let dir = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../target/kodak-lowlight"
        ));
        lowlight::make(k, dir);
        run_set(dir, &opts, false, limit).0
    });
    figure(&examples, &out_dir.join("enhance_examples.jpg"));
    plot(&rows, &out_dir.join("enhance_per_image.svg"));
    let doc = json!({
        "machine": stamp.0, "commit": stamp.1, "bpp": BPP,
        "options": format!("{opts:?}"),
        "rows": rows_json(&rows),
        "synthetic_kodak": synthetic.as_deref().map(rows_json),
    });
    std::fs::write(
        out_dir.join("enhance.json"),
        serde_json::to_string_pretty(&doc).unwrap(),
    )
    .expect("write json");
    replace_section(
        "enhance",
        &markdown(&rows, synthetic.as_deref(), &opts, &stamp),
    );
}

/// Mean of figure `k` over `rows`.
fn mean_of(rows: &[Row], k: usize, f: fn(&Row) -> Option<&[f64; 8]>) -> f64 {
    mean(rows.iter().filter_map(f).map(|v| v[k]))
}

/// `| label | psnr | ssim | … |` from the means of `f` over `rows`.
fn measured_row(s: &mut String, rows: &[Row], label: &str, f: fn(&Row) -> Option<&[f64; 8]>) {
    let v: Vec<f64> = (0..8).map(|k| mean_of(rows, k, f)).collect();
    let _ = writeln!(
        s,
        "| {label} | {:.2} | {:.3} | {:.2} | {:.3} | {:.1} | {:.2} | {:.1} | {:.2} |",
        v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]
    );
}

const TABLE_HEAD: &str = "| method | PSNR | SSIM | PSNR-gm | SSIM-gm | LOE | DE | EME | NIQE |\n|---|---|---|---|---|---|---|---|---|";

/// The exposure test of issue 14 for `--exposure auto` (how many outputs landed within
/// `exposure::TOLERANCE` of their metered target), and how far each mode's output mean
/// luma is from the reference's.
fn landing(rows: &[Row]) -> String {
    let tol = gsi::enhance::exposure::TOLERANCE;
    let hit = rows
        .iter()
        .filter(|r| (r.metered_luma - r.metered_target).abs() <= tol)
        .count();
    let worst = rows
        .iter()
        .map(|r| (r.metered_luma - r.metered_target).abs())
        .fold(0f32, f32::max);
    let err = |f: fn(&Row) -> f32| {
        mean(
            rows.iter()
                .map(|r| (f64::from(f(r)) - r.reference_luma).abs()),
        )
    };
    format!(
        "Exposure test (`--exposure auto`): the output's mean luma is within ±{tol} of its metered target \
         on {hit} of {} images (worst miss {worst:.3}). Mean absolute difference between the output's mean \
         luma and the reference's: default {:.3}, `--exposure auto` {:.3}.",
        rows.len(),
        err(|r| r.luma.1),
        err(|r| r.metered_luma)
    )
}

/// Stage 1's fidelity to the low image, with and without fitting it at full scale.
fn stage1_fidelity(rows: &[Row]) -> String {
    let better = rows
        .iter()
        .filter(|r| r.stage1_psnr > r.unlifted_stage1_psnr)
        .count();
    format!(
        "Stage 1's file against the low image: mean PSNR {:.2} dB, {:.2} dB with `lift_dark` off (higher on {better} \
         of {} images).",
        mean(rows.iter().map(|r| r.stage1_psnr)),
        mean(rows.iter().map(|r| r.unlifted_stage1_psnr)),
        rows.len()
    )
}

fn per_image(s: &mut String, rows: &[Row]) {
    let _ = writeln!(
        s,
        "| image | N | Cr (stage 1) | mean luma in → out; reference | auto: target → out, PSNR | enhance s | PSNR | SSIM | PSNR-gm | SSIM-gm | LOE | DE | EME | NIQE | auto-gamma PSNR / SSIM |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        let g = &r.gsi;
        let _ = writeln!(
            s,
            "| {} | {} | {:.1}× | {:.3} → {:.3}; {:.3} | {:.3} → {:.3}, {:.2} | {:.1} | {:.2} | {:.3} | {:.2} | {:.3} | {:.1} | {:.2} | {:.1} | {:.2} | {:.2} / {:.3} |",
            r.image, r.gaussians, r.cr_bytes, r.luma.0, r.luma.1, r.reference_luma,
            r.metered_target, r.metered_luma, r.metered[0], r.enhance_s,
            g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], r.auto_gamma[0], r.auto_gamma[1]
        );
    }
}

fn markdown(
    rows: &[Row],
    synthetic: Option<&[Row]>,
    opts: &EnhanceOptions,
    stamp: &(String, String),
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Stage 2: low-light enhancement in the container (LOL eval15)\n\n\
         Machine: {}. Commit: `{}`. Produced by `cargo run --release --example report -- --enhance-only`.\n\n\
         Each of the {} low-light images is encoded at {BPP} bpp (stage 1, default settings: a dark image is fitted brightened to full scale, `gsi::fit::dark`), enhanced with \
         `gsi enhance` defaults ({} iterations, K = {}, hidden {}, working size {} px, exposure target {}, \
         the paper's loss weights, {}), decoded at 600×400 and scored against `high` with `gsi::metrics` \
         (the conventions of `../shared/data/README.md`; LOE against the low input). \
         Reference rows are that README's, measured on the raw images.\n",
        stamp.0, stamp.1, rows.len(), opts.iterations, opts.experts, opts.hidden, opts.work_side, opts.params.exposure_target,
        match opts.denoise {
            Some(d) => format!(
                "denoised first across neighbouring Gaussians: range {} spreads, strength {}, {} passes",
                d.range_spreads, d.strength, d.passes
            ),
            None => "no denoising".to_owned(),
        } + &match opts.tone {
            Some(t) => format!(
                ", and a tone curve x^{} after the mixture at the same mean luma ({} passes)",
                t.exponent, t.passes
            ),
            None => String::new(),
        }
    );
    let _ = writeln!(s, "{TABLE_HEAD}");
    measured_row(
        &mut s,
        rows,
        &format!("**gsi** (encode {BPP} bpp → enhance → decode)"),
        |r| Some(&r.gsi),
    );
    measured_row(
        &mut s,
        rows,
        "gsi `--no-denoise` (the default without its denoising)",
        |r| Some(&r.plain),
    );
    measured_row(
        &mut s,
        rows,
        "gsi `--tone 1` (the default without its tone curve)",
        |r| Some(&r.untoned),
    );
    measured_row(
        &mut s,
        rows,
        "gsi, stage 1 fitted at the image's own level (`lift_dark` off)",
        |r| Some(&r.unlifted),
    );
    measured_row(
        &mut s,
        rows,
        "gsi `--exposure auto` (metered, reached)",
        |r| Some(&r.metered),
    );
    measured_row(
        &mut s,
        rows,
        "gsi with the paper's exposure target E = 0.7",
        |r| r.paper_exposure.as_ref(),
    );
    measured_row(&mut s, rows, "auto-gamma, measured here", |r| {
        Some(&r.auto_gamma)
    });
    measured_row(&mut s, rows, "input, measured here", |r| Some(&r.input));
    for (name, figures) in README_ROWS {
        let _ = writeln!(s, "| {name}, README | {figures} | – |");
    }
    let _ = writeln!(
        s,
        "\nNIQE (lower is better) is `gsi::metrics::niqe` with LIVE's pristine model (`data/niqe`); the README \
         measured none, so its rows have no NIQE.\n\n{}\n\n{}",
        landing(rows),
        stage1_fidelity(rows)
    );
    let med = |f: fn(&Row) -> f64| median(rows.iter().map(f).collect());
    let _ = writeln!(
        s,
        "\nTimes (median over images): encode {:.1} s, enhance {:.1} s (max {:.1} s). Sizes (median): stage 1 {} bytes \
         (Cr {:.1}× by bytes); enhanced with `gORC` kept {} bytes ({:.1}×), with `--discard-original` {} bytes ({:.1}×).\n",
        med(|r| r.encode_s),
        med(|r| r.enhance_s),
        rows.iter().map(|r| r.enhance_s).fold(0.0, f64::max),
        med(|r| r.stage1_bytes as f64),
        med(|r| r.cr_bytes),
        med(|r| r.kept_bytes as f64),
        med(|r| 720_000.0 / r.kept_bytes as f64),
        med(|r| r.discarded_bytes as f64),
        med(|r| 720_000.0 / r.discarded_bytes as f64),
    );
    let _ = writeln!(
        s,
        "![input / gsi / reference](bench/enhance_examples.jpg)\n\n![per-image PSNR](bench/enhance_per_image.svg)\n"
    );
    per_image(&mut s, rows);
    if let Some(syn) = synthetic {
        let _ = writeln!(
            s,
            "\n### The synthetic low-light Kodak set (validation)\n\n\
             The {} Kodak photographs darkened as a shorter exposure darkens them (linear light times a gain, \
             through the sRGB curve), with the per-channel noise measured on eval15's low images (σ 1.93 / 1.19 / 1.55 \
             8-bit steps for R / G / B) and their spread of mean luma (0.025–0.097), quantized to 8 bits; the \
             originals are the references (`cargo run --release --example lowlight_set`, which also prints the \
             measurements). Stage 2's defaults are judged on this set and eval15 together. Same pipeline and \
             settings as above, decoded at 768×512.\n",
            syn.len()
        );
        let _ = writeln!(s, "{TABLE_HEAD}");
        measured_row(
            &mut s,
            syn,
            &format!("**gsi** (encode {BPP} bpp → enhance → decode)"),
            |r| Some(&r.gsi),
        );
        measured_row(&mut s, syn, "gsi `--no-denoise`", |r| Some(&r.plain));
        measured_row(&mut s, syn, "gsi `--tone 1`", |r| Some(&r.untoned));
        measured_row(
            &mut s,
            syn,
            "gsi, stage 1 fitted at the image's own level (`lift_dark` off)",
            |r| Some(&r.unlifted),
        );
        measured_row(
            &mut s,
            syn,
            "gsi `--exposure auto` (metered, reached)",
            |r| Some(&r.metered),
        );
        measured_row(&mut s, syn, "auto-gamma", |r| Some(&r.auto_gamma));
        measured_row(&mut s, syn, "input", |r| Some(&r.input));
        let meds = |f: fn(&Row) -> f64| median(syn.iter().map(f).collect());
        let _ = writeln!(
            s,
            "\n{} {} Enhance time (median) {:.1} s for 768×512 images.\n",
            landing(syn),
            stage1_fidelity(syn),
            meds(|r| r.enhance_s)
        );
        per_image(&mut s, syn);
    }
    let _ = writeln!(s);
    s
}

/// Rows of input | gsi | reference, each at half size.
fn figure(examples: &[Example], path: &Path) {
    let Some(&(_, _, _, w, h)) = examples.first() else {
        return;
    };
    let (tw, th) = (w / 2, h / 2);
    let mut canvas = image::RgbImage::new(3 * tw, th * examples.len() as u32);
    for (row, (low, out, high, w, h)) in examples.iter().enumerate() {
        for (col, img) in [low, out, high].into_iter().enumerate() {
            let full = image::RgbImage::from_raw(*w, *h, img.clone()).expect("sizes");
            let small =
                image::imageops::resize(&full, tw, th, image::imageops::FilterType::Triangle);
            image::imageops::replace(
                &mut canvas,
                &small,
                i64::from(col as u32 * tw),
                i64::from(row as u32 * th),
            );
        }
    }
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 88)
        .encode_image(&canvas)
        .expect("jpeg");
    std::fs::write(path, bytes).expect("write figure");
}

fn plot(rows: &[Row], path: &Path) {
    let root = SVGBackend::new(path, (900, 420)).into_drawing_area();
    root.fill(&WHITE).unwrap();
    let n = rows.len();
    let mut chart = ChartBuilder::on(&root)
        .caption("LOL eval15: PSNR per image (dB)", ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(45)
        .build_cartesian_2d(0f64..n as f64, 0f64..30f64)
        .unwrap();
    chart
        .configure_mesh()
        .x_labels(n)
        .x_label_formatter(&|x| {
            rows.get(*x as usize).map_or(String::new(), |r| {
                r.image.trim_end_matches(".png").to_owned()
            })
        })
        .y_desc("PSNR (dB)")
        .draw()
        .unwrap();
    let bars = |k: f64, f: fn(&Row) -> f64, color: RGBColor| {
        rows.iter().enumerate().map(move |(i, r)| {
            let x = i as f64 + 0.1 + 0.4 * k;
            Rectangle::new([(x, 0.0), (x + 0.38, f(r))], color.filled())
        })
    };
    chart
        .draw_series(bars(0.0, |r| r.gsi[0], RGBColor(31, 119, 180)))
        .unwrap()
        .label("gsi (encode → enhance → decode)")
        .legend(|(x, y)| {
            Rectangle::new(
                [(x, y - 5), (x + 10, y + 5)],
                RGBColor(31, 119, 180).filled(),
            )
        });
    chart
        .draw_series(bars(1.0, |r| r.auto_gamma[0], RGBColor(255, 127, 14)))
        .unwrap()
        .label("auto-gamma on the raw image")
        .legend(|(x, y)| {
            Rectangle::new(
                [(x, y - 5), (x + 10, y + 5)],
                RGBColor(255, 127, 14).filled(),
            )
        });
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .unwrap();
    root.present().unwrap();
}
