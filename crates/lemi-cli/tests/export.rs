//! `lemi export`: the round trip (quads and texels read back from the `.glb` files with the `gltf`
//! crate equal the bundle's), the Khronos glTF-Validator over every exported cell (0 errors, 0
//! warnings; a deliberately broken file is reported with errors, so the check can fail), the
//! bytes against the cell files, and clear errors for missing, damaged and foreign bundles.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{assert_clean_error, assert_clean_error_all, lemi, stderr, tmp};
use lemi_core::bundle::Bundle;

/// Two cells of the builtin city: 64² texels, 4 layers (as the bake tests' small bundle, one cell
/// wider).
const SMALL: [&str; 11] = [
    "builtin:city:20k:3",
    "--region",
    "15,1.7,-5,35,1.7,5",
    "--cell-size",
    "10",
    "--resolution",
    "64",
    "--layers",
    "4",
    "--alpha-deg",
    "0.5",
];

fn bake(out: &Path, extra: &[&str]) {
    let mut args = vec!["bake"];
    args.extend(SMALL);
    args.extend(["-o", out.to_str().unwrap()]);
    args.extend(extra);
    let o = lemi(&args);
    assert!(o.status.success(), "bake: {}", stderr(&o));
}

fn export(bundle: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "export",
        bundle.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    lemi(&args)
}

/// Every quad of a `.glb` as (macro-texture, corners, macro-texel corners), in file order, and
/// its images decoded to RGBA8 (in image order).
type ReadBack = (
    Vec<(usize, [[f32; 3]; 4], [[u32; 2]; 4])>,
    Vec<(u32, u32, Vec<u8>)>,
);

fn read_glb(path: &Path) -> ReadBack {
    let bytes = std::fs::read(path).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).expect("a valid glTF");
    let blob = gltf.blob.as_deref().expect("a GLB with a binary chunk");
    let view_bytes = |view: gltf::buffer::View| {
        let start = view.offset();
        &blob[start..start + view.length()]
    };
    let mut images = Vec::new();
    for image in gltf.images() {
        let gltf::image::Source::View { view, mime_type } = image.source() else {
            panic!("images are embedded");
        };
        assert_eq!(mime_type, "image/png");
        let img = image::load_from_memory(view_bytes(view))
            .unwrap()
            .to_rgba8();
        images.push((img.width(), img.height(), img.into_raw()));
    }
    let mut quads = Vec::new();
    let impostors = gltf
        .meshes()
        .find(|m| m.name() == Some("impostors"))
        .expect("an impostors mesh");
    for prim in impostors.primitives() {
        let material = prim.material();
        assert!(material.unlit(), "quads are unlit");
        match material.alpha_mode() {
            gltf::material::AlphaMode::Mask => assert_eq!(material.alpha_cutoff(), Some(0.5)),
            gltf::material::AlphaMode::Opaque => {}
            mode => panic!("quads are alpha-tested or opaque, not {mode:?}"),
        }
        let texture = material
            .pbr_metallic_roughness()
            .base_color_texture()
            .expect("a base colour texture")
            .texture();
        let m = texture.source().index();
        let reader = prim.reader(|_| Some(blob));
        let p: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        let uv: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
        let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
        assert_eq!(p.len() % 4, 0);
        assert_eq!(idx.len(), p.len() / 4 * 6);
        let (w, h) = (images[m].0 as f32, images[m].1 as f32);
        for q in 0..p.len() / 4 {
            let base = 4 * q as u32;
            assert_eq!(idx[6 * q..6 * q + 6], [0, 1, 2, 0, 2, 3].map(|i| base + i));
            let corners = std::array::from_fn(|k| p[4 * q + k]);
            let texels = std::array::from_fn(|k| {
                let [u, v] = uv[4 * q + k];
                let (x, y) = (u * w, v * h);
                assert!((x - x.round()).abs() < 1e-3 && (y - y.round()).abs() < 1e-3);
                [x.round() as u32, y.round() as u32]
            });
            quads.push((m, corners, texels));
        }
    }
    (quads, images)
}

/// The exported quads and texels are the bundle's, cell by cell.
fn assert_round_trip(bundle: &Path, out: &Path) {
    let b = Bundle::open(bundle).unwrap();
    for id in b.cell_ids() {
        let file = b.cell(id).unwrap();
        let (quads, images) = read_glb(&out.join(format!("cells/{id}.glb")));
        let opaque = lemi_export::opaque_quads(&file).unwrap();
        let order = lemi_export::quad_order(&file.header.quads, &opaque);
        let expected: Vec<_> = order
            .iter()
            .map(|&k| {
                let q = &file.header.quads[k];
                (q.macro_index as usize, q.corners, q.macro_texel_corners())
            })
            .collect();
        assert_eq!(quads.len(), file.header.quads.len(), "cell {id}");
        assert_eq!(quads, expected, "cell {id}: quads differ");
        let macros = file.decode_macros().unwrap();
        assert_eq!(images.len(), macros.len());
        for (i, (m, (w, h, rgba))) in macros.iter().zip(&images).enumerate() {
            assert_eq!((m.width, m.height), (*w, *h), "cell {id} macro {i}");
            assert!(m.rgba == *rgba, "cell {id} macro {i}: texels differ");
        }
    }
}

