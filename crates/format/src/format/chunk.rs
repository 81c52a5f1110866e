//! Signature and chunk framing: `length u32 BE | type [u8; 4] | payload | CRC-32 u32 BE`.

use super::error::{Error, ErrorKind, Result};
use byteorder::{BigEndian, ByteOrder, WriteBytesExt};
use std::io::{Read, Write};

/// The eight bytes every gsi file starts with. As in PNG, the high-bit first byte catches
/// 7-bit transports, `\r\n` catches CRLF translation, `\x1a` stops DOS `type`, and the
/// final `\n` catches LF-to-CRLF translation.
pub const SIGNATURE: [u8; 8] = [0x89, b'G', b'S', b'I', b'\r', b'\n', 0x1a, b'\n'];

pub use super::chunk_type::ChunkType;

/// Where a chunk sat in the stream, as `gsi info` reports it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkInfo {
    pub ty: ChunkType,
    /// Offset of the chunk's length field from the start of the file.
    pub offset: u64,
    /// Payload length in bytes.
    pub length: u32,
    pub crc32: u32,
}

/// A whole chunk held in memory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RawChunk {
    pub ty: ChunkType,
    pub data: Vec<u8>,
}

/// CRC-32 (ISO-HDLC, as in PNG and zlib) of the type bytes followed by the payload.
pub fn chunk_crc(ty: ChunkType, data: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(&ty.0);
    h.update(data);
    h.finalize()
}

/// Write one framed chunk.
pub fn write_chunk<W: Write>(w: &mut W, ty: ChunkType, data: &[u8]) -> Result<()> {
    let len = u32::try_from(data.len()).map_err(|_| {
        Error::new(
            ErrorKind::LimitExceeded,
            format!("chunk {ty} payload of {} bytes", data.len()),
        )
    })?;
    w.write_u32::<BigEndian>(len)?;
    w.write_all(&ty.0)?;
    w.write_all(data)?;
    w.write_u32::<BigEndian>(chunk_crc(ty, data))?;
    Ok(())
}

/// Framed length of a chunk with a payload of `payload` bytes.
pub const fn framed_len(payload: usize) -> u64 {
    payload as u64 + 12
}

/// A reader that counts the bytes it has delivered, for error offsets.
pub struct Counting<R> {
    pub inner: R,
    pub pos: u64,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.pos += n as u64;
        Ok(n)
    }
}

/// The fixed 8-byte part in front of a payload.
pub fn parse_chunk_head(head: &[u8; 8]) -> (u32, ChunkType) {
    let len = BigEndian::read_u32(&head[..4]);
    (len, ChunkType([head[4], head[5], head[6], head[7]]))
}

/// Read exactly `len` bytes without reserving them up front: a length field that lies
/// about a short stream costs only the bytes actually present.
pub fn read_payload<R: Read>(r: &mut R, len: u32) -> Result<Vec<u8>> {
    let mut data = Vec::with_capacity((len as usize).min(1 << 16));
    r.take(u64::from(len)).read_to_end(&mut data)?;
    if data.len() != len as usize {
        return Err(Error::new(
            ErrorKind::Truncated,
            format!("payload has {} of {len} bytes", data.len()),
        ));
    }
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn criticality_follows_first_letter() {
        assert!(ChunkType::HEADER.is_critical());
        assert!(!ChunkType::COMPRESSION_META.is_critical());
        assert!(!ChunkType(*b"GH1R").is_valid());
    }

    #[test]
    fn crc_covers_type_and_payload() {
        // CRC-32 of "IEND" is PNG's well-known 0xAE426082.
        assert_eq!(chunk_crc(ChunkType(*b"IEND"), &[]), 0xAE42_6082);
        let mut v = Vec::new();
        write_chunk(&mut v, ChunkType::END, &[]).unwrap();
        assert_eq!(v.len(), 12);
        assert_eq!(&v[..8], b"\0\0\0\0GEND");
    }
}
