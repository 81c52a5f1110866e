//! `gsi decode`: render a file to an image at any size.

use crate::device::{self, DeviceArg};
use crate::{io, read_gsi, Failure};
use gsi::format::Limits;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// The .gsi file (`-` for standard input).
    file: PathBuf,
    /// Output image, PNG or JPEG by extension (`-`: PNG on standard output).
    #[arg(short, long)]
    output: PathBuf,
    /// Output width in pixels (height follows the aspect ratio unless given).
    #[arg(long, conflicts_with = "scale")]
    width: Option<u32>,
    /// Output height in pixels (width follows the aspect ratio unless given).
    #[arg(long, conflicts_with = "scale")]
    height: Option<u32>,
    /// Scale factor applied to the stored size, e.g. 2 or 0.5.
    #[arg(long)]
    scale: Option<f64>,
    /// Where to render: `auto` uses a hardware GPU when there is one (and says so when
    /// it falls back to the CPU); `gpu` uses any adapter wgpu offers, software ones
    /// included, and fails when there is none.
    #[arg(long, value_enum, default_value_t = DeviceArg::Auto)]
    device: DeviceArg,
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
        (Some(ow), Some(oh), None) => Ok((ow, oh)),
        (Some(ow), None, None) => Ok((ow, fit(f64::from(ow) * hf / wf)?.max(1))),
        (None, Some(oh), None) => Ok((fit(f64::from(oh) * wf / hf)?.max(1), oh)),
        (None, None, None) => Ok((w, h)),
    }
}

pub fn run(args: Args) -> Result<(), Failure> {
    let f = read_gsi(&args.file)?;
    let h = &f.records.header;
    let (w, ht) = output_size(h.width, h.height, &args)?;
    Limits::default().check_output(w, ht)?;
    // Refuse an unsupported output format before any rendering (or GPU start-up).
    let format = format_of(&args.output)?;
    let scene = f.records.to_scene();
    // On the CPU, tiles are blended a band at a time straight into the 8-bit output: 3
    // bytes per pixel in memory, not a float image and then an 8-bit copy.
    let cpu = |scene: &gsi::Scene| gsi::render::render_rgb8(scene, w, ht, &Limits::default());
    let rgb = match device::open(args.device, "decoding", false)? {
        None => cpu(&scene)?,
        Some(gpu) => match gpu.render(&scene, w, ht) {
            Ok(image) => image.to_rgb8(),
            // Too large for this adapter's buffers: `auto` falls back, `gpu` fails.
            Err(e)
                if e.kind() == gsi::gpu::ErrorKind::LimitExceeded
                    && args.device == DeviceArg::Auto =>
            {
                eprintln!("gsi: {e}; decoding on the CPU");
                cpu(&scene)?
            }
            Err(e) => return Err(e.into()),
        },
    };
    let bytes = encode_image(&rgb, w, ht, format)?;
    io::write_output(&args.output, &bytes)
        .map_err(|e| Failure(format!("{}: {e}", args.output.display())))
}

/// What `gsi decode` writes.
#[derive(Clone, Copy)]
enum ImageFormat {
    Png,
    Jpeg,
}

/// PNG unless the output path ends in .jpg/.jpeg; other extensions are refused.
fn format_of(path: &Path) -> Result<ImageFormat, Failure> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("jpg" | "jpeg") => Ok(ImageFormat::Jpeg),
        None | Some("png") => Ok(ImageFormat::Png),
        Some(other) => Err(Failure(format!(
            "unsupported output format .{other} (use .png or .jpg)"
        ))),
    }
}

fn encode_image(rgb: &[u8], w: u32, h: u32, format: ImageFormat) -> Result<Vec<u8>, Failure> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    let color = image::ExtendedColorType::Rgb8;
    match format {
        ImageFormat::Jpeg => image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 95)
            .write_image(rgb, w, h, color)?,
        ImageFormat::Png => {
            image::codecs::png::PngEncoder::new(&mut out).write_image(rgb, w, h, color)?
        }
    }
    Ok(out)
}
