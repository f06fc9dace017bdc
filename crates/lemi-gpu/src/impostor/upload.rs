//! Uploading a cell, along one path: [`ImpostorCell::begin_upload`] checks the adapter's limits
//! and uploads the geometry in one go, [`PendingImpostorCell::upload_step`] writes the
//! macro-textures a few rows at a time within a byte budget, and [`PendingImpostorCell::finish`]
//! hands over the drawable [`ImpostorCell`]. This is the streaming runtime's upload (GI 2002
//! sec. 3, runtime step 2: "to amortize the cost of texture downloads over several frames,
//! prefetched impostor textures are downloaded to texture memory in smaller chunks"). The one-shot
//! [`ImpostorCell::upload`] is the same path run to completion: [`ImpostorCellData::prepare`],
//! [`ImpostorCell::begin_upload`], one unbounded [`PendingImpostorCell::upload_step`] and
//! [`PendingImpostorCell::finish`].

use std::sync::Arc;

use lemi_core::bundle::{CellFile, Quad};
use lemi_core::compress::{BlockFormat, MacroTexture};
use lemi_core::Scene;
use wgpu::util::DeviceExt;

use super::atlas::{Atlas, Place};
use super::layout::{
    Bounds, ImpostorCellData, QuadDraw, QuadGeometry, QUAD_ALPHA_CUTOFF, QUAD_FULL_ALPHA,
};
#[cfg(doc)]
use super::ImpostorRenderer;
use crate::scene::{GpuGeometry, GpuMaterials, GpuScene, UploadOptions};
use crate::{Gpu, GpuError};

/// Group 1 of the quad pipeline: an atlas page of macro-textures as stored (binding 3, fetched
/// texel by texel), its bilinear sampler (binding 4), the same page decoded to linear light
/// (binding 5, the filtered fetches of minified quads) and the page's [`PageParams`] (binding 6).
/// Created by both [`ImpostorCell::begin_upload`] and [`ImpostorRenderer::new`]; wgpu deduplicates
/// equal layouts, and WebGPU makes equal layouts compatible in any case.
pub(super) fn macro_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let texture = |binding, filterable| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    };
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("lemi macro-texture"),
        entries: &[
            texture(3, false),
            wgpu::BindGroupLayoutEntry {
                binding: 4,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
            texture(5, true),
            wgpu::BindGroupLayoutEntry {
                binding: 6,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: wgpu::BufferSize::new(16),
                },
                count: None,
            },
        ],
    })
}

/// What the quad shader needs to know of an atlas page (binding 6 of [`macro_layout`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct PageParams {
    /// x: 1 where the page's transparent texels are transparent black (RGBA8 pages, made so at
    /// upload, and BC1, whose transparent index decodes so), so that a bilinear fetch's colour
    /// over its alpha is the mean of the opaque texels it covers; 0 where they carry a colour of
    /// their own (BC7: the mean of their block's opaque texels, chosen by the encoder), and the
    /// fetch's colour is taken as it is.
    flags: [f32; 4],
}

/// Whether transparent texels of `format` pages are transparent black ([`PageParams`]).
fn transparent_black(format: wgpu::TextureFormat) -> bool {
    !matches!(
        format,
        wgpu::TextureFormat::Bc7RgbaUnorm | wgpu::TextureFormat::Bc7RgbaUnormSrgb
    )
}

/// RGBA8 macro-texture texels as the quad shader expects them: alpha 255 at or above
/// [`QUAD_FULL_ALPHA`], [`lemi_core::compress::FRINGE_ALPHA`] for outline fringe texels between it
/// and [`QUAD_ALPHA_CUTOFF`] (what the alpha tests decide does not change), and transparent texels
/// black, so that filtering weighs opaque texels only ([`PageParams`]).
fn premultiply(rgba: &mut [u8]) {
    for t in rgba.chunks_exact_mut(4) {
        let a = f32::from(t[3]) / 255.0;
        if a >= QUAD_FULL_ALPHA {
            t[3] = 255;
        } else if a >= QUAD_ALPHA_CUTOFF {
            t[3] = lemi_core::compress::FRINGE_ALPHA;
        } else {
            t.copy_from_slice(&[0; 4]);
        }
    }
}

