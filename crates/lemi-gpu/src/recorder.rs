//! The crack-free layer recorder: draws the triangles of one slab (already clipped to the slab with
//! [`lemi_core::clip::clip_to_slab`], positions relative to the cell centre) into one `Res × Res`
//! cube-face layer: sRGB RGBA with binary alpha and the linear depth along the face axis per texel.
//!
//! Based on the TR on the error metric (Jeschke, Wimmer, TR-186-2-02-04, sec. 2.2): a polygon
//! crossing a slab border is cut there and both layers record their part; a texel only partly
//! covered by each part would be lost in both, so coverage is **conservative**: every texel whose
//! square the projected triangle touches at all is covered. This uses overestimated conservative
//! rasterization by triangle dilation in the vertex shader (Hasselgren, Akenine-Möller, Ohlsson,
//! "Conservative Rasterization", GPU Gems 2, ch. 42): each vertex carries its whole triangle
//! (non-indexed draw; no geometry shader or storage buffer, so it runs on GL/llvmpipe and
//! Vulkan/lavapipe), the vertex shader moves every edge outward by half a texel diagonal and
//! intersects adjacent moved edges; the fragment shader keeps exactly the texels whose
//! square overlaps the projected triangle (separating axes: the box axes and the edge normals).
//! Triangles degenerate in projection (edge-on) are drawn as a triangle around their grown bounding
//! box, and the same fragment test keeps the texels their segment touches.
//!
//! Shading is the shared module ([`crate::shading`]). Moved corners carry their barycentric
//! coordinates with respect to the original triangle; the fragment shader clamps them to the
//! triangle, so texels inside get the original interpolation and the overshoot the nearest values
//! on the triangle (colours, normals and UVs are never extrapolated).
//!
//! [`Coverage::CentreSampled`] records with ordinary rasterization instead (a texel is covered when
//! its centre lies inside the projected triangle, as in the reference renderer): the baseline of
//! Schaufler's layered impostors, which have no conservative coverage. It is a uniform of the same
//! pipeline; the conservative path is unchanged by it.
//!
//! Depth test: nearest wins (reverse-Z, `Greater`); an overshoot fragment (texel centre outside its
//! triangle) is pushed back by a relative 2⁻¹⁶ in the depth buffer, so along a shared edge the
//! triangle containing the texel centre wins, as in the reference renderer.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use bytemuck::{Pod, Zeroable};
use glam::DVec3;
use lemi_core::camera::View;
use lemi_core::clip::ClipVertex;
use lemi_core::clip_border::is_clip_edge;
use lemi_core::Face;
use wgpu::util::DeviceExt;

use crate::renderer::DEPTH_FORMAT;
use crate::shading::{Lighting, ShadingGlobals, SHADING_WGSL};
use crate::targets::Targets;
use crate::{Gpu, GpuError, GpuMaterials};
use lemi_core::compress::TexelRect;

const RECORDER_WGSL: &str = include_str!("recorder.wgsl");

/// Triangles `first .. first + count` (triangle indices, not vertex indices) use `material`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaterialRun {
    pub material: u32,
    pub first: u32,
    pub count: u32,
}

/// Which texels a triangle covers when recorded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Coverage {
    /// Every texel whose square the projected triangle touches (crack-free recording, TR sec. 2.2).
    #[default]
    Conservative,
    /// Ordinary rasterization: the texels whose centre the projected triangle covers.
    CentreSampled,
    /// Conservative only across clipping edges (edges on one of the slab's border planes, given to
    /// [`LayerRecorder::record_with`]), centre-sampled across every other edge: a surface cut at a
    /// border still covers every texel its cut touches in both layers (TR sec. 2.2, no cracks),
    /// while silhouettes and outlines land where the reference renderer puts them instead of
    /// growing by up to a texel. Edges shared by two triangles of a slab stay watertight: a texel
    /// centre on the shared edge counts as inside both. Not yet what the bake records with: on the
    /// crack test's terrain it leaves a few background pixels where a far surface crosses the
    /// seam of two faces, and on a `builtin:city:1M` cell the certificate counts one-pixel strips
    /// along building edges in every view (39,333 crack pixels in 104 views): a silhouette that
    /// is no longer grown is uncovered by the parallax the placement allows.
    ClipEdges,
}

