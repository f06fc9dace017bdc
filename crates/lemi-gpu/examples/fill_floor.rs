//! The floor of a far-field frame on this adapter: the GPU time of one opaque textured pass over
//! every pixel of the view, drawn by the impostor renderer's quad pipeline as one quad, and as the
//! same square cut into `n × n` quads (what a bake's micro-textures make of it), without and with
//! the alpha test; and the same with a second, hidden layer behind (what depth rejection costs),
//! with three more out of view, and hidden behind a wall of near geometry.
//!
//! ```text
//! cargo run --release -p lemi-gpu --example fill_floor -- [--size WxH] [--reps N]
//!     [--texel-filter footprint|nearest]
//! ```
//!
//! A layered far field cannot cost less than the first line (one texel fetch and store per
//! pixel); the rest shows what cutting it into quads and stacking layers add. The texture's
//! texels span about 1.2 pixels, so the default footprint filter takes one bilinear fetch a
//! pixel; `--texel-filter nearest` gives the nearest-texel pipeline, the one a runtime frame
//! takes for draw calls whose texels all span two pixels or more (the cells here carry no
//! `SeenFrom`, so the renderer cannot choose it by itself).

use std::sync::Arc;

use glam::DVec3;
use lemi_core::bundle::Quad;
use lemi_core::camera::Camera;
use lemi_core::compress::MacroTexture;
use lemi_core::{Face, Material, Mesh, SceneBuilder, Vertex};
use lemi_gpu::{GpuMaterials, ImpostorCell, ImpostorRenderer, RenderOptions, TexelFilter};

type Error = Box<dyn std::error::Error>;

