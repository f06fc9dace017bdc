//! Block compression of the macro-textures into GPU formats: BC7, and BC1 with punch-through alpha.
//!
//! This work is based on:
//! - Khronos Data Format Specification 1.3, sec. 21 "S3TC Compressed Texture Image Formats" (BC1):
//!   a 4×4 block is two RGB565 endpoints `c0`, `c1` and sixteen 2-bit indices; when `c0 ≤ c1`
//!   (as 16-bit integers) the palette is `c0, c1, (c0 + c1)/2` and index 3 is transparent black
//!   (the punch-through alpha mode, 4 bits a texel);
//! - Khronos Data Format Specification 1.3, sec. 22 "BPTC Compressed Texture Image Formats" (BC7):
//!   128-bit blocks in eight modes; mode 5 stores RGB endpoints of 7 bits and alpha endpoints of
//!   8 bits with separate 2-bit index sets, so alpha 0 and 255 are represented exactly;
//! - encoders: Intel's ISPC Texture Compressor for BC7 (`intel_tex_2`, its prebuilt kernels), the
//!   cluster fit of libsquish for BC1 (`texpresso`, which gives texels of alpha < 128 the
//!   transparent index); decoding with bcdec (`bcdec_rs`).
//!
//! The layers' alpha is binary (opaque when alpha ≥ 128) and the renderer alpha-tests it, so a
//! texel whose alpha changes side of 128 opens a crack or a false silhouette. [`encode_blocks`]
//! therefore decodes every block it wrote and re-encodes any block that breaks the alpha test with
//! an exact-alpha encoding of its own (BC7 mode 5, BC1's three-colour mode), counted in
//! [`BlockEncodeStats::alpha_fixed_blocks`]: after encoding, every texel's alpha is on the side of
//! 128 it was on. Before encoding, a transparent texel takes the mean colour of its block's opaque
//! texels (its colour is never seen), so the endpoints fit the visible texels.
//!
//! [`analyze_blocks`] measures an encoding against its source: alpha-test mismatches, largest and
//! RMS colour error over the opaque texels.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::basis_universal::BasisFormat;
use super::layer_image::{FRINGE_ALPHA, FULL_ALPHA};
use super::CompressError;

/// How a bundle stores its macro-textures (`lemi bake --texture-format`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TextureFormat {
    /// Lossless PNG, uploaded as RGBA8.
    #[default]
    Png,
    /// BC7 (16 bytes per 4×4 block) in KTX2.
    Bc7,
    /// BC1 with punch-through alpha (8 bytes per 4×4 block) in KTX2.
    Bc1,
    /// Basis Universal ETC1S (BasisLZ) in KTX2, transcoded to BC1 at load time.
    Etc1s,
    /// Basis Universal UASTC (Zstandard) in KTX2, transcoded to BC7 at load time.
    Uastc,
}

impl TextureFormat {
    pub const ALL: [TextureFormat; 5] = [
        TextureFormat::Png,
        TextureFormat::Bc7,
        TextureFormat::Bc1,
        TextureFormat::Etc1s,
        TextureFormat::Uastc,
    ];

    /// Whether the format keeps a third alpha level between transparent and fully opaque, the
    /// mark of the outline fringe ([`super::outline_fringe`]): PNG exactly, BC7 and UASTC within
    /// their alpha error; BC1's one-bit alpha (and ETC1S, transcoded to it) does not.
    pub fn keeps_fringe(self) -> bool {
        matches!(
            self,
            TextureFormat::Png | TextureFormat::Bc7 | TextureFormat::Uastc
        )
    }

    /// The name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            TextureFormat::Png => "png",
            TextureFormat::Bc7 => "bc7",
            TextureFormat::Bc1 => "bc1",
            TextureFormat::Etc1s => "etc1s",
            TextureFormat::Uastc => "uastc",
        }
    }

    pub fn is_png(&self) -> bool {
        *self == TextureFormat::Png
    }

    /// The block format the GPU samples, `None` for PNG (a Basis Universal format's is the one
    /// it is transcoded to).
    pub fn block(self) -> Option<BlockFormat> {
        match self {
            TextureFormat::Png => None,
            TextureFormat::Bc7 => Some(BlockFormat::Bc7),
            TextureFormat::Bc1 => Some(BlockFormat::Bc1),
            TextureFormat::Etc1s | TextureFormat::Uastc => self.basis().map(|b| b.runtime_block()),
        }
    }

    /// The Basis Universal encoding, `None` for the formats stored as sampled.
    pub fn basis(self) -> Option<BasisFormat> {
        match self {
            TextureFormat::Etc1s => Some(BasisFormat::Etc1s),
            TextureFormat::Uastc => Some(BasisFormat::Uastc),
            _ => None,
        }
    }

    /// Parses a name of [`TextureFormat::name`].
    pub fn from_name(name: &str) -> Option<TextureFormat> {
        TextureFormat::ALL.into_iter().find(|f| f.name() == name)
    }
}

