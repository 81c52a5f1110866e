//! The encoder section of BENCHMARKS.md (`report:encode`): quality against size and time
//! on Kodak and LOL's normal-light images, against JPEG at equal or fewer bytes, with
//! BD-rates and the adaptive-against-random curves.

use super::{images, load, mean, median, Args};
use gsi::fit::{encode, Budget, EncodeOptions, Init, Progress};
use gsi::metrics::{self, Rgb8};
use plotters::prelude::*;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The encoder section: every image of Kodak and LOL's normal-light set at each `--bpp`,
/// against JPEG at most its size; the adaptive-against-random curves; `DIR/encode.json`,
/// the plots and the `report:encode` section of BENCHMARKS.md.
pub fn section(args: &Args, stamp: &(String, String)) {
    let mut rows = Vec::new();
    let sets: Vec<(&str, &PathBuf)> = [("kodak", &args.kodak), ("lol-high", &args.lol)]
        .into_iter()
        .filter_map(|(n, d)| d.as_ref().map(|d| (n, d)))
        .collect();
    for (set, dir) in sets {
        for path in images(dir, args.limit) {
            let (target, rgb) = load(&path);
            let (w, h) = (target.width, target.height);
            for &bpp in &args.bpp {
                let opts = EncodeOptions {
                    budget: Budget::Bpp(bpp),
                    iterations: args.iterations,
                    ..EncodeOptions::default()
                };
                let t0 = Instant::now();
                let e = encode(&target, &opts, gsi::Device::Cpu, &mut |_| {}).expect("encode");
                let seconds = t0.elapsed().as_secs_f64();
                let decoded = gsi::render::render(&e.records.to_scene(), w, h)
                    .expect("render")
                    .to_rgb8();
                let score = |img: &[u8]| {
                    let (a, b) = (
                        Rgb8::new(w, h, &rgb).unwrap(),
                        Rgb8::new(w, h, img).unwrap(),
                    );
                    (metrics::psnr(a, b).unwrap(), metrics::ssim(a, b).unwrap())
                };
                let (psnr, ssim) = score(&decoded);
                let jpeg = jpeg_at_most(&rgb, w, h, e.bytes.len()).map(|(q, n, img)| {
                    let (p, s) = score(&img);
                    (q, n, p, s)
                });
                let row = Row {
                    set: set.into(),
                    image: path.file_name().unwrap().to_string_lossy().into_owned(),
                    target_bpp: bpp,
                    gaussians: e.records.header.count,
                    bytes: e.bytes.len(),
                    bpp: e.bytes.len() as f64 * 8.0 / f64::from(w * h),
                    psnr,
                    ssim,
                    seconds,
                    jpeg,
                    float_psnr: e.float_psnr,
                    bits: attribute_bits(&e.records, true),
                    bits_packed: attribute_bits(&e.records, false),
                };
                eprintln!(
                    "{set} {} @{bpp}: N {} {:.3} bpp {:.2} dB {:.1}s | JPEG {}",
                    row.image,
                    row.gaussians,
                    row.bpp,
                    row.psnr,
                    row.seconds,
                    row.jpeg
                        .map_or("-".into(), |j| format!("q{} {:.2} dB", j.0, j.2))
                );
                rows.push(row);
            }
        }
    }
    let curve = args.curve_image.as_ref().map(|p| init_curves(p, args));
    write_outputs(args, &rows, curve.as_ref(), stamp);
}

