//! `lemi compare SCENE…`: every far-field strategy on the same scene, cells, path and viewpoints,
//! side by side. For each strategy it does, in this process, what a user would do by hand:
//!
//! 1. the bake of `lemi bake SCENE… --strategy S` (the same job from the same flags) for the
//!    layered strategies (`lemi`, `cubemap`, `equidistant`); `warp` and `dynamic` run on the
//!    `lemi` bundle (its cells and near lists);
//! 2. the walk of `lemi walk BUNDLE --strategy S` ([`lemi_walk::walk`]) along one path (the
//!    automatic one, generated once); the all-geometry replay runs once, with the first walk;
//! 3. the evaluation of `lemi eval BUNDLE --strategy S` at the same viewpoints.
//!
//! Then it writes `COMPARISON.md` (tables), `comparison.json` (every number) and
//! `frame_times.svg` (frame time and far-field primitives per frame of every strategy) into the
//! output directory, besides each walk's and evaluation's own files. A strategy whose job fails
//! gets its error in the table; the others go on, and the command exits with status 1 at the end.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use lemi_bake::Baker;
use lemi_core::cell::CellId;
use lemi_core::{Aabb, Scene};
use lemi_eval::{EvalOptions, EvalRun, ViewpointSet};
use lemi_gpu::{BackendChoice, Gpu};
use lemi_strategy::StrategyKind;
use lemi_walk::{auto_path, CameraPath, FrameRecord, WalkOptions, WalkRun, WalkSummary};
use serde::Serialize;

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
    #[arg(long, value_parser = crate::cmd_render::parse_size, default_value = "1280x720")]
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
    #[arg(long, value_parser = crate::cmd_render::parse_size)]
    pub eval_size: Option<(u32, u32)>,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Print the comparison as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What a layered strategy's bake did (from `lemi bake`'s summary).
#[derive(Clone, Debug, Serialize)]
struct BakeRow {
    bundle: PathBuf,
    strategy: StrategyKind,
    adapter: String,
    /// Cells in the bundle (baked now or before).
    cells: usize,
    baked: usize,
    skipped: usize,
    seconds: f64,
    load_seconds: f64,
    prepare_seconds: f64,
    /// Bytes of the cell files.
    bytes: u64,
    warnings: Vec<String>,
    /// Per cell, what `lemi bake --json` reports for it.
    per_cell: Vec<lemi_bake::CellReport>,
}

/// A strategy's evaluation: the bundle totals of `lemi eval --json` without the per-view detail
/// (kept in each evaluation's own report).
#[derive(Clone, Debug, Serialize)]
struct EvalRow {
    views: u64,
    error_pixels: u64,
    /// `None` (JSON `null`): infinite.
    max_error_px: Option<f32>,
    p99_error_px: Option<f32>,
    mean_error_px: Option<f64>,
    above_1px: f64,
    crack_pixels: u64,
    views_with_cracks: u64,
    mean_flip: f32,
    max_flip: f32,
    coverage: f64,
    min_coverage: f64,
    /// `None`: identical images (infinite PSNR).
    psnr: Option<f64>,
    ssim: f64,
    min_ssim: f64,
    verdict: String,
    strategy: StrategyKind,
    placement_max_error_px: f32,
    placement_p99_error_px: f32,
    gap_filled_pixels: u64,
    size: [u32; 2],
    fov_x_deg: f64,
    seconds: f64,
    report: PathBuf,
}

/// One strategy's row of numbers.
#[derive(Serialize)]
struct Row {
    strategy: StrategyKind,
    bundle: Option<PathBuf>,
    bake: Option<BakeRow>,
    walk: Option<WalkSummary>,
    eval: Option<EvalRow>,
    errors: Vec<String>,
    /// The walk's impostor frames (for the plot).
    #[serde(skip)]
    frames: Vec<FrameRecord>,
}

/// The all-geometry replay's frame times.
#[derive(Serialize)]
struct GeometryTimes {
    median_ms: Option<f64>,
    p99_ms: Option<f64>,
    gpu_median_ms: Option<f64>,
}

/// `comparison.json`.
#[derive(Serialize)]
struct Comparison<'a> {
    command: &'a str,
    seconds: f64,
    strategies: &'a [Row],
    geometry: Option<GeometryTimes>,
}

