//! A glTF 2.0 document under construction with its one binary buffer: appends buffer views (each
//! 4-byte aligned), accessors with the bounds the specification requires, images, textures and
//! materials, and frames the result as a GLB (`gltf::binary::Glb`). The document model is
//! gltf-json's (`gltf::json`), so every object is written by the library, not by hand.

use std::borrow::Cow;

use gltf::json;
use json::validation::Checked::Valid;
use json::validation::USize64;

use crate::ExportError;

/// A document and its binary chunk.
pub(crate) struct Document {
    pub(crate) root: json::Root,
    pub(crate) bin: Vec<u8>,
}

/// What a buffer view holds (glTF's `target`): vertex attributes, indices, or neither (images).
#[derive(Clone, Copy)]
pub(crate) enum ViewKind {
    Vertices,
    Indices,
    Other,
}

impl Document {
    pub(crate) fn new(generator: &str) -> Document {
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
        }
    }

    /// Appends `bytes` to the binary chunk (4-byte aligned) as a new buffer view.
    pub(crate) fn view(&mut self, bytes: &[u8], kind: ViewKind) -> json::Index<json::buffer::View> {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        let target = match kind {
            ViewKind::Vertices => Some(Valid(json::buffer::Target::ArrayBuffer)),
            ViewKind::Indices => Some(Valid(json::buffer::Target::ElementArrayBuffer)),
            ViewKind::Other => None,
        };
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target,
            extensions: None,
            extras: Default::default(),
        })
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
    ) -> json::Index<json::Accessor> {
        let view = self.view(bytes, kind);
        let (min, max) = match bounds {
            Some((lo, hi)) => (Some(json::Value::from(lo)), Some(json::Value::from(hi))),
            None => (None, None),
        };
        self.root.push(json::Accessor {
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
        })
    }

    /// `POSITION`: three f32 per vertex, with the bounds glTF requires.
    pub(crate) fn positions(&mut self, p: &[[f32; 3]]) -> json::Index<json::Accessor> {
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
    pub(crate) fn normals(&mut self, n: &[[f32; 3]]) -> json::Index<json::Accessor> {
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
    pub(crate) fn texcoords(&mut self, uv: &[[f32; 2]]) -> json::Index<json::Accessor> {
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

    /// `COLOR_0`: four normalised unsigned bytes per vertex (linear RGBA).
    pub(crate) fn colors(&mut self, c: &[[u8; 4]]) -> json::Index<json::Accessor> {
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
    ) -> json::Index<json::Accessor> {
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

fn bytemuck_f32<'a>(values: impl Iterator<Item = &'a f32>) -> Vec<u8> {
    values.flat_map(|v| v.to_le_bytes()).collect()
}

/// A JSON value as glTF `extras` (a raw JSON value in gltf-json).
pub(crate) fn extras(value: &serde_json::Value) -> Result<json::Extras, ExportError> {
    let raw = serde_json::value::to_raw_value(value)
        .map_err(|e| ExportError::Gltf(format!("serializing extras: {e}")))?;
    Ok(Some(raw))
}
