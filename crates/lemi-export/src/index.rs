//! `cells.json`: the index of an export. A client reads it once, then streams the cells' `.glb`
//! files as the viewer moves: the grid locates the viewer's cell, the cell boxes and the
//! prediction rule (the runtime's, `lemi_runtime::predict`, with its parameters recorded here)
//! say which cells to fetch next, and the file sizes what that costs.

use lemi_core::bundle::Manifest;
use lemi_core::cell::ViewCell;
use serde::{Deserialize, Serialize};

use crate::{CellGlb, ExportOptions};

/// The index's file name in the export directory.
pub const INDEX_FILE: &str = "cells.json";
/// The index's `format` field.
pub const INDEX_FORMAT: &str = "lemi-gltf-export";
/// The index's `version` field.
pub const INDEX_VERSION: u32 = 1;

/// The observer model the runtime prefetches cells by (`lemi_runtime::PredictOptions` and the
/// constants of `lemi_runtime::predict`): every cell gets its earliest possible arrival time
/// under a bounded speed and acceleration; cells reachable within the horizon are fetched, soonest
/// first.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PredictionRule {
    /// Always `"earliest-arrival"` (`docs/EXPORT.md` describes it step by step).
    pub rule: String,
    pub horizon_seconds: f64,
    pub max_speed: f64,
    pub max_acceleration: f64,
    pub max_cells: usize,
    /// Samples of the horizon when looking for the first contact.
    pub samples: u32,
    /// Bisection steps after sampling.
    pub bisection_steps: u32,
}

impl Default for PredictionRule {
    /// The runtime's defaults (`PredictOptions::default()`); the CLI fills them in from
    /// `lemi-runtime` itself.
    fn default() -> Self {
        PredictionRule {
            rule: "earliest-arrival".into(),
            horizon_seconds: 2.0,
            max_speed: 10.0,
            max_acceleration: 5.0,
            max_cells: 27,
            samples: 128,
            bisection_steps: 40,
        }
    }
}

/// The grid of the bundle: cell `(i, j, k)` spans `origin + (i, j, k)·step` to `+ step`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IndexGrid {
    pub origin: [f64; 3],
    /// The size of one cell per axis.
    pub step: [f64; 3],
    pub counts: [i32; 3],
}

/// One exported cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellIndexEntry {
    /// `x_y_z`, the bundle's cell id.
    pub id: String,
    pub index: [i32; 3],
    pub min: [f64; 3],
    pub max: [f64; 3],
    /// The reference viewpoint (the cell's centre).
    pub center: [f64; 3],
    /// Relative to the index.
    pub file: String,
    pub bytes: u64,
    /// Bytes of the bundle's cell file it was exported from.
    pub source_bytes: u64,
    pub quads: usize,
    pub macro_textures: usize,
    pub texture_bytes: u64,
    /// Bytes of the quads' vertex and index data as stored (compressed with `meshopt`).
    #[serde(default)]
    pub quad_bytes: u64,
    /// The quads' primitives (one per macro-texture and kind): a renderer's draw calls.
    #[serde(default)]
    pub quad_primitives: usize,
    pub near_triangles: u64,
    /// Bytes of the near geometry (vertices, indices and its material images; 0 without it).
    #[serde(default)]
    pub near_bytes: u64,
}

/// What the bundle was baked from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IndexScene {
    pub fingerprint: String,
    pub sources: Vec<String>,
    pub up: String,
}

/// `cells.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExportIndex {
    pub format: String,
    pub version: u32,
    pub generator: String,
    pub scene: IndexScene,
    pub params_hash: String,
    /// α of the bake (radians).
    pub alpha: f64,
    pub resolution: u32,
    pub faces: Vec<String>,
    /// `png` or `ktx2`.
    pub textures: String,
    /// The bundle's texture format (`png`, `bc7`, `bc1`).
    pub bundle_texture_format: String,
    /// How vertex and index data are stored: `meshopt` (`EXT_meshopt_compression`), `meshopt-v1`
    /// (`KHR_meshopt_compression`, vertex codec version 1) or `plain`.
    #[serde(default)]
    pub geometry: String,
    /// Whether the cell files hold the near geometry.
    pub near: bool,
    pub grid: IndexGrid,
    pub prediction: PredictionRule,
    pub cells: Vec<CellIndexEntry>,
}

impl ExportIndex {
    pub(crate) fn new(manifest: &Manifest, options: &ExportOptions, near: bool) -> ExportIndex {
        let grid = &manifest.grid;
        ExportIndex {
            format: INDEX_FORMAT.into(),
            version: INDEX_VERSION,
            generator: options.generator.clone(),
            scene: IndexScene {
                fingerprint: manifest.scene.fingerprint.clone(),
                sources: manifest.scene.sources.clone(),
                up: manifest.scene.up.clone(),
            },
            params_hash: manifest.params_hash.clone(),
            alpha: manifest.params.alpha,
            resolution: manifest.params.resolution,
            faces: manifest
                .params
                .faces
                .iter()
                .map(|f| f.name().to_string())
                .collect(),
            textures: options.textures.name().into(),
            bundle_texture_format: manifest.params.texture_format.name().into(),
            geometry: options.geometry.name().into(),
            near,
            grid: IndexGrid {
                origin: grid.origin.to_array(),
                step: grid.step().to_array(),
                counts: grid.counts.to_array(),
            },
            prediction: options.prediction.clone(),
            cells: Vec::new(),
        }
    }

    pub(crate) fn push(&mut self, cell: &ViewCell, file: String, glb: &CellGlb, source_bytes: u64) {
        let b = cell.bounds();
        self.cells.push(CellIndexEntry {
            id: cell.id().to_string(),
            index: cell.index.to_array(),
            min: b.min.to_array(),
            max: b.max.to_array(),
            center: cell.center.to_array(),
            file,
            bytes: glb.bytes.len() as u64,
            source_bytes,
            quads: glb.quads,
            macro_textures: glb.macro_textures,
            texture_bytes: glb.texture_bytes,
            quad_bytes: glb.quad_bytes.stored,
            quad_primitives: glb.quad_primitives,
            near_triangles: glb.near_triangles,
            near_bytes: glb.near_bytes,
        });
    }

    /// Total bytes of the exported cell files.
    pub fn bytes(&self) -> u64 {
        self.cells.iter().map(|c| c.bytes).sum()
    }

    /// Total bytes of the bundle's cell files they were exported from.
    pub fn source_bytes(&self) -> u64 {
        self.cells.iter().map(|c| c.source_bytes).sum()
    }
}
