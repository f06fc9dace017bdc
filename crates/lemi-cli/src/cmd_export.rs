//! `lemi export BUNDLE -o DIR [--cells …] [--textures png|ktx2] [--geometry meshopt|meshopt-v1|plain]
//! [--with-near] [--viewer]`: one
//! binary glTF 2.0 file per view cell plus `cells.json` (`lemi-export`, `docs/EXPORT.md`);
//! `--viewer` adds the web viewer (`web/viewer`, three.js from `web/node_modules`).

use std::path::{Path, PathBuf};

use anyhow::bail;
use lemi_core::bundle::Bundle;
use lemi_core::cell::CellId;
use lemi_export::{ExportGeometry, ExportOptions, ExportSummary, ExportTextures, PredictionRule};
use serde_json::json;

#[derive(clap::Args)]
pub struct Args {
    /// The bundle directory (holds manifest.json).
    pub bundle: PathBuf,
    /// Output directory (created if needed): cells/<id>.glb and cells.json.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Only these cells, as grid coordinates `x_y_z` (comma-separated); default: every baked cell.
    #[arg(long, value_delimiter = ',')]
    pub cells: Vec<String>,
    /// Texture format of the exported files: png (core glTF 2.0) or ktx2 (the bundle's KTX2
    /// files through KHR_texture_basisu; bundles baked with --texture-format bc7, bc1, uastc or
    /// etc1s).
    #[arg(long, value_enum, default_value = "png")]
    pub textures: TexturesArg,
    /// How vertex and index data are stored: meshopt (compressed with EXT_meshopt_compression,
    /// the quads' texture coordinates as integers through KHR_mesh_quantization; about a quarter
    /// of the bytes, for readers with a meshopt decoder such as three.js and Babylon.js),
    /// meshopt-v1 (the same through KHR_meshopt_compression with the codec's version 1, about 3
    /// bytes a quad fewer, for readers of that extension such as three.js r179 and later) or
    /// plain (core glTF 2.0 only, for any reader).
    #[arg(long, value_enum, default_value = "meshopt")]
    pub geometry: GeometryArg,
    /// Also export each cell's near geometry with its materials (loads the scene the bundle was
    /// baked from).
    #[arg(long)]
    pub with_near: bool,
    /// With --with-near: the scene to use instead of the manifest's sources (must be the same
    /// scene: checked against the bundle's fingerprint).
    #[arg(long = "scene", value_name = "SCENE")]
    pub scene_override: Vec<String>,
    /// Also copy the web viewer (index.html, its scripts and three.js) into the output directory.
    #[arg(long)]
    pub viewer: bool,
    /// Where the web viewer and its node packages are (default: the `web` directory of lemi's
    /// source tree; run `npm ci` there first).
    #[arg(long, value_name = "DIR")]
    pub web_dir: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexturesArg {
    Png,
    Ktx2,
}

impl From<TexturesArg> for ExportTextures {
    fn from(t: TexturesArg) -> Self {
        match t {
            TexturesArg::Png => ExportTextures::Png,
            TexturesArg::Ktx2 => ExportTextures::Ktx2,
        }
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeometryArg {
    Meshopt,
    #[value(name = "meshopt-v1")]
    MeshoptV1,
    Plain,
}

impl From<GeometryArg> for ExportGeometry {
    fn from(g: GeometryArg) -> Self {
        match g {
            GeometryArg::Meshopt => ExportGeometry::Meshopt,
            GeometryArg::MeshoptV1 => ExportGeometry::MeshoptV1,
            GeometryArg::Plain => ExportGeometry::Plain,
        }
    }
}

/// How the exported files store textures and geometry.
#[derive(Clone, Copy, Debug, Default)]
pub struct Storage {
    pub textures: ExportTextures,
    pub geometry: ExportGeometry,
}

/// The runtime's prediction rule with its parameters, for `cells.json`.
pub fn prediction_rule() -> PredictionRule {
    let o = lemi_runtime::PredictOptions::default();
    PredictionRule {
        horizon_seconds: o.horizon_seconds,
        max_speed: o.max_speed,
        max_acceleration: o.max_acceleration,
        max_cells: o.max_cells,
        ..PredictionRule::default()
    }
}

/// Exports `bundle` into `out`: with the near geometry when `with_near` (the scene is loaded and
/// checked against the bundle), `cells` (ids as given) or every cell.
pub fn export(
    bundle: &Path,
    out: &Path,
    cells: &[String],
    storage: Storage,
    with_near: bool,
    scene_override: &[String],
    quiet: bool,
) -> anyhow::Result<ExportSummary> {
    if !bundle.is_dir() {
        bail!(
            "{}: not a bundle directory (expected a directory holding manifest.json)",
            bundle.display()
        );
    }
    let (opened, scene) = if with_near {
        let (b, s) = crate::bundle_view::open(bundle, scene_override, quiet)?;
        (b, Some(s))
    } else {
        if !scene_override.is_empty() {
            bail!("--scene is only used with --with-near");
        }
        (Bundle::open(bundle)?, None)
    };
    let ids = parse_cells(&opened, cells)?;
    let options = ExportOptions {
        cells: ids,
        textures: storage.textures,
        geometry: storage.geometry,
        prediction: prediction_rule(),
        generator: format!("lemi {}", env!("CARGO_PKG_VERSION")),
    };
    let total = options
        .cells
        .as_ref()
        .map_or(opened.manifest().cells.len(), |c| c.len());
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(total as u64)
    };
    let summary = lemi_export::export_bundle(&opened, scene.as_ref(), out, &options, |done, _| {
        bar.set_position(done as u64)
    });
    bar.finish_and_clear();
    Ok(summary?)
}

fn parse_cells(bundle: &Bundle, cells: &[String]) -> anyhow::Result<Option<Vec<CellId>>> {
    if cells.is_empty() {
        return Ok(None);
    }
    let grid = &bundle.manifest().grid;
    let mut ids = Vec::new();
    for id in cells {
        let cell = crate::load::parse_cell_flag(grid, id)?;
        if bundle.entry(cell.id()).is_none() {
            bail!(
                "--cells: cell {} was not baked into {}",
                cell.id(),
                bundle.dir().display()
            );
        }
        if !ids.contains(&cell.id()) {
            ids.push(cell.id());
        }
    }
    Ok(Some(ids))
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let summary = export(
        &args.bundle,
        &args.output,
        &args.cells,
        Storage {
            textures: args.textures.into(),
            geometry: args.geometry.into(),
        },
        args.with_near,
        &args.scene_override,
        args.json,
    )?;
    if args.viewer {
        crate::web::install_viewer(&args.output, args.web_dir.as_deref())?;
    }
    let index = &summary.index;
    let (bytes, source) = (index.bytes(), index.source_bytes());
    let worst = index
        .cells
        .iter()
        .map(|c| c.bytes as f64 / c.source_bytes.max(1) as f64)
        .fold(0.0, f64::max);
    if args.json {
        let out = json!({
            "output": args.output,
            "index": summary.index_path,
            "cells": index.cells,
            "bytes": bytes,
            "source_bytes": source,
            "max_bytes_ratio": worst,
            "textures": index.textures,
            "geometry": index.geometry,
            "near": index.near,
            "viewer": args.viewer,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let quads: usize = index.cells.iter().map(|c| c.quads).sum();
    let near: u64 = index.cells.iter().map(|c| c.near_triangles).sum();
    println!(
        "exported   {} cells of {}: {quads} quads, {near} near triangles, {} textures, {} geometry",
        index.cells.len(),
        args.bundle.display(),
        index.textures,
        index.geometry
    );
    println!(
        "bytes      {:.1} KB of .glb from {:.1} KB of cell files (largest ratio {worst:.3})",
        bytes as f64 / 1e3,
        source as f64 / 1e3
    );
    println!("wrote      {}", summary.index_path.display());
    if args.viewer {
        println!(
            "viewer     {} (serve the directory: lemi serve {})",
            args.output.join("index.html").display(),
            args.output.display()
        );
    }
    Ok(())
}
