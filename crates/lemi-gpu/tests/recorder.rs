//! Layer recorder tests on whatever adapter wgpu finds (Mesa's lavapipe or llvmpipe in CI):
//! conservative coverage against a CPU brute force (exact texel-square / triangle overlap), no crack
//! where a surface is cut at a slab border (TR-186-2-02-04 sec. 2.2), colour and depth equal to the
//! reference renderer's, determinism. Without an adapter they fail with the install hint, unless
//! `LEMI_SKIP_GPU_TESTS=1`.

use glam::{DVec2, DVec3};
use lemi_core::camera::View;
use lemi_core::clip::{clip_to_slab, ClipVertex};
use lemi_core::{Face, Material, Mesh, SceneBuilder, Texture};
use lemi_gpu::{
    GpuMaterials, GpuScene, LayerFrame, LayerRecorder, Lighting, MaterialRun, RecordOptions,
    RenderOptions, Renderer, UploadOptions,
};
use lemi_testkit::{clip_vertex as cv, gpu, one_run as all_runs, wavy_surface, white_materials};

/// A small deterministic generator (xorshift64*), so the tests need no extra crate.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// Pixel coordinates (texel `(i, j)` spans `[i, i+1] × [j, j+1]`) of a point in front of `face`.
fn to_pixel(face: Face, rel: DVec3, res: u32) -> DVec2 {
    let (s, t, _) = face.project(rel).expect("in front of the face");
    DVec2::new((s + 1.0) * 0.5 * res as f64, (t + 1.0) * 0.5 * res as f64)
}

/// Exact overlap of the closed square centred at `c` with half size `h` and the closed triangle
/// `p` (which may be degenerate), by separating axes: the box axes and the three edge normals.
fn square_meets_triangle(c: DVec2, h: f64, p: &[DVec2; 3]) -> bool {
    let mut axes = vec![DVec2::X, DVec2::Y];
    for k in 0..3 {
        let e = p[(k + 1) % 3] - p[k];
        if e.length_squared() > 0.0 {
            axes.push(e.perp());
        }
    }
    axes.iter().all(|n| {
        let d = p.map(|q| n.dot(q));
        let lo = d[0].min(d[1]).min(d[2]);
        let hi = d[0].max(d[1]).max(d[2]);
        let r = h * (n.x.abs() + n.y.abs());
        let pc = n.dot(c);
        pc + r >= lo && pc - r <= hi
    })
}

/// Texels of a `res × res` face whose square (half size `h`) meets the projected triangle.
fn brute_force(face: Face, tri: &[ClipVertex], res: u32, h: f64) -> Vec<bool> {
    let p = [0, 1, 2].map(|k| to_pixel(face, tri[k].rel, res));
    let mut out = vec![false; (res * res) as usize];
    for j in 0..res {
        for i in 0..res {
            let c = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
            out[(j * res + i) as usize] = square_meets_triangle(c, h, &p);
        }
    }
    out
}

/// A random small triangle in front of `face`: ordinary, thin sliver, or edge-on (its plane
/// contains the eye, so it projects to a segment), or long with an acute corner.
fn random_triangle(rng: &mut Rng, face: Face, res: u32, kind: u32) -> [ClipVertex; 3] {
    let depth = rng.range(4.0, 12.0);
    let texel = 2.0 * depth / res as f64;
    let p = face.point(rng.range(-0.8, 0.8), rng.range(-0.8, 0.8), depth);
    let mut off = || {
        DVec3::new(
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
        ) * texel
    };
    let n = [0.0, 0.0, 1.0];
    match kind {
        0 => {
            let (a, b) = (off(), off());
            [cv(p, n), cv(p + a, n), cv(p + b, n)]
        }
        1 => {
            let a = off() * 2.0;
            let eps = off() * 0.01;
            [cv(p, n), cv(p + a, n), cv(p + a * 0.5 + eps, n)]
        }
        3 => {
            let a = off() * 4.0;
            let b = a * 0.9 + off() * 0.1;
            [cv(p, n), cv(p + a, n), cv(p + b, n)]
        }
        _ => {
            let u = off();
            let (l1, l2) = (1.0 + 0.02 * rng.next(), 1.0 + 0.02 * rng.next());
            [cv(p, n), cv(p * l1, n), cv(p * l2 + u * rng.next(), n)]
        }
    }
}

