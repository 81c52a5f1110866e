//! Encoder: records (plus optional ancillary chunks) to bytes.

use super::chunk::{framed_len, write_chunk, ChunkType, RawChunk, SIGNATURE};
use super::error::{invalid, Result};
use super::meta::{CompressionMeta, MAX_SETTINGS_LEN};
use super::records::{attribute_preamble_len, minor_for_method, Records};
use std::io::Write;

/// What goes into a file besides the records.
#[derive(Clone, Debug)]
pub struct WriteOptions {
    /// zstd level for attribute payloads (the writer keeps whichever of stored and zstd is smaller).
    pub zstd_level: i32,
    /// PSNR of the stored result, when the encoder measured it.
    pub psnr: Option<f32>,
    /// Encoder settings for `gCRM`; `None` writes no `gCRM` chunk.
    pub settings: Option<String>,
    /// Further ancillary chunks, written in order after the attributes.
    pub ancillary: Vec<RawChunk>,
    /// Also consider compression method 3 (§5.4.4) for each attribute, and method 4
    /// (§5.4.5) for one whose angles are shaped, keeping the smallest payload; a file that
    /// uses method 3 is written as version 1.6 and one that uses method 4 as 1.7, which
    /// earlier decoders refuse ("compression method 3", "… 4"). (Colours stored by
    /// footprint are written in method 5, version 1.8, whatever this says: no other
    /// method holds them.) Off by default, so that a plain write
    /// stays readable by every 1.0 decoder; the encoder turns it on. (Method 2, for
    /// decoders of 1.1–1.5, is written only where a file already of such a minor is
    /// rewritten for stage 2, which keeps its `GHDR`.)
    pub context_coding: bool,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            zstd_level: 19,
            psnr: None,
            settings: Some(String::new()),
            ancillary: Vec::new(),
            context_coding: false,
        }
    }
}

/// Write a complete file and return its size in bytes.
///
/// Chunk order: signature, `GHDR`, `gCRM`, `GCRW` or `GCRT` (where the records weigh by
/// columns), `GPOS`, `GCOV`, `GCOL`, `GOPA`, `GTRC`, the given ancillary chunks, `GEND`.
/// Every payload is built first so that `gCRM` can state the exact size of the file it is
/// part of.
pub fn write_file<W: Write>(w: &mut W, records: &Records, opts: &WriteOptions) -> Result<u64> {
    if !records.is_consistent() {
        return Err(invalid("records do not match the header's count"));
    }
    for a in &opts.ancillary {
        if a.ty.is_critical() || !a.ty.is_valid() || a.ty == ChunkType::COMPRESSION_META {
            return Err(invalid(format!(
                "{} cannot be passed as an ancillary chunk",
                a.ty
            )));
        }
    }
    let attributes = [
        (ChunkType::POSITIONS, Some(&records.positions)),
        (ChunkType::COVARIANCE, Some(&records.covariance)),
        (ChunkType::COLORS, Some(&records.colors)),
        (ChunkType::OPACITY, records.opacity.as_ref()),
    ];
    let mut body: Vec<(ChunkType, Vec<u8>)> = Vec::new();
    // First after the header and `gCRM`, so that a streaming decoder knows the rule before
    // any Gaussian.
    if let Some(ty) = ChunkType::of_weight_rule(records.weights) {
        body.push((ty, Vec::new()));
    }
    // The least minor version that every payload's method needs (§2.5).
    let mut minor = 0;
    for (ty, a) in attributes {
        if let Some(a) = a {
            // Colours stored by footprint take method 5 whatever the options: no other
            // says what their values mean (§5.4.6).
            let p = records.attribute_payload(a, opts.zstd_level, opts.context_coding)?;
            minor = minor.max(minor_for_method(
                p[attribute_preamble_len(a.components()) - 5],
            ));
            body.push((ty, p));
        }
    }
    if let Some(t) = &records.tone {
        body.push((ChunkType::TONE_CURVE, super::trc::to_payload(t)));
    }
    body.extend(opts.ancillary.iter().map(|c| (c.ty, c.data.clone())));

    // §2.5: a file that uses method 2 or 3 says so in its minor version.
    let mut header = records.header;
    header.version_minor = header.version_minor.max(minor);
    let header = header.to_bytes();
    let mut total = SIGNATURE.len() as u64 + framed_len(header.len()) + framed_len(0);
    total += body.iter().map(|(_, d)| framed_len(d.len())).sum::<u64>();
    let meta = match &opts.settings {
        Some(s) if s.len() > MAX_SETTINGS_LEN => {
            return Err(invalid(format!("settings of {} bytes", s.len())))
        }
        Some(s) => {
            total += framed_len(CompressionMeta::payload_len(s));
            Some(CompressionMeta::new(
                &records.header,
                records.opacity.is_some(),
                total,
                opts.psnr,
                s.clone(),
            ))
        }
        None => None,
    };

    w.write_all(&SIGNATURE)?;
    write_chunk(w, ChunkType::HEADER, &header)?;
    if let Some(m) = meta {
        write_chunk(w, ChunkType::COMPRESSION_META, &m.to_payload())?;
    }
    for (ty, data) in &body {
        write_chunk(w, *ty, data)?;
    }
    write_chunk(w, ChunkType::END, &[])?;
    Ok(total)
}

/// [`write_file`] into a new vector.
pub fn to_bytes(records: &Records, opts: &WriteOptions) -> Result<Vec<u8>> {
    let mut v = Vec::new();
    write_file(&mut v, records, opts)?;
    Ok(v)
}
