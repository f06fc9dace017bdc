//! `lemi bake SCENE… -o BUNDLE`: bakes the view cells of a region into a bundle (GI 2002 sec. 3-5):
//! per cell placement, classification, crack-free GPU recording and compression, each cell file
//! written atomically as soon as it is done. Resumable (intact cells baked with identical
//! parameters are skipped), shardable (`--shard K/N`, then `lemi bake --merge BUNDLE`).
//!
//! `--strategy` picks the far-field layering baked (`BakeParams::layering`): `lemi` (the optimal
//! placement, the default), `cubemap` (one layer per face) or `equidistant` (Schaufler's layered
//! impostors, with `--overlap`). `warp` and `dynamic` are not baked: they run from a `lemi` bundle.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use indicatif::{ProgressBar, ProgressStyle};
use lemi_bake::{BakeJob, Baker, CellOutcome};
use lemi_core::bundle::{BakeParams, LayerTarget, Layering, ParamsError, SceneRef};
use lemi_core::cell::{CellGrid, Shard, ViewCell};
use lemi_core::compress::TextureFormat;
use lemi_core::placement::{alpha_from_output_view, min_face_res_for_output_view, PixelChoice};
use lemi_core::{Aabb, Face};
use lemi_gpu::{BackendChoice, Gpu};
use serde_json::json;

use crate::load::{load_scene, SceneArgs, UpArg};

