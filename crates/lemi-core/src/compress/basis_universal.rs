//! Basis Universal macro-textures: ETC1S (BasisLZ-supercompressed) and UASTC (Zstandard) in KTX2,
//! transcoded at load time to the block format the runtime samples.
//!
//! This work is based on:
//! - Khronos KTX File Format Specification 2.0, sec. 3.12.2 "BasisLZ" (the global data: a header
//!   of codebook sizes, one image descriptor per image, then the endpoint and selector codebooks
//!   and the Huffman tables) and sec. 3.12.3 (Zstandard), with the data format descriptors of
//!   KDFS 1.3 sec. 5.6 for `KHR_DF_MODEL_ETC1S` (163: an RGB sample and an AAA sample of 64 bits
//!   each) and `KHR_DF_MODEL_UASTC` (166: one RGBA sample of 128 bits);
//! - the `.basis` file layout of Basis Universal 1.16 (`basisu_file_headers.h`), whose ETC1S
//!   codebooks, tables and slices are the same bytes KTX2 stores (the reference encoder's
//!   `create_ktx2_file` copies them over as done here);
//! - encoding by the reference encoder (Binomial's Basis Universal 1.16, C++, through the
//!   `basis-universal` crate); transcoding by the `basisu` crate, a pure-Rust port of the reference
//!   transcoder that reads KTX2 itself.
//!
//! What lemi adds: the layers' alpha is binary and alpha-tested, so a texel whose alpha changes
//! side of 128 opens a crack (module docs of [`super::block_compression`]). ETC1S codes the alpha
//! as a second, lossy slice whose shared selector codebook can flip a few edge texels (about 0.05 %
//! of a `builtin:city:1M` cell's texels at quality 128). The encoder therefore transcodes what it
//! wrote and lists the texels whose alpha came out on the wrong side in the KTX2 key/value entry
//! [`ALPHA_FIXES_KEY`] (little-endian `u32` texel indices, row-major); other readers ignore it.
//! [`transcode_basis`] flips those texels' alpha, then re-encodes every block of the target
//! format whose decoded alpha disagrees exactly ([`make_alpha_exact`]), so the runtime's alpha
//! test sees every texel as baked. ETC1S is transcoded to BC1 (with punch-through alpha on the
//! blocks that need it), UASTC to BC7.

use std::panic::{catch_unwind, AssertUnwindSafe};

use super::block_compression::{
    decode_blocks, make_alpha_exact, prepare_image, BlockFormat, TextureFormat,
};
use super::ktx2_container::{assemble, Ktx2Error, Layout, IDENTIFIER, MAX_SIDE};
use super::CompressError;

/// The key/value entry holding the texels whose transcoded alpha must be flipped.
pub const ALPHA_FIXES_KEY: &str = "lemi.alphaFixes";

/// The ETC1S quality level lemi encodes with (1-255; Basis Universal's default is 128): the
/// codebook sizes, hence bytes against colour error. lemi encodes ETC1S without endpoint
/// rate-distortion optimisation ([`ETC1S_ENDPOINT_RDO`]), which is where the encoder spends a
/// third of its time and which, on impostor atlases, costs more colour than it saves bytes; at
/// 80 the files are as small as the default's with it (docs/COMPRESSION.md sec. 5 has the
/// measurements).
pub const ETC1S_QUALITY: u32 = 80;

/// Whether the ETC1S encoder runs endpoint rate-distortion optimisation (see [`ETC1S_QUALITY`]).
pub const ETC1S_ENDPOINT_RDO: bool = false;

/// The UASTC level lemi encodes with: Basis Universal's "faster" (1 of 0-4; its default is 2),
/// which takes less than half the default's time at 0.4 dB less PSNR on impostor atlases
/// (docs/COMPRESSION.md sec. 5).
pub const UASTC_LEVEL: u32 = basis_universal_sys::UastcPackFlags_PackUASTCLevelFaster as u32;

const VK_FORMAT_UNDEFINED: u32 = 0;
const SCHEME_BASISLZ: u32 = 1;
const SCHEME_ZSTD: u32 = 2;
const KHR_DF_MODEL_ETC1S: u8 = 163;
const KHR_DF_MODEL_UASTC: u8 = 166;
const KHR_DF_TRANSFER_SRGB: u8 = 2;
const ZSTD_LEVEL: i32 = super::ktx2_container::ZSTD_LEVEL;

/// A Basis Universal encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BasisFormat {
    /// ETC1S with BasisLZ supercompression: smallest files, about BC1's colour quality or below.
    Etc1s,
    /// UASTC 4×4 (16 bytes a block) with Zstandard: about BC7's quality.
    Uastc,
}

impl BasisFormat {
    /// The block format lemi transcodes it to for the GPU.
    pub fn runtime_block(self) -> BlockFormat {
        match self {
            BasisFormat::Etc1s => BlockFormat::Bc1,
            BasisFormat::Uastc => BlockFormat::Bc7,
        }
    }

