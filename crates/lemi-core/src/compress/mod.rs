//! Compression stages of GI 2002 sec. 5 (Jeschke, Wimmer et al., *Layered Environment-Map
//! Impostors for Arbitrary Scenes*), one file per stage, each a function over plain layer images
//! that returns its output and the statistics that measure it:
//!
//! | stage | file | paper |
//! |---|---|---|
//! | gap filling | [`gap_fill`] | sec. 5.1 |
//! | hidden-texel removal | [`hidden_texels`] | sec. 5.2 |
//! | micro-textures (impostor quads) | [`micro_textures`] | sec. 5.3 |
//! | macro-texture packing | [`macro_packing`] | sec. 5.4 |
//! | GPU block formats (BC7, BC1) | [`block_compression`] | KDFS 1.3 secs. 21–22 |
//! | Basis Universal (ETC1S, UASTC) | [`basis_universal`] | KTX 2.0 sec. 3.12 |
//! | KTX2 container | [`ktx2_container`] | KTX 2.0 |
//!
//! PNG storage of the macro-textures (end of sec. 5.4) belongs to the bundle writer, as does the
//! choice between PNG and a block format in KTX2.
//! [`compress_cell`] runs the stages in order for one view cell, in parallel over faces and layers
//! (deterministic: the result does not depend on the thread count). See `docs/COMPRESSION.md`.

pub mod basis_universal;
pub mod block_compression;
pub mod gap_fill;
pub mod hidden_texels;
pub mod ktx2_container;
pub mod layer_image;
pub mod macro_packing;
pub mod micro_textures;
pub mod outline_fringe;

use rayon::prelude::*;

pub use basis_universal::{
    encode_basis, read_basis_ktx2, transcode_basis, BasisEncodeStats, BasisFormat, BasisKtx2,
    TranscodedBasis,
};
pub use block_compression::{
    analyze_blocks, decode_blocks, encode_blocks, make_alpha_exact, BlockEncodeStats, BlockFormat,
    BlockQuality, TextureFormat,
};
pub use gap_fill::{
    close_near_seam, copy_outlines, fill_gaps, plan_gap_fill, GapFillPlan, GapFillStats, GapSources,
};
pub use hidden_texels::{
    remove_hidden_texels, remove_hidden_texels_in_cell, HiddenTexelOptions, HiddenTexelStats,
    TexelShift,
};
pub use ktx2_container::{read_ktx2, write_ktx2, Ktx2Error, Ktx2Texture, Supercompression};
pub use layer_image::{LayerImage, FRINGE_ALPHA, FULL_ALPHA, OPAQUE_ALPHA, TRANSPARENT};
pub use macro_packing::{
    analyze_block_sharing, analyze_packing, pack_micro_textures, pack_rects, pack_stacked,
    stack_rects, BlockSharingStats, MacroPlacement, MacroTexture, Packing, PackingOptions,
    PackingStats, Stack, StackedPacking,
};
pub use micro_textures::{
    analyze_micro_textures, extract_micro_textures, quad_corners, MicroTexture,
    MicroTextureOptions, MicroTextureStats, TexelRect,
};
pub use outline_fringe::{is_fringe_alpha, mark_outline_fringe, split_outline_fringe, FRINGE_GRID};

use crate::face::Face;

/// Errors of the compression stages; each says what is wrong with which input.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CompressError {
    #[error("layer image of resolution {res} has {rgba_len} RGBA bytes, {border_len} border flags and {far_border_len} far-border flags (expected res²·4, res² and res², res ≥ 1)")]
    BadImage {
        res: u32,
        rgba_len: usize,
        border_len: usize,
        far_border_len: usize,
    },
    #[error("layer {layer} has resolution {found}, the other layers of its face {expected}")]
    ResolutionMismatch {
        layer: usize,
        expected: u32,
        found: u32,
    },
    #[error("face {face}: {reason}")]
    BadFace { face: Face, reason: String },
    #[error("{option}: {reason}")]
    BadOption {
        option: &'static str,
        reason: String,
    },
    #[error("{0}")]
    Invalid(String),
}

