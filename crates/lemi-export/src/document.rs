//! A glTF 2.0 document under construction with its one binary buffer: appends buffer views (each
//! 4-byte aligned), accessors with the bounds the specification requires, images, textures and
//! materials, and frames the result as a GLB (`gltf::binary::Glb`). The document model is
//! gltf-json's (`gltf::json`), so every object is written by the library, not by hand.
//!
//! With [`ExportGeometry::Meshopt`] every vertex and index buffer view is stored compressed
//! through `EXT_meshopt_compression` (A. Kapoulkine's vertex and index codecs, meshoptimizer's
//! `meshopt_encodeVertexBuffer` / `meshopt_encodeIndexBuffer` through the `meshopt` crate):
//! lossless, so the decoded bytes are the ones [`ExportGeometry::Plain`] stores as they are. The
//! compressed bytes live in the GLB's binary chunk (buffer 0); the views themselves point into a
//! second buffer without data that the extension marks as its fallback (the extension's
//! "Fallback buffers"), so the extension is required to read the file.

use std::borrow::Cow;

use gltf::json;
use json::validation::Checked::Valid;
use json::validation::USize64;

use crate::{ExportError, ExportGeometry};

/// The name of the extension for compressed vertex and index data.
pub const MESHOPT: &str = "EXT_meshopt_compression";
/// The name of the extension for integer vertex attributes.
pub const QUANTIZATION: &str = "KHR_mesh_quantization";

/// A document and its binary chunk.
pub(crate) struct Document {
    pub(crate) root: json::Root,
    pub(crate) bin: Vec<u8>,
    pub(crate) geometry: ExportGeometry,
    /// Bytes of the compressed views once decoded: the length of the fallback buffer (buffer 1).
    fallback_len: usize,
    /// Bytes of vertex and index data as stored (compressed or not), and decoded.
    pub(crate) geometry_bytes: GeometryBytes,
}

/// Bytes of the vertex and index data of a document: as stored in the file, and as a reader
/// holds them once decoded (equal without compression).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GeometryBytes {
    pub stored: u64,
    pub decoded: u64,
}

/// What a buffer view holds (glTF's `target`): vertex attributes, indices, or neither (images).
#[derive(Clone, Copy)]
pub(crate) enum ViewKind {
    Vertices,
    Indices,
    Other,
}

impl Document {
    pub(crate) fn new(generator: &str, geometry: ExportGeometry) -> Document {
        let root = json::Root {
            asset: json::Asset {
                version: "2.0".into(),
                generator: Some(generator.into()),
                ..Default::default()
            },
            ..Default::default()
        };
        Document {
            root,
            bin: Vec::new(),
            geometry,
            fallback_len: 0,
            geometry_bytes: GeometryBytes::default(),
        }
    }

