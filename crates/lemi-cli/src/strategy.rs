//! `--strategy NAME` for `walk`, `eval` and `compare`: which far-field strategy draws a bundle.

use anyhow::{anyhow, Result};
use lemi_core::bundle::Manifest;
use lemi_strategy::{StrategyError, StrategyKind};

/// The strategy to run on a bundle ([`StrategyKind::for_bundle`]), its errors worded for the
/// `--strategy` flag.
pub fn kind_for(manifest: &Manifest, name: Option<&str>) -> Result<StrategyKind> {
    let requested = name
        .map(StrategyKind::parse)
        .transpose()
        .map_err(|e| anyhow!("--strategy: {e}"))?;
    StrategyKind::for_bundle(manifest, requested).map_err(|e| match e {
        StrategyError::NotBakedFor { requested, baked } => anyhow!(
            "--strategy {requested}: this bundle was baked for `{baked}`; bake one for `{requested}` with `lemi bake --strategy {requested}`"
        ),
        e => anyhow!("--strategy {e}"),
    })
}
