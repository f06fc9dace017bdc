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
//!   re-indexed per source mesh), uploaded with [`GpuGeometry::upload`] against the scene's
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
//! - One vertex/index buffer holds all quads of a cell, in draw order: nearest layer first (a
//!   quad's `layer` counts far to near), so that depth rejection skips the far texels nearer
//!   layers hide; within a layer the opaque quads first, by macro-texture, then the alpha-tested
//!   ones; ties keep the cell's order. Each run of one layer, kind and macro-texture is one draw
//!   call (a few per layer). The near geometry is drawn before all quads.
//! - Draw order decides only between fragments of equal depth: where the grown rims
//!   ([`QUAD_GROWTH_TEXELS`]) of two adjacent quads of one layer overlap and their interpolated
//!   depths are bit-equal, the quad drawn first shows its edge texel. Putting opaque quads first
//!   changed that choice for about 0.02 % of the pixels of a city frame (at most 0.05 %) compared
//!   with the earlier macro-texture-then-layer order: each such pixel keeps its depth bits and
//!   shows the edge texel of the adjacent quad of the same layer instead, one texel over (which
//!   neighbour wins an exact tie was arbitrary before too). Everything else (the linear path,
//!   the opaque pipeline, culling) changes no pixel.
//! - Culling: each draw call keeps the box around its quads; a frame skips the draw calls whose
//!   box lies wholly outside the view frustum (with a margin), which cannot change the image. A
//!   view along a cube axis then draws about one face of quads.
//! - Targets, formats and readback are those of [`crate::Renderer::render`]: sRGB colour, the
//!   linear view depth as the bits of an f32 in an `R32Uint` target, a `Depth32Float` reverse-Z
//!   depth buffer, background set to [`RenderOptions::clear`] and depth `f32::INFINITY`. With
//!   linear quads a frame is two render passes, near geometry (sRGB view) then quads (linear
//!   view), the second loading the first's targets; timestamp queries around both give
//!   [`ImpostorRenderer::last_gpu_ms`].

use std::sync::{Arc, Mutex};

use bytemuck::{Pod, Zeroable};
use lemi_core::bundle::Quad;
use lemi_core::camera::View;
use lemi_core::compress::MacroTexture;
use lemi_core::{Mesh, Scene};
use wgpu::util::DeviceExt;

use crate::renderer::{
    Frame, GpuTime, RenderOptions, COLOR_FORMAT, DEPTH_FORMAT, VIEW_DEPTH_FORMAT,
};
use crate::scene::{GpuGeometry, GpuMaterials, GpuScene, UploadOptions};
use crate::shading::{vertex_layout, ShadingGlobals, SHADING_WGSL};
use crate::targets::{PassPart, Targets, LINEAR_COLOR_FORMAT};
use crate::{Gpu, GpuError};

/// The reference renderer's entry points: the near geometry is drawn with exactly this source.
const RENDER_WGSL: &str = include_str!("render.wgsl");
/// The quad entry points, appended to the shading module.
const IMPOSTOR_WGSL: &str = include_str!("impostor.wgsl");

/// Quad fragments whose macro-texel alpha (0..=1) is below this are discarded.
pub const QUAD_ALPHA_CUTOFF: f32 = 0.5;

/// One quad corner on the GPU: world position and macro-texture coordinates (20 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
struct QuadVertex {
    position: [f32; 3],
    /// Macro-texture coordinates in texels (not normalised).
    uv: [f32; 2],
    /// The quad's texel rectangle in the macro-texture `[x0, y0, x1, y1]` (same for all four
    /// vertices): the fragment shader clamps its fetch to it.
    rect: [f32; 4],
}

const QUAD_ATTRIBUTES: [wgpu::VertexAttribute; 3] = wgpu::vertex_attr_array![
    0 => Float32x3,
    1 => Float32x2,
    2 => Float32x4,
];

/// How far (in texels of its layer) every quad is grown beyond its texel rectangle, so that
/// neighbouring quads overlap instead of meeting edge to edge: without it, pixels whose centre
/// falls exactly on a shared edge, a T-junction or a cube-face seam are covered by neither quad
/// (found by the no-crack test). The grown rim shows the quad's edge texels (the fetch is clamped
/// to the rectangle), so it never shows a neighbour's texels from the macro-texture.
pub const QUAD_GROWTH_TEXELS: f64 = 1.0 / 16.0;

fn quad_vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<QuadVertex>() as wgpu::BufferAddress,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &QUAD_ATTRIBUTES,
    }
}

/// Group 1 of the quad pipeline: macro-texture (binding 3) and its nearest sampler (binding 4).
/// Created by both [`ImpostorCell::upload`] and [`ImpostorRenderer::new`]; wgpu deduplicates equal
/// layouts, and WebGPU makes equal layouts compatible in any case.
fn macro_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("lemi macro-texture"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 4,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::NonFiltering),
                count: None,
            },
        ],
    })
}

/// One draw call: quads of one macro-texture, a contiguous index range, drawn with the opaque
/// pipeline (every texel of every quad passes the alpha test) or the alpha-tested one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct MacroDraw {
    macro_index: u32,
    first_index: u32,
    index_count: u32,
    opaque: bool,
}

/// GPU resources of one baked cell: its near geometry, its macro-textures and its quads.
pub struct ImpostorCell {
    near: GpuScene,
    /// Vertex and index buffer of all quads; `None` without quads.
    quad_buffers: Option<(wgpu::Buffer, wgpu::Buffer)>,
    /// One bind group per macro-texture, in the cell's order.
    macro_groups: Vec<wgpu::BindGroup>,
    /// Draw calls in draw order (nearest layer first).
    draws: Vec<MacroDraw>,
    /// The box around each draw call's quads.
    bounds: Vec<Bounds>,
    quad_count: usize,
    opaque_quads: usize,
    texture_bytes: u64,
    /// The macro-textures' format ([`macro_format`]).
    macro_format: wgpu::TextureFormat,
}