impl std::fmt::Display for TextureFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A 4×4 block-compressed format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BlockFormat {
    Bc7,
    Bc1,
}

/// Side of a block in texels.
pub const BLOCK: u32 = 4;

impl BlockFormat {
    /// Bytes of one 4×4 block.
    pub fn block_bytes(self) -> usize {
        match self {
            BlockFormat::Bc7 => 16,
            BlockFormat::Bc1 => 8,
        }
    }

    /// Bytes of a `width × height` image (partial blocks count whole).
    pub fn image_bytes(self, width: u32, height: u32) -> usize {
        width.div_ceil(BLOCK) as usize * height.div_ceil(BLOCK) as usize * self.block_bytes()
    }

    pub fn texture_format(self) -> TextureFormat {
        match self {
            BlockFormat::Bc7 => TextureFormat::Bc7,
            BlockFormat::Bc1 => TextureFormat::Bc1,
        }
    }

    /// Decodes one block to 16 RGBA texels, row-major.
    pub fn decode_block(self, block: &[u8]) -> [[u8; 4]; 16] {
        let mut out = [0u8; 64];
        match self {
            BlockFormat::Bc7 => bcdec_rs::bc7(block, &mut out, 16),
            BlockFormat::Bc1 => bcdec_rs::bc1(block, &mut out, 16),
        }
        let mut px = [[0u8; 4]; 16];
        for (i, p) in px.iter_mut().enumerate() {
            p.copy_from_slice(&out[4 * i..4 * i + 4]);
        }
        px
    }
}

/// What an encoding did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BlockEncodeStats {
    pub blocks: u64,
    /// Bytes of the encoded image.
    pub bytes: u64,
    /// Blocks the encoder got wrong on the alpha test, re-encoded with exact alpha.
    pub alpha_fixed_blocks: u64,
}

/// How close an encoding is to its source ([`analyze_blocks`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BlockQuality {
    /// Texels whose alpha is on the other side of 128 after decoding (must be 0).
    pub alpha_mismatches: u64,
    /// Texels opaque in the source.
    pub opaque_texels: u64,
    /// Largest difference of one colour channel over the opaque texels (0..=255).
    pub max_colour_error: u8,
    /// Root mean square colour channel difference over the opaque texels.
    pub rmse: f64,
}

/// The 16 texels of block `(bx, by)` of a `width × height` RGBA8 image; texels beyond the image
/// repeat its last column or row (partial blocks at the right and bottom edges).
fn read_block(rgba: &[u8], width: u32, height: u32, bx: u32, by: u32) -> [[u8; 4]; 16] {
    let mut px = [[0u8; 4]; 16];
    for (i, p) in px.iter_mut().enumerate() {
        let x = (bx * BLOCK + i as u32 % BLOCK).min(width - 1);
        let y = (by * BLOCK + i as u32 / BLOCK).min(height - 1);
        let o = 4 * (y as usize * width as usize + x as usize);
        p.copy_from_slice(&rgba[o..o + 4]);
    }
    px
}

fn opaque(p: &[u8; 4]) -> bool {
    p[3] >= 128
}

/// The alpha level of a texel: 0 transparent, 1 outline fringe ([`super::outline_fringe`]), 2
/// fully opaque.
fn alpha_level(p: &[u8; 4]) -> u8 {
    u8::from(p[3] >= 128) + u8::from(p[3] >= FULL_ALPHA)
}

/// Whether `format` keeps the fringe level of alpha (BC7 does; BC1's one-bit alpha does not).
fn keeps_fringe(format: BlockFormat) -> bool {
    format == BlockFormat::Bc7
}

/// Whether `decoded` shows every texel of `px` on its alpha level as `format` keeps them.
fn same_alpha(format: BlockFormat, px: &[[u8; 4]; 16], decoded: &[[u8; 4]; 16]) -> bool {
    if keeps_fringe(format) {
        px.iter()
            .zip(decoded)
            .all(|(a, b)| alpha_level(a) == alpha_level(b))
    } else {
        px.iter().zip(decoded).all(|(a, b)| opaque(a) == opaque(b))
    }
}

