//! Drawing cells: [`ImpostorRenderer`] holds the reference pipeline for the near geometry, the
//! two quad pipelines (opaque and alpha-tested), the globals and cached render targets, and
//! renders a cell with or without readback, timing each frame with timestamp queries.

use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use lemi_core::camera::View;
use lemi_core::enclosure::Window;

use super::layout::{quad_vertex_layout, QUAD_ALPHA_CUTOFF, QUAD_FULL_ALPHA};
use super::upload::{macro_format, macro_layout};
use super::ImpostorCell;
#[cfg(doc)]
use super::ImpostorCellData;
use crate::renderer::{Frame, GpuTime, RenderOptions};
use crate::scene::{GpuChunk, GpuMaterials};
use crate::shading::{ShadingGlobals, SHADING_WGSL};
use crate::targets::{PassPart, Targets, LINEAR_COLOR_FORMAT};
use crate::{Gpu, GpuError};

/// The reference renderer's entry points: the near geometry is drawn with exactly this source.
const RENDER_WGSL: &str = include_str!("../render.wgsl");
/// The quad entry points, appended to the shading module.
const IMPOSTOR_WGSL: &str = include_str!("impostor.wgsl");

/// Index ranges of uploaded chunks, drawn in this order.
pub type Ranges<'a> = Vec<(&'a GpuChunk, Range<u32>)>;

/// What one frame of [`ImpostorRenderer::render_composite`] draws.
#[derive(Default)]
pub struct Composite<'a> {
    /// Index ranges of uploaded chunks (e.g. the kept ranges of [`crate::CulledGeometry`] culls)
    /// drawn over the whole view.
    pub geometry: Ranges<'a>,
    /// Index ranges drawn only inside their own window (a scissor rectangle), after `geometry`:
    /// e.g. the rooms of an [`lemi_core::enclosure::Enclosure`] seen through doorways
    /// ([`lemi_core::enclosure::Sight::window`]).
    pub scissored: Vec<(Window, Ranges<'a>)>,
    /// Index ranges drawn only inside `window` (all of the view without one).
    pub windowed: Ranges<'a>,
    /// Cells whose quads are drawn, inside `window` (their own near geometry is not drawn:
    /// upload them with an empty near list).
    pub cells: Vec<&'a ImpostorCell>,
    /// The part of the view `windowed` and the quads are restricted to (a scissor rectangle; its
    /// frustum culls the quads' draws), e.g. the openings of an
    /// [`lemi_core::enclosure::Enclosure`]. `None`: the whole view.
    pub window: Option<Window>,
}

/// How an impostor quad's pixels take their colour from its macro-texels. Coverage (the alpha test)
/// is the same in both: the texel under the pixel's centre decides it, so filtering never opens a
/// crack or grows a silhouette.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TexelFilter {
    /// The texel under the pixel's centre, as the bake stored it. Where a quad is minified (more
    /// than one texel per pixel: towards a cube face's edges, where a texel subtends down to a
    /// third of its angle at the face's centre, or in a smaller view than the bake was made for)
    /// nearest sampling skips texels, and the far field shimmers as the viewer moves.
    Nearest,
    /// The texel under the centre where a texel spans at least two pixels (magnified quads: bit
    /// for bit [`TexelFilter::Nearest`]); elsewhere the mean, in linear light, of the opaque
    /// texels under the pixel's footprint, from bilinear fetches that stay half a texel inside
    /// the quad's rectangle (no texel of another micro-texture or of the transparent gap is ever
    /// mixed in): one fetch where a texel spans one to two pixels (the hardware's tent filter),
    /// one fetch at the nearest texel corner where it spans half a pixel to one (the mean of
    /// those 2×2 texels), four such fetches at the centres of the footprint's quarters where
    /// texels are smaller still (up to 4×4 texels: exact up to four texels a pixel, sampled
    /// beyond). A box filter of the footprint, what a mip level would give, without storing one.
    #[default]
    Footprint,
}

