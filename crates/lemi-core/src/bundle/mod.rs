//! The bundle: everything baked for a scene (`docs/FORMAT.md`). A directory holding
//! `manifest.json` and `cells/<id>.lemicell`, one checksummed container file per view cell.
//!
//! These types are the file format, deliberately independent of the in-memory types of the stages
//! that produce them, so the format changes only on purpose (bump [`BUNDLE_VERSION`]).

use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::cell::{CellGrid, CellId, ViewCell};
use crate::compress::{
    decode_blocks, encode_blocks, pack_stacked, read_basis_ktx2, read_ktx2, transcode_basis,
    BasisFormat, BlockFormat, CompressError, Ktx2Texture, MacroTexture, PackingOptions, TexelRect,
    TextureFormat,
};
use crate::container::{self, Blob, ContainerError};
use crate::object_cell::ObjectSetup;
use crate::Face;

mod params;
mod reader;
pub use params::{ParamsError, MAX_LAYERS, MAX_RESOLUTION, MIN_RESOLUTION};
pub use reader::{check_cell_bytes, read_cell_file, Bundle, CellCheck, VerifiedCell};

/// Version of the manifest and cell files of a layered bundle. Readers reject versions other
/// than this one and [`HLOD_BUNDLE_VERSION`].
pub const BUNDLE_VERSION: u32 = 2;
/// Version of the manifest and cell files of an HLOD bundle ([`Layering::Hlod`]): version 2 plus
/// the cell header's `hlod` section and its `hlod.bin` blob (`docs/FORMAT.md`). Layered bundles
/// stay version 2, byte for byte; a reader of version 2 only rejects an HLOD bundle by its version.
pub const HLOD_BUNDLE_VERSION: u32 = 3;
/// Version of the manifest and cell files of a layered bundle whose macro-textures are
/// block-compressed in KTX2 ([`BakeParams::texture_format`] BC7 or BC1), as written: version 4
/// with the small blobs made smaller (`near.bin` and the layers' distances in `layers.bin`
/// Zstandard-compressed, `quads.bin` as columns, Zstandard-compressed). PNG bundles stay version 2,
/// byte for byte; a reader of versions 2 and 3 rejects a block bundle by its version.
pub const BLOCK_BUNDLE_VERSION: u32 = 5;
/// The first version of block-compressed bundles, still read: version 2 plus the cell header's
/// `texture_format`, one KTX2 blob per macro-texture instead of a PNG.
pub const BLOCK_BUNDLE_VERSION_4: u32 = 4;
/// Version of the manifest and cell file of an object-impostor bundle (`lemi bake-object`,
/// [`crate::object_cell`]): the manifest and the cell header carry the `object` section (view
/// cell, object box, frame, TR placement inputs); the cell's blobs are laid out as version 5
/// whatever the texture format, and its quads' corners are computed in the object's canonical
/// frame and mapped to the world by that frame. Readers of versions 2 to 5 reject it by its
/// version.
pub const OBJECT_BUNDLE_VERSION: u32 = 6;

/// Version of the manifest and cell files of a layered bundle whose macro-textures are
/// block-compressed or Basis Universal in KTX2, as written now: version 5 with `quads.bin` holding
/// only what the packing cannot derive ([`encode_packed_quads`]: each quad's face, layer and
/// texel rectangle); where each micro-texture lies in the macro-textures is recomputed on reading
/// by [`crate::compress::pack_rects`] with the cell header's `packing` options (2.5 ms for a city
/// cell's 15 k quads), which the writer checks reproduces the bake's placement exactly. Version 5
/// cells are still read.
pub const PACKED_BUNDLE_VERSION_7: u32 = 7;

/// Version of the manifest and cell files of a layered bundle in a block format or Basis
/// Universal, as written now: version 7 whose `packing` options may stack micro-textures of a
/// face in shared blocks ([`PackingOptions::stack`], 0 for none); the reader derives the places with
/// [`crate::compress::pack_stacked`]. Version 7 cells (no stacks) are still read; a reader of
/// version 7 rejects version 8 by its version.
pub const PACKED_BUNDLE_VERSION: u32 = 8;

/// The version a bundle baked with `params` is written with.
pub fn version_for(params: &BakeParams) -> u32 {
    match params.layering {
        Layering::Hlod { .. } => HLOD_BUNDLE_VERSION,
        _ if params.texture_format.block().is_some() => PACKED_BUNDLE_VERSION,
        _ => BUNDLE_VERSION,
    }
}
/// The alpha test of the impostor quads: a macro-texel whose alpha (0..=1) is below this is not
/// drawn. Macro-texels are baked with alpha 0 or 255 and every texture format keeps each texel on
/// its side of it; the runtime's quad shader and the glTF export (`alphaCutoff`) both use it.
pub const QUAD_ALPHA_CUTOFF: f32 = 0.5;
/// The runtime's first alpha test: a macro-texel with alpha (0..=1) at or above this is drawn
/// wherever it lies; one between [`QUAD_ALPHA_CUTOFF`] and this is an outline *fringe* texel
/// (`BakeParams::outline_fringe`, [`crate::compress::outline_fringe`]), drawn only over a pixel
/// where something was drawn before it. (`crate::compress::FULL_ALPHA` / 255 passes it,
/// `FULL_ALPHA − 1` does not.) Bundles without fringe texels have alpha 0 or 1 only, for which
/// both tests agree; a renderer that knows only [`QUAD_ALPHA_CUTOFF`] (the glTF export) draws
/// fringe texels everywhere, as conservative recording made them.
pub const QUAD_FULL_ALPHA: f32 = 0.75;
/// How far (in texels of its layer) every quad is grown beyond its texel rectangle when drawn, so
/// that neighbouring quads overlap instead of meeting edge to edge: without it, pixels whose centre
/// falls exactly on a shared edge, a T-junction or a cube-face seam are covered by neither quad
/// (found by the no-crack test). The grown rim shows the quad's edge texels (the runtime clamps
/// its fetch to the rectangle), so it never shows a neighbour's texels from the macro-texture.
/// [`Quad::drawn_vertices`] applies it; the runtime and the glTF export both draw those vertices.
pub const QUAD_GROWTH_TEXELS: f64 = 1.0 / 16.0;
/// Magic bytes of a cell file.
pub const CELL_MAGIC: &[u8; 8] = b"LEMICELL";
/// `format` field of the manifest.
pub const MANIFEST_FORMAT: &str = "lemi-bundle";

/// How the number of layers is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LayerTarget {
    /// A fixed number of layers per face; the near-field distance follows.
    Layers(u32),
    /// A near-field distance (from the cell centre); the fewest layers that reach it.
    NearField(f64),
}

/// How the layers of a face are placed and recorded: the far-field strategy of a layered bundle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Layering {
    /// lemi: the optimal placement of GI 2002 / TR-186-2-02-04 (one-texel spacing, parallax
    /// ranges), conservative recording with shared clip borders, gap filling.
    #[default]
    Optimal,
    /// A conventional cube environment map: one layer per face, the near field where one layer
    /// puts it (`target` is ignored).
    Single,
    /// Schaufler's layered impostors (1998): the optimal placement's number of layers, spaced
    /// uniformly in depth between the near field and the farthest scene point, their depth ranges
    /// overlapping by `overlap` (a fraction of a slab's depth, on each side), ordinary
    /// (centre-sampled) rasterization, no gap filling.
    Equidistant { overlap: f64 },
    /// HLOD (the engines' baseline, `lemi_core::hlod`): no layers are recorded; the far field is
    /// the scene's far triangles simplified with meshoptimizer in distance bands whose nearest
    /// distances grow by `band_factor`, each within the screen-space error `error_px · alpha`.
    /// The near field is the optimal placement's, as for `lemi`.
    Hlod { error_px: f64, band_factor: f64 },
}

impl Layering {
    pub fn is_optimal(&self) -> bool {
        *self == Layering::Optimal
    }
}

/// Every parameter that changes what a cell contains. Two bakes with equal parameters and scene
/// fingerprint produce interchangeable cells (this is what resuming and merging check).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BakeParams {
    pub cell_size: f64,
    /// Cell height (Y) when the cells are flat boxes rather than cubes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell_height: Option<f64>,
    /// Texels per face side (`Res`).
    pub resolution: u32,
    pub target: LayerTarget,
    /// Baked faces in lemi's order.
    pub faces: Vec<Face>,
    /// Allowed parallax angle in radians.
    pub alpha: f64,
    /// The output view α was derived from (for evaluation), if any.
    pub output_fov_deg: Option<f64>,
    pub output_width: Option<u32>,
    /// Micro-texture grid cell size in texels (GI 2002 sec. 5.3).
    pub micro_grid: u32,
    /// Minimum opaque fraction while growing a micro-texture.
    pub micro_threshold: f64,
    /// How the layers are placed and recorded (absent in the file: [`Layering::Optimal`], so the
    /// parameters and hash of existing bundles are unchanged).
    #[serde(default, skip_serializing_if = "Layering::is_optimal")]
    pub layering: Layering,
    /// How the macro-textures are stored (absent in the file: PNG, so the parameters and hash of
    /// existing bundles are unchanged). Ignored by HLOD, which has no macro-textures.
    #[serde(default, skip_serializing_if = "TextureFormat::is_png")]
    pub texture_format: TextureFormat,
    /// Copy every recorded outline texel into the adjacent layer on the side where parallax
    /// uncovers the strip beside it (`lemi_core::compress::copy_outlines`): no background shows
    /// through outlines, at the price of copies displayed up to 2α off (bake with α of a third
    /// of a pixel to keep every pixel within one). Absent in the file: off, so the parameters
    /// and hash of existing bundles are unchanged. Only the crack-free layerings record it.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub outline_copies: bool,
    /// Mark the conservative overshoot of outlines as fringe texels, which the runtime draws only
    /// where something lies behind them (`lemi_core::compress::outline_fringe`): silhouettes
    /// against the sky land where the geometry's do instead of a texel outside. The recording
    /// then lets a triangle containing a texel's centre win that texel over an overshoot at any
    /// depth. Absent in the file: off. Only the crack-free layerings, and texture formats with a
    /// third alpha level, record it.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub outline_fringe: bool,
}

impl BakeParams {
    /// A stable hash of the parameters (hex BLAKE3 of their canonical JSON).
    pub fn hash(&self) -> String {
        let json = serde_json::to_vec(self).unwrap_or_default();
        blake3::hash(&json).to_hex().to_string()
    }
}

/// What scene a bundle was baked from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneRef {
    /// Inputs as given (`builtin:…` specs or paths).
    pub sources: Vec<String>,
    /// `"y"` or `"z"`.
    pub up: String,
    /// Hex BLAKE3 over the sources' contents (see `lemi_scene::fingerprint`).
    pub fingerprint: String,
    pub triangles: u64,
}

/// One baked cell in the manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellEntry {
    pub id: CellId,
    /// Path relative to the bundle directory.
    pub file: String,
    pub bytes: u64,
    /// Hex BLAKE3 of the whole cell file.
    pub blake3: String,
}

/// `manifest.json`. Written with a checksum of its bytes as the last member, which is not a field
/// of this type ([`Manifest::encode`], [`Manifest::read`]). Unknown members are an error, so a
/// damaged member name (`"checksun"`, `"sceme"`) is never silently ignored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    pub generator: String,
    pub scene: SceneRef,
    pub params: BakeParams,
    pub params_hash: String,
    pub grid: CellGrid,
    pub cells: Vec<CellEntry>,
    /// An object-impostor bundle's setup ([`OBJECT_BUNDLE_VERSION`]): the one cell (id `0_0_0`)
    /// serves viewpoints in `object.cell`, not in `grid` (a nominal one-cell grid).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<ObjectSetup>,
}

/// One layer of one face as baked.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayerInfo {
    pub distance: f64,
    pub near_border: f64,
    /// `f64::MAX` stands for infinity (the farthest layer; JSON has no ∞).
    pub far_border: f64,
}

/// A textured quad of the far field: a micro-texture placed in 3D. Stored in the `quads.bin` blob
/// as [`QUAD_RECORD_BYTES`]-byte records (see `docs/FORMAT.md`); the corners are not stored but
/// recomputed from face, layer distance and texel rectangle on reading, so they are exact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quad {
    pub face: Face,
    /// Layer index, far to near.
    pub layer: u16,
    /// Texel rectangle `[x0, y0, x1, y1]` (half-open) of the face image the quad covers.
    pub texels: [u16; 4],
    /// Corners in world space, in the order (s0,t0), (s1,t0), (s1,t1), (s0,t1) of the face image.
    pub corners: [[f32; 3]; 4],
    /// Index into [`CellHeader::macros`].
    pub macro_index: u32,
    /// Texel rectangle `[x, y, w, h]` in the macro-texture, as stored (after rotation).
    pub rect: [u32; 4],
    /// Stored rotated by 90° (GI 2002 sec. 5.4: tall micro-textures are turned to lie flat).
    pub rotated: bool,
    /// A fringe quad ([`CellHeader::fringe_quads`]): its texels are outline fringe, drawn only
    /// where something lies behind them. Not stored per quad: the fringe quads are the last
    /// `fringe_quads` of the cell.
    pub fringe: bool,
}

