//! The bake job end to end on whatever adapter wgpu finds (Mesa's lavapipe or llvmpipe in CI): a
//! small deterministic scene (a tiled ground and boxes at distances spanning the near field and
//! every slab), three 10 m cells, 4 horizontal faces of 4 layers at 64² texels.
//!
//! - resuming skips intact cells of an identical run and re-bakes exactly the damaged, missing or
//!   outdated ones (other parameters, another scene, a moved grid);
//! - shards (`--shard K/N`) merged give the bundle of a single run, byte for byte; merging refuses
//!   missing shards, disagreeing shard records and cell files changed after baking;
//! - damaged bundle files give errors that name the file and say what is wrong;
//! - a baked cell is internally consistent (layers, quads, macro-textures, near list, statistics)
//!   and its file round-trips exactly, floats included.
//!
//! Without an adapter the GPU tests fail with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.

use std::cell::Cell;
use std::path::{Path, PathBuf};

use glam::{DVec3, IVec3};
use lemi_bake::{merge, run, BakeJob, Baker, CellOutcome, RunSummary};
use lemi_core::bundle::{
    cell_file_name, manifest_path, read_cell_file, BakeParams, Bundle, BundleError, CellCheck,
    CellFile, CellHeader, CellStats, LayerInfo, LayerTarget, Manifest, SceneRef, BUNDLE_VERSION,
};
use lemi_core::cell::{CellGrid, Shard, ViewCell};
use lemi_core::{Aabb, Face, Material, Mesh, Scene, SceneBuilder, Texture, Vertex};
use lemi_testkit::{add_closed_box as add_box, gpu};

// ---------------------------------------------------------------------------------------------
// fixtures

/// Small parameters: with α = 0.02 rad the 4 layers of a 10 m cell lie at about 393, 131, 79 and
/// 56 m, the near field ends at about 49 m.
fn params() -> BakeParams {
    BakeParams {
        alpha: 0.02,
        ..lemi_testkit::small_params(64, LayerTarget::Layers(4))
    }
}

/// The test scene (deterministic): a ground of 20 m tiles over ±520 m with a checker of vertex
/// colours, and boxes along and between the four horizontal directions at distances from 20 m
/// (inside every cell's near field) to 450 m (the farthest layer); three materials, one textured.
fn scene() -> Scene {
    let mut b = SceneBuilder::new();
    b.add_source("test:bake_jobs");
    let checker: Vec<u8> = (0..8 * 8)
        .flat_map(|i| {
            if (i % 8 + i / 8) % 2 == 0 {
                [230, 220, 200, 255]
            } else {
                [90, 60, 40, 255]
            }
        })
        .collect();
    let tex = b.add_texture(Texture {
        name: "checker".into(),
        width: 8,
        height: 8,
        rgba8: checker,
    });
    let ground = b.add_material(Material {
        name: "ground".into(),
        base_color: [0.45, 0.55, 0.35, 1.0],
        texture: None,
    });
    let brick = b.add_material(Material {
        name: "brick".into(),
        base_color: [0.8, 0.4, 0.3, 1.0],
        texture: Some(tex),
    });
    let glass = b.add_material(Material {
        name: "glass".into(),
        base_color: [0.3, 0.45, 0.9, 1.0],
        texture: None,
    });

    let tile = 20.0f32;
    let n = 52;
    let mut mesh = Mesh {
        material: ground,
        ..Default::default()
    };
    for j in 0..n {
        for i in 0..n {
            let x0 = -520.0 + tile * i as f32;
            let z0 = -520.0 + tile * j as f32;
            let c = if (i + j) % 2 == 0 {
                [255, 255, 255, 255]
            } else {
                [170, 190, 150, 255]
            };
            let base = mesh.vertices.len() as u32;
            for [x, z] in [
                [x0, z0],
                [x0, z0 + tile],
                [x0 + tile, z0 + tile],
                [x0 + tile, z0],
            ] {
                mesh.vertices.push(Vertex::new(
                    [x, 0.0, z],
                    [0.0, 1.0, 0.0],
                    [x / tile, z / tile],
                    c,
                ));
            }
            mesh.indices
                .extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
        }
    }
    b.add_mesh(mesh);

    let distances = [20.0f32, 35.0, 60.0, 75.0, 95.0, 120.0, 160.0, 250.0, 450.0];
    let directions: [[f32; 2]; 8] = [
        [1.0, 0.0],
        [-1.0, 0.0],
        [0.0, 1.0],
        [0.0, -1.0],
        [0.8, 0.6],
        [-0.6, 0.8],
        [-0.8, -0.6],
        [0.6, -0.8],
    ];
    for (k, dir) in directions.iter().enumerate() {
        for (m, &d) in distances.iter().enumerate() {
            // keep the boxes off the cells (|x| < 15, |z| < 5) and off each other
            let d = d + 3.0 * k as f32;
            let [cx, cz] = [
                dir[0] * d + if dir[1] == 1.0 { 25.0 } else { 0.0 },
                dir[1] * d,
            ];
            let w = 2.0 + 0.06 * d;
            let h = 4.0 + 0.12 * d + 3.0 * ((k + m) % 3) as f32;
            let (material, color) = if (k + m) % 2 == 0 {
                (brick, [255, 240, 230, 255])
            } else {
                (glass, [200, 220, 255, 255])
            };
            add_box(
                &mut b,
                material,
                [cx - w, 0.0, cz - w],
                [cx + w, h, cz + w],
                color,
            );
        }
    }
    b.finish()
}

fn scene_ref(scene: &Scene, fingerprint: &str) -> SceneRef {
    SceneRef {
        sources: vec!["test:bake_jobs".into()],
        up: "y".into(),
        fingerprint: fingerprint.into(),
        triangles: scene.triangle_count(),
    }
}

/// Three 10 m cells in a row at eye height: ids `0_0_0`, `1_0_0`, `2_0_0`.
fn grid() -> CellGrid {
    let region = Aabb::new(DVec3::new(-15.0, 1.7, -5.0), DVec3::new(15.0, 1.7, 5.0));
    CellGrid::tile(region, 10.0).unwrap()
}

