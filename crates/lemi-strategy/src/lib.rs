//! Far-field strategies behind one interface, so that `lemi walk`, `lemi eval` and `lemi compare`
//! run every impostor technique of the literature the same way (`--strategy NAME`).
//!
//! A strategy draws one frame of a cell: the cell's near geometry (the triangles the bundle's cell
//! file lists as near field, the same for every strategy of a bundle) and, in its own way, the far
//! field. The strategies:
//!
//! | name | what | bakes | source |
//! |---|---|---|---|
//! | `lemi` | optimal layered environment maps | per cell (`lemi bake`) | GI 2002, TR-186-2-02-04 |
//! | `cubemap` | one layer, near field where one layer puts it | per cell (`lemi bake --strategy cubemap`) | GI 2002 sec. 4.3 |
//! | `equidistant` | the same layer count spaced uniformly in depth, overlapping depth ranges, ordinary rasterization, no gap filling | per cell (`lemi bake --strategy equidistant`) | Schaufler 1998 |
//! | `warp` | colour + depth + camera at the cell's sample point, forward-mapped depth, hole filling, backward-mapped colour | on first use of a cell | terrain impostors report |
//! | `dynamic` | one billboard per far object, regenerated when a validity angle exceeds a pixel | no (at run time) | Schaufler 1995, RTR sec. 10.7.1 |
//! | `hlod` | the far field as geometry simplified with meshoptimizer in distance bands within the same α | per cell (`lemi bake --strategy hlod`) | Garland & Heckbert 1997; 3D Tiles' geometric error |
//!
//! The first three are *layered bundles*: they differ only in how the bake placed and recorded the
//! layers, and are drawn by [`layered::LayeredStrategy`] (the streaming runtime). `warp` and
//! `dynamic` use a `lemi` bundle for its grid and near lists and build their far field themselves.

pub mod dynamic;
pub mod hlod;
pub mod layered;
pub mod portal;
pub mod warp;

use std::sync::Arc;

use glam::DVec3;
use lemi_core::bundle::Bundle;
use lemi_core::camera::View;
use lemi_core::cell::CellId;
use lemi_core::Scene;
use lemi_gpu::{Frame, Gpu, GpuMaterials, RenderOptions};
use serde::{Deserialize, Serialize};

/// Every strategy name, in the order of the comparison tables.
pub const STRATEGY_NAMES: [&str; 6] = ["lemi", "cubemap", "equidistant", "warp", "dynamic", "hlod"];

/// A strategy, by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StrategyKind {
    Lemi,
    Cubemap,
    Equidistant,
    Warp,
    Dynamic,
    Hlod,
}

impl StrategyKind {
    pub const ALL: [StrategyKind; 6] = [
        StrategyKind::Lemi,
        StrategyKind::Cubemap,
        StrategyKind::Equidistant,
        StrategyKind::Warp,
        StrategyKind::Dynamic,
        StrategyKind::Hlod,
    ];

    pub fn name(self) -> &'static str {
        match self {
            StrategyKind::Lemi => "lemi",
            StrategyKind::Cubemap => "cubemap",
            StrategyKind::Equidistant => "equidistant",
            StrategyKind::Warp => "warp",
            StrategyKind::Dynamic => "dynamic",
            StrategyKind::Hlod => "hlod",
        }
    }

    /// Parses a strategy name; an unknown name is an error listing the known ones.
    pub fn parse(name: &str) -> Result<StrategyKind, StrategyError> {
        StrategyKind::ALL
            .into_iter()
            .find(|k| k.name() == name.trim())
            .ok_or_else(|| StrategyError::UnknownStrategy(name.to_string()))
    }

    /// Whether the strategy is drawn from a layered bundle baked for it.
    pub fn is_layered(self) -> bool {
        matches!(
            self,
            StrategyKind::Lemi | StrategyKind::Cubemap | StrategyKind::Equidistant
        )
    }

    /// Whether the strategy is drawn from a bundle baked for it (the layered strategies and
    /// `hlod`); `warp` and `dynamic` run from a `lemi` bundle.
    pub fn is_baked(self) -> bool {
        self.is_layered() || self == StrategyKind::Hlod
    }

    /// The strategy to run on the bundle of `manifest`: `requested` if given and the bundle can
    /// serve it, else the strategy the bundle was baked for ([`layered::bundle_strategy`]). A
    /// layered strategy (and `hlod`) needs a bundle baked for it; `warp` and `dynamic` take their cells and
    /// near lists from a `lemi` bundle.
    pub fn for_bundle(
        manifest: &lemi_core::bundle::Manifest,
        requested: Option<StrategyKind>,
    ) -> Result<StrategyKind, StrategyError> {
        let baked = layered::bundle_strategy(manifest);
        let Some(requested) = requested else {
            return Ok(baked);
        };
        if requested.is_baked() && requested != baked {
            return Err(StrategyError::NotBakedFor { requested, baked });
        }
        if !requested.is_baked() && baked != StrategyKind::Lemi {
            return Err(StrategyError::NeedsLemiBundle { requested, baked });
        }
        Ok(requested)
    }
}