    pub fn texture_format(self) -> TextureFormat {
        match self {
            BasisFormat::Etc1s => TextureFormat::Etc1s,
            BasisFormat::Uastc => TextureFormat::Uastc,
        }
    }
}

/// What an encoding did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BasisEncodeStats {
    /// Bytes of the KTX2 file.
    pub bytes: u64,
    /// Bytes of the transcoded blocks (texture memory).
    pub block_bytes: u64,
    /// Texels whose alpha the file lists as flipped ([`ALPHA_FIXES_KEY`]).
    pub alpha_fixes: u64,
    /// Blocks of the transcoded image re-encoded for an exact alpha test.
    pub fixed_blocks: u64,
}

/// A Basis Universal KTX2 file transcoded to a block format.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TranscodedBasis {
    pub source: BasisFormat,
    pub format: BlockFormat,
    pub width: u32,
    pub height: u32,
    /// Level 0's blocks, row-major.
    pub blocks: Vec<u8>,
    /// Texels whose alpha the file lists as flipped.
    pub alpha_fixes: u64,
    /// Blocks re-encoded for an exact alpha test.
    pub fixed_blocks: u64,
}

/// Encodes a `width × height` RGBA8 macro-texture (sides multiples of 4, as the block packing
/// makes them) as `format` in KTX2. The alpha test of what [`transcode_basis`] gives back is
/// checked texel by texel against `rgba` (an error if it is not exact, which the alpha fixes make
/// impossible).
pub fn encode_basis(
    format: BasisFormat,
    width: u32,
    height: u32,
    rgba: &[u8],
) -> Result<(Vec<u8>, BasisEncodeStats), CompressError> {
    let src = prepare_image(width, height, rgba)?;
    if width % 4 != 0 || height % 4 != 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(CompressError::Invalid(format!(
            "a Basis Universal macro-texture of {width}×{height} texels (sides must be multiples of 4, at most {MAX_SIDE})"
        )));
    }
    let basis = run_encoder(format, width, height, &src)?;
    let file = BasisFile::parse(&basis).map_err(CompressError::Invalid)?;
    let invalid = |e: Ktx2Error| CompressError::Invalid(e.to_string());
    let plain = file.to_ktx2(format, width, height, &[]).map_err(invalid)?;
    // the alpha the file shows, against the source's
    let shown = transcode_level(&plain, basisu::TargetFormat::Rgba32).map_err(invalid)?;
    let fixes: Vec<u32> = (0..(width * height) as usize)
        .filter(|&i| (shown[4 * i + 3] >= 128) != (src[4 * i + 3] >= 128))
        .map(|i| i as u32)
        .collect();
    let ktx2 = if fixes.is_empty() {
        plain
    } else {
        file.to_ktx2(format, width, height, &fixes)
            .map_err(invalid)?
    };
    let t = transcode_basis(&ktx2).map_err(invalid)?;
    let decoded = decode_blocks(t.format, width, height, &t.blocks)?;
    let wrong = (0..(width * height) as usize)
        .filter(|&i| (decoded[4 * i + 3] >= 128) != (src[4 * i + 3] >= 128))
        .count();
    if wrong > 0 {
        return Err(CompressError::Invalid(format!(
            "{wrong} texels of the {format:?} macro-texture change side of the alpha test after transcoding"
        )));
    }
    let stats = BasisEncodeStats {
        bytes: ktx2.len() as u64,
        block_bytes: t.blocks.len() as u64,
        alpha_fixes: fixes.len() as u64,
        fixed_blocks: t.fixed_blocks,
    };
    Ok((ktx2, stats))
}