impl Quad {
    /// Macro-texture texel-edge coordinates `[x, y]` of the quad's corners, in the order of
    /// [`Quad::corners`]; divide by the macro-texture's size for texture coordinates. Undoes the
    /// 90° clockwise turn of a rotated micro-texture (see
    /// [`crate::compress::MacroPlacement::macro_corners`]): with `rect = [x, y, w, h]` as stored,
    /// an unrotated quad maps its corners to `(x, y) (x+w, y) (x+w, y+h) (x, y+h)`, a rotated one to
    /// `(x+w, y) (x+w, y+h) (x, y+h) (x, y)`.
    pub fn macro_texel_corners(&self) -> [[u32; 2]; 4] {
        let [x, y, w, h] = self.rect;
        if self.rotated {
            [[x + w, y], [x + w, y + h], [x, y + h], [x, y]]
        } else {
            [[x, y], [x + w, y], [x + w, y + h], [x, y + h]]
        }
    }

    /// The quad as drawn: its corners and macro-texel corners (in the order of [`Quad::corners`])
    /// grown by [`QUAD_GROWTH_TEXELS`] on every side, positions in world space (f32) and texture
    /// coordinates in macro-texels (not normalised). The growth is computed in f64 from the f32
    /// corners, so every renderer that draws these vertices (lemi's runtime, the glTF export)
    /// draws the same f32 numbers. The texture coordinates are the macro-texel edges
    /// `± QUAD_GROWTH_TEXELS`, exact in f32 (multiples of 1/16 below 2²⁰).
    pub fn drawn_vertices(&self) -> [([f32; 3], [f32; 2]); 4] {
        use glam::{DVec2, DVec3};
        let uv = self
            .macro_texel_corners()
            .map(|t| DVec2::new(t[0] as f64, t[1] as f64));
        let p = self.corners.map(|c| DVec3::from_array(c.map(f64::from)));
        // texel steps along the quad's edges (in world space and in the macro-texture)
        let (w, h) = (
            (self.texels[2].saturating_sub(self.texels[0])).max(1) as f64,
            (self.texels[3].saturating_sub(self.texels[1])).max(1) as f64,
        );
        let e = QUAD_GROWTH_TEXELS;
        let (du, dv) = ((p[1] - p[0]) * (e / w), (p[3] - p[0]) * (e / h));
        let (tu, tv) = ((uv[1] - uv[0]) * (e / w), (uv[3] - uv[0]) * (e / h));
        let signs = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        std::array::from_fn(|k| {
            let (su, sv) = signs[k];
            let pos = p[k] + du * su + dv * sv;
            let t = uv[k] + tu * su + tv * sv;
            (pos.as_vec3().to_array(), [t.x as f32, t.y as f32])
        })
    }

    /// The world size of one of the quad's texels: the shorter of its edges' lengths divided
    /// by their texel counts (a layer's texels are squares, so the two agree up to f32 rounding;
    /// an object frame may stretch one axis).
    pub fn texel_size(&self) -> f64 {
        use glam::DVec3;
        let p = self.corners.map(|c| DVec3::from_array(c.map(f64::from)));
        let w = self.texels[2].saturating_sub(self.texels[0]).max(1) as f64;
        let h = self.texels[3].saturating_sub(self.texels[1]).max(1) as f64;
        (p[1].distance(p[0]) / w).min(p[3].distance(p[0]) / h)
    }
}

/// A macro-texture: stored as a blob named `name`, a PNG or (version 4) a KTX2 file in the cell's
/// [`CellHeader::texture_format`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MacroInfo {
    pub name: String,
    pub width: u32,
    pub height: u32,
}

/// Numbers that describe a baked cell (GI 2002 Table 2 and more).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CellStats {
    pub far_triangles: u64,
    pub near_triangles: u64,
    pub submitted_triangles: u64,
    pub raw_bytes: u64,
    pub opaque_texels_recorded: u64,
    pub opaque_texels_after_gap_fill: u64,
    /// Texels the outline copies added ([`BakeParams::outline_copies`]; counted in
    /// `opaque_texels_after_gap_fill`, absent when none).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub outline_copies: u64,
    /// Recorded texels marked as outline fringe ([`BakeParams::outline_fringe`]; counted in
    /// `opaque_texels_recorded`, absent when none).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub outline_fringe: u64,
    /// Fringe quads among the cell's quads ([`CellHeader::fringe_quads`], formats without the
    /// fringe's alpha level; absent when none).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub fringe_quads: u64,
    pub opaque_texels_after_hidden_removal: u64,
    pub micro_textures: u64,
    pub micro_fill_ratio: f64,
    pub macro_textures: u64,
    pub macro_bytes: u64,
    pub png_bytes: u64,
    /// Bytes of the KTX2 macro-textures (block formats; absent for PNG cells).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub ktx2_bytes: u64,
    /// Bytes of the macro-textures' block data, what they occupy in texture memory when the GPU
    /// has the format (block formats; absent for PNG cells, which occupy `macro_bytes` as RGBA8).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub block_bytes: u64,
    /// Seconds per stage, by name. Not stored in the cell file (a cell's bytes depend only on the
    /// scene and the parameters, so shards and re-runs give identical bundles); reported by the
    /// bake's summary.
    #[serde(skip)]
    pub seconds: Vec<(String, f64)>,
}

fn is_zero(v: &u64) -> bool {
    *v == 0
}

impl CellStats {
    /// Bytes of the stored macro-textures (PNG or KTX2).
    pub fn texture_bytes(&self) -> u64 {
        self.png_bytes + self.ktx2_bytes
    }

    /// Bytes the macro-textures occupy in texture memory in their stored format (RGBA8 for PNG).
    pub fn texture_memory_bytes(&self) -> u64 {
        if self.block_bytes > 0 {
            self.block_bytes
        } else {
            self.macro_bytes
        }
    }
}

/// The JSON header of a cell file. Blobs: `near.bin` (the near list, `(mesh u32, tri u32)` pairs
/// little-endian), `quads.bin` and one PNG (version 2) or KTX2 file (version 4) per macro-texture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellHeader {
    pub cell: ViewCell,
    pub params_hash: String,
    pub scene_fingerprint: String,
    /// Texels per face side (`Res`).
    pub resolution: u32,
    pub near_field: f64,
    /// The baked faces, in lemi's order.
    pub faces: Vec<Face>,
    /// Per baked face (same order as `faces`), its layers far to near.
    pub layers: Vec<Vec<LayerInfo>>,
    /// The impostor quads (stored in the `quads.bin` blob, not in the JSON header).
    #[serde(skip)]
    pub quads: Vec<Quad>,
    pub macros: Vec<MacroInfo>,
    /// How the macro-textures are stored: PNG (absent in the file, version 2) or a block format
    /// in KTX2 (version 4).
    #[serde(default, skip_serializing_if = "TextureFormat::is_png")]
    pub texture_format: TextureFormat,
    pub stats: CellStats,
    /// The simplified far field of an HLOD bundle (version 3 only); its meshes are stored in the
    /// `hlod.bin` blob.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hlod: Option<HlodHeader>,
    /// An object impostor's setup (version 6 only): the frame that maps the quads' canonical
    /// corners to the world. `cell` is then the canonical cell (centred on the reference
    /// viewpoint at the canonical origin) and `near.bin` lists every scene triangle drawn as
    /// geometry in the cell: all but the object's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<ObjectSetup>,
    /// The options the macro-textures were packed with (version 7): the reader derives each
    /// quad's place in the macro-textures from them and the quads' sizes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub packing: Option<PackingOptions>,
    /// How many quads at the end of [`CellHeader::quads`] are *fringe quads*: the outline fringe
    /// of a texture format without its alpha level (`BakeParams::outline_fringe` with BC1 or
    /// ETC1S, [`crate::compress::split_outline_fringe`]), drawn only where something lies behind
    /// them. Absent (0) in the file otherwise; a reader that ignores it draws them as ordinary
    /// quads (the glTF export marks them `extras.lemi_fringe`).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub fringe_quads: u64,
}

impl CellHeader {
    /// The world point the quads' layers are placed around: the cell's reference viewpoint, or
    /// for an object cell its world position. Seen from there, a layer's texels are all one
    /// size (the glTF export places the quads relative to it; the runtime bounds their texel
    /// scale from it, `crate::texel_scale`).
    pub fn quad_origin(&self) -> DVec3 {
        match &self.object {
            Some(o) => o.frame.to_world(self.cell.center),
            None => self.cell.center,
        }
    }

    /// The farthest a viewpoint of the cell lies from [`CellHeader::quad_origin`]: the distance
    /// of the cell box's farthest corner (for an object cell, mapped to the world by its frame,
    /// an affine map, so a corner is still the farthest point).
    pub fn quad_reach(&self) -> f64 {
        let origin = self.quad_origin();
        (self.cell.corners().iter())
            .map(|&corner| {
                let world = match &self.object {
                    Some(o) => o.frame.to_world(corner),
                    None => corner,
                };
                world.distance(origin)
            })
            .fold(0.0, f64::max)
    }

    /// The world corners of the quad covering texels `rect` of the layer of `face` at `distance`
    /// (in [`Quad::corners`] order): the face's layer square around the cell's reference
    /// viewpoint, or for an object cell the canonical square mapped by its frame. Every reader and
    /// the bake compute them here, so the stored and the recomputed corners are the same numbers.
    pub fn quad_corners(
        &self,
        face: Face,
        distance: f64,
        rect: crate::compress::TexelRect,
    ) -> [[f32; 3]; 4] {
        let center = self.cell.center;
        crate::compress::quad_corners(face, distance, self.resolution, rect).map(|c| {
            match &self.object {
                Some(o) => o.frame.to_world(c),
                None => center + c,
            }
            .as_vec3()
            .to_array()
        })
    }
}

/// The simplified far field of a cell (`lemi_core::hlod::HlodFarField` as stored).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HlodHeader {
    /// The bound as a multiple of α.
    pub error_px: f64,
    pub band_factor: f64,
    /// Far triangles before simplification.
    pub source_triangles: u64,
    pub bands: Vec<HlodBandInfo>,
}

/// One distance band as stored: its meshes follow each other in `hlod.bin`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HlodBandInfo {
    pub near: f64,
    /// `f64::MAX` for an unbounded band.
    pub far: f64,
    /// The absolute error (metres) the band was simplified with.
    pub error_bound: f64,
    /// The largest error meshoptimizer reported, metres.
    pub result_error: f64,
    pub source_triangles: u64,
    pub meshes: Vec<HlodMeshInfo>,
    /// The meshes (stored in `hlod.bin`, not in the JSON header).
    #[serde(skip)]
    pub data: Vec<crate::Mesh>,
}

/// Sizes of one stored mesh.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HlodMeshInfo {
    pub material: u32,
    pub vertices: u32,
    pub triangles: u32,
}

impl HlodHeader {
    /// The stored form of a simplified far field.
    pub fn of(far: &crate::hlod::HlodFarField, options: &crate::hlod::HlodOptions) -> HlodHeader {
        HlodHeader {
            error_px: options.error_px,
            band_factor: options.band_factor,
            source_triangles: far.source_triangles(),
            bands: far
                .bands
                .iter()
                .map(|b| HlodBandInfo {
                    near: b.near,
                    far: b.far,
                    error_bound: b.error_bound,
                    result_error: b.result_error,
                    source_triangles: b.source_triangles,
                    meshes: b
                        .meshes
                        .iter()
                        .map(|m| HlodMeshInfo {
                            material: m.material,
                            vertices: m.vertices.len() as u32,
                            triangles: m.triangle_count() as u32,
                        })
                        .collect(),
                    data: b.meshes.clone(),
                })
                .collect(),
        }
    }

    /// Every mesh, bands near to far.
    pub fn meshes(&self) -> impl Iterator<Item = &crate::Mesh> {
        self.bands.iter().flat_map(|b| b.data.iter())
    }

    /// Triangles after simplification.
    pub fn triangles(&self) -> u64 {
        self.meshes().map(|m| m.triangle_count() as u64).sum()
    }

    /// Bytes of the meshes as drawn (vertices and 32-bit indices).
    pub fn mesh_bytes(&self) -> u64 {
        self.meshes()
            .map(|m| {
                (m.vertices.len() * std::mem::size_of::<crate::Vertex>() + m.indices.len() * 4)
                    as u64
            })
            .sum()
    }
}

/// An error reading or writing a bundle: the file (or bundle directory) and what is wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct BundleError {
    pub path: PathBuf,
    pub kind: BundleErrorKind,
}

impl BundleError {
    pub fn new(path: impl Into<PathBuf>, kind: BundleErrorKind) -> BundleError {
        BundleError {
            path: path.into(),
            kind,
        }
    }

    fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> BundleError {
        BundleError::new(path, BundleErrorKind::Invalid(message.into()))
    }
}