impl ImpostorCell {
    /// `materials`: the scene's materials uploaded once ([`GpuMaterials::upload`]); `scene`: the
    /// scene the cell was baked from; `near`: the cell's near list, (mesh index, triangle index)
    /// pairs into `scene.meshes` (out-of-range pairs are [`GpuError::Invalid`] naming the pair;
    /// triangles whose vertex indices are out of range are skipped, as [`GpuGeometry::upload`]
    /// does); `quads` and `macros`: from the cell file (a `macro_index` out of range, an empty
    /// `rect` or one outside its macro-texture, non-finite corners and macro-textures whose data
    /// does not match their size are [`GpuError::Invalid`]; macro-textures larger than the
    /// adapter's texture limit are [`GpuError::Limit`]).
    ///
    /// All input is checked before any GPU work.
    pub fn upload(
        gpu: &Gpu,
        materials: Arc<GpuMaterials>,
        scene: &Scene,
        near: &[[u32; 2]],
        quads: &[Quad],
        macros: &[MacroTexture],
    ) -> Result<ImpostorCell, GpuError> {
        let near_meshes = near_meshes(scene, near)?;
        let max_dim = gpu.limits().max_texture_dimension_2d;
        let mut texture_bytes = 0u64;
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
            if m.width > max_dim || m.height > max_dim {
                return Err(GpuError::Limit(format!(
                    "macro-texture {i} is {}x{}, larger than this adapter's textures ({max_dim} per side)",
                    m.width, m.height
                )));
            }
            texture_bytes += expected;
        }
        let QuadGeometry {
            vertices,
            indices,
            draws,
            bounds,
            opaque_quads,
        } = quad_geometry(quads, macros)?;
        let format = macro_format(&gpu.device);
        let limits = gpu.limits();
        let vertex_bytes = std::mem::size_of_val(vertices.as_slice()) as u64;
        let index_bytes = std::mem::size_of_val(indices.as_slice()) as u64;
        if vertex_bytes.max(index_bytes) > limits.max_buffer_size {
            return Err(GpuError::Limit(format!(
                "{} quads need a {} byte buffer, more than this adapter's {} bytes",
                quads.len(),
                vertex_bytes.max(index_bytes),
                limits.max_buffer_size
            )));
        }
        let geometry = GpuGeometry::upload(gpu, &near_meshes, &UploadOptions::default())?;
        let near = GpuScene::from_parts(materials, geometry)?;
        let (quad_buffers, macro_groups) = gpu.scoped("uploading impostor quads", || {
            let device = &gpu.device;
            let quad_buffers = (!indices.is_empty()).then(|| {
                let v = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("lemi impostor quad vertices"),
                    contents: bytemuck::cast_slice(&vertices),
                    usage: wgpu::BufferUsages::VERTEX,
                });
                let i = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("lemi impostor quad indices"),
                    contents: bytemuck::cast_slice(&indices),
                    usage: wgpu::BufferUsages::INDEX,
                });
                (v, i)
            });
            let layout = macro_layout(device);
            let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("lemi macro-texture sampler"),
                address_mode_u: wgpu::AddressMode::ClampToEdge,
                address_mode_v: wgpu::AddressMode::ClampToEdge,
                address_mode_w: wgpu::AddressMode::ClampToEdge,
                mag_filter: wgpu::FilterMode::Nearest,
                min_filter: wgpu::FilterMode::Nearest,
                mipmap_filter: wgpu::MipmapFilterMode::Nearest,
                ..Default::default()
            });
            let groups: Vec<wgpu::BindGroup> = macros
                .iter()
                .enumerate()
                .map(|(i, m)| {
                    let label = format!("lemi macro-texture {i}");
                    let view = upload_macro(gpu, &label, m, format);
                    device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some(&label),
                        layout: &layout,
                        entries: &[
                            wgpu::BindGroupEntry {
                                binding: 3,
                                resource: wgpu::BindingResource::TextureView(&view),
                            },
                            wgpu::BindGroupEntry {
                                binding: 4,
                                resource: wgpu::BindingResource::Sampler(&sampler),
                            },
                        ],
                    })
                })
                .collect();
            (quad_buffers, groups)
        })?;
        Ok(ImpostorCell {
            near,
            quad_buffers,
            macro_groups,
            draws,
            bounds,
            quad_count: quads.len(),
            opaque_quads,
            texture_bytes,
            macro_format: format,
        })
    }

    /// Triangles of the near geometry on the GPU.
    pub fn near_triangles(&self) -> u64 {
        self.near.triangle_count()
    }

    /// Impostor quads of the cell.
    pub fn quad_count(&self) -> usize {
        self.quad_count
    }

    /// Bytes of macro-texture data on the GPU (RGBA8, no mipmaps).
    pub fn texture_bytes(&self) -> u64 {
        self.texture_bytes
    }

    /// Draw calls the quads take: one per run of quads of one layer, one kind (opaque or
    /// alpha-tested) and one macro-texture.
    pub fn quad_draw_calls(&self) -> usize {
        self.draws.len()
    }

    /// Quads whose texels all pass the alpha test, drawn with the opaque pipeline (no `discard`,
    /// so the rasterizer may test and write depth before shading).
    pub fn opaque_quad_count(&self) -> usize {
        self.opaque_quads
    }
}

/// Copies the triangles of the near list out of `scene`, one mesh per referenced source mesh (same
/// material, vertices re-indexed, triangles in near-list order).
fn near_meshes(scene: &Scene, near: &[[u32; 2]]) -> Result<Vec<Mesh>, GpuError> {
    for (k, &[m, t]) in near.iter().enumerate() {
        let Some(mesh) = scene.meshes.get(m as usize) else {
            return Err(GpuError::Invalid(format!(
                "near list entry {k} (mesh {m}, triangle {t}) names a mesh past the scene's {} meshes",
                scene.meshes.len()
            )));
        };
        if t as usize >= mesh.triangle_count() {
            return Err(GpuError::Invalid(format!(
                "near list entry {k} (mesh {m}, triangle {t}) names a triangle past mesh {m}'s {} triangles",
                mesh.triangle_count()
            )));
        }
    }
    let mut order: Vec<[u32; 2]> = near.to_vec();
    order.sort_by_key(|p| p[0]); // stable: near-list order within a mesh
    let mut out = Vec::new();
    let mut remap: Vec<u32> = Vec::new();
    for group in order.chunk_by(|a, b| a[0] == b[0]) {
        let Some(src) = group.first().and_then(|p| scene.meshes.get(p[0] as usize)) else {
            continue;
        };
        remap.clear();
        remap.resize(src.vertices.len(), u32::MAX);
        let mut mesh = Mesh {
            material: src.material,
            vertices: Vec::new(),
            indices: Vec::with_capacity(group.len() * 3),
        };
        for &[_, t] in group {
            let t = t as usize;
            let Some(tri) = src.indices.get(3 * t..3 * t + 3) else {
                continue;
            };
            if tri.iter().any(|&i| i as usize >= src.vertices.len()) {
                continue;
            }
            for &i in tri {
                let i = i as usize;
                if remap[i] == u32::MAX {
                    remap[i] = mesh.vertices.len() as u32;
                    mesh.vertices.push(src.vertices[i]);
                }
                mesh.indices.push(remap[i]);
            }
        }
        if !mesh.indices.is_empty() {
            out.push(mesh);
        }
    }
    Ok(out)
}

/// The quads of a cell on the CPU: shared vertex/index arrays and the draw calls in draw order.
struct QuadGeometry {
    vertices: Vec<QuadVertex>,
    indices: Vec<u32>,
    draws: Vec<MacroDraw>,
    /// The box around each draw call's quads, for culling.
    bounds: Vec<Bounds>,
    /// Quads drawn without the alpha test.
    opaque_quads: usize,
}

/// Checks the quads against `macros` and builds their [`QuadGeometry`] (see the module docs for
/// the order).
fn quad_geometry(quads: &[Quad], macros: &[MacroTexture]) -> Result<QuadGeometry, GpuError> {
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
    let opaque: Vec<bool> = quads
        .iter()
        .map(|q| {
            macros
                .get(q.macro_index as usize)
                .is_some_and(|m| rect_opaque(m, q.rect))
        })
        .collect();
    let order = draw_order(quads, &opaque);
    let mut vertices = Vec::with_capacity(4 * quads.len());
    let mut indices = Vec::with_capacity(6 * quads.len());
    let mut draws: Vec<MacroDraw> = Vec::new();
    let mut bounds: Vec<Bounds> = Vec::new();
    let mut run = None;
    for &k in &order {
        let q = &quads[k];
        let base = vertices.len() as u32;
        let uv = q
            .macro_texel_corners()
            .map(|t| glam::DVec2::new(t[0] as f64, t[1] as f64));
        let p = q.corners.map(|c| glam::DVec3::from_array(c.map(f64::from)));
        // texel steps along the quad's edges (in world space and in the macro-texture)
        let (w, h) = (
            (q.texels[2].saturating_sub(q.texels[0])).max(1) as f64,
            (q.texels[3].saturating_sub(q.texels[1])).max(1) as f64,
        );
        let e = QUAD_GROWTH_TEXELS;
        let (du, dv) = ((p[1] - p[0]) * (e / w), (p[3] - p[0]) * (e / h));
        let (tu, tv) = ((uv[1] - uv[0]) * (e / w), (uv[3] - uv[0]) * (e / h));
        let signs = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        let [x, y, rw, rh] = q.rect;
        let rect = [x as f32, y as f32, (x + rw) as f32, (y + rh) as f32];
        let first = indices.len() as u32;
        let key = (q.layer, q.face, opaque[k], q.macro_index);
        if run != Some(key) {
            run = Some(key);
            draws.push(MacroDraw {
                macro_index: q.macro_index,
                first_index: first,
                index_count: 0,
                opaque: opaque[k],
            });
            bounds.push(Bounds::EMPTY);
        }
        let (Some(d), Some(b)) = (draws.last_mut(), bounds.last_mut()) else {
            continue;
        };
        for ((pk, uvk), (su, sv)) in p.iter().zip(&uv).zip(signs) {
            let pos = *pk + du * su + dv * sv;
            let t = *uvk + tu * su + tv * sv;
            let position = pos.as_vec3();
            b.add(position.as_dvec3());
            vertices.push(QuadVertex {
                position: position.to_array(),
                uv: [t.x as f32, t.y as f32],
                rect,
            });
        }
        indices.extend([0, 1, 2, 0, 2, 3].map(|i| base + i));
        d.index_count += 6;
    }
    Ok(QuadGeometry {
        vertices,
        indices,
        draws,
        bounds,
        opaque_quads: opaque.iter().filter(|&&o| o).count(),
    })
}

