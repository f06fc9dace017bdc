//! `lemi walk BUNDLE (--auto | --path P)`: headless replay of a camera path through a baked region
//! (GI 2002 sec. 3 and 6, Figs. 8-9). The runtime streams cells ahead of the viewer
//! (`lemi-runtime`: prediction, background loading, LRU cache, uploads under a per-frame budget)
//! and draws the current cell's near geometry plus its impostors; the same path is then replayed
//! drawing all geometry. Writes `frames.csv`, `summary.json` and `plot.png` (frame rate and
//! primitives per frame, cell changes and stalls marked).
//!
//! The replay is paced in real time: a frame that finishes before its time on the path waits, so
//! the background loader gets exactly the time a real walk would give it. When frames take longer
//! than the path's frame interval (software rendering at high resolution), the loader gets more
//! time than in real time; the summary says so (`slower_than_real_time_frames`).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use lemi_core::camera::View;
use lemi_gpu::{
    BackendChoice, Gpu, GpuMaterials, GpuScene, RenderOptions, Renderer, UploadOptions,
};
use lemi_runtime::{StallPolicy, StreamerOptions};
use lemi_strategy::{FrameRequest, StrategyContext};

use crate::walk::{auto_path, write_csv, write_plot, CameraPath, FrameRecord, Mode, Summary};

/// Replay a camera path with streaming impostors and with all geometry; frame times, plots.
#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("path_source").required(true).args(["auto", "path"])))]
pub struct Args {
    /// The bundle directory.
    pub bundle: PathBuf,
    /// Generate a walkthrough of every baked cell plus a flyover inside the baked region.
    #[arg(long)]
    pub auto: bool,
    /// Replay this camera path (`lemi-path` JSON, as `lemi view` records it).
    #[arg(long, value_name = "PATH.json")]
    pub path: Option<PathBuf>,
    /// Output size `WIDTHxHEIGHT`.
    #[arg(long, value_parser = crate::cmd_render::parse_size, default_value = "1280x720")]
    pub size: (u32, u32),
    /// Horizontal field of view in degrees; default: the bake's output view (60° without one).
    #[arg(long)]
    pub fov: Option<f64>,
    /// Walking speed of `--auto` (m/s).
    #[arg(long, default_value_t = 1.4)]
    pub walk_speed: f64,
    /// Flying speed of `--auto` (m/s).
    #[arg(long, default_value_t = 10.0)]
    pub fly_speed: f64,
    /// Frames per second of `--auto`.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Output directory (frames.csv, summary.json, plot.png, path.json); default BUNDLE/walk.
    #[arg(short = 'o', long = "out")]
    pub out: Option<PathBuf>,
    /// Also write every Nth impostor frame as PNG into this directory.
    #[arg(long)]
    pub frames_dir: Option<PathBuf>,
    /// With --frames-dir: write every Nth frame.
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..))]
    pub every: u64,
    /// Skip the all-geometry replay.
    #[arg(long)]
    pub no_geometry: bool,
    /// Cell cache budget in MiB (CPU + GPU bytes of streamed cells).
    #[arg(long, default_value_t = 512)]
    pub cache_mb: u64,
    /// Texture upload budget per frame in KiB.
    #[arg(long, default_value_t = 8192)]
    pub upload_kb: u64,
    /// Highest observer speed the prefetching plans for (m/s).
    #[arg(long, default_value_t = 12.0)]
    pub max_speed: f64,
    /// When the current cell is not ready: wait for it (block) or draw all geometry for that
    /// frame (fallback). Both count a stall.
    #[arg(long, value_enum, default_value = "block")]
    pub stall: StallArg,
    /// The scene, if it moved since the bake (checked against the bundle's fingerprint).
    #[arg(long = "scene", value_name = "SCENE")]
    pub scene_override: Vec<String>,
    /// Far-field strategy: lemi, cubemap or equidistant (the strategy the bundle was baked for;
    /// default), warp or dynamic (built at run time from the bundle's cells and near lists).
    #[arg(long)]
    pub strategy: Option<String>,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum StallArg {
    Block,
    Fallback,
}