/// The best-quality baseline JPEG (4:2:0 as the `image` crate writes it) no larger than
/// `budget` bytes, decoded: `(quality, bytes, rgb)`.
fn jpeg_at_most(rgb: &[u8], w: u32, h: u32, budget: usize) -> Option<(u8, usize, Vec<u8>)> {
    use image::ImageEncoder;
    let enc = |q: u8| {
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, q)
            .write_image(rgb, w, h, image::ExtendedColorType::Rgb8)
            .expect("in-memory JPEG");
        out
    };
    let (mut lo, mut hi) = (1u8, 100u8);
    if enc(1).len() > budget {
        return None;
    }
    while lo < hi {
        let mid = (lo + hi).div_ceil(2);
        if enc(mid).len() <= budget {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    let bytes = enc(lo);
    let decoded = image::load_from_memory(&bytes)
        .expect("own JPEG decodes")
        .to_rgb8()
        .into_raw();
    Some((lo, bytes.len(), decoded))
}

struct Row {
    set: String,
    image: String,
    target_bpp: f32,
    gaussians: u32,
    bytes: usize,
    bpp: f64,
    psnr: f64,
    ssim: f64,
    seconds: f64,
    jpeg: Option<(u8, usize, f64, f64)>,
    /// PSNR of the float fit before quantization.
    float_psnr: f64,
    /// Bits per Gaussian of GPOS, GCOV, GCOL (GOPA: none in `sum` files) as written, and
    /// as the 1.0 codings (stored or zstd) would write the same codes.
    bits: [f64; 3],
    bits_packed: [f64; 3],
}

/// Bits per Gaussian of each attribute payload, with or without the coded method (3);
/// colours stored by footprint are in method 5 either way.
fn attribute_bits(r: &gsi::format::Records, coded: bool) -> [f64; 3] {
    let n = f64::from(r.header.count.max(1));
    [&r.positions, &r.covariance, &r.colors].map(|a| {
        let p = r
            .attribute_payload(a, 19, coded)
            .expect("in-memory payload");
        p.len() as f64 * 8.0 / n
    })
}

/// Curves of the adaptive and the random start on one image with the same N.
struct Curves {
    image: String,
    gaussians: usize,
    random: Vec<Progress>,
    random_psnr: f64,
    adaptive: Vec<Progress>,
    adaptive_psnr: f64,
    adaptive_iterations: u32,
}

fn init_curves(path: &Path, args: &Args) -> Curves {
    let (target, _) = load(path);
    let n = 4000;
    let run = |init, iterations| {
        let opts = EncodeOptions {
            budget: Budget::Gaussians(n),
            iterations,
            init,
            ..EncodeOptions::default()
        };
        let mut curve = Vec::new();
        let e = encode(&target, &opts, gsi::Device::Cpu, &mut |p| curve.push(*p)).expect("encode");
        (curve, e.psnr)
    };
    let (random, random_psnr) = run(Init::Random, args.curve_iterations);
    let adaptive_iterations = (args.curve_iterations / 10).max(1);
    let (adaptive, adaptive_psnr) = run(Init::Adaptive, adaptive_iterations);
    eprintln!(
        "curve: random {} it {:.2} dB; adaptive {} it {:.2} dB",
        args.curve_iterations, random_psnr, adaptive_iterations, adaptive_psnr
    );
    Curves {
        image: path.file_name().unwrap().to_string_lossy().into_owned(),
        gaussians: n,
        random,
        random_psnr,
        adaptive,
        adaptive_psnr,
        adaptive_iterations,
    }
}

fn write_outputs(args: &Args, rows: &[Row], curve: Option<&Curves>, stamp: &(String, String)) {
    let json_rows: Vec<_> = rows
        .iter()
        .map(|r| {
            json!({
                "set": r.set, "image": r.image, "target_bpp": r.target_bpp, "gaussians": r.gaussians,
                "bytes": r.bytes, "bpp": r.bpp, "psnr": r.psnr, "ssim": r.ssim, "seconds": r.seconds,
                "float_psnr": r.float_psnr, "bits_per_gaussian": r.bits, "bits_per_gaussian_packed": r.bits_packed,
                "jpeg": r.jpeg.map(|(q, n, p, s)| json!({"quality": q, "bytes": n, "psnr": p, "ssim": s})),
            })
        })
        .collect();
    let curve_json = curve.map(|c| {
        let pts = |v: &[Progress]| v.iter().map(|p| json!([p.iteration, p.psnr, p.seconds])).collect::<Vec<_>>();
        json!({"image": c.image, "gaussians": c.gaussians, "random": pts(&c.random), "random_psnr": c.random_psnr,
               "adaptive": pts(&c.adaptive), "adaptive_psnr": c.adaptive_psnr})
    });
    let doc = json!({"machine": stamp.0, "commit": stamp.1, "iterations": args.iterations, "rows": json_rows, "init_curves": curve_json});
    std::fs::write(
        args.out.join("encode.json"),
        serde_json::to_string_pretty(&doc).unwrap(),
    )
    .expect("write json");
    plot_rd(rows, &args.out.join("psnr_bpp.svg"));
    plot_time(rows, &args.out.join("psnr_time.svg"));
    if let Some(c) = curve {
        plot_curves(c, &args.out.join("init_curves.svg"));
    }
    let md = markdown(args, rows, curve, stamp);
    super::replace_section("encode", &md);
    eprintln!(
        "wrote {} and BENCHMARKS.md",
        args.out.join("encode.json").display()
    );
}

fn markdown(args: &Args, rows: &[Row], curve: Option<&Curves>, stamp: &(String, String)) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "## Stage-1 encoder: quality against size and time\n");
    let _ = writeln!(
        s,
        "Machine: {}. Commit: `{}`. Release build, CPU only, {} iterations, adaptive start, `sum` blending, \
         default bit depths. Regenerate with `cargo run --release --example report` (writes `{}/`).\n",
        stamp.0,
        stamp.1,
        args.iterations,
        args.out.display()
    );
    let _ = writeln!(s, "PSNR and SSIM on 8-bit RGB of the decoded file against the original. JPEG: the `image` crate's baseline encoder at the highest quality whose file is no larger than the gsi file (equal bytes or fewer).\n");
    let _ = writeln!(s, "| set | target bpp | images | mean bpp | gsi PSNR | gsi SSIM | JPEG PSNR (≤ same bytes) | JPEG SSIM | median encode s | mean N |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    let mut groups: Vec<(String, f32)> =
        rows.iter().map(|r| (r.set.clone(), r.target_bpp)).collect();
    groups.dedup();
    groups.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    groups.dedup();
    for (set, bpp) in &groups {
        let g: Vec<&Row> = rows
            .iter()
            .filter(|r| &r.set == set && r.target_bpp == *bpp)
            .collect();
        let jp: Vec<&(u8, usize, f64, f64)> = g.iter().filter_map(|r| r.jpeg.as_ref()).collect();
        let _ = writeln!(
            s,
            "| {set} | {bpp} | {} | {:.3} | {:.2} | {:.4} | {} | {} | {:.1} | {:.0} |",
            g.len(),
            mean(g.iter().map(|r| r.bpp)),
            mean(g.iter().map(|r| r.psnr)),
            mean(g.iter().map(|r| r.ssim)),
            if jp.is_empty() {
                "-".into()
            } else {
                format!(
                    "{:.2} ({} of {})",
                    mean(jp.iter().map(|j| j.2)),
                    jp.len(),
                    g.len()
                )
            },
            if jp.is_empty() {
                "-".into()
            } else {
                format!("{:.4}", mean(jp.iter().map(|j| j.3)))
            },
            median(g.iter().map(|r| r.seconds).collect()),
            mean(g.iter().map(|r| f64::from(r.gaussians))),
        );
    }
    let _ = writeln!(s, "\nBits per Gaussian by attribute (chunk payloads, preambles included), as written (method 3 where smaller, `sum` files in Morton order) and as the 1.0 codings (stored or zstd) would write the same codes; quantization loss is the float fit's PSNR minus the stored file's (negative where quantization-aware fine-tuning left the float parameters tuned to their quantized values):\n");
    let _ = writeln!(s, "| set | target bpp | GPOS | GCOV | GCOL | total | total, 1.0 coding | quantization loss dB |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    for (set, bpp) in &groups {
        let g: Vec<&Row> = rows
            .iter()
            .filter(|r| &r.set == set && r.target_bpp == *bpp)
            .collect();
        let b = |k: usize| mean(g.iter().map(|r| r.bits[k]));
        let _ = writeln!(
            s,
            "| {set} | {bpp} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} |",
            b(0),
            b(1),
            b(2),
            mean(g.iter().map(|r| r.bits.iter().sum::<f64>())),
            mean(g.iter().map(|r| r.bits_packed.iter().sum::<f64>())),
            mean(g.iter().map(|r| r.float_psnr - r.psnr)),
        );
    }
    let _ = writeln!(s, "\nReference (`../shared/data/README.md`, libjpeg 4:2:0 via Pillow, Kodak mean, interpolated): JPEG 29.36 dB at 0.5 bpp, 32.88 dB at 1.0 bpp; WebP 31.79 / 35.28; AVIF 32.66 / 36.12. GaussianImage's published codec on Kodak: 27.4 dB at 0.43 bpp, 28.7 at 0.71, 29.65 at 1.00, 30.5 at 1.28.\n");
    for set in groups
        .iter()
        .map(|g| &g.0)
        .collect::<std::collections::BTreeSet<_>>()
    {
        let points = |jpeg: bool| -> Vec<(f64, f64)> {
            groups
                .iter()
                .filter(|g| &g.0 == set)
                .filter_map(|(_, bpp)| {
                    let g: Vec<&Row> = rows
                        .iter()
                        .filter(|r| &r.set == set && r.target_bpp == *bpp)
                        .collect();
                    if jpeg {
                        let j: Vec<(f64, f64)> = g
                            .iter()
                            .filter_map(|r| {
                                r.jpeg.map(|j| (j.1 as f64 * r.bpp / r.bytes as f64, j.2))
                            })
                            .collect();
                        (j.len() == g.len())
                            .then(|| (mean(j.iter().map(|x| x.0)), mean(j.iter().map(|x| x.1))))
                    } else {
                        Some((
                            mean(g.iter().map(|r| r.bpp)),
                            mean(g.iter().map(|r| r.psnr)),
                        ))
                    }
                })
                .collect()
        };
        let (gsi_pts, jpeg_pts) = (points(false), points(true));
        let rate = |pts: &[(f64, f64)]| {
            pts.iter()
                .map(|(b, p)| format!("{p:.2} dB @ {b:.3}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let _ = writeln!(
            s,
            "BD-rate of gsi against JPEG (image crate, ≤ same bytes; mean bpp and PSNR per target, piecewise-linear in log rate over the PSNR range both cover), {set}: **{}** (gsi {}; JPEG {}).\n",
            bd_rate(&jpeg_pts, &gsi_pts).map_or("no overlap".into(), |d| format!("{d:+.1} %")),
            rate(&gsi_pts),
            rate(&jpeg_pts),
        );
    }
    let _ = writeln!(
        s,
        "![PSNR against bpp]({}/psnr_bpp.svg)\n![PSNR against encode time]({}/psnr_time.svg)\n",
        args.out.display(),
        args.out.display()
    );
    if let Some(c) = curve {
        let reached = c
            .adaptive
            .iter()
            .find(|p| p.psnr >= c.random_psnr)
            .map(|p| p.iteration);
        let _ = writeln!(
            s,
            "### Adaptive against random initialization\n\n{}, N = {}: the paper's random start reaches **{:.2} dB** (stored file) after {} iterations; \
             the adaptive start reaches **{:.2} dB** after {} iterations (1/10). First iteration at which the adaptive run's render \
             is at least the random run's final PSNR: {}.\n\n![PSNR against iteration]({}/init_curves.svg)\n",
            c.image,
            c.gaussians,
            c.random_psnr,
            args.curve_iterations,
            c.adaptive_psnr,
            c.adaptive_iterations,
            reached.map_or("not reached".into(), |i| i.to_string()),
            args.out.display()
        );
    }
    let _ = writeln!(s, "<details><summary>Per image</summary>\n\n| set | image | target | N | bytes | bpp | PSNR | SSIM | s | JPEG q | JPEG bytes | JPEG PSNR |\n|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let j = r.jpeg.map_or("| - | - | - |".into(), |(q, n, p, _)| {
            format!("| {q} | {n} | {p:.2} |")
        });
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.3} | {:.2} | {:.4} | {:.1} {j}",
            r.set, r.image, r.target_bpp, r.gaussians, r.bytes, r.bpp, r.psnr, r.ssim, r.seconds
        );
    }
    let _ = writeln!(s, "\n</details>\n");
    s
}

