//! `--strategy NAME` for `walk`, `eval` and `compare`: which far-field strategy draws a bundle.

use std::sync::Arc;

use anyhow::{bail, Context, Result};
use lemi_core::bundle::{Bundle, Manifest};
use lemi_core::Scene;
use lemi_eval::{EvalOptions, EvalRun, StrategyCells};
use lemi_gpu::{Gpu, GpuMaterials, RenderOptions};
use lemi_runtime::StreamerOptions;
use lemi_strategy::dynamic::{DynamicOptions, DynamicStrategy};
use lemi_strategy::layered::{bundle_strategy, LayeredStrategy};
use lemi_strategy::warp::{WarpOptions, WarpStrategy};
use lemi_strategy::{Strategy, StrategyContext, StrategyKind};

/// The strategy to run on a bundle: `name` if given (checked against what the bundle can serve),
/// else the strategy the bundle was baked for.
pub fn kind_for(manifest: &Manifest, name: Option<&str>) -> Result<StrategyKind> {
    let baked = bundle_strategy(manifest);
    let Some(name) = name else {
        return Ok(baked);
    };
    let kind = StrategyKind::parse(name).map_err(|e| anyhow::anyhow!("--strategy: {e}"))?;
    if kind.is_layered() && kind != baked {
        bail!(
            "--strategy {kind}: this bundle was baked for `{baked}`; bake one for `{kind}` with `lemi bake --strategy {kind}`"
        );
    }
    if !kind.is_layered() && baked != StrategyKind::Lemi {
        bail!(
            "--strategy {kind} takes its cells and near lists from a `lemi` bundle; this one was baked for `{baked}`"
        );
    }
    Ok(kind)
}

/// What the strategies of `bundle` are built from: the GPU, the bundle and its scene with the
/// scene's materials uploaded.
pub fn context(gpu: &Arc<Gpu>, bundle: &Bundle, scene: Arc<Scene>) -> Result<StrategyContext> {
    let materials = GpuMaterials::upload(gpu, &scene.materials, &scene.textures)
        .context("uploading the scene's materials")?;
    Ok(StrategyContext {
        gpu: gpu.clone(),
        bundle: bundle.clone(),
        scene,
        materials: Arc::new(materials),
    })
}

/// Opens strategy `kind` on the bundle of `ctx`.
pub fn open(
    ctx: &StrategyContext,
    kind: StrategyKind,
    streamer: StreamerOptions,
) -> Result<Box<dyn Strategy>> {
    Ok(match kind {
        StrategyKind::Lemi | StrategyKind::Cubemap | StrategyKind::Equidistant => {
            Box::new(LayeredStrategy::new(ctx, kind, streamer)?)
        }
        StrategyKind::Warp => Box::new(WarpStrategy::new(ctx, WarpOptions::default())?),
        StrategyKind::Dynamic => Box::new(DynamicStrategy::new(ctx, DynamicOptions::default())?),
    })
}

/// The certificate of strategy `kind` on `bundle`: layered bundles through
/// [`lemi_eval::evaluate_bundle`] (their own texels' depths), the others through the strategy
/// ([`StrategyCells`]). `progress(done, total, what)` as there.
pub fn evaluate(
    gpu: &Arc<Gpu>,
    bundle: &Bundle,
    scene: Arc<Scene>,
    kind: StrategyKind,
    options: &EvalOptions,
    progress: impl FnMut(usize, usize, &str),
) -> Result<EvalRun> {
    if kind.is_layered() {
        return Ok(lemi_eval::evaluate_bundle(
            gpu, bundle, &scene, options, progress,
        )?);
    }
    let ctx = context(gpu, bundle, scene.clone())?;
    let mut strategy = open(&ctx, kind, Default::default())?;
    let render = RenderOptions {
        clear: options.clear,
        ..Default::default()
    };
    let mut cells = StrategyCells::new(strategy.as_mut(), render);
    Ok(lemi_eval::evaluate_with(
        gpu, bundle, &scene, options, &mut cells, progress,
    )?)
}