/// GPU resources of one baked cell: its near geometry, its macro-textures (packed into atlas
/// pages) and its quads.
pub struct ImpostorCell {
    pub(super) near: GpuScene,
    /// Vertex and index buffer of all quads; `None` without quads.
    pub(super) quad_buffers: Option<(wgpu::Buffer, wgpu::Buffer)>,
    /// One bind group per atlas page.
    pub(super) page_groups: Vec<wgpu::BindGroup>,
    /// Draw calls in draw order (by face and kind).
    pub(super) draws: Vec<QuadDraw>,
    /// The box around each draw call's quads.
    pub(super) bounds: Vec<Bounds>,
    quad_count: usize,
    opaque_quads: usize,
    texture_bytes: u64,
    /// Bytes of the atlas pages on the GPU.
    page_bytes: u64,
    /// The atlas pages' format ([`macro_format`], or its block-compressed counterpart).
    pub(super) macro_format: wgpu::TextureFormat,
}

impl ImpostorCell {
    /// `materials`: the scene's materials uploaded once ([`GpuMaterials::upload`]); `scene`: the
    /// scene the cell was baked from; `near`: the cell's near list, (mesh index, triangle index)
    /// pairs into `scene.meshes` (out-of-range pairs are [`GpuError::Extract`] naming the pair;
    /// triangles whose vertex indices are out of range are skipped, as [`GpuGeometry::upload`]
    /// does); `quads` and `macros`: from the cell file (a `macro_index` out of range, an empty
    /// `rect` or one outside its macro-texture, non-finite corners and macro-textures whose data
    /// does not match their size are [`GpuError::Invalid`]; macro-textures larger than the
    /// adapter's texture limit are [`GpuError::Limit`]).
    ///
    /// All input is checked before any GPU work. This is the incremental upload run to
    /// completion ([`ImpostorCellData::prepare_for`] this adapter, [`ImpostorCell::begin_upload`], one
    /// [`PendingImpostorCell::upload_step`] without a budget, [`PendingImpostorCell::finish`]); it
    /// copies `macros` once, and frees each copy as soon as its texture is written.
    pub fn upload(
        gpu: &Gpu,
        materials: Arc<GpuMaterials>,
        scene: &Scene,
        near: &[[u32; 2]],
        quads: &[Quad],
        macros: &[MacroTexture],
    ) -> Result<ImpostorCell, GpuError> {
        let side = gpu.limits().max_texture_dimension_2d;
        let data = ImpostorCellData::prepare_for(scene, near, quads, macros.to_vec(), side, None)?;
        let mut pending = ImpostorCell::begin_upload(gpu, materials, data)?;
        pending.upload_step(gpu, u64::MAX)?;
        pending.finish()
    }

    /// [`ImpostorCell::upload`] of a cell file: block-compressed macro-textures (bundle version
    /// 4) go to the GPU as they are stored where this adapter samples their format
    /// ([`Gpu::has_block_format`]), and are decoded to RGBA8 elsewhere (as PNG ones are).
    /// Macro-textures that do not decode are [`GpuError::Invalid`].
    pub fn upload_file(
        gpu: &Gpu,
        materials: Arc<GpuMaterials>,
        scene: &Scene,
        file: &CellFile,
    ) -> Result<ImpostorCell, GpuError> {
        let bad = |e: lemi_core::container::ContainerError| GpuError::Invalid(e.to_string());
        let macros = file.decode_macros().map_err(bad)?;
        let side = gpu.limits().max_texture_dimension_2d;
        let data = ImpostorCellData::prepare_for(
            scene,
            &file.near,
            &file.header.quads,
            macros,
            side,
            Some(super::SeenFrom::of(&file.header)),
        )?;
        let data = match file.block_macros().map_err(bad)? {
            Some(b) if b.first().is_some_and(|m| gpu.has_block_format(m.format)) => {
                data.with_blocks(b)?
            }
            _ => data,
        };
        let mut pending = ImpostorCell::begin_upload(gpu, materials, data)?;
        pending.upload_step(gpu, u64::MAX)?;
        pending.finish()
    }