/// The layers of one face of a view cell with their distances, in either order: nearest first
/// (distances strictly increasing) or farthest first, as recorded (strictly decreasing).
#[derive(Clone, Debug, PartialEq)]
pub struct FaceLayers {
    pub face: Face,
    /// Distance of every layer from the reference viewpoint, strictly monotonic.
    pub distances: Vec<f64>,
    pub layers: Vec<LayerImage>,
}

/// Parameters of all stages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompressOptions {
    /// Run gap filling (sec. 5.1; default `true`). Off for layerings that do not fill gaps
    /// (Schaufler's layered impostors, `Layering::Equidistant`): the layers then go to hidden-texel
    /// removal as recorded and [`CompressStats::gap_fill`] stays zero.
    pub gap_fill: bool,
    /// Which texels gap filling copies (default: the clip-edge texels of the far border).
    pub gap_sources: GapSources,
    /// After gap filling, copy every recorded outline texel into the adjacent layer on the side
    /// its point lies ([`gap_fill::copy_outlines`]; default `false`). Needs layers recorded with
    /// [`LayerImage::behind_plane`].
    pub outline_copies: bool,
    /// After hidden-texel removal, take each layer's outline fringe texels into micro-textures
    /// of their own ([`outline_fringe::split_outline_fringe`], a grid of [`FRINGE_GRID`]),
    /// which follow all others in [`CompressedCell::micro_textures`] (default `false`): for
    /// texture formats without the fringe's alpha level.
    pub fringe_quads: bool,
    pub hidden: HiddenTexelOptions,
    pub micro: MicroTextureOptions,
    pub packing: PackingOptions,
}

impl Default for CompressOptions {
    fn default() -> Self {
        CompressOptions {
            gap_fill: true,
            gap_sources: GapSources::default(),
            outline_copies: false,
            fringe_quads: false,
            hidden: HiddenTexelOptions::default(),
            micro: MicroTextureOptions::default(),
            packing: PackingOptions::default(),
        }
    }
}

/// Statistics of a whole cell.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompressStats {
    /// RGBA8 bytes of all input layer images.
    pub layer_bytes: u64,
    pub gap_fill: GapFillStats,
    pub hidden: HiddenTexelStats,
    pub micro: MicroTextureStats,
    pub packing: PackingStats,
}

/// A compressed view cell: the quads, the atlases and where each quad's texels are.
#[derive(Clone, Debug, PartialEq)]
pub struct CompressedCell {
    /// All micro-textures, ordered by face (input order), layer, then extraction order; then
    /// the fringe micro-textures ([`CompressOptions::fringe_quads`]) in the same order.
    pub micro_textures: Vec<MicroTexture>,
    /// How many micro-textures at the end of [`CompressedCell::micro_textures`] hold outline
    /// fringe texels only (0 without [`CompressOptions::fringe_quads`]).
    pub fringe_micro_textures: usize,
    pub macro_textures: Vec<MacroTexture>,
    /// One per micro-texture.
    pub placements: Vec<MacroPlacement>,
    pub stats: CompressStats,
}

/// Stages 1–3 of one face: what [`pack_cell`] packs with the other faces of its cell.
#[derive(Clone, Debug, PartialEq)]
pub struct CompressedFace {
    /// Ordered by layer, then extraction order.
    pub micro_textures: Vec<MicroTexture>,
    /// The fringe micro-textures ([`CompressOptions::fringe_quads`]), in the same order.
    pub fringe_micro_textures: Vec<MicroTexture>,
    /// The stages' statistics (without packing).
    pub stats: CompressStats,
}