/// Draws [`ImpostorCell`]s: the reference pipeline for near geometry, the quad pipelines (opaque
/// and alpha-tested), globals and cached render targets.
pub struct ImpostorRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    near_pipelines: crate::renderer::GeometryPipelines,
    /// Quad pipelines by view-depth target (without: frames not read back; with) and filter
    /// ([`TexelFilter::Nearest`], [`TexelFilter::Footprint`]: the
    /// shader's `FOOTPRINT` constant, so the texel filter costs nothing where it is off, not even
    /// on a software rasterizer, which runs both sides of a branch) and kind: quads some of whose
    /// texels fail the alpha test (`fs_quad`, with `discard`) and quads all of whose texels pass
    /// it (`fs_quad_opaque`, no `discard`).
    quad_pipelines: [[QuadPipelines; 2]; 2],
    /// The macro-texture format this renderer's quad pipelines expect ([`macro_format`]);
    /// `Rgba8Unorm` means the quads are drawn through the colour target's linear view.
    macro_format: wgpu::TextureFormat,
    globals: wgpu::Buffer,
    globals_group: wgpu::BindGroup,
    max_dim: u32,
    targets: Mutex<Option<Targets>>,
    last_gpu: GpuTime,
    /// The last frame's quad draw calls (high 32 bits) and how many of them took nearest texels
    /// although the filter is [`TexelFilter::Footprint`] (low 32 bits).
    last_draws: AtomicU64,
    texel_filter: TexelFilter,
    /// Group 2 of the fringe pipelines: the depth buffer as the earlier passes left it.
    drawn_depth_layout: wgpu::BindGroupLayout,
}

/// The quad pipelines of one texel filter.
struct QuadPipelines {
    alpha_tested: wgpu::RenderPipeline,
    opaque: wgpu::RenderPipeline,
    /// The outline fringe texels of quads that have them (`fs_quad_fringe`), in a pass after all
    /// others that samples the depth buffer those left.
    fringe: wgpu::RenderPipeline,
    /// Fringe quads (`fs_quad_fringe_quads`) in the same pass.
    fringe_quads: wgpu::RenderPipeline,
}