/// Bake view cells into a bundle of layered impostors.
#[derive(clap::Args)]
pub struct Args {
    /// Scene inputs (as for `lemi render`); not needed with --merge.
    #[arg(value_name = "SCENE", required_unless_present = "merge")]
    pub scenes: Vec<String>,
    /// Up axis of the input files.
    #[arg(long, value_enum, default_value = "y")]
    pub up: UpArg,
    /// The bundle directory to write (created if missing).
    #[arg(
        short = 'o',
        long = "out",
        value_name = "BUNDLE",
        required_unless_present = "merge"
    )]
    pub out: Option<PathBuf>,
    /// Write the manifest of BUNDLE from its shards' records (after all `--shard K/N` runs).
    #[arg(long, value_name = "BUNDLE", conflicts_with_all = ["scenes", "out", "shard", "cells", "region"])]
    pub merge: Option<PathBuf>,
    /// Region the viewer moves in, `x0,y0,z0,x1,y1,z1` in scene coordinates (after --up); cells
    /// tile it. Default: the scene's ground footprint at --eye-height.
    #[arg(long, value_parser = parse_region, allow_hyphen_values = true)]
    pub region: Option<Aabb>,
    /// Eye height above the scene's lowest point for the default region (metres).
    #[arg(long, default_value_t = 1.7, allow_hyphen_values = true)]
    pub eye_height: f64,
    /// Only these cells of the grid, as grid coordinates `x_y_z` (comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub cells: Vec<String>,
    /// View-cell side in metres.
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true)]
    pub cell_size: f64,
    /// View-cell height in metres (the eye-height range a ground-level viewer moves in); default:
    /// the cell size (cubic cells).
    #[arg(long, allow_hyphen_values = true)]
    pub cell_height: Option<f64>,
    /// Texels per cube-face side (Res).
    #[arg(long, default_value_t = 512)]
    pub resolution: u32,
    /// Layers per face.
    #[arg(long, conflicts_with = "near_field")]
    pub layers: Option<u32>,
    /// Near-field distance from the cell centre (m): the fewest layers that reach it.
    #[arg(long, allow_hyphen_values = true)]
    pub near_field: Option<f64>,
    /// Faces to bake: 4 (the horizontal ones, for ground-level scenes) or 6.
    #[arg(long, default_value_t = 4)]
    pub faces: u32,
    /// Horizontal field of view of the output view in degrees (α = its edge pixel).
    #[arg(long, conflicts_with = "alpha_deg")]
    pub output_fov: Option<f64>,
    /// Width of the output view in pixels.
    #[arg(long, conflicts_with = "alpha_deg")]
    pub output_width: Option<u32>,
    /// Allowed parallax angle α in degrees instead of an output view.
    #[arg(long, allow_hyphen_values = true)]
    pub alpha_deg: Option<f64>,
    /// α as a fraction of the output view's edge pixel (default 1): e.g. 0.33 with
    /// --outline-copies, whose copies are drawn up to 2α off.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "alpha_deg")]
    pub alpha_px: Option<f64>,
    /// Far-field strategy to bake: lemi (optimal layer placement), cubemap (one layer per face),
    /// equidistant (Schaufler's uniformly spaced, overlapping layers) or hlod (the far field as
    /// geometry simplified with meshoptimizer within the same α). warp and dynamic are not
    /// baked: they run from a lemi bundle (`lemi walk/eval --strategy`).
    #[arg(long, default_value = "lemi")]
    pub strategy: String,
    /// With --strategy equidistant: how far adjacent layers' depth ranges overlap, as a fraction
    /// of a slab's depth on each side, in [0, 1] (default 0.1).
    #[arg(long, allow_hyphen_values = true)]
    pub overlap: Option<f64>,
    /// With --strategy hlod: the screen-space error bound of the simplified far field, as a
    /// multiple of the parallax angle α (default 1; `lemi_core::hlod`).
    #[arg(long, allow_hyphen_values = true)]
    pub hlod_error_px: Option<f64>,
    /// With --strategy hlod: the ratio of the far to the near distance of each band the far field
    /// is simplified in (default 2).
    #[arg(long, allow_hyphen_values = true)]
    pub hlod_band_factor: Option<f64>,
    /// How the macro-textures are stored: bc1 (the default: 8 bytes a 4×4 block, punch-through
    /// alpha), bc7 (16 bytes a block), both in KTX2 supercompressed with Zstandard, or png
    /// (lossless, RGBA8 in texture memory). --strategy hlod has no macro-textures.
    #[arg(long, value_parser = parse_texture_format)]
    pub texture_format: Option<TextureFormat>,
    /// Copy each layer's outline texels into the adjacent layer on the side where parallax
    /// uncovers the strip beside them (docs/COMPRESSION.md, "Outline copies"): no background or
    /// farther layer shows through an outline from anywhere in the cell, at the price of copies
    /// drawn up to 2α off. With α of a third of an output pixel (`--alpha-px 0.33`) every
    /// pixel stays within one. Not with --strategy equidistant.
    #[arg(long)]
    pub outline_copies: bool,
    /// Mark the texel that conservative recording grows an outline by as fringe, which the
    /// runtime draws only where something lies behind it (docs/COMPRESSION.md, "Outline
    /// fringe"): silhouettes against the sky land where the geometry's do instead of up to a
    /// texel outside, while strips over farther surfaces stay closed. BC7, UASTC and PNG mark the
    /// fringe texels by their alpha; BC1 and ETC1S, whose alpha has one bit, keep them in quads
    /// of their own ("fringe quads"). Not with --strategy equidistant.
    #[arg(long)]
    pub outline_fringe: bool,
    /// Micro-texture grid cell in texels (GI 2002 sec. 5.3).
    #[arg(long, default_value_t = 8)]
    pub micro_grid: u32,
    /// Minimum opaque fraction while a micro-texture grows.
    #[arg(long, default_value_t = 0.6, allow_hyphen_values = true)]
    pub micro_threshold: f64,
    /// Bake only shard K of N (`K/N`, 0 ≤ K < N), e.g. `--shard $JOB_COMPLETION_INDEX/8`.
    #[arg(long, value_parser = parse_shard)]
    pub shard: Option<Shard>,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The texture format a bake gets without `--texture-format`, chosen by measurement
/// (docs/COMPRESSION.md, "The default format"): BC1 keeps the mean FLIP within 0.005 of the PNG
/// bake's at a fifth of its texture memory on every scene measured.
pub const DEFAULT_TEXTURE_FORMAT: TextureFormat = TextureFormat::Bc1;

/// The format of a bake given `--texture-format` (or not): the default for layers, PNG (no
/// textures at all) for `--strategy hlod`.
pub(crate) fn texture_format_for(given: Option<TextureFormat>, hlod: bool) -> TextureFormat {
    match given {
        Some(f) => f,
        None if hlod => TextureFormat::Png,
        None => DEFAULT_TEXTURE_FORMAT,
    }
}

/// `--texture-format NAME`.
pub(crate) fn parse_texture_format(name: &str) -> std::result::Result<TextureFormat, String> {
    TextureFormat::from_name(name)
        .ok_or_else(|| format!("unknown texture format `{name}`: png, bc7, bc1, uastc or etc1s"))
}

