//! Export of a bundle to glTF 2.0, so that any engine (three.js, Babylon.js, Godot, Unity, Unreal,
//! Bevy) draws the far field lemi baked: one binary glTF file per view cell
//! ([`cell_gltf`]) and a `cells.json` index ([`index`]) that a client streams the cells by. The
//! format is documented in `docs/EXPORT.md`.
//!
//! Everything is read through the bundle's one reader (`Bundle::verified_cell`: every check of a
//! cell file), and every file is written atomically (`lemi_core::container::write_atomic`).

pub mod cell_gltf;
mod document;
pub mod index;
pub mod serve;

use std::path::{Path, PathBuf};

use lemi_core::bundle::{Bundle, BundleError};
use lemi_core::cell::CellId;
use lemi_core::Scene;

pub use cell_gltf::{export_cell, opaque_quads, quad_order, CellGlb, CellOptions};
pub use document::{GeometryBytes, MESHOPT, MESHOPT_KHR, QUANTIZATION};
pub use index::{CellIndexEntry, ExportIndex, PredictionRule, INDEX_FILE, INDEX_FORMAT};

/// How the macro-textures are stored in the exported files.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ExportTextures {
    /// PNG in the core glTF 2.0 (the bundle's PNG files as they are, or block-compressed texels
    /// decoded and stored as PNG).
    #[default]
    Png,
    /// The bundle's KTX2 files through `KHR_texture_basisu` (block-compressed and Basis Universal
    /// bundles only).
    Ktx2,
}

impl ExportTextures {
    pub fn name(self) -> &'static str {
        match self {
            ExportTextures::Png => "png",
            ExportTextures::Ktx2 => "ktx2",
        }
    }
}

/// How the vertex and index data are stored in the exported files.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ExportGeometry {
    /// Compressed (`EXT_meshopt_compression`, lossless) with the quads' texture coordinates as
    /// 16-bit integers (`KHR_mesh_quantization`, `KHR_texture_transform`): about a quarter of
    /// the bytes; needs a reader with a meshopt decoder (three.js, Babylon.js, glTFast).
    #[default]
    Meshopt,
    /// The same through `KHR_meshopt_compression` with meshoptimizer's vertex codec version 1
    /// (3 bytes a quad fewer, docs/EXPORT.md): for readers of that extension (three.js r179 and
    /// later).
    MeshoptV1,
    /// Core glTF 2.0 only (f32 attributes, u16/u32 indices): any reader.
    Plain,
}

impl ExportGeometry {
    pub fn name(self) -> &'static str {
        match self {
            ExportGeometry::Meshopt => "meshopt",
            ExportGeometry::MeshoptV1 => "meshopt-v1",
            ExportGeometry::Plain => "plain",
        }
    }

    /// Whether vertex and index views are stored compressed (and the quads' texture coordinates
    /// as integers).
    pub fn compressed(self) -> bool {
        self.meshopt_extension().is_some()
    }

    /// The glTF extension the compressed views use, `None` for plain geometry.
    pub fn meshopt_extension(self) -> Option<&'static str> {
        match self {
            ExportGeometry::Meshopt => Some(document::MESHOPT),
            ExportGeometry::MeshoptV1 => Some(document::MESHOPT_KHR),
            ExportGeometry::Plain => None,
        }
    }
}

/// What went wrong exporting; every message names the file or what to do.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The bundle or one of its cell files failed a check of the bundle's reader.
    #[error(transparent)]
    Bundle(#[from] BundleError),
    #[error("{}: cannot write it: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Something the export cannot represent.
    #[error("{0}")]
    Unsupported(String),
    /// The near list does not index the scene given.
    #[error("{0}")]
    Near(String),
    /// Building the glTF document failed (a bug or a limit).
    #[error("{0}")]
    Gltf(String),
}

/// What to export.
#[derive(Clone, Debug, Default)]
pub struct ExportOptions {
    /// The cells to export (default: every baked cell, in manifest order).
    pub cells: Option<Vec<CellId>>,
    pub textures: ExportTextures,
    pub geometry: ExportGeometry,
    /// The prediction rule a client streams the cells by, recorded in `cells.json`.
    pub prediction: PredictionRule,
    /// `asset.generator` and the index's `generator`, e.g. `lemi 0.1.0`.
    pub generator: String,
}

/// What an export wrote.
#[derive(Clone, Debug)]
pub struct ExportSummary {
    pub index: ExportIndex,
    /// `cells.json`.
    pub index_path: PathBuf,
}

/// Exports the cells of `bundle` into `out` (created if needed): `out/cells/<id>.glb` per cell
/// and `out/cells.json`. With `scene` (the scene the bundle was baked from, checked by the
/// caller against the manifest's fingerprint) the files hold the near geometry too. `progress`
/// is called after each cell with (done, total).
pub fn export_bundle(
    bundle: &Bundle,
    scene: Option<&Scene>,
    out: &Path,
    options: &ExportOptions,
    mut progress: impl FnMut(usize, usize),
) -> Result<ExportSummary, ExportError> {
    let manifest = bundle.manifest();
    if let lemi_core::bundle::Layering::Hlod { .. } = manifest.params.layering {
        return Err(ExportError::Unsupported(format!(
            "{}: an HLOD bundle has no impostor layers to export (bake with --strategy lemi)",
            bundle.dir().display()
        )));
    }
    let ids = match &options.cells {
        Some(ids) => ids.clone(),
        None => bundle.cell_ids(),
    };
    let cells_dir = out.join("cells");
    std::fs::create_dir_all(&cells_dir).map_err(|source| ExportError::Write {
        path: cells_dir.clone(),
        source,
    })?;
    let mut index = ExportIndex::new(manifest, options, scene.is_some());
    let cell_options = CellOptions {
        textures: options.textures,
        geometry: options.geometry,
        alpha: manifest.params.alpha,
        generator: &options.generator,
    };
    for (k, &id) in ids.iter().enumerate() {
        let verified = bundle.verified_cell(id)?;
        let glb = export_cell(&verified.file, scene, &cell_options).map_err(|e| match e {
            ExportError::Gltf(m) | ExportError::Near(m) | ExportError::Unsupported(m) => {
                ExportError::Gltf(format!("{}: {m}", bundle.cell_path(id).display()))
            }
            e => e,
        })?;
        let file = format!("cells/{id}.glb");
        let path = out.join(&file);
        lemi_core::container::write_atomic(&path, &glb.bytes).map_err(|source| {
            ExportError::Write {
                path: path.clone(),
                source,
            }
        })?;
        index.push(&verified.file.header.cell, file, &glb, verified.entry.bytes);
        progress(k + 1, ids.len());
    }
    let index_path = out.join(INDEX_FILE);
    let json = serde_json::to_vec_pretty(&index)
        .map_err(|e| ExportError::Gltf(format!("serializing {INDEX_FILE}: {e}")))?;
    lemi_core::container::write_atomic(&index_path, &json).map_err(|source| {
        ExportError::Write {
            path: index_path.clone(),
            source,
        }
    })?;
    Ok(ExportSummary { index, index_path })
}