impl ImpostorRenderer {
    pub fn new(gpu: &Gpu) -> Result<ImpostorRenderer, GpuError> {
        gpu.scoped("creating the impostor render pipelines", || {
            let device = &gpu.device;
            let depth_stencil = Some(crate::renderer::frame_depth_stencil());
            let primitive = crate::renderer::frame_primitive();
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
            let near_pipelines = crate::renderer::GeometryPipelines::new(
                device,
                &near_layout,
                &near_module,
                "lemi impostor renderer: near geometry",
            );
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
            let drawn_depth_layout =
                device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("lemi impostor renderer: drawn depth"),
                    entries: &[wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: wgpu::ShaderStages::FRAGMENT,
                        ty: wgpu::BindingType::Texture {
                            sample_type: wgpu::TextureSampleType::Depth,
                            view_dimension: wgpu::TextureViewDimension::D2,
                            multisampled: false,
                        },
                        count: None,
                    }],
                });
            let fringe_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("lemi impostor renderer: outline fringe"),
                bind_group_layouts: &[
                    Some(gpu.globals_layout()),
                    Some(&macro_layout),
                    Some(&drawn_depth_layout),
                ],
                immediate_size: 0,
            });
            // The quads' colour target: the linear view where macro-textures are linear.
            let macro_format = macro_format(device);
            let quad_targets = |view_depth: bool| {
                let mut targets = crate::renderer::frame_targets(view_depth);
                if macro_format == wgpu::TextureFormat::Rgba8Unorm {
                    targets[0] = Some(wgpu::ColorTargetState {
                        format: LINEAR_COLOR_FORMAT,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    });
                }
                targets
            };
            let quad_pipeline_for =
                |label: &str, entry_point: &str, footprint: bool, view_depth| {
                    let fringe = entry_point.starts_with("fs_quad_fringe");
                    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                        label: Some(label),
                        layout: Some(if fringe { &fringe_layout } else { &quad_layout }),
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
                            compilation_options: wgpu::PipelineCompilationOptions {
                                constants: &[("FOOTPRINT", f64::from(u8::from(footprint)))],
                                ..Default::default()
                            },
                            targets: &quad_targets(view_depth),
                        }),
                        multiview_mask: None,
                        cache: None,
                    })
                };
            let quad_pipelines = [false, true].map(|view_depth| {
                [false, true].map(|footprint| QuadPipelines {
                    alpha_tested: quad_pipeline_for(
                        "lemi impostor renderer: quads",
                        "fs_quad",
                        footprint,
                        view_depth,
                    ),
                    opaque: quad_pipeline_for(
                        "lemi impostor renderer: opaque quads",
                        "fs_quad_opaque",
                        footprint,
                        view_depth,
                    ),
                    fringe: quad_pipeline_for(
                        "lemi impostor renderer: outline fringe",
                        "fs_quad_fringe",
                        footprint,
                        view_depth,
                    ),
                    fringe_quads: quad_pipeline_for(
                        "lemi impostor renderer: fringe quads",
                        "fs_quad_fringe_quads",
                        footprint,
                        view_depth,
                    ),
                })
            });
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
                near_pipelines,
                quad_pipelines,
                macro_format,
                globals,
                globals_group,
                max_dim: gpu.limits().max_texture_dimension_2d,
                targets: Mutex::new(None),
                last_gpu: GpuTime::default(),
                last_draws: AtomicU64::new(0),
                texel_filter: TexelFilter::default(),
                drawn_depth_layout,
            }
        })
    }

    /// How quads take their colour from their texels from now on ([`TexelFilter::Footprint`] by
    /// default).
    pub fn set_texel_filter(&mut self, filter: TexelFilter) {
        self.texel_filter = filter;
    }

    pub fn texel_filter(&self) -> TexelFilter {
        self.texel_filter
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

    /// Renders the cell like [`ImpostorRenderer::render`], reading the frame back only with
    /// `readback` (else `None` once the GPU has finished, as
    /// [`ImpostorRenderer::render_no_readback`]).
    pub fn render_frame(
        &self,
        cell: &ImpostorCell,
        view: &View,
        options: &RenderOptions,
        readback: bool,
    ) -> Result<Option<Frame>, GpuError> {
        self.render_parts(cell, view, options, true, readback)
    }

    /// GPU time of the last frame's render pass (near geometry and quads) in milliseconds, from
    /// timestamp queries at its beginning and end, resolved in the frame's own submission; `None`
    /// before the first frame or without [`wgpu::Features::TIMESTAMP_QUERY`]. See
    /// [`crate::Renderer::last_gpu_ms`].
    pub fn last_gpu_ms(&self) -> Option<f64> {
        self.last_gpu.get()
    }

    /// The last frame's quad draw calls, and how many of them were drawn with nearest texels
    /// because every texel of theirs spans two pixels or more in that view (the footprint filter
    /// would have taken the texel under each pixel's centre: the same pixels; see
    /// [`ImpostorCellData::prepare_for`]).
    pub fn last_quad_draws(&self) -> (u32, u32) {
        let v = self.last_draws.load(Ordering::Relaxed);
        ((v >> 32) as u32, v as u32)
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
        let near = &cell.near;
        let geometry: Vec<(&GpuChunk, Range<u32>)> = if with_near {
            near.geometry
                .chunks()
                .iter()
                .map(|c| (c, 0..c.index_count))
                .collect()
        } else {
            Vec::new()
        };
        let parts = Composite {
            geometry,
            cells: vec![cell],
            ..Composite::default()
        };
        self.render_composite(&parts, &near.materials, view, options, readback)
    }

    /// Renders a frame of several parts (portal impostors, TR sec. 3, see [`Composite`]): its
    /// geometry, shaded exactly like [`crate::Renderer`] with `materials`, then the quads of its
    /// cells, all depth-tested against each other in one frame. Reads the images back with
    /// `readback` (otherwise waits for the GPU and returns `None`;
    /// [`ImpostorRenderer::last_gpu_ms`] times the frame either way).
    pub fn render_composite(
        &self,
        parts: &Composite<'_>,
        materials: &GpuMaterials,
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
        let mut globals = ShadingGlobals::new(view, &options.lighting, options.alpha_cutoff)?;
        // the first alpha test keeps the fully opaque texels; the fringe pass those between
        globals.params[1] = QUAD_FULL_ALPHA;
        globals.params[2] = QUAD_ALPHA_CUTOFF;
        // impostor.wgsl: w says the quads draw into the linear view of the colour target (their
        // texels pass through as sRGB-encoded bytes), so a filtered colour, taken in linear light,
        // is encoded by the shader
        globals.params[3] = f32::from(u8::from(!self.macro_format.is_srgb()));
        let cells = &parts.cells;
        for w in parts
            .window
            .iter()
            .chain(parts.scissored.iter().map(|(w, _)| w))
        {
            let [x0, y0, x1, y1] = w.rect;
            if x0 >= x1 || y0 >= y1 || x1 > width || y1 > height {
                return Err(GpuError::Invalid(format!(
                    "window {:?} is empty or outside the {width}x{height} view",
                    w.rect
                )));
            }
        }
        let window = parts.window;
        let scissored = parts.scissored.iter().flat_map(|(_, r)| r);
        for (chunk, range) in parts
            .geometry
            .iter()
            .chain(scissored)
            .chain(&parts.windowed)
        {
            if materials.bind_group(chunk.material).is_none() {
                return Err(GpuError::Invalid(format!(
                    "near geometry uses material {} but only {} materials were uploaded",
                    chunk.material,
                    materials.len()
                )));
            }
            if range.start > range.end || range.end > chunk.index_count {
                return Err(GpuError::Invalid(format!(
                    "index range {range:?} outside a chunk of {} indices",
                    chunk.index_count
                )));
            }
        }
        for cell in cells {
            for d in &cell.draws {
                if cell.page_groups.get(d.page as usize).is_none() {
                    return Err(GpuError::Invalid(format!(
                        "quads use atlas page {} but only {} were uploaded",
                        d.page,
                        cell.page_groups.len()
                    )));
                }
            }
            // RGBA8 or block-compressed pages alike, as long as both decode sRGB or neither does
            if cell.macro_format.is_srgb() != self.macro_format.is_srgb() && !cell.draws.is_empty()
            {
                return Err(GpuError::Invalid(format!(
                    "the cell's macro-textures are {:?} but this renderer draws {:?} ones: the cell was \
                     uploaded on another device",
                    cell.macro_format, self.macro_format
                )));
            }
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
        let draw_near = !parts.geometry.is_empty()
            || !parts.windowed.is_empty()
            || parts.scissored.iter().any(|(_, r)| !r.is_empty());
        let view_proj = window.map_or_else(|| view.view_proj(), |w| w.view_proj);
        // the scissor of `w`, the whole view for `None`
        let scissor = |pass: &mut wgpu::RenderPass<'_>, w: Option<&Window>| {
            let [x0, y0, x1, y1] = w.map_or([0, 0, width, height], |w| w.rect);
            pass.set_scissor_rect(x0, y0, x1 - x0, y1 - y0);
        };
        let quads: Vec<(&ImpostorCell, &(wgpu::Buffer, wgpu::Buffer))> = cells
            .iter()
            .filter(|c| !c.draws.is_empty())
            .filter_map(|c| c.quad_buffers.as_ref().map(|b| (*c, b)))
            .collect();
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
            let two_passes = linear && draw_near && !quads.is_empty();
            // outline fringe texels: one more pass, after the depth buffer is copied
            let fringe_pass = quads.iter().any(|(c, _)| c.draws.iter().any(|d| d.fringe));
            let mut pass = targets.begin_pass_part(
                &mut encoder,
                "lemi impostor pass",
                if two_passes || fringe_pass {
                    PassPart::First
                } else {
                    PassPart::Whole
                },
                linear && !draw_near,
                true,
                readback,
            );
            if draw_near {
                pass.set_bind_group(0, &self.globals_group, &[]);
                let mut bound = crate::renderer::BoundMaterial::default();
                let groups = std::iter::once((None, &parts.geometry))
                    .chain(parts.scissored.iter().map(|(w, r)| (Some(w), r)))
                    .chain(std::iter::once((window.as_ref(), &parts.windowed)));
                let draws = groups.flat_map(|(w, ranges)| {
                    ranges
                        .iter()
                        .enumerate()
                        .map(move |(i, r)| ((i == 0).then_some(w), r))
                });
                for (first_of, (chunk, range)) in draws {
                    if let Some(w) = first_of {
                        scissor(&mut pass, w);
                    }
                    if range.is_empty() {
                        continue;
                    }
                    self.near_pipelines.bind_material(
                        &mut pass,
                        materials,
                        chunk.material,
                        (options.alpha_cutoff, readback),
                        &mut bound,
                    );
                    pass.set_vertex_buffer(0, chunk.vertices.slice(..));
                    pass.set_index_buffer(chunk.indices.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(range.clone(), 0, 0..1);
                }
            }
            if two_passes {
                drop(pass);
                pass = targets.begin_pass_part(
                    &mut encoder,
                    "lemi impostor quad pass",
                    if fringe_pass {
                        PassPart::Middle
                    } else {
                        PassPart::Last
                    },
                    true,
                    true,
                    readback,
                );
            }
            let (mut quad_draws, mut nearest_draws) = (0u32, 0u32);
            // the frame's side of the texel scale bound, once for all draw calls
            let footprint = self.texel_filter == TexelFilter::Footprint;
            let seen = lemi_core::texel_scale::pixel_angle(view).map(|a| (view.eye(), a));
            // the quads' draw calls (`fringe`: the pieces of quads around their outline fringe
            // texels instead, with the fringe pipeline), each culled by its box
            let mut draw_quads = |pass: &mut wgpu::RenderPass<'_>, fringe: bool| {
                scissor(pass, window.as_ref());
                let mut pipeline = None;
                for (cell, (vertices, indices)) in &quads {
                    pass.set_bind_group(0, &self.globals_group, &[]);
                    pass.set_vertex_buffer(0, vertices.slice(..));
                    pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
                    let mut bound = None;
                    for (d, b) in cell.draws.iter().zip(&cell.bounds) {
                        let Some(g) = cell.page_groups.get(d.page as usize) else {
                            continue;
                        };
                        if d.fringe != fringe || b.outside(&view_proj) {
                            continue;
                        }
                        // the footprint filter only where some texel may span less than two
                        // pixels: elsewhere it takes the centre texel, as the nearest pipeline
                        // does
                        let filter =
                            footprint && !seen.is_some_and(|(e, a)| b.texels_magnified(e, a));
                        nearest_draws += u32::from(footprint && !filter);
                        let kind = (filter, d.opaque, d.fringe_quads);
                        if pipeline != Some(kind) {
                            let pipelines =
                                &self.quad_pipelines[usize::from(readback)][usize::from(filter)];
                            pass.set_pipeline(if d.fringe_quads {
                                &pipelines.fringe_quads
                            } else if fringe {
                                &pipelines.fringe
                            } else if d.opaque {
                                &pipelines.opaque
                            } else {
                                &pipelines.alpha_tested
                            });
                            pipeline = Some(kind);
                        }
                        quad_draws += 1;
                        if bound != Some(d.page) {
                            pass.set_bind_group(1, g, &[]);
                            bound = Some(d.page);
                        }
                        pass.draw_indexed(d.first_index..d.first_index + d.index_count, 0, 0..1);
                    }
                }
            };
            draw_quads(&mut pass, false);
            if fringe_pass {
                drop(pass);
                targets.copy_depth(&mut encoder);
                let drawn = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("lemi impostor drawn depth"),
                    layout: &self.drawn_depth_layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(targets.depth_copy()),
                    }],
                });
                pass = targets.begin_pass_part(
                    &mut encoder,
                    "lemi impostor outline fringe pass",
                    PassPart::Last,
                    linear,
                    true,
                    readback,
                );
                pass.set_bind_group(2, &drawn, &[]);
                draw_quads(&mut pass, true);
            }
            drop(pass);
            self.last_draws.store(
                (u64::from(quad_draws) << 32) | u64::from(nearest_draws),
                Ordering::Relaxed,
            );
            targets.finish_encoding(&mut encoder, readback);
            self.queue.submit([encoder.finish()]);
        })?;
        // Every drawn fragment writes alpha 1; alpha 0 is the clear.
        targets.collect(
            &self.device,
            &self.queue,
            readback,
            options.clear,
            &self.last_gpu,
        )
    }
}

