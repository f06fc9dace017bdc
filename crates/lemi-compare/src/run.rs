//! The comparison's loop: the bakes, then per strategy the walk and the evaluation, then the
//! tables, the JSON and the plot.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use lemi_bake::{BakeError, BakeJob, Baker};
use lemi_core::bundle::Bundle;
use lemi_core::Scene;
use lemi_eval::{EvalError, EvalOptions};
use lemi_gpu::Gpu;
use lemi_runtime::StreamerOptions;
use lemi_strategy::{StrategyContext, StrategyError, StrategyKind};
use lemi_walk::{auto_path, CameraPath, FrameRecord, PathError, WalkError, WalkOptions, WalkRun};

use crate::{error_chain, render_markdown, BakeRow, CompareError, Comparison, EvalRow};
use crate::{FormatRow, GeometryTimes, Row};
use lemi_core::compress::TextureFormat;

/// What to compare and how.
#[derive(Clone, Debug)]
pub struct CompareOptions {
    /// The strategies, in the order of the tables; distinct, at least one ([`check_strategies`]).
    pub strategies: Vec<StrategyKind>,
    /// The output directory: bundles (`OUT/STRATEGY`), walks (`OUT/walk-STRATEGY`), evaluations
    /// (`OUT/eval-STRATEGY`), `path.json`, `COMPARISON.md`, `comparison.json`, `frame_times.svg`.
    pub out: PathBuf,
    /// Size of the walk's frames.
    pub walk_size: (u32, u32),
    /// Frames per second, walking and flying speed (m/s) of the generated path.
    pub fps: f64,
    pub walk_speed: f64,
    pub fly_speed: f64,
    /// How the layered strategies stream their cells during the walk.
    pub streamer: StreamerOptions,
    /// The viewpoints and image size of the evaluations.
    pub eval: EvalOptions,
    /// The command that made the comparison (recorded in `COMPARISON.md` and `comparison.json`).
    pub command: String,
    /// Texture formats the `lemi` strategy is also baked in (`OUT/lemi-FORMAT`) and evaluated,
    /// each against the reference and against the PNG bake (the `lemi` strategy's own when it
    /// is PNG, else `OUT/lemi-png` when listed); the `lemi` strategy's own format is not baked
    /// twice. Empty: none.
    pub texture_formats: Vec<TextureFormat>,
}

/// A finished comparison (its files are written).
#[derive(Debug)]
pub struct ComparisonRun {
    pub rows: Vec<Row>,
    pub geometry: Option<GeometryTimes>,
    /// The `lemi` bake in the further texture formats.
    pub formats: Vec<FormatRow>,
    /// `COMPARISON.md`.
    pub markdown: String,
    /// `comparison.json`.
    pub json: String,
    /// Why `frame_times.svg` could not be drawn, if it could not.
    pub plot_error: Option<WalkError>,
}

/// Checks that `strategies` names at least one strategy and none twice.
pub fn check_strategies(strategies: &[StrategyKind]) -> Result<(), CompareError> {
    for (i, k) in strategies.iter().enumerate() {
        if strategies[..i].contains(k) {
            return Err(CompareError::Repeated(*k));
        }
    }
    if strategies.is_empty() {
        return Err(CompareError::NoStrategies);
    }
    Ok(())
}

/// Bakes `job` (a layered strategy's bake) of `scene` into its bundle; `load_seconds` and
/// `warnings` of the row are left for the caller, who loaded the scene.
pub fn bake(
    gpu: &Gpu,
    scene: &Scene,
    job: &BakeJob,
    strategy: StrategyKind,
) -> Result<BakeRow, BakeError> {
    let t = Instant::now();
    let baker = Baker::new(gpu, scene, job.params.clone())?;
    let prepare_seconds = t.elapsed().as_secs_f64();
    let summary = lemi_bake::run(job, |cell| baker.bake(cell, |_| {}), |_, _, _| {})?;
    let report = summary.report();
    Ok(BakeRow {
        bundle: job.bundle.clone(),
        strategy,
        adapter: gpu.info().name.clone(),
        cells: summary.outcomes.len(),
        baked: report.baked,
        skipped: report.skipped,
        seconds: summary.seconds,
        load_seconds: 0.0,
        prepare_seconds,
        bytes: report.bytes,
        warnings: Vec::new(),
        per_cell: report.per_cell,
    })
}

