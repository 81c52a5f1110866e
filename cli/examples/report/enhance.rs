//! The stage-2 section of BENCHMARKS.md: every low-light image of the validation sets
//! (LOL `val30`, the synthetic dark Kodak set, `mef13`) and of LOL eval15 encoded,
//! enhanced in the container with the defaults and with each default turned off,
//! decoded and scored; contact sheets in `DIR/enhance/`.

use crate::metrics_table::{auto_gamma_exponent, gamma_curve, gamma_for_mean, README_ROWS};
use crate::{commit, images, load, lowlight, machine, mean, median, replace_section};
use gsi::enhance::curve::CurveOptions;
use gsi::enhance::exposure::Exposure;
use gsi::enhance::fit::EnhanceOptions;
use gsi::enhance::{Enhanced, Outcome};
use gsi::fit::{encode, Budget, EncodeOptions};
use gsi::format::{ChunkedFile, Limits};
use gsi::metrics::{self, Rgb8};
use serde_json::json;
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Stage-1 size: 1.1 bpp is 21.8× fewer bytes than 8-bit RGB.
pub const BPP: f32 = 1.1;

/// What each output is scored by.
#[derive(Clone, Copy, Debug, Default)]
struct Scores {
    /// PSNR, SSIM, and both after scaling to the reference's mean luma (with a reference).
    psnr: Option<f64>,
    ssim: Option<f64>,
    psnr_gm: Option<f64>,
    ssim_gm: Option<f64>,
    /// Mean CIELAB a*, b* minus the reference's (with a reference).
    cast: Option<[f64; 2]>,
    /// Luma standard deviation on the reference's flat 16-pixel blocks, median.
    flat_noise: Option<f64>,
    loe: f64,
    niqe: Option<f64>,
    /// Mean display luma, and the share of pixels with a channel at 250 or above.
    luma: f64,
    clipped: f64,
}

fn score(low: &[u8], reference: Option<&[u8]>, out: &[u8], w: u32, h: u32) -> Scores {
    let rgb = |d| Rgb8::new(w, h, d).expect("sizes match");
    let full = reference.map(|r| metrics::full_reference(rgb(r), rgb(out)).expect("scores"));
    Scores {
        psnr: full.as_ref().map(|f| f.psnr),
        ssim: full.as_ref().map(|f| f.ssim),
        psnr_gm: full.as_ref().map(|f| f.psnr_gm),
        ssim_gm: full.as_ref().map(|f| f.ssim_gm),
        cast: reference.map(|r| metrics::color_cast(rgb(r), rgb(out)).expect("cast")),
        flat_noise: reference.and_then(|r| metrics::flat_noise(rgb(r), rgb(out)).expect("noise")),
        loe: metrics::loe(rgb(low), rgb(out)).expect("loe"),
        niqe: metrics::niqe(rgb(out)).ok(),
        luma: mean_luma(out, w, h),
        clipped: metrics::clipped_share(rgb(out)),
    }
}

/// Auto-gamma on rendered values (clamped to `[0, 1]`): the power that brings their mean
/// BT.601 luma to 0.5, then 8 bits as a decoder rounds (`gsi::render::to_u8`). Applied
/// after the rounding instead, the power turns each 8-bit step of the shadows into
/// several, a grain that NIQE reads as natural texture.
fn gamma_curve_f32(rgb: &[f32]) -> Vec<u8> {
    let v = |c: f32| f64::from(c.clamp(0.0, 1.0));
    let mean = f64::from(gsi::enhance::working::mean_luma(rgb));
    let g = gamma_for_mean(mean.clamp(1e-6, 1.0 - 1e-6));
    rgb.iter()
        .map(|&c| gsi::render::to_u8(v(c).powf(g) as f32))
        .collect()
}

fn mean_luma(rgb: &[u8], w: u32, h: u32) -> f64 {
    let luma = metrics::luma(Rgb8::new(w, h, rgb).unwrap());
    luma.iter().sum::<f64>() / luma.len() as f64 / 255.0
}

