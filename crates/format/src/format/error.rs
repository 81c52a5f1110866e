//! Typed decoding errors that carry where in the byte stream they happened.

use super::chunk_type::ChunkType;
use std::fmt;

/// What went wrong, as a stable category (the corpus test and the CLI rely on it).
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// The underlying reader or writer failed.
    Io,
    /// The stream ended inside the signature, a chunk, or before `GEND`.
    Truncated,
    /// The first eight bytes are not the gsi signature.
    BadSignature,
    /// A chunk's CRC-32 does not match its type and payload.
    CrcMismatch,
    /// A critical chunk (upper-case first letter) this decoder does not know.
    UnknownCriticalChunk,
    /// A chunk type with bytes outside ASCII letters.
    BadChunkType,
    /// A chunk appears where the ordering rules forbid it, or twice.
    ChunkOrder,
    /// A required chunk is absent.
    MissingChunk,
    /// A chunk's length is outside the range its type allows.
    BadChunkLength,
    /// The file's major version is not one this decoder implements.
    UnsupportedVersion,
    /// A field holds a value the specification does not allow.
    InvalidValue,
    /// Honouring the file would exceed a [`Limits`](super::Limits) bound.
    LimitExceeded,
    /// A zstd payload is corrupt or decompresses to the wrong size.
    Decompression,
}

impl ErrorKind {
    /// Short, stable identifier (used in corpus manifests and machine-readable output).
    pub fn name(self) -> &'static str {
        match self {
            ErrorKind::Io => "io",
            ErrorKind::Truncated => "truncated",
            ErrorKind::BadSignature => "bad-signature",
            ErrorKind::CrcMismatch => "crc-mismatch",
            ErrorKind::UnknownCriticalChunk => "unknown-critical-chunk",
            ErrorKind::BadChunkType => "bad-chunk-type",
            ErrorKind::ChunkOrder => "chunk-order",
            ErrorKind::MissingChunk => "missing-chunk",
            ErrorKind::BadChunkLength => "bad-chunk-length",
            ErrorKind::UnsupportedVersion => "unsupported-version",
            ErrorKind::InvalidValue => "invalid-value",
            ErrorKind::LimitExceeded => "limit-exceeded",
            ErrorKind::Decompression => "decompression",
        }
    }

    fn describe(self) -> &'static str {
        match self {
            ErrorKind::Io => "I/O error",
            ErrorKind::Truncated => "unexpected end of file",
            ErrorKind::BadSignature => "not a gsi file (bad signature)",
            ErrorKind::CrcMismatch => "CRC mismatch",
            ErrorKind::UnknownCriticalChunk => "unknown critical chunk",
            ErrorKind::BadChunkType => "invalid chunk type",
            ErrorKind::ChunkOrder => "chunk out of order",
            ErrorKind::MissingChunk => "missing required chunk",
            ErrorKind::BadChunkLength => "bad chunk length",
            ErrorKind::UnsupportedVersion => "unsupported version",
            ErrorKind::InvalidValue => "invalid value",
            ErrorKind::LimitExceeded => "limit exceeded",
            ErrorKind::Decompression => "corrupt compressed data",
        }
    }
}

/// A decoding or encoding failure: its kind, the chunk it concerns and the byte offset
/// of the chunk (or of the offending field) in the stream, when known.
#[derive(Debug)]
pub struct Error {
    kind: ErrorKind,
    chunk: Option<ChunkType>,
    offset: Option<u64>,
    detail: String,
    source: Option<std::io::Error>,
}

impl Error {
    pub fn new(kind: ErrorKind, detail: impl Into<String>) -> Self {
        Error {
            kind,
            chunk: None,
            offset: None,
            detail: detail.into(),
            source: None,
        }
    }

    pub fn io(e: std::io::Error) -> Self {
        let kind = if e.kind() == std::io::ErrorKind::UnexpectedEof {
            ErrorKind::Truncated
        } else {
            ErrorKind::Io
        };
        Error {
            kind,
            chunk: None,
            offset: None,
            detail: String::new(),
            source: Some(e),
        }
    }

    /// Attach the chunk and offset, keeping any that are already set (the innermost wins).
    pub fn at(mut self, chunk: Option<ChunkType>, offset: u64) -> Self {
        self.chunk = self.chunk.or(chunk);
        self.offset = self.offset.or(Some(offset));
        self
    }

    pub fn kind(&self) -> ErrorKind {
        self.kind
    }
    pub fn chunk(&self) -> Option<ChunkType> {
        self.chunk
    }
    pub fn offset(&self) -> Option<u64> {
        self.offset
    }
}

impl fmt::Display for Error {
    /// One line, e.g. `CRC mismatch in chunk GCOL at byte 1234: stored 0x…, computed 0x…`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.kind.describe())?;
        if let Some(c) = self.chunk {
            write!(f, " in chunk {c}")?;
        }
        if let Some(o) = self.offset {
            write!(f, " at byte {o}")?;
        }
        if !self.detail.is_empty() {
            write!(f, ": {}", self.detail)?;
        }
        if let Some(e) = &self.source {
            write!(f, ": {e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.source.as_ref().map(|e| e as _)
    }
}

impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Self {
        Error::io(e)
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Shorthand for an [`ErrorKind::InvalidValue`] error.
pub fn invalid(detail: impl Into<String>) -> Error {
    Error::new(ErrorKind::InvalidValue, detail)
}
