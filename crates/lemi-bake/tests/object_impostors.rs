//! Object impostors (TR-186-2-02-04 sec. 2.1-2.2; `lemi bake-object`): objects crossing many
//! layers, baked for a box and for a shaft view cell, rendered through the impostor renderer from
//! the cell's corners, edge midpoints and (shafts) points far back, show no crack; bundles round-
//! trip; the runtime's cell lookup never serves the impostor outside its view cell.
//!
//! **The crack criterion.** A pixel is judged when the reference shows the object there and at
//! all 8 neighbours (inside the object's image, not on a silhouette, where the impostor may
//! legitimately move by about a pixel); it is a crack when the impostor shows background there.
//! Behind the object there is nothing, so a hole in a layer, a missing slab or a seam between two
//! layers shows as background. [`the_crack_criterion_has_teeth`] drops one layer's quads and
//! checks that the same criterion then finds cracks.
//!
//! Without an adapter the tests fail with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.

use std::sync::Arc;

use glam::DVec3;
use lemi_bake::object_bake::{bake_object, object_params, write_object_bundle, ObjectBake};
use lemi_core::bundle::{BakeParams, Bundle, LayerTarget, SceneRef};
use lemi_core::camera::{Camera, View};
use lemi_core::classify::TriRef;
use lemi_core::object_cell::{object_bounds, ObjectSetup, ObjectViewCell};
use lemi_core::placement::{alpha_from_output_view, PixelChoice};
use lemi_core::{Face, Material, Mesh, Scene, SceneBuilder, Vertex};
use lemi_gpu::{
    Frame, Gpu, GpuMaterials, GpuScene, ImpostorCell, ImpostorRenderer, RenderOptions, Renderer,
    UploadOptions,
};
use lemi_testkit::{gpu, serial};

/// Output view of the judged images (α is its edge pixel).
const WIDTH: u32 = 192;
const HEIGHT: u32 = 144;
const FOV_X: f64 = 60.0;
/// Texels across the impostor.
const RES: u32 = 256;
const CLEAR: [u8; 4] = [255, 0, 255, 255];

fn vertex(p: DVec3, n: DVec3, c: [u8; 4]) -> Vertex {
    Vertex::new(
        p.as_vec3().to_array(),
        n.normalize_or(DVec3::Y).as_vec3().to_array(),
        [0.0, 0.0],
        c,
    )
}

/// A wavy strip along +X from `x0` to `x1` (26 m wide, graded: finer near), below eye height, so
/// that from a cell looking along +X it crosses every layer at a grazing angle.
fn strip(x0: f64, x1: f64) -> Mesh {
    let height = |x: f64, z: f64| -1.5 + 0.8 * (0.21 * x).sin() * (0.3 * z).cos() + 0.02 * x;
    let mut xs = vec![x0];
    while *xs.last().unwrap_or(&x1) < x1 {
        let x = xs[xs.len() - 1];
        xs.push((x + 0.25 + 0.02 * (x - x0)).min(x1));
    }
    let zs: Vec<f64> = (0..=52).map(|k| -13.0 + 0.5 * k as f64).collect();
    let mut mesh = Mesh {
        material: 0,
        vertices: Vec::new(),
        indices: Vec::new(),
    };
    for &x in &xs {
        for &z in &zs {
            let (dx, dz) = (
                height(x + 0.01, z) - height(x - 0.01, z),
                height(x, z + 0.01) - height(x, z - 0.01),
            );
            let n = DVec3::new(-dx / 0.02, 1.0, -dz / 0.02);
            let shade = (120.0 + 100.0 * ((x * 0.7).sin() * (z * 0.9).cos()).abs()) as u8;
            mesh.vertices.push(vertex(
                DVec3::new(x, height(x, z), z),
                n,
                [shade, 200, 90, 255],
            ));
        }
    }
    let w = zs.len() as u32;
    for i in 0..xs.len() as u32 - 1 {
        for j in 0..w - 1 {
            let a = i * w + j;
            mesh.indices
                .extend_from_slice(&[a, a + w, a + 1, a + 1, a + w, a + w + 1]);
        }
    }
    mesh
}

