//! `lemi demo`: the main job on the built-in default scene. Bakes a strip of view cells of
//! `builtin:city` on an avenue into a bundle (exactly what `lemi bake` does), then renders the
//! impostor view from a corner of the first cell next to the reference and their difference
//! (exactly what `lemi render BUNDLE --compare` does), and prints both summaries. A second run
//! resumes: cells already baked with the same parameters are skipped.

use std::path::PathBuf;

use anyhow::Context;
use glam::DVec3;

use crate::load::{SceneArgs, UpArg};

#[derive(clap::Args)]
pub struct Args {
    /// Scene to use.
    #[arg(long, default_value = "builtin:city")]
    pub scene: String,
    /// Output directory (the bundle goes to `OUT/bundle`).
    #[arg(short = 'o', long = "out", default_value = "out/demo")]
    pub out: PathBuf,
    /// View-cell side in metres.
    #[arg(long, default_value_t = 10.0)]
    pub cell: f64,
    /// View-cell height in metres: the eye-height range around 1.7 m the viewer walks in.
    #[arg(long, default_value_t = 1.0)]
    pub cell_height: f64,
    /// Number of cells in the strip.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub cells: u32,
    /// Texels per cube-face side [default: the smallest at which a layer texel covers at most
    /// one pixel of the demo's output view, 1663 for 960 px at 60°, so that the impostors are as
    /// sharp as the geometry].
    #[arg(long, value_parser = clap::value_parser!(u32).range(16..=8192))]
    pub resolution: Option<u32>,
    /// Layers per face.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub layers: u32,
    /// Bake without the outline fringe (docs/COMPRESSION.md, "1c. Outline fringe"), which the
    /// demo uses by default at the matched resolution or above (it is made for texels of at
    /// most an output pixel): silhouettes where the geometry's are (on its 312 certificate views
    /// false coverage 0.062 % → 0.027 %, silhouette p99 1.42 → 1.00 px) for a frame 4–12 %
    /// dearer.
    #[arg(long)]
    pub no_outline_fringe: bool,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
}

/// The output view the demo bakes for and renders: 960×540 (the size `lemi view` opens), 60°
/// horizontal field of view.
const OUT_W: u32 = 960;
const OUT_H: u32 = 540;
const OUT_FOV_X: f64 = 60.0;
/// Eye height above the street (m).
const EYE: f64 = 1.7;

pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.cell.is_finite() && args.cell > 0.0) {
        anyhow::bail!(
            "--cell must be a positive number of metres (got {})",
            args.cell
        );
    }
    // layers as sharp as the output view: a texel subtends at most one output pixel
    let matched = lemi_core::placement::min_face_res_for_output_view(OUT_FOV_X.to_radians(), OUT_W)
        .context("the resolution matching the demo's output view")?;
    let resolution = args.resolution.unwrap_or(matched);
    // the fringe pass closes gaps of up to two pixels: made for texels of at most a pixel
    let outline_fringe = !args.no_outline_fringe && resolution >= matched;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output directory {}", args.out.display()))?;
    let bundle = args.out.join("bundle");
    // The strip: along the avenue the city generator keeps free of buildings (z = 0, x from 15 m).
    let x0 = 15.0;
    let x1 = x0 + args.cell * args.cells as f64;
    let half = 0.5 * args.cell;
    let region = lemi_core::Aabb::new(DVec3::new(x0, EYE, -half), DVec3::new(x1, EYE, half));
    println!(
        "lemi demo: baking {} cells of {} m along the avenue of {} into {} \
         ({resolution}² layers for a {OUT_W}×{OUT_H}, {OUT_FOV_X}° view)",
        args.cells,
        args.cell,
        args.scene,
        bundle.display()
    );
    println!();
    crate::cmd_bake::run(crate::cmd_bake::Args {
        scenes: vec![args.scene.clone()],
        up: UpArg::Y,
        out: Some(bundle.clone()),
        merge: None,
        region: Some(region),
        eye_height: EYE,
        cells: Vec::new(),
        cell_size: args.cell,
        cell_height: Some(args.cell_height),
        resolution,
        layers: Some(args.layers),
        near_field: None,
        faces: 4,
        output_fov: Some(OUT_FOV_X),
        output_width: Some(OUT_W),
        alpha_deg: None,
        outline_copies: false,
        alpha_px: None,
        micro_grid: 8,
        micro_threshold: 0.6,
        strategy: "lemi".into(),
        overlap: None,
        hlod_error_px: None,
        hlod_band_factor: None,
        shard: None,
        backend: args.backend.clone(),
        json: false,
        texture_format: None,
        outline_fringe,
    })?;

    // From the corner of the first cell, looking down the avenue.
    let corner = DVec3::new(
        x0 + 0.01 * args.cell,
        EYE + 0.49 * args.cell_height,
        half * 0.98,
    );
    let fov_y = 2.0
        * ((OUT_FOV_X.to_radians() / 2.0).tan() * OUT_H as f64 / OUT_W as f64)
            .atan()
            .to_degrees();
    let compare_path = args.out.join("compare.png");
    println!();
    println!(
        "lemi demo: reference | impostor | difference from the cell corner ({:.2}, {:.2}, {:.2})",
        corner.x, corner.y, corner.z
    );
    println!();
    crate::cmd_render::run(crate::cmd_render::Args {
        scene: SceneArgs {
            scenes: vec![bundle.to_string_lossy().into_owned()],
            up: UpArg::Y,
        },
        eye: Some(corner),
        look: Some(corner + DVec3::new(100.0, 6.0, -12.0)),
        dir: None,
        yaw: None,
        pitch: None,
        fov: fov_y,
        size: (OUT_W, OUT_H),
        near: lemi_core::camera::DEFAULT_NEAR,
        output: compare_path,
        depth: None,
        backend: args.backend,
        clear: [150, 190, 235, 255],
        frames: 1,
        json: false,
        texel_filter: crate::cmd_render::TexelFilterArg::Footprint,
        compare: true,
        scene_override: Vec::new(),
        with_object: Vec::new(),
    })
}
