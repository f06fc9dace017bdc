//! KTX2 container of a block-compressed macro-texture: writer and reader.
//!
//! This work is based on:
//! - Khronos KTX File Format Specification 2.0 (KTX 2.0): sec. 3.1 identifier, 3.2 header,
//!   3.3 index, 3.9 level index, 3.10 data format descriptor, 3.11 key/value data (`KTXwriter`),
//!   3.13 mip level data (levels stored smallest first, each aligned to
//!   `lcm(texel block size, 4)`; no supercompression);
//! - Khronos Data Format Specification 1.3, sec. 5 (the basic descriptor block) and sec. 5.6
//!   (colour models `KHR_DF_MODEL_BC1A` = 128 and `KHR_DF_MODEL_BC7` = 134; BC1A has a colour
//!   sample and an alpha sample over the same 64 bits, BC7 one colour sample of 128 bits);
//! - Vulkan formats `VK_FORMAT_BC1_RGBA_SRGB_BLOCK` (134) and `VK_FORMAT_BC7_SRGB_BLOCK` (146): the
//!   macro-textures hold sRGB-encoded colours with straight alpha.
//!
//! The reader accepts what the writer writes (the two formats, 2D, one face, no supercompression)
//! and checks everything it relies on, so damaged data is a [`Ktx2Error`], never a panic.
//! [`Ktx2Texture::levels`] are largest first.

use super::block_compression::{BlockFormat, BLOCK};

/// The 12-byte file identifier «KTX 20»\r\n\x1A\n.
pub const IDENTIFIER: [u8; 12] = [
    0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
];

const VK_FORMAT_BC1_RGBA_SRGB_BLOCK: u32 = 134;
const VK_FORMAT_BC7_SRGB_BLOCK: u32 = 146;
const KHR_DF_MODEL_BC1A: u8 = 128;
const KHR_DF_MODEL_BC7: u8 = 134;
const KHR_DF_PRIMARIES_BT709: u8 = 1;
const KHR_DF_TRANSFER_SRGB: u8 = 2;
const KHR_DF_CHANNEL_BC1A_ALPHA: u8 = 1;
const KHR_DF_SAMPLE_DATATYPE_LINEAR: u8 = 0x10;
const HEADER_BYTES: usize = 80;
const LEVEL_INDEX_BYTES: usize = 24;
const WRITER: &str = "lemi";

/// Errors of reading a KTX2 file; each says what is wrong.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum Ktx2Error {
    #[error("not a KTX2 file (bad identifier)")]
    BadIdentifier,
    #[error("KTX2 data truncated: {0}")]
    Truncated(String),
    #[error("KTX2 vkFormat {0} is not one lemi stores (BC1 RGBA sRGB 134, BC7 sRGB 146)")]
    UnsupportedFormat(u32),
    #[error("KTX2 header: {0}")]
    BadHeader(String),
    #[error("KTX2 data format descriptor: {0}")]
    BadDfd(String),
    #[error("KTX2 level {level}: {reason}")]
    BadLevel { level: usize, reason: String },
}

/// A block-compressed texture read from a KTX2 file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ktx2Texture {
    pub format: BlockFormat,
    pub width: u32,
    pub height: u32,
    /// Block data per mip level, level 0 (largest) first.
    pub levels: Vec<Vec<u8>>,
}

fn vk_format(format: BlockFormat) -> u32 {
    match format {
        BlockFormat::Bc1 => VK_FORMAT_BC1_RGBA_SRGB_BLOCK,
        BlockFormat::Bc7 => VK_FORMAT_BC7_SRGB_BLOCK,
    }
}

/// Size of mip level `l` of a `width × height` texture.
pub fn level_size(width: u32, height: u32, l: usize) -> (u32, u32) {
    ((width >> l).max(1), (height >> l).max(1))
}