/// How [`LayerRecorder::record_with`] records and what it reads back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordOptions<'a> {
    pub coverage: Coverage,
    /// The depths along the face axis (relative to the centre) of the slab's borders, whose
    /// clipping edges [`Coverage::ClipEdges`] covers conservatively (ignored by the other modes).
    pub clip_planes: &'a [f64],
    /// Read back the per-texel depth too ([`LayerFrame::depth`]); the bake needs only colour.
    pub depth: bool,
    /// Read back only the tiles of [`READBACK_TILE`]² texels that the triangles' grown bounding
    /// boxes touch (every other texel is known to be empty), and neither draw nor read back
    /// anything for a slab without triangles. `false` reads back the whole layer.
    pub sparse: bool,
    /// The depth along the face axis of the layer's plane: each covered texel is told whether
    /// its recorded point lies behind it ([`LayerFrame::behind_plane`]), for the outline copies
    /// of `lemi_core::compress::copy_outlines`. The shader writes the side into the colour
    /// target's alpha (1 in front of or on the plane, ½ behind it; the readback makes alpha
    /// binary again), so it costs no depth readback. `None`: not asked.
    pub side_plane: Option<f64>,
    /// Tell each covered texel whether its centre lies outside every triangle of the slab that
    /// covers it (a conservative overshoot, [`LayerFrame::overshoot`]), for the bake's outline
    /// fringe (`lemi_core::compress::mark_outline_fringe`). The shader lowers the alpha of
    /// such a texel by a further ¼ and pushes its depth back so far that a triangle containing the
    /// centre wins the texel at any depth of the slab, so the winning colour and depth change
    /// where an overshoot lay in front of a farther triangle: a recording that marks a fringe and
    /// the depth recording of its certificate both mark. `false`: not asked.
    pub mark_overshoot: bool,
}

impl Default for RecordOptions<'_> {
    fn default() -> Self {
        RecordOptions {
            coverage: Coverage::Conservative,
            clip_planes: &[],
            depth: true,
            sparse: true,
            side_plane: None,
            mark_overshoot: false,
        }
    }
}

/// Side in texels of the tiles that sparse recording reads back ([`RecordOptions::sparse`]).
pub const READBACK_TILE: u32 = 64;

/// One recorded layer, rows top to bottom in the texel convention of [`lemi_core::face`].
#[derive(Clone, Debug, PartialEq)]
pub struct LayerFrame {
    pub res: u32,
    /// sRGB-encoded RGBA8; alpha 255 where covered, `[0, 0, 0, 0]` elsewhere.
    pub rgba: Vec<u8>,
    /// Linear depth along the face axis; `f32::INFINITY` where not covered. Empty when the
    /// recording did not ask for depth ([`RecordOptions::depth`]).
    pub depth: Vec<f32>,
    /// Every texel outside this rectangle is uncovered: the bounding box of the tiles read back
    /// ([`RecordOptions::sparse`]), the whole layer otherwise.
    pub content: TexelRect,
    /// Per texel, whether it is covered by a point behind [`RecordOptions::side_plane`]
    /// (farther from the centre). Empty when the recording did not ask.
    pub behind_plane: Vec<bool>,
    /// Per texel, whether it is a conservative overshoot: covered, but its centre inside no
    /// triangle of the slab ([`RecordOptions::mark_overshoot`]). Empty when not asked.
    pub overshoot: Vec<bool>,
}

impl LayerFrame {
    /// Whether texel `(i, j)` is covered (`false` outside the image).
    pub fn covered(&self, i: u32, j: u32) -> bool {
        i < self.res
            && j < self.res
            && self
                .rgba
                .get(4 * (j as usize * self.res as usize + i as usize) + 3)
                .is_some_and(|&a| a == 255)
    }

    /// RGBA of texel `(i, j)`; `None` outside the image.
    pub fn texel(&self, i: u32, j: u32) -> Option<[u8; 4]> {
        if i >= self.res || j >= self.res {
            return None;
        }
        let k = 4 * (j as usize * self.res as usize + i as usize);
        self.rgba.get(k..k + 4).and_then(|s| s.try_into().ok())
    }