#[test]
fn exported_quads_and_texels_are_the_bundles() {
    let d = tmp("export", "round-trip");
    for format in ["png", "bc7"] {
        let bundle = d.join(format);
        bake(&bundle, &["--texture-format", format]);
        let out = d.join(format!("{format}-gltf"));
        let o = export(&bundle, &out, &["--json"]);
        assert!(o.status.success(), "{format}: {}", stderr(&o));
        assert_round_trip(&bundle, &out);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let index: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("cells.json")).unwrap()).unwrap();
        assert_eq!(index["format"], "lemi-gltf-export");
        assert_eq!(index["cells"].as_array().unwrap().len(), 2, "{index}");
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(bundle.join("manifest.json")).unwrap()).unwrap();
        assert_eq!(index["scene"]["fingerprint"], m["scene"]["fingerprint"]);
        for c in index["cells"].as_array().unwrap() {
            let (bytes, source) = (
                c["bytes"].as_u64().unwrap(),
                c["source_bytes"].as_u64().unwrap(),
            );
            let on_disk = std::fs::metadata(out.join(c["file"].as_str().unwrap()))
                .unwrap()
                .len();
            assert_eq!(bytes, on_disk);
            eprintln!(
                "{format} cell {}: {bytes} bytes of .glb from a {source}-byte cell file (ratio {:.3})",
                c["id"],
                bytes as f64 / source as f64
            );
            // what a file holds: the macro-textures (a PNG bundle's files as they are), 92 bytes
            // a quad (4 f32 corners, 4 f32 texture coordinates, 6 u16 indices, 4-byte aligned
            // per primitive) and a few KB of JSON; the cell file deflates its 20-byte quad
            // records, so a cell of many quads exports larger than it is (docs/EXPORT.md)
            let id: lemi_core::cell::CellId = c["id"].as_str().unwrap().parse().unwrap();
            let file = Bundle::open(&bundle).unwrap().cell(id).unwrap();
            let textures = c["texture_bytes"].as_u64().unwrap();
            if format == "png" {
                let stored: usize = file.macro_blobs.iter().map(|b| b.len()).sum();
                assert_eq!(textures, stored as u64, "{c}");
            }
            let quads = c["quads"].as_u64().unwrap();
            assert_eq!(quads, file.header.quads.len() as u64);
            assert!(bytes <= textures + 92 * quads + 8 * 1024, "{c}");
        }
        assert!(v["max_bytes_ratio"].is_number(), "{v}");
    }
    // only some cells; the near geometry needs the scene and is written too
    let bundle = d.join("png");
    let out = d.join("near");
    let o = export(&bundle, &out, &["--cells", "1_0_0", "--with-near"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("cells/1_0_0.glb").is_file());
    assert!(!out.join("cells/0_0_0.glb").exists());
    let gltf = gltf::Gltf::open(out.join("cells/1_0_0.glb")).unwrap();
    let near = gltf
        .meshes()
        .find(|m| m.name() == Some("near"))
        .expect("a near mesh");
    assert!(near.primitives().len() > 0);
    let extras: serde_json::Value = serde_json::from_str(
        gltf.scenes()
            .next()
            .unwrap()
            .extras()
            .as_ref()
            .unwrap()
            .get(),
    )
    .unwrap();
    let lemi = &extras["lemi"];
    assert_eq!(lemi["cell"], "1_0_0");
    assert_eq!(lemi["layer_count"], serde_json::json!([4, 4, 4, 4]));
    assert!(lemi["alpha"].as_f64().unwrap() > 0.0);
    assert!(lemi["near_triangles"].as_u64().unwrap() > 0);
    for key in ["box", "reference_viewpoint", "layers", "scene_fingerprint"] {
        assert!(!lemi[key].is_null(), "{key}: {lemi}");
    }
}

/// `node` and `web/node_modules` (npm ci in web/), or `None` after a visible skip.
fn node_tools() -> Option<PathBuf> {
    let web = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../web");
    if Command::new("node").arg("--version").output().is_err() {
        lemi_testkit::skip("node is not installed (.ci/run installs it)");
        return None;
    }
    if !web.join("node_modules/gltf-validator").is_dir() {
        lemi_testkit::skip(&format!(
            "{}/node_modules/gltf-validator missing (run `npm ci` in web/, as .ci/run does)",
            web.display()
        ));
        return None;
    }
    Some(web)
}

