//! Streaming decoder: parses chunk by chunk from any `Read`, no seeking.

use super::chunk::{self, ChunkInfo, ChunkType, Counting, RawChunk, SIGNATURE};
use super::error::{invalid, Error, ErrorKind, Result};
use super::header::{Header, HEADER_LEN};
use super::limits::{AllocBudget, Limits};
use super::meta::CompressionMeta;
use super::records::{attribute_preamble_len, Attribute, Records, METHOD_FOOTPRINT};
use crate::model::{CovParam, WeightRule};
use byteorder::{BigEndian, ByteOrder};
use std::io::Read;

/// Everything a file holds, parsed and validated.
#[derive(Clone, Debug, PartialEq)]
pub struct GsiFile {
    pub records: Records,
    pub metadata: Option<CompressionMeta>,
    /// Ancillary chunks this decoder does not interpret, in stream order.
    pub ancillary: Vec<RawChunk>,
    /// Every chunk in stream order, with its offset, length and CRC.
    pub chunks: Vec<ChunkInfo>,
    /// Bytes read, signature through `GEND`.
    pub file_bytes: u64,
}

/// Pull decoder over a byte stream.
///
/// ```
/// # fn main() -> Result<(), gsi_format::format::Error> {
/// # let bytes = gsi_format::format::tests_support::tiny_file();
/// let mut dec = gsi_format::format::Decoder::new(&bytes[..]);
/// let header = dec.read_header()?;
/// assert_eq!((header.width, header.height), (4, 3));
/// let file = dec.finish()?;
/// assert_eq!(file.records.header.count, 2);
/// # Ok(()) }
/// ```
pub struct Decoder<R> {
    input: Counting<R>,
    limits: Limits,
    budget: AllocBudget,
    header: Option<Header>,
    chunks: Vec<ChunkInfo>,
}

/// Minimum and maximum payload length each known chunk type allows (spec §4).
fn length_range(ty: ChunkType) -> Option<(u32, u32)> {
    use super::meta::{MAX_SETTINGS_LEN, META_FIXED_LEN};
    use super::records::attribute_preamble_len as pre;
    Some(match ty {
        ChunkType::HEADER => (HEADER_LEN as u32, HEADER_LEN as u32),
        ChunkType::END | ChunkType::COLUMN_WEIGHTS | ChunkType::COLUMN_WEIGHTS_32 => (0, 0),
        ChunkType::POSITIONS => (pre(2) as u32, u32::MAX),
        ChunkType::COVARIANCE | ChunkType::COLORS => (pre(3) as u32, u32::MAX),
        ChunkType::OPACITY => (pre(1) as u32, u32::MAX),
        ChunkType::COMPRESSION_META => (
            META_FIXED_LEN as u32,
            (META_FIXED_LEN + MAX_SETTINGS_LEN) as u32,
        ),
        ChunkType::ENHANCER => (super::enhancer::MIN_ENHANCER_LEN as u32, u32::MAX),
        ChunkType::ORIGINAL_COLORS => ((5 + pre(3)) as u32, u32::MAX),
        ChunkType::TONE_CURVE => (
            super::trc::MIN_TRC_LEN as u32,
            super::trc::MAX_TRC_LEN as u32,
        ),
        _ => return None,
    })
}

impl<R: Read> Decoder<R> {
    pub fn new(input: R) -> Self {
        Self::with_limits(input, Limits::default())
    }

    pub fn with_limits(input: R, limits: Limits) -> Self {
        Decoder {
            input: Counting {
                inner: input,
                pos: 0,
            },
            budget: AllocBudget::new(&limits),
            limits,
            header: None,
            chunks: Vec::new(),
        }
    }

