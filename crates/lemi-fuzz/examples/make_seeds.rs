//! Writes the synthetic seed files of `fuzz/corpus/` (the import tests' small PLY, OBJ+MTL and
//! glTF files, containers, camera paths). The baked cell files and manifests beside them come from
//! a real bake (see `docs/RELIABILITY.md`).
//!
//!     cargo run -p lemi-fuzz --example make_seeds

#[path = "../../lemi-scene/tests/import_common/mod.rs"]
mod import_common;

use std::path::Path;

use import_common::*;
use lemi_core::bundle::CELL_MAGIC;
use lemi_core::compress::{
    encode_basis, encode_blocks, write_ktx2, BasisFormat, BlockFormat, Supercompression,
};
use lemi_core::container::{self, Blob};

fn put(target: &str, name: &str, bytes: &[u8]) {
    let dir = lemi_fuzz::fuzz_dir().join("corpus").join(target);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    println!("{} ({} bytes)", path.display(), bytes.len());
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn main() {
    let tmp = tempfile::tempdir().expect("tempdir");

    // PLY: the import tests' mesh in every encoding, plus one with normals, uv and alpha.
    put("ply", "ascii.ply", &ply_bytes(PlyFormat::Ascii));
    put("ply", "le.ply", &ply_bytes(PlyFormat::Le));
    put("ply", "be.ply", &ply_bytes(PlyFormat::Be));
    put(
        "ply",
        "normals_uv_extra.ply",
        b"ply\nformat ascii 1.0\nobj_info x\nelement vertex 3\nproperty double x\nproperty double y\n\
property double z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float s\n\
property float t\nproperty ushort red\nproperty ushort green\nproperty ushort blue\n\
property uchar alpha\nproperty list uchar short extra\nelement face 1\n\
property list uint int vertex_index\nelement edge 1\nproperty int vertex1\nproperty int vertex2\n\
end_header\n0 0 0 0 0 1 0 0 65535 0 0 255 2 7 8\n1 0 0 0 0 1 1 0 0 65535 0 128 0\n\
0 1 0 0 0 1 0 1 0 0 65535 0 1 -3\n3 0 1 2\n0 1\n",
    );
    put("ply_gz", "le.ply.gz", &gzip(&ply_bytes(PlyFormat::Le)));
    put(
        "ply_gz",
        "ascii.ply.gz",
        &gzip(&ply_bytes(PlyFormat::Ascii)),
    );

    // OBJ: OBJ bytes, a NUL, then the MTL library `input.mtl` (see `lemi_fuzz::fuzz_obj`).
    let obj = "# test\nmtllib input.mtl\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nusemtl paint\nf 1/1/1 2/2/1 3/3/1 4/4/1\n\
o tri\nv 3 0 0 1 0 0\nv 3 1 0 0 1 0\nv 3 0 2 0 0 1\nusemtl glass\nf -3 -2 -1\nl 1 2\n";
    let mtl = "newmtl paint\nKd 0.2 0.4 0.6\nmap_Kd -s 1 1 1 tex.png\n\
newmtl glass\nKd 1 1 1\nd 0.5\nmap_Kd missing.png\n";
    put("obj", "with_mtl.obj", format!("{obj}\0{mtl}").as_bytes());
    put(
        "obj",
        "plain.obj",
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1 4/1/1\n\
f 1 3 4\nl 1 2\n",
    );

    // glTF: data URIs, GLB, and external `tex.png` with a data-URI buffer.
    let gltf = read(&write_gltf(tmp.path(), "s.gltf", GltfStorage::DataUri));
    put("gltf", "data_uri.gltf", &gltf);
    put(
        "gltf",
        "binary.glb",
        &read(&write_gltf(tmp.path(), "s.glb", GltfStorage::Binary)),
    );
    let external_image = String::from_utf8_lossy(&gltf)
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("\"images\"") {
                "  \"images\": [{\"uri\": \"tex.png\"}],".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    put("gltf", "image_file.gltf", external_image.as_bytes());

    // Containers with a JSON header: empty, and with blobs.
    let header = serde_json::json!({"kind": "seed", "n": [1, 2.5, null]});
    let blobs = [
        Blob {
            name: "a.bin".into(),
            data: vec![1, 2, 3],
        },
        Blob {
            name: String::new(),
            data: vec![],
        },
    ];
    let enc = |h: &serde_json::Value, b: &[Blob]| {
        container::encode(CELL_MAGIC, 2, h, b).unwrap_or_else(|e| panic!("encode: {e}"))
    };
    put("container", "blobs.lemicell", &enc(&header, &blobs));
    put(
        "container",
        "empty.lemicell",
        &enc(&serde_json::json!({}), &[]),
    );

    // KTX2: BC1 and BC7 macro-textures as block-format cells store them (Zstandard, and without
    // supercompression), one with a second level; an 8×8 gradient with a transparent corner.
    let rgba: Vec<u8> = (0..64u32)
        .flat_map(|i| {
            let (x, y) = ((i % 8) as u8, (i / 8) as u8);
            [x * 30, y * 30, 90, if x < 2 && y < 2 { 0 } else { 255 }]
        })
        .collect();
    for format in [BlockFormat::Bc1, BlockFormat::Bc7] {
        let (blocks, _) = encode_blocks(format, 8, 8, &rgba).expect("encode");
        let (small, _) = encode_blocks(format, 4, 4, &rgba[..64]).expect("encode");
        let name = format!("{format:?}").to_lowercase();
        for (tag, levels, scheme) in [
            ("zstd", vec![blocks.clone()], Supercompression::Zstd),
            ("raw", vec![blocks.clone()], Supercompression::None),
            ("mips", vec![blocks.clone(), small], Supercompression::Zstd),
        ] {
            let file = write_ktx2(format, 8, 8, &levels, scheme).expect("ktx2");
            put("ktx2", &format!("{name}_{tag}.ktx2"), &file);
        }
    }

    // Basis Universal: ETC1S (BasisLZ) and UASTC (Zstandard) of the same 8×8 image, as `etc1s` and
    // `uastc` cells store them
    for format in [BasisFormat::Etc1s, BasisFormat::Uastc] {
        let (file, _) = encode_basis(format, 8, 8, &rgba).expect("basis");
        let name = format!("{format:?}").to_lowercase();
        put("ktx2", &format!("{name}.ktx2"), &file);
    }

    // Camera paths: the format's example, and one with a full turn and unknown fields.
    put(
        "camera_path",
        "example.json",
        br#"{
  "format": "lemi-path",
  "version": 1,
  "fps": 30,
  "keys": [
    { "t": 0.0, "eye": [0.0, 1.7, 0.0], "yaw_deg": 0.0,  "pitch_deg": 0.0 },
    { "t": 2.5, "eye": [3.5, 1.7, 0.0], "yaw_deg": 90.0, "pitch_deg": -5.0 }
  ]
}
"#,
    );
    put(
        "camera_path",
        "turn.json",
        br#"{"format":"lemi-path","version":1,"fps":1000,"note":"x","keys":[
{"t":-1,"eye":[1e3,-2,3],"yaw_deg":350,"pitch_deg":90},
{"t":0.001,"eye":[0,0,0],"yaw_deg":10,"pitch_deg":-90},
{"t":0.5,"eye":[0,0,1],"yaw_deg":-720,"pitch_deg":0}]}"#,
    );
}
