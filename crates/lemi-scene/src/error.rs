use std::path::PathBuf;

/// Everything that can go wrong while building a scene. Every variant names its input.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Malformed { path: PathBuf, message: String },
    #[error("{path}: unsupported file type (expected .gltf, .glb, .obj, .ply or .ply.gz)")]
    Unsupported { path: PathBuf },
    #[error("built-in scene `{spec}`: {message}")]
    BadBuiltin { spec: String, message: String },
    #[error("no triangles in {inputs}")]
    Empty { inputs: String },
}
