//! `lemi compare SCENE…`: every far-field strategy on the same scene, cells, path and viewpoints,
//! side by side ([`lemi_compare::run`]). The bake of each layered strategy is the job
//! `lemi bake SCENE… --strategy S` builds from the same flags. A strategy whose job fails gets its
//! error in the table; the others go on, and the command exits with status 1 at the end.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use lemi_compare::{BakeRow, CompareOptions};
use lemi_core::cell::CellId;
use lemi_core::compress::TextureFormat;
use lemi_core::Aabb;
use lemi_eval::{EvalOptions, ViewpointSet};
use lemi_gpu::{BackendChoice, Gpu};
use lemi_strategy::StrategyKind;

use crate::cmd_walk::{streamer_options, StallArg};
use crate::load::UpArg;

/// Run every far-field strategy on the same scene, cells, path and viewpoints; write tables and plots.
#[derive(clap::Args)]
pub struct Args {
    /// Scene inputs (files, directories or builtin:NAME[:TRIANGLES[:SEED]]).
    #[arg(value_name = "SCENE", required = true)]
    pub scenes: Vec<String>,
    /// Strategies to compare, comma-separated (lemi, cubemap, equidistant, warp, dynamic).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "lemi,cubemap,equidistant,warp,dynamic"
    )]
    pub strategies: Vec<String>,
    /// Output directory (bundles, walks, evals, COMPARISON.md, comparison.json, frame_times.svg).
    #[arg(short = 'o', long = "out", default_value = "compare")]
    pub out: PathBuf,
    /// Up axis of the scene files: y or z.
    #[arg(long, value_enum, default_value = "y")]
    pub up: UpArg,
    /// Region of view cells `x0,y0,z0,x1,y1,z1` (as for `lemi bake`).
    #[arg(long, value_parser = crate::cmd_bake::parse_region, allow_hyphen_values = true)]
    pub region: Option<Aabb>,
    /// Only these cells, `x_y_z` comma-separated (as for `lemi bake`).
    #[arg(long, value_delimiter = ',')]
    pub cells: Vec<String>,
    /// View-cell side in metres.
    #[arg(long, default_value_t = 10.0)]
    pub cell_size: f64,
    /// Flat cells of this height (passed to `lemi bake`).
    #[arg(long)]
    pub cell_height: Option<f64>,
    /// Texels per face side.
    #[arg(long, default_value_t = 512)]
    pub resolution: u32,
    /// Layers per face of the `lemi` placement (`equidistant` uses the same count).
    #[arg(long)]
    pub layers: Option<u32>,
    /// Baked faces: 4 (horizontal) or 6.
    #[arg(long, default_value_t = 4)]
    pub faces: u32,
    /// Allowed parallax angle in degrees (default: one pixel of the output view).
    #[arg(long)]
    pub alpha_deg: Option<f64>,
    /// Output width the bake assumes (sets α).
    #[arg(long)]
    pub output_width: Option<u32>,
    /// Output horizontal fov the bake assumes (sets α).
    #[arg(long)]
    pub output_fov: Option<f64>,
    /// Depth overlap of `equidistant` slabs (fraction of a slab on each side).
    #[arg(long, default_value_t = 0.1)]
    pub overlap: f64,
    /// Size of the walk's frames `WIDTHxHEIGHT`.
    #[arg(long, value_parser = lemi_core::camera::parse_size, default_value = "1280x720")]
    pub walk_size: (u32, u32),
    /// Frames per second of the generated path.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Walking speed of the generated path (m/s).
    #[arg(long, default_value_t = 1.4)]
    pub walk_speed: f64,
    /// Flying speed of the generated path (m/s).
    #[arg(long, default_value_t = 10.0)]
    pub fly_speed: f64,
    /// Random interior viewpoints per cell in the evaluation.
    #[arg(long, default_value_t = 0)]
    pub viewpoints: usize,
    /// Evaluate only the centre and corners of each cell.
    #[arg(long)]
    pub corners_only: bool,
    /// Evaluate only these cells (comma-separated ids; default: every baked cell).
    #[arg(long, value_delimiter = ',')]
    pub eval_cells: Vec<CellId>,
    /// Evaluation image size (default: the bake's output view).
    #[arg(long, value_parser = lemi_core::camera::parse_size)]
    pub eval_size: Option<(u32, u32)>,
    /// Also bake the `lemi` strategy with these texture formats (comma-separated: png, bc7, bc1;
    /// the strategies are baked with the bake's default, bc1) and report each one's disk bytes,
    /// texture memory, encode seconds and image cost against the reference and, with png among
    /// them, against the PNG bake.
    #[arg(long, value_delimiter = ',', value_parser = crate::cmd_bake::parse_texture_format)]
    pub texture_formats: Vec<TextureFormat>,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Print the comparison as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> Result<()> {
    let mut kinds = Vec::new();
    for name in &args.strategies {
        kinds.push(StrategyKind::parse(name).map_err(|e| anyhow!("--strategies: {e}"))?);
    }
    lemi_compare::check_strategies(&kinds).map_err(|e| anyhow!("--strategies: {e}"))?;
    for (flag, v) in [
        ("--fps", args.fps),
        ("--walk-speed", args.walk_speed),
        ("--fly-speed", args.fly_speed),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{flag} must be a positive number (got {v})");
        }
    }
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    let t0 = Instant::now();
    let gpu = Arc::new(Gpu::new(backend)?);
    let options = CompareOptions {
        strategies: kinds,
        out: args.out.clone(),
        walk_size: args.walk_size,
        fps: args.fps,
        walk_speed: args.walk_speed,
        fly_speed: args.fly_speed,
        streamer: streamer_options(512, 8192, 12.0, StallArg::Block),
        eval: EvalOptions {
            cells: (!args.eval_cells.is_empty()).then(|| args.eval_cells.clone()),
            set: if args.corners_only {
                ViewpointSet::Corners
            } else {
                ViewpointSet::Full
            },
            random_viewpoints: args.viewpoints,
            size: args.eval_size,
            ..Default::default()
        },
        command: std::env::args().collect::<Vec<_>>().join(" "),
        texture_formats: args.texture_formats.clone(),
    };
    let say = |m: &str| {
        if !args.json {
            eprintln!("[{:>6.1} s] {m}", t0.elapsed().as_secs_f64());
        }
    };
    let bake_one =
        |k: StrategyKind, f: Option<TextureFormat>, dir: &Path| bake(&args, k, f, dir, &gpu);
    let done = lemi_compare::run(&gpu, &options, bake_one, say)?;
    if let Some(e) = &done.plot_error {
        eprintln!("warning: no plot ({e})");
    }
    if args.json {
        println!("{}", done.json);
    } else {
        print!("{}", done.markdown);
        println!(
            "\nwrote {} (COMPARISON.md, comparison.json, frame_times.svg)",
            args.out.display()
        );
    }
    let mut failed = false;
    for r in &done.rows {
        for e in &r.errors {
            eprintln!("error: {}: {e}", r.strategy);
            failed = true;
        }
    }
    for f in &done.formats {
        for e in &f.errors {
            eprintln!("error: lemi with {} textures: {e}", f.format);
            failed = true;
        }
    }
    if failed {
        std::process::exit(1);
    }
    Ok(())
}