/// Default output view (as `lemi layers`).
const DEFAULT_FOV_DEG: f64 = 60.0;
const DEFAULT_WIDTH: u32 = 1280;
/// Default `--overlap` of the equidistant strategy.
const DEFAULT_OVERLAP: f64 = 0.1;
/// The strategies `lemi bake` bakes, by `--strategy` name.
const BAKED_STRATEGIES: [&str; 4] = ["lemi", "cubemap", "equidistant", "hlod"];

/// The layering of `--strategy NAME` (with `--overlap`), or a clear error.
/// The flag that sets the parameter a [`ParamsError`] is about.
fn flag_of(e: &ParamsError) -> &'static str {
    match e {
        ParamsError::CellSize(_) => "--cell-size",
        ParamsError::CellHeight(_) => "--cell-height",
        ParamsError::Resolution(_) => "--resolution",
        ParamsError::NoFaces => "--faces",
        ParamsError::Alpha(_) => "--alpha-deg/--output-fov",
        ParamsError::Layers(_) => "--layers",
        ParamsError::NearField { .. } => "--near-field",
        ParamsError::MicroGrid { .. } => "--micro-grid",
        ParamsError::MicroThreshold(_) => "--micro-threshold",
        ParamsError::Overlap(_) => "--overlap",
        ParamsError::OutlineCopies => "--outline-copies",
        ParamsError::OutlineFringe(_) => "--outline-fringe",
        ParamsError::Hlod(e) => match e.option() {
            "band_factor" => "--hlod-band-factor",
            _ => "--hlod-error-px",
        },
    }
}

fn layering_of(name: &str, overlap: Option<f64>, hlod: [Option<f64>; 2]) -> Result<Layering> {
    let name = name.trim();
    let layering = match name {
        "lemi" => Layering::Optimal,
        "cubemap" => Layering::Single,
        "equidistant" => {
            let o = overlap.unwrap_or(DEFAULT_OVERLAP);
            if !(o.is_finite() && (0.0..=1.0).contains(&o)) {
                bail!(
                    "--overlap must be a fraction of a layer's depth in [0, 1] (got {o}): how far \
                     adjacent equidistant layers overlap on each side"
                );
            }
            Layering::Equidistant { overlap: o }
        }
        "hlod" => {
            let defaults = lemi_core::hlod::HlodOptions::default();
            Layering::Hlod {
                error_px: hlod[0].unwrap_or(defaults.error_px),
                band_factor: hlod[1].unwrap_or(defaults.band_factor),
            }
        }
        "warp" | "dynamic" => bail!(
            "--strategy {name} is not baked: it runs from a `lemi` bundle (`lemi bake --strategy \
             lemi`, then `lemi walk/eval BUNDLE --strategy {name}`); `lemi bake` bakes {}",
            BAKED_STRATEGIES.join(", ")
        ),
        _ => bail!(
            "unknown --strategy `{name}`: `lemi bake` bakes {} (warp and dynamic run from a `lemi` \
             bundle with `lemi walk/eval --strategy`)",
            BAKED_STRATEGIES.join(", ")
        ),
    };
    if overlap.is_some() && !matches!(layering, Layering::Equidistant { .. }) {
        bail!("--overlap only applies to --strategy equidistant (got --strategy {name})");
    }
    for (value, flag) in hlod.iter().zip(["--hlod-error-px", "--hlod-band-factor"]) {
        if value.is_some() && !matches!(layering, Layering::Hlod { .. }) {
            bail!("{flag} only applies to --strategy hlod (got --strategy {name})");
        }
    }
    Ok(layering)
}

/// The `--strategy` name of a layering, and a description for the summary.
fn strategy_name(layering: &Layering) -> (&'static str, String) {
    match layering {
        Layering::Optimal => ("lemi", "optimal layer placement".into()),
        Layering::Single => ("cubemap", "one layer per face".into()),
        Layering::Equidistant { overlap } => (
            "equidistant",
            format!("uniformly spaced layers, overlap {overlap}"),
        ),
        Layering::Hlod {
            error_px,
            band_factor,
        } => (
            "hlod",
            format!("far field simplified within {error_px} α, bands × {band_factor}"),
        ),
    }
}

pub(crate) fn parse_region(s: &str) -> Result<Aabb, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e}"))?;
    if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "`{s}`: expected six finite numbers x0,y0,z0,x1,y1,z1"
        ));
    }
    let a = DVec3::new(v[0], v[1], v[2]);
    let b = DVec3::new(v[3], v[4], v[5]);
    Ok(Aabb::new(a.min(b), a.max(b)))
}

