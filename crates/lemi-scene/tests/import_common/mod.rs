//! Writers for small glTF, GLB, OBJ+MTL and PLY files used by the import tests.
#![allow(dead_code)]

use std::io::Write;
use std::path::Path;

use base64::Engine;

/// A `w × h` PNG with a colour gradient.
pub fn png(w: u32, h: u32) -> Vec<u8> {
    let img = image::RgbaImage::from_fn(w, h, |x, y| {
        image::Rgba([(x * 40 % 256) as u8, (y * 40 % 256) as u8, 7, 255])
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| e.to_string())
        .unwrap_or_else(|e| panic!("png encode: {e}"));
    out.into_inner()
}

fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// How the glTF test file stores its buffer and image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GltfStorage {
    /// `.gltf` + external `data.bin` + external `tex.png`.
    External,
    /// `.gltf` with `data:` URIs for both.
    DataUri,
    /// `.glb` with the image in a buffer view.
    Binary,
}

/// Texture size of the glTF test scene.
pub const GLTF_TEX: (u32, u32) = (4, 2);

/// The glTF test scene: a textured quad (2 triangles, u16 indices) under a node hierarchy
/// `T(0,5,0) · T(10,0,0)·S(2)`, plus a non-indexed triangle with normals under `T(0,0,-20)·S(2,1,1)`
/// and a POINTS primitive that must be skipped.
/// Expected bounds: min (0, 0, -20), max (12, 7, 0); 3 triangles.
pub fn write_gltf(dir: &Path, name: &str, storage: GltfStorage) -> std::path::PathBuf {
    let png = png(GLTF_TEX.0, GLTF_TEX.1);
    let mut bin = Vec::new();
    bin.extend(f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0., 1., 1., 0.])); // 0..48
    bin.extend(f32s(&[0., 1., 1., 1., 0., 0., 1., 0.])); // 48..80
    for i in [0u16, 1, 2, 1, 3, 2] {
        bin.extend(i.to_le_bytes()); // 80..92
    }
    bin.extend(f32s(&[1., 0., 0., 0., 1., 0., 1., 0., 1.])); // 92..128
    let s = std::f32::consts::FRAC_1_SQRT_2;
    bin.extend(f32s(&[s, s, 0., s, s, 0., s, s, 0.])); // 128..164
    let png_offset = bin.len();
    if storage == GltfStorage::Binary {
        bin.extend(&png);
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
    }
    let b64 = |b: &[u8]| base64::engine::general_purpose::STANDARD.encode(b);
    let buffer = match storage {
        GltfStorage::External => format!(r#"{{"uri":"data.bin","byteLength":{}}}"#, bin.len()),
        GltfStorage::DataUri => format!(
            r#"{{"uri":"data:application/octet-stream;base64,{}","byteLength":{}}}"#,
            b64(&bin),
            bin.len()
        ),
        GltfStorage::Binary => format!(r#"{{"byteLength":{}}}"#, bin.len()),
    };
    let image = match storage {
        GltfStorage::External => r#"{"uri":"tex.png"}"#.to_string(),
        GltfStorage::DataUri => format!(r#"{{"uri":"data:image/png;base64,{}"}}"#, b64(&png)),
        GltfStorage::Binary => r#"{"bufferView":5,"mimeType":"image/png"}"#.to_string(),
    };
    let extra_view = if storage == GltfStorage::Binary {
        format!(
            r#",{{"buffer":0,"byteOffset":{png_offset},"byteLength":{}}}"#,
            png.len()
        )
    } else {
        String::new()
    };
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0, 2]}}],
  "nodes": [
    {{"translation": [0, 5, 0], "children": [1]}},
    {{"translation": [10, 0, 0], "scale": [2, 2, 2], "mesh": 0}},
    {{"translation": [0, 0, -20], "scale": [2, 1, 1], "mesh": 1}}
  ],
  "meshes": [
    {{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "indices": 2, "material": 0}}]}},
    {{"primitives": [
      {{"attributes": {{"POSITION": 3, "NORMAL": 4}}}},
      {{"attributes": {{"POSITION": 3}}, "mode": 0}}
    ]}}
  ],
  "materials": [{{"pbrMetallicRoughness": {{"baseColorFactor": [0.5, 0.25, 1.0, 1.0],
                 "baseColorTexture": {{"index": 0}}}}}}],
  "textures": [{{"source": 0}}],
  "images": [{image}],
  "buffers": [{buffer}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 80, "byteLength": 12}},
    {{"buffer": 0, "byteOffset": 92, "byteLength": 36}},
    {{"buffer": 0, "byteOffset": 128, "byteLength": 36}}{extra_view}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"}},
    {{"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}},
    {{"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,1]}},
    {{"bufferView": 4, "componentType": 5126, "count": 3, "type": "VEC3"}}
  ]
}}"#
    );
    let path = dir.join(name);
    match storage {
        GltfStorage::External => {
            write(&dir.join("data.bin"), &bin);
            write(&dir.join("tex.png"), &png);
            write(&path, json.as_bytes());
        }
        GltfStorage::DataUri => write(&path, json.as_bytes()),
        GltfStorage::Binary => write(&path, &glb(json.as_bytes(), &bin)),
    }
    path
}