#[test]
fn coverage_is_conservative_and_tight() {
    let Some(gpu) = gpu() else { return };
    let res = 48;
    let rec = LayerRecorder::new(&gpu, res).expect("recorder");
    let mats = white_materials(&gpu);
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let lighting = Lighting::default();
    for n in 0..240u32 {
        let face = Face::ALL[(n % 6) as usize];
        let tri = random_triangle(&mut rng, face, res, n % 4);
        let f = rec
            .record(
                &mats,
                DVec3::new(3.0, -2.0, 7.0),
                face,
                &tri,
                &all_runs(&tri),
                0.1,
                &lighting,
            )
            .expect("record");
        // Must cover: squares meeting the triangle even when grown by 1/256 px (a cut that merely
        // grazes a texel, as the f64 clip-border traversal finds it, is covered despite f32
        // rounding).
        let must = brute_force(face, &tri, res, 0.5 + 1.0 / 256.0);
        // May cover: squares within one texel of the triangle.
        let may = brute_force(face, &tri, res, 1.5);
        let depths = tri.map(|v| face.depth(v.rel));
        let (dmin, dmax) = (
            depths.iter().cloned().fold(f64::INFINITY, f64::min),
            depths.iter().cloned().fold(0.0, f64::max),
        );
        let mut count = 0;
        for j in 0..res {
            for i in 0..res {
                let k = (j * res + i) as usize;
                let got = f.covered(i, j);
                assert!(
                    got || !must[k],
                    "triangle {n} (kind {}, face {face}): texel ({i}, {j}) meets it but is not \
                     covered; {tri:?}",
                    n % 4
                );
                assert!(
                    !got || may[k],
                    "triangle {n} (kind {}, face {face}): texel ({i}, {j}) covered but farther \
                     than one texel",
                    n % 4
                );
                if got {
                    count += 1;
                    let d = f.depth[k] as f64;
                    assert!(
                        d >= dmin * (1.0 - 1e-4) && d <= dmax * (1.0 + 1e-4),
                        "triangle {n}: depth {d} outside [{dmin}, {dmax}]"
                    );
                }
            }
        }
        assert!(count > 0, "triangle {n} covers nothing");
    }
}

#[test]
fn no_crack_where_a_surface_crosses_a_slab_border() {
    let Some(gpu) = gpu() else { return };
    let res = 64;
    let rec = LayerRecorder::new(&gpu, res).expect("recorder");
    let mats = white_materials(&gpu);
    let lighting = Lighting::default();
    let center = DVec3::new(1000.0, 50.0, -2000.0);
    for face in [Face::PosX, Face::NegZ] {
        let surface = wavy_surface(face, 9);
        let (mut near_part, mut far_part) = (Vec::new(), Vec::new());
        for tri in surface.chunks_exact(3) {
            let t = [tri[0], tri[1], tri[2]];
            clip_to_slab(&t, face, 5.0, 10.0, &mut near_part);
            clip_to_slab(&t, face, 10.0, f64::INFINITY, &mut far_part);
        }
        assert!(!near_part.is_empty() && !far_part.is_empty());
        let record = |v: &[ClipVertex]| {
            rec.record(&mats, center, face, v, &all_runs(v), 0.1, &lighting)
                .expect("record")
        };
        let (a, b) = (record(&near_part), record(&far_part));
        let whole = record(&surface);
        let mut must = vec![false; (res * res) as usize];
        for tri in surface.chunks_exact(3) {
            for (m, x) in must.iter_mut().zip(brute_force(face, tri, res, 0.5 - 1e-3)) {
                *m |= x;
            }
        }
        let mut covered = 0;
        for j in 0..res {
            for i in 0..res {
                let k = (j * res + i) as usize;
                let union = a.covered(i, j) || b.covered(i, j);
                assert!(
                    union || !whole.covered(i, j),
                    "face {face}: crack at texel ({i}, {j})"
                );
                assert!(union || !must[k], "face {face}: texel ({i}, {j}) missing");
                covered += union as usize;
                // Each part keeps to its slab (depths within rounding of the border).
                if a.covered(i, j) {
                    assert!(a.depth[k] <= 10.0 + 1e-3, "near part depth {}", a.depth[k]);
                }
                if b.covered(i, j) {
                    assert!(b.depth[k] >= 10.0 - 1e-3, "far part depth {}", b.depth[k]);
                }
            }
        }
        assert!(covered > 1000, "face {face}: only {covered} texels");
        // The cut edges (both ends snapped onto the border) appear at identical texels in both
        // layers: every texel a cut segment touches is covered in both.
        let mut cuts = 0;
        for tri in near_part.chunks_exact(3) {
            for e in 0..3 {
                let (p, q) = (tri[e], tri[(e + 1) % 3]);
                if face.depth(p.rel) != 10.0 || face.depth(q.rel) != 10.0 {
                    continue;
                }
                cuts += 1;
                let seg = [p, q, q];
                for (k, m) in brute_force(face, &seg, res, 0.5 - 1e-3).iter().enumerate() {
                    let (i, j) = (k as u32 % res, k as u32 / res);
                    assert!(
                        !m || (a.covered(i, j) && b.covered(i, j)),
                        "face {face}: cut edge texel ({i}, {j}) not in both layers"
                    );
                }
            }
        }
        assert!(cuts > 20, "face {face}: only {cuts} cut edges");
    }
}