    /// The atlas pages' texture format (RGBA8, or BC7/BC1 for blocks uploaded as stored).
    pub fn texture_format(&self) -> wgpu::TextureFormat {
        self.macro_format
    }

    /// Triangles of the near geometry on the GPU.
    pub fn near_triangles(&self) -> u64 {
        self.near.triangle_count()
    }

    /// Impostor quads of the cell.
    pub fn quad_count(&self) -> usize {
        self.quad_count
    }

    /// Bytes of macro-texture data (RGBA8, or BC7/BC1 blocks; no mipmaps), what the cell uploads.
    pub fn texture_bytes(&self) -> u64 {
        self.texture_bytes
    }

    /// Bytes of the atlas pages holding the macro-textures on the GPU (at least
    /// [`ImpostorCell::texture_bytes`]: the packing's gaps are resident too).
    pub fn resident_texture_bytes(&self) -> u64 {
        self.page_bytes
    }

    /// Atlas pages (textures) holding the macro-textures; 1 for any cell up to a page.
    pub fn atlas_pages(&self) -> usize {
        self.page_groups.len()
    }

    /// Draw calls the quads take at most (a view skips the faces it does not see): one per run of
    /// quads of one cube face, one kind (opaque or alpha-tested) and one atlas page, so at most
    /// 12 per page.
    pub fn quad_draw_calls(&self) -> usize {
        self.draws.len()
    }

    /// Quads whose texels all pass the alpha test, drawn with the opaque pipeline (no `discard`,
    /// so the rasterizer may test and write depth before shading).
    pub fn opaque_quad_count(&self) -> usize {
        self.opaque_quads
    }
}

/// The format macro-textures are uploaded in on `device`. Their texels are final sRGB-encoded
/// colours that the quads copy to the sRGB colour target unchanged. Where the colour target has a
/// linear view ([`crate::targets::linear_views_supported`]) they are `Rgba8Unorm` and drawn
/// through that view: no sRGB decode on fetching, no encode on storing (both cost a software
/// rasterizer much), the bytes pass through. Elsewhere (GL) they are `Rgba8UnormSrgb`, drawn into
/// the sRGB view: decoded on fetching and re-encoded on storing, which round-trips exactly.
pub(super) fn macro_format(device: &wgpu::Device) -> wgpu::TextureFormat {
    if crate::targets::linear_views_supported(device) {
        wgpu::TextureFormat::Rgba8Unorm
    } else {
        wgpu::TextureFormat::Rgba8UnormSrgb
    }
}

/// The page format of block-compressed macro-textures: the block format's variant that matches
/// [`macro_format`] (sRGB-decoded where the quads draw into the sRGB view, passed through where
/// they draw into the linear view), so a renderer draws both kinds of cells alike.
fn block_page_format(device: &wgpu::Device, format: BlockFormat) -> wgpu::TextureFormat {
    let srgb = macro_format(device).is_srgb();
    match (format, srgb) {
        (BlockFormat::Bc7, false) => wgpu::TextureFormat::Bc7RgbaUnorm,
        (BlockFormat::Bc7, true) => wgpu::TextureFormat::Bc7RgbaUnormSrgb,
        (BlockFormat::Bc1, false) => wgpu::TextureFormat::Bc1RgbaUnorm,
        (BlockFormat::Bc1, true) => wgpu::TextureFormat::Bc1RgbaUnormSrgb,
    }
}

/// Bytes of a `width × height` texture of `format` (RGBA8 or a 4×4 block format).
fn texture_bytes_of(format: wgpu::TextureFormat, width: u32, height: u32) -> u64 {
    let (bw, bh) = format.block_dimensions();
    let blocks = width.div_ceil(bw) as u64 * height.div_ceil(bh) as u64;
    blocks * format.block_copy_size(None).unwrap_or(4) as u64
}