/// The data format descriptor (KDFS sec. 5): `dfdTotalSize` then one basic descriptor block.
fn dfd(format: BlockFormat) -> Vec<u8> {
    let (model, samples): (u8, &[u8]) = match format {
        // colour and alpha over the same 64 bits; alpha is linear in an sRGB format
        BlockFormat::Bc1 => (
            KHR_DF_MODEL_BC1A,
            &[0, KHR_DF_CHANNEL_BC1A_ALPHA | KHR_DF_SAMPLE_DATATYPE_LINEAR],
        ),
        BlockFormat::Bc7 => (KHR_DF_MODEL_BC7, &[0]),
    };
    let bits = 8 * format.block_bytes() as u32;
    let block_size = 24 + 16 * samples.len() as u32;
    let mut d = Vec::new();
    d.extend_from_slice(&(4 + block_size).to_le_bytes()); // dfdTotalSize
    d.extend_from_slice(&0u32.to_le_bytes()); // vendorId 0 (Khronos), descriptorType 0 (basic)
    d.extend_from_slice(&(2u32 | (block_size << 16)).to_le_bytes()); // versionNumber 2, size
    d.extend_from_slice(&[model, KHR_DF_PRIMARIES_BT709, KHR_DF_TRANSFER_SRGB, 0]); // straight alpha
    d.extend_from_slice(&[3, 3, 0, 0]); // texel block 4×4×1×1, stored minus one
    d.extend_from_slice(&[format.block_bytes() as u8, 0, 0, 0, 0, 0, 0, 0]); // bytesPlane0..7
    for &channel in samples {
        d.extend_from_slice(&0u16.to_le_bytes()); // bitOffset
        d.push((bits - 1) as u8); // bitLength, minus one
        d.push(channel);
        d.extend_from_slice(&[0, 0, 0, 0]); // samplePosition0..3
        d.extend_from_slice(&0u32.to_le_bytes()); // sampleLower
        d.extend_from_slice(&u32::MAX.to_le_bytes()); // sampleUpper
    }
    d
}

fn pad_to(out: &mut Vec<u8>, align: usize) {
    while out.len() % align != 0 {
        out.push(0);
    }
}

