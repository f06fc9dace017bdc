//! The shading every lemi pipeline shares: one WGSL module ([`SHADING_WGSL`]), its uniform layouts,
//! the vertex layout of [`lemi_core::Vertex`], and a CPU mirror of the formula for tests and
//! metrics.
//!
//! Formula (Lambert's cosine law, J. H. Lambert, *Photometria*, 1760, made two-sided with `|n·l|`
//! instead of `max(n·l, 0)` because scenes are polygon soups without consistent winding):
//! `colour = base_colour × texture × vertex colour × (ambient + sun · |n · l|)`, all in linear RGB;
//! textures are decoded from sRGB by the texture format, the output is encoded to sRGB by the
//! render target format (IEC 61966-2-1 transfer function).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use lemi_core::camera::View;

use crate::GpuError;

/// The shared shading module: structs, bindings (group 0 globals, group 1 material) and the
/// functions `transform_vertex`, `surface_albedo`, `shade`. Pipelines append their entry points.
pub const SHADING_WGSL: &str = include_str!("shading.wgsl");

/// The pipeline constants of [`SHADING_WGSL`] for a material with a texture of its own or without
/// one (`TEXTURED`: without, the white texel's sample is the constant 1 and no fetch is made), for
/// the fragment stage of every pipeline that shades geometry with it.
pub(crate) fn material_constants(textured: bool) -> [(&'static str, f64); 1] {
    [("TEXTURED", f64::from(u8::from(textured)))]
}

/// One directional light plus ambient, fixed and deterministic.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Direction *towards* the light (world space, need not be unit length).
    pub direction: [f32; 3],
    /// Linear RGB of the directional light.
    pub sun: [f32; 3],
    /// Linear RGB of the ambient term.
    pub ambient: [f32; 3],
}

impl Default for Lighting {
    /// Light from above and to the side, `(1, 3, 2)` normalised (elevation ≈ 53°), sun 0.7 and
    /// ambient 0.3 grey, so a white surface facing the light is exactly white.
    fn default() -> Self {
        Lighting {
            direction: [1.0, 3.0, 2.0],
            sun: [0.7; 3],
            ambient: [0.3; 3],
        }
    }
}

impl Lighting {
    /// The unit light direction, or an error for a zero or non-finite one.
    pub fn unit_direction(&self) -> Result<Vec3, GpuError> {
        let d = Vec3::from(self.direction);
        if !d.is_finite() || d.length_squared() == 0.0 {
            return Err(GpuError::Invalid(format!(
                "light direction must be finite and non-zero, got {:?}",
                self.direction
            )));
        }
        Ok(d.normalize())
    }

    /// The CPU mirror of WGSL `shade`: `albedo × (ambient + sun · |n·l|)` in linear RGB.
    pub fn shade(&self, albedo: [f32; 3], normal: [f32; 3]) -> [f32; 3] {
        let n = Vec3::from(normal);
        let ndl = match (self.unit_direction(), n.length_squared() > 1e-20) {
            (Ok(l), true) => n.normalize().dot(l).abs(),
            _ => 0.0,
        };
        std::array::from_fn(|i| albedo[i] * (self.ambient[i] + self.sun[i] * ndl))
    }
}

/// sRGB-encoded byte → linear value (IEC 61966-2-1).
pub fn srgb_to_linear(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear value → sRGB-encoded byte (IEC 61966-2-1), clamped to [0, 1] and rounded.
pub fn linear_to_srgb(v: f32) -> u8 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let s = if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5).floor() as u8
}

/// The group-0 uniform of [`SHADING_WGSL`] (`Globals`), 176 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct ShadingGlobals {
    pub clip_from_rel: [[f32; 4]; 4],
    pub eye_hi: [f32; 4],
    pub eye_lo: [f32; 4],
    pub depth_axis: [f32; 4],
    pub light_dir: [f32; 4],
    pub light_color: [f32; 4],
    pub ambient: [f32; 4],
    /// x: alpha cutoff.
    pub params: [f32; 4],
}

