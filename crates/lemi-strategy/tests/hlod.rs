//! The `hlod` strategy (the far field as geometry simplified with meshoptimizer in distance
//! bands, `lemi_core::hlod`) on whatever adapter wgpu finds (Mesa's lavapipe or llvmpipe in CI),
//! over one 10 m cell of `builtin:city:20k` (x ∈ [15, 25], z ∈ [−5, 5]) baked in the test with
//! α = one pixel of the 160 × 120, 45° (vertical) output view the frames are drawn at:
//!
//! - from the cell's corners (its four horizontal corners at eye height and at the cell's top,
//!   looking in four directions), the measured screen-space error of the far pixels (the strategy's
//!   own measure: the distance from each shown point to the reference surface, as an angle in
//!   output pixels) stays within the 1 α bound: 99th percentile ≤ 1 px, and at most 0.2 % of the
//!   far pixels over twice the bound. The slack is argued: meshoptimizer's error is a quadric
//!   estimate at the collapsed vertices, not a Hausdorff bound (a collapsed triangle's interior
//!   can sweep past the original silhouette), and the measure samples the reference surface at
//!   pixel spacing; the maximum is printed, not bounded (a few pixels reach tens of pixels, see
//!   the run's output);
//! - a 4 α bound leaves fewer than 90 % of the triangles of the 1 α bound, and more error;
//! - a bundle of another strategy is refused.
//!
//! Without an adapter the GPU tests fail with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.

use std::path::Path;
use std::sync::Arc;

use glam::DVec3;
use lemi_core::bundle::{BakeParams, Bundle, LayerTarget, Layering, SceneRef};
use lemi_core::camera::Camera;
use lemi_core::cell::CellGrid;
use lemi_core::{Aabb, Face, Scene};
use lemi_gpu::{Gpu, RenderOptions};
use lemi_strategy::hlod::HlodStrategy;
use lemi_strategy::{FrameRequest, Strategy, StrategyContext, StrategyError, StrategyKind};

const W: u32 = 160;
const H: u32 = 120;
const FOV_Y: f64 = 45.0;

fn alpha() -> f64 {
    (FOV_Y / H as f64).to_radians()
}

fn params(error_px: f64) -> BakeParams {
    BakeParams {
        cell_size: 10.0,
        cell_height: None,
        resolution: 64,
        target: LayerTarget::Layers(8),
        faces: Face::HORIZONTAL.to_vec(),
        alpha: alpha(),
        output_fov_deg: None,
        output_width: None,
        micro_grid: 8,
        micro_threshold: 0.6,
        layering: Layering::Hlod {
            error_px,
            band_factor: 2.0,
        },
        texture_format: Default::default(),
        outline_copies: false,
        outline_fringe: false,
    }
}

fn bake(gpu: &Gpu, scene: &Scene, dir: &Path, error_px: f64) -> Bundle {
    let params = params(error_px);
    let region = Aabb::new(DVec3::new(15.0, 1.7, -5.0), DVec3::new(25.0, 1.7, 5.0));
    let grid = CellGrid::tile(region, 10.0).unwrap();
    let job = lemi_bake::BakeJob {
        bundle: dir.to_path_buf(),
        scene: SceneRef {
            sources: vec!["builtin:city:20k".into()],
            up: "y".into(),
            fingerprint: "test".into(),
            triangles: scene.triangle_count(),
        },
        params: params.clone(),
        cells: grid.cells(),
        grid,
        shard: None,
    };
    let baker = lemi_bake::Baker::new(gpu, scene, params).unwrap();
    lemi_bake::run(&job, |c| baker.bake(c, |_| {}), |_, _, _| {}).unwrap();
    Bundle::open(dir).unwrap()
}