fn parse_shard(s: &str) -> Result<Shard, String> {
    Shard::parse(s).map_err(|e| e.to_string())
}

/// A bake job built from the flags (`lemi bake`, and `lemi compare` for each layered strategy):
/// the job, the scene it bakes, the GPU backend and what the flags warn of.
pub(crate) struct Prepared {
    pub job: BakeJob,
    pub scene: lemi_core::Scene,
    pub backend: BackendChoice,
    pub warnings: Vec<String>,
    pub load_seconds: f64,
}

/// α (radians) from `--alpha-deg`, or from the output view `--output-fov`/`--output-width`
/// (its edge pixel, times `--alpha-px`; defaults 60°, 1280 px, 1), with the output view it came
/// from.
pub(crate) fn alpha_of(
    alpha_deg: Option<f64>,
    alpha_px: Option<f64>,
    output_fov: Option<f64>,
    output_width: Option<u32>,
) -> Result<(f64, Option<f64>, Option<u32>)> {
    let px = alpha_px.unwrap_or(1.0);
    if !(px.is_finite() && px > 0.0 && px <= 16.0) {
        bail!("--alpha-px must be a fraction of an output pixel in (0, 16], got {px}");
    }
    Ok(match alpha_deg {
        Some(a) => {
            if !(a.is_finite() && a > 0.0 && a < 20.0) {
                bail!("--alpha-deg must be in (0, 20) degrees, got {a}");
            }
            (a.to_radians(), None, None)
        }
        None => {
            let fov = output_fov.unwrap_or(DEFAULT_FOV_DEG);
            let width = output_width.unwrap_or(DEFAULT_WIDTH);
            if !(fov.is_finite() && fov > 0.0 && fov < 180.0) {
                bail!("--output-fov must be in (0, 180) degrees, got {fov}");
            }
            let a = alpha_from_output_view(fov.to_radians(), width, PixelChoice::Edge)
                .context("--output-fov/--output-width")?;
            (a * px, Some(fov), Some(width))
        }
    })
}

/// The scene inputs as recorded in a bundle: files by absolute path (so the bundle can be
/// rendered from anywhere), `builtin:` specs as given.
pub(crate) fn absolute_sources(scenes: &[String]) -> Vec<String> {
    scenes
        .iter()
        .map(|s| {
            if s.starts_with("builtin:") {
                s.clone()
            } else {
                std::fs::canonicalize(s)
                    .map(|p| p.to_string_lossy().into_owned())
                    .unwrap_or_else(|_| s.clone())
            }
        })
        .collect()
}

