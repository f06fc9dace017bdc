//! The CPU side of a cell's impostor (no GPU work): the quads' vertex and index arrays with their
//! draw calls in draw order, the opaque quads, the boxes a frame culls draw calls by, and the near
//! geometry copied out of the scene ([`Scene::extract`]), gathered in [`ImpostorCellData`]. See
//! the module docs of [`crate::impostor`] for the order and why.

use bytemuck::{Pod, Zeroable};
use lemi_core::bundle::BlockMacro;
use lemi_core::bundle::{CellHeader, Quad};
use lemi_core::classify::TriRef;
use lemi_core::compress::MacroTexture;
use lemi_core::texel_scale::{TexelScale, TexelScaleTable};
use lemi_core::{Mesh, Scene};

use super::atlas::{self, Atlas};
#[cfg(doc)]
use super::{ImpostorCell, PendingImpostorCell};
use crate::GpuError;

/// The atlas page side [`ImpostorCellData::prepare`] packs for: wgpu's default texture limit,
/// which every adapter but downlevel ones (WebGL2: 2048) has.
pub const DEFAULT_PAGE_SIDE: u32 = 8192;

/// Quad fragments whose macro-texel alpha (0..=1) is below this are discarded (the bundle's
/// alpha test, [`lemi_core::bundle::QUAD_ALPHA_CUTOFF`]).
pub use lemi_core::bundle::QUAD_ALPHA_CUTOFF;

/// Quad fragments whose macro-texel alpha is below this and not below [`QUAD_ALPHA_CUTOFF`] are
/// outline fringe, drawn in a pass of their own ([`lemi_core::bundle::QUAD_FULL_ALPHA`]).
pub use lemi_core::bundle::QUAD_FULL_ALPHA;

/// One quad corner on the GPU (44 bytes): world position, macro-texture coordinates, the quad's
/// rectangle in its macro-texture and where that macro-texture lies in its atlas page.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub(super) struct QuadVertex {
    pub(super) position: [f32; 3],
    /// Macro-texture coordinates in texels (not normalised).
    pub(super) uv: [f32; 2],
    /// The quad's texel rectangle in the macro-texture `[x0, y0, x1, y1]` (same for all four
    /// vertices): the fragment shader clamps its fetch to it.
    pub(super) rect: [f32; 4],
    /// The macro-texture's top-left texel in its atlas page: added to the clamped texel as an
    /// integer, so the texel fetched is exactly the one of the macro-texture on its own.
    pub(super) offset: [u32; 2],
}

const QUAD_ATTRIBUTES: [wgpu::VertexAttribute; 4] = wgpu::vertex_attr_array![
    0 => Float32x3,
    1 => Float32x2,
    2 => Float32x4,
    3 => Uint32x2,
];

/// How far (in texels of its layer) every quad is grown beyond its texel rectangle (the bundle's
/// [`lemi_core::bundle::QUAD_GROWTH_TEXELS`], applied by [`Quad::drawn_vertices`], which the glTF
/// export draws too).
pub use lemi_core::bundle::QUAD_GROWTH_TEXELS;

pub(super) fn quad_vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<QuadVertex>() as wgpu::BufferAddress,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &QUAD_ATTRIBUTES,
    }
}

/// One draw call: the quads of one cube face, one kind and one atlas page, a contiguous index
/// range, drawn with the opaque pipeline (every texel of every quad passes the alpha test) or the
/// alpha-tested one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct QuadDraw {
    pub(super) page: u32,
    pub(super) first_index: u32,
    pub(super) index_count: u32,
    pub(super) opaque: bool,
    /// The draw holds the pieces of quads around their outline fringe texels (alpha in
    /// [`QUAD_ALPHA_CUTOFF`], [`QUAD_FULL_ALPHA`]), drawn in the fringe pass only.
    pub(super) fringe: bool,
    /// The draw holds fringe quads ([`Quad::fringe`]: every opaque texel is outline fringe,
    /// whatever its alpha), drawn in the fringe pass only.
    pub(super) fringe_quads: bool,
}

/// The quads of a cell on the CPU: shared vertex/index arrays, the draw calls in draw order and
/// where the macro-textures go in the atlas pages.
pub(super) struct QuadGeometry {
    pub(super) vertices: Vec<QuadVertex>,
    pub(super) indices: Vec<u32>,
    pub(super) draws: Vec<QuadDraw>,
    pub(super) atlas: Atlas,
    /// The box around each draw call's quads, for culling.
    pub(super) bounds: Vec<Bounds>,
    /// Quads drawn without the alpha test.
    pub(super) opaque_quads: usize,
}

/// Where a cell's quads are seen from, for the texel scale bounds of its draw calls: the cell
/// file's [`CellHeader::quad_origin`] and [`CellHeader::quad_reach`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeenFrom {
    pub origin: glam::DVec3,
    /// The farthest a viewpoint of the cell lies from `origin`.
    pub reach: f64,
}

impl SeenFrom {
    /// Where a cell file's quads are seen from.
    pub fn of(header: &CellHeader) -> SeenFrom {
        SeenFrom {
            origin: header.quad_origin(),
            reach: header.quad_reach(),
        }
    }
}

