//! The three layerings of a bake (`BakeParams::layering`) on one small cell: the optimal placement
//! (lemi), one layer per face (cubemap) and Schaufler's equidistant overlapping layers.
//!
//! - the layers per face: the single layering has one layer and the one-layer placement's near
//!   field; the equidistant one has the optimal placement's layer count and near field, borders
//!   spaced uniformly up to the farthest scene point, quads in the middle of their slabs;
//! - each is recognisable: the impostor render at the cell centre (near geometry + quads through
//!   `lemi_gpu::ImpostorRenderer`) matches the reference render of the full scene within stated
//!   bounds (mean absolute RGB difference, share of clearly differing pixels, share of holes), and
//!   the same cell without its quads does not (the bounds have teeth);
//! - `Baker::record_depths` is consistent with the bake: same faces and layer distances, and the
//!   re-recorded depth images cover the baked texels (all of them for the equidistant layering,
//!   which adds none by gap filling or near-seam closing);
//! - the equidistant bake fills no gaps and records the triangles of the overlaps twice;
//!   `BakeParams::validate` rejects a bad overlap by name.
//!
//! Without an adapter the GPU tests fail with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.

use std::sync::Arc;

use glam::{DVec3, IVec3};
use lemi_bake::Baker;
use lemi_core::bundle::{BakeParams, CellFile, LayerTarget, Layering};
use lemi_core::camera::Camera;
use lemi_core::cell::ViewCell;
use lemi_core::compress::{MacroPlacement, MacroTexture};
use lemi_core::layering::{axis_of, farthest_along};
use lemi_core::placement::{place_env_layers, EnvParams, Target};
use lemi_core::{Face, Material, Mesh, Scene, SceneBuilder, Vertex};
use lemi_gpu::{
    Frame, Gpu, GpuMaterials, GpuScene, ImpostorCell, ImpostorRenderer, RenderOptions, Renderer,
    UploadOptions,
};
use lemi_testkit::gpu;

/// Texels per face side, and the width of the compared views.
const RES: u32 = 64;
const LAYERS: u32 = 4;
const ALPHA: f64 = 0.02;

fn params(layering: Layering) -> BakeParams {
    BakeParams {
        cell_size: 10.0,
        cell_height: None,
        resolution: RES,
        target: LayerTarget::Layers(LAYERS),
        faces: Face::HORIZONTAL.to_vec(),
        alpha: ALPHA,
        output_fov_deg: None,
        output_width: None,
        micro_grid: 8,
        micro_threshold: 0.6,
        layering,
        texture_format: Default::default(),
        outline_copies: false,
        outline_fringe: false,
    }
}

const EQUIDISTANT: Layering = Layering::Equidistant { overlap: 0.1 };

