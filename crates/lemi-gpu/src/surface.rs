//! Presenting to a window: [`WindowSurface`] opens a [`Gpu`] on an adapter that can present to a
//! window's surface, and shows CPU images (the read-back [`crate::Frame`]s of the renderers, with
//! whatever the caller drew over them) in the window through a one-triangle blit.
//!
//! The renderers draw offscreen and read back on every backend; presenting their RGBA keeps one
//! code path for the viewer, the headless replay and the tests, at the cost of one upload per
//! frame (small next to a software rasterizer's frame time). The window itself is the caller's
//! (any `raw-window-handle` window, e.g. winit's); this module only needs its handles.
//!
//! Adapter choice follows [`Gpu::new`]: the same backend order ([`BackendChoice`]),
//! `WGPU_ADAPTER_NAME` and `WGPU_POWER_PREF`, plus the condition that the adapter supports the
//! surface.

use std::fmt;
use std::sync::Arc;

use crate::device::{no_adapter_message, scoped};
use crate::{BackendChoice, Gpu, GpuError};

const BLIT_WGSL: &str = r#"
@group(0) @binding(0) var src: texture_2d<f32>;
@group(0) @binding(1) var samp: sampler;

struct VsOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

// One triangle that covers the viewport; uv (0, 0) is the image's top-left corner.
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VsOut {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: VsOut;
    out.pos = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    return vec4<f32>(textureSample(src, samp, in.uv).rgb, 1.0);
}
"#;

/// What [`WindowSurface::present`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Presented {
    /// The image is on screen.
    Shown,
    /// The frame was skipped (window occluded, swapchain timed out or outdated and reconfigured);
    /// try again next frame.
    Skipped(&'static str),
}

/// The uploaded source image and its bind group.
struct Source {
    width: u32,
    height: u32,
    texture: wgpu::Texture,
    group: wgpu::BindGroup,
}

/// A window's surface on its own [`Gpu`], with the blit that presents CPU images.
pub struct WindowSurface {
    gpu: Arc<Gpu>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// `Rgba8UnormSrgb` when the surface format is sRGB (decoded on sampling, encoded on store),
    /// `Rgba8Unorm` otherwise (the sRGB bytes pass through unchanged): either way the window shows
    /// the image's bytes.
    source_format: wgpu::TextureFormat,
    source: Option<Source>,
}

impl fmt::Debug for WindowSurface {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("WindowSurface")
            .field("gpu", &self.gpu)
            .field("format", &self.config.format)
            .field("present_mode", &self.config.present_mode)
            .field("size", &(self.config.width, self.config.height))
            .finish()
    }
}

impl WindowSurface {
    /// Opens a device on an adapter that can present to `window` (its display: `display`, e.g.
    /// winit's `OwnedDisplayHandle`, which the GL backend needs at instance creation) and
    /// configures the surface at `width × height` (clamped to at least 1). `vsync`: wait for the
    /// display (FIFO) rather than present as fast as possible where the surface allows it.
    pub fn new<W, D>(
        window: W,
        display: D,
        choice: BackendChoice,
        width: u32,
        height: u32,
        vsync: bool,
    ) -> Result<WindowSurface, GpuError>
    where
        W: wgpu::WindowHandle + Clone + 'static,
        D: wgpu::rwh::HasDisplayHandle + fmt::Debug + Send + Sync + Clone + 'static,
    {
        pollster::block_on(Self::new_async(
            window, display, choice, width, height, vsync,
        ))
    }

