//! The TR's object impostor figure reproduced (TR-186-2-02-04 Fig. 11): the Stanford dragon,
//! scaled so that its longest side is 20 m, seen from a 10 m cubic view cell at 42, 59, 96, 142,
//! 209 and 563 m (from the cell's border to the dragon's near side). For each distance: the
//! object placement's layer count against the TR's (120, 60, 30, 15, 7, 1), the bake
//! (`lemi bake-object`'s pipeline: resolution from Schaufler's rule, α = the edge pixel of the
//! output view), the certificate (`lemi eval` on the bundle: every corner, face and edge midpoint,
//! centre and random viewpoints of the cell, each looking at the dragon), a
//! reference | impostor | difference image from a corner of the cell's near face, and the frame
//! time of the impostor against the dragon's geometry (GPU timestamp medians, the same views).
//!
//! ```text
//! cargo run --release -p lemi-eval --example dragon_object -- DRAGON.ply.gz OUT_DIR
//!     [--output-width 1024] [--distances 42,59,96,142,209,563] [--reps 15] [--viewpoints 4]
//! ```
//!
//! Writes `OUT_DIR/d<D>/bundle` (the object bundle, baked from the scaled dragon: `lemi eval`
//! on it needs the same scaling, so the certificate is computed here), `OUT_DIR/d<D>/corner.png`,
//! and `OUT_DIR/dragon.md` (the table) and `OUT_DIR/dragon.json`.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use lemi_bake::object_bake::{bake_object, object_bake_params, write_object_bundle};
use lemi_core::bundle::{Bundle, SceneRef};
use lemi_core::classify::TriRef;
use lemi_core::object_cell::{object_bounds, ObjectSetup, ObjectViewCell};
use lemi_core::placement::{alpha_from_output_view, PixelChoice};
use lemi_core::{Aabb, Scene};
use lemi_eval::{camera, evaluate_bundle, layered_crack_tolerance, side_by_side, EvalOptions};
use lemi_gpu::{
    BackendChoice, Gpu, GpuMaterials, GpuScene, ImpostorCell, ImpostorRenderer, RenderOptions,
    Renderer, UploadOptions,
};
use serde_json::json;

/// The TR's Fig. 11 distances (m) and layer counts.
const TR: [(f64, usize); 6] = [
    (42.0, 120),
    (59.0, 60),
    (96.0, 30),
    (142.0, 15),
    (209.0, 7),
    (563.0, 1),
];
const CELL: f64 = 10.0;
const DRAGON_SIZE: f64 = 20.0;
const FOV_X: f64 = 60.0;

struct Args {
    dragon: PathBuf,
    out: PathBuf,
    width: u32,
    distances: Vec<f64>,
    reps: usize,
    viewpoints: usize,
}

fn parse_args() -> Result<Args> {
    let mut it = std::env::args().skip(1);
    let mut pos = Vec::new();
    let mut a = Args {
        dragon: PathBuf::new(),
        out: PathBuf::new(),
        width: 1024,
        distances: TR.iter().map(|t| t.0).collect(),
        reps: 15,
        viewpoints: 4,
    };
    while let Some(x) = it.next() {
        let mut value = |name: &str| it.next().with_context(|| format!("{name} needs a value"));
        match x.as_str() {
            "--output-width" => a.width = value("--output-width")?.parse()?,
            "--distances" => {
                a.distances = value("--distances")?
                    .split(',')
                    .map(|d| d.trim().parse::<f64>())
                    .collect::<Result<_, _>>()?
            }
            "--reps" => a.reps = value("--reps")?.parse()?,
            "--viewpoints" => a.viewpoints = value("--viewpoints")?.parse()?,
            _ => pos.push(x),
        }
    }
    let [dragon, out] = &pos[..] else {
        bail!("usage: dragon_object DRAGON.ply.gz OUT_DIR [--output-width W] [--distances ..] [--reps N] [--viewpoints N]");
    };
    a.dragon = dragon.into();
    a.out = out.into();
    Ok(a)
}

