//! glTF 2.0 reader (`.gltf` with external or `data:` buffers and images, `.glb`), based on the
//! Khronos glTF 2.0 specification (3.5 Scenes: node hierarchy and transforms; 3.6 Binary data
//! storage and 3.6.2 Accessors; 3.7 Geometry: meshes and primitive topologies; 3.9 Materials;
//! 4 GLB file format).
//!
//! The `gltf` crate parses and validates the JSON and the GLB container; buffers, images and
//! accessors are resolved here with checked arithmetic, so every broken reference or short buffer
//! is an error naming the file rather than a panic. Node transforms are applied in `f64`
//! (positions by the world matrix, normals by the inverse transpose of its upper 3×3, winding
//! flipped when the determinant is negative, spec 3.7.2.1). Triangle lists, strips and fans,
//! indexed or not, are read; point and line primitives are skipped and counted. Materials take the
//! base colour factor and the base colour texture (decoded with `image` to RGBA8 sRGB); vertices
//! take `TEXCOORD_0` and `COLOR_0` (linear, stored as 8-bit linear).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use base64::Engine;
use glam::{DMat3, DMat4, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use gltf::{Gltf, Semantic};
use lemi_core::{Material, Mesh, SceneBuilder, Vertex};

use super::{decode_texture, malformed, read_file, read_referenced, ImportReport};
use crate::{LoadOptions, SceneError};

pub(super) fn load(
    path: &Path,
    options: &LoadOptions,
    builder: &mut SceneBuilder,
    report: &mut ImportReport,
) -> Result<(), SceneError> {
    let bytes = read_file(path)?;
    let gltf = parse(&bytes).map_err(|e| malformed(path, format!("glTF: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let doc = &gltf.document;
    // Required extensions that change how geometry is stored cannot be ignored (spec 3.12).
    for ext in doc.extensions_required() {
        if ext != "KHR_mesh_quantization" && !ext.starts_with("KHR_materials_") {
            return Err(malformed(
                path,
                format!("glTF: requires extension {ext}, which is not supported"),
            ));
        }
    }

    let mut buffers: Vec<Vec<u8>> = Vec::new();
    for buffer in doc.buffers() {
        let what = format!("buffer {}", buffer.index());
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => gltf
                .blob
                .clone()
                .ok_or_else(|| malformed(path, format!("{what}: the GLB has no BIN chunk")))?,
            gltf::buffer::Source::Uri(uri) => read_uri(dir, uri)
                .map_err(|e| malformed(path, format!("{what} (`{}`): {e}", short(uri))))?,
        };
        if data.len() < buffer.length() {
            return Err(malformed(
                path,
                format!(
                    "{what}: {} bytes declared but only {} present",
                    buffer.length(),
                    data.len()
                ),
            ));
        }
        buffers.push(data);
    }

    let mut ctx = Ctx {
        path,
        dir,
        doc,
        buffers: &buffers,
        materials: HashMap::new(),
        textures: HashMap::new(),
    };

    // The nodes to draw: the default scene, else the first, else every root node.
    let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    if let Some(f) = is_child.get_mut(c.index()) {
                        *f = true;
                    }
                }
            }
            doc.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    };
    let mut visited = vec![false; doc.nodes().len()];
    let mut stack: Vec<(gltf::Node, DMat4)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, DMat4::IDENTITY))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        // A node reached twice (a cycle or a shared subtree, both invalid glTF) is drawn once.
        if std::mem::replace(&mut visited[node.index()], true) {
            report.warn(
                path,
                format!("node {} is reachable more than once", node.index()),
            );
            continue;
        }
        let local = node.transform().matrix().map(|c| c.map(f64::from));
        let world = parent * DMat4::from_cols_array_2d(&local);
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                ctx.primitive(&prim, &world, options, builder, report)?;
            }
        }
        let children: Vec<_> = node.children().collect();
        for c in children.into_iter().rev() {
            stack.push((c, world));
        }
    }
    Ok(())
}