/// An axis-aligned box around the quads of one draw call (their vertices as uploaded).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Bounds {
    min: glam::DVec3,
    max: glam::DVec3,
}

impl Bounds {
    const EMPTY: Bounds = Bounds {
        min: glam::DVec3::splat(f64::INFINITY),
        max: glam::DVec3::splat(f64::NEG_INFINITY),
    };

    fn add(&mut self, p: glam::DVec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// Whether the box lies entirely outside one of the clip volume's planes of `view_proj`
    /// (`-w ≤ x, y ≤ w`, `0 ≤ z ≤ w`), by a margin far above the f32 error of the GPU's vertex
    /// transform, so that a culled draw call could not have produced a single fragment: culling
    /// never changes the image.
    fn outside(&self, view_proj: &glam::DMat4) -> bool {
        if !(self.min.cmple(self.max).all()) {
            return true; // empty
        }
        let corners = (0..8).map(|i| {
            let pick = |bit: usize, lo: f64, hi: f64| if i & bit == 0 { lo } else { hi };
            let p = glam::DVec3::new(
                pick(1, self.min.x, self.max.x),
                pick(2, self.min.y, self.max.y),
                pick(4, self.min.z, self.max.z),
            );
            *view_proj * p.extend(1.0)
        });
        let mut out = [true; 6];
        for c in corners {
            // plane value ≥ −margin: possibly inside
            let margin = 1e-4 * (c.x.abs() + c.y.abs() + c.z.abs() + c.w.abs()) + 1e-9;
            let planes = [c.w + c.x, c.w - c.x, c.w + c.y, c.w - c.y, c.z, c.w - c.z];
            for (o, v) in out.iter_mut().zip(planes) {
                if v >= -margin {
                    *o = false;
                }
            }
        }
        out.iter().any(|&o| o)
    }
}

/// The smallest macro-texel alpha (0..=255) the quad shader keeps: `a / 255 ≥ QUAD_ALPHA_CUTOFF`.
fn min_kept_alpha() -> u8 {
    (0..=255u8)
        .find(|&a| a as f32 / 255.0 >= QUAD_ALPHA_CUTOFF)
        .unwrap_or(255)
}

/// Whether every texel of `rect` (`[x, y, w, h]`, inside `m`) passes the alpha test, so the quad
/// can be drawn without it: the opaque pipeline then writes exactly what the alpha-tested one
/// would (the fetch is clamped to the rectangle, so even the grown rim shows only these texels).
fn rect_opaque(m: &MacroTexture, rect: [u32; 4]) -> bool {
    let keep = min_kept_alpha();
    let [x, y, w, h] = rect.map(|v| v as usize);
    let stride = 4 * m.width as usize;
    (y..y + h).all(|row| {
        let start = row * stride + 4 * x;
        m.rgba
            .get(start..start + 4 * w)
            .is_some_and(|px| px.chunks_exact(4).all(|t| t[3] >= keep))
    })
}

/// The order quads are drawn in, as indices into `quads` (see the module docs): nearest layer
/// first (a quad's `layer` counts far to near) so that depth rejection skips what nearer layers
/// hide; within a layer by face (so that a draw call's quads lie in one plane and a view culls
/// the faces it does not see), the opaque quads before the alpha-tested ones, and by
/// macro-texture, so that each (layer, face, kind, macro-texture) run is one draw call; ties keep
/// the cell's order.
fn draw_order(quads: &[Quad], opaque: &[bool]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..quads.len()).collect();
    order.sort_by_key(|&k| {
        (
            std::cmp::Reverse(quads[k].layer),
            quads[k].face,
            !opaque[k],
            quads[k].macro_index,
        )
    });
    order
}

/// The format macro-textures are uploaded in on `device`. Their texels are final sRGB-encoded
/// colours that the quads copy to the sRGB colour target unchanged. Where the colour target has a
/// linear view ([`crate::targets::linear_views_supported`]) they are `Rgba8Unorm` and drawn
/// through that view: no sRGB decode on fetching, no encode on storing (both cost a software
/// rasterizer much), the bytes pass through. Elsewhere (GL) they are `Rgba8UnormSrgb`, drawn into
/// the sRGB view: decoded on fetching and re-encoded on storing, which round-trips exactly.
fn macro_format(device: &wgpu::Device) -> wgpu::TextureFormat {
    if crate::targets::linear_views_supported(device) {
        wgpu::TextureFormat::Rgba8Unorm
    } else {
        wgpu::TextureFormat::Rgba8UnormSrgb
    }
}

/// Uploads one macro-texture as a single-level texture of `format` ([`macro_format`]).
fn upload_macro(
    gpu: &Gpu,
    label: &str,
    m: &MacroTexture,
    format: wgpu::TextureFormat,
) -> wgpu::TextureView {
    let size = wgpu::Extent3d {
        width: m.width,
        height: m.height,
        depth_or_array_layers: 1,
    };
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    gpu.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        &m.rgba,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(4 * m.width),
            rows_per_image: Some(m.height),
        },
        size,
    );
    texture.create_view(&wgpu::TextureViewDescriptor::default())
}

/// Draws [`ImpostorCell`]s: the reference pipeline for near geometry, the quad pipelines (opaque
/// and alpha-tested), globals and cached render targets.
pub struct ImpostorRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    near_pipeline: wgpu::RenderPipeline,
    /// Quads some of whose texels fail the alpha test (`fs_quad`, with `discard`).
    quad_pipeline: wgpu::RenderPipeline,
    /// Quads all of whose texels pass it (`fs_quad_opaque`, no `discard`).
    opaque_pipeline: wgpu::RenderPipeline,
    /// The macro-texture format this renderer's quad pipelines expect ([`macro_format`]);
    /// `Rgba8Unorm` means the quads are drawn through the colour target's linear view.
    macro_format: wgpu::TextureFormat,
    globals: wgpu::Buffer,
    globals_group: wgpu::BindGroup,
    max_dim: u32,
    targets: Mutex<Option<Targets>>,
    last_gpu: GpuTime,
}

