//! Errors of the runtime. Every error about a cell names its file; none is a panic: nothing
//! that comes from a user (a file, a flag, a bundle) may cause one.

use std::path::PathBuf;

use lemi_core::cell::CellId;

/// Everything that can go wrong while streaming a bundle.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RuntimeError {
    /// A cell could not be read, verified, decoded or uploaded; `path` is its file.
    #[error("{}: {message}", path.display())]
    Cell {
        id: CellId,
        path: PathBuf,
        message: String,
    },
    /// The manifest is unusable for streaming (bad grid, unknown cell ids, …).
    #[error("{}: {message}", path.display())]
    Manifest { path: PathBuf, message: String },
    /// An option is out of range; names the option.
    #[error("streaming option `{option}`: {message}")]
    Options {
        option: &'static str,
        message: String,
    },
    /// The background loader could not be started or stopped unexpectedly.
    #[error("the background cell loader {0}")]
    Loader(String),
}

impl RuntimeError {
    /// The cell this error is about, if any.
    pub fn cell_id(&self) -> Option<CellId> {
        match self {
            RuntimeError::Cell { id, .. } => Some(*id),
            _ => None,
        }
    }
}