    /// Appends `bytes` to the binary chunk (4-byte aligned) and returns their offset.
    fn append(&mut self, bytes: &[u8]) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        offset
    }

    /// Appends `bytes` to the binary chunk (4-byte aligned) as a new buffer view.
    pub(crate) fn view(&mut self, bytes: &[u8], kind: ViewKind) -> json::Index<json::buffer::View> {
        let offset = self.append(bytes);
        if !matches!(kind, ViewKind::Other) {
            self.geometry_bytes.stored += bytes.len() as u64;
            self.geometry_bytes.decoded += bytes.len() as u64;
        }
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target(kind),
            extensions: None,
            extras: Default::default(),
        })
    }

    /// A buffer view of `count` elements of `stride` bytes (`bytes`), compressed with
    /// meshoptimizer's codec for `kind` (`ATTRIBUTES` for vertices, `TRIANGLES` for triangle
    /// indices) into the binary chunk, decoding into the fallback buffer (see the module docs).
    fn compressed_view(
        &mut self,
        bytes: &[u8],
        count: usize,
        stride: usize,
        kind: ViewKind,
    ) -> Result<json::Index<json::buffer::View>, ExportError> {
        let (encoded, mode) = match kind {
            ViewKind::Vertices => (encode_vertices(bytes, stride)?, "ATTRIBUTES"),
            ViewKind::Indices => (encode_triangles(bytes, stride)?, "TRIANGLES"),
            ViewKind::Other => {
                return Err(ExportError::Gltf(
                    "only vertex and index data are compressed".into(),
                ))
            }
        };
        let offset = self.append(&encoded);
        while self.fallback_len % 4 != 0 {
            self.fallback_len += 1;
        }
        let decoded_at = self.fallback_len;
        self.fallback_len += bytes.len();
        self.geometry_bytes.stored += encoded.len() as u64;
        self.geometry_bytes.decoded += bytes.len() as u64;
        self.use_extension(MESHOPT, true);
        let mut ext = json::extensions::buffer::View::default();
        ext.others.insert(
            MESHOPT.into(),
            serde_json::json!({
                "buffer": 0,
                "byteOffset": offset,
                "byteLength": encoded.len(),
                "byteStride": stride,
                "count": count,
                "mode": mode,
            }),
        );
        Ok(self.root.push(json::buffer::View {
            buffer: json::Index::new(1),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(decoded_at)),
            // glTF: vertex attribute views may give their stride, index views must not
            byte_stride: matches!(kind, ViewKind::Vertices).then_some(json::buffer::Stride(stride)),
            name: None,
            target: target(kind),
            extensions: Some(ext),
            extras: Default::default(),
        }))
    }

    /// A view of vertex or index data: compressed with [`ExportGeometry::Meshopt`], else as is.
    fn data_view(
        &mut self,
        bytes: &[u8],
        count: usize,
        stride: usize,
        kind: ViewKind,
    ) -> Result<json::Index<json::buffer::View>, ExportError> {
        match (self.geometry, kind) {
            (ExportGeometry::Meshopt, ViewKind::Vertices | ViewKind::Indices) => {
                self.compressed_view(bytes, count, stride, kind)
            }
            _ => Ok(self.view(bytes, kind)),
        }
    }

    /// A tightly packed accessor over a new buffer view holding `bytes`.
    #[allow(clippy::too_many_arguments)]
    fn accessor(
        &mut self,
        bytes: &[u8],
        kind: ViewKind,
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        normalized: bool,
        bounds: Option<(Vec<f32>, Vec<f32>)>,
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        let view = match bytes.len().checked_div(count) {
            Some(stride) => self.data_view(bytes, count, stride, kind)?,
            None => self.view(bytes, kind),
        };
        let (min, max) = match bounds {
            Some((lo, hi)) => (Some(json::Value::from(lo)), Some(json::Value::from(hi))),
            None => (None, None),
        };
        Ok(self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            name: None,
            normalized,
            sparse: None,
        }))
    }

    /// `POSITION`: three f32 per vertex, with the bounds glTF requires.
    pub(crate) fn positions(
        &mut self,
        p: &[[f32; 3]],
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for v in p {
            for i in 0..3 {
                lo[i] = lo[i].min(v[i]);
                hi[i] = hi[i].max(v[i]);
            }
        }
        self.accessor(
            bytemuck_f32(p.iter().flatten()).as_slice(),
            ViewKind::Vertices,
            p.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            false,
            Some((lo.to_vec(), hi.to_vec())),
        )
    }

    /// `NORMAL`: three f32 per vertex.
    pub(crate) fn normals(
        &mut self,
        n: &[[f32; 3]],
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        self.accessor(
            bytemuck_f32(n.iter().flatten()).as_slice(),
            ViewKind::Vertices,
            n.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            false,
            None,
        )
    }

    /// `TEXCOORD_n`: two f32 per vertex.
    pub(crate) fn texcoords(
        &mut self,
        uv: &[[f32; 2]],
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        self.accessor(
            bytemuck_f32(uv.iter().flatten()).as_slice(),
            ViewKind::Vertices,
            uv.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec2,
            false,
            None,
        )
    }

    /// `TEXCOORD_n` as two unsigned 16-bit integers per vertex (not normalised), which
    /// `KHR_mesh_quantization` allows (and which makes the extension required); a material maps
    /// them to texture coordinates through `KHR_texture_transform`'s scale.
    pub(crate) fn texcoords_u16(
        &mut self,
        uv: &[[u16; 2]],
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        self.use_extension(QUANTIZATION, true);
        let bytes: Vec<u8> = uv.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(
            &bytes,
            ViewKind::Vertices,
            uv.len(),
            json::accessor::ComponentType::U16,
            json::accessor::Type::Vec2,
            false,
            None,
        )
    }

    /// `COLOR_0`: four normalised unsigned bytes per vertex (linear RGBA).
    pub(crate) fn colors(
        &mut self,
        c: &[[u8; 4]],
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        let bytes: Vec<u8> = c.iter().flatten().copied().collect();
        self.accessor(
            &bytes,
            ViewKind::Vertices,
            c.len(),
            json::accessor::ComponentType::U8,
            json::accessor::Type::Vec4,
            true,
            None,
        )
    }

    /// Triangle indices, as u16 when every index fits below u16's primitive-restart value, else
    /// u32. `vertex_count` is the number of vertices they index.
    pub(crate) fn indices(
        &mut self,
        indices: &[u32],
        vertex_count: usize,
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        if vertex_count <= u16::MAX as usize {
            let bytes: Vec<u8> = indices
                .iter()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect();
            self.accessor(
                &bytes,
                ViewKind::Indices,
                indices.len(),
                json::accessor::ComponentType::U16,
                json::accessor::Type::Scalar,
                false,
                None,
            )
        } else {
            let bytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
            self.accessor(
                &bytes,
                ViewKind::Indices,
                indices.len(),
                json::accessor::ComponentType::U32,
                json::accessor::Type::Scalar,
                false,
                None,
            )
        }
    }

    /// An image stored in the binary chunk (`image/png` or `image/ktx2`).
    pub(crate) fn image(
        &mut self,
        bytes: &[u8],
        mime: &str,
        name: String,
    ) -> json::Index<json::Image> {
        let view = self.view(bytes, ViewKind::Other);
        self.root.push(json::Image {
            buffer_view: Some(view),
            mime_type: Some(json::image::MimeType(mime.into())),
            name: Some(name),
            uri: None,
            extensions: None,
            extras: Default::default(),
        })
    }

    /// Declares an extension as used (and, with `required`, as required to load the file).
    pub(crate) fn use_extension(&mut self, name: &str, required: bool) {
        if !self.root.extensions_used.iter().any(|e| e == name) {
            self.root.extensions_used.push(name.into());
        }
        if required && !self.root.extensions_required.iter().any(|e| e == name) {
            self.root.extensions_required.push(name.into());
        }
    }

    /// The document as a GLB: the JSON chunk, then the binary chunk (the single buffer).
    pub(crate) fn into_glb(mut self) -> Result<Vec<u8>, ExportError> {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        if !self.bin.is_empty() {
            self.root.buffers = vec![json::Buffer {
                byte_length: USize64::from(self.bin.len()),
                name: None,
                uri: None,
                extensions: None,
                extras: Default::default(),
            }];
        }
        if self.fallback_len > 0 {
            // the buffer the compressed views decode into: no data, marked as the extension's
            // fallback (readers that know the extension never load it)
            let mut ext = json::extensions::buffer::Buffer::default();
            ext.others
                .insert(MESHOPT.into(), serde_json::json!({ "fallback": true }));
            self.root.buffers.push(json::Buffer {
                byte_length: USize64::from(self.fallback_len),
                name: Some("meshopt fallback".into()),
                uri: None,
                extensions: Some(ext),
                extras: Default::default(),
            });
        }
        let mut json_bytes = self
            .root
            .to_vec()
            .map_err(|e| ExportError::Gltf(format!("serializing the glTF JSON: {e}")))?;
        // the JSON chunk is padded with spaces to 4 bytes (GLB spec, "Structured JSON Content")
        while json_bytes.len() % 4 != 0 {
            json_bytes.push(b' ');
        }
        let length = 12
            + 8
            + json_bytes.len()
            + if self.bin.is_empty() {
                0
            } else {
                8 + self.bin.len()
            };
        let length = u32::try_from(length).map_err(|_| {
            ExportError::Gltf(format!(
                "{length} bytes is more than a GLB file can hold (4 GiB)"
            ))
        })?;
        let glb = gltf::binary::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                length,
            },
            json: Cow::Owned(json_bytes),
            bin: (!self.bin.is_empty()).then_some(Cow::Owned(self.bin)),
        };
        glb.to_vec()
            .map_err(|e| ExportError::Gltf(format!("framing the GLB: {e}")))
    }
}

