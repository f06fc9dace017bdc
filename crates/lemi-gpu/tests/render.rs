//! Reference renderer tests on whatever adapter wgpu finds (Mesa's lavapipe or llvmpipe in CI):
//! expected colours from the shading formula, texture sampling, depth order, determinism, chunking.
//! Without an adapter they fail with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.

use glam::DVec3;
use lemi_core::camera::Camera;
use lemi_core::{Material, Mesh, Scene, SceneBuilder, Texture, Vertex};
use lemi_gpu::shading::{linear_to_srgb, srgb_to_linear};
use lemi_gpu::{Frame, Gpu, GpuScene, Lighting, RenderOptions, Renderer, UploadOptions};
use lemi_testkit::gpu;

fn vertex(p: [f32; 3], uv: [f32; 2], color: [u8; 4]) -> Vertex {
    Vertex::new(p, [0.0, 0.0, 1.0], uv, color)
}

/// An axis-aligned quad facing +Z at depth `z`, spanning `[x0, x1] × [y0, y1]`; uv (0,0) top-left.
fn quad(material: u32, x0: f32, x1: f32, y0: f32, y1: f32, z: f32) -> Mesh {
    let w = [255; 4];
    Mesh {
        material,
        vertices: vec![
            vertex([x0, y1, z], [0.0, 0.0], w),
            vertex([x1, y1, z], [1.0, 0.0], w),
            vertex([x1, y0, z], [1.0, 1.0], w),
            vertex([x0, y0, z], [0.0, 1.0], w),
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

fn material(name: &str, base_color: [f32; 4], texture: Option<u32>) -> Material {
    Material {
        name: name.into(),
        base_color,
        texture,
    }
}

/// A 64×64, 90° camera at the origin looking along −Z.
fn camera() -> Camera {
    Camera::new(DVec3::ZERO, -DVec3::Z, DVec3::Y, 90.0, 64, 64).expect("valid camera")
}

fn render(gpu: &Gpu, scene: &Scene, upload: &UploadOptions) -> Frame {
    let gs = GpuScene::upload(gpu, scene, upload).expect("upload");
    let r = Renderer::new(gpu).expect("renderer");
    r.render(&gs, &camera().view(), &RenderOptions::default())
        .expect("render")
}

/// Expected sRGB bytes of a +Z-facing surface of linear albedo `albedo` under default lighting.
fn expected(albedo: [f32; 3]) -> [u8; 3] {
    Lighting::default()
        .shade(albedo, [0.0, 0.0, 1.0])
        .map(linear_to_srgb)
}

fn assert_close(got: [u8; 4], want: [u8; 3], what: &str) {
    for c in 0..3 {
        assert!(
            (got[c] as i32 - want[c] as i32).abs() <= 1,
            "{what}: got {got:?}, expected {want:?} (±1)"
        );
    }
    assert_eq!(got[3], 255, "{what}: alpha");
}

#[test]
fn coloured_quad_has_the_shaded_colour_and_depth() {
    let Some(gpu) = gpu() else { return };
    let mut b = SceneBuilder::new();
    let base = [0.8, 0.4, 0.2, 1.0];
    b.add_material(material("orange", base, None));
    // Spans x, y in [-1, 1] at distance 5: NDC ±0.2, pixels 25.6..38.4, so the pixels whose
    // centres (i + 0.5) fall inside are 26..=37.
    b.add_mesh(quad(0, -1.0, 1.0, -1.0, 1.0, -5.0));
    let f = render(&gpu, &b.finish(), &UploadOptions::default());
    eprintln!("adapter: {}", gpu.describe());
    let want = expected([0.8, 0.4, 0.2]);
    for (x, y) in [(32, 32), (26, 26), (37, 37), (26, 37)] {
        assert_close(f.pixel(x, y).unwrap_or_default(), want, "inside the quad");
    }
    for (x, y) in [(0, 0), (25, 32), (38, 32), (32, 25), (32, 38), (63, 63)] {
        assert_eq!(f.pixel(x, y), Some([0, 0, 0, 0]), "background at {x},{y}");
        assert_eq!(f.depth_at(x, y), Some(f32::INFINITY));
    }
    let d = f.depth_at(32, 32).unwrap_or(0.0);
    assert!((d - 5.0).abs() < 1e-4, "centre depth {d}");
    assert_eq!(f.covered_count(), 12 * 12);
}

#[test]
fn clear_colour_fills_the_background_only() {
    let Some(gpu) = gpu() else { return };
    let mut b = SceneBuilder::new();
    b.add_material(material("white", [1.0; 4], None));
    b.add_mesh(quad(0, -1.0, 1.0, -1.0, 1.0, -5.0));
    let gs = GpuScene::upload(&gpu, &b.finish(), &UploadOptions::default()).expect("upload");
    let opts = RenderOptions {
        clear: [10, 20, 30, 40],
        ..Default::default()
    };
    let f = Renderer::new(&gpu)
        .and_then(|r| r.render(&gs, &camera().view(), &opts))
        .expect("render");
    assert_eq!(f.pixel(0, 0), Some([10, 20, 30, 40]));
    assert_close(
        f.pixel(32, 32).unwrap_or_default(),
        expected([1.0; 3]),
        "white",
    );
}

#[test]
fn textured_quad_samples_the_texture() {
    let Some(gpu) = gpu() else { return };
    // 4x4 texture, one colour per 2x2 quadrant (sRGB bytes).
    let q = [
        [200u8, 30, 30],
        [30, 200, 30],
        [30, 30, 200],
        [220, 220, 40],
    ];
    let mut rgba = Vec::new();
    for y in 0..4 {
        for x in 0..4 {
            let c = q[(y / 2) * 2 + x / 2];
            rgba.extend_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    let mut b = SceneBuilder::new();
    let t = b.add_texture(Texture {
        name: "quadrants".into(),
        width: 4,
        height: 4,
        rgba8: rgba,
    });
    let base = [1.0, 0.5, 1.0, 1.0];
    b.add_material(material("textured", base, Some(t)));
    // At distance 1.25 the quad covers NDC ±0.8: pixels 6.4..57.6.
    b.add_mesh(quad(0, -1.0, 1.0, -1.0, 1.0, -1.25));
    let f = render(&gpu, &b.finish(), &UploadOptions::default());
    for (k, (x, y)) in [(16, 16), (47, 16), (16, 47), (47, 47)]
        .into_iter()
        .enumerate()
    {
        let albedo: [f32; 3] = std::array::from_fn(|c| srgb_to_linear(q[k][c]) * base[c]);
        assert_close(
            f.pixel(x, y).unwrap_or_default(),
            expected(albedo),
            &format!("quadrant {k}"),
        );
    }
}

#[test]
fn nearer_quad_wins_whatever_the_order() {
    let Some(gpu) = gpu() else { return };
    for near_first in [true, false] {
        let mut b = SceneBuilder::new();
        b.add_material(material("red", [1.0, 0.0, 0.0, 1.0], None));
        b.add_material(material("green", [0.0, 1.0, 0.0, 1.0], None));
        let near = quad(1, -0.5, 0.5, -0.5, 0.5, -3.0);
        let far = quad(0, -2.0, 2.0, -2.0, 2.0, -6.0);
        if near_first {
            b.add_mesh(near);
            b.add_mesh(far);
        } else {
            b.add_mesh(far);
            b.add_mesh(near);
        }
        let f = render(&gpu, &b.finish(), &UploadOptions::default());
        assert_close(
            f.pixel(32, 32).unwrap_or_default(),
            expected([0.0, 1.0, 0.0]),
            "near quad",
        );
        let d = f.depth_at(32, 32).unwrap_or(0.0);
        assert!((d - 3.0).abs() < 1e-4, "depth {d}");
        // NDC x of the far quad's edge: 2/6 → pixel 42.7; the near quad ends at 0.5/3 → 37.3.
        assert_close(
            f.pixel(40, 32).unwrap_or_default(),
            expected([1.0, 0.0, 0.0]),
            "far quad",
        );
        let d = f.depth_at(40, 32).unwrap_or(0.0);
        assert!((d - 6.0).abs() < 1e-4, "depth {d}");
    }
}

/// A bumpy, vertex-coloured height field of `n × n` cells (2n² triangles) in front of the camera,
/// split over two materials.
fn bumpy_scene(n: u32) -> Scene {
    let mut b = SceneBuilder::new();
    b.add_material(material("a", [0.9, 0.8, 0.7, 1.0], None));
    b.add_material(material("b", [0.3, 0.6, 0.9, 1.0], None));
    for m in 0..2u32 {
        let mut vertices = Vec::new();
        let mut indices = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let x = -3.0 + 6.0 * i as f32 / n as f32;
                let y = -3.0 + 6.0 * j as f32 / n as f32;
                let z = -6.0 - 0.7 * (1.3 * x + m as f32).sin() * (0.9 * y).cos();
                let c = [(i * 255 / n) as u8, (j * 255 / n) as u8, 128, 255];
                vertices.push(Vertex::new(
                    [x, y + m as f32 * 0.2, z],
                    [0.3 * x.sin(), 0.2, 1.0],
                    [0.0; 2],
                    c,
                ));
            }
        }
        for j in 0..n {
            for i in 0..n {
                let v = j * (n + 1) + i;
                indices.extend_from_slice(&[v, v + 1, v + n + 2, v, v + n + 2, v + n + 1]);
            }
        }
        b.add_mesh(Mesh {
            material: m,
            vertices,
            indices,
        });
    }
    b.finish()
}

#[test]
fn same_input_renders_bit_identically() {
    let Some(gpu) = gpu() else { return };
    let scene = bumpy_scene(24);
    let a = render(&gpu, &scene, &UploadOptions::default());
    let b = render(&gpu, &scene, &UploadOptions::default());
    assert!(a.covered_count() > 1000);
    assert!(a == b, "two renders of the same scene differ");
}

#[test]
fn chunked_upload_renders_the_same_image() {
    let Some(gpu) = gpu() else { return };
    let scene = bumpy_scene(24);
    let whole = GpuScene::upload(&gpu, &scene, &UploadOptions::default()).expect("upload");
    assert_eq!(whole.geometry.chunks().len(), 2, "one chunk per material");
    // 60 vertices per chunk: every mesh (625 vertices) must be split.
    let tiny = UploadOptions {
        max_chunk_bytes: 36 * 60,
    };
    let chunked = GpuScene::upload(&gpu, &scene, &tiny).expect("chunked upload");
    assert!(
        chunked.geometry.chunks().len() > 20,
        "chunks: {}",
        chunked.geometry.chunks().len()
    );
    assert_eq!(chunked.triangle_count(), scene.triangle_count());
    assert_eq!(whole.triangle_count(), scene.triangle_count());
    let r = Renderer::new(&gpu).expect("renderer");
    let view = camera().view();
    let opts = RenderOptions::default();
    let a = r.render(&whole, &view, &opts).expect("render");
    let b = r.render(&chunked, &view, &opts).expect("render");
    assert!(a.covered_count() > 1000);
    assert!(a == b, "chunked and unchunked renders differ");
}

#[test]
fn far_from_origin_keeps_precision() {
    let Some(gpu) = gpu() else { return };
    let o = DVec3::new(12_000.0, 300.0, -8_000.0);
    let mut b = SceneBuilder::new();
    b.add_material(material("white", [1.0; 4], None));
    let mut m = quad(0, -1.0, 1.0, -1.0, 1.0, -5.0);
    for v in &mut m.vertices {
        v.position = [
            v.position[0] + o.x as f32,
            v.position[1] + o.y as f32,
            v.position[2] + o.z as f32,
        ];
    }
    b.add_mesh(m);
    let gs = GpuScene::upload(&gpu, &b.finish(), &UploadOptions::default()).expect("upload");
    let cam = Camera::new(o, -DVec3::Z, DVec3::Y, 90.0, 64, 64).expect("camera");
    let f = Renderer::new(&gpu)
        .and_then(|r| r.render(&gs, &cam.view(), &RenderOptions::default()))
        .expect("render");
    assert_eq!(f.covered_count(), 12 * 12);
    let d = f.depth_at(32, 32).unwrap_or(0.0);
    assert!((d - 5.0).abs() < 1e-3, "centre depth {d}");
}

#[test]
fn bad_material_index_is_an_error() {
    let Some(gpu) = gpu() else { return };
    let materials = std::sync::Arc::new(
        lemi_gpu::GpuMaterials::upload(&gpu, &[Material::default()], &[]).expect("materials"),
    );
    let m = quad(3, -1.0, 1.0, -1.0, 1.0, -5.0);
    let geometry =
        lemi_gpu::GpuGeometry::upload(&gpu, [&m], &UploadOptions::default()).expect("geometry");
    let e = GpuScene::from_parts(materials, geometry)
        .err()
        .map(|e| e.to_string());
    assert!(e.is_some_and(|e| e.contains("material 3")));
}

#[test]
fn cube_face_views_hit_the_texel_of_the_face_convention() {
    let Some(gpu) = gpu() else { return };
    use lemi_core::camera::View;
    use lemi_core::Face;
    let res = 32;
    let center = DVec3::new(100.0, 20.0, -50.0);
    let r = Renderer::new(&gpu).expect("renderer");
    for (k, face) in Face::ALL.into_iter().enumerate() {
        let (i, j) = (3 + 4 * k as u32, 25 - 3 * k as u32);
        let (s, t) = Face::texel_center(i, j, res);
        // A 0.4 m square around the texel centre's point at distance 10 (a texel is 0.625 m there).
        let p = center + face.point(s, t, 10.0);
        let (a, b) = (face.right() * 0.2, face.down() * 0.2);
        let corners = [p - a - b, p + a - b, p + a + b, p - a + b];
        let vertices = corners
            .iter()
            .map(|c| vertex(c.as_vec3().to_array(), [0.0; 2], [255; 4]))
            .collect();
        let mut sb = SceneBuilder::new();
        sb.add_material(material("white", [1.0; 4], None));
        sb.add_mesh(Mesh {
            material: 0,
            vertices,
            indices: vec![0, 1, 2, 0, 2, 3],
        });
        let gs = GpuScene::upload(&gpu, &sb.finish(), &UploadOptions::default()).expect("upload");
        let view = View::cube_face(center, face, res, 0.1);
        let f = r
            .render(&gs, &view, &RenderOptions::default())
            .expect("render");
        assert_eq!(f.covered_count(), 1, "face {face}");
        let d = f.depth_at(i, j).unwrap_or(0.0);
        assert!(
            (d - 10.0).abs() < 1e-3,
            "face {face}: texel ({i}, {j}) depth {d}"
        );
    }
}

#[test]
fn oversized_image_is_an_error() {
    let Some(gpu) = gpu() else { return };
    let gs = GpuScene::upload(
        &gpu,
        &SceneBuilder::new().finish(),
        &UploadOptions::default(),
    )
    .expect("upload");
    let max = gpu.limits().max_texture_dimension_2d;
    let cam = Camera::new(DVec3::ZERO, -DVec3::Z, DVec3::Y, 60.0, max + 1, 4).expect("camera");
    let e = Renderer::new(&gpu)
        .and_then(|r| r.render(&gs, &cam.view(), &RenderOptions::default()))
        .err()
        .map(|e| e.to_string());
    assert!(e.is_some_and(|e| e.contains("image size")));
}

/// Geometry is drawn without the shader's alpha test when the cutoff is 0 (the default, which no
/// alpha is below), so the rasterizer may test depth before shading: the picture is the one the
/// alpha-tested pipeline draws, texel for texel, on a scene of interpenetrating surfaces (depth
/// order decided per pixel) whose texture alpha is never 0; and a positive cutoff still discards.
#[test]
fn geometry_without_the_alpha_test_draws_what_the_alpha_test_draws() {
    let Some(gpu) = gpu() else { return };
    let mut scene = bumpy_scene(24);
    // a texture whose alpha steps through 1..=255 (never 0), on the second surface
    let rgba: Vec<u8> = (0..64u32)
        .flat_map(|i| [200, (4 * i) as u8, 90, (1 + 4 * i).min(255) as u8])
        .collect();
    scene.textures.push(Texture {
        name: "alpha steps".into(),
        width: 8,
        height: 8,
        rgba8: rgba,
    });
    scene.materials[1].texture = Some(0);
    let gs = GpuScene::upload(&gpu, &scene, &UploadOptions::default()).expect("upload");
    let r = Renderer::new(&gpu).expect("renderer");
    let draw = |cutoff: f32| {
        let options = RenderOptions {
            alpha_cutoff: cutoff,
            ..Default::default()
        };
        r.render(&gs, &camera().view(), &options).expect("render")
    };
    // cutoff 0: the pipeline without the test; the smallest positive cutoff: the alpha-tested
    // one, which discards nothing here (every alpha is at least 1/255)
    let (opaque, masked) = (draw(0.0), draw(f32::MIN_POSITIVE));
    assert!(opaque.covered_count() > 1000);
    assert!(
        opaque == masked,
        "the two pipelines draw different pictures"
    );
    // half the texture's alpha is below 0.5: those fragments are discarded
    let cut = draw(0.5);
    assert!(
        cut.covered_count() < opaque.covered_count(),
        "a cutoff of 0.5 discards: {} of {} pixels covered",
        cut.covered_count(),
        opaque.covered_count()
    );
}

/// Untextured materials are drawn by pipelines that take the white texel's sample as the constant
/// 1 instead of fetching it (`TEXTURED` off): the picture is, pixel for pixel and depth for
/// depth, the one drawn when the same materials sample an explicit 1×1 white texture through the
/// textured pipelines, with and without the alpha test, and a textured material drawn after an
/// untextured one in the same pass still shows its texture.
#[test]
fn untextured_materials_draw_what_sampling_a_white_texture_draws() {
    let Some(gpu) = gpu() else { return };
    let untextured = bumpy_scene(24);
    let mut textured = untextured.clone();
    textured.textures.push(Texture {
        name: "white".into(),
        width: 1,
        height: 1,
        rgba8: vec![255; 4],
    });
    for m in &mut textured.materials {
        m.texture = Some(0);
    }
    let r = Renderer::new(&gpu).expect("renderer");
    for cutoff in [0.0, 0.5] {
        let options = RenderOptions {
            alpha_cutoff: cutoff,
            ..Default::default()
        };
        let draw = |scene: &Scene| {
            let gs = GpuScene::upload(&gpu, scene, &UploadOptions::default()).expect("upload");
            r.render(&gs, &camera().view(), &options).expect("render")
        };
        let (a, b) = (draw(&untextured), draw(&textured));
        assert!(a.covered_count() > 1000);
        assert!(
            a == b,
            "cutoff {cutoff}: untextured and white-textured materials draw different pictures"
        );
    }
    // the second material textured red, the first untextured: the pipeline follows the material
    let mut mixed = untextured;
    mixed.textures.push(Texture {
        name: "red".into(),
        width: 1,
        height: 1,
        rgba8: vec![255, 0, 0, 255],
    });
    mixed.materials[1].texture = Some(0);
    let gs = GpuScene::upload(&gpu, &mixed, &UploadOptions::default()).expect("upload");
    let f = r
        .render(&gs, &camera().view(), &RenderOptions::default())
        .expect("render");
    let (mut red, mut other) = (0, 0);
    for y in 0..64 {
        for x in 0..64 {
            match f.pixel(x, y) {
                Some([_, 0, 0, 255]) => red += 1,
                Some([_, _, _, 255]) => other += 1,
                _ => {}
            }
        }
    }
    assert!(
        red > 100 && other > 100,
        "{red} pixels of the red-textured material, {other} of the untextured one"
    );
}
