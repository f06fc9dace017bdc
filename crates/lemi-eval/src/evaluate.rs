//! [`evaluate_view`]: every metric of one viewpoint from its reference frame, impostor frame and
//! per-pixel geometric error, in one call; [`ViewEval::result`] turns it into a report row. It only
//! combines [`crate::image_metrics`] and [`crate::stats`].

use lemi_gpu::Frame;

use crate::image_metrics::{self, check_pair, Coverage, CrackStats, FlipResult, SilhouetteStats};
use crate::report::{ErrorSummary, ViewResult};
use crate::stats::PixelErrorStats;
use crate::EvalError;

/// All metrics of one viewpoint.
#[derive(Clone, Debug)]
pub struct ViewEval {
    /// Statistics of the geometric error (pixels; NaN entries ignored).
    pub error: PixelErrorStats,
    pub flip: FlipResult,
    pub psnr: f64,
    pub ssim: f64,
    pub coverage: Coverage,
    pub cracks: CrackStats,
    pub silhouette: SilhouetteStats,
}

/// Computes all metrics of one viewpoint. `geometric_error_px` has one entry per pixel (row-major,
/// NaN where not applicable); `far_tolerance` is passed to [`image_metrics::crack_pixels`]; `ppd` to
/// [`image_metrics::flip`].
pub fn evaluate_view(
    reference: &Frame,
    impostor: &Frame,
    geometric_error_px: &[f32],
    far_tolerance: &dyn Fn(usize, f32) -> f32,
    ppd: f32,
) -> Result<ViewEval, EvalError> {
    let n = check_pair(reference, impostor)?;
    if geometric_error_px.len() != n {
        return Err(EvalError::BufferLength {
            what: "geometric error",
            width: reference.width,
            height: reference.height,
            expected: n,
            actual: geometric_error_px.len(),
            unit: "values",
        });
    }
    Ok(ViewEval {
        error: PixelErrorStats::from_values(geometric_error_px),
        flip: image_metrics::flip(reference, impostor, ppd)?,
        psnr: image_metrics::psnr(reference, impostor)?,
        ssim: image_metrics::ssim(reference, impostor)?,
        coverage: image_metrics::coverage(reference, impostor)?,
        cracks: image_metrics::crack_pixels(reference, impostor, far_tolerance)?,
        silhouette: image_metrics::silhouettes(reference, impostor)?,
    })
}

impl ViewEval {
    /// The report row of this view.
    pub fn result(
        &self,
        cell: impl Into<String>,
        viewpoint: impl Into<String>,
        eye: [f64; 3],
        dir: [f64; 3],
    ) -> ViewResult {
        ViewResult {
            cell: cell.into(),
            viewpoint: viewpoint.into(),
            eye,
            dir,
            error: ErrorSummary::of(&self.error),
            crack_pixels: self.cracks.count,
            crack_samples: self.cracks.first.iter().map(|&(x, y)| [x, y]).collect(),
            mean_flip: self.flip.mean,
            psnr: self.psnr,
            ssim: self.ssim,
            coverage: self.coverage.share,
            silhouette: ErrorSummary::of(&self.silhouette.distances),
            displacement: ErrorSummary::of(&self.silhouette.displacement),
            false_coverage_pixels: self.silhouette.false_coverage,
            silhouette_floor: None,
            pixels: self.flip.width as u64 * self.flip.height as u64,
        }
    }
}