/// Checks the quads against `macros`, packs the macro-textures into atlas pages of at most
/// `max_side` texels per side and builds their [`QuadGeometry`] (see the module docs for the
/// order).
pub(super) fn quad_geometry(
    quads: &[Quad],
    macros: &[MacroTexture],
    max_side: u32,
    seen_from: Option<SeenFrom>,
) -> Result<QuadGeometry, GpuError> {
    if quads.len() > (u32::MAX / 6) as usize {
        return Err(GpuError::Limit(format!(
            "{} quads are more than one cell can index",
            quads.len()
        )));
    }
    for (k, q) in quads.iter().enumerate() {
        let Some(m) = macros.get(q.macro_index as usize) else {
            return Err(GpuError::Invalid(format!(
                "quad {k} uses macro-texture {} but the cell has {} macro-textures",
                q.macro_index,
                macros.len()
            )));
        };
        let [x, y, w, h] = q.rect;
        if w == 0
            || h == 0
            || x as u64 + w as u64 > m.width as u64
            || y as u64 + h as u64 > m.height as u64
        {
            return Err(GpuError::Invalid(format!(
                "quad {k} has texel rectangle {:?} (x, y, w, h), empty or outside its {}x{} macro-texture {}",
                q.rect, m.width, m.height, q.macro_index
            )));
        }
        if !q.corners.iter().flatten().all(|c| c.is_finite()) {
            return Err(GpuError::Invalid(format!(
                "quad {k} has non-finite corners {:?}",
                q.corners
            )));
        }
    }
    let (opaque, fringe): (Vec<bool>, Vec<bool>) = quads
        .iter()
        .map(|q| {
            macros
                .get(q.macro_index as usize)
                .map_or((false, false), |m| rect_kinds(m, q.rect))
        })
        .unzip();
    let sizes: Vec<(u32, u32)> = macros.iter().map(|m| (m.width, m.height)).collect();
    let atlas = atlas::pack(&sizes, max_side)?;
    let place = |q: &Quad| atlas.places.get(q.macro_index as usize).copied();
    // each quad's texel scale bound as drawn (grown), from the cell's origin when known
    let scales: Vec<Option<TexelScale>> = quads
        .iter()
        .map(|q| {
            let corners = q
                .drawn_vertices()
                .map(|(p, _)| glam::Vec3::from_array(p).as_dvec3());
            let w = (q.texels[2].saturating_sub(q.texels[0])).max(1) as f64;
            let h = (q.texels[3].saturating_sub(q.texels[1])).max(1) as f64;
            let g = 2.0 * QUAD_GROWTH_TEXELS;
            seen_from.and_then(|v| TexelScale::of_quad(v.origin, corners, [w + g, h + g]))
        })
        .collect();
    let reach = seen_from.map_or(0.0, |v| v.reach);
    let largest_texels = (scales.iter().flatten())
        .map(|s| s.factor(0.0))
        .fold(f64::INFINITY, f64::min);
    let band: Vec<u8> = (scales.iter())
        .map(|s| scale_band(s, reach, largest_texels))
        .collect();
    let order = draw_order(quads, &opaque, &band, |q| place(q).map_or(0, |p| p.page));
    let mut vertices = Vec::with_capacity(4 * quads.len());
    let mut indices = Vec::with_capacity(6 * quads.len());
    let mut draws: Vec<QuadDraw> = Vec::new();
    let mut bounds: Vec<Bounds> = Vec::new();
    let mut run = None;
    for &k in order.iter().filter(|&&k| !quads[k].fringe) {
        let q = &quads[k];
        let base = vertices.len() as u32;
        let [x, y, rw, rh] = q.rect;
        let rect = [x as f32, y as f32, (x + rw) as f32, (y + rh) as f32];
        let first = indices.len() as u32;
        let Some(at) = place(q) else {
            continue; // checked above: every quad's macro-texture exists
        };
        let offset = [at.x, at.y];
        let new = QuadDraw {
            page: at.page,
            first_index: first,
            index_count: 0,
            opaque: opaque[k],
            fringe: false,
            fringe_quads: false,
        };
        let key = (q.face, opaque[k], at.page, band[k]);
        let (d, b) = draw_of(
            &mut draws,
            &mut bounds,
            &mut run,
            key,
            new,
            scales[k],
            seen_from,
        );
        for (position, uv) in q.drawn_vertices() {
            b.add(glam::Vec3::from_array(position).as_dvec3());
            vertices.push(QuadVertex {
                position,
                uv,
                rect,
                offset,
            });
        }
        indices.extend([0, 1, 2, 0, 2, 3].map(|i| base + i));
        d.index_count += 6;
    }
    // the outline fringe, drawn in the fringe pass alone: per quad that has fringe texels,
    // pieces of it around them only (runs of FRINGE_BLOCK² texel blocks), and the fringe quads
    // whole
    let mut run = None;
    for &k in order.iter().filter(|&&k| fringe[k] || quads[k].fringe) {
        let q = &quads[k];
        let (Some(at), Some(m)) = (place(q), macros.get(q.macro_index as usize)) else {
            continue;
        };
        let [x, y, rw, rh] = q.rect;
        let rect = [x as f32, y as f32, (x + rw) as f32, (y + rh) as f32];
        let new = QuadDraw {
            page: at.page,
            first_index: indices.len() as u32,
            index_count: 0,
            opaque: false,
            fringe: true,
            fringe_quads: q.fringe,
        };
        let key = (q.face, at.page, band[k], q.fringe);
        let (d, b) = draw_of(
            &mut draws,
            &mut bounds,
            &mut run,
            key,
            new,
            scales[k],
            seen_from,
        );
        let pieces = match q.fringe {
            true => Vec::new(),
            false => fringe_pieces(m, q.rect),
        };
        let whole = q.fringe.then(|| q.drawn_vertices());
        for corners in pieces
            .into_iter()
            .map(|p| piece_vertices(q, p))
            .chain(whole)
        {
            let base = vertices.len() as u32;
            for (position, uv) in corners {
                b.add(glam::Vec3::from_array(position).as_dvec3());
                vertices.push(QuadVertex {
                    position,
                    uv,
                    rect,
                    offset: [at.x, at.y],
                });
            }
            indices.extend([0, 1, 2, 0, 2, 3].map(|i| base + i));
            d.index_count += 6;
        }
    }
    Ok(QuadGeometry {
        vertices,
        indices,
        draws,
        atlas,
        bounds,
        opaque_quads: (opaque.iter().zip(quads))
            .filter(|(&o, q)| o && !q.fringe)
            .count(),
    })
}