/// The block as the encoders get it: alpha 255 for opaque texels ([`FRINGE_ALPHA`] for outline
/// fringe texels where `fringe`, else 255 for them too), transparent texels in the mean opaque
/// colour with alpha 0.
fn prepare_block(px: &mut [[u8; 4]; 16], fringe: bool) {
    let (mut sum, mut n) = ([0u32; 3], 0u32);
    for p in px.iter().filter(|p| opaque(p)) {
        for c in 0..3 {
            sum[c] += p[c] as u32;
        }
        n += 1;
    }
    let mean = if n == 0 {
        [0u8; 3]
    } else {
        [0, 1, 2].map(|c| ((sum[c] + n / 2) / n) as u8)
    };
    for p in px.iter_mut() {
        if opaque(p) {
            p[3] = if fringe && alpha_level(p) == 1 {
                FRINGE_ALPHA
            } else {
                255
            };
        } else {
            *p = [mean[0], mean[1], mean[2], 0];
        }
    }
}

/// The image as block encoders get it ([`prepare_block`] over every 4×4 block): alpha 0, 255 or
/// (outline fringe) [`FRINGE_ALPHA`], transparent texels in the mean colour of their block's
/// opaque texels.
pub fn prepare_image(width: u32, height: u32, rgba: &[u8]) -> Result<Vec<u8>, CompressError> {
    check_image(width, height, rgba)?;
    let mut out = rgba.to_vec();
    let w = width as usize;
    for by in 0..height.div_ceil(BLOCK) {
        for bx in 0..width.div_ceil(BLOCK) {
            let mut px = read_block(rgba, width, height, bx, by);
            prepare_block(&mut px, true);
            for (i, p) in px.iter().enumerate() {
                let (x, y) = (bx * BLOCK + i as u32 % BLOCK, by * BLOCK + i as u32 / BLOCK);
                if x < width && y < height {
                    let o = 4 * (y as usize * w + x as usize);
                    out[o..o + 4].copy_from_slice(p);
                }
            }
        }
    }
    Ok(out)
}

fn check_image(width: u32, height: u32, rgba: &[u8]) -> Result<(), CompressError> {
    if width == 0 || height == 0 || rgba.len() != 4 * width as usize * height as usize {
        return Err(CompressError::Invalid(format!(
            "an image of {width}×{height} texels cannot have {} RGBA bytes",
            rgba.len()
        )));
    }
    Ok(())
}

/// Encodes a `width × height` RGBA8 image (row-major, row 0 first) into `format`, blocks
/// row-major. Every texel decodes to an alpha on the same side of 128 as its source, and in BC7
/// on the same alpha level (transparent, outline fringe, fully opaque).
pub fn encode_blocks(
    format: BlockFormat,
    width: u32,
    height: u32,
    rgba: &[u8],
) -> Result<(Vec<u8>, BlockEncodeStats), CompressError> {
    check_image(width, height, rgba)?;
    let (bw, bh) = (width.div_ceil(BLOCK), height.div_ceil(BLOCK));
    let bb = format.block_bytes();
    let mut out = vec![0u8; format.image_bytes(width, height)];
    let fixed: u64 = out
        .par_chunks_mut(bw as usize * bb)
        .enumerate()
        .map(|(by, row)| {
            let by = by as u32;
            let blocks: Vec<[[u8; 4]; 16]> = (0..bw)
                .map(|bx| {
                    let mut px = read_block(rgba, width, height, bx, by);
                    prepare_block(&mut px, keeps_fringe(format));
                    px
                })
                .collect();
            encode_row(format, &blocks, row);
            let mut fixed = 0;
            for (px, block) in blocks.iter().zip(row.chunks_exact_mut(bb)) {
                fixed += fix_alpha(format, px, block) as u64;
            }
            fixed
        })
        .sum();
    let stats = BlockEncodeStats {
        blocks: bw as u64 * bh as u64,
        bytes: out.len() as u64,
        alpha_fixed_blocks: fixed,
    };
    Ok((out, stats))
}

/// Encodes one row of prepared blocks with the format's encoder.
/// Keeps the alpha tests exact: when `block` decodes with a texel's alpha on another level than
/// in `px` (as [`prepare_block`] leaves it; [`same_alpha`]), replaces it with an exact-alpha
/// encoding of `px` (BC7 mode 5, BC1's three-colour mode); says whether it did.
fn fix_alpha(format: BlockFormat, px: &[[u8; 4]; 16], block: &mut [u8]) -> bool {
    let decoded = format.decode_block(block);
    if same_alpha(format, px, &decoded) {
        return false;
    }
    match format {
        BlockFormat::Bc7 => block.copy_from_slice(&bc7_mode5_block(px)),
        BlockFormat::Bc1 => block.copy_from_slice(&bc1_three_colour_block(px)),
    }
    true
}

