//! `image::open("x.gsi")` in any Rust program: an [`image::ImageDecoder`] for `.gsi` files,
//! and [`register`], which installs it in the `image` crate's decoding hooks (by the
//! `.gsi` extension and by the file signature).
//!
//! The `image` crate asks a decoder for its size before decoding, so a file decodes at its
//! stored size; render at another size with [`crate::Reader`]. Decoding honours both the
//! default [`crate::Limits`] and the `image::Limits` the caller sets.

use std::io::Read;

use image::error::{
    DecodingError, ImageFormatHint, LimitError, LimitErrorKind, ParameterError, ParameterErrorKind,
};
use image::{ColorType, ImageDecoder, ImageError, ImageResult};

use crate::format::{ErrorKind, SIGNATURE};
use crate::{Limits, Reader};

/// A `.gsi` file as an `image` decoder: 8-bit RGB at the stored size.
#[derive(Debug)]
pub struct GsiDecoder {
    reader: Reader,
}

impl GsiDecoder {
    /// Read a whole `.gsi` file (with the default [`Limits`]).
    pub fn new<R: Read>(input: R) -> ImageResult<GsiDecoder> {
        Ok(GsiDecoder {
            reader: Reader::with_limits(input, Limits::default()).map_err(to_image_error)?,
        })
    }
}

/// `gsi`'s error as the `image` crate's: limits as limits, bad files as decoding errors.
fn to_image_error(e: crate::Error) -> ImageError {
    match e.kind() {
        ErrorKind::LimitExceeded => {
            ImageError::Limits(LimitError::from_kind(LimitErrorKind::InsufficientMemory))
        }
        ErrorKind::Io => ImageError::IoError(std::io::Error::other(e)),
        _ => ImageError::Decoding(DecodingError::new(ImageFormatHint::Name("gsi".into()), e)),
    }
}

impl ImageDecoder for GsiDecoder {
    fn dimensions(&self) -> (u32, u32) {
        self.reader.output_size()
    }

    fn color_type(&self) -> ColorType {
        ColorType::Rgb8
    }

    fn read_image(self, buf: &mut [u8]) -> ImageResult<()> {
        if buf.len() as u64 != self.total_bytes() {
            return Err(ImageError::Parameter(ParameterError::from_kind(
                ParameterErrorKind::DimensionMismatch,
            )));
        }
        self.reader.read_image(buf).map_err(to_image_error)
    }

    fn read_image_boxed(self: Box<Self>, buf: &mut [u8]) -> ImageResult<()> {
        (*self).read_image(buf)
    }

    fn set_limits(&mut self, mut limits: image::Limits) -> ImageResult<()> {
        limits.check_support(&image::LimitSupport::default())?;
        let (w, h) = self.dimensions();
        limits.check_dimensions(w, h)?;
        // The output image is what this decoder allocates beyond the file it has read.
        limits.reserve(self.total_bytes())?;
        Ok(())
    }
}

/// Install [`GsiDecoder`] in the `image` crate for the `gsi` extension and the `.gsi`
/// signature, so that `image::open`, `ImageReader::with_guessed_format` and friends read
/// `.gsi` files. Returns `false` if a `gsi` decoding hook was already registered (by an
/// earlier call, say); calling it more than once is harmless.
///
/// ```
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// gsi::image_support::register();
/// # let dir = std::env::temp_dir().join(format!("gsi-doc-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir)?;
/// # let path = dir.join("tiny.gsi");
/// # std::fs::write(&path, gsi::format::tests_support::tiny_file())?;
/// let img = image::open(&path)?.to_rgb8();
/// assert_eq!(img.dimensions(), (4, 3));
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok(())
/// # }
/// ```
pub fn register() -> bool {
    static SIGNATURE_HOOK: std::sync::Once = std::sync::Once::new();
    SIGNATURE_HOOK.call_once(|| {
        image::hooks::register_format_detection_hook("gsi".into(), &SIGNATURE, None);
    });
    image::hooks::register_decoding_hook(
        "gsi".into(),
        Box::new(|r| Ok(Box::new(GsiDecoder::new(r)?))),
    )
}