    /// Read the signature and the `GHDR` chunk (once), so size and count are known
    /// before any attribute is decoded.
    pub fn read_header(&mut self) -> Result<Header> {
        if let Some(h) = self.header {
            return Ok(h);
        }
        let mut sig = [0u8; 8];
        self.input
            .read_exact(&mut sig)
            .map_err(|e| Error::io(e).at(None, 0))?;
        if sig != SIGNATURE {
            return Err(Error::new(ErrorKind::BadSignature, "").at(None, 0));
        }
        let (offset, c) = self.next_chunk()?;
        if c.ty != ChunkType::HEADER {
            return Err(
                Error::new(ErrorKind::ChunkOrder, "first chunk must be GHDR")
                    .at(Some(c.ty), offset),
            );
        }
        let h = Header::parse(&c.data, &self.limits).map_err(|e| e.at(Some(c.ty), offset))?;
        self.header = Some(h);
        Ok(h)
    }

    /// Read the remaining chunks through `GEND` and assemble the file.
    pub fn finish(mut self) -> Result<GsiFile> {
        let header = self.read_header()?;
        let (mut pos, mut col, mut opa, mut meta) = (None, None, None, None);
        let mut cov: Option<Attribute> = None;
        let mut tone = None;
        let mut columns: Option<WeightRule> = None;
        // Stage 2's chunks are kept unparsed (spec §2.3), but each may appear once.
        let (mut enhancer, mut original) = (false, false);
        let mut ancillary = Vec::new();
        loop {
            let (offset, c) = self.next_chunk()?;
            let here = |e: Error| e.at(Some(c.ty), offset);
            let once = |seen: bool| {
                if seen {
                    Err(Error::new(ErrorKind::ChunkOrder, "appears twice").at(Some(c.ty), offset))
                } else {
                    Ok(())
                }
            };
            let (limits, budget) = (&self.limits, &mut self.budget);
            // Colours stored by footprint (method 5, §5.4.6) read the sizes of a
            // `log-scale-rotation` covariance read before them (§2.4); no other payload
            // needs them.
            let method = c.data.get(attribute_preamble_len(3) - 5).copied();
            let sizes = match (c.ty, method, &cov, header.cov_param) {
                (
                    ChunkType::COLORS,
                    Some(METHOD_FOOTPRINT),
                    Some(cov),
                    CovParam::LogScaleRotation,
                ) => Some(super::footprint::sizes(&cov.quantizers, &cov.codes).map_err(here)?),
                (ChunkType::COLORS, Some(METHOD_FOOTPRINT), _, CovParam::Cholesky) => {
                    return Err(here(invalid(
                        "GCOL in method 5 (colours by footprint) in a cholesky file",
                    )));
                }
                (ChunkType::COLORS, Some(METHOD_FOOTPRINT), None, _) => {
                    return Err(here(Error::new(
                        ErrorKind::ChunkOrder,
                        "GCOL in method 5 (colours by footprint) before GCOV",
                    )));
                }
                _ => None,
            };
            let mut attr = |comps| {
                Attribute::parse(
                    &c.data,
                    comps,
                    header.count,
                    limits,
                    budget,
                    sizes.as_deref(),
                )
                .map_err(here)
            };
            match c.ty {
                ChunkType::END => break,
                ChunkType::HEADER => {
                    return Err(
                        Error::new(ErrorKind::ChunkOrder, "appears twice").at(Some(c.ty), offset)
                    )
                }
                ChunkType::POSITIONS => {
                    once(pos.is_some())?;
                    pos = Some(attr(2)?);
                }
                ChunkType::COVARIANCE => {
                    once(cov.is_some())?;
                    cov = Some(attr(3)?);
                }
                ChunkType::COLORS => {
                    once(col.is_some())?;
                    col = Some(attr(3)?);
                }
                ChunkType::OPACITY => {
                    once(opa.is_some())?;
                    opa = Some(attr(1)?);
                }
                ChunkType::TONE_CURVE => {
                    once(tone.is_some())?;
                    tone = Some(super::trc::parse(&c.data).map_err(here)?);
                }
                ChunkType::COLUMN_WEIGHTS | ChunkType::COLUMN_WEIGHTS_32 => {
                    let rule = [WeightRule::Columns, WeightRule::Columns32]
                        .into_iter()
                        .find(|&r| ChunkType::of_weight_rule(r) == Some(c.ty))
                        .expect("a column rule's chunk");
                    // One column rule per file (spec §2.4).
                    if columns.is_some_and(|seen| seen != rule) {
                        return Err(Error::new(
                            ErrorKind::ChunkOrder,
                            "beside the other column rule's chunk (GCRW and GCRT)",
                        )
                        .at(Some(c.ty), offset));
                    }
                    once(columns.is_some())?;
                    columns = Some(rule);
                }
                ChunkType::COMPRESSION_META => {
                    once(meta.is_some())?;
                    meta = Some(CompressionMeta::parse(&c.data).map_err(here)?);
                }
                ChunkType::ENHANCER => {
                    once(enhancer)?;
                    enhancer = true;
                    ancillary.push(c);
                }
                ChunkType::ORIGINAL_COLORS => {
                    once(original)?;
                    original = true;
                    ancillary.push(c);
                }
                ty if ty.is_critical() => {
                    return Err(
                        Error::new(ErrorKind::UnknownCriticalChunk, "").at(Some(ty), offset)
                    );
                }
                _ => ancillary.push(c),
            }
        }
        let end = self.input.pos;
        let missing = |name: &str| {
            Error::new(
                ErrorKind::MissingChunk,
                format!("no {name} chunk before GEND"),
            )
            .at(None, end)
        };
        let records = Records {
            header,
            positions: pos.ok_or_else(|| missing("GPOS"))?,
            covariance: cov.ok_or_else(|| missing("GCOV"))?,
            colors: col.ok_or_else(|| missing("GCOL"))?,
            opacity: opa,
            tone,
            weights: columns.unwrap_or(WeightRule::PerPixel),
        };
        Ok(GsiFile {
            records,
            metadata: meta,
            ancillary,
            chunks: self.chunks,
            file_bytes: end,
        })
    }

