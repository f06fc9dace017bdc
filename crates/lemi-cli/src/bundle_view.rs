//! Opening a baked bundle for rendering ([`lemi_scene::open_bundle`]) with a progress bar, its
//! errors worded for `--scene`.

use std::path::Path;

use anyhow::Result;
use lemi_core::bundle::{manifest_path, Bundle};
use lemi_core::Scene;
use lemi_scene::OpenBundleError;

use crate::load::{print_warnings, progress_bar};

/// Whether `path` is a bundle directory (holds `manifest.json`).
pub fn is_bundle(path: &str) -> bool {
    manifest_path(Path::new(path)).is_file()
}

/// The bundle and the scene it was baked from. `scene_override`: scene inputs to use instead of
/// the manifest's sources; they must have the bundle's fingerprint.
pub fn open(bundle: &Path, scene_override: &[String], quiet: bool) -> Result<(Bundle, Scene)> {
    let (bar, progress) = progress_bar(quiet);
    let opened = lemi_scene::open_bundle(bundle, scene_override, Some(progress));
    bar.finish_and_clear();
    let opened = opened.map_err(|e| match e {
        OpenBundleError::Fingerprint {
            bundle,
            sources,
            source,
        } => anyhow::Error::new(source).context(format!(
            "fingerprinting the scene of {} ({}); pass --scene if it moved",
            bundle.display(),
            sources.join(" ")
        )),
        OpenBundleError::WrongScene {
            bundle,
            sources,
            scheme,
            source,
        } => anyhow::Error::new(source).context(format!(
            "the scene {} is not the one {} was baked from; pass the original scene with --scene, \
             or bake again{}",
            sources.join(" "),
            bundle.display(),
            lemi_scene::legacy_note(scheme)
        )),
        e => e.into(),
    })?;
    print_warnings(&opened.report);
    Ok((opened.bundle, opened.scene))
}
