//! KTX2 container of a block-compressed macro-texture: writer and reader.
//!
//! This work is based on:
//! - Khronos KTX File Format Specification 2.0 (KTX 2.0): sec. 3.1 identifier, 3.2 header,
//!   3.3 index, 3.9 level index, 3.10 data format descriptor, 3.11 key/value data (`KTXwriter`),
//!   3.13 mip level data (levels stored smallest first, each aligned to
//!   `lcm(texel block size, 4)` without supercompression, unaligned with it), and
//!   `supercompressionScheme` 2, Zstandard (sec. 3.12.3: each level compressed on its own, the
//!   level index giving its compressed and uncompressed lengths; no global data);
//! - Zstandard (RFC 8878) through the reference library (`zstd` crate);
//! - Khronos Data Format Specification 1.3, sec. 5 (the basic descriptor block) and sec. 5.6
//!   (colour models `KHR_DF_MODEL_BC1A` = 128 and `KHR_DF_MODEL_BC7` = 134; BC1A has a colour
//!   sample and an alpha sample over the same 64 bits, BC7 one colour sample of 128 bits);
//! - Vulkan formats `VK_FORMAT_BC1_RGBA_SRGB_BLOCK` (134) and `VK_FORMAT_BC7_SRGB_BLOCK` (146): the
//!   macro-textures hold sRGB-encoded colours with straight alpha.
//!
//! The reader accepts what the writer writes (the two formats, 2D, one face, no supercompression
//! or Zstandard) and checks everything it relies on, so damaged data is a [`Ktx2Error`], never a
//! panic: a level's Zstandard data must inflate to exactly the level's size.
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
/// The largest side the reader accepts (the packer's sides are at most 4096; 16384 is the
/// largest 2D texture most GPUs sample).
pub const MAX_SIDE: u32 = 16384;
const SCHEME_NONE: u32 = 0;
const SCHEME_ZSTD: u32 = 2;
/// The Zstandard level lemi writes: 19, the highest of the ordinary levels (20 to 22 need more
/// memory and gain < 0.1 % on macro-textures; level 9 is 4-8× faster and ~10 % larger).
pub const ZSTD_LEVEL: i32 = 19;

/// The KTX2 `supercompressionScheme` of a file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Supercompression {
    /// 0: the levels are the blocks as uploaded.
    #[default]
    None,
    /// 2: each level Zstandard-compressed ([`ZSTD_LEVEL`]).
    Zstd,
}

impl Supercompression {
    /// The header's `supercompressionScheme`.
    pub fn scheme(self) -> u32 {
        match self {
            Supercompression::None => SCHEME_NONE,
            Supercompression::Zstd => SCHEME_ZSTD,
        }
    }
}

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
    #[error("KTX2 writer: {0}")]
    Write(String),
}

/// A block-compressed texture read from a KTX2 file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ktx2Texture {
    pub format: BlockFormat,
    pub width: u32,
    pub height: u32,
    /// How the file stored the levels (they are inflated here).
    pub supercompression: Supercompression,
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

/// Writes a KTX2 file of `levels` (level 0 first, each `format.image_bytes` of its level size),
/// supercompressed as `supercompression` says.
pub fn write_ktx2(
    format: BlockFormat,
    width: u32,
    height: u32,
    levels: &[Vec<u8>],
    supercompression: Supercompression,
) -> Result<Vec<u8>, Ktx2Error> {
    let max_levels = 32 - width.max(height).leading_zeros() as usize;
    if width == 0 || height == 0 || levels.is_empty() || levels.len() > max_levels {
        return Err(Ktx2Error::Write(format!(
            "{} levels of a {width}×{height} texture",
            levels.len()
        )));
    }
    for (l, data) in levels.iter().enumerate() {
        let (w, h) = level_size(width, height, l);
        if data.len() != format.image_bytes(w, h) {
            return Err(Ktx2Error::Write(format!(
                "level {l} has {} bytes, {w}×{h} texels of {format:?} have {}",
                data.len(),
                format.image_bytes(w, h)
            )));
        }
    }
    let stored: Vec<std::borrow::Cow<[u8]>> = match supercompression {
        Supercompression::None => levels.iter().map(|l| l[..].into()).collect(),
        Supercompression::Zstd => levels
            .iter()
            .map(|l| {
                // with the frame's content checksum: damage inside the frame is caught by the
                // decoder too, not only by the cell file's hash
                let mut z = zstd::bulk::Compressor::new(ZSTD_LEVEL)?;
                z.include_checksum(true)?;
                z.compress(l).map(Into::into)
            })
            .collect::<std::io::Result<_>>()
            .map_err(|e| Ktx2Error::Write(format!("Zstandard: {e}")))?,
    };
    let raw: Vec<u64> = levels.iter().map(|l| l.len() as u64).collect();
    // lcm(8 or 16, 4) without supercompression, 1 with (KTX 2.0 sec. 3.13)
    let align = match supercompression {
        Supercompression::None => format.block_bytes().max(4),
        Supercompression::Zstd => 1,
    };
    Ok(assemble(&Layout {
        vk_format: vk_format(format),
        width,
        height,
        dfd: &dfd(format),
        scheme: supercompression.scheme(),
        global_data: &[],
        key_values: &[],
        levels: &stored.iter().map(|s| &s[..]).collect::<Vec<_>>(),
        raw_lengths: &raw,
        align,
    }))
}

