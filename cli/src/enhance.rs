//! `gsi enhance`: zero-shot low-light enhancement of a .gsi file's colours, in the file.

use crate::device::DeviceArg;
use crate::{io, Failure};
use gsi::enhance;
use gsi::enhance::curve::CurveOptions;
use gsi::enhance::exposure::Exposure;
use gsi::enhance::fit::EnhanceOptions;
use gsi::format::{ChunkType, ChunkedFile, Limits};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("dest").required(true).args(["in_place", "output"])))]
#[command(group(clap::ArgGroup::new("mode").args(["revert", "apply_from"])))]
pub struct Args {
    /// The .gsi file to enhance (`-` reads standard input). Several files, or a folder
    /// (its .gsi files), make a batch: enhanced in place, or written to the folder OUTPUT.
    #[arg(required = true, value_name = "INPUT")]
    inputs: Vec<PathBuf>,
    /// Replace the input file (through a synced temporary file in the same folder).
    #[arg(long)]
    in_place: bool,
    /// Write the result here instead (`-` for standard output), or in the folder of a batch.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// In a batch, how many files are enhanced at once (default: one per core, at most 4; one
    /// on a GPU).
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
    /// Optimizer iterations of the fit.
    #[arg(long, default_value_t = EnhanceOptions::default().iterations)]
    iterations: u32,
    /// Show the result at this mean brightness (Rec. 601 luma, in (0, 1)), or `auto`: at
    /// the exposure metered from the image, as a camera meters a scene. Default: middle
    /// grey (0.46), where a camera's averaging meter puts a scene's mean.
    #[arg(long, value_name = "E|auto", value_parser = parse_exposure)]
    exposure: Option<Exposure>,
    /// Number of colour operators K, the identity included (paper: 16).
    #[arg(long, default_value_t = EnhanceOptions::default().experts)]
    experts: usize,
    /// Adam's initial step (it decays on a cosine to 1 % of this).
    #[arg(long, default_value_t = EnhanceOptions::default().learning_rate)]
    learning_rate: f32,
    /// Loss weights λ1..λ7 (exposure, hue, spatial, colour, contrast, TV, entropy), comma-separated.
    #[arg(long, value_name = "L1,..,L7", value_delimiter = ',')]
    weights: Option<Vec<f32>>,
    /// Where the mixture (every Gaussian's operators, forward and backward) runs: `auto`
    /// uses a hardware GPU when there is one, `gpu` any adapter (software ones included),
    /// `cpu` the CPU. The render, the loss and the head run on the CPU either way.
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    device: DeviceArg,
    /// Enhance even an image that is not low-light (less than a quarter of it
    /// under-exposed, or black), or one enhanced before whose original colours were discarded. In a
    /// batch, also enhance again the files that carry an enhancement (in place) or whose
    /// output exists (by default skipped).
    #[arg(long)]
    force: bool,
    /// Undo an earlier enhancement, restoring the file byte for byte.
    #[arg(long)]
    revert: bool,
    /// Apply the enhancer stored in this file instead of fitting one.
    #[arg(long, value_name = "SOURCE.gsi")]
    apply_from: Option<PathBuf>,
    /// Do not keep the original colours (smaller file; --revert becomes impossible).
    #[arg(long, conflicts_with = "revert")]
    discard_original: bool,
    /// Smooth the colours across neighbouring Gaussians of like size and value first (an
    /// edge-preserving average; format spec §7.2.1). Off by default: the tone curve keeps
    /// the noise of the shadows down, and on the validation pairs the smoothing cost
    /// 0.2–0.4 dB for a little less grain on flat surfaces.
    #[arg(long, conflicts_with = "no_denoise")]
    denoise: bool,
    /// No denoising: the default (kept so that older command lines still run).
    #[arg(long, hide = true)]
    no_denoise: bool,
    /// Power of the tone curve the result is shown through (format spec §6.6): below 1
    /// lifts shadows more than highlights, as a camera's curve does between a short
    /// exposure and a longer one, and keeps their noise down. 1 only sets the exposure.
    #[arg(long, value_name = "G", default_value_t = CurveOptions::default().exponent, value_parser = tone_exponent)]
    tone: f32,
    /// Do not lift the shadows on their own: by default, where a scene's highlights (a
    /// lamp, a window, a sky) keep the tone curve from reaching the exposure, a gain map
    /// lifts the darker regions more than the lit ones (format spec §7.2.3).
    #[arg(long)]
    no_local: bool,
    /// Keep the colour of the darkest regions: by default, where the low image was lit
    /// within its noise of black, the colour the curve would lift out of the noise and
    /// the sensor's black level is moved towards grey (format spec §7.2.4).
    #[arg(long)]
    keep_shadow_colour: bool,
    /// Keep the Gaussians that stage 1 fitted to the noise of a dark capture: by default,
    /// a `sum` file's Gaussians whose colour stands within three noise levels of what
    /// their footprint can resolve are shrunk or removed first, so that the lift does not
    /// show them as black dots and bright needles on flat surfaces (format spec §7.2.5).
    #[arg(long)]
    keep_speckle: bool,
    /// Seed of the fit's initialization.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bar and no summary line.
    #[arg(long)]
    quiet: bool,
    /// Print the loss terms (unweighted) every 50 iterations, to tune `--weights`.
    #[arg(long, conflicts_with = "quiet")]
    verbose: bool,
}

