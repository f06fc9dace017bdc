//! One view cell as a binary glTF 2.0 file: the impostor quads, grouped per macro-texture, and
//! optionally the cell's near geometry with its materials.
//!
//! This work is based on the runtime of GI 2002 (Jeschke, Wimmer et al., *Layered
//! Environment-Map Impostors for Arbitrary Scenes*, sec. 3): the far field of a view cell is a set
//! of textured quads, alpha-tested and depth-tested against each other and the near geometry, so
//! any renderer with an alpha test draws it without sorting. In glTF 2.0 terms:
//!
//! - **Quads**: node `impostors`, mesh `impostors`, one triangle primitive per macro-texture and
//!   kind (opaque, alpha-tested; in `header.macros` order), each quad four vertices and two
//!   triangles `0 1 2, 0 2 3`. The vertices are the ones lemi's runtime draws
//!   ([`Quad::drawn_vertices`]: the corners in the order of [`Quad::corners`] and the
//!   macro-texel corners, both grown by `QUAD_GROWTH_TEXELS` so that neighbouring quads overlap
//!   in any renderer). Positions are relative to the node's translation ([`lemi_core::bundle::CellHeader::quad_origin`]); with
//!   [`ExportGeometry::Meshopt`] they go through the `EXPONENTIAL` filter on a power-of-two grid
//!   per quad, within [`POSITION_TOLERANCE_TEXELS`] of its layer's texels, else f32. Within a
//!   primitive the quads are in the runtime's draw order:
//!   by cube face, then the nearest layer first (a quad's `layer` counts far to near), ties in the
//!   cell's order, so depth rejection skips what nearer layers hide. `TEXCOORD_0` holds the grown
//!   texel coordinates `t` (multiples of 1/16): with [`ExportGeometry::Meshopt`] as u16
//!   `16·t + 1` (`KHR_mesh_quantization`) that the material's `KHR_texture_transform` maps to
//!   `t / side`, exactly; with [`ExportGeometry::Plain`] (or a macro-texture side above
//!   [`MAX_QUANTIZED_SIDE`]) as f32 `t / side`. A reader rounds `t` to get the quad's texel
//!   rectangle back.
//! - **Fringe quads** (a BC1 or ETC1S bundle baked with `--outline-fringe`,
//!   [`lemi_core::bundle::CellHeader::fringe_quads`]): primitives of their own, after the other
//!   primitives of their macro-texture, with `extras` `{"lemi_fringe": true}`. Their texels are
//!   the outline fringe, which lemi's runtime draws only where something lies behind them (or in
//!   a gap of up to two pixels); a renderer that draws them as ordinary quads shows the
//!   silhouettes a texel wider, as a bake without the fringe does, and one that skips them may
//!   show background between outlines (docs/COMPRESSION.md, "1c. Outline fringe").
//! - **Geometry**: with [`ExportGeometry::Meshopt`] every vertex and index view is compressed
//!   with `EXT_meshopt_compression` (see `document.rs`), losslessly but for the quads' filtered
//!   positions.
//! - **Materials**: `KHR_materials_unlit` (the layers are pre-shaded, final sRGB colours),
//!   `alphaMode: MASK` with `alphaCutoff` [`QUAD_ALPHA_CUTOFF`] (the runtime's alpha test), or
//!   `OPAQUE` for the quads whose texels all pass it ([`opaque_quads`]: as the runtime's opaque
//!   pipeline, so a renderer can test depth before shading; a separate primitive per kind),
//!   double-sided, base colour factor 1, metallic 0, roughness 1 (what an unlit-unaware reader
//!   falls back to), the macro-texture as base colour texture through a nearest-texel,
//!   clamp-to-edge sampler (the runtime fetches texels, it never filters).
//! - **Textures**: the bundle's PNG files as they are (no re-encoding, so the texels and the bytes
//!   are the bake's), or for a block-compressed bundle the texels decoded and stored as PNG; or
//!   (`ExportTextures::Ktx2`) the bundle's KTX2 files through `KHR_texture_basisu`, see
//!   `docs/EXPORT.md` for what that means for BC7/BC1.
//! - **Near geometry** (optional, it needs the scene): node `near`, one primitive per source mesh
//!   of the near list ([`Scene::extract`], as the runtime draws it) with `POSITION`, `NORMAL`,
//!   `TEXCOORD_0` (when its material has a texture), `COLOR_0` (when a vertex colour is not white)
//!   and the material: base colour factor and texture, metallic 0, roughness 1, double-sided.
//! - **`extras`** of the scene: the cell (id, grid index, box, reference viewpoint), α, the
//!   faces and their layers (distances and borders), resolution, near field, quad and triangle
//!   counts, the bundle's parameters hash and scene fingerprint.