/// What [`assemble`] lays out as a KTX2 file.
pub(crate) struct Layout<'a> {
    pub vk_format: u32,
    pub width: u32,
    pub height: u32,
    /// The data format descriptor, `dfdTotalSize` first.
    pub dfd: &'a [u8],
    pub scheme: u32,
    /// Supercompression global data (BasisLZ's codebooks; empty otherwise).
    pub global_data: &'a [u8],
    /// Key/value pairs after `KTXwriter` (keys without their NUL).
    pub key_values: &'a [(&'a str, &'a [u8])],
    /// The levels as stored (after supercompression), level 0 first.
    pub levels: &'a [&'a [u8]],
    /// Each level's `uncompressedByteLength` (0 for BasisLZ).
    pub raw_lengths: &'a [u64],
    /// Alignment of each level's data.
    pub align: usize,
}

/// Lays out a 2D, one-face KTX2 file (KTX 2.0 secs. 3.1-3.13): header, level index, data format
/// descriptor, key/value data (`KTXwriter` = lemi, then `key_values` sorted by key as the
/// specification asks), global data aligned to 8, levels smallest first.
pub(crate) fn assemble(l: &Layout) -> Vec<u8> {
    let n = l.levels.len();
    let mut kvd = Vec::new();
    let mut entries: Vec<(String, &[u8])> = vec![("KTXwriter".into(), b"lemi\0")];
    entries.extend(l.key_values.iter().map(|(k, v)| (k.to_string(), *v)));
    entries.sort_by(|a, b| a.0.cmp(&b.0));
    for (key, value) in entries {
        kvd.extend_from_slice(&((key.len() + 1 + value.len()) as u32).to_le_bytes());
        kvd.extend_from_slice(key.as_bytes());
        kvd.push(0);
        kvd.extend_from_slice(value);
        pad_to(&mut kvd, 4);
    }
    let dfd_offset = HEADER_BYTES + n * LEVEL_INDEX_BYTES;
    let kvd_offset = dfd_offset + l.dfd.len();
    let mut sgd_offset = kvd_offset + kvd.len();
    if !l.global_data.is_empty() {
        sgd_offset = sgd_offset.div_ceil(8) * 8;
    }
    // level data after the global data, smallest level first
    let mut offsets = vec![0usize; n];
    let mut end = sgd_offset + l.global_data.len();
    for lv in (0..n).rev() {
        end = end.div_ceil(l.align) * l.align;
        offsets[lv] = end;
        end += l.levels[lv].len();
    }
    let mut out = Vec::with_capacity(end);
    out.extend_from_slice(&IDENTIFIER);
    for v in [
        l.vk_format,
        1, // typeSize: 1 for block-compressed and Basis formats
        l.width,
        l.height,
        0, // pixelDepth
        0, // layerCount: not an array
        1, // faceCount
        n as u32,
        l.scheme,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in [
        dfd_offset as u32,
        l.dfd.len() as u32,
        kvd_offset as u32,
        kvd.len() as u32,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let sgd_at = if l.global_data.is_empty() {
        0
    } else {
        sgd_offset
    };
    out.extend_from_slice(&(sgd_at as u64).to_le_bytes()); // sgdByteOffset
    out.extend_from_slice(&(l.global_data.len() as u64).to_le_bytes()); // sgdByteLength
    for ((offset, level), raw) in offsets.iter().zip(l.levels).zip(l.raw_lengths) {
        for v in [*offset as u64, level.len() as u64, *raw] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out.extend_from_slice(l.dfd);
    out.extend_from_slice(&kvd);
    if !l.global_data.is_empty() {
        pad_to(&mut out, 8);
        out.extend_from_slice(l.global_data);
    }
    for lv in (0..n).rev() {
        pad_to(&mut out, l.align);
        debug_assert_eq!(out.len(), offsets[lv]);
        out.extend_from_slice(l.levels[lv]);
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
/// supercompression or Zstandard), checking the identifier, header, index, data format descriptor
/// and levels, and inflating Zstandard levels to exactly their size.
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
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return bad(format!(
            "a {width}×{height} texture (lemi stores sides of 1 to {MAX_SIDE} texels)"
        ));
    }
    if depth != 0 || layers != 0 || faces != 1 {
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
    let supercompression = match scheme {
        SCHEME_NONE => Supercompression::None,
        SCHEME_ZSTD => Supercompression::Zstd,
        _ => {
            return bad(format!(
                "supercompressionScheme {scheme} (lemi stores block formats with 0, none, or 2, Zstandard)"
            ))
        }
    };
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
    // bytesPlane0 is the block size; writers of supercompressed files may leave it 0 ("unsized",
    // as KTX 2.0 asked before its errata)
    let plane0 = dfd_bytes[20] as usize;
    let plane0_ok = plane0 == format.block_bytes()
        || (plane0 == 0 && supercompression != Supercompression::None);
    if dfd_bytes[16..18] != [3, 3] || !plane0_ok {
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
            "{sgd_len} bytes of supercompression global data (none with scheme {scheme})"
        ));
    }
    let align = match supercompression {
        Supercompression::None => format.block_bytes().max(4) as u64,
        Supercompression::Zstd => 1,
    };
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
        let len_ok = match supercompression {
            Supercompression::None => len == want,
            Supercompression::Zstd => len > 0,
        };
        if !len_ok || raw != want {
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
        let data = match supercompression {
            Supercompression::None => bytes[r].to_vec(),
            Supercompression::Zstd => inflate_zstd(&bytes[r], want as usize)
                .map_err(|e| bad_level(format!("Zstandard data: {e}")))?,
        };
        levels.push(data);
    }
    debug_assert!(levels.iter().all(|d| !d.is_empty()) && BLOCK == 4);
    Ok(Ktx2Texture {
        format,
        width,
        height,
        supercompression,
        levels,
    })
}

/// Inflates Zstandard data to exactly `size` bytes; memory grows with what the data really
/// inflates to (never beyond `size` + 1), not with what a damaged header claims.
fn inflate_zstd(data: &[u8], size: usize) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let mut out = Vec::with_capacity(size.min(64 * data.len() + (1 << 16)));
    zstd::stream::read::Decoder::with_buffer(data)
        .and_then(|d| d.take(size as u64 + 1).read_to_end(&mut out))
        .map_err(|e| e.to_string())?;
    if out.len() != size {
        return Err(format!(
            "inflates to {} bytes, the level has {size}",
            out.len()
        ));
    }
    Ok(out)
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

    const SCHEMES: [(Supercompression, Option<ktx2::SupercompressionScheme>); 2] = [
        (Supercompression::None, None),
        (
            Supercompression::Zstd,
            Some(ktx2::SupercompressionScheme::Zstandard),
        ),
    ];

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
            for (sc, scheme) in SCHEMES {
                for (w, h, n) in [(64u32, 32u32, 1usize), (64, 32, 7), (256, 16, 3)] {
                    let lv = levels(format, w, h, n);
                    let file = write_ktx2(format, w, h, &lv, sc).unwrap();
                    let r = ktx2::Reader::new(&file[..]).expect("ktx2 crate reads the file");
                    let hd = r.header();
                    assert_eq!(hd.format, Some(vk));
                    assert_eq!((hd.pixel_width, hd.pixel_height, hd.pixel_depth), (w, h, 0));
                    assert_eq!((hd.face_count, hd.level_count), (1, n as u32));
                    assert_eq!(hd.supercompression_scheme, scheme);
                    assert_eq!(r.color_model(), Some(model));
                    assert_eq!(r.transfer_function(), Some(ktx2::TransferFunction::SRGB));
                    assert_eq!(r.is_alpha_premultiplied(), Some(false));
                    assert_eq!(r.writer(), Some("lemi\0")); // a NUL-terminated UTF-8 value
                    let got: Vec<ktx2::Level> = r.levels().collect();
                    assert_eq!(got.len(), n);
                    for (a, b) in got.iter().zip(&lv) {
                        assert_eq!(a.uncompressed_byte_length, b.len() as u64);
                        // the stored level, inflated by the reference library's streaming API
                        // (not the call lemi's reader makes)
                        let raw = match sc {
                            Supercompression::None => a.data.to_vec(),
                            Supercompression::Zstd => zstd::decode_all(a.data).unwrap(),
                        };
                        assert_eq!(raw, *b);
                    }
                    // and lemi's own reader
                    let t = read_ktx2(&file).unwrap();
                    assert_eq!((t.format, t.width, t.height), (format, w, h));
                    assert_eq!(t.supercompression, sc);
                    assert_eq!(t.levels, lv);
                    let dec = decode_blocks(format, w, h, &t.levels[0]).unwrap();
                    assert_eq!(dec.len(), 4 * (w * h) as usize);
                }
            }
        }
    }

    #[test]
    fn zstandard_makes_empty_texels_nearly_free() {
        // a macro-texture's unused area is transparent, all blocks alike
        let (w, h) = (256u32, 128u32);
        let mut rgba = image(w, h);
        rgba[4 * (w * h / 2) as usize..].fill(0);
        let blocks = encode_blocks(BlockFormat::Bc1, w, h, &rgba).unwrap().0;
        let plain = write_ktx2(
            BlockFormat::Bc1,
            w,
            h,
            std::slice::from_ref(&blocks),
            Supercompression::None,
        )
        .unwrap();
        let zstd = write_ktx2(BlockFormat::Bc1, w, h, &[blocks], Supercompression::Zstd).unwrap();
        assert!(
            zstd.len() < plain.len() / 2,
            "{} {}",
            zstd.len(),
            plain.len()
        );
    }

    #[test]
    fn every_truncation_is_an_error() {
        for (sc, _) in SCHEMES {
            let lv = levels(BlockFormat::Bc1, 16, 8, 2);
            let file = write_ktx2(BlockFormat::Bc1, 16, 8, &lv, sc).unwrap();
            for len in 0..file.len() {
                assert!(
                    read_ktx2(&file[..len]).is_err(),
                    "{sc:?}: {len} of {} bytes",
                    file.len()
                );
            }
        }
    }

    #[test]
    fn damaged_zstandard_levels_are_clear_errors() {
        let (w, h) = (64u32, 64u32);
        let lv = levels(BlockFormat::Bc7, w, h, 1);
        let file = write_ktx2(BlockFormat::Bc7, w, h, &lv, Supercompression::Zstd).unwrap();
        let (off, len) = (u64_at(&file, 80) as usize, u64_at(&file, 88) as usize);
        assert_eq!(off + len, file.len());
        // every byte of the frame flipped in turn: an error naming the level (the frame carries
        // a checksum of its content), or where a header bit does not matter the same blocks
        for i in off..file.len() {
            let mut f = file.clone();
            f[i] ^= 0x5a;
            match read_ktx2(&f) {
                Err(Ktx2Error::BadLevel { level: 0, reason }) => {
                    assert!(reason.contains("Zstandard"), "{reason}")
                }
                Err(e) => panic!("byte {i}: {e}"),
                Ok(t) => assert_eq!(t.levels, lv, "byte {i}"),
            }
        }
        // a frame that inflates to less or more than the level
        let short = zstd::bulk::compress(&lv[0][..lv[0].len() - 16], 3).unwrap();
        let long = zstd::bulk::compress(&[lv[0].clone(), vec![0; 16]].concat(), 3).unwrap();
        for frame in [short, long] {
            let mut f = file[..off].to_vec();
            f.extend_from_slice(&frame);
            f[88..96].copy_from_slice(&(frame.len() as u64).to_le_bytes());
            let e = read_ktx2(&f).unwrap_err();
            assert!(matches!(e, Ktx2Error::BadLevel { level: 0, .. }), "{e}");
            assert!(e.to_string().contains("Zstandard"), "{e}");
        }
        // a huge size claimed by a damaged header is refused before anything is inflated
        let mut f = file.clone();
        f[20..24].copy_from_slice(&(1u32 << 20).to_le_bytes());
        assert!(matches!(
            read_ktx2(&f).unwrap_err(),
            Ktx2Error::BadHeader(_)
        ));
        // an unknown scheme (3 is zlib) is named
        let mut f = file.clone();
        f[44..48].copy_from_slice(&3u32.to_le_bytes());
        let e = read_ktx2(&f).unwrap_err();
        assert!(e.to_string().contains("supercompressionScheme 3"), "{e}");
    }

    #[test]
    fn the_writer_refuses_wrong_level_sizes() {
        let lv = levels(BlockFormat::Bc1, 16, 8, 1);
        for (sc, _) in SCHEMES {
            assert!(write_ktx2(BlockFormat::Bc7, 16, 8, &lv, sc).is_err());
            assert!(write_ktx2(BlockFormat::Bc1, 16, 16, &lv, sc).is_err());
            assert!(write_ktx2(BlockFormat::Bc1, 16, 8, &[], sc).is_err());
        }
    }

    #[test]
    fn damaged_headers_are_clear_errors() {
        let file = write_ktx2(
            BlockFormat::Bc7,
            16,
            16,
            &levels(BlockFormat::Bc7, 16, 16, 1),
            Supercompression::None,
        )
        .unwrap();
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
        assert!(matches!(patch(44, 2), Ktx2Error::BadLevel { .. })); // Zstandard: not a frame
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
