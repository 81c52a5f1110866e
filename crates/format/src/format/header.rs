//! The `GHDR` chunk: what a decoder must know before any attribute.

use super::error::{invalid, Error, ErrorKind, Result};
use super::limits::Limits;
use crate::model::{Blend, CovParam};
use byteorder::{BigEndian, ByteOrder};

/// Major version this decoder implements; a file with another major is refused.
pub const VERSION_MAJOR: u8 = 1;
/// Minor version of a file that no coded payload (method 2 or 3) needs; minors add only what a
/// lower one may ignore, or refuses by name (§2.5).
pub const VERSION_MINOR: u8 = 0;
/// Minor version of a file with a payload of compression method 2 (§5.4).
pub const VERSION_MINOR_CODED: u8 = 1;
/// Minor version of a file with a payload of compression method 3 (§5.4.4).
pub const VERSION_MINOR_CODED_RAW: u8 = 6;
/// Minor version of a file with a payload of compression method 4 (§5.4.5).
pub const VERSION_MINOR_SHAPED: u8 = 7;
/// The least minor version of a file that holds a payload of method 5 (colours at the
/// precision of their footprint, §5.4.6).
pub const VERSION_MINOR_FOOTPRINT: u8 = 8;
/// Exact payload length of `GHDR`.
pub const HEADER_LEN: usize = 18;

/// Header flag: Gaussians are stored most important first, so a prefix renders a preview.
pub const FLAG_IMPORTANCE_ORDERED: u8 = 1;

/// Colour space of the colour records.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ColorSpace {
    /// sRGB-encoded R, G, B (the transfer curve is applied: values are display values).
    Srgb,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    pub version_major: u8,
    pub version_minor: u8,
    pub width: u32,
    pub height: u32,
    pub count: u32,
    pub blend: Blend,
    pub cov_param: CovParam,
    pub color_space: ColorSpace,
    pub flags: u8,
}

impl Header {
    pub fn new(width: u32, height: u32, count: u32, blend: Blend, cov_param: CovParam) -> Self {
        Header {
            version_major: VERSION_MAJOR,
            version_minor: VERSION_MINOR,
            width,
            height,
            count,
            blend,
            cov_param,
            color_space: ColorSpace::Srgb,
            flags: 0,
        }
    }

    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        b[0] = self.version_major;
        b[1] = self.version_minor;
        BigEndian::write_u32(&mut b[2..6], self.width);
        BigEndian::write_u32(&mut b[6..10], self.height);
        BigEndian::write_u32(&mut b[10..14], self.count);
        b[14] = match self.blend {
            Blend::Sum => 0,
            Blend::Alpha => 1,
        };
        b[15] = match self.cov_param {
            CovParam::Cholesky => 0,
            CovParam::LogScaleRotation => 1,
        };
        b[16] = match self.color_space {
            ColorSpace::Srgb => 0,
        };
        b[17] = self.flags;
        b
    }

    /// Parse and validate a `GHDR` payload (its length is checked by the framing layer).
    pub fn parse(b: &[u8], limits: &Limits) -> Result<Header> {
        if b.len() != HEADER_LEN {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                format!("GHDR is {} bytes, not {HEADER_LEN}", b.len()),
            ));
        }
        if b[0] != VERSION_MAJOR {
            return Err(Error::new(
                ErrorKind::UnsupportedVersion,
                format!(
                    "major version {} (this decoder reads {VERSION_MAJOR})",
                    b[0]
                ),
            ));
        }
        let width = BigEndian::read_u32(&b[2..6]);
        let height = BigEndian::read_u32(&b[6..10]);
        let count = BigEndian::read_u32(&b[10..14]);
        if width == 0 || height == 0 {
            return Err(invalid(format!("image size {width}x{height} is empty")));
        }
        if width > limits.max_dimension || height > limits.max_dimension {
            return Err(Error::new(
                ErrorKind::LimitExceeded,
                format!(
                    "image size {width}x{height} exceeds {} per side",
                    limits.max_dimension
                ),
            ));
        }
        if count > limits.max_gaussians {
            return Err(Error::new(
                ErrorKind::LimitExceeded,
                format!(
                    "{count} Gaussians exceeds the limit of {}",
                    limits.max_gaussians
                ),
            ));
        }
        let blend = match b[14] {
            0 => Blend::Sum,
            1 => Blend::Alpha,
            v => return Err(invalid(format!("blend mode {v}"))),
        };
        let cov_param = match b[15] {
            0 => CovParam::Cholesky,
            1 => CovParam::LogScaleRotation,
            v => return Err(invalid(format!("covariance parameterization {v}"))),
        };
        let color_space = match b[16] {
            0 => ColorSpace::Srgb,
            v => return Err(invalid(format!("colour space {v}"))),
        };
        Ok(Header {
            version_major: b[0],
            version_minor: b[1],
            width,
            height,
            count,
            blend,
            cov_param,
            color_space,
            flags: b[17],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_roundtrips() {
        let mut h = Header::new(768, 512, 9000, Blend::Alpha, CovParam::LogScaleRotation);
        h.flags = FLAG_IMPORTANCE_ORDERED;
        assert_eq!(Header::parse(&h.to_bytes(), &Limits::default()).unwrap(), h);
    }

    #[test]
    fn header_refuses_bad_fields() {
        let good = Header::new(4, 4, 1, Blend::Sum, CovParam::Cholesky).to_bytes();
        let l = Limits::default();
        let kind = |f: &dyn Fn(&mut [u8; HEADER_LEN])| {
            let mut b = good;
            f(&mut b);
            Header::parse(&b, &l).unwrap_err().kind()
        };
        assert_eq!(kind(&|b| b[0] = 2), ErrorKind::UnsupportedVersion);
        assert_eq!(
            kind(&|b| b[2..6].copy_from_slice(&[0; 4])),
            ErrorKind::InvalidValue
        );
        assert_eq!(
            kind(&|b| b[10..14].copy_from_slice(&[0xff; 4])),
            ErrorKind::LimitExceeded
        );
        assert_eq!(kind(&|b| b[14] = 7), ErrorKind::InvalidValue);
        assert_eq!(kind(&|b| b[15] = 2), ErrorKind::InvalidValue);
        assert_eq!(kind(&|b| b[16] = 1), ErrorKind::InvalidValue);
    }
}