/// The draw call a quad of run `key` goes into, with its bounds: `new` (and new bounds) when the
/// key differs from the last quad's (`run`), else the last one; the quad's texel scale bound
/// (`scale`; `None`: unbounded) joins the draw call's.
fn draw_of<'a, K: PartialEq>(
    draws: &'a mut Vec<QuadDraw>,
    bounds: &'a mut Vec<Bounds>,
    run: &mut Option<K>,
    key: K,
    new: QuadDraw,
    scale: Option<TexelScale>,
    seen_from: Option<SeenFrom>,
) -> (&'a mut QuadDraw, &'a mut Bounds) {
    let reach = seen_from.map_or(0.0, |v| v.reach);
    if run.as_ref() != Some(&key) || draws.is_empty() || bounds.len() != draws.len() {
        *run = Some(key);
        draws.push(new);
        bounds.push(Bounds {
            texel_scale: scale.map(|s| TexelScaleTable::new(reach, s)),
            origin: seen_from.map_or(glam::DVec3::ZERO, |v| v.origin),
            ..Bounds::EMPTY
        });
    } else if let (Some(b), Some(s)) = (bounds.last_mut(), scale) {
        if let Some(t) = &mut b.texel_scale {
            t.add(s);
        }
    }
    let n = draws.len() - 1;
    let b = &mut bounds[n];
    if scale.is_none() {
        b.texel_scale = None;
    }
    (&mut draws[n], b)
}

/// Side in texels of the blocks the fringe pass draws around outline fringe texels: the grid
/// the bake cuts fringe quads on, so both forms of the fringe are drawn in the same pieces.
const FRINGE_BLOCK: u32 = lemi_core::compress::FRINGE_GRID;

/// The pieces of `rect` (`[x, y, w, h]` in `m`) the fringe pass draws: every [`FRINGE_BLOCK`]²
/// block (clipped to the rectangle) that holds an outline fringe texel, runs of them along a
/// block row merged, as `[x0, y0, x1, y1]` in macro-texels.
fn fringe_pieces(m: &MacroTexture, rect: [u32; 4]) -> Vec<[u32; 4]> {
    let (kept, full) = (min_alpha(QUAD_ALPHA_CUTOFF), min_alpha(QUAD_FULL_ALPHA));
    let [x, y, w, h] = rect;
    let is_fringe = |tx: u32, ty: u32| {
        let i = 4 * (ty as usize * m.width as usize + tx as usize) + 3;
        m.rgba.get(i).is_some_and(|a| (kept..full).contains(a))
    };
    let mut pieces = Vec::new();
    for y0 in (y..y + h).step_by(FRINGE_BLOCK as usize) {
        let y1 = (y0 + FRINGE_BLOCK).min(y + h);
        let mut open: Option<u32> = None;
        for x0 in (x..x + w).step_by(FRINGE_BLOCK as usize) {
            let x1 = (x0 + FRINGE_BLOCK).min(x + w);
            let hit = (y0..y1).any(|ty| (x0..x1).any(|tx| is_fringe(tx, ty)));
            match (hit, open) {
                (true, None) => open = Some(x0),
                (false, Some(start)) => {
                    pieces.push([start, y0, x0, y1]);
                    open = None;
                }
                _ => {}
            }
        }
        if let Some(start) = open {
            pieces.push([start, y0, x + w, y1]);
        }
    }
    pieces
}