/// Makes the alpha test of `blocks` (a `width × height` image of `format`, e.g. transcoded from
/// another encoding) exact against `rgba`, the texels it must show: every block that decodes with
/// a texel on the wrong side of alpha 128 is re-encoded exactly from `rgba` (transparent texels in
/// the mean opaque colour of their block). Returns the number of blocks replaced.
pub fn make_alpha_exact(
    format: BlockFormat,
    width: u32,
    height: u32,
    rgba: &[u8],
    blocks: &mut [u8],
) -> Result<u64, CompressError> {
    check_image(width, height, rgba)?;
    if blocks.len() != format.image_bytes(width, height) {
        return Err(CompressError::Invalid(format!(
            "{format:?} data of {} bytes cannot hold an image of {width}×{height} texels",
            blocks.len()
        )));
    }
    let bw = width.div_ceil(BLOCK);
    let bb = format.block_bytes();
    Ok(blocks
        .par_chunks_mut(bw as usize * bb)
        .enumerate()
        .map(|(by, row)| {
            let mut fixed = 0;
            for (bx, block) in row.chunks_exact_mut(bb).enumerate() {
                let mut px = read_block(rgba, width, height, bx as u32, by as u32);
                prepare_block(&mut px, keeps_fringe(format));
                fixed += fix_alpha(format, &px, block) as u64;
            }
            fixed
        })
        .sum())
}

fn encode_row(format: BlockFormat, blocks: &[[[u8; 4]; 16]], out: &mut [u8]) {
    match format {
        BlockFormat::Bc7 => {
            // a 4-texel-high strip holding the blocks side by side
            let w = blocks.len() * 4;
            let mut strip = vec![0u8; w * 4 * 4];
            for (bx, px) in blocks.iter().enumerate() {
                for (i, p) in px.iter().enumerate() {
                    let o = 4 * ((i / 4) * w + bx * 4 + i % 4);
                    strip[o..o + 4].copy_from_slice(p);
                }
            }
            let surface = intel_tex_2::RgbaSurface {
                data: &strip,
                width: w as u32,
                height: 4,
                stride: 4 * w as u32,
            };
            intel_tex_2::bc7::compress_blocks_into(
                // "fast": 0.09 dB below "basic" at half its time (docs/BENCHMARKS.md)
                &intel_tex_2::bc7::alpha_fast_settings(),
                &surface,
                out,
            );
        }
        BlockFormat::Bc1 => {
            let params = texpresso::Params {
                algorithm: texpresso::Algorithm::ClusterFit,
                ..Default::default()
            };
            for (px, block) in blocks.iter().zip(out.chunks_exact_mut(8)) {
                texpresso::Format::Bc1.compress_block_masked(*px, 0xffff, params, block);
            }
        }
    }
}

/// Decodes a block-compressed `width × height` image to RGBA8.
pub fn decode_blocks(
    format: BlockFormat,
    width: u32,
    height: u32,
    blocks: &[u8],
) -> Result<Vec<u8>, CompressError> {
    if width == 0 || height == 0 || blocks.len() != format.image_bytes(width, height) {
        return Err(CompressError::Invalid(format!(
            "{format:?} data of {} bytes cannot hold an image of {width}×{height} texels ({} bytes)",
            blocks.len(),
            if width == 0 || height == 0 {
                0
            } else {
                format.image_bytes(width, height)
            }
        )));
    }
    let bw = width.div_ceil(BLOCK) as usize;
    let bb = format.block_bytes();
    let mut rgba = vec![0u8; 4 * width as usize * height as usize];
    rgba.par_chunks_mut(4 * width as usize * BLOCK as usize)
        .enumerate()
        .for_each(|(by, rows)| {
            let rows_here = rows.len() / (4 * width as usize);
            for bx in 0..bw {
                let o = (by * bw + bx) * bb;
                let px = format.decode_block(&blocks[o..o + bb]);
                for (i, p) in px.iter().enumerate() {
                    let (x, y) = (bx * 4 + i % 4, i / 4);
                    if x < width as usize && y < rows_here {
                        let d = 4 * (y * width as usize + x);
                        rows[d..d + 4].copy_from_slice(p);
                    }
                }
            }
        });
    Ok(rgba)
}

/// Measures an encoding of `rgba` (see [`BlockQuality`]).
pub fn analyze_blocks(
    format: BlockFormat,
    width: u32,
    height: u32,
    rgba: &[u8],
    blocks: &[u8],
) -> Result<BlockQuality, CompressError> {
    check_image(width, height, rgba)?;
    let decoded = decode_blocks(format, width, height, blocks)?;
    let mut q = BlockQuality::default();
    let mut sq = 0u64;
    for (a, b) in rgba.chunks_exact(4).zip(decoded.chunks_exact(4)) {
        if (a[3] >= 128) != (b[3] >= 128) {
            q.alpha_mismatches += 1;
        }
        if a[3] >= 128 {
            q.opaque_texels += 1;
            for c in 0..3 {
                let d = a[c].abs_diff(b[c]);
                q.max_colour_error = q.max_colour_error.max(d);
                sq += d as u64 * d as u64;
            }
        }
    }
    if q.opaque_texels > 0 {
        q.rmse = (sq as f64 / (3 * q.opaque_texels) as f64).sqrt();
    }
    Ok(q)
}