/// Runs gap filling (unless [`CompressOptions::gap_fill`] is off), hidden-texel removal,
/// micro-texture extraction and packing on one view cell. The layer images are modified in place
/// (gap filled, hidden texels erased). A micro-texture's
/// `layer` is the index of its layer in the caller's order.
pub fn compress_cell(
    faces: &mut [FaceLayers],
    options: &CompressOptions,
) -> Result<CompressedCell, CompressError> {
    let compressed: Vec<CompressedFace> = faces
        .par_iter_mut()
        .map(|f| compress_face(f, options))
        .collect::<Result<_, _>>()?;
    pack_cell(compressed, options)
}

/// Stages 1–3 (gap filling unless [`CompressOptions::gap_fill`] is off, hidden-texel removal,
/// micro-texture extraction) on one face, so that a bake can drop a face's layer images before it
/// records the next ([`pack_cell`] then packs the faces of the cell). The same as the face's part
/// of [`compress_cell`].
pub fn compress_face(
    f: &mut FaceLayers,
    options: &CompressOptions,
) -> Result<CompressedFace, CompressError> {
    options.micro.validate()?;
    if f.distances.len() != f.layers.len() {
        return Err(CompressError::BadFace {
            face: f.face,
            reason: format!(
                "{} layer images but {} distances",
                f.layers.len(),
                f.distances.len()
            ),
        });
    }
    if f.distances.iter().any(|d| !(d.is_finite() && *d > 0.0))
        || !(f.distances.windows(2).all(|w| w[0] < w[1])
            || f.distances.windows(2).all(|w| w[0] > w[1]))
    {
        return Err(CompressError::BadFace {
            face: f.face,
            reason: format!(
                "layer distances must be finite, positive and strictly monotonic, got {:?}",
                f.distances
            ),
        });
    }
    layer_image::common_res(&f.layers).map_err(|e| CompressError::BadFace {
        face: f.face,
        reason: e.to_string(),
    })?;
    let mut stats = CompressStats {
        layer_bytes: f.layers.iter().map(|l| l.rgba.len() as u64).sum(),
        ..Default::default()
    };
    // stages 1 and 2 want the nearest layer first
    let far_first = f.distances.len() > 1 && f.distances[0] > f.distances[1];
    if far_first {
        f.layers.reverse();
    }
    let gaps = if options.gap_fill {
        fill_gaps(&mut f.layers, options.gap_sources)
    } else {
        Ok(GapFillStats::default())
    };
    let gaps = gaps.and_then(|mut g| {
        if options.outline_copies {
            g.outline_copies = copy_outlines(&mut f.layers)?;
        }
        Ok(g)
    });
    let result = gaps.and_then(|g| {
        let hidden = match options.hidden.cell_half {
            Some(half) => {
                let res = f.layers.first().map_or(0, |l| l.res);
                let mut nearest_first = f.distances.clone();
                if far_first {
                    nearest_first.reverse();
                }
                let shift = TexelShift::of_face(f.face, half, res);
                remove_hidden_texels_in_cell(
                    &mut f.layers,
                    &nearest_first,
                    &shift,
                    &options.hidden,
                )?
            }
            None => remove_hidden_texels(&mut f.layers, &options.hidden)?,
        };
        Ok((g, hidden))
    });
    if far_first {
        f.layers.reverse();
    }
    let (gaps, mut hidden) = result?;
    if far_first {
        hidden.removed_per_layer.reverse();
    }
    stats.gap_fill.add(&gaps);
    stats.hidden.add(&hidden);
    // stage 3 per layer, in parallel, collected in order (the fringe texels first taken out
    // into an image of their own where asked)
    let face = f.face;
    let fringe_micro = MicroTextureOptions {
        cell_size: FRINGE_GRID,
        ..options.micro
    };
    type Extracted = (Vec<MicroTexture>, MicroTextureStats, Vec<MicroTexture>);
    let extracted: Vec<Extracted> = f
        .layers
        .par_iter_mut()
        .zip(f.distances.par_iter())
        .enumerate()
        .map(|(k, (l, &d))| {
            let fringe = match options.fringe_quads {
                true => split_outline_fringe(l)?,
                false => None,
            };
            let (m, s) = extract_micro_textures(l, face, k as u32, d, &options.micro)?;
            let fm = match fringe {
                Some(image) => extract_micro_textures(&image, face, k as u32, d, &fringe_micro)?.0,
                None => Vec::new(),
            };
            Ok((m, s, fm))
        })
        .collect::<Result<_, CompressError>>()?;
    let mut micro_textures = Vec::new();
    let mut fringe_micro_textures = Vec::new();
    for (m, s, fm) in extracted {
        stats.micro.add(&s);
        micro_textures.extend(m);
        fringe_micro_textures.extend(fm);
    }
    Ok(CompressedFace {
        micro_textures,
        fringe_micro_textures,
        stats,
    })
}