/// The drawn corners of the part `piece` (`[x0, y0, x1, y1]` in macro-texels, inside the quad's
/// rectangle) of quad `q`, grown like the quad by [`QUAD_GROWTH_TEXELS`]: world positions from the
/// quad's affine map of macro-texture coordinates (its corners and theirs, rotated or not), as
/// [`Quad::drawn_vertices`] gives them for the whole rectangle.
fn piece_vertices(q: &Quad, piece: [u32; 4]) -> [([f32; 3], [f32; 2]); 4] {
    use glam::{DMat2, DVec2, DVec3};
    let uv = q
        .macro_texel_corners()
        .map(|t| DVec2::new(t[0] as f64, t[1] as f64));
    let p = q.corners.map(|c| DVec3::from_array(c.map(f64::from)));
    // macro-texture coordinates → (a, b) along the quad's edges 0→1 and 0→3
    let to_edges = DMat2::from_cols(uv[1] - uv[0], uv[3] - uv[0]).inverse();
    let g = QUAD_GROWTH_TEXELS;
    let [x0, y0, x1, y1] = piece.map(f64::from);
    let corners = [
        (x0 - g, y0 - g),
        (x1 + g, y0 - g),
        (x1 + g, y1 + g),
        (x0 - g, y1 + g),
    ];
    corners.map(|(u, v)| {
        let ab = to_edges * (DVec2::new(u, v) - uv[0]);
        let pos = p[0] + (p[1] - p[0]) * ab.x + (p[3] - p[0]) * ab.y;
        (pos.as_vec3().to_array(), [u as f32, v as f32])
    })
}

/// What a frame needs to know of one draw call's quads: the axis-aligned box around them (their
/// vertices as uploaded), for culling, and the bound of their texel scale, for the choice of
/// pipeline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Bounds {
    pub(super) min: glam::DVec3,
    pub(super) max: glam::DVec3,
    /// Relative to the cell's [`Bounds::origin`]; `None` where no bound is known (no origin was
    /// given, or a quad it does not apply to): the draw keeps the texel filter.
    pub(super) texel_scale: Option<TexelScaleTable>,
    /// The point [`Bounds::texel_scale`] is relative to (the cell's
    /// [`lemi_core::bundle::CellHeader::quad_origin`]).
    pub(super) origin: glam::DVec3,
}

/// Where a quad's texels may take the nearest-texel pipeline: the footprint filter takes the texel
/// under the pixel's centre wherever a pixel step spans at most half a texel
/// (`impostor.wgsl`, `quad_color`), so a draw whose bound stays under that writes the same pixels
/// with either pipeline. The bound is exact math; the GPU's differences of f32 texture
/// coordinates, and the helper pixels of a 2×2 quad just outside a quad's edge, differ from it
/// by far less than the 1 % kept in hand.
pub(super) const NEAREST_BELOW_TEXELS_PER_PIXEL: f64 = 0.5 / 1.01;

impl Bounds {
    pub(super) const EMPTY: Bounds = Bounds {
        min: glam::DVec3::splat(f64::INFINITY),
        max: glam::DVec3::splat(f64::NEG_INFINITY),
        texel_scale: None,
        origin: glam::DVec3::ZERO,
    };

    /// Whether every quad of the draw shows texels of at least two pixels to an eye at `eye`
    /// whose pixels subtend at most `pixel_angle` ([`lemi_core::texel_scale::pixel_angle`] of the view), so
    /// that the footprint filter would take the texel under each pixel's centre, as nearest
    /// sampling does.
    pub(super) fn texels_magnified(&self, eye: glam::DVec3, pixel_angle: f64) -> bool {
        self.texel_scale.is_some_and(|s| {
            s.texels_per_pixel(eye.distance(self.origin), pixel_angle)
                <= NEAREST_BELOW_TEXELS_PER_PIXEL
        })
    }