/// Runs the reference encoder: one sRGB image, no mip levels, to a `.basis` file.
fn run_encoder(
    format: BasisFormat,
    width: u32,
    height: u32,
    rgba: &[u8],
) -> Result<Vec<u8>, CompressError> {
    use basis_universal::{BasisTextureFormat, ColorSpace, Compressor, CompressorParams};
    let mut params = CompressorParams::new();
    match format {
        BasisFormat::Etc1s => {
            params.set_basis_format(BasisTextureFormat::ETC1S);
            params.set_etc1s_quality_level(ETC1S_QUALITY);
            params.set_no_endpoint_rdo(!ETC1S_ENDPOINT_RDO);
        }
        BasisFormat::Uastc => {
            params.set_basis_format(BasisTextureFormat::UASTC4x4);
            // `CompressorParams::set_uastc_quality_level` ORs the level into the pack flags,
            // which already hold the default level (2), so it can only raise the level; the flags
            // are set whole instead (the level is their low nibble, no other flag is used)
            // SAFETY: `params.0` is the live parameter object `CompressorParams::new` allocated
            unsafe {
                basis_universal_sys::compressor_params_set_pack_uastc_flags(
                    params.0,
                    UASTC_LEVEL as basis_universal_sys::UastcPackFlags,
                );
            }
        }
    }
    params.set_color_space(ColorSpace::Srgb);
    params.set_generate_mipmaps(false);
    params.set_print_status_to_stdout(false);
    params.source_image_mut(0).init(rgba, width, height, 4);
    // One thread: the encoder's own job pool (Basis Universal 1.16, `basisu::job_pool`) sets its
    // kill flag without holding the mutex its workers wait on, so a worker that has just found no
    // work can miss the wake-up and the pool's destructor then waits for it forever (seen as a
    // hung bake). With one thread the pool has no workers and runs every job on the caller;
    // callers encode several macro-textures in parallel instead (separate compressors, as the
    // `basisu` tool's parallel mode does).
    let mut compressor = Compressor::new(1);
    // SAFETY: the parameters are set through the crate's checked setters (format, quality in
    // range, one source image of `width × height` RGBA texels, validated by `prepare_image`)
    let ok = unsafe { compressor.init(&params) };
    if !ok {
        return Err(CompressError::Invalid(
            "the Basis Universal encoder refused its parameters".into(),
        ));
    }
    // SAFETY: as above; `process` reads only what `init` was given
    unsafe { compressor.process() }.map_err(|e| {
        CompressError::Invalid(format!("the Basis Universal encoder failed: {e:?}"))
    })?;
    Ok(compressor.basis_file().to_vec())
}

/// The parts of a `.basis` file (Basis Universal 1.16, one 2D image, one level) KTX2 stores.
struct BasisFile<'a> {
    uastc: bool,
    endpoint_count: u16,
    selector_count: u16,
    endpoints: &'a [u8],
    selectors: &'a [u8],
    tables: &'a [u8],
    rgb: &'a [u8],
    alpha: Option<&'a [u8]>,
}

/// Little-endian unsigned integer of `n` bytes at `o`.
fn le(b: &[u8], o: usize, n: usize) -> Result<u64, String> {
    let s = b
        .get(o..o + n)
        .ok_or_else(|| format!(".basis file of {} bytes truncated at {o}", b.len()))?;
    Ok(s.iter().rev().fold(0u64, |v, &x| (v << 8) | x as u64))
}

fn slice<'a>(b: &'a [u8], o: u64, n: u64, what: &str) -> Result<&'a [u8], String> {
    b.get(o as usize..(o + n) as usize).ok_or_else(|| {
        format!(
            ".basis {what} at {o}..{} beyond its {} bytes",
            o + n,
            b.len()
        )
    })
}

