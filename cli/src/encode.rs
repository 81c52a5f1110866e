//! `gsi encode`: fit Gaussians to an image and write a .gsi file.

use crate::device::{self, DeviceArg};
use crate::{batch, image_io, io, Failure};
use gsi::fit::{self, Budget, EncodeOptions, Init, Loss, Target};
use gsi::format::BitDepths;
use gsi::model::Blend;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// Input image: PNG, JPEG, BMP, TIFF, WebP or PNM (8 or 16 bit; grey, RGB or RGBA),
    /// recognised by its bytes and turned upright by its EXIF orientation. `-` reads
    /// standard input. Several files, or a folder (its image files), make a batch:
    /// then OUTPUT is a folder, and each file is written there as `<name>.gsi`.
    #[arg(required = true, value_name = "INPUT")]
    inputs: Vec<PathBuf>,
    /// Output .gsi file (`-` for standard output), or the folder of a batch.
    #[arg(short, long)]
    output: PathBuf,
    /// In a batch, encode again files whose output already exists and is a valid .gsi
    /// file (by default they are skipped).
    #[arg(long)]
    force: bool,
    /// In a batch, how many files are encoded at once (default: one per core, at most 4; one
    /// on a GPU).
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
    /// Number of Gaussians (at least 1).
    #[arg(long, group = "budget", value_parser = clap::value_parser!(u32).range(1..))]
    gaussians: Option<u32>,
    /// Target size in bits per pixel (the file is shrunk until it fits).
    #[arg(long, group = "budget")]
    bpp: Option<f32>,
    /// Target PSNR in dB of the stored file (Gaussians are added until it is met).
    #[arg(long, group = "budget")]
    target_psnr: Option<f32>,
    /// From fast to thorough, 1..=9: each level a measured choice of optimizer steps,
    /// how many of them fit a reduced copy of the image first, and the colour solves
    /// (BENCHMARKS.md has the time and PSNR of each on Kodak).
    #[arg(long, default_value_t = fit::Effort::DEFAULT.level(),
          value_parser = clap::value_parser!(u8).range(1..=9))]
    effort: u8,
    /// Expert override of the effort level's optimizer steps (coarse ones included).
    #[arg(long)]
    iterations: Option<u32>,
    /// Expert override of the bit depths, `POSITION,COVARIANCE,COLOUR,OPACITY[,ANGLE]`
    /// (each 1..=24; without ANGLE, one bit under the covariance's scales); by default
    /// they are chosen from the image size (for 768×512 in `sum` mode: 12,6,8,6,8), and
    /// in `sum` mode the colour's from the fit's error (5 to 14 bits: coarser where the
    /// Gaussians cannot follow the texture, so that the bits buy more of them). In `sum`
    /// mode each angle keeps the bits its Gaussian's shape needs, ANGLE being the uniform
    /// depth whose noise they match (none for a round Gaussian, ANGLE + 2 for the thinnest),
    /// and each colour is stored at the precision of its footprint, COLOUR being the depth
    /// of the grid they share (a Gaussian's step halves for every 8/3 doublings of its area).
    #[arg(long, value_name = "P,C,K,O[,A]")]
    bits: Option<String>,
    /// Initialization: content-adaptive, or the paper's random cold start.
    #[arg(long, value_enum, default_value_t = InitArg::Adaptive)]
    init: InitArg,
    /// Blending: `sum` (GaussianImage) or `alpha` (front-to-back, paper Eq. 6-8).
    #[arg(long, value_enum, default_value_t = BlendArg::Sum)]
    blend: BlendArg,
    /// Loss: `l2` (mean squared error, what PSNR measures) or `l1-ms-ssim`, the paper's
    /// Eq. 9 with λ = 0.2.
    #[arg(long, value_enum, default_value_t = LossArg::L2)]
    loss: LossArg,
    /// Where the optimizer steps run: `auto` uses a hardware GPU when there is one, `gpu`
    /// any adapter (software ones included), `cpu` the CPU. Initialization, colour solves,
    /// pruning and the final measurement run on the CPU either way.
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    device: DeviceArg,
    /// Seed of every random choice; the same seed and thread count give the same file.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bar and no summary line.
    #[arg(long)]
    quiet: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum InitArg {
    Adaptive,
    Random,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum LossArg {
    L2,
    L1MsSsim,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum BlendArg {
    Sum,
    Alpha,
}

/// Load an image (any format [`image_io::open`] reads, upright) as RGB in `[0, 1]`,
/// converting grey, alpha and 16-bit explicitly: grey is replicated, alpha is dropped (the
/// image is taken as composited), 8- and 16-bit samples become `f32` as
/// [`gsi::RgbImage::from_rgb8`] and [`gsi::RgbImage::from_rgb16`] say (the Python package
/// takes arrays the same way), and float images are taken as they are.
pub fn load_image(path: &Path) -> Result<Target, Failure> {
    use image::DynamicImage as D;
    let img = image_io::open(path)?;
    let (width, height) = (img.width(), img.height());
    let target = match img {
        D::ImageRgb32F(_) | D::ImageRgba32F(_) => Some(Target {
            width,
            height,
            data: img.into_rgb32f().into_raw(),
        }),
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
            Target::from_rgb16(width, height, &img.into_rgb16().into_raw())
        }
        _ => Target::from_rgb8(width, height, &img.into_rgb8().into_raw()),
    };
    target.ok_or_else(|| Failure(format!("{}: {width}x{height} is too large", path.display())))
}

/// Resolution of the work bar.
const WORK_STEPS: u64 = 1000;

/// The image extensions a folder given as a batch's input is searched for.
const IMAGE_EXTENSIONS: &[&str] = &[
    "png", "jpg", "jpeg", "bmp", "tif", "tiff", "webp", "ppm", "pgm", "pnm",
];

fn options(args: &Args) -> Result<EncodeOptions, Failure> {
    let budget = match (args.gaussians, args.bpp, args.target_psnr) {
        (Some(n), _, _) => Budget::Gaussians(n as usize),
        (_, Some(b), _) if b.is_finite() && b > 0.0 => Budget::Bpp(b),
        (_, Some(b), _) => return Err(Failure(format!("--bpp {b} must be positive"))),
        (_, _, Some(p)) if p.is_finite() && p > 0.0 => Budget::TargetPsnr(p),
        (_, _, Some(p)) => return Err(Failure(format!("--target-psnr {p} must be positive"))),
        _ => Budget::Bpp(1.0),
    };
    if args.iterations == Some(0) {
        return Err(Failure("--iterations must be at least 1".into()));
    }
    let bits = args
        .bits
        .as_deref()
        .map(parse_bits)
        .transpose()?
        .map(|b| BitDepths {
            angle_by_shape: args.blend == BlendArg::Sum,
            color_by_footprint: false,
            ..b
        });
    let mut leveled = EncodeOptions::default();
    fit::Effort::new(args.effort)
        .ok_or_else(|| Failure(format!("--effort {} is not in 1..=9", args.effort)))?
        .apply(&mut leveled);
    Ok(EncodeOptions {
        bits,
        budget,
        iterations: args.iterations.unwrap_or(leveled.iterations),
        init: match args.init {
            InitArg::Adaptive => Init::Adaptive,
            InitArg::Random => Init::Random,
        },
        blend: match args.blend {
            BlendArg::Sum => Blend::Sum,
            BlendArg::Alpha => Blend::Alpha,
        },
        seed: args.seed,
        loss: match args.loss {
            LossArg::L2 => Loss::L2,
            LossArg::L1MsSsim => Loss::L1MsSsim { lambda: 0.2 },
        },
        ..leveled
    })
}

/// `--bits P,C,K,O[,A]`: four or five depths, each 1..=24. Without `A`, the angle takes
/// one bit fewer than the covariance's scales (the defaults name their angle apart:
/// [`gsi::fit::default_bits`]).
fn parse_bits(s: &str) -> Result<BitDepths, Failure> {
    let bad = || {
        Failure(format!(
            "--bits {s}: expected four or five depths 1..=24, as 12,8,8,6 or 12,8,8,6,7"
        ))
    };
    let d: Vec<u8> = s
        .split(',')
        .map(|x| x.trim().parse::<u8>().ok().filter(|b| (1..=24).contains(b)))
        .collect::<Option<_>>()
        .ok_or_else(bad)?;
    let (position, covariance, color, opacity, angle) = match d[..] {
        [p, c, k, o] => (p, c, k, o, c.saturating_sub(1).max(1)),
        [p, c, k, o, a] => (p, c, k, o, a),
        _ => return Err(bad()),
    };
    Ok(BitDepths {
        position,
        covariance,
        angle,
        angle_by_shape: false,
        color_by_footprint: false,
        color,
        opacity,
    })
}

/// Encode `target`, read from `input`, into `output`; the summary line.
fn encode_file(
    input: &Path,
    target: &Target,
    output: &Path,
    opts: &EncodeOptions,
    on: gsi::Device,
    progress: &mut dyn FnMut(&fit::Progress),
) -> Result<(fit::Encoded, String), Failure> {
    let encoded = fit::encode(target, opts, on, progress)
        .map_err(|e| Failure(format!("{}: {e}", input.display())))?;
    io::write_output(output, &encoded.bytes)
        .map_err(|e| Failure(format!("{}: {e}", output.display())))?;
    let px = f64::from(target.width) * f64::from(target.height);
    let bytes = encoded.bytes.len() as f64;
    let mut summary = format!(
        "N {}  {} bytes  {:.3} bpp  Cr {:.1}x  PSNR {:.2} dB (float fit {:.2})",
        encoded.records.header.count,
        encoded.bytes.len(),
        bytes * 8.0 / px,
        3.0 * px / bytes,
        encoded.psnr,
        encoded.float_psnr
    );
    if let Some(short) = shortfall(opts, &encoded) {
        summary = format!("{summary}; {short}");
    }
    Ok((encoded, summary))
}

/// What a `--target-psnr` the file fell short of says: the file is written all the same
/// (it is the best the encoder's bounded growth found), and the shortfall is printed even
/// under `--quiet`, as a missed `--bpp` is refused aloud.
fn shortfall(opts: &EncodeOptions, encoded: &fit::Encoded) -> Option<String> {
    match opts.budget {
        Budget::TargetPsnr(p) if encoded.psnr < f64::from(p) => Some(format!(
            "warning: --target-psnr {p} not reached ({:.2} dB with {} Gaussians, as many as \
             the encoder grows to); --gaussians or --bpp can ask for more",
            encoded.psnr, encoded.records.header.count
        )),
        _ => None,
    }
}

pub fn run(args: Args) -> Result<(), Failure> {
    let opts = options(&args)?;
    if batch::is_batch(&args.inputs, Some(&args.output)) {
        return run_batch(&args, &opts);
    }
    let input = &args.inputs[0];
    // The bar follows the work, not the steps: coarse steps are cheaper, and a bar that
    // counted them as full ones would promise an early finish.
    let bar = io::progress_bar(WORK_STEPS, args.quiet, io::WORK_BAR);
    let mut progress = |p: &fit::Progress| {
        bar.set_position((p.work * WORK_STEPS as f64) as u64);
        bar.set_message(format!(
            "it {}/{}  N {}  PSNR {:.2} dB",
            p.iteration, p.total, p.gaussians, p.psnr
        ));
    };
    // The image is read before the GPU starts: a bad input is refused at once.
    let target = load_image(input)?;
    let gpu = device::open(args.device, "fitting", args.quiet)?;
    let on = gpu.as_ref().map_or(gsi::Device::Cpu, gsi::Device::Gpu);
    let (encoded, summary) = encode_file(input, &target, &args.output, &opts, on, &mut progress)?;
    bar.finish_and_clear();
    if !args.quiet {
        if let Some(why) = &encoded.fallback {
            eprintln!("gsi: {why}");
        }
        eprintln!("{summary}");
    } else if let Some(short) = shortfall(&opts, &encoded) {
        eprintln!("gsi: {short}");
    }
    Ok(())
}

/// `gsi encode` of many files into the folder `args.output`.
fn run_batch(args: &Args, opts: &EncodeOptions) -> Result<(), Failure> {
    let inputs = batch::expand(&args.inputs, IMAGE_EXTENSIONS)?;
    let jobs = batch::plan(inputs, &args.output, "gsi")?;
    let gpu = device::open(args.device, "fitting", args.quiet)?;
    let parallel = batch::parallel(args.jobs, gpu.is_some())?;
    let skip = |job: &batch::Job| {
        let valid = !args.force
            && std::fs::File::open(&job.output).is_ok_and(|f| {
                gsi::format::read_file(std::io::BufReader::new(f), gsi::format::Limits::default())
                    .is_ok()
            });
        valid.then(|| "a valid .gsi file is there (--force encodes it again)".to_string())
    };
    batch::run(&jobs, parallel, args.quiet, skip, |job, report| {
        let on = gpu.as_ref().map_or(gsi::Device::Cpu, gsi::Device::Gpu);
        // The budget loops may add passes; the bar follows the work of the pass.
        let mut progress = |p: &fit::Progress| report(p.work as f32);
        let target = load_image(&job.input)?;
        let (encoded, summary) =
            encode_file(&job.input, &target, &job.output, opts, on, &mut progress)?;
        let fallback = encoded
            .fallback
            .map(|w| format!(" ({w})"))
            .unwrap_or_default();
        Ok(format!("{}: {summary}{fallback}", job.output.display()))
    })
}
