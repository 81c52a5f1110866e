//! Time against PSNR for each `--effort` level (issue 13): the Kodak images at 1 bpp,
//! encoded one after another on the CPU, each level and the fit before effort levels
//! (400 full-resolution steps at the old rates) in the same run. Writes `effort.json` and `effort.svg`, and
//! the `report:effort` section of BENCHMARKS.md.

use super::{commit, images, load, machine, mean, median, replace_section};
use gsi::fit::{encode, Budget, Effort, EncodeOptions, LearningRates};
use plotters::prelude::*;
use serde_json::json;
use std::path::Path;
use std::time::Instant;

/// One configuration: a level, or the fit before levels.
#[derive(Clone)]
struct Config {
    label: String,
    level: Option<u8>,
    opts: EncodeOptions,
}

struct Row {
    image: String,
    seconds: f64,
    psnr: f64,
    gaussians: u32,
    bpp: f64,
}

/// The configurations of `levels`, and the fit before levels when none of them is it and
/// `before` asks for it.
fn configs(levels: &[u8], before: bool) -> Vec<Config> {
    let base = EncodeOptions {
        budget: Budget::Bpp(1.0),
        ..EncodeOptions::default()
    };
    let reference = Config {
        label: "before: 400 steps, full resolution, GaussianImage's rates".into(),
        level: None,
        opts: EncodeOptions {
            iterations: 400,
            coarse: None,
            color_solve: 10,
            lr: BEFORE_RATES,
            lab: gsi::fit::Lab {
                solve_stored_colors: false,
                ..Default::default()
            },
            ..base.clone()
        },
    };
    let leveled = levels.iter().map(|&l| {
        let mut opts = base.clone();
        Effort::new(l).expect("levels are 1..=9").apply(&mut opts);
        Config {
            label: format!("effort {l}"),
            level: Some(l),
            opts,
        }
    });
    // A level that is the fit before levels is its own reference.
    let leveled: Vec<Config> = leveled.collect();
    if !before || leveled.iter().any(is_before) {
        leveled
    } else {
        std::iter::once(reference).chain(leveled).collect()
    }
}

