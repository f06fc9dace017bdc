//! Opening a baked bundle for rendering: the manifest, the scene it was baked from (from the
//! manifest's sources or `--scene`, checked against the fingerprint).

use std::path::Path;

use anyhow::{Context, Result};
use lemi_core::bundle::{manifest_path, Bundle};
use lemi_core::{Scene, UpAxis};

use crate::load::{load_scene, SceneArgs, UpArg};

/// Whether `path` is a bundle directory (holds `manifest.json`).
pub fn is_bundle(path: &str) -> bool {
    manifest_path(Path::new(path)).is_file()
}

/// The bundle and the scene it was baked from. `scene_override`: scene inputs to use instead of
/// the manifest's sources; they must have the bundle's fingerprint.
pub fn open(bundle: &Path, scene_override: &[String], quiet: bool) -> Result<(Bundle, Scene)> {
    let bundle = Bundle::open(bundle)?;
    let manifest = bundle.manifest();
    let up = if manifest.scene.up == "z" {
        UpArg::Z
    } else {
        UpArg::Y
    };
    let sources = if scene_override.is_empty() {
        manifest.scene.sources.clone()
    } else {
        scene_override.to_vec()
    };
    let fp = lemi_scene::fingerprint(&sources, UpAxis::from(up)).with_context(|| {
        format!(
            "fingerprinting the scene of {} ({}); pass --scene if it moved",
            bundle.dir().display(),
            sources.join(" ")
        )
    })?;
    bundle.expect_scene(&fp).with_context(|| {
        format!(
            "the scene {} is not the one {} was baked from; pass the original scene with --scene, \
             or bake again",
            sources.join(" "),
            bundle.dir().display()
        )
    })?;
    let (scene, _) = load_scene(
        &SceneArgs {
            scenes: sources,
            up,
        },
        quiet,
    )?;
    Ok((bundle, scene))
}