    /// Number of covered texels.
    pub fn covered_count(&self) -> usize {
        self.rgba.chunks_exact(4).filter(|p| p[3] == 255).count()
    }
}

/// The recorder's vertex: the whole triangle (the three corners' positions and shading attributes,
/// in triangle order) and which corner this vertex is. 148 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
struct RecVertex {
    positions: [[f32; 3]; 3],
    corner: u32,
    normals: [[f32; 3]; 3],
    uv01: [f32; 4],
    uv2: [f32; 2],
    colors: [[f32; 4]; 3],
}

const REC_ATTRIBUTES: [wgpu::VertexAttribute; 12] = wgpu::vertex_attr_array![
    0 => Float32x3,
    1 => Float32x3,
    2 => Float32x3,
    3 => Uint32,
    4 => Float32x3,
    5 => Float32x3,
    6 => Float32x3,
    7 => Float32x4,
    8 => Float32x2,
    9 => Float32x4,
    10 => Float32x4,
    11 => Float32x4,
];

/// Records layers of one resolution; pipeline and render targets are made once.
pub struct LayerRecorder {
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// By whether the view depth is written (0: a recording that reads back colour only, which
    /// then neither clears nor stores the view-depth target) and by material kind: untextured
    /// (0, the shader's `TEXTURED` constant off: the white texel's sample taken as the constant
    /// 1, no fetch) and textured (1); the same texels for an untextured material
    /// ([`crate::GpuMaterials::textured`]).
    pipelines: [[wgpu::RenderPipeline; 2]; 2],
    globals: wgpu::Buffer,
    globals_group: wgpu::BindGroup,
    res: u32,
    targets: Mutex<Targets>,
    /// Texels read back from the GPU so far (colour; depth reads the same texels again).
    texels_read: AtomicU64,
}