/// GaussianImage's published codec points on Kodak (bpp, mean PSNR), as issue 12 quotes
/// them.
const GAUSSIAN_IMAGE_KODAK: [(f64, f64); 4] =
    [(0.43, 27.4), (0.71, 28.7), (1.00, 29.65), (1.28, 30.5)];

/// Bjøntegaard delta rate of `test` against `anchor`, each a curve of (bpp, PSNR) points
/// (at least two, PSNR increasing with rate): the mean difference in log rate at equal
/// PSNR over the PSNR range both cover, as a percentage (negative: `test` needs fewer
/// bits). Piecewise-linear in log rate rather than the original cubic fit, which
/// overshoots with few points; `None` where the curves do not overlap.
fn bd_rate(anchor: &[(f64, f64)], test: &[(f64, f64)]) -> Option<f64> {
    let curve = |pts: &[(f64, f64)]| {
        let mut c: Vec<(f64, f64)> = pts.iter().map(|&(r, p)| (p, r.ln())).collect();
        c.sort_by(|a, b| a.0.total_cmp(&b.0));
        c
    };
    let (a, t) = (curve(anchor), curve(test));
    let lo = a.first()?.0.max(t.first()?.0);
    let hi = a.last()?.0.min(t.last()?.0);
    if a.len() < 2 || t.len() < 2 || hi <= lo {
        return None;
    }
    let at = |c: &[(f64, f64)], p: f64| {
        let i = c
            .windows(2)
            .position(|w| p <= w[1].0)
            .unwrap_or(c.len() - 2);
        let (p0, r0, p1, r1) = (c[i].0, c[i].1, c[i + 1].0, c[i + 1].1);
        r0 + (r1 - r0) * (p - p0) / (p1 - p0).max(1e-12)
    };
    let steps = 1000;
    let mean_diff = (0..steps)
        .map(|k| {
            let p = lo + (hi - lo) * (k as f64 + 0.5) / steps as f64;
            at(&t, p) - at(&a, p)
        })
        .sum::<f64>()
        / steps as f64;
    Some((mean_diff.exp() - 1.0) * 100.0)
}

