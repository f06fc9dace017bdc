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
/// Its Khronos successor, which also reads the vertex codec's version 1
/// ([`ExportGeometry::MeshoptV1`]).
pub const MESHOPT_KHR: &str = "KHR_meshopt_compression";
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
        filter: Option<&str>,
    ) -> Result<json::Index<json::buffer::View>, ExportError> {
        let (encoded, mode) = match kind {
            ViewKind::Vertices => (
                encode_vertices(bytes, stride, self.codec_version())?,
                "ATTRIBUTES",
            ),
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
        let name = self.meshopt_name();
        self.use_extension(name, true);
        let mut ext = json::extensions::buffer::View::default();
        let mut meshopt = serde_json::json!({
            "buffer": 0,
            "byteOffset": offset,
            "byteLength": encoded.len(),
            "byteStride": stride,
            "count": count,
            "mode": mode,
        });
        if let Some(filter) = filter {
            meshopt["filter"] = filter.into();
        }
        ext.others.insert(name.into(), meshopt);
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

    /// The meshopt extension of this document's geometry (the EXT one for plain documents, which
    /// never name it).
    fn meshopt_name(&self) -> &'static str {
        self.geometry.meshopt_extension().unwrap_or(MESHOPT)
    }

    /// The vertex codec's bitstream version: 1 with `KHR_meshopt_compression`, else 0.
    fn codec_version(&self) -> u8 {
        u8::from(self.geometry == ExportGeometry::MeshoptV1)
    }

    /// A view of vertex or index data: compressed unless the geometry is plain, else as is.
    fn data_view(
        &mut self,
        bytes: &[u8],
        count: usize,
        stride: usize,
        kind: ViewKind,
        filter: Option<&str>,
    ) -> Result<json::Index<json::buffer::View>, ExportError> {
        match kind {
            ViewKind::Vertices | ViewKind::Indices if self.geometry.compressed() => {
                self.compressed_view(bytes, count, stride, kind, filter)
            }
            _ => Ok(self.view(bytes, kind)),
        }
    }

    /// A tightly packed accessor over a new buffer view holding `bytes`; a compressed view
    /// carries the meshopt `filter` the reader applies after decoding (the bytes are then the
    /// filter's encoding).
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
        filter: Option<&str>,
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        let view = match bytes.len().checked_div(count) {
            Some(stride) => self.data_view(bytes, count, stride, kind, filter)?,
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
        self.accessor(
            bytemuck_f32(p.iter().flatten()).as_slice(),
            ViewKind::Vertices,
            p.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            false,
            Some(bounds(p)),
            None,
        )
    }

    /// `POSITION` within `tolerance[i]` of `p[i]` (per vertex, in the same units): with
    /// [`ExportGeometry::Meshopt`] each vertex is stored as integers on a grid of step `2^e`,
    /// the largest power of two not above twice its tolerance, through `EXT_meshopt_compression`'s
    /// `EXPONENTIAL` filter ([`exponential_filter`]), which a reader decodes to f32 `m · 2^e`;
    /// else (or where a coordinate is too large for 24-bit mantissas on that grid) as f32, exactly.
    pub(crate) fn positions_within(
        &mut self,
        p: &[[f32; 3]],
        tolerance: &[f64],
    ) -> Result<json::Index<json::Accessor>, ExportError> {
        let filtered = if self.geometry.compressed() {
            exponential_filter(p, tolerance)
        } else {
            None
        };
        let Some((words, decoded)) = filtered else {
            return self.positions(p);
        };
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        self.accessor(
            &bytes,
            ViewKind::Vertices,
            p.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            false,
            Some(bounds(&decoded)),
            Some("EXPONENTIAL"),
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
            ext.others.insert(
                self.meshopt_name().into(),
                serde_json::json!({ "fallback": true }),
            );
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
/// most 256, as `EXT_meshopt_compression` requires), at its default level 2, in bitstream
/// `version` 0 (the one `EXT_meshopt_compression` specifies) or 1 (`KHR_meshopt_compression`);
/// checked against the header the codec wrote.
fn encode_vertices(bytes: &[u8], stride: usize, version: u8) -> Result<Vec<u8>, ExportError> {
    if stride == 0 || stride % 4 != 0 || stride > 256 || bytes.len() % stride != 0 {
        return Err(ExportError::Gltf(format!(
            "no vertex codec for {stride}-byte vertices over {} bytes",
            bytes.len()
        )));
    }
    let count = bytes.len() / stride;
    // SAFETY: meshoptimizer's bound for these sizes is the buffer's length, and the encoder
    // reads `count · stride` bytes of `bytes` and writes at most `bound` bytes of `encoded`.
    let encoded = unsafe {
        let bound = meshopt::ffi::meshopt_encodeVertexBufferBound(count, stride);
        let mut encoded = vec![0u8; bound];
        let n = meshopt::ffi::meshopt_encodeVertexBufferLevel(
            encoded.as_mut_ptr(),
            encoded.len(),
            bytes.as_ptr().cast(),
            count,
            stride,
            2,
            i32::from(version),
        );
        encoded.truncate(n);
        encoded
    };
    // the codec's header byte: 0xa0 | version
    if encoded.first() != Some(&(0xa0 | version)) {
        return Err(ExportError::Gltf(format!(
            "meshoptimizer wrote vertex codec header {:?}, not version {version}",
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

/// The component-wise bounds of `p`, which glTF requires of `POSITION`.
fn bounds(p: &[[f32; 3]]) -> (Vec<f32>, Vec<f32>) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for v in p {
        for i in 0..3 {
            lo[i] = lo[i].min(v[i]);
            hi[i] = hi[i].max(v[i]);
        }
    }
    (lo.to_vec(), hi.to_vec())
}

/// `EXT_meshopt_compression`'s `EXPONENTIAL` filter, encoded: each f32 component as one 32-bit
/// word, a signed 8-bit exponent `e` in the top byte and a signed 24-bit mantissa `m` below it,
/// which a reader decodes as `m · 2^e` (exactly, in f32). The exponent is chosen per vertex from
/// its tolerance `t`: the largest `e` with `2^e ≤ 2t`, so that rounding to the grid moves no
/// component by more than `t`. Neighbouring vertices with the same tolerance share the grid,
/// which is what lets the vertex codec predict them. Returns the words and the decoded
/// positions, or `None` when a tolerance is not positive and finite or a coordinate needs more
/// than 24 bits on its grid (then the caller stores f32).
pub(crate) fn exponential_filter(
    p: &[[f32; 3]],
    tolerance: &[f64],
) -> Option<(Vec<u32>, Vec<[f32; 3]>)> {
    if p.len() != tolerance.len() {
        return None;
    }
    let mut words = Vec::with_capacity(3 * p.len());
    let mut decoded = Vec::with_capacity(p.len());
    for (v, &t) in p.iter().zip(tolerance) {
        if !(t.is_finite() && t > 0.0) {
            return None;
        }
        // exponents far from 0 keep every decoded value a normal f32 (exact); a grid finer
        // than needed is fine, a coarser one is not
        let e = (2.0 * t).log2().floor().min(100.0);
        if e < -100.0 {
            return None;
        }
        let e = e as i32;
        let step = 2f64.powi(e);
        let mut out = [0f32; 3];
        for (c, o) in v.iter().zip(&mut out) {
            let m = (*c as f64 / step).round();
            if m.is_nan() || m.abs() >= (1 << 23) as f64 {
                return None;
            }
            let m = m as i32;
            words.push(((e as u32) << 24) | (m as u32 & 0x00ff_ffff));
            *o = (m as f64 * step) as f32;
        }
        decoded.push(out);
    }
    Some((words, decoded))
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

#[cfg(test)]
mod tests {
    use super::exponential_filter;
    use proptest::prelude::*;

    /// What a reader does with a word of the `EXPONENTIAL` filter (the extension's decoder:
    /// sign-extend the low 24 bits, the top byte is the signed exponent).
    fn decode(w: u32) -> f32 {
        let m = ((w << 8) as i32) >> 8;
        let e = (w as i32) >> 24;
        (m as f64 * 2f64.powi(e)) as f32
    }

    proptest! {
        /// Every decoded component is within its vertex's tolerance, the words decode to the
        /// positions returned, and vertices of one tolerance share one grid.
        #[test]
        fn filtered_positions_stay_within_tolerance(
            p in prop::collection::vec(prop::array::uniform3(-1.0e4f32..1.0e4), 1..40),
            t in 1.0e-4f64..10.0,
        ) {
            let tol: Vec<f64> = p.iter().enumerate().map(|(i, _)| t * (1 + i % 3) as f64).collect();
            // a coordinate whose mantissa on its grid needs more than 24 signed bits has no
            // word: then the filter must decline the whole buffer (the caller stores f32)
            let fits = p.iter().zip(&tol).all(|(v, &t)| {
                let step = 2f64.powf((2.0 * t).log2().floor());
                v.iter().all(|&c| (c as f64 / step).round().abs() < (1 << 23) as f64)
            });
            let Some((words, decoded)) = exponential_filter(&p, &tol) else {
                prop_assert!(!fits, "declined a buffer that fits 24 bits");
                return Ok(());
            };
            prop_assert!(fits, "encoded a buffer that does not fit 24 bits");
            prop_assert_eq!(words.len(), 3 * p.len());
            for (i, v) in p.iter().enumerate() {
                for c in 0..3 {
                    let got = decode(words[3 * i + c]);
                    prop_assert_eq!(got, decoded[i][c]);
                    let off = (got as f64 - v[c] as f64).abs();
                    // the grid's rounding plus the f32 rounding of the decoded value
                    prop_assert!(off <= tol[i] + 1e-7 * v[c].abs() as f64, "{} vs {}", got, v[c]);
                }
            }
            for i in 3..p.len() {
                prop_assert_eq!(words[3 * i] >> 24, words[3 * (i - 3)] >> 24);
            }
        }
    }

    #[test]
    fn unusable_tolerances_and_huge_coordinates_fall_back() {
        let p = [[1.0f32, 2.0, 3.0]];
        for t in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e-40] {
            assert!(exponential_filter(&p, &[t]).is_none(), "{t}");
        }
        // 2^30 on a grid of 2^-4: a 34-bit mantissa
        assert!(exponential_filter(&[[1.0e9, 0.0, 0.0]], &[0.05]).is_none());
        // 9914.671 on a grid of 2^-13: a 27-bit mantissa
        assert!(exponential_filter(&[[9914.671, 0.0, 0.0]], &[1.0e-4]).is_none());
        assert!(exponential_filter(&[[f32::NAN, 0.0, 0.0]], &[0.05]).is_none());
        assert!(
            exponential_filter(&p, &[0.1, 0.1]).is_none(),
            "one tolerance a vertex"
        );
    }
}