#[cfg(test)]
mod tests {
    //! Timestamps and frames without readback, of [`ImpostorRenderer`] and of the reference
    //! [`crate::Renderer`].
    use std::sync::Arc;

    use super::*;
    use crate::impostor::test_support::{gpu, pattern, quad, scene, view};
    use crate::{GpuMaterials, GpuScene, UploadOptions};

    /// The test scene, and a cell of it: its first triangle as near geometry, two quads.
    fn scene_and_cell(gpu: &crate::Gpu) -> (lemi_core::Scene, ImpostorCell) {
        let scene = scene();
        let materials =
            Arc::new(GpuMaterials::upload(gpu, &scene.materials, &scene.textures).expect("mats"));
        let macros = vec![pattern(13, 9, 0), pattern(32, 16, 1)];
        let quads = [
            quad(0, [0, 0, 13, 9], [-4.0, -0.5, 0.5, 3.5, -5.0]),
            quad(1, [0, 0, 32, 16], [-3.0, 3.0, -3.5, 0.0, -6.0]),
        ];
        let cell = ImpostorCell::upload(gpu, materials, &scene, &[[0, 0]], &quads, &macros)
            .expect("upload");
        (scene, cell)
    }

    #[test]
    fn gpu_times_and_frames_without_readback() {
        let Some(gpu) = gpu() else { return };
        let (scene, cell) = scene_and_cell(&gpu);
        let view = view();
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

    /// The colour a frame left in `targets`, read back after the fact (background alpha 0).
    fn colour_left_in(gpu: &crate::Gpu, targets: &Mutex<Option<Targets>>) -> Vec<u8> {
        let guard = targets.lock().expect("targets");
        let t = guard.as_ref().expect("a frame was drawn");
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        t.copy_rects_to_readback(&mut encoder, &[t.whole()], false);
        gpu.queue.submit([encoder.finish()]);
        t.read_rects(&gpu.device, &[t.whole()], false)
            .expect("colour")
            .rgba
    }

    /// The read-back frame's colour with the background at alpha 0, as the target holds it.
    fn as_stored(frame: &Frame) -> Vec<u8> {
        let mut rgba = frame.rgba.clone();
        for (px, d) in rgba.chunks_exact_mut(4).zip(&frame.depth) {
            if *d == f32::INFINITY {
                px.copy_from_slice(&[0; 4]);
            }
        }
        rgba
    }

    #[test]
    fn frames_without_readback_draw_the_same_colour_without_the_view_depth_target() {
        let Some(gpu) = gpu() else { return };
        let (scene, cell) = scene_and_cell(&gpu);
        let view = view();
        let opts = RenderOptions {
            clear: [0; 4],
            ..RenderOptions::default()
        };
        let r = ImpostorRenderer::new(&gpu).expect("renderer");
        let frame = r.render(&cell, &view, &opts).expect("render");
        let want = as_stored(&frame);
        // the near geometry and both kinds of quads are in the picture
        let drawn = want.chunks_exact(4).filter(|p| p[3] == 255).count();
        assert!(drawn > 500, "{drawn} pixels drawn");
        r.render_no_readback(&cell, &view, &opts)
            .expect("no readback");
        assert!(colour_left_in(&gpu, &r.targets) == want, "impostor frame");
        let reference = crate::Renderer::new(&gpu).expect("reference renderer");
        let all = GpuScene::upload(&gpu, &scene, &UploadOptions::default()).expect("scene");
        let want = as_stored(&reference.render(&all, &view, &opts).expect("reference"));
        reference
            .render_no_readback(&all, &view, &opts)
            .expect("reference without readback");
        assert!(
            colour_left_in(&gpu, reference.targets()) == want,
            "reference frame"
        );
    }
}