/// Each default turned the other way in turn, and the metered exposure.
const VARIANTS: [&str; 6] = [
    "`--tone 1` (no power curve: the exposure only)",
    "`--no-local` (no gain map)",
    "`--keep-shadow-colour` (no chroma map)",
    "`--keep-speckle` (Gaussians within the noise kept)",
    "`--denoise` (denoised first)",
    "`--exposure auto` (metered)",
];

fn variant_options(k: usize, d: &EnhanceOptions) -> EnhanceOptions {
    let curve = d.curve.unwrap_or_default();
    match k {
        0 => EnhanceOptions {
            curve: Some(CurveOptions {
                exponent: 1.0,
                ..curve
            }),
            ..d.clone()
        },
        1 => EnhanceOptions {
            curve: Some(CurveOptions {
                local: false,
                ..curve
            }),
            ..d.clone()
        },
        2 => EnhanceOptions {
            curve: Some(CurveOptions {
                chroma: false,
                ..curve
            }),
            ..d.clone()
        },
        3 => EnhanceOptions {
            speckle: false,
            ..d.clone()
        },
        4 => EnhanceOptions {
            denoise: Some(gsi::enhance::denoise::DenoiseOptions::default()),
            ..d.clone()
        },
        _ => EnhanceOptions {
            exposure: Exposure::Metered,
            ..d.clone()
        },
    }
}

struct Row {
    image: String,
    size: (u32, u32),
    gaussians: u32,
    stage1_bytes: usize,
    /// Enhanced, with `gORC` kept and discarded (the stage-1 size where left unchanged).
    kept_bytes: usize,
    discarded_bytes: usize,
    encode_s: f64,
    enhance_s: f64,
    dark_share: f32,
    enhanced: bool,
    capped: bool,
    beta: Option<f32>,
    input: Scores,
    gsi: Scores,
    variants: Vec<Scores>,
    /// Auto-gamma (mean luma to 0.5) on the raw low image and on the decoded stage-1 file.
    auto_gamma: Scores,
    auto_gamma_stage1: Scores,
    /// Auto-gamma on the stage-1 render before its rounding to 8 bits: on the values the
    /// container's own curve acts on.
    auto_gamma_stage1_float: Scores,
    reference_luma: Option<f64>,
    /// For the contact sheets: input, output, reference.
    pictures: (Vec<u8>, Vec<u8>, Option<Vec<u8>>),
}