/// A bumpy closed ball of radius `r` around `c` (its depth spans several layers).
fn ball(c: DVec3, r: f64) -> Mesh {
    let (nu, nv) = (96u32, 48u32);
    let mut mesh = Mesh {
        material: 0,
        vertices: Vec::new(),
        indices: Vec::new(),
    };
    for j in 0..=nv {
        let th = std::f64::consts::PI * j as f64 / nv as f64;
        for i in 0..=nu {
            let ph = std::f64::consts::TAU * i as f64 / nu as f64;
            let d = DVec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
            let rr = r * (1.0 + 0.08 * (5.0 * ph).sin() * (4.0 * th).sin());
            let shade = (100.0 + 150.0 * (0.5 + 0.5 * (3.0 * ph).sin())) as u8;
            mesh.vertices
                .push(vertex(c + d * rr, d, [200, shade, 255 - shade, 255]));
        }
    }
    let w = nu + 1;
    for j in 0..nv {
        for i in 0..nu {
            let a = j * w + i;
            mesh.indices
                .extend_from_slice(&[a, a + 1, a + w, a + 1, a + w + 1, a + w]);
        }
    }
    mesh
}

fn scene(meshes: Vec<Mesh>) -> Scene {
    let mut b = SceneBuilder::new();
    b.add_material(Material {
        name: "white".into(),
        base_color: [1.0; 4],
        texture: None,
    });
    for m in meshes {
        b.add_mesh(m);
    }
    b.finish()
}

fn alpha() -> f64 {
    alpha_from_output_view(FOV_X.to_radians(), WIDTH, PixelChoice::Edge).expect("alpha")
}

fn all_triangles(scene: &Scene) -> Vec<TriRef> {
    let mut v = Vec::new();
    for (m, mesh) in scene.meshes.iter().enumerate() {
        for t in 0..mesh.triangle_count() as u32 {
            v.push(TriRef {
                mesh: m as u32,
                tri: t,
            });
        }
    }
    v
}

fn bake(gpu: &Gpu, scene: &Scene, cell: ObjectViewCell) -> (ObjectSetup, ObjectBake, BakeParams) {
    let object = all_triangles(scene);
    let setup = ObjectSetup::new(cell, object_bounds(scene, &object), Some(RES), alpha())
        .expect("object setup");
    let placement = setup.place().expect("placement");
    let params = object_params(&setup, placement.layers.len(), &scene_params());
    let baked = bake_object(gpu, scene, &object, &setup, params.clone(), |_| {}).expect("bake");
    (setup, baked, params)
}

fn view(eye: DVec3, at: DVec3) -> View {
    let fov_y = 2.0
        * ((0.5 * FOV_X.to_radians()).tan() * HEIGHT as f64 / WIDTH as f64)
            .atan()
            .to_degrees();
    Camera::look_at(eye, at, DVec3::Y, fov_y, WIDTH, HEIGHT)
        .expect("camera")
        .with_near(0.05)
        .expect("near")
        .view()
}

/// Judged pixels and cracks of one view (see the module docs).
fn cracks(reference: &Frame, impostor: &Frame) -> (usize, usize) {
    let (w, h) = (reference.width as usize, reference.height as usize);
    let on = |f: &Frame, x: usize, y: usize| f.depth[y * w + x].is_finite();
    let (mut judged, mut cracks) = (0, 0);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let inside = (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| on(reference, xx, yy)));
            if !inside {
                continue;
            }
            judged += 1;
            if !on(impostor, x, y) {
                cracks += 1;
            }
        }
    }
    (judged, cracks)
}

