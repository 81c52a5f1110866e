//! The `gCRM` ancillary chunk: how much smaller than raw pixels the file is, and how good.

use super::error::{invalid, Error, ErrorKind, Result};
use super::header::Header;
use byteorder::{BigEndian, ByteOrder, WriteBytesExt};

/// Fixed part of a `gCRM` payload; UTF-8 encoder settings follow.
pub const META_FIXED_LEN: usize = 26;
/// Longest settings text.
pub const MAX_SETTINGS_LEN: usize = 4096;
const FLAG_PSNR: u8 = 1;

/// Compression figures as the encoder saw them when it wrote the file.
#[derive(Clone, Debug, PartialEq)]
pub struct CompressionMeta {
    /// Size of the whole file these figures describe, this chunk included.
    pub file_bytes: u64,
    /// Scalars per Gaussian: 2 position + 3 covariance + 3 colour (+ 1 opacity).
    pub dof_per_gaussian: u8,
    /// Paper Eq. 10 with the actual parameter count: `3·W·H / (dof · N)`; 0 when N = 0.
    pub cr_dof: f32,
    /// Raw 8-bit RGB bytes over file bytes: `3·W·H / file_bytes`.
    pub cr_bytes: f32,
    /// Bits per pixel of the reference size: `8 · file_bytes / (W·H)`.
    pub bpp: f32,
    /// PSNR (dB, 8-bit RGB) of the stored, quantized result against the encoder's input.
    pub psnr: Option<f32>,
    /// Free-form `key=value` lines describing how the file was made.
    pub settings: String,
}

/// Ratios of a file of `file_bytes` bytes holding `header.count` Gaussians.
pub fn ratios(header: &Header, has_opacity: bool, file_bytes: u64) -> (u8, f32, f32, f32) {
    let dof = if has_opacity { 9u8 } else { 8 };
    let px = f64::from(header.width) * f64::from(header.height);
    let cr_dof = if header.count == 0 {
        0.0
    } else {
        3.0 * px / (f64::from(dof) * f64::from(header.count))
    };
    let cr_bytes = 3.0 * px / file_bytes.max(1) as f64;
    let bpp = 8.0 * file_bytes as f64 / px;
    (dof, cr_dof as f32, cr_bytes as f32, bpp as f32)
}

impl CompressionMeta {
    pub fn new(
        header: &Header,
        has_opacity: bool,
        file_bytes: u64,
        psnr: Option<f32>,
        settings: String,
    ) -> Self {
        let (dof_per_gaussian, cr_dof, cr_bytes, bpp) = ratios(header, has_opacity, file_bytes);
        CompressionMeta {
            file_bytes,
            dof_per_gaussian,
            cr_dof,
            cr_bytes,
            bpp,
            psnr: psnr.filter(|p| *p >= 0.0),
            settings,
        }
    }

    /// Payload length, known before the ratios are (the writer needs it to size the file).
    pub fn payload_len(settings: &str) -> usize {
        META_FIXED_LEN + settings.len()
    }

    pub fn to_payload(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(Self::payload_len(&self.settings));
        out.write_u64::<BigEndian>(self.file_bytes).unwrap();
        out.push(self.dof_per_gaussian);
        out.push(if self.psnr.is_some() { FLAG_PSNR } else { 0 });
        for v in [
            self.cr_dof,
            self.cr_bytes,
            self.bpp,
            self.psnr.unwrap_or(0.0),
        ] {
            out.write_f32::<BigEndian>(v).unwrap();
        }
        out.extend_from_slice(self.settings.as_bytes());
        out
    }

    pub fn parse(p: &[u8]) -> Result<CompressionMeta> {
        if p.len() < META_FIXED_LEN || p.len() > META_FIXED_LEN + MAX_SETTINGS_LEN {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                format!("gCRM of {} bytes", p.len()),
            ));
        }
        let f = |at: usize| BigEndian::read_f32(&p[at..at + 4]);
        let (cr_dof, cr_bytes, bpp, psnr) = (f(10), f(14), f(18), f(22));
        // PSNR alone may be +∞: the stored result can equal the input exactly.
        let ratios_ok = [cr_dof, cr_bytes, bpp]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0);
        if !ratios_ok || psnr.is_nan() || psnr < 0.0 {
            return Err(invalid("gCRM holds a negative or non-finite figure"));
        }
        if !matches!(p[8], 8 | 9) {
            return Err(invalid(format!(
                "gCRM counts {} parameters per Gaussian",
                p[8]
            )));
        }
        let settings = std::str::from_utf8(&p[META_FIXED_LEN..])
            .map_err(|_| invalid("gCRM settings are not UTF-8"))?
            .to_owned();
        Ok(CompressionMeta {
            file_bytes: BigEndian::read_u64(&p[..8]),
            dof_per_gaussian: p[8],
            cr_dof,
            cr_bytes,
            bpp,
            psnr: (p[9] & FLAG_PSNR != 0).then_some(psnr),
            settings,
        })
    }
}