/// Encode, enhance (defaults and variants), decode and score every image of `low`, with
/// the reference of the same name in `high` where given.
fn run_set(low: &Path, high: Option<&Path>, limit: usize) -> Vec<Row> {
    let opts = EnhanceOptions::default();
    let lim = Limits::default();
    let mut rows = Vec::new();
    for low_path in images(low, limit) {
        let name = low_path.file_name().unwrap().to_string_lossy().into_owned();
        let (target, low_rgb) = load(&low_path);
        let reference = high.map(|d| load(&d.join(&name)).1);
        let (w, h) = (target.width, target.height);
        let t0 = Instant::now();
        let enc_opts = EncodeOptions {
            budget: Budget::Bpp(BPP),
            ..EncodeOptions::default()
        };
        let e = encode(&target, &enc_opts, gsi::Device::Cpu, &mut |_| {}).expect("encode");
        let encode_s = t0.elapsed().as_secs_f64();
        let file = ChunkedFile::parse(&e.bytes, lim).expect("own file parses");
        let render = |bytes: &[u8]| {
            let scene = ChunkedFile::parse(bytes, lim)
                .unwrap()
                .file
                .records
                .to_scene();
            gsi::render::render(&scene, w, h).expect("render")
        };
        let decode = |bytes: &[u8]| render(bytes).to_rgb8();
        let run = |o: &EnhanceOptions| -> Option<Enhanced> {
            match gsi::enhance::enhance(&file, o, true, &lim, gsi::Device::Cpu, &mut |_| {})
                .expect("enhance")
            {
                Outcome::Enhanced(done) => Some(*done),
                _ => None,
            }
        };
        let t0 = Instant::now();
        let done = run(&opts);
        let enhance_s = t0.elapsed().as_secs_f64();
        let stage1_render = render(&e.bytes);
        let stage1 = stage1_render.to_rgb8();
        let sc = |out: &[u8]| score(&low_rgb, reference.as_deref(), out, w, h);
        let (out, kept_bytes, discarded_bytes) = match &done {
            Some(d) => {
                let discarded = gsi::enhance::apply_from(
                    &file,
                    &ChunkedFile::parse(&d.bytes, lim).unwrap(),
                    false,
                    &lim,
                )
                .expect("apply");
                (decode(&d.bytes), d.bytes.len(), discarded.len())
            }
            None => (stage1.clone(), e.bytes.len(), e.bytes.len()),
        };
        let variants = (0..VARIANTS.len())
            .map(|k| {
                let v = run(&variant_options(k, &opts));
                sc(&v.map_or_else(|| stage1.clone(), |v| decode(&v.bytes)))
            })
            .collect();
        let plan = done.as_ref().and_then(|d| d.plan.as_ref());
        let assessment =
            gsi::enhance::assess::assess(&file.file.records.to_scene(), opts.work_side);
        let row = Row {
            image: name.clone(),
            size: (w, h),
            gaussians: e.records.header.count,
            stage1_bytes: e.bytes.len(),
            kept_bytes,
            discarded_bytes,
            encode_s,
            enhance_s,
            dark_share: assessment.dark_share,
            enhanced: done.is_some(),
            capped: plan.is_some_and(|p| p.capped),
            beta: plan.and_then(|p| p.gain.as_ref().map(|_| p.beta)),
            input: sc(&low_rgb),
            gsi: sc(&out),
            variants,
            auto_gamma: sc(&gamma_curve(&low_rgb, auto_gamma_exponent(&low_rgb, w, h))),
            auto_gamma_stage1: sc(&gamma_curve(&stage1, auto_gamma_exponent(&stage1, w, h))),
            auto_gamma_stage1_float: sc(&gamma_curve_f32(&stage1_render.data)),
            reference_luma: reference.as_ref().map(|r| mean_luma(r, w, h)),
            pictures: (low_rgb, out, reference),
        };
        eprintln!(
            "{name}: N {} {:.0}% dark{} encode {:.1}s enhance {:.1}s luma {:.3} -> {:.3}{}",
            row.gaussians,
            100.0 * row.dark_share,
            if row.enhanced { "" } else { " (unchanged)" },
            row.encode_s,
            row.enhance_s,
            row.input.luma,
            row.gsi.luma,
            row.gsi.psnr.map_or(String::new(), |p| format!(
                ", {p:.2} dB {:.3}",
                row.gsi.ssim.unwrap()
            ))
        );
        rows.push(row);
    }
    rows
}

fn scores_json(s: &Scores) -> serde_json::Value {
    json!({
        "psnr": s.psnr, "ssim": s.ssim, "psnr_gm": s.psnr_gm, "ssim_gm": s.ssim_gm,
        "cast_ab": s.cast, "flat_noise": s.flat_noise, "loe": s.loe, "niqe": s.niqe,
        "mean_luma": s.luma, "clipped": s.clipped,
    })
}

fn rows_json(rows: &[Row]) -> serde_json::Value {
    json!(rows
        .iter()
        .map(|r| json!({
            "image": r.image, "gaussians": r.gaussians, "stage1_bytes": r.stage1_bytes,
            "enhanced_bytes": r.kept_bytes, "enhanced_bytes_discard_original": r.discarded_bytes,
            "encode_s": r.encode_s, "enhance_s": r.enhance_s, "under_exposed": r.dark_share,
            "enhanced": r.enhanced, "capped": r.capped, "gain_map_beta": r.beta,
            "reference_luma": r.reference_luma,
            "gsi": scores_json(&r.gsi), "input": scores_json(&r.input),
            "auto_gamma": scores_json(&r.auto_gamma),
            "auto_gamma_stage1": scores_json(&r.auto_gamma_stage1),
            "auto_gamma_stage1_float": scores_json(&r.auto_gamma_stage1_float),
            "variants": VARIANTS.iter().zip(&r.variants)
                .map(|(n, s)| (n.to_string(), scores_json(s))).collect::<serde_json::Map<_, _>>(),
        }))
        .collect::<Vec<_>>())
}

