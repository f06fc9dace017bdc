//! Scenes on the GPU: materials (one bind group each: base colour uniform, mip-mapped texture,
//! shared sampler) and geometry in chunks that respect the device's buffer limits, so scenes of
//! millions of triangles upload, and so the baker can upload transient per-slab triangle sets against
//! materials uploaded once.
//!
//! Chunking: meshes are grouped by material (stable, in input order) and packed into vertex/index
//! buffer pairs no larger than [`UploadOptions::max_chunk_bytes`] and the device's
//! `max_buffer_size`; a mesh that does not fit is split at triangle boundaries with its vertices
//! re-indexed per chunk. One draw call per chunk.

use std::sync::Arc;

use lemi_core::{Material, Mesh, Scene, Texture, Vertex};
use wgpu::util::DeviceExt;

use crate::shading::MaterialUniform;
use crate::texture::{mip_chain, upload_levels};
use crate::{Gpu, GpuError};

/// Default chunk size: 128 MiB per vertex or index buffer.
pub const DEFAULT_MAX_CHUNK_BYTES: u64 = 128 << 20;

/// How geometry is cut into GPU buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UploadOptions {
    /// Upper bound for one vertex buffer and one index buffer, in bytes (further capped by the
    /// device's `max_buffer_size`; at least one triangle always fits).
    pub max_chunk_bytes: u64,
}

impl Default for UploadOptions {
    fn default() -> Self {
        UploadOptions {
            max_chunk_bytes: DEFAULT_MAX_CHUNK_BYTES,
        }
    }
}

/// A scene's materials on the GPU, one bind group per material (group 1 of the shading module).
pub struct GpuMaterials {
    bind_groups: Vec<wgpu::BindGroup>,
    /// Per material, whether it samples a texture of its own (else the 1×1 white one).
    textured: Vec<bool>,
}

impl GpuMaterials {
    /// Uploads materials and the textures they use (each texture once, with mipmaps). Materials
    /// without a texture sample a 1×1 white texture.
    pub fn upload(
        gpu: &Gpu,
        materials: &[Material],
        textures: &[Texture],
    ) -> Result<GpuMaterials, GpuError> {
        let max_dim = gpu.limits().max_texture_dimension_2d;
        // Decode mip chains on the CPU first so that bad input fails before any GPU work.
        let mut chains: Vec<Option<Vec<crate::texture::MipLevel>>> = vec![None; textures.len()];
        for m in materials {
            if let Some(t) = m.texture {
                let tex = textures.get(t as usize).ok_or_else(|| {
                    GpuError::Invalid(format!(
                        "material `{}` uses texture {t} but the scene has {} textures",
                        m.name,
                        textures.len()
                    ))
                })?;
                if chains[t as usize].is_none() {
                    chains[t as usize] = Some(mip_chain(tex, max_dim)?);
                }
            }
            if m.base_color.iter().any(|c| !c.is_finite()) {
                return Err(GpuError::Invalid(format!(
                    "material `{}` has a non-finite base colour {:?}",
                    m.name, m.base_color
                )));
            }
        }
        gpu.scoped("uploading materials and textures", || {
            let white = upload_levels(
                gpu,
                "lemi white",
                &[crate::texture::MipLevel {
                    width: 1,
                    height: 1,
                    rgba8: vec![255; 4],
                }],
            );
            let views: Vec<Option<wgpu::TextureView>> = chains
                .iter()
                .zip(textures)
                .map(|(c, t)| c.as_ref().map(|levels| upload_levels(gpu, &t.name, levels)))
                .collect();
            let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("lemi base colour sampler"),
                address_mode_u: wgpu::AddressMode::Repeat,
                address_mode_v: wgpu::AddressMode::Repeat,
                address_mode_w: wgpu::AddressMode::Repeat,
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                mipmap_filter: wgpu::MipmapFilterMode::Linear,
                ..Default::default()
            });
            let texture_view = |m: &Material| {
                m.texture
                    .and_then(|t| views.get(t as usize).and_then(|v| v.as_ref()))
            };
            let textured = materials
                .iter()
                .map(|m| texture_view(m).is_some())
                .collect();
            let bind_groups = materials
                .iter()
                .map(|m| {
                    let uniform =
                        gpu.device
                            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                                label: Some("lemi material"),
                                contents: bytemuck::bytes_of(&MaterialUniform {
                                    base_color: m.base_color,
                                }),
                                usage: wgpu::BufferUsages::UNIFORM,
                            });
                    let view = texture_view(m).unwrap_or(&white);
                    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some(&m.name),
                        layout: gpu.material_layout(),
                        entries: &[
                            wgpu::BindGroupEntry {
                                binding: 0,
                                resource: uniform.as_entire_binding(),
                            },
                            wgpu::BindGroupEntry {
                                binding: 1,
                                resource: wgpu::BindingResource::TextureView(view),
                            },
                            wgpu::BindGroupEntry {
                                binding: 2,
                                resource: wgpu::BindingResource::Sampler(&sampler),
                            },
                        ],
                    })
                })
                .collect();
            GpuMaterials {
                bind_groups,
                textured,
            }
        })
    }

    pub fn len(&self) -> usize {
        self.bind_groups.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bind_groups.is_empty()
    }

    /// The bind group of material `i` (for group 1 of the shading module).
    pub fn bind_group(&self, i: u32) -> Option<&wgpu::BindGroup> {
        self.bind_groups.get(i as usize)
    }

    /// Whether material `i` samples a texture of its own; `false` for one that samples the 1×1
    /// white texture, which pipelines for untextured materials draw without a fetch (`true` for
    /// an unknown material: its pipeline then samples whatever is bound).
    pub fn textured(&self, i: u32) -> bool {
        self.textured.get(i as usize).copied().unwrap_or(true)
    }
}