impl<'a> BasisFile<'a> {
    /// Parses the header (77 bytes of packed little-endian fields) and the slice descriptors
    /// (23 bytes each) of `basis_file_headers.h`.
    fn parse(b: &'a [u8]) -> Result<BasisFile<'a>, String> {
        const HEADER: u64 = 77;
        const SLICE_DESC: u64 = 23;
        const FLAG_HAS_ALPHA_SLICE: u64 = 1;
        if le(b, 0, 2)? != u64::from(u16::from_le_bytes(*b"sB")) || le(b, 4, 2)? != HEADER {
            return Err("not a .basis file of the expected version".into());
        }
        let slices = le(b, 14, 3)?;
        let images = le(b, 17, 3)?;
        let uastc = le(b, 20, 1)? == 1;
        let slice_descs = le(b, 65, 4)?;
        let mut rgb = None;
        let mut alpha = None;
        for s in 0..slices {
            let o = (slice_descs + s * SLICE_DESC) as usize;
            let (image, level, flags) = (le(b, o, 3)?, le(b, o + 3, 1)?, le(b, o + 4, 1)?);
            if image != 0 || level != 0 {
                return Err(format!(
                    ".basis slice {s} of image {image}, level {level} (one level of one image expected)"
                ));
            }
            let data = slice(b, le(b, o + 13, 4)?, le(b, o + 17, 4)?, "slice")?;
            // a UASTC slice holds RGBA and is flagged as having alpha; ETC1S stores alpha as a
            // second, flagged slice
            if flags & FLAG_HAS_ALPHA_SLICE != 0 && !uastc {
                alpha = Some(data);
            } else {
                rgb = Some(data);
            }
        }
        let rgb = rgb.ok_or("a .basis file without a colour slice")?;
        if images != 1 {
            return Err(format!("a .basis file of {images} images (1 expected)"));
        }
        Ok(BasisFile {
            uastc,
            endpoint_count: le(b, 39, 2)? as u16,
            selector_count: le(b, 48, 2)? as u16,
            endpoints: slice(b, le(b, 41, 4)?, le(b, 45, 3)?, "endpoint codebook")?,
            selectors: slice(b, le(b, 50, 4)?, le(b, 54, 3)?, "selector codebook")?,
            tables: slice(b, le(b, 57, 4)?, le(b, 61, 4)?, "Huffman tables")?,
            rgb,
            alpha,
        })
    }

    /// The KTX2 file of KTX 2.0 sec. 3.12.2 (ETC1S) or 3.12.3 (UASTC, Zstandard), with the alpha
    /// fixes as a key/value entry when there are any.
    fn to_ktx2(
        &self,
        format: BasisFormat,
        width: u32,
        height: u32,
        fixes: &[u32],
    ) -> Result<Vec<u8>, Ktx2Error> {
        if self.uastc != (format == BasisFormat::Uastc) {
            return Err(Ktx2Error::Write(format!(
                "the encoder wrote {} data for {format:?}",
                if self.uastc { "UASTC" } else { "ETC1S" }
            )));
        }
        let fix_bytes: Vec<u8> = fixes.iter().flat_map(|i| i.to_le_bytes()).collect();
        let key_values: Vec<(&str, &[u8])> = if fixes.is_empty() {
            vec![]
        } else {
            vec![(ALPHA_FIXES_KEY, &fix_bytes[..])]
        };
        let has_alpha = self.alpha.is_some() || format == BasisFormat::Uastc;
        let dfd = basis_dfd(format, has_alpha);
        match format {
            BasisFormat::Etc1s => {
                let alpha = self.alpha.unwrap_or(&[]);
                let mut level = self.rgb.to_vec();
                level.extend_from_slice(alpha);
                let mut sgd = Vec::new();
                sgd.extend_from_slice(&self.endpoint_count.to_le_bytes());
                sgd.extend_from_slice(&self.selector_count.to_le_bytes());
                for n in [
                    self.endpoints.len(),
                    self.selectors.len(),
                    self.tables.len(),
                    0, // extendedByteLength
                    // the one image descriptor: flags, RGB slice offset and length, alpha's
                    0,
                    0,
                    self.rgb.len(),
                    if alpha.is_empty() { 0 } else { self.rgb.len() },
                    alpha.len(),
                ] {
                    sgd.extend_from_slice(&(n as u32).to_le_bytes());
                }
                sgd.extend_from_slice(self.endpoints);
                sgd.extend_from_slice(self.selectors);
                sgd.extend_from_slice(self.tables);
                Ok(assemble(&Layout {
                    vk_format: VK_FORMAT_UNDEFINED,
                    width,
                    height,
                    dfd: &dfd,
                    scheme: SCHEME_BASISLZ,
                    global_data: &sgd,
                    key_values: &key_values,
                    levels: &[&level],
                    raw_lengths: &[0],
                    align: 1,
                }))
            }
            BasisFormat::Uastc => {
                let mut z = zstd::bulk::Compressor::new(ZSTD_LEVEL)
                    .map_err(|e| Ktx2Error::Write(format!("Zstandard: {e}")))?;
                z.include_checksum(true)
                    .map_err(|e| Ktx2Error::Write(format!("Zstandard: {e}")))?;
                let level = z
                    .compress(self.rgb)
                    .map_err(|e| Ktx2Error::Write(format!("Zstandard: {e}")))?;
                Ok(assemble(&Layout {
                    vk_format: VK_FORMAT_UNDEFINED,
                    width,
                    height,
                    dfd: &dfd,
                    scheme: SCHEME_ZSTD,
                    global_data: &[],
                    key_values: &key_values,
                    levels: &[&level],
                    raw_lengths: &[self.rgb.len() as u64],
                    align: 1,
                }))
            }
        }
    }
}

/// The data format descriptor of an ETC1S or UASTC file (KDFS 1.3 sec. 5.6; sRGB transfer, BT.709
/// primaries, straight alpha; `bytesPlane0` 0 as both are supercompressed).
fn basis_dfd(format: BasisFormat, alpha: bool) -> Vec<u8> {
    // (bitOffset, bitLength − 1, channel): ETC1S RGB = 0 and AAA = 15 over 64 bits each; UASTC
    // RGBA = 3 or RGB = 4 over 128 bits
    let (model, samples): (u8, Vec<(u16, u8, u8)>) = match format {
        BasisFormat::Etc1s if alpha => (KHR_DF_MODEL_ETC1S, vec![(0, 63, 0), (64, 63, 15)]),
        BasisFormat::Etc1s => (KHR_DF_MODEL_ETC1S, vec![(0, 63, 0)]),
        BasisFormat::Uastc => (
            KHR_DF_MODEL_UASTC,
            vec![(0, 127, if alpha { 3 } else { 4 })],
        ),
    };
    let block_size = 24 + 16 * samples.len() as u32;
    let mut d = Vec::new();
    d.extend_from_slice(&(4 + block_size).to_le_bytes()); // dfdTotalSize
    d.extend_from_slice(&0u32.to_le_bytes()); // vendorId 0 (Khronos), descriptorType 0 (basic)
    d.extend_from_slice(&(2u32 | (block_size << 16)).to_le_bytes()); // versionNumber 2, size
    d.extend_from_slice(&[model, 1, KHR_DF_TRANSFER_SRGB, 0]); // BT.709, sRGB, straight alpha
    d.extend_from_slice(&[3, 3, 0, 0]); // texel block 4×4×1×1, stored minus one
    d.extend_from_slice(&[0; 8]); // bytesPlane0..7: 0, supercompressed
    for (offset, length, channel) in samples {
        d.extend_from_slice(&offset.to_le_bytes());
        d.push(length);
        d.push(channel);
        d.extend_from_slice(&[0; 8]); // samplePosition0..3, sampleLower
        d.extend_from_slice(&u32::MAX.to_le_bytes()); // sampleUpper
    }
    d
}

/// What lemi's reader checks of a Basis Universal KTX2 file before transcoding it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BasisKtx2 {
    pub format: BasisFormat,
    pub width: u32,
    pub height: u32,
    /// The texels whose transcoded alpha must be flipped.
    pub alpha_fixes: Vec<u32>,
}

