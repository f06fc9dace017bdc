//! The offscreen targets every lemi pipeline renders into and reads back: an sRGB colour image, a
//! linear view-depth image (`R32Uint` holding f32 bits, renderable on every backend) and a reverse-Z
//! depth buffer, plus the two readback buffers. The reference renderer, the layer recorder and the
//! impostor renderer share them, so their passes clear, store and read back identically.
//!
//! Also: an `Rgba8Unorm` view of the colour texture where the backend has view formats (the
//! impostor quads store their sRGB-encoded texels through it unchanged), and, on devices with
//! timestamp queries, two timestamps around a frame's passes, resolved in the frame's own
//! submission and read back with its images in the same wait ([`Targets::read_frame`]). The
//! readback maps all buffers at once and strips row padding, converts depth and fixes the
//! background in one pass over the rows.

use crate::renderer::{
    padded_bytes_per_row, Frame, GpuTime, COLOR_FORMAT, DEPTH_FORMAT, VIEW_DEPTH_FORMAT,
};
use crate::GpuError;
use lemi_core::compress::TexelRect;

/// The colour texture's second view format: the same bytes without sRGB encoding.
pub(crate) const LINEAR_COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Which part of a frame a pass is ([`Targets::begin_pass_part`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PassPart {
    /// The whole frame in one pass: clear, draw, keep colour and view depth.
    Whole,
    /// The first of two passes: clear, draw, keep all three targets.
    First,
    /// The second of two passes: load, draw, keep colour and view depth.
    Last,
    /// A pass between the first and the last: load, draw, keep all three targets.
    Middle,
}

/// What [`Targets::read_rects`] read: whole images, the texels of the rectangles filled in.
pub(crate) struct RectReadback {
    pub rgba: Vec<u8>,
    /// f32 view depth as stored, when asked for.
    pub depth: Option<Vec<f32>>,
    /// Texels read (the rectangles' area).
    pub texels: u64,
}

/// Whether a colour texture on `device` can be rendered through an `Rgba8Unorm` view as well as
/// its `Rgba8UnormSrgb` format (wgpu's `DownlevelFlags::VIEW_FORMATS`, which only the GL backend
/// lacks).
pub(crate) fn linear_views_supported(device: &wgpu::Device) -> bool {
    device.adapter_info().backend != wgpu::Backend::Gl
}

/// Render targets and readback buffers of one size.
pub(crate) struct Targets {
    /// An `Rgba8Unorm` view of the colour texture, where the backend allows it.
    color_linear: Option<wgpu::TextureView>,
    /// Timestamps around a pass, when the device has [`wgpu::Features::TIMESTAMP_QUERY`].
    timer: Option<PassTimer>,
    pub(crate) width: u32,
    pub(crate) height: u32,
    color: wgpu::TextureView,
    color_texture: wgpu::Texture,
    view_depth: wgpu::TextureView,
    view_depth_texture: wgpu::Texture,
    depth: wgpu::TextureView,
    depth_texture: wgpu::Texture,
    /// A copy of the depth buffer taken between passes ([`Targets::copy_depth`]), which a later
    /// pass samples (the impostor renderer's outline fringe pass).
    depth_copy_texture: wgpu::Texture,
    depth_copy: wgpu::TextureView,
    color_readback: wgpu::Buffer,
    depth_readback: wgpu::Buffer,
}

impl Targets {
    /// Targets of `width × height`; `label` prefixes the resources' debug names.
    pub(crate) fn new(device: &wgpu::Device, width: u32, height: u32, label: &str) -> Targets {
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let linear = linear_views_supported(device);
        let tex = |what: &str, format, usage, view_formats: &[wgpu::TextureFormat]| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(&format!("{label} {what}")),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats,
            })
        };
        let rt = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let readback = |what: &str| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("{label} {what} readback")),
                size: padded_bytes_per_row(width, 4) as u64 * height as u64,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let linear_format = [LINEAR_COLOR_FORMAT];
        let color_texture = tex(
            "colour",
            COLOR_FORMAT,
            rt,
            if linear { &linear_format } else { &[] },
        );
        let view_depth_texture = tex("view depth", VIEW_DEPTH_FORMAT, rt, &[]);
        let depth = tex(
            "depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            &[],
        );
        let depth_copy_texture = tex(
            "depth copy",
            DEPTH_FORMAT,
            wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::TEXTURE_BINDING,
            &[],
        );
        Targets {
            color_linear: linear.then(|| {
                color_texture.create_view(&wgpu::TextureViewDescriptor {
                    label: Some(&format!("{label} colour (linear view)")),
                    format: Some(LINEAR_COLOR_FORMAT),
                    ..Default::default()
                })
            }),
            timer: PassTimer::new(device, label),
            width,
            height,
            color: color_texture.create_view(&Default::default()),
            color_texture,
            view_depth: view_depth_texture.create_view(&Default::default()),
            view_depth_texture,
            depth: depth.create_view(&Default::default()),
            depth_texture: depth,
            depth_copy: depth_copy_texture.create_view(&Default::default()),
            depth_copy_texture,
            color_readback: readback("colour"),
            depth_readback: readback("view depth"),
        }
    }

    /// A pass that clears colour and view depth to 0 and the depth buffer to 0 (reverse-Z far),
    /// with timestamps written at the beginning and the end of the
    /// pass when the device supports them; [`Targets::resolve_timer`] after the pass and
    /// [`Targets::read_frame`] (or [`Targets::read_timer`]) turn them into milliseconds. Without
    /// `view_depth` the pass has no view-depth target (pipelines of [`frame_targets`]`(false)`).
    ///
    /// [`frame_targets`]: crate::renderer::frame_targets
    pub(crate) fn begin_timed_pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        label: &str,
        view_depth: bool,
    ) -> wgpu::RenderPass<'e> {
        self.begin_pass_part(encoder, label, PassPart::Whole, false, true, view_depth)
    }

    /// Whether the colour target also has a linear (`Rgba8Unorm`) view, see
    /// [`Targets::begin_pass_part`].
    pub(crate) fn has_linear_color(&self) -> bool {
        self.color_linear.is_some()
    }

    /// One pass of a frame drawn in one ([`PassPart::Whole`]) or two passes ([`PassPart::First`]
    /// clears and keeps the depth buffer, [`PassPart::Last`] loads everything). `linear_color`
    /// renders colour through the `Rgba8Unorm` view of the sRGB colour texture, so fragment
    /// outputs are stored as they are, without sRGB encoding (ignored without such a view,
    /// [`Targets::has_linear_color`]). `timed`: the frame's timestamps (beginning in the first
    /// part, end in the last). `view_depth`: whether the pass writes the view-depth target; a
    /// frame that is not read back has no use for it, and leaves it out as a renderer presenting
    /// its frames would (it costs a store per fragment on a software rasterizer).
    pub(crate) fn begin_pass_part<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        label: &str,
        part: PassPart,
        linear_color: bool,
        timed: bool,
        view_depth: bool,
    ) -> wgpu::RenderPass<'e> {
        // (PassPart::Middle is neither)
        let first = matches!(part, PassPart::Whole | PassPart::First);
        let last = matches!(part, PassPart::Whole | PassPart::Last);
        let timestamp_writes = self
            .timer
            .as_ref()
            .filter(|_| timed && (first || last))
            .map(|t| wgpu::RenderPassTimestampWrites {
                query_set: &t.queries,
                beginning_of_pass_write_index: first.then_some(0),
                end_of_pass_write_index: last.then_some(1),
            });
        let color_ops = wgpu::Operations {
            load: if first {
                wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT)
            } else {
                wgpu::LoadOp::Load
            },
            store: wgpu::StoreOp::Store,
        };
        let color_view = match (&self.color_linear, linear_color) {
            (Some(v), true) => v,
            _ => &self.color,
        };
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[
                Some(wgpu::RenderPassColorAttachment {
                    view: color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: color_ops,
                }),
                view_depth.then_some(wgpu::RenderPassColorAttachment {
                    view: &self.view_depth,
                    depth_slice: None,
                    resolve_target: None,
                    ops: color_ops,
                }),
            ],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth,
                depth_ops: Some(wgpu::Operations {
                    load: if first {
                        wgpu::LoadOp::Clear(0.0)
                    } else {
                        wgpu::LoadOp::Load
                    },
                    store: if last {
                        wgpu::StoreOp::Discard
                    } else {
                        wgpu::StoreOp::Store
                    },
                }),
                stencil_ops: None,
            }),
            timestamp_writes,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }

    /// Copies the depth buffer (as the last pass stored it: [`PassPart::First`] or
    /// [`PassPart::Middle`]) into the texture [`Targets::depth_copy`] views, for a later pass to
    /// sample.
    pub(crate) fn copy_depth(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.copy_texture_to_texture(
            self.depth_texture.as_image_copy(),
            self.depth_copy_texture.as_image_copy(),
            self.depth_texture.size(),
        );
    }

    /// The copy of the depth buffer [`Targets::copy_depth`] writes (reverse-Z: 0 where nothing
    /// was drawn).
    pub(crate) fn depth_copy(&self) -> &wgpu::TextureView {
        &self.depth_copy
    }

    /// Copies colour and view depth into the readback buffers (after the pass).
    pub(crate) fn copy_to_readback(&self, encoder: &mut wgpu::CommandEncoder) {
        self.copy_rects_to_readback(encoder, &[self.whole()], true);
    }

    /// The whole target as one rectangle.
    pub(crate) fn whole(&self) -> TexelRect {
        TexelRect {
            x0: 0,
            y0: 0,
            x1: self.width,
            y1: self.height,
        }
    }

    /// Copies the rectangles `rects` of the colour (and, with `depth`, the view depth) into the
    /// readback buffers, each where a copy of the whole image would put it, so that
    /// [`Targets::read_rects`] finds them at their rows and columns. Rectangles must lie inside
    /// the target.
    pub(crate) fn copy_rects_to_readback(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        rects: &[TexelRect],
        depth: bool,
    ) {
        let padded = padded_bytes_per_row(self.width, 4);
        let targets = [
            (&self.color_texture, &self.color_readback),
            (&self.view_depth_texture, &self.depth_readback),
        ];
        for (texture, buffer) in targets.into_iter().take(if depth { 2 } else { 1 }) {
            for r in rects.iter().filter(|r| !r.is_empty()) {
                encoder.copy_texture_to_buffer(
                    wgpu::TexelCopyTextureInfo {
                        texture,
                        mip_level: 0,
                        origin: wgpu::Origin3d {
                            x: r.x0,
                            y: r.y0,
                            z: 0,
                        },
                        aspect: wgpu::TextureAspect::All,
                    },
                    wgpu::TexelCopyBufferInfo {
                        buffer,
                        layout: wgpu::TexelCopyBufferLayout {
                            // a multiple of the 4-byte texel, as copies require
                            offset: r.y0 as u64 * padded as u64 + 4 * r.x0 as u64,
                            bytes_per_row: Some(padded),
                            rows_per_image: Some(r.y1 - r.y0),
                        },
                    },
                    wgpu::Extent3d {
                        width: r.x1 - r.x0,
                        height: r.y1 - r.y0,
                        depth_or_array_layers: 1,
                    },
                );
            }
        }
    }

    /// Resolves the pass timestamps into the timer's readback buffer (after the pass, in the same
    /// encoder as [`Targets::copy_to_readback`], so reading them costs no extra submission).
    pub(crate) fn resolve_timer(&self, encoder: &mut wgpu::CommandEncoder) {
        if let Some(t) = &self.timer {
            encoder.resolve_query_set(&t.queries, 0..2, &t.resolve, 0);
            encoder.copy_buffer_to_buffer(&t.resolve, 0, &t.readback, 0, Some(TIMER_BYTES));
        }
    }

    /// Reads back, after a submission that copied `rects` ([`Targets::copy_rects_to_readback`]),
    /// the colour (RGBA8, as rendered) and, with `depth`, the view depth (f32 bits as stored) of
    /// those rectangles into whole-image buffers: texels outside every rectangle are `[0; 4]` and
    /// depth 0, as after the pass's clear. Returns the images and the number of texels read.
    pub(crate) fn read_rects(
        &self,
        device: &wgpu::Device,
        rects: &[TexelRect],
        depth: bool,
    ) -> Result<RectReadback, GpuError> {
        let (w, h) = (self.width as usize, self.height as usize);
        // zeroed allocations: the pages of texels no rectangle covers are never written
        let mut rgba = vec![0u8; 4 * w * h];
        let mut depths = depth.then(|| vec![0f32; w * h]);
        if rects.iter().all(TexelRect::is_empty) {
            return Ok(RectReadback {
                rgba,
                depth: depths,
                texels: 0,
            });
        }
        let buffers: Vec<&wgpu::Buffer> = [&self.color_readback, &self.depth_readback]
            .into_iter()
            .take(if depth { 2 } else { 1 })
            .collect();
        map_all(device, &buffers)?;
        let result = (|| -> Result<u64, GpuError> {
            let padded = padded_bytes_per_row(self.width, 4) as usize;
            let colour = self
                .color_readback
                .get_mapped_range(..)
                .map_err(|e| GpuError::Readback(e.to_string()))?;
            let mut read = 0u64;
            for r in rects.iter().filter(|r| !r.is_empty()) {
                let (x0, x1) = (r.x0 as usize, r.x1 as usize);
                for y in r.y0 as usize..r.y1 as usize {
                    rgba[4 * (y * w + x0)..4 * (y * w + x1)]
                        .copy_from_slice(&colour[y * padded + 4 * x0..y * padded + 4 * x1]);
                }
                read += r.texels();
            }
            if let Some(depths) = depths.as_mut() {
                let bytes = self
                    .depth_readback
                    .get_mapped_range(..)
                    .map_err(|e| GpuError::Readback(e.to_string()))?;
                for r in rects.iter().filter(|r| !r.is_empty()) {
                    let (x0, x1) = (r.x0 as usize, r.x1 as usize);
                    for y in r.y0 as usize..r.y1 as usize {
                        let src = &bytes[y * padded + 4 * x0..y * padded + 4 * x1];
                        for (d, b) in depths[y * w + x0..y * w + x1]
                            .iter_mut()
                            .zip(src.chunks_exact(4))
                        {
                            *d = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                        }
                    }
                }
            }
            Ok(read)
        })();
        for b in buffers {
            b.unmap();
        }
        Ok(RectReadback {
            rgba,
            depth: depths,
            texels: result?,
        })
    }

    /// Reads back a [`Frame`] after submission: colour and view depth, with pixels no fragment was
    /// written to (colour alpha 0 after the clear; every lemi fragment writes alpha 1) set to
    /// `clear` and depth `f32::INFINITY`; plus the pass's GPU time in milliseconds when the pass
    /// was timed ([`Targets::begin_timed_pass`], [`Targets::resolve_timer`]) on a device with
    /// timestamp queries. One wait for all three buffers.
    pub(crate) fn read_frame(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        clear: [u8; 4],
    ) -> Result<(Frame, Option<f64>), GpuError> {
        let mut buffers = vec![&self.color_readback, &self.depth_readback];
        if let Some(t) = &self.timer {
            buffers.push(&t.readback);
        }
        map_all(device, &buffers)?;
        let frame = self.extract_frame(clear);
        let ms = self.timer.as_ref().map(|t| t.elapsed_ms(queue));
        for b in buffers {
            b.unmap();
        }
        Ok((frame?, ms.flatten()))
    }
    /// Ends a frame's encoding after its last pass: resolves the pass timer and, with `readback`,
    /// copies colour and view depth into the readback buffers.
    pub(crate) fn finish_encoding(&self, encoder: &mut wgpu::CommandEncoder, readback: bool) {
        self.resolve_timer(encoder);
        if readback {
            self.copy_to_readback(encoder);
        }
    }

    /// After the frame's submission: its GPU time into `time` and, with `readback`, the frame
    /// ([`Targets::read_frame`]; background `clear`), else `None` once the GPU has finished.
    pub(crate) fn collect(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        readback: bool,
        clear: [u8; 4],
        time: &GpuTime,
    ) -> Result<Option<Frame>, GpuError> {
        if !readback {
            time.set(self.read_timer(device, queue)?);
            return Ok(None);
        }
        let (frame, ms) = self.read_frame(device, queue, clear)?;
        time.set(ms);
        Ok(Some(frame))
    }

    /// The pass's GPU time in milliseconds (after submission of a timed and resolved pass), without
    /// reading the images; `None` without timestamp queries.
    pub(crate) fn read_timer(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Option<f64>, GpuError> {
        let Some(t) = &self.timer else {
            device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| GpuError::Readback(e.to_string()))?;
            return Ok(None);
        };
        map_all(device, &[&t.readback])?;
        let ms = t.elapsed_ms(queue);
        t.readback.unmap();
        Ok(ms)
    }

    /// Colour and depth out of the mapped readback buffers, rows unpadded, background fixed.
    fn extract_frame(&self, clear: [u8; 4]) -> Result<Frame, GpuError> {
        let (w, h) = (self.width as usize, self.height as usize);
        let padded = padded_bytes_per_row(self.width, 4) as usize;
        let colour = self
            .color_readback
            .get_mapped_range(..)
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let depth_bytes = self
            .depth_readback
            .get_mapped_range(..)
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let mut rgba = Vec::with_capacity(4 * w * h);
        let mut depth: Vec<f32> = Vec::with_capacity(w * h);
        for y in 0..h {
            let row = y * padded..y * padded + 4 * w;
            let start = rgba.len();
            rgba.extend_from_slice(&colour[row.clone()]);
            depth.extend(
                depth_bytes[row]
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            );
            let d0 = depth.len() - w;
            for (px, d) in rgba[start..]
                .chunks_exact_mut(4)
                .zip(depth[d0..].iter_mut())
            {
                if px[3] == 0 {
                    px.copy_from_slice(&clear);
                    *d = f32::INFINITY;
                }
            }
        }
        Ok(Frame {
            width: self.width,
            height: self.height,
            rgba,
            depth,
        })
    }
}

