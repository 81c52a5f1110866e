//! What a file holds and how compact it is, as `gsi info` prints it: in prose
//! ([`to_text`]) or as JSON ([`to_json`], feature `info`), so that the command-line tool,
//! the Python package and any other front end describe a file with the same keys and
//! figures.

use crate::format::{ChunkType, CompressionMeta, EnhancerRecord, GsiFile, Limits, OriginalColors};
use crate::model::WeightRule;
use serde_json::json;

/// Ratios measured on the file as read (the stored `gCRM` may describe an older write).
fn measured(f: &GsiFile) -> CompressionMeta {
    let r = &f.records;
    CompressionMeta::new(
        &r.header,
        r.opacity.is_some(),
        f.file_bytes,
        None,
        String::new(),
    )
}

/// What stage 2 left in the file: its enhancer (or why it cannot be read) and whether
/// the original colours were kept in a `gORC` that `--revert` accepts.
struct Stage2 {
    enhancer: Option<Result<EnhancerRecord, String>>,
    revertible: bool,
}

fn stage2(f: &GsiFile) -> Stage2 {
    let find = |ty| f.ancillary.iter().find(|c| c.ty == ty);
    Stage2 {
        enhancer: find(ChunkType::ENHANCER)
            .map(|c| EnhancerRecord::parse(&c.data, &Limits::default()).map_err(|e| e.to_string())),
        revertible: find(ChunkType::ORIGINAL_COLORS).is_some_and(|c| {
            OriginalColors::parse(&c.data).is_ok_and(|o| o.validate(&f.records).is_ok())
        }),
    }
}

/// The range of a gain map's gains.
fn gain_range(g: &crate::format::GainMap) -> (f32, f32) {
    let q = &g.gains.quantizers[0];
    (q.min, q.max)
}

/// The range of a chroma map's scales.
fn chroma_range(c: &crate::format::ChromaMap) -> (f32, f32) {
    let q = &c.scales.quantizers[0];
    (q.min, q.max)
}

/// Bits per Gaussian that each attribute chunk spends, its preamble included (`None`
/// without Gaussians).
fn bits_per_gaussian(f: &GsiFile) -> Option<Vec<(ChunkType, f64)>> {
    let n = f.records.header.count;
    (n > 0).then(|| {
        f.chunks
            .iter()
            .filter(|c| {
                [
                    ChunkType::POSITIONS,
                    ChunkType::COVARIANCE,
                    ChunkType::COLORS,
                    ChunkType::OPACITY,
                ]
                .contains(&c.ty)
            })
            .map(|c| (c.ty, f64::from(c.length) * 8.0 / f64::from(n)))
            .collect()
    })
}

fn finite_or_null(x: f32) -> serde_json::Value {
    if x.is_finite() {
        json!(x)
    } else {
        serde_json::Value::Null
    }
}

/// What `gsi info --json` prints: the header, the compression ratios measured on the file as
/// read, the stored encoder settings, what stage 2 left in the file, bits per Gaussian, the
/// quantizers and the chunk table. Non-finite ratios (a file with no pixels) are `null`.
pub fn to_json(f: &GsiFile) -> serde_json::Value {
    let h = &f.records.header;
    let m = measured(f);
    let stage = stage2(f);
    let quantizers = |a: &crate::format::Attribute| {
        a.quantizers
            .iter()
            .map(|q| json!({"bits": q.bits, "min": q.min, "max": q.max}))
            .collect::<Vec<_>>()
    };
    let r = &f.records;
    json!({
        "version": format!("{}.{}", h.version_major, h.version_minor),
        "width": h.width,
        "height": h.height,
        "gaussians": h.count,
        "blend": h.blend.name(),
        "cov_param": h.cov_param.name(),
        "color_space": "srgb",
        "opacity": r.opacity.is_some(),
        "weights": r.weights.name(),
        "importance_ordered": h.flags & crate::format::FLAG_IMPORTANCE_ORDERED != 0,
        "file_bytes": f.file_bytes,
        "bpp": finite_or_null(m.bpp),
        "dof_per_gaussian": m.dof_per_gaussian,
        "cr_dof": finite_or_null(m.cr_dof),
        "cr_bytes": finite_or_null(m.cr_bytes),
        "psnr": f.metadata.as_ref().and_then(|s| s.psnr).map(finite_or_null),
        "encoder_settings": f.metadata.as_ref().map(|s| s.settings.clone()),
        "enhancer": match stage.enhancer {
            None => serde_json::Value::Null,
            Some(Err(e)) => json!({"error": e}),
            Some(Ok(e)) => json!({
                "experts": e.experts,
                "hidden": e.hidden,
                "map": [e.map_width, e.map_height],
                "iterations": e.fit.iterations,
                "exposure": e.fit.exposure,
                "speckle": e.speckle.map(|k| json!({"threshold": k.threshold})),
                "denoise": e.denoise.map(|d| json!({
                    "range": d.range, "strength": d.strength, "passes": d.passes,
                })),
                "tone": e.tone.map(|t| json!({
                    "exponent": t.exponent, "scale": t.scale, "passes": t.passes,
                })),
                "gain": e.gain.as_ref().map(|g| {
                    let (lo, hi) = gain_range(g);
                    json!({"map": [g.width, g.height], "min": lo, "max": hi})
                }),
                "chroma": e.chroma.as_ref().map(|c| {
                    let (lo, hi) = chroma_range(c);
                    json!({"map": [c.width, c.height], "min": lo, "max": hi})
                }),
                "revertible": stage.revertible,
            }),
        },
        "tone_curve": r.tone.as_ref().map(|t| {
            let at = [0.01f32, 0.05, 0.1, 0.25, 0.5, 1.0].map(|x| [x, t.eval(0, x)]);
            json!({"curves": t.curves(), "knots": t.knots(), "at": at})
        }),
        "bits_per_gaussian": bits_per_gaussian(f).map(|b| {
            b.iter()
                .map(|(ty, bits)| (ty.to_string(), json!(bits)))
                .collect::<serde_json::Map<_, _>>()
        }),
        "quantizers": {
            "GPOS": quantizers(&r.positions),
            "GCOV": quantizers(&r.covariance),
            "GCOL": quantizers(&r.colors),
            "GOPA": r.opacity.as_ref().map(quantizers),
        },
        // Colours stored by footprint (spec §5.4.6): the quantizers above span the colours
        // times `2^k`; this is the base of their classes.
        "color_footprint_base": r.colors.footprint,
        "chunks": f.chunks.iter().map(|c| json!({
            "type": c.ty.to_string(),
            "offset": c.offset,
            "length": c.length,
            "crc32": format!("{:08x}", c.crc32),
        })).collect::<Vec<_>>(),
    })
}

