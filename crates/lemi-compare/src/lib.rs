//! `lemi-compare`: every far-field strategy on the same scene, cells, path and viewpoints, side by
//! side, as in the comparisons of Jeschke, Wimmer & Schumann, "Layered Environment-Map Impostors
//! for Arbitrary Scenes" (Graphics Interface 2002), sec. 6. For each strategy [`run`] does what a
//! user would do by hand:
//!
//! 1. the bake of a layered strategy (`lemi`, `cubemap`, `equidistant`), given by the caller
//!    (it builds the bake job from its own inputs; [`bake`] runs one); `warp` and `dynamic` run on
//!    the `lemi` bundle (its cells and near lists);
//! 2. the walk ([`lemi_walk::walk`]) along one path (the automatic one, generated once); the
//!    all-geometry replay runs once, with the first walk;
//! 3. the certificate ([`lemi_eval::evaluate_strategy`]) at the same viewpoints.
//!
//! Then it writes `COMPARISON.md` ([`render_markdown`]), `comparison.json` (every number,
//! [`Comparison`]) and `frame_times.svg` (frame time and far-field primitives per frame of every
//! strategy) into the output directory, besides each walk's and evaluation's own files. A
//! strategy whose job fails gets its error in its [`Row`]; the others go on.

mod markdown;
mod rows;
mod run;

use std::path::PathBuf;

pub use markdown::render_markdown;
pub(crate) use rows::encode_seconds_per_cell;
pub use rows::{BakeRow, Comparison, EvalRow, FormatRow, GeometryTimes, Row};
pub use run::{bake, check_strategies, run, CompareOptions, ComparisonRun};

/// What stops a comparison as a whole (a strategy's own failure is kept in its [`Row`]).
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// No strategy to compare.
    #[error("name at least one strategy")]
    NoStrategies,
    /// A strategy listed twice.
    #[error("`{0}` is listed twice")]
    Repeated(lemi_strategy::StrategyKind),
    /// Reading or writing a file failed.
    #[error("{what} {}: {source}", path.display())]
    Io {
        what: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// `comparison.json` could not be made.
    #[error("comparison.json: {0}")]
    Json(#[from] serde_json::Error),
}

/// `error` and its causes joined by `: `, as a row of the tables shows them.
pub(crate) fn error_chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut cause = error.source();
    while let Some(c) = cause {
        text.push_str(": ");
        text.push_str(&c.to_string());
        cause = c.source();
    }
    text
}