impl LayerRecorder {
    /// A recorder of `res × res` layers.
    pub fn new(gpu: &Gpu, res: u32) -> Result<LayerRecorder, GpuError> {
        let max_dim = gpu.limits().max_texture_dimension_2d;
        if res == 0 || res > max_dim {
            return Err(GpuError::Limit(format!(
                "layer resolution {res} is outside what this adapter renders (1..={max_dim})"
            )));
        }
        gpu.scoped("creating the layer recorder", || {
            let device = &gpu.device;
            let source = format!("{SHADING_WGSL}\n{RECORDER_WGSL}");
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("lemi layer recorder"),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("lemi layer recorder"),
                bind_group_layouts: &[Some(gpu.globals_layout()), Some(gpu.material_layout())],
                immediate_size: 0,
            });
            let pipeline = |textured: bool, view_depth: bool| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("lemi layer recorder"),
                    layout: Some(&layout),
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some("vs_main"),
                        compilation_options: Default::default(),
                        buffers: &[Some(wgpu::VertexBufferLayout {
                            array_stride: std::mem::size_of::<RecVertex>() as wgpu::BufferAddress,
                            step_mode: wgpu::VertexStepMode::Vertex,
                            attributes: &REC_ATTRIBUTES,
                        })],
                    },
                    primitive: wgpu::PrimitiveState {
                        topology: wgpu::PrimitiveTopology::TriangleList,
                        cull_mode: None,
                        ..Default::default()
                    },
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: DEPTH_FORMAT,
                        depth_write_enabled: Some(true),
                        depth_compare: Some(wgpu::CompareFunction::Greater),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                    multisample: wgpu::MultisampleState::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: &module,
                        entry_point: Some("fs_main"),
                        compilation_options: wgpu::PipelineCompilationOptions {
                            constants: &crate::shading::material_constants(textured),
                            ..Default::default()
                        },
                        targets: &crate::renderer::frame_targets(view_depth),
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            };
            let globals = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("lemi recorder globals"),
                size: std::mem::size_of::<ShadingGlobals>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let globals_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("lemi recorder globals"),
                layout: gpu.globals_layout(),
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: globals.as_entire_binding(),
                }],
            });
            LayerRecorder {
                device: gpu.device.clone(),
                queue: gpu.queue.clone(),
                pipelines: [
                    [pipeline(false, false), pipeline(true, false)],
                    [pipeline(false, true), pipeline(true, true)],
                ],
                globals,
                globals_group,
                res,
                targets: Mutex::new(Targets::new(device, res, res, "lemi layer")),
                texels_read: AtomicU64::new(0),
            }
        })
    }

    /// The layer resolution.
    pub fn res(&self) -> u32 {
        self.res
    }

    /// Texels read back from the GPU by this recorder so far (a layer read back whole counts
    /// `res²`; sparse recording counts the tiles it read, [`RecordOptions::sparse`]).
    pub fn texels_read(&self) -> u64 {
        self.texels_read.load(Ordering::Relaxed)
    }

    /// Records `triangles` (three vertices each, positions relative to `center`, already clipped to
    /// the slab) seen along `face` from `center`, with the materials of `runs` and near plane
    /// `near`, with conservative coverage. Triangles not named by any run are not drawn.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        materials: &GpuMaterials,
        center: DVec3,
        face: Face,
        triangles: &[ClipVertex],
        runs: &[MaterialRun],
        near: f64,
        lighting: &Lighting,
    ) -> Result<LayerFrame, GpuError> {
        self.record_with(
            materials,
            center,
            face,
            triangles,
            runs,
            near,
            lighting,
            &RecordOptions::default(),
        )
    }

    /// [`LayerRecorder::record`] with a choice of coverage, readback and depth
    /// ([`RecordOptions`]).
    #[allow(clippy::too_many_arguments)]
    pub fn record_with(
        &self,
        materials: &GpuMaterials,
        center: DVec3,
        face: Face,
        triangles: &[ClipVertex],
        runs: &[MaterialRun],
        near: f64,
        lighting: &Lighting,
        options: &RecordOptions,
    ) -> Result<LayerFrame, GpuError> {
        let coverage = options.coverage;
        if !center.is_finite() {
            return Err(GpuError::Invalid(format!(
                "layer centre must be finite, got {center:?}"
            )));
        }
        if !(near.is_finite() && near > 0.0) {
            return Err(GpuError::Invalid(format!(
                "near plane must be finite and positive, got {near}"
            )));
        }
        if triangles.len() % 3 != 0 {
            return Err(GpuError::Invalid(format!(
                "triangle vertices come in threes, got {}",
                triangles.len()
            )));
        }
        if let Some(i) = triangles.iter().position(|v| !v.rel.is_finite()) {
            return Err(GpuError::Invalid(format!(
                "triangle {} has a non-finite vertex position {:?}",
                i / 3,
                triangles[i].rel
            )));
        }
        let tri_count = triangles.len() / 3;
        for r in runs {
            if materials.bind_group(r.material).is_none() {
                return Err(GpuError::Invalid(format!(
                    "a run uses material {} but only {} materials were uploaded",
                    r.material,
                    materials.len()
                )));
            }
            if r.first as usize + r.count as usize > tri_count {
                return Err(GpuError::Invalid(format!(
                    "run of material {} covers triangles {}..{} but there are {tri_count}",
                    r.material,
                    r.first,
                    r.first as u64 + r.count as u64
                )));
            }
        }
        // Vertices relative to the centre: the view's eye is the origin of that frame.
        let view = View::cube_face(DVec3::ZERO, face, self.res, near);
        let mut globals = ShadingGlobals::new(&view, lighting, 0.0)?;
        if let Some(plane) = options.side_plane {
            if !(plane.is_finite() && plane > 0.0) {
                return Err(GpuError::Invalid(format!(
                    "the side plane must be a finite positive depth, got {plane}"
                )));
            }
            // 0 (never a plane's depth) means no side plane in recorder.wgsl
            globals.depth_axis[3] = plane as f32;
        }
        if options.mark_overshoot {
            globals.eye_lo[3] = 1.0;
        }
        globals.params[1] = self.res as f32;
        globals.params[2] = near as f32;
        globals.params[3] = match coverage {
            Coverage::Conservative => 0.0,
            Coverage::CentreSampled => 1.0,
            Coverage::ClipEdges => 2.0,
        };
        let planes = if coverage == Coverage::ClipEdges {
            options.clip_planes
        } else {
            &[]
        };
        let n = self.res as usize * self.res as usize;
        let drawn = runs.iter().map(|r| r.count as usize).sum::<usize>() > 0;
        if options.sparse && !drawn {
            // nothing is drawn: the layer is empty, no pass and no readback
            return Ok(LayerFrame {
                res: self.res,
                rgba: vec![0; 4 * n],
                depth: if options.depth {
                    vec![f32::INFINITY; n]
                } else {
                    Vec::new()
                },
                content: TexelRect::empty(),
                behind_plane: if options.side_plane.is_some() {
                    vec![false; n]
                } else {
                    Vec::new()
                },
                overshoot: if options.mark_overshoot {
                    vec![false; n]
                } else {
                    Vec::new()
                },
            });
        }
        let rects = if options.sparse {
            touched_tiles(triangles, runs, face, self.res)
        } else {
            vec![TexelRect::full(self.res)]
        };
        let vertices = rec_vertices(triangles, face, planes);
        let targets = self
            .targets
            .lock()
            .map_err(|_| GpuError::Readback("recorder target cache poisoned".into()))?;
        crate::device::scoped(&self.device, "recording a layer", || {
            self.queue
                .write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));
            let buffer = (!vertices.is_empty()).then(|| {
                self.device
                    .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("lemi recorder vertices"),
                        contents: bytemuck::cast_slice(&vertices),
                        usage: wgpu::BufferUsages::VERTEX,
                    })
            });
            let mut encoder = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("lemi record"),
                });
            {
                let mut pass = targets.begin_pass_part(
                    &mut encoder,
                    "lemi layer pass",
                    crate::targets::PassPart::Whole,
                    false,
                    false,
                    options.depth,
                );
                if let Some(buffer) = &buffer {
                    pass.set_bind_group(0, &self.globals_group, &[]);
                    pass.set_vertex_buffer(0, buffer.slice(..));
                    let mut pipeline = None;
                    for r in runs.iter().filter(|r| r.count > 0) {
                        if let Some(g) = materials.bind_group(r.material) {
                            let textured = materials.textured(r.material);
                            if pipeline != Some(textured) {
                                pass.set_pipeline(
                                    &self.pipelines[usize::from(options.depth)]
                                        [usize::from(textured)],
                                );
                                pipeline = Some(textured);
                            }
                            pass.set_bind_group(1, g, &[]);
                            pass.draw(3 * r.first..3 * (r.first + r.count), 0..1);
                        }
                    }
                }
            }
            targets.copy_rects_to_readback(&mut encoder, &rects, options.depth);
            self.queue.submit([encoder.finish()]);
        })?;
        let read = targets.read_rects(&self.device, &rects, options.depth)?;
        self.texels_read.fetch_add(read.texels, Ordering::Relaxed);
        let (mut rgba, depth) = (read.rgba, read.depth);
        // binary alpha; uncovered texels transparent black at infinite depth (texels outside
        // the rectangles were never drawn: already transparent black)
        let mut depth = depth.unwrap_or_default();
        let res = self.res as usize;
        let mut behind_plane = if options.side_plane.is_some() {
            vec![false; n]
        } else {
            Vec::new()
        };
        let mut overshoot = if options.mark_overshoot {
            vec![false; n]
        } else {
            Vec::new()
        };
        for r in &rects {
            for y in r.y0 as usize..r.y1 as usize {
                for x in r.x0 as usize..r.x1 as usize {
                    let k = y * res + x;
                    let px = &mut rgba[4 * k..4 * k + 4];
                    if px[3] == 0 {
                        px.copy_from_slice(&[0; 4]);
                        if let Some(d) = depth.get_mut(k) {
                            *d = f32::INFINITY;
                        }
                    } else {
                        // alpha 1 (in front of the side plane) or ½ (behind it), each ¼
                        // lower for a marked overshoot (recorder.wgsl): 255, 191, 128, 64
                        let a = px[3];
                        if let Some(b) = behind_plane.get_mut(k) {
                            *b = a < 160;
                        }
                        if let Some(o) = overshoot.get_mut(k) {
                            *o = (160..224).contains(&a) || a < 96;
                        }
                        px[3] = 255;
                    }
                }
            }
        }
        if options.depth && options.sparse {
            // texels outside every rectangle: not covered
            let mut inside = vec![false; n];
            for r in &rects {
                for y in r.y0 as usize..r.y1 as usize {
                    inside[y * res + r.x0 as usize..y * res + r.x1 as usize].fill(true);
                }
            }
            for (d, _) in depth.iter_mut().zip(&inside).filter(|(_, &i)| !i) {
                *d = f32::INFINITY;
            }
        }
        Ok(LayerFrame {
            res: self.res,
            rgba,
            depth,
            content: rects.iter().fold(TexelRect::empty(), |a, r| a.union(r)),
            behind_plane,
            overshoot,
        })
    }
}

