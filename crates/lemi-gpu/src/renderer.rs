//! The reference renderer: draws a [`GpuScene`] from a [`View`] into an sRGB colour image and a
//! linear depth image, and reads both back. It is the ground truth impostors are compared with.
//!
//! One pass, no MSAA (comparisons want exact texels), no back-face culling (polygon soups), reverse-Z
//! depth test (`Greater`, cleared to 0; see `lemi_core::camera`), shading from the shared module
//! ([`crate::shading`]). A second colour target stores the view depth (distance along the view axis)
//! as the bits of an f32 in `R32Uint`, so the depth image is linear on every backend. Readback
//! pads rows to wgpu's 256-byte `COPY_BYTES_PER_ROW_ALIGNMENT`. A frame that is not read back
//! (`render_frame`, as a runtime presenting its frames draws them) has no view-depth target: the
//! same colour without a second store per fragment.

use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use lemi_core::camera::View;
use lemi_core::culling::CullList;

use crate::culled::{CullStats, GpuCulledScene};
use crate::scene::{GpuChunk, GpuMaterials, GpuScene};
use crate::shading::{vertex_layout, Lighting, ShadingGlobals, SHADING_WGSL};
use crate::targets::Targets;
use crate::{Gpu, GpuError};

/// The colour target format: linear shading output, encoded to sRGB on store.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// The linear view-depth target format: the bits of an f32 (`R32Float` is not renderable on every
/// backend, `R32Uint` is).
pub const VIEW_DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
/// The depth buffer format (reverse-Z).
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

const RENDER_WGSL: &str = include_str!("render.wgsl");

/// Per-frame options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    pub lighting: Lighting,
    /// sRGB-encoded RGBA written where no geometry was drawn (default transparent black).
    pub clear: [u8; 4],
    /// Fragments whose albedo alpha is below this are discarded (0, the default, keeps all).
    pub alpha_cutoff: f32,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            lighting: Lighting::default(),
            clear: [0, 0, 0, 0],
            alpha_cutoff: 0.0,
        }
    }
}

/// A rendered image, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// sRGB-encoded RGBA8; alpha 255 where geometry was drawn, the clear colour elsewhere.
    pub rgba: Vec<u8>,
    /// Linear view-space distance along the view axis; `f32::INFINITY` for background.
    pub depth: Vec<f32>,
}

impl Frame {
    /// RGBA of pixel `(x, y)`; `None` outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 4]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = 4 * (y as usize * self.width as usize + x as usize);
        self.rgba.get(i..i + 4).and_then(|s| s.try_into().ok())
    }

    /// Depth of pixel `(x, y)`; `None` outside the image.
    pub fn depth_at(&self, x: u32, y: u32) -> Option<f32> {
        if x >= self.width || y >= self.height {
            return None;
        }
        self.depth
            .get(y as usize * self.width as usize + x as usize)
            .copied()
    }

    /// Pixels where geometry was drawn.
    pub fn covered_count(&self) -> usize {
        self.depth.iter().filter(|d| d.is_finite()).count()
    }
}

/// Bytes per row padded to `COPY_BYTES_PER_ROW_ALIGNMENT` (256).
pub fn padded_bytes_per_row(width: u32, bytes_per_texel: u32) -> u32 {
    let unpadded = width * bytes_per_texel;
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    unpadded.div_ceil(align) * align
}

/// The reference renderer: pipeline, globals and cached render targets.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipelines: GeometryPipelines,
    globals: wgpu::Buffer,
    globals_group: wgpu::BindGroup,
    max_dim: u32,
    targets: Mutex<Option<Targets>>,
    last_gpu: GpuTime,
}

impl Renderer {
    /// The cached render targets (tests read what a frame left in them).
    #[cfg(test)]
    pub(crate) fn targets(&self) -> &Mutex<Option<Targets>> {
        &self.targets
    }

