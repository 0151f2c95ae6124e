//! Byte-level helpers: LEB128 varints, a bounds-checked reader, and section framing
//! (tag, length, optional zlib, CRC-32). See `spec/format.md` §2-§3.

#[cfg(any(feature = "encoder", feature = "internals"))]
use std::io::Write;

use crate::error::{Error, Result};

/// Appends `v` as an unsigned LEB128 varint (7 bits per byte, low first).
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    loop {
        let b = (v & 0x7F) as u8;
        v >>= 7;
        if v == 0 {
            out.push(b);
            return;
        }
        out.push(b | 0x80);
    }
}

/// Bounds-checked reader over a byte slice; every error names the section and field.
pub struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    pub section: &'static str,
}

impl<'a> Reader<'a> {
    pub fn new(data: &'a [u8], section: &'static str) -> Self {
        Reader {
            data,
            pos: 0,
            section,
        }
    }

    pub fn pos(&self) -> usize {
        self.pos
    }

    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    pub fn is_empty(&self) -> bool {
        self.remaining() == 0
    }

    pub fn err(&self, field: &'static str, detail: impl Into<String>) -> Error {
        Error::format(self.section, field, detail)
    }

    pub fn u8(&mut self, field: &'static str) -> Result<u8> {
        let b = *self
            .data
            .get(self.pos)
            .ok_or_else(|| self.err(field, "data ends early"))?;
        self.pos += 1;
        Ok(b)
    }

    pub fn bytes(&mut self, n: usize, field: &'static str) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(self.err(
                field,
                format!("needs {n} bytes, only {} left", self.remaining()),
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    pub fn rest(&mut self) -> &'a [u8] {
        let s = &self.data[self.pos..];
        self.pos = self.data.len();
        s
    }

    /// Reads an unsigned LEB128 varint of at most 10 bytes; rejects overlong encodings
    /// (a final zero byte after the first) and values above `u64::MAX`.
    pub fn varint(&mut self, field: &'static str) -> Result<u64> {
        let mut v = 0u64;
        for i in 0..10 {
            let b = self.u8(field)?;
            let payload = u64::from(b & 0x7F);
            if i == 9 && payload > 1 {
                return Err(self.err(field, "varint overflows 64 bits"));
            }
            v |= payload << (7 * i);
            if b & 0x80 == 0 {
                if i > 0 && b == 0 {
                    return Err(self.err(field, "overlong varint"));
                }
                return Ok(v);
            }
        }
        Err(self.err(field, "varint longer than 10 bytes"))
    }

    /// Reads a varint that must not exceed `max`.
    pub fn varint_max(&mut self, field: &'static str, max: u64) -> Result<u64> {
        let v = self.varint(field)?;
        if v > max {
            return Err(self.err(field, format!("value {v} exceeds the maximum {max}")));
        }
        Ok(v)
    }

