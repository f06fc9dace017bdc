//! Timings of the `dynamic` strategy (one billboard per far object, regenerated when Schaufler's
//! validity angles exceed a pixel) on a procedural city, a measurement rather than a test:
//! `cargo run --release -p lemi-strategy --example dynamic_city_walk`. Two 10 m cells of
//! `builtin:city:100k:1` are baked at 256²; then the viewer walks along the avenue at 640×480,
//! 30 frames per second: 45 frames at 1.4 m/s, then 30 frames at 10 m/s into the next cell.

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use lemi_core::bundle::{Bundle, LayerTarget};
use lemi_core::camera::Camera;
use lemi_gpu::{GpuMaterials, GpuScene, RenderOptions, Renderer, UploadOptions};
use lemi_strategy::dynamic::{DynamicOptions, DynamicStrategy};
use lemi_strategy::{FrameRequest, Strategy, StrategyContext};
use lemi_testkit::EYE;

const FOV: f64 = 60.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Some(gpu) = lemi_testkit::gpu() else {
        return Ok(());
    };
    let gpu = Arc::new(gpu);
    let scene = lemi_scene::builtin::build("city:100k:1")?;
    let dir = tempfile::tempdir()?;
    let bundle = dir.path().join("bundle");
    let params = lemi_testkit::small_params(256, LayerTarget::NearField(20.0));
    let t = Instant::now();
    let grid = lemi_testkit::row_of_cells(2);
    lemi_testkit::bake_grid(&gpu, &scene, &params, &grid, &bundle, "city-100k-1");
    println!(
        "baked {} triangles in {:.1} s",
        scene.triangle_count(),
        t.elapsed().as_secs_f64()
    );
    let materials = Arc::new(GpuMaterials::upload(
        &gpu,
        &scene.materials,
        &scene.textures,
    )?);
    let scene = Arc::new(scene);
    let ctx = StrategyContext {
        gpu: gpu.clone(),
        bundle: Bundle::open(&bundle)?,
        scene: scene.clone(),
        materials,
    };
    let t = Instant::now();
    let mut s = DynamicStrategy::new(&ctx, DynamicOptions::default())?;
    println!(
        "{} base objects in {:.0} ms",
        s.base_objects(),
        t.elapsed().as_secs_f64() * 1e3
    );
    let (w, h) = (640, 480);
    let options = RenderOptions::default();
    let mut rows = Vec::new();
    let mut x = -5.0;
    for i in 0..75 {
        x += if i < 45 { 1.4 } else { 10.0 } / 30.0;
        let eye = DVec3::new(x, EYE, 0.0);
        let view = Camera::from_yaw_pitch(eye, 90.0, 0.0, FOV, w, h)?.view();
        let t = Instant::now();
        let f = s.frame(&FrameRequest {
            eye,
            velocity: DVec3::ZERO,
            dt: 1.0 / 30.0,
            view: &view,
            options: &options,
            measure_error: false,
            read_back: true,
        })?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let st = s.last_frame().clone();
        rows.push((ms, f.regenerations));
        if i % 5 == 0 || i == 45 {
            println!(
                "frame {i}: cell {:?}, {ms:.0} ms (cell {:.0}, generation {:.0}, upload {:.0}, draw {:.0}), {} regenerated ({:?}), {} objects ({} visible), {} billboards, {} near + {} far-geometry triangles, {} texels, {} MB held",
                f.cell.map(|c| c.to_string()),
                st.cell_seconds * 1e3,
                st.generation_seconds * 1e3,
                st.upload_seconds * 1e3,
                st.draw_seconds * 1e3,
                f.regenerations,
                st.reasons,
                st.objects,
                st.visible,
                f.far_primitives,
                f.near_triangles - st.far_geometry_triangles,
                st.far_geometry_triangles,
                st.texels,
                f.cache_bytes >> 20
            );
        }
    }
    for (name, part) in [("1.4 m/s", &rows[1..45]), ("10 m/s", &rows[45..])] {
        let n = part.len() as f64;
        println!(
            "{name}: {:.0} ms per frame, {:.1} regenerations per frame (mean of {n} frames)",
            part.iter().map(|r| r.0).sum::<f64>() / n,
            part.iter().map(|r| r.1 as f64).sum::<f64>() / n
        );
    }
    // the reference frame (all geometry), timed after a warm-up frame
    let full = GpuScene::upload(&gpu, &scene, &UploadOptions::default())?;
    let renderer = Renderer::new(&gpu)?;
    let v = Camera::from_yaw_pitch(DVec3::new(0.0, EYE, 0.0), 90.0, 0.0, FOV, w, h)?.view();
    renderer.render(&full, &v, &options)?;
    let t = Instant::now();
    renderer.render(&full, &v, &options)?;
    println!(
        "reference frame: {:.0} ms; report {:?}",
        t.elapsed().as_secs_f64() * 1e3,
        s.report()
    );
    Ok(())
}