/// Bakes the layered strategy `k` with `format` textures (`None`: `lemi bake`'s default) into
/// `dir`: the job `lemi bake` builds from the same flags.
fn bake(
    args: &Args,
    k: StrategyKind,
    format: Option<TextureFormat>,
    dir: &Path,
    gpu: &Gpu,
) -> Result<BakeRow> {
    let prepared = crate::cmd_bake::prepare(&crate::cmd_bake::Args {
        scenes: args.scenes.clone(),
        up: args.up,
        out: Some(dir.to_path_buf()),
        merge: None,
        region: args.region,
        eye_height: 1.7,
        cells: args.cells.clone(),
        cell_size: args.cell_size,
        cell_height: args.cell_height,
        resolution: args.resolution,
        layers: args.layers,
        near_field: None,
        faces: args.faces,
        output_fov: args.output_fov,
        output_width: args.output_width,
        alpha_deg: args.alpha_deg,
        outline_copies: false,
        alpha_px: None,
        micro_grid: 8,
        micro_threshold: 0.6,
        strategy: k.name().into(),
        overlap: (k == StrategyKind::Equidistant).then_some(args.overlap),
        hlod_error_px: None,
        hlod_band_factor: None,
        shard: None,
        backend: args.backend.clone(),
        json: true,
        texture_format: format,
        outline_fringe: false,
    })?;
    let row = lemi_compare::bake(gpu, &prepared.scene, &prepared.job, k)?;
    Ok(BakeRow {
        load_seconds: prepared.load_seconds,
        warnings: prepared.warnings,
        ..row
    })
}