fn target(kind: ViewKind) -> Option<json::validation::Checked<json::buffer::Target>> {
    match kind {
        ViewKind::Vertices => Some(Valid(json::buffer::Target::ArrayBuffer)),
        ViewKind::Indices => Some(Valid(json::buffer::Target::ElementArrayBuffer)),
        ViewKind::Other => None,
    }
}

/// meshoptimizer's vertex codec over `bytes`, elements of `stride` bytes (a multiple of 4, at
/// most 256, as `EXT_meshopt_compression` requires), level 2 (its default), bitstream version 0,
/// the one the extension specifies (checked: a newer codec version would not be readable).
fn encode_vertices(bytes: &[u8], stride: usize) -> Result<Vec<u8>, ExportError> {
    fn encode<const S: usize>(bytes: &[u8]) -> Result<Vec<u8>, ExportError> {
        let elements: Vec<[u8; S]> = bytes
            .chunks_exact(S)
            .map(|c| std::array::from_fn(|i| c[i]))
            .collect();
        meshopt::encode_vertex_buffer(&elements)
            .map_err(|e| ExportError::Gltf(format!("meshopt vertex encoding: {e}")))
    }
    let encoded = match stride {
        4 => encode::<4>(bytes),
        8 => encode::<8>(bytes),
        12 => encode::<12>(bytes),
        16 => encode::<16>(bytes),
        _ => Err(ExportError::Gltf(format!(
            "no vertex codec for {stride}-byte vertices"
        ))),
    }?;
    // the codec's header byte: 0xa0 | version
    if encoded.first() != Some(&0xa0) {
        return Err(ExportError::Gltf(format!(
            "meshoptimizer wrote vertex codec header {:?}; EXT_meshopt_compression reads version 0 (0xa0) only",
            encoded.first()
        )));
    }
    Ok(encoded)
}

