//! lemi-bake: the bake job (GI 2002 sec. 3-5): which cells to bake, resuming, sharding and merging,
//! atomic output ([`orchestrate`]), and the work of one cell: placement, classification,
//! crack-free GPU recording, compression ([`cell_bake`]).

pub mod cell_bake;
pub mod orchestrate;
pub mod report;

pub use cell_bake::{compress_options, Baker, Stage};
pub use orchestrate::{merge, run, BakeError, BakeJob, CellOutcome, RunSummary, ShardRecord};
pub use report::{BakeReport, CellReport};
