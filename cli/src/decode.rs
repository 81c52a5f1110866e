//! `gsi decode`: render a file to an image at any size.

use crate::device::{self, DeviceArg};
use crate::image_io::{ppm_header, OutputFormat};
use crate::{io, read_gsi, Failure};
use gsi::format::Limits;
use gsi::render;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// The .gsi file (`-` for standard input). Several files, or a folder (its .gsi
    /// files), make a batch: then OUTPUT is a folder, and each file is written there as
    /// `<name>.<--format>`.
    #[arg(required = true, value_name = "FILE")]
    files: Vec<PathBuf>,
    /// Output image by extension: .png, .jpg (quality 95), .webp (lossless) or .ppm (`-`:
    /// PNG on standard output); or the folder of a batch.
    #[arg(short, long)]
    output: PathBuf,
    /// The format of the images written: png, jpg, webp or ppm. By default PNG in a
    /// batch, and the output's extension for one file.
    #[arg(long)]
    format: Option<String>,
    /// In a batch, decode again files whose output already exists and is a readable
    /// image (by default they are skipped).
    #[arg(long)]
    force: bool,
    /// In a batch, how many files are decoded at once (default: one per core, at most 4; one
    /// on a GPU).
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
    /// Output width in pixels (height follows the aspect ratio unless given).
    #[arg(long, conflicts_with = "scale")]
    width: Option<u32>,
    /// Output height in pixels (width follows the aspect ratio unless given).
    #[arg(long, conflicts_with = "scale")]
    height: Option<u32>,
    /// Scale factor applied to the stored size, e.g. 2 or 0.5.
    #[arg(long)]
    scale: Option<f64>,
    /// Where to render: `auto` (as `cpu`) renders on the CPU, which decoded an image
    /// many times faster than a GPU with its start-up (BENCHMARKS.md); `gpu` uses any
    /// adapter wgpu offers, software ones included, and fails when there is none.
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    device: DeviceArg,
}

/// The GPU a decode renders on: only one asked for by `--device gpu`. Unlike a fit,
/// whose steps repay a GPU's start-up many times over, a decode is one render, and the
/// start-up costs more than the render: on a machine with an NVIDIA H200 and 16 cores, a
/// whole `gsi decode` of kodim23 at 1 bpp took 267 ms with `--device gpu` against 14 ms
/// with `--device cpu`, and 599 ms against 70 ms at 4243×2829 (BENCHMARKS.md). Where there
/// is no GPU, looking for one (wgpu asking Vulkan's drivers, a software one among them)
/// made the development machine's 24 ms decode 88 ms.
fn decode_device(device: DeviceArg) -> Result<Option<gsi::gpu::Gpu>, Failure> {
    match device {
        DeviceArg::Gpu => device::open(device, "decoding", false),
        DeviceArg::Auto | DeviceArg::Cpu => Ok(None),
    }
}

/// Output size from the stored size and the requested width/height/scale.
fn output_size(w: u32, h: u32, args: &Args) -> Result<(u32, u32), Failure> {
    let fit = |x: f64| -> Result<u32, Failure> {
        if x.is_finite() && x >= 0.5 && x < f64::from(u32::MAX) {
            Ok(x.round() as u32)
        } else {
            Err(Failure(format!("output size {x} is out of range")))
        }
    };
    let (wf, hf) = (f64::from(w), f64::from(h));
    match (args.width, args.height, args.scale) {
        (_, _, Some(s)) if !(s.is_finite() && s > 0.0) => {
            Err(Failure(format!("scale {s} must be positive")))
        }
        (_, _, Some(s)) => Ok((fit(wf * s)?, fit(hf * s)?)),
        (width, height, None) => Ok(gsi::scaled_size((w, h), width, height)?),
    }
}

pub fn run(args: Args) -> Result<(), Failure> {
    if crate::batch::is_batch(&args.files, Some(&args.output)) {
        return run_batch(&args);
    }
    // Input and output are checked before any rendering (or GPU start-up).
    let format = match &args.format {
        Some(f) => OutputFormat::named(f)?,
        None => OutputFormat::of(&args.output)?,
    };
    let file = &args.files[0];
    let f = read_gsi(file)?;
    let h = &f.records.header;
    let (w, ht) = output_size(h.width, h.height, &args)?;
    Limits::default().check_output(w, ht)?;
    let gpu = decode_device(args.device)?;
    decode_file(f, &args.output, format, &args, gpu.as_ref())
}

/// `gsi decode` of many files into the folder `args.output`.
fn run_batch(args: &Args) -> Result<(), Failure> {
    let ext = args.format.as_deref().unwrap_or("png");
    let format = OutputFormat::named(ext)?;
    let files = crate::batch::expand(&args.files, &["gsi"])?;
    let jobs = crate::batch::plan(files, &args.output, ext)?;
    let gpu = decode_device(args.device)?;
    let parallel = crate::batch::parallel(args.jobs, gpu.is_some())?;
    let skip = |job: &crate::batch::Job| {
        let readable = !args.force && image::image_dimensions(&job.output).is_ok();
        readable.then(|| "an image is there (--force decodes it again)".to_string())
    };
    crate::batch::run(&jobs, parallel, false, skip, |job, _| {
        let f = read_gsi(&job.input)?;
        decode_file(f, &job.output, format, args, gpu.as_ref())
            .map_err(|Failure(e)| Failure(format!("{}: {e}", job.input.display())))?;
        Ok(format!("{}: written", job.output.display()))
    })
}

/// Render `f` at the size `args` ask for and write it to `output` as `format`.
fn decode_file(
    f: gsi::format::GsiFile,
    output: &Path,
    format: OutputFormat,
    args: &Args,
    gpu: Option<&gsi::gpu::Gpu>,
) -> Result<(), Failure> {
    let h = &f.records.header;
    let (w, ht) = output_size(h.width, h.height, args)?;
    let limits = Limits::default();
    limits.check_output(w, ht)?;
    let scene = f.records.to_scene();
    let named = |Failure(e)| Failure(format!("{}: {e}", output.display()));
    if gpu.is_none() && format == OutputFormat::Pnm {
        // A PPM is its header and then its rows, written a window at a time as they are
        // rendered: the image is never held whole (a 12 MP decode's 36 MB), nor are its
        // pages faulted in. (PNG stays whole: the `png` crate's streaming writer, at the
        // `image` crate's settings, measured 4–10 % slower.)
        return io::write_with(output, |out| -> Result<(), Failure> {
            out.write_all(&ppm_header(w, ht))?;
            Ok(render::render_rgb8_rows(&scene, w, ht, &limits, |rows| {
                out.write_all(rows)
            })?)
        })
        .map_err(named);
    }
    // On the CPU, tiles are blended a band at a time straight into the 8-bit output: 3
    // bytes per pixel in memory, not a float image and then an 8-bit copy.
    let rgb = match gpu {
        None => render::render_rgb8(&scene, w, ht, &limits)?,
        Some(gpu) => gpu.render(&scene, w, ht)?.to_rgb8(),
    };
    io::write_with(output, |out| format.write(out, &rgb, w, ht)).map_err(named)
}
