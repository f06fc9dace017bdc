//! Opening a baked bundle together with the scene it was baked from: the scene is loaded from the
//! manifest's sources (or from other inputs that must have the same fingerprint), in the up axis
//! the bundle was baked with, so that whatever draws the bundle draws it over the right geometry.

use std::path::{Path, PathBuf};

use lemi_core::bundle::{Bundle, BundleError};
use lemi_core::{Scene, UpAxis};

use crate::import::{load_with_report, ImportReport};
use crate::{fingerprint, LoadOptions, ProgressFn, SceneError};

/// A bundle and the scene it was baked from.
#[derive(Debug)]
pub struct OpenedBundle {
    pub bundle: Bundle,
    pub scene: Scene,
    /// What the import skipped or warned about.
    pub report: ImportReport,
}

/// Why [`open_bundle`] failed; each names the bundle or the scene inputs.
#[derive(Debug, thiserror::Error)]
pub enum OpenBundleError {
    /// The bundle itself (its manifest) cannot be opened.
    #[error(transparent)]
    Bundle(#[from] BundleError),
    /// The scene inputs cannot be fingerprinted (moved, unreadable).
    #[error("fingerprinting the scene of {} ({})", bundle.display(), sources.join(" "))]
    Fingerprint {
        bundle: PathBuf,
        sources: Vec<String>,
        #[source]
        source: SceneError,
    },
    /// The scene inputs are not the scene the bundle was baked from.
    #[error("the scene {} is not the one {} was baked from", sources.join(" "), bundle.display())]
    WrongScene {
        bundle: PathBuf,
        sources: Vec<String>,
        #[source]
        source: Box<BundleError>,
    },
    /// The scene has the right fingerprint but cannot be loaded.
    #[error("loading {}", sources.join(" "))]
    Load {
        sources: Vec<String>,
        #[source]
        source: SceneError,
    },
}

/// Opens the bundle in `dir` and loads the scene it was baked from: `scene_override` if not
/// empty (inputs to use instead of the manifest's sources, e.g. after the scene moved), checked
/// against the bundle's scene fingerprint before anything is loaded. `progress` is called during
/// slow loads.
pub fn open_bundle(
    dir: &Path,
    scene_override: &[String],
    progress: Option<ProgressFn>,
) -> Result<OpenedBundle, OpenBundleError> {
    let bundle = Bundle::open(dir)?;
    let manifest = bundle.manifest();
    let up = if manifest.scene.up == "z" {
        UpAxis::Z
    } else {
        UpAxis::Y
    };
    let sources = if scene_override.is_empty() {
        manifest.scene.sources.clone()
    } else {
        scene_override.to_vec()
    };
    let fp = match fingerprint(&sources, up) {
        Ok(fp) => fp,
        Err(source) => {
            return Err(OpenBundleError::Fingerprint {
                bundle: bundle.dir().to_path_buf(),
                sources,
                source,
            })
        }
    };
    if let Err(source) = bundle.expect_scene(&fp) {
        return Err(OpenBundleError::WrongScene {
            bundle: bundle.dir().to_path_buf(),
            sources,
            source: Box::new(source),
        });
    }
    match load_with_report(&sources, &LoadOptions { up, progress }) {
        Ok((scene, report)) => Ok(OpenedBundle {
            bundle,
            scene,
            report,
        }),
        Err(source) => Err(OpenBundleError::Load { sources, source }),
    }
}