fn job(bundle: &Path, scene: &Scene, params: BakeParams, shard: Option<Shard>) -> BakeJob {
    let grid = grid();
    BakeJob {
        bundle: bundle.to_path_buf(),
        scene: scene_ref(scene, "fingerprint-of-the-test-scene"),
        params,
        cells: grid.cells(),
        grid,
        shard,
    }
}

/// Runs `job` with the real baker, counting the cells it is asked to bake.
fn bake(job: &BakeJob, baker: &Baker<'_>, calls: &Cell<usize>) -> RunSummary {
    run(
        job,
        |cell| {
            calls.set(calls.get() + 1);
            baker.bake(cell, |_| {})
        },
        |_, _, _| {},
    )
    .unwrap_or_else(|e| panic!("bake of {}: {e}", job.bundle.display()))
}

/// `(id, baked?)` per outcome.
fn outcomes(s: &RunSummary) -> Vec<(String, bool)> {
    s.outcomes
        .iter()
        .map(|o| match o {
            CellOutcome::Baked { entry, .. } => (entry.id.to_string(), true),
            CellOutcome::Skipped { entry, .. } => (entry.id.to_string(), false),
        })
        .collect()
}

fn cell_path(bundle: &Path, id: &str) -> PathBuf {
    bundle.join(cell_file_name(id.parse().expect("a cell id")))
}

/// Reads a baked cell of `bundle` through the bundle's reader (every check).
fn read_cell(bundle: &Path, id: &str) -> Result<CellFile, BundleError> {
    Bundle::open(bundle)?.cell(id.parse().expect("a cell id"))
}

