//! Peak signal-to-noise ratio on 8-bit RGB.

use super::{check_pair, MetricError, Rgb8};

/// `10·log10(255² / MSE)`, the MSE taken over every channel of every pixel.
///
/// Identical images give `f64::INFINITY`: it is the true limit, and a caller that must
/// print a finite number (JSON has no infinity) decides how; `gsi compare` prints `null`.
pub fn psnr(reference: Rgb8<'_>, image: Rgb8<'_>) -> Result<f64, MetricError> {
    check_pair(reference, image)?;
    // Squared differences of bytes are integers: summing them exactly in u64 keeps the
    // result independent of summation order (up to 2^64 / 255² ≈ 2.8e14 values).
    let sse: u64 = reference
        .data
        .iter()
        .zip(image.data)
        .map(|(&a, &b)| {
            let d = a.abs_diff(b) as u64;
            d * d
        })
        .sum();
    Ok(psnr_of_sse(sse, reference.data.len() as u64))
}

/// PSNR (dB) of 8-bit values from their summed squared error over `values` values:
/// infinite when they agree. For callers that sum the error themselves (the GPU fit).
pub fn psnr_of_sse(sse: u64, values: u64) -> f64 {
    if sse == 0 {
        return f64::INFINITY;
    }
    let mse = sse as f64 / values as f64;
    10.0 * (255.0f64 * 255.0 / mse).log10()
}