fn plot_rd(rows: &[Row], path: &Path) {
    let root = SVGBackend::new(path, (720, 480)).into_drawing_area();
    root.fill(&WHITE).unwrap();
    let (lo, hi) = rows.iter().fold((f64::MAX, f64::MIN), |(a, b), r| {
        (a.min(r.psnr), b.max(r.psnr))
    });
    let maxb = rows.iter().map(|r| r.bpp).fold(0.0, f64::max) * 1.1;
    let mut c = ChartBuilder::on(&root)
        .caption(
            "PSNR against file size (each point an image)",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..maxb.max(0.1), (lo - 2.0).min(20.0)..hi + 2.0)
        .unwrap();
    c.configure_mesh()
        .x_desc("bits per pixel")
        .y_desc("PSNR (dB)")
        .draw()
        .unwrap();
    c.draw_series(
        rows.iter()
            .map(|r| Circle::new((r.bpp, r.psnr), 3, BLUE.filled())),
    )
    .unwrap()
    .label("gsi")
    .legend(|(x, y)| Circle::new((x, y), 3, BLUE.filled()));
    c.draw_series(rows.iter().filter_map(|r| {
        r.jpeg
            .map(|j| Cross::new((j.1 as f64 * r.bpp / r.bytes as f64, j.2), 4, RED))
    }))
    .unwrap()
    .label("JPEG (image crate), ≤ same bytes")
    .legend(|(x, y)| Cross::new((x, y), 4, RED));
    c.draw_series(LineSeries::new(GAUSSIAN_IMAGE_KODAK, GREEN.stroke_width(2)))
        .unwrap()
        .label("GaussianImage codec, Kodak mean (published)")
        .legend(|(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], GREEN));
    c.configure_series_labels()
        .background_style(WHITE)
        .border_style(BLACK)
        .draw()
        .unwrap();
    root.present().unwrap();
}

