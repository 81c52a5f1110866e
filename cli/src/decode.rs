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
    keep_freed_memory();
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
    render_on_this_thread_too();
    decode_file(f, &args.output, format, &args, gpu.as_ref())
}

/// Have glibc's `malloc` reuse freed memory rather than unmap it. By default each block of
/// 128 KiB or more gets a mapping of its own, unmapped when freed, and a free top of the
/// heap over 128 KiB is given back: a decode's arrays (codes, dequantized attributes,
/// projected Gaussians, the window of rows) are of that size, so each was faulted in
/// afresh, a page at a time (2–3 µs a page on the virtual machine measured), even where
/// an array freed before it could have held it. Raised for the decode, a process that
/// lives for one file or a batch of them, the freed pages are reused; kodim23 to PPM took
/// 0.3–0.5 ms less CPU (101 paired processes); kodim23's encode gained nothing (+1 %
/// CPU, 3 paired runs), so only the decode sets them. The library leaves the process's
/// allocator alone; this is the program's choice.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` sets parameters of the allocator, which it applies under its own
    // lock; it is called before any thread of this process is started.
    unsafe {
        // 32 MiB, glibc's largest mapping threshold on 64-bit targets; a larger block
        // (a whole 12 MP image) still gets its own mapping.
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 128 << 20);
    }
}

/// Make this thread one of the render's threads (the first of rayon's global pool, whose
/// size is as rayon's default), rather than one that hands each step of the render to
/// the pool and sleeps until it is done: one thread fewer to start, and no hand-over and
/// wake-up per step. kodim23 to PPM: 0.3 ms less CPU and 0.5 ms less wall time (101
/// paired processes). Not for a batch, whose files are decoded on threads of their own
/// while this one only waits for them.
///
/// Called once the file is parsed, just before the render: started before the parse, the
/// pool's other thread had nothing to do for its 1.5 ms (an idle rayon thread yields a
/// while before it sleeps). kodim23 to PPM, 61 paired processes: 0.14 ms less CPU and
/// 0.28 ms less wall time started here. (A pool whose thread is never given work costs
/// 0.2 ms of CPU over one thread alone: a 0.25 bpp file decoded to 16×16.)
fn render_on_this_thread_too() {
    // An error means that the pool exists already, as it is: nothing to do.
    let _ = rayon::ThreadPoolBuilder::new()
        .use_current_thread()
        .build_global();
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
    // The codes are not needed once dequantized: freed, the render reuses their pages.
    drop(f);
    let named = |Failure(e)| Failure(format!("{}: {e}", output.display()));
    if gpu.is_none() && format == OutputFormat::Pnm {
        // A PPM is its header and then its rows, written a window at a time as they are
        // rendered: the image is never held whole (a 12 MP decode's 36 MB), nor are its
        // pages faulted in. (PNG stays whole: the `png` crate's streaming writer, at the
        // `image` crate's settings, measured 4–10 % slower.)
        return io::write_with(output, |out| -> Result<(), Failure> {
            out.write_all(&ppm_header(w, ht))?;
            Ok(render::render_rgb8_rows(scene, w, ht, &limits, |rows| {
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