fn layerings() -> [(&'static str, Layering); 3] {
    [
        ("optimal", Layering::Optimal),
        ("single", Layering::Single),
        ("equidistant", EQUIDISTANT),
    ]
}

fn cell() -> ViewCell {
    ViewCell {
        index: IVec3::ZERO,
        center: DVec3::new(0.0, 1.7, 0.0),
        half: DVec3::splat(5.0),
    }
}

// ---------------------------------------------------------------------------------------------
// the scene

fn vertex(p: [f32; 3], n: [f32; 3], color: [u8; 4]) -> Vertex {
    Vertex::new(p, n, [0.0; 2], color)
}

/// An axis-aligned box standing on the ground, its own shade of `color` per side (12 triangles).
fn add_box(mesh: &mut Mesh, min: [f32; 3], max: [f32; 3], color: [u8; 3]) {
    let shade = |n: [f32; 3]| match n {
        [1.0, _, _] => 1.0,
        [-1.0, _, _] => 0.8,
        [_, 1.0, _] => 0.6,
        [_, _, 1.0] => 0.9,
        _ => 0.7,
    };
    let sides = lemi_testkit::box_sides(min, max, false);
    lemi_testkit::push_quads(mesh, &sides, lemi_testkit::NO_UV, |n| {
        let c = color.map(|v| (v as f32 * shade(n)) as u8);
        [c[0], c[1], c[2], 255]
    });
}

/// Height of the test terrain: flat within 60 m of the cell, then rising ever more steeply (a
/// bowl), so the far field of every layering fills a good part of every view from the cell.
fn height(x: f32, z: f32) -> f32 {
    let r = ((x * x + z * z).sqrt() - 60.0).max(0.0);
    0.001 * r * r
}

/// A checkered terrain of 20 m tiles over ±600 m ([`height`]) and towers in 8 directions at 20 m
/// (inside the near field of every layering) to 560 m (beyond the one-layer near field); one white
/// material, vertex colours. About 7 500 triangles.
fn scene() -> Scene {
    let mut b = SceneBuilder::new();
    b.add_source("test:strategies");
    let white = b.add_material(Material {
        name: "white".into(),
        base_color: [1.0; 4],
        texture: None,
    });
    let mut ground = Mesh {
        material: white,
        ..Default::default()
    };
    let (tile, n) = (20.0f32, 60);
    for j in 0..n {
        for i in 0..n {
            let x0 = -600.0 + tile * i as f32;
            let z0 = -600.0 + tile * j as f32;
            let c = if (i + j) % 2 == 0 {
                [200, 200, 190, 255]
            } else {
                [90, 130, 70, 255]
            };
            let base = ground.vertices.len() as u32;
            for [x, z] in [
                [x0, z0],
                [x0, z0 + tile],
                [x0 + tile, z0 + tile],
                [x0 + tile, z0],
            ] {
                let (e, y) = (0.5, height(x, z));
                let n = glam::Vec3::new(
                    height(x - e, z) - height(x + e, z),
                    2.0 * e,
                    height(x, z - e) - height(x, z + e),
                )
                .normalize();
                ground.vertices.push(vertex([x, y, z], n.to_array(), c));
            }
            ground
                .indices
                .extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
        }
    }
    b.add_mesh(ground);
    let mut boxes = Mesh {
        material: white,
        ..Default::default()
    };
    let palette: [[u8; 3]; 6] = [
        [230, 80, 60],
        [60, 120, 230],
        [240, 200, 60],
        [150, 70, 200],
        [60, 200, 190],
        [250, 250, 250],
    ];
    let distances = [20.0f32, 45.0, 70.0, 110.0, 170.0, 260.0, 380.0, 560.0];
    for k in 0..8 {
        let a = std::f32::consts::FRAC_PI_4 * k as f32 + 0.2;
        let (dx, dz) = (a.cos(), a.sin());
        for (m, &d) in distances.iter().enumerate() {
            // alternate sides of the ray, so near boxes do not hide all far ones
            let side = if m % 2 == 0 { 0.12 } else { -0.12 };
            let (cx, cz) = (d * (dx - side * dz), d * (dz + side * dx));
            let w = 1.5 + 0.05 * d;
            let (y0, h) = (height(cx, cz) - 1.0, 8.0 + 0.1 * d);
            add_box(
                &mut boxes,
                [cx - w, y0, cz - w],
                [cx + w, y0 + h, cz + w],
                palette[(k + m) % palette.len()],
            );
        }
    }
    b.add_mesh(boxes);
    b.finish()
}

// ---------------------------------------------------------------------------------------------
// rendering and comparing

/// The compared views from `eye`: along the four face axes and the four diagonals (seams between
/// faces), horizontal, 90° vertical field of view, `RES × RES` pixels (about a texel a pixel).
fn views_from(eye: DVec3) -> Vec<(String, lemi_core::camera::View)> {
    (0..8)
        .map(|k| {
            let a = std::f64::consts::FRAC_PI_4 * k as f64;
            let dir = DVec3::new(a.cos(), 0.0, a.sin());
            let cam = Camera::new(eye, dir, DVec3::Y, 90.0, RES, RES).expect("camera");
            (format!("yaw{}", 45 * k), cam.view())
        })
        .collect()
}

/// The four horizontal corners of the cell (just inside), at the centre's height.
fn corners() -> Vec<DVec3> {
    let c = cell();
    let h = 0.98 * c.half;
    [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .map(|(x, z)| c.center + DVec3::new(x * h.x, 0.0, z * h.z))
        .to_vec()
}

/// How much an impostor image differs from the reference.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Diff {
    pixels: u64,
    /// Sum over pixels of the mean absolute RGB difference (0..255).
    abs_sum: f64,
    /// Pixels whose largest channel difference exceeds [`DIFFERS`].
    differing: u64,
    /// Pixels where the reference shows a surface and the impostor background.
    holes: u64,
    reference_covered: u64,
}

/// A channel difference that is clearly not resampling noise.
const DIFFERS: i32 = 48;

impl Diff {
    fn add(&mut self, reference: &Frame, impostor: &Frame) {
        for (r, i) in reference
            .rgba
            .chunks_exact(4)
            .zip(impostor.rgba.chunks_exact(4))
        {
            self.pixels += 1;
            let d: Vec<i32> = (0..3).map(|c| (r[c] as i32 - i[c] as i32).abs()).collect();
            self.abs_sum += d.iter().sum::<i32>() as f64 / 3.0;
            if d.iter().any(|&x| x > DIFFERS) {
                self.differing += 1;
            }
            if r[3] == 255 {
                self.reference_covered += 1;
                if i[3] != 255 {
                    self.holes += 1;
                }
            }
        }
    }
    fn mean_abs(&self) -> f64 {
        self.abs_sum / self.pixels.max(1) as f64
    }
    fn differing_share(&self) -> f64 {
        self.differing as f64 / self.pixels.max(1) as f64
    }
    fn hole_share(&self) -> f64 {
        self.holes as f64 / self.reference_covered.max(1) as f64
    }
}

/// Bounds every layering must meet at the cell centre, over the 8 views (measured on llvmpipe:
/// optimal 4.6 / 5.8 % / 0, single 4.1 / 4.9 % / 0, equidistant 2.7 / 4.3 % / 0.09 %; the cell
/// without quads: 29-35 / 18-21 % / 22-25 %). The conservative recording of the optimal and single
/// layerings grows silhouettes by up to a texel, so at the reference viewpoint they differ a
/// little more than centre-sampled equidistant layers; off the centre it is the other way round.
const MAX_MEAN_ABS: f64 = 8.0;
const MAX_DIFFERING: f64 = 0.10;
const MAX_HOLES: f64 = 0.01;

fn within_bounds(d: &Diff) -> bool {
    d.mean_abs() <= MAX_MEAN_ABS
        && d.differing_share() <= MAX_DIFFERING
        && d.hole_share() <= MAX_HOLES
}

/// A baked cell and its decoded macro-textures.
struct Baked {
    file: CellFile,
    macros: Vec<MacroTexture>,
}

fn bake<'a>(gpu: &Gpu, scene: &'a Scene, layering: Layering) -> (Baked, Baker<'a>) {
    let baker = Baker::new(gpu, scene, params(layering)).expect("baker");
    let file = baker.bake(&cell(), |_| {}).expect("bake");
    // through the file format, as the runtime reads it
    let file = CellFile::decode(&file.encode().expect("encode")).expect("decode");
    let macros = file.decode_macros().expect("macro-textures");
    (Baked { file, macros }, baker)
}