pub fn run(args: Args) -> Result<()> {
    let mut kinds = Vec::new();
    for name in &args.strategies {
        let k = StrategyKind::parse(name).map_err(|e| anyhow!("--strategies: {e}"))?;
        if kinds.contains(&k) {
            bail!("--strategies: `{k}` is listed twice");
        }
        kinds.push(k);
    }
    if kinds.is_empty() {
        bail!("--strategies: name at least one strategy");
    }
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
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output directory {}", args.out.display()))?;
    let t0 = Instant::now();
    let say = |m: &str| {
        if !args.json {
            eprintln!("[{:>6.1} s] {m}", t0.elapsed().as_secs_f64());
        }
    };
    let gpu = Arc::new(Gpu::new(backend)?);

    // 1. bakes
    let mut bake_list: Vec<StrategyKind> =
        kinds.iter().copied().filter(|k| k.is_layered()).collect();
    if kinds.iter().any(|k| !k.is_layered()) && !bake_list.contains(&StrategyKind::Lemi) {
        bake_list.insert(0, StrategyKind::Lemi);
    }
    let mut bakes: Vec<(StrategyKind, Result<BakeRow>)> = Vec::new();
    for &k in &bake_list {
        let dir = args.out.join(k.name());
        say(&format!("baking {k} into {}", dir.display()));
        let bake = bake(&args, k, &dir, &gpu).with_context(|| format!("bake ({k})"));
        bakes.push((k, bake));
    }

    // 2. walks and 3. evaluations
    let mut rows = Vec::new();
    let mut path: Option<CameraPath> = None;
    let mut geometry: Vec<FrameRecord> = Vec::new();
    let mut geometry_times: Option<GeometryTimes> = None;
    for &k in &kinds {
        let mut row = Row {
            strategy: k,
            bundle: None,
            bake: None,
            walk: None,
            eval: None,
            errors: Vec::new(),
            frames: Vec::new(),
        };
        let baked = if k.is_layered() {
            k
        } else {
            StrategyKind::Lemi
        };
        match bakes.iter().find(|(b, _)| *b == baked) {
            Some((_, Ok(b))) if k.is_layered() => row.bake = Some(b.clone()),
            Some((_, Ok(_))) | None => {}
            Some((_, Err(e))) => {
                row.errors.push(format!("{e:#}"));
                rows.push(row);
                continue;
            }
        }
        let bundle_dir = args.out.join(baked.name());
        row.bundle = Some(bundle_dir.clone());
        let opened = crate::bundle_view::open(&bundle_dir, &[], true)
            .with_context(|| format!("opening the bundle for {k}"));
        let (bundle, scene) = match opened {
            Ok(o) => o,
            Err(e) => {
                row.errors.push(format!("{e:#}"));
                rows.push(row);
                continue;
            }
        };
        let scene = Arc::new(scene);
        say(&format!("walking {k}"));
        let walk = walk(
            &args,
            k,
            &gpu,
            &bundle,
            &scene,
            &mut path,
            geometry_times.is_none(),
        )
        .with_context(|| format!("walk ({k})"));
        match walk {
            Ok(run) => {
                if geometry_times.is_none() {
                    let s = &run.summary.stats;
                    geometry_times = Some(GeometryTimes {
                        median_ms: s.geometry_median_ms,
                        p99_ms: s.geometry_p99_ms,
                        gpu_median_ms: s.geometry_gpu_median_ms,
                    });
                    geometry = run.geometry;
                }
                row.frames = run.impostor;
                row.walk = Some(run.summary);
            }
            Err(e) => row.errors.push(format!("{e:#}")),
        }
        say(&format!("evaluating {k}"));
        match eval(&args, k, &gpu, &bundle, scene).with_context(|| format!("eval ({k})")) {
            Ok(e) => row.eval = Some(e),
            Err(e) => row.errors.push(format!("{e:#}")),
        }
        rows.push(row);
    }

    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let markdown = render_markdown(&rows, geometry_times.as_ref(), &command);
    let md_path = args.out.join("COMPARISON.md");
    lemi_core::container::write_atomic(&md_path, markdown.as_bytes())
        .with_context(|| format!("writing {}", md_path.display()))?;
    let svg_path = args.out.join("frame_times.svg");
    let walks: Vec<(&str, &[FrameRecord])> = (rows.iter())
        .map(|r| (r.strategy.name(), r.frames.as_slice()))
        .collect();
    if let Err(e) = lemi_walk::write_frame_times_svg(&svg_path, &walks, &geometry) {
        eprintln!("warning: no plot ({e})");
    }
    let all = Comparison {
        command: &command,
        seconds: t0.elapsed().as_secs_f64(),
        strategies: &rows,
        geometry: geometry_times,
    };
    let json_path = args.out.join("comparison.json");
    let text = serde_json::to_string_pretty(&all)?;
    lemi_core::container::write_atomic(&json_path, text.as_bytes())
        .with_context(|| format!("writing {}", json_path.display()))?;
    if args.json {
        println!("{text}");
    } else {
        print!("{markdown}");
        println!(
            "\nwrote {} (COMPARISON.md, comparison.json, frame_times.svg)",
            args.out.display()
        );
    }
    let failed: Vec<&Row> = rows.iter().filter(|r| !r.errors.is_empty()).collect();
    if !failed.is_empty() {
        for r in &failed {
            for e in &r.errors {
                eprintln!("error: {}: {e}", r.strategy);
            }
        }
        std::process::exit(1);
    }
    Ok(())
}