/// The validator's report per file.
fn validate(web: &Path, files: &[PathBuf]) -> Vec<serde_json::Value> {
    let o = Command::new("node")
        .arg(web.join("tools/validate.mjs"))
        .args(files)
        .output()
        .unwrap();
    assert!(o.status.success(), "validator: {}", stderr(&o));
    String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn every_exported_cell_passes_the_khronos_validator() {
    let Some(web) = node_tools() else { return };
    let d = tmp("export", "validator");
    let bundle = d.join("b");
    bake(&bundle, &[]);
    let out = d.join("gltf");
    let o = export(&bundle, &out, &["--with-near"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let files: Vec<PathBuf> = ["0_0_0", "1_0_0"]
        .iter()
        .map(|id| out.join(format!("cells/{id}.glb")))
        .collect();
    for r in validate(&web, &files) {
        assert_eq!(r["errors"], 0, "{r}");
        assert_eq!(r["warnings"], 0, "{r}");
    }
    // KTX2 textures (a BC7 bundle's files through KHR_texture_basisu): no errors; the warnings
    // are the validator not knowing the extension, so not the KTX2 MIME type or image format
    let bc7 = d.join("bc7");
    bake(&bc7, &["--texture-format", "bc7"]);
    let ktx2 = d.join("ktx2");
    let o = export(&bc7, &ktx2, &["--textures", "ktx2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = &validate(&web, &[ktx2.join("cells/0_0_0.glb")])[0];
    assert_eq!(r["errors"], 0, "{r}");
    for m in r["messages"].as_array().unwrap() {
        let code = m["code"].as_str().unwrap();
        assert!(
            [
                "UNSUPPORTED_EXTENSION",
                "UNUSED_OBJECT",
                "VALUE_NOT_IN_LIST",
                "IMAGE_UNRECOGNIZED_FORMAT"
            ]
            .contains(&code),
            "{m}"
        );
        if code == "VALUE_NOT_IN_LIST" {
            assert!(m["pointer"].as_str().unwrap().ends_with("/mimeType"), "{m}");
        }
    }
    // a broken file: the first accessor reads far past its buffer view
    let bytes = std::fs::read(&files[0]).unwrap();
    let glb = gltf::binary::Glb::from_slice(&bytes).unwrap();
    let mut json: serde_json::Value = serde_json::from_slice(&glb.json).unwrap();
    let count = json["accessors"][0]["count"].as_u64().unwrap();
    json["accessors"][0]["count"] = (count * 1000).into();
    let broken = gltf::binary::Glb {
        header: glb.header,
        json: serde_json::to_vec(&json).unwrap().into(),
        bin: glb.bin.clone(),
    }
    .to_vec()
    .unwrap();
    let broken_path = d.join("broken.glb");
    std::fs::write(&broken_path, broken).unwrap();
    let r = &validate(&web, &[broken_path])[0];
    assert!(r["errors"].as_u64().unwrap() > 0, "{r}");
    let codes: Vec<&str> = r["messages"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|m| m["code"].as_str())
        .collect();
    assert!(
        codes.iter().any(|c| c.contains("ACCESSOR")),
        "the error names the accessor: {r}"
    );
}

#[test]
fn missing_damaged_and_foreign_bundles_are_clear_errors() {
    let d = tmp("export", "errors");
    let out = d.join("out");
    // missing
    let missing = d.join("missing");
    assert_clean_error_all(&export(&missing, &out, &[]), &["missing", "not a bundle"]);
    // a directory without a manifest
    let empty = d.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert_clean_error(&export(&empty, &out, &[]), "manifest.json");
    // a foreign manifest (another program's JSON)
    let foreign = d.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(
        foreign.join("manifest.json"),
        br#"{"format":"something-else","version":1}"#,
    )
    .unwrap();
    assert_clean_error_all(&export(&foreign, &out, &[]), &["manifest.json", "lemi"]);
    // a damaged cell file
    let bundle = d.join("b");
    bake(&bundle, &[]);
    let cell = bundle.join("cells/1_0_0.lemicell");
    let mut bytes = std::fs::read(&cell).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x20;
    std::fs::write(&cell, bytes).unwrap();
    assert_clean_error_all(&export(&bundle, &out, &[]), &["1_0_0.lemicell", "BLAKE3"]);
    // flags
    assert_clean_error_all(
        &export(&bundle, &out, &["--cells", "7_0_0"]),
        &["--cells", "7_0_0"],
    );
    assert_clean_error_all(
        &export(&bundle, &out, &["--cells", "0_0_0", "--textures", "ktx2"]),
        &["--textures ktx2", "bc7"],
    );
    // lemi serve on something that is neither a bundle nor an export
    assert_clean_error_all(
        &lemi(&["serve", empty.to_str().unwrap(), "--port", "0"]),
        &["empty", "neither a bundle", "cells.json"],
    );
    // the cells before the damaged one were exported, and the index is not written over a
    // partial export
    assert!(!out.join("cells.json").exists());
}