impl ImpostorRenderer {
    pub fn new(gpu: &Gpu) -> Result<ImpostorRenderer, GpuError> {
        gpu.scoped("creating the impostor render pipelines", || {
            let device = &gpu.device;
            let color_targets = [
                Some(wgpu::ColorTargetState {
                    format: COLOR_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                }),
                Some(wgpu::ColorTargetState {
                    format: VIEW_DEPTH_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                }),
            ];
            let depth_stencil = Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Greater),
                stencil: Default::default(),
                bias: Default::default(),
            });
            let primitive = wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            };
            // Near geometry: the reference renderer's exact source and state.
            let near_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("lemi impostor renderer: near geometry"),
                source: wgpu::ShaderSource::Wgsl(format!("{SHADING_WGSL}\n{RENDER_WGSL}").into()),
            });
            let near_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("lemi impostor renderer: near geometry"),
                bind_group_layouts: &[Some(gpu.globals_layout()), Some(gpu.material_layout())],
                immediate_size: 0,
            });
            let near_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("lemi impostor renderer: near geometry"),
                layout: Some(&near_layout),
                vertex: wgpu::VertexState {
                    module: &near_module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(vertex_layout())],
                },
                primitive,
                depth_stencil: depth_stencil.clone(),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &near_module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &color_targets,
                }),
                multiview_mask: None,
                cache: None,
            });
            // Quads.
            let quad_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("lemi impostor renderer: quads"),
                source: wgpu::ShaderSource::Wgsl(format!("{SHADING_WGSL}\n{IMPOSTOR_WGSL}").into()),
            });
            let macro_layout = macro_layout(device);
            let quad_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("lemi impostor renderer: quads"),
                bind_group_layouts: &[Some(gpu.globals_layout()), Some(&macro_layout)],
                immediate_size: 0,
            });
            // The quads' colour target: the linear view where macro-textures are linear.
            let macro_format = macro_format(device);
            let mut quad_targets = color_targets.clone();
            if macro_format == wgpu::TextureFormat::Rgba8Unorm {
                quad_targets[0] = Some(wgpu::ColorTargetState {
                    format: LINEAR_COLOR_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                });
            }
            let quad_pipeline_for = |label: &str, entry_point: &str| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some(label),
                    layout: Some(&quad_layout),
                    vertex: wgpu::VertexState {
                        module: &quad_module,
                        entry_point: Some("vs_quad"),
                        compilation_options: Default::default(),
                        buffers: &[Some(quad_vertex_layout())],
                    },
                    primitive,
                    depth_stencil: depth_stencil.clone(),
                    multisample: wgpu::MultisampleState::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: &quad_module,
                        entry_point: Some(entry_point),
                        compilation_options: Default::default(),
                        targets: &quad_targets,
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            };
            let quad_pipeline = quad_pipeline_for("lemi impostor renderer: quads", "fs_quad");
            let opaque_pipeline =
                quad_pipeline_for("lemi impostor renderer: opaque quads", "fs_quad_opaque");
            let globals = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("lemi impostor globals"),
                size: std::mem::size_of::<ShadingGlobals>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let globals_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("lemi impostor globals"),
                layout: gpu.globals_layout(),
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: globals.as_entire_binding(),
                }],
            });
            ImpostorRenderer {
                device: gpu.device.clone(),
                queue: gpu.queue.clone(),
                near_pipeline,
                quad_pipeline,
                opaque_pipeline,
                macro_format,
                globals,
                globals_group,
                max_dim: gpu.limits().max_texture_dimension_2d,
                targets: Mutex::new(None),
                last_gpu: GpuTime::default(),
            }
        })
    }

    /// Renders the cell from `view`: its near geometry (shaded exactly like [`crate::Renderer`],
    /// including `options.alpha_cutoff`), then its impostor quads, in one pass, and reads the
    /// colour and depth images back (background: `options.clear`, depth `f32::INFINITY`).
    pub fn render(
        &self,
        cell: &ImpostorCell,
        view: &View,
        options: &RenderOptions,
    ) -> Result<Frame, GpuError> {
        self.render_parts(cell, view, options, true, true)
            .and_then(|f| f.ok_or_else(|| GpuError::Readback("no frame was read back".into())))
    }

    /// Renders like [`ImpostorRenderer::render`] and waits until the GPU has finished, without
    /// copying or reading the images back (for timing the rendering alone;
    /// [`ImpostorRenderer::last_gpu_ms`] is updated too).
    pub fn render_no_readback(
        &self,
        cell: &ImpostorCell,
        view: &View,
        options: &RenderOptions,
    ) -> Result<(), GpuError> {
        self.render_parts(cell, view, options, true, false)
            .map(|_| ())
    }

    /// GPU time of the last frame's render pass (near geometry and quads) in milliseconds, from
    /// timestamp queries at its beginning and end, resolved in the frame's own submission; `None`
    /// before the first frame or without [`wgpu::Features::TIMESTAMP_QUERY`]. See
    /// [`crate::Renderer::last_gpu_ms`].
    pub fn last_gpu_ms(&self) -> Option<f64> {
        self.last_gpu.get()
    }

    /// Like [`ImpostorRenderer::render`] but only the impostor quads, without the near geometry.
    pub fn render_impostors_only(
        &self,
        cell: &ImpostorCell,
        view: &View,
        options: &RenderOptions,
    ) -> Result<Frame, GpuError> {
        self.render_parts(cell, view, options, false, true)
            .and_then(|f| f.ok_or_else(|| GpuError::Readback("no frame was read back".into())))
    }

    fn render_parts(
        &self,
        cell: &ImpostorCell,
        view: &View,
        options: &RenderOptions,
        with_near: bool,
        readback: bool,
    ) -> Result<Option<Frame>, GpuError> {
        let (width, height) = (view.width, view.height);
        if width == 0 || height == 0 || width > self.max_dim || height > self.max_dim {
            return Err(GpuError::Limit(format!(
                "image size {width}x{height} is outside what this adapter renders (1..={} per side)",
                self.max_dim
            )));
        }
        let mut globals = ShadingGlobals::new(view, &options.lighting, options.alpha_cutoff)?;
        globals.params[1] = QUAD_ALPHA_CUTOFF;
        let near = &cell.near;
        for chunk in near.geometry.chunks() {
            if near.materials.bind_group(chunk.material).is_none() {
                return Err(GpuError::Invalid(format!(
                    "near geometry uses material {} but only {} materials were uploaded",
                    chunk.material,
                    near.materials.len()
                )));
            }
        }
        for d in &cell.draws {
            if cell.macro_groups.get(d.macro_index as usize).is_none() {
                return Err(GpuError::Invalid(format!(
                    "quads use macro-texture {} but only {} were uploaded",
                    d.macro_index,
                    cell.macro_groups.len()
                )));
            }
        }
        if cell.macro_format != self.macro_format && !cell.draws.is_empty() {
            return Err(GpuError::Invalid(format!(
                "the cell's macro-textures are {:?} but this renderer draws {:?} ones: the cell was \
                 uploaded on another device",
                cell.macro_format, self.macro_format
            )));
        }
        let mut guard = self
            .targets
            .lock()
            .map_err(|_| GpuError::Readback("render target cache poisoned".into()))?;
        if guard
            .as_ref()
            .is_none_or(|t| t.width != width || t.height != height)
        {
            *guard = Some(crate::device::scoped(
                &self.device,
                "creating impostor render targets",
                || Targets::new(&self.device, width, height, "lemi impostor"),
            )?);
        }
        let Some(targets) = guard.as_ref() else {
            return Err(GpuError::Readback("render targets missing".into()));
        };
        let linear = self.macro_format == wgpu::TextureFormat::Rgba8Unorm;
        if linear && !targets.has_linear_color() {
            return Err(GpuError::Invalid(
                "the colour target has no linear view for the quads".into(),
            ));
        }
        let draw_near = with_near && !near.geometry.chunks().is_empty();
        let view_proj = view.view_proj();
        let quads = cell
            .quad_buffers
            .as_ref()
            .filter(|_| !cell.draws.is_empty());
        crate::device::scoped(&self.device, "rendering impostors", || {
            self.queue
                .write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));
            let mut encoder = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("lemi impostor render"),
                });
            // Near geometry into the sRGB view; quads into the linear view where macro-textures
            // are linear, so a frame with both takes two passes (the second loads the first's
            // targets, depth included).
            let two_passes = linear && draw_near && quads.is_some();
            let mut pass = targets.begin_pass_part(
                &mut encoder,
                "lemi impostor pass",
                if two_passes {
                    PassPart::First
                } else {
                    PassPart::Whole
                },
                linear && !draw_near,
                true,
            );
            if draw_near {
                pass.set_pipeline(&self.near_pipeline);
                pass.set_bind_group(0, &self.globals_group, &[]);
                let mut bound = None;
                for chunk in near.geometry.chunks() {
                    if bound != Some(chunk.material) {
                        if let Some(g) = near.materials.bind_group(chunk.material) {
                            pass.set_bind_group(1, g, &[]);
                        }
                        bound = Some(chunk.material);
                    }
                    pass.set_vertex_buffer(0, chunk.vertices.slice(..));
                    pass.set_index_buffer(chunk.indices.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(0..chunk.index_count, 0, 0..1);
                }
            }
            if two_passes {
                drop(pass);
                pass = targets.begin_pass_part(
                    &mut encoder,
                    "lemi impostor quad pass",
                    PassPart::Last,
                    true,
                    true,
                );
            }
            if let Some((vertices, indices)) = quads {
                pass.set_bind_group(0, &self.globals_group, &[]);
                pass.set_vertex_buffer(0, vertices.slice(..));
                pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
                let (mut pipeline, mut bound) = (None, None);
                for (d, b) in cell.draws.iter().zip(&cell.bounds) {
                    let Some(g) = cell.macro_groups.get(d.macro_index as usize) else {
                        continue;
                    };
                    if b.outside(&view_proj) {
                        continue;
                    }
                    if pipeline != Some(d.opaque) {
                        pass.set_pipeline(if d.opaque {
                            &self.opaque_pipeline
                        } else {
                            &self.quad_pipeline
                        });
                        pipeline = Some(d.opaque);
                    }
                    if bound != Some(d.macro_index) {
                        pass.set_bind_group(1, g, &[]);
                        bound = Some(d.macro_index);
                    }
                    pass.draw_indexed(d.first_index..d.first_index + d.index_count, 0, 0..1);
                }
            }
            drop(pass);
            targets.resolve_timer(&mut encoder);
            if readback {
                targets.copy_to_readback(&mut encoder);
            }
            self.queue.submit([encoder.finish()]);
        })?;
        if !readback {
            self.last_gpu
                .set(targets.read_timer(&self.device, &self.queue)?);
            return Ok(None);
        }
        // Every drawn fragment writes alpha 1; alpha 0 is the clear.
        let (frame, ms) = targets.read_frame(&self.device, &self.queue, options.clear)?;
        self.last_gpu.set(ms);
        Ok(Some(frame))
    }
}