#[test]
fn surface_spanning_many_slabs_has_no_hole() {
    let Some(gpu) = gpu() else { return };
    let res = 64;
    let rec = LayerRecorder::new(&gpu, res).expect("recorder");
    let mats = white_materials(&gpu);
    let lighting = Lighting::default();
    let borders = [5.0, 8.6, 9.2, 9.7, 10.1, 10.6, 11.3, f64::INFINITY];
    for (face, center) in [
        (Face::NegY, DVec3::new(-7.5, 3.0, 12.0)),
        (Face::PosZ, DVec3::new(250.0, -80.0, 4000.0)),
    ] {
        let surface = wavy_surface(face, 11);
        let mut union = vec![false; (res * res) as usize];
        for w in borders.windows(2) {
            let mut part = Vec::new();
            for tri in surface.chunks_exact(3) {
                clip_to_slab(&[tri[0], tri[1], tri[2]], face, w[0], w[1], &mut part);
            }
            let f = rec
                .record(&mats, center, face, &part, &all_runs(&part), 0.1, &lighting)
                .expect("record");
            for (u, px) in union.iter_mut().zip(f.rgba.chunks_exact(4)) {
                *u |= px[3] == 255;
            }
        }
        let mut must = vec![false; (res * res) as usize];
        for tri in surface.chunks_exact(3) {
            for (m, x) in must.iter_mut().zip(brute_force(face, tri, res, 0.5 - 1e-3)) {
                *m |= x;
            }
        }
        for (k, (u, m)) in union.iter().zip(&must).enumerate() {
            assert!(
                *u || !m,
                "face {face}: hole at texel ({}, {})",
                k as u32 % res,
                k as u32 / res
            );
        }
        assert!(must.iter().filter(|m| **m).count() > 1000);
    }
}