    fn add(&mut self, p: glam::DVec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// Whether the box lies entirely outside one of the clip volume's planes of `view_proj`
    /// (`-w ≤ x, y ≤ w`, `0 ≤ z ≤ w`), by a margin far above the f32 error of the GPU's vertex
    /// transform, so that a culled draw call could not have produced a single fragment: culling
    /// never changes the image.
    pub(super) fn outside(&self, view_proj: &glam::DMat4) -> bool {
        lemi_core::frustum::box_outside(self.min, self.max, view_proj)
    }
}

/// The smallest macro-texel alpha (0..=255) with `a / 255 ≥ cutoff`.
fn min_alpha(cutoff: f32) -> u8 {
    (0..=255u8)
        .find(|&a| a as f32 / 255.0 >= cutoff)
        .unwrap_or(255)
}

/// Whether every texel of `rect` (`[x, y, w, h]`, inside `m`) passes the alpha test, so the quad
/// can be drawn without it: the opaque pipeline then writes exactly what the alpha-tested one
/// would (the fetch is clamped to the rectangle, so even the grown rim shows only these texels).
/// And whether some texel of it is outline fringe (alpha in [`QUAD_ALPHA_CUTOFF`],
/// [`QUAD_FULL_ALPHA`]), for the fringe pass. Returns `(opaque, fringe)`.
fn rect_kinds(m: &MacroTexture, rect: [u32; 4]) -> (bool, bool) {
    let (kept, full) = (min_alpha(QUAD_ALPHA_CUTOFF), min_alpha(QUAD_FULL_ALPHA));
    let [x, y, w, h] = rect.map(|v| v as usize);
    let stride = 4 * m.width as usize;
    let (mut opaque, mut fringe) = (true, false);
    for row in y..y + h {
        let start = row * stride + 4 * x;
        let Some(px) = m.rgba.get(start..start + 4 * w) else {
            return (false, false);
        };
        for t in px.chunks_exact(4) {
            opaque &= t[3] >= full;
            fringe |= (kept..full).contains(&t[3]);
        }
    }
    (opaque, fringe)
}

/// The order quads are drawn in, as indices into `quads` (see the module docs): by face (so that
/// a view culls the faces it does not see), the opaque quads before the alpha-tested ones, by
/// atlas page (`page_of`), by texel scale band (`band`, [`scale_band`]), so that each (face, kind,
/// page, band) run is one draw call; within a run the nearest layer first (a quad's `layer`
/// counts far to near) so that depth rejection skips what nearer layers hide, then by
/// macro-texture; ties keep the cell's order.
///
/// Two quads of one layer and one band are drawn in the same relative order as when every
/// (layer, face, kind, macro-texture) run was its own draw call: face, then kind, then
/// macro-texture (pages aside, which only a cell larger than one page has). Only quads of one
/// layer can meet at bit-equal depths (where their grown rims overlap), where the one drawn
/// first shows; quads of different layers never do, so the order of layers between kinds and
/// bands changes no pixel.
fn draw_order(
    quads: &[Quad],
    opaque: &[bool],
    band: &[u8],
    page_of: impl Fn(&Quad) -> u32,
) -> Vec<usize> {
    let mut order: Vec<usize> = (0..quads.len()).collect();
    order.sort_by_key(|&k| {
        (
            quads[k].face,
            !opaque[k],
            page_of(&quads[k]),
            band[k],
            std::cmp::Reverse(quads[k].layer),
            quads[k].macro_index,
        )
    });
    order
}

/// The band of a quad: 0 where its texels, seen from anywhere within `reach` of the origin,
/// subtend at least half the angle of the cell's largest texels seen from the origin
/// (`largest`, the smallest [`TexelScale::factor`] at the origin: a cube face's central
/// texels), 1 elsewhere; quads without a bound are a band of their own. A view in which the
/// largest texels span four pixels or more (the paper's 512² layers for a 1280 px, 60° view:
/// 4.3) draws band 0 with nearest texels from anywhere in the cell; band 1 (the rims of the
/// faces, and of the nearest layers more of them) whenever its own bound allows. Two bands keep
/// a cell of 4 faces at 16 draw calls (opaque and alpha-tested).
fn scale_band(scale: &Option<TexelScale>, reach: f64, largest: f64) -> u8 {
    match scale {
        Some(s) if s.factor(reach) <= 2.0 * largest => 0,
        Some(_) => 1,
        None => u8::MAX,
    }
}

/// A cell's impostor data checked and laid out for the GPU, on the CPU only (no GPU work, `Send`):
/// the near geometry copied out of the scene, the quads' vertex and index arrays and draw calls,
/// and the decoded macro-textures. Built by [`ImpostorCellData::prepare`], typically on a
/// background thread; uploaded with [`ImpostorCell::begin_upload`] and
/// [`PendingImpostorCell::upload_step`].
pub struct ImpostorCellData {
    pub(super) near_meshes: Vec<Mesh>,
    pub(super) geometry: QuadGeometry,
    pub(super) macros: Vec<MacroTexture>,
    /// The macro-textures as stored block-compressed, uploaded as they are
    /// ([`ImpostorCellData::with_blocks`]); the RGBA8 copies are then dropped.
    pub(super) blocks: Option<Vec<BlockMacro>>,
    pub(super) quad_count: usize,
}

impl ImpostorCellData {
    /// Checks and lays out a cell's data, everything but the adapter's limits (those are checked
    /// by [`ImpostorCell::begin_upload`]; [`ImpostorCell::upload`] runs both). A near list entry naming a mesh or triangle `scene` lacks is [`GpuError::Extract`]; a
    /// macro-texture whose data does not match its size, a `macro_index` out of range, an empty
    /// `rect` or one outside its macro-texture and non-finite corners are [`GpuError::Invalid`].
    pub fn prepare(
        scene: &Scene,
        near: &[[u32; 2]],
        quads: &[Quad],
        macros: Vec<MacroTexture>,
    ) -> Result<ImpostorCellData, GpuError> {
        Self::prepare_for(scene, near, quads, macros, DEFAULT_PAGE_SIDE, None)
    }