/// One vertex/index buffer pair drawn with one material.
pub struct GpuChunk {
    pub material: u32,
    pub vertices: wgpu::Buffer,
    pub indices: wgpu::Buffer,
    pub index_count: u32,
}

/// Triangles on the GPU, in chunks.
pub struct GpuGeometry {
    chunks: Vec<GpuChunk>,
    triangles: u64,
    max_material: Option<u32>,
}

/// CPU-side chunk under construction.
struct ChunkBuilder {
    material: u32,
    vertices: Vec<Vertex>,
    indices: Vec<u32>,
}

impl GpuGeometry {
    /// Uploads the triangles of `meshes`, grouped by material and chunked (see the module docs).
    /// Triangles with an index past their mesh's vertex array are skipped.
    pub fn upload<'a>(
        gpu: &Gpu,
        meshes: impl IntoIterator<Item = &'a Mesh>,
        options: &UploadOptions,
    ) -> Result<GpuGeometry, GpuError> {
        let stride = std::mem::size_of::<Vertex>() as u64;
        let cap = options
            .max_chunk_bytes
            .min(gpu.limits().max_buffer_size)
            .max(3 * stride);
        let max_vertices = (cap / stride).min(u32::MAX as u64) as usize;
        let max_indices = ((cap / 4).min(u32::MAX as u64) as usize / 3 * 3).max(3);
        let mut by_material: Vec<&Mesh> = meshes.into_iter().collect();
        by_material.sort_by_key(|m| m.material); // stable: input order within a material
        let mut geometry = GpuGeometry {
            chunks: Vec::new(),
            triangles: 0,
            max_material: None,
        };
        let mut b = ChunkBuilder {
            material: by_material.first().map(|m| m.material).unwrap_or(0),
            vertices: Vec::new(),
            indices: Vec::new(),
        };
        // Generation stamps for re-indexing split meshes: remap[v] is valid when stamp[v] == gen.
        let mut remap: Vec<u32> = Vec::new();
        let mut stamp: Vec<u64> = Vec::new();
        let mut gen: u64 = 0;
        for mesh in by_material {
            if mesh.indices.len() < 3 {
                continue;
            }
            if mesh.material != b.material {
                geometry.flush(gpu, &mut b)?;
                b.material = mesh.material;
            }
            let n = mesh.vertices.len();
            let valid = mesh.indices.iter().all(|&i| (i as usize) < n);
            let whole = mesh.indices.len() / 3 * 3;
            let fits_empty = n <= max_vertices && whole <= max_indices;
            if valid
                && fits_empty
                && (b.vertices.len() + n > max_vertices || b.indices.len() + whole > max_indices)
            {
                // Start a new chunk rather than split a mesh that fits in one.
                geometry.flush(gpu, &mut b)?;
            }
            if valid
                && b.vertices.len() + n <= max_vertices
                && b.indices.len() + whole <= max_indices
            {
                // Fast path: the whole mesh fits in the current chunk.
                let base = b.vertices.len() as u32;
                b.vertices.extend_from_slice(&mesh.vertices);
                b.indices
                    .extend(mesh.indices[..whole].iter().map(|&i| i + base));
                continue;
            }
            if n == 0 {
                continue;
            }
            // Split at triangle boundaries, re-indexing vertices per chunk.
            gen += 1;
            remap.clear();
            remap.resize(n, 0);
            stamp.clear();
            stamp.resize(n, 0);
            for tri in mesh.indices.chunks_exact(3) {
                if tri.iter().any(|&i| i as usize >= n) {
                    continue;
                }
                let new = tri
                    .iter()
                    .enumerate()
                    .filter(|&(k, &i)| stamp[i as usize] != gen && !tri[..k].contains(&i))
                    .count();
                if b.vertices.len() + new > max_vertices || b.indices.len() + 3 > max_indices {
                    geometry.flush(gpu, &mut b)?;
                    gen += 1;
                }
                for &i in tri {
                    let i = i as usize;
                    if stamp[i] != gen {
                        stamp[i] = gen;
                        remap[i] = b.vertices.len() as u32;
                        b.vertices.push(mesh.vertices[i]);
                    }
                    b.indices.push(remap[i]);
                }
            }
        }
        geometry.flush(gpu, &mut b)?;
        Ok(geometry)
    }

    fn flush(&mut self, gpu: &Gpu, b: &mut ChunkBuilder) -> Result<(), GpuError> {
        if b.indices.is_empty() {
            b.vertices.clear();
            return Ok(());
        }
        let chunk = gpu.scoped("uploading geometry", || {
            let vertices = gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("lemi vertices"),
                    contents: bytemuck::cast_slice(&b.vertices),
                    usage: wgpu::BufferUsages::VERTEX,
                });
            let indices = gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("lemi indices"),
                    contents: bytemuck::cast_slice(&b.indices),
                    usage: wgpu::BufferUsages::INDEX,
                });
            GpuChunk {
                material: b.material,
                vertices,
                indices,
                index_count: b.indices.len() as u32,
            }
        })?;
        self.triangles += b.indices.len() as u64 / 3;
        self.max_material = Some(self.max_material.map_or(b.material, |m| m.max(b.material)));
        self.chunks.push(chunk);
        b.vertices.clear();
        b.indices.clear();
        Ok(())
    }

    pub fn chunks(&self) -> &[GpuChunk] {
        &self.chunks
    }

    pub fn triangle_count(&self) -> u64 {
        self.triangles
    }
}