/// What `gsi info` prints: the same facts as [`to_json`] in a few lines of prose.
pub fn to_text(f: &GsiFile) -> String {
    let h = &f.records.header;
    let m = measured(f);
    let mut s = format!(
        "{}x{} pixels, {} Gaussians, {} blending, {} covariance{}, weights {}\n\
         {} bytes: {:.3} bpp, Cr {:.1}x by parameters (Eq. 10, {} per Gaussian), {:.1}x by bytes\n",
        h.width,
        h.height,
        h.count,
        h.blend.name(),
        h.cov_param.name(),
        if f.records.opacity.is_some() {
            ", opacity"
        } else {
            ""
        },
        match f.records.weights {
            WeightRule::Columns => "by columns in bands of 16 rows (GCRW)",
            WeightRule::Columns32 => "by columns in bands of 32 rows (GCRT)",
            WeightRule::PerPixel => "per pixel",
        },
        f.file_bytes,
        m.bpp,
        m.cr_dof,
        m.dof_per_gaussian,
        m.cr_bytes,
    );
    if let Some(p) = f.metadata.as_ref().and_then(|s| s.psnr) {
        s += &format!("stored result: {p:.2} dB PSNR against the encoder's input\n");
    }
    if let Some(b) = bits_per_gaussian(f) {
        let total: f64 = b.iter().map(|(_, x)| x).sum();
        let each: Vec<String> = b.iter().map(|(ty, x)| format!("{ty} {x:.1}")).collect();
        s += &format!(
            "bits per Gaussian: {total:.1} ({}; version {}.{})\n",
            each.join(", "),
            h.version_major,
            h.version_minor
        );
    }
    let st = stage2(f);
    match &st.enhancer {
        Some(Ok(e)) => {
            s += &format!(
                "enhanced: {}{}{} colour operators (hidden {}), {}x{} weight map, fitted in {} iterations to exposure {}{}; {}\n",
                match e.speckle {
                    Some(k) => format!(
                        "Gaussians within the noise removed (threshold {:.4}), then ",
                        k.threshold
                    ),
                    None => String::new(),
                },
                match e.denoise {
                    Some(d) => format!(
                        "denoised ({}, range {:.4}, strength {}), then ",
                        passes(d.passes),
                        d.range,
                        d.strength
                    ),
                    None => String::new(),
                },
                e.experts,
                e.hidden,
                e.map_width,
                e.map_height,
                e.fit.iterations,
                e.fit.exposure,
                match &e.gain {
                    Some(g) => {
                        let (lo, hi) = gain_range(g);
                        format!(
                            ", then a {}x{} gain map ({lo:.2} to {hi:.2}: the shadows lifted on their own)",
                            g.width, g.height
                        )
                    }
                    None => String::new(),
                } + &match &e.chroma {
                    Some(c) => {
                        let (lo, hi) = chroma_range(c);
                        format!(
                            ", then a {}x{} chroma map ({lo:.2} to {hi:.2}: the colour of what was within the noise of black moved towards grey)",
                            c.width, c.height
                        )
                    }
                    None => String::new(),
                } + &match e.tone {
                    Some(t) => format!(
                        ", then a tone curve ({:.4}·x^{}, {})",
                        t.scale,
                        t.exponent,
                        passes(t.passes)
                    ),
                    None => String::new(),
                },
                if st.revertible {
                    "original colours kept (--revert restores them)"
                } else {
                    "original colours discarded"
                }
            )
        }
        Some(Err(e)) => s += &format!("enhanced, but its gENH chunk is unreadable: {e}\n"),
        None => {}
    }
    if let Some(t) = &f.records.tone {
        let at: Vec<String> = [0.01f32, 0.1, 0.5, 1.0]
            .iter()
            .map(|&x| format!("{x} -> {:.3}", t.eval(0, x)))
            .collect();
        s += &format!(
            "shown through a tone curve (GTRC, {} curve{} of {} knots: {})\n",
            t.curves(),
            if t.curves() == 1 { "" } else { "s" },
            t.knots(),
            at.join(", ")
        );
    }
    s += "chunks:";
    for c in &f.chunks {
        s += &format!(
            "\n  {} at byte {:>8}, {:>8} bytes, crc {:08x}",
            c.ty, c.offset, c.length, c.crc32
        );
    }
    s
}

/// "1 pass", "2 passes".
fn passes(n: u8) -> String {
    format!("{n} pass{}", if n == 1 { "" } else { "es" })
}
