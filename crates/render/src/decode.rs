//! Decoding for programs that embed the decoder: one call ([`decode`]), or a [`Reader`]
//! that reads a file once, then sizes and fills buffers the caller owns.
//!
//! Both enforce [`Limits`] on the file *and* on the render: the output size is checked
//! against `max_output_pixels`, and what this module allocates (the [`decode`] image; a
//! band of scratch per thread) against `max_alloc`. Pixels are blended a band of tiles at a
//! time and written straight into the output layout, so an 8-bit decode needs the 3 or 4
//! bytes per pixel of its output, not a float copy of it.

use std::io::Read;

use crate::render;
use gsi_format::format::{self, Error, ErrorKind, GsiFile, Header, Limits, Result};
use gsi_format::model::Scene;

/// The layout of decoded pixels, rows top to bottom, no padding.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PixelFormat {
    /// 8-bit RGB, 3 bytes per pixel: `floor(clamp(c, 0, 1)·255 + 0.5)` of each channel.
    Rgb8,
    /// 8-bit RGBA, 4 bytes per pixel, alpha 255.
    Rgba8,
    /// `f32` RGB in native byte order, 12 bytes per pixel, not clamped (`sum` blending may
    /// leave `[0, 1]`).
    RgbF32,
}

impl PixelFormat {
    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Rgb8 => 3,
            PixelFormat::Rgba8 => 4,
            PixelFormat::RgbF32 => 12,
        }
    }
}

/// A decoded image.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub format: PixelFormat,
    /// `width · height · format.bytes_per_pixel()` bytes.
    pub data: Vec<u8>,
}

/// Read a `.gsi` file from `input` and render it at `width × height` in 8-bit RGB, with
/// the default [`Limits`] (suited to untrusted input).
///
/// ```
/// # let bytes = gsi_format::format::tests_support::tiny_file();
/// let image = gsi_render::decode::decode(&bytes[..], 8, 6)?;
/// assert_eq!((image.width, image.height, image.data.len()), (8, 6, 8 * 6 * 3));
/// # Ok::<(), gsi_format::format::Error>(())
/// ```
pub fn decode<R: Read>(input: R, width: u32, height: u32) -> Result<Image> {
    let reader = Reader::new(input)?;
    Ok(Image {
        width,
        height,
        format: PixelFormat::Rgb8,
        data: render::render_rgb8(&reader.scene, width, height, &reader.limits)?,
    })
}

/// The size to render at when a caller names a width, a height, both or neither: a
/// missing side follows the stored aspect ratio `stored` (rounded to the nearest pixel, at
/// least 1), and neither gives the stored size. `gsi decode --width/--height` and the
/// Python package's `decode` size their output this way. An error where a side would not
/// fit in a `u32`; the size itself is checked when it is rendered.
///
/// ```
/// assert_eq!(gsi_render::decode::scaled_size((768, 512), Some(300), None)?, (300, 200));
/// assert_eq!(gsi_render::decode::scaled_size((768, 512), None, Some(100))?, (150, 100));
/// assert_eq!(gsi_render::decode::scaled_size((768, 512), None, None)?, (768, 512));
/// # Ok::<(), gsi_format::format::Error>(())
/// ```
pub fn scaled_size(
    stored: (u32, u32),
    width: Option<u32>,
    height: Option<u32>,
) -> Result<(u32, u32)> {
    let (w, h) = (f64::from(stored.0), f64::from(stored.1));
    let side = |x: f64| -> Result<u32> {
        if x.is_finite() && x < f64::from(u32::MAX) {
            Ok((x.round() as u32).max(1))
        } else {
            Err(Error::new(
                ErrorKind::LimitExceeded,
                format!("output size {x} is out of range"),
            ))
        }
    };
    match (width, height) {
        (Some(ow), Some(oh)) => Ok((ow, oh)),
        (Some(ow), None) => Ok((ow, side(f64::from(ow) * h / w.max(1.0))?)),
        (None, Some(oh)) => Ok((side(f64::from(oh) * w / h.max(1.0))?, oh)),
        (None, None) => Ok(stored),
    }
}