    /// [`ImpostorCellData::prepare`] with atlas pages of at most `max_side` texels per side (the
    /// adapter's texture side; [`ImpostorCell::begin_upload`] checks the pages against it) and,
    /// with `seen_from` (from the cell file's header, [`SeenFrom::of`]), each face's draw calls
    /// split in two bands of their texel scale, with a bound of it for any eye
    /// ([`lemi_core::texel_scale`]): a frame then draws with nearest texels every draw call whose
    /// texels span two pixels or more, where the footprint filter would take the texel under
    /// each pixel's centre anyway (the same pixels, without the filter's cost). Without
    /// `seen_from` every draw call keeps the texel filter.
    pub fn prepare_for(
        scene: &Scene,
        near: &[[u32; 2]],
        quads: &[Quad],
        macros: Vec<MacroTexture>,
        max_side: u32,
        seen_from: Option<SeenFrom>,
    ) -> Result<ImpostorCellData, GpuError> {
        let near: Vec<TriRef> = near.iter().map(|&pair| TriRef::from(pair)).collect();
        let near_meshes = scene.extract(&near)?;
        for (i, m) in macros.iter().enumerate() {
            let expected = m.width as u64 * m.height as u64 * 4;
            if m.width == 0 || m.height == 0 || m.rgba.len() as u64 != expected {
                return Err(GpuError::Invalid(format!(
                    "macro-texture {i} is {}x{} but has {} bytes of RGBA8 data (expected {expected})",
                    m.width,
                    m.height,
                    m.rgba.len()
                )));
            }
        }
        let geometry = quad_geometry(quads, &macros, max_side, seen_from)?;
        Ok(ImpostorCellData {
            near_meshes,
            geometry,
            macros,
            blocks: None,
            quad_count: quads.len(),
        })
    }

    /// Uploads the macro-textures as the block-compressed `blocks` of the cell file
    /// (`CellFile::block_macros`: the same macro-textures, in order) instead of the RGBA8 data
    /// they were prepared with, which is dropped (the quads' layout, made from it, stays). For an
    /// adapter with the format ([`crate::Gpu::has_block_format`]; [`ImpostorCell::begin_upload`] refuses
    /// the cell otherwise). Sizes that differ from the RGBA8 ones, or that are not multiples of
    /// 4, are [`GpuError::Invalid`].
    pub fn with_blocks(mut self, blocks: Vec<BlockMacro>) -> Result<ImpostorCellData, GpuError> {
        if blocks.len() != self.macros.len() {
            return Err(GpuError::Invalid(format!(
                "{} block-compressed macro-textures for {} macro-textures",
                blocks.len(),
                self.macros.len()
            )));
        }
        for (i, (b, m)) in blocks.iter().zip(&self.macros).enumerate() {
            let expected = b.format.image_bytes(b.width, b.height);
            if (b.width, b.height) != (m.width, m.height)
                || b.width % 4 != 0
                || b.height % 4 != 0
                || b.data.len() != expected
            {
                return Err(GpuError::Invalid(format!(
                    "block-compressed macro-texture {i} is {}x{} with {} bytes ({expected} expected), \
                     the macro-texture {}x{} (sides must be multiples of 4)",
                    b.width,
                    b.height,
                    b.data.len(),
                    m.width,
                    m.height
                )));
            }
        }
        for m in &mut self.macros {
            m.rgba = Vec::new();
        }
        self.blocks = Some(blocks);
        Ok(self)
    }

    pub fn quad_count(&self) -> usize {
        self.quad_count
    }

    /// Triangles of the near geometry.
    pub fn near_triangles(&self) -> u64 {
        self.near_meshes
            .iter()
            .map(|m| m.indices.len() as u64 / 3)
            .sum()
    }

    /// Bytes of macro-texture data (RGBA8, or the blocks with [`ImpostorCellData::with_blocks`]),
    /// what the GPU will hold as textures.
    pub fn texture_bytes(&self) -> u64 {
        match &self.blocks {
            Some(b) => b.iter().map(|b| b.data.len() as u64).sum(),
            None => self.macros.iter().map(|m| m.rgba.len() as u64).sum(),
        }
    }

    /// Bytes of vertex and index data (near geometry and quads), uploaded by
    /// [`ImpostorCell::begin_upload`] in one go.
    pub fn geometry_bytes(&self) -> u64 {
        let near: u64 = self
            .near_meshes
            .iter()
            .map(|m| {
                std::mem::size_of_val(m.vertices.as_slice()) as u64
                    + std::mem::size_of_val(m.indices.as_slice()) as u64
            })
            .sum();
        near + std::mem::size_of_val(self.geometry.vertices.as_slice()) as u64
            + std::mem::size_of_val(self.geometry.indices.as_slice()) as u64
    }

    /// Bytes this value holds in main memory (texture plus geometry data; small bookkeeping not
    /// counted).
    pub fn cpu_bytes(&self) -> u64 {
        self.texture_bytes() + self.geometry_bytes()
    }