/// The validation sets and eval15, from LOL eval15's folder (`LOL/eval15`, beside
/// `LOL/val30` and `../mef13`) and Kodak (for the synthetic set, built in `target/`).
pub fn section(eval15: &Path, kodak: Option<&Path>, out_dir: &Path, limit: usize) {
    let stamp = (machine(), commit());
    let lol = eval15.parent().expect("LOL/eval15 has a parent");
    let data = lol.parent().expect("LOL has a parent");
    let synthetic = kodak.map(|k| {
        // Derived from Kodak: built where the build goes, never into the repository.
        let dir = PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../target/kodak-lowlight"
        ));
        lowlight::make(k, &dir);
        dir
    });
    let pairs = |d: &Path| run_set(&d.join("low"), Some(&d.join("high")), limit);
    let val30 = pairs(&lol.join("val30"));
    let syn = synthetic.as_deref().map(pairs);
    let mef13 = run_set(&data.join("mef13"), None, limit);
    let eval = pairs(eval15);
    let sheets = out_dir.join("enhance");
    std::fs::create_dir_all(&sheets).expect("sheet folder");
    let mut worst: Vec<&Row> = val30.iter().collect();
    worst.sort_by(|a, b| a.gsi.psnr.unwrap().total_cmp(&b.gsi.psnr.unwrap()));
    contact_sheet(
        &worst[..worst.len().min(6)],
        &sheets.join("val30-worst.png"),
    );
    contact_sheet(&mef13.iter().collect::<Vec<_>>(), &sheets.join("mef13.png"));
    let opts = EnhanceOptions::default();
    let doc = json!({
        "machine": stamp.0, "commit": stamp.1, "bpp": BPP,
        "options": format!("{opts:?}"),
        "val30": rows_json(&val30), "eval15": rows_json(&eval),
        "synthetic_kodak": syn.as_deref().map(rows_json), "mef13": rows_json(&mef13),
    });
    std::fs::write(
        out_dir.join("enhance.json"),
        serde_json::to_string_pretty(&doc).unwrap(),
    )
    .expect("write json");
    replace_section(
        "enhance",
        &markdown(&val30, &eval, syn.as_deref(), &mef13, &opts, &stamp),
    );
}

/// Mean of `f` over the rows where it is defined.
fn mean_of(rows: &[Row], f: impl Fn(&Row) -> Option<f64>) -> f64 {
    mean(rows.iter().filter_map(f))
}

/// `| label | PSNR | SSIM | PSNR-gm | SSIM-gm | cast | noise | |Δ luma| | LOE | NIQE |`
/// from the means over `rows` of the scores `f` picks.
fn measured_row(s: &mut String, rows: &[Row], label: &str, f: impl Fn(&Row) -> &Scores) {
    let m = |g: &dyn Fn(&Scores) -> Option<f64>| mean_of(rows, |r| g(f(r)));
    let cast = [
        m(&|x| x.cast.map(|c| c[0])),
        m(&|x| x.cast.map(|c| c[1])),
        m(&|x| x.cast.map(|c| c[0].hypot(c[1]))),
    ];
    let noise = median(rows.iter().filter_map(|r| f(r).flat_noise).collect());
    let luma_err = mean_of(rows, |r| r.reference_luma.map(|l| (f(r).luma - l).abs()));
    let _ = writeln!(
        s,
        "| {label} | {:.2} | {:.3} | {:.2} | {:.3} | {:+.1}, {:+.1} ({:.1}) | {noise:.2} | {luma_err:.3} | {:.0} | {:.2} |",
        m(&|x| x.psnr),
        m(&|x| x.ssim),
        m(&|x| x.psnr_gm),
        m(&|x| x.ssim_gm),
        cast[0],
        cast[1],
        cast[2],
        m(&|x| Some(x.loe)),
        median(rows.iter().filter_map(|r| f(r).niqe).collect()),
    );
}

