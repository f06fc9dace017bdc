//! Portal impostors at run time ([`lemi_strategy::portal`]) on `builtin:interior:20k:1`: the
//! south window of the south-west room (x = 16.2 m, facing −Z) and the west door, each baked in
//! the test as a portal impostor for its shaft (60°, from 1.5 m, bounded by the room) with α one
//! pixel of the 160 × 120, 45° (vertical) frames:
//!
//! - from inside the window's shaft, looking out, the frame draws its quads and fewer triangles
//!   than the scene has, and shows what the geometry shows: the same coverage (at most 0.5 % of
//!   the pixels differ in being drawn at all) and the same colours up to the impostor's error
//!   (mean absolute difference of the drawn pixels at most 6 of 255, measured 0.2 to 0.5);
//! - outside every shaft (in the street, and in the room nearer the window than the shaft
//!   starts) no impostor is drawn, and the frame is the geometry's: 99.9 % of the pixels
//!   identical (the classes change the draw order, so a fragment of equal depth may differ);
//! - from the rooms, the outside drawn only through the openings and the other rooms only through
//!   the doorways leading to them change no pixel (99.9 % identical to the frame drawing all of
//!   it over the whole view) and draw fewer triangles;
//! - a bundle that is not an object impostor is refused.
//!
//! Without an adapter the test fails with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.

use std::path::Path;
use std::sync::Arc;

use glam::DVec3;
use lemi_bake::object_bake::{bake_object, object_bake_params, write_object_bundle};
use lemi_core::bundle::{Bundle, LayerTarget, SceneRef};
use lemi_core::camera::{Camera, View};
use lemi_core::enclosure::Enclosure;
use lemi_core::object_cell::{object_bounds, ObjectSetup, Portal};
use lemi_core::{Aabb, Scene};
use lemi_gpu::{Frame, Gpu, GpuMaterials, GpuScene, RenderOptions, Renderer, UploadOptions};
use lemi_strategy::portal::PortalStrategy;
use lemi_strategy::{FrameRequest, Strategy};

const W: u32 = 160;
const H: u32 = 120;
const FOV_Y: f64 = 45.0;
const BUILDING: ([f64; 3], [f64; 3]) = ([11.999, -0.001, -7.301], [28.601, 9.401, 7.301]);

fn bake(
    gpu: &Gpu,
    scene: &Scene,
    portal: &Portal,
    max: f64,
    enclosure: &Enclosure,
    dir: &Path,
) -> Bundle {
    let alpha = (FOV_Y / H as f64).to_radians();
    let keep = Aabb::new(DVec3::from(BUILDING.0), DVec3::from(BUILDING.1));
    let frame = portal.frame(60.0, 1.5).expect("frame");
    let object = portal.select(&frame, scene, &keep, 2.0 * max * 30f64.to_radians().tan());
    assert!(!object.is_empty());
    let bounds = object_bounds(scene, &object);
    let mut setup = ObjectSetup::through_portal(portal, 60.0, 1.5, Some(max), bounds, None, alpha)
        .expect("setup");
    setup.enclosure = Some(enclosure.clone());
    let placement = setup.place().expect("placement");
    let params = object_bake_params(
        &setup,
        placement.layers.len(),
        (None, None),
        Default::default(),
    );
    let mut baked = bake_object(gpu, scene, &object, &setup, params.clone(), |_| {}).expect("bake");
    let scene_ref = SceneRef {
        sources: vec!["builtin:interior:20k:1".into()],
        up: "y".into(),
        fingerprint: "test".into(),
        triangles: scene.triangle_count(),
    };
    write_object_bundle(dir, scene_ref, &params, &mut baked).expect("write");
    Bundle::open(dir).expect("open")
}

/// A still frame's request at `eye`.
fn request<'a>(eye: DVec3, view: &'a View, options: &'a RenderOptions) -> FrameRequest<'a> {
    FrameRequest {
        eye,
        velocity: DVec3::ZERO,
        dt: 0.1,
        view,
        options,
        measure_error: false,
        read_back: true,
    }
}

fn view(eye: DVec3, target: DVec3) -> View {
    Camera::look_at(eye, target, DVec3::Y, FOV_Y, W, H)
        .expect("camera")
        .view()
}

