//! Evaluating any strategy with `lemi eval`'s viewpoints and metrics: [`StrategyCells`] adapts a
//! [`Strategy`] to [`crate::CellRenderer`].
//!
//! Layered bundles are evaluated by [`crate::evaluate_bundle`], which re-records the layers'
//! depths to measure the error of every impostor texel and judges cracks against one slab. The
//! other strategies measure their own per-pixel error ([`lemi_strategy::FrameRequest::measure_error`]);
//! their cracks are the pixels that show background where the reference shows a surface (they
//! have no slabs to bound a see-through depth by).

use glam::DVec3;
use lemi_core::camera::View;
use lemi_core::cell::ViewCell;
use lemi_gpu::RenderOptions;
use lemi_strategy::{FrameRequest, Strategy};

use crate::{CellRenderer, EvalError, RenderedView};

/// A strategy as the evaluation's renderer: every view is one frame with the error measured.
pub struct StrategyCells<'a> {
    pub strategy: &'a mut dyn Strategy,
    pub options: RenderOptions,
    /// Impostors regenerated or far fields prepared over the evaluation.
    pub regenerations: u64,
    /// Views whose strategy frame fell back to all geometry.
    pub fallback_views: u64,
}

impl<'a> StrategyCells<'a> {
    pub fn new(strategy: &'a mut dyn Strategy, options: RenderOptions) -> StrategyCells<'a> {
        StrategyCells {
            strategy,
            options,
            regenerations: 0,
            fallback_views: 0,
        }
    }
}

impl CellRenderer for StrategyCells<'_> {
    fn begin_cell(&mut self, cell: &ViewCell) -> Result<(), EvalError> {
        self.strategy
            .preload(
                cell.center,
                DVec3::ZERO,
                std::time::Duration::from_secs(600),
            )
            .map_err(|e| EvalError::Job(format!("preparing cell {}: {e}", cell.id())))
    }

    fn render(&mut self, view: &View, eye: DVec3) -> Result<RenderedView, EvalError> {
        let request = FrameRequest {
            eye,
            velocity: DVec3::ZERO,
            dt: 1.0 / 30.0,
            view,
            options: &self.options,
            measure_error: true,
            read_back: true,
        };
        let f = self
            .strategy
            .frame(&request)
            .map_err(|e| EvalError::Job(format!("{} frame: {e}", self.strategy.kind())))?;
        self.regenerations += f.regenerations;
        if f.fallback {
            self.fallback_views += 1;
        }
        let frame = f.frame.ok_or_else(|| {
            EvalError::Job(format!(
                "{} frame: the strategy returned no pixels",
                self.strategy.kind()
            ))
        })?;
        let n = frame.rgba.len() / 4;
        Ok(RenderedView {
            frame,
            error_px: f.error_px.unwrap_or_else(|| vec![f32::NAN; n]),
            gap_filled: None,
        })
    }

    fn crack_tolerance(&self, _far: f32) -> f32 {
        f32::INFINITY
    }
}

/// The certificate of strategy `kind` on `bundle`: layered bundles through
/// [`crate::evaluate_bundle`] (their own texels' depths), the others through the strategy
/// ([`StrategyCells`]); `progress(done, total, what)` as there.
pub fn evaluate_strategy(
    gpu: &std::sync::Arc<lemi_gpu::Gpu>,
    bundle: &lemi_core::bundle::Bundle,
    scene: std::sync::Arc<lemi_core::Scene>,
    kind: lemi_strategy::StrategyKind,
    options: &crate::EvalOptions,
    progress: impl FnMut(usize, usize, &str),
) -> Result<crate::EvalRun, EvalError> {
    if kind.is_layered() {
        return crate::evaluate_bundle(gpu, bundle, &scene, options, progress);
    }
    let job = |what: &str| {
        let what = what.to_string();
        move |e: lemi_strategy::StrategyError| EvalError::Job(format!("{what}: {e}"))
    };
    let ctx = lemi_strategy::StrategyContext::new(gpu.clone(), bundle.clone(), scene.clone())
        .map_err(job("preparing the strategy"))?;
    let mut strategy =
        lemi_strategy::open(&ctx, kind, Default::default()).map_err(job("opening the strategy"))?;
    let render = RenderOptions {
        clear: options.clear,
        ..Default::default()
    };
    let mut cells = StrategyCells::new(strategy.as_mut(), render);
    crate::evaluate_with(gpu, bundle, &scene, options, &mut cells, progress)
}