fn read_all(path: &Path) -> Result<Vec<u8>, Failure> {
    let mut bytes = Vec::new();
    io::open_input(path)
        .and_then(|mut r| r.read_to_end(&mut bytes))
        .map_err(|e| Failure(format!("{}: {e}", path.display())))?;
    Ok(bytes)
}

fn parse(path: &Path, bytes: &[u8]) -> Result<ChunkedFile, Failure> {
    ChunkedFile::parse(bytes, Limits::default())
        .map_err(|e| Failure(format!("{}: {e}", path.display())))
}

pub fn run(args: Args) -> Result<(), Failure> {
    check(&args)?;
    if crate::batch::is_batch(&args.inputs, args.output.as_deref()) {
        return run_batch(&args);
    }
    let input = &args.inputs[0];
    if args.in_place && input == Path::new("-") {
        return Err(Failure(
            "--in-place needs a file, not standard input".into(),
        ));
    }
    let dest = args.output.clone().unwrap_or_else(|| input.clone());
    let bar = io::progress_bar(u64::from(args.iterations), args.quiet, io::ITERATIONS_BAR);
    let mut progress = |p: &gsi::enhance::fit::Progress| {
        bar.set_position(u64::from(p.iteration));
        if args.verbose && (p.iteration % 50 == 0 || p.iteration == p.iterations) {
            let (t, m) = (&p.terms, &p.map);
            bar.suspend(|| {
                eprintln!(
                    "it {:>5}  total {:.4}  exposure {:.4}  hue {:.4}  spatial {:.4}  colour {:.4}  contrast {:.4}  tv {:.2e}  entropy {:.3}",
                    p.iteration, t.total, t.exposure, t.hue, t.spatial, t.colour, t.contrast, m.tv, m.entropy
                )
            });
        }
        if p.iteration % 10 == 0 {
            bar.set_message(format!("loss {:.3}", p.terms.total));
        }
    };
    let lines = enhance_file(&args, input, &dest, &OnceLock::new(), &mut progress);
    bar.finish_and_clear();
    for line in lines? {
        if !args.quiet {
            eprintln!("{line}");
        }
    }
    Ok(())
}

fn parse_exposure(s: &str) -> Result<Exposure, String> {
    if s == "auto" {
        return Ok(Exposure::Metered);
    }
    match s.parse::<f32>() {
        Ok(e) if e > 0.0 && e < 1.0 => Ok(Exposure::Exactly(e)),
        _ => Err(format!("{s}: a mean luma in (0, 1), or `auto`")),
    }
}