/// Bakes the layered strategy `k` into `dir`: the job `lemi bake` builds from the same flags.
fn bake(args: &Args, k: StrategyKind, dir: &Path, gpu: &Gpu) -> Result<BakeRow> {
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
        micro_grid: 8,
        micro_threshold: 0.6,
        strategy: k.name().into(),
        overlap: (k == StrategyKind::Equidistant).then_some(args.overlap),
        shard: None,
        backend: args.backend.clone(),
        json: true,
    })?;
    let t = Instant::now();
    let baker = Baker::new(gpu, &prepared.scene, prepared.job.params.clone())?;
    let prepare_seconds = t.elapsed().as_secs_f64();
    let summary = lemi_bake::run(&prepared.job, |cell| baker.bake(cell, |_| {}), |_, _, _| {})?;
    let report = summary.report();
    Ok(BakeRow {
        bundle: dir.to_path_buf(),
        strategy: k,
        adapter: gpu.info().name.clone(),
        cells: summary.outcomes.len(),
        baked: report.baked,
        skipped: report.skipped,
        seconds: summary.seconds,
        load_seconds: prepared.load_seconds,
        prepare_seconds,
        bytes: report.bytes,
        warnings: prepared.warnings,
        per_cell: report.per_cell,
    })
}

/// Walks strategy `k` along `path` (generated from the bundle's cells if still `None`), as
/// `lemi walk --strategy k` does, and writes the walk's files into `OUT/walk-k`.
fn walk(
    args: &Args,
    k: StrategyKind,
    gpu: &Arc<Gpu>,
    bundle: &lemi_core::bundle::Bundle,
    scene: &Arc<Scene>,
    path: &mut Option<CameraPath>,
    geometry: bool,
) -> Result<WalkRun> {
    let manifest = bundle.manifest();
    let kind = crate::strategy::kind_for(manifest, Some(k.name()))?;
    let path = match path {
        Some(p) => p,
        None => {
            let baked: Vec<_> = (manifest.cells.iter())
                .filter_map(|c| manifest.grid.cell_of(c.id).ok())
                .collect();
            let p = auto_path(
                &manifest.grid,
                &baked,
                args.walk_speed,
                args.fly_speed,
                args.fps,
            )
            .context("the automatic path")?;
            p.write(&args.out.join("path.json"))?;
            path.insert(p)
        }
    };
    let dir = args.out.join(format!("walk-{}", k.name()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    path.write(&dir.join("path.json"))?;
    let ctx = lemi_strategy::StrategyContext::new(gpu.clone(), bundle.clone(), scene.clone())?;
    let streamer = streamer_options(512, 8192, 12.0, StallArg::Block);
    let mut strategy = lemi_strategy::open(&ctx, kind, streamer)?;
    let mut run = lemi_walk::walk(
        strategy.as_mut(),
        path,
        WalkOptions {
            size: args.walk_size,
            fov_x_deg: manifest.params.output_fov_deg.unwrap_or(60.0),
            geometry,
            ..WalkOptions::new(gpu, scene, &manifest.grid)
        },
    )?;
    run.summary.out = Some(dir.clone());
    run.write_files(&dir)?;
    Ok(run)
}

/// Evaluates strategy `k` as `lemi eval --strategy k` does; the report goes to `OUT/eval-k`.
fn eval(
    args: &Args,
    k: StrategyKind,
    gpu: &Arc<Gpu>,
    bundle: &lemi_core::bundle::Bundle,
    scene: Arc<Scene>,
) -> Result<EvalRow> {
    let manifest = bundle.manifest();
    let kind = crate::strategy::kind_for(manifest, Some(k.name()))?;
    let options = EvalOptions {
        cells: (!args.eval_cells.is_empty()).then(|| args.eval_cells.clone()),
        set: if args.corners_only {
            ViewpointSet::Corners
        } else {
            ViewpointSet::Full
        },
        random_viewpoints: args.viewpoints,
        size: args.eval_size,
        ..Default::default()
    };
    let t = Instant::now();
    let run: EvalRun =
        lemi_eval::evaluate_strategy(gpu, bundle, scene, kind, &options, |_, _, _| {})?;
    let seconds = t.elapsed().as_secs_f64();
    let dir = args.out.join(format!("eval-{}", k.name()));
    let report = lemi_eval::write_report(&dir, &run.result, &run.worst)?;
    let (w, h, fov) = lemi_eval::output_view(manifest, &options);
    let s = &run.result.summary;
    let finite32 = |x: f32| x.is_finite().then_some(x);
    let finite64 = |x: f64| x.is_finite().then_some(x);
    Ok(EvalRow {
        views: s.views,
        error_pixels: s.error_pixels,
        max_error_px: finite32(s.max_error_px),
        p99_error_px: finite32(s.p99_error_px),
        mean_error_px: finite64(s.mean_error_px),
        above_1px: s.above_1px,
        crack_pixels: s.crack_pixels,
        views_with_cracks: s.views_with_cracks,
        mean_flip: s.mean_flip,
        max_flip: s.max_flip,
        coverage: s.coverage,
        min_coverage: s.min_coverage,
        psnr: finite64(s.psnr),
        ssim: s.ssim,
        min_ssim: s.min_ssim,
        verdict: lemi_eval::verdict(&run.result),
        strategy: kind,
        placement_max_error_px: run.placement.max(),
        placement_p99_error_px: run.placement.p99(),
        gap_filled_pixels: run.gap_filled.count(),
        size: [w, h],
        fov_x_deg: fov,
        seconds,
        report,
    })
}

fn fmt_ms(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{v:.1}"))
}

fn fmt_bytes(x: Option<f64>) -> String {
    match x {
        None => "–".into(),
        Some(b) if b >= 1e6 => format!("{:.2} MB", b / 1e6),
        Some(b) if b >= 1e3 => format!("{:.1} kB", b / 1e3),
        Some(b) => format!("{b:.0} B"),
    }
}

/// The tables of `COMPARISON.md`.
fn render_markdown(rows: &[Row], geometry: Option<&GeometryTimes>, command: &str) -> String {
    let mut m = String::new();
    let _ = writeln!(m, "# Far-field strategies compared\n");
    let _ = writeln!(m, "Made by:\n\n```\n{command}\n```\n");
    let geo_median = geometry.and_then(|g| g.median_ms);
    if let Some(w) = rows.iter().find_map(|r| r.walk.as_ref()) {
        let _ = writeln!(
            m,
            "Walk: {} frames at {}×{}, adapter {}. Every strategy replays the same path; the all-geometry replay of that path: median {} ms, p99 {} ms, GPU median {} ms.\n",
            w.stats.frames,
            w.size[0],
            w.size[1],
            w.adapter,
            fmt_ms(geo_median),
            fmt_ms(geometry.and_then(|g| g.p99_ms)),
            fmt_ms(geometry.and_then(|g| g.gpu_median_ms)),
        );
    }
    let _ = writeln!(
        m,
        "| strategy | bake s/cell | disk/cell | texture memory/cell | median ms | p99 ms | GPU median ms | speed-up | stalls | regenerations | far-field pixels | max px | p99 px | crack px | mean FLIP |"
    );
    let _ = writeln!(
        m,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let dash = || "–".to_string();
    for r in rows {
        let name = r.strategy.name();
        if !r.errors.is_empty() && r.walk.is_none() && r.eval.is_none() {
            let _ = writeln!(m, "| {name} | failed: see below | | | | | | | | | | | |");
            continue;
        }
        let walk = r.walk.as_ref();
        let per_cell = r.bake.as_ref().filter(|b| b.cells > 0).map(|b| {
            let c = b.cells as f64;
            (format!("{:.1}", b.seconds / c), b.bytes as f64 / c)
        });
        let bake_s = match r.strategy {
            StrategyKind::Warp => walk.map(|w| {
                let n = (w.prepared_cells as f64).max(1.0);
                format!("{:.1} (at run time)", w.prepare_seconds / n)
            }),
            StrategyKind::Dynamic => Some("none (at run time)".into()),
            _ => per_cell.as_ref().map(|p| p.0.clone()),
        };
        let disk = match r.strategy {
            StrategyKind::Warp | StrategyKind::Dynamic => "none".into(),
            _ => fmt_bytes(per_cell.map(|p| p.1)),
        };
        let median = walk.and_then(|w| w.stats.impostor_median_ms);
        let speedup = match (median, geo_median) {
            (Some(a), Some(g)) if a > 0.0 => format!("{:.1}×", g / a),
            _ => dash(),
        };
        let e = r.eval.as_ref();
        let px = |x: Option<Option<f32>>| match x {
            Some(Some(x)) => format!("{x:.2}"),
            Some(None) => "∞".into(),
            None => dash(),
        };
        let far_share = e.and_then(|e| {
            let all = e.views as f64 * e.size[0] as f64 * e.size[1] as f64;
            (all > 0.0).then(|| format!("{:.1} %", 100.0 * e.error_pixels as f64 / all))
        });
        let _ = writeln!(
            m,
            "| {name} | {} | {disk} | {} | {} | {} | {} | {speedup} | {} | {} | {} | {} | {} | {} | {} |",
            bake_s.unwrap_or_else(dash),
            fmt_bytes(walk.map(|w| w.texture_bytes_per_cell)),
            fmt_ms(median),
            fmt_ms(walk.and_then(|w| w.stats.impostor_p99_ms)),
            fmt_ms(walk.and_then(|w| w.stats.impostor_gpu_median_ms)),
            walk.map_or_else(dash, |w| w.stats.stalls.to_string()),
            walk.map_or_else(dash, |w| w.regenerations.to_string()),
            far_share.unwrap_or_else(dash),
            px(e.map(|e| e.max_error_px)),
            px(e.map(|e| e.p99_error_px)),
            e.map_or_else(dash, |e| e.crack_pixels.to_string()),
            e.map_or_else(dash, |e| format!("{:.3}", e.mean_flip)),
        );
    }
    let _ = writeln!(
        m,
        "\nColumns: *bake s/cell* and *disk/cell* from the bake (seconds and bytes over \
         the cells baked); *texture memory/cell*: bytes of far-field textures the runtime held for \
         one cell; *median/p99 ms*: wall-clock frame time of the walk (readback included), \
         *GPU median ms*: the render passes alone (timestamp queries; only for strategies whose \
         frame is all GPU work), \
         *speed-up*: all-geometry median over the strategy's median; *stalls*: frames that waited \
         for a cell; *regenerations*: impostors regenerated (dynamic) or far fields recorded at \
         run time (warp); *far-field pixels*: share of the evaluated pixels drawn by the far field (the rest is near \
         geometry or background), the pixels the error columns are over; *max/p99 px*: geometric error of the far-field pixels in output pixels \
         (`lemi eval --strategy S`); *crack px*: pixels where the reference shows a surface and \
         the strategy shows background (layered strategies also count pixels showing something \
         farther than one slab behind); *mean FLIP*: mean over the views of the per-view mean \
         FLIP."
    );
    let mut notes = String::new();
    for r in rows {
        if let Some(e) = &r.eval {
            let _ = writeln!(
                notes,
                "- {}: {} views evaluated, coverage {:.4}, PSNR {} dB, SSIM {:.3}.",
                r.strategy,
                e.views,
                e.coverage,
                e.psnr.map_or("∞".into(), |x| format!("{x:.1}")),
                e.ssim,
            );
        }
        for err in &r.errors {
            let _ = writeln!(notes, "- {} failed: {}", r.strategy, err.replace('\n', " "));
        }
    }
    if !notes.is_empty() {
        let _ = writeln!(m, "\n{notes}");
    }
    let _ = writeln!(m, "\n![frame time per frame](frame_times.svg)");
    m
}