impl ShadingGlobals {
    /// Globals for drawing `view` under `lighting`; fragments whose albedo alpha is below
    /// `alpha_cutoff` are discarded (0 keeps everything).
    pub fn new(view: &View, lighting: &Lighting, alpha_cutoff: f32) -> Result<Self, GpuError> {
        if !alpha_cutoff.is_finite() {
            return Err(GpuError::Invalid(format!(
                "alpha cutoff must be finite, got {alpha_cutoff}"
            )));
        }
        let l = lighting.unit_direction()?;
        let g = view.gpu();
        if !g.clip_from_rel.is_finite() || !g.eye_hi.is_finite() {
            return Err(GpuError::Invalid(
                "the view matrix or projection is not finite or not invertible".into(),
            ));
        }
        Ok(ShadingGlobals {
            clip_from_rel: g.clip_from_rel.to_cols_array_2d(),
            eye_hi: g.eye_hi.extend(0.0).to_array(),
            eye_lo: g.eye_lo.extend(0.0).to_array(),
            depth_axis: g.depth_axis.extend(0.0).to_array(),
            light_dir: l.extend(0.0).to_array(),
            light_color: Vec3::from(lighting.sun).extend(1.0).to_array(),
            ambient: Vec3::from(lighting.ambient).extend(1.0).to_array(),
            params: [alpha_cutoff, 0.0, 0.0, 0.0],
        })
    }
}

/// The group-1 uniform of [`SHADING_WGSL`] (`MaterialUniform`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct MaterialUniform {
    pub base_color: [f32; 4],
}

/// Vertex attributes of [`lemi_core::Vertex`]: locations 0..=3 = position, normal, uv, colour.
pub const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 4] = wgpu::vertex_attr_array![
    0 => Float32x3,
    1 => Float32x3,
    2 => Float32x2,
    3 => Unorm8x4,
];

/// The vertex buffer layout of [`lemi_core::Vertex`] (36-byte stride).
pub fn vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<lemi_core::Vertex>() as wgpu::BufferAddress,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &VERTEX_ATTRIBUTES,
    }
}

/// The bind group layouts of the shading module.
pub(crate) struct Layouts {
    pub globals: wgpu::BindGroupLayout,
    pub material: wgpu::BindGroupLayout,
}

impl Layouts {
    pub fn new(device: &wgpu::Device) -> Layouts {
        let vf = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let globals = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("lemi globals"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: vf,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: wgpu::BufferSize::new(
                        std::mem::size_of::<ShadingGlobals>() as u64
                    ),
                },
                count: None,
            }],
        });
        let material = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("lemi material"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(
                            std::mem::size_of::<MaterialUniform>() as u64,
                        ),
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        Layouts { globals, material }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips_every_byte() {
        for b in 0..=255u8 {
            assert_eq!(linear_to_srgb(srgb_to_linear(b)), b);
        }
        assert_eq!(linear_to_srgb(0.5), 188);
        assert!((srgb_to_linear(128) - 0.215_861).abs() < 1e-5);
    }

    #[test]
    fn default_light_makes_a_lit_white_surface_white() {
        let l = Lighting::default();
        let n = l.unit_direction().unwrap_or(Vec3::Y).to_array();
        assert_eq!(l.shade([1.0; 3], n).map(|c| (c * 1e5).round()), [1e5; 3]);
        // two-sided: the back face is lit the same
        let back = (-Vec3::from(n)).to_array();
        assert_eq!(l.shade([0.5; 3], back), l.shade([0.5; 3], n));
        // perpendicular to the light: ambient only
        let d = Vec3::from(l.direction);
        let perp = d.any_orthogonal_vector().to_array();
        let s = l.shade([1.0; 3], perp);
        assert!((s[0] - 0.3).abs() < 1e-6, "{s:?}");
    }

    #[test]
    fn globals_layout_is_176_bytes() {
        assert_eq!(std::mem::size_of::<ShadingGlobals>(), 176);
        assert_eq!(std::mem::size_of::<lemi_core::Vertex>(), 36);
    }
}
