//! The typed rows of a comparison: what each strategy's bake, walk and evaluation measured, as
//! `comparison.json` holds them.

use std::path::{Path, PathBuf};

use lemi_core::bundle::Manifest;
use lemi_core::compress::TextureFormat;
use lemi_eval::{AgainstResult, EvalOptions, EvalRun, TextureFootprint};
use lemi_strategy::StrategyKind;
use lemi_walk::{FrameRecord, WalkSummary};
use serde::Serialize;

/// What a layered strategy's bake did (from the bake's summary).
#[derive(Clone, Debug, Serialize)]
pub struct BakeRow {
    pub bundle: PathBuf,
    pub strategy: StrategyKind,
    pub adapter: String,
    /// Cells in the bundle (baked now or before).
    pub cells: usize,
    pub baked: usize,
    pub skipped: usize,
    pub seconds: f64,
    pub load_seconds: f64,
    pub prepare_seconds: f64,
    /// Bytes of the cell files.
    pub bytes: u64,
    pub warnings: Vec<String>,
    /// Per cell, what `lemi bake --json` reports for it.
    pub per_cell: Vec<lemi_bake::CellReport>,
}

/// A strategy's evaluation: the bundle totals of `lemi eval --json` without the per-view detail
/// (kept in each evaluation's own report).
#[derive(Clone, Debug, Serialize)]
pub struct EvalRow {
    pub views: u64,
    pub error_pixels: u64,
    /// `None` (JSON `null`): infinite.
    pub max_error_px: Option<f32>,
    pub p99_error_px: Option<f32>,
    pub mean_error_px: Option<f64>,
    pub above_1px: f64,
    pub crack_pixels: u64,
    pub views_with_cracks: u64,
    pub mean_flip: f32,
    pub max_flip: f32,
    pub coverage: f64,
    pub min_coverage: f64,
    /// `None`: identical images (infinite PSNR).
    pub psnr: Option<f64>,
    pub ssim: f64,
    pub min_ssim: f64,
    pub verdict: String,
    pub strategy: StrategyKind,
    pub placement_max_error_px: f32,
    pub placement_p99_error_px: f32,
    pub gap_filled_pixels: u64,
    pub size: [u32; 2],
    pub fov_x_deg: f64,
    pub seconds: f64,
    pub report: PathBuf,
    /// What the evaluated cells take on disk and in texture memory (layered strategies).
    pub textures: Option<TextureFootprint>,
}

impl EvalRow {
    /// The row of evaluation `run` of strategy `kind` on the bundle of `manifest` with `options`,
    /// which took `seconds` and wrote its report to `report`.
    pub fn new(
        run: &EvalRun,
        kind: StrategyKind,
        manifest: &Manifest,
        options: &EvalOptions,
        seconds: f64,
        report: &Path,
    ) -> EvalRow {
        let (w, h, fov) = lemi_eval::output_view(manifest, options);
        let s = &run.result.summary;
        let finite32 = |x: f32| x.is_finite().then_some(x);
        let finite64 = |x: f64| x.is_finite().then_some(x);
        EvalRow {
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
            report: report.to_path_buf(),
            textures: run.textures.clone(),
        }
    }
}

/// The `lemi` bake in one more texture format (`lemi compare --texture-formats`): what it takes
/// and what it costs in image, against the reference and against the PNG bake of the same
/// cells (the `lemi` strategy's row).
#[derive(Clone, Debug, Serialize)]
pub struct FormatRow {
    pub format: TextureFormat,
    pub bundle: PathBuf,
    pub bake: Option<BakeRow>,
    pub eval: Option<EvalRow>,
    /// The same views against the PNG bake's.
    pub against_png: Option<AgainstResult>,
    pub errors: Vec<String>,
}

/// Seconds per baked cell spent encoding the macro-textures (the bake stage named by the
/// format), and the whole bake's seconds per cell.
pub(crate) fn encode_seconds_per_cell(bake: &BakeRow, format: TextureFormat) -> Option<(f64, f64)> {
    let baked: Vec<_> = bake
        .per_cell
        .iter()
        .filter(|c| c.status == "baked")
        .collect();
    if baked.is_empty() {
        return None;
    }
    let n = baked.len() as f64;
    let encode: f64 = baked
        .iter()
        .filter_map(|c| c.stage_seconds.get(format.name()))
        .sum();
    let whole: f64 = baked.iter().map(|c| c.seconds).sum();
    Some((encode / n, whole / n))
}

/// One strategy's row of numbers.
#[derive(Debug, Serialize)]
pub struct Row {
    pub strategy: StrategyKind,
    pub bundle: Option<PathBuf>,
    pub bake: Option<BakeRow>,
    pub walk: Option<WalkSummary>,
    pub eval: Option<EvalRow>,
    /// What failed, each with its causes (shown in the tables).
    pub errors: Vec<String>,
    /// The walk's impostor frames (for the plot).
    #[serde(skip)]
    pub frames: Vec<FrameRecord>,
}

/// The all-geometry replays' frame times: unculled (`median_ms`, `p99_ms`, `gpu_median_ms`) and
/// geometry-culled (`culled_*`, the baseline speed-ups are quoted against).
#[derive(Clone, Debug, Default, Serialize)]
pub struct GeometryTimes {
    pub median_ms: Option<f64>,
    pub p99_ms: Option<f64>,
    pub gpu_median_ms: Option<f64>,
    pub culled_median_ms: Option<f64>,
    pub culled_p99_ms: Option<f64>,
    pub culled_gpu_median_ms: Option<f64>,
    /// Mean triangles a geometry-culled frame submitted.
    pub culled_mean_triangles: Option<f64>,
}

/// `comparison.json`.
#[derive(Debug, Serialize)]
pub struct Comparison<'a> {
    pub command: &'a str,
    pub seconds: f64,
    pub strategies: &'a [Row],
    pub geometry: Option<GeometryTimes>,
    /// `lemi` baked in further texture formats (`--texture-formats`).
    pub texture_formats: &'a [FormatRow],
}