/// Packs JSON and BIN chunks into a GLB container (glTF 2.0 spec, section 4.4).
pub fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let mut j = json.to_vec();
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while b.len() % 4 != 0 {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(0x4E4F_534Au32.to_le_bytes());
    out.extend(j);
    out.extend((b.len() as u32).to_le_bytes());
    out.extend(0x004E_4942u32.to_le_bytes());
    out.extend(b);
    out
}

pub fn write(path: &Path, bytes: &[u8]) {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).unwrap_or_else(|e| panic!("{}: {e}", parent.display()));
    }
    std::fs::write(path, bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

/// Texture size of the OBJ test scene.
pub const OBJ_TEX: (u32, u32) = (8, 4);

/// OBJ test scene: a quad (`f` with 4 corners) and a triangle, material `paint` with
/// `Kd 0.2 0.4 0.6` and `map_Kd textures/wood.png` (relative to the MTL in `mtl/`).
/// 3 triangles; bounds (0,0,0)–(3,1,2).
pub fn write_obj(dir: &Path, name: &str) -> std::path::PathBuf {
    let obj = "# test\nmtllib mtl/scene.mtl\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl paint\nf 1/1 2/2 3/3 4/4\n\
o tri\nv 3 0 0\nv 3 1 0\nv 3 0 2\nf 5 6 7\n";
    let mtl = "newmtl paint\nKd 0.2 0.4 0.6\nmap_Kd textures/wood.png\n";
    write(&dir.join("mtl/scene.mtl"), mtl.as_bytes());
    write(
        &dir.join("mtl/textures/wood.png"),
        &png(OBJ_TEX.0, OBJ_TEX.1),
    );
    let path = dir.join(name);
    write(&path, obj.as_bytes());
    path
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlyFormat {
    Ascii,
    Le,
    Be,
}

/// PLY test mesh: 5 vertices with uchar colours, a quad and a triangle (3 triangles), vertex 0
/// pure red. Bounds (0,0,0)–(1,2,3).
pub const PLY_VERTS: [[f32; 3]; 5] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 2.0, 0.0],
    [0.0, 2.0, 0.0],
    [0.0, 0.0, 3.0],
];
pub const PLY_FACES: [&[u32]; 2] = [&[0, 1, 2, 3], &[0, 4, 1]];

pub fn ply_bytes(format: PlyFormat) -> Vec<u8> {
    let (fmt, list) = match format {
        PlyFormat::Ascii => ("ascii", "property list uchar int vertex_indices"),
        PlyFormat::Le => (
            "binary_little_endian",
            "property list uint8 int32 vertex_indices",
        ),
        PlyFormat::Be => ("binary_big_endian", "property list uchar uint vertex_index"),
    };
    let mut out = format!(
        "ply\nformat {fmt} 1.0\ncomment made by a test\nelement vertex {}\nproperty float x\n\
property float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
element face {}\n{list}\nend_header\n",
        PLY_VERTS.len(),
        PLY_FACES.len()
    )
    .into_bytes();
    let colour = |i: usize| {
        if i == 0 {
            [255u8, 0, 0]
        } else {
            [255u8, 255, 255]
        }
    };
    for (i, v) in PLY_VERTS.iter().enumerate() {
        let c = colour(i);
        match format {
            PlyFormat::Ascii => out
                .extend(format!("{} {} {} {} {} {}\n", v[0], v[1], v[2], c[0], c[1], c[2]).bytes()),
            PlyFormat::Le => {
                v.iter().for_each(|x| out.extend(x.to_le_bytes()));
                out.extend(c);
            }
            PlyFormat::Be => {
                v.iter().for_each(|x| out.extend(x.to_be_bytes()));
                out.extend(c);
            }
        }
    }
    for f in PLY_FACES {
        match format {
            PlyFormat::Ascii => {
                let s: Vec<String> = f.iter().map(|i| i.to_string()).collect();
                out.extend(format!("{} {}\n", f.len(), s.join(" ")).bytes());
            }
            PlyFormat::Le => {
                out.push(f.len() as u8);
                f.iter().for_each(|i| out.extend(i.to_le_bytes()));
            }
            PlyFormat::Be => {
                out.push(f.len() as u8);
                f.iter().for_each(|i| out.extend(i.to_be_bytes()));
            }
        }
    }
    out
}

pub fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(bytes)
        .and_then(|_| enc.finish())
        .unwrap_or_else(|e| panic!("gzip: {e}"))
}

/// `<workspace root>/.test-data`, or `$LEMI_TEST_DATA`.
pub fn test_data() -> std::path::PathBuf {
    match std::env::var_os("LEMI_TEST_DATA") {
        Some(d) => d.into(),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.test-data"),
    }
}
