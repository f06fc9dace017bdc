//! Base colour textures on the GPU: a full mip chain built on the CPU (2×2 box filter in linear
//! space, i.e. sRGB-decoded, then re-encoded; Williams, "Pyramidal Parametrics", SIGGRAPH 1983),
//! uploaded as `Rgba8UnormSrgb` so sampling decodes sRGB. CPU mip generation keeps the result
//! identical on every backend.

use lemi_core::Texture;

use crate::shading::{linear_to_srgb, srgb_to_linear};
use crate::{Gpu, GpuError};

/// One mip level: size and tightly packed sRGB RGBA8 rows.
#[derive(Clone, Debug, PartialEq)]
pub struct MipLevel {
    pub width: u32,
    pub height: u32,
    pub rgba8: Vec<u8>,
}

/// The next smaller level: each texel averages the (up to) 2×2 texels it covers, colour in linear
/// space, alpha linearly.
pub fn downsample(level: &MipLevel, lut: &[f32; 256]) -> MipLevel {
    let w = (level.width / 2).max(1);
    let h = (level.height / 2).max(1);
    let mut out = vec![0u8; (w * h * 4) as usize];
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0f32; 4];
            let mut n = 0f32;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let sx = (2 * x + dx).min(level.width - 1);
                let sy = (2 * y + dy).min(level.height - 1);
                let i = ((sy * level.width + sx) * 4) as usize;
                for c in 0..3 {
                    acc[c] += lut[level.rgba8[i + c] as usize];
                }
                acc[3] += level.rgba8[i + 3] as f32;
                n += 1.0;
            }
            let o = ((y * w + x) * 4) as usize;
            for c in 0..3 {
                out[o + c] = linear_to_srgb(acc[c] / n);
            }
            out[o + 3] = (acc[3] / n + 0.5).floor() as u8;
        }
    }
    MipLevel {
        width: w,
        height: h,
        rgba8: out,
    }
}

/// The full mip chain of `texture` down to 1×1, dropping leading levels larger than `max_dim`.
pub fn mip_chain(texture: &Texture, max_dim: u32) -> Result<Vec<MipLevel>, GpuError> {
    let (w, h) = (texture.width, texture.height);
    let expected = w as u64 * h as u64 * 4;
    if w == 0 || h == 0 || texture.rgba8.len() as u64 != expected {
        return Err(GpuError::Invalid(format!(
            "texture `{}` is {w}x{h} but has {} bytes of RGBA8 data (expected {expected})",
            texture.name,
            texture.rgba8.len()
        )));
    }
    let lut: [f32; 256] = std::array::from_fn(|i| srgb_to_linear(i as u8));
    let mut levels = vec![MipLevel {
        width: w,
        height: h,
        rgba8: texture.rgba8.clone(),
    }];
    while let Some(last) = levels.last() {
        if last.width == 1 && last.height == 1 {
            break;
        }
        let next = downsample(last, &lut);
        levels.push(next);
    }
    let skip = levels
        .iter()
        .take_while(|l| l.width > max_dim || l.height > max_dim)
        .count();
    Ok(levels.split_off(skip.min(levels.len() - 1)))
}

/// Uploads a mip chain as an `Rgba8UnormSrgb` texture and returns its view.
pub fn upload_levels(gpu: &Gpu, label: &str, levels: &[MipLevel]) -> wgpu::TextureView {
    let (w, h) = levels
        .first()
        .map(|l| (l.width, l.height))
        .unwrap_or((1, 1));
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
        mip_level_count: levels.len().max(1) as u32,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8UnormSrgb,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for (mip, level) in levels.iter().enumerate() {
        gpu.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: mip as u32,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &level.rgba8,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * level.width),
                rows_per_image: Some(level.height),
            },
            wgpu::Extent3d {
                width: level.width,
                height: level.height,
                depth_or_array_layers: 1,
            },
        );
    }
    texture.create_view(&wgpu::TextureViewDescriptor::default())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mip_chain_averages_in_linear_space() {
        // black and white checker 2x2: the 1x1 level is linear 0.5 -> sRGB 188, not 128.
        let t = Texture {
            name: "checker".into(),
            width: 2,
            height: 2,
            rgba8: vec![
                0, 0, 0, 255, 255, 255, 255, 255, 255, 255, 255, 255, 0, 0, 0, 255,
            ],
        };
        let levels = mip_chain(&t, 16).unwrap();
        assert_eq!(levels.len(), 2);
        assert_eq!(levels[1].rgba8, vec![188, 188, 188, 255]);
        // a 5x3 texture has levels 5x3, 2x1, 1x1
        let t = Texture {
            name: "odd".into(),
            width: 5,
            height: 3,
            rgba8: vec![7; 60],
        };
        let sizes: Vec<_> = mip_chain(&t, 16)
            .unwrap()
            .iter()
            .map(|l| (l.width, l.height))
            .collect();
        assert_eq!(sizes, vec![(5, 3), (2, 1), (1, 1)]);
        // too large for the device: leading levels dropped
        let sizes: Vec<_> = mip_chain(&t, 2)
            .unwrap()
            .iter()
            .map(|l| (l.width, l.height))
            .collect();
        assert_eq!(sizes, vec![(2, 1), (1, 1)]);
    }

    #[test]
    fn bad_texture_size_is_an_error() {
        let t = Texture {
            name: "broken.png".into(),
            width: 4,
            height: 4,
            rgba8: vec![0; 10],
        };
        let e = mip_chain(&t, 16).err().map(|e| e.to_string());
        assert!(e.is_some_and(|e| e.contains("broken.png") && e.contains("expected 64")));
    }
}