/// Checks the flags, loads the scene and builds the job (`-o` is required).
pub(crate) fn prepare(args: &Args) -> Result<Prepared> {
    let Some(out) = args.out.clone() else {
        bail!("-o BUNDLE is required");
    };
    let layering = layering_of(
        &args.strategy,
        args.overlap,
        [args.hlod_error_px, args.hlod_band_factor],
    )?;
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    let faces: Vec<Face> = match args.faces {
        4 => Face::HORIZONTAL.to_vec(),
        6 => Face::ALL.to_vec(),
        n => bail!("--faces must be 4 (horizontal) or 6 (all), got {n}"),
    };
    let target = match (args.layers, args.near_field) {
        (_, Some(d)) => LayerTarget::NearField(d),
        (Some(n), None) => LayerTarget::Layers(n),
        (None, None) => LayerTarget::Layers(64),
    };
    let (alpha, fov, width) = alpha_of(
        args.alpha_deg,
        args.alpha_px,
        args.output_fov,
        args.output_width,
    )?;
    let hlod = matches!(layering, Layering::Hlod { .. });
    let texture_format = texture_format_for(args.texture_format, hlod);
    if hlod && !texture_format.is_png() {
        bail!(
            "--texture-format {texture_format} does not apply to --strategy hlod (its far field is \
             geometry, it has no macro-textures)"
        );
    }
    let params = BakeParams {
        cell_size: args.cell_size,
        cell_height: args.cell_height,
        resolution: args.resolution,
        target,
        faces,
        alpha,
        output_fov_deg: fov,
        output_width: width,
        micro_grid: args.micro_grid,
        micro_threshold: args.micro_threshold,
        layering,
        texture_format,
        outline_copies: args.outline_copies,
        outline_fringe: args.outline_fringe,
    };
    params
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", flag_of(&e)))?;
    let mut warnings = Vec::new();
    if let (Some(f), Some(w)) = (fov, width) {
        if let Ok(min) = min_face_res_for_output_view(f.to_radians(), w) {
            if args.resolution < min {
                warnings.push(format!(
                    "--resolution {} is below the {min} texels per face at which a layer texel \
                     subtends at most one pixel of the {w} px, {f}° output view: impostors will \
                     look blurrier than the geometry (the one-pixel guarantee assumes no magnification)",
                    args.resolution
                ));
                if args.outline_fringe {
                    warnings.push(format!(
                        "--outline-fringe: the runtime closes gaps of up to two pixels between \
                         two outlines' fringes, made for fringe texels of at most a pixel; at \
                         --resolution {} a texel spans up to {:.2} px of the output view, so \
                         background may show between outlines (crack pixels); bake at \
                         --resolution {min} or more",
                        args.resolution,
                        f64::from(min) / f64::from(args.resolution)
                    ));
                }
            }
        }
    }

    let px = args.alpha_px.unwrap_or(1.0);
    if let (true, Some(f), Some(w), true) = (args.outline_copies, fov, width, px > 0.5) {
        // the copies are drawn up to 2α off: within a pixel needs α ≤ ½ px
        warnings.push(format!(
            "--outline-copies with α of {px} pixel of the {w} px, {f}° output view draws copies \
             up to {} px off; to keep every pixel within one, give α a third of a pixel: \
             --alpha-px 0.33",
            2.0 * px
        ));
    }

    let sources = absolute_sources(&args.scenes);
    let scene_args = SceneArgs {
        scenes: sources.clone(),
        up: args.up,
    };
    let (scene, load_seconds) = load_scene(&scene_args, args.json)?;
    let fingerprint =
        lemi_scene::fingerprint(&sources, args.up.into()).context("fingerprinting the scene")?;
    if let Some(w) = older_fingerprint_warning(&out) {
        warnings.push(w);
    }
    let region = match args.region {
        Some(r) => r,
        None => {
            if !args.eye_height.is_finite() {
                bail!("--eye-height must be finite (got {})", args.eye_height);
            }
            let b = scene.bounds;
            let y = b.min.y + args.eye_height;
            Aabb::new(
                DVec3::new(b.min.x, y, b.min.z),
                DVec3::new(b.max.x, y, b.max.z),
            )
        }
    };
    let grid = CellGrid::tile_with_height(region, args.cell_size, args.cell_height)
        .context("--region/--cell-size/--cell-height")?;
    let cells: Vec<ViewCell> = if args.cells.is_empty() {
        grid.cells()
    } else {
        let mut v = Vec::new();
        for id in &args.cells {
            let c = crate::load::parse_cell_flag(&grid, id)?;
            if !v.contains(&c) {
                v.push(c);
            }
        }
        v
    };
    let job = BakeJob {
        bundle: out.clone(),
        scene: SceneRef {
            sources,
            up: match args.up {
                UpArg::Y => "y".into(),
                UpArg::Z => "z".into(),
            },
            fingerprint,
            triangles: scene.triangle_count(),
        },
        params,
        grid,
        cells,
        shard: args.shard,
    };
    Ok(Prepared {
        job,
        scene,
        backend,
        warnings,
        load_seconds,
    })
}

/// A warning when the bundle being resumed was fingerprinted under an older scheme: its cells carry
/// that fingerprint, so they are baked again rather than skipped.
fn older_fingerprint_warning(bundle: &std::path::Path) -> Option<String> {
    let path = lemi_core::bundle::manifest_path(bundle);
    let bytes = std::fs::read(&path).ok()?;
    let manifest: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    let fp = manifest.get("scene")?.get("fingerprint")?.as_str()?;
    let scheme = lemi_scene::FingerprintScheme::of(fp)?;
    (scheme != lemi_scene::FingerprintScheme::CURRENT).then(|| {
        format!(
            "{} was baked under scene fingerprint scheme {} (which also hashed files beside the \
             scene that it does not use); its cells are baked again under scheme {}, not skipped",
            path.display(),
            scheme.number(),
            lemi_scene::FingerprintScheme::CURRENT.number()
        )
    })
}