/// What is wrong with a bundle file. The messages say what to do where something can be done.
#[derive(Debug, thiserror::Error)]
pub enum BundleErrorKind {
    #[error("cannot read or write it: {0}")]
    Io(#[source] std::io::Error),
    /// Truncated, a checksum that does not match, another version, a malformed header or blob.
    #[error("{0}")]
    Container(#[source] ContainerError),
    /// A manifest that is not one, or one that contradicts itself.
    #[error("{0}")]
    Invalid(String),
    /// The cell is not listed in the manifest (`path` is the bundle directory).
    #[error(
        "cell {id} is not in the bundle's manifest (it was not baked); baked cells: {}",
        list_ids(baked)
    )]
    NotBaked { id: CellId, baked: Vec<CellId> },
    /// A point outside every cell of the bundle's grid (`path` is the bundle directory).
    #[error("({:.2}, {:.2}, {:.2}) is outside the baked region (grid origin {origin:?}, {cell_size} m cells, {counts:?})", point[0], point[1], point[2])]
    OutsideGrid {
        point: [f64; 3],
        origin: [f64; 3],
        cell_size: f64,
        counts: [i32; 3],
    },
    /// A point outside an object impostor's view cell (`path` is the bundle directory): the
    /// object is drawn as geometry there, never as its impostor.
    #[error("({:.2}, {:.2}, {:.2}) is outside the object impostor's view cell {cell}", point[0], point[1], point[2])]
    OutsideObjectCell { point: [f64; 3], cell: String },
    #[error("is {actual} bytes, the bundle records {expected} (changed or damaged after baking); bake it again")]
    Size { actual: u64, expected: u64 },
    #[error("does not match the BLAKE3 hash the bundle records for it (changed or damaged after baking); bake it again")]
    Hash,
    #[error("baked with other parameters than the bundle (parameters hash {}…, the manifest says {}…); bake it again", short(found), short(expected))]
    Params { found: String, expected: String },
    #[error("baked from another scene than the bundle (fingerprint {}…, the manifest says {}…); bake it again", short(found), short(expected))]
    Scene { found: String, expected: String },
    /// The cell file holds another cell than the one asked for (or, resuming, the same index at
    /// another place or size).
    #[error("holds cell {found}{}, not {expected}", if *moved { " at another position or size" } else { "" })]
    WrongCell {
        found: CellId,
        expected: CellId,
        moved: bool,
    },
    /// The scene given to draw the bundle with is not the one it was baked from (`path` is the
    /// manifest).
    #[error("was baked from another scene (fingerprint {}…) than the one given (fingerprint {}…); give the scene it was baked from", short(baked), short(given))]
    OtherScene { baked: String, given: String },
}

impl BundleErrorKind {
    /// Whether the file is unusable as it is on disk (damaged, stale or foreign) rather than
    /// missing from the manifest or the grid.
    pub fn is_damage(&self) -> bool {
        !matches!(
            self,
            BundleErrorKind::NotBaked { .. }
                | BundleErrorKind::OutsideGrid { .. }
                | BundleErrorKind::OutsideObjectCell { .. }
        )
    }
}

fn short(hash: &str) -> &str {
    hash.get(..12).unwrap_or(hash)
}

