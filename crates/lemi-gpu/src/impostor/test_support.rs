//! What the GPU unit tests of the impostor module share: a one-triangle scene in front of a
//! camera at the origin looking along −Z, quads facing it and patterned macro-textures. The tests
//! run on whatever adapter wgpu finds; without one they fail with the install hint, unless
//! `LEMI_SKIP_GPU_TESTS=1`.

use lemi_core::bundle::Quad;
use lemi_core::camera::{Camera, View};
use lemi_core::compress::MacroTexture;
use lemi_core::{Face, Material, Mesh, Scene, SceneBuilder, Vertex};

use crate::Gpu;

pub(crate) fn gpu() -> Option<Gpu> {
    Gpu::for_tests()
}

/// A quad facing a camera at the origin looking along −Z, at depth `z`.
pub(crate) fn quad(macro_index: u32, rect: [u32; 4], [x0, x1, y0, y1, z]: [f32; 5]) -> Quad {
    Quad {
        fringe: false,
        face: Face::NegZ,
        layer: 0,
        texels: [0, 0, rect[2] as u16, rect[3] as u16],
        corners: [[x0, y1, z], [x1, y1, z], [x1, y0, z], [x0, y0, z]],
        macro_index,
        rect,
        rotated: false,
    }
}

/// A `w × h` macro-texture of distinct opaque colours (seeded by `k`), every 7th texel clear.
pub(crate) fn pattern(w: u32, h: u32, k: u32) -> MacroTexture {
    let mut rgba = Vec::with_capacity((4 * w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let a = if (i + k) % 7 == 0 { 0 } else { 255 };
            rgba.extend_from_slice(&[
                (x * 37 + k * 11) as u8,
                (y * 23 + k * 5) as u8,
                (i * 13 + k) as u8,
                a,
            ]);
        }
    }
    MacroTexture {
        width: w,
        height: h,
        rgba,
    }
}

pub(crate) fn scene() -> Scene {
    let mut b = SceneBuilder::new();
    b.add_material(Material::default());
    let v = |p: [f32; 3]| Vertex::new(p, [0.0, 0.0, 1.0], [0.0, 0.0], [200, 180, 90, 255]);
    b.add_mesh(Mesh {
        material: 0,
        vertices: vec![
            v([-0.5, -0.5, -2.0]),
            v([0.5, -0.5, -2.0]),
            v([0.0, 0.4, -2.0]),
        ],
        indices: vec![0, 1, 2],
    });
    b.finish()
}

/// A 64×64 view from the origin along −Z with a 90° field of view.
pub(crate) fn view() -> View {
    Camera::new(
        glam::DVec3::ZERO,
        -glam::DVec3::Z,
        glam::DVec3::Y,
        90.0,
        64,
        64,
    )
    .expect("camera")
    .view()
}