/// The dragon scaled about its centre so its longest side is [`DRAGON_SIZE`], then moved so its
/// box is centred on the origin.
fn scaled(mut scene: Scene) -> Scene {
    let b = scene.bounds;
    let k = DRAGON_SIZE / b.size().max_element();
    let c = b.center();
    let mut bounds = Aabb::EMPTY;
    for mesh in &mut scene.meshes {
        for v in &mut mesh.vertices {
            let p = (DVec3::from_array(v.position.map(f64::from)) - c) * k;
            bounds.grow(p);
            v.position = p.as_vec3().to_array();
        }
    }
    scene.bounds = bounds;
    scene
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() -> Result<()> {
    let args = parse_args()?;
    std::fs::create_dir_all(&args.out)?;
    let gpu = Gpu::new(BackendChoice::Auto)?;
    println!(
        "adapter {}; timestamps {}",
        gpu.describe(),
        gpu.has_timestamps()
    );
    let t = Instant::now();
    let scene = scaled(lemi_scene::load(
        &[args.dragon.to_string_lossy().into_owned()],
        &lemi_scene::LoadOptions::default(),
    )?);
    let size = scene.bounds.size();
    println!(
        "dragon: {} triangles, {:.2} × {:.2} × {:.2} m, loaded in {:.1} s",
        scene.triangle_count(),
        size.x,
        size.y,
        size.z,
        t.elapsed().as_secs_f64()
    );
    let object: Vec<TriRef> = scene
        .meshes
        .iter()
        .enumerate()
        .flat_map(|(m, mesh)| {
            (0..mesh.triangle_count() as u32).map(move |tri| TriRef {
                mesh: m as u32,
                tri,
            })
        })
        .collect();
    let bounds = object_bounds(&scene, &object);
    let alpha = alpha_from_output_view(FOV_X.to_radians(), args.width, PixelChoice::Edge)?;
    let (w, h) = (args.width, args.width * 9 / 16);
    let materials = Arc::new(GpuMaterials::upload(
        &gpu,
        &scene.materials,
        &scene.textures,
    )?);
    let full = GpuScene::upload(&gpu, &scene, &UploadOptions::default())?;
    let reference = Renderer::new(&gpu)?;
    let impostors = ImpostorRenderer::new(&gpu)?;
    let options = RenderOptions::default();
    let mut rows = Vec::new();
    let mut table = String::from(
        "| distance | layers (TR) | res | quads | cell file | bake | views | max px | p99 px | cracks | mean FLIP | impostor GPU ms | geometry GPU ms | ratio |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for &d in &args.distances {
        // the cell: a 10 m cube in front of the dragon's side (+Z), centred on it across
        let near = bounds.max.z + d;
        let c = bounds.center();
        let cell = ObjectViewCell::Box {
            min: DVec3::new(c.x - CELL / 2.0, c.y - CELL / 2.0, near),
            max: DVec3::new(c.x + CELL / 2.0, c.y + CELL / 2.0, near + CELL),
        };
        let setup = ObjectSetup::new(cell, bounds, None, alpha)?;
        let placement = setup.place()?;
        let params = object_bake_params(
            &setup,
            placement.layers.len(),
            (Some(FOV_X), Some(args.width)),
            Default::default(),
        );
        let t = Instant::now();
        let mut baked = bake_object(&gpu, &scene, &object, &setup, params.clone(), |_| {})?;
        let bake_s = t.elapsed().as_secs_f64();
        let dir = args.out.join(format!("d{d}"));
        let bundle_dir = dir.join("bundle");
        let scene_ref = SceneRef {
            sources: vec![format!(
                "{} scaled to {DRAGON_SIZE} m",
                args.dragon.display()
            )],
            up: "y".into(),
            fingerprint: "scaled-dragon".into(),
            triangles: scene.triangle_count(),
        };
        let (_, bytes) = write_object_bundle(&bundle_dir, scene_ref, &params, &mut baked)?;
        let bundle = Bundle::open(&bundle_dir)?;
        let t = Instant::now();
        let run = evaluate_bundle(
            &gpu,
            &bundle,
            &scene,
            &EvalOptions {
                random_viewpoints: args.viewpoints,
                clear: [0, 0, 0, 0],
                ..Default::default()
            },
            |_, _, _| {},
        )?;
        let eval_s = t.elapsed().as_secs_f64();
        let s = &run.result.summary;
        // the image from a corner of the near face, and the frame times from its 4 corners
        let file = bundle.cell(bundle.cell_ids()[0])?;
        let gpu_cell = ImpostorCell::upload_file(&gpu, materials.clone(), &scene, &file)?;
        let corners = [
            DVec3::new(c.x - CELL / 2.0, c.y - CELL / 2.0, near),
            DVec3::new(c.x + CELL / 2.0, c.y - CELL / 2.0, near),
            DVec3::new(c.x + CELL / 2.0, c.y + CELL / 2.0, near),
            DVec3::new(c.x - CELL / 2.0, c.y + CELL / 2.0, near),
        ];
        let (mut imp_ms, mut geo_ms) = (Vec::new(), Vec::new());
        for (k, eye) in corners.iter().enumerate() {
            let view = camera(*eye, (c - *eye).normalize(), FOV_X, w, h)?.view();
            if k == 0 {
                let r = reference.render(&full, &view, &options)?;
                let i = impostors.render(&gpu_cell, &view, &options)?;
                let vc = setup.canonical_cell();
                let tol = layered_crack_tolerance(&r, &file, &vc);
                side_by_side(&r, &i, &tol)?
                    .image
                    .save(dir.join("corner.png"))?;
            }
            for _ in 0..args.reps {
                impostors.render_no_readback(&gpu_cell, &view, &options)?;
                if let Some(ms) = impostors.last_gpu_ms() {
                    imp_ms.push(ms);
                }
                reference.render_no_readback(&full, &view, &options)?;
                if let Some(ms) = reference.last_gpu_ms() {
                    geo_ms.push(ms);
                }
            }
        }
        let (imp, geo) = (median(imp_ms), median(geo_ms));
        let tr = TR.iter().find(|t| (t.0 - d).abs() < 0.5).map(|t| t.1);
        let layers = placement.layers.len();
        println!(
            "{d} m: {layers} layers (TR {}), res {}, {} quads, {:.0} KB, bake {bake_s:.1} s; \
             {} views: max {:.2} px, p99 {:.2} px, {} cracks, FLIP {:.3} (eval {eval_s:.0} s); \
             GPU impostor {imp:.2} ms, geometry {geo:.2} ms ({:.3}×)",
            tr.map_or("-".into(), |t| t.to_string()),
            setup.params.res,
            file.header.quads.len(),
            bytes as f64 / 1e3,
            s.views,
            s.max_error_px,
            s.p99_error_px,
            s.crack_pixels,
            s.mean_flip,
            imp / geo
        );
        table.push_str(&format!(
            "| {d} m | {layers} ({}) | {}² | {} | {:.0} KB | {bake_s:.1} s | {} | {:.2} | {:.2} | {} | {:.3} | {imp:.2} | {geo:.2} | {:.3} |\n",
            tr.map_or("-".into(), |t| t.to_string()),
            setup.params.res,
            file.header.quads.len(),
            bytes as f64 / 1e3,
            s.views,
            s.max_error_px,
            s.p99_error_px,
            s.crack_pixels,
            s.mean_flip,
            imp / geo
        ));
        rows.push(json!({
            "distance": d,
            "layers": layers,
            "tr_layers": tr,
            "resolution": setup.params.res,
            "quads": file.header.quads.len(),
            "cell_bytes": bytes,
            "bake_seconds": bake_s,
            "views": s.views,
            "max_error_px": s.max_error_px,
            "p99_error_px": s.p99_error_px,
            "crack_pixels": s.crack_pixels,
            "mean_flip": s.mean_flip,
            "impostor_gpu_ms": imp,
            "geometry_gpu_ms": geo,
        }));
    }
    std::fs::write(args.out.join("dragon.md"), &table)?;
    std::fs::write(
        args.out.join("dragon.json"),
        serde_json::to_string_pretty(&json!({
            "output": format!("{w}x{h}, {FOV_X}° horizontal"),
            "alpha_deg": alpha.to_degrees(),
            "rows": rows,
        }))?,
    )?;
    println!("{table}");
    Ok(())
}