    pub fn new(gpu: &Gpu) -> Result<Renderer, GpuError> {
        gpu.scoped("creating the reference render pipeline", || {
            let device = &gpu.device;
            let source = format!("{SHADING_WGSL}\n{RENDER_WGSL}");
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("lemi reference renderer"),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("lemi reference renderer"),
                bind_group_layouts: &[Some(gpu.globals_layout()), Some(gpu.material_layout())],
                immediate_size: 0,
            });
            let pipelines =
                GeometryPipelines::new(device, &layout, &module, "lemi reference renderer");
            let globals = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("lemi globals"),
                size: std::mem::size_of::<ShadingGlobals>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let globals_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("lemi globals"),
                layout: gpu.globals_layout(),
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: globals.as_entire_binding(),
                }],
            });
            Renderer {
                device: gpu.device.clone(),
                queue: gpu.queue.clone(),
                pipelines,
                globals,
                globals_group,
                max_dim: gpu.limits().max_texture_dimension_2d,
                targets: Mutex::new(None),
                last_gpu: GpuTime::default(),
            }
        })
    }

    /// Renders `scene` from `view` and reads the colour and depth images back.
    pub fn render(
        &self,
        scene: &GpuScene,
        view: &View,
        options: &RenderOptions,
    ) -> Result<Frame, GpuError> {
        self.render_frame(scene, view, options, true)
            .and_then(|f| f.ok_or_else(|| GpuError::Readback("no frame was read back".into())))
    }

    /// Renders `scene` like [`Renderer::render`] with the same pipeline and shading, drawing only
    /// the chunks, groups and clusters whose box may be in view (the `geometry-culled` baseline,
    /// see [`crate::culled`]); the image is the unculled one. Returns it with what was submitted.
    pub fn render_culled(
        &self,
        scene: &GpuCulledScene,
        view: &View,
        options: &RenderOptions,
    ) -> Result<(Frame, CullStats), GpuError> {
        let (frame, stats) = self.render_culled_frame(scene, view, options, true)?;
        let frame = frame.ok_or_else(|| GpuError::Readback("no frame was read back".into()))?;
        Ok((frame, stats))
    }

    /// [`Renderer::render_culled`] without the readback (see [`Renderer::render_no_readback`]).
    pub fn render_culled_no_readback(
        &self,
        scene: &GpuCulledScene,
        view: &View,
        options: &RenderOptions,
    ) -> Result<CullStats, GpuError> {
        Ok(self.render_culled_frame(scene, view, options, false)?.1)
    }

    /// Renders like [`Renderer::render`] and waits until the GPU has finished, without copying or
    /// reading the images back (for timing the rendering alone; [`Renderer::last_gpu_ms`] is
    /// updated too).
    pub fn render_no_readback(
        &self,
        scene: &GpuScene,
        view: &View,
        options: &RenderOptions,
    ) -> Result<(), GpuError> {
        self.render_frame(scene, view, options, false).map(|_| ())
    }

    /// [`Renderer::render_culled`], reading the frame back only with `readback` (see
    /// [`Renderer::render_frame`]).
    pub fn render_culled_frame(
        &self,
        scene: &GpuCulledScene,
        view: &View,
        options: &RenderOptions,
        readback: bool,
    ) -> Result<(Option<Frame>, CullStats), GpuError> {
        let list = scene.geometry.cull(&view.view_proj());
        let frame = self.draw_culled(scene, &list, view, options, readback)?;
        Ok((frame, CullStats::from(&list)))
    }

    /// GPU time of the last frame's render pass in milliseconds, from timestamp queries written at
    /// its beginning and end (resolved in the frame's own submission, read with its readback);
    /// `None` before the first frame or when the device has no
    /// [`wgpu::Features::TIMESTAMP_QUERY`]. On Mesa's software rasterizers this is the time the
    /// rasterizer took for the pass (see `examples/frame_timing.rs`).
    pub fn last_gpu_ms(&self) -> Option<f64> {
        self.last_gpu.get()
    }

    /// Renders `scene` from `view` and, with `readback`, reads the frame back ([`Renderer::render`]);
    /// without, waits until the GPU has finished and returns `None`
    /// ([`Renderer::render_no_readback`]): what a caller that times frames as a runtime presents
    /// them uses, reading back only the frames it keeps.
    pub fn render_frame(
        &self,
        scene: &GpuScene,
        view: &View,
        options: &RenderOptions,
        readback: bool,
    ) -> Result<Option<Frame>, GpuError> {
        for chunk in scene.geometry.chunks() {
            if scene.materials.bind_group(chunk.material).is_none() {
                return Err(GpuError::Invalid(format!(
                    "geometry uses material {} but only {} materials were uploaded",
                    chunk.material,
                    scene.materials.len()
                )));
            }
        }
        let draws: Vec<(&GpuChunk, Range<u32>)> = scene
            .geometry
            .chunks()
            .iter()
            .map(|c| (c, 0..c.index_count))
            .collect();
        self.draw_ranges(&scene.materials, &draws, view, options, readback)
    }

    fn draw_culled(
        &self,
        scene: &GpuCulledScene,
        list: &CullList,
        view: &View,
        options: &RenderOptions,
        readback: bool,
    ) -> Result<Option<Frame>, GpuError> {
        let chunks = scene.geometry.chunks();
        let draws = list
            .draws
            .iter()
            .map(|d| {
                chunks
                    .get(d.chunk)
                    .filter(|c| d.indices.start <= d.indices.end && d.indices.end <= c.index_count)
                    .map(|c| (c, d.indices.clone()))
                    .ok_or_else(|| {
                        GpuError::Invalid(format!(
                            "a culled draw names indices {:?} of chunk {} of {}",
                            d.indices,
                            d.chunk,
                            chunks.len()
                        ))
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        self.draw_ranges(&scene.materials, &draws, view, options, readback)
    }

    /// Draws index ranges of chunks in order, with one pass, pipeline and shading for every path.
    fn draw_ranges(
        &self,
        materials: &GpuMaterials,
        draws: &[(&GpuChunk, Range<u32>)],
        view: &View,
        options: &RenderOptions,
        readback: bool,
    ) -> Result<Option<Frame>, GpuError> {
        let (width, height) = (view.width, view.height);
        if width == 0 || height == 0 || width > self.max_dim || height > self.max_dim {
            return Err(GpuError::Limit(format!(
                "image size {width}x{height} is outside what this adapter renders (1..={} per side)",
                self.max_dim
            )));
        }
        let globals = ShadingGlobals::new(view, &options.lighting, options.alpha_cutoff)?;
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
                "creating render targets",
                || Targets::new(&self.device, width, height, "lemi"),
            )?);
        }
        let Some(targets) = guard.as_ref() else {
            return Err(GpuError::Readback("render targets missing".into()));
        };
        for (chunk, _) in draws {
            if materials.bind_group(chunk.material).is_none() {
                return Err(GpuError::Invalid(format!(
                    "geometry uses material {} but only {} materials were uploaded",
                    chunk.material,
                    materials.len()
                )));
            }
        }
        crate::device::scoped(&self.device, "rendering", || {
            self.queue
                .write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));
            let mut encoder = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("lemi render"),
                });
            {
                // the view depth only where the frame is read back
                let mut pass =
                    targets.begin_timed_pass(&mut encoder, "lemi reference pass", readback);
                pass.set_bind_group(0, &self.globals_group, &[]);
                let mut bound = BoundMaterial::default();
                let mut buffers: Option<&GpuChunk> = None;
                for (chunk, range) in draws {
                    self.pipelines.bind_material(
                        &mut pass,
                        materials,
                        chunk.material,
                        (options.alpha_cutoff, readback),
                        &mut bound,
                    );
                    if !buffers.is_some_and(|b| std::ptr::eq(b, *chunk)) {
                        pass.set_vertex_buffer(0, chunk.vertices.slice(..));
                        pass.set_index_buffer(chunk.indices.slice(..), wgpu::IndexFormat::Uint32);
                        buffers = Some(chunk);
                    }
                    pass.draw_indexed(range.clone(), 0, 0..1);
                }
            }
            targets.finish_encoding(&mut encoder, readback);
            self.queue.submit([encoder.finish()]);
        })?;
        // The depth target is cleared to 0; the colour alpha (255 where a fragment was written, 0
        // after the clear) tells geometry from background.
        targets.collect(
            &self.device,
            &self.queue,
            readback,
            options.clear,
            &self.last_gpu,
        )
    }
}