impl std::fmt::Display for StrategyKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Errors of the strategies.
#[derive(Debug, thiserror::Error)]
pub enum StrategyError {
    #[error(
        "unknown strategy `{0}`: the strategies are lemi, cubemap, equidistant, warp, dynamic, hlod"
    )]
    UnknownStrategy(String),
    /// A layered strategy asked of a bundle baked for another one.
    #[error("{requested}: this bundle was baked for `{baked}`")]
    NotBakedFor {
        requested: StrategyKind,
        baked: StrategyKind,
    },
    /// `warp` or `dynamic` asked of a bundle that is not a `lemi` bundle.
    #[error("{requested} takes its cells and near lists from a `lemi` bundle; this one was baked for `{baked}`")]
    NeedsLemiBundle {
        requested: StrategyKind,
        baked: StrategyKind,
    },
    /// An option of a strategy is out of range: the strategy, the option (its field name in the
    /// strategy's options struct, so that a front end can name its own flag or key) and what is
    /// wrong, with the value (e.g. `must be 0..=4 (got 9)`).
    #[error("{strategy} option `{option}` {message}")]
    BadOption {
        strategy: StrategyKind,
        option: &'static str,
        message: String,
    },
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Gpu(#[from] lemi_gpu::GpuError),
    #[error(transparent)]
    Runtime(#[from] lemi_runtime::RuntimeError),
}

/// What every strategy is built from: the GPU, the bundle (grid, near lists, parameters) and the
/// scene it was baked from, with the scene's materials already on the GPU.
#[derive(Clone)]
pub struct StrategyContext {
    pub gpu: Arc<Gpu>,
    pub bundle: Bundle,
    pub scene: Arc<Scene>,
    pub materials: Arc<GpuMaterials>,
}

/// One frame's request.
#[derive(Clone, Copy, Debug)]
pub struct FrameRequest<'a> {
    pub eye: DVec3,
    /// Observer velocity (m/s), for prefetching.
    pub velocity: DVec3,
    /// Seconds since the previous frame.
    pub dt: f64,
    pub view: &'a View,
    pub options: &'a RenderOptions,
    /// Also measure the per-pixel geometric error ([`StrategyFrame::error_px`]) if the strategy
    /// can (evaluation only; may be slow).
    pub measure_error: bool,
    /// Read the frame's pixels back ([`StrategyFrame::frame`]). Without it a strategy draws the
    /// frame and waits for the GPU, as a runtime that presents its frames does, and returns no
    /// pixels where it can (a walk times its frames so, reading back only the frames it keeps);
    /// strategies that finish the frame on the CPU read it back anyway.
    pub read_back: bool,
}

impl FrameRequest<'_> {
    /// Whether the frame's pixels are needed: asked for, or for measuring the error.
    pub fn needs_pixels(&self) -> bool {
        self.read_back || self.measure_error
    }
}