/// Stage 4 over the whole cell: packs the micro-textures of its faces (in face order) into
/// macro-textures.
pub fn pack_cell(
    faces: Vec<CompressedFace>,
    options: &CompressOptions,
) -> Result<CompressedCell, CompressError> {
    let mut stats = CompressStats::default();
    let mut micro_textures = Vec::new();
    let mut fringe = Vec::new();
    for f in faces {
        stats.layer_bytes += f.stats.layer_bytes;
        stats.gap_fill.add(&f.stats.gap_fill);
        stats.hidden.add(&f.stats.hidden);
        stats.micro.add(&f.stats.micro);
        micro_textures.extend(f.micro_textures);
        fringe.extend(f.fringe_micro_textures);
    }
    let fringe_micro_textures = fringe.len();
    micro_textures.extend(fringe);
    let (macro_textures, placements, packing) =
        pack_micro_textures(&micro_textures, &options.packing)?;
    stats.packing = packing;
    Ok(CompressedCell {
        micro_textures,
        fringe_micro_textures,
        macro_textures,
        placements,
        stats,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two layers of one face, nearest first: a red block at x 2..6 in the near layer, a blue
    /// block at x 6..10 in the far one (a surface split between them, one texel short of closing).
    fn split_surface() -> Vec<FaceLayers> {
        let res = 16;
        let block = |x0: u32, x1: u32, c: [u8; 4]| {
            let mut l = LayerImage::new(res);
            for y in 4..12 {
                for x in x0..x1 {
                    let i = l.index(x, y);
                    l.set_texel(i, c);
                }
            }
            l
        };
        // the cut between them runs along the near block's last column (x = 5)
        let mut near = block(2, 6, [255, 0, 0, 255]);
        for y in 4..12 {
            let i = near.index(5, y);
            near.border[i] = true;
            near.far_border[i] = true;
        }
        vec![FaceLayers {
            face: Face::PosZ,
            distances: vec![50.0, 100.0],
            layers: vec![near, block(6, 10, [0, 0, 255, 255])],
        }]
    }

    #[test]
    fn gap_filling_is_on_by_default_and_can_be_turned_off() {
        assert!(CompressOptions::default().gap_fill);
        let mut filled = split_surface();
        let on = compress_cell(&mut filled, &CompressOptions::default()).unwrap();
        assert!(on.stats.gap_fill.filled > 0, "{:?}", on.stats.gap_fill);
        // the near layer's border texels were copied into the far layer at x = 5
        let far = &filled[0].layers[1];
        assert_eq!(far.texel(far.index(5, 8)), [255, 0, 0, 255]);

        let mut raw = split_surface();
        let options = CompressOptions {
            gap_fill: false,
            ..Default::default()
        };
        let off = compress_cell(&mut raw, &options).unwrap();
        assert_eq!(off.stats.gap_fill, GapFillStats::default());
        let far = &raw[0].layers[1];
        assert!(!far.is_opaque(far.index(5, 8)), "no texel copied");
        assert_eq!(far.opaque_count(), 4 * 8);
        assert!(off.stats.hidden.opaque_before < on.stats.hidden.opaque_before);
    }
}