use glam::DVec3;
use gltf::json;
use json::validation::Checked::Valid;
use lemi_core::bundle::{CellFile, LayerInfo, Quad, QUAD_ALPHA_CUTOFF};
use lemi_core::classify::TriRef;
use lemi_core::compress::TextureFormat;
use lemi_core::Scene;
use serde_json::json;

use crate::document::{extras, Document, GeometryBytes};
use crate::{ExportError, ExportGeometry, ExportTextures};

/// How far an exported quad vertex may lie from the one lemi's runtime draws, in texels of the
/// quad's layer: a quarter of the growth (`QUAD_GROWTH_TEXELS`, 1/16 texel) by which the runtime
/// makes neighbouring quads overlap, so that they still overlap by 3/32 texel (and every vertex
/// stays within 1/64 texel, about 1/64 output pixel at the resolution the layers are made for).
pub const POSITION_TOLERANCE_TEXELS: f64 = lemi_core::bundle::QUAD_GROWTH_TEXELS / 4.0;

/// The name of the extension for unlit materials.
pub const UNLIT: &str = "KHR_materials_unlit";
/// The name of the extension for KTX2 textures.
pub const BASISU: &str = "KHR_texture_basisu";
/// The name of the extension that maps the quads' integer texture coordinates.
pub const TEXTURE_TRANSFORM: &str = "KHR_texture_transform";
/// The largest macro-texture side whose quads get integer texture coordinates: `16·side + 2`
/// must fit a u16 (coordinates in 1/16 texel, shifted by one so that the grown rim at −1/16 is
/// not negative). Larger macro-textures keep f32 coordinates.
pub const MAX_QUANTIZED_SIDE: u32 = (u16::MAX as u32 - 2) / 16;

/// One exported cell and the numbers that describe it.
#[derive(Clone, Debug, PartialEq)]
pub struct CellGlb {
    /// The `.glb` file.
    pub bytes: Vec<u8>,
    pub quads: usize,
    pub macro_textures: usize,
    /// Bytes of the embedded macro-texture images.
    pub texture_bytes: u64,
    /// Near triangles written (0 without the scene).
    pub near_triangles: u64,
    /// Bytes of the near geometry (vertices, indices and material images).
    pub near_bytes: u64,
    /// Bytes of the quads' vertex and index data, as stored and as decoded.
    pub quad_bytes: GeometryBytes,
    /// Primitives of the quads (one per macro-texture and kind): a renderer's draw calls.
    pub quad_primitives: usize,
}

