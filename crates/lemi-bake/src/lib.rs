//! lemi-bake: the bake job (GI 2002 sec. 3-5): which cells to bake, resuming, sharding and merging,
//! atomic output ([`orchestrate`]), and the work of one cell: placement, classification,
//! crack-free GPU recording, compression ([`cell_bake`]).

pub mod cell_bake;
pub mod object_bake;
pub mod orchestrate;
pub mod report;

pub use cell_bake::{compress_options, Baker, Stage};
pub use object_bake::{bake_object, ObjectBake};
pub use orchestrate::{merge, run, BakeError, BakeJob, CellOutcome, RunSummary, ShardRecord};
pub use report::{BakeReport, CellReport};