/// Writes a KTX2 file of `levels` (level 0 first, each `format.image_bytes` of its level size).
pub fn write_ktx2(format: BlockFormat, width: u32, height: u32, levels: &[Vec<u8>]) -> Vec<u8> {
    assert!(width > 0 && height > 0 && !levels.is_empty());
    for (l, data) in levels.iter().enumerate() {
        let (w, h) = level_size(width, height, l);
        assert_eq!(data.len(), format.image_bytes(w, h), "level {l} size");
    }
    let n = levels.len();
    let dfd = dfd(format);
    let mut kvd = Vec::new();
    let entry = format!("KTXwriter\0{WRITER}\0");
    kvd.extend_from_slice(&(entry.len() as u32).to_le_bytes());
    kvd.extend_from_slice(entry.as_bytes());
    pad_to(&mut kvd, 4);
    let dfd_offset = HEADER_BYTES + n * LEVEL_INDEX_BYTES;
    let kvd_offset = dfd_offset + dfd.len();
    let align = format.block_bytes().max(4); // lcm(8 or 16, 4)
                                             // level data after the key/value data, smallest level first
    let mut offsets = vec![0usize; n];
    let mut end = kvd_offset + kvd.len();
    for l in (0..n).rev() {
        end = end.div_ceil(align) * align;
        offsets[l] = end;
        end += levels[l].len();
    }
    let mut out = Vec::with_capacity(end);
    out.extend_from_slice(&IDENTIFIER);
    for v in [
        vk_format(format),
        1, // typeSize: 1 for block-compressed formats
        width,
        height,
        0, // pixelDepth
        0, // layerCount: not an array
        1, // faceCount
        n as u32,
        0, // supercompressionScheme: none
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in [
        dfd_offset as u32,
        dfd.len() as u32,
        kvd_offset as u32,
        kvd.len() as u32,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&0u64.to_le_bytes()); // sgdByteOffset
    out.extend_from_slice(&0u64.to_le_bytes()); // sgdByteLength
    for l in 0..n {
        let len = levels[l].len() as u64;
        for v in [offsets[l] as u64, len, len] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out.extend_from_slice(&dfd);
    out.extend_from_slice(&kvd);
    for l in (0..n).rev() {
        pad_to(&mut out, align);
        debug_assert_eq!(out.len(), offsets[l]);
        out.extend_from_slice(&levels[l]);
    }
    out
}

fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes(b[o..o + 4].try_into().unwrap())
}

fn u64_at(b: &[u8], o: usize) -> u64 {
    u64::from_le_bytes(b[o..o + 8].try_into().unwrap())
}

/// The byte range `offset .. offset + len` of `bytes`, or an error naming `what`.
fn range(
    bytes: &[u8],
    offset: u64,
    len: u64,
    what: &str,
) -> Result<std::ops::Range<usize>, Ktx2Error> {
    match offset.checked_add(len) {
        Some(end) if end <= bytes.len() as u64 => Ok(offset as usize..end as usize),
        _ => Err(Ktx2Error::Truncated(format!(
            "{what} at bytes {offset}..{} beyond the end of the {} bytes",
            offset as u128 + len as u128,
            bytes.len()
        ))),
    }
}

/// Reads a KTX2 file written by [`write_ktx2`] (BC1 RGBA sRGB or BC7 sRGB, 2D, no
/// supercompression), checking the identifier, header, index, data format descriptor and levels.
pub fn read_ktx2(bytes: &[u8]) -> Result<Ktx2Texture, Ktx2Error> {
    if bytes.len() < IDENTIFIER.len() || bytes[..12] != IDENTIFIER {
        return Err(Ktx2Error::BadIdentifier);
    }
    if bytes.len() < HEADER_BYTES {
        return Err(Ktx2Error::Truncated(format!(
            "{} bytes, the header alone has {HEADER_BYTES}",
            bytes.len()
        )));
    }
    let h: Vec<u32> = (0..9).map(|i| u32_at(bytes, 12 + 4 * i)).collect();
    let [vk, type_size, width, height, depth, layers, faces, level_count, scheme] =
        h[..].try_into().unwrap();
    let format = match vk {
        VK_FORMAT_BC1_RGBA_SRGB_BLOCK => BlockFormat::Bc1,
        VK_FORMAT_BC7_SRGB_BLOCK => BlockFormat::Bc7,
        other => return Err(Ktx2Error::UnsupportedFormat(other)),
    };
    let bad = |m: String| Err(Ktx2Error::BadHeader(m));
    if type_size != 1 {
        return bad(format!(
            "typeSize {type_size} (1 for block-compressed formats)"
        ));
    }
    if width == 0 || height == 0 || depth != 0 || layers != 0 || faces != 1 {
        return bad(format!(
            "a {width}×{height}×{depth} texture of {layers} layers and {faces} faces (lemi stores 2D textures)"
        ));
    }
    let max_levels = 32 - width.max(height).leading_zeros();
    if level_count == 0 || level_count > max_levels {
        return bad(format!(
            "levelCount {level_count} for {width}×{height} (1 to {max_levels})"
        ));
    }
    if scheme != 0 {
        return bad(format!(
            "supercompressionScheme {scheme} (block formats are stored without)"
        ));
    }
    let n = level_count as usize;
    let index_end = HEADER_BYTES + n * LEVEL_INDEX_BYTES;
    if bytes.len() < index_end {
        return Err(Ktx2Error::Truncated(format!(
            "{} bytes, the header and the index of {n} levels have {index_end}",
            bytes.len()
        )));
    }
    // data format descriptor
    let (dfd_off, dfd_len) = (u32_at(bytes, 48), u32_at(bytes, 52));
    let dfd_bytes = &bytes[range(
        bytes,
        dfd_off as u64,
        dfd_len as u64,
        "the data format descriptor",
    )?];
    let expected = dfd(format);
    if dfd_bytes.len() < 28 || u32_at(dfd_bytes, 0) as usize != dfd_bytes.len() {
        return Err(Ktx2Error::BadDfd(format!(
            "{} bytes with dfdTotalSize {}",
            dfd_bytes.len(),
            if dfd_bytes.len() >= 4 {
                u32_at(dfd_bytes, 0)
            } else {
                0
            }
        )));
    }
    if dfd_bytes[12] != expected[12] {
        return Err(Ktx2Error::BadDfd(format!(
            "colour model {} does not match vkFormat {vk} (expected {})",
            dfd_bytes[12], expected[12]
        )));
    }
    if dfd_bytes[14] != KHR_DF_TRANSFER_SRGB {
        return Err(Ktx2Error::BadDfd(format!(
            "transfer function {} with an sRGB vkFormat",
            dfd_bytes[14]
        )));
    }
    if dfd_bytes[16..18] != [3, 3] || dfd_bytes[20] as usize != format.block_bytes() {
        return Err(Ktx2Error::BadDfd(format!(
            "texel block {}×{} of {} bytes (expected 4×4 of {})",
            dfd_bytes[16] as u32 + 1,
            dfd_bytes[17] as u32 + 1,
            dfd_bytes[20],
            format.block_bytes()
        )));
    }
    let (sgd_len, kvd_off, kvd_len) = (u64_at(bytes, 72), u32_at(bytes, 56), u32_at(bytes, 60));
    range(bytes, kvd_off as u64, kvd_len as u64, "the key/value data")?;
    if sgd_len != 0 {
        return bad(format!(
            "{sgd_len} bytes of supercompression global data without supercompression"
        ));
    }
    let align = format.block_bytes().max(4) as u64;
    let mut levels = Vec::with_capacity(n);
    for l in 0..n {
        let o = HEADER_BYTES + l * LEVEL_INDEX_BYTES;
        let (off, len, raw) = (
            u64_at(bytes, o),
            u64_at(bytes, o + 8),
            u64_at(bytes, o + 16),
        );
        let (w, h) = level_size(width, height, l);
        let want = format.image_bytes(w, h) as u64;
        let bad_level = |reason: String| Ktx2Error::BadLevel { level: l, reason };
        if len != want || raw != want {
            return Err(bad_level(format!(
                "{len} bytes ({raw} uncompressed) for {w}×{h} texels of {format:?} ({want} bytes)"
            )));
        }
        if off % align != 0 {
            return Err(bad_level(format!(
                "offset {off} not aligned to {align} bytes"
            )));
        }
        let r = range(bytes, off, len, &format!("level {l}"))?;
        levels.push(bytes[r].to_vec());
    }
    debug_assert!(levels.iter().all(|d| !d.is_empty()) && BLOCK == 4);
    Ok(Ktx2Texture {
        format,
        width,
        height,
        levels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compress::block_compression::{decode_blocks, encode_blocks};

    fn image(w: u32, h: u32) -> Vec<u8> {
        let mut rgba = vec![0u8; 4 * (w * h) as usize];
        for (i, p) in rgba.chunks_exact_mut(4).enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let a = if (x / 3 + y / 2) % 4 == 0 { 0 } else { 255 };
            p.copy_from_slice(&[(x * 255 / w) as u8, (y * 255 / h) as u8, 90, a]);
        }
        rgba
    }

    /// Mip levels by taking every other texel (enough to give each level its own data).
    fn levels(format: BlockFormat, w: u32, h: u32, count: usize) -> Vec<Vec<u8>> {
        (0..count)
            .map(|l| {
                let (lw, lh) = level_size(w, h, l);
                encode_blocks(format, lw, lh, &image(lw, lh)).unwrap().0
            })
            .collect()
    }

    #[test]
    fn the_ktx2_crate_reads_what_lemi_writes() {
        for (format, vk, model) in [
            (
                BlockFormat::Bc7,
                ktx2::Format::BC7_SRGB_BLOCK,
                ktx2::ColorModel::BC7,
            ),
            (
                BlockFormat::Bc1,
                ktx2::Format::BC1_RGBA_SRGB_BLOCK,
                ktx2::ColorModel::BC1A,
            ),
        ] {
            for (w, h, n) in [(64u32, 32u32, 1usize), (64, 32, 7), (256, 16, 3)] {
                let lv = levels(format, w, h, n);
                let file = write_ktx2(format, w, h, &lv);
                let r = ktx2::Reader::new(&file[..]).expect("ktx2 crate reads the file");
                let hd = r.header();
                assert_eq!(hd.format, Some(vk));
                assert_eq!((hd.pixel_width, hd.pixel_height, hd.pixel_depth), (w, h, 0));
                assert_eq!((hd.face_count, hd.level_count), (1, n as u32));
                assert_eq!(hd.supercompression_scheme, None);
                assert_eq!(r.color_model(), Some(model));
                assert_eq!(r.transfer_function(), Some(ktx2::TransferFunction::SRGB));
                assert_eq!(r.is_alpha_premultiplied(), Some(false));
                assert_eq!(r.writer(), Some("lemi\0")); // a NUL-terminated UTF-8 value
                let got: Vec<&[u8]> = r.levels().map(|l| l.data).collect();
                assert_eq!(got.len(), n);
                for (a, b) in got.iter().zip(&lv) {
                    assert_eq!(*a, &b[..]);
                }
                // and lemi's own reader
                let t = read_ktx2(&file).unwrap();
                assert_eq!((t.format, t.width, t.height), (format, w, h));
                assert_eq!(t.levels, lv);
                let dec = decode_blocks(format, w, h, &t.levels[0]).unwrap();
                assert_eq!(dec.len(), 4 * (w * h) as usize);
            }
        }
    }

    #[test]
    fn every_truncation_is_an_error() {
        let file = write_ktx2(BlockFormat::Bc1, 16, 8, &levels(BlockFormat::Bc1, 16, 8, 2));
        for len in 0..file.len() {
            assert!(
                read_ktx2(&file[..len]).is_err(),
                "{len} of {} bytes",
                file.len()
            );
        }
    }

    #[test]
    fn damaged_headers_are_clear_errors() {
        let file = write_ktx2(
            BlockFormat::Bc7,
            16,
            16,
            &levels(BlockFormat::Bc7, 16, 16, 1),
        );
        let patch = |at: usize, v: u32| {
            let mut f = file.clone();
            f[at..at + 4].copy_from_slice(&v.to_le_bytes());
            read_ktx2(&f).unwrap_err()
        };
        let mut f = file.clone();
        f[1] = b'Q';
        assert_eq!(read_ktx2(&f).unwrap_err(), Ktx2Error::BadIdentifier);
        assert_eq!(patch(12, 37), Ktx2Error::UnsupportedFormat(37));
        assert!(matches!(patch(16, 4), Ktx2Error::BadHeader(_))); // typeSize
        assert!(matches!(patch(20, 0), Ktx2Error::BadHeader(_))); // width
        assert!(matches!(patch(36, 6), Ktx2Error::BadHeader(_))); // faces
        assert!(matches!(patch(40, 9), Ktx2Error::BadHeader(_))); // levels beyond 16×16's
        assert!(matches!(patch(44, 1), Ktx2Error::BadHeader(_))); // BasisLZ
        assert!(matches!(patch(48, 1 << 30), Ktx2Error::Truncated(_))); // dfd offset
        assert!(matches!(
            patch(20, 32),
            Ktx2Error::BadLevel { level: 0, .. }
        )); // size mismatch
        assert!(matches!(patch(80, 7), Ktx2Error::BadLevel { level: 0, .. })); // misaligned
        let dfd_off = u32_at(&file, 48) as usize;
        let mut f = file.clone();
        f[dfd_off + 12] = KHR_DF_MODEL_BC1A; // colour model of another format
        assert!(matches!(read_ktx2(&f).unwrap_err(), Ktx2Error::BadDfd(_)));
        // every message says what is wrong
        assert!(patch(12, 37).to_string().contains("vkFormat 37"));
    }

    #[test]
    fn the_dfd_is_the_khronos_basic_block() {
        let d = dfd(BlockFormat::Bc7);
        assert_eq!(d.len(), 4 + 24 + 16);
        assert_eq!(u32_at(&d, 0), 44);
        assert_eq!(u32_at(&d, 8), 2 | (40 << 16));
        let d = dfd(BlockFormat::Bc1);
        assert_eq!(d.len(), 4 + 24 + 32);
        assert_eq!(d[28 + 16 + 3], 1 | 0x10); // the alpha sample, linear
    }
}