/// The colour targets of a frame: sRGB colour and, with `view_depth`, the view depth's bits (the
/// shaders write both; a pipeline without the second target drops that output).
pub(crate) fn frame_targets(view_depth: bool) -> [Option<wgpu::ColorTargetState>; 2] {
    let target = |format| wgpu::ColorTargetState {
        format,
        blend: None,
        write_mask: wgpu::ColorWrites::ALL,
    };
    [
        Some(target(COLOR_FORMAT)),
        view_depth.then(|| target(VIEW_DEPTH_FORMAT)),
    ]
}

/// The depth state of a frame: reverse-Z (`Greater`, cleared to 0), written.
pub(crate) fn frame_depth_stencil() -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::Greater),
        stencil: Default::default(),
        bias: Default::default(),
    }
}

/// Triangle lists, no culling (scenes are polygon soups without consistent winding).
pub(crate) fn frame_primitive() -> wgpu::PrimitiveState {
    wgpu::PrimitiveState {
        topology: wgpu::PrimitiveTopology::TriangleList,
        cull_mode: None,
        ..Default::default()
    }
}

/// The pipelines that draw geometry with the shared shading (`render.wgsl`), into the colour and
/// view-depth targets with the reverse-Z depth test, no culling (polygon soups): one with the
/// alpha test, and one without it for a cutoff of 0 (the default), which no albedo is below, so
/// both draw the same pixels; without the shader's `discard` the rasterizer may test depth
/// before shading (Mesa's does), as any renderer draws opaque geometry. Each for textured
/// materials and for untextured ones (the shader's `TEXTURED` constant: the white texel's sample,
/// exactly 1, taken as a constant, so no fetch), which draw the same pixels for an untextured
/// material.
pub(crate) struct GeometryPipelines {
    /// By material kind (untextured: 0, textured: 1), then view-depth target: without (0,
    /// frames not read back) and with (1).
    masked: [[wgpu::RenderPipeline; 2]; 2],
    opaque: [[wgpu::RenderPipeline; 2]; 2],
}

