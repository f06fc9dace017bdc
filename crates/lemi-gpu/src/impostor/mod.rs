//! The impostor renderer: what the runtime shows for one baked view cell. The cell's near geometry
//! is drawn as real triangles, the far field as the cell's layered impostor quads, both in one
//! submission.
//!
//! Based on the runtime of *Layered Environment-Map Impostors for Arbitrary Scenes* (Jeschke,
//! Wimmer et al., GI 2002, sec. 3): inside a view cell the viewer sees the near geometry plus, per
//! cube face, concentric layers of textured quads; the quads are alpha-tested (a layer only holds
//! what its slab contains) and depth-tested against each other and the near geometry, so no sorting
//! or blending is needed.
//!
//! - Near geometry: the triangles of the cell's near list are copied out of the scene (vertices
//!   re-indexed per source mesh, [`Scene::extract`]), uploaded with [`GpuGeometry::upload`] against the scene's
//!   materials, and drawn with the reference renderer's shader source and pipeline state (shared
//!   shading module, no culling, reverse-Z `Greater`), so they are shaded bit-identically to
//!   [`crate::Renderer`].
//! - Quads: unlit. Macro-texture texels are final sRGB-encoded colours, copied to the colour
//!   target unchanged: where the backend has texture view formats (all but GL), macro-textures
//!   are `Rgba8Unorm` and the quads are drawn through an `Rgba8Unorm` view of the sRGB colour
//!   target, so the bytes pass through without the sRGB decode and encode a software rasterizer
//!   spends much of a quad's shading on; on GL they are `Rgba8UnormSrgb` into the sRGB view,
//!   decoded on fetching and re-encoded on storing, which round-trips bit-exactly. Nearest texel
//!   (`textureLoad`), no mipmaps, clamped to the quad's rectangle. Fragments whose texel alpha is
//!   below [`QUAD_ALPHA_CUTOFF`] are discarded. Texture coordinates of a corner are
//!   [`Quad::macro_texel_corners`] (this undoes the 90° turn of rotated micro-textures). Positions
//!   are made relative to the eye before the projection, like the shading module does, so world
//!   coordinates of thousands of metres stay precise. No back-face culling.
//! - Opaque quads: a quad whose texels (in its rectangle) all pass the alpha test is drawn with a
//!   second quad pipeline without `discard` (decided on the CPU from the macro-texture data). It
//!   writes exactly what the alpha-tested pipeline would, but lets the rasterizer test and write
//!   depth before shading (Mesa's llvmpipe tests early with `discard` too, but then writes depth
//!   late and loses its fast paths); about 60 % of a city cell's quads are opaque.
//! - Macro-textures are packed once more at upload, into a few large textures (atlas pages; one
//!   for any cell of ordinary size, see `atlas`): a quad's vertices carry its macro-texture's
//!   offset in the page, added to the clamped texel as an integer, so the texel fetched is
//!   exactly the one of the macro-texture on its own.
//! - One vertex/index buffer holds all quads of a cell, in draw order: by cube face, the opaque
//!   quads before the alpha-tested ones, by atlas page, by spread band (below); within that the
//!   nearest layer first (a quad's `layer` counts far to near), so that depth rejection skips
//!   the far texels nearer layers hide, then by macro-texture; ties keep the cell's order. Each
//!   run of one face, kind, page and band is one draw call: at most 2 bands × 2 kinds per face
//!   and page whatever the layer and macro-texture counts (16 for a cell of 4 faces, 12 of them
//!   in view along an axis), so the far field's cost is its pixels, not how the bake cut it
//!   (GI 2002 sec. 1: the rendering speed of the far field decoupled from its complexity). The
//!   near geometry is drawn before all quads.
//! - Texel filter per draw call: a cell laid out with where it is seen from (the runtime's,
//!   `lemi render`'s: [`ImpostorCellData::prepare_for`] with [`SeenFrom::of`] its header) splits
//!   each face's quads into two bands (`layout::scale_band`: the quads whose texels subtend at
//!   least half the angle of the cell's largest ones from anywhere in the cell, and the rest)
//!   and keeps per draw call a bound of how many texels a pixel spans for any eye, tabulated
//!   over the eye's distance from the cell's origin ([`lemi_core::texel_scale`]). A frame
//!   evaluates it (constant time a draw call) and draws with the nearest-texel pipeline every
//!   draw call whose texels all span two pixels or more, where [`TexelFilter::Footprint`] takes
//!   the texel under the pixel's centre anyway: the same pixels without the filter's cost,
//!   which a software rasterizer pays for every pixel the filtering pipeline shades, needed or
//!   not. At the paper's settings (512² layers, a 1280 px, 60° view) that is 10-12 of the 12
//!   draw calls in view from a cell's centre and 6 from near its corners (the inner band).
//! - Draw order decides only between fragments of equal depth: where the grown rims
//!   ([`QUAD_GROWTH_TEXELS`]) of two adjacent quads of one layer overlap and their interpolated
//!   depths are bit-equal, the quad drawn first shows its edge texel. Quads of different layers
//!   never meet at equal depth, and two quads of one layer keep the relative order they had when
//!   every (layer, face, kind, macro-texture) run was a draw call of its own (face, kind,
//!   macro-texture), so merging the runs changed no pixel (checked on city bundles with
//!   `examples/frame_timing --check`). Putting opaque quads first (earlier) changed that choice
//!   for about 0.02 % of the pixels of a city frame compared with the macro-texture-then-layer
//!   order before it: each such pixel shows the edge texel of the adjacent quad of the same layer
//!   instead, one texel over. The texel scale bands change it again where two adjacent quads
//!   of one layer fall into different bands: 117 of 921,600 pixels in 1 of 16 `city:1M` frames
//!   at 1280×720, none in the others (`frame_timing --check`, nearest texels, so that only the
//!   order differs; the same with the filter). Everything else
//!   (the linear path, the opaque pipeline, culling, the texel filter's choice per draw call)
//!   changes no pixel.
//! - Culling: each draw call keeps the box around its quads; a frame skips the draw calls whose
//!   box lies wholly outside the view frustum (with a margin), which cannot change the image. A
//!   view along a cube axis then draws about one face of quads.
//! - Targets, formats and readback are those of [`crate::Renderer::render`]: sRGB colour, the
//!   linear view depth as the bits of an f32 in an `R32Uint` target, a `Depth32Float` reverse-Z
//!   depth buffer, background set to [`RenderOptions::clear`] and depth `f32::INFINITY`; frames
//!   not read back leave the view-depth target out, as the reference renderer's do. With
//!   linear quads a frame is two render passes, near geometry (sRGB view) then quads (linear
//!   view), the second loading the first's targets; timestamp queries around both give
//!   [`ImpostorRenderer::last_gpu_ms`].
//!
//! The module's parts: `layout` on the CPU (quad geometry, draw order, opaque quads, culling
//! boxes, near geometry: [`ImpostorCellData`]), `atlas` (the pages' packing), `upload` to the GPU (one path, incremental or run
//! to completion: [`ImpostorCell`], [`PendingImpostorCell`]) and `render` ([`ImpostorRenderer`]).
//!
//! [`GpuGeometry::upload`]: crate::GpuGeometry::upload
//! [`Quad::macro_texel_corners`]: lemi_core::bundle::Quad::macro_texel_corners
//! [`RenderOptions::clear`]: crate::RenderOptions::clear
//! [`Scene::extract`]: lemi_core::Scene::extract

mod atlas;
mod layout;
mod render;
#[cfg(test)]
mod test_support;
mod upload;

pub use layout::{
    ImpostorCellData, SeenFrom, DEFAULT_PAGE_SIDE, QUAD_ALPHA_CUTOFF, QUAD_GROWTH_TEXELS,
};
pub use render::{Composite, ImpostorRenderer, TexelFilter};
pub use upload::{ImpostorCell, PendingImpostorCell};