/// One drawn frame and what it took.
#[derive(Clone, Debug)]
pub struct StrategyFrame {
    /// The frame's pixels; `None` when the request did not ask for them
    /// ([`FrameRequest::read_back`]) and the strategy drew the frame on the GPU alone.
    pub frame: Option<Frame>,
    /// Id of the view cell the eye is in, if any.
    pub cell: Option<CellId>,
    /// Near-field triangles drawn (every triangle of the scene on a fallback frame).
    pub near_triangles: u64,
    /// Far-field primitives drawn: quads (layered), billboards (dynamic), warped samples (warp).
    pub far_primitives: u64,
    /// The frame had to wait for its cell's far field, or drew all geometry instead.
    pub stalled: bool,
    /// The frame was drawn with all geometry (no far field available).
    pub fallback: bool,
    /// Bytes the strategy holds for its far field after the frame (CPU + GPU).
    pub cache_bytes: u64,
    /// Impostors regenerated during the frame (dynamic); far fields baked during the frame (warp).
    pub regenerations: u64,
    /// Warnings raised during the frame.
    pub warnings: Vec<String>,
    /// GPU time of the frame's render passes (timestamp queries), when the whole frame is GPU
    /// work and the adapter has timestamps; `None` otherwise (warp and dynamic do CPU work per
    /// frame, so only their wall-clock time is meaningful).
    pub gpu_ms: Option<f64>,
    /// With [`FrameRequest::measure_error`]: per pixel (row-major), the angle in output pixels
    /// between where the pixel's surface point truly is and where the frame shows it; `NaN` where
    /// it does not apply (background, near geometry). `None` if the strategy cannot measure it.
    pub error_px: Option<Vec<f32>>,
}

impl StrategyFrame {
    /// The frame's pixels; an error when the request did not ask for them
    /// ([`FrameRequest::read_back`]).
    pub fn pixels(&self) -> Result<&Frame, StrategyError> {
        self.frame.as_ref().ok_or_else(|| {
            StrategyError::Invalid("the frame was drawn without reading its pixels back".into())
        })
    }
}

/// Totals of a strategy over its life (for the comparison tables).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StrategyReport {
    /// Seconds spent preparing far fields (warp: recording sample images); layered bundles
    /// report their bake separately.
    pub prepare_seconds: f64,
    /// Far fields prepared.
    pub prepared_cells: u64,
    /// Impostors regenerated (dynamic).
    pub regenerations: u64,
    /// Frames that stalled.
    pub stalls: u64,
    /// Cells loaded from disk (layered).
    pub loads: u64,
    pub evictions: u64,
    /// The most bytes held for the far field at once.
    pub peak_bytes: u64,
    /// Texture bytes per prepared cell (mean), what the GPU holds for one cell's far field.
    pub texture_bytes_per_cell: f64,
}

/// A far-field strategy: draws frames along a path.
pub trait Strategy {
    fn kind(&self) -> StrategyKind;
    /// Gets ready for a path starting at `eye` (loads or prepares the first cells), waiting at
    /// most `timeout`.
    fn preload(
        &mut self,
        eye: DVec3,
        velocity: DVec3,
        timeout: std::time::Duration,
    ) -> Result<(), StrategyError>;
    /// Draws one frame.
    fn frame(&mut self, request: &FrameRequest<'_>) -> Result<StrategyFrame, StrategyError>;
    /// Totals so far.
    fn report(&self) -> StrategyReport;
}

impl StrategyContext {
    /// The context of `bundle` and the scene it was baked from, with the scene's materials
    /// uploaded to `gpu`.
    pub fn new(
        gpu: Arc<Gpu>,
        bundle: Bundle,
        scene: Arc<Scene>,
    ) -> Result<StrategyContext, StrategyError> {
        let materials = Arc::new(GpuMaterials::upload(
            &gpu,
            &scene.materials,
            &scene.textures,
        )?);
        Ok(StrategyContext {
            gpu,
            bundle,
            scene,
            materials,
        })
    }
}

/// Opens strategy `kind` on the bundle of `ctx` with each strategy's default options
/// (`streamer`: how the layered strategies stream their cells).
pub fn open(
    ctx: &StrategyContext,
    kind: StrategyKind,
    streamer: lemi_runtime::StreamerOptions,
) -> Result<Box<dyn Strategy>, StrategyError> {
    Ok(match kind {
        StrategyKind::Lemi | StrategyKind::Cubemap | StrategyKind::Equidistant => {
            Box::new(layered::LayeredStrategy::new(ctx, kind, streamer)?)
        }
        StrategyKind::Warp => Box::new(warp::WarpStrategy::new(ctx, Default::default())?),
        StrategyKind::Dynamic => Box::new(dynamic::DynamicStrategy::new(ctx, Default::default())?),
        StrategyKind::Hlod => Box::new(hlod::HlodStrategy::new(ctx)?),
    })
}