/// The tiles of [`READBACK_TILE`]² texels (clamped to the layer) that the triangles of `runs`
/// can write, as one rectangle per run of adjacent tiles in a tile row: a triangle writes only
/// texels within its projected bounding box grown by the conservative dilation (half a texel
/// diagonal, [`Coverage::Conservative`]); two texels of margin cover that and rounding. A triangle
/// with a corner not in front of the face (none after clipping to a slab) touches everything.
fn touched_tiles(
    triangles: &[ClipVertex],
    runs: &[MaterialRun],
    face: Face,
    res: u32,
) -> Vec<TexelRect> {
    let tiles = res.div_ceil(READBACK_TILE) as usize;
    let mut touched = vec![false; tiles * tiles];
    let scale = 0.5 * res as f64;
    'tris: for r in runs {
        let (a, b) = (r.first as usize, (r.first + r.count) as usize);
        for tri in triangles.get(3 * a..3 * b).unwrap_or(&[]).chunks_exact(3) {
            let (mut lo, mut hi) = (
                glam::DVec2::splat(f64::INFINITY),
                glam::DVec2::splat(-f64::INFINITY),
            );
            for v in tri {
                let Some((s, t, _)) = face.project(v.rel) else {
                    touched.fill(true);
                    break 'tris;
                };
                let p = glam::DVec2::new((s + 1.0) * scale, (t + 1.0) * scale);
                lo = lo.min(p);
                hi = hi.max(p);
            }
            let lo = (lo - 2.0).max(glam::DVec2::ZERO);
            let hi = (hi + 2.0).min(glam::DVec2::splat(res as f64));
            if !(lo.x < hi.x && lo.y < hi.y) {
                continue;
            }
            let t = READBACK_TILE as f64;
            let (tx0, ty0) = ((lo.x / t) as usize, (lo.y / t) as usize);
            let (tx1, ty1) = (
                ((hi.x / t).ceil() as usize).min(tiles),
                ((hi.y / t).ceil() as usize).min(tiles),
            );
            for ty in ty0..ty1 {
                touched[ty * tiles + tx0..ty * tiles + tx1].fill(true);
            }
        }
    }
    let mut rects = Vec::new();
    for ty in 0..tiles {
        let row = &touched[ty * tiles..(ty + 1) * tiles];
        let mut tx = 0;
        while tx < tiles {
            if !row[tx] {
                tx += 1;
                continue;
            }
            let start = tx;
            while tx < tiles && row[tx] {
                tx += 1;
            }
            let edge = |k: usize| (k as u32 * READBACK_TILE).min(res);
            rects.push(TexelRect {
                x0: edge(start),
                y0: edge(ty),
                x1: edge(tx),
                y1: edge(ty + 1),
            });
        }
    }
    rects
}

