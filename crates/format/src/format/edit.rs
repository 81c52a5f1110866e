//! Rewriting a file in place of its colours, keeping every other chunk byte for byte.
//!
//! Stage 2 changes one attribute of a finished file. Re-encoding the whole file would
//! re-quantize and re-compress the geometry, so it could change bytes the enhancer never
//! touched, and undoing it could not be exact. Instead a file is handled as its list of
//! chunks: `GCOL` is replaced, `gCRM` is rewritten to describe the new size (spec §7.1),
//! `GTRC`, `gENH` and `gORC` are added before `GEND`, and everything else is copied
//! untouched (spec §7.4).

use super::chunk::{framed_len, write_chunk, ChunkType, RawChunk, SIGNATURE};
use super::enhancer::{EnhancerRecord, OriginalColors};
use super::error::{invalid, Error, ErrorKind, Result};
use super::limits::Limits;
use super::meta::{CompressionMeta, MAX_SETTINGS_LEN};
use super::reader::{read_file, GsiFile};
use super::records::{newest_coding, Attribute};
use crate::model::ToneCurve;

/// A validated file together with the payload of each of its chunks, in stream order.
#[derive(Clone, Debug)]
pub struct ChunkedFile {
    pub file: GsiFile,
    /// Every chunk from `GHDR` through `GEND`.
    pub chunks: Vec<RawChunk>,
}

impl ChunkedFile {
    /// Parse and validate `bytes` as a whole file (bytes after `GEND` are ignored).
    pub fn parse(bytes: &[u8], limits: Limits) -> Result<ChunkedFile> {
        let file = read_file(bytes, limits)?;
        let chunks = file
            .chunks
            .iter()
            .map(|c| {
                let start = c.offset as usize + 8;
                RawChunk {
                    ty: c.ty,
                    data: bytes[start..start + c.length as usize].to_vec(),
                }
            })
            .collect();
        Ok(ChunkedFile { file, chunks })
    }

    fn find(&self, ty: ChunkType) -> Option<&RawChunk> {
        self.chunks.iter().find(|c| c.ty == ty)
    }