/// One macro-texture's data on its way to the GPU, in upload rows: texel rows for RGBA8, rows
/// of 4×4 blocks for a block format.
struct MacroUpload {
    width: u32,
    height: u32,
    /// Texel rows per upload row (1, or 4 for blocks).
    row_texels: u32,
    /// Bytes per upload row.
    row_bytes: u64,
    data: Vec<u8>,
}

/// A cell whose upload is in progress: the geometry is on the GPU, the macro-textures are written
/// row by row into their atlas pages by [`PendingImpostorCell::upload_step`]. It cannot be drawn
/// (there is no way to hand it to [`ImpostorRenderer`]); [`PendingImpostorCell::finish`] turns a
/// complete one into an [`ImpostorCell`].
///
/// A page's texture is created when the first rows of a macro-texture on it are written, and a
/// macro-texture's CPU copy is freed when its last row is, so a cell in transit holds at most one
/// macro-texture twice.
pub struct PendingImpostorCell {
    near: GpuScene,
    quad_buffers: Option<(wgpu::Buffer, wgpu::Buffer)>,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// Where the macro-textures go.
    atlas: Atlas,
    /// The pages' textures and bind groups created so far, by page.
    pages: Vec<Option<(wgpu::Texture, wgpu::BindGroup)>>,
    /// CPU copies; a completed macro-texture's `data` is emptied.
    macros: Vec<MacroUpload>,
    draws: Vec<QuadDraw>,
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
    /// completion and [`PendingImpostorCell::finish`]. [`ImpostorCell::upload`] is this path run
    /// to completion at once; whatever the budgets, the result draws exactly like its.
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
        for (p, &(w, h)) in data.geometry.atlas.pages.iter().enumerate() {
            if w > max_dim || h > max_dim {
                return Err(GpuError::Limit(format!(
                    "atlas page {p} is {w}x{h}, larger than this adapter's textures ({max_dim} per side): \
                     prepare the cell for this adapter (ImpostorCellData::prepare_for)"
                )));
            }
        }
        let texture_bytes = data.texture_bytes();
        let page_format = match data.blocks.as_ref().and_then(|b| b.first()) {
            Some(b) if !gpu.has_block_format(b.format) => {
                return Err(GpuError::Invalid(format!(
                    "this adapter cannot sample {} macro-textures: upload them decoded to RGBA8",
                    b.format.texture_format()
                )))
            }
            Some(b) => block_page_format(&gpu.device, b.format),
            None => macro_format(&gpu.device),
        };
        if page_format.is_compressed() {
            // copies into a block-compressed page must be block-aligned
            let aligned = |v: u32| v % 4 == 0;
            let pages_ok = data
                .geometry
                .atlas
                .pages
                .iter()
                .all(|&(w, h)| aligned(w) && aligned(h));
            let places_ok = data
                .geometry
                .atlas
                .places
                .iter()
                .all(|p| aligned(p.x) && aligned(p.y));
            if !pages_ok || !places_ok {
                return Err(GpuError::Invalid(
                    "block-compressed macro-textures packed off 4×4 block boundaries".into(),
                ));
            }
        }
        let ImpostorCellData {
            near_meshes,
            geometry:
                QuadGeometry {
                    vertices,
                    indices,
                    draws,
                    atlas,
                    bounds,
                    opaque_quads,
                },
            macros,
            blocks,
            quad_count,
        } = data;
        let macros: Vec<MacroUpload> = match blocks {
            Some(blocks) => blocks
                .into_iter()
                .map(|b| MacroUpload {
                    width: b.width,
                    height: b.height,
                    row_texels: 4,
                    row_bytes: (b.width / 4) as u64 * b.format.block_bytes() as u64,
                    data: b.data,
                })
                .collect(),
            None => macros
                .into_iter()
                .map(|mut m| {
                    premultiply(&mut m.rgba);
                    MacroUpload {
                        width: m.width,
                        height: m.height,
                        row_texels: 1,
                        row_bytes: 4 * m.width as u64,
                        data: m.rgba,
                    }
                })
                .collect(),
        };
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
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
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
            pages: atlas.pages.iter().map(|_| None).collect(),
            atlas,
            macros,
            draws,
            bounds,
            quad_count,
            opaque_quads,
            texture_bytes,
            macro_format: page_format,
            geometry_bytes,
            next_macro: 0,
            next_row: 0,
            uploaded: 0,
        })
    }

    /// Bytes this cell holds on the GPU: atlas pages plus vertex and index buffers.
    pub fn gpu_bytes(&self) -> u64 {
        self.page_bytes + buffer_bytes(&self.quad_buffers, &self.near)
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
                let row_bytes = m.row_bytes;
                let rows_left = m.height / m.row_texels - self.next_row;
                let fit = (max_bytes.saturating_sub(written) / row_bytes).min(rows_left as u64);
                let rows = if written == 0 { fit.max(1) } else { fit } as u32;
                if rows == 0 {
                    break;
                }
                let Some(&Place { page, x, y }) = self.atlas.places.get(self.next_macro) else {
                    break;
                };
                let Some(slot) = self.pages.get_mut(page as usize) else {
                    break;
                };
                if slot.is_none() {
                    let Some(&(width, height)) = self.atlas.pages.get(page as usize) else {
                        break;
                    };
                    *slot = Some(create_page(
                        gpu,
                        page,
                        (width, height),
                        self.macro_format,
                        &self.layout,
                        &self.sampler,
                    ));
                }
                let Some((texture, _)) = slot.as_ref() else {
                    break;
                };
                let start = (self.next_row as u64 * row_bytes) as usize;
                let end = start + (rows as u64 * row_bytes) as usize;
                gpu.queue.write_texture(
                    wgpu::TexelCopyTextureInfo {
                        texture,
                        mip_level: 0,
                        origin: wgpu::Origin3d {
                            x,
                            y: y + self.next_row * m.row_texels,
                            z: 0,
                        },
                        aspect: wgpu::TextureAspect::All,
                    },
                    &m.data[start..end],
                    wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(row_bytes as u32),
                        // rows of blocks for a block format
                        rows_per_image: Some(rows),
                    },
                    wgpu::Extent3d {
                        width: m.width,
                        height: rows * m.row_texels,
                        depth_or_array_layers: 1,
                    },
                );
                written += rows as u64 * row_bytes;
                self.uploaded += rows as u64 * row_bytes;
                self.next_row += rows;
                if self.next_row * m.row_texels == m.height {
                    // Complete: the page stays alive through its bind group.
                    self.macros[self.next_macro].data = Vec::new();
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

    /// Bytes held on the GPU so far: geometry buffers plus the atlas pages created so far.
    pub fn gpu_bytes(&self) -> u64 {
        let pages: u64 = (self.atlas.pages.iter().zip(&self.pages))
            .filter(|(_, made)| made.is_some())
            .map(|(&(w, h), _)| texture_bytes_of(self.macro_format, w, h))
            .sum();
        self.geometry_bytes + pages
    }

    /// Bytes of macro-texture data still held in main memory.
    pub fn cpu_bytes(&self) -> u64 {
        self.macros.iter().map(|m| m.data.len() as u64).sum()
    }

    /// The drawable cell; [`GpuError::Invalid`] if some macro-texture is not completely written.
    pub fn finish(self) -> Result<ImpostorCell, GpuError> {
        let page_bytes: u64 = (self.atlas.pages.iter())
            .map(|&(w, h)| texture_bytes_of(self.macro_format, w, h))
            .sum();
        let page_groups: Option<Vec<wgpu::BindGroup>> = (self.pages.into_iter())
            .map(|p| p.map(|(_, g)| g))
            .collect();
        let (true, Some(page_groups)) = (self.next_macro >= self.macros.len(), page_groups) else {
            return Err(GpuError::Invalid(format!(
                "the cell's upload is incomplete: {} of {} macro-texture bytes written",
                self.uploaded, self.texture_bytes
            )));
        };
        Ok(ImpostorCell {
            near: self.near,
            quad_buffers: self.quad_buffers,
            page_groups,
            draws: self.draws,
            bounds: self.bounds,
            quad_count: self.quad_count,
            opaque_quads: self.opaque_quads,
            texture_bytes: self.texture_bytes,
            page_bytes,
            macro_format: self.macro_format,
        })
    }
}

