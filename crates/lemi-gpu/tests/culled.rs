//! The `geometry-culled` baseline: frustum culling over Morton-ordered clusters never changes the
//! image of the unculled reference renderer, and submits fewer triangles.

use glam::DVec3;
use lemi_core::camera::Camera;
use lemi_gpu::{CullOptions, GpuCulledScene, GpuScene, RenderOptions, Renderer, UploadOptions};

const CLEAR: [u8; 4] = [150, 190, 235, 255];

#[test]
fn culled_city_frames_equal_unculled_with_fewer_triangles() {
    let _serial = lemi_testkit::serial();
    let Some(gpu) = lemi_testkit::gpu() else {
        return;
    };
    let scene = lemi_scene::builtin::build("city:20k:3").expect("city");
    let total = scene.triangle_count();
    let full = GpuScene::upload(&gpu, &scene, &UploadOptions::default()).expect("upload");
    // small chunks too, so that the chunk level of the hierarchy is exercised
    let small = CullOptions {
        cluster_triangles: 32,
        group_clusters: 8,
        upload: UploadOptions {
            max_chunk_bytes: 64 << 10,
        },
    };
    let culled = [
        GpuCulledScene::upload(&gpu, &scene, &CullOptions::default()).expect("culled upload"),
        GpuCulledScene::upload(&gpu, &scene, &small).expect("culled upload"),
    ];
    for c in &culled {
        assert_eq!(c.triangle_count(), total);
    }
    assert!(culled[1].geometry.chunks().len() > 5);
    let renderer = Renderer::new(&gpu).expect("renderer");
    let options = RenderOptions {
        clear: CLEAR,
        ..Default::default()
    };
    let b = scene.bounds;
    let span = b.size().length();
    let views = [
        // inside the city, looking along the avenue
        (
            "along the avenue",
            DVec3::new(-60.0, 1.7, 0.0),
            DVec3::new(100.0, 1.7, 0.0),
        ),
        // in the plaza, looking across the blocks
        (
            "across the blocks",
            DVec3::new(0.0, 1.7, 20.0),
            DVec3::new(10.0, 5.0, 200.0),
        ),
        // at the foot of the landmark tower (72 m at x = 115, z = 54), looking up at it
        (
            "looking up",
            DVec3::new(100.0, 1.7, 30.0),
            DVec3::new(115.0, 60.0, 53.0),
        ),
        // from outside, the whole city in view
        (
            "from outside",
            b.center() + DVec3::new(0.3, 0.6, 1.0) * span,
            b.center(),
        ),
        // from outside, looking away: nothing
        (
            "looking away",
            b.center() + DVec3::new(0.0, 0.0, 1.0) * span,
            b.center() + DVec3::new(0.0, 0.0, 2.0) * span,
        ),
    ];
    for (what, eye, target) in views {
        let view = Camera::look_at(eye, target, DVec3::Y, 60.0, 160, 96)
            .expect("camera")
            .view();
        let want = renderer.render(&full, &view, &options).expect("render");
        for (k, c) in culled.iter().enumerate() {
            let (got, stats) = renderer
                .render_culled(c, &view, &options)
                .expect("render culled");
            assert!(got == want, "{what} (layout {k}): the culled frame differs");
            let no_readback = renderer
                .render_culled_no_readback(c, &view, &options)
                .expect("render culled");
            assert_eq!(no_readback, stats);
            if what == "looking away" {
                assert_eq!(want.covered_count(), 0, "{what}");
                assert_eq!(stats.triangles, 0, "{what}");
                assert_eq!(stats.draw_calls, 0, "{what}");
            } else {
                assert!(want.covered_count() > 0, "{what}");
                assert!(stats.triangles > 0, "{what}");
                if what != "from outside" {
                    assert!(
                        stats.triangles < total * 3 / 4,
                        "{what} (layout {k}): {} of {total} triangles submitted",
                        stats.triangles
                    );
                } else {
                    assert!(stats.triangles <= total, "{what}");
                }
            }
            eprintln!(
                "{what} (layout {k}): {} of {total} triangles, {} draws, {} boxes tested",
                stats.triangles, stats.draw_calls, stats.boxes_tested
            );
        }
    }
}

#[test]
fn culled_scene_checks_its_materials() {
    let _serial = lemi_testkit::serial();
    let Some(gpu) = lemi_testkit::gpu() else {
        return;
    };
    let scene = lemi_scene::builtin::build("city:10k:1").expect("city");
    let culled =
        lemi_gpu::CulledGeometry::upload(&gpu, &scene, &CullOptions::default()).expect("upload");
    let none =
        std::sync::Arc::new(lemi_gpu::GpuMaterials::upload(&gpu, &[], &[]).expect("no materials"));
    let e = GpuCulledScene::from_parts(none, culled)
        .err()
        .expect("missing materials are an error")
        .to_string();
    assert!(e.contains("material"), "{e}");
}