/// Time `levels` (and the fit before levels) on the Kodak images in `kodak`. With `keep`,
/// the levels of an earlier run's `effort.json` that this run does not time are kept, when
/// that run scored the same images: the slow levels can be run apart.
pub fn section(kodak: &Path, out_dir: &Path, limit: usize, levels: &[u8], keep: bool) {
    let stamp = (machine(), commit());
    let files = images(kodak, limit);
    // Kept levels bring the reference of the run that timed them.
    let configs = configs(levels, !keep);
    let mut results: Vec<Vec<Row>> = configs.iter().map(|_| Vec::new()).collect();
    // Image by image, every configuration in turn: the machine's drift in load falls on
    // all of them alike.
    for path in &files {
        let (target, _) = load(path);
        let px = f64::from(target.width * target.height);
        for (c, rows) in configs.iter().zip(&mut results) {
            let t0 = Instant::now();
            let e = encode(&target, &c.opts, gsi::Device::Cpu, &mut |_| {}).expect("encode");
            let row = Row {
                image: path.file_name().unwrap().to_string_lossy().into_owned(),
                seconds: t0.elapsed().as_secs_f64(),
                psnr: e.psnr,
                gaussians: e.records.header.count,
                bpp: e.bytes.len() as f64 * 8.0 / px,
            };
            eprintln!(
                "effort: {} {}: {:.2} dB {:.1} s N {}",
                row.image, c.label, row.psnr, row.seconds, row.gaussians
            );
            rows.push(row);
        }
    }
    let mut configs = configs;
    let mut commits = vec![stamp.1.clone(); configs.len()];
    if keep {
        let names: Vec<String> = results[0].iter().map(|r| r.image.clone()).collect();
        for (level, commit, rows) in earlier(&out_dir.join("effort.json"), &names) {
            if configs.iter().all(|c| c.level != Some(level)) {
                configs.extend(self::configs(&[level], false));
                commits.push(commit);
                results.push(rows);
            }
        }
        let mut order: Vec<usize> = (0..configs.len()).collect();
        order.sort_by_key(|&k| configs[k].level);
        configs = order.iter().map(|&k| configs[k].clone()).collect();
        commits = order.iter().map(|&k| commits[k].clone()).collect();
        let mut taken: Vec<Option<Vec<Row>>> = results.into_iter().map(Some).collect();
        results = order.iter().map(|&k| taken[k].take().unwrap()).collect();
    }
    plot(&configs, &results, &out_dir.join("effort.svg"));
    let doc = json!({
        "machine": stamp.0, "commit": stamp.1, "bpp": 1.0,
        "configs": configs.iter().zip(&results).zip(&commits).map(|((c, rows), commit)| json!({
            "label": c.label, "level": c.level, "commit": commit,
            "iterations": c.opts.iterations,
            "coarse": c.opts.coarse.map(|k| json!({"factor": k.factor, "fraction": k.fraction})),
            "color_solve": c.opts.color_solve,
            "rows": rows.iter().map(|r| json!({
                "image": r.image, "seconds": r.seconds, "psnr": r.psnr,
                "gaussians": r.gaussians, "bpp": r.bpp,
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    });
    std::fs::write(
        out_dir.join("effort.json"),
        serde_json::to_string_pretty(&doc).unwrap(),
    )
    .expect("write json");
    replace_section("effort", &markdown(&configs, &results, &commits, &stamp));
}

/// The levels of an earlier `effort.json` that scored exactly `images`, with the commit
/// each was measured at and its rows; none where the file is missing or of other images.
fn earlier(path: &Path, images: &[String]) -> Vec<(u8, String, Vec<Row>)> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Vec::new();
    };
    let doc: serde_json::Value = serde_json::from_str(&text).expect("effort.json is JSON");
    let top = doc["commit"].as_str().unwrap_or("").to_string();
    let mut out = Vec::new();
    for c in doc["configs"].as_array().into_iter().flatten() {
        let Some(level) = c["level"].as_u64() else {
            continue;
        };
        let rows: Vec<Row> = c["rows"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|r| Row {
                image: r["image"].as_str().unwrap_or("").to_string(),
                seconds: r["seconds"].as_f64().unwrap_or(f64::NAN),
                psnr: r["psnr"].as_f64().unwrap_or(f64::NAN),
                gaussians: r["gaussians"].as_u64().unwrap_or(0) as u32,
                bpp: r["bpp"].as_f64().unwrap_or(f64::NAN),
            })
            .collect();
        // Kept only if the level still means what it meant then.
        let mut now = EncodeOptions::default();
        Effort::new(level as u8)
            .expect("levels are 1..=9")
            .apply(&mut now);
        let same = c["iterations"].as_u64() == Some(u64::from(now.iterations))
            && c["color_solve"].as_u64() == Some(u64::from(now.color_solve))
            && c["coarse"]["fraction"].as_f64().map(|f| f as f32) == now.coarse.map(|k| k.fraction);
        let scored: Vec<&str> = rows.iter().map(|r| r.image.as_str()).collect();
        if same && scored == images {
            let commit = c["commit"].as_str().map_or(top.clone(), str::to_string);
            out.push((level as u8, commit, rows));
        }
    }
    out
}

/// Whether `c` is the fit before effort levels: 400 full-resolution steps at
/// GaussianImage's rates, no final colour solve.
fn is_before(c: &Config) -> bool {
    c.opts.iterations == 400
        && c.opts.coarse.is_none()
        && c.opts.color_solve == 10
        && c.opts.lr == BEFORE_RATES
        && !c.opts.lab.solve_stored_colors
}

/// The learning rates of the fit before effort levels (GaussianImage's), which the
/// levels' rates replaced.
const BEFORE_RATES: LearningRates = LearningRates {
    position: 2e-4,
    log_scale: 0.01,
    rotation: 0.01,
    color: 0.005,
    opacity: 0.01,
};

fn markdown(
    configs: &[Config],
    results: &[Vec<Row>],
    commits: &[String],
    stamp: &(String, String),
) -> String {
    let before = configs
        .iter()
        .position(is_before)
        .map_or(&results[0], |k| &results[k]);
    let mut s = format!(
        "## Stage-1 encoder: effort levels, time against PSNR (issue 13)\n\n\
         Machine: {}. Commit: `{}`. The {} Kodak images at 1 bpp, on the CPU (`--device cpu`),\n\
         one encode at a time; for each image every configuration of a run in turn. PSNR of the stored\n\
         file; Δ is the mean of each image's difference to the fit before effort levels\n\
         (400 full-resolution steps at GaussianImage's learning rates, the default before the levels;\n\
         its colours stored as its last step left them, without the final colour solve).\n\
         Regenerate: `cargo run --release --example report -- --effort-only`.\n\n\
         | configuration | steps (coarse share) | colour solve | median time | mean PSNR | Δ PSNR | median N |\n\
         |---|---|---|---|---|---|---|\n",
        stamp.0,
        stamp.1,
        before.len()
    );
    let kept: Vec<String> = configs
        .iter()
        .zip(commits)
        .filter(|(_, k)| **k != stamp.1)
        .map(|(c, k)| format!("{} (`{k}`)", c.label))
        .collect();
    if !kept.is_empty() {
        s.insert_str(
            s.find("| configuration").unwrap_or(s.len()),
            &format!(
                "Kept from an earlier run on the same images (`--effort-keep`): {}.\n\n",
                kept.join(", ")
            ),
        );
    }
    for (c, rows) in configs.iter().zip(results) {
        let delta = mean(rows.iter().zip(before).map(|(r, b)| r.psnr - b.psnr));
        let coarse = c.opts.coarse.map_or("none".to_string(), |k| {
            format!(
                "{} at 1/{}",
                (c.opts.iterations as f32 * k.fraction) as u32,
                k.factor
            )
        });
        s += &format!(
            "| {}{} | {} ({coarse}) | {} | {:.1} s | {:.2} dB | {:+.2} dB | {:.0} |\n",
            c.label,
            match (
                c.level == Some(Effort::DEFAULT.level()),
                c.level.is_some() && is_before(c)
            ) {
                (true, true) => " (default; the fit before levels)",
                (true, false) => " (default)",
                (false, true) => " (the fit before levels)",
                _ => "",
            },
            c.opts.iterations,
            c.opts.color_solve,
            median(rows.iter().map(|r| r.seconds).collect()),
            mean(rows.iter().map(|r| r.psnr)),
            delta,
            median(rows.iter().map(|r| f64::from(r.gaussians)).collect()),
        );
    }
    s += "\n![PSNR against encode time per effort level](bench/effort.svg)\n";
    s
}

/// Each configuration's images (small points) and its median time against mean PSNR.
fn plot(configs: &[Config], results: &[Vec<Row>], path: &Path) {
    let root = SVGBackend::new(path, (720, 480)).into_drawing_area();
    root.fill(&WHITE).unwrap();
    let all = || results.iter().flatten();
    let (lo, hi) = all().fold((f64::MAX, f64::MIN), |(a, b), r| {
        (a.min(r.psnr), b.max(r.psnr))
    });
    let maxt = all().map(|r| r.seconds).fold(1.0, f64::max) * 1.1;
    let mut c = ChartBuilder::on(&root)
        .caption(
            "Kodak at 1 bpp: PSNR against encode time",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d((0.5f64..maxt).log_scale(), (lo - 0.5)..(hi + 0.5))
        .unwrap();
    c.configure_mesh()
        .x_desc("encode time (s, log scale)")
        .y_desc("PSNR (dB)")
        .draw()
        .unwrap();
    for (cfg, rows) in configs.iter().zip(results) {
        let colour = if is_before(cfg) { RED } else { BLUE };
        c.draw_series(
            rows.iter()
                .map(|r| Circle::new((r.seconds, r.psnr), 2, colour.mix(0.25).filled())),
        )
        .unwrap();
        let at = (
            median(rows.iter().map(|r| r.seconds).collect()),
            mean(rows.iter().map(|r| r.psnr)),
        );
        let name = cfg.level.map_or("before".to_string(), |l| format!("e{l}"));
        c.draw_series([Circle::new(at, 5, colour.filled())])
            .unwrap();
        c.draw_series([Text::new(name, at, ("sans-serif", 13).into_font())])
            .unwrap();
    }
    root.present().unwrap();
}