/// meshoptimizer's index codec over triangle indices of `stride` bytes (2 or 4).
fn encode_triangles(bytes: &[u8], stride: usize) -> Result<Vec<u8>, ExportError> {
    let indices: Vec<u32> = match stride {
        2 => bytes
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]) as u32)
            .collect(),
        4 => bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        _ => {
            return Err(ExportError::Gltf(format!(
                "no index codec for {stride}-byte indices"
            )))
        }
    };
    if indices.len() % 3 != 0 {
        return Err(ExportError::Gltf(format!(
            "{} indices are not whole triangles",
            indices.len()
        )));
    }
    let vertex_count = indices.iter().max().map_or(0, |&m| m as usize + 1);
    meshopt::encode_index_buffer(&indices, vertex_count)
        .map_err(|e| ExportError::Gltf(format!("meshopt index encoding: {e}")))
}

fn bytemuck_f32<'a>(values: impl Iterator<Item = &'a f32>) -> Vec<u8> {
    values.flat_map(|v| v.to_le_bytes()).collect()
}

/// A JSON value as glTF `extras` (a raw JSON value in gltf-json).
pub(crate) fn extras(value: &serde_json::Value) -> Result<json::Extras, ExportError> {
    let raw = serde_json::value::to_raw_value(value)
        .map_err(|e| ExportError::Gltf(format!("serializing extras: {e}")))?;
    Ok(Some(raw))
}