// ---------------------------------------------------------------------------------------------
// Incremental upload, for the streaming runtime (GI 2002 sec. 3, runtime step 2: "to amortize the
// cost of texture downloads over several frames, prefetched impostor textures are downloaded to
// texture memory in smaller chunks").

/// A cell's impostor data checked and laid out for the GPU, on the CPU only (no GPU work, `Send`):
/// the near geometry copied out of the scene, the quads' vertex and index arrays and draw calls,
/// and the decoded macro-textures. Built by [`ImpostorCellData::prepare`], typically on a
/// background thread; uploaded with [`ImpostorCell::begin_upload`] and
/// [`PendingImpostorCell::upload_step`].
pub struct ImpostorCellData {
    near_meshes: Vec<Mesh>,
    geometry: QuadGeometry,
    macros: Vec<MacroTexture>,
    quad_count: usize,
}

impl ImpostorCellData {
    /// Checks and lays out a cell's data exactly as [`ImpostorCell::upload`] does (same errors,
    /// same order of checks), except the adapter's limits, which [`ImpostorCell::begin_upload`]
    /// checks.
    pub fn prepare(
        scene: &Scene,
        near: &[[u32; 2]],
        quads: &[Quad],
        macros: Vec<MacroTexture>,
    ) -> Result<ImpostorCellData, GpuError> {
        let near_meshes = near_meshes(scene, near)?;
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
        let geometry = quad_geometry(quads, &macros)?;
        Ok(ImpostorCellData {
            near_meshes,
            geometry,
            macros,
            quad_count: quads.len(),
        })
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

    /// Bytes of macro-texture data (RGBA8), what the GPU will hold as textures.
    pub fn texture_bytes(&self) -> u64 {
        self.macros.iter().map(|m| m.rgba.len() as u64).sum()
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
        self.macros
            .iter()
            .map(|m| m.rgba.len() as u64)
            .max()
            .unwrap_or(0)
    }
}

/// A cell whose upload is in progress: the geometry is on the GPU, the macro-textures are written
/// row by row by [`PendingImpostorCell::upload_step`]. It cannot be drawn (there is no way to hand
/// it to [`ImpostorRenderer`]); [`PendingImpostorCell::finish`] turns a complete one into an
/// [`ImpostorCell`].
///
/// A macro-texture's GPU texture is created when its first rows are written and its CPU copy is
/// freed when its last row is, so a cell in transit holds at most one macro-texture twice.
pub struct PendingImpostorCell {
    near: GpuScene,
    quad_buffers: Option<(wgpu::Buffer, wgpu::Buffer)>,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// One bind group per macro-texture begun so far, in order.
    macro_groups: Vec<wgpu::BindGroup>,
    /// The texture being written (the last one of `macro_groups`), until it is complete.
    current: Option<wgpu::Texture>,
    /// CPU copies; a completed macro-texture's `rgba` is emptied.
    macros: Vec<MacroTexture>,
    draws: Vec<MacroDraw>,
    bounds: Vec<Bounds>,
    quad_count: usize,
    opaque_quads: usize,
    texture_bytes: u64,
    macro_format: wgpu::TextureFormat,
    geometry_bytes: u64,
    /// Next macro-texture and row to write.
    next_macro: usize,
    next_row: u32,
    uploaded: u64,
}

impl ImpostorCell {
    /// Starts an incremental upload: checks the adapter's limits (macro-textures larger than its
    /// textures, quad arrays larger than its buffers are [`GpuError::Limit`]), uploads the near
    /// geometry and the quads' vertex and index buffers (in one go) and returns the cell with no
    /// macro-texture written yet. Then call [`PendingImpostorCell::upload_step`] until it reports
    /// completion and [`PendingImpostorCell::finish`]. The result draws exactly like
    /// [`ImpostorCell::upload`]'s.
    pub fn begin_upload(
        gpu: &Gpu,
        materials: Arc<GpuMaterials>,
        data: ImpostorCellData,
    ) -> Result<PendingImpostorCell, GpuError> {
        let limits = gpu.limits();
        let max_dim = limits.max_texture_dimension_2d;
        for (i, m) in data.macros.iter().enumerate() {
            if m.width > max_dim || m.height > max_dim {
                return Err(GpuError::Limit(format!(
                    "macro-texture {i} is {}x{}, larger than this adapter's textures ({max_dim} per side)",
                    m.width, m.height
                )));
            }
        }
        let texture_bytes = data.texture_bytes();
        let ImpostorCellData {
            near_meshes,
            geometry:
                QuadGeometry {
                    vertices,
                    indices,
                    draws,
                    bounds,
                    opaque_quads,
                },
            macros,
            quad_count,
        } = data;
        let vertex_bytes = std::mem::size_of_val(vertices.as_slice()) as u64;
        let index_bytes = std::mem::size_of_val(indices.as_slice()) as u64;
        if vertex_bytes.max(index_bytes) > limits.max_buffer_size {
            return Err(GpuError::Limit(format!(
                "{quad_count} quads need a {} byte buffer, more than this adapter's {} bytes",
                vertex_bytes.max(index_bytes),
                limits.max_buffer_size
            )));
        }
        let geometry = GpuGeometry::upload(gpu, &near_meshes, &UploadOptions::default())?;
        drop(near_meshes);
        let near = GpuScene::from_parts(materials, geometry)?;
        let (quad_buffers, layout, sampler) = gpu.scoped("uploading impostor quads", || {
            let device = &gpu.device;
            let quad_buffers = (!indices.is_empty()).then(|| {
                let v = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("lemi impostor quad vertices"),
                    contents: bytemuck::cast_slice(&vertices),
                    usage: wgpu::BufferUsages::VERTEX,
                });
                let i = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("lemi impostor quad indices"),
                    contents: bytemuck::cast_slice(&indices),
                    usage: wgpu::BufferUsages::INDEX,
                });
                (v, i)
            });
            let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("lemi macro-texture sampler"),
                address_mode_u: wgpu::AddressMode::ClampToEdge,
                address_mode_v: wgpu::AddressMode::ClampToEdge,
                address_mode_w: wgpu::AddressMode::ClampToEdge,
                mag_filter: wgpu::FilterMode::Nearest,
                min_filter: wgpu::FilterMode::Nearest,
                mipmap_filter: wgpu::MipmapFilterMode::Nearest,
                ..Default::default()
            });
            (quad_buffers, macro_layout(device), sampler)
        })?;
        let geometry_bytes = buffer_bytes(&quad_buffers, &near);
        Ok(PendingImpostorCell {
            near,
            quad_buffers,
            layout,
            sampler,
            macro_groups: Vec::with_capacity(macros.len()),
            current: None,
            macros,
            draws,
            bounds,
            quad_count,
            opaque_quads,
            texture_bytes,
            macro_format: macro_format(&gpu.device),
            geometry_bytes,
            next_macro: 0,
            next_row: 0,
            uploaded: 0,
        })
    }

    /// Bytes this cell holds on the GPU: macro-textures plus vertex and index buffers.
    pub fn gpu_bytes(&self) -> u64 {
        self.texture_bytes + buffer_bytes(&self.quad_buffers, &self.near)
    }
}

