//! Opening a baked bundle together with the scene it was baked from: the scene is loaded from the
//! manifest's sources (or from other inputs that must have the same fingerprint), in the up axis
//! the bundle was baked with, so that whatever draws the bundle draws it over the right geometry.

use std::path::{Path, PathBuf};

use lemi_core::bundle::{Bundle, BundleError};
use lemi_core::{Scene, UpAxis};

use crate::import::{load_with_report, ImportReport};
use crate::{fingerprint_with, FingerprintScheme, LoadOptions, ProgressFn, SceneError};

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
    /// The scene inputs are not the scene the bundle was baked from (under the fingerprint
    /// scheme the bundle was baked with, `scheme`).
    #[error("the scene {} is not the one {} was baked from{}", sources.join(" "), bundle.display(), legacy_note(*scheme))]
    WrongScene {
        bundle: PathBuf,
        sources: Vec<String>,
        scheme: FingerprintScheme,
        #[source]
        source: Box<BundleError>,
    },
    /// The bundle's scene fingerprint was made with a scheme this lemi does not know.
    #[error("{}: the scene fingerprint `{fingerprint}` is of a scheme this lemi does not know (it knows schemes 1 and 2: bare hex and `v2:`); open the bundle with the lemi that baked it, or bake it again", bundle.display())]
    UnknownScheme {
        bundle: PathBuf,
        fingerprint: String,
    },
    /// The scene has the right fingerprint but cannot be loaded.
    #[error("loading {}", sources.join(" "))]
    Load {
        sources: Vec<String>,
        #[source]
        source: SceneError,
    },
}

/// What a scene mismatch adds for a bundle fingerprinted under scheme 1, which also covered files
/// beside the scene that it does not use.
pub fn legacy_note(scheme: FingerprintScheme) -> &'static str {
    match scheme {
        FingerprintScheme::V1 => {
            " (the bundle's fingerprint is of scheme 1, from before `v2:` fingerprints: it also \
             covers every .bin, .mtl, .png, .jpg and .jpeg file beside a scene file, used or not, \
             so such a file added, changed or removed there since the bake changes it too; put \
             the directory back as it was, or bake the bundle again, which fingerprints the scene \
             by what it references)"
        }
        FingerprintScheme::V2 => "",
    }
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
    let Some(scheme) = FingerprintScheme::of(&manifest.scene.fingerprint) else {
        return Err(OpenBundleError::UnknownScheme {
            bundle: lemi_core::bundle::manifest_path(bundle.dir()),
            fingerprint: manifest.scene.fingerprint.clone(),
        });
    };
    // A bundle is checked under the scheme it was baked with, so older bundles keep opening.
    let fp = match fingerprint_with(&sources, up, scheme) {
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
            scheme,
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