/// Renders the reference and the impostor from every viewpoint of the cell, looking at the
/// object's centre; returns (views, judged pixels, cracks, the worst view's label).
fn judge(
    gpu: &Gpu,
    scene: &Scene,
    setup: &ObjectSetup,
    baked: &ObjectBake,
) -> (usize, usize, usize, String) {
    let materials =
        Arc::new(GpuMaterials::upload(gpu, &scene.materials, &scene.textures).expect("materials"));
    let full = GpuScene::upload(gpu, scene, &UploadOptions::default()).expect("scene");
    let cell =
        ImpostorCell::upload_file(gpu, materials, scene, &baked.file).expect("impostor cell");
    let reference = Renderer::new(gpu).expect("renderer");
    let impostors = ImpostorRenderer::new(gpu).expect("impostor renderer");
    let options = RenderOptions {
        clear: CLEAR,
        ..Default::default()
    };
    let (mut views, mut judged, mut found) = (0, 0, 0);
    let mut worst = (0, String::new());
    for (label, eye) in setup.cell.eval_viewpoints(2, 7) {
        if label.starts_with("face") {
            continue;
        }
        let v = view(eye, setup.object_centre());
        let r = reference.render(&full, &v, &options).expect("reference");
        let i = impostors.render(&cell, &v, &options).expect("impostor");
        let (j, c) = cracks(&r, &i);
        views += 1;
        judged += j;
        found += c;
        if c > worst.0 {
            worst = (c, label);
        }
    }
    (views, judged, found, worst.1)
}

fn assert_no_cracks(name: &str, scene: Scene, cell: ObjectViewCell, min_layers: usize) {
    let _guard = serial();
    let Some(gpu) = gpu() else { return };
    let (setup, baked, _) = bake(&gpu, &scene, cell);
    let layers = baked.placement.layers.len();
    assert!(
        layers >= min_layers,
        "{name}: only {layers} layers; the test needs an object crossing many"
    );
    assert!(!baked.file.header.quads.is_empty(), "{name}: no quads");
    let (views, judged, found, worst) = judge(&gpu, &scene, &setup, &baked);
    eprintln!("{name}: {layers} layers, {views} views, {judged} judged pixels, {found} cracks");
    assert!(
        judged > 1000 * views / 10,
        "{name}: too few judged pixels ({judged})"
    );
    assert_eq!(
        found, 0,
        "{name}: {found} crack pixels (worst view: {worst})"
    );
}

#[test]
fn a_strip_across_many_layers_shows_no_crack_from_a_box_cell() {
    let cell = ObjectViewCell::parse("box:-3,-1,-3,3,2,3").expect("cell");
    assert_no_cracks("strip, box", scene(vec![strip(6.0, 160.0)]), cell, 8);
}

#[test]
fn a_ball_shows_no_crack_from_a_box_cell_and_from_a_shaft() {
    let c = DVec3::new(40.0, 3.0, 2.0);
    let box_cell = ObjectViewCell::parse("box:0,0,-4,8,6,4").expect("cell");
    assert_no_cracks("ball, box", scene(vec![ball(c, 9.0)]), box_cell, 3);
    // a shaft toward the ball from −X and a little above: points far back in it see the most
    let shaft = ObjectViewCell::parse("shaft:40,3,2,-1,0.15,0.1,24,20").expect("shaft");
    assert_no_cracks("ball, shaft", scene(vec![ball(c, 9.0)]), shaft, 3);
}

#[test]
fn a_strip_shows_no_crack_from_a_shaft() {
    // apex in the middle of the strip, the shaft opening back along −X
    let shaft = ObjectViewCell::parse("shaft:90,-1,0,-1,0.02,0,16,80").expect("shaft");
    assert_no_cracks("strip, shaft", scene(vec![strip(12.0, 160.0)]), shaft, 8);
}

#[test]
fn the_crack_criterion_has_teeth() {
    let _guard = serial();
    let Some(gpu) = gpu() else { return };
    let scene = scene(vec![strip(6.0, 160.0)]);
    let cell = ObjectViewCell::parse("box:-3,-1,-3,3,2,3").expect("cell");
    let (setup, mut baked, _) = bake(&gpu, &scene, cell);
    // drop the quads of a middle layer
    let n = baked.placement.layers.len() as u16;
    let before = baked.file.header.quads.len();
    baked.file.header.quads.retain(|q| q.layer != n / 2);
    assert!(baked.file.header.quads.len() < before);
    let (_, _, found, _) = judge(&gpu, &scene, &setup, &baked);
    assert!(found > 0, "a missing layer must show as cracks");
}