/// An atlas page's texture and its bind group (group 1 of the quad pipelines, [`macro_layout`]).
fn create_page(
    gpu: &Gpu,
    page: u32,
    (width, height): (u32, u32),
    format: wgpu::TextureFormat,
    layout: &wgpu::BindGroupLayout,
    sampler: &wgpu::Sampler,
) -> (wgpu::Texture, wgpu::BindGroup) {
    let label = format!("lemi macro-texture atlas page {page}");
    // Texels stored sRGB-encoded and passed through are filtered through an sRGB view: decoded
    // to linear light before they are mixed.
    let srgb = format.add_srgb_suffix();
    let view_formats = [srgb];
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(&label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: if srgb == format { &[] } else { &view_formats },
    });
    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
    let linear = texture.create_view(&wgpu::TextureViewDescriptor {
        format: Some(srgb),
        ..Default::default()
    });
    let params = PageParams {
        flags: [
            f32::from(u8::from(transparent_black(format))),
            0.0,
            0.0,
            0.0,
        ],
    };
    let params = gpu
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(&label),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
    let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(&label),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::TextureView(&view),
            },
            wgpu::BindGroupEntry {
                binding: 4,
                resource: wgpu::BindingResource::Sampler(sampler),
            },
            wgpu::BindGroupEntry {
                binding: 5,
                resource: wgpu::BindingResource::TextureView(&linear),
            },
            wgpu::BindGroupEntry {
                binding: 6,
                resource: params.as_entire_binding(),
            },
        ],
    });
    (texture, group)
}