fn tone_exponent(s: &str) -> Result<f32, String> {
    let max = gsi::format::MAX_TONE_EXPONENT;
    match s.parse::<f32>() {
        Ok(g) if g > 0.0 && g <= max => Ok(g),
        _ => Err(format!("{s}: an exponent in (0, {max}]")),
    }
}

/// The options' own checks, before any file is read.
fn check(args: &Args) -> Result<(), Failure> {
    if args.iterations == 0 {
        return Err(Failure("--iterations must be at least 1".into()));
    }
    let most = usize::from(gsi::format::MAX_EXPERTS);
    if !(1..=most).contains(&args.experts) {
        return Err(Failure(format!(
            "--experts {} must be in 1..={most}",
            args.experts
        )));
    }
    if !(args.learning_rate.is_finite() && args.learning_rate > 0.0) {
        return Err(Failure(format!(
            "--learning-rate {} must be positive",
            args.learning_rate
        )));
    }
    options(args).map(|_| ())
}

/// `gsi enhance` of many files, in place or into the folder `args.output`.
fn run_batch(args: &Args) -> Result<(), Failure> {
    let files = crate::batch::expand(&args.inputs, &["gsi"])?;
    let jobs = match &args.output {
        Some(dir) => crate::batch::plan(files, dir, "gsi")?,
        None => files
            .into_iter()
            .map(|f| crate::batch::Job {
                output: f.clone(),
                input: f,
            })
            .collect(),
    };
    let fits = !args.revert && args.apply_from.is_none();
    let gpu = OnceLock::new();
    if fits {
        device(args, &gpu)?;
    }
    let parallel = crate::batch::parallel(args.jobs, gpu.get().is_some_and(Option::is_some))?;
    let skip = |job: &crate::batch::Job| {
        if args.force || args.revert || args.apply_from.is_some() {
            return None;
        }
        let bytes = std::fs::read(&job.output).ok()?;
        let file = ChunkedFile::parse(&bytes, Limits::default()).ok()?;
        let enhanced = file.chunks.iter().any(|c| c.ty == ChunkType::ENHANCER);
        match (args.in_place, enhanced) {
            (true, true) => Some("enhanced before (--force enhances it again)".to_string()),
            (true, false) => None,
            (false, _) => Some("a valid .gsi file is there (--force enhances again)".to_string()),
        }
    };
    crate::batch::run(&jobs, parallel, args.quiet, skip, |job, report| {
        let iterations = args.iterations.max(1) as f32;
        let mut progress =
            |p: &gsi::enhance::fit::Progress| report(p.iteration as f32 / iterations);
        let lines = enhance_file(args, &job.input, &job.output, &gpu, &mut progress)?;
        Ok(lines.join("; "))
    })
}

/// The device a fit runs on, opened the first time one is asked for: a file that needs
/// no fit starts no GPU.
fn device<'g>(
    args: &Args,
    cell: &'g OnceLock<Option<gsi::gpu::Gpu>>,
) -> Result<Option<&'g gsi::gpu::Gpu>, Failure> {
    if let Some(gpu) = cell.get() {
        return Ok(gpu.as_ref());
    }
    let opened = crate::device::open(args.device, "enhancing", args.quiet)?;
    Ok(cell.get_or_init(|| opened).as_ref())
}