/// A read `.gsi` file, ready to render into buffers of the caller's at any size.
///
/// ```
/// use gsi_render::decode::{PixelFormat, Reader};
/// # let bytes = gsi_format::format::tests_support::tiny_file();
/// let mut reader = Reader::new(&bytes[..])?; // the whole file, CRC-checked
/// assert_eq!(reader.output_size(), (4, 3)); // the stored size, until set
/// reader.set_output_size(40, 30)?;
/// reader.set_pixel_format(PixelFormat::Rgba8);
/// let mut buf = vec![0u8; reader.output_buffer_size()?];
/// reader.read_image(&mut buf)?; // tiles rendered straight into `buf`
/// assert!(buf.chunks(4).all(|px| px[3] == 255));
/// # Ok::<(), gsi_format::format::Error>(())
/// ```
#[derive(Debug)]
pub struct Reader {
    file: GsiFile,
    scene: Scene,
    limits: Limits,
    size: (u32, u32),
    format: PixelFormat,
}

impl Reader {
    /// Read a whole file with the default [`Limits`].
    pub fn new<R: Read>(input: R) -> Result<Reader> {
        Reader::with_limits(input, Limits::default())
    }

    /// Read a whole file under `limits`, which also bound every later render.
    pub fn with_limits<R: Read>(input: R, limits: Limits) -> Result<Reader> {
        let file = format::read_file(input, limits)?;
        let scene = file.records.to_scene();
        let h = &file.records.header;
        let size = (h.width, h.height);
        Ok(Reader {
            file,
            scene,
            limits,
            size,
            format: PixelFormat::Rgb8,
        })
    }

    /// The file's header: stored size, Gaussian count, blend mode.
    pub fn header(&self) -> &Header {
        &self.file.records.header
    }

    /// The whole file as read (records, metadata, chunks).
    pub fn file(&self) -> &GsiFile {
        &self.file
    }

    /// The Gaussians, as the renderer sees them.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Render at `width × height` from now on (any size: geometry is normalized).
    /// Refused when empty or over the limits' `max_output_pixels`.
    pub fn set_output_size(&mut self, width: u32, height: u32) -> Result<()> {
        self.limits.check_output(width, height)?;
        self.size = (width, height);
        Ok(())
    }

    /// The size [`Reader::read_image`] renders at: the stored size unless set.
    pub fn output_size(&self) -> (u32, u32) {
        self.size
    }

    /// Render in `format` from now on (8-bit RGB unless set).
    pub fn set_pixel_format(&mut self, format: PixelFormat) {
        self.format = format;
    }

    pub fn pixel_format(&self) -> PixelFormat {
        self.format
    }

    /// Bytes [`Reader::read_image`] fills; an error if they cannot be addressed.
    pub fn output_buffer_size(&self) -> Result<usize> {
        let (w, h) = self.size;
        render::buffer_len(w, h, self.format.bytes_per_pixel(), &self.limits)
    }

    /// Render into `buf`, which must hold exactly [`Reader::output_buffer_size`] bytes.
    /// Can be called again, at other sizes or formats, without reading the file again.
    pub fn read_image(&self, buf: &mut [u8]) -> Result<()> {
        let (w, h) = self.size;
        self.limits.check_output(w, h)?;
        let want = self.output_buffer_size()?;
        if buf.len() != want {
            return Err(Error::new(
                ErrorKind::InvalidValue,
                format!(
                    "buffer holds {} bytes, {w}x{h} {:?} needs {want}",
                    buf.len(),
                    self.format
                ),
            ));
        }
        let (scene, limits) = (&self.scene, &self.limits);
        match self.format {
            PixelFormat::Rgb8 => render::render_as::<render::Rgb8Out>(scene, w, h, buf, limits),
            PixelFormat::Rgba8 => render::render_as::<render::Rgba8Out>(scene, w, h, buf, limits),
            PixelFormat::RgbF32 => {
                render::render_as::<render::RgbF32BytesOut>(scene, w, h, buf, limits)
            }
        }
    }
}
