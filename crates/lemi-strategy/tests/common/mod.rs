//! What the strategy test suites share, from `lemi-testkit`: one GPU test at a time, boxes for
//! their scenes, the two-cell grid at eye height and baking it into a bundle.

use std::path::Path;

use lemi_core::bundle::BakeParams;
use lemi_core::cell::CellGrid;
use lemi_core::Scene;
use lemi_gpu::Gpu;

pub use lemi_testkit::{add_box, serial, EYE};

/// Two 10 m cells at eye height: `0_0_0` and `1_0_0` along +X.
pub fn grid() -> CellGrid {
    lemi_testkit::row_of_cells(2)
}

/// Bakes every cell of [`grid`] of `scene` with `params` into `bundle`; `name` stands for the
/// scene's source and fingerprint.
pub fn bake(gpu: &Gpu, scene: &Scene, params: &BakeParams, bundle: &Path, name: &str) {
    lemi_testkit::bake_grid(gpu, scene, params, &grid(), bundle, name);
}