/// Materials plus geometry: what the renderer draws.
pub struct GpuScene {
    pub materials: Arc<GpuMaterials>,
    pub geometry: GpuGeometry,
}

impl GpuScene {
    /// Uploads a whole scene.
    pub fn upload(gpu: &Gpu, scene: &Scene, options: &UploadOptions) -> Result<GpuScene, GpuError> {
        let materials = Arc::new(GpuMaterials::upload(
            gpu,
            &scene.materials,
            &scene.textures,
        )?);
        let geometry = GpuGeometry::upload(gpu, &scene.meshes, options)?;
        GpuScene::from_parts(materials, geometry)
    }

    /// Geometry against materials uploaded earlier (the baker uploads per-slab triangle sets this
    /// way). Fails when a chunk names a material that does not exist.
    pub fn from_parts(
        materials: Arc<GpuMaterials>,
        geometry: GpuGeometry,
    ) -> Result<GpuScene, GpuError> {
        if let Some(m) = geometry.max_material {
            if m as usize >= materials.len() {
                return Err(GpuError::Invalid(format!(
                    "a mesh uses material {m} but only {} materials were uploaded",
                    materials.len()
                )));
            }
        }
        Ok(GpuScene {
            materials,
            geometry,
        })
    }

    pub fn triangle_count(&self) -> u64 {
        self.geometry.triangle_count()
    }
}
