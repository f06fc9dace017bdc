//! What the strategy test suites share: one GPU test at a time, boxes for their scenes, the
//! two-cell grid at eye height and baking it into a bundle.

use std::path::Path;
use std::sync::{Mutex, MutexGuard};

use glam::DVec3;
use lemi_bake::{run, BakeJob, Baker};
use lemi_core::bundle::{BakeParams, SceneRef};
use lemi_core::cell::CellGrid;
use lemi_core::{Aabb, Mesh, Scene, SceneBuilder, Vertex};
use lemi_gpu::Gpu;

/// Eye height of the cells (m).
pub const EYE: f64 = 1.7;

/// GPU tests share two cores: one at a time.
pub fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|p| p.into_inner())
}

/// An axis-aligned box without a bottom face, one colour.
pub fn add_box(b: &mut SceneBuilder, material: u32, min: [f32; 3], max: [f32; 3], color: [u8; 4]) {
    let [x0, y0, z0] = min;
    let [x1, y1, z1] = max;
    let faces: [([f32; 3], [[f32; 3]; 4]); 5] = [
        (
            [1.0, 0.0, 0.0],
            [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],
        ),
        (
            [-1.0, 0.0, 0.0],
            [[x0, y0, z1], [x0, y1, z1], [x0, y1, z0], [x0, y0, z0]],
        ),
        (
            [0.0, 1.0, 0.0],
            [[x0, y1, z0], [x0, y1, z1], [x1, y1, z1], [x1, y1, z0]],
        ),
        (
            [0.0, 0.0, 1.0],
            [[x1, y0, z1], [x1, y1, z1], [x0, y1, z1], [x0, y0, z1]],
        ),
        (
            [0.0, 0.0, -1.0],
            [[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]],
        ),
    ];
    let mut mesh = Mesh {
        material,
        ..Default::default()
    };
    for (n, corners) in faces {
        let base = mesh.vertices.len() as u32;
        for c in corners {
            mesh.vertices.push(Vertex::new(c, n, [0.0, 0.0], color));
        }
        mesh.indices
            .extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    b.add_mesh(mesh);
}

/// Two 10 m cells at eye height: `0_0_0` and `1_0_0` along +X.
pub fn grid() -> CellGrid {
    let region = Aabb::new(DVec3::new(-10.0, EYE, -5.0), DVec3::new(10.0, EYE, 5.0));
    CellGrid::tile(region, 10.0).expect("grid")
}

/// Bakes every cell of [`grid`] of `scene` with `params` into `bundle`; `name` stands for the
/// scene's source and fingerprint.
pub fn bake(gpu: &Gpu, scene: &Scene, params: &BakeParams, bundle: &Path, name: &str) {
    let grid = grid();
    let job = BakeJob {
        bundle: bundle.to_path_buf(),
        scene: SceneRef {
            sources: vec![format!("test:{name}")],
            up: "y".into(),
            fingerprint: format!("fingerprint-of-the-{name}-scene"),
            triangles: scene.triangle_count(),
        },
        params: params.clone(),
        cells: grid.cells(),
        grid,
        shard: None,
    };
    let baker = Baker::new(gpu, scene, params.clone()).expect("baker");
    run(&job, |cell| baker.bake(cell, |_| {}), |_, _, _| {}).expect("bake");
}