    /// The largest macro-texture's bytes (how much [`PendingImpostorCell`] may hold twice, on the
    /// CPU and the GPU, while it uploads).
    pub fn largest_texture_bytes(&self) -> u64 {
        match &self.blocks {
            Some(b) => b.iter().map(|b| b.data.len() as u64).max(),
            None => self.macros.iter().map(|m| m.rgba.len() as u64).max(),
        }
        .unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lemi_core::Face;

    fn quad(macro_index: u32, layer: u16, rect: [u32; 4]) -> Quad {
        Quad {
            fringe: false,
            face: Face::NegZ,
            layer,
            texels: [0, 0, rect[2] as u16, rect[3] as u16],
            corners: [[0.0; 3]; 4],
            macro_index,
            rect,
            rotated: false,
        }
    }

    fn macro_texture(width: u32, height: u32) -> MacroTexture {
        MacroTexture {
            width,
            height,
            rgba: vec![0; (width * height * 4) as usize],
        }
    }

    fn opaque_macro(width: u32, height: u32) -> MacroTexture {
        MacroTexture {
            width,
            height,
            rgba: [9, 9, 9, 255].repeat((width * height) as usize),
        }
    }

    fn set_alpha(m: &mut MacroTexture, x: u32, y: u32, a: u8) {
        m.rgba[(4 * (y * m.width + x) + 3) as usize] = a;
    }

    #[test]
    fn quads_draw_by_face_and_kind_nearest_layer_first() {
        let mut m0 = opaque_macro(8, 8);
        set_alpha(&mut m0, 3, 3, 0);
        set_alpha(&mut m0, 5, 0, 128); // 128/255 ≥ 0.5 but < 0.75: outline fringe
        set_alpha(&mut m0, 6, 0, 127); // 127/255 < 0.5: discarded
        set_alpha(&mut m0, 0, 1, 192); // 192/255 ≥ 0.75: drawn everywhere
        assert_eq!(min_alpha(QUAD_ALPHA_CUTOFF), 128);
        assert_eq!(min_alpha(QUAD_FULL_ALPHA), 192);
        let macros = [m0, opaque_macro(4, 4)];
        let quads = [
            quad(0, 1, [0, 0, 2, 2]), // alpha 255 and 192: opaque
            quad(1, 5, [0, 0, 4, 4]), // opaque
            quad(0, 3, [2, 2, 2, 2]), // holds (3, 3): alpha-tested
            quad(0, 1, [6, 0, 1, 1]), // alpha 127: alpha-tested
            quad(0, 1, [4, 0, 2, 1]), // alpha 255 and 128: alpha-tested, with fringe
            quad(1, 1, [0, 0, 2, 2]), // opaque
        ];
        let QuadGeometry {
            vertices: v,
            indices: i,
            draws,
            atlas,
            bounds,
            opaque_quads,
        } = quad_geometry(&quads, &macros, 64, None).expect("valid quads");
        assert_eq!(bounds.len(), draws.len());
        assert_eq!(opaque_quads, 3);
        assert_eq!(v.len(), 28);
        assert_eq!(i.len(), 42);
        let d = |first_index, quads: u32, opaque, fringe| QuadDraw {
            page: 0,
            first_index,
            index_count: 6 * quads,
            opaque,
            fringe,
            fringe_quads: false,
        };
        // one face: the opaque quads 1 (layer 5), 0 (layer 1, macro 0) and 5 (layer 1, macro 1)
        // in one draw, then the alpha-tested quads 2 (layer 3), 4 and 3 (layer 1) in another,
        // then for the fringe pass the block of quad 4 around its fringe texel (all of it: a
        // 2×1 rectangle is one block)
        assert_eq!(
            draws,
            vec![
                d(0, 3, true, false),
                d(18, 3, false, false),
                d(36, 1, false, true)
            ]
        );
        // both macro-textures side by side on one page
        assert_eq!(atlas.pages, vec![(16, 8)]);
        assert_eq!(v[0].offset, [8, 0]);
        assert_eq!(v[4].offset, [0, 0]);
        assert_eq!(v[8].offset, [8, 0]);
        // the layer-3 quad (fourth): rect [2, 2, 2, 2] of 8x8, texel coordinates, grown by
        // QUAD_GROWTH_TEXELS on every side; the fetch is clamped to the rectangle
        let g = QUAD_GROWTH_TEXELS as f32;
        assert_eq!(v[12].uv, [2.0 - g, 2.0 - g]);
        assert_eq!(v[14].uv, [4.0 + g, 4.0 + g]);
        assert_eq!(v[12].rect, [2.0, 2.0, 4.0, 4.0]);
        assert_eq!(v[4].rect, [0.0, 0.0, 2.0, 2.0]);
        assert_eq!(v[20].rect, [4.0, 0.0, 6.0, 1.0]);
        assert_eq!(v[16].rect, [6.0, 0.0, 7.0, 1.0]);
        // the fringe piece of quad 4 is the whole quad as drawn: the same texel rectangle, the
        // same grown texture coordinates, the same corners up to rounding
        for c in 0..4 {
            let (piece, whole) = (v[24 + c], v[20 + c]);
            assert_eq!(
                (piece.rect, piece.uv, piece.offset),
                (whole.rect, whole.uv, whole.offset)
            );
            for a in 0..3 {
                assert!(
                    (piece.position[a] - whole.position[a]).abs() < 1e-5,
                    "{piece:?}"
                );
            }
        }
        assert_eq!(i[6..12], [4, 5, 6, 4, 6, 7]);
    }

    /// Fringe quads (BC1's outline fringe, fully opaque texels) are drawn whole in the fringe
    /// pass with their own pipeline, never in the first pass, and do not count as opaque.
    #[test]
    fn fringe_quads_are_drawn_whole_in_the_fringe_pass_only() {
        let macros = [opaque_macro(8, 8)];
        let mut fringe = quad(0, 2, [4, 4, 4, 2]);
        fringe.fringe = true;
        let quads = [quad(0, 1, [0, 0, 4, 4]), fringe];
        let g = quad_geometry(&quads, &macros, 64, None).expect("valid quads");
        assert_eq!(g.opaque_quads, 1);
        let d = |first_index, opaque, fringe, fringe_quads| QuadDraw {
            page: 0,
            first_index,
            index_count: 6,
            opaque,
            fringe,
            fringe_quads,
        };
        assert_eq!(
            g.draws,
            vec![d(0, true, false, false), d(6, false, true, true)]
        );
        // the fringe quad as any quad is drawn: its grown corners and texture coordinates
        for (c, (position, uv)) in fringe.drawn_vertices().into_iter().enumerate() {
            assert_eq!(
                (g.vertices[4 + c].position, g.vertices[4 + c].uv),
                (position, uv)
            );
            assert_eq!(g.vertices[4 + c].rect, [4.0, 4.0, 8.0, 6.0]);
        }
    }

    /// A quad of the `−Z` face layer at distance 100 around the origin, texels `rect` (x0, y0,
    /// x1, y1) of a 64² face image.
    fn face_quad(macro_index: u32, rect: [u16; 4]) -> Quad {
        let at = |x: u16, y: u16| {
            let s = |v: u16| (-1.0 + 2.0 * v as f32 / 64.0) * 100.0;
            [-s(x), -s(y), -100.0]
        };
        Quad {
            fringe: false,
            face: Face::NegZ,
            layer: 0,
            texels: rect,
            corners: [
                at(rect[0], rect[1]),
                at(rect[2], rect[1]),
                at(rect[2], rect[3]),
                at(rect[0], rect[3]),
            ],
            macro_index,
            rect: [0, 0, (rect[2] - rect[0]) as u32, (rect[3] - rect[1]) as u32],
            rotated: false,
        }
    }

    #[test]
    fn quads_near_a_face_centre_and_at_its_corner_are_drawn_in_two_bands() {
        let macros = [opaque_macro(4, 4), opaque_macro(4, 4)];
        // the corner quad first in the cell's order: the bands put the central one first
        let quads = [face_quad(0, [0, 0, 4, 4]), face_quad(1, [30, 30, 34, 34])];
        let seen = SeenFrom {
            origin: glam::DVec3::ZERO,
            reach: 5.0,
        };
        let banded = quad_geometry(&quads, &macros, 64, Some(seen)).expect("quads");
        assert_eq!(banded.draws.len(), 2);
        assert_eq!(banded.vertices[0].rect, [0.0, 0.0, 4.0, 4.0]);
        let [centre, corner] = [0, 1].map(|k| banded.bounds[k].texel_scale.expect("bound"));
        // the corner's texels look about three times smaller (g² = 3) from the origin
        let ratio = corner.texels_per_pixel(0.0, 1.0) / centre.texels_per_pixel(0.0, 1.0);
        assert!((2.5..3.1).contains(&ratio), "{ratio}");
        // the central quad's macro-texture (1) is drawn first
        assert_eq!(
            banded.vertices[0].offset,
            [banded.atlas.places[1].x, banded.atlas.places[1].y]
        );
        // without knowing where the cell is seen from: one draw call, no bound, the cell's order
        let plain = quad_geometry(&quads, &macros, 64, None).expect("quads");
        assert_eq!(plain.draws.len(), 1);
        assert_eq!(plain.bounds[0].texel_scale, None);
        assert_eq!(
            plain.vertices[0].offset,
            [plain.atlas.places[0].x, plain.atlas.places[0].y]
        );
    }

    #[test]
    fn empty_bounds_are_outside_every_view() {
        // the box test itself is lemi_core::frustum's (tested there); a draw call without
        // vertices is never drawn
        let view = lemi_core::camera::Camera::new(
            glam::DVec3::ZERO,
            -glam::DVec3::Z,
            glam::DVec3::Y,
            90.0,
            64,
            64,
        )
        .expect("camera")
        .view();
        assert!(Bounds::EMPTY.outside(&view.view_proj()));
    }

    #[test]
    fn bad_rects_are_errors() {
        let macros = [macro_texture(8, 8)];
        for rect in [
            [0, 0, 0, 2],
            [7, 0, 2, 1],
            [0, 0, 8, 9],
            [u32::MAX, 0, 2, 2],
        ] {
            let r = quad_geometry(&[quad(0, 0, rect)], &macros, 64, None);
            assert!(matches!(r, Err(GpuError::Invalid(_))), "{rect:?}");
        }
        assert!(quad_geometry(&[quad(0, 0, [0, 0, 8, 8])], &macros, 64, None).is_ok());
        // a macro-texture larger than the pages may be
        assert!(matches!(
            quad_geometry(&[quad(0, 0, [0, 0, 8, 8])], &macros, 4, None),
            Err(GpuError::Limit(_))
        ));
    }
}