/// Whether each quad's texels (its rectangle of its macro-texture) all pass the alpha test, so
/// it can be drawn without it (`alphaMode: OPAQUE`): as the runtime's opaque pipeline, this lets
/// a renderer test depth before shading.
pub fn opaque_quads(file: &CellFile) -> Result<Vec<bool>, ExportError> {
    let macros = file
        .decode_macros()
        .map_err(|e| ExportError::Gltf(format!("decoding the macro-textures: {e}")))?;
    // the smallest alpha byte the test keeps: a / 255 ≥ cutoff
    let keep = (0..=255u8)
        .find(|&a| a as f32 / 255.0 >= QUAD_ALPHA_CUTOFF)
        .unwrap_or(255);
    Ok(file
        .header
        .quads
        .iter()
        .map(|q| {
            let Some(m) = macros.get(q.macro_index as usize) else {
                return false;
            };
            let [x, y, w, h] = q.rect.map(|v| v as usize);
            let stride = 4 * m.width as usize;
            (y..y + h).all(|row| {
                let start = row * stride + 4 * x;
                m.rgba
                    .get(start..start + 4 * w)
                    .is_some_and(|px| px.chunks_exact(4).all(|t| t[3] >= keep))
            })
        })
        .collect())
}

/// The order the quads are written in: one primitive per macro-texture and kind (opaque quads
/// before alpha-tested ones, fringe quads last), within it by face, then the nearest layer first (a quad's `layer`
/// counts far to near), ties in the cell's order: the runtime's order within a draw call
/// (`lemi_gpu::impostor`), so depth rejection skips what nearer layers hide.
pub fn quad_order(quads: &[Quad], opaque: &[bool]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..quads.len()).collect();
    order.sort_by_key(|&k| {
        (
            quads[k].macro_index,
            quads[k].fringe,
            !opaque.get(k).copied().unwrap_or(false),
            quads[k].face,
            std::cmp::Reverse(quads[k].layer),
        )
    });
    order
}

/// A face's layers far to near as three arrays (`distance`, `near_border`, `far_border`, `null`
/// for ∞), at f32 precision (a distance to 1e-7 of itself, where a layer texel is 2/Res of it):
/// 7.5 KB for 4 × 64 layers, against 26 KB as one object per layer with all of f64's digits.
fn layer_table(face: &[LayerInfo]) -> serde_json::Value {
    let column = |f: &dyn Fn(&LayerInfo) -> f64| {
        face.iter()
            .map(|l| {
                // the shortest decimal that reads back as the f32 (serde_json writes an
                // f32 widened to f64 with all of the f64's digits)
                let v = f(l);
                (v < f64::MAX).then(|| (v as f32).to_string().parse::<f64>().unwrap_or(v))
            })
            .collect::<Vec<_>>()
    };
    json!({
        "distance": column(&|l| l.distance),
        "near_border": column(&|l| l.near_border),
        "far_border": column(&|l| l.far_border),
    })
}

/// How a cell is exported.
#[derive(Clone, Copy, Debug)]
pub struct CellOptions<'a> {
    pub textures: ExportTextures,
    pub geometry: ExportGeometry,
    /// The bundle's α (radians), recorded in the cell's `extras`.
    pub alpha: f64,
    /// `asset.generator`, e.g. `lemi 0.1.0`.
    pub generator: &'a str,
}

