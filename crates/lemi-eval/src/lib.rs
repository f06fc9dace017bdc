//! `lemi-eval`: the metrics, aggregation and report of `lemi eval`.
//!
//! The eval job renders, for sampled viewpoints of each baked view cell, a reference image (all
//! geometry) and an impostor image (what the runtime shows), both as [`lemi_gpu::Frame`], plus a
//! per-pixel geometric error in output pixels. This crate turns those into numbers and a report:
//!
//! - [`image_metrics`]: FLIP (NVIDIA's perceptual difference, via `nv-flip`), PSNR, SSIM
//!   (Wang et al. 2004), coverage and crack detection, all on a pair of frames;
//! - [`stats`]: [`PixelErrorStats`], a mergeable accumulator of per-pixel errors (count, max, mean,
//!   p99, share above 1 px, histogram), aggregated view → cell → bundle;
//! - [`evaluate`]: [`evaluate_view`], every metric of one viewpoint in one call;
//! - [`report`]: [`ViewResult`] / [`CellResult`] / [`BundleResult`], the [`verdict`] line, and
//!   [`write_report`] (`report.json` + a self-contained static `index.html`).
//!
//! No function here panics on bad input: mismatched sizes and malformed frames are [`EvalError`]s.

pub mod compare;
pub mod evaluate;
pub mod image_metrics;
pub mod report;
pub mod run;
pub mod stats;
pub mod strategy_cells;

pub use compare::{layered_crack_tolerance, side_by_side, SideBySide};
pub use evaluate::{evaluate_view, ViewEval};
pub use image_metrics::{
    coverage, crack_pixels, flip, mse_from_psnr, mse_rgb, ppd_default, ppd_for_monitor,
    ppd_for_view, psnr, psnr_from_mse, silhouettes, silhouettes_within, ssim, Coverage, CrackStats,
    FlipResult, GuardBand, SilhouetteStats, MAX_CRACK_SAMPLES,
};
pub use lemi_gpu::Frame;
pub use report::{
    severity_cmp, verdict, write_report, Aggregate, BundleResult, CellResult, ErrorSummary,
    OutlineStats, ViewResult, WorstSet, WorstView, WORST_PER_BUNDLE, WORST_PER_CELL,
};
pub use run::{
    camera, evaluate_bundle, evaluate_bundle_against, evaluate_with, output_view, turned_camera,
    AgainstResult, CellRenderer, EvalOptions, EvalRun, RenderedView, TextureFootprint,
    ViewpointSet,
};
pub use stats::{Histogram, PixelErrorStats};
pub use strategy_cells::{evaluate_strategy, StrategyCells};

/// Everything that can go wrong while evaluating or writing a report.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// Two images that must have the same size do not.
    #[error(
        "image size mismatch: {what_a} is {a_width}x{a_height}, {what_b} is {b_width}x{b_height}"
    )]
    SizeMismatch {
        what_a: &'static str,
        a_width: u32,
        a_height: u32,
        what_b: &'static str,
        b_width: u32,
        b_height: u32,
    },
    /// A buffer does not have the length its image size implies.
    #[error("{what}: a {width}x{height} image needs {expected} {unit}, the buffer has {actual}")]
    BufferLength {
        what: &'static str,
        width: u32,
        height: u32,
        expected: usize,
        actual: usize,
        unit: &'static str,
    },
    /// Reading or writing a report file failed.
    #[error("{context}: {source}")]
    Io {
        context: String,
        #[source]
        source: std::io::Error,
    },
    /// Encoding an image or JSON failed.
    #[error("encoding {what}: {message}")]
    Encode { what: String, message: String },
    /// The eval job failed (bundle, scene, GPU), with the reason.
    #[error("{0}")]
    Job(String),
}

impl EvalError {
    pub(crate) fn io(context: impl Into<String>, source: std::io::Error) -> EvalError {
        EvalError::Io {
            context: context.into(),
            source,
        }
    }
}
