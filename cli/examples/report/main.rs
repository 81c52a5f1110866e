//! The figures of BENCHMARKS.md, from one command, a module per section:
//!
//! ```sh
//! cargo run --release --example report -- [--kodak DIR] [--lol DIR] [--bpp 0.5,1.0]
//!     [--iterations T] [--limit N] [--curve-image FILE] [--curve-iterations T] [--out DIR]
//!     [--quick | --enhance-only | --effort-only | --encode-only] [--efforts 1,3,5,7,9] [--effort-keep]
//!     [--no-kodak] [--no-lol] [--no-curve] [--no-effort]
//! ```
//!
//! - `decode.rs` (`report:decode`): parse and CPU render of random scenes;
//! - `metrics_table.rs` (`report:metrics`): the metrics on LOL eval15 beside the reference
//!   table;
//! - `encode.rs` (`report:encode`, `DIR/encode.json`, SVG plots): every image and bpp target
//!   encoded, decoded and scored against a JPEG of at most the same size, and one image
//!   fitted from the adaptive and from the paper's random start;
//! - `enhance.rs` (`report:enhance`, `DIR/enhance.json`, contact sheets): stage 2 on the
//!   validation sets and LOL eval15;
//! - `effort.rs` (`report:effort`, `DIR/effort.json`, `DIR/effort.svg`): every `--effort`
//!   level on Kodak.
//!
//! Each rewrites its section between the `report:NAME` markers of BENCHMARKS.md, with the
//! machine and commit. Arguments are parsed by clap (`--help`).

mod decode;
mod effort;
mod encode;
mod enhance;
mod metrics_table;
// The report builds the synthetic set; the example `lowlight_set` also measures.
#[allow(dead_code)]
mod lowlight;

use gsi::fit::{EncodeOptions, Target};
use std::path::{Path, PathBuf};

/// The figures of BENCHMARKS.md, regenerated section by section.
#[derive(clap::Parser)]
#[command(name = "report")]
struct Cli {
    /// Kodak images (default: ../shared/data/kodak).
    #[arg(long, value_name = "DIR")]
    kodak: Option<PathBuf>,
    /// LOL normal-light images (default: ../shared/data/LOL/eval15/high).
    #[arg(long, value_name = "DIR")]
    lol: Option<PathBuf>,
    /// No Kodak rows.
    #[arg(long)]
    no_kodak: bool,
    /// No LOL rows (and no stage-2 or metrics section).
    #[arg(long)]
    no_lol: bool,
    /// The bpp targets of the encoder section.
    #[arg(long, value_delimiter = ',', default_value = "0.5,1.0")]
    bpp: Vec<f32>,
    /// Optimizer steps of every encode (default: the default effort's).
    #[arg(long)]
    iterations: Option<u32>,
    /// At most this many images of each set.
    #[arg(long, default_value_t = usize::MAX, hide_default_value = true)]
    limit: usize,
    /// The image of the adaptive-against-random curves (default: kodim23).
    #[arg(long, value_name = "FILE")]
    curve_image: Option<PathBuf>,
    /// No adaptive-against-random curves.
    #[arg(long)]
    no_curve: bool,
    /// Steps of the random start's curve.
    #[arg(long, default_value_t = 1000)]
    curve_iterations: u32,
    /// Where the JSON and SVG files go.
    #[arg(long, default_value = "bench")]
    out: PathBuf,
    /// Only the decoder and metrics sections (seconds, not the encoder's half hour).
    #[arg(long, group = "only")]
    quick: bool,
    /// Only the stage-2 section (LOL eval15 encode, enhance, decode).
    #[arg(long, group = "only")]
    enhance_only: bool,
    /// Only the effort section.
    #[arg(long, group = "only")]
    effort_only: bool,
    /// Only the encoder section (quality against size and time).
    #[arg(long, group = "only")]
    encode_only: bool,
    /// The effort levels the effort section times.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5,6,7,8,9",
          value_parser = clap::value_parser!(u8).range(1..=9))]
    efforts: Vec<u8>,
    /// No effort section.
    #[arg(long)]
    no_effort: bool,
    /// Keep the levels of an earlier effort run that this one does not time.
    #[arg(long)]
    effort_keep: bool,
}

/// [`Cli`] with the defaults resolved and the `--no-*` switches applied.
struct Args {
    kodak: Option<PathBuf>,
    lol: Option<PathBuf>,
    bpp: Vec<f32>,
    iterations: u32,
    limit: usize,
    curve_image: Option<PathBuf>,
    curve_iterations: u32,
    out: PathBuf,
    quick: bool,
    enhance_only: bool,
    effort_only: bool,
    encode_only: bool,
    efforts: Vec<u8>,
    effort_keep: bool,
}

