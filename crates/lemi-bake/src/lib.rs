//! lemi-bake: orchestration of the bake (GI 2002 sec. 3-5): which cells to bake, resuming,
//! sharding and merging, atomic output. The per-cell work (placement, classification, GPU recording,
//! compression) is a function handed to [`run`], so the orchestration is independent of the GPU.

pub mod orchestrate;

pub use orchestrate::{merge, run, BakeError, BakeJob, CellOutcome, RunSummary};
