//! `gsi compare`: image-quality figures of an image against a reference, or of one image
//! alone. The conventions are those of `gsi::metrics` (and of `shared/data/README.md`).

use crate::{image_io, Failure};
use gsi::metrics::{self, Rgb8};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// The reference image, in any format `gsi encode` reads (`-` for standard input); with
    /// --no-reference,
    /// the image to measure.
    #[arg(value_name = "REF")]
    reference: PathBuf,
    /// The image to compare with REF (for LOE, REF is the enhancement's input).
    #[arg(
        value_name = "IMG",
        required_unless_present = "no_reference",
        conflicts_with = "no_reference"
    )]
    image: Option<PathBuf>,
    /// Measure REF alone: DE, EME and NIQE (NIQE only for images of at least 96×96).
    #[arg(long)]
    no_reference: bool,
    /// Print JSON instead of text. An infinite PSNR (identical images) is `null`.
    #[arg(long)]
    json: bool,
}

/// An 8-bit RGB image as the metrics take it: width, height, pixels.
struct Loaded(u32, u32, Vec<u8>);

impl Loaded {
    fn view(&self) -> Result<Rgb8<'_>, Failure> {
        Ok(Rgb8::new(self.0, self.1, &self.2)?)
    }
}

fn load(path: &Path) -> Result<Loaded, Failure> {
    let img = image_io::open(path)?.to_rgb8();
    Ok(Loaded(img.width(), img.height(), img.into_raw()))
}

pub fn run(args: Args) -> Result<(), Failure> {
    let first = load(&args.reference)?;
    let rows: Vec<(&str, f64, &str)> = match &args.image {
        None => {
            let r = metrics::no_reference(first.view()?);
            let mut rows = vec![("de", r.de, "bits"), ("eme", r.eme, "")];
            rows.extend(r.niqe.map(|v| ("niqe", v, "")));
            rows
        }
        Some(path) => {
            let second = load(path)?;
            let r = metrics::full_reference(first.view()?, second.view()?).map_err(|e| {
                Failure(format!(
                    "{} against {}: {e}",
                    path.display(),
                    args.reference.display()
                ))
            })?;
            vec![
                ("psnr", r.psnr, "dB"),
                ("ssim", r.ssim, ""),
                ("ms_ssim", r.ms_ssim, ""),
                ("psnr_gm", r.psnr_gm, "dB"),
                ("ssim_gm", r.ssim_gm, ""),
                ("loe", r.loe, ""),
                ("de", r.de, "bits"),
                ("eme", r.eme, ""),
            ]
        }
    };
    if args.json {
        let map: serde_json::Map<String, Value> = rows
            .iter()
            .map(|&(k, v, _)| (k.to_string(), finite_or_null(v)))
            .collect();
        crate::io::print_line(&serde_json::to_string_pretty(&Value::Object(map))?)?;
    } else {
        for (k, v, unit) in rows {
            let v = if v.is_finite() {
                format!("{v:>10.4}")
            } else {
                format!("{:>10}", "inf")
            };
            crate::io::print_line(format!("{k:<8} {v} {unit}").trim_end())?;
        }
    }
    Ok(())
}

/// JSON has no infinity: identical images (infinite PSNR) print `null`.
fn finite_or_null(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}