    async fn new_async<W, D>(
        window: W,
        display: D,
        choice: BackendChoice,
        width: u32,
        height: u32,
        vsync: bool,
    ) -> Result<WindowSurface, GpuError>
    where
        W: wgpu::WindowHandle + Clone + 'static,
        D: wgpu::rwh::HasDisplayHandle + fmt::Debug + Send + Sync + Clone + 'static,
    {
        let wanted_name = std::env::var("WGPU_ADAPTER_NAME")
            .ok()
            .map(|s| s.to_lowercase());
        let mut notes = Vec::new();
        for backends in choice.attempts() {
            if backends.is_empty() {
                continue;
            }
            let mut desc = wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(
                display.clone(),
            ));
            desc.backends = backends;
            let instance = wgpu::Instance::new(desc);
            let surface = match instance
                .create_surface(wgpu::SurfaceTarget::Window(Box::new(window.clone())))
            {
                Ok(s) => s,
                Err(e) => {
                    notes.push(format!("{backends:?}: no surface ({e})"));
                    continue;
                }
            };
            let adapter = match &wanted_name {
                Some(name) => instance
                    .enumerate_adapters(backends)
                    .await
                    .into_iter()
                    .find(|a| {
                        a.get_info().name.to_lowercase().contains(name.as_str())
                            && a.is_surface_supported(&surface)
                    }),
                None => instance
                    .request_adapter(&wgpu::RequestAdapterOptions {
                        power_preference: wgpu::PowerPreference::from_env().unwrap_or_default(),
                        force_fallback_adapter: false,
                        compatible_surface: Some(&surface),
                        ..Default::default()
                    })
                    .await
                    .ok(),
            };
            let Some(adapter) = adapter else {
                notes.push(format!(
                    "{backends:?}: no adapter that presents to the window"
                ));
                continue;
            };
            let info = adapter.get_info();
            let (device, queue) = adapter
                .request_device(&wgpu::DeviceDescriptor {
                    label: Some("lemi window"),
                    required_features: wgpu::Features::empty(),
                    required_limits: adapter.limits(),
                    ..Default::default()
                })
                .await
                .map_err(|e| GpuError::Device {
                    adapter: format!("{} ({:?})", info.name, info.backend),
                    message: e.to_string(),
                })?;
            let caps = surface.get_capabilities(&adapter);
            let Some(mut config) =
                surface.get_default_config(&adapter, width.max(1), height.max(1))
            else {
                notes.push(format!(
                    "{backends:?}: adapter {} cannot present to the window",
                    info.name
                ));
                continue;
            };
            // An sRGB format if there is one (the images are sRGB-encoded either way).
            if let Some(f) = caps.formats.iter().find(|f| f.is_srgb()) {
                config.format = *f;
            }
            config.present_mode = if vsync {
                wgpu::PresentMode::AutoVsync
            } else {
                wgpu::PresentMode::AutoNoVsync
            };
            let gpu = Arc::new(Gpu::from_parts(device, queue, info));
            return Self::with_surface(gpu, surface, config);
        }
        let tried = if notes.is_empty() {
            String::new()
        } else {
            format!(" ({})", notes.join("; "))
        };
        let name = wanted_name
            .map(|n| format!("WGPU_ADAPTER_NAME={n}: "))
            .unwrap_or_default();
        Err(GpuError::NoAdapter(format!(
            "{name}no adapter can present to the window{tried}; {}",
            no_adapter_message(&choice.to_string())
        )))
    }

    fn with_surface(
        gpu: Arc<Gpu>,
        surface: wgpu::Surface<'static>,
        config: wgpu::SurfaceConfiguration,
    ) -> Result<WindowSurface, GpuError> {
        let source_format = if config.format.is_srgb() {
            wgpu::TextureFormat::Rgba8UnormSrgb
        } else {
            wgpu::TextureFormat::Rgba8Unorm
        };
        let device = &gpu.device;
        let (pipeline, layout, sampler) = scoped(device, "creating the window blit", || {
            surface.configure(device, &config);
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("lemi blit"),
                source: wgpu::ShaderSource::Wgsl(BLIT_WGSL.into()),
            });
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("lemi blit"),
                entries: &[
                    wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: wgpu::ShaderStages::FRAGMENT,
                        ty: wgpu::BindingType::Texture {
                            sample_type: wgpu::TextureSampleType::Float { filterable: true },
                            view_dimension: wgpu::TextureViewDimension::D2,
                            multisampled: false,
                        },
                        count: None,
                    },
                    wgpu::BindGroupLayoutEntry {
                        binding: 1,
                        visibility: wgpu::ShaderStages::FRAGMENT,
                        ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                        count: None,
                    },
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("lemi blit"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("lemi blit"),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: config.format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            });
            let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("lemi blit"),
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                ..Default::default()
            });
            (pipeline, layout, sampler)
        })?;
        Ok(WindowSurface {
            gpu,
            surface,
            config,
            pipeline,
            layout,
            sampler,
            source_format,
            source: None,
        })
    }

    /// The device, for the renderers that draw the frames.
    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    /// The surface's size in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.config.width, self.config.height)
    }

    /// `"Bgra8UnormSrgb, Fifo"`: the surface format and present mode.
    pub fn describe(&self) -> String {
        format!("{:?}, {:?}", self.config.format, self.config.present_mode)
    }

    /// Reconfigures the surface for a new window size (ignored while a side is 0: minimized).
    pub fn resize(&mut self, width: u32, height: u32) -> Result<(), GpuError> {
        if width == 0 || height == 0 || (width, height) == self.size() {
            return Ok(());
        }
        let max = self.gpu.limits().max_texture_dimension_2d;
        self.config.width = width.min(max);
        self.config.height = height.min(max);
        scoped(&self.gpu.device, "configuring the window surface", || {
            self.surface.configure(&self.gpu.device, &self.config)
        })
    }

    /// Shows `rgba` (sRGB-encoded RGBA8, `width × height`, rows top to bottom) stretched over the
    /// whole window.
    pub fn present(&mut self, rgba: &[u8], width: u32, height: u32) -> Result<Presented, GpuError> {
        if width == 0 || height == 0 || rgba.len() != 4 * width as usize * height as usize {
            return Err(GpuError::Invalid(format!(
                "an image of {} bytes is not {width}x{height} RGBA8",
                rgba.len()
            )));
        }
        let max = self.gpu.limits().max_texture_dimension_2d;
        if width > max || height > max {
            return Err(GpuError::Limit(format!(
                "image size {width}x{height} is larger than this adapter's textures (1..={max} per side)"
            )));
        }
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) => t,
            wgpu::CurrentSurfaceTexture::Suboptimal(t) => {
                // show this one; reconfigure before the next
                let shown = self.blit(t, rgba, width, height);
                scoped(&self.gpu.device, "configuring the window surface", || {
                    self.surface.configure(&self.gpu.device, &self.config)
                })?;
                return shown;
            }
            wgpu::CurrentSurfaceTexture::Timeout => return Ok(Presented::Skipped("timeout")),
            wgpu::CurrentSurfaceTexture::Occluded => return Ok(Presented::Skipped("occluded")),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                scoped(&self.gpu.device, "configuring the window surface", || {
                    self.surface.configure(&self.gpu.device, &self.config)
                })?;
                return Ok(Presented::Skipped("surface outdated"));
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(GpuError::Wgpu {
                    what: "acquiring the next window image".into(),
                    message: "validation error".into(),
                })
            }
        };
        self.blit(frame, rgba, width, height)
    }

    fn blit(
        &mut self,
        frame: wgpu::SurfaceTexture,
        rgba: &[u8],
        width: u32,
        height: u32,
    ) -> Result<Presented, GpuError> {
        let gpu = self.gpu.clone();
        let device = &gpu.device;
        if self
            .source
            .as_ref()
            .is_none_or(|s| s.width != width || s.height != height)
        {
            self.source = Some(scoped(
                device,
                "creating the window's source image",
                || {
                    let texture = device.create_texture(&wgpu::TextureDescriptor {
                        label: Some("lemi blit source"),
                        size: wgpu::Extent3d {
                            width,
                            height,
                            depth_or_array_layers: 1,
                        },
                        mip_level_count: 1,
                        sample_count: 1,
                        dimension: wgpu::TextureDimension::D2,
                        format: self.source_format,
                        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                        view_formats: &[],
                    });
                    let view = texture.create_view(&Default::default());
                    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("lemi blit"),
                        layout: &self.layout,
                        entries: &[
                            wgpu::BindGroupEntry {
                                binding: 0,
                                resource: wgpu::BindingResource::TextureView(&view),
                            },
                            wgpu::BindGroupEntry {
                                binding: 1,
                                resource: wgpu::BindingResource::Sampler(&self.sampler),
                            },
                        ],
                    });
                    Source {
                        width,
                        height,
                        texture,
                        group,
                    }
                },
            )?);
        }
        let Some(source) = self.source.as_ref() else {
            return Err(GpuError::Invalid("the blit source is missing".into()));
        };
        scoped(device, "presenting to the window", || {
            gpu.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &source.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                rgba,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * width),
                    rows_per_image: Some(height),
                },
                wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
            );
            let view = frame.texture.create_view(&Default::default());
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("lemi blit"),
            });
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("lemi blit"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &source.group, &[]);
                pass.draw(0..3, 0..1);
            }
            gpu.queue.submit([encoder.finish()]);
            gpu.queue.present(frame);
        })?;
        Ok(Presented::Shown)
    }
}
