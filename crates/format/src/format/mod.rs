//! The `.gsi` container: bytes in, records out, and back. Knows nothing of rendering.
//!
//! `format-spec.md` at the repository root is the normative description of every byte
//! handled here; section numbers in comments refer to it.

pub mod angle;
mod chunk;
mod chunk_type;
mod coder;
pub mod context;
mod edit;
mod enhancer;
mod error;
pub mod footprint;
mod header;
mod limits;
mod meta;
pub mod quant;
mod reader;
mod records;
pub mod settings;
pub mod trc;
mod writer;

pub use chunk::{chunk_crc, ChunkInfo, ChunkType, RawChunk, SIGNATURE};
pub use edit::ChunkedFile;
pub use enhancer::{
    tensor_sizes, ChromaMap, Denoise, EnhancerRecord, FitSettings, GainMap, OriginalColors,
    Speckle, Tone, MAX_DENOISE_PASSES, MAX_EXPERTS, MAX_GAIN, MAX_HIDDEN, MAX_TONE_EXPONENT,
    MAX_TONE_PASSES, TENSORS,
};
pub use error::{Error, ErrorKind, Result};
pub use header::{
    ColorSpace, Header, FLAG_IMPORTANCE_ORDERED, VERSION_MAJOR, VERSION_MINOR, VERSION_MINOR_CODED,
    VERSION_MINOR_CODED_RAW, VERSION_MINOR_FOOTPRINT, VERSION_MINOR_SHAPED,
};
pub use limits::{Limits, DEFAULT_RENDER_WORK};
pub use meta::CompressionMeta;
pub use quant::{Quantizer, MAX_BITS};
pub use reader::{read_file, Decoder, GsiFile};
pub use records::{
    minor_for_method, Attribute, BitDepths, Records, METHOD_CODED, METHOD_CODED_RAW,
    METHOD_FOOTPRINT, METHOD_SHAPED,
};
pub use settings::EncoderSettings;
pub use writer::{to_bytes, write_file, WriteOptions};

/// Small fixtures for doc examples and tests. Not part of the stable API.
#[doc(hidden)]
pub mod tests_support {
    use super::*;
    use crate::model::{Blend, CovParam, GaussianSet, Scene};

    /// A 4×3 scene of two Gaussians.
    pub fn tiny_scene() -> Scene {
        Scene {
            tone: None,
            weights: crate::model::WeightRule::PerPixel,
            width: 4,
            height: 3,
            blend: Blend::Sum,
            cov_param: CovParam::Cholesky,
            gaussians: GaussianSet {
                positions: vec![[0.25, 0.5], [0.75, 0.5]],
                cov: vec![[0.25, 0.0, 0.25], [0.125, 0.0625, 0.25]],
                colors: vec![[1.0, 0.5, 0.0], [0.0, 0.25, 1.0]],
                opacity: None,
            },
        }
    }

    /// [`tiny_scene`] written with 8-bit quantizers and no `gCRM`.
    pub fn tiny_file() -> Vec<u8> {
        let bits = BitDepths {
            position: 8,
            covariance: 8,
            angle: 8,
            angle_by_shape: false,
            color_by_footprint: false,
            color: 8,
            opacity: 8,
        };
        let opts = WriteOptions {
            settings: None,
            ..WriteOptions::default()
        };
        to_bytes(&Records::from_scene(&tiny_scene(), bits), &opts).expect("in-memory write")
    }
}