/// Bytes of the two resolved timestamps.
const TIMER_BYTES: u64 = 2 * wgpu::QUERY_SIZE as u64;

/// Two timestamp queries (beginning and end of one pass) and the buffers to read them back.
struct PassTimer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
}

impl PassTimer {
    /// `None` unless the device was opened with [`wgpu::Features::TIMESTAMP_QUERY`].
    fn new(device: &wgpu::Device, label: &str) -> Option<PassTimer> {
        if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            return None;
        }
        let buffer = |what: &str, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("{label} timestamps {what}")),
                size: TIMER_BYTES,
                usage,
                mapped_at_creation: false,
            })
        };
        Some(PassTimer {
            queries: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some(&format!("{label} pass timestamps")),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolve: buffer(
                "resolve",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            readback: buffer(
                "readback",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
        })
    }

    /// End minus beginning in milliseconds, from the mapped readback buffer; `None` when the
    /// values are unusable (end before beginning, or the buffer cannot be read).
    fn elapsed_ms(&self, queue: &wgpu::Queue) -> Option<f64> {
        let bytes = self.readback.get_mapped_range(..).ok()?;
        let t: &[u64] = bytemuck::try_cast_slice(&bytes).ok()?;
        let (begin, end) = (*t.first()?, *t.get(1)?);
        let ticks = end.checked_sub(begin)?;
        Some(ticks as f64 * queue.get_timestamp_period() as f64 * 1e-6)
    }
}

/// Maps every buffer for reading and waits once for all of them.
fn map_all(device: &wgpu::Device, buffers: &[&wgpu::Buffer]) -> Result<(), GpuError> {
    let (tx, rx) = std::sync::mpsc::channel();
    for b in buffers {
        let tx = tx.clone();
        b.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
    }
    drop(tx);
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| GpuError::Readback(e.to_string()))?;
    for _ in buffers {
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
    }
    Ok(())
}
