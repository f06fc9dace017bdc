//! `--strategy NAME` for `walk`, `eval` and `compare`: which far-field strategy draws a bundle.

use anyhow::{bail, Result};
use lemi_core::bundle::Manifest;
use lemi_strategy::layered::bundle_strategy;
use lemi_strategy::StrategyKind;

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