#[test]
fn object_bundles_round_trip_and_serve_only_their_view_cell() {
    let _guard = serial();
    let Some(gpu) = gpu() else { return };
    let c = DVec3::new(40.0, 3.0, 2.0);
    // the ball and a second object that stays geometry
    let scene = scene(vec![ball(c, 9.0), ball(DVec3::new(-30.0, 0.0, 0.0), 2.0)]);
    let object: Vec<TriRef> = all_triangles(&scene)
        .into_iter()
        .filter(|r| r.mesh == 0)
        .collect();
    let cell = ObjectViewCell::parse("box:0,0,-4,8,6,4").expect("cell");
    let setup =
        ObjectSetup::new(cell, object_bounds(&scene, &object), Some(128), alpha()).expect("setup");
    let placement = setup.place().expect("placement");
    let base = BakeParams {
        resolution: 128,
        ..scene_params()
    };
    let params = object_params(&setup, placement.layers.len(), &base);
    let mut baked =
        bake_object(&gpu, &scene, &object, &setup, params.clone(), |_| {}).expect("bake");
    // the near list is exactly the other object
    assert_eq!(
        baked.file.near.len(),
        scene.meshes[1].triangle_count(),
        "every triangle but the object's is drawn as geometry"
    );
    assert!(baked.file.near.iter().all(|&[m, _]| m == 1));
    let dir = tempfile::tempdir().expect("temp dir");
    let scene_ref = SceneRef {
        sources: vec!["test:object".into()],
        up: "y".into(),
        fingerprint: "fingerprint-of-the-object-scene".into(),
        triangles: scene.triangle_count(),
    };
    write_object_bundle(dir.path(), scene_ref, &params, &mut baked).expect("write");
    let bundle = Bundle::open(dir.path()).expect("open");
    let manifest = bundle.manifest();
    assert_eq!(manifest.version, lemi_core::bundle::OBJECT_BUNDLE_VERSION);
    // inside the cell (its corners too): the cell; outside, even in the nominal grid cell: none
    for (label, p) in setup.cell.eval_viewpoints(4, 1) {
        let (_, file) = bundle.cell_at(p).unwrap_or_else(|e| panic!("{label}: {e}"));
        assert_eq!(
            file.header.quads, baked.file.header.quads,
            "corners read back exactly"
        );
        assert_eq!(file.header.object.as_ref(), Some(&setup));
    }
    for p in [
        DVec3::new(8.5, 3.0, 0.0),
        DVec3::new(4.0, 3.0, 4.01),
        DVec3::new(20.0, 3.0, 0.0),
        DVec3::new(-1.0, 3.0, 0.0),
    ] {
        assert!(manifest.locate(p).is_none(), "{p} is outside the view cell");
        let e = bundle.cell_at(p).expect_err("outside");
        assert!(
            e.to_string()
                .contains("outside the object impostor's view cell"),
            "{e}"
        );
    }
}