#[test]
fn textured_gouraud_quad_matches_the_reference_renderer() {
    let Some(gpu) = gpu() else { return };
    let res = 64;
    let face = Face::PosX;
    let center = DVec3::new(-500.0, 12.0, 300.0);
    let base = [0.8, 0.5, 0.3, 1.0];
    let material = Material {
        name: "clay".into(),
        base_color: base,
        texture: Some(0),
    };
    // An 8×8 texture with smooth gradients (sRGB bytes).
    let mut rgba = Vec::new();
    for y in 0..8u8 {
        for x in 0..8u8 {
            rgba.extend_from_slice(&[60 + 24 * x, 230 - 20 * y, 100 + 10 * (x + y), 255]);
        }
    }
    let texture = Texture {
        name: "gradient".into(),
        width: 8,
        height: 8,
        rgba8: rgba,
    };
    let uvs = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    // A tilted quad at depth ≈ 8 with one normal for all corners.
    let corners = [
        face.point(-0.5, -0.4, 7.0),
        face.point(0.5, -0.4, 9.0),
        face.point(0.5, 0.4, 9.0),
        face.point(-0.5, 0.4, 7.0),
    ];
    let normal = (corners[1] - corners[0])
        .cross(corners[3] - corners[0])
        .normalize()
        .as_vec3()
        .to_array();
    // Different vertex colours per corner: the interpolation must match too.
    let colors = [
        [200u8, 255, 180, 255],
        [40, 90, 255, 255],
        [255, 20, 60, 255],
        [120, 200, 10, 255],
    ];
    let idx = [0usize, 1, 2, 0, 2, 3];
    let tris: Vec<ClipVertex> = idx
        .iter()
        .map(|&k| ClipVertex {
            rel: corners[k],
            normal,
            uv: uvs[k],
            color: colors[k].map(|c| c as f32),
        })
        .collect();
    let lighting = Lighting {
        direction: [0.4, 0.7, -0.2],
        ..Lighting::default()
    };
    let mats = GpuMaterials::upload(
        &gpu,
        std::slice::from_ref(&material),
        std::slice::from_ref(&texture),
    )
    .expect("mats");
    let rec = LayerRecorder::new(&gpu, res).expect("recorder");
    let f = rec
        .record(&mats, center, face, &tris, &all_runs(&tris), 0.1, &lighting)
        .expect("record");

    let mut sb = SceneBuilder::new();
    sb.add_texture(texture);
    sb.add_material(material);
    sb.add_mesh(Mesh {
        material: 0,
        vertices: tris.iter().map(|v| v.to_vertex(center)).collect(),
        indices: (0..6).collect(),
    });
    let gs = GpuScene::upload(&gpu, &sb.finish(), &UploadOptions::default()).expect("upload");
    let view = View::cube_face(center, face, res, 0.1);
    let opts = RenderOptions {
        lighting,
        ..RenderOptions::default()
    };
    let r = Renderer::new(&gpu)
        .expect("renderer")
        .render(&gs, &view, &opts)
        .expect("render");
    let mut compared = 0;
    for j in 1..res - 1 {
        for i in 1..res - 1 {
            let inner = (0..9).all(|n| {
                r.pixel(i + n % 3 - 1, j + n / 3 - 1)
                    .is_some_and(|p| p[3] == 255)
            });
            if !inner {
                continue;
            }
            let (got, want) = (
                f.texel(i, j).unwrap_or_default(),
                r.pixel(i, j).unwrap_or_default(),
            );
            for c in 0..4 {
                assert!(
                    (got[c] as i32 - want[c] as i32).abs() <= 1,
                    "texel ({i}, {j}): recorder {got:?}, reference {want:?}"
                );
            }
            let (dg, dw) = (
                f.depth[(j * res + i) as usize],
                r.depth_at(i, j).unwrap_or(0.0),
            );
            assert!(
                (dg - dw).abs() <= 1e-4 * dw,
                "texel ({i}, {j}) depth {dg} vs {dw}"
            );
            compared += 1;
        }
    }
    assert!(compared > 300, "only {compared} texels compared");
    // Conservative: the recorder covers at least what the reference renderer covers.
    for j in 0..res {
        for i in 0..res {
            assert!(f.covered(i, j) || r.pixel(i, j).is_some_and(|p| p[3] == 0));
        }
    }
}

/// A wavy surface facing +Y recorded into one 64² layer with `mats` (material 0).
fn record_wavy(rec: &LayerRecorder, mats: &GpuMaterials) -> LayerFrame {
    record_wavy_with(rec, mats, &RecordOptions::default()).expect("record")
}

/// [`record_wavy`] with `options`.
fn record_wavy_with(
    rec: &LayerRecorder,
    mats: &GpuMaterials,
    options: &RecordOptions,
) -> Result<LayerFrame, lemi_gpu::GpuError> {
    let surface = wavy_surface(Face::PosY, 12);
    rec.record_with(
        mats,
        DVec3::ZERO,
        Face::PosY,
        &surface,
        &all_runs(&surface),
        0.1,
        &Lighting::default(),
        options,
    )
}

