//! [`WalkError`]: everything that can go wrong walking a path or writing its files.

use std::path::PathBuf;

use crate::path::PathError;

/// An error of this crate; each names the file, the field or the frame at fault.
#[derive(Debug, thiserror::Error)]
pub enum WalkError {
    /// A camera path file, or the input of [`crate::auto_path`], is not usable.
    #[error("camera path {}: {source}", path.display())]
    Path {
        path: PathBuf,
        #[source]
        source: PathError,
    },
    /// A file that is not a camera path.
    #[error("camera path {}: not a camera path (no `format`: \"{}\" field)", path.display(), crate::path::FORMAT)]
    NotAPath { path: PathBuf },
    /// A JSON file could not be parsed or written.
    #[error("{what} {}: {source}", path.display())]
    Json {
        what: &'static str,
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    /// Reading or writing a file failed.
    #[error("{what} {}: {source}", path.display())]
    Io {
        what: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// `frames.csv` could not be read or written.
    #[error("frame CSV {}: {source}", path.display())]
    Csv {
        path: PathBuf,
        #[source]
        source: csv::Error,
    },
    /// A plot could not be drawn or written.
    #[error("walk plot {}: {message}", path.display())]
    Plot { path: PathBuf, message: String },
    /// The options of a walk are not usable (the message names the option).
    #[error("{0}")]
    Options(String),
    /// A pose of the path gives no camera.
    #[error("the camera of frame {frame}: {source}")]
    Camera {
        frame: u64,
        #[source]
        source: lemi_core::camera::CameraError,
    },
    /// The strategy failed.
    #[error("{what} ({strategy}): {source}")]
    Strategy {
        what: String,
        strategy: &'static str,
        #[source]
        source: lemi_strategy::StrategyError,
    },
    /// The GPU failed (uploading the scene, rendering a geometry frame).
    #[error("{what}: {source}")]
    Gpu {
        what: String,
        #[source]
        source: lemi_gpu::GpuError,
    },
    /// The caller's frame observer failed (e.g. writing a frame image).
    #[error("{0}")]
    Observer(String),
}

impl WalkError {
    pub(crate) fn io(what: &'static str, path: &std::path::Path, source: std::io::Error) -> Self {
        WalkError::Io {
            what,
            path: path.to_path_buf(),
            source,
        }
    }
}
