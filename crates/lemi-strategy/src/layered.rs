//! The layered strategies (`lemi`, `cubemap`, `equidistant`): a bundle baked for the strategy,
//! streamed by `lemi-runtime` (prediction, background loading, LRU cache, chunked uploads) and drawn
//! by [`ImpostorRenderer`]: the current cell's near geometry, then its impostor quads. A frame whose
//! cell is not ready (or not baked, or damaged) draws all geometry and says so.

use std::time::Duration;

use glam::DVec3;
use lemi_core::cell::CellId;
use lemi_gpu::{GpuScene, ImpostorRenderer, Renderer, UploadOptions};
use lemi_runtime::{Streamer, StreamerOptions};

use crate::{
    FrameRequest, Strategy, StrategyContext, StrategyError, StrategyFrame, StrategyKind,
    StrategyReport,
};

/// A layered bundle drawn through the streaming runtime.
pub struct LayeredStrategy {
    kind: StrategyKind,
    streamer: Streamer,
    impostors: ImpostorRenderer,
    renderer: Renderer,
    full: GpuScene,
    total_triangles: u64,
    texture_bytes: u64,
    uploaded_cells: u64,
    last_cell: Option<CellId>,
}

impl LayeredStrategy {
    /// Opens the bundle of `ctx` for streaming. `kind` must be the strategy the bundle was baked
    /// for (its manifest's `layering`).
    pub fn new(
        ctx: &StrategyContext,
        kind: StrategyKind,
        options: StreamerOptions,
    ) -> Result<LayeredStrategy, StrategyError> {
        if !kind.is_layered() {
            return Err(StrategyError::Invalid(format!(
                "`{kind}` is not drawn from a layered bundle"
            )));
        }
        let baked = bundle_strategy(ctx.bundle.manifest());
        if baked != kind {
            return Err(StrategyError::Invalid(format!(
                "{} was baked for the strategy `{baked}`, not `{kind}`: bake it with `lemi bake --strategy {kind}`",
                ctx.bundle.dir().display()
            )));
        }
        let streamer = Streamer::new(
            ctx.gpu.clone(),
            ctx.bundle.manifest().clone(),
            ctx.bundle.dir(),
            ctx.scene.clone(),
            ctx.materials.clone(),
            options,
        )?;
        let full = GpuScene::upload(&ctx.gpu, &ctx.scene, &UploadOptions::default())?;
        Ok(LayeredStrategy {
            kind,
            streamer,
            impostors: ImpostorRenderer::new(&ctx.gpu)?,
            renderer: Renderer::new(&ctx.gpu)?,
            full,
            total_triangles: ctx.scene.triangle_count(),
            texture_bytes: 0,
            uploaded_cells: 0,
            last_cell: None,
        })
    }
}

/// The strategy a layered bundle was baked for.
pub fn bundle_strategy(manifest: &lemi_core::bundle::Manifest) -> StrategyKind {
    use lemi_core::bundle::Layering;
    match manifest.params.layering {
        Layering::Optimal => StrategyKind::Lemi,
        Layering::Single => StrategyKind::Cubemap,
        Layering::Equidistant { .. } => StrategyKind::Equidistant,
        Layering::Hlod { .. } => StrategyKind::Hlod,
    }
}

impl Strategy for LayeredStrategy {
    fn kind(&self) -> StrategyKind {
        self.kind
    }

    fn preload(
        &mut self,
        eye: DVec3,
        velocity: DVec3,
        timeout: Duration,
    ) -> Result<(), StrategyError> {
        self.streamer.preload(eye, velocity, timeout)?;
        Ok(())
    }

    fn frame(&mut self, r: &FrameRequest<'_>) -> Result<StrategyFrame, StrategyError> {
        let state = self.streamer.frame(r.eye, r.velocity, r.dt);
        let warnings = state.warnings.clone();
        let cell = state.current_cell;
        let stalled = state.stalled;
        let cache_bytes = state.cache_bytes;
        let (frame, near, quads, fallback, gpu_ms) = match state.ready {
            Some(c) => {
                if cell != self.last_cell {
                    self.texture_bytes += c.texture_bytes();
                    self.uploaded_cells += 1;
                }
                (
                    self.impostors
                        .render_frame(c, r.view, r.options, r.needs_pixels())?,
                    c.near_triangles(),
                    c.quad_count() as u64,
                    false,
                    self.impostors.last_gpu_ms(),
                )
            }
            None => (
                self.renderer
                    .render_frame(&self.full, r.view, r.options, r.needs_pixels())?,
                self.total_triangles,
                0,
                true,
                self.renderer.last_gpu_ms(),
            ),
        };
        self.last_cell = cell;
        Ok(StrategyFrame {
            frame,
            cell,
            near_triangles: near,
            far_primitives: quads,
            stalled,
            fallback,
            cache_bytes,
            regenerations: 0,
            warnings,
            gpu_ms,
            error_px: None,
        })
    }

    fn report(&self) -> StrategyReport {
        let s = self.streamer.stats();
        StrategyReport {
            prepare_seconds: 0.0,
            prepared_cells: s.uploads,
            regenerations: 0,
            stalls: s.stalls,
            loads: s.loads,
            evictions: s.evictions,
            peak_bytes: s.peak_cache_bytes,
            texture_bytes_per_cell: if self.uploaded_cells > 0 {
                self.texture_bytes as f64 / self.uploaded_cells as f64
            } else {
                0.0
            },
        }
    }
}