/// (pixels drawn in one frame only, pixels drawn in both, mean absolute colour difference over
/// those, identical pixels).
fn compare(a: &Frame, b: &Frame) -> (usize, usize, f64, usize) {
    let (mut coverage, mut both, mut diff, mut same) = (0, 0, 0.0, 0);
    for (p, q) in a.rgba.chunks_exact(4).zip(b.rgba.chunks_exact(4)) {
        if p == q {
            same += 1;
        }
        match (p[3] == 255, q[3] == 255) {
            (true, true) => {
                both += 1;
                diff += (0..3)
                    .map(|i| (f64::from(p[i]) - f64::from(q[i])).abs())
                    .sum::<f64>()
                    / 3.0;
            }
            (false, false) => {}
            _ => coverage += 1,
        }
    }
    (coverage, both, diff / both.max(1) as f64, same)
}

#[test]
fn portal_frames_show_the_geometry_and_only_inside_their_cells() {
    let _guard = lemi_testkit::serial();
    let Some(gpu) = lemi_testkit::gpu() else {
        return;
    };
    let gpu = Arc::new(gpu);
    let scene = lemi_scene::builtin::build("interior:20k:1").expect("scene");
    let dir = tempfile::tempdir().expect("tempdir");
    let window = Portal::parse("16.2,1.75,-7.3,0,0,-1,1.2,1.4").expect("window");
    let door = Portal::parse("12,1.25,-3.6,-1,0,0,1,2.2").expect("door");
    // the whole building, all eight openings: from its rooms the outside is drawn only through
    // their part of the view
    let spec = lemi_scene::builtin::BuiltinSpec::parse("builtin:interior:20k:1").expect("spec");
    let enclosure = lemi_scene::builtin::interior_layout(&spec)
        .expect("layout")
        .enclosure();
    assert_eq!(
        enclosure
            .rooms
            .iter()
            .map(|r| r.openings.len())
            .sum::<usize>(),
        8
    );
    assert_eq!(enclosure.doorways.len(), 3);
    let bundles = vec![
        bake(
            &gpu,
            &scene,
            &window,
            7.5,
            &enclosure,
            &dir.path().join("portal-0"),
        ),
        bake(
            &gpu,
            &scene,
            &door,
            8.5,
            &enclosure,
            &dir.path().join("portal-1"),
        ),
    ];
    let materials =
        Arc::new(GpuMaterials::upload(&gpu, &scene.materials, &scene.textures).expect("mats"));
    let mut strategy =
        PortalStrategy::new(&gpu, &scene, materials.clone(), &bundles).expect("portals");
    assert!(strategy.has_enclosure());
    assert!(strategy.class_count() >= 3, "{}", strategy.class_count());
    let mut unwindowed = PortalStrategy::new(&gpu, &scene, materials.clone(), &bundles)
        .expect("portals")
        .without_enclosure();
    assert!(!unwindowed.has_enclosure());
    let full = GpuScene::upload(&gpu, &scene, &UploadOptions::default()).expect("scene");
    let reference = Renderer::new(&gpu).expect("renderer");
    let options = RenderOptions::default();
    let frame = |strategy: &mut PortalStrategy, eye: DVec3, target: DVec3| {
        let v = view(eye, target);
        let f = strategy.frame(&request(eye, &v, &options)).expect("frame");
        let r = reference.render(&full, &v, &options).expect("reference");
        (f, r)
    };
    let total = scene.triangle_count();
    // in the rooms, the window changes no pixel but draws fewer triangles: looking out of the
    // window, along the room, down at the floor (no opening in view: no quads either)
    let mut fewer = 0;
    for (eye, target, openings_in_view) in [
        (
            DVec3::new(16.2, 1.75, -3.0),
            DVec3::new(16.2, 1.75, -40.0),
            true,
        ),
        (
            DVec3::new(14.0, 1.7, -5.0),
            DVec3::new(19.0, 1.5, -1.0),
            true,
        ),
        (
            DVec3::new(16.0, 1.7, -3.0),
            DVec3::new(16.0, 0.15, -3.5),
            false,
        ),
    ] {
        let v = view(eye, target);
        let request = request(eye, &v, &options);
        let a = strategy.frame(&request).expect("windowed frame");
        let b = unwindowed.frame(&request).expect("frame");
        let (coverage, _, _, same) =
            compare(a.pixels().expect("pixels"), b.pixels().expect("pixels"));
        let n = (W * H) as usize;
        println!(
            "{eye}: {} triangles windowed, {} without; {same} of {n} pixels identical",
            a.near_triangles, b.near_triangles
        );
        assert!(same * 1000 >= n * 999, "{eye}: {same} of {n} identical");
        assert!(coverage * 1000 <= n, "{eye}: {coverage}");
        assert!(a.near_triangles <= b.near_triangles, "{eye}");
        if a.near_triangles < b.near_triangles {
            fewer += 1;
        }
        if !openings_in_view {
            assert_eq!(a.far_primitives, 0, "{eye}: quads with no opening in view");
        }
    }
    assert_eq!(fewer, 3, "the window culled nothing");
    // from every room's centre, eight ways round and up and down: the other rooms drawn only
    // through the doorways change no pixel, and where a room is out of sight its walls are not
    // drawn
    let layout = lemi_scene::builtin::interior_layout(&spec).expect("layout");
    let (mut views, mut fewer) = (0, 0);
    for room in &layout.rooms {
        let c = (DVec3::from_array(room.min.map(f64::from))
            + DVec3::from_array(room.max.map(f64::from)))
            * 0.5;
        for k in 0..10 {
            let a = std::f64::consts::TAU * k as f64 / 8.0;
            let dir = match k {
                8 => DVec3::new(0.3, 1.0, 0.0),
                9 => DVec3::new(0.0, -1.0, 0.3),
                _ => DVec3::new(a.cos(), -0.1, a.sin()),
            };
            let v = view(c, c + dir);
            let request = request(c, &v, &options);
            let a = strategy.frame(&request).expect("room frame");
            let b = unwindowed.frame(&request).expect("frame");
            let (coverage, _, _, same) =
                compare(a.pixels().expect("pixels"), b.pixels().expect("pixels"));
            let n = (W * H) as usize;
            assert!(
                same * 1000 >= n * 999,
                "{}, {dir}: {same} of {n} identical",
                room.name
            );
            assert!(coverage * 1000 <= n, "{}, {dir}: {coverage}", room.name);
            assert!(a.near_triangles <= b.near_triangles, "{}, {dir}", room.name);
            views += 1;
            if a.near_triangles < b.near_triangles {
                fewer += 1;
            }
        }
    }
    println!("rooms: {fewer} of {views} views drew fewer triangles");
    assert!(
        fewer * 2 > views,
        "the rooms culled little: {fewer} of {views}"
    );
    // inside the window's shaft, looking out through it
    for (eye, target) in [
        (DVec3::new(16.2, 1.75, -3.0), DVec3::new(16.2, 1.75, -40.0)),
        (DVec3::new(17.5, 2.2, -1.0), DVec3::new(14.0, 1.0, -40.0)),
        (DVec3::new(15.0, 1.3, -4.5), DVec3::new(22.0, 3.0, -40.0)),
    ] {
        let (f, r) = frame(&mut strategy, eye, target);
        assert!(f.far_primitives > 0, "{eye}: no quads");
        assert!(
            f.near_triangles < total,
            "{eye}: {} triangles",
            f.near_triangles
        );
        let (coverage, both, diff, _) = compare(f.pixels().expect("pixels"), &r);
        let n = (W * H) as usize;
        println!("{eye}: coverage differs {coverage} px, {both} px drawn, mean |diff| {diff:.2}");
        assert!(
            coverage * 200 <= n,
            "{eye}: {coverage} pixels differ in coverage"
        );
        assert!(diff <= 6.0, "{eye}: mean colour difference {diff}");
    }
    // outside every cell: the geometry's frame
    for (eye, target) in [
        (DVec3::new(0.0, 1.7, -20.0), DVec3::new(16.0, 2.0, -7.0)),
        (DVec3::new(16.2, 1.75, -6.5), DVec3::new(16.2, 1.75, -40.0)),
    ] {
        assert_eq!(strategy.active(eye), 0, "{eye}");
        let (f, r) = frame(&mut strategy, eye, target);
        assert_eq!(f.far_primitives, 0, "{eye}");
        let (coverage, _, _, same) = compare(f.pixels().expect("pixels"), &r);
        let n = (W * H) as usize;
        assert!(
            same * 1000 >= n * 999,
            "{eye}: {same} of {n} pixels identical"
        );
        assert!(coverage * 1000 <= n, "{eye}: {coverage}");
    }
    // not an object impostor's bundle
    let city_dir = tempfile::tempdir().expect("tempdir");
    let params = lemi_testkit::small_params(32, LayerTarget::Layers(2));
    lemi_testkit::bake_grid(
        &gpu,
        &scene,
        &params,
        &lemi_testkit::row_of_cells(1),
        city_dir.path(),
        "interior",
    );
    let cells = Bundle::open(city_dir.path()).expect("cells");
    let e = PortalStrategy::new(&gpu, &scene, materials, &[cells]).expect_err("refused");
    assert!(e.to_string().contains("not an object impostor"), "{e}");
}