/// Reads a synthetic cell file (empty parameters hash and fingerprint) with the reader's checks
/// of the file itself.
fn read_synthetic(path: &Path, cell: &ViewCell) -> Result<CellFile, BundleError> {
    let check = CellCheck {
        id: cell.id(),
        entry: None,
        params_hash: "",
        scene_fingerprint: "",
        cell: Some(cell),
    };
    read_cell_file(path, &check).map(|v| v.file)
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn flip_byte(path: &Path, at: usize) {
    let mut bytes = read(path);
    bytes[at] ^= 0x20;
    std::fs::write(path, bytes).unwrap();
}

/// Copies a bundle directory (one level of subdirectories, as bundles have).
fn copy_bundle(from: &Path, to: &Path) {
    for e in walk(from) {
        let rel = e.strip_prefix(from).unwrap();
        let dst = to.join(rel);
        std::fs::create_dir_all(dst.parent().unwrap()).unwrap();
        std::fs::copy(&e, &dst).unwrap();
    }
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
}

/// What differs between two cell files, field by field of the header (and blobs), for a failure
/// message that says why a bake was not reproducible.
fn describe_difference(a: &[u8], b: &[u8]) -> String {
    let (fa, fb) = match (CellFile::decode(a), CellFile::decode(b)) {
        (Ok(fa), Ok(fb)) => (fa, fb),
        (ra, rb) => return format!("decode: {:?} / {:?}", ra.err(), rb.err()),
    };
    let mut out = vec![format!("{} vs {} bytes", a.len(), b.len())];
    let ja = serde_json::to_value(&fa.header).unwrap();
    let jb = serde_json::to_value(&fb.header).unwrap();
    for (key, va) in ja.as_object().unwrap() {
        let vb = &jb[key];
        if va == vb {
            continue;
        }
        match (va.as_object(), vb.as_object()) {
            (Some(oa), Some(ob)) => {
                for (k, x) in oa {
                    if Some(x) != ob.get(k) {
                        out.push(format!("header.{key}.{k}: {x} vs {}", ob[k]));
                    }
                }
            }
            _ => {
                let (sa, sb) = (va.to_string(), vb.to_string());
                out.push(format!(
                    "header.{key} differs ({} vs {} chars of JSON)",
                    sa.len(),
                    sb.len()
                ));
            }
        }
    }
    if fa.header.quads != fb.header.quads {
        let first = fa
            .header
            .quads
            .iter()
            .zip(&fb.header.quads)
            .position(|(x, y)| x != y);
        out.push(format!(
            "quads: {} vs {}, first difference at {first:?}",
            fa.header.quads.len(),
            fb.header.quads.len()
        ));
    }
    if fa.near != fb.near {
        out.push(format!(
            "near list: {} vs {} entries",
            fa.near.len(),
            fb.near.len()
        ));
    }
    let differing: Vec<usize> = (0..fa.macro_blobs.len().max(fb.macro_blobs.len()))
        .filter(|&i| fa.macro_blobs.get(i) != fb.macro_blobs.get(i))
        .collect();
    if !differing.is_empty() {
        out.push(format!("PNG blobs differ: {differing:?}"));
    }
    out.join("; ")
}

/// Asserts that the cell files of two bundles are byte-identical; the failure message says which
/// fields differ.
fn assert_same_cell_files(reference: &Path, other: &Path, ids: &[String], what: &str) {
    for id in ids {
        let a = read(&cell_path(reference, id));
        let b = read(&cell_path(other, id));
        assert!(
            a == b,
            "{what}: cell {id} is not byte-identical to the single run's (the bake is not \
             deterministic): {}",
            describe_difference(&a, &b)
        );
    }
}

/// A synthetic, valid cell file for runs that need no GPU (error paths).
fn synthetic_cell(cell: &ViewCell, tag: u32) -> CellFile {
    CellFile {
        header: CellHeader {
            fringe_quads: 0,
            cell: *cell,
            params_hash: String::new(),
            scene_fingerprint: String::new(),
            resolution: 64,
            near_field: 49.0,
            faces: vec![Face::PosX],
            layers: vec![vec![LayerInfo {
                distance: 100.0,
                near_border: 49.0,
                far_border: f64::MAX,
            }]],
            quads: Vec::new(),
            macros: Vec::new(),
            stats: CellStats {
                far_triangles: u64::from(tag),
                ..Default::default()
            },
            hlod: None,
            object: None,
            texture_format: Default::default(),
            packing: None,
        },
        near: vec![[0, tag], [1, 2]],
        macro_blobs: Vec::new(),
    }
}

fn err_text<T: std::fmt::Debug, E: std::fmt::Display>(r: Result<T, E>, what: &str) -> String {
    match r {
        Ok(v) => panic!("{what}: expected an error, got {v:?}"),
        Err(e) => e.to_string(),
    }
}

fn assert_mentions(text: &str, needles: &[&str], what: &str) {
    for n in needles {
        assert!(
            text.contains(n),
            "{what}: the error `{text}` does not mention `{n}`"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// tests

#[test]
fn resume_skips_identical_cells_and_rebakes_changed_ones() {
    let Some(gpu) = gpu() else { return };
    let scene = scene();
    let dir = tempfile::tempdir().unwrap();
    let bundle = dir.path().join("bundle");
    let job1 = job(&bundle, &scene, params(), None);
    let baker = Baker::new(&gpu, &scene, params()).unwrap();
    let calls = Cell::new(0);
    let ids: Vec<String> = job1.cells.iter().map(|c| c.id().to_string()).collect();
    assert_eq!(ids, ["0_0_0", "1_0_0", "2_0_0"]);

    // first run: everything baked
    let s = bake(&job1, &baker, &calls);
    assert_eq!(calls.get(), 3);
    assert!(outcomes(&s).iter().all(|(_, baked)| *baked), "{s:?}");
    assert_eq!(s.record, manifest_path(&bundle));
    let manifest1 = read(&manifest_path(&bundle));
    let files1: Vec<Vec<u8>> = ids.iter().map(|id| read(&cell_path(&bundle, id))).collect();

    // identical run: nothing baked, nothing rewritten
    let s = bake(&job1, &baker, &calls);
    assert_eq!(calls.get(), 3, "an identical run must not bake");
    assert_eq!(
        outcomes(&s),
        ids.iter().map(|id| (id.clone(), false)).collect::<Vec<_>>()
    );
    assert!(
        read(&manifest_path(&bundle)) == manifest1,
        "manifest changed"
    );
    for (id, before) in ids.iter().zip(&files1) {
        assert!(
            &read(&cell_path(&bundle, id)) == before,
            "cell {id} changed"
        );
    }

    // a damaged cell (one flipped byte) is re-baked, alone
    let damaged = cell_path(&bundle, "1_0_0");
    let len = read(&damaged).len();
    flip_byte(&damaged, len / 2);
    let s = bake(&job1, &baker, &calls);
    assert_eq!(calls.get(), 4);
    assert_eq!(
        outcomes(&s),
        [
            ("0_0_0".to_string(), false),
            ("1_0_0".to_string(), true),
            ("2_0_0".to_string(), false)
        ]
    );
    read_cell(&bundle, "1_0_0").expect("the re-baked cell is intact");
    assert!(
        read(&damaged) == files1[1],
        "re-baking a cell gives other bytes"
    );

    // a missing cell is re-baked, alone
    std::fs::remove_file(cell_path(&bundle, "2_0_0")).unwrap();
    let s = bake(&job1, &baker, &calls);
    assert_eq!(calls.get(), 5);
    assert_eq!(
        outcomes(&s),
        [
            ("0_0_0".to_string(), false),
            ("1_0_0".to_string(), false),
            ("2_0_0".to_string(), true)
        ]
    );
    // the manifest lists the files as they are now (here: as they were)
    assert!(
        read(&manifest_path(&bundle)) == manifest1,
        "manifest changed"
    );
    let m = Manifest::read(&bundle).unwrap();
    for e in &m.cells {
        let bytes = read(&bundle.join(&e.file));
        assert_eq!(e.bytes, bytes.len() as u64, "{}", e.id);
        assert_eq!(e.blake3, blake3::hash(&bytes).to_hex().as_str(), "{}", e.id);
    }

    // a changed parameter re-bakes everything
    let mut p2 = params();
    p2.micro_threshold = 0.5;
    let job2 = job(&bundle, &scene, p2.clone(), None);
    let baker2 = Baker::new(&gpu, &scene, p2.clone()).unwrap();
    let s = bake(&job2, &baker2, &calls);
    assert_eq!(calls.get(), 8, "a parameter change must re-bake every cell");
    assert!(outcomes(&s).iter().all(|(_, baked)| *baked));
    let m = Manifest::read(&bundle).unwrap();
    assert_eq!(m.params, p2);
    assert_eq!(m.params_hash, p2.hash());
    assert_ne!(m.params_hash, params().hash());
    for id in &ids {
        let f = read_cell(&bundle, id).unwrap();
        assert_eq!(f.header.params_hash, p2.hash(), "cell {id}");
    }

    // so does a changed scene (another fingerprint)
    let mut job3 = job2.clone();
    job3.scene.fingerprint = "fingerprint-of-an-edited-scene".into();
    let s = bake(&job3, &baker2, &calls);
    assert_eq!(calls.get(), 11, "a scene change must re-bake every cell");
    assert!(outcomes(&s).iter().all(|(_, baked)| *baked));
    // and after that, an identical run skips again
    let s = bake(&job3, &baker2, &calls);
    assert_eq!(calls.get(), 11);
    assert!(outcomes(&s).iter().all(|(_, baked)| !*baked));
    // atomic writes leave no temporary files behind
    let leftovers: Vec<PathBuf> = walk(&bundle)
        .into_iter()
        .filter(|p| p.to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn shards_merge_to_the_single_run_bundle() {
    let Some(gpu) = gpu() else { return };
    let scene = scene();
    let dir = tempfile::tempdir().unwrap();
    let baker = Baker::new(&gpu, &scene, params()).unwrap();
    let calls = Cell::new(0);

    // A: one run
    let a = dir.path().join("a");
    let single = bake(&job(&a, &scene, params(), None), &baker, &calls);
    assert_eq!(single.outcomes.len(), 3);
    let manifest_a = Manifest::read(&a).unwrap();
    let ids: Vec<String> = manifest_a.cells.iter().map(|c| c.id.to_string()).collect();
    assert_eq!(ids.len(), 3);

    for n in [2u32, 3] {
        let b = dir.path().join(format!("shards-of-{n}"));
        let mut baked = Vec::new();
        for k in 0..n {
            let s = bake(
                &job(&b, &scene, params(), Some(Shard { k, n })),
                &baker,
                &calls,
            );
            assert_eq!(s.record, b.join(format!("shards/{k}-of-{n}.json")));
            assert!(
                !manifest_path(&b).exists(),
                "a shard must not write the manifest"
            );
            baked.extend(outcomes(&s).into_iter().map(|(id, _)| id));
        }
        baked.sort();
        assert_eq!(baked, ids, "the {n} shards together bake every cell once");
        let merged = merge(&b).unwrap_or_else(|e| panic!("merge of {n} shards: {e}"));
        assert_eq!(Manifest::read(&b).unwrap(), merged);
        assert_eq!(merged.generator, manifest_a.generator);
        assert_same_cell_files(&a, &b, &ids, &format!("{n} shards"));
        assert_eq!(
            merged, manifest_a,
            "the manifest merged from {n} shards differs from the single run's"
        );
        assert!(
            read(&manifest_path(&b)) == read(&manifest_path(&a)),
            "{n} shards: manifest.json is not byte-identical to the single run's"
        );
    }
    assert_eq!(calls.get(), 9);

    // a shard missing: the error names it
    let c = dir.path().join("shards-of-3");
    let missing = dir.path().join("missing-shard");
    copy_bundle(&c, &missing);
    std::fs::remove_file(missing.join("manifest.json")).unwrap();
    std::fs::remove_file(missing.join("shards/1-of-3.json")).unwrap();
    let e = err_text(merge(&missing), "merge with shard 1/3 missing");
    assert_mentions(
        &e,
        &["1/3", "not been baked"],
        "merge with shard 1/3 missing",
    );
    assert!(!e.contains("0/3") && !e.contains("2/3"), "{e}");
    assert!(!manifest_path(&missing).exists());

    // a shard baked with other parameters: the records disagree
    let b2 = dir.path().join("shards-of-2");
    let mixed = dir.path().join("mixed-params");
    copy_bundle(&b2, &mixed);
    std::fs::remove_file(mixed.join("manifest.json")).unwrap();
    let mut p2 = params();
    p2.micro_threshold = 0.5;
    let baker2 = Baker::new(&gpu, &scene, p2.clone()).unwrap();
    let s = bake(
        &job(&mixed, &scene, p2, Some(Shard { k: 1, n: 2 })),
        &baker2,
        &calls,
    );
    assert!(
        outcomes(&s).iter().all(|(_, baked)| *baked),
        "other parameters re-bake"
    );
    let e = err_text(merge(&mixed), "merge of shards with different parameters");
    assert_mentions(
        &e,
        &["disagrees", "-of-2.json", "parameters"],
        "merge of shards with different parameters",
    );
    assert!(!manifest_path(&mixed).exists());
}

#[test]
fn corrupt_or_truncated_files_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let g = grid();
    let cell = g.cells()[1];
    let good = synthetic_cell(&cell, 7).encode().unwrap();
    assert_eq!(CellFile::decode(&good).unwrap(), synthetic_cell(&cell, 7));
    let path = dir.path().join("cell.lemicell");
    let p = path.display().to_string();
    let check = |bytes: &[u8], needles: &[&str], what: &str| {
        std::fs::write(&path, bytes).unwrap();
        let e = err_text(read_synthetic(&path, &cell), what);
        assert_mentions(&e, &[&p], what);
        assert_mentions(&e, needles, what);
    };

    // truncated anywhere: inside the magic, the version, the header, a blob, the checksum
    for cut in [5, 10, 20, good.len() / 2, good.len() - 40, good.len() - 10] {
        check(&good[..cut], &["truncated"], &format!("cut to {cut} bytes"));
    }
    check(&[], &["truncated", "magic"], "an empty file");
    check(
        &good[..good.len() - 10],
        &["checksum"],
        "cut inside the checksum",
    );
    // one flipped byte in the JSON header, in the near list blob, in the checksum
    let header_at = 20 + 10;
    let blob_at = good
        .windows(8)
        .position(|w| w == b"near.bin")
        .expect("a near.bin blob")
        + 8
        + 8
        + 1;
    for at in [header_at, blob_at, good.len() - 1] {
        let mut bad = good.clone();
        bad[at] ^= 0x20;
        check(
            &bad,
            &["corrupt", "checksum"],
            &format!("a byte flipped at {at}"),
        );
    }
    let mut bad = good.clone();
    bad[..8].copy_from_slice(b"LEMIMESH");
    check(&bad, &["not a lemi cell file", "magic"], "a wrong magic");
    check(
        b"{\"format\":\"lemi-bundle\"}",
        &["magic"],
        "a JSON file named .lemicell",
    );
    let mut bad = good.clone();
    bad[8..12].copy_from_slice(&99u32.to_le_bytes());
    check(
        &bad,
        &["version 99", "not supported"],
        "an unsupported version",
    );
    std::fs::remove_file(&path).unwrap();
    let e = err_text(read_synthetic(&path, &cell), "a missing cell file");
    assert_mentions(&e, &[&p], "a missing cell file");

    // manifests
    let bundle = dir.path().join("bundle");
    std::fs::create_dir_all(&bundle).unwrap();
    let mp = manifest_path(&bundle);
    let mps = mp.display().to_string();
    assert!(mps.ends_with("manifest.json"));
    let e = err_text(Manifest::read(&bundle), "a missing manifest");
    assert_mentions(&e, &[&mps], "a missing manifest");
    let scene = SceneBuilder::new().finish();
    let valid = Manifest {
        format: "lemi-bundle".into(),
        version: BUNDLE_VERSION,
        generator: "test".into(),
        scene: scene_ref(&scene, "f"),
        params: params(),
        params_hash: params().hash(),
        grid: g.clone(),
        cells: Vec::new(),
        object: None,
    };
    valid.write(&bundle).unwrap();
    assert_eq!(Manifest::read(&bundle).unwrap(), valid);
    let json = serde_json::to_value(&valid).unwrap();
    let write_json = |v: &serde_json::Value| {
        std::fs::write(&mp, serde_json::to_vec_pretty(v).unwrap()).unwrap();
    };
    std::fs::write(&mp, b"{ \"format\": \"lemi-bundle\", ").unwrap();
    let e = err_text(Manifest::read(&bundle), "an invalid JSON manifest");
    assert_mentions(
        &e,
        &[&mps, "not a valid lemi manifest"],
        "an invalid JSON manifest",
    );
    let mut v = json.clone();
    v["format"] = "lemi-something-else".into();
    write_json(&v);
    let e = err_text(Manifest::read(&bundle), "a manifest of another format");
    assert_mentions(
        &e,
        &[&mps, "lemi-something-else", "lemi-bundle"],
        "a manifest of another format",
    );
    let mut v = json.clone();
    v["version"] = 99.into();
    write_json(&v);
    let e = err_text(Manifest::read(&bundle), "a manifest of version 99");
    assert_mentions(
        &e,
        &[&mps, "version 99", "not supported"],
        "a manifest of version 99",
    );
    let mut v = json.clone();
    v.as_object_mut().unwrap().remove("params");
    write_json(&v);
    let e = err_text(Manifest::read(&bundle), "a manifest without params");
    assert_mentions(&e, &[&mps, "params"], "a manifest without params");

    // merge refuses cell files changed after baking (no GPU needed: synthetic cells)
    let shards = dir.path().join("sharded");
    let scene_ref = scene_ref(&scene, "f");
    for k in 0..2 {
        let job = BakeJob {
            bundle: shards.clone(),
            scene: scene_ref.clone(),
            params: params(),
            grid: g.clone(),
            cells: g.cells(),
            shard: Some(Shard { k, n: 2 }),
        };
        run(&job, |c| Ok(synthetic_cell(c, 1)), |_, _, _| {}).unwrap();
    }
    let merged = merge(&shards).unwrap();
    assert_eq!(merged.cells.len(), 3);
    let victim = cell_path(&shards, "2_0_0");
    let original = read(&victim);
    let vs = victim.display().to_string();
    // re-encoded with other content: a valid file, but not the one recorded
    let mut other = CellFile::decode(&original).unwrap();
    other.near.push([3, 4]);
    std::fs::write(&victim, other.encode().unwrap()).unwrap();
    let e = err_text(merge(&shards), "merge after a cell file was replaced");
    assert_mentions(
        &e,
        &[&vs, "does not match its shard record"],
        "merge after a cell file was replaced",
    );
    // damaged
    std::fs::write(&victim, &original).unwrap();
    merge(&shards).unwrap();
    flip_byte(&victim, original.len() / 2);
    let e = err_text(merge(&shards), "merge after a cell file was damaged");
    assert_mentions(
        &e,
        &[&vs, "does not match its shard record"],
        "merge after a cell file was damaged",
    );
    // gone
    std::fs::remove_file(&victim).unwrap();
    let e = err_text(merge(&shards), "merge after a cell file was deleted");
    assert_mentions(&e, &[&vs], "merge after a cell file was deleted");
    // nothing to merge
    let e = err_text(merge(&bundle), "merge of a bundle without shards");
    assert_mentions(&e, &["shards"], "merge of a bundle without shards");
    std::fs::create_dir_all(bundle.join("shards")).unwrap();
    let e = err_text(merge(&bundle), "merge of an empty shards directory");
    assert_mentions(
        &e,
        &["no shard records"],
        "merge of an empty shards directory",
    );
    // a shard record that is not one
    std::fs::write(bundle.join("shards/0-of-1.json"), b"[1, 2, 3]").unwrap();
    let e = err_text(merge(&bundle), "merge of a bad shard record");
    assert_mentions(
        &e,
        &["0-of-1.json", "not a lemi shard record"],
        "merge of a bad shard record",
    );
}

#[test]
fn baked_cell_is_consistent() {
    let Some(gpu) = gpu() else { return };
    let scene = scene();
    let dir = tempfile::tempdir().unwrap();
    let bundle = dir.path().join("bundle");
    let p = params();
    let mut j = job(&bundle, &scene, p.clone(), None);
    j.cells = vec![grid().cell(IVec3::new(1, 0, 0)).unwrap()];
    let baker = Baker::new(&gpu, &scene, p.clone()).unwrap();
    let mut stages = Vec::new();
    let s = run(
        &j,
        |cell| baker.bake(cell, |st| stages.push(st.to_string())),
        |_, _, _| {},
    )
    .unwrap();
    let [CellOutcome::Baked { entry, file, .. }] = s.outcomes.as_slice() else {
        panic!("expected one baked cell: {:?}", s.outcomes);
    };
    let file: &CellFile = file;
    let h = &file.header;
    let layers = match p.target {
        LayerTarget::Layers(n) => n as usize,
        LayerTarget::NearField(_) => unreachable!(),
    };
    // every stage ran, every (face, layer) was recorded
    assert_eq!(stages.first().map(String::as_str), Some("placement"));
    assert_eq!(stages.last().map(String::as_str), Some("png"));
    assert_eq!(
        stages.iter().filter(|s| s.starts_with("record")).count(),
        p.faces.len() * layers
    );

    // header: the cell, the job's hashes, one layer list per face, far to near
    assert_eq!(h.cell, j.cells[0]);
    assert_eq!(h.params_hash, p.hash());
    assert_eq!(h.scene_fingerprint, j.scene.fingerprint);
    assert_eq!(h.layers.len(), p.faces.len());
    for (face, list) in p.faces.iter().zip(&h.layers) {
        assert_eq!(list.len(), layers, "face {face}");
        for l in list {
            assert!(
                l.near_border < l.distance && l.distance < l.far_border,
                "face {face}: {l:?}"
            );
        }
        for w in list.windows(2) {
            assert!(w[0].distance > w[1].distance, "face {face}: {w:?}");
            assert_eq!(w[0].near_border, w[1].far_border, "face {face}: {w:?}");
        }
        assert_eq!(list[0].far_border, f64::MAX);
        assert!(
            list[layers - 1].near_border <= h.near_field,
            "face {face}: near field {}",
            h.near_field
        );
        assert!(h.near_field > p.cell_size * 0.5);
    }

    // quads: on a baked face and layer, at that layer's distance, in a macro-texture
    assert!(!h.quads.is_empty(), "the scene shows far geometry");
    assert!(!h.macros.is_empty());
    assert_eq!(file.macro_blobs.len(), h.macros.len());
    let mut per_face_layer = vec![vec![0usize; layers]; p.faces.len()];
    for (i, q) in h.quads.iter().enumerate() {
        let slot = p
            .faces
            .iter()
            .position(|&f| f == q.face)
            .unwrap_or_else(|| panic!("quad {i} on unbaked face {}", q.face));
        let layer = q.layer as usize;
        assert!(layer < layers, "quad {i}: layer {layer}");
        per_face_layer[slot][layer] += 1;
        let m = h
            .macros
            .get(q.macro_index as usize)
            .unwrap_or_else(|| panic!("quad {i}: macro {} of {}", q.macro_index, h.macros.len()));
        let [x, y, w, hh] = q.rect;
        assert!(w > 0 && hh > 0, "quad {i}: empty rect {:?}", q.rect);
        assert!(
            x + w <= m.width && y + hh <= m.height,
            "quad {i}: rect {:?} outside its {}x{} macro-texture",
            q.rect,
            m.width,
            m.height
        );
        for [u, v] in q.macro_texel_corners() {
            assert!(u <= m.width && v <= m.height, "quad {i}");
        }
        let [tx0, ty0, tx1, ty1] = q.texels.map(u32::from);
        assert!(
            tx0 < tx1 && ty0 < ty1 && tx1 <= p.resolution && ty1 <= p.resolution,
            "quad {i}: texels {:?} outside the {}² face",
            q.texels,
            p.resolution
        );
        let (tw, th) = (tx1 - tx0, ty1 - ty0);
        let footprint = if q.rotated { (th, tw) } else { (tw, th) };
        assert_eq!(
            footprint,
            (w, hh),
            "quad {i}: texels {:?}, rect {:?}",
            q.texels,
            q.rect
        );
        let d = h.layers[slot][layer].distance;
        for c in q.corners {
            let rel = DVec3::from(c.map(f64::from)) - h.cell.center;
            let depth = rel.dot(q.face.forward());
            assert!(
                (depth - d).abs() < 1e-3 * d,
                "quad {i} of face {} layer {layer}: corner at depth {depth}, layer at {d}",
                q.face
            );
            let lateral = (rel - depth * q.face.forward()).abs().max_element();
            assert!(
                lateral <= d * (1.0 + 1e-4),
                "quad {i}: corner {rel} off the face"
            );
        }
    }
    // the scene has geometry in every slab of every face (boxes from 56 to 450 m in all directions)
    for (slot, counts) in per_face_layer.iter().enumerate() {
        assert!(
            counts.iter().all(|&c| c > 0),
            "face {}: quads per layer {counts:?}",
            p.faces[slot]
        );
    }
    let macros = file.decode_macros().unwrap();
    assert_eq!(macros.len(), h.macros.len());
    for (m, info) in macros.iter().zip(&h.macros) {
        assert_eq!((m.width, m.height), (info.width, info.height));
        assert_eq!(m.rgba.len(), (4 * m.width * m.height) as usize);
        assert!(m.rgba.chunks_exact(4).any(|t| t[3] == 255), "{}", info.name);
    }
    // each quad's texels are not all transparent
    for (i, q) in h.quads.iter().enumerate() {
        let m = &macros[q.macro_index as usize];
        let [x, y, w, hh] = q.rect;
        let opaque = (y..y + hh)
            .flat_map(|r| (x..x + w).map(move |c| (r, c)))
            .filter(|&(r, c)| m.rgba[(4 * (r * m.width + c) + 3) as usize] > 0)
            .count();
        assert!(opaque > 0, "quad {i}: no opaque texel in {:?}", q.rect);
    }

    // near list: valid, distinct triangles of the scene, and the boxes at 20 m are in it
    assert!(!file.near.is_empty());
    let mut seen = std::collections::HashSet::new();
    for &[mesh, tri] in &file.near {
        let m = scene
            .meshes
            .get(mesh as usize)
            .unwrap_or_else(|| panic!("near list: mesh {mesh} of {}", scene.meshes.len()));
        assert!(
            (tri as usize) < m.triangle_count(),
            "near list: triangle {tri} of mesh {mesh} ({} triangles)",
            m.triangle_count()
        );
        assert!(seen.insert((mesh, tri)), "near list: ({mesh}, {tri}) twice");
    }
    assert!(file.near.iter().any(|&[mesh, _]| mesh > 0), "no box near");

    // statistics
    let st = &h.stats;
    assert_eq!(st.near_triangles, file.near.len() as u64);
    assert!(st.far_triangles > 0);
    assert!(st.far_triangles <= scene.triangle_count());
    assert!(st.submitted_triangles >= st.far_triangles, "{st:?}");
    assert!(
        st.submitted_triangles <= (layers as u64 + 1) * st.far_triangles,
        "submitted {} for {} far triangles and {layers} layers: not binned per slab",
        st.submitted_triangles,
        st.far_triangles
    );
    assert_eq!(
        st.png_bytes,
        file.macro_blobs.iter().map(|b| b.len() as u64).sum::<u64>()
    );
    assert_eq!(st.micro_textures, h.quads.len() as u64);
    assert_eq!(st.macro_textures, h.macros.len() as u64);
    assert_eq!(
        st.raw_bytes,
        (p.faces.len() * layers) as u64 * 4 * u64::from(p.resolution * p.resolution),
        "raw bytes of {} RGBA8 layer images",
        p.faces.len() * layers
    );
    assert!(st.opaque_texels_recorded > 0);
    assert!(st.opaque_texels_after_hidden_removal <= st.opaque_texels_after_gap_fill);
    assert!(
        st.micro_fill_ratio > 0.0 && st.micro_fill_ratio <= 1.0,
        "{st:?}"
    );

    // the file on disk is the file returned (less the stage timings, which cell files do not
    // store), and round-trips
    let mut stored = file.clone();
    stored.header.stats.seconds.clear();
    let path = bundle.join(&entry.file);
    let bytes = read(&path);
    assert_eq!(entry.bytes, bytes.len() as u64);
    let back = read_cell(&bundle, &entry.id.to_string()).unwrap();
    assert!(
        back == stored,
        "the cell file read back differs from the baked one: {}",
        describe_file_difference(&stored, &back)
    );
    let encoded = file.encode().unwrap();
    assert!(encoded == bytes, "re-encoding gives other bytes");
    assert!(
        back.encode().unwrap() == bytes,
        "decode → encode gives other bytes"
    );
    // whatever its numbers: a stored f64 that a parser without exact float parsing (serde_json's
    // default) reads one ulp off; ~9 % of arbitrary f64 values are such values, and any of the
    // header's (near field, layer distances, cell centre, fill ratio) may be one
    let mut pinned = stored.clone();
    pinned.header.stats.micro_fill_ratio = 0.050712363999999996;
    let back = CellFile::decode(&pinned.encode().unwrap()).unwrap();
    assert!(
        back == pinned,
        "decode(encode(cell)) differs from the cell: {}",
        describe_file_difference(&pinned, &back)
    );
}

/// Which parts of two decoded cell files differ (compact, for failure messages).
fn describe_file_difference(a: &CellFile, b: &CellFile) -> String {
    let (ha, hb) = (&a.header, &b.header);
    let mut out = Vec::new();
    let mut field = |name: &str, x: String, y: String| {
        if x != y {
            let (x, y) = if x.len() > 300 {
                (format!("{} chars", x.len()), format!("{} chars", y.len()))
            } else {
                (x, y)
            };
            out.push(format!("{name}: {x} vs {y}"));
        }
    };
    field("cell", format!("{:?}", ha.cell), format!("{:?}", hb.cell));
    field(
        "near_field",
        format!("{:?}", ha.near_field),
        format!("{:?}", hb.near_field),
    );
    field(
        "layers",
        format!("{:?}", ha.layers),
        format!("{:?}", hb.layers),
    );
    field(
        "macros",
        format!("{:?}", ha.macros),
        format!("{:?}", hb.macros),
    );
    let sa = serde_json::to_value(&ha.stats).unwrap();
    let sb = serde_json::to_value(&hb.stats).unwrap();
    for (k, x) in sa.as_object().unwrap() {
        let y = &sb[k];
        if x != y {
            out.push(format!("stats.{k}: {x} vs {y}"));
        }
    }
    if ha.stats != hb.stats && sa == sb {
        out.push(format!(
            "stats differ below JSON precision: {:?} vs {:?}",
            ha.stats, hb.stats
        ));
    }
    for (i, (x, y)) in ha.quads.iter().zip(&hb.quads).enumerate() {
        if x != y {
            out.push(format!("quad {i}: {x:?} vs {y:?}"));
            break;
        }
    }
    if ha.quads.len() != hb.quads.len() {
        out.push(format!("{} vs {} quads", ha.quads.len(), hb.quads.len()));
    }
    if a.near != b.near {
        out.push("near list".into());
    }
    if a.macro_blobs != b.macro_blobs {
        out.push("PNG blobs".into());
    }
    if out.is_empty() {
        out.push("(another field)".into());
    }
    out.join("; ")
}

/// Resuming must not keep a cell file that describes another cell: moving the region by half a cell
/// keeps every id (`x_y_z` of the grid index) and the parameters, but moves every cell. (No GPU
/// needed: synthetic cells.)
#[test]
fn resume_rebakes_cells_that_moved() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = dir.path().join("bundle");
    let scene = SceneBuilder::new().finish();
    let calls = Cell::new(0);
    let fake = |c: &ViewCell| {
        calls.set(calls.get() + 1);
        Ok(synthetic_cell(c, 1))
    };
    let j1 = job(&bundle, &scene, params(), None);
    run(&j1, fake, |_, _, _| {}).unwrap();
    assert_eq!(calls.get(), 3);

    let moved = CellGrid::tile(
        Aabb::new(DVec3::new(-10.0, 1.7, -5.0), DVec3::new(20.0, 1.7, 5.0)),
        10.0,
    )
    .unwrap();
    assert_eq!(moved.counts, j1.grid.counts);
    let mut j2 = j1.clone();
    j2.cells = moved.cells();
    j2.grid = moved;
    for (a, b) in j1.cells.iter().zip(&j2.cells) {
        assert_eq!(a.id(), b.id());
        assert_ne!(a.center, b.center);
    }
    let s = run(&j2, fake, |_, _, _| {}).unwrap();
    let stale: Vec<String> = j2
        .cells
        .iter()
        .filter(|c| {
            read_cell(&bundle, &c.id().to_string())
                .map(|f| f.header.cell != **c)
                .unwrap_or(true)
        })
        .map(|c| c.id().to_string())
        .collect();
    assert!(
        stale.is_empty() && calls.get() == 6,
        "after moving the grid by half a cell, cells {stale:?} were kept from the old grid \
         (outcomes {:?}): their reference viewpoints are not the manifest grid's",
        outcomes(&s)
    );
}

/// `--texture-format bc7|bc1`: the same cell as the PNG bake, quad for quad (the texel rectangles
/// exact), each quad's footprint on 4×4 block boundaries, every texel's alpha on the same side of
/// 128 after decoding the blocks (the Basis formats after transcoding to them), colours close;
/// cells of version 8 (the quads' places and stacks derived from the packing) in a bundle that reads back.
#[test]
fn block_formats_keep_every_quad_and_the_alpha_test() {
    use lemi_core::bundle::PACKED_BUNDLE_VERSION;
    use lemi_core::compress::{MacroPlacement, TextureFormat};
    let Some(gpu) = gpu() else { return };
    let scene = scene();
    let cell = grid().cell(IVec3::new(1, 0, 0)).unwrap();
    let bake_in = |format: TextureFormat| {
        let p = BakeParams {
            texture_format: format,
            ..params()
        };
        let baker = Baker::new(&gpu, &scene, p).unwrap();
        let mut stages = Vec::new();
        let file = baker.bake(&cell, |st| stages.push(st.to_string())).unwrap();
        assert_eq!(stages.last().map(String::as_str), Some(format.name()));
        file
    };
    let png = bake_in(TextureFormat::Png);
    let png_macros = png.decode_macros().unwrap();
    for format in [
        TextureFormat::Bc7,
        TextureFormat::Bc1,
        TextureFormat::Uastc,
        TextureFormat::Etc1s,
    ] {
        let file = bake_in(format);
        let h = &file.header;
        assert_eq!(h.texture_format, format);
        assert_eq!(
            file.encode().unwrap()[8..12],
            PACKED_BUNDLE_VERSION.to_le_bytes()
        );
        let back = CellFile::decode(&file.encode().unwrap()).unwrap();
        let mut without_seconds = file.clone();
        without_seconds.header.stats.seconds.clear();
        assert!(
            back == without_seconds,
            "{format}: the cell file round-trips"
        );
        // statistics: the KTX2 files on disk, the block data in texture memory
        let block = format.block().unwrap();
        let st = &h.stats;
        assert_eq!(st.png_bytes, 0);
        assert_eq!(
            st.ktx2_bytes,
            file.macro_blobs.iter().map(|b| b.len() as u64).sum::<u64>()
        );
        assert_eq!(
            st.block_bytes,
            h.macros
                .iter()
                .map(|m| block.image_bytes(m.width, m.height) as u64)
                .sum::<u64>()
        );
        assert!(st.texture_memory_bytes() < png.header.stats.texture_memory_bytes());
        // the same quads, texel rectangles exact
        assert_eq!(h.quads.len(), png.header.quads.len());
        let macros = file.decode_macros().unwrap();
        let (mut sq, mut n, mut worst) = (0f64, 0u64, 0u8);
        for (q, pq) in h.quads.iter().zip(&png.header.quads) {
            assert_eq!((q.face, q.layer, q.texels), (pq.face, pq.layer, pq.texels));
            // the same size (a member of a stack turns with its stack, and lies at its offset in
            // it: blocks are the stacks', tested with the packer)
            let unturned = |q: &lemi_core::bundle::Quad| match q.rotated {
                true => (q.rect[3], q.rect[2]),
                false => (q.rect[2], q.rect[3]),
            };
            assert_eq!(unturned(q), unturned(pq));
            let (w, h_) = (
                (q.texels[2] - q.texels[0]) as u32,
                (q.texels[3] - q.texels[1]) as u32,
            );
            let at = |q: &lemi_core::bundle::Quad| MacroPlacement {
                macro_index: q.macro_index,
                x: q.rect[0],
                y: q.rect[1],
                rotated: q.rotated,
            };
            let (a, b) = (at(q), at(pq));
            for y in 0..h_ {
                for x in 0..w {
                    let texel = |p: &MacroPlacement, m: &[lemi_core::compress::MacroTexture]| {
                        let mt = &m[p.macro_index as usize];
                        let (mx, my) = p.macro_texel(w, h_, x, y);
                        let o = 4 * (my * mt.width + mx) as usize;
                        [mt.rgba[o], mt.rgba[o + 1], mt.rgba[o + 2], mt.rgba[o + 3]]
                    };
                    let (c, r) = (texel(&a, &macros), texel(&b, &png_macros));
                    assert_eq!(
                        c[3] >= 128,
                        r[3] >= 128,
                        "{format}: quad {q:?} texel ({x}, {y})"
                    );
                    if r[3] >= 128 {
                        for k in 0..3 {
                            let d = c[k].abs_diff(r[k]);
                            worst = worst.max(d);
                            sq += (d as f64).powi(2);
                        }
                        n += 3;
                    }
                }
            }
        }
        let rmse = (sq / n.max(1) as f64).sqrt();
        eprintln!("{format}: {n} opaque channel values, RMS error {rmse:.2}, worst {worst}");
        // checker-textured boxes at 64²: measured 4.5 (BC7) and 7.7 (BC1) RMS; ETC1S gives each
        // block one hue modulated in intensity, so a block across two checker colours loses its
        // hue (measured 19.5)
        let bound = match format.block() {
            _ if format == TextureFormat::Etc1s => 24.0,
            Some(lemi_core::compress::BlockFormat::Bc7) => 6.0,
            _ => 10.0,
        };
        assert!(rmse < bound, "{format}: RMS colour error {rmse}");
    }
    // a whole bundle in BC1: manifest and cells of version 8, read back by the one reader
    let dir = tempfile::tempdir().unwrap();
    let bundle = dir.path().join("bundle");
    let p = BakeParams {
        texture_format: TextureFormat::Bc1,
        ..params()
    };
    let mut j = job(&bundle, &scene, p.clone(), None);
    j.cells = vec![cell];
    let baker = Baker::new(&gpu, &scene, p).unwrap();
    run(&j, |c| baker.bake(c, |_| {}), |_, _, _| {}).unwrap();
    let b = Bundle::open(&bundle).unwrap();
    assert_eq!(b.manifest().version, PACKED_BUNDLE_VERSION);
    let f = b.cell(cell.id()).unwrap();
    assert_eq!(f.header.texture_format, TextureFormat::Bc1);
    assert!(f.block_macros().unwrap().is_some());
}
