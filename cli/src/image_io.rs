//! Images in and out of the CLI, through the `image` crate: the formats users bring
//! (PNG, JPEG, BMP, TIFF, WebP, PNM; 8 or 16 bit; grey, RGB, RGBA), read by content rather
//! than by name and turned upright by their EXIF orientation, and the formats
//! `gsi decode` writes. The library's lean decoder knows none of this.

use crate::{io, Failure};
use image::{DynamicImage, ImageDecoder, ImageReader};
use std::io::{Cursor, Read, Write};
use std::path::Path;

/// The formats [`open`] reads, for error messages.
const READS: &str = "PNG, JPEG, BMP, TIFF, WebP or PNM";

/// Read the image at `path` (`-`: standard input) in whatever format its bytes are,
/// upright: an EXIF orientation (JPEG, PNG, TIFF and WebP carry one) is applied, as
/// viewers do, so that a phone photograph is fitted the way it is seen. Decoding is
/// bounded by the `image` crate's default limits (512 MiB per allocation).
pub fn open(path: &Path) -> Result<DynamicImage, Failure> {
    let named = |e: &dyn std::fmt::Display| Failure(format!("{}: {e}", path.display()));
    // Read once, whole: the JPEG check below needs every byte, and the decoders that
    // seek (TIFF) need a seekable source, which standard input is not.
    let mut bytes = Vec::new();
    io::open_input(path)
        .and_then(|mut r| r.read_to_end(&mut bytes))
        .map_err(|e| named(&e))?;
    let reader = ImageReader::new(Cursor::new(&bytes[..]))
        .with_guessed_format()
        .map_err(|e| named(&e))?;
    if reader.format().is_none() {
        return Err(named(&format_args!("not an image gsi reads ({READS})")));
    }
    // The JPEG decoder fills a stream cut short with grey and says nothing; a damaged
    // photograph is refused here instead of being fitted, missing half, without a word.
    if reader.format() == Some(image::ImageFormat::Jpeg) && !jpeg_reaches_its_end(&bytes) {
        return Err(named(
            &"the JPEG data ends before its end-of-image marker: the file is truncated or damaged",
        ));
    }
    let described = |e: image::ImageError| match e {
        image::ImageError::Unsupported(u) => named(&format_args!("{u} (gsi reads {READS})")),
        other => named(&other),
    };
    let mut decoder = reader.into_decoder().map_err(described)?;
    // An unreadable orientation tag is no reason to refuse the pixels.
    let orientation = decoder
        .orientation()
        .unwrap_or(image::metadata::Orientation::NoTransforms);
    let mut img = DynamicImage::from_decoder(decoder).map_err(described)?;
    img.apply_orientation(orientation);
    Ok(img)
}