/// Enhance (or revert, or apply an enhancer to) `input`, writing `dest`; the lines to
/// tell the user. A fit runs on [`device`]`(args, gpu)`.
fn enhance_file(
    args: &Args,
    input: &Path,
    dest: &Path,
    gpu: &OnceLock<Option<gsi::gpu::Gpu>>,
    progress: &mut dyn FnMut(&gsi::enhance::fit::Progress),
) -> Result<Vec<String>, Failure> {
    let named = |e: gsi::format::Error| Failure(format!("{}: {e}", input.display()));
    let limits = Limits::default();
    let bytes = read_all(input)?;
    let file = parse(input, &bytes)?;
    let keep = !args.discard_original;
    let mut lines = Vec::new();

    let out = if args.revert {
        file.revert().map_err(named)?
    } else if let Some(src) = &args.apply_from {
        let source = parse(src, &read_all(src)?)?;
        enhance::apply_from(&file, &source, keep, &limits).map_err(named)?
    } else {
        let opts = options(args)?;
        let on = device(args, gpu)?.map_or(gsi::Device::Cpu, gsi::Device::Gpu);
        let start = std::time::Instant::now();
        let outcome = enhance::enhance(&file, &opts, keep, &limits, on, progress).map_err(named)?;
        let done = match outcome {
            enhance::Outcome::Enhanced(done) => done,
            enhance::Outcome::NotLowLight(a) => {
                lines.push(format!(
                    "{}: {a}: {}, left unchanged (--force enhances it anyway)",
                    input.display(),
                    a.verdict()
                ));
                if !args.in_place {
                    write(dest, &bytes)?;
                }
                return Ok(lines);
            }
            enhance::Outcome::OriginalDiscarded => {
                return Err(Failure(format!(
                    "{}: already enhanced and its original colours were discarded; --force enhances the enhanced colours again",
                    input.display()
                )))
            }
        };
        let fitted = &done.fitted;
        for why in [&fitted.fallback, &fitted.denoise_skipped]
            .into_iter()
            .flatten()
        {
            lines.push(format!("gsi: {why}"));
        }
        let aim = match &done.plan {
            Some(p) if p.gain.is_some() => format!(
                " (aimed at {:.3}; shadows lifted on their own, beta {:.2})",
                p.target, p.beta
            ),
            Some(p) if p.capped => {
                format!(" (aimed at {:.3}; held back by the highlights)", p.target)
            }
            Some(p) => format!(" (aimed at {:.3})", p.target),
            None => String::new(),
        };
        lines.push(format!(
            "enhanced: {:.0}% under-exposed, mean luma {:.3} -> {:.3}{aim}, K {}, {} iterations, {:.1} s",
            100.0 * done.assessment.dark_share,
            done.mean_luma.0,
            done.mean_luma.1,
            opts.experts,
            opts.iterations,
            start.elapsed().as_secs_f64()
        ));
        done.bytes
    };
    write(dest, &out)?;
    lines.push(format!("{}: {} bytes", dest.display(), out.len()));
    Ok(lines)
}

/// The fit's options from the command line.
fn options(args: &Args) -> Result<EnhanceOptions, Failure> {
    let weights = match &args.weights {
        None => EnhanceOptions::default().weights,
        Some(w) if w.len() == 7 && w.iter().all(|x| x.is_finite() && *x >= 0.0) => {
            let mut a = [0.0; 7];
            a.copy_from_slice(w);
            gsi::enhance::loss::LossWeights::from_array(a)
        }
        Some(w) => {
            return Err(Failure(format!(
                "--weights {w:?}: seven finite, non-negative numbers are needed"
            )))
        }
    };
    let defaults = EnhanceOptions::default();
    Ok(EnhanceOptions {
        weights,
        exposure: args.exposure.unwrap_or_default(),
        learning_rate: args.learning_rate,
        iterations: args.iterations,
        experts: args.experts,
        seed: args.seed,
        force: args.force,
        denoise: args
            .denoise
            .then(gsi::enhance::denoise::DenoiseOptions::default),
        curve: Some(CurveOptions {
            exponent: args.tone,
            local: !args.no_local,
            chroma: !args.keep_shadow_colour,
        }),
        speckle: !args.keep_speckle,
        ..defaults
    })
}

fn write(dest: &Path, bytes: &[u8]) -> Result<(), Failure> {
    io::write_output(dest, bytes).map_err(|e| Failure(format!("{}: {e}", dest.display())))
}