#[test]
fn recording_is_deterministic() {
    let Some(gpu) = gpu() else { return };
    let rec = LayerRecorder::new(&gpu, 64).expect("recorder");
    let mats = white_materials(&gpu);
    let (a, b): (LayerFrame, LayerFrame) = (record_wavy(&rec, &mats), record_wavy(&rec, &mats));
    assert!(a.covered_count() > 1000);
    assert_eq!(a, b);
}

/// The side plane ([`RecordOptions::side_plane`]): the shader tells each covered texel whether
/// its recorded point lies behind the plane, exactly as its read-back depth does, and the colour
/// is the same as without it (alpha binary again).
#[test]
fn the_side_of_the_plane_matches_the_recorded_depth() {
    let Some(gpu) = gpu() else { return };
    let rec = LayerRecorder::new(&gpu, 64).expect("recorder");
    let mats = white_materials(&gpu);
    let plain = record_wavy(&rec, &mats);
    let mut depths: Vec<f32> = plain
        .depth
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .collect();
    depths.sort_by(f32::total_cmp);
    let plane = depths[depths.len() / 2] as f64;
    let record = |side_plane: Option<f64>| {
        let options = RecordOptions {
            side_plane,
            ..Default::default()
        };
        record_wavy_with(&rec, &mats, &options)
    };
    let sided = record(Some(plane)).expect("record with a side plane");
    assert_eq!(sided.rgba, plain.rgba);
    assert_eq!(sided.depth, plain.depth);
    assert!(plain.behind_plane.is_empty(), "not asked, not computed");
    assert_eq!(sided.behind_plane.len(), sided.depth.len());
    let (mut behind, mut front) = (0, 0);
    for (k, (&b, &d)) in sided.behind_plane.iter().zip(&sided.depth).enumerate() {
        assert_eq!(
            b,
            d.is_finite() && d > plane as f32,
            "texel {k} at depth {d}"
        );
        if b {
            behind += 1;
        } else if d.is_finite() {
            front += 1;
        }
    }
    assert!(
        behind > 200 && front > 200,
        "{behind} behind, {front} in front"
    );
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(record(Some(bad)).is_err(), "side plane {bad}");
    }
}

/// An untextured material is recorded by the pipeline without the texture fetch (the white
/// texel's sample taken as the constant 1): the layer is texel for texel and depth for depth the
/// one recorded when the material samples an explicit 1×1 white texture.
#[test]
fn untextured_material_records_what_a_white_texture_records() {
    let Some(gpu) = gpu() else { return };
    let rec = LayerRecorder::new(&gpu, 64).expect("recorder");
    let material = |texture| Material {
        name: "tinted".into(),
        base_color: [0.7, 0.5, 0.9, 1.0],
        texture,
    };
    let white = Texture {
        name: "white".into(),
        width: 1,
        height: 1,
        rgba8: vec![255; 4],
    };
    let untextured = GpuMaterials::upload(&gpu, &[material(None)], &[]).expect("mats");
    let textured = GpuMaterials::upload(&gpu, &[material(Some(0))], std::slice::from_ref(&white))
        .expect("mats");
    assert!(!untextured.textured(0) && textured.textured(0));
    let (a, b) = (record_wavy(&rec, &untextured), record_wavy(&rec, &textured));
    assert!(a.covered_count() > 1000);
    assert!(a == b, "the untextured pipeline records other texels");
}