/// Whether a JPEG stream (ITU-T T.81 §B.1) reaches its end-of-image marker: the segments
/// from the start-of-image marker are walked by their lengths, each scan's entropy-coded
/// data up to the next marker that is not a restart (`FF 00` is a stuffed byte, `FF FF`
/// fill), until `FF D9`. A stream that runs out first was cut short. Bytes after the
/// marker (some cameras append data) are not looked at.
fn jpeg_reaches_its_end(b: &[u8]) -> bool {
    if !b.starts_with(&[0xFF, 0xD8]) {
        return false;
    }
    let mut i = 2;
    loop {
        if b.get(i) != Some(&0xFF) {
            return false;
        }
        while b.get(i) == Some(&0xFF) {
            i += 1;
        }
        let Some(&marker) = b.get(i) else {
            return false;
        };
        i += 1;
        match marker {
            0xD9 => return true,
            0x01 | 0xD0..=0xD7 => continue,
            _ => {}
        }
        let Some(len) = b
            .get(i..i + 2)
            .map(|l| usize::from(u16::from_be_bytes([l[0], l[1]])))
        else {
            return false;
        };
        if len < 2 || i + len > b.len() {
            return false;
        }
        i += len;
        if marker == 0xDA {
            // Entropy-coded data runs to the next marker other than RSTn.
            loop {
                let Some(at) = b[i..].iter().position(|&x| x == 0xFF) else {
                    return false;
                };
                let j = i + at;
                match b.get(j + 1) {
                    None => return false,
                    Some(0x00 | 0xD0..=0xD7 | 0xFF) => i = j + 1,
                    Some(_) => {
                        i = j;
                        break;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{jpeg_reaches_its_end, OutputFormat};

    #[test]
    fn a_ppm_is_its_header_and_the_pixels_themselves() {
        let rgb: Vec<u8> = (0..5 * 2 * 3).map(|i| i as u8).collect();
        let mut bytes = Vec::new();
        let Ok(()) = OutputFormat::Pnm.write(&mut bytes, &rgb, 5, 2) else {
            panic!("a 5×2 PPM refused")
        };
        assert_eq!(bytes, [super::ppm_header(5, 2), rgb.clone()].concat());
        let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
        assert_eq!((img.width(), img.height()), (5, 2));
        assert_eq!(img.as_raw(), &rgb);
        // Pixels that are not w × h × 3 bytes are refused by every format.
        for f in [OutputFormat::Pnm, OutputFormat::Png] {
            assert!(f.write(&mut Vec::new(), &rgb, 5, 3).is_err());
        }
    }

    /// A JPEG of `w`×`h` noise from the `image` crate's encoder.
    fn jpeg(w: u32, h: u32) -> Vec<u8> {
        let px: Vec<u8> = (0..w * h * 3)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
            .collect();
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .encode(&px, w, h, image::ExtendedColorType::Rgb8)
            .unwrap();
        out
    }

    #[test]
    fn a_whole_jpeg_reaches_its_end_and_a_cut_one_does_not() {
        let whole = jpeg(64, 48);
        assert!(jpeg_reaches_its_end(&whole));
        let mut trailing = whole.clone();
        trailing.extend_from_slice(b"appended by a camera");
        assert!(jpeg_reaches_its_end(&trailing));
        for cut in [2, 3, 20, whole.len() / 2, whole.len() - 2, whole.len() - 1] {
            assert!(!jpeg_reaches_its_end(&whole[..cut]), "cut at {cut}");
        }
        assert!(!jpeg_reaches_its_end(b"not a jpeg"));
        assert!(!jpeg_reaches_its_end(&[]));
    }
}

/// What `gsi decode` writes, chosen by the output's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    Png,
    /// Baseline JPEG at quality 95.
    Jpeg,
    /// Lossless WebP (the `image` crate's encoder writes no lossy WebP).
    WebP,
    /// Binary PPM (P6).
    Pnm,
}

impl OutputFormat {
    /// The format for `path`: by extension, PNG where there is none (and for `-`).
    pub fn of(path: &Path) -> Result<OutputFormat, Failure> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            None | Some("png") => Ok(OutputFormat::Png),
            Some("jpg" | "jpeg") => Ok(OutputFormat::Jpeg),
            Some("webp") => Ok(OutputFormat::WebP),
            Some("ppm" | "pnm") => Ok(OutputFormat::Pnm),
            Some(other) => Err(Failure(format!(
                "unsupported output format .{other} (use .png, .jpg, .webp or .ppm)"
            ))),
        }
    }

    /// The format named `name` (an extension without its dot, as `--format` takes it).
    pub fn named(name: &str) -> Result<OutputFormat, Failure> {
        OutputFormat::of(Path::new(&format!("x.{name}")))
    }

    /// Write `rgb` (8-bit RGB, `w`×`h`) to `out` in this format.
    pub fn write(self, out: &mut dyn Write, rgb: &[u8], w: u32, h: u32) -> Result<(), Failure> {
        use image::ImageEncoder;
        if rgb.len() as u64 != u64::from(w) * u64::from(h) * 3 {
            return Err(Failure(format!(
                "{} bytes of RGB for a {w}×{h} image",
                rgb.len()
            )));
        }
        let color = image::ExtendedColorType::Rgb8;
        match self {
            OutputFormat::Png => {
                // A render of Gaussians is smooth: Paeth's filter on every row wrote
                // files from 1.5 % smaller to 2.1 % larger (median 0.1 % smaller) than
                // a filter chosen row by row, in 15 % less time (median; 18 fitted
                // files of Kodak, photos12 and mef13 at their own sizes).
                use image::codecs::png::{CompressionType, FilterType, PngEncoder};
                PngEncoder::new_with_quality(out, CompressionType::Fast, FilterType::Paeth)
                    .write_image(rgb, w, h, color)?
            }
            OutputFormat::Jpeg => image::codecs::jpeg::JpegEncoder::new_with_quality(out, 95)
                .write_image(rgb, w, h, color)?,
            OutputFormat::WebP => {
                image::codecs::webp::WebPEncoder::new_lossless(out).write_image(rgb, w, h, color)?
            }
            OutputFormat::Pnm => {
                out.write_all(&ppm_header(w, h))?;
                out.write_all(rgb)?;
            }
        }
        Ok(())
    }
}

/// The header of a binary PPM (P6) of `w`×`h` 8-bit RGB pixels: its pixel rows follow
/// it as they are, top to bottom, so a PPM can be written a few rows at a time.
pub fn ppm_header(w: u32, h: u32) -> Vec<u8> {
    format!("P6\n{w} {h}\n255\n").into_bytes()
}