    /// Read one framed chunk, checking type, length range, limits and CRC.
    fn next_chunk(&mut self) -> Result<(u64, RawChunk)> {
        let offset = self.input.pos;
        let mut head = [0u8; 8];
        self.input.read_exact(&mut head).map_err(|e| {
            let e = Error::io(e).at(None, offset);
            if e.kind() == ErrorKind::Truncated && self.input.pos == offset {
                Error::new(ErrorKind::Truncated, "stream ends before GEND").at(None, offset)
            } else {
                e
            }
        })?;
        let (len, ty) = chunk::parse_chunk_head(&head);
        let fail = |kind, detail: String| Err(Error::new(kind, detail).at(Some(ty), offset));
        if !ty.is_valid() {
            return fail(
                ErrorKind::BadChunkType,
                "type bytes must be ASCII letters".into(),
            );
        }
        if let Some((lo, hi)) = length_range(ty) {
            if len < lo || len > hi {
                return fail(
                    ErrorKind::BadChunkLength,
                    format!("{len} bytes, allowed {lo}..={hi}"),
                );
            }
        }
        if len > self.limits.max_chunk_len {
            return fail(
                ErrorKind::LimitExceeded,
                format!(
                    "{len} bytes exceeds the chunk limit of {}",
                    self.limits.max_chunk_len
                ),
            );
        }
        self.budget
            .reserve(u64::from(len), "chunk payload")
            .map_err(|e| e.at(Some(ty), offset))?;
        let data = chunk::read_payload(&mut self.input, len).map_err(|e| e.at(Some(ty), offset))?;
        let mut crc = [0u8; 4];
        self.input
            .read_exact(&mut crc)
            .map_err(|e| Error::io(e).at(Some(ty), offset))?;
        let stored = BigEndian::read_u32(&crc);
        let computed = chunk::chunk_crc(ty, &data);
        if stored != computed {
            return fail(
                ErrorKind::CrcMismatch,
                format!("stored {stored:#010x}, computed {computed:#010x}"),
            );
        }
        self.chunks.push(ChunkInfo {
            ty,
            offset,
            length: len,
            crc32: stored,
        });
        Ok((offset, RawChunk { ty, data }))
    }
}

/// Decode a whole file from a reader with the given limits.
pub fn read_file<R: Read>(input: R, limits: Limits) -> Result<GsiFile> {
    Decoder::with_limits(input, limits).finish()
}
