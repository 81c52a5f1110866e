//! Image-quality metrics: full-reference (PSNR, SSIM, MS-SSIM and their GT-mean variants),
//! the lightness-order error of an enhancement, and the no-reference DE, EME and NIQE.
//!
//! The conventions are those of the reference table in `shared/data/README.md`, so that
//! figures measured here can be set beside it; `tests/metrics.rs` reproduces that table's
//! rows for the LOL inputs, gamma 0.4 and auto-gamma to prove it. In short:
//!
//! * Images are 8-bit RGB ([`Rgb8`]), read as `f64` in `[0, 255]`.
//! * PSNR: MSE over all three channels, peak 255 ([`psnr`]).
//! * SSIM: scikit-image's `structural_similarity(.., channel_axis=2, data_range=255,
//!   gaussian_weights=True, sigma=1.5, use_sample_covariance=False)` ([`ssim`]).
//! * MS-SSIM: Wang et al. 2003 on the same per-scale SSIM ([`ms_ssim`]).
//! * Gray level: ITU-R BT.601 luma `0.299 R + 0.587 G + 0.114 B`, unrounded for GT-mean
//!   and EME, rounded to 8 bits for DE.
//! * GT-mean: the image scaled so its mean luma equals the reference's ([`gt_mean`]).
//! * LOE, DE, EME: see [`loe`], [`de`], [`eme`].
//! * NIQE: LIVE's MATLAB release and pristine model, 96×96 patches ([`niqe`]).
//! * Colour cast: mean CIELAB `a*`, `b*` against the reference's ([`color_cast`]); noise
//!   on the reference's flat patches ([`flat_noise`]); the share of clipped pixels
//!   ([`clipped_share`]).
//!
//! A differentiable SSIM / MS-SSIM loss on `f32` images for the encoder lives beside them
//! ([`ssim_loss_grad`], [`ms_ssim_loss_grad`]); it shares the window and the per-scale
//! arithmetic with the metrics, so the encoder optimises what `gsi compare` reports.
//!
//! This module has no dependencies and is part of the lean decoder build.

mod color;
mod enhancement;
mod filter;
mod loss;
mod niqe;
mod psnr;
mod sobel;
mod ssim;

pub use color::{color_cast, linear_to_srgb, mean_ab, srgb_to_linear, BT601, BT601_F32};
pub use enhancement::{
    clipped_share, de, eme, flat_noise, gt_mean, loe, luma, CLIPPED_FROM, EME_BLOCK, EME_EPS,
    FLAT_BLOCK, FLAT_MAX_STD, LOE_ROWS,
};
pub use filter::Real;
pub use loss::{ms_ssim_loss_grad, ssim_loss_grad, LossWorkspace};
pub use niqe::{niqe, NIQE_PATCH};
pub use psnr::{psnr, psnr_of_sse};
pub use sobel::{sobel_row, sobel_taps};
pub use ssim::{ms_ssim, ssim, MS_SSIM_WEIGHTS};

use std::fmt;

/// Side of the SSIM window (11 taps, σ = 1.5): the smallest side an image may have.
pub const WINDOW: u32 = filter::TAPS as u32;

/// A borrowed 8-bit RGB image: row-major, `[r, g, b]` per pixel, rows top to bottom
/// (the layout of `image::RgbImage` and of `gsi::RgbImage::to_rgb8`).
///
/// The length is checked once, here, so that no metric has to index defensively.
#[derive(Clone, Copy, Debug)]
pub struct Rgb8<'a> {
    width: u32,
    height: u32,
    data: &'a [u8],
}

impl<'a> Rgb8<'a> {
    /// Wrap `data`, which must hold exactly `width * height * 3` bytes of a non-empty image.
    pub fn new(width: u32, height: u32, data: &'a [u8]) -> Result<Self, MetricError> {
        if width == 0 || height == 0 {
            return Err(MetricError::Empty);
        }
        let expected = width as usize * height as usize * 3;
        if data.len() != expected {
            return Err(MetricError::BufferLength {
                expected,
                actual: data.len(),
            });
        }
        Ok(Rgb8 {
            width,
            height,
            data,
        })
    }
    pub fn width(&self) -> u32 {
        self.width
    }
    pub fn height(&self) -> u32 {
        self.height
    }
    pub fn data(&self) -> &'a [u8] {
        self.data
    }
    fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// Why a metric could not be computed. Every metric returns it rather than panicking.