/// Bytes of a cell's vertex and index buffers (quads and near geometry) as allocated.
fn buffer_bytes(quad_buffers: &Option<(wgpu::Buffer, wgpu::Buffer)>, near: &GpuScene) -> u64 {
    let quads = quad_buffers
        .as_ref()
        .map_or(0, |(v, i)| v.size() + i.size());
    let near: u64 = near
        .geometry
        .chunks()
        .iter()
        .map(|c| c.vertices.size() + c.indices.size())
        .sum();
    quads + near
}

impl PendingImpostorCell {
    /// Writes up to `max_bytes` of macro-texture rows (with `queue.write_texture`, whole rows, in
    /// the cell's macro-texture order; at least one row per call, so a budget below one row still
    /// progresses) and returns whether every macro-texture is now complete. The writes are queued
    /// and reach the GPU with the next submission, before any later draw.
    pub fn upload_step(&mut self, gpu: &Gpu, max_bytes: u64) -> Result<bool, GpuError> {
        if self.is_complete() {
            return Ok(true);
        }
        gpu.scoped("uploading macro-texture rows", || {
            let mut written = 0u64;
            while let Some(m) = self.macros.get(self.next_macro) {
                let row_bytes = 4 * m.width as u64;
                let rows_left = m.height - self.next_row;
                let fit = (max_bytes.saturating_sub(written) / row_bytes).min(rows_left as u64);
                let rows = if written == 0 { fit.max(1) } else { fit } as u32;
                if rows == 0 {
                    break;
                }
                if self.current.is_none() {
                    let label = format!("lemi macro-texture {}", self.next_macro);
                    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
                        label: Some(&label),
                        size: wgpu::Extent3d {
                            width: m.width,
                            height: m.height,
                            depth_or_array_layers: 1,
                        },
                        mip_level_count: 1,
                        sample_count: 1,
                        dimension: wgpu::TextureDimension::D2,
                        format: self.macro_format,
                        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                        view_formats: &[],
                    });
                    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
                    self.macro_groups.push(gpu.device.create_bind_group(
                        &wgpu::BindGroupDescriptor {
                            label: Some(&label),
                            layout: &self.layout,
                            entries: &[
                                wgpu::BindGroupEntry {
                                    binding: 3,
                                    resource: wgpu::BindingResource::TextureView(&view),
                                },
                                wgpu::BindGroupEntry {
                                    binding: 4,
                                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                                },
                            ],
                        },
                    ));
                    self.current = Some(texture);
                }
                let Some(texture) = self.current.as_ref() else {
                    break;
                };
                let start = (self.next_row as u64 * row_bytes) as usize;
                let end = start + (rows as u64 * row_bytes) as usize;
                gpu.queue.write_texture(
                    wgpu::TexelCopyTextureInfo {
                        texture,
                        mip_level: 0,
                        origin: wgpu::Origin3d {
                            x: 0,
                            y: self.next_row,
                            z: 0,
                        },
                        aspect: wgpu::TextureAspect::All,
                    },
                    &m.rgba[start..end],
                    wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(4 * m.width),
                        rows_per_image: Some(rows),
                    },
                    wgpu::Extent3d {
                        width: m.width,
                        height: rows,
                        depth_or_array_layers: 1,
                    },
                );
                written += rows as u64 * row_bytes;
                self.uploaded += rows as u64 * row_bytes;
                self.next_row += rows;
                if self.next_row == m.height {
                    // Complete: the GPU texture stays alive through its bind group.
                    self.macros[self.next_macro].rgba = Vec::new();
                    self.current = None;
                    self.next_macro += 1;
                    self.next_row = 0;
                }
            }
        })?;
        Ok(self.is_complete())
    }

    /// Whether every macro-texture has been written.
    pub fn is_complete(&self) -> bool {
        self.next_macro >= self.macros.len()
    }

    /// Macro-texture bytes written so far.
    pub fn uploaded_bytes(&self) -> u64 {
        self.uploaded
    }

    /// Macro-texture bytes still to write.
    pub fn remaining_bytes(&self) -> u64 {
        self.texture_bytes - self.uploaded
    }

    /// Bytes of macro-texture data of the whole cell.
    pub fn texture_bytes(&self) -> u64 {
        self.texture_bytes
    }

    /// Bytes of the vertex and index buffers [`ImpostorCell::begin_upload`] created and filled.
    pub fn geometry_bytes(&self) -> u64 {
        self.geometry_bytes
    }

    /// Bytes held on the GPU so far: geometry buffers plus the macro-textures created so far.
    pub fn gpu_bytes(&self) -> u64 {
        let textures: u64 = self
            .macros
            .iter()
            .take(self.macro_groups.len())
            .map(|m| 4 * m.width as u64 * m.height as u64)
            .sum();
        self.geometry_bytes + textures
    }

    /// Bytes of macro-texture data still held in main memory.
    pub fn cpu_bytes(&self) -> u64 {
        self.macros.iter().map(|m| m.rgba.len() as u64).sum()
    }

    /// The drawable cell; [`GpuError::Invalid`] if some macro-texture is not completely written.
    pub fn finish(self) -> Result<ImpostorCell, GpuError> {
        if !self.is_complete() || self.macro_groups.len() != self.macros.len() {
            return Err(GpuError::Invalid(format!(
                "the cell's upload is incomplete: {} of {} macro-texture bytes written",
                self.uploaded, self.texture_bytes
            )));
        }
        Ok(ImpostorCell {
            near: self.near,
            quad_buffers: self.quad_buffers,
            macro_groups: self.macro_groups,
            draws: self.draws,
            bounds: self.bounds,
            quad_count: self.quad_count,
            opaque_quads: self.opaque_quads,
            texture_bytes: self.texture_bytes,
            macro_format: self.macro_format,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lemi_core::Face;

    fn quad(macro_index: u32, layer: u16, rect: [u32; 4]) -> Quad {
        Quad {
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
    fn quads_draw_nearest_layer_first_opaque_ones_first_by_macro() {
        let mut m0 = opaque_macro(8, 8);
        set_alpha(&mut m0, 3, 3, 0);
        set_alpha(&mut m0, 5, 0, 128); // 128/255 ≥ 0.5: kept
        set_alpha(&mut m0, 6, 0, 127); // 127/255 < 0.5: discarded
        assert_eq!(min_kept_alpha(), 128);
        let macros = [m0, opaque_macro(4, 4)];
        let quads = [
            quad(0, 1, [0, 0, 2, 2]), // opaque
            quad(1, 5, [0, 0, 4, 4]), // opaque
            quad(0, 3, [2, 2, 2, 2]), // holds (3, 3): alpha-tested
            quad(0, 1, [6, 0, 1, 1]), // alpha 127: alpha-tested
            quad(0, 1, [4, 0, 2, 1]), // alpha 255 and 128: opaque
            quad(1, 1, [0, 0, 2, 2]), // opaque
        ];
        let QuadGeometry {
            vertices: v,
            indices: i,
            draws,
            bounds,
            opaque_quads,
        } = quad_geometry(&quads, &macros).expect("valid quads");
        assert_eq!(bounds.len(), draws.len());
        assert_eq!(opaque_quads, 4);
        assert_eq!(v.len(), 24);
        assert_eq!(i.len(), 36);
        let d = |macro_index, first_index, quads: u32, opaque| MacroDraw {
            macro_index,
            first_index,
            index_count: 6 * quads,
            opaque,
        };
        // layer 5 (quad 1); layer 3 (quad 2); layer 1: opaque quads 0, 4 (macro 0) and 5
        // (macro 1), then the alpha-tested quad 3.
        assert_eq!(
            draws,
            vec![
                d(1, 0, 1, true),
                d(0, 6, 1, false),
                d(0, 12, 2, true),
                d(1, 24, 1, true),
                d(0, 30, 1, false),
            ]
        );
        // the layer-3 quad (second): rect [2, 2, 2, 2] of 8x8, texel coordinates, grown by
        // QUAD_GROWTH_TEXELS on every side; the fetch is clamped to the rectangle
        let g = QUAD_GROWTH_TEXELS as f32;
        assert_eq!(v[4].uv, [2.0 - g, 2.0 - g]);
        assert_eq!(v[6].uv, [4.0 + g, 4.0 + g]);
        assert_eq!(v[4].rect, [2.0, 2.0, 4.0, 4.0]);
        assert_eq!(v[8].rect, [0.0, 0.0, 2.0, 2.0]);
        assert_eq!(v[12].rect, [4.0, 0.0, 6.0, 1.0]);
        assert_eq!(i[6..12], [4, 5, 6, 4, 6, 7]);
    }

    #[test]
    fn bounds_outside_the_view_are_culled_only_when_wholly_outside() {
        use glam::DVec3;
        let view = lemi_core::camera::Camera::new(
            DVec3::new(10.0, 0.0, 0.0),
            -DVec3::Z,
            DVec3::Y,
            90.0,
            64,
            64,
        )
        .expect("camera")
        .view();
        let vp = view.view_proj();
        let b = |min: [f64; 3], max: [f64; 3]| Bounds {
            min: DVec3::from_array(min) + DVec3::new(10.0, 0.0, 0.0),
            max: DVec3::from_array(max) + DVec3::new(10.0, 0.0, 0.0),
        };
        // in front, straddling the left edge, around the eye: kept
        assert!(!b([-1.0, -1.0, -6.0], [1.0, 1.0, -5.0]).outside(&vp));
        assert!(!b([-9.0, -1.0, -5.0], [-4.0, 1.0, -5.0]).outside(&vp));
        assert!(!b([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]).outside(&vp));
        // a plane seen edge-on at the frustum's side (x = −z, 45° left): kept
        assert!(!b([-5.0, -1.0, -5.0], [-5.0, 1.0, -5.0]).outside(&vp));
        // behind the eye, wholly left, above, right: culled
        assert!(b([-1.0, -1.0, 2.0], [1.0, 1.0, 3.0]).outside(&vp));
        assert!(b([-9.0, -1.0, -5.0], [-6.0, 1.0, -5.0]).outside(&vp));
        assert!(b([-1.0, 6.0, -5.0], [1.0, 8.0, -5.0]).outside(&vp));
        assert!(b([6.0, -1.0, -5.0], [9.0, 1.0, -5.0]).outside(&vp));
        assert!(Bounds::EMPTY.outside(&vp));
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
            let r = quad_geometry(&[quad(0, 0, rect)], &macros);
            assert!(matches!(r, Err(GpuError::Invalid(_))), "{rect:?}");
        }
        assert!(quad_geometry(&[quad(0, 0, [0, 0, 8, 8])], &macros).is_ok());
    }
}

#[cfg(test)]
mod incremental_tests {
    //! The incremental upload ([`ImpostorCell::begin_upload`] + [`PendingImpostorCell`]) against
    //! the one-shot [`ImpostorCell::upload`], on whatever adapter wgpu finds. Without an adapter
    //! the test fails with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.
    use super::*;

    use lemi_core::camera::Camera;
    use lemi_core::{Face, Material, SceneBuilder, Vertex};

    fn gpu() -> Option<Gpu> {
        Gpu::for_tests()
    }

    /// A quad facing a camera at the origin looking along −Z, at depth `z`.
    fn quad(macro_index: u32, rect: [u32; 4], [x0, x1, y0, y1, z]: [f32; 5]) -> Quad {
        Quad {
            face: Face::NegZ,
            layer: 0,
            texels: [0, 0, rect[2] as u16, rect[3] as u16],
            corners: [[x0, y1, z], [x1, y1, z], [x1, y0, z], [x0, y0, z]],
            macro_index,
            rect,
            rotated: false,
        }
    }

    /// A `w × h` macro-texture of distinct opaque colours (seeded by `k`), every 7th texel clear.
    fn pattern(w: u32, h: u32, k: u32) -> MacroTexture {
        let mut rgba = Vec::with_capacity((4 * w * h) as usize);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let a = if (i + k) % 7 == 0 { 0 } else { 255 };
                rgba.extend_from_slice(&[
                    (x * 37 + k * 11) as u8,
                    (y * 23 + k * 5) as u8,
                    (i * 13 + k) as u8,
                    a,
                ]);
            }
        }
        MacroTexture {
            width: w,
            height: h,
            rgba,
        }
    }

    fn scene() -> Scene {
        let mut b = SceneBuilder::new();
        b.add_material(Material::default());
        let v = |p: [f32; 3]| Vertex::new(p, [0.0, 0.0, 1.0], [0.0, 0.0], [200, 180, 90, 255]);
        b.add_mesh(Mesh {
            material: 0,
            vertices: vec![
                v([-0.5, -0.5, -2.0]),
                v([0.5, -0.5, -2.0]),
                v([0.0, 0.4, -2.0]),
            ],
            indices: vec![0, 1, 2],
        });
        b.finish()
    }

    #[test]
    fn gpu_times_and_frames_without_readback() {
        let Some(gpu) = gpu() else { return };
        let scene = scene();
        let materials =
            Arc::new(GpuMaterials::upload(&gpu, &scene.materials, &scene.textures).expect("mats"));
        let macros = vec![pattern(13, 9, 0), pattern(32, 16, 1)];
        let quads = [
            quad(0, [0, 0, 13, 9], [-4.0, -0.5, 0.5, 3.5, -5.0]),
            quad(1, [0, 0, 32, 16], [-3.0, 3.0, -3.5, 0.0, -6.0]),
        ];
        let near = [[0u32, 0u32]];
        let cell = ImpostorCell::upload(&gpu, materials.clone(), &scene, &near, &quads, &macros)
            .expect("upload");
        let view = Camera::new(
            glam::DVec3::ZERO,
            -glam::DVec3::Z,
            glam::DVec3::Y,
            90.0,
            64,
            64,
        )
        .expect("camera")
        .view();
        let opts = RenderOptions::default();
        let check = |ms: Option<f64>| {
            if gpu.has_timestamps() {
                assert!(ms.is_some_and(|ms| ms.is_finite() && ms >= 0.0), "{ms:?}");
            } else {
                assert_eq!(ms, None);
            }
        };
        let r = ImpostorRenderer::new(&gpu).expect("renderer");
        assert_eq!(r.last_gpu_ms(), None, "no frame yet");
        let first = r.render(&cell, &view, &opts).expect("render");
        check(r.last_gpu_ms());
        r.render_no_readback(&cell, &view, &opts)
            .expect("no readback");
        check(r.last_gpu_ms());
        assert!(r.render(&cell, &view, &opts).expect("again") == first);
        let reference = crate::Renderer::new(&gpu).expect("reference renderer");
        let all = GpuScene::upload(&gpu, &scene, &UploadOptions::default()).expect("scene");
        assert_eq!(reference.last_gpu_ms(), None);
        let want = reference.render(&all, &view, &opts).expect("reference");
        check(reference.last_gpu_ms());
        reference
            .render_no_readback(&all, &view, &opts)
            .expect("reference without readback");
        check(reference.last_gpu_ms());
        assert!(reference.render(&all, &view, &opts).expect("again") == want);
    }

    #[test]
    fn incremental_upload_renders_like_the_one_shot_upload() {
        let Some(gpu) = gpu() else { return };
        let scene = scene();
        let materials =
            Arc::new(GpuMaterials::upload(&gpu, &scene.materials, &scene.textures).expect("mats"));
        // Three macro-textures of different widths (rows of 52, 128 and 36 bytes).
        let macros = vec![pattern(13, 9, 0), pattern(32, 16, 1), pattern(9, 21, 2)];
        let quads = [
            quad(0, [0, 0, 13, 9], [-4.0, -0.5, 0.5, 3.5, -5.0]),
            quad(1, [0, 0, 32, 16], [-3.0, 3.0, -3.5, 0.0, -6.0]),
            quad(2, [0, 0, 9, 21], [0.5, 3.5, 0.5, 4.0, -5.5]),
            quad(1, [4, 4, 8, 8], [-1.0, 1.0, -1.0, 1.0, -7.0]),
        ];
        let near = [[0u32, 0u32]];
        let total: u64 = macros.iter().map(|m| m.rgba.len() as u64).sum();
        let one_shot =
            ImpostorCell::upload(&gpu, materials.clone(), &scene, &near, &quads, &macros)
                .expect("one-shot upload");
        let r = ImpostorRenderer::new(&gpu).expect("renderer");
        let view = Camera::new(
            glam::DVec3::ZERO,
            -glam::DVec3::Z,
            glam::DVec3::Y,
            90.0,
            64,
            64,
        )
        .expect("camera")
        .view();
        let opts = RenderOptions::default();
        let want = r.render(&one_shot, &view, &opts).expect("render one-shot");
        assert!(want.covered_count() > 1000, "{}", want.covered_count());
        for budget in [0u64, 1, 100, 200, 1000, u64::MAX] {
            let data =
                ImpostorCellData::prepare(&scene, &near, &quads, macros.clone()).expect("prepare");
            assert_eq!(data.texture_bytes(), total);
            assert_eq!(data.quad_count(), 4);
            assert_eq!(data.near_triangles(), 1);
            let mut pending =
                ImpostorCell::begin_upload(&gpu, materials.clone(), data).expect("begin");
            assert_eq!(pending.texture_bytes(), total);
            assert_eq!(pending.geometry_bytes() + total, one_shot.gpu_bytes());
            assert!(!pending.is_complete());
            let mut steps = 0;
            loop {
                let before = pending.uploaded_bytes();
                let done = pending.upload_step(&gpu, budget).expect("upload step");
                let step = pending.uploaded_bytes() - before;
                // at most the budget, or one row (128 bytes at most here) when below it
                assert!(step > 0, "a step always progresses");
                assert!(
                    step <= budget.max(128),
                    "step of {step} bytes, budget {budget}"
                );
                steps += 1;
                assert_eq!(pending.uploaded_bytes() + pending.remaining_bytes(), total);
                if done {
                    break;
                }
                assert!(steps < 10_000);
            }
            assert_eq!(pending.uploaded_bytes(), total);
            assert_eq!(pending.cpu_bytes(), 0, "CPU copies are freed once uploaded");
            if budget == u64::MAX {
                assert_eq!(steps, 1);
            } else if budget >= 128 {
                assert!(steps as u64 >= total / budget, "{steps} steps");
            }
            let cell = pending.finish().expect("finish");
            assert_eq!(cell.texture_bytes(), one_shot.texture_bytes());
            assert_eq!(cell.gpu_bytes(), one_shot.gpu_bytes());
            assert_eq!(cell.quad_draw_calls(), one_shot.quad_draw_calls());
            let got = r.render(&cell, &view, &opts).expect("render incremental");
            assert!(
                got == want,
                "budget {budget}: the incremental upload renders differently"
            );
        }
        // An incomplete cell cannot be finished.
        let data = ImpostorCellData::prepare(&scene, &near, &quads, macros.clone()).expect("prep");
        let mut pending = ImpostorCell::begin_upload(&gpu, materials.clone(), data).expect("begin");
        pending.upload_step(&gpu, 300).expect("step");
        match pending.finish() {
            Err(GpuError::Invalid(m)) => assert!(m.contains("incomplete"), "{m}"),
            Err(e) => panic!("expected Invalid, got {e}"),
            Ok(_) => panic!("an incomplete upload finished"),
        }
        // A cell without macro-textures is complete at once.
        let data = ImpostorCellData::prepare(&scene, &near, &[], Vec::new()).expect("prep");
        let pending = ImpostorCell::begin_upload(&gpu, materials.clone(), data).expect("begin");
        assert!(pending.is_complete());
        assert_eq!(pending.finish().expect("finish").near_triangles(), 1);
        // prepare checks like upload does.
        let short = MacroTexture {
            width: 4,
            height: 4,
            rgba: vec![0; 3],
        };
        assert!(matches!(
            ImpostorCellData::prepare(&scene, &near, &[], vec![short]),
            Err(GpuError::Invalid(_))
        ));
        assert!(matches!(
            ImpostorCellData::prepare(&scene, &[[3, 0]], &[], Vec::new()),
            Err(GpuError::Invalid(_))
        ));
        assert!(matches!(
            ImpostorCellData::prepare(&scene, &[], &quads, Vec::new()),
            Err(GpuError::Invalid(_))
        ));
    }
}