/// Parses and validates the JSON (and GLB container). Like `Gltf::from_slice`, except that it
/// first checks the one reference `gltf-json`'s validation indexes without a bounds check, and
/// that it accepts a `POSITION` accessor without `min`/`max` (required by the spec but often
/// missing, and not used here).
pub(crate) fn parse(bytes: &[u8]) -> Result<Gltf, String> {
    use gltf::json::validation::Validate;
    // `gltf` 1.4 subtracts the 12-byte header from a GLB's declared length unchecked (an overflow
    // panic in builds with overflow checks): a length shorter than the header is refused here.
    if let Some(len) = bytes
        .strip_prefix(b"glTF")
        .and_then(|rest| rest.get(4..8))
        .map(|l| u32::from_le_bytes([l[0], l[1], l[2], l[3]]))
        .filter(|&l| l < 12)
    {
        return Err(format!(
            "GLB header: total length {len} is shorter than the 12-byte header"
        ));
    }
    let gltf = Gltf::from_slice_without_validation(bytes).map_err(|e| e.to_string())?;
    let root = gltf.document.as_json();
    for (mi, m) in root.meshes.iter().enumerate() {
        for (pi, p) in m.primitives.iter().enumerate() {
            for idx in p.attributes.values() {
                if idx.value() >= root.accessors.len() {
                    return Err(format!(
                        "meshes[{mi}].primitives[{pi}]: accessor {} does not exist",
                        idx.value()
                    ));
                }
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, gltf::json::Path::new, &mut |path, error| {
        let path = path();
        let p = path.as_str();
        if !(p.ends_with(".min") || p.ends_with(".max")) {
            errors.push(format!("{p}: {error}"));
        }
    });
    if !errors.is_empty() {
        let n = errors.len();
        errors.truncate(3);
        return Err(format!(
            "invalid document ({n} problems): {}",
            errors.join("; ")
        ));
    }
    Ok(gltf)
}

/// Shortens a URI for messages (`data:` URIs can be megabytes long).
fn short(uri: &str) -> String {
    if uri.len() > 60 {
        format!("{}…", uri.chars().take(40).collect::<String>())
    } else {
        uri.to_string()
    }
}

/// Where a buffer or image URI points: `None` for a `data:` URI (its bytes are inside the glTF
/// file), else the file it names, relative to the glTF file's directory `dir` (percent-decoded;
/// `../` and `file://` paths allowed). Other schemes and bad encodings are errors.
pub(crate) fn uri_path(dir: &Path, uri: &str) -> Result<Option<PathBuf>, String> {
    if uri.starts_with("data:") {
        return Ok(None);
    }
    let rel = if let Some(p) = uri.strip_prefix("file://") {
        p.to_string()
    } else if uri.contains("://") {
        return Err("only relative paths and `data:` URIs are supported".into());
    } else {
        percent_encoding::percent_decode_str(uri)
            .decode_utf8()
            .map_err(|e| format!("bad URI encoding: {e}"))?
            .into_owned()
    };
    Ok(Some(dir.join(rel)))
}

/// Reads a buffer or image URI: `data:` (base64) or a path relative to the glTF file.
fn read_uri(dir: &Path, uri: &str) -> Result<Vec<u8>, String> {
    match uri_path(dir, uri)? {
        Some(full) => read_referenced(&full).map_err(|e| format!("{}: {e}", full.display())),
        None => {
            let rest = uri.strip_prefix("data:").unwrap_or(uri);
            let (_, payload) = rest
                .split_once(";base64,")
                .ok_or("only base64 `data:` URIs are supported")?;
            base64::engine::general_purpose::STANDARD
                .decode(payload.trim())
                .map_err(|e| format!("bad base64: {e}"))
        }
    }
}

struct Ctx<'a> {
    path: &'a Path,
    dir: &'a Path,
    doc: &'a gltf::Document,
    buffers: &'a [Vec<u8>],
    /// glTF material index (`None`: the default material) → scene material.
    materials: HashMap<Option<usize>, u32>,
    /// glTF image index → scene texture (`None` if it could not be decoded).
    textures: HashMap<usize, Option<u32>>,
}

impl Ctx<'_> {
    fn err(&self, message: String) -> SceneError {
        malformed(self.path, message)
    }

    fn primitive(
        &mut self,
        prim: &gltf::Primitive,
        world: &DMat4,
        options: &LoadOptions,
        builder: &mut SceneBuilder,
        report: &mut ImportReport,
    ) -> Result<(), SceneError> {
        let mode = prim.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            report.skipped_primitives += 1;
            report.warn(self.path, format!("skipped a {mode:?} primitive"));
            return Ok(());
        }
        let Some(pos_acc) = prim.get(&Semantic::Positions) else {
            report.warn(self.path, "skipped a primitive without POSITION");
            return Ok(());
        };
        let what = |name: &str| format!("accessor {} ({name})", pos_acc.index());
        let positions = read_accessor(&pos_acc, self.buffers, false)
            .map_err(|e| self.err(format!("{}: {e}", what("POSITION"))))?;
        if positions.dims < 3 {
            return Err(self.err(format!("{}: POSITION must be VEC3", what("POSITION"))));
        }
        let n = positions.count;
        let attr = |sem: Semantic,
                    name: &str,
                    min_dims: usize|
         -> Result<Option<Values>, SceneError> {
            let Some(acc) = prim.get(&sem) else {
                return Ok(None);
            };
            let v = read_accessor(&acc, self.buffers, true).map_err(|e| {
                malformed(self.path, format!("accessor {} ({name}): {e}", acc.index()))
            })?;
            if v.dims < min_dims || v.count < n {
                return Err(malformed(
                    self.path,
                    format!(
                        "accessor {} ({name}): {} elements of {} components, expected {n} of at least {min_dims}",
                        acc.index(),
                        v.count,
                        v.dims
                    ),
                ));
            }
            Ok(Some(v))
        };
        let normals = attr(Semantic::Normals, "NORMAL", 3)?;
        let uvs = attr(Semantic::TexCoords(0), "TEXCOORD_0", 2)?;
        let colors = attr(Semantic::Colors(0), "COLOR_0", 3)?;

        let normal_matrix = {
            let m3 = DMat3::from_mat4(*world);
            let det = m3.determinant();
            (det.is_finite() && det != 0.0).then(|| m3.inverse().transpose())
        };
        let flip = DMat3::from_mat4(*world).determinant() < 0.0;
        let mut vertices = Vec::with_capacity(n);
        for i in 0..n {
            let p = positions.get(i);
            let wp = world.transform_point3(DVec3::new(p[0], p[1], p[2]));
            let normal = match (&normals, normal_matrix) {
                (Some(nv), Some(nm)) => {
                    let q = nv.get(i);
                    (nm * DVec3::new(q[0], q[1], q[2])).as_vec3().to_array()
                }
                _ => [0.0; 3],
            };
            let uv = uvs
                .as_ref()
                .map(|u| {
                    let q = u.get(i);
                    [q[0] as f32, q[1] as f32]
                })
                .unwrap_or([0.0; 2]);
            let color = colors
                .as_ref()
                .map(|c| {
                    let q = c.get(i);
                    let alpha = if c.dims >= 4 { q[3] } else { 1.0 };
                    [q[0], q[1], q[2], alpha].map(unit_to_u8)
                })
                .unwrap_or([255; 4]);
            vertices.push(Vertex::new(
                options.up.to_y_up(wp.as_vec3().to_array()),
                options.up.to_y_up(normal),
                uv,
                color,
            ));
        }

        let list: Vec<u32> = match prim.indices() {
            Some(acc) => {
                let v = read_accessor(&acc, self.buffers, false)
                    .map_err(|e| self.err(format!("accessor {} (indices): {e}", acc.index())))?;
                if v.dims != 1
                    || !matches!(
                        acc.data_type(),
                        DataType::U8 | DataType::U16 | DataType::U32
                    )
                {
                    return Err(self.err(format!(
                        "accessor {} (indices): must be an unsigned integer SCALAR",
                        acc.index()
                    )));
                }
                // Integer components are exact in f64; out-of-range ones are counted by the builder.
                v.data.iter().map(|&x| x as u32).collect()
            }
            None => (0..n as u32).collect(),
        };
        let mut indices = Vec::with_capacity(list.len().saturating_mul(3));
        match mode {
            Mode::Triangles => indices.extend_from_slice(&list[..list.len() / 3 * 3]),
            Mode::TriangleStrip => {
                for i in 0..list.len().saturating_sub(2) {
                    let t = if i % 2 == 0 {
                        [list[i], list[i + 1], list[i + 2]]
                    } else {
                        [list[i + 1], list[i], list[i + 2]]
                    };
                    indices.extend_from_slice(&t);
                }
            }
            _ => {
                for i in 1..list.len().saturating_sub(1) {
                    indices.extend_from_slice(&[list[0], list[i], list[i + 1]]);
                }
            }
        }
        if flip {
            for t in indices.chunks_exact_mut(3) {
                t.swap(1, 2);
            }
        }
        let material = self.material(prim.material(), builder, report);
        builder.add_mesh(Mesh {
            material,
            vertices,
            indices,
        });
        Ok(())
    }

    fn material(
        &mut self,
        m: gltf::Material,
        builder: &mut SceneBuilder,
        report: &mut ImportReport,
    ) -> u32 {
        if let Some(&id) = self.materials.get(&m.index()) {
            return id;
        }
        let pbr = m.pbr_metallic_roughness();
        let texture = pbr
            .base_color_texture()
            .and_then(|info| self.texture(info.texture().index(), builder, report));
        let name = match (m.index(), m.name()) {
            (_, Some(n)) => n.to_string(),
            (Some(i), None) => format!("material {i}"),
            (None, None) => "glTF default".to_string(),
        };
        let id = builder.add_material(Material {
            name,
            base_color: pbr.base_color_factor(),
            texture,
        });
        self.materials.insert(m.index(), id);
        id
    }

    /// Decodes the image of texture `tex` once; warns and returns `None` on failure.
    fn texture(
        &mut self,
        tex: usize,
        builder: &mut SceneBuilder,
        report: &mut ImportReport,
    ) -> Option<u32> {
        let json = self.doc.as_json();
        let image = json.textures.get(tex)?.source.value();
        if let Some(&t) = self.textures.get(&image) {
            return t;
        }
        let result = self.image_bytes(image).and_then(|bytes| {
            decode_texture(format!("{} image {image}", self.path.display()), &bytes)
                .map_err(|e| e.to_string())
        });
        let id = match result {
            Ok(t) => Some(builder.add_texture(t)),
            Err(e) => {
                report.missing_textures += 1;
                report.warn(self.path, format!("image {image}: {e}"));
                None
            }
        };
        self.textures.insert(image, id);
        id
    }

    fn image_bytes(&self, image: usize) -> Result<Vec<u8>, String> {
        let json = self.doc.as_json();
        let img = json.images.get(image).ok_or("no such image")?;
        if let Some(view) = &img.buffer_view {
            let view = self
                .doc
                .views()
                .nth(view.value())
                .ok_or("no such buffer view")?;
            let buf = self
                .buffers
                .get(view.buffer().index())
                .ok_or("no such buffer")?;
            let end = view.offset().checked_add(view.length()).ok_or("bad view")?;
            buf.get(view.offset()..end)
                .map(<[u8]>::to_vec)
                .ok_or_else(|| "buffer view out of range".to_string())
        } else if let Some(uri) = &img.uri {
            read_uri(self.dir, uri)
        } else {
            Err("image has neither uri nor bufferView".into())
        }
    }
}

