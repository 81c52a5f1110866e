//! Resource bounds a decoder checks *before* it allocates.

use super::error::{Error, ErrorKind, Result};

/// Upper bounds on what a file may make the decoder allocate or render.
///
/// Every length, count and decompressed size read from a file is checked against these
/// before memory is reserved for it, so a hostile file costs at most `max_alloc` bytes
/// however its fields are set. The defaults admit any realistic image; an embedding
/// program that decodes untrusted files may tighten them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Largest header width or height, in pixels.
    pub max_dimension: u32,
    /// Largest number of Gaussians.
    pub max_gaussians: u32,
    /// Largest chunk payload, in bytes.
    pub max_chunk_len: u32,
    /// Largest decompressed size of one attribute payload, in bytes.
    pub max_decompressed: u64,
    /// Total bytes the decoder may hold for chunk payloads, decompressed data and records.
    pub max_alloc: u64,
    /// Largest number of output pixels a render may be asked for.
    pub max_output_pixels: u64,
    /// Largest number of Gaussian–pixel pairs a render may evaluate: the output pixels
    /// inside each Gaussian's 3σ box, summed over the Gaussians. It bounds the work a
    /// file can ask for, which the output size and the Gaussian count bound only as a
    /// product: a 176-byte file of 59,136 identical image-sized Gaussians asks for
    /// 5.3·10^9 pairs at 300×300 and 5.9·10^10 at 1000×1000, minutes to hours of CPU.
    pub max_render_work: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_dimension: 1 << 16,
            max_gaussians: 1 << 23,
            max_chunk_len: 1 << 28,
            max_decompressed: 1 << 28,
            max_alloc: 1 << 31,
            max_output_pixels: 1 << 27,
            max_render_work: DEFAULT_RENDER_WORK,
        }
    }
}

/// The default [`Limits::max_render_work`]: 2^32 pairs, about ten seconds of CPU on two
/// cores. Real photographs stay well below it: a 4 MP file of 92,000 Gaussians rendered
/// at 64 MP needs 1.1·10^9 pairs, Kodak at 1 bpp rendered at 25 MP 4.9·10^8, a 600×400
/// LOL file at its own size 4·10^6.
pub const DEFAULT_RENDER_WORK: u64 = 1 << 32;

impl Limits {
    /// Bounds with no practical limit; for trusted input only.
    pub fn unlimited() -> Self {
        Limits {
            max_dimension: u32::MAX,
            max_gaussians: u32::MAX,
            max_chunk_len: u32::MAX,
            max_decompressed: u64::MAX,
            max_alloc: u64::MAX,
            max_output_pixels: u64::MAX,
            max_render_work: u64::MAX,
        }
    }

    /// Refuse a render of `width × height` that would evaluate `pairs` Gaussian–pixel
    /// pairs, over `max_render_work`.
    pub fn check_render_work(&self, pairs: u64, width: u32, height: u32) -> Result<()> {
        if pairs > self.max_render_work {
            return Err(Error::new(
                ErrorKind::LimitExceeded,
                format!(
                    "rendering {width}x{height} would evaluate {pairs} Gaussian-pixel pairs, \
                     over the render-work limit of {}",
                    self.max_render_work
                ),
            ));
        }
        Ok(())
    }

    /// Refuse an allocation of `bytes` for `what` over `max_alloc`.
    pub fn check_alloc(&self, bytes: u64, what: &str) -> Result<()> {
        if bytes > self.max_alloc {
            return Err(Error::new(
                ErrorKind::LimitExceeded,
                format!(
                    "{what} needs {bytes} bytes, over the allocation limit of {}",
                    self.max_alloc
                ),
            ));
        }
        Ok(())
    }

    /// Refuse an output size of more than `max_output_pixels` (or a zero dimension).
    pub fn check_output(&self, width: u32, height: u32) -> Result<()> {
        if width == 0 || height == 0 {
            return Err(Error::new(
                ErrorKind::InvalidValue,
                format!("output size {width}x{height} is empty"),
            ));
        }
        let px = u64::from(width) * u64::from(height);
        if px > self.max_output_pixels {
            return Err(Error::new(
                ErrorKind::LimitExceeded,
                format!(
                    "output {width}x{height} exceeds {} pixels",
                    self.max_output_pixels
                ),
            ));
        }
        Ok(())
    }
}

/// Running total of the bytes a decode has reserved, against `Limits::max_alloc`.
#[derive(Debug)]
pub struct AllocBudget {
    left: u64,
}

impl AllocBudget {
    pub fn new(limits: &Limits) -> Self {
        AllocBudget {
            left: limits.max_alloc,
        }
    }

    /// Account for `bytes` about to be allocated, or refuse.
    pub fn reserve(&mut self, bytes: u64, what: &str) -> Result<()> {
        if bytes > self.left {
            return Err(Error::new(
                ErrorKind::LimitExceeded,
                format!(
                    "{what} needs {bytes} bytes, {} left of the allocation limit",
                    self.left
                ),
            ));
        }
        self.left -= bytes;
        Ok(())
    }

    /// Give back bytes that were freed.
    pub fn release(&mut self, bytes: u64) {
        self.left = self.left.saturating_add(bytes);
    }
}