fn plot_time(rows: &[Row], path: &Path) {
    let root = SVGBackend::new(path, (720, 480)).into_drawing_area();
    root.fill(&WHITE).unwrap();
    let (lo, hi) = rows.iter().fold((f64::MAX, f64::MIN), |(a, b), r| {
        (a.min(r.psnr), b.max(r.psnr))
    });
    let maxt = rows.iter().map(|r| r.seconds).fold(0.0, f64::max) * 1.1;
    let mut c = ChartBuilder::on(&root)
        .caption(
            "PSNR against encode time (each point an image and target)",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..maxt.max(1.0), (lo - 2.0).min(20.0)..hi + 2.0)
        .unwrap();
    c.configure_mesh()
        .x_desc("encode time (s)")
        .y_desc("PSNR (dB)")
        .draw()
        .unwrap();
    c.draw_series(
        rows.iter()
            .map(|r| Circle::new((r.seconds, r.psnr), 3, BLUE.filled())),
    )
    .unwrap();
    root.present().unwrap();
}

fn plot_curves(cv: &Curves, path: &Path) {
    let root = SVGBackend::new(path, (720, 480)).into_drawing_area();
    root.fill(&WHITE).unwrap();
    let all = cv.random.iter().chain(&cv.adaptive);
    let (lo, hi) = all.fold((f64::MAX, f64::MIN), |(a, b), p| {
        (a.min(p.psnr), b.max(p.psnr))
    });
    let maxi = cv.random.last().map_or(1, |p| p.iteration) as f64;
    let mut c = ChartBuilder::on(&root)
        .caption(
            format!(
                "{}: PSNR of the render during fitting, N = {}",
                cv.image, cv.gaussians
            ),
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..maxi, (lo - 1.0).max(0.0)..hi + 1.0)
        .unwrap();
    c.configure_mesh()
        .x_desc("iteration")
        .y_desc("PSNR (dB)")
        .draw()
        .unwrap();
    c.draw_series(LineSeries::new(
        cv.random.iter().map(|p| (f64::from(p.iteration), p.psnr)),
        RED,
    ))
    .unwrap()
    .label("random start (paper)")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    c.draw_series(LineSeries::new(
        cv.adaptive.iter().map(|p| (f64::from(p.iteration), p.psnr)),
        BLUE,
    ))
    .unwrap()
    .label("adaptive start")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    c.configure_series_labels()
        .background_style(WHITE)
        .border_style(BLACK)
        .draw()
        .unwrap();
    root.present().unwrap();
}

#[cfg(test)]
mod tests {
    use super::bd_rate;

    #[test]
    fn bd_rate_of_a_curve_at_half_the_rate_is_minus_half() {
        let a = [(0.25, 25.0), (0.5, 27.0), (1.0, 29.0), (1.5, 30.5)];
        let half: Vec<(f64, f64)> = a.iter().map(|&(r, p)| (r / 2.0, p)).collect();
        assert!((bd_rate(&a, &half).unwrap() + 50.0).abs() < 1e-6);
        assert!(bd_rate(&a, &a).unwrap().abs() < 1e-9);
        assert!(bd_rate(&a, &[(1.0, 40.0), (2.0, 41.0)]).is_none());
    }
}
