//! What lemi's test suites share (a dev-only crate): the GPU-or-skip helper, skips that show in
//! the test run's output, one GPU test at a time, box scenes, small bake parameters, a two-cell
//! grid at eye height and baking it into a bundle.
//!
//! **Skips are visible.** The test harness captures what a passing test prints, so a test that
//! returns early with `eprintln!` passes silently. [`skip`] writes straight to the process's
//! standard error (which the harness does not capture), so every skip shows in `cargo test`'s
//! output as `SKIPPED <test>: <reason>`, and, when `LEMI_SKIP_LOG` names a file, appends the same
//! line to it (CI prints the count at the end of the run).

use std::io::Write;
use std::path::Path;
use std::sync::{Mutex, MutexGuard};

use glam::DVec3;
use lemi_bake::{run, BakeJob, Baker};
use lemi_core::bundle::{BakeParams, LayerTarget, Layering, Manifest, SceneRef};
use lemi_core::cell::CellGrid;
use lemi_core::clip::ClipVertex;
use lemi_core::{Aabb, Face, Mesh, Scene, SceneBuilder, Vertex};
use lemi_gpu::{BackendChoice, Gpu};

/// Says that the running test is skipped and why, where the test run's output shows it.
pub fn skip(reason: &str) {
    let thread = std::thread::current();
    let line = format!("SKIPPED {}: {reason}\n", thread.name().unwrap_or("a test"));
    let _ = std::io::stderr().write_all(line.as_bytes());
    if let Some(log) = std::env::var_os("LEMI_SKIP_LOG") {
        if let Ok(mut f) = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
        {
            let _ = f.write_all(line.as_bytes());
        }
    }
}

/// The adapter, or `None` after a visible [`skip`] when there is none and
/// `LEMI_SKIP_GPU_TESTS=1` (without it, a machine with no adapter fails with the install hint).
pub fn gpu() -> Option<Gpu> {
    match Gpu::new(BackendChoice::Auto) {
        Ok(g) => Some(g),
        Err(e) if std::env::var("LEMI_SKIP_GPU_TESTS").as_deref() == Ok("1") => {
            skip(&format!("no GPU adapter (LEMI_SKIP_GPU_TESTS=1): {e}"));
            None
        }
        Err(e) => panic!("{e}"),
    }
}

/// `Some(path)` when the file exists; otherwise a visible [`skip`] naming it and `None`.
pub fn require_file(path: &Path, how_to_get_it: &str) -> Option<std::path::PathBuf> {
    if path.is_file() {
        Some(path.to_path_buf())
    } else {
        skip(&format!("{} not found ({how_to_get_it})", path.display()));
        None
    }
}

/// GPU tests share two cores (and some pace frames in real time): one at a time.
pub fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|p| p.into_inner())
}