/// Far-pixel errors over the corner views, sorted.
fn corner_errors(gpu: &Arc<Gpu>, bundle: &Bundle, scene: &Arc<Scene>) -> Vec<f32> {
    let ctx = StrategyContext::new(gpu.clone(), bundle.clone(), scene.clone()).unwrap();
    let mut s = HlodStrategy::new(&ctx).unwrap();
    let cell = bundle.first_cell().unwrap();
    let mut errors = Vec::new();
    let options = RenderOptions::default();
    for (dx, dz) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        for y in [1.7, cell.center.y + cell.half.y - 1e-3] {
            // just inside the cell so the eye locates it
            let eye = DVec3::new(
                cell.center.x + dx * (cell.half.x - 1e-3),
                y,
                cell.center.z + dz * (cell.half.z - 1e-3),
            );
            for yaw in [0.0, 90.0, 180.0, 270.0] {
                let view = Camera::from_yaw_pitch(eye, yaw, -3.0, FOV_Y, W, H)
                    .unwrap()
                    .view();
                let f = s
                    .frame(&FrameRequest {
                        eye,
                        velocity: DVec3::ZERO,
                        dt: 1.0 / 30.0,
                        view: &view,
                        options: &options,
                        measure_error: true,
                        read_back: true,
                    })
                    .unwrap();
                assert!(!f.fallback, "{eye} yaw {yaw}: fell back: {:?}", f.warnings);
                assert!(f.far_primitives > 0);
                errors.extend(f.error_px.unwrap().into_iter().filter(|e| e.is_finite()));
            }
        }
    }
    assert!(errors.len() > 1000, "{} far pixels", errors.len());
    errors.sort_by(f32::total_cmp);
    errors
}

fn percentile(sorted: &[f32], p: f64) -> f32 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn far_triangles(bundle: &Bundle) -> (u64, u64) {
    let id = bundle.cell_ids()[0];
    let h = bundle.cell(id).unwrap().header.hlod.unwrap();
    (h.source_triangles, h.triangles())
}

#[test]
fn simplified_far_field_stays_within_its_bound_and_4_alpha_simplifies_more() {
    let _guard = lemi_testkit::serial();
    let Some(gpu) = lemi_testkit::gpu() else {
        return;
    };
    let gpu = Arc::new(gpu);
    let scene = Arc::new(lemi_scene::builtin::build("city:20k").unwrap());
    let tmp = tempfile::tempdir().unwrap();

    let one = bake(&gpu, &scene, &tmp.path().join("one"), 1.0);
    let e1 = corner_errors(&gpu, &one, &scene);
    let (src, t1) = far_triangles(&one);
    let (p99, max) = (percentile(&e1, 0.99), e1[e1.len() - 1]);
    println!(
        "1 α: {src} far triangles -> {t1}; far pixels {}, p99 {p99:.3} px, max {max:.3} px",
        e1.len()
    );
    let over = |e: &[f32], b: f32| e.iter().filter(|&&x| x > b).count() as f64 / e.len() as f64;
    println!(
        "1 α: share over 1 px {:.5}, over 2 px {:.5}",
        over(&e1, 1.0),
        over(&e1, 2.0)
    );
    assert!(t1 < src, "1 α simplified nothing ({t1} of {src})");
    assert!(p99 <= 1.0, "p99 {p99} px over the 1 px bound");
    assert!(
        over(&e1, 2.0) <= 0.002,
        "{:.4} of the far pixels over twice the bound (max {max} px)",
        over(&e1, 2.0)
    );

    let four = bake(&gpu, &scene, &tmp.path().join("four"), 4.0);
    let e4 = corner_errors(&gpu, &four, &scene);
    let (src4, t4) = far_triangles(&four);
    let p99_4 = percentile(&e4, 0.99);
    println!(
        "4 α: {src4} far triangles -> {t4}; p99 {p99_4:.3} px, max {:.3} px",
        e4[e4.len() - 1]
    );
    assert_eq!(src4, src);
    assert!(
        (t4 as f64) < 0.9 * t1 as f64,
        "4 α keeps {t4} triangles, 1 α {t1}"
    );
    assert!(p99_4 <= 4.0, "4 α: p99 {p99_4} px over the 4 px bound");

    // a bundle of another strategy is refused
    let mut lemi = params(1.0);
    lemi.layering = Layering::Optimal;
    let manifest = lemi_testkit::manifest_without_cells(
        lemi,
        one.manifest().grid.clone(),
        one.manifest().scene.clone(),
    );
    let other = Bundle::from_manifest(tmp.path(), manifest).unwrap();
    let ctx = StrategyContext::new(gpu.clone(), other, scene.clone()).unwrap();
    assert!(matches!(
        HlodStrategy::new(&ctx),
        Err(StrategyError::NotBakedFor {
            requested: StrategyKind::Hlod,
            baked: StrategyKind::Lemi
        })
    ));
}