fn parse_args() -> Args {
    use clap::Parser;
    let c = Cli::parse();
    let shared = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).join("../shared/data");
    let unless =
        |no: bool, p: Option<PathBuf>, default: PathBuf| (!no).then(|| p.unwrap_or(default));
    Args {
        kodak: unless(c.no_kodak, c.kodak, shared.join("kodak")),
        lol: unless(c.no_lol, c.lol, shared.join("LOL/eval15/high")),
        bpp: c.bpp,
        iterations: c.iterations.unwrap_or(EncodeOptions::default().iterations),
        limit: c.limit,
        curve_image: unless(c.no_curve, c.curve_image, shared.join("kodak/kodim23.png")),
        curve_iterations: c.curve_iterations,
        out: c.out,
        quick: c.quick,
        enhance_only: c.enhance_only,
        effort_only: c.effort_only,
        encode_only: c.encode_only,
        efforts: if c.no_effort { Vec::new() } else { c.efforts },
        effort_keep: c.effort_keep,
    }
}

fn load(path: &Path) -> (Target, Vec<u8>) {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    let (width, height) = img.dimensions();
    let raw = img.into_raw();
    let data = raw.iter().map(|&v| f32::from(v) / 255.0).collect();
    (
        Target {
            width,
            height,
            data,
        },
        raw,
    )
}

fn images(dir: &Path, limit: usize) -> Vec<PathBuf> {
    let mut v = lowlight::pngs(dir);
    v.truncate(limit);
    v
}

fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_owned())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    format!("{cores} cores, {cpu}")
}

fn commit() -> String {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
            .output()
            .ok()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
            .unwrap_or_default()
    };
    let dirty = !git(&["status", "--porcelain", "--untracked-files=no"]).is_empty();
    format!(
        "{}{}",
        git(&["rev-parse", "--short", "HEAD"]),
        if dirty { "-dirty" } else { "" }
    )
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n.max(1) as f64
}

fn main() {
    let args = parse_args();
    // Stamp the commit the measured binary was built from, not the one at the end of the run.
    let stamp = (machine(), commit());
    std::fs::create_dir_all(&args.out).expect("output folder");
    let lol_root = args.lol.as_ref().map(|l| {
        l.parent()
            .expect("LOL/eval15/high has a parent")
            .to_path_buf()
    });
    if args.enhance_only {
        if let Some(lol) = &lol_root {
            enhance::section(lol, args.kodak.as_deref(), &args.out, args.limit);
        }
        return;
    }
    if args.effort_only {
        if let Some(kodak) = &args.kodak {
            effort::section(
                kodak,
                &args.out,
                args.limit,
                &args.efforts,
                args.effort_keep,
            );
        }
        return;
    }
    if args.encode_only {
        encode::section(&args, &stamp);
        return;
    }
    replace_section("decode", &decode::section(&stamp));
    if let Some(lol) = &lol_root {
        replace_section("metrics", &metrics_table::section(lol, &stamp));
    }
    if args.quick {
        return;
    }
    encode::section(&args, &stamp);
    if let Some(lol) = &lol_root {
        enhance::section(lol, args.kodak.as_deref(), &args.out, args.limit);
    }
    if let Some(kodak) = args.kodak.as_ref().filter(|_| !args.efforts.is_empty()) {
        effort::section(
            kodak,
            &args.out,
            args.limit,
            &args.efforts,
            args.effort_keep,
        );
    }
}

/// Rewrite the part of BENCHMARKS.md between `<!-- report:NAME:start -->` and
/// `<!-- report:NAME:end -->` (appended when the markers are missing).
fn replace_section(name: &str, body: &str) {
    let bench = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).join("BENCHMARKS.md");
    let old = std::fs::read_to_string(&bench).unwrap_or_default();
    let (start, end) = (
        format!("<!-- report:{name}:start -->"),
        format!("<!-- report:{name}:end -->"),
    );
    let section = format!("{start}\n{body}{end}");
    let new = match (old.find(&start), old.find(&end)) {
        (Some(a), Some(b)) if a < b => format!("{}{}{}", &old[..a], section, &old[b + end.len()..]),
        _ => format!("{old}\n{section}\n"),
    };
    std::fs::write(&bench, new).expect("write BENCHMARKS.md");
}