/// Maps a linear colour component in 0..=1 to 0..=255.
fn unit_to_u8(x: f64) -> u8 {
    if x.is_nan() {
        0
    } else {
        (x * 255.0).round().clamp(0.0, 255.0) as u8
    }
}

/// Accessor contents as `f64`, `dims` components per element.
struct Values {
    data: Vec<f64>,
    dims: usize,
    count: usize,
}

impl Values {
    /// Element `i`, padded with zeros to four components.
    fn get(&self, i: usize) -> [f64; 4] {
        let mut out = [0.0; 4];
        let s = &self.data[i * self.dims..(i + 1) * self.dims];
        out[..self.dims.min(4)].copy_from_slice(&s[..self.dims.min(4)]);
        out
    }
}

fn component_size(t: DataType) -> usize {
    match t {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

fn read_component(t: DataType, b: &[u8]) -> f64 {
    match t {
        DataType::I8 => b[0] as i8 as f64,
        DataType::U8 => b[0] as f64,
        DataType::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
        DataType::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
        DataType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        DataType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
    }
}

/// Integer to 0..1 (or −1..1) as glTF's normalized accessors define (spec 3.11, "Animations"
/// equations for normalized integers).
fn normalize(t: DataType, v: f64) -> f64 {
    match t {
        DataType::I8 => (v / 127.0).max(-1.0),
        DataType::U8 => v / 255.0,
        DataType::I16 => (v / 32767.0).max(-1.0),
        DataType::U16 => v / 65535.0,
        DataType::U32 | DataType::F32 => v,
    }
}

/// Reads `count × dims` components from `buf[start..]` (`buf` ending where the buffer view ends)
/// with `stride` bytes between elements, checking every range.
fn read_strided(
    buf: &[u8],
    start: usize,
    stride: usize,
    count: usize,
    t: DataType,
    dims: usize,
    out: &mut Vec<f64>,
) -> Result<(), String> {
    let cs = component_size(t);
    let elem = cs * dims;
    if count == 0 {
        return Ok(());
    }
    let end = stride
        .checked_mul(count - 1)
        .and_then(|x| x.checked_add(elem))
        .and_then(|x| x.checked_add(start))
        .ok_or("accessor range overflows")?;
    if end > buf.len() {
        return Err(format!(
            "accessor reads bytes up to {end}, past the end of its buffer view or buffer"
        ));
    }
    out.reserve(count * dims);
    for i in 0..count {
        let base = start + i * stride;
        for j in 0..dims {
            let o = base + j * cs;
            out.push(read_component(t, &buf[o..o + cs]));
        }
    }
    Ok(())
}

fn view_range(
    view: &gltf::buffer::View,
    buffers: &[Vec<u8>],
) -> Result<(usize, usize, usize), String> {
    let b = view.buffer().index();
    let len = buffers.get(b).map(Vec::len).ok_or("no such buffer")?;
    let end = view
        .offset()
        .checked_add(view.length())
        .ok_or("buffer view range overflows")?;
    if end > len {
        return Err(format!("buffer view {} ends past its buffer", view.index()));
    }
    Ok((b, view.offset(), end))
}

/// The most components a sparse accessor without a buffer view may have (16 Mi, 128 MiB as
/// `f64`): its elements are zeros that no byte of the file backs, so its `count` is the only thing
/// sizing them, and a few bytes of JSON must not ask for gigabytes.
const MAX_VIEWLESS_COMPONENTS: usize = 1 << 24;

/// Reads an accessor (dense and sparse parts) into `f64`s; with `normalize_ints`, integer
/// components are mapped to 0..1 / −1..1 (as `TEXCOORD_n` and `COLOR_n` require), otherwise only
/// when the accessor says `normalized`.
fn read_accessor(
    acc: &gltf::Accessor,
    buffers: &[Vec<u8>],
    normalize_ints: bool,
) -> Result<Values, String> {
    let t = acc.data_type();
    let dims = match acc.dimensions() {
        Dimensions::Scalar => 1,
        Dimensions::Vec2 => 2,
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        d => return Err(format!("unexpected accessor type {d:?}")),
    };
    let count = acc.count();
    let elem = component_size(t) * dims;
    let mut data = Vec::new();
    match acc.view() {
        Some(view) => {
            let (b, vstart, vend) = view_range(&view, buffers)?;
            let stride = view.stride().unwrap_or(elem);
            if stride < elem {
                return Err(format!(
                    "byte stride {stride} is smaller than an element ({elem})"
                ));
            }
            let start = vstart.checked_add(acc.offset()).ok_or("offset overflows")?;
            read_strided(
                &buffers[b][..vend],
                start,
                stride,
                count,
                t,
                dims,
                &mut data,
            )?;
        }
        None => {
            if acc.sparse().is_none() {
                return Err("accessor has no buffer view".into());
            }
            // Zeros that no byte of the file backs: `count` alone would size the allocation.
            let total = count
                .checked_mul(dims)
                .filter(|&t| t <= MAX_VIEWLESS_COMPONENTS)
                .ok_or_else(|| {
                    format!(
                        "sparse accessor without a buffer view has {count} elements; lemi reads \
                         at most {MAX_VIEWLESS_COMPONENTS} components without one"
                    )
                })?;
            data = vec![0.0; total];
        }
    }
    if let Some(sparse) = acc.sparse() {
        let n = sparse.count();
        let iv = sparse.indices();
        let it = match iv.index_type() {
            gltf::accessor::sparse::IndexType::U8 => DataType::U8,
            gltf::accessor::sparse::IndexType::U16 => DataType::U16,
            gltf::accessor::sparse::IndexType::U32 => DataType::U32,
        };
        let (b, vstart, vend) = view_range(&iv.view(), buffers)?;
        let start = vstart.checked_add(iv.offset()).ok_or("offset overflows")?;
        let mut idx = Vec::new();
        read_strided(
            &buffers[b][..vend],
            start,
            component_size(it),
            n,
            it,
            1,
            &mut idx,
        )?;
        let vv = sparse.values();
        let (b, vstart, vend) = view_range(&vv.view(), buffers)?;
        let start = vstart.checked_add(vv.offset()).ok_or("offset overflows")?;
        let mut vals = Vec::new();
        read_strided(&buffers[b][..vend], start, elem, n, t, dims, &mut vals)?;
        for (k, &i) in idx.iter().enumerate() {
            let i = i as usize;
            if i >= count {
                return Err(format!(
                    "sparse index {i} is past the accessor's {count} elements"
                ));
            }
            data[i * dims..(i + 1) * dims].copy_from_slice(&vals[k * dims..(k + 1) * dims]);
        }
    }
    if t != DataType::F32 && (acc.normalized() || normalize_ints) {
        for v in &mut data {
            *v = normalize(t, *v);
        }
    }
    Ok(Values { data, dims, count })
}