    pub fn f32(&mut self, field: &'static str) -> Result<f32> {
        let b = self.bytes(4, field)?;
        Ok(f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub fn f64(&mut self, field: &'static str) -> Result<f64> {
        let b = self.bytes(8, field)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(f64::from_le_bytes(a))
    }

    pub fn i16(&mut self, field: &'static str) -> Result<i16> {
        let b = self.bytes(2, field)?;
        Ok(i16::from_le_bytes([b[0], b[1]]))
    }

    /// Fails unless every byte was consumed.
    pub fn expect_end(&self) -> Result<()> {
        if self.remaining() != 0 {
            return Err(self.err(
                "end",
                format!("{} unexpected trailing bytes", self.remaining()),
            ));
        }
        Ok(())
    }
}

/// Section tag bit: payload is zlib-deflated.
pub const TAG_DEFLATED: u8 = 0x80;
/// Section tag bit: a decoder that does not know this section id may skip it.
pub const TAG_SKIPPABLE: u8 = 0x40;
/// Mask of the section id inside the tag byte.
pub const TAG_ID_MASK: u8 = 0x3F;
/// Payloads smaller than this are never tried with zlib (it cannot win).
#[cfg(any(feature = "encoder", feature = "internals"))]
const MIN_DEFLATE_TRY: usize = 24;

/// Appends one section: `tag | len | [raw_len] | payload | crc32`. The payload is deflated
/// when that makes it smaller (and `allow_deflate`). `crc_start` is where the CRC coverage
/// begins in `out` (the tag byte, or the file start for the header section).
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn put_section(
    out: &mut Vec<u8>,
    id: u8,
    payload: &[u8],
    allow_deflate: bool,
    crc_from_file_start: bool,
) {
    let start = if crc_from_file_start { 0 } else { out.len() };
    let mut deflated: Option<Vec<u8>> = None;
    if allow_deflate && payload.len() >= MIN_DEFLATE_TRY {
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        // Writing into a Vec cannot fail.
        let dynamic = z.write_all(payload).ok().and_then(|()| z.finish().ok());
        let mut overhead = Vec::new();
        put_varint(&mut overhead, payload.len() as u64);
        for c in [dynamic, zlib_static_blocks(payload)].into_iter().flatten() {
            let best = deflated
                .as_ref()
                .map_or(payload.len(), |d| d.len() + overhead.len());
            if c.len() + overhead.len() < best {
                deflated = Some(c);
            }
        }
    }
    match deflated {
        Some(c) => {
            out.push(id | TAG_DEFLATED);
            put_varint(out, c.len() as u64);
            put_varint(out, payload.len() as u64);
            out.extend_from_slice(&c);
        }
        None => {
            out.push(id);
            put_varint(out, payload.len() as u64);
            out.extend_from_slice(payload);
        }
    }
    let crc = crc32fast::hash(&out[start..]);
    out.extend_from_slice(&crc.to_le_bytes());
}

/// A zlib stream of `payload` made only of deflate's fixed-Huffman blocks. miniz_oxide (behind
/// flate2) always writes dynamic blocks, whose code tables cost 30-40 bytes: on a section of a
/// few hundred bytes (group names: `face_1, face_2, ...` and their order) fixed codes are
/// smaller by most of that table, and zlib itself would choose them.
#[cfg(any(feature = "encoder", feature = "internals"))]
fn zlib_static_blocks(payload: &[u8]) -> Option<Vec<u8>> {
    use miniz_oxide::deflate::core::{
        compress, create_comp_flags_from_zip_params, CompressionStrategy, CompressorOxide,
        TDEFLFlush, TDEFLStatus,
    };
    let flags = create_comp_flags_from_zip_params(9, 1, CompressionStrategy::Fixed as i32);
    let mut compressor = CompressorOxide::new(flags);
    // Fixed codes spend at most 9 bits on a literal: this always suffices.
    let mut out = vec![0u8; payload.len() + payload.len() / 4 + 64];
    let (status, read, written) = compress(&mut compressor, payload, &mut out, TDEFLFlush::Finish);
    (status == TDEFLStatus::Done && read == payload.len()).then(|| {
        out.truncate(written);
        out
    })
}

/// One framed section as read from the file, not yet inflated: a decoder that skips the
/// section (an unknown skippable one) never pays for its inflation.
pub struct RawSection<'a> {
    pub id: u8,
    pub skippable: bool,
    /// The payload as stored (a zlib stream when `raw_len` is set).
    stored: &'a [u8],
    /// Length of a deflated payload once inflated.
    pub raw_len: Option<u64>,
    /// Bytes the section occupies in the file (framing included).
    pub stored_bytes: usize,
}

impl<'a> RawSection<'a> {
    /// Payload bytes after inflation.
    pub fn payload_len(&self) -> u64 {
        self.raw_len.unwrap_or(self.stored.len() as u64)
    }

    /// The payload: borrowed when stored, inflated (exactly `raw_len` bytes, which the
    /// caller has checked against its limits) when deflated.
    pub fn payload(&self) -> Result<std::borrow::Cow<'a, [u8]>> {
        let Some(n) = self.raw_len else {
            return Ok(self.stored.into());
        };
        // Inflated by miniz_oxide's core into a buffer of exactly `n` bytes (one allocation,
        // the size charged; no std::io machinery in a decoder-only build). A stream that is
        // corrupt, fails its Adler-32, ends early or has more than `n` bytes is refused.
        use miniz_oxide::inflate::core::{decompress, inflate_flags, DecompressorOxide};
        use miniz_oxide::inflate::TINFLStatus;
        let corrupt = || {
            Error::format(
                "file",
                "payload",
                format!(
                    "section {}: zlib data corrupt or not of its raw length {n}",
                    self.id
                ),
            )
        };
        let mut out = vec![0u8; usize::try_from(n).map_err(|_| corrupt())?];
        let flags = inflate_flags::TINFL_FLAG_PARSE_ZLIB_HEADER
            | inflate_flags::TINFL_FLAG_COMPUTE_ADLER32
            | inflate_flags::TINFL_FLAG_USING_NON_WRAPPING_OUTPUT_BUF;
        let mut state = Box::<DecompressorOxide>::default();
        let (status, _, written) = decompress(&mut state, self.stored, &mut out, 0, flags);
        if status != TINFLStatus::Done || written != out.len() {
            return Err(corrupt());
        }
        Ok(out.into())
    }
}

