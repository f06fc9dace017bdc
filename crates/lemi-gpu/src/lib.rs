//! lemi-gpu: everything that talks to the GPU through wgpu (one renderer for bake, view and eval).
//!
//! - [`Gpu`]: adapter and device setup (any wgpu backend; Mesa's lavapipe/llvmpipe without a GPU).
//! - [`shading`]: the one shading model (WGSL module + CPU mirror) every pipeline shares.
//! - [`GpuScene`]: materials and chunked geometry on the GPU.
//! - [`Renderer`]: the reference renderer, the ground truth impostors are compared with.
//! - [`GpuCulledScene`]: the same scene in Morton-ordered clusters with bounding boxes, drawn
//!   frustum-culled by [`Renderer::render_culled`] (the `geometry-culled` baseline).
//! - [`ImpostorRenderer`]: the runtime view of one baked cell ([`ImpostorCell`]): near geometry
//!   plus the layered impostor quads.
//! - [`LayerRecorder`] and [`CellRecorder`]: the crack-free recording of a cell's layers (what the
//!   bake compresses and the certificate measures depths with).
//!
//! ```no_run
//! use lemi_core::camera::Camera;
//! use lemi_gpu::{BackendChoice, Gpu, GpuScene, RenderOptions, Renderer, UploadOptions};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! # let scene = lemi_core::SceneBuilder::new().finish();
//! let gpu = Gpu::new(BackendChoice::Auto)?;
//! let gpu_scene = GpuScene::upload(&gpu, &scene, &UploadOptions::default())?;
//! let camera = Camera::look_at(
//!     glam::DVec3::new(0.0, 2.0, 10.0), glam::DVec3::ZERO, glam::DVec3::Y, 60.0, 1280, 720)?;
//! let frame = Renderer::new(&gpu)?.render(&gpu_scene, &camera.view(), &RenderOptions::default())?;
//! assert_eq!(frame.rgba.len(), 1280 * 720 * 4);
//! # Ok(()) }
//! ```

pub mod cell_recorder;
pub mod culled;
mod device;
pub mod impostor;
pub mod recorder;
mod renderer;
mod scene;
pub mod shading;
mod surface;
mod targets;
pub mod texture;

pub use cell_recorder::{CellRecorder, RecordError, RecordedFace, Recording};
pub use culled::{CullOptions, CullStats, CulledGeometry, GpuCulledScene};
pub use device::{no_adapter_message, BackendChoice, Gpu, GpuError};
pub use impostor::{
    Composite, ImpostorCell, ImpostorCellData, ImpostorRenderer, PendingImpostorCell, SeenFrom,
    TexelFilter, DEFAULT_PAGE_SIDE, QUAD_ALPHA_CUTOFF,
};
pub use recorder::{LayerFrame, LayerRecorder, MaterialRun, RecordOptions};
pub use renderer::{
    padded_bytes_per_row, Frame, RenderOptions, Renderer, COLOR_FORMAT, DEPTH_FORMAT,
    VIEW_DEPTH_FORMAT,
};
pub use scene::{
    GpuChunk, GpuGeometry, GpuMaterials, GpuScene, UploadOptions, DEFAULT_MAX_CHUNK_BYTES,
};
pub use shading::{Lighting, ShadingGlobals};
pub use surface::{Presented, WindowSurface};