pub fn run(args: Args) -> Result<()> {
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    for (flag, v) in [
        ("--walk-speed", args.walk_speed),
        ("--fly-speed", args.fly_speed),
        ("--max-speed", args.max_speed),
        ("--fps", args.fps),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{flag} must be a positive number (got {v})");
        }
    }
    if let Some(f) = args.fov {
        if !(f.is_finite() && f > 0.0 && f < 180.0) {
            bail!("--fov must be in (0, 180) degrees (got {f})");
        }
    }
    let (bundle, scene) = crate::bundle_view::open(&args.bundle, &args.scene_override, args.json)?;
    let manifest = bundle.manifest().clone();
    let baked: Vec<_> = manifest
        .cells
        .iter()
        .filter_map(|c| manifest.grid.cell_of(c.id).ok())
        .collect();
    let path = match &args.path {
        Some(p) => CameraPath::read(p)?,
        None => auto_path(
            &manifest.grid,
            &baked,
            args.walk_speed,
            args.fly_speed,
            args.fps,
        )
        .context("--auto")?,
    };
    let out = args.out.clone().unwrap_or_else(|| args.bundle.join("walk"));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    if let Some(d) = &args.frames_dir {
        std::fs::create_dir_all(d)
            .with_context(|| format!("creating --frames-dir {}", d.display()))?;
    }
    path.write(&out.join("path.json"))?;

    let (w, h) = args.size;
    let fov_x = args.fov.or(manifest.params.output_fov_deg).unwrap_or(60.0);
    let fov_y = 2.0
        * ((0.5 * fov_x.to_radians()).tan() * h as f64 / w as f64)
            .atan()
            .to_degrees();
    let gpu = Arc::new(Gpu::new(backend)?);
    let scene = Arc::new(scene);
    let materials = Arc::new(
        GpuMaterials::upload(&gpu, &scene.materials, &scene.textures)
            .context("uploading the scene's materials")?,
    );
    let options = StreamerOptions {
        cache_budget_bytes: args.cache_mb.saturating_mul(1 << 20),
        upload_budget_bytes_per_frame: args.upload_kb.saturating_mul(1 << 10),
        max_speed: args.max_speed,
        stall_policy: match args.stall {
            StallArg::Block => StallPolicy::Block,
            StallArg::Fallback => StallPolicy::Fallback,
        },
        ..Default::default()
    };
    let ctx = StrategyContext {
        gpu: gpu.clone(),
        bundle: bundle.clone(),
        scene: scene.clone(),
        materials: materials.clone(),
    };
    let kind = crate::strategy::kind_for(&manifest, args.strategy.as_deref())?;
    let mut strategy = crate::strategy::open(&ctx, kind, options)?;
    let renderer = Renderer::new(&gpu)?;
    let render_options = RenderOptions {
        clear: [150, 190, 235, 255],
        ..Default::default()
    };
    // All geometry: for the comparison replay.
    let full = GpuScene::upload(&gpu, &scene, &UploadOptions::default())
        .context("uploading the scene for the geometry replay")?;
    let total_triangles = scene.triangle_count();
    let frames: Vec<_> = path.frames().collect();
    let n = frames.len() as u64;
    let bar = if args.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(n * if args.no_geometry { 1 } else { 2 })
    };
    bar.set_style(
        ProgressStyle::with_template("{elapsed:>4} [{bar:30}] {pos}/{len} frames  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    if let Some((_, _, first)) = frames.first() {
        bar.set_message("preloading the first cells");
        strategy
            .preload(first.eye, first.velocity, Duration::from_secs(60))
            .context("preloading the first cells")?;
    }
    let dt = 1.0 / path.fps;
    let mut impostor = Vec::with_capacity(frames.len());
    let mut warnings = Vec::new();
    let mut slow_frames = 0u64;
    let mut last_cell: Option<String> = None;
    let mut regenerations = 0u64;
    let start = Instant::now();
    let t0 = frames.first().map(|f| f.1).unwrap_or(0.0);
    for (index, t, pose) in &frames {
        // real-time pacing: this frame starts at its time on the path
        let due = Duration::from_secs_f64((t - t0).max(0.0));
        match due.checked_sub(start.elapsed()) {
            Some(wait) => std::thread::sleep(wait),
            None if *index > 0 => slow_frames += 1,
            None => {}
        }
        let view = camera_view(pose, fov_y, w, h)?;
        let t_frame = Instant::now();
        let f = strategy
            .frame(&FrameRequest {
                eye: pose.eye,
                velocity: pose.velocity,
                dt,
                view: &view,
                options: &render_options,
                measure_error: false,
            })
            .with_context(|| format!("rendering frame {index} ({kind})"))?;
        let cpu_ms = 1e3 * t_frame.elapsed().as_secs_f64();
        warnings.extend(f.warnings.iter().cloned());
        let switch = *index > 0 && f.cell != last_cell;
        last_cell = f.cell.clone();
        regenerations += f.regenerations;
        let frame = f.frame;
        let record = FrameRecord {
            frame: *index,
            t: *t,
            mode: Mode::Impostor,
            cpu_ms,
            gpu_ms: f.gpu_ms,
            near_triangles: f.near_triangles,
            impostor_quads: f.far_primitives,
            total_triangles: if f.fallback {
                total_triangles
            } else {
                f.near_triangles
            },
            cell: f.cell,
            cell_switch: switch,
            stalled: f.stalled,
            cache_bytes: f.cache_bytes,
            fallback: f.fallback,
        };
        if let Some(d) = &args.frames_dir {
            if index % args.every == 0 {
                let p = d.join(format!("frame-{index:06}.png"));
                image::RgbaImage::from_raw(frame.width, frame.height, frame.rgba)
                    .context("frame has the wrong size")?
                    .save(&p)
                    .with_context(|| format!("writing {}", p.display()))?;
            }
        }
        impostor.push(record);
        bar.inc(1);
        bar.set_message(format!(
            "impostors, cell {}",
            last_cell.as_deref().unwrap_or("-")
        ));
    }
    let report = strategy.report();
    drop(strategy);
    let mut geometry = Vec::new();
    if !args.no_geometry {
        for (index, t, pose) in &frames {
            let view = camera_view(pose, fov_y, w, h)?;
            let t_frame = Instant::now();
            renderer
                .render(&full, &view, &render_options)
                .context("rendering a geometry frame")?;
            geometry.push(FrameRecord {
                frame: *index,
                t: *t,
                mode: Mode::Geometry,
                cpu_ms: 1e3 * t_frame.elapsed().as_secs_f64(),
                gpu_ms: renderer.last_gpu_ms(),
                near_triangles: 0,
                impostor_quads: 0,
                total_triangles,
                cell: manifest.grid.locate(pose.eye).map(|c| c.id().to_string()),
                cell_switch: false,
                stalled: false,
                cache_bytes: 0,
                fallback: false,
            });
            bar.inc(1);
            bar.set_message("all geometry");
        }
    }
    bar.finish_and_clear();
    let mut all = impostor.clone();
    all.extend(geometry.iter().cloned());
    write_csv(&out.join("frames.csv"), &all)?;
    let summary = Summary::of(&impostor, &geometry);
    summary.write_json(&out.join("summary.json"))?;
    write_plot(&out.join("plot.png"), &impostor, &geometry)?;
    let mut v = serde_json::to_value(&summary)?;
    v["slower_than_real_time_frames"] = serde_json::json!(slow_frames);
    v["size"] = serde_json::json!([w, h]);
    v["fov_x_deg"] = serde_json::json!(fov_x);
    v["adapter"] = serde_json::json!(gpu.describe());
    v["strategy"] = serde_json::json!(kind.name());
    v["loads"] = serde_json::json!(report.loads);
    v["evictions"] = serde_json::json!(report.evictions);
    v["peak_cache_bytes"] = serde_json::json!(report.peak_bytes);
    v["regenerations"] = serde_json::json!(regenerations);
    v["prepare_seconds"] = serde_json::json!(report.prepare_seconds);
    v["prepared_cells"] = serde_json::json!(report.prepared_cells);
    v["texture_bytes_per_cell"] = serde_json::json!(report.texture_bytes_per_cell);
    v["warnings"] = serde_json::json!(warnings);
    v["out"] = serde_json::json!(out);
    let summary_path = out.join("summary.json");
    lemi_core::container::write_atomic(&summary_path, &serde_json::to_vec_pretty(&v)?)
        .with_context(|| format!("writing {}", summary_path.display()))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let ms = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.1} ms"));
    println!("lemi walk");
    println!("adapter    {}", gpu.describe());
    println!(
        "path       {} frames at {} fps ({:.1} s), {w}x{h}, {fov_x}° horizontal",
        summary.frames,
        path.fps,
        path.duration()
    );
    println!(
        "{:<10} median {}, p99 {}; {} cell switches, {} stalls, {} loads, {} evictions, {} regenerations, peak cache {:.1} MB",
        kind.name(),
        ms(summary.impostor_median_ms),
        ms(summary.impostor_p99_ms),
        summary.cell_switches,
        summary.stalls,
        report.loads,
        report.evictions,
        regenerations,
        report.peak_bytes as f64 / 1e6
    );
    if !args.no_geometry {
        println!(
            "geometry   median {}, p99 {}; speed-up of the median {}",
            ms(summary.geometry_median_ms),
            ms(summary.geometry_p99_ms),
            summary
                .speedup_median
                .map_or("-".to_string(), |s| format!("{s:.1}x"))
        );
    }
    if summary.impostor_gpu_median_ms.is_some() || summary.geometry_gpu_median_ms.is_some() {
        println!(
            "gpu time   median {} ({}), {} (all geometry); speed-up {}",
            ms(summary.impostor_gpu_median_ms),
            kind.name(),
            ms(summary.geometry_gpu_median_ms),
            summary
                .speedup_gpu_median
                .map_or("-".to_string(), |s| format!("{s:.1}x"))
        );
    }
    if slow_frames > 0 {
        println!(
            "note       {slow_frames} frames took longer than the path's frame interval: the loader had more time than in real time"
        );
    }
    println!(
        "wrote      {} (frames.csv, summary.json, plot.png, path.json)",
        out.display()
    );
    Ok(())
}

fn camera_view(pose: &crate::walk::Pose, fov_y: f64, w: u32, h: u32) -> Result<View> {
    Ok(pose
        .camera(fov_y, w, h)
        .context("a camera of the path")?
        .view())
}