#[cfg(test)]
mod tests {
    //! The incremental upload ([`ImpostorCell::begin_upload`] + [`PendingImpostorCell`]) against
    //! the one-shot [`ImpostorCell::upload`].
    use super::*;

    use crate::impostor::test_support::{gpu, pattern, quad, scene, view};
    use crate::{ImpostorRenderer, RenderOptions};
    use lemi_core::scene::ExtractError;

    /// Block-compressed macro-textures uploaded as stored, in chunks of block rows: every budget
    /// renders like the one-shot upload, the pages are in the block format and hold its bytes
    /// (a quarter of RGBA8 for BC7, an eighth for BC1), and the picture has the coverage of the
    /// same blocks decoded to RGBA8 on the CPU, colours within the decoders' rounding.
    #[test]
    fn block_compressed_macro_textures_upload_in_block_rows() {
        use lemi_core::bundle::BlockMacro;
        use lemi_core::compress::decode_blocks;
        let Some(gpu) = gpu() else { return };
        if !gpu.has_block_format(BlockFormat::Bc7) {
            eprintln!("SKIPPED block_compressed_macro_textures_upload_in_block_rows: no BC on this adapter");
            return;
        }
        let scene = scene();
        let materials =
            Arc::new(GpuMaterials::upload(&gpu, &scene.materials, &scene.textures).expect("mats"));
        let rgba = vec![pattern(16, 12, 0), pattern(32, 16, 1), pattern(8, 20, 2)];
        let quads = [
            quad(0, [0, 0, 13, 9], [-4.0, -0.5, 0.5, 3.5, -5.0]),
            quad(1, [0, 0, 32, 16], [-3.0, 3.0, -3.5, 0.0, -6.0]),
            quad(2, [0, 0, 8, 20], [0.5, 3.5, 0.5, 4.0, -5.5]),
            quad(1, [4, 4, 8, 8], [-1.0, 1.0, -1.0, 1.0, -7.0]),
        ];
        let near = [[0u32, 0u32]];
        // The texels as stored: filtering weighs a BC7 page's transparent texels (which carry
        // their block's mean colour) unlike a decoded page's (transparent black), see PageParams.
        let mut r = ImpostorRenderer::new(&gpu).expect("renderer");
        r.set_texel_filter(crate::TexelFilter::Nearest);
        let (view, opts) = (view(), RenderOptions::default());
        let rgba_cell = ImpostorCell::upload(&gpu, materials.clone(), &scene, &near, &quads, &rgba)
            .expect("RGBA8 upload");
        for format in [BlockFormat::Bc7, BlockFormat::Bc1] {
            let blocks: Vec<BlockMacro> = rgba
                .iter()
                .map(|m| BlockMacro::encode(format, m).expect("encode"))
                .collect();
            let decoded: Vec<MacroTexture> = blocks
                .iter()
                .map(|b| MacroTexture {
                    width: b.width,
                    height: b.height,
                    rgba: decode_blocks(b.format, b.width, b.height, &b.data).expect("decode"),
                })
                .collect();
            let prepare = || {
                ImpostorCellData::prepare(&scene, &near, &quads, decoded.clone())
                    .expect("prepare")
                    .with_blocks(blocks.clone())
                    .expect("blocks")
            };
            let total: u64 = blocks.iter().map(|b| b.data.len() as u64).sum();
            let mut one =
                ImpostorCell::begin_upload(&gpu, materials.clone(), prepare()).expect("begin");
            one.upload_step(&gpu, u64::MAX).expect("upload");
            let one = one.finish().expect("finish");
            assert!(one.texture_format().is_compressed());
            assert_eq!(one.texture_bytes(), total);
            let per_block = format.block_bytes() as u64;
            assert_eq!(
                one.resident_texture_bytes() * 64 / per_block,
                rgba_cell.resident_texture_bytes(),
                "{format:?}: 16 texels of 4 bytes against a block"
            );
            let want = r.render(&one, &view, &opts).expect("render");
            // the same blocks decoded on the CPU: the same coverage, colours close
            let cpu =
                ImpostorCell::upload(&gpu, materials.clone(), &scene, &near, &quads, &decoded)
                    .expect("decoded upload");
            let cpu = r.render(&cpu, &view, &opts).expect("render decoded");
            assert!(want.covered_count() > 1000);
            assert_eq!(
                want.depth, cpu.depth,
                "{format:?}: the alpha test passes the same texels"
            );
            let worst = want
                .rgba
                .iter()
                .zip(&cpu.rgba)
                .map(|(a, b)| a.abs_diff(*b))
                .max();
            assert!(
                worst <= Some(3),
                "{format:?}: GPU and CPU decoding differ by {worst:?}"
            );
            for budget in [0u64, 1, 100, 1000] {
                let mut pending =
                    ImpostorCell::begin_upload(&gpu, materials.clone(), prepare()).expect("begin");
                let mut steps = 0;
                while !pending.upload_step(&gpu, budget).expect("step") {
                    steps += 1;
                    assert!(steps < 10_000);
                }
                assert_eq!(pending.uploaded_bytes(), total);
                assert_eq!(pending.cpu_bytes(), 0);
                let cell = pending.finish().expect("finish");
                assert_eq!(cell.gpu_bytes(), one.gpu_bytes());
                let got = r.render(&cell, &view, &opts).expect("render");
                assert!(
                    got == want,
                    "{format:?} budget {budget}: renders differently"
                );
            }
        }
        // blocks of other sizes than the prepared macro-textures are refused
        let data =
            ImpostorCellData::prepare(&scene, &near, &[], vec![pattern(8, 8, 0)]).expect("prep");
        let wrong = BlockMacro {
            format: BlockFormat::Bc1,
            width: 4,
            height: 8,
            data: vec![0; 16],
        };
        assert!(matches!(
            data.with_blocks(vec![wrong]),
            Err(GpuError::Invalid(_))
        ));
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
        let view = view();
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
            assert_eq!(
                pending.geometry_bytes() + one_shot.resident_texture_bytes(),
                one_shot.gpu_bytes()
            );
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
            Err(GpuError::Extract(ExtractError::NoMesh { .. }))
        ));
        assert!(matches!(
            ImpostorCellData::prepare(&scene, &[], &quads, Vec::new()),
            Err(GpuError::Invalid(_))
        ));
    }
}