/// The non-indexed vertex stream: each vertex with its whole triangle, positions in f32 relative to
/// the cell centre (the f64 → f32 rounding happens after the centre was subtracted), colours
/// normalised to [0, 1]. `corner` is the corner index (bits 0–1) and, from bit 2, one bit per edge
/// `k → k+1` that is a clipping edge on one of `planes` ([`is_clip_edge`]).
fn rec_vertices(triangles: &[ClipVertex], face: Face, planes: &[f64]) -> Vec<RecVertex> {
    let mut out = Vec::with_capacity(triangles.len());
    for tri in triangles.chunks_exact(3) {
        let clip_edges = (0..3)
            .filter(|&k| is_clip_edge(&tri[k], &tri[(k + 1) % 3], face, planes))
            .fold(0u32, |bits, k| bits | 1 << (2 + k));
        let v = RecVertex {
            positions: [0, 1, 2].map(|k| tri[k].rel.as_vec3().to_array()),
            corner: 0,
            normals: [0, 1, 2].map(|k| tri[k].normal),
            uv01: [tri[0].uv[0], tri[0].uv[1], tri[1].uv[0], tri[1].uv[1]],
            uv2: tri[2].uv,
            colors: [0, 1, 2].map(|k| tri[k].color.map(|c| (c / 255.0).clamp(0.0, 1.0))),
        };
        out.extend((0..3).map(|corner| RecVertex {
            corner: corner | clip_edges,
            ..v
        }));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertex_is_148_bytes_and_carries_the_whole_triangle() {
        assert_eq!(std::mem::size_of::<RecVertex>(), 148);
        let v = |x: f64| ClipVertex {
            rel: DVec3::new(x, 0.0, 1.0),
            normal: [0.0, 0.0, 1.0],
            uv: [0.0; 2],
            color: [255.0, 510.0, 0.0, 255.0],
        };
        let r = rec_vertices(&[v(0.0), v(1.0), v(2.0)], Face::PosZ, &[]);
        assert_eq!(r.len(), 3);
        assert_eq!(r.iter().map(|v| v.corner).collect::<Vec<_>>(), [0, 1, 2]);
        assert_eq!(r[1].positions, r[0].positions);
        assert_eq!(r[2].positions[1][0], 1.0);
        assert_eq!(r[0].colors[2], [1.0, 1.0, 0.0, 1.0]);
    }

    /// Texel-centre coverage of the projected triangle `p` (pixel coordinates): `Some(true)` inside
    /// by more than `eps` pixels, `Some(false)` outside by more than `eps`, `None` on an edge.
    fn centre_inside(c: glam::DVec2, p: &[glam::DVec2; 3], eps: f64) -> Option<bool> {
        let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
        let mut min_d = f64::INFINITY;
        for k in 0..3 {
            let (a, b) = (p[k], p[(k + 1) % 3]);
            let e = b - a;
            // signed distance, positive inside for either orientation
            let d = e.perp_dot(c - a) / e.length() * area.signum();
            min_d = min_d.min(d);
        }
        if min_d > eps {
            Some(true)
        } else if min_d < -eps {
            Some(false)
        } else {
            None
        }
    }

    /// Centre-sampled recording covers exactly the texels whose centre lies inside the projected
    /// triangle (ties within 0.01 px aside), a subset of the conservative coverage, which covers
    /// more (the texels the triangle only touches). Clip-edge coverage lies between them: with no
    /// clipping edge it is the centre-sampled coverage; with edge 0 → 1 on a border plane it adds
    /// the texels that edge passes through and no others.
    #[test]
    fn centre_sampled_coverage_is_the_texel_centres_inside() {
        let Some(gpu) = Gpu::for_tests() else { return };
        let m = lemi_core::Material {
            name: "white".into(),
            base_color: [1.0; 4],
            texture: None,
        };
        let mats = GpuMaterials::upload(&gpu, &[m], &[]).expect("materials");
        let res = 32;
        let rec = LayerRecorder::new(&gpu, res).expect("recorder");
        let l = Lighting::default();
        let mut seed = 0x1234_5678_9abc_def1u64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let face = Face::PosZ;
        let (mut extra, mut centre_total, mut clip_extra) = (0usize, 0usize, 0usize);
        for _ in 0..24 {
            let depth = 5.0 + 5.0 * rnd();
            // corners 0 and 1 share their depth: edge 0 → 1 lies on the plane `plane`
            let shared = depth * (1.0 + 0.2 * rnd());
            let mut n = 0;
            let mut corner = || {
                n += 1;
                let d = if n <= 2 {
                    shared
                } else {
                    depth * (1.0 + 0.2 * rnd())
                };
                let rel = face.point(1.6 * rnd() - 0.8, 1.6 * rnd() - 0.8, d);
                ClipVertex {
                    rel,
                    normal: [0.0, 0.0, 1.0],
                    uv: [0.0; 2],
                    color: [255.0; 4],
                }
            };
            let tri = [corner(), corner(), corner()];
            let plane = tri[0].rel.dot(face.forward());
            let runs = [MaterialRun {
                material: 0,
                first: 0,
                count: 1,
            }];
            let rec_with = |c, planes: &[f64]| {
                let options = RecordOptions {
                    coverage: c,
                    clip_planes: planes,
                    ..Default::default()
                };
                rec.record_with(&mats, DVec3::ZERO, face, &tri, &runs, 0.1, &l, &options)
                    .expect("record")
            };
            let cons = rec_with(Coverage::Conservative, &[plane]);
            let centre = rec_with(Coverage::CentreSampled, &[plane]);
            let unclipped = rec_with(Coverage::ClipEdges, &[]);
            let clipped = rec_with(Coverage::ClipEdges, &[plane]);
            assert_eq!(
                cons,
                rec.record(&mats, DVec3::ZERO, face, &tri, &runs, 0.1, &l)
                    .unwrap()
            );
            let p = tri.map(|v| {
                let (s, t, _) = face.project(v.rel).expect("in front");
                glam::DVec2::new((s + 1.0) * 0.5 * res as f64, (t + 1.0) * 0.5 * res as f64)
            });
            for j in 0..res {
                for i in 0..res {
                    let c = glam::DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
                    let covered = centre.covered(i, j);
                    if let Some(inside) = centre_inside(c, &p, 0.01) {
                        assert_eq!(covered, inside, "texel ({i}, {j}) of {p:?}");
                        assert_eq!(unclipped.covered(i, j), inside, "clip-edge mode, no plane");
                        if inside {
                            assert!(clipped.covered(i, j), "clip-edge mode misses ({i}, {j})");
                        }
                    }
                    if clipped.covered(i, j) {
                        assert!(cons.covered(i, j), "clip-edge mode beyond conservative");
                        // beyond the centre-sampled texels only those the clipping edge
                        // touches (0.01 px of slack for rounding; the centre test itself is
                        // inclusive by 1/64 px, so 0.03 px there)
                        let (a, b) = (p[0], p[1]);
                        let r = 0.5 + 0.01;
                        let n = (b - a).perp();
                        let touches = a.min(b).cmple(c + r).all()
                            && a.max(b).cmpge(c - r).all()
                            && n.dot(c - a).abs() <= r * (n.x.abs() + n.y.abs());
                        assert!(
                            covered || centre_inside(c, &p, 0.03) != Some(false) || touches,
                            "clip-edge mode covers ({i}, {j}) of {p:?}, away from the clipping edge"
                        );
                        if !covered {
                            clip_extra += 1;
                        }
                    }
                    if covered {
                        assert!(cons.covered(i, j), "conservative misses ({i}, {j})");
                        let k = (j * res + i) as usize;
                        let d = centre.depth[k];
                        assert!(d.is_finite() && (d - cons.depth[k]).abs() <= 1e-3 * d);
                    }
                }
            }
            // every texel the clipping edge passes through is covered
            let mut on_edge = vec![false; (res * res) as usize];
            lemi_core::clip_border::traverse(p[0], p[1], res, &mut on_edge);
            for (k, _) in on_edge.iter().enumerate().filter(|(_, &e)| e) {
                let (i, j) = (k as u32 % res, k as u32 / res);
                assert!(
                    clipped.covered(i, j),
                    "clipping edge texel ({i}, {j}) of {p:?}"
                );
            }
            centre_total += centre.covered_count();
            extra += cons.covered_count() - centre.covered_count();
        }
        assert!(
            centre_total > 0 && extra > 0 && clip_extra > 0 && clip_extra < extra,
            "{centre_total} {extra} {clip_extra}"
        );
    }
}