/// Least-significant-bit-first writer of a 128-bit block.
struct Bits {
    value: u128,
    len: u32,
}

impl Bits {
    fn put(&mut self, v: u32, n: u32) {
        self.value |= ((v as u128) & ((1u128 << n) - 1)) << self.len;
        self.len += n;
    }
}

/// The two opaque texel colours farthest apart (any texels when none is opaque): endpoints of a
/// palette line through the block's colours.
fn endpoint_pair(px: &[[u8; 4]; 16]) -> ([u8; 3], [u8; 3]) {
    let any = px.iter().any(opaque);
    let set: Vec<[u8; 3]> = px
        .iter()
        .filter(|p| !any || opaque(p))
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    let d = |a: &[u8; 3], b: &[u8; 3]| -> i32 {
        (0..3).map(|c| (a[c] as i32 - b[c] as i32).pow(2)).sum()
    };
    let mut best = (set[0], set[0], -1);
    for (i, a) in set.iter().enumerate() {
        for b in &set[i..] {
            if d(a, b) > best.2 {
                best = (*a, *b, d(a, b));
            }
        }
    }
    (best.0, best.1)
}

/// Index of the palette entry closest to `p` (squared RGB distance).
fn nearest(palette: &[[i32; 3]], p: &[u8; 4]) -> u32 {
    let d = |q: &[i32; 3]| -> i32 { (0..3).map(|c| (q[c] - p[c] as i32).pow(2)).sum() };
    (0..palette.len())
        .min_by_key(|&i| d(&palette[i]))
        .unwrap_or(0) as u32
}

/// A BC7 mode 5 block (KDFS sec. 22): RGB endpoints of 7 bits at the two opaque colours farthest
/// apart, alpha endpoints 0 and 255 with separate indices, so every texel's alpha is exactly 0 or 255.
pub(crate) fn bc7_mode5_block(px: &[[u8; 4]; 16]) -> [u8; 16] {
    let (lo, hi) = endpoint_pair(px);
    let mut e0 = lo.map(|c| (c >> 1) as u32);
    let mut e1 = hi.map(|c| (c >> 1) as u32);
    let expand = |e: [u32; 3]| e.map(|c| ((c << 1) | (c >> 6)) as i32);
    const W: [i32; 4] = [0, 21, 43, 64];
    let palette = |e0: [u32; 3], e1: [u32; 3]| -> Vec<[i32; 3]> {
        let (a, b) = (expand(e0), expand(e1));
        W.iter()
            .map(|&w| [0, 1, 2].map(|c| (a[c] * (64 - w) + b[c] * w + 32) >> 6))
            .collect()
    };
    let mut ci: Vec<u32> = px.iter().map(|p| nearest(&palette(e0, e1), p)).collect();
    // anchor texel 0 stores its index with one bit: its index must be < 2
    if ci[0] >= 2 {
        std::mem::swap(&mut e0, &mut e1);
        ci.iter_mut().for_each(|i| *i = 3 - *i);
    }
    // alpha from 255 to 0 (or 0 to 255) in four steps: 255, 171, 84, 0; an outline fringe texel
    // takes 171 (between the two alpha tests), and the anchor texel's index stays below 2
    let (a0, a1, ai): (u32, u32, Vec<u32>) = if opaque(&px[0]) {
        let index = |p: &[u8; 4]| [3, 1, 0][alpha_level(p) as usize];
        (255, 0, px.iter().map(index).collect())
    } else {
        let index = |p: &[u8; 4]| [0, 2, 3][alpha_level(p) as usize];
        (0, 255, px.iter().map(index).collect())
    };
    let mut b = Bits { value: 0, len: 0 };
    b.put(1 << 5, 6); // mode 5
    b.put(0, 2); // no channel rotation
    for c in 0..3 {
        b.put(e0[c], 7);
        b.put(e1[c], 7);
    }
    b.put(a0, 8);
    b.put(a1, 8);
    for indices in [&ci, &ai] {
        for (t, &i) in indices.iter().enumerate() {
            b.put(i, if t == 0 { 1 } else { 2 });
        }
    }
    debug_assert_eq!(b.len, 128);
    b.value.to_le_bytes()
}