/// Renders every view with the reference renderer and through the impostor renderer of `baked`
/// (with `quads = false`, the same cell without its quads: near geometry only).
/// With `LEMI_STRATEGIES_DUMP=DIR`, the compared views are written there as
/// `<name>_<view>.png`, reference | impostor side by side.
fn compare(gpu: &Gpu, scene: &Scene, baked: &Baked, quads: bool, name: &str) -> Diff {
    compare_from(gpu, scene, baked, quads, name, &[cell().center])
}

/// [`compare`] over the views of [`views_from`] every eye of `eyes`.
fn compare_from(
    gpu: &Gpu,
    scene: &Scene,
    baked: &Baked,
    quads: bool,
    name: &str,
    eyes: &[DVec3],
) -> Diff {
    let full = GpuScene::upload(gpu, scene, &UploadOptions::default()).expect("scene upload");
    let materials: Arc<GpuMaterials> = full.materials.clone();
    let no_quads = Vec::new();
    let cell = ImpostorCell::upload(
        gpu,
        materials,
        scene,
        &baked.file.near,
        if quads {
            &baked.file.header.quads
        } else {
            &no_quads
        },
        &baked.macros,
    )
    .expect("impostor cell upload");
    let reference = Renderer::new(gpu).expect("renderer");
    let impostors = ImpostorRenderer::new(gpu).expect("impostor renderer");
    let options = RenderOptions {
        clear: [0, 0, 0, 0],
        ..Default::default()
    };
    let mut diff = Diff::default();
    let dump = std::env::var_os("LEMI_STRATEGIES_DUMP").map(std::path::PathBuf::from);
    let views: Vec<(String, lemi_core::camera::View)> = eyes
        .iter()
        .enumerate()
        .flat_map(|(e, &eye)| {
            views_from(eye)
                .into_iter()
                .map(move |(n, v)| (format!("eye{e}_{n}"), v))
        })
        .collect();
    for (view_name, view) in views {
        let r = reference.render(&full, &view, &options).expect("reference");
        let i = impostors.render(&cell, &view, &options).expect("impostor");
        diff.add(&r, &i);
        if let Some(dir) = &dump {
            let w = 4 * r.width as usize;
            let both: Vec<u8> = r
                .rgba
                .chunks_exact(w)
                .zip(i.rgba.chunks_exact(w))
                .flat_map(|(a, b)| a.iter().chain(b).copied())
                .collect();
            let both: Vec<u8> = both
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect();
            let png = lemi_core::bundle::encode_png(&both, 2 * r.width, r.height).expect("png");
            std::fs::create_dir_all(dir).expect("dump dir");
            std::fs::write(dir.join(format!("{name}_{view_name}.png")), png).expect("dump");
        }
    }
    diff
}