#[test]
fn bad_runs_and_parameters_are_errors() {
    let Some(gpu) = gpu() else { return };
    let rec = LayerRecorder::new(&gpu, 8).expect("recorder");
    let mats = white_materials(&gpu);
    let tri = [cv(DVec3::new(0.0, 0.0, 5.0), [0.0, 0.0, 1.0]); 3];
    let l = Lighting::default();
    let run = |material, first, count| {
        [MaterialRun {
            material,
            first,
            count,
        }]
    };
    let c = DVec3::ZERO;
    let e = |r: Result<LayerFrame, lemi_gpu::GpuError>| r.err().map(|e| e.to_string());
    assert!(
        e(rec.record(&mats, c, Face::PosZ, &tri, &run(1, 0, 1), 0.1, &l))
            .is_some_and(|m| m.contains("material 1"))
    );
    assert!(
        e(rec.record(&mats, c, Face::PosZ, &tri, &run(0, 0, 2), 0.1, &l))
            .is_some_and(|m| m.contains("triangles 0..2"))
    );
    assert!(e(rec.record(&mats, c, Face::PosZ, &tri[..2], &[], 0.1, &l)).is_some());
    assert!(e(rec.record(&mats, c, Face::PosZ, &tri, &[], 0.0, &l)).is_some());
    let mut nan = tri;
    nan[1].rel.y = f64::NAN;
    assert!(
        e(rec.record(&mats, c, Face::PosZ, &nan, &run(0, 0, 1), 0.1, &l))
            .is_some_and(|m| m.contains("triangle 0") && m.contains("non-finite"))
    );
    assert!(LayerRecorder::new(&gpu, 0).is_err());
    let empty = rec
        .record(&mats, c, Face::PosZ, &[], &[], 0.1, &l)
        .expect("empty layer");
    assert_eq!(empty.covered_count(), 0);
    assert!(empty.depth.iter().all(|d| d.is_infinite()));
}

/// Sparse recording (the default, `RecordOptions::sparse`): a slab without triangles draws
/// nothing and reads nothing back; a small triangle reads back only the tiles around it
/// (`READBACK_TILE`² texels each), and the layer equals the one read back whole, depths
/// included; the frame's content rectangle holds every covered texel.
#[test]
fn a_slab_without_triangles_costs_no_readback() {
    let Some(gpu) = gpu() else { return };
    let res = 256;
    let rec = LayerRecorder::new(&gpu, res).expect("recorder");
    let mats = white_materials(&gpu);
    let l = Lighting::default();
    let c = DVec3::ZERO;
    let empty = rec
        .record(&mats, c, Face::PosZ, &[], &[], 0.1, &l)
        .expect("empty layer");
    assert_eq!(rec.texels_read(), 0, "an empty slab reads nothing back");
    assert_eq!(empty.covered_count(), 0);
    assert!(empty.content.is_empty());
    // a small triangle near the centre of the face
    let tri = [
        cv(DVec3::new(0.01, 0.01, 5.0), [0.0, 0.0, -1.0]),
        cv(DVec3::new(0.2, 0.02, 5.0), [0.0, 0.0, -1.0]),
        cv(DVec3::new(0.05, 0.3, 5.0), [0.0, 0.0, -1.0]),
    ];
    let runs = all_runs(&tri);
    let sparse = rec
        .record(&mats, c, Face::PosZ, &tri, &runs, 0.1, &l)
        .expect("sparse");
    let read = rec.texels_read();
    let tile = lemi_gpu::recorder::READBACK_TILE as u64;
    assert!(
        read > 0 && read <= 4 * tile * tile,
        "{read} texels read for a triangle within a few tiles"
    );
    let full = rec
        .record_with(
            &mats,
            c,
            Face::PosZ,
            &tri,
            &runs,
            0.1,
            &l,
            &RecordOptions {
                sparse: false,
                ..Default::default()
            },
        )
        .expect("full");
    assert_eq!(rec.texels_read() - read, res as u64 * res as u64);
    assert!(sparse.covered_count() > 0);
    assert_eq!(sparse.rgba, full.rgba);
    assert_eq!(sparse.depth, full.depth);
    for j in 0..res {
        for i in 0..res {
            if full.covered(i, j) {
                assert!(sparse.content.contains(i, j), "covered ({i}, {j}) outside");
            }
        }
    }
}

