//! The offscreen targets every lemi pipeline renders into and reads back: an sRGB colour image, a
//! linear view-depth image (`R32Uint` holding f32 bits, renderable on every backend) and a reverse-Z
//! depth buffer, plus the two readback buffers. The reference renderer, the layer recorder and the
//! impostor renderer share them, so their passes clear, store and read back identically.

use crate::renderer::{
    padded_bytes_per_row, read_rows, COLOR_FORMAT, DEPTH_FORMAT, VIEW_DEPTH_FORMAT,
};
use crate::GpuError;

/// Render targets and readback buffers of one size.
pub(crate) struct Targets {
    pub(crate) width: u32,
    pub(crate) height: u32,
    color: wgpu::TextureView,
    color_texture: wgpu::Texture,
    view_depth: wgpu::TextureView,
    view_depth_texture: wgpu::Texture,
    depth: wgpu::TextureView,
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
        let tex = |what: &str, format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(&format!("{label} {what}")),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
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
        let color_texture = tex("colour", COLOR_FORMAT, rt);
        let view_depth_texture = tex("view depth", VIEW_DEPTH_FORMAT, rt);
        let depth = tex(
            "depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        Targets {
            width,
            height,
            color: color_texture.create_view(&Default::default()),
            color_texture,
            view_depth: view_depth_texture.create_view(&Default::default()),
            view_depth_texture,
            depth: depth.create_view(&Default::default()),
            color_readback: readback("colour"),
            depth_readback: readback("view depth"),
        }
    }

    /// A pass that clears colour and view depth to 0 and the depth buffer to 0 (reverse-Z far).
    pub(crate) fn begin_pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        label: &str,
    ) -> wgpu::RenderPass<'e> {
        let clear = wgpu::Operations {
            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
            store: wgpu::StoreOp::Store,
        };
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[
                Some(wgpu::RenderPassColorAttachment {
                    view: &self.color,
                    depth_slice: None,
                    resolve_target: None,
                    ops: clear,
                }),
                Some(wgpu::RenderPassColorAttachment {
                    view: &self.view_depth,
                    depth_slice: None,
                    resolve_target: None,
                    ops: clear,
                }),
            ],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(0.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }

    /// Copies colour and view depth into the readback buffers (after the pass).
    pub(crate) fn copy_to_readback(&self, encoder: &mut wgpu::CommandEncoder) {
        for (texture, buffer) in [
            (&self.color_texture, &self.color_readback),
            (&self.view_depth_texture, &self.depth_readback),
        ] {
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(padded_bytes_per_row(self.width, 4)),
                        rows_per_image: Some(self.height),
                    },
                },
                wgpu::Extent3d {
                    width: self.width,
                    height: self.height,
                    depth_or_array_layers: 1,
                },
            );
        }
    }

    /// Reads back the colour (RGBA8, as rendered) and the view depth (f32) after submission.
    pub(crate) fn read(&self, device: &wgpu::Device) -> Result<(Vec<u8>, Vec<f32>), GpuError> {
        let rgba = read_rows(device, &self.color_readback, self.width, self.height)?;
        let depth = read_rows(device, &self.depth_readback, self.width, self.height)?
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        Ok((rgba, depth))
    }
}