#[test]
fn an_object_impostor_replaces_its_object_in_a_cells_near_field() {
    use lemi_core::cell::ViewCell;
    use lemi_core::object_cell::compose_objects;
    let _guard = serial();
    let Some(gpu) = gpu() else { return };
    // an environment-map cell with few layers (a wide near field), a ball inside that near field
    // and a far strip in its layers
    let cell = ViewCell {
        index: glam::IVec3::ZERO,
        center: DVec3::new(0.0, 2.0, 0.0),
        half: DVec3::new(3.0, 1.0, 3.0),
    };
    let env_params = BakeParams {
        cell_size: 6.0,
        cell_height: Some(2.0),
        resolution: RES,
        target: LayerTarget::Layers(3),
        faces: Face::HORIZONTAL.to_vec(),
        alpha: alpha(),
        output_fov_deg: Some(FOV_X),
        output_width: Some(WIDTH),
        micro_grid: 8,
        micro_threshold: 0.6,
        layering: Default::default(),
        texture_format: Default::default(),
        outline_copies: false,
        outline_fringe: false,
    };
    let probe = scene(vec![ball(DVec3::new(30.0, 3.0, 1.0), 4.0)]);
    let near_field = lemi_bake::Baker::new(&gpu, &probe, env_params.clone())
        .expect("baker")
        .plan(&cell)
        .expect("plan")
        .near_field;
    let c = DVec3::new(0.5 * near_field, 3.0, 1.0);
    let radius = 0.15 * c.x;
    assert!(c.x - radius > cell.half.x, "the ball lies outside the cell");
    let scene = scene(vec![
        ball(c, radius),
        strip(near_field + 5.0, near_field + 80.0),
    ]);
    let env = lemi_bake::Baker::new(&gpu, &scene, env_params)
        .expect("baker")
        .bake(&cell, |_| {})
        .expect("env bake");
    let ball_tris = scene.meshes[0].triangle_count();
    assert!(
        env.near.iter().filter(|t| t[0] == 0).count() == ball_tris,
        "the ball is in the cell's near field"
    );
    // the ball's impostor for the cell's box
    let object: Vec<TriRef> = all_triangles(&scene)
        .into_iter()
        .filter(|r| r.mesh == 0)
        .collect();
    let view_cell = ObjectViewCell::Box {
        min: cell.center - cell.half,
        max: cell.center + cell.half,
    };
    let setup = ObjectSetup::new(
        view_cell,
        object_bounds(&scene, &object),
        Some(RES),
        alpha(),
    )
    .expect("setup");
    let placement = setup.place().expect("placement");
    let params = object_params(&setup, placement.layers.len(), &scene_params());
    let obj = bake_object(&gpu, &scene, &object, &setup, params, |_| {}).expect("object bake");
    let (composed, n) = compose_objects(&env, &[&obj.file]).expect("compose");
    assert_eq!(n, 1);
    assert_eq!(composed.near.len(), env.near.len() - ball_tris);
    assert_eq!(
        composed.header.quads.len(),
        env.header.quads.len() + obj.file.header.quads.len()
    );
    // composed with an object that is not in the near field: nothing changes
    let (same, none) = compose_objects(&composed, &[&obj.file]).expect("compose again");
    assert_eq!((none, same.near.len()), (0, composed.near.len()));
    // the composed cell shows the ball without cracks from the cell's corners and edges
    let materials =
        Arc::new(GpuMaterials::upload(&gpu, &scene.materials, &scene.textures).expect("materials"));
    let full = GpuScene::upload(&gpu, &scene, &UploadOptions::default()).expect("scene");
    let drawn = ImpostorCell::upload_file(&gpu, materials, &scene, &composed).expect("cell");
    let reference = Renderer::new(&gpu).expect("renderer");
    let impostors = ImpostorRenderer::new(&gpu).expect("impostor renderer");
    let options = RenderOptions {
        clear: CLEAR,
        ..Default::default()
    };
    let (mut judged, mut found) = (0, 0);
    for (label, eye) in view_cell.eval_viewpoints(2, 3) {
        if label.starts_with("face") {
            continue;
        }
        let v = view(eye, c);
        let r = reference.render(&full, &v, &options).expect("reference");
        let i = impostors.render(&drawn, &v, &options).expect("impostor");
        let (j, k) = cracks(&r, &i);
        judged += j;
        found += k;
    }
    assert!(
        judged > 10_000,
        "{judged} judged pixels, near field {near_field}, ball at {c} radius {radius}"
    );
    assert_eq!(found, 0, "{found} crack pixels");
}

/// The object bake parameters of these tests, before [`object_params`].
fn scene_params() -> BakeParams {
    BakeParams {
        cell_size: 1.0,
        cell_height: None,
        resolution: RES,
        target: LayerTarget::Layers(1),
        faces: vec![Face::PosZ],
        alpha: alpha(),
        output_fov_deg: Some(FOV_X),
        output_width: Some(WIDTH),
        micro_grid: 8,
        micro_threshold: 0.6,
        layering: Default::default(),
        texture_format: Default::default(),
        outline_copies: false,
        outline_fringe: false,
    }
}