/// The opaque texels of the baked quads, per (face slot, layer): linear texel indices.
fn baked_texels(b: &Baked, faces: &[Face]) -> Vec<Vec<Vec<usize>>> {
    let h = &b.file.header;
    let mut out: Vec<Vec<Vec<usize>>> =
        h.layers.iter().map(|l| vec![Vec::new(); l.len()]).collect();
    for q in &h.quads {
        let slot = faces
            .iter()
            .position(|&f| f == q.face)
            .expect("a baked face");
        let [x0, y0, x1, y1] = q.texels.map(u32::from);
        let p = MacroPlacement {
            macro_index: q.macro_index,
            x: q.rect[0],
            y: q.rect[1],
            rotated: q.rotated,
        };
        let m = &b.macros[q.macro_index as usize];
        for j in y0..y1 {
            for i in x0..x1 {
                let (mx, my) = p.macro_texel(x1 - x0, y1 - y0, i - x0, j - y0);
                if m.rgba[4 * (my * m.width + mx) as usize + 3] == 255 {
                    out[slot][q.layer as usize].push((j * h.resolution + i) as usize);
                }
            }
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// tests

/// Layer counts, near fields and spacing per face, for each layering.
#[test]
fn layers_per_face_follow_the_layering() {
    let Some(gpu) = gpu() else { return };
    let scene = scene();
    let c = cell();
    let (optimal, _) = bake(&gpu, &scene, Layering::Optimal);
    let (single, _) = bake(&gpu, &scene, Layering::Single);
    let (equi, _) = bake(&gpu, &scene, EQUIDISTANT);
    let (o, s, e) = (&optimal.file.header, &single.file.header, &equi.file.header);
    for h in [o, s, e] {
        assert_eq!(h.faces, Face::HORIZONTAL.to_vec());
        assert_eq!(h.layers.len(), 4);
    }
    for (slot, &face) in o.faces.iter().enumerate() {
        let env = EnvParams::box_face(c.half, axis_of(face), RES, ALPHA);
        let opt = place_env_layers(&env, Target::Layers(LAYERS as usize)).unwrap();
        let one = place_env_layers(&env, Target::Layers(1)).unwrap();
        // optimal: the placement as computed
        let ol = &o.layers[slot];
        assert_eq!(ol.len(), LAYERS as usize);
        for (a, b) in ol.iter().zip(&opt.layers) {
            assert_eq!(a.distance, b.distance);
            assert_eq!(a.near_border, b.near_border);
        }
        assert_eq!(ol.last().unwrap().near_border, opt.near_field);
        // single: one layer, the one-layer near field
        let sl = &s.layers[slot];
        assert_eq!(sl.len(), 1, "face {face}");
        assert_eq!(sl[0].distance, one.layers[0].distance);
        assert_eq!(sl[0].near_border, one.near_field);
        assert_eq!(sl[0].far_border, f64::MAX);
        // equidistant: the optimal count and near field, uniform borders up to the farthest point
        let el = &e.layers[slot];
        let n = el.len();
        assert_eq!(n, opt.layers.len(), "face {face}");
        assert_eq!(el[n - 1].near_border, opt.near_field);
        let far = farthest_along(&scene.bounds, c.center, face);
        assert!(
            far > opt.near_field,
            "the scene extends beyond the near field"
        );
        assert_eq!(el[0].far_border, far);
        let h = (far - opt.near_field) / n as f64;
        for (k, l) in el.iter().enumerate() {
            let near = opt.near_field + h * (n - 1 - k) as f64;
            assert!(
                (l.near_border - near).abs() < 1e-9 * far,
                "face {face} layer {k}: {l:?}"
            );
            assert!((l.far_border - l.near_border - h).abs() < 1e-9 * far);
            assert!((l.distance - (l.near_border + 0.5 * h)).abs() < 1e-9 * far);
        }
    }
    assert_eq!(s.near_field, {
        let env = EnvParams::box_face(c.half, axis_of(Face::PosX), RES, ALPHA);
        place_env_layers(&env, Target::Layers(1))
            .unwrap()
            .near_field
    });
    assert_eq!(e.near_field, o.near_field);
    assert!(s.near_field > o.near_field);
    // the single layer's near field leaves part of the scene in the far field
    assert!(s.near_field < 500.0, "{}", s.near_field);
    println!(
        "near field: optimal {:.1} m, single {:.1} m, equidistant {:.1} m",
        o.near_field, s.near_field, e.near_field
    );
    println!(
        "equidistant +X layers: {:?}",
        e.layers[0]
            .iter()
            .map(|l| (
                l.near_border.round(),
                l.distance.round(),
                l.far_border.round()
            ))
            .collect::<Vec<_>>()
    );
}

/// Each layering's impostor at the cell centre matches the reference render; without its quads it
/// does not.
#[test]
fn every_layering_is_recognisable_at_the_cell_centre() {
    let Some(gpu) = gpu() else { return };
    let scene = scene();
    let mut failures = Vec::new();
    for (name, layering) in layerings() {
        let (baked, _) = bake(&gpu, &scene, layering);
        let d = compare(&gpu, &scene, &baked, true, name);
        let s = &baked.file.header.stats;
        println!(
            "{name:12} mean |ΔRGB| {:.2}, differing {:.2} %, holes {} ({:.3} % of {} covered); \
             {} quads, {} micro-textures, PNG {} B, far {} / submitted {} triangles",
            d.mean_abs(),
            100.0 * d.differing_share(),
            d.holes,
            100.0 * d.hole_share(),
            d.reference_covered,
            baked.file.header.quads.len(),
            s.micro_textures,
            s.png_bytes,
            s.far_triangles,
            s.submitted_triangles
        );
        assert!(
            d.reference_covered > d.pixels / 3,
            "the scene fills the views: {d:?}"
        );
        if !within_bounds(&d) {
            failures.push(format!("{name}: {d:?}"));
        }
        // for information: from the cell's corners (where parallax, cracks and seams show)
        let off = compare_from(
            &gpu,
            &scene,
            &baked,
            true,
            &format!("{name}_corners"),
            &corners(),
        );
        println!(
            "{name:12} from the corners: mean |ΔRGB| {:.2}, differing {:.2} %, holes {} ({:.3} %)",
            off.mean_abs(),
            100.0 * off.differing_share(),
            off.holes,
            100.0 * off.hole_share()
        );
        // teeth: the same cell without its quads is far off
        let bare = compare(&gpu, &scene, &baked, false, &format!("{name}_bare"));
        println!(
            "{name:12} without quads: mean |ΔRGB| {:.2}, differing {:.2} %, holes {:.2} %",
            bare.mean_abs(),
            100.0 * bare.differing_share(),
            100.0 * bare.hole_share()
        );
        assert!(
            !within_bounds(&bare),
            "{name}: the bounds cannot tell a cell without quads: {bare:?}"
        );
    }
    assert!(
        failures.is_empty(),
        "outside the bounds (mean ≤ {MAX_MEAN_ABS}, differing ≤ {MAX_DIFFERING}, holes ≤ {MAX_HOLES}): {failures:#?}"
    );
}

/// `record_depths` re-records what the bake recorded, for every layering.
#[test]
fn record_depths_matches_the_bake_for_every_layering() {
    let Some(gpu) = gpu() else { return };
    let scene = scene();
    for (name, layering) in layerings() {
        let (baked, baker) = bake(&gpu, &scene, layering);
        let h = &baked.file.header;
        let depths = baker.record_depths(&cell()).expect("record depths");
        assert_eq!(depths.faces, h.faces, "{name}");
        assert_eq!(depths.res, RES);
        assert_eq!(depths.center, cell().center);
        assert_eq!(depths.depth.len(), h.layers.len());
        for (slot, layers) in h.layers.iter().enumerate() {
            let dist: Vec<f64> = layers.iter().map(|l| l.distance).collect();
            assert_eq!(depths.distances[slot], dist, "{name} face slot {slot}");
            assert_eq!(depths.depth[slot].len(), layers.len());
            assert!(depths.depth[slot]
                .iter()
                .all(|d| d.len() == (RES * RES) as usize));
            // stored in tiles: never more than the layers whole
            let stored: usize = depths.depth[slot].iter().map(|d| d.stored_bytes()).sum();
            assert!(stored <= layers.len() * (RES * RES) as usize * 4);
        }
        // the same texels as the bake recorded (same slabs, same coverage)
        let finite: u64 = depths
            .depth
            .iter()
            .flatten()
            .map(|d| d.finite_count() as u64)
            .sum();
        assert_eq!(finite, h.stats.opaque_texels_recorded, "{name}");
        let texels = baked_texels(&baked, &h.faces);
        let (mut total, mut covered, mut in_range) = (0usize, 0usize, 0usize);
        // baked texels neither re-recorded nor explained by gap filling (a copy of the closer
        // layer's recorded texel) or by the near seam (innermost layer)
        let mut unexplained = 0usize;
        for (slot, face) in texels.iter().enumerate() {
            for (k, layer) in face.iter().enumerate() {
                let info = h.layers[slot][k];
                let far = if info.far_border >= f64::MAX {
                    f64::INFINITY
                } else {
                    info.far_border
                };
                // the recorded depth range: the slab, extended by the overlap for equidistant
                let ext = match layering {
                    Layering::Equidistant { overlap } => overlap * (far - info.near_border),
                    _ => 0.0,
                };
                let (lo, hi) = (
                    (info.near_border - ext).max(h.near_field) * (1.0 - 1e-4),
                    if k == 0 {
                        f64::INFINITY
                    } else {
                        (far + ext) * (1.0 + 1e-4)
                    },
                );
                let innermost = k + 1 == h.layers[slot].len();
                for &t in layer {
                    total += 1;
                    let d = depths.depth[slot][k].get(t).unwrap_or(f32::NAN) as f64;
                    if d.is_finite() {
                        covered += 1;
                        if d >= lo && d <= hi {
                            in_range += 1;
                        }
                    } else if !innermost {
                        let closer = depths.depth[slot][k + 1].get(t).unwrap_or(f32::NAN);
                        if !closer.is_finite() && k + 2 != h.layers[slot].len() {
                            unexplained += 1;
                        }
                    }
                }
            }
        }
        let share = covered as f64 / total.max(1) as f64;
        println!(
            "{name:12} {total} baked texels, {covered} re-recorded ({:.2} %), {in_range} in their layer's range",
            100.0 * share
        );
        assert!(total > 0, "{name}: nothing baked");
        assert_eq!(
            in_range, covered,
            "{name}: a re-recorded depth outside its layer's range"
        );
        let s = &h.stats;
        match layering {
            Layering::Equidistant { .. } => {
                // nothing is added by gap filling or near-seam closing: every texel was recorded
                assert_eq!(covered, total, "{name}");
                assert_eq!(s.opaque_texels_after_gap_fill, s.opaque_texels_recorded);
                // the overlaps are recorded in both slabs
                assert!(s.submitted_triangles > s.far_triangles, "{s:?}");
            }
            _ => {
                // gap filling and the near seam add texels that were not recorded, but only where
                // the closer layer (or, for the innermost layer, the near field) has them
                assert_eq!(unexplained, 0, "{name}");
                assert!(
                    share >= 0.5,
                    "{name}: only {:.2} % re-recorded",
                    100.0 * share
                );
                assert!(s.opaque_texels_after_gap_fill >= s.opaque_texels_recorded);
            }
        }
    }
}

#[test]
fn a_bad_overlap_is_rejected_by_name() {
    for o in [-0.1, 1.5, f64::NAN, f64::INFINITY] {
        let e = params(Layering::Equidistant { overlap: o })
            .validate()
            .expect_err("a bad overlap");
        assert!(e.to_string().contains("overlap"), "{e}");
    }
    for o in [0.0, 0.1, 1.0] {
        params(Layering::Equidistant { overlap: o })
            .validate()
            .expect("a good overlap");
    }
    params(Layering::Single).validate().expect("single");
}

/// The equidistant placement in a scene that does not reach beyond the near field on some face
/// (only the ground within 30 m there): the documented fallback, twice the near field.
#[test]
fn equidistant_falls_back_when_the_scene_ends_inside_the_near_field() {
    let mut b = SceneBuilder::new();
    let white = b.add_material(Material {
        name: "white".into(),
        base_color: [1.0; 4],
        texture: None,
    });
    let mut m = Mesh {
        material: white,
        ..Default::default()
    };
    add_box(
        &mut m,
        [-30.0, 0.0, -30.0],
        [300.0, 5.0, 30.0],
        [200, 200, 200],
    );
    b.add_mesh(m);
    let scene = b.finish();
    let p = params(EQUIDISTANT);
    let placements = lemi_core::layering::place_cell_in(&p, &cell(), &scene.bounds).unwrap();
    let nf = placements[0].near_field;
    for (f, pl) in p.faces.iter().zip(&placements) {
        let far = farthest_along(&scene.bounds, cell().center, *f);
        let want = if far > nf { far } else { 2.0 * nf };
        assert_eq!(pl.layers[0].far_border, want, "face {f}");
        assert_eq!(pl.layers.len(), LAYERS as usize);
    }
    assert_eq!(placements[0].layers[0].far_border, 300.0);
    assert_eq!(placements[1].layers[0].far_border, 2.0 * nf);
    // without the scene's bounds the equidistant layering cannot be placed
    let e = lemi_core::layering::place_cell(&p, &cell()).expect_err("needs bounds");
    assert!(e.to_string().contains("bounds"), "{e}");
}
