//! `gsi encode`: fit Gaussians to an image and write a .gsi file.

use crate::device::{self, DeviceArg};
use crate::{io, Failure};
use gsi::fit::{self, Budget, EncodeOptions, Init, Loss, Target};
use gsi::model::Blend;
use std::io::{IsTerminal, Read};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// Input image: PNG, JPEG (8 or 16 bit; grey, RGB or RGBA). `-` reads standard input.
    input: PathBuf,
    /// Output .gsi file (`-` for standard output).
    #[arg(short, long)]
    output: PathBuf,
    /// Number of Gaussians.
    #[arg(long, group = "budget")]
    gaussians: Option<usize>,
    /// Target size in bits per pixel (the file is shrunk until it fits).
    #[arg(long, group = "budget")]
    bpp: Option<f32>,
    /// Target PSNR in dB of the stored file (Gaussians are added until it is met).
    #[arg(long, group = "budget")]
    target_psnr: Option<f32>,
    /// Optimizer iterations.
    #[arg(long, default_value_t = 400)]
    iterations: u32,
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

#[derive(Clone, Copy, clap::ValueEnum)]
enum BlendArg {
    Sum,
    Alpha,
}

/// Load an image as RGB in `[0, 1]`, converting grey, alpha and 16-bit explicitly:
/// grey is replicated, alpha is dropped (the image is taken as composited), 16-bit
/// values are scaled by 1/65535.
pub fn load_image(path: &Path) -> Result<Target, Failure> {
    let named = |e: &dyn std::fmt::Display| Failure(format!("{}: {e}", path.display()));
    let img = if path == Path::new("-") {
        let mut bytes = Vec::new();
        std::io::stdin()
            .lock()
            .read_to_end(&mut bytes)
            .map_err(|e| named(&e))?;
        image::load_from_memory(&bytes)
    } else {
        image::ImageReader::open(path)
            .map_err(|e| named(&e))?
            .with_guessed_format()
            .map_err(|e| named(&e))?
            .decode()
    }
    .map_err(|e| named(&e))?;
    let (width, height) = (img.width(), img.height());
    let data: Vec<f32> = if img.color().bytes_per_pixel() / img.color().channel_count() > 1 {
        img.into_rgb32f().into_raw()
    } else {
        img.into_rgb8()
            .into_raw()
            .into_iter()
            .map(|v| f32::from(v) / 255.0)
            .collect()
    };
    Ok(Target {
        width,
        height,
        data,
    })
}

pub fn run(args: Args) -> Result<(), Failure> {
    let target = load_image(&args.input)?;
    let budget = match (args.gaussians, args.bpp, args.target_psnr) {
        (Some(n), _, _) => Budget::Gaussians(n),
        (_, Some(b), _) if b.is_finite() && b > 0.0 => Budget::Bpp(b),
        (_, Some(b), _) => return Err(Failure(format!("--bpp {b} must be positive"))),
        (_, _, Some(p)) if p.is_finite() && p > 0.0 => Budget::TargetPsnr(p),
        (_, _, Some(p)) => return Err(Failure(format!("--target-psnr {p} must be positive"))),
        _ => Budget::Bpp(1.0),
    };
    if args.iterations == 0 {
        return Err(Failure("--iterations must be at least 1".into()));
    }
    let opts = EncodeOptions {
        budget,
        iterations: args.iterations,
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
        ..EncodeOptions::default()
    };
    let show = !args.quiet && std::io::stderr().is_terminal();
    let bar = indicatif::ProgressBar::new(u64::from(args.iterations));
    if show {
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} it  {msg}  ETA {eta}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
    } else {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let mut progress = |p: &fit::Progress| {
        bar.set_length(u64::from(p.total));
        bar.set_position(u64::from(p.iteration));
        bar.set_message(format!("N {}  PSNR {:.2} dB", p.gaussians, p.psnr));
    };
    let gpu = device::open(args.device, "fitting", args.quiet)?;
    let on = gpu.as_ref().map_or(gsi::Device::Cpu, gsi::Device::Gpu);
    let encoded = fit::encode(&target, &opts, on, &mut progress)?;
    bar.finish_and_clear();
    if let (Some(why), false) = (&encoded.fallback, args.quiet) {
        eprintln!("gsi: {why}");
    }
    io::write_output(&args.output, &encoded.bytes)
        .map_err(|e| Failure(format!("{}: {e}", args.output.display())))?;
    if !args.quiet {
        let px = f64::from(target.width) * f64::from(target.height);
        let bytes = encoded.bytes.len() as f64;
        eprintln!(
            "N {}  {} bytes  {:.3} bpp  Cr {:.1}x  PSNR {:.2} dB",
            encoded.records.header.count,
            encoded.bytes.len(),
            bytes * 8.0 / px,
            3.0 * px / bytes,
            encoded.psnr
        );
    }
    Ok(())
}