    /// Tag an error about the content of chunk `ty` with where that chunk sits.
    fn blame(&self, ty: ChunkType) -> impl Fn(Error) -> Error + '_ {
        move |e| match self.file.chunks.iter().find(|c| c.ty == ty) {
            Some(c) => e.at(Some(ty), c.offset),
            None => e,
        }
    }

    /// The stored enhancer, if the file has one.
    pub fn enhancer(&self, limits: &Limits) -> Result<Option<EnhancerRecord>> {
        self.find(ChunkType::ENHANCER)
            .map(|c| {
                EnhancerRecord::parse(&c.data, limits).map_err(self.blame(ChunkType::ENHANCER))
            })
            .transpose()
    }

    /// The colours as they were before stage 2, if the file kept them, checked as spec
    /// §7.3 asks: a `GCOL` payload for this file's header, and a valid `gCRM` payload
    /// where the flag says one follows. An invalid `gORC` is an error, so that nothing
    /// calls a file revertible that [`revert`](Self::revert) would refuse.
    pub fn original(&self) -> Result<Option<OriginalColors>> {
        let Some(c) = self.find(ChunkType::ORIGINAL_COLORS) else {
            return Ok(None);
        };
        let blame = self.blame(ChunkType::ORIGINAL_COLORS);
        let orc = OriginalColors::parse(&c.data).map_err(&blame)?;
        orc.validate(&self.file.records).map_err(&blame)?;
        Ok(Some(orc))
    }

    /// The colour records stage 2 starts from: those in `gORC` when the file was already
    /// enhanced and kept them, else those in `GCOL`.
    pub fn base_colors(&self, limits: &Limits) -> Result<Attribute> {
        match self.original()? {
            Some(orc) => {
                let count = self.file.records.header.count;
                let sizes = self.file.records.footprint_sizes();
                Attribute::parse_standalone(&orc.colors, 3, count, limits, sizes.as_deref())
                    .map_err(self.blame(ChunkType::ORIGINAL_COLORS))
            }
            None => Ok(self.file.records.colors.clone()),
        }
    }

    /// A copy of this file whose colours are `colors`, made by `enhancer`.
    ///
    /// The colours the file had before its first enhancement go into `gORC` when
    /// `keep_original`, so that [`revert`](Self::revert) can restore it byte for byte.
    /// The file shows its blended values through `tone` (spec §6.6) where there is one;
    /// any `GTRC` it had is dropped.
    pub fn with_colors(
        &self,
        colors: &Attribute,
        enhancer: &EnhancerRecord,
        tone: Option<&ToneCurve>,
        keep_original: bool,
        zstd_level: i32,
    ) -> Result<Vec<u8>> {
        let header = &self.file.records.header;
        if colors.components() != 3 || colors.count() != header.count as usize {
            return Err(invalid(
                "replacement colours do not match the header's count",
            ));
        }
        let original = match self.original()? {
            Some(orc) => orc,
            None => OriginalColors {
                colors: self
                    .find(ChunkType::COLORS)
                    .expect("validated")
                    .data
                    .clone(),
                metadata: self
                    .find(ChunkType::COMPRESSION_META)
                    .map(|c| c.data.clone()),
            },
        };
        let mut out: Vec<RawChunk> = Vec::with_capacity(self.chunks.len() + 2);
        for c in &self.chunks {
            match c.ty {
                ChunkType::ENHANCER | ChunkType::ORIGINAL_COLORS | ChunkType::TONE_CURVE => {}
                ChunkType::END => {
                    if let Some(t) = tone {
                        out.push(RawChunk {
                            ty: ChunkType::TONE_CURVE,
                            data: super::trc::to_payload(t),
                        });
                    }
                    out.push(RawChunk {
                        ty: ChunkType::ENHANCER,
                        data: enhancer.to_payload(zstd_level)?,
                    });
                    if keep_original {
                        out.push(RawChunk {
                            ty: ChunkType::ORIGINAL_COLORS,
                            data: original.to_payload()?,
                        });
                    }
                    out.push(c.clone());
                }
                // `GHDR` is kept byte for byte (§7.4), so the colours take only a method
                // its minor allows: a 1.0 file stays readable by 1.0 decoders, a 1.1 file
                // may use method 2, a 1.6 file (or 1.7: colours are never shaped) method 3.
                ChunkType::COLORS => out.push(RawChunk {
                    ty: c.ty,
                    data: colors
                        .to_payload_coded(zstd_level, newest_coding(header.version_minor))?,
                }),
                _ => out.push(c.clone()),
            }
        }
        if let Some(old) = &original.metadata {
            let old =
                CompressionMeta::parse(old).map_err(self.blame(ChunkType::COMPRESSION_META))?;
            let mut settings = old.settings;
            let line = "stage2=enhanced (colours rewritten by gENH; psnr refers to none)";
            if settings.len() + line.len() < MAX_SETTINGS_LEN {
                if !settings.is_empty() {
                    settings.push('\n');
                }
                settings.push_str(line);
            }
            // The ratios describe this file, so they wait until its size is known; the
            // stage-1 PSNR compared other colours with the input and is dropped.
            let meta_len = CompressionMeta::payload_len(&settings);
            let total = SIGNATURE.len() as u64
                + out
                    .iter()
                    .map(|c| match c.ty {
                        ChunkType::COMPRESSION_META => framed_len(meta_len),
                        _ => framed_len(c.data.len()),
                    })
                    .sum::<u64>();
            let has_opacity = self.file.records.opacity.is_some();
            let meta = CompressionMeta::new(header, has_opacity, total, None, settings);
            for c in out
                .iter_mut()
                .filter(|c| c.ty == ChunkType::COMPRESSION_META)
            {
                c.data = meta.to_payload();
            }
        }
        join(&out)
    }

    /// The file as it was before stage 2: `GCOL` and `gCRM` from `gORC`, and no `gENH`,
    /// `gORC` or `GTRC`. Exact for files whose chunks were last rewritten by
    /// [`with_colors`](Self::with_colors).
    pub fn revert(&self) -> Result<Vec<u8>> {
        let original = self.original()?.ok_or_else(|| {
            Error::new(
                ErrorKind::MissingChunk,
                "no gORC chunk: the original colours were not kept (or the file was never enhanced)",
            )
        })?;
        let mut out = Vec::with_capacity(self.chunks.len());
        for c in &self.chunks {
            match c.ty {
                ChunkType::ENHANCER | ChunkType::ORIGINAL_COLORS | ChunkType::TONE_CURVE => {}
                ChunkType::COLORS => out.push(RawChunk {
                    ty: c.ty,
                    data: original.colors.clone(),
                }),
                ChunkType::COMPRESSION_META => {
                    if let Some(m) = &original.metadata {
                        out.push(RawChunk {
                            ty: c.ty,
                            data: m.clone(),
                        });
                    }
                }
                _ => out.push(c.clone()),
            }
        }
        let bytes = join(&out)?;
        // The restored chunks came from an ancillary chunk nobody validated: check the
        // result as a whole before anyone writes it.
        read_file(&bytes[..], Limits::default())?;
        Ok(bytes)
    }
}

/// Serialize a chunk list (which must end with `GEND`) behind the signature.
fn join(chunks: &[RawChunk]) -> Result<Vec<u8>> {
    let total =
        SIGNATURE.len() as u64 + chunks.iter().map(|c| framed_len(c.data.len())).sum::<u64>();
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(&SIGNATURE);
    for c in chunks {
        write_chunk(&mut out, c.ty, &c.data)?;
    }
    Ok(out)
}