/// A BC1 block in its three-colour mode (`c0 ≤ c1`, KDFS sec. 21): RGB565 endpoints at the two
/// opaque colours farthest apart, transparent texels on index 3.
pub(crate) fn bc1_three_colour_block(px: &[[u8; 4]; 16]) -> [u8; 8] {
    let (lo, hi) = endpoint_pair(px);
    let pack = |c: [u8; 3]| -> u16 {
        ((c[0] as u16 >> 3) << 11) | ((c[1] as u16 >> 2) << 5) | (c[2] as u16 >> 3)
    };
    let unpack = |v: u16| -> [i32; 3] {
        let (r, g, b) = ((v >> 11) & 31, (v >> 5) & 63, v & 31);
        [
            ((r << 3) | (r >> 2)) as i32,
            ((g << 2) | (g >> 4)) as i32,
            ((b << 3) | (b >> 2)) as i32,
        ]
    };
    let (mut c0, mut c1) = (pack(lo), pack(hi));
    if c0 > c1 {
        std::mem::swap(&mut c0, &mut c1);
    }
    let (p0, p1) = (unpack(c0), unpack(c1));
    let palette = [p0, p1, [0, 1, 2].map(|c| (p0[c] + p1[c]) / 2)];
    let mut indices = 0u32;
    for (t, p) in px.iter().enumerate() {
        let i = if opaque(p) { nearest(&palette, p) } else { 3 };
        indices |= i << (2 * t);
    }
    let mut block = [0u8; 8];
    block[0..2].copy_from_slice(&c0.to_le_bytes());
    block[2..4].copy_from_slice(&c1.to_le_bytes());
    block[4..8].copy_from_slice(&indices.to_le_bytes());
    block
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bounding box of the opaque texels' colours (all texels when none is opaque).
    fn colour_box(px: &[[u8; 4]; 16]) -> ([u8; 3], [u8; 3]) {
        let any = px.iter().any(opaque);
        let (mut lo, mut hi) = ([255u8; 3], [0u8; 3]);
        for p in px.iter().filter(|p| !any || opaque(p)) {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        (lo, hi)
    }

    fn xorshift(seed: u32) -> impl FnMut() -> u32 {
        let mut s = seed.wrapping_mul(2654435761).max(1);
        move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s
        }
    }

    /// A binary alpha of a disc, stripes and single texels, with alpha values next to 128 on
    /// both sides (127 transparent, 128 opaque).
    fn alpha_pattern(w: u32, h: u32, seed: u32) -> Vec<u8> {
        let mut rnd = xorshift(seed);
        let mut a = Vec::with_capacity((w * h) as usize);
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f32 - w as f32 / 3.0, y as f32 - h as f32 / 2.0);
                let disc = dx * dx + dy * dy < (w.min(h) as f32 / 4.0).powi(2);
                let on = disc ^ ((x + 2 * y) % 11 < 3) ^ (rnd() % 17 == 0);
                a.push(match (on, rnd() % 3) {
                    (true, 0) => FULL_ALPHA,
                    (true, _) => 255,
                    (false, 0) => 127,
                    (false, _) => 0,
                });
            }
        }
        a
    }

    /// Smooth colour (gradients of 2 to 4 units a texel, so up to 12 across a block) under
    /// [`alpha_pattern`].
    fn gradient_image(w: u32, h: u32, seed: u32) -> Vec<u8> {
        let alpha = alpha_pattern(w, h, seed);
        let mut rgba = Vec::with_capacity(4 * alpha.len());
        for (i, a) in alpha.into_iter().enumerate() {
            let (x, y) = ((i as u32 % w) as f32, (i as u32 / w) as f32);
            rgba.extend_from_slice(&[
                (4.0 * x).min(255.0) as u8,
                (40.0 + 3.0 * y).min(255.0) as u8,
                (250.0 - 2.0 * (x + y)).max(0.0) as u8,
                a,
            ]);
        }
        rgba
    }

    /// Two random colours per 4×4 block in a random pattern, under [`alpha_pattern`].
    fn two_colour_image(w: u32, h: u32, seed: u32) -> Vec<u8> {
        let alpha = alpha_pattern(w, h, seed);
        let mut rnd = xorshift(seed + 99);
        let colours: Vec<[u8; 3]> = (0..2 * w.div_ceil(4) * h.div_ceil(4))
            .map(|_| {
                let v = rnd();
                [v as u8, (v >> 8) as u8, (v >> 16) as u8]
            })
            .collect();
        let mut rgba = Vec::with_capacity(4 * alpha.len());
        for (i, a) in alpha.into_iter().enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let b = (y / 4) * w.div_ceil(4) + x / 4;
            let c = colours[(2 * b + rnd() % 2) as usize];
            rgba.extend_from_slice(&[c[0], c[1], c[2], a]);
        }
        rgba
    }

    fn round_trip(format: BlockFormat, w: u32, h: u32, rgba: &[u8]) -> BlockQuality {
        let (blocks, stats) = encode_blocks(format, w, h, rgba).unwrap();
        assert_eq!(blocks.len(), format.image_bytes(w, h));
        assert_eq!(stats.bytes as usize, blocks.len());
        let q = analyze_blocks(format, w, h, rgba, &blocks).unwrap();
        assert_eq!(q.alpha_mismatches, 0, "{format:?} {w}×{h}: {q:?}");
        q
    }

    const SIZES: [(u32, u32, u32); 5] =
        [(64, 64, 1), (36, 20, 2), (5, 3, 3), (1, 1, 4), (128, 8, 5)];

    #[test]
    fn bc7_round_trip_keeps_alpha_exact_and_colour_close() {
        for (w, h, seed) in SIZES {
            // a gradient across a block is a line in colour space, which BC7's endpoints and 2- to
            // 4-bit indices follow; blocks with transparent texels use the alpha modes (5- to
            // 7-bit endpoints and a p-bit): measured 7 at worst, 1.8 RMS
            let q = round_trip(BlockFormat::Bc7, w, h, &gradient_image(w, h, seed));
            assert!(q.max_colour_error <= 10 && q.rmse < 2.5, "{w}×{h}: {q:?}");
            // two colours a block in a pattern no partition table holds, with alpha: one subset,
            // the colours at the endpoints of 5- to 7-bit precision: measured 12 at worst, 2.5 RMS
            let q = round_trip(BlockFormat::Bc7, w, h, &two_colour_image(w, h, seed));
            assert!(q.max_colour_error <= 16 && q.rmse < 3.5, "{w}×{h}: {q:?}");
        }
    }

    #[test]
    fn bc1_round_trip_keeps_alpha_exact_and_colour_close() {
        for (w, h, seed) in SIZES {
            // RGB565 endpoints (rounding error up to 4 in red and blue, 2 in green) and one or two
            // interpolated entries a third or half of the way: measured 9 at worst, 2.5 RMS
            let q = round_trip(BlockFormat::Bc1, w, h, &gradient_image(w, h, seed));
            assert!(q.max_colour_error <= 12 && q.rmse < 3.5, "{w}×{h}: {q:?}");
            // two colours a block are the two endpoints, each within RGB565's rounding
            let q = round_trip(BlockFormat::Bc1, w, h, &two_colour_image(w, h, seed));
            assert!(q.max_colour_error <= 8 && q.rmse < 3.0, "{w}×{h}: {q:?}");
        }
    }

    #[test]
    fn a_solid_colour_is_within_the_endpoint_precision() {
        // one colour per block: BC7 (≥ 7-bit endpoints) within 2, BC1 (RGB565 and the 1/3, 2/3
        // or 1/2 palette points) within 8 per channel
        let (w, h) = (16u32, 16u32);
        let mut img = vec![0u8; 4 * 256];
        for (i, p) in img.chunks_exact_mut(4).enumerate() {
            let b = ((i as u32 % w) / 4 + 4 * ((i as u32 / w) / 4)) as u8;
            p.copy_from_slice(&[b * 17, 255 - b * 13, b * 7 + 30, 255]);
        }
        assert!(round_trip(BlockFormat::Bc7, w, h, &img).max_colour_error <= 2);
        assert!(round_trip(BlockFormat::Bc1, w, h, &img).max_colour_error <= 8);
    }

    #[test]
    fn fully_transparent_and_fully_opaque_blocks() {
        let (w, h) = (8u32, 8u32);
        let mut img = vec![0u8; 4 * 64];
        for (i, p) in img.chunks_exact_mut(4).enumerate() {
            let x = i as u32 % w;
            p.copy_from_slice(&[200, 100, 50, if x < 4 { 0 } else { 255 }]);
        }
        for f in [BlockFormat::Bc7, BlockFormat::Bc1] {
            let (blocks, stats) = encode_blocks(f, w, h, &img).unwrap();
            assert_eq!(stats.blocks, 4);
            let dec = decode_blocks(f, w, h, &blocks).unwrap();
            for (a, b) in img.chunks_exact(4).zip(dec.chunks_exact(4)) {
                assert_eq!(a[3] >= 128, b[3] >= 128, "{f:?}");
            }
        }
    }

    /// Outline fringe texels (alpha between the two alpha tests) stay fringe in BC7, from the
    /// encoder or from the exact mode-5 block, next to transparent and fully opaque texels in any
    /// mix; BC1 keeps only the first alpha test (fringe texels decode opaque).
    #[test]
    fn bc7_keeps_the_fringe_level_bc1_the_alpha_test() {
        for seed in 0..100u32 {
            let (w, h) = (12, 8);
            let mut img = gradient_image(w, h, seed);
            for (i, p) in img.chunks_exact_mut(4).enumerate() {
                let r = (i as u32)
                    .wrapping_mul(2_654_435_761)
                    .wrapping_add(seed * 97)
                    >> 29;
                p[3] = [0, FRINGE_ALPHA, 255, FRINGE_ALPHA, 255, 255, 0, 200][r as usize];
            }
            for f in [BlockFormat::Bc7, BlockFormat::Bc1] {
                let (blocks, _) = encode_blocks(f, w, h, &img).expect("encode");
                let dec = decode_blocks(f, w, h, &blocks).expect("decode");
                for (a, b) in img.chunks_exact(4).zip(dec.chunks_exact(4)) {
                    let (a, b) = ([a[0], a[1], a[2], a[3]], [b[0], b[1], b[2], b[3]]);
                    if f == BlockFormat::Bc7 {
                        assert_eq!(alpha_level(&a), alpha_level(&b), "{seed}: {a:?} {b:?}");
                    } else {
                        assert_eq!(opaque(&a), opaque(&b), "{seed}: {a:?} {b:?}");
                    }
                }
            }
            let mut px = read_block(&img, w, h, 1, 1);
            prepare_block(&mut px, true);
            let dec = BlockFormat::Bc7.decode_block(&bc7_mode5_block(&px));
            assert!(px
                .iter()
                .zip(&dec)
                .all(|(a, b)| alpha_level(a) == alpha_level(b)));
        }
    }

    #[test]
    fn the_exact_alpha_blocks_decode_with_exact_alpha() {
        for seed in 0..200u32 {
            let img = if seed % 2 == 0 {
                gradient_image(4, 4, seed)
            } else {
                two_colour_image(4, 4, seed)
            };
            let mut px = read_block(&img, 4, 4, 0, 0);
            prepare_block(&mut px, false);
            for (format, block) in [
                (BlockFormat::Bc7, bc7_mode5_block(&px).to_vec()),
                (BlockFormat::Bc1, bc1_three_colour_block(&px).to_vec()),
            ] {
                let dec = format.decode_block(&block);
                let (lo, hi) = colour_box(&px);
                for (a, b) in px.iter().zip(&dec) {
                    assert_eq!(b[3], if opaque(a) { 255 } else { 0 }, "{format:?} {seed}");
                    if opaque(a) {
                        // the endpoints are opaque texels (rounded to the endpoint precision), so
                        // a texel is no farther from its palette entry than the block's spread
                        for c in 0..3 {
                            let spread = hi[c] - lo[c];
                            assert!(
                                a[c].abs_diff(b[c]) <= spread.saturating_add(8),
                                "{format:?} {seed}: {a:?} {b:?}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn a_block_that_breaks_the_alpha_test_is_re_encoded() {
        // an opaque block encoded for a block with transparent texels breaks the alpha test;
        // the verification in encode_blocks replaces exactly such blocks
        let img = two_colour_image(4, 4, 7);
        let mut px = read_block(&img, 4, 4, 0, 0);
        prepare_block(&mut px, false);
        assert!(px.iter().any(|p| !opaque(p)) && px.iter().any(opaque));
        let mut wrong = [0u8; 16];
        let solid = vec![[10u8, 20, 30, 255]; 16];
        encode_row(BlockFormat::Bc7, &[solid.try_into().unwrap()], &mut wrong);
        let dec = BlockFormat::Bc7.decode_block(&wrong);
        assert!(px.iter().zip(&dec).any(|(a, b)| opaque(a) != opaque(b)));
        let fixed = bc7_mode5_block(&px);
        let dec = BlockFormat::Bc7.decode_block(&fixed);
        assert!(px.iter().zip(&dec).all(|(a, b)| opaque(a) == opaque(b)));
    }

    #[test]
    fn wrong_sizes_are_errors() {
        assert!(encode_blocks(BlockFormat::Bc7, 4, 4, &[0; 63]).is_err());
        assert!(encode_blocks(BlockFormat::Bc1, 0, 4, &[]).is_err());
        assert!(decode_blocks(BlockFormat::Bc1, 8, 4, &[0; 8]).is_err());
        assert!(decode_blocks(BlockFormat::Bc7, 0, 0, &[]).is_err());
    }

    #[test]
    fn format_names() {
        for f in TextureFormat::ALL {
            assert_eq!(TextureFormat::from_name(f.name()), Some(f));
            assert_eq!(
                serde_json::to_string(&f).unwrap(),
                format!("\"{}\"", f.name())
            );
        }
        assert_eq!(TextureFormat::from_name("dxt1"), None);
    }
}