/// Overshoot marking ([`RecordOptions::mark_overshoot`], for the bake's outline fringe): of a
/// single triangle (not seen edge-on), a covered texel whose centre lies inside the triangle is
/// never marked and all but a few whose centre lies outside are (texels within 0.15 px of an
/// edge may go either way), the colours are
/// the same as
/// without marking, and a triangle containing a texel's centre wins the texel over another's
/// overshoot even when that one is nearer.
#[test]
fn overshoot_is_marked_where_no_triangle_covers_the_centre() {
    let Some(gpu) = gpu() else { return };
    let res = 48;
    let rec = LayerRecorder::new(&gpu, res).expect("recorder");
    let mats = white_materials(&gpu);
    let mut rng = Rng(0x0bad_cafe_1234_5678);
    let lighting = Lighting::default();
    let marked = RecordOptions {
        mark_overshoot: true,
        ..Default::default()
    };
    let record = |face: Face, tris: &[ClipVertex], options: &RecordOptions| {
        rec.record_with(
            &mats,
            DVec3::ZERO,
            face,
            tris,
            &all_runs(tris),
            0.1,
            &lighting,
            options,
        )
        .expect("record")
    };
    let (mut inside, mut outside, mut unmarked) = (0, 0, 0);
    for n in 0..120u32 {
        let face = Face::ALL[(n % 6) as usize];
        let tri = random_triangle(&mut rng, face, res, n % 4);
        let plain = record(face, &tri, &RecordOptions::default());
        let f = record(face, &tri, &marked);
        assert!(plain.overshoot.is_empty(), "not asked, not computed");
        assert_eq!(
            f.rgba, plain.rgba,
            "triangle {n}: marking changes no colour"
        );
        let p = [0, 1, 2].map(|k| to_pixel(face, tri[k].rel, res));
        for j in 0..res {
            for i in 0..res {
                let k = (j * res + i) as usize;
                if !f.covered(i, j) {
                    assert!(!f.overshoot[k]);
                    continue;
                }
                let c = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
                // signed distances of the centre to the three edges, inside positive
                let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
                let side = |a: DVec2, b: DVec2| {
                    let e = b - a;
                    area.signum() * e.perp_dot(c - a) / e.length().max(1e-12)
                };
                let d = side(p[0], p[1]).min(side(p[1], p[2])).min(side(p[2], p[0]));
                // (a triangle seen edge-on has no inside to speak of: its barycentrics are
                // not defined, and it is left out)
                if area.abs() < 0.5 {
                    continue;
                }
                // the shader's barycentrics, interpolated in f32 over a triangle dilated far
                // beyond its acute corners, are off by up to a tenth of a pixel on slivers
                // (measured 0.1 px on one 0.3 px wide): texels that close to an edge may go
                // either way
                if d > 0.15 {
                    assert!(
                        !f.overshoot[k],
                        "triangle {n}: ({i}, {j}) inside by {d} px, marked"
                    );
                    inside += 1;
                } else if d < -0.15 {
                    outside += 1;
                    unmarked += u32::from(!f.overshoot[k]);
                }
            }
        }
    }
    assert!(
        inside > 20 && outside > 200,
        "{inside} inside, {outside} outside"
    );
    // near a very acute corner the interpolated barycentrics call a few outside texels inside
    // (up to half a pixel out): those are kept whole, as without marking, which is safe
    assert!(
        unmarked * 50 <= outside,
        "{unmarked} of {outside} texels outside their triangle not marked"
    );

    // a small near triangle in front of a large far one: where the near one's overshoot lies
    // over a centre of the far one, marking lets the far one win
    let face = Face::NegZ;
    let n = [0.0, 0.0, 1.0];
    let near = [
        cv(face.point(-0.3, -0.3, 5.0), n),
        cv(face.point(0.3, -0.3, 5.0), n),
        cv(face.point(0.0, 0.3, 5.0), n),
    ];
    let far = [
        cv(face.point(-0.9, -0.9, 9.0), n),
        cv(face.point(0.9, -0.9, 9.0), n),
        cv(face.point(0.0, 0.9, 9.0), n),
    ];
    let both: Vec<ClipVertex> = near.iter().chain(&far).copied().collect();
    let plain = record(face, &both, &RecordOptions::default());
    let f = record(face, &both, &marked);
    let (mut won, mut kept) = (0, 0);
    for k in 0..(res * res) as usize {
        let near_plain = plain.depth[k] < 7.0;
        if near_plain && f.depth[k] > 7.0 {
            // the near triangle's overshoot, lost to the far triangle's centre
            assert!(!f.overshoot[k]);
            won += 1;
        } else if near_plain {
            kept += 1;
        }
    }
    assert!(
        won > 10 && kept > 50,
        "{won} texels won by the far triangle, {kept} kept"
    );
}