/// Why a strategy's walk or evaluation failed (kept, with its causes, in the strategy's row).
#[derive(Debug, thiserror::Error)]
enum StepError {
    #[error("opening the bundle for {0}")]
    Open(StrategyKind, #[source] lemi_scene::OpenBundleError),
    #[error("the automatic path")]
    AutoPath(#[source] PathError),
    #[error("creating {}", .0.display())]
    CreateDir(PathBuf, #[source] std::io::Error),
    #[error(transparent)]
    Walk(#[from] WalkError),
    #[error(transparent)]
    Strategy(#[from] StrategyError),
    #[error(transparent)]
    Eval(#[from] EvalError),
}

/// Runs the comparison: `bake(kind, format, dir)` bakes the layered strategy `kind` with
/// macro-textures in `format` (`None`: the bake's default) into `dir` (the `lemi` bundle is
/// baked too when `warp` or `dynamic` is compared or texture formats are); `progress` is told
/// what starts. Writes the files into `options.out`.
pub fn run<E: std::fmt::Display>(
    gpu: &Arc<Gpu>,
    options: &CompareOptions,
    mut bake: impl FnMut(StrategyKind, Option<TextureFormat>, &Path) -> Result<BakeRow, E>,
    mut progress: impl FnMut(&str),
) -> Result<ComparisonRun, CompareError> {
    check_strategies(&options.strategies)?;
    let out = &options.out;
    std::fs::create_dir_all(out).map_err(|source| CompareError::Io {
        what: "creating the output directory",
        path: out.clone(),
        source,
    })?;
    let t0 = Instant::now();
    let kinds = &options.strategies;

    // 1. bakes
    let mut bake_list: Vec<StrategyKind> = kinds.iter().copied().filter(|k| k.is_baked()).collect();
    let formats = &options.texture_formats;
    if (kinds.iter().any(|k| !k.is_baked()) || !formats.is_empty())
        && !bake_list.contains(&StrategyKind::Lemi)
    {
        bake_list.insert(0, StrategyKind::Lemi);
    }
    let mut bakes: Vec<(StrategyKind, Result<BakeRow, String>)> = Vec::new();
    for &k in &bake_list {
        let dir = out.join(k.name());
        progress(&format!("baking {k} into {}", dir.display()));
        let row = bake(k, None, &dir).map_err(|e| format!("bake ({k}): {e:#}"));
        bakes.push((k, row));
    }
    let lemi_dir = out.join(StrategyKind::Lemi.name());
    let lemi_format = Bundle::open(&lemi_dir)
        .ok()
        .map(|b| b.manifest().params.texture_format);
    let mut format_rows = Vec::new();
    for &f in formats {
        // the `lemi` strategy's own format is its bake, not baked twice
        let own = Some(f) == lemi_format;
        let dir = if own {
            lemi_dir.clone()
        } else {
            out.join(format!("lemi-{}", f.name()))
        };
        let mut row = FormatRow {
            format: f,
            bundle: dir.clone(),
            bake: None,
            eval: None,
            against_png: None,
            errors: Vec::new(),
        };
        if own {
            row.bake = (bakes.iter())
                .find(|(k, _)| *k == StrategyKind::Lemi)
                .and_then(|(_, b)| b.as_ref().ok().cloned());
        } else {
            progress(&format!(
                "baking lemi with {f} textures into {}",
                dir.display()
            ));
            match bake(StrategyKind::Lemi, Some(f), &dir) {
                Ok(b) => row.bake = Some(b),
                Err(e) => row.errors.push(format!("bake (lemi, {f}): {e:#}")),
            }
        }
        format_rows.push(row);
    }

    // 2. walks and 3. evaluations
    let mut rows = Vec::new();
    let mut path: Option<CameraPath> = None;
    let mut geometry: Vec<FrameRecord> = Vec::new();
    let mut culled: Vec<FrameRecord> = Vec::new();
    let mut geometry_times: Option<GeometryTimes> = None;
    for &k in kinds {
        let mut row = Row {
            strategy: k,
            bundle: None,
            bake: None,
            walk: None,
            eval: None,
            errors: Vec::new(),
            frames: Vec::new(),
        };
        let baked = if k.is_baked() { k } else { StrategyKind::Lemi };
        match bakes.iter().find(|(b, _)| *b == baked) {
            Some((_, Ok(b))) if k.is_baked() => row.bake = Some(b.clone()),
            Some((_, Ok(_))) | None => {}
            Some((_, Err(e))) => {
                row.errors.push(e.clone());
                rows.push(row);
                continue;
            }
        }
        let bundle_dir = out.join(baked.name());
        row.bundle = Some(bundle_dir.clone());
        let (bundle, scene) = match lemi_scene::open_bundle(&bundle_dir, &[], None) {
            Ok(o) => (o.bundle, Arc::new(o.scene)),
            Err(e) => {
                row.errors.push(error_chain(&StepError::Open(k, e)));
                rows.push(row);
                continue;
            }
        };
        progress(&format!("walking {k}"));
        let first = geometry_times.is_none();
        match walk(options, k, gpu, &bundle, &scene, &mut path, first) {
            Ok(run) => {
                if first {
                    let s = &run.summary.stats;
                    geometry_times = Some(GeometryTimes {
                        median_ms: s.geometry_median_ms,
                        p99_ms: s.geometry_p99_ms,
                        gpu_median_ms: s.geometry_gpu_median_ms,
                        culled_median_ms: s.culled_median_ms,
                        culled_p99_ms: s.culled_p99_ms,
                        culled_gpu_median_ms: s.culled_gpu_median_ms,
                        culled_mean_triangles: s.culled_mean_triangles,
                    });
                    geometry = run.geometry;
                    culled = run.culled;
                }
                row.frames = run.impostor;
                row.walk = Some(run.summary);
            }
            Err(e) => row.errors.push(format!("walk ({k}): {}", error_chain(&e))),
        }
        progress(&format!("evaluating {k}"));
        match eval(options, k, gpu, &bundle, scene) {
            Ok(e) => row.eval = Some(e),
            Err(e) => row.errors.push(format!("eval ({k}): {}", error_chain(&e))),
        }
        rows.push(row);
    }

    // the PNG bake every other format is compared with, if there is one
    let png_dir = match lemi_format {
        Some(TextureFormat::Png) => Some(lemi_dir.clone()),
        _ => (format_rows.iter())
            .find(|r| r.format.is_png() && r.bake.is_some())
            .map(|r| r.bundle.clone()),
    };
    for row in format_rows.iter_mut().filter(|r| r.bake.is_some()) {
        progress(&format!("evaluating lemi with {} textures", row.format));
        let against = png_dir.as_deref().filter(|_| !row.format.is_png());
        if let Err(e) = eval_format(options, gpu, row, against) {
            row.errors
                .push(format!("eval (lemi, {}): {}", row.format, error_chain(&e)));
        }
    }

    let command = &options.command;
    let markdown = render_markdown(&rows, &format_rows, geometry_times.as_ref(), command);
    write(&out.join("COMPARISON.md"), markdown.as_bytes())?;
    let mut walks: Vec<(&str, &[FrameRecord])> = (rows.iter())
        .map(|r| (r.strategy.name(), r.frames.as_slice()))
        .collect();
    if !culled.is_empty() {
        walks.push(("geometry-culled", culled.as_slice()));
    }
    let plot_error =
        lemi_walk::write_frame_times_svg(&out.join("frame_times.svg"), &walks, &geometry).err();
    let all = Comparison {
        command,
        seconds: t0.elapsed().as_secs_f64(),
        strategies: &rows,
        geometry: geometry_times.clone(),
        texture_formats: &format_rows,
    };
    let json = serde_json::to_string_pretty(&all)?;
    write(&out.join("comparison.json"), json.as_bytes())?;
    Ok(ComparisonRun {
        rows,
        geometry: geometry_times,
        formats: format_rows,
        markdown,
        json,
        plot_error,
    })
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), CompareError> {
    lemi_core::container::write_atomic(path, bytes).map_err(|source| CompareError::Io {
        what: "writing",
        path: path.to_path_buf(),
        source,
    })
}

/// Walks strategy `k` along `path` (generated from the bundle's cells if still `None`, and
/// written to `OUT/path.json`) and writes the walk's files into `OUT/walk-k`.
fn walk(
    options: &CompareOptions,
    k: StrategyKind,
    gpu: &Arc<Gpu>,
    bundle: &Bundle,
    scene: &Arc<Scene>,
    path: &mut Option<CameraPath>,
    geometry: bool,
) -> Result<WalkRun, StepError> {
    let manifest = bundle.manifest();
    let kind = StrategyKind::for_bundle(manifest, Some(k))?;
    let path = match path {
        Some(p) => p,
        None => {
            let baked: Vec<_> = (manifest.cells.iter())
                .filter_map(|c| manifest.grid.cell_of(c.id).ok())
                .collect();
            let p = auto_path(
                &manifest.grid,
                &baked,
                options.walk_speed,
                options.fly_speed,
                options.fps,
            )
            .map_err(StepError::AutoPath)?;
            p.write(&options.out.join("path.json"))?;
            path.insert(p)
        }
    };
    let dir = options.out.join(format!("walk-{}", k.name()));
    std::fs::create_dir_all(&dir).map_err(|e| StepError::CreateDir(dir.clone(), e))?;
    path.write(&dir.join("path.json"))?;
    let ctx = StrategyContext::new(gpu.clone(), bundle.clone(), scene.clone())?;
    let mut strategy = lemi_strategy::open(&ctx, kind, options.streamer.clone())?;
    let mut run = lemi_walk::walk(
        strategy.as_mut(),
        path,
        WalkOptions {
            size: options.walk_size,
            fov_x_deg: manifest.params.output_fov_deg.unwrap_or(60.0),
            geometry,
            culled: geometry,
            ..WalkOptions::new(gpu, scene, &manifest.grid)
        },
    )?;
    run.summary.out = Some(dir.clone());
    run.write_files(&dir)?;
    Ok(run)
}

/// Evaluates the `lemi` bake of `row`'s texture format at the comparison's viewpoints, against
/// the reference and against the PNG bake in `png_dir` if there is one; the report goes to
/// `OUT/eval-lemi-F`.
fn eval_format(
    options: &CompareOptions,
    gpu: &Arc<Gpu>,
    row: &mut FormatRow,
    png_dir: Option<&Path>,
) -> Result<(), StepError> {
    let opened = lemi_scene::open_bundle(&row.bundle, &[], None)
        .map_err(|e| StepError::Open(StrategyKind::Lemi, e))?;
    let png = match png_dir {
        None => None,
        Some(d) => Some(
            Bundle::open(d)
                .map_err(|e| StepError::Eval(EvalError::Job(format!("{}: {e}", d.display()))))?,
        ),
    };
    let t = Instant::now();
    let run = lemi_eval::evaluate_bundle_against(
        gpu,
        &opened.bundle,
        &opened.scene,
        png.as_ref(),
        &options.eval,
        |_, _, _| {},
    )?;
    let seconds = t.elapsed().as_secs_f64();
    let dir = (options.out).join(format!("eval-lemi-{}", row.format.name()));
    let report = lemi_eval::write_report(&dir, &run.result, &run.worst)?;
    row.against_png = run.against.clone();
    row.eval = Some(EvalRow::new(
        &run,
        StrategyKind::Lemi,
        opened.bundle.manifest(),
        &options.eval,
        seconds,
        &report,
    ));
    Ok(())
}

/// Evaluates strategy `k` at the comparison's viewpoints; the report goes to `OUT/eval-k`.
fn eval(
    options: &CompareOptions,
    k: StrategyKind,
    gpu: &Arc<Gpu>,
    bundle: &Bundle,
    scene: Arc<Scene>,
) -> Result<EvalRow, StepError> {
    let manifest = bundle.manifest();
    let kind = StrategyKind::for_bundle(manifest, Some(k))?;
    let t = Instant::now();
    let run = lemi_eval::evaluate_strategy(gpu, bundle, scene, kind, &options.eval, |_, _, _| {})?;
    let seconds = t.elapsed().as_secs_f64();
    let dir = options.out.join(format!("eval-{}", k.name()));
    let report = lemi_eval::write_report(&dir, &run.result, &run.worst)?;
    Ok(EvalRow::new(
        &run,
        kind,
        manifest,
        &options.eval,
        seconds,
        &report,
    ))
}