/// Exports one verified cell file. `scene` (the scene the bundle was baked from, checked by the
/// caller) adds the near geometry.
pub fn export_cell(
    file: &CellFile,
    scene: Option<&Scene>,
    options: &CellOptions,
) -> Result<CellGlb, ExportError> {
    let CellOptions {
        textures,
        geometry,
        alpha,
        generator,
    } = *options;
    let header = &file.header;
    if header.hlod.is_some() {
        return Err(ExportError::Unsupported(
            "an HLOD bundle has no impostor layers to export (bake with --strategy lemi)".into(),
        ));
    }
    let mut doc = Document::new(generator, geometry);
    doc.use_extension(UNLIT, false);
    let sampler = doc.root.push(json::texture::Sampler {
        mag_filter: Some(Valid(json::texture::MagFilter::Nearest)),
        min_filter: Some(Valid(json::texture::MinFilter::Nearest)),
        name: Some("texels".into()),
        wrap_s: Valid(json::texture::WrappingMode::ClampToEdge),
        wrap_t: Valid(json::texture::WrappingMode::ClampToEdge),
        extensions: None,
        extras: Default::default(),
    });

    // macro-textures: images, textures, materials
    let images = macro_images(file, textures)?;
    let mut texture_bytes = 0u64;
    let mut materials = Vec::with_capacity(images.len());
    for (i, (bytes, mime)) in images.iter().enumerate() {
        texture_bytes += bytes.len() as u64;
        let image = doc.image(bytes, mime, format!("macro{i}"));
        let texture = match textures {
            ExportTextures::Png => json::Texture {
                name: Some(format!("macro{i}")),
                sampler: Some(sampler),
                source: image,
                extensions: None,
                extras: Default::default(),
            },
            ExportTextures::Ktx2 => {
                doc.use_extension(BASISU, true);
                let mut ext = json::extensions::texture::Texture::default();
                ext.others
                    .insert(BASISU.into(), json!({ "source": image.value() }));
                json::Texture {
                    name: Some(format!("macro{i}")),
                    sampler: Some(sampler),
                    // no core source: the KTX2 image is reachable only through the required
                    // extension (gltf-json leaves out a source of u32::MAX)
                    source: json::Index::new(u32::MAX),
                    extensions: Some(ext),
                    extras: Default::default(),
                }
            }
        };
        let texture = doc.root.push(texture);
        let transform = header
            .macros
            .get(i)
            .and_then(|m| quantized_texcoords(geometry, m.width, m.height));
        if transform.is_some() {
            doc.use_extension(TEXTURE_TRANSFORM, true);
        }
        materials.push([
            doc.root.push(quad_material(texture, i, true, transform)),
            doc.root.push(quad_material(texture, i, false, transform)),
        ]);
    }

    // quads: one primitive per macro-texture, in the runtime's order, relative to the node's
    // origin (the reference viewpoint, in f32 as the node's translation holds it)
    let quads = &header.quads;
    let origin = header.quad_origin().as_vec3().as_dvec3();
    let opaque = opaque_quads(file)?;
    let order = quad_order(quads, &opaque);
    let mut primitives = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let m = quads[order[start]].macro_index;
        let kind = opaque[order[start]];
        let fringe = quads[order[start]].fringe;
        let end = start
            + order[start..]
                .iter()
                .take_while(|&&k| {
                    quads[k].macro_index == m && opaque[k] == kind && quads[k].fringe == fringe
                })
                .count();
        let info = header.macros.get(m as usize).ok_or_else(|| {
            ExportError::Gltf(format!("a quad uses macro-texture {m}, the cell has fewer"))
        })?;
        let quantized = quantized_texcoords(geometry, info.width, info.height).is_some();
        let (w, h) = (info.width as f32, info.height as f32);
        let n = end - start;
        let mut positions = Vec::with_capacity(4 * n);
        let mut tolerance = Vec::with_capacity(4 * n);
        let mut uvs = Vec::with_capacity(4 * n);
        let mut indices = Vec::with_capacity(6 * n);
        for &k in &order[start..end] {
            let base = positions.len() as u32;
            let t = POSITION_TOLERANCE_TEXELS * quads[k].texel_size();
            for (p, uv) in quads[k].drawn_vertices() {
                positions.push(
                    (DVec3::from_array(p.map(f64::from)) - origin)
                        .as_vec3()
                        .to_array(),
                );
                tolerance.push(t);
                uvs.push(uv);
            }
            indices.extend([0, 1, 2, 0, 2, 3].map(|i| base + i));
        }
        let position = doc.positions_within(&positions, &tolerance)?;
        let uv = if quantized {
            // multiples of 1/16 texel from −1/16 to side + 1/16: exact as 16·t + 1
            let texels: Vec<[u16; 2]> = uvs
                .iter()
                .map(|t| t.map(|c| (16.0 * c + 1.0).round().clamp(0.0, u16::MAX as f32) as u16))
                .collect();
            doc.texcoords_u16(&texels)?
        } else {
            let normalised: Vec<[f32; 2]> = uvs.iter().map(|t| [t[0] / w, t[1] / h]).collect();
            doc.texcoords(&normalised)?
        };
        let index = doc.indices(&indices, positions.len())?;
        let material = materials
            .get(m as usize)
            .map(|pair| pair[usize::from(!kind)]);
        let mut quads_primitive = primitive(
            [
                (json::mesh::Semantic::Positions, position),
                (json::mesh::Semantic::TexCoords(0), uv),
            ],
            index,
            material,
        );
        if fringe {
            quads_primitive.extras = extras(&json!({ "lemi_fringe": true }))?;
        }
        primitives.push(quads_primitive);
        start = end;
    }
    let quad_bytes = doc.geometry_bytes;
    let quad_primitives = primitives.len();
    let mut nodes = Vec::new();
    if !primitives.is_empty() {
        let mesh = doc.root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some("impostors".into()),
            primitives,
            weights: None,
        });
        let mut impostors = node("impostors", mesh);
        impostors.translation = Some(origin.as_vec3().to_array());
        nodes.push(doc.root.push(impostors));
    }

    // near geometry
    let bin_before_near = doc.bin.len();
    let mut near_triangles = 0;
    if let Some(scene) = scene {
        let refs: Vec<TriRef> = file.near.iter().map(|&p| TriRef::from(p)).collect();
        let meshes = scene.extract(&refs).map_err(|e| {
            ExportError::Near(format!(
                "the near list does not fit the scene ({e}); export with the scene the bundle was baked from"
            ))
        })?;
        let mut near_materials = std::collections::HashMap::new();
        let mut near_primitives = Vec::new();
        for mesh in &meshes {
            if mesh.indices.is_empty() {
                continue;
            }
            near_triangles += mesh.triangle_count() as u64;
            let material = match near_materials.get(&mesh.material) {
                Some(&m) => m,
                None => {
                    let m = near_material(&mut doc, scene, mesh.material)?;
                    near_materials.insert(mesh.material, m);
                    m
                }
            };
            let textured = scene
                .materials
                .get(mesh.material as usize)
                .is_some_and(|m| m.texture.is_some());
            let p: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| v.position).collect();
            let n: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| v.normal).collect();
            let mut attributes = vec![
                (json::mesh::Semantic::Positions, doc.positions(&p)?),
                (json::mesh::Semantic::Normals, doc.normals(&n)?),
            ];
            if textured {
                let uv: Vec<[f32; 2]> = mesh.vertices.iter().map(|v| v.uv).collect();
                attributes.push((json::mesh::Semantic::TexCoords(0), doc.texcoords(&uv)?));
            }
            if mesh.vertices.iter().any(|v| v.color != [255; 4]) {
                let c: Vec<[u8; 4]> = mesh.vertices.iter().map(|v| v.color).collect();
                attributes.push((json::mesh::Semantic::Colors(0), doc.colors(&c)?));
            }
            let index = doc.indices(&mesh.indices, mesh.vertices.len())?;
            near_primitives.push(primitive(attributes, index, Some(material)));
        }
        if !near_primitives.is_empty() {
            let mesh = doc.root.push(json::Mesh {
                extensions: None,
                extras: Default::default(),
                name: Some("near".into()),
                primitives: near_primitives,
                weights: None,
            });
            nodes.push(doc.root.push(node("near", mesh)));
        }
    }
    let near_bytes = (doc.bin.len() - bin_before_near) as u64;

    let cell = &header.cell;
    let bounds = cell.bounds();
    let info = json!({
        "lemi": {
            "cell": cell.id().to_string(),
            "index": cell.index.to_array(),
            "box": { "min": bounds.min.to_array(), "max": bounds.max.to_array() },
            "reference_viewpoint": cell.center.to_array(),
            "alpha": alpha,
            "resolution": header.resolution,
            "near_field": header.near_field,
            "faces": header.faces.iter().map(|f| f.name()).collect::<Vec<_>>(),
            "layer_count": header.layers.iter().map(|l| l.len()).collect::<Vec<_>>(),
            "layers": header.layers.iter().map(|face| layer_table(face)).collect::<Vec<_>>(),
            "quads": quads.len(),
            "fringe_quads": header.fringe_quads,
            "macro_textures": header.macros.len(),
            "near_triangles": near_triangles,
            "alpha_cutoff": QUAD_ALPHA_CUTOFF,
            "params_hash": header.params_hash,
            "scene_fingerprint": header.scene_fingerprint,
            "texture_format": header.texture_format.name(),
        }
    });
    let scene_index = doc.root.push(json::Scene {
        extensions: None,
        extras: extras(&info)?,
        name: Some(format!("cell {}", cell.id())),
        nodes,
    });
    doc.root.scene = Some(scene_index);
    let quads_n = quads.len();
    let macro_textures = header.macros.len();
    let bytes = doc.into_glb()?;
    Ok(CellGlb {
        bytes,
        quads: quads_n,
        macro_textures,
        texture_bytes,
        near_triangles,
        near_bytes,
        quad_bytes,
        quad_primitives,
    })
}