const TABLE_HEAD: &str = "| method | PSNR | SSIM | PSNR-gm | SSIM-gm | cast Δa*, Δb* (mean \\|Δ\\|) | flat noise | \\|Δ luma\\| | LOE | NIQE (median) |\n|---|---|---|---|---|---|---|---|---|---|";

fn pairs_table(s: &mut String, rows: &[Row]) {
    let _ = writeln!(s, "{TABLE_HEAD}");
    measured_row(
        s,
        rows,
        &format!("**gsi** (encode {BPP} bpp → enhance → decode)"),
        |r| &r.gsi,
    );
    for (k, name) in VARIANTS.iter().enumerate() {
        measured_row(s, rows, &format!("gsi {name}"), |r| &r.variants[k]);
    }
    measured_row(s, rows, "auto-gamma on the raw low image", |r| {
        &r.auto_gamma
    });
    measured_row(s, rows, "auto-gamma on the decoded stage-1 file", |r| {
        &r.auto_gamma_stage1
    });
    measured_row(
        s,
        rows,
        "auto-gamma on the stage-1 render before its rounding",
        |r| &r.auto_gamma_stage1_float,
    );
    measured_row(s, rows, "input", |r| &r.input);
}

fn times_and_sizes(rows: &[Row]) -> String {
    let med = |f: &dyn Fn(&Row) -> f64| median(rows.iter().map(f).collect());
    let cr = |bytes: usize, r: &Row| 3.0 * f64::from(r.size.0 * r.size.1) / bytes as f64;
    format!(
        "Times (median): encode {:.1} s, enhance {:.2} s (max {:.1} s). Sizes (median): stage 1 {} bytes (Cr {:.1}×); \
         enhanced with `gORC` kept {} bytes ({:.1}×), with `--discard-original` {} bytes ({:.1}×, smallest {:.1}×).",
        med(&|r| r.encode_s),
        med(&|r| r.enhance_s),
        rows.iter().map(|r| r.enhance_s).fold(0.0, f64::max),
        med(&|r| r.stage1_bytes as f64),
        med(&|r| cr(r.stage1_bytes, r)),
        med(&|r| r.kept_bytes as f64),
        med(&|r| cr(r.kept_bytes, r)),
        med(&|r| r.discarded_bytes as f64),
        med(&|r| cr(r.discarded_bytes, r)),
        rows.iter().map(|r| cr(r.discarded_bytes, r)).fold(f64::INFINITY, f64::min),
    )
}

fn per_image(s: &mut String, rows: &[Row]) {
    let _ = writeln!(
        s,
        "| image | N | under-exposed | mean luma in → out; reference | PSNR | SSIM | cast Δa*, Δb* | auto-gamma PSNR / SSIM |\n|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        let c = r.gsi.cast.unwrap_or_default();
        let _ = writeln!(
            s,
            "| {} | {} | {:.0}% | {:.3} → {:.3}; {:.3} | {:.2} | {:.3} | {:+.1}, {:+.1} | {:.2} / {:.3} |",
            r.image,
            r.gaussians,
            100.0 * r.dark_share,
            r.input.luma,
            r.gsi.luma,
            r.reference_luma.unwrap_or(f64::NAN),
            r.gsi.psnr.unwrap_or(f64::NAN),
            r.gsi.ssim.unwrap_or(f64::NAN),
            c[0],
            c[1],
            r.auto_gamma.psnr.unwrap_or(f64::NAN),
            r.auto_gamma.ssim.unwrap_or(f64::NAN),
        );
    }
}