fn list_ids(ids: &[CellId]) -> String {
    if ids.is_empty() {
        return "none".into();
    }
    ids.iter()
        .map(|i| i.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Path of the manifest in a bundle directory.
pub fn manifest_path(bundle: &Path) -> PathBuf {
    bundle.join("manifest.json")
}

/// Relative path of a cell file.
pub fn cell_file_name(id: CellId) -> String {
    format!("cells/{id}.lemicell")
}

impl Manifest {
    /// The view cell whose impostors serve the viewpoint `p` (baked or not): the grid cell holding
    /// it (half-open on the upper side), or for an object bundle its one cell if `p` lies in the
    /// object's view cell, and nothing elsewhere (there the object is drawn as geometry).
    pub fn locate(&self, p: DVec3) -> Option<ViewCell> {
        match &self.object {
            Some(o) => self
                .grid
                .cell(glam::IVec3::ZERO)
                .filter(|_| o.cell.contains(p)),
            None => self.grid.locate(p),
        }
    }

    /// Reads `manifest.json` and checks its format and version (what [`Bundle::open`] builds
    /// on; use that to read cells).
    ///
    /// A manifest with a checksum (every manifest lemi writes now) is used only if the checksum
    /// is the hash of its bytes; one without (written before the checksum was added) is read
    /// as it is.
    pub fn read(bundle: &Path) -> Result<Manifest, BundleError> {
        let path = manifest_path(bundle);
        let bytes =
            std::fs::read(&path).map_err(|e| BundleError::new(&path, BundleErrorKind::Io(e)))?;
        Manifest::decode(&path, &bytes)
    }

    /// [`Manifest::read`] of `bytes`, the contents of the manifest at `path` (named in errors).
    pub fn decode(path: &Path, bytes: &[u8]) -> Result<Manifest, BundleError> {
        let json = verify_manifest_checksum(bytes).map_err(|e| BundleError::invalid(path, e))?;
        let m: Manifest = serde_json::from_slice(&json)
            .map_err(|e| BundleError::invalid(path, format!("not a valid lemi manifest: {e}")))?;
        if m.format != MANIFEST_FORMAT {
            return Err(BundleError::invalid(
                path,
                format!("format is `{}`, expected `{MANIFEST_FORMAT}`", m.format),
            ));
        }
        if let Some(object) = &m.object {
            if m.version != OBJECT_BUNDLE_VERSION {
                return Err(BundleError::invalid(
                    path,
                    format!(
                        "an `object` section in a version {} manifest (object bundles are version {OBJECT_BUNDLE_VERSION})",
                        m.version
                    ),
                ));
            }
            if let Err(e) = object.frame.validate() {
                return Err(BundleError::invalid(path, format!("object: {e}")));
            }
            return Ok(m);
        }
        let block_4 = matches!(
            m.version,
            BLOCK_BUNDLE_VERSION_4 | BLOCK_BUNDLE_VERSION | PACKED_BUNDLE_VERSION_7
        ) && version_for(&m.params) == PACKED_BUNDLE_VERSION;
        if m.version != version_for(&m.params) && !block_4 {
            return Err(BundleError::invalid(
                path,
                format!(
                    "bundle version {} is not supported here (this lemi reads version {BUNDLE_VERSION}, {HLOD_BUNDLE_VERSION} for HLOD bundles, {BLOCK_BUNDLE_VERSION_4}, {BLOCK_BUNDLE_VERSION}, {PACKED_BUNDLE_VERSION_7} or {PACKED_BUNDLE_VERSION} for block-compressed textures and {OBJECT_BUNDLE_VERSION} for object impostors, each with the parameters that call for it)",
                    m.version
                ),
            ));
        }
        Ok(m)
    }

    /// Writes `manifest.json` atomically ([`Manifest::encode`]).
    pub fn write(&self, bundle: &Path) -> Result<(), BundleError> {
        let path = manifest_path(bundle);
        let json = self
            .encode()
            .map_err(|e| BundleError::invalid(&path, e.to_string()))?;
        container::write_atomic(&path, &json)
            .map_err(|e| BundleError::new(path, BundleErrorKind::Io(e)))
    }

    /// The bytes of `manifest.json`: the manifest as pretty JSON whose last member is its
    /// checksum, `"checksum": "blake3:` and the 64 lowercase hex digits of the BLAKE3 hash of every
    /// byte of the file before `"checksum"`, then `"`, a newline and the closing `}`
    /// (`docs/FORMAT.md`). Any byte changed (whitespace too) or cut off is detected.
    pub fn encode(&self) -> Result<Vec<u8>, serde_json::Error> {
        let mut out = serde_json::to_vec_pretty(self)?;
        // Pretty JSON of an object with members ends with its last member, a newline and `}`.
        out.truncate(out.len().saturating_sub(MEMBERS_END.len()));
        out.extend_from_slice(b",\n  ");
        let hash = blake3::hash(&out);
        out.extend_from_slice(CHECKSUM_OPEN);
        out.extend_from_slice(hash.to_hex().as_bytes());
        out.extend_from_slice(CHECKSUM_CLOSE);
        Ok(out)
    }
}

/// How the manifest's checksum member starts, after the separator `,\n  ` that ends the hashed
/// bytes; 64 lowercase hex digits and [`CHECKSUM_CLOSE`] follow and end the file.
const CHECKSUM_OPEN: &[u8] = b"\"checksum\": \"blake3:";
const CHECKSUM_CLOSE: &[u8] = b"\"\n}";
/// How pretty JSON of an object ends after its last member.
const MEMBERS_END: &[u8] = b"\n}";
const CHECKSUM_TAIL: usize = CHECKSUM_OPEN.len() + 64 + CHECKSUM_CLOSE.len();

/// Checks the checksum of the bytes of a manifest and returns its JSON without the checksum
/// member. A manifest without one (written before it was added) is returned as it is, unless
/// it names a `checksum` anywhere: then the checksum is damaged or was moved, and the manifest
/// is refused.
fn verify_manifest_checksum(bytes: &[u8]) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    if let Some(hashed_len) = bytes.len().checked_sub(CHECKSUM_TAIL) {
        let (hashed, tail) = bytes.split_at(hashed_len);
        let hex = &tail[CHECKSUM_OPEN.len()..CHECKSUM_OPEN.len() + 64];
        if tail.starts_with(CHECKSUM_OPEN)
            && tail.ends_with(CHECKSUM_CLOSE)
            && hex.iter().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
        {
            if blake3::hash(hashed).to_hex().as_bytes() != hex {
                return Err(MANIFEST_CHECKSUM_MISMATCH.into());
            }
            // The hash matched, so these are the bytes lemi wrote: the members, then `,\n  `.
            let members = hashed
                .strip_suffix(b",\n  ")
                .ok_or_else(|| format!("{MANIFEST_CHECKSUM_MISPLACED} (no member before it)"))?;
            let mut json = members.to_vec();
            json.extend_from_slice(MEMBERS_END);
            return Ok(std::borrow::Cow::Owned(json));
        }
    }
    if bytes.windows(10).any(|w| w == b"\"checksum\"") {
        return Err(MANIFEST_CHECKSUM_MISPLACED.into());
    }
    Ok(std::borrow::Cow::Borrowed(bytes))
}

const MANIFEST_CHECKSUM_MISMATCH: &str =
    "corrupt: checksum mismatch (the manifest was modified or \
     damaged after baking); run the same `lemi bake` again (or `lemi bake --merge` for a sharded \
     bake) to write it anew: intact cells are kept";
const MANIFEST_CHECKSUM_MISPLACED: &str = "corrupt: its `checksum` is damaged or not where lemi \
     writes it (the last member, `\"checksum\": \"blake3:` and 64 lowercase hex digits); run the \
     same `lemi bake` again (or `lemi bake --merge` for a sharded bake) to write it anew: intact \
     cells are kept";

/// A decoded cell file.
#[derive(Clone, Debug, PartialEq)]
pub struct CellFile {
    pub header: CellHeader,
    /// `(mesh, triangle)` pairs drawn as geometry.
    pub near: Vec<[u32; 2]>,
    /// The stored macro-textures (PNG or KTX2 files, as `header.texture_format` says), in
    /// `header.macros` order.
    pub macro_blobs: Vec<Vec<u8>>,
}

impl CellFile {
    pub fn encode(&self) -> Result<Vec<u8>, ContainerError> {
        let quads = &self.header.quads;
        let fringe = quads.iter().filter(|q| q.fringe).count();
        if fringe as u64 != self.header.fringe_quads
            || quads[quads.len() - fringe..].iter().any(|q| !q.fringe)
        {
            return Err(ContainerError::Header(format!(
                "the header says {} fringe quads, the quads hold {fringe}, and they must be the \
                 last ones",
                self.header.fringe_quads
            )));
        }
        if self.header.object.is_some() {
            return self.encode_v5(OBJECT_BUNDLE_VERSION);
        }
        if self.header.hlod.is_none() && self.header.texture_format.block().is_some() {
            return match self.header.packing {
                Some(_) => self.encode_v5(PACKED_BUNDLE_VERSION),
                None => self.encode_v5(BLOCK_BUNDLE_VERSION),
            };
        }
        let mut blobs = Vec::with_capacity(2 + self.macro_blobs.len());
        blobs.push(Blob {
            name: "near.bin".into(),
            data: bytemuck::cast_slice(&self.near).to_vec(),
        });
        blobs.push(Blob {
            name: "quads.bin".into(),
            data: encode_quads(&self.header.quads)?,
        });
        for (m, blob) in self.header.macros.iter().zip(&self.macro_blobs) {
            blobs.push(Blob {
                name: m.name.clone(),
                data: blob.clone(),
            });
        }
        let version = match &self.header.hlod {
            Some(h) => {
                blobs.push(Blob {
                    name: "hlod.bin".into(),
                    data: encode_hlod(h)?,
                });
                HLOD_BUNDLE_VERSION
            }
            None => BUNDLE_VERSION,
        };
        container::encode(CELL_MAGIC, version, &self.header, &blobs)
    }

    /// A block-compressed cell as version 5: `near.bin`, `quads.bin` ([`encode_quad_columns`]),
    /// `layers.bin` (the header's `layers`, which the JSON header then leaves empty), then the
    /// macro-textures. Object cells use the same layout as `version` 6, and version 7 the same
    /// with `quads.bin` as [`encode_packed_quads`].
    fn encode_v5(&self, version: u32) -> Result<Vec<u8>, ContainerError> {
        let mut blobs = Vec::with_capacity(3 + self.macro_blobs.len());
        blobs.push(Blob {
            name: "near.bin".into(),
            data: zstd_blob("near.bin", bytemuck::cast_slice(&self.near))?,
        });
        blobs.push(Blob {
            name: "quads.bin".into(),
            data: match (version, &self.header.packing) {
                (PACKED_BUNDLE_VERSION_7 | PACKED_BUNDLE_VERSION, Some(packing)) => {
                    encode_packed_quads(&self.header.quads, packing)?
                }
                _ => encode_quad_columns(&self.header.quads)?,
            },
        });
        blobs.push(Blob {
            name: "layers.bin".into(),
            data: encode_layers(&self.header)?,
        });
        for (m, blob) in self.header.macros.iter().zip(&self.macro_blobs) {
            blobs.push(Blob {
                name: m.name.clone(),
                data: blob.clone(),
            });
        }
        let header = CellHeader {
            layers: Vec::new(),
            quads: Vec::new(),
            ..self.header.clone()
        };
        container::encode(CELL_MAGIC, version, &header, &blobs)
    }

    pub fn decode(bytes: &[u8]) -> Result<CellFile, ContainerError> {
        let (version, mut header, blobs): (u32, CellHeader, Vec<Blob>) =
            container::decode_versions(
                CELL_MAGIC,
                "cell",
                BUNDLE_VERSION..=PACKED_BUNDLE_VERSION,
                bytes,
            )?;
        let v5 = version >= BLOCK_BUNDLE_VERSION;
        match (version, &header.object) {
            (OBJECT_BUNDLE_VERSION, Some(o)) => {
                o.frame.validate().map_err(ContainerError::Header)?;
            }
            (OBJECT_BUNDLE_VERSION, None) => {
                return Err(ContainerError::Header(
                    "a version 6 cell without its `object` section".into(),
                ))
            }
            (_, Some(_)) => {
                return Err(ContainerError::Header(format!(
                    "an `object` section in a version {version} cell (object cells are version {OBJECT_BUNDLE_VERSION})"
                )))
            }
            _ => {}
        }
        let mut it = blobs.into_iter();
        let near_blob = it
            .next()
            .filter(|b| b.name == "near.bin")
            .ok_or_else(|| ContainerError::Header("missing near.bin".into()))?;
        let near_raw = if v5 {
            unzstd_blob("near.bin", &near_blob.data, 1 << 32)?
        } else {
            near_blob.data
        };
        if near_raw.len() % 8 != 0 {
            return Err(ContainerError::Header(format!(
                "near.bin: {} bytes is not a whole number of 8-byte pairs",
                near_raw.len()
            )));
        }
        let near: Vec<[u32; 2]> = near_raw
            .chunks_exact(8)
            .map(|c| {
                [
                    u32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                    u32::from_le_bytes([c[4], c[5], c[6], c[7]]),
                ]
            })
            .collect();
        let quads_blob = it
            .next()
            .filter(|b| b.name == "quads.bin")
            .ok_or_else(|| ContainerError::Header("missing quads.bin".into()))?;
        if v5 {
            let layers_blob = it
                .next()
                .filter(|b| b.name == "layers.bin")
                .ok_or_else(|| ContainerError::Header("missing layers.bin".into()))?;
            if !header.layers.is_empty() {
                return Err(ContainerError::Header(
                    "a version 5 cell with `layers` in its header (they are in layers.bin)".into(),
                ));
            }
            header.layers = decode_layers(&layers_blob.data, &header)?;
            let columns = unzstd_blob("quads.bin", &quads_blob.data, 1 << 32)?;
            let records = if matches!(version, PACKED_BUNDLE_VERSION_7 | PACKED_BUNDLE_VERSION) {
                if version == PACKED_BUNDLE_VERSION_7 && header.packing.is_some_and(|p| p.stack > 0)
                {
                    return Err(ContainerError::Header(
                        "a version 7 cell whose `packing` stacks micro-textures (stacks are version 8)"
                            .into(),
                    ));
                }
                decode_packed_quads(&columns, &header)?
            } else {
                decode_quad_columns(&columns)?
            };
            header.quads = decode_quad_records(&records, &header)?;
        } else {
            header.quads = decode_quads(&quads_blob.data, &header)?;
        }
        let mut macro_blobs: Vec<Vec<u8>> = it.map(|b| b.data).collect();
        match (version, &mut header.hlod) {
            (HLOD_BUNDLE_VERSION, Some(h)) => {
                if macro_blobs.len() != header.macros.len() + 1 {
                    return Err(ContainerError::Header("missing hlod.bin".into()));
                }
                let data = macro_blobs.pop().unwrap_or_default();
                decode_hlod(&data, h)?;
            }
            (HLOD_BUNDLE_VERSION, None) => {
                return Err(ContainerError::Header(
                    "a version 3 cell without its `hlod` section".into(),
                ))
            }
            (_, Some(_)) => {
                return Err(ContainerError::Header(format!(
                    "an `hlod` section in a version {version} cell (HLOD cells are version {HLOD_BUNDLE_VERSION})"
                )))
            }
            _ => {}
        }
        match (version, header.texture_format.block()) {
            (OBJECT_BUNDLE_VERSION, _) => {}
            (
                BLOCK_BUNDLE_VERSION_4
                | BLOCK_BUNDLE_VERSION
                | PACKED_BUNDLE_VERSION_7
                | PACKED_BUNDLE_VERSION,
                Some(_),
            ) => {}
            (
                BLOCK_BUNDLE_VERSION_4
                | BLOCK_BUNDLE_VERSION
                | PACKED_BUNDLE_VERSION_7
                | PACKED_BUNDLE_VERSION,
                None,
            ) => {
                return Err(ContainerError::Header(format!(
                    "a version {version} cell without a block `texture_format`"
                )))
            }
            (_, Some(_)) => {
                return Err(ContainerError::Header(format!(
                    "`texture_format` {} in a version {version} cell (block-compressed cells are version {BLOCK_BUNDLE_VERSION_4}, {BLOCK_BUNDLE_VERSION}, {PACKED_BUNDLE_VERSION_7} or {PACKED_BUNDLE_VERSION})",
                    header.texture_format
                )))
            }
            (_, None) => {}
        }
        if macro_blobs.len() != header.macros.len() {
            return Err(ContainerError::Header(format!(
                "{} macro-textures listed but {} stored",
                header.macros.len(),
                macro_blobs.len()
            )));
        }
        if header.fringe_quads as usize > header.quads.len() {
            return Err(ContainerError::Header(format!(
                "{} fringe quads in a cell of {} quads",
                header.fringe_quads,
                header.quads.len()
            )));
        }
        let first_fringe = header.quads.len() - header.fringe_quads as usize;
        for q in &mut header.quads[first_fringe..] {
            q.fringe = true;
        }
        for (i, q) in header.quads.iter().enumerate() {
            let fits = header.macros.get(q.macro_index as usize).is_some_and(|m| {
                let [x, y, w, h] = q.rect.map(u64::from);
                x + w <= m.width as u64 && y + h <= m.height as u64
            });
            if !fits {
                return Err(ContainerError::Header(format!(
                    "quad {i} references a missing macro-texture or lies outside it"
                )));
            }
        }
        if let Some(basis) = header.texture_format.basis() {
            for (m, blob) in header.macros.iter().zip(&macro_blobs) {
                check_basis_ktx2(m, basis, blob)?;
            }
        } else if let Some(format) = header.texture_format.block() {
            for (m, blob) in header.macros.iter().zip(&macro_blobs) {
                check_ktx2(m, format, blob)?;
            }
        }
        Ok(CellFile {
            header,
            near,
            macro_blobs,
        })
    }

    /// The block-compressed macro-textures as stored (level 0), ready to upload to a GPU that has
    /// the format; `None` for a PNG cell.
    pub fn block_macros(&self) -> Result<Option<Vec<BlockMacro>>, ContainerError> {
        if let Some(basis) = self.header.texture_format.basis() {
            return self
                .header
                .macros
                .iter()
                .zip(&self.macro_blobs)
                .map(|(m, blob)| {
                    check_basis_ktx2(m, basis, blob)?;
                    let t = transcode_basis(blob)
                        .map_err(|e| ContainerError::Header(format!("{}: {e}", m.name)))?;
                    Ok(BlockMacro {
                        format: t.format,
                        width: t.width,
                        height: t.height,
                        data: t.blocks,
                    })
                })
                .collect::<Result<Vec<_>, _>>()
                .map(Some);
        }
        let Some(format) = self.header.texture_format.block() else {
            return Ok(None);
        };
        self.header
            .macros
            .iter()
            .zip(&self.macro_blobs)
            .map(|(m, blob)| {
                let mut t = check_ktx2(m, format, blob)?;
                Ok(BlockMacro {
                    format,
                    width: t.width,
                    height: t.height,
                    data: t.levels.swap_remove(0),
                })
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }

    /// Decodes the macro-textures to RGBA8 (PNG, or KTX2 block data decoded on the CPU), checking
    /// that each has the size its header says.
    pub fn decode_macros(&self) -> Result<Vec<MacroTexture>, ContainerError> {
        if let Some(blocks) = self.block_macros()? {
            return blocks
                .iter()
                .map(|b| {
                    let rgba = decode_blocks(b.format, b.width, b.height, &b.data)
                        .map_err(|e| ContainerError::Header(e.to_string()))?;
                    Ok(MacroTexture {
                        width: b.width,
                        height: b.height,
                        rgba,
                    })
                })
                .collect();
        }
        self.header
            .macros
            .iter()
            .zip(&self.macro_blobs)
            .map(|(m, png)| {
                let img = image::load_from_memory_with_format(png, image::ImageFormat::Png)
                    .map_err(|e| {
                        ContainerError::Header(format!("{}: not a valid PNG: {e}", m.name))
                    })?
                    .to_rgba8();
                if img.width() != m.width || img.height() != m.height {
                    return Err(ContainerError::Header(format!(
                        "{}: PNG is {}x{}, the header says {}x{}",
                        m.name,
                        img.width(),
                        img.height(),
                        m.width,
                        m.height
                    )));
                }
                Ok(MacroTexture {
                    width: m.width,
                    height: m.height,
                    rgba: img.into_raw(),
                })
            })
            .collect()
    }
}

/// A block-compressed macro-texture as stored: level 0's blocks, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BlockMacro {
    pub format: BlockFormat,
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl BlockMacro {
    /// `m` encoded to `format` ([`crate::compress::encode_blocks`]).
    pub fn encode(format: BlockFormat, m: &MacroTexture) -> Result<BlockMacro, CompressError> {
        Ok(BlockMacro {
            format,
            width: m.width,
            height: m.height,
            data: encode_blocks(format, m.width, m.height, &m.rgba)?.0,
        })
    }
}

/// Reads the header of a macro-texture's Basis Universal KTX2 blob and checks it against its
/// header entry and the cell's format (the data itself is checked by transcoding it).
fn check_basis_ktx2(m: &MacroInfo, format: BasisFormat, blob: &[u8]) -> Result<(), ContainerError> {
    let t =
        read_basis_ktx2(blob).map_err(|e| ContainerError::Header(format!("{}: {e}", m.name)))?;
    let kind = "a Basis Universal";
    check_macro_entry(
        m,
        t.format == format,
        &t.format,
        (t.width, t.height),
        format.texture_format(),
        kind,
    )
}

/// Reads a macro-texture's KTX2 blob and checks it against its header entry and the cell's format.
fn check_ktx2(
    m: &MacroInfo,
    format: BlockFormat,
    blob: &[u8],
) -> Result<Ktx2Texture, ContainerError> {
    let t = read_ktx2(blob).map_err(|e| ContainerError::Header(format!("{}: {e}", m.name)))?;
    let kind = "a block-compressed";
    check_macro_entry(
        m,
        t.format == format,
        &t.format,
        (t.width, t.height),
        format.texture_format(),
        kind,
    )?;
    Ok(t)
}

/// A KTX2 macro-texture of `stored` format (`same`: the cell's) and `size` against its header
/// entry `m` and the cell's `expected` format; block sides must be multiples of 4.
fn check_macro_entry(
    m: &MacroInfo,
    same: bool,
    stored: &dyn std::fmt::Debug,
    (width, height): (u32, u32),
    expected: TextureFormat,
    kind: &str,
) -> Result<(), ContainerError> {
    if !same || width != m.width || height != m.height {
        return Err(ContainerError::Header(format!(
            "{}: KTX2 of {stored:?} {width}x{height}, the header says {expected} {}x{}",
            m.name, m.width, m.height
        )));
    }
    if m.width % 4 != 0 || m.height % 4 != 0 {
        return Err(ContainerError::Header(format!(
            "{}: {kind} macro-texture of {}x{} texels (sides must be multiples of 4)",
            m.name, m.width, m.height
        )));
    }
    Ok(())
}

/// Bytes of one quad record in `quads.bin` (before deflate).
pub const QUAD_RECORD_BYTES: usize = 20;

/// `quads.bin`: the quads as little-endian records `face u8, rotated u8, layer u16,
/// macro_index u32, texel x0 y0 x1 y1 u16 ×4, macro x y u16 ×2`, deflated (zlib). The macro
/// footprint is the texel rectangle's size, swapped when rotated.
fn encode_quads(quads: &[Quad]) -> Result<Vec<u8>, ContainerError> {
    use std::io::Write;
    let raw = encode_quad_records(quads)?;
    let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    enc.write_all(&raw)
        .and_then(|_| enc.finish())
        .map_err(|e| ContainerError::Header(format!("compressing quads.bin: {e}")))
}

/// The quads as [`QUAD_RECORD_BYTES`]-byte records (see [`encode_quads`]).
fn encode_quad_records(quads: &[Quad]) -> Result<Vec<u8>, ContainerError> {
    let mut raw = Vec::with_capacity(quads.len() * QUAD_RECORD_BYTES);
    for q in quads {
        let to16 = |v: u32| {
            u16::try_from(v).map_err(|_| {
                ContainerError::Header(format!("macro-texture position {v} exceeds 65535"))
            })
        };
        raw.push(q.face.index() as u8);
        raw.push(q.rotated as u8);
        raw.extend_from_slice(&q.layer.to_le_bytes());
        raw.extend_from_slice(&q.macro_index.to_le_bytes());
        for t in q.texels {
            raw.extend_from_slice(&t.to_le_bytes());
        }
        raw.extend_from_slice(&to16(q.rect[0])?.to_le_bytes());
        raw.extend_from_slice(&to16(q.rect[1])?.to_le_bytes());
    }
    Ok(raw)
}

/// Inverse of [`encode_quads`]; recomputes the corners from the header's layers.
fn decode_quads(data: &[u8], header: &CellHeader) -> Result<Vec<Quad>, ContainerError> {
    use std::io::Read;
    let bad = |m: String| ContainerError::Header(format!("quads.bin: {m}"));
    let mut raw = Vec::new();
    flate2::read::ZlibDecoder::new(data)
        .take(1 << 32)
        .read_to_end(&mut raw)
        .map_err(|e| bad(format!("not valid zlib data: {e}")))?;
    decode_quad_records(&raw, header)
}

/// The Zstandard level of the small blobs of version 5 (as the KTX2 levels').
const BLOB_ZSTD_LEVEL: i32 = crate::compress::ktx2_container::ZSTD_LEVEL;

/// `data` Zstandard-compressed (one frame with its content checksum).
fn zstd_blob(name: &str, data: &[u8]) -> Result<Vec<u8>, ContainerError> {
    let mut z = zstd::bulk::Compressor::new(BLOB_ZSTD_LEVEL)
        .map_err(|e| ContainerError::Header(format!("compressing {name}: {e}")))?;
    z.include_checksum(true)
        .and_then(|_| z.compress(data))
        .map_err(|e| ContainerError::Header(format!("compressing {name}: {e}")))
}

/// Inverse of [`zstd_blob`], refusing more than `limit` bytes.
fn unzstd_blob(name: &str, data: &[u8], limit: u64) -> Result<Vec<u8>, ContainerError> {
    use std::io::Read;
    let mut raw = Vec::new();
    zstd::stream::read::Decoder::with_buffer(data)
        .and_then(|d| d.take(limit + 1).read_to_end(&mut raw))
        .map_err(|e| ContainerError::Header(format!("{name}: not valid Zstandard data: {e}")))?;
    if raw.len() as u64 > limit {
        return Err(ContainerError::Header(format!(
            "{name}: inflates to more than {limit} bytes"
        )));
    }
    Ok(raw)
}

/// `quads.bin` of version 5: the same fields as [`encode_quads`]' records, stored as columns
/// (every quad's face, then every rotation flag, layer, macro index, x0, y0, x1, y1, macro x,
/// macro y; little-endian, in quad order), Zstandard-compressed. Columns of like values compress
/// about twice as well as interleaved records (a city cell's 14.8 k quads: 121 KB in zlib records,
/// 66 KB in columns).
fn encode_quad_columns(quads: &[Quad]) -> Result<Vec<u8>, ContainerError> {
    let records = encode_quad_records(quads)?;
    let n = quads.len();
    let mut raw = Vec::with_capacity(records.len());
    for (at, width) in QUAD_FIELDS {
        for r in records.chunks_exact(QUAD_RECORD_BYTES) {
            raw.extend_from_slice(&r[at..at + width]);
        }
    }
    debug_assert_eq!(raw.len(), n * QUAD_RECORD_BYTES);
    zstd_blob("quads.bin", &raw)
}

/// `quads.bin` of version 7: what the packing cannot derive, as columns of the quads in their
/// order: the count (`u32`), every face (`u8`), then the layer (as the difference to the previous
/// quad's), `x0` and `y0` (as the differences to the previous quad's `x1` and `y0`, both counting
/// as 0 when the face or layer changes), width and height, each zigzag-coded into three byte planes (low bytes of all quads, then middle, then
/// high), Zstandard-compressed. Rotation, macro-texture and place are those
/// [`crate::compress::pack_rects`] gives the quads' sizes with `packing`; the writer checks that
/// they are the quads' (an error otherwise). On a `builtin:city:1M` cell (14.8 k quads) 31 KB
/// against the 66 KB of version 5's columns.
fn encode_packed_quads(
    quads: &[Quad],
    packing: &PackingOptions,
) -> Result<Vec<u8>, ContainerError> {
    let sizes = quad_sizes(quads);
    let derived = pack_stacked(&quad_face_rects(quads), packing)
        .map_err(|e| ContainerError::Header(format!("quads.bin: packing the quads: {e}")))?
        .packing;
    for (i, (q, p)) in quads.iter().zip(&derived.placements).enumerate() {
        let (w, h) = p.footprint(sizes[i].0, sizes[i].1);
        if q.macro_index != p.macro_index || q.rect != [p.x, p.y, w, h] || q.rotated != p.rotated {
            return Err(ContainerError::Header(format!(
                "quads.bin: quad {i} lies at {:?} of macro-texture {}, the packing puts it at {:?} of {}",
                q.rect, q.macro_index, [p.x, p.y, w, h], p.macro_index
            )));
        }
    }
    let n = quads.len();
    let mut raw = Vec::with_capacity(4 + n * 16);
    raw.extend_from_slice(&(n as u32).to_le_bytes());
    raw.extend(quads.iter().map(|q| q.face as u8));
    let mut columns: [Vec<u32>; 5] = Default::default();
    // (face, layer, x1, y0) of the previous quad: x0 is coded against its x1 (the extraction
    // goes along rows, so a quad often starts where the previous one ends), y0 against its y0
    let mut prev: Option<(Face, u16, i64, i64)> = None;
    let mut prev_layer = 0i64;
    for q in quads {
        let [x0, y0, x1, y1] = q.texels.map(i64::from);
        let (px, py) = match prev {
            Some((f, l, px, py)) if f == q.face && l == q.layer => (px, py),
            _ => (0, 0),
        };
        let layer = i64::from(q.layer);
        for (c, v) in
            columns
                .iter_mut()
                .zip([layer - prev_layer, x0 - px, y0 - py, x1 - x0, y1 - y0])
        {
            c.push(zigzag(v));
        }
        prev = Some((q.face, q.layer, x1, y0));
        prev_layer = layer;
    }
    for c in &columns {
        for shift in [0, 8, 16] {
            raw.extend(c.iter().map(|v| (v >> shift) as u8));
        }
    }
    zstd_blob("quads.bin", &raw)
}

/// The quads' `(face, texel rectangle)` as the packer takes them ([`pack_stacked`]).
fn quad_face_rects(quads: &[Quad]) -> Vec<(u32, TexelRect)> {
    quads
        .iter()
        .map(|q| {
            let [x0, y0, x1, y1] = q.texels.map(u32::from);
            (q.face.index() as u32, TexelRect { x0, y0, x1, y1 })
        })
        .collect()
}

/// The texel rectangles' sizes `(w, h)` of `quads`.
fn quad_sizes(quads: &[Quad]) -> Vec<(u32, u32)> {
    quads
        .iter()
        .map(|q| {
            let [x0, y0, x1, y1] = q.texels.map(u32::from);
            (x1.saturating_sub(x0), y1.saturating_sub(y0))
        })
        .collect()
}

fn zigzag(v: i64) -> u32 {
    ((v << 1) ^ (v >> 63)) as u32
}

fn unzigzag(v: u32) -> i64 {
    (v >> 1) as i64 ^ -((v & 1) as i64)
}

/// Inverse of [`encode_packed_quads`] up to version 5's records (then read as those are), with
/// the packing derived from the header's `packing` and checked against its macro-textures.
fn decode_packed_quads(raw: &[u8], header: &CellHeader) -> Result<Vec<u8>, ContainerError> {
    let bad = |m: String| ContainerError::Header(format!("quads.bin: {m}"));
    let packing = header
        .packing
        .as_ref()
        .ok_or_else(|| bad("a version 7 or 8 cell without its `packing` options".into()))?;
    let n = match raw.get(..4) {
        Some(b) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
        None => return Err(bad(format!("{} bytes, no quad count", raw.len()))),
    };
    // the count, a face byte and 5 columns of 3 byte planes per quad
    if (raw.len() - 4) as u64 != n as u64 * 16 {
        return Err(bad(format!(
            "{} bytes for {n} quads ({} expected)",
            raw.len(),
            4 + n as u64 * 16
        )));
    }
    let faces = &raw[4..4 + n];
    let column = |c: usize, i: usize| -> u32 {
        let o = 4 + n + 3 * n * c;
        (0..3).fold(0u32, |v, p| v | (raw[o + p * n + i] as u32) << (8 * p))
    };
    let mut records = vec![0u8; n * QUAD_RECORD_BYTES];
    let mut texels = Vec::with_capacity(n);
    let mut prev: Option<(u8, i64, i64, i64)> = None;
    let mut layer = 0i64;
    for i in 0..n {
        layer += unzigzag(column(0, i));
        let (px, py) = match prev {
            Some((f, l, px, py)) if f == faces[i] && l == layer => (px, py),
            _ => (0, 0),
        };
        let x0 = px + unzigzag(column(1, i));
        let y0 = py + unzigzag(column(2, i));
        let (x1, y1) = (x0 + unzigzag(column(3, i)), y0 + unzigzag(column(4, i)));
        let in_u16 = |v: i64| (0..=u16::MAX as i64).contains(&v);
        if !(in_u16(layer) && in_u16(x0) && in_u16(y0) && in_u16(x1) && in_u16(y1)) {
            return Err(bad(format!(
                "quad {i}: layer {layer}, texels {x0},{y0}..{x1},{y1} out of range"
            )));
        }
        prev = Some((faces[i], layer, x1, y0));
        texels.push([x0, y0, x1, y1].map(|v| v as u16));
        let r = &mut records[i * QUAD_RECORD_BYTES..(i + 1) * QUAD_RECORD_BYTES];
        r[0] = faces[i];
        r[2..4].copy_from_slice(&(layer as u16).to_le_bytes());
        for (k, v) in [x0, y0, x1, y1].iter().enumerate() {
            r[8 + 2 * k..10 + 2 * k].copy_from_slice(&(*v as u16).to_le_bytes());
        }
    }
    let rects: Vec<(u32, TexelRect)> = texels
        .iter()
        .zip(faces)
        .map(|(t, &f)| {
            let [x0, y0, x1, y1] = t.map(u32::from);
            (f as u32, TexelRect { x0, y0, x1, y1 })
        })
        .collect();
    let derived = pack_stacked(&rects, packing)
        .map_err(|e| bad(format!("packing the quads: {e}")))?
        .packing;
    let listed: Vec<(u32, u32)> = header.macros.iter().map(|m| (m.width, m.height)).collect();
    if derived.macro_sizes != listed {
        return Err(bad(format!(
            "the packing derives macro-textures of {:?}, the header lists {listed:?}",
            derived.macro_sizes
        )));
    }
    for (i, p) in derived.placements.iter().enumerate() {
        let r = &mut records[i * QUAD_RECORD_BYTES..(i + 1) * QUAD_RECORD_BYTES];
        r[1] = p.rotated as u8;
        r[4..8].copy_from_slice(&p.macro_index.to_le_bytes());
        for (k, v) in [p.x, p.y].iter().enumerate() {
            let v = u16::try_from(*v).map_err(|_| bad(format!("quad {i}: macro place {v}")))?;
            r[16 + 2 * k..18 + 2 * k].copy_from_slice(&v.to_le_bytes());
        }
    }
    Ok(records)
}

/// Offsets and widths of the fields of a quad record, in column order.
const QUAD_FIELDS: [(usize, usize); 10] = [
    (0, 1),
    (1, 1),
    (2, 2),
    (4, 4),
    (8, 2),
    (10, 2),
    (12, 2),
    (14, 2),
    (16, 2),
    (18, 2),
];

/// Inverse of [`encode_quad_columns`] up to the records, then as [`decode_quads`].
fn decode_quad_columns(columns: &[u8]) -> Result<Vec<u8>, ContainerError> {
    if columns.len() % QUAD_RECORD_BYTES != 0 {
        return Err(ContainerError::Header(format!(
            "quads.bin: {} bytes is not a whole number of {QUAD_RECORD_BYTES}-byte quads",
            columns.len()
        )));
    }
    let n = columns.len() / QUAD_RECORD_BYTES;
    let mut records = vec![0u8; columns.len()];
    let mut src = 0;
    for (at, width) in QUAD_FIELDS {
        for (i, r) in records.chunks_exact_mut(QUAD_RECORD_BYTES).enumerate() {
            let o = src + i * width;
            r[at..at + width].copy_from_slice(&columns[o..o + width]);
        }
        src += n * width;
    }
    Ok(records)
}

/// `layers.bin` of version 5: per baked face (header order) its layer count (u32) and per layer,
/// far to near, `distance`, `near_border`, `far_border` (f64, little-endian, `f64::MAX` for ∞),
/// Zstandard-compressed: the header's `layers`, exact, in a sixth of the JSON's bytes.
fn encode_layers(header: &CellHeader) -> Result<Vec<u8>, ContainerError> {
    let mut raw = Vec::new();
    for face in &header.layers {
        let n = u32::try_from(face.len())
            .map_err(|_| ContainerError::Header("too many layers".into()))?;
        raw.extend_from_slice(&n.to_le_bytes());
        for l in face {
            for v in [l.distance, l.near_border, l.far_border] {
                raw.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    zstd_blob("layers.bin", &raw)
}

/// Inverse of [`encode_layers`] for the header's faces; the values are checked where the JSON
/// header's are (the quads' corners must be finite).
fn decode_layers(data: &[u8], header: &CellHeader) -> Result<Vec<Vec<LayerInfo>>, ContainerError> {
    let bad = |m: String| ContainerError::Header(format!("layers.bin: {m}"));
    let limit = header.faces.len() as u64 * (4 + 24 * MAX_LAYERS as u64);
    let raw = unzstd_blob("layers.bin", data, limit)?;
    let mut at = 0usize;
    let mut take = |n: usize| -> Result<&[u8], ContainerError> {
        let r = raw
            .get(at..at + n)
            .ok_or_else(|| bad(format!("truncated at byte {at} of {}", raw.len())))?;
        at += n;
        Ok(r)
    };
    let mut layers = Vec::with_capacity(header.faces.len());
    for face in &header.faces {
        let n = u32::from_le_bytes(take(4)?.try_into().unwrap_or_default()) as usize;
        if n > MAX_LAYERS as usize {
            return Err(bad(format!("face {face}: {n} layers")));
        }
        let mut list = Vec::with_capacity(n);
        for _ in 0..n {
            let v = take(24)?;
            let f =
                |i: usize| f64::from_le_bytes(v[8 * i..8 * i + 8].try_into().unwrap_or_default());
            list.push(LayerInfo {
                distance: f(0),
                near_border: f(1),
                far_border: f(2),
            });
        }
        layers.push(list);
    }
    if at != raw.len() {
        return Err(bad(format!(
            "{} bytes after the layers of {} faces",
            raw.len() - at,
            header.faces.len()
        )));
    }
    Ok(layers)
}

/// The quads of [`encode_quads`]' records (inflated), corners recomputed from the header's layers.
fn decode_quad_records(raw: &[u8], header: &CellHeader) -> Result<Vec<Quad>, ContainerError> {
    let bad = |m: String| ContainerError::Header(format!("quads.bin: {m}"));
    if raw.len() % QUAD_RECORD_BYTES != 0 {
        return Err(bad(format!(
            "{} bytes is not a whole number of {QUAD_RECORD_BYTES}-byte records",
            raw.len()
        )));
    }
    if header.layers.len() != header.faces.len() {
        return Err(bad(format!(
            "{} faces but {} layer lists",
            header.faces.len(),
            header.layers.len()
        )));
    }
    let res = header.resolution;
    let u16_at = |r: &[u8], i: usize| u16::from_le_bytes([r[i], r[i + 1]]);
    raw.chunks_exact(QUAD_RECORD_BYTES)
        .enumerate()
        .map(|(i, r)| {
            let face = Face::from_index(r[0] as usize)
                .ok_or_else(|| bad(format!("quad {i}: face {} does not exist", r[0])))?;
            let rotated = match r[1] {
                0 => false,
                1 => true,
                v => return Err(bad(format!("quad {i}: rotation flag {v}"))),
            };
            let layer = u16_at(r, 2);
            let macro_index = u32::from_le_bytes([r[4], r[5], r[6], r[7]]);
            let texels = [u16_at(r, 8), u16_at(r, 10), u16_at(r, 12), u16_at(r, 14)];
            let [x0, y0, x1, y1] = texels.map(u32::from);
            if x0 >= x1 || y0 >= y1 || x1 > res || y1 > res {
                return Err(bad(format!(
                    "quad {i}: texel rectangle {texels:?} is empty or outside the {res}² face"
                )));
            }
            let slot = header
                .faces
                .iter()
                .position(|&f| f == face)
                .ok_or_else(|| bad(format!("quad {i}: face {face} was not baked")))?;
            let distance = header.layers[slot]
                .get(layer as usize)
                .map(|l| l.distance)
                .ok_or_else(|| bad(format!("quad {i}: face {face} has no layer {layer}")))?;
            let rect = crate::compress::TexelRect { x0, y0, x1, y1 };
            let corners = header.quad_corners(face, distance, rect);
            if corners.iter().flatten().any(|c| !c.is_finite()) {
                return Err(bad(format!("quad {i}: non-finite corners")));
            }
            let (w, h) = (x1 - x0, y1 - y0);
            let (fw, fh) = if rotated { (h, w) } else { (w, h) };
            Ok(Quad {
                fringe: false,
                face,
                layer,
                texels,
                corners,
                macro_index,
                rect: [u16_at(r, 16) as u32, u16_at(r, 18) as u32, fw, fh],
                rotated,
            })
        })
        .collect()
}

/// `hlod.bin`: per band near to far, per mesh in header order, its vertices
/// ([`crate::Vertex`], 36 bytes little-endian: position, normal, uv as f32, colour as 4 u8) then
/// its indices (u32 little-endian), deflated (zlib).
fn encode_hlod(h: &HlodHeader) -> Result<Vec<u8>, ContainerError> {
    use std::io::Write;
    let mut raw = Vec::new();
    for (b, band) in h.bands.iter().enumerate() {
        if band.data.len() != band.meshes.len() {
            return Err(ContainerError::Header(format!(
                "hlod band {b}: {} meshes listed, {} given",
                band.meshes.len(),
                band.data.len()
            )));
        }
        for m in &band.data {
            raw.extend_from_slice(bytemuck::cast_slice(&m.vertices));
            raw.extend_from_slice(bytemuck::cast_slice(&m.indices));
        }
    }
    let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(&raw)
        .and_then(|_| enc.finish())
        .map_err(|e| ContainerError::Header(format!("compressing hlod.bin: {e}")))
}

/// Inverse of [`encode_hlod`], into `h`'s bands; checks sizes, indices and finite positions.
fn decode_hlod(data: &[u8], h: &mut HlodHeader) -> Result<(), ContainerError> {
    use std::io::Read;
    let bad = |m: String| ContainerError::Header(format!("hlod.bin: {m}"));
    let vsize = std::mem::size_of::<crate::Vertex>() as u64;
    let expected: u64 = h
        .bands
        .iter()
        .flat_map(|b| &b.meshes)
        .map(|m| m.vertices as u64 * vsize + m.triangles as u64 * 12)
        .sum();
    let mut raw = Vec::new();
    flate2::read::ZlibDecoder::new(data)
        .take(expected.saturating_add(1))
        .read_to_end(&mut raw)
        .map_err(|e| bad(format!("not valid zlib data: {e}")))?;
    if raw.len() as u64 != expected {
        return Err(bad(format!(
            "{} bytes, the header's meshes need {expected}",
            raw.len()
        )));
    }
    let mut at = 0usize;
    for (b, band) in h.bands.iter_mut().enumerate() {
        band.data.clear();
        for (k, info) in band.meshes.iter().enumerate() {
            let nv = info.vertices as usize * vsize as usize;
            let vertices: Vec<crate::Vertex> = raw[at..at + nv]
                .chunks_exact(vsize as usize)
                .map(bytemuck::pod_read_unaligned)
                .collect();
            at += nv;
            let ni = info.triangles as usize * 12;
            let indices: Vec<u32> = raw[at..at + ni]
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            at += ni;
            if indices.iter().any(|&i| i >= info.vertices) {
                return Err(bad(format!(
                    "band {b} mesh {k}: an index past its vertices"
                )));
            }
            if vertices
                .iter()
                .any(|v| v.position.iter().any(|c| !c.is_finite()))
            {
                return Err(bad(format!("band {b} mesh {k}: a non-finite position")));
            }
            band.data.push(crate::Mesh {
                material: info.material,
                vertices,
                indices,
            });
        }
    }
    Ok(())
}

/// Encodes an RGBA8 image as PNG (best compression: macro-textures are written once, read often).
pub fn encode_png(rgba: &[u8], width: u32, height: u32) -> Result<Vec<u8>, ContainerError> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Best,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(rgba, width, height, image::ExtendedColorType::Rgba8)
    .map_err(|e| ContainerError::Header(format!("encoding a {width}x{height} PNG: {e}")))?;
    Ok(out)
}

/// The reference viewpoint of a cell as f64 (helper for stages that work relative to it).
pub fn reference_viewpoint(cell: &ViewCell) -> DVec3 {
    cell.center
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compress::pack_rects;
    use glam::IVec3;

    pub(crate) fn sample_cell() -> CellFile {
        CellFile {
            header: CellHeader {
                fringe_quads: 0,
                cell: ViewCell {
                    index: IVec3::new(1, 0, 2),
                    center: DVec3::new(15.0, 1.7, 25.0),
                    half: DVec3::splat(5.0),
                },
                params_hash: "abc".into(),
                scene_fingerprint: "def".into(),
                resolution: 64,
                near_field: 42.0,
                faces: vec![Face::PosX],
                layers: vec![vec![LayerInfo {
                    distance: 100.0,
                    near_border: 50.0,
                    far_border: f64::MAX,
                }]],
                quads: vec![Quad {
                    fringe: false,
                    face: Face::PosX,
                    layer: 0,
                    texels: [8, 16, 16, 24],
                    corners: crate::compress::quad_corners(
                        Face::PosX,
                        100.0,
                        64,
                        crate::compress::TexelRect {
                            x0: 8,
                            y0: 16,
                            x1: 16,
                            y1: 24,
                        },
                    )
                    .map(|c| (DVec3::new(15.0, 1.7, 25.0) + c).as_vec3().to_array()),
                    macro_index: 0,
                    rect: [0, 0, 8, 8],
                    rotated: false,
                }],
                macros: vec![MacroInfo {
                    name: "macro0.png".into(),
                    width: 64,
                    height: 64,
                }],
                stats: CellStats::default(),
                hlod: None,
                object: None,
                texture_format: Default::default(),
                packing: None,
            },
            near: vec![[0, 1], [2, 3]],
            macro_blobs: vec![vec![137, 80, 78, 71]],
        }
    }

    #[test]
    fn cell_files_round_trip_and_reject_damage() {
        let c = sample_cell();
        let bytes = c.encode().unwrap();
        let back = CellFile::decode(&bytes).unwrap();
        assert_eq!(back, c);
        // +X face, texel edges 8 and 16 of 64 → s = −0.75, −0.5; right is −Z, so z = 25 + 75
        assert_eq!(back.header.quads[0].corners[0][0], 115.0);
        assert_eq!(back.header.quads[0].corners[0][2], 100.0);
        assert!(CellFile::decode(&bytes[..bytes.len() / 2]).is_err());
        let mut bad_quad = c.clone();
        bad_quad.header.quads[0].layer = 3;
        let bytes3 = bad_quad.encode().unwrap();
        let err = CellFile::decode(&bytes3).unwrap_err().to_string();
        assert!(err.contains("no layer 3"), "{err}");
        let mut bad = bytes.clone();
        let n = bad.len();
        bad[n / 3] ^= 1;
        assert!(CellFile::decode(&bad).is_err());
    }

    /// The fringe quads are the last `fringe_quads` of the cell: the header's count sets their
    /// flags on reading, the writer refuses a count that disagrees with the flags or flags that
    /// are not the last quads, and the reader a count above the quads'.
    #[test]
    fn fringe_quads_are_the_last_ones_and_round_trip() {
        let mut c = sample_cell();
        let mut fringe = c.header.quads[0];
        fringe.fringe = true;
        fringe.rect = [8, 0, 8, 8];
        c.header.quads.push(fringe);
        c.header.fringe_quads = 1;
        let bytes = c.encode().expect("encodes");
        let back = CellFile::decode(&bytes).expect("decodes");
        assert_eq!(back, c);
        assert_eq!(
            back.header
                .quads
                .iter()
                .map(|q| q.fringe)
                .collect::<Vec<_>>(),
            [false, true]
        );
        // a cell without fringe quads does not mention them (bundles from before are unchanged)
        let plain = sample_cell().encode().expect("encodes");
        let find = |b: &[u8]| b.windows(12).any(|w| w == b"fringe_quads");
        assert!(find(&bytes) && !find(&plain));
        let mut count = c.clone();
        count.header.fringe_quads = 2;
        let e = count
            .encode()
            .expect_err("count of 2, one flag")
            .to_string();
        assert!(e.contains("fringe quads"), "{e}");
        let mut order = c.clone();
        order.header.quads.swap(0, 1);
        let e = order.encode().expect_err("not the last").to_string();
        assert!(e.contains("last"), "{e}");
        // a damaged count: the header says 5 of 2
        let mut header = c.header.clone();
        header.fringe_quads = 5;
        header.quads.clear();
        let forged = container::encode(
            CELL_MAGIC,
            BUNDLE_VERSION,
            &header,
            &[
                Blob {
                    name: "near.bin".into(),
                    data: bytemuck::cast_slice(&c.near).to_vec(),
                },
                Blob {
                    name: "quads.bin".into(),
                    data: encode_quads(&c.header.quads).expect("quads"),
                },
                Blob {
                    name: "macro0.png".into(),
                    data: c.macro_blobs[0].clone(),
                },
            ],
        )
        .expect("encodes");
        let e = CellFile::decode(&forged).expect_err("5 of 2").to_string();
        assert!(e.contains("5 fringe quads in a cell of 2 quads"), "{e}");
    }

    #[test]
    fn hlod_cells_are_version_3_and_round_trip() {
        let mut c = sample_cell();
        let v = |p: [f32; 3]| crate::Vertex::new(p, [0.0, 1.0, 0.0], [0.5, 0.5], [255; 4]);
        let mesh = crate::Mesh {
            material: 2,
            vertices: vec![v([0.0; 3]), v([1.0, 0.0, 0.0]), v([0.0, 0.0, 1.0])],
            indices: vec![0, 1, 2],
        };
        let far = crate::hlod::HlodFarField {
            bands: vec![crate::hlod::HlodBand {
                near: 10.0,
                far: 20.0,
                error_bound: 0.01,
                result_error: 0.005,
                source_triangles: 7,
                meshes: vec![mesh.clone()],
            }],
        };
        c.header.hlod = Some(HlodHeader::of(&far, &Default::default()));
        let bytes = c.encode().unwrap();
        assert_eq!(bytes[8..12], HLOD_BUNDLE_VERSION.to_le_bytes());
        let back = CellFile::decode(&bytes).unwrap();
        assert_eq!(back, c);
        let h = back.header.hlod.unwrap();
        assert_eq!(h.meshes().next(), Some(&mesh));
        assert_eq!((h.triangles(), h.source_triangles), (1, 7));
        // a layered cell stays version 2
        assert_eq!(
            sample_cell().encode().unwrap()[8..12],
            BUNDLE_VERSION.to_le_bytes()
        );
        // an index past the vertices is a clear error
        let mut bad = c.clone();
        if let Some(h) = bad.header.hlod.as_mut() {
            h.bands[0].data[0].indices[2] = 9;
        }
        let err = CellFile::decode(&bad.encode().unwrap())
            .unwrap_err()
            .to_string();
        assert!(err.contains("index past its vertices"), "{err}");
        // sizes that disagree with the blob
        let mut bad = c.clone();
        if let Some(h) = bad.header.hlod.as_mut() {
            h.bands[0].data[0].indices.extend([0, 1, 2]);
        }
        let err = CellFile::decode(&bad.encode().unwrap())
            .unwrap_err()
            .to_string();
        assert!(err.contains("hlod.bin"), "{err}");
    }

    /// `sample_cell` with its 64² macro-texture block-compressed in a Zstandard-supercompressed
    /// KTX2 (as bakes write them).
    fn block_cell(format: TextureFormat) -> (CellFile, Vec<u8>) {
        block_cell_with(format, crate::compress::Supercompression::Zstd)
    }

    /// `sample_cell` with its 64² macro-texture block-compressed in KTX2, supercompressed with `sc`
    /// (`None`: as bakes wrote them before Zstandard).
    fn block_cell_with(
        format: TextureFormat,
        sc: crate::compress::Supercompression,
    ) -> (CellFile, Vec<u8>) {
        let rgba: Vec<u8> = (0..64 * 64)
            .flat_map(|i| {
                [
                    (i % 64 * 4) as u8,
                    (i / 64 * 4) as u8,
                    90,
                    (i % 3 != 0) as u8 * 255,
                ]
            })
            .collect();
        let block = format.block().unwrap();
        let (blocks, _) = crate::compress::encode_blocks(block, 64, 64, &rgba).unwrap();
        let mut c = sample_cell();
        c.header.texture_format = format;
        c.header.macros[0].name = "macro0.ktx2".into();
        c.macro_blobs = vec![crate::compress::write_ktx2(block, 64, 64, &[blocks], sc).unwrap()];
        (c, rgba)
    }

    /// A BC1 cell of quads with texel rectangles `(face, layer, x0, y0, w, h)` on two faces of
    /// three layers, placed by the packer as a bake places them, in stacks or not (version 5:
    /// the places stored).
    fn packed_cell(rects: &[(usize, u16, u16, u16, u16, u16)], stack: u32) -> CellFile {
        let packing = PackingOptions {
            max_size: 1024,
            block: 4,
            trim: true,
            stack,
        };
        let faces = [Face::PosX, Face::NegZ];
        let face_rects: Vec<(u32, TexelRect)> = rects
            .iter()
            .map(|&(f, _, x0, y0, w, h)| {
                let (x0, y0) = (x0 as u32, y0 as u32);
                let rect = TexelRect {
                    x0,
                    y0,
                    x1: x0 + w as u32,
                    y1: y0 + h as u32,
                };
                (faces[f].index() as u32, rect)
            })
            .collect();
        let derived = pack_stacked(&face_rects, &packing).unwrap().packing;
        let mut c = sample_cell();
        c.header.texture_format = TextureFormat::Bc1;
        c.header.resolution = 512;
        c.header.faces = faces.to_vec();
        let layer = |d: f64| LayerInfo {
            distance: d,
            near_border: d * 0.9,
            far_border: d * 1.1,
        };
        c.header.layers = vec![vec![layer(300.0), layer(200.0), layer(100.0)]; 2];
        c.header.macros = derived
            .macro_sizes
            .iter()
            .enumerate()
            .map(|(i, &(width, height))| MacroInfo {
                name: format!("macro{i}.ktx2"),
                width,
                height,
            })
            .collect();
        c.macro_blobs = derived
            .macro_sizes
            .iter()
            .map(|&(w, h)| {
                crate::compress::write_ktx2(
                    BlockFormat::Bc1,
                    w,
                    h,
                    &[vec![0u8; BlockFormat::Bc1.image_bytes(w, h)]],
                    crate::compress::Supercompression::Zstd,
                )
                .unwrap()
            })
            .collect();
        c.header.quads = rects
            .iter()
            .zip(&derived.placements)
            .map(|(&(f, layer, x0, y0, w, h), p)| {
                let (fw, fh) = p.footprint(w as u32, h as u32);
                Quad {
                    fringe: false,
                    face: c.header.faces[f],
                    layer,
                    texels: [x0, y0, x0 + w, y0 + h],
                    corners: [[0.0; 3]; 4],
                    macro_index: p.macro_index,
                    rect: [p.x, p.y, fw, fh],
                    rotated: p.rotated,
                }
            })
            .collect();
        // the corners as the reader computes them
        CellFile::decode(&c.encode().unwrap()).unwrap()
    }

    proptest::proptest! {
        #[test]
        fn packed_quads_round_trip(
            rects in proptest::collection::vec(
                (0usize..2, 0u16..3, 0u16..480, 0u16..480, 1u16..32, 1u16..32),
                1..300,
            )
        ) {
            let mut rects = rects;
            // as a bake orders them: face by face, layer by layer
            rects.sort_by_key(|r| (r.0, r.1));
            for stack in [0, 2, 1024] {
                let v5 = packed_cell(&rects, stack);
                let mut c = v5.clone();
                c.header.packing =
                    Some(PackingOptions { max_size: 1024, block: 4, trim: true, stack });
                let bytes = c.encode().unwrap();
                proptest::prop_assert_eq!(&bytes[8..12], &PACKED_BUNDLE_VERSION.to_le_bytes());
                let back = CellFile::decode(&bytes).unwrap();
                proptest::prop_assert_eq!(&back.header.quads, &v5.header.quads);
                proptest::prop_assert_eq!(back, c);
            }
        }
    }

    /// Version 7 and 8 cells store no macro-texture places: the reader derives them with the packer, so
    /// the packer's placements are part of the format. This pins them on a fixed input; if a
    /// change to `pack_rects` fails it, version 7 cells would read wrong: keep the old packer for
    /// them and write a new version.
    #[test]
    fn the_packers_placements_are_pinned_by_version_7() {
        let sizes: Vec<(u32, u32)> = (0..3000u32)
            .map(|i| (1 + i * 7 % 37, 1 + i * 11 % 29))
            .collect();
        let mut hasher = blake3::Hasher::new();
        for (block, trim) in [(4, true), (4, false), (1, true)] {
            let p = pack_rects(
                &sizes,
                &PackingOptions {
                    max_size: 1024,
                    block,
                    trim,
                    stack: 0,
                },
            )
            .unwrap();
            hash_packing(&mut hasher, &p);
        }
        assert_eq!(
            hasher.finalize().to_hex().as_str(),
            "f0cadab8b5b979ce0fc1dd4af5eda41a33a48a52c768bd65dea70f53de3b32bb"
        );
    }

    /// Feeds a packing's macro sizes and placements to `hasher` (the pins below).
    fn hash_packing(hasher: &mut blake3::Hasher, p: &crate::compress::Packing) {
        for (w, h) in &p.macro_sizes {
            hasher.update(&w.to_le_bytes());
            hasher.update(&h.to_le_bytes());
        }
        for q in &p.placements {
            hasher.update(&q.macro_index.to_le_bytes());
            hasher.update(&q.x.to_le_bytes());
            hasher.update(&q.y.to_le_bytes());
            hasher.update(&[q.rotated as u8]);
        }
    }

    /// Version 8 cells derive the stacks as well ([`pack_stacked`]): this pins the stacking and
    /// the places of the stacks' members on a fixed input of two faces whose thin rectangles
    /// overlap and touch across layers. A change that fails it needs a new version.
    #[test]
    fn the_stacks_and_their_placements_are_pinned_by_version_8() {
        let rects: Vec<(u32, TexelRect)> = (0..3000u32)
            .map(|i| {
                let (x0, y0) = (i * 37 % 500, i * 13 % 500);
                let (w, h) = if i % 3 == 0 {
                    (1 + i % 200, 1 + i % 2)
                } else {
                    (1 + i * 7 % 37, 1 + i * 11 % 29)
                };
                (
                    i / 1500,
                    TexelRect {
                        x0,
                        y0,
                        x1: x0 + w,
                        y1: y0 + h,
                    },
                )
            })
            .collect();
        let options = PackingOptions {
            max_size: 1024,
            block: 4,
            trim: true,
            stack: 1024,
        };
        let p = pack_stacked(&rects, &options).unwrap();
        assert!(p.stacks.len() < rects.len());
        let mut hasher = blake3::Hasher::new();
        for s in &p.stacks {
            hasher.update(&(s.members.len() as u32).to_le_bytes());
            for m in &s.members {
                hasher.update(&(*m as u32).to_le_bytes());
            }
        }
        hash_packing(&mut hasher, &p.packing);
        assert_eq!(
            hasher.finalize().to_hex().as_str(),
            "63f94ec12749f73e1df2fbe29d8709ad3112a95d9a8b162c8f6bbf60b4b4b9bb"
        );
    }

    #[test]
    fn packed_quads_are_smaller_and_must_lie_where_the_packing_puts_them() {
        let rects: Vec<_> = (0..2000u16)
            .map(|i| {
                let (f, l) = ((i / 1000) as usize, i / 400 % 3);
                (f, l, i * 7 % 480, i * 13 % 480, 1 + i % 9, 1 + i % 23)
            })
            .collect();
        let v5 = packed_cell(&rects, 0);
        let mut c = v5.clone();
        c.header.packing = Some(PackingOptions {
            max_size: 1024,
            block: 4,
            trim: true,
            stack: 0,
        });
        let (old, new) = (v5.encode().unwrap(), c.encode().unwrap());
        assert_eq!(old[8..12], BLOCK_BUNDLE_VERSION.to_le_bytes());
        assert!(new.len() < old.len(), "{} {}", new.len(), old.len());
        // a quad the packing would put elsewhere cannot be written as version 7 or 8
        let mut moved = c.clone();
        moved.header.quads[5].rect[0] += 4;
        let e = moved.encode().unwrap_err().to_string();
        assert!(
            e.contains("quad 5") && e.contains("the packing puts it"),
            "{e}"
        );
        // a reader whose macro-textures disagree with the derived packing refuses the cell
        let mut header = c.header.clone();
        header.macros[0].width += 4;
        let raw = encode_packed_quads(&c.header.quads, &c.header.packing.unwrap()).unwrap();
        let raw = unzstd_blob("quads.bin", &raw, 1 << 32).unwrap();
        let e = decode_packed_quads(&raw, &header).unwrap_err().to_string();
        assert!(e.contains("the packing derives"), "{e}");
        // truncated columns, and a version 7 header without its options
        for len in [0, 3, 4, raw.len() - 1] {
            assert!(
                decode_packed_quads(&raw[..len], &c.header).is_err(),
                "{len}"
            );
        }
        let mut header = c.header.clone();
        header.packing = None;
        let e = decode_packed_quads(&raw, &header).unwrap_err().to_string();
        assert!(e.contains("without its `packing`"), "{e}");
    }

    #[test]
    fn block_compressed_cells_are_version_5_and_round_trip() {
        use crate::compress::Supercompression;
        for (format, sc) in [
            (TextureFormat::Bc7, Supercompression::Zstd),
            (TextureFormat::Bc1, Supercompression::Zstd),
            // as written before Zstandard: still read
            (TextureFormat::Bc7, Supercompression::None),
            (TextureFormat::Bc1, Supercompression::None),
        ] {
            let (c, rgba) = block_cell_with(format, sc);
            let bytes = c.encode().unwrap();
            assert_eq!(bytes[8..12], BLOCK_BUNDLE_VERSION.to_le_bytes());
            let back = CellFile::decode(&bytes).unwrap();
            assert_eq!(back, c);
            let blocks = back.block_macros().unwrap().unwrap();
            assert_eq!(
                (blocks[0].format, blocks[0].width),
                (format.block().unwrap(), 64)
            );
            assert_eq!(
                blocks[0].data.len(),
                format.block().unwrap().image_bytes(64, 64)
            );
            // the CPU fallback decodes with the alpha test intact
            let m = back.decode_macros().unwrap();
            for (a, b) in rgba.chunks_exact(4).zip(m[0].rgba.chunks_exact(4)) {
                assert_eq!(a[3] >= 128, b[3] >= 128);
            }
        }
        // a PNG cell has no block macros and stays version 2
        assert_eq!(sample_cell().block_macros().unwrap(), None);
        assert_eq!(
            sample_cell().encode().unwrap()[8..12],
            BUNDLE_VERSION.to_le_bytes()
        );
    }

    #[test]
    fn damaged_ktx2_in_a_cell_is_a_clear_error() {
        let (c, _) = block_cell(TextureFormat::Bc7);
        let decode_err = |c: &CellFile| {
            CellFile::decode(&c.encode().unwrap())
                .unwrap_err()
                .to_string()
        };
        // truncated KTX2 (the cell's own checksum is recomputed by encode: the KTX2 checks see it)
        let mut bad = c.clone();
        let n = bad.macro_blobs[0].len();
        bad.macro_blobs[0].truncate(n - 100);
        let e = decode_err(&bad);
        assert!(e.contains("macro0.ktx2") && e.contains("truncated"), "{e}");
        // not KTX2 at all
        let mut bad = c.clone();
        bad.macro_blobs[0] = vec![137, 80, 78, 71];
        let e = decode_err(&bad);
        assert!(e.contains("macro0.ktx2") && e.contains("identifier"), "{e}");
        // another format than the header's
        let mut bad = c.clone();
        bad.header.texture_format = TextureFormat::Bc1;
        let e = decode_err(&bad);
        assert!(e.contains("the header says bc1"), "{e}");
        // another size than the header's
        let mut bad = c.clone();
        bad.header.macros[0].width = 32;
        let e = decode_err(&bad);
        assert!(e.contains("the header says bc7 32x64"), "{e}");
        // the version and the format disagree: a version 2 cell naming a block format, a
        // version 4 cell without one
        let blobs = |c: &CellFile| {
            vec![
                Blob {
                    name: "near.bin".into(),
                    data: bytemuck::cast_slice(&c.near).to_vec(),
                },
                Blob {
                    name: "quads.bin".into(),
                    data: encode_quads(&c.header.quads).unwrap(),
                },
                Blob {
                    name: c.header.macros[0].name.clone(),
                    data: c.macro_blobs[0].clone(),
                },
            ]
        };
        let v2 = container::encode(CELL_MAGIC, BUNDLE_VERSION, &c.header, &blobs(&c)).unwrap();
        let e = CellFile::decode(&v2).unwrap_err().to_string();
        assert!(
            e.contains("`texture_format` bc7 in a version 2 cell"),
            "{e}"
        );
        let png = sample_cell();
        let v4 = container::encode(
            CELL_MAGIC,
            BLOCK_BUNDLE_VERSION_4,
            &png.header,
            &blobs(&png),
        )
        .unwrap();
        let e = CellFile::decode(&v4).unwrap_err().to_string();
        assert!(e.contains("version 4 cell without"), "{e}");
        // a version 4 cell as bakes wrote them before version 5 (zlib records, raw near list,
        // layers in the header, KTX2 without supercompression) still reads, to the same cell
        let (old, _) = block_cell_with(TextureFormat::Bc7, crate::compress::Supercompression::None);
        let v4 = container::encode(
            CELL_MAGIC,
            BLOCK_BUNDLE_VERSION_4,
            &old.header,
            &blobs(&old),
        )
        .unwrap();
        assert_eq!(CellFile::decode(&v4).unwrap(), old);
        // one bit flipped anywhere in the file fails the cell's checksum first
        let mut bytes = c.encode().unwrap();
        let mid = bytes.len() / 2;
        bytes[mid] ^= 1;
        assert!(CellFile::decode(&bytes).is_err());
    }

    #[test]
    fn version_5_blobs_are_checked() {
        let (c, _) = block_cell(TextureFormat::Bc1);
        let bytes = c.encode().unwrap();
        let (version, header, blobs): (u32, CellHeader, Vec<Blob>) =
            container::decode_versions(CELL_MAGIC, "cell", BUNDLE_VERSION..=5, &bytes).unwrap();
        assert_eq!(version, 5);
        assert!(header.layers.is_empty(), "the layers are in layers.bin");
        let names: Vec<&str> = blobs.iter().map(|b| b.name.as_str()).collect();
        assert_eq!(
            names,
            ["near.bin", "quads.bin", "layers.bin", "macro0.ktx2"]
        );
        // the columns hold the records' bytes, field by field
        let columns = unzstd_blob("quads.bin", &blobs[1].data, 1 << 20).unwrap();
        assert_eq!(
            decode_quad_columns(&columns).unwrap(),
            encode_quad_records(&c.header.quads).unwrap()
        );
        let n = c.header.quads.len();
        assert_eq!(
            columns[..n],
            c.header
                .quads
                .iter()
                .map(|q| q.face.index() as u8)
                .collect::<Vec<_>>()[..]
        );
        // each blob replaced by damaged data is an error naming it (the container's checksum is
        // recomputed by encode, so the blob's own checks see it)
        let with = |i: usize, data: Vec<u8>, header: &CellHeader| {
            let mut b = blobs.clone();
            b[i].data = data;
            let f = container::encode(CELL_MAGIC, 5, header, &b).unwrap();
            CellFile::decode(&f).unwrap_err().to_string()
        };
        for (i, name) in [(0, "near.bin"), (1, "quads.bin"), (2, "layers.bin")] {
            let mut d = blobs[i].data.clone();
            let mid = d.len() / 2;
            d[mid] ^= 0x41;
            let e = with(i, d, &header);
            assert!(e.contains(name), "{name}: {e}");
            let e = with(
                i,
                blobs[i].data[..blobs[i].data.len() - 3].to_vec(),
                &header,
            );
            assert!(e.contains(name), "{name}: {e}");
        }
        // well-formed Zstandard of the wrong sizes
        let z = |raw: &[u8]| zstd_blob("x", raw).unwrap();
        let e = with(0, z(&[1, 2, 3]), &header);
        assert!(e.contains("near.bin") && e.contains("8-byte"), "{e}");
        let e = with(1, z(&[0; 21]), &header);
        assert!(e.contains("quads.bin") && e.contains("20-byte"), "{e}");
        let e = with(2, z(&[1, 0, 0, 0]), &header);
        assert!(e.contains("layers.bin") && e.contains("truncated"), "{e}");
        let mut raw = zstd::decode_all(&blobs[2].data[..]).unwrap();
        raw.push(0);
        let e = with(2, z(&raw), &header);
        assert!(
            e.contains("layers.bin") && e.contains("after the layers"),
            "{e}"
        );
        // layers in the JSON header of a version 5 cell
        let e = with(2, blobs[2].data.clone(), &c.header);
        assert!(e.contains("`layers` in its header"), "{e}");
    }

    #[test]
    fn texture_format_is_part_of_the_params_hash_only_when_not_png() {
        let mut p = BakeParams {
            cell_size: 10.0,
            cell_height: None,
            resolution: 64,
            target: LayerTarget::Layers(8),
            faces: vec![Face::PosX],
            alpha: 0.001,
            output_fov_deg: None,
            output_width: None,
            micro_grid: 8,
            micro_threshold: 0.5,
            layering: Layering::Optimal,
            texture_format: TextureFormat::Png,
            outline_copies: false,
            outline_fringe: false,
        };
        let png = p.hash();
        let json = serde_json::to_string(&p).unwrap();
        assert!(!json.contains("texture_format"), "{json}");
        assert_eq!(version_for(&p), BUNDLE_VERSION);
        p.texture_format = TextureFormat::Bc7;
        assert_ne!(p.hash(), png);
        assert!(serde_json::to_string(&p)
            .unwrap()
            .contains("\"texture_format\":\"bc7\""));
        assert_eq!(version_for(&p), PACKED_BUNDLE_VERSION);
        let bc7 = p.hash();
        p.texture_format = TextureFormat::Bc1;
        assert!(p.hash() != bc7 && p.hash() != png);
    }

    #[test]
    fn drawn_vertices_grow_the_quad_by_a_sixteenth_texel() {
        // a 4 x 2 texel quad of a 64² face at distance 8, stored rotated at (10, 20)
        let rect = crate::compress::TexelRect {
            x0: 8,
            y0: 16,
            x1: 12,
            y1: 18,
        };
        let corners = crate::compress::quad_corners(Face::PosX, 8.0, 64, rect)
            .map(|c| c.as_vec3().to_array());
        let q = Quad {
            fringe: false,
            face: Face::PosX,
            layer: 0,
            texels: [8, 16, 12, 18],
            corners,
            macro_index: 0,
            rect: [10, 20, 2, 4],
            rotated: true,
        };
        let v = q.drawn_vertices();
        // texel coordinates: the macro-texel corners moved 1/16 texel outwards, exactly
        let g = QUAD_GROWTH_TEXELS as f32;
        let t = q.macro_texel_corners();
        let grown = [(-g, -g), (g, -g), (g, g), (-g, g)];
        for k in 0..4 {
            // the quad's u runs along the macro-texture's y when rotated
            let (du, dv) = grown[k];
            assert_eq!(
                v[k].1,
                [t[k][0] as f32 - dv, t[k][1] as f32 + du],
                "corner {k}"
            );
        }
        // positions: 1/16 of a texel (2/64 · 8 = 0.25 m) beyond each edge
        let texel = 2.0 / 64.0 * 8.0;
        let expected = crate::compress::quad_corners(Face::PosX, 8.0, 64, rect);
        let step = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        for k in 0..4 {
            let e = expected[k]
                + Face::PosX.right() * (step[k].0 * texel / 16.0)
                + Face::PosX.down() * (step[k].1 * texel / 16.0);
            let got = glam::DVec3::from_array(v[k].0.map(f64::from));
            assert!((got - e).length() < 1e-5, "corner {k}: {got} vs {e}");
        }
    }

    #[test]
    fn macro_texel_corners_undo_the_rotation() {
        use crate::compress::MacroPlacement;
        // a 3 x 5 micro-texture placed at (10, 20), rotated: footprint 5 x 3
        let p = MacroPlacement {
            macro_index: 0,
            x: 10,
            y: 20,
            rotated: true,
        };
        let (fw, fh) = p.footprint(3, 5);
        let q = Quad {
            fringe: false,
            face: Face::PosX,
            layer: 0,
            texels: [0, 0, 3, 5],
            corners: [[0.0; 3]; 4],
            macro_index: 0,
            rect: [10, 20, fw, fh],
            rotated: true,
        };
        assert_eq!(q.macro_texel_corners(), p.macro_corners(3, 5));
        let p = MacroPlacement {
            rotated: false,
            ..p
        };
        let q = Quad {
            rect: [10, 20, 3, 5],
            rotated: false,
            ..q
        };
        assert_eq!(q.macro_texel_corners(), p.macro_corners(3, 5));
    }

    #[test]
    fn png_round_trip_and_size_check() {
        let rgba: Vec<u8> = (0..4 * 6 * 4).map(|i| (i * 7 % 256) as u8).collect();
        let png = encode_png(&rgba, 6, 4).unwrap();
        let mut c = sample_cell();
        c.header.macros[0].width = 6;
        c.header.macros[0].height = 4;
        c.macro_blobs = vec![png];
        let m = c.decode_macros().unwrap();
        assert_eq!(m[0].rgba, rgba);
        c.header.macros[0].width = 7;
        assert!(c.decode_macros().is_err());
        c.macro_blobs = vec![vec![1, 2, 3]];
        assert!(c.decode_macros().is_err());
    }
}
