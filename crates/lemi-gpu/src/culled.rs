//! The `geometry-culled` baseline on the GPU: a scene uploaded in the spatially coherent chunks of
//! [`lemi_core::culling::CullLayout`] (per material, Morton-ordered clusters of triangles in groups,
//! each with a bounding box), drawn by [`crate::Renderer::render_culled`] with the reference
//! renderer's pipeline and shading after frustum culling the hierarchy on the CPU. The culling test
//! is conservative, so the image is the unculled one; only fewer triangles are submitted.

use std::sync::Arc;

use glam::DMat4;
use lemi_core::culling::{CullHierarchy, CullLayout, CullLayoutOptions, CullList};
use lemi_core::{Scene, Vertex};
use wgpu::util::DeviceExt;

use crate::scene::{GpuChunk, GpuMaterials, UploadOptions};
use crate::{Gpu, GpuError};

/// How a scene is cut for culling.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CullOptions {
    /// Triangles per cluster, the finest culling unit.
    pub cluster_triangles: usize,
    /// Clusters per group (the hierarchy's middle level, so the per-frame test stays cheap).
    pub group_clusters: usize,
    /// Buffer limits of one chunk, as for the unculled upload.
    pub upload: UploadOptions,
}

impl Default for CullOptions {
    fn default() -> Self {
        let l = CullLayoutOptions::default();
        CullOptions {
            cluster_triangles: l.cluster_triangles,
            group_clusters: l.group_clusters,
            upload: UploadOptions::default(),
        }
    }
}

/// What one culled frame submitted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CullStats {
    /// Triangles submitted.
    pub triangles: u64,
    /// Draw calls issued.
    pub draw_calls: u64,
    /// Boxes the CPU tested (chunks, groups and clusters).
    pub boxes_tested: u64,
}

impl From<&CullList> for CullStats {
    fn from(l: &CullList) -> Self {
        CullStats {
            triangles: l.triangles,
            draw_calls: l.draws.len() as u64,
            boxes_tested: l.boxes_tested,
        }
    }
}

/// Geometry in culling chunks: the GPU buffers and the boxes of their hierarchy.
pub struct CulledGeometry {
    chunks: Vec<GpuChunk>,
    hierarchy: CullHierarchy,
}

impl CulledGeometry {
    /// Lays out and uploads `scene`'s triangles (see [`CullLayout::build`]; triangles with an
    /// index past their mesh's vertex array are skipped).
    pub fn upload(
        gpu: &Gpu,
        scene: &Scene,
        options: &CullOptions,
    ) -> Result<CulledGeometry, GpuError> {
        let stride = std::mem::size_of::<Vertex>() as u64;
        let cap = options
            .upload
            .max_chunk_bytes
            .min(gpu.limits().max_buffer_size)
            .max(3 * stride);
        let layout = CullLayout::build(
            &scene.meshes,
            &CullLayoutOptions {
                cluster_triangles: options.cluster_triangles,
                group_clusters: options.group_clusters,
                max_vertices: (cap / stride).min(u32::MAX as u64) as usize,
                max_indices: ((cap / 4).min(u32::MAX as u64) as usize / 3 * 3).max(3),
            },
        );
        let chunks = gpu.scoped("uploading culled geometry", || {
            layout
                .chunks
                .iter()
                .map(|c| GpuChunk {
                    material: c.material,
                    vertices: gpu
                        .device
                        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                            label: Some("lemi culled vertices"),
                            contents: bytemuck::cast_slice(&c.vertices),
                            usage: wgpu::BufferUsages::VERTEX,
                        }),
                    indices: gpu
                        .device
                        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                            label: Some("lemi culled indices"),
                            contents: bytemuck::cast_slice(&c.indices),
                            usage: wgpu::BufferUsages::INDEX,
                        }),
                    index_count: c.indices.len() as u32,
                })
                .collect()
        })?;
        Ok(CulledGeometry {
            chunks,
            hierarchy: layout.hierarchy,
        })
    }

    /// The draws of the chunks, groups and clusters whose box is not outside the clip volume of
    /// `view_proj` (CPU only).
    pub fn cull(&self, view_proj: &DMat4) -> CullList {
        self.hierarchy.cull(view_proj)
    }

    pub fn chunks(&self) -> &[GpuChunk] {
        &self.chunks
    }

    pub fn hierarchy(&self) -> &CullHierarchy {
        &self.hierarchy
    }

    pub fn triangle_count(&self) -> u64 {
        self.hierarchy.triangle_count()
    }
}

/// Materials plus culling geometry: what [`crate::Renderer::render_culled`] draws.
pub struct GpuCulledScene {
    pub materials: Arc<GpuMaterials>,
    pub geometry: CulledGeometry,
}

impl GpuCulledScene {
    /// Uploads a whole scene for culled drawing.
    pub fn upload(
        gpu: &Gpu,
        scene: &Scene,
        options: &CullOptions,
    ) -> Result<GpuCulledScene, GpuError> {
        let materials = Arc::new(GpuMaterials::upload(
            gpu,
            &scene.materials,
            &scene.textures,
        )?);
        GpuCulledScene::from_parts(materials, CulledGeometry::upload(gpu, scene, options)?)
    }

    /// Culling geometry against materials uploaded earlier (e.g. those of the unculled
    /// [`crate::GpuScene`] of the same scene). Fails when a chunk names a material that does not
    /// exist.
    pub fn from_parts(
        materials: Arc<GpuMaterials>,
        geometry: CulledGeometry,
    ) -> Result<GpuCulledScene, GpuError> {
        if let Some(m) = geometry.chunks.iter().map(|c| c.material).max() {
            if m as usize >= materials.len() {
                return Err(GpuError::Invalid(format!(
                    "a mesh uses material {m} but only {} materials were uploaded",
                    materials.len()
                )));
            }
        }
        Ok(GpuCulledScene {
            materials,
            geometry,
        })
    }

    pub fn triangle_count(&self) -> u64 {
        self.geometry.triangle_count()
    }
}