/// The `KHR_texture_transform` (scale, offset) that maps a macro-texture's integer texture
/// coordinates `16·t + 1` (t in texels) to `t / side`, or `None` when its quads keep f32
/// coordinates (plain geometry, or a side above [`MAX_QUANTIZED_SIDE`]).
fn quantized_texcoords(geometry: ExportGeometry, width: u32, height: u32) -> Option<[[f64; 2]; 2]> {
    (geometry.compressed() && width <= MAX_QUANTIZED_SIDE && height <= MAX_QUANTIZED_SIDE).then(
        || {
            let (sx, sy) = (1.0 / (16.0 * width as f64), 1.0 / (16.0 * height as f64));
            [[sx, sy], [-sx, -sy]]
        },
    )
}

/// The macro-textures as image bytes and MIME type, in `header.macros` order.
fn macro_images(
    file: &CellFile,
    textures: ExportTextures,
) -> Result<Vec<(Vec<u8>, &'static str)>, ExportError> {
    let format = file.header.texture_format;
    match (textures, format) {
        (ExportTextures::Png, TextureFormat::Png) => Ok(file
            .macro_blobs
            .iter()
            .map(|b| (b.clone(), "image/png"))
            .collect()),
        (ExportTextures::Png, _) => {
            let decoded = file
                .decode_macros()
                .map_err(|e| ExportError::Gltf(format!("decoding the macro-textures: {e}")))?;
            decoded
                .into_iter()
                .map(|m| Ok((encode_png(m.width, m.height, &m.rgba)?, "image/png")))
                .collect()
        }
        (ExportTextures::Ktx2, f) if f.block().is_some() => Ok(file
            .macro_blobs
            .iter()
            .map(|b| (b.clone(), "image/ktx2"))
            .collect()),
        (ExportTextures::Ktx2, _) => Err(ExportError::Unsupported(
            "--textures ktx2 needs a bundle baked with --texture-format bc7, bc1, uastc or etc1s (this one stores PNG)".into(),
        )),
    }
}