fn u32_at(b: &[u8], o: usize) -> Result<u32, Ktx2Error> {
    b.get(o..o + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or_else(|| Ktx2Error::Truncated(format!("{} bytes, field at {o}", b.len())))
}

/// Reads the header, data format descriptor and key/value data of a Basis Universal KTX2 file
/// written by [`encode_basis`], checking what lemi relies on.
pub fn read_basis_ktx2(bytes: &[u8]) -> Result<BasisKtx2, Ktx2Error> {
    if bytes.len() < 12 || bytes[..12] != IDENTIFIER {
        return Err(Ktx2Error::BadIdentifier);
    }
    let bad = |m: String| Err(Ktx2Error::BadHeader(m));
    let (vk, width, height) = (u32_at(bytes, 12)?, u32_at(bytes, 20)?, u32_at(bytes, 24)?);
    let (depth, layers, faces) = (u32_at(bytes, 28)?, u32_at(bytes, 32)?, u32_at(bytes, 36)?);
    let (levels, scheme) = (u32_at(bytes, 40)?, u32_at(bytes, 44)?);
    if vk != VK_FORMAT_UNDEFINED {
        return Err(Ktx2Error::UnsupportedFormat(vk));
    }
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return bad(format!(
            "a {width}×{height} texture (lemi stores sides of 1 to {MAX_SIDE} texels)"
        ));
    }
    if depth != 0 || layers != 0 || faces != 1 || levels != 1 {
        return bad(format!(
            "a {width}×{height}×{depth} texture of {layers} layers, {faces} faces and {levels} levels (lemi stores one 2D level)"
        ));
    }
    if width % 4 != 0 || height % 4 != 0 {
        return bad(format!(
            "a {width}×{height} Basis Universal macro-texture (sides must be multiples of 4)"
        ));
    }
    let (dfd_off, dfd_len) = (u32_at(bytes, 48)? as usize, u32_at(bytes, 52)? as usize);
    let dfd = bytes
        .get(dfd_off..dfd_off.saturating_add(dfd_len))
        .filter(|d| d.len() >= 28)
        .ok_or_else(|| {
            Ktx2Error::Truncated(format!(
                "data format descriptor at {dfd_off}..+{dfd_len} of {} bytes",
                bytes.len()
            ))
        })?;
    let format = match (dfd[12], scheme) {
        (KHR_DF_MODEL_ETC1S, SCHEME_BASISLZ) => BasisFormat::Etc1s,
        (KHR_DF_MODEL_UASTC, SCHEME_ZSTD) => BasisFormat::Uastc,
        (model, scheme) => {
            return Err(Ktx2Error::BadDfd(format!(
                "colour model {model} with supercompressionScheme {scheme} (lemi stores ETC1S with BasisLZ, 163/1, or UASTC with Zstandard, 166/2)"
            )))
        }
    };
    // the level and the global data lie inside the file, and the level's inflated size is what
    // the texture's blocks take (the transcoder allocates what the index says)
    let u64_at = |o: usize| -> Result<u64, Ktx2Error> {
        Ok(u32_at(bytes, o)? as u64 | (u32_at(bytes, o + 4)? as u64) << 32)
    };
    let inside = |off: u64, len: u64, what: &str| -> Result<(), Ktx2Error> {
        match off.checked_add(len) {
            Some(end) if end <= bytes.len() as u64 => Ok(()),
            _ => Err(Ktx2Error::Truncated(format!(
                "{what} at {off}..+{len} beyond the end of the {} bytes",
                bytes.len()
            ))),
        }
    };
    let (level_off, level_len, level_raw) = (u64_at(80)?, u64_at(88)?, u64_at(96)?);
    inside(level_off, level_len, "level 0")?;
    inside(u64_at(64)?, u64_at(72)?, "the supercompression global data")?;
    let blocks_bytes = (width as u64 / 4) * (height as u64 / 4) * 16;
    let raw_ok = match format {
        BasisFormat::Etc1s => level_raw == 0,
        BasisFormat::Uastc => level_raw == blocks_bytes,
    };
    if level_len == 0 || !raw_ok {
        return Err(Ktx2Error::BadLevel {
            level: 0,
            reason: format!(
                "{level_len} bytes inflating to {level_raw} for a {width}×{height} {format:?} texture"
            ),
        });
    }
    if dfd[14] != KHR_DF_TRANSFER_SRGB {
        return Err(Ktx2Error::BadDfd(format!(
            "transfer function {} (lemi's macro-textures are sRGB, 2)",
            dfd[14]
        )));
    }
    // key/value data: the alpha fixes
    let (kvd_off, kvd_len) = (u32_at(bytes, 56)? as usize, u32_at(bytes, 60)? as usize);
    let kvd = bytes
        .get(kvd_off..kvd_off.saturating_add(kvd_len))
        .ok_or_else(|| {
            Ktx2Error::Truncated(format!(
                "key/value data at {kvd_off}..+{kvd_len} of {} bytes",
                bytes.len()
            ))
        })?;
    let mut alpha_fixes = Vec::new();
    let mut o = 0usize;
    while o + 4 <= kvd.len() {
        let len = u32_at(kvd, o)? as usize;
        let entry = kvd
            .get(o + 4..(o + 4).saturating_add(len))
            .ok_or_else(|| Ktx2Error::Truncated(format!("key/value entry at {o}")))?;
        let key_end = entry.iter().position(|&c| c == 0).unwrap_or(entry.len());
        if &entry[..key_end] == ALPHA_FIXES_KEY.as_bytes() {
            let value = &entry[(key_end + 1).min(entry.len())..];
            if value.len() % 4 != 0 {
                return bad(format!(
                    "{ALPHA_FIXES_KEY} of {} bytes (u32 texel indices)",
                    value.len()
                ));
            }
            alpha_fixes = value
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            if let Some(&i) = alpha_fixes.iter().find(|&&i| i >= width * height) {
                return bad(format!(
                    "{ALPHA_FIXES_KEY} names texel {i} of a {width}×{height} texture"
                ));
            }
        }
        o += (4 + len).div_ceil(4) * 4;
    }
    Ok(BasisKtx2 {
        format,
        width,
        height,
        alpha_fixes,
    })
}

