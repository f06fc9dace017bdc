//! `lemi demo`: the main job on the built-in default scene. Loads `builtin:city`, places the layers
//! of a 10 m view cell on the avenue for a 1280×720, 60° output view, renders the reference image
//! from a cell corner and the four horizontal cube faces a bake records from the cell centre, and
//! prints a summary with timings and where the files went.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glam::DVec3;
use lemi_core::camera::{Camera, View};
use lemi_core::placement::{
    alpha_from_output_view, place_env_layers, Bound, Dim, EnvParams, PixelChoice, Target,
};
use lemi_core::Face;
use lemi_gpu::{BackendChoice, Frame, Gpu, GpuScene, RenderOptions, Renderer, UploadOptions};

use crate::load::{load_scene, SceneArgs, UpArg};

#[derive(clap::Args)]
pub struct Args {
    /// Scene to use.
    #[arg(long, default_value = "builtin:city")]
    pub scene: String,
    /// Output directory.
    #[arg(short = 'o', long = "out", default_value = "out/demo")]
    pub out: PathBuf,
    /// View-cell side in metres.
    #[arg(long, default_value_t = 10.0)]
    pub cell: f64,
    /// Texels per cube-face side.
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(16..=8192))]
    pub resolution: u32,
    /// Layers per face.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub layers: u32,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
}

const OUT_W: u32 = 1280;
const OUT_H: u32 = 720;
const OUT_FOV_Y: f64 = 60.0;

pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.cell.is_finite() && args.cell > 0.0) {
        anyhow::bail!(
            "--cell must be a positive number of metres (got {})",
            args.cell
        );
    }
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output directory {}", args.out.display()))?;
    let t_all = Instant::now();

    let scene_args = SceneArgs {
        scenes: vec![args.scene.clone()],
        up: UpArg::Y,
    };
    let (scene, load_s) = load_scene(&scene_args, false)?;

    // Placement for the output view (α = the angle of its outermost pixel, horizontally).
    let aspect = OUT_W as f64 / OUT_H as f64;
    let fov_x = 2.0 * ((OUT_FOV_Y.to_radians() / 2.0).tan() * aspect).atan();
    let alpha = alpha_from_output_view(fov_x, OUT_W, PixelChoice::Edge)?;
    let m = args.cell / 2.0;
    let params = EnvParams::cube(m, args.resolution, alpha, Dim::Three);
    let placement = place_env_layers(&params, Target::Layers(args.layers as usize))
        .context("placing the layers")?;
    let by_texel = placement
        .layers
        .iter()
        .filter(|l| l.bound_by == Bound::OneTexel)
        .count();

    // The cell: on the avenue (kept free of buildings by the city generator), eye height 1.7 m.
    let center = DVec3::new(20.0, 1.7, 0.0);
    let corner = center + DVec3::new(-m, 0.0, m);

    let gpu = Gpu::new(backend)?;
    let t = Instant::now();
    let gpu_scene = GpuScene::upload(&gpu, &scene, &UploadOptions::default())
        .context("uploading the scene to the GPU")?;
    let upload_s = t.elapsed().as_secs_f64();
    let renderer = Renderer::new(&gpu)?;
    let options = RenderOptions {
        clear: [150, 190, 235, 255],
        ..Default::default()
    };

    let t = Instant::now();
    let cam = Camera::look_at(
        corner,
        corner + DVec3::new(100.0, 8.0, -10.0),
        DVec3::Y,
        OUT_FOV_Y,
        OUT_W,
        OUT_H,
    )?;
    let reference = renderer
        .render(&gpu_scene, &cam.view(), &options)
        .context("rendering the reference view")?;
    let reference_s = t.elapsed().as_secs_f64();
    let reference_path = args.out.join("reference.png");
    save(&reference, &reference_path)?;

    let t = Instant::now();
    let res = args.resolution;
    let mut strip = image::RgbaImage::new(res * 4, res);
    for (k, face) in Face::HORIZONTAL.iter().enumerate() {
        let view = View::cube_face(center, *face, res, 0.05);
        let f = renderer
            .render(&gpu_scene, &view, &options)
            .with_context(|| format!("rendering cube face {face}"))?;
        let img = image::RgbaImage::from_raw(res, res, f.rgba)
            .context("rendered face has the wrong size")?;
        // Face images use the cube-map convention, mirrored as seen from inside; unmirror for display.
        let img = image::imageops::flip_horizontal(&img);
        image::imageops::replace(&mut strip, &img, (k as u32 * res) as i64, 0);
    }
    let faces_s = t.elapsed().as_secs_f64();
    let faces_path = args.out.join("faces.png");
    strip
        .save(&faces_path)
        .with_context(|| format!("writing {}", faces_path.display()))?;

    println!("lemi demo");
    println!(
        "scene      {}: {} triangles, {} materials, {:.0} x {:.0} m, loaded in {load_s:.2} s",
        scene.sources.join(" "),
        scene.stats.triangles,
        scene.materials.len(),
        scene.bounds.size().x,
        scene.bounds.size().z
    );
    println!("adapter    {}", gpu.describe());
    println!(
        "output     {OUT_W}x{OUT_H}, {OUT_FOV_Y}° vertical fov -> alpha = {:.4}° (outermost pixel)",
        alpha.to_degrees()
    );
    println!(
        "cell       {} m at ({:.1}, {:.1}, {:.1}), {}² texels per face, {} layers ({} bound by one-texel spacing)",
        args.cell, center.x, center.y, center.z, res, placement.layers.len(), by_texel
    );
    if let (Some(first), Some(last)) = (placement.layers.first(), placement.layers.last()) {
        println!(
            "layers     farthest at {:.1} m, nearest at {:.2} m; near field {:.2} m from the centre",
            first.distance, last.distance, placement.near_field
        );
    }
    println!(
        "time       upload {upload_s:.2} s, reference view {reference_s:.2} s, 4 cube faces {faces_s:.2} s, total {:.2} s",
        t_all.elapsed().as_secs_f64()
    );
    println!(
        "wrote      {} (reference view from the cell corner)",
        reference_path.display()
    );
    println!(
        "wrote      {} (+X -X +Z -Z faces from the cell centre, unmirrored)",
        faces_path.display()
    );
    Ok(())
}

fn save(frame: &Frame, path: &Path) -> anyhow::Result<()> {
    let img = image::RgbaImage::from_raw(frame.width, frame.height, frame.rgba.clone())
        .context("rendered image has the wrong size")?;
    img.save(path)
        .with_context(|| format!("writing {}", path.display()))
}
