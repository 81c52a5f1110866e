//! Stage 2: zero-shot low-light enhancement inside a `.gsi` file (paper §III-B).
//!
//! Geometry is frozen: the positions, covariances and opacities of a file are copied
//! byte for byte, and only the colour records change. A small mixture of colour
//! operators, mixed per Gaussian by a weight map over the image, is fitted to the one
//! image with no-reference losses and stored in the file (`gENH`) beside the original
//! colours (`gORC`), so that the enhancement can be re-applied without fitting
//! ([`apply_from`]) or undone exactly ([`ChunkedFile::revert`]).
//!
//! * [`mixture`]: the enhancer as stored and applied (no rendering needed).
//! * [`denoise`]: the smoothing across neighbouring Gaussians that comes before it.
//! * [`tone`]: the tone curve on the rendered values that comes after it.
//! * `exposure`: metering the image, for the exposure to aim at and whether to act.
//! * `features`, `loss`, `operator`, `fit`: fitting it (feature `encode`).

pub mod denoise;
pub mod mixture;
pub mod tone;

#[cfg(feature = "encode")]
pub mod exposure;
#[cfg(feature = "encode")]
pub mod features;
#[cfg(feature = "encode")]
pub mod fit;
#[cfg(all(feature = "encode", feature = "gpu"))]
pub(crate) mod gpu;
#[cfg(feature = "encode")]
pub mod loss;
#[cfg(feature = "encode")]
pub mod operator;

pub use mixture::Enhancer;

use crate::format::{Attribute, ChunkedFile, EnhancerRecord, Limits, Records, Result};
use crate::model::Scene;

/// The records a file holds before any enhancement: its geometry with the colours in
/// `gORC` when it has them, else those in `GCOL`. Stage 2 reads the scene to enhance
/// from them, and the bit depths to store the new colours with.
pub fn base_records(file: &ChunkedFile, limits: &Limits) -> Result<Records> {
    Ok(Records {
        colors: file.base_colors(limits)?,
        ..file.file.records.clone()
    })
}

/// Quantize enhanced colours with the bit depths the file's colours had (8 where a
/// component was constant and stored in 0 bits).
pub fn colors_like(colors: &[[f32; 3]], like: &Attribute) -> Attribute {
    let bits = std::array::from_fn(|c| match like.quantizers.get(c).map_or(0, |q| q.bits) {
        0 => 8,
        b => b,
    });
    Attribute::fit(colors, bits)
}

/// Apply the enhancer stored in `source` to the colours of `target` (its original
/// colours, when it was enhanced before and kept them): no fitting and no rendering.
/// Returns the new file.
pub fn apply_from(
    target: &ChunkedFile,
    source: &ChunkedFile,
    keep_original: bool,
    limits: &Limits,
) -> Result<Vec<u8>> {
    let record = source.enhancer(limits)?.ok_or_else(|| {
        crate::format::Error::new(
            crate::format::ErrorKind::MissingChunk,
            "the source file has no gENH chunk",
        )
    })?;
    let base = base_records(target, limits)?;
    let colors = apply_record(&record, &base.to_scene(), limits)?;
    rewrite(target, &base, &colors, &record, keep_original)
}

/// The colours the stored enhancer `record` makes of `scene`'s (spec §7.2): its
/// denoising first, where it has one, then the mixture, then its tone curve, where it
/// has one. Fails only where the footprint search of the denoising or the curve would
/// pass `limits`.
pub fn apply_record(
    record: &EnhancerRecord,
    scene: &Scene,
    limits: &Limits,
) -> Result<Vec<[f32; 3]>> {
    let g = &scene.gaussians;
    // One footprint search serves both steps: it depends on the geometry only.
    let nb = if record.denoise.is_some() || record.tone.is_some() {
        Some(denoise::Neighbours::new(scene, limits)?)
    } else {
        None
    };
    let colors = match (&record.denoise, &nb) {
        (Some(d), Some(nb)) => nb.denoise(&g.colors, d),
        _ => g.colors.clone(),
    };
    let colors = Enhancer::from_record(record).apply(&g.positions, &colors);
    Ok(match (&record.tone, &nb) {
        (Some(t), Some(nb)) => tone::apply(nb, &colors, t),
        _ => colors,
    })
}

/// Fit an enhancer to the file's (original) colours, with its mixture on `device`, and
/// return the rewritten file with what the fit did. With `opts.denoise`, the colours are
/// denoised first, and with `opts.tone` the mixture's output goes through a tone curve;
/// the enhancer stores both. The caller decides beforehand whether
/// the image needs it ([`fit::scene_metering`], [`exposure::Metering::is_low_light`]).
#[cfg(feature = "encode")]
pub fn enhance(
    file: &ChunkedFile,
    opts: &fit::EnhanceOptions,
    keep_original: bool,
    limits: &Limits,
    device: crate::Device<'_>,
    progress: &mut dyn FnMut(&fit::Progress),
) -> Result<(Vec<u8>, fit::Fitted)> {
    let base = base_records(file, limits)?;
    let mut scene = base.to_scene();
    // Denoised first, so that the fit sees (and its losses measure) the cleaner image. A
    // scene whose footprints overlap too much for the neighbour search (within `limits`)
    // is enhanced without it and without the tone curve (which needs the same search),
    // and the caller is told.
    let mut stored_denoise = None;
    let mut skipped = None;
    let mut nb = None;
    if opts.denoise.is_some() || opts.tone.is_some() {
        match denoise::Neighbours::new(&scene, limits) {
            Ok(found) => nb = Some(found),
            Err(e) if e.kind() == crate::format::ErrorKind::LimitExceeded => {
                skipped = Some(format!("enhanced without denoising or tone curve: {e}"));
            }
            Err(e) => return Err(e),
        }
    }
    if let (Some(o), Some(nb)) = (&opts.denoise, &nb) {
        stored_denoise = o.resolve(nb, &scene.gaussians.colors);
        if let Some(d) = &stored_denoise {
            scene.gaussians.colors = nb.denoise(&scene.gaussians.colors, d);
        }
    }
    let mut fitted = fit::fit(&scene, opts, &features::FeatureBank, device, progress);
    fitted.record.denoise = stored_denoise;
    // The curve last, on the mixture's output, keeping the mean luma the fit reached.
    if let (Some(o), Some(nb)) = (&opts.tone, &nb) {
        fitted.record.tone = o.resolve(nb, &scene, &fitted.colors, opts.work_side);
        if let Some(t) = &fitted.record.tone {
            fitted.colors = tone::apply(nb, &fitted.colors, t);
        }
    }
    fitted.denoise_skipped = skipped;
    let bytes = rewrite(file, &base, &fitted.colors, &fitted.record, keep_original)?;
    Ok((bytes, fitted))
}

/// `file` with `colors` (quantized like the base colours) and the enhancer `record` in
/// place of its base colours.
fn rewrite(
    file: &ChunkedFile,
    base: &Records,
    colors: &[[f32; 3]],
    record: &crate::format::EnhancerRecord,
    keep_original: bool,
) -> Result<Vec<u8>> {
    file.with_colors(
        &colors_like(colors, &base.colors),
        record,
        keep_original,
        crate::format::WriteOptions::default().zstd_level,
    )
}