#[non_exhaustive]
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MetricError {
    /// A side of an image is zero.
    Empty,
    /// A buffer does not hold `width * height * channels` values.
    BufferLength { expected: usize, actual: usize },
    /// The two images of a full-reference metric differ in size.
    SizeMismatch {
        reference: (u32, u32),
        image: (u32, u32),
    },
    /// An image is smaller than the metric's window (SSIM needs 11×11, NIQE 96×96).
    TooSmall { width: u32, height: u32, min: u32 },
}

impl fmt::Display for MetricError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MetricError::Empty => f.write_str("empty image"),
            MetricError::BufferLength { expected, actual } => {
                write!(
                    f,
                    "buffer holds {actual} values, the image needs {expected}"
                )
            }
            MetricError::SizeMismatch { reference, image } => write!(
                f,
                "size mismatch: reference is {}x{}, image is {}x{}",
                reference.0, reference.1, image.0, image.1
            ),
            MetricError::TooSmall { width, height, min } => write!(
                f,
                "image is {width}x{height}, the metric needs at least {min}x{min} pixels"
            ),
        }
    }
}

impl std::error::Error for MetricError {}

/// Full-reference figures of an image against its reference (see [`full_reference`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Report {
    /// dB; `f64::INFINITY` when the images are identical.
    pub psnr: f64,
    pub ssim: f64,
    pub ms_ssim: f64,
    /// PSNR after [`gt_mean`] (dB, may be infinite).
    pub psnr_gm: f64,
    /// SSIM after [`gt_mean`].
    pub ssim_gm: f64,
    /// Lightness-order error with the *reference* as the input of an enhancement.
    pub loe: f64,
    /// Discrete entropy of the image (bits).
    pub de: f64,
    /// Measure of enhancement of the image.
    pub eme: f64,
}

/// No-reference figures of one image (see [`no_reference`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoRefReport {
    pub de: f64,
    pub eme: f64,
    /// [`niqe`]; `None` for an image smaller than one 96×96 patch.
    pub niqe: Option<f64>,
}

/// Every metric of `image` against `reference`.
///
/// LOE compares lightness order, not fidelity, so here `reference` plays the part of the
/// enhancement's *input* and `image` its output: `loe(reference, image)`. DE and EME are
/// those of `image`. Both images must be the same size, at least 11×11.
pub fn full_reference(reference: Rgb8<'_>, image: Rgb8<'_>) -> Result<Report, MetricError> {
    check_pair(reference, image)?;
    let gm = gt_mean(reference, image)?;
    let gm = Rgb8::new(image.width, image.height, &gm)?;
    Ok(Report {
        psnr: psnr(reference, image)?,
        ssim: ssim(reference, image)?,
        ms_ssim: ms_ssim(reference, image)?,
        psnr_gm: psnr(reference, gm)?,
        ssim_gm: ssim(reference, gm)?,
        loe: loe(reference, image)?,
        de: de(image),
        eme: eme(image),
    })
}

/// The metrics that need no reference: DE, EME and NIQE.
pub fn no_reference(image: Rgb8<'_>) -> NoRefReport {
    NoRefReport {
        de: de(image),
        eme: eme(image),
        niqe: niqe(image).ok(),
    }
}

/// Both images the same size.
fn check_pair(reference: Rgb8<'_>, image: Rgb8<'_>) -> Result<(), MetricError> {
    if (reference.width, reference.height) != (image.width, image.height) {
        return Err(MetricError::SizeMismatch {
            reference: (reference.width, reference.height),
            image: (image.width, image.height),
        });
    }
    Ok(())
}