/// The sides of the box `[min, max]`: outward normal and four corners counter-clockwise seen from
/// outside, in the order +X, −X, +Y, −Y, +Z, −Z; without the bottom (−Y) unless `bottom`.
pub fn box_sides(min: [f32; 3], max: [f32; 3], bottom: bool) -> Vec<([f32; 3], [[f32; 3]; 4])> {
    let [x0, y0, z0] = min;
    let [x1, y1, z1] = max;
    let mut sides = vec![
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
            [0.0, -1.0, 0.0],
            [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],
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
    if !bottom {
        sides.remove(3);
    }
    sides
}

/// Appends quads to `mesh`: per quad four vertices with the texture coordinates `uvs` and two
/// triangles `0 1 2, 0 2 3`; `color(normal)` gives each quad's vertex colour.
pub fn push_quads(
    mesh: &mut Mesh,
    quads: &[([f32; 3], [[f32; 3]; 4])],
    uvs: [[f32; 2]; 4],
    color: impl Fn([f32; 3]) -> [u8; 4],
) {
    for &(n, corners) in quads {
        let base = mesh.vertices.len() as u32;
        for (c, uv) in corners.iter().zip(uvs) {
            mesh.vertices.push(Vertex::new(*c, n, uv, color(n)));
        }
        mesh.indices
            .extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
}

/// Texture coordinates of an untextured quad.
pub const NO_UV: [[f32; 2]; 4] = [[0.0; 2]; 4];
/// Texture coordinates spanning the texture once.
pub const UNIT_UV: [[f32; 2]; 4] = [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]];

/// A box standing on the ground (no bottom face), one colour, as a mesh of its own.
pub fn add_box(b: &mut SceneBuilder, material: u32, min: [f32; 3], max: [f32; 3], color: [u8; 4]) {
    let mut mesh = Mesh {
        material,
        ..Default::default()
    };
    push_quads(&mut mesh, &box_sides(min, max, false), NO_UV, |_| color);
    b.add_mesh(mesh);
}

/// A closed box (6 faces, each with the texture once), one colour, as a mesh of its own.
pub fn add_closed_box(
    b: &mut SceneBuilder,
    material: u32,
    min: [f32; 3],
    max: [f32; 3],
    color: [u8; 4],
) {
    let mut mesh = Mesh {
        material,
        ..Default::default()
    };
    push_quads(&mut mesh, &box_sides(min, max, true), UNIT_UV, |_| color);
    b.add_mesh(mesh);
}

/// A flat ground at y = 0 of `n × n` square tiles of side `tile` from `(origin, origin)`, as one
/// mesh; `color(i, j)` gives tile `(i, j)`'s colour.
pub fn add_ground(
    b: &mut SceneBuilder,
    material: u32,
    origin: f32,
    tile: f32,
    n: usize,
    color: impl Fn(usize, usize) -> [u8; 4],
) {
    let mut mesh = Mesh {
        material,
        ..Default::default()
    };
    for j in 0..n {
        for i in 0..n {
            let (x0, z0) = (origin + tile * i as f32, origin + tile * j as f32);
            let corners = [
                [x0, 0.0, z0],
                [x0, 0.0, z0 + tile],
                [x0 + tile, 0.0, z0 + tile],
                [x0 + tile, 0.0, z0],
            ];
            let c = color(i, j);
            push_quads(&mut mesh, &[([0.0, 1.0, 0.0], corners)], NO_UV, |_| c);
        }
    }
    b.add_mesh(mesh);
}

/// Small bake parameters for tests: 10 m cubic cells, the four horizontal faces, α = 0.03 rad,
/// an 8-texel micro-grid with threshold 0.6, the optimal layering.
pub fn small_params(resolution: u32, target: LayerTarget) -> BakeParams {
    BakeParams {
        cell_size: 10.0,
        cell_height: None,
        resolution,
        target,
        faces: Face::HORIZONTAL.to_vec(),
        alpha: 0.03,
        output_fov_deg: None,
        output_width: None,
        micro_grid: 8,
        micro_threshold: 0.6,
        layering: Layering::Optimal,
        texture_format: Default::default(),
        outline_copies: false,
        outline_fringe: false,
    }
}

/// Eye height of the test cells (m).
pub const EYE: f64 = 1.7;

/// `n` 10 m cells at eye height along +X from x = −10 (`0_0_0`, `1_0_0`, …).
pub fn row_of_cells(n: usize) -> CellGrid {
    let x1 = -10.0 + 10.0 * n as f64;
    let region = Aabb::new(DVec3::new(-10.0, EYE, -5.0), DVec3::new(x1, EYE, 5.0));
    match CellGrid::tile(region, 10.0) {
        Ok(g) => g,
        Err(e) => panic!("a row of {n} cells: {e}"),
    }
}

/// The manifest of a bundle of `scene` with `params` and `grid` and no cells yet, for tests of
/// what is decided from the manifest alone.
pub fn manifest_without_cells(params: BakeParams, grid: CellGrid, scene: SceneRef) -> Manifest {
    Manifest {
        format: lemi_core::bundle::MANIFEST_FORMAT.into(),
        version: lemi_core::bundle::BUNDLE_VERSION,
        generator: "test".into(),
        scene,
        params_hash: params.hash(),
        params,
        grid,
        cells: Vec::new(),
        object: None,
    }
}

/// Bakes every cell of `grid` of `scene` with `params` into `bundle`; `name` stands for the
/// scene's source and fingerprint.
pub fn bake_grid(
    gpu: &Gpu,
    scene: &Scene,
    params: &BakeParams,
    grid: &CellGrid,
    bundle: &Path,
    name: &str,
) {
    let job = BakeJob {
        bundle: bundle.to_path_buf(),
        scene: SceneRef {
            sources: vec![format!("test:{name}")],
            up: "y".into(),
            fingerprint: format!("fingerprint-of-the-{name}-scene"),
            triangles: scene.triangle_count(),
        },
        params: params.clone(),
        grid: grid.clone(),
        cells: grid.cells(),
        shard: None,
    };
    let baker = match Baker::new(gpu, scene, params.clone()) {
        Ok(b) => b,
        Err(e) => panic!("baker: {e}"),
    };
    if let Err(e) = run(&job, |c| baker.bake(c, |_| {}), |_, _, _| {}) {
        panic!("baking the {name} scene: {e}");
    }
}

/// Adds an untextured material of colour `rgba` (linear) and returns its index.
pub fn plain_material(b: &mut SceneBuilder, name: &str, rgba: [f32; 4]) -> u32 {
    b.add_material(lemi_core::Material {
        name: name.into(),
        base_color: rgba,
        texture: None,
    })
}

/// A checker of white and pale green tiles, for [`add_ground`].
pub fn checker(i: usize, j: usize) -> [u8; 4] {
    if (i + j) % 2 == 0 {
        [255; 4]
    } else {
        [170, 190, 150, 255]
    }
}

/// Positions on rings around the origin: ring `m` at distance `distances[m]` holds `count(m)`
/// positions at equal angles (odd rings turned by half a step). Yields `(m, a, d, x, z)` for
/// position `a` of ring `m`.
pub fn ring_positions(
    distances: &[f32],
    count: impl Fn(usize) -> usize,
) -> Vec<(usize, usize, f32, f32, f32)> {
    let mut out = Vec::new();
    for (m, &d) in distances.iter().enumerate() {
        let n = count(m);
        for a in 0..n {
            let angle = (a as f32 + 0.5 * (m % 2) as f32) * std::f32::consts::TAU / n as f32;
            out.push((m, a, d, d * angle.cos(), d * angle.sin()));
        }
    }
    out
}

/// One white, untextured material on the GPU (for recording tests).
pub fn white_materials(gpu: &Gpu) -> lemi_gpu::GpuMaterials {
    let m = lemi_core::Material {
        name: "white".into(),
        base_color: [1.0; 4],
        texture: None,
    };
    match lemi_gpu::GpuMaterials::upload(gpu, &[m], &[]) {
        Ok(m) => m,
        Err(e) => panic!("materials: {e}"),
    }
}

/// A clipped-triangle vertex at `rel` (relative to the reference viewpoint), white, untextured.
pub fn clip_vertex(rel: DVec3, normal: [f32; 3]) -> ClipVertex {
    ClipVertex {
        rel,
        normal,
        uv: [0.0; 2],
        color: [255.0; 4],
    }
}

/// All of `vertices` as one run of material 0.
pub fn one_run(vertices: &[ClipVertex]) -> Vec<lemi_gpu::MaterialRun> {
    vec![lemi_gpu::MaterialRun {
        material: 0,
        first: 0,
        count: (vertices.len() / 3) as u32,
    }]
}

/// A wavy height field facing `face` around depth 10 (`cells × cells` quads, two triangles
/// each), crossing the depth 10 many times: a continuous surface over many slab borders.
pub fn wavy_surface(face: Face, cells: u32) -> Vec<ClipVertex> {
    let point = |a: u32, b: u32| {
        let s = -0.7 + 1.4 * a as f64 / cells as f64;
        let t = -0.7 + 1.4 * b as f64 / cells as f64;
        let d = 10.0 + 1.5 * (5.0 * s).sin() * (4.0 * t).cos();
        face.point(s, t, d)
    };
    let n = [0.3, 0.8, 0.5];
    let mut out = Vec::new();
    for b in 0..cells {
        for a in 0..cells {
            let (p00, p10, p11, p01) = (
                point(a, b),
                point(a + 1, b),
                point(a + 1, b + 1),
                point(a, b + 1),
            );
            out.extend([p00, p10, p11, p00, p11, p01].map(|p| clip_vertex(p, n)));
        }
    }
    out
}