/// Reads the framing of the next section at `r` (a reader over the whole file) and checks its
/// CRC, which covers the file bytes from `crc_start` (default: the tag byte) to the end of the
/// payload. A deflated section's raw length is checked against what zlib can expand to.
pub fn read_section<'a>(
    r: &mut Reader<'a>,
    crc_start: Option<usize>,
    verify: bool,
) -> Result<RawSection<'a>> {
    let start = r.pos();
    let crc_from = crc_start.unwrap_or(start);
    let tag = r.u8("tag")?;
    let id = tag & TAG_ID_MASK;
    let deflated = tag & TAG_DEFLATED != 0;
    let stored_len = r.varint("length")?;
    if stored_len > r.remaining() as u64 {
        return Err(r.err(
            "length",
            format!(
                "section {id} at byte {start} claims {stored_len} bytes, only {} left",
                r.remaining()
            ),
        ));
    }
    let raw_len = if deflated {
        // zlib cannot expand more than ~1032:1, so a larger claim is a zip bomb or corruption.
        let cap = stored_len.saturating_mul(1040).saturating_add(64);
        Some(r.varint_max("raw_length", cap)?)
    } else {
        None
    };
    let stored = r.bytes(stored_len as usize, "payload")?;
    let covered_end = r.pos();
    let crc_bytes = r.bytes(4, "crc32")?;
    let crc = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    if verify && crc32fast::hash(&r.data[crc_from..covered_end]) != crc {
        return Err(r.err(
            "crc32",
            format!("checksum mismatch in section {id} (data corrupted)"),
        ));
    }
    Ok(RawSection {
        id,
        skippable: tag & TAG_SKIPPABLE != 0,
        stored,
        raw_len,
        stored_bytes: r.pos() - start,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_round_trip_and_reject_overlong() {
        for v in [0u64, 1, 127, 128, 300, 1 << 35, u64::MAX] {
            let mut b = Vec::new();
            put_varint(&mut b, v);
            let mut r = Reader::new(&b, "t");
            assert_eq!(r.varint("v").unwrap(), v);
            r.expect_end().unwrap();
        }
        assert!(Reader::new(&[0x80, 0x00], "t").varint("v").is_err());
        assert!(Reader::new(&[0x80], "t").varint("v").is_err());
        assert!(Reader::new(&[0xFF; 11], "t").varint("v").is_err());
    }

    #[test]
    fn sections_round_trip_stored_and_deflated() {
        let small = b"abc".to_vec();
        let big = vec![7u8; 1000];
        let mut out = Vec::new();
        put_section(&mut out, 3, &small, true, false);
        put_section(&mut out, 5, &big, true, false);
        assert!(out.len() < 100, "zlib should win on repetitive data");
        let mut r = Reader::new(&out, "file");
        let a = read_section(&mut r, None, true).unwrap();
        assert_eq!((a.id, &*a.payload().unwrap()), (3, small.as_slice()));
        let b = read_section(&mut r, None, true).unwrap();
        assert_eq!((b.id, b.payload_len()), (5, 1000));
        assert_eq!(&*b.payload().unwrap(), big.as_slice());
        r.expect_end().unwrap();
        // Zip-bomb cap: a raw length beyond what zlib can expand to is refused when the
        // framing is read, before anything is inflated.
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        z.write_all(&big).unwrap();
        let stream = z.finish().unwrap();
        let mut bomb = Vec::new();
        bomb.push(5 | TAG_DEFLATED);
        put_varint(&mut bomb, stream.len() as u64);
        put_varint(&mut bomb, stream.len() as u64 * 1040 + 65);
        bomb.extend_from_slice(&stream);
        bomb.extend_from_slice(&[0; 4]);
        assert!(read_section(&mut Reader::new(&bomb, "file"), None, false).is_err());
    }

    #[test]
    fn small_sections_take_fixed_huffman_codes_when_smaller() {
        // A names-like payload: 30 incompressible bytes, then a stem and a run of 1s.
        let mut payload: Vec<u8> = (0..30u32).map(|i| (i * 97 + 13) as u8).collect();
        payload.extend_from_slice(b"\x14face_\x02");
        payload.extend(std::iter::repeat_n(1u8, 50));
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        z.write_all(&payload).unwrap();
        let dynamic = z.finish().unwrap();
        let fixed = zlib_static_blocks(&payload).unwrap();
        assert!(
            fixed.len() + 10 < dynamic.len(),
            "{} vs {}",
            fixed.len(),
            dynamic.len()
        );
        let mut out = Vec::new();
        put_section(&mut out, 6, &payload, true, false);
        // tag, two one-byte lengths, the fixed-code stream, CRC.
        assert_eq!(out.len(), 3 + fixed.len() + 4);
        let mut r = Reader::new(&out, "file");
        let s = read_section(&mut r, None, true).unwrap();
        assert_eq!(&*s.payload().unwrap(), payload.as_slice());
        // Data that fixed codes cannot shrink stays stored.
        let noise: Vec<u8> = (0..200u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
            .collect();
        let mut out = Vec::new();
        put_section(&mut out, 6, &noise, true, false);
        assert_eq!(out[0], 6);
    }
}