/// Transcodes level 0 of a Basis Universal KTX2 file to `target`; a panic of the transcoder on
/// damaged data is an error too.
fn transcode_level(bytes: &[u8], target: basisu::TargetFormat) -> Result<Vec<u8>, Ktx2Error> {
    let run = || {
        basisu::Transcoder::new(bytes)
            .and_then(|t| t.transcode(0, target, basisu::DecodeFlags::NONE))
            .map_err(|e| Ktx2Error::BadLevel {
                level: 0,
                reason: format!("Basis Universal transcoder: {e:?}"),
            })
    };
    catch_unwind(AssertUnwindSafe(run)).unwrap_or_else(|_| {
        Err(Ktx2Error::BadLevel {
            level: 0,
            reason: "the Basis Universal transcoder failed on damaged data".into(),
        })
    })
}

/// Transcodes a Basis Universal KTX2 file to the block format of [`BasisFormat::runtime_block`]
/// (ETC1S → BC1, UASTC → BC7) with an exact alpha test (module docs).
pub fn transcode_basis(bytes: &[u8]) -> Result<TranscodedBasis, Ktx2Error> {
    let info = read_basis_ktx2(bytes)?;
    let (width, height) = (info.width, info.height);
    if width % 4 != 0 || height % 4 != 0 {
        return Err(Ktx2Error::BadHeader(format!(
            "a {width}×{height} Basis Universal macro-texture (sides must be multiples of 4)"
        )));
    }
    let format = info.format.runtime_block();
    let target = match format {
        BlockFormat::Bc1 => basisu::TargetFormat::Bc1Rgb,
        BlockFormat::Bc7 => basisu::TargetFormat::Bc7Rgba,
    };
    let mut blocks = transcode_level(bytes, target)?;
    let mut rgba = transcode_level(bytes, basisu::TargetFormat::Rgba32)?;
    let texels = (width * height) as usize;
    if blocks.len() != format.image_bytes(width, height) || rgba.len() != 4 * texels {
        return Err(Ktx2Error::BadLevel {
            level: 0,
            reason: format!(
                "transcoded to {} block bytes and {} RGBA bytes for {width}×{height} texels",
                blocks.len(),
                rgba.len()
            ),
        });
    }
    for &i in &info.alpha_fixes {
        let a = &mut rgba[4 * i as usize + 3];
        *a = if *a >= 128 { 0 } else { 255 };
    }
    let fixed_blocks =
        make_alpha_exact(format, width, height, &rgba, &mut blocks).map_err(|e| {
            Ktx2Error::BadLevel {
                level: 0,
                reason: e.to_string(),
            }
        })?;
    Ok(TranscodedBasis {
        source: info.format,
        format,
        width,
        height,
        blocks,
        alpha_fixes: info.alpha_fixes.len() as u64,
        fixed_blocks,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-built macro-texture: smooth gradients, a second colour region, binary alpha with
    /// holes and ragged edges (alpha values next to 128 on both sides), a transparent margin.
    fn image(w: u32, h: u32) -> Vec<u8> {
        let mut rgba = vec![0u8; 4 * (w * h) as usize];
        for (i, p) in rgba.chunks_exact_mut(4).enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let inside = x >= 4 && y >= 4 && x < w - 4 && y < h - 4;
            let hole = (x / 3 + y / 2) % 5 == 0 || (x * 7 + y * 3) % 11 == 0;
            let a = match (inside && !hole, (x + y) % 2) {
                (true, 0) => 128,
                (true, _) => 255,
                (false, 0) => 127,
                (false, _) => 0,
            };
            let c = if x < w / 2 {
                [(x * 255 / w) as u8, (y * 255 / h) as u8, 90]
            } else {
                [200, 40 + (y % 8) as u8, 60]
            };
            p.copy_from_slice(&[c[0], c[1], c[2], a]);
        }
        rgba
    }

    fn worst_colour_error(a: &[u8], b: &[u8]) -> (i32, f64) {
        let (mut max, mut sq, mut n) = (0, 0.0, 0u64);
        for (p, q) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
            if p[3] >= 128 {
                for c in 0..3 {
                    let d = (p[c] as i32 - q[c] as i32).abs();
                    max = max.max(d);
                    sq += (d * d) as f64;
                    n += 1;
                }
            }
        }
        (max, (sq / n as f64).sqrt())
    }

    #[test]
    fn round_trip_keeps_every_texels_alpha_and_the_colours_within_the_formats_error() {
        let (w, h) = (64u32, 48u32);
        let src = image(w, h);
        // (format, largest and RMS colour error allowed): ETC1S codes a block with one colour
        // and four intensity offsets out of shared codebooks (5-bit colours), UASTC about as BC7
        for (format, max_err, rms_err) in
            [(BasisFormat::Etc1s, 32, 8.0), (BasisFormat::Uastc, 16, 4.0)]
        {
            let (ktx2, stats) = encode_basis(format, w, h, &src).unwrap();
            assert_eq!(stats.bytes, ktx2.len() as u64);
            let t = transcode_basis(&ktx2).unwrap();
            assert_eq!((t.source, t.width, t.height), (format, w, h));
            assert_eq!(t.format, format.runtime_block());
            assert_eq!(t.blocks.len(), t.format.image_bytes(w, h));
            assert_eq!(stats.block_bytes, t.blocks.len() as u64);
            let dec = decode_blocks(t.format, w, h, &t.blocks).unwrap();
            for (i, (p, q)) in src.chunks_exact(4).zip(dec.chunks_exact(4)).enumerate() {
                assert_eq!(
                    p[3] >= 128,
                    q[3] >= 128,
                    "{format:?} texel {i}: {p:?} {q:?}"
                );
            }
            let (max, rms) = worst_colour_error(&src, &dec);
            eprintln!(
                "{format:?}: {} bytes, colour error max {max}, RMS {rms:.2}, {} alpha fixes, {} blocks re-encoded",
                ktx2.len(),
                stats.alpha_fixes,
                t.fixed_blocks
            );
            assert!(max <= max_err && rms <= rms_err, "{format:?}: {max} {rms}");
        }
    }

    #[test]
    fn the_ktx2_crate_reads_the_basis_files_lemi_writes() {
        let (w, h) = (32u32, 16u32);
        for (format, scheme, model) in [
            (
                BasisFormat::Etc1s,
                ktx2::SupercompressionScheme::BasisLZ,
                ktx2::ColorModel::ETC1S,
            ),
            (
                BasisFormat::Uastc,
                ktx2::SupercompressionScheme::Zstandard,
                ktx2::ColorModel::UASTC,
            ),
        ] {
            let (file, _) = encode_basis(format, w, h, &image(w, h)).unwrap();
            let r = ktx2::Reader::new(&file[..]).expect("ktx2 crate reads the file");
            let hd = r.header();
            assert_eq!(hd.format, None, "{format:?}: VK_FORMAT_UNDEFINED");
            assert_eq!((hd.pixel_width, hd.pixel_height, hd.pixel_depth), (w, h, 0));
            assert_eq!((hd.face_count, hd.level_count, hd.layer_count), (1, 1, 0));
            assert_eq!(hd.supercompression_scheme, Some(scheme));
            assert_eq!(r.color_model(), Some(model));
            assert_eq!(r.transfer_function(), Some(ktx2::TransferFunction::SRGB));
            assert_eq!(r.writer(), Some("lemi\0"));
            assert_eq!(r.levels().count(), 1);
            if format == BasisFormat::Etc1s {
                assert!(!r.supercompression_global_data().is_empty());
            }
        }
    }

    /// The KTX2 rewrite is bit-exact: the reference C++ transcoder reading the encoder's `.basis`
    /// and the pure-Rust transcoder reading lemi's KTX2 give the same texels.
    #[test]
    fn ktx2_transcodes_to_the_texels_the_reference_transcoder_reads_from_the_basis_file() {
        use basis_universal::{TranscodeParameters, Transcoder, TranscoderTextureFormat};
        let (w, h) = (64u32, 32u32);
        let src = prepare_image(w, h, &image(w, h)).unwrap();
        for format in [BasisFormat::Etc1s, BasisFormat::Uastc] {
            let basis = run_encoder(format, w, h, &src).unwrap();
            let ktx2 = BasisFile::parse(&basis)
                .unwrap()
                .to_ktx2(format, w, h, &[])
                .unwrap();
            let mut reference = Transcoder::new();
            reference.prepare_transcoding(&basis).unwrap();
            let expected = reference
                .transcode_image_level(
                    &basis,
                    TranscoderTextureFormat::RGBA32,
                    TranscodeParameters {
                        image_index: 0,
                        level_index: 0,
                        decode_flags: None,
                        output_row_pitch_in_blocks_or_pixels: None,
                        output_rows_in_pixels: None,
                    },
                )
                .unwrap();
            let got = transcode_level(&ktx2, basisu::TargetFormat::Rgba32).unwrap();
            assert_eq!(got.len(), expected.len(), "{format:?}");
            assert!(got == expected, "{format:?}: texels differ");
        }
    }

    #[test]
    fn alpha_fixes_flip_exactly_the_listed_texels() {
        let (w, h) = (16u32, 16u32);
        let src = prepare_image(w, h, &image(w, h)).unwrap();
        let basis = run_encoder(BasisFormat::Etc1s, w, h, &src).unwrap();
        let file = BasisFile::parse(&basis).unwrap();
        let plain = transcode_basis(&file.to_ktx2(BasisFormat::Etc1s, w, h, &[]).unwrap()).unwrap();
        let fixes = [0u32, 17, 255];
        let fixed = file.to_ktx2(BasisFormat::Etc1s, w, h, &fixes).unwrap();
        assert_eq!(read_basis_ktx2(&fixed).unwrap().alpha_fixes, fixes);
        let fixed = transcode_basis(&fixed).unwrap();
        let (a, b) = (
            decode_blocks(plain.format, w, h, &plain.blocks).unwrap(),
            decode_blocks(fixed.format, w, h, &fixed.blocks).unwrap(),
        );
        for i in 0..(w * h) as usize {
            let flipped = (a[4 * i + 3] >= 128) != (b[4 * i + 3] >= 128);
            assert_eq!(flipped, fixes.contains(&(i as u32)), "texel {i}");
        }
        // a fix naming a texel outside the image is an error, not a panic
        let bad = file.to_ktx2(BasisFormat::Etc1s, w, h, &[w * h]).unwrap();
        let e = transcode_basis(&bad).unwrap_err().to_string();
        assert!(e.contains(ALPHA_FIXES_KEY), "{e}");
    }

    #[test]
    fn damaged_or_truncated_files_are_errors_not_panics() {
        let (w, h) = (32u32, 32u32);
        for format in [BasisFormat::Etc1s, BasisFormat::Uastc] {
            let (file, _) = encode_basis(format, w, h, &image(w, h)).unwrap();
            for len in [0, 11, 12, 40, 80, file.len() / 2, file.len() - 1] {
                assert!(
                    transcode_basis(&file[..len]).is_err(),
                    "{format:?} truncated to {len} bytes"
                );
            }
            // every byte of the header, index and descriptors, and a sample of the data, flipped:
            // an error or some image, never a panic
            let mut errors = 0;
            for i in (0..file.len()).step_by(if file.len() > 400 { 7 } else { 1 }) {
                let mut d = file.clone();
                d[i] ^= 0x5A;
                errors += transcode_basis(&d).is_err() as u32;
            }
            assert!(errors > 0, "{format:?}");
            // a level index claiming an absurd inflated size (the transcoder would allocate it)
            let mut d = file.clone();
            d[96..104].copy_from_slice(&(1u64 << 56).to_le_bytes());
            assert!(matches!(
                read_basis_ktx2(&d),
                Err(Ktx2Error::BadLevel { .. })
            ));
            let e = read_basis_ktx2(b"not a texture at all").unwrap_err();
            assert_eq!(e, Ktx2Error::BadIdentifier);
        }
        // a block-format file is not a Basis file
        let bc1 = super::super::ktx2_container::write_ktx2(
            BlockFormat::Bc1,
            4,
            4,
            &[vec![0u8; 8]],
            super::super::Supercompression::None,
        )
        .unwrap();
        assert!(matches!(
            read_basis_ktx2(&bc1),
            Err(Ktx2Error::UnsupportedFormat(_))
        ));
    }
}