fn main() -> Result<(), Error> {
    let (mut width, mut height, mut reps) = (1280u32, 720u32, 20usize);
    let mut filter = TexelFilter::Footprint;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--size" => {
                let v = args.next().ok_or("--size needs WxH")?;
                (width, height) = lemi_core::camera::parse_size(&v)?;
            }
            "--reps" => reps = args.next().ok_or("--reps needs N")?.parse()?,
            "--texel-filter" => {
                filter = match args.next().as_deref() {
                    Some("nearest") => TexelFilter::Nearest,
                    Some("footprint") => TexelFilter::Footprint,
                    v => return Err(format!("--texel-filter {v:?}: nearest or footprint").into()),
                }
            }
            _ => return Err(format!("unknown argument {a}").into()),
        }
    }
    let Some(gpu) = lemi_testkit::gpu() else {
        return Ok(());
    };
    // A scene of one triangle far behind the camera (mesh 0, the near geometry of the first
    // cases), and a wall across the whole view 40 m ahead (mesh 1, the near geometry of the last).
    let mut b = SceneBuilder::new();
    b.add_material(Material::default());
    let v = |p: [f32; 3]| Vertex::new(p, [0.0, 0.0, 1.0], [0.0, 0.0], [255; 4]);
    b.add_mesh(Mesh {
        material: 0,
        vertices: vec![v([0.0, 0.0, 5.0]), v([1.0, 0.0, 5.0]), v([0.0, 1.0, 5.0])],
        indices: vec![0, 1, 2],
    });
    let wall = |x: f32, y: f32| v([x, y, -40.0]);
    b.add_mesh(Mesh {
        material: 0,
        vertices: vec![
            wall(-60.0, -40.0),
            wall(60.0, -40.0),
            wall(60.0, 40.0),
            wall(-60.0, 40.0),
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
    });
    let scene = b.finish();
    let materials = Arc::new(GpuMaterials::upload(
        &gpu,
        &scene.materials,
        &scene.textures,
    )?);
    let mut renderer = ImpostorRenderer::new(&gpu)?;
    renderer.set_texel_filter(filter);
    let fov = 60.0;
    let view = Camera::new(DVec3::ZERO, -DVec3::Z, DVec3::Y, fov, width, height)?.view();
    // A square at depth z covering the whole view, with a 1024² texture.
    let res = 1024u32;
    let (half_w, aspect) = ((fov.to_radians() / 2.0).tan(), height as f64 / width as f64);
    let square = |z: f64, n: u32, hole_every: u32| -> (Vec<Quad>, MacroTexture) {
        let s = 1.05 * half_w.max(half_w * aspect) * z; // half side, a little beyond the view
        let mut rgba = Vec::with_capacity((4 * res * res) as usize);
        for y in 0..res {
            for x in 0..res {
                let clear = hole_every > 0 && (x + y) % hole_every == 0;
                rgba.extend_from_slice(&[(x % 256) as u8, (y % 256) as u8, 90, 255 * !clear as u8]);
            }
        }
        let step = res / n;
        let mut quads = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (x0, y0) = (i * step, j * step);
                let corner = |tx: u32, ty: u32| {
                    let u = tx as f64 / res as f64 * 2.0 - 1.0;
                    let v = 1.0 - ty as f64 / res as f64 * 2.0;
                    [(u * s) as f32, (v * s) as f32, -z as f32]
                };
                quads.push(Quad {
                    fringe: false,
                    face: Face::NegZ,
                    layer: 0,
                    texels: [x0 as u16, y0 as u16, (x0 + step) as u16, (y0 + step) as u16],
                    corners: [
                        corner(x0, y0),
                        corner(x0 + step, y0),
                        corner(x0 + step, y0 + step),
                        corner(x0, y0 + step),
                    ],
                    macro_index: 0,
                    rect: [x0, y0, step, step],
                    rotated: false,
                });
            }
        }
        (
            quads,
            MacroTexture {
                width: res,
                height: res,
                rgba,
            },
        )
    };
    let options = RenderOptions::default();
    println!(
        "{}: {width}x{height}, {filter:?} texels, GPU medians over {reps} frames (render_impostors_only, timestamps: passes only)",
        gpu.describe()
    );
    for (label, n, holes, layers) in [
        ("1 quad, opaque", 1, 0, 1),
        ("16x16 quads, opaque", 16, 0, 1),
        ("64x64 quads, opaque", 64, 0, 1),
        ("128x128 quads, opaque", 128, 0, 1),
        ("64x64 quads, alpha-tested", 64, 97, 1),
        ("64x64 quads, opaque, + a hidden layer behind", 64, 0, 2),
        ("64x64 quads, opaque, + 3 layers out of view", 64, 0, 4),
    ] {
        let (mut quads, tex) = square(50.0, n, holes);
        let mut macros = vec![tex];
        if layers == 2 {
            let (mut behind, tex) = square(80.0, n, holes);
            for q in &mut behind {
                q.macro_index = 1;
            }
            quads.extend(behind);
            macros.push(tex);
        }
        if layers == 4 {
            // the same square turned to the other three horizontal directions: out of view
            let (front, tex) = square(50.0, n, holes);
            macros.push(tex);
            for turn in 1..4 {
                let a = turn as f32 * std::f32::consts::FRAC_PI_2;
                let (sin, cos) = a.sin_cos();
                quads.extend(front.iter().map(|q| {
                    Quad {
                        corners: q
                            .corners
                            .map(|[x, y, z]| [cos * x + sin * z, y, -sin * x + cos * z]),
                        macro_index: 1,
                        ..*q
                    }
                }));
            }
        }
        let cell = ImpostorCell::upload(&gpu, materials.clone(), &scene, &[], &quads, &macros)?;
        let mut ms = Vec::with_capacity(reps);
        for _ in 0..reps + 2 {
            renderer.render_impostors_only(&cell, &view, &options)?;
            ms.push(renderer.last_gpu_ms().unwrap_or(f64::NAN));
        }
        ms.drain(..2); // warm-up
        ms.sort_by(f64::total_cmp);
        println!(
            "{label:>46}: {:>7} quads, {:.2} ms",
            cell.quad_count(),
            ms[ms.len() / 2]
        );
    }
    // The near geometry hiding the far field: a wall across the view in front of 64×64 quads,
    // drawn as a frame of the runtime (near geometry, then quads), against the wall alone.
    let (quads, tex) = square(50.0, 64, 0);
    let cell = ImpostorCell::upload(
        &gpu,
        materials.clone(),
        &scene,
        &[[1, 0], [1, 1]],
        &quads,
        &[tex],
    )?;
    let wall_only = ImpostorCell::upload(&gpu, materials, &scene, &[[1, 0], [1, 1]], &[], &[])?;
    for (label, c) in [
        ("a wall of near geometry alone", &wall_only),
        ("... with 64x64 quads hidden behind it", &cell),
    ] {
        let mut ms = Vec::with_capacity(reps);
        for _ in 0..reps + 2 {
            renderer.render(c, &view, &options)?;
            ms.push(renderer.last_gpu_ms().unwrap_or(f64::NAN));
        }
        ms.drain(..2);
        ms.sort_by(f64::total_cmp);
        println!(
            "{label:>46}: {:>7} quads, {:.2} ms",
            c.quad_count(),
            ms[ms.len() / 2]
        );
    }
    Ok(())
}
