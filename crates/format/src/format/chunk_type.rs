//! The four-letter tag that names a chunk (spec §2): below the errors, which name the
//! chunk they were found in, and the framing, which reads it.

use crate::model::WeightRule;
use std::fmt;

/// A four-letter chunk type. Upper-case first letter: critical (a decoder that does not
/// know it must refuse the file); lower-case: ancillary (safe to skip).
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ChunkType(pub [u8; 4]);

impl ChunkType {
    pub const HEADER: ChunkType = ChunkType(*b"GHDR");
    pub const POSITIONS: ChunkType = ChunkType(*b"GPOS");
    pub const COVARIANCE: ChunkType = ChunkType(*b"GCOV");
    pub const COLORS: ChunkType = ChunkType(*b"GCOL");
    pub const OPACITY: ChunkType = ChunkType(*b"GOPA");
    pub const END: ChunkType = ChunkType(*b"GEND");
    /// The tone curve every blended value goes through (spec §6.6, version 1.2).
    pub const TONE_CURVE: ChunkType = ChunkType(*b"GTRC");
    /// Weights by the column rule (spec §6.3.2, version 1.4): empty, its presence is the
    /// message.
    pub const COLUMN_WEIGHTS: ChunkType = ChunkType(*b"GCRW");
    /// Weights by the column rule in bands of 32 rows (spec §6.3.2, version 1.5): empty,
    /// as `GCRW`, which a file may not carry beside it.
    pub const COLUMN_WEIGHTS_32: ChunkType = ChunkType(*b"GCRT");
    /// Compression metadata.
    pub const COMPRESSION_META: ChunkType = ChunkType(*b"gCRM");
    /// Reserved: a fitted stage-2 enhancer.
    pub const ENHANCER: ChunkType = ChunkType(*b"gENH");
    /// Reserved: the colour records as they were before enhancement.
    pub const ORIGINAL_COLORS: ChunkType = ChunkType(*b"gORC");

    /// The chunk that says a file weighs by `rule` (spec §6.3.2), `None` for the
    /// per-pixel rule, which no chunk announces. The reader and the writer both map
    /// through it.
    pub fn of_weight_rule(rule: WeightRule) -> Option<ChunkType> {
        match rule {
            WeightRule::PerPixel => None,
            WeightRule::Columns => Some(ChunkType::COLUMN_WEIGHTS),
            WeightRule::Columns32 => Some(ChunkType::COLUMN_WEIGHTS_32),
        }
    }

    pub fn is_critical(self) -> bool {
        self.0[0].is_ascii_uppercase()
    }

    /// Every byte an ASCII letter.
    pub fn is_valid(self) -> bool {
        self.0.iter().all(u8::is_ascii_alphabetic)
    }

    pub fn as_str(&self) -> &str {
        std::str::from_utf8(&self.0).unwrap_or("????")
    }
}

impl fmt::Display for ChunkType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_valid() {
            f.write_str(self.as_str())
        } else {
            write!(
                f,
                "{:02x}{:02x}{:02x}{:02x}",
                self.0[0], self.0[1], self.0[2], self.0[3]
            )
        }
    }
}

impl fmt::Debug for ChunkType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ChunkType({self})")
    }
}
