//! lemi-scene: turns scene files and built-in scene specs into one [`lemi_core::Scene`].
//!
//! `SCENE` arguments are a file (`.gltf`, `.glb`, `.obj`, `.ply`, `.ply.gz`), a directory (every
//! supported file below it, recursively) or a built-in spec `builtin:NAME[:triangles[:seed]]` with
//! `NAME` one of `city`, `terrain`, `forest`, `interior`. [`open_bundle`] opens a baked bundle with
//! the scene it was baked from (checked against the bundle's scene fingerprint).

pub mod builtin;
mod bundle;
mod error;
mod fingerprint;
pub mod import;

pub use bundle::{legacy_note, open_bundle, OpenBundleError, OpenedBundle};
pub use error::SceneError;
pub use fingerprint::{fingerprint, fingerprint_with, FingerprintScheme};

use std::sync::Arc;

use lemi_core::UpAxis;

/// A progress callback: `(what, done, total)`; `total == 0` when unknown.
pub type ProgressFn = Arc<dyn Fn(&str, u64, u64) + Send + Sync>;

/// Options for [`load`].
#[derive(Clone, Default)]
pub struct LoadOptions {
    /// Up axis of the source files (built-in scenes are always +Y up).
    pub up: UpAxis,
    /// Called now and then during slow loads.
    pub progress: Option<ProgressFn>,
}

impl std::fmt::Debug for LoadOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoadOptions")
            .field("up", &self.up)
            .field("progress", &self.progress.is_some())
            .finish()
    }
}

pub use import::load;