fn mef13_table(s: &mut String, rows: &[Row]) {
    let _ = writeln!(
        s,
        "| photograph | under-exposed | enhanced | mean luma in → out | clipped in → out | NIQE out / auto-gamma on stage 1 / the same before rounding |\n|---|---|---|---|---|---|"
    );
    for r in rows {
        let how = match (r.enhanced, r.beta, r.capped) {
            (false, _, _) => "no".to_string(),
            (true, Some(b), _) => format!("yes, gain map β {b:.2}"),
            (true, None, true) => "yes, held back by its highlights".to_string(),
            (true, None, false) => "yes".to_string(),
        };
        let _ = writeln!(
            s,
            "| {} | {:.0}% | {how} | {:.3} → {:.3} | {:.2}% → {:.2}% | {:.2} / {:.2} / {:.2} |",
            r.image,
            100.0 * r.dark_share,
            r.input.luma,
            r.gsi.luma,
            100.0 * r.input.clipped,
            100.0 * r.gsi.clipped,
            r.gsi.niqe.unwrap_or(f64::NAN),
            r.auto_gamma_stage1.niqe.unwrap_or(f64::NAN),
            r.auto_gamma_stage1_float.niqe.unwrap_or(f64::NAN),
        );
    }
    let dark: Vec<&Row> = rows.iter().filter(|r| r.input.luma <= 0.25).collect();
    let lifted = dark.iter().filter(|r| r.gsi.luma >= 0.30).count();
    let worst_clip = rows
        .iter()
        .map(|r| 100.0 * (r.gsi.clipped - r.input.clipped))
        .fold(f64::NEG_INFINITY, f64::max);
    let niqe = |f: &dyn Fn(&Row) -> Option<f64>| median(rows.iter().filter_map(f).collect());
    let enhanced: Vec<&Row> = rows.iter().filter(|r| r.enhanced).collect();
    let niqe_enh =
        |f: &dyn Fn(&Row) -> Option<f64>| median(enhanced.iter().filter_map(|r| f(r)).collect());
    let _ = writeln!(
        s,
        "\nOf the {} photographs with mean luma ≤ 0.25, {lifted} end at 0.30 or more. Clipped pixels rise by at most \
         {worst_clip:.2} points (the input is the original photograph; a photograph left unchanged differs from it \
         by the codec only). Median NIQE: {:.2} for gsi's outputs against {:.2} for auto-gamma applied to the same \
         decoded stage-1 files and {:.2} for auto-gamma on their render before its rounding to 8 bits (the values \
         gsi's curve acts on); over the {} photographs it enhances, {:.2} against {:.2} and {:.2}.",
        dark.len(),
        niqe(&|r| r.gsi.niqe),
        niqe(&|r| r.auto_gamma_stage1.niqe),
        niqe(&|r| r.auto_gamma_stage1_float.niqe),
        enhanced.len(),
        niqe_enh(&|r| r.gsi.niqe),
        niqe_enh(&|r| r.auto_gamma_stage1.niqe),
        niqe_enh(&|r| r.auto_gamma_stage1_float.niqe),
    );
}