impl GeometryPipelines {
    /// The pipelines from `module` (the shading module with `render.wgsl`) with `layout`
    /// (globals and material bind groups).
    pub(crate) fn new(
        device: &wgpu::Device,
        layout: &wgpu::PipelineLayout,
        module: &wgpu::ShaderModule,
        label: &str,
    ) -> GeometryPipelines {
        let pipeline = |fragment: &str, textured: bool, view_depth: bool| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(layout),
                vertex: wgpu::VertexState {
                    module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(vertex_layout())],
                },
                primitive: frame_primitive(),
                depth_stencil: Some(frame_depth_stencil()),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module,
                    entry_point: Some(fragment),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: &crate::shading::material_constants(textured),
                        ..Default::default()
                    },
                    targets: &frame_targets(view_depth),
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let both = |fragment: &str| {
            [false, true].map(|textured| [false, true].map(|v| pipeline(fragment, textured, v)))
        };
        GeometryPipelines {
            masked: both("fs_main"),
            opaque: both("fs_main_opaque"),
        }
    }

    /// The pipeline for an alpha cutoff (the one without the test when nothing can be below it),
    /// for a pass with or without the view-depth target, for a material with or without a
    /// texture ([`crate::GpuMaterials::textured`]).
    pub(crate) fn for_material(
        &self,
        cutoff: f32,
        view_depth: bool,
        textured: bool,
    ) -> &wgpu::RenderPipeline {
        let (t, v) = (usize::from(textured), usize::from(view_depth));
        if cutoff > 0.0 {
            &self.masked[t][v]
        } else {
            &self.opaque[t][v]
        }
    }
}

/// What a pass has bound for geometry so far: the material (group 1) and the kind of pipeline.
#[derive(Default)]
pub(crate) struct BoundMaterial {
    material: Option<u32>,
    textured: Option<bool>,
}

impl GeometryPipelines {
    /// Binds `material`'s bind group and the pipeline of its kind (textured or not; `frame`: the
    /// alpha cutoff and whether the pass has the view-depth target), each only where it differs
    /// from what `bound` says the pass has.
    pub(crate) fn bind_material(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        materials: &GpuMaterials,
        material: u32,
        (cutoff, view_depth): (f32, bool),
        bound: &mut BoundMaterial,
    ) {
        if bound.material == Some(material) {
            return;
        }
        let textured = materials.textured(material);
        if bound.textured != Some(textured) {
            pass.set_pipeline(self.for_material(cutoff, view_depth, textured));
            bound.textured = Some(textured);
        }
        if let Some(g) = materials.bind_group(material) {
            pass.set_bind_group(1, g, &[]);
        }
        bound.material = Some(material);
    }
}

/// The last frame's GPU time in milliseconds (f64 bits; `u64::MAX` for none), shared by reference.
#[derive(Debug)]
pub(crate) struct GpuTime(AtomicU64);

impl Default for GpuTime {
    fn default() -> Self {
        GpuTime(AtomicU64::new(u64::MAX))
    }
}

impl GpuTime {
    pub(crate) fn get(&self) -> Option<f64> {
        match self.0.load(Ordering::Relaxed) {
            u64::MAX => None,
            bits => Some(f64::from_bits(bits)),
        }
    }

    pub(crate) fn set(&self, ms: Option<f64>) {
        self.0
            .store(ms.map_or(u64::MAX, f64::to_bits), Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_pad_to_256_bytes() {
        assert_eq!(padded_bytes_per_row(1, 4), 256);
        assert_eq!(padded_bytes_per_row(64, 4), 256);
        assert_eq!(padded_bytes_per_row(65, 4), 512);
        assert_eq!(padded_bytes_per_row(1280, 4), 5120);
    }
}
