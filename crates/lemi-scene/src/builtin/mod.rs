//! Built-in procedural scenes: `city`, `terrain`, `forest`.
use lemi_core::Scene;

use crate::SceneError;

/// Builds a built-in scene from the part of the spec after `builtin:`, e.g. `city:100000:7`.
pub fn build(spec: &str) -> Result<Scene, SceneError> {
    Err(SceneError::BadBuiltin {
        spec: spec.into(),
        message: "not available".into(),
    })
}