pub fn run(args: Args) -> Result<()> {
    if let Some(bundle) = &args.merge {
        let m = lemi_bake::merge(bundle)?;
        if args.json {
            println!(
                "{}",
                serde_json::to_string_pretty(&json!({
                    "merged": bundle,
                    "cells": m.cells.len(),
                    "bytes": m.cells.iter().map(|c| c.bytes).sum::<u64>(),
                }))?
            );
        } else {
            println!(
                "merged     {} cells into {}",
                m.cells.len(),
                lemi_core::bundle::manifest_path(bundle).display()
            );
        }
        return Ok(());
    }
    let Prepared {
        job,
        scene,
        backend,
        warnings,
        load_seconds: load_s,
    } = prepare(&args)?;
    let out = job.bundle.clone();
    let params = job.params.clone();
    for w in &warnings {
        eprintln!("warning: {w}");
    }

    let gpu = Gpu::new(backend)?;
    let t_prep = Instant::now();
    let baker = Baker::new(&gpu, &scene, params.clone())?;
    let prep_s = t_prep.elapsed().as_secs_f64();
    let mine = match job.shard {
        Some(s) => s.select(&job.cells).len(),
        None => job.cells.len(),
    };
    let bar = if args.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(mine as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{elapsed:>4} [{bar:30}] {pos}/{len} cells  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let stage_bar = bar.clone();
    let summary = lemi_bake::run(
        &job,
        |cell| {
            let id = cell.id();
            baker.bake(cell, |stage| {
                stage_bar.set_message(format!("cell {id}: {stage}"));
            })
        },
        |_, _, outcome| {
            bar.inc(1);
            if let CellOutcome::Baked { entry, seconds, .. } = outcome {
                bar.println(format!(
                    "baked      cell {} in {seconds:.1} s ({} bytes)",
                    entry.id, entry.bytes
                ));
            }
        },
    )?;
    bar.finish_and_clear();

    let report = summary.report();
    let (per_cell, total, baked, skipped, bytes) = (
        &report.per_cell,
        &report.total,
        report.baked,
        report.skipped,
        report.bytes,
    );
    let (strategy, strategy_note) = strategy_name(&params.layering);
    // seconds of the macro-texture encode (the stage named by the format), summed over the cells
    let encode_s: f64 = total
        .seconds
        .iter()
        .filter(|(k, _)| k == params.texture_format.name())
        .map(|(_, v)| v)
        .sum();
    if args.json {
        let out_json = json!({
            "bundle": out,
            "strategy": strategy,
            "layering": params.layering,
            "record": summary.record,
            "adapter": gpu.info().name,
            "cells": per_cell.len(),
            "baked": baked,
            "skipped": skipped,
            "stale_temp_files_removed": summary.stale_temp_files_removed,
            "seconds": summary.seconds,
            "load_seconds": load_s,
            "prepare_seconds": prep_s,
            "bytes": bytes,
            "raw_bytes": total.raw_bytes,
            "macro_bytes": total.macro_bytes,
            "png_bytes": total.png_bytes,
            "texture_format": params.texture_format,
            "ktx2_bytes": total.ktx2_bytes,
            "texture_bytes": total.texture_bytes(),
            "texture_memory_bytes": total.texture_memory_bytes(),
            "encode_seconds": encode_s,
            "far_triangles": total.far_triangles,
            "near_triangles": total.near_triangles,
            "submitted_triangles": total.submitted_triangles,
            "micro_textures": total.micro_textures,
            "macro_textures": total.macro_textures,
            "outline_copies": total.outline_copies,
            "outline_fringe": total.outline_fringe,
            "fringe_quads": total.fringe_quads,
            "stage_seconds": total.seconds.iter().cloned().collect::<std::collections::BTreeMap<String, f64>>(),
            "warnings": warnings,
            "per_cell": per_cell,
        });
        println!("{}", serde_json::to_string_pretty(&out_json)?);
        return Ok(());
    }
    println!("lemi bake");
    println!(
        "scene      {}: {} triangles, loaded in {load_s:.2} s",
        args.scenes.join(" "),
        scene.triangle_count()
    );
    println!("adapter    {}", gpu.describe());
    println!("strategy   {strategy} ({strategy_note})");
    println!(
        "cells      {} ({} baked, {} skipped as already baked) of a {}x{}x{} grid of {} m cells{}",
        per_cell.len(),
        baked,
        skipped,
        job.grid.counts.x,
        job.grid.counts.y,
        job.grid.counts.z,
        params.cell_size,
        params
            .cell_height
            .map(|h| format!(", {h} m tall"))
            .unwrap_or_default()
    );
    let n = per_cell.len().max(1) as f64;
    println!(
        "triangles  per cell: {:.0} far, {:.0} near, {:.0} submitted to the recorder ({:.2}x the far ones)",
        total.far_triangles as f64 / n,
        total.near_triangles as f64 / n,
        total.submitted_triangles as f64 / n,
        total.submitted_triangles as f64 / total.far_triangles.max(1) as f64
    );
    println!(
        "bytes      per cell: raw layers {}, macro-textures {}, PNG {}; all cells: {} micro-textures in {} macro-textures",
        human(total.raw_bytes as f64 / n),
        human(total.macro_bytes as f64 / n),
        human(total.png_bytes as f64 / n),
        total.micro_textures,
        total.macro_textures
    );
    if params.outline_copies {
        println!(
            "copies     per cell: {:.0} outline texels copied into an adjacent layer ({:.1} % of the recorded texels)",
            total.outline_copies as f64 / n,
            100.0 * total.outline_copies as f64 / total.opaque_texels_recorded.max(1) as f64
        );
    }
    if params.outline_fringe {
        println!(
            "fringe     per cell: {:.0} outline texels marked as fringe, drawn only over something ({:.1} % of the recorded texels)",
            total.outline_fringe as f64 / n,
            100.0 * total.outline_fringe as f64 / total.opaque_texels_recorded.max(1) as f64
        );
        if total.fringe_quads > 0 {
            println!(
                "           per cell: {:.0} fringe quads ({}'s one-bit alpha cannot mark the fringe: it \
                 is kept in quads of its own)",
                total.fringe_quads as f64 / n,
                params.texture_format.name()
            );
        }
    }
    if !matches!(params.layering, Layering::Hlod { .. }) {
        println!(
            "textures   {} per cell: {} on disk, {} in texture memory; encoded in {:.2} s per baked cell",
            params.texture_format,
            human(total.texture_bytes() as f64 / n),
            human(total.texture_memory_bytes() as f64 / n),
            encode_s / baked.max(1) as f64
        );
    }
    let stages: Vec<String> = total
        .seconds
        .iter()
        .map(|(k, v)| format!("{k} {:.2}", v / baked.max(1) as f64))
        .collect();
    if baked > 0 {
        println!("seconds    per baked cell: {}", stages.join(", "));
    }
    println!(
        "time       {:.1} s in all (load {load_s:.1} s, prepare {prep_s:.1} s)",
        summary.seconds
    );
    println!(
        "wrote      {} ({} in cell files)",
        summary.record.display(),
        human(bytes as f64)
    );
    if summary.stale_temp_files_removed > 0 {
        println!(
            "removed    {} temporary files left by runs killed while writing",
            summary.stale_temp_files_removed
        );
    }
    if job.shard.is_some() {
        println!(
            "next       when every shard is done: lemi bake --merge {}",
            out.display()
        );
    }
    Ok(())
}

/// Bytes with a binary-ish unit, for humans.
pub fn human(b: f64) -> String {
    if b >= 1e9 {
        format!("{:.2} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else if b >= 1e3 {
        format!("{:.0} KB", b / 1e3)
    } else {
        format!("{b:.0} B")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--alpha-px F` is F times the output view's edge pixel, with the view recorded; it is
    /// checked; `--alpha-deg` records no view.
    #[test]
    fn alpha_px_scales_the_output_views_edge_pixel() {
        let one = alpha_of(None, None, Some(60.0), Some(1280)).expect("one pixel");
        let third = alpha_of(None, Some(1.0 / 3.0), Some(60.0), Some(1280)).expect("a third");
        assert!((third.0 * 3.0 - one.0).abs() < 1e-15, "{third:?} {one:?}");
        assert_eq!((third.1, third.2), (Some(60.0), Some(1280)));
        let edge = alpha_from_output_view(60f64.to_radians(), 1280, PixelChoice::Edge).unwrap();
        assert_eq!(one.0, edge);
        for bad in [0.0, -0.5, f64::NAN, f64::INFINITY, 17.0] {
            let e = alpha_of(None, Some(bad), None, None).expect_err("bad --alpha-px");
            assert!(e.to_string().contains("--alpha-px"), "{e}");
        }
        let deg = alpha_of(Some(0.02), None, None, None).expect("degrees");
        assert_eq!((deg.1, deg.2), (None, None));
    }
}