/// RGBA8 as PNG (the image crate's encoder).
pub(crate) fn encode_png(width: u32, height: u32, rgba: &[u8]) -> Result<Vec<u8>, ExportError> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Best,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(rgba, width, height, image::ExtendedColorType::Rgba8)
    .map_err(|e| ExportError::Gltf(format!("encoding a {width}x{height} PNG: {e}")))?;
    Ok(out)
}

/// The material of macro-texture `i`'s quads: alpha-tested (`MASK`), or `opaque` for quads whose
/// texels all pass the test.
fn quad_material(
    texture: json::Index<json::Texture>,
    i: usize,
    opaque: bool,
    transform: Option<[[f64; 2]; 2]>,
) -> json::Material {
    let extensions = transform.map(|[scale, offset]| {
        let mut ext = json::extensions::texture::Info::default();
        ext.others.insert(
            TEXTURE_TRANSFORM.into(),
            json!({ "offset": offset, "scale": scale }),
        );
        ext
    });
    json::Material {
        alpha_cutoff: (!opaque).then_some(json::material::AlphaCutoff(QUAD_ALPHA_CUTOFF)),
        alpha_mode: Valid(if opaque {
            json::material::AlphaMode::Opaque
        } else {
            json::material::AlphaMode::Mask
        }),
        double_sided: true,
        name: Some(if opaque {
            format!("macro{i}-opaque")
        } else {
            format!("macro{i}")
        }),
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_factor: json::material::PbrBaseColorFactor([1.0; 4]),
            base_color_texture: Some(json::texture::Info {
                index: texture,
                tex_coord: 0,
                extensions,
                extras: Default::default(),
            }),
            metallic_factor: json::material::StrengthFactor(0.0),
            roughness_factor: json::material::StrengthFactor(1.0),
            metallic_roughness_texture: None,
            extensions: None,
            extras: Default::default(),
        },
        extensions: Some(json::extensions::material::Material {
            unlit: Some(json::extensions::material::Unlit {}),
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// The material of a near mesh: base colour factor and texture (PNG), metallic 0, roughness 1.
fn near_material(
    doc: &mut Document,
    scene: &Scene,
    index: u32,
) -> Result<json::Index<json::Material>, ExportError> {
    let default = lemi_core::Material::default();
    let m = scene.materials.get(index as usize).unwrap_or(&default);
    let texture = match m.texture.and_then(|t| scene.textures.get(t as usize)) {
        Some(t) => {
            let png = encode_png(t.width, t.height, &t.rgba8)?;
            let image = doc.image(&png, "image/png", t.name.clone());
            // scene textures repeat and are filtered (the reference renderer's sampler)
            let repeat = doc.root.push(json::texture::Sampler {
                mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
                min_filter: Some(Valid(json::texture::MinFilter::LinearMipmapLinear)),
                name: None,
                wrap_s: Valid(json::texture::WrappingMode::Repeat),
                wrap_t: Valid(json::texture::WrappingMode::Repeat),
                extensions: None,
                extras: Default::default(),
            });
            Some(doc.root.push(json::Texture {
                name: Some(t.name.clone()),
                sampler: Some(repeat),
                source: image,
                extensions: None,
                extras: Default::default(),
            }))
        }
        None => None,
    };
    Ok(doc.root.push(json::Material {
        alpha_mode: Valid(json::material::AlphaMode::Opaque),
        double_sided: true,
        name: Some(m.name.clone()),
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_factor: json::material::PbrBaseColorFactor(
                m.base_color.map(|c| c.clamp(0.0, 1.0)),
            ),
            base_color_texture: texture.map(|index| json::texture::Info {
                index,
                tex_coord: 0,
                extensions: None,
                extras: Default::default(),
            }),
            metallic_factor: json::material::StrengthFactor(0.0),
            roughness_factor: json::material::StrengthFactor(1.0),
            metallic_roughness_texture: None,
            extensions: None,
            extras: Default::default(),
        },
        ..Default::default()
    }))
}

fn primitive(
    attributes: impl IntoIterator<Item = (json::mesh::Semantic, json::Index<json::Accessor>)>,
    indices: json::Index<json::Accessor>,
    material: Option<json::Index<json::Material>>,
) -> json::mesh::Primitive {
    json::mesh::Primitive {
        attributes: attributes.into_iter().map(|(s, a)| (Valid(s), a)).collect(),
        extensions: None,
        extras: Default::default(),
        indices: Some(indices),
        material,
        mode: Valid(json::mesh::Mode::Triangles),
        targets: None,
    }
}

fn node(name: &str, mesh: json::Index<json::Mesh>) -> json::Node {
    json::Node {
        mesh: Some(mesh),
        name: Some(name.into()),
        ..Default::default()
    }
}