fn markdown(
    val30: &[Row],
    eval15: &[Row],
    syn: Option<&[Row]>,
    mef13: &[Row],
    opts: &EnhanceOptions,
    stamp: &(String, String),
) -> String {
    let mut s = String::new();
    let curve = opts.curve.unwrap_or_default();
    let _ = writeln!(
        s,
        "## Stage 2: low-light enhancement in the container\n\n\
         Machine: {}. Commit: `{}`. Produced by `cargo run --release --example report -- --enhance-only`.\n\n\
         Each low-light image is encoded at {BPP} bpp (stage 1 defaults), enhanced with the `gsi enhance` defaults \
         and decoded at its own size. The defaults: the low-light decision (a quarter of the image lit below 0.2), \
         {}{}, the mixture ({} iterations, K = {}, working size {} px), then the tone curve `S(a·x^{})` on the blended \
         values at mean luma {} (middle grey), its scale capped by the scene's highlights, a gain map that lifts \
         the shadows where the cap holds the curve back, and a chroma map that moves the colour of regions lit \
         within the noise of black towards grey. Scored with `gsi::metrics` (`../shared/data/README.md`'s \
         conventions; cast: mean CIELAB a*, b* minus the reference's; flat noise: median luma deviation, 8-bit \
         steps, on the reference's flat 16-pixel blocks; LOE against the low input). Defaults were chosen on `val30`, \
         the synthetic set and `mef13`; eval15 is reported, not tuned on.\n",
        stamp.0,
        stamp.1,
        if opts.speckle {
            "the Gaussians within three noise levels of their footprint's precision removed (`sum` files), "
        } else {
            ""
        },
        match opts.denoise {
            Some(d) => format!(
                "denoising across neighbouring Gaussians (range {} spreads, {} pass)",
                d.range_spreads, d.passes
            ),
            None => "no denoising".to_owned(),
        },
        opts.iterations,
        opts.experts,
        opts.work_side,
        curve.exponent,
        gsi::enhance::curve::MID_GREY,
    );
    let _ = writeln!(s, "### LOL `val30` (validation, {} pairs)\n", val30.len());
    pairs_table(&mut s, val30);
    let _ = writeln!(s, "\n{}\n", times_and_sizes(val30));
    if let Some(syn) = syn {
        let _ = writeln!(
            s,
            "### The synthetic dark Kodak set (validation, {} images)\n\n\
             Kodak darkened in linear light with the noise measured on LOL's low images (`cargo run --release \
             --example lowlight_set`); the originals are the references.\n",
            syn.len()
        );
        pairs_table(&mut s, syn);
        let _ = writeln!(s, "\n{}\n", times_and_sizes(syn));
    }
    let _ = writeln!(
        s,
        "### `mef13` (validation, no references: photographs lit unevenly)\n"
    );
    mef13_table(&mut s, mef13);
    let _ = writeln!(
        s,
        "\n{}\n\n![input / gsi, mef13](bench/enhance/mef13.png)\n",
        times_and_sizes(mef13)
    );
    let _ = writeln!(s, "### LOL eval15 (reported, not tuned on)\n");
    pairs_table(&mut s, eval15);
    for (name, figures) in README_ROWS {
        // PSNR | SSIM | PSNR-gm | SSIM-gm | LOE | DE | EME, as that README gives them.
        let f: Vec<&str> = figures.split('|').map(str::trim).collect();
        let _ = writeln!(
            s,
            "| {name}, README | {} | {} | {} | {} | – | – | – | {} | – |",
            f[0], f[1], f[2], f[3], f[4]
        );
    }
    let _ = writeln!(s, "\n{}\n", times_and_sizes(eval15));
    per_image(&mut s, eval15);
    let _ = writeln!(
        s,
        "\nThe six `val30` pairs gsi scores lowest (input / gsi / reference):\n\n\
         ![input / gsi / reference, val30](bench/enhance/val30-worst.png)\n"
    );
    per_image(&mut s, val30);
    let _ = writeln!(s);
    s
}

/// A PNG of each row's input, output and reference (where there is one), at most 240
/// pixels high.
fn contact_sheet(rows: &[&Row], path: &Path) {
    let tile = |rgb: &[u8], (w, h): (u32, u32)| {
        let img = image::RgbImage::from_raw(w, h, rgb.to_vec()).expect("sizes");
        let th = h.min(240);
        let tw = (f64::from(w) * f64::from(th) / f64::from(h)).round() as u32;
        image::imageops::resize(&img, tw, th, image::imageops::FilterType::Triangle)
    };
    let tiles: Vec<Vec<image::RgbImage>> = rows
        .iter()
        .map(|r| {
            let (low, out, reference) = &r.pictures;
            std::iter::once(low)
                .chain(std::iter::once(out))
                .chain(reference.iter())
                .map(|p| tile(p, r.size))
                .collect()
        })
        .collect();
    let gap = 4;
    let width = tiles
        .iter()
        .map(|t| t.iter().map(|i| i.width() + gap).sum::<u32>())
        .max()
        .unwrap_or(1);
    let height: u32 = tiles
        .iter()
        .map(|t| t[0].height() + gap)
        .sum::<u32>()
        .max(1);
    let mut canvas = image::RgbImage::from_pixel(width, height, image::Rgb([255, 255, 255]));
    let mut y = 0;
    for row in &tiles {
        let mut x = 0;
        for t in row {
            image::imageops::replace(&mut canvas, t, i64::from(x), i64::from(y));
            x += t.width() + gap;
        }
        y += row[0].height() + gap;
    }
    canvas.save(path).expect("write contact sheet");
}
