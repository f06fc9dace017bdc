//! `lemi eval BUNDLE`: the error certificate of a bake. For every evaluated cell, viewpoints at the
//! centre, corners, face and edge midpoints and random interior points, looking along every baked
//! face and their diagonals, at the output view the bake assumed: reference vs impostor image,
//! measured parallax error in pixels, crack pixels, FLIP, PSNR, SSIM, coverage. Writes a JSON and
//! static HTML report and prints one verdict line; `--require-max-px` turns it into a gate.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use lemi_eval::{EvalOptions, ViewpointSet};
use std::sync::Arc;

use lemi_gpu::{BackendChoice, Gpu};

/// Measure how far the impostor images of a bundle are from the real geometry.
#[derive(clap::Args)]
pub struct Args {
    /// The bundle directory.
    pub bundle: PathBuf,
    /// Only these cells (grid coordinates `x_y_z`, comma-separated); default: every baked cell.
    #[arg(long, value_delimiter = ',')]
    pub cells: Vec<lemi_core::cell::CellId>,
    /// Random interior viewpoints per cell (besides centre, corners, face and edge midpoints).
    #[arg(long, default_value_t = 4)]
    pub viewpoints: usize,
    /// Only the centre and the corners (and the random viewpoints): a quick certificate.
    #[arg(long)]
    pub corners_only: bool,
    /// Seed of the random viewpoints.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output size `WIDTHxHEIGHT`; default: the bake's output width at 16:9.
    #[arg(long, value_parser = lemi_core::camera::parse_size)]
    pub size: Option<(u32, u32)>,
    /// Horizontal field of view in degrees; default: the bake's.
    #[arg(long)]
    pub fov: Option<f64>,
    /// The scene, if it moved since the bake (checked against the bundle's fingerprint).
    #[arg(long = "scene", value_name = "SCENE")]
    pub scene_override: Vec<String>,
    /// Report directory (report.json, index.html, worst views); default BUNDLE/eval.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Fail (exit status 2) when the maximum geometric error (all impostor pixels) exceeds this
    /// many pixels.
    #[arg(long, value_name = "PX")]
    pub require_max_px: Option<f64>,
    /// Fail (exit status 2) when the maximum placement error (pixels showing a layer's own texels,
    /// i.e. not gap-filled ones) exceeds this many pixels: the bound the layer placement promises.
    #[arg(long, value_name = "PX")]
    pub require_placement_max_px: Option<f64>,
    /// Fail (exit status 2) when any view has crack pixels.
    #[arg(long)]
    pub require_no_cracks: bool,
    /// Fail (exit status 2) when some view's silhouette distance p99 (reference against impostor
    /// coverage outlines) exceeds this many pixels.
    #[arg(long, value_name = "PX")]
    pub require_silhouette_p99: Option<f64>,
    /// Fail (exit status 2) when some view's coverage displacement p99 (how far the impostor's
    /// coverage lies from the reference's, a slit closed or a thin feature dropped counted by its
    /// own pixels) exceeds this many pixels.
    #[arg(long, value_name = "PX")]
    pub require_displacement_p99: Option<f64>,
    /// Fail (exit status 2) when the impostor covers more than this share (0..1) of all evaluated
    /// pixels where the reference shows background.
    #[arg(long, value_name = "SHARE")]
    pub require_false_coverage: Option<f64>,
    /// Also measure, per view, the silhouette distance of the geometry against itself seen
    /// turned by this many pixels right and up (e.g. 0.1): the floor of the metric for any
    /// renderer that moves points by that much, since features narrower than a pixel show at one
    /// sampling of the pixel grid and not at another. Reported next to the impostor's maximum;
    /// one more reference render per view.
    #[arg(long, value_name = "PX")]
    pub silhouette_floor: Option<f64>,
    /// Another bake of the same scene and cells (e.g. the PNG bake of a BC1 bundle): its frames
    /// of the same views are compared with this bundle's (FLIP, PSNR, pixels of changed
    /// coverage), the image cost of a texture format.
    #[arg(long, value_name = "BUNDLE")]
    pub against: Option<PathBuf>,
    /// With --against: fail (exit status 2) when the mean FLIP against the other bake exceeds
    /// this.
    #[arg(long, value_name = "FLIP", requires = "against")]
    pub require_against_flip: Option<f64>,
    /// Far-field strategy to judge: the one the bundle was baked for (default), or warp or
    /// dynamic (built at run time from a `lemi` bundle's cells and near lists).
    #[arg(long)]
    pub strategy: Option<String>,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Print the bundle summary as JSON (per cell under `cells`).
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> Result<()> {
    for (flag, v) in [
        ("--require-max-px", args.require_max_px),
        ("--require-placement-max-px", args.require_placement_max_px),
        ("--require-silhouette-p99", args.require_silhouette_p99),
        ("--require-displacement-p99", args.require_displacement_p99),
    ] {
        if let Some(x) = v {
            if !(x.is_finite() && x >= 0.0) {
                bail!("{flag} must be a number of pixels >= 0 (got {x})");
            }
        }
    }
    for (flag, v) in [
        ("--require-false-coverage", args.require_false_coverage),
        ("--require-against-flip", args.require_against_flip),
    ] {
        if let Some(x) = v {
            if !(0.0..=1.0).contains(&x) {
                bail!("{flag} must be in [0, 1] (got {x})");
            }
        }
    }
    if let Some(x) = args.silhouette_floor {
        if !(x.is_finite() && x > 0.0 && x <= 1.0) {
            bail!("--silhouette-floor must be a fraction of a pixel in (0, 1] (got {x})");
        }
    }
    if let Some(f) = args.fov {
        if !(f.is_finite() && f > 0.0 && f < 180.0) {
            bail!("--fov must be in (0, 180) degrees (got {f})");
        }
    }
    if args.viewpoints > 10_000 {
        bail!("--viewpoints {} is absurd (at most 10000)", args.viewpoints);
    }
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    let (bundle, scene) = crate::bundle_view::open(&args.bundle, &args.scene_override, args.json)?;
    let manifest = bundle.manifest().clone();
    for id in &args.cells {
        if bundle.entry(*id).is_none() {
            let baked: Vec<String> = bundle.cell_ids().iter().map(|c| c.to_string()).collect();
            bail!(
                "--cells: cell {id} is not baked in {} (baked: {})",
                args.bundle.display(),
                baked.join(", ")
            );
        }
    }
    let options = EvalOptions {
        cells: (!args.cells.is_empty()).then(|| args.cells.clone()),
        set: if args.corners_only {
            ViewpointSet::Corners
        } else {
            ViewpointSet::Full
        },
        random_viewpoints: args.viewpoints,
        seed: args.seed,
        size: args.size,
        fov_x_deg: args.fov,
        silhouette_floor_px: args.silhouette_floor,
        ..Default::default()
    };
    let kind = crate::strategy::kind_for(&manifest, args.strategy.as_deref())?;
    let against = match &args.against {
        None => None,
        Some(_) if !kind.is_layered() => {
            bail!("--against compares two layered bakes; strategy {kind} is drawn at run time")
        }
        Some(path) => Some(
            lemi_core::bundle::Bundle::open(path)
                .with_context(|| format!("--against {}", path.display()))?,
        ),
    };
    let gpu = Arc::new(Gpu::new(backend)?);
    let bar = if args.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    bar.set_style(
        ProgressStyle::with_template("{elapsed:>4} [{bar:30}] {pos}/{len} views  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let progress = |done: usize, total: usize, what: &str| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
        bar.set_message(what.to_string());
    };
    let t = std::time::Instant::now();
    let run = match &against {
        Some(other) => lemi_eval::evaluate_bundle_against(
            &gpu,
            &bundle,
            &scene,
            Some(other),
            &options,
            progress,
        )
        .with_context(|| format!("--against {}", other.dir().display()))?,
        None => {
            lemi_eval::evaluate_strategy(&gpu, &bundle, Arc::new(scene), kind, &options, progress)?
        }
    };
    bar.finish_and_clear();
    let seconds = t.elapsed().as_secs_f64();
    let dir = args
        .report
        .clone()
        .unwrap_or_else(|| args.bundle.join("eval"));
    let index = lemi_eval::write_report(&dir, &run.result, &run.worst)?;
    let verdict = if kind.is_layered() {
        format!(
            "{}; placement (layers' own texels) max {:.2} px, gap-filled or copied texels max {:.2} px ({:.2} % of impostor pixels)",
            lemi_eval::verdict(&run.result),
            run.placement.max(),
            run.gap_filled.max(),
            100.0 * run.gap_filled.count() as f64
                / (run.placement.count() + run.gap_filled.count()).max(1) as f64
        )
    } else {
        format!(
            "{} (strategy {kind}: error as the strategy measures it, cracks = background where the reference has a surface)",
            lemi_eval::verdict(&run.result)
        )
    };
    let s = &run.result.summary;
    if args.json {
        let mut v = serde_json::to_value(&run.result)?;
        v["verdict"] = serde_json::Value::String(verdict.clone());
        v["strategy"] = serde_json::json!(kind.name());
        v["placement_max_error_px"] = serde_json::json!(run.placement.max());
        v["placement_p99_error_px"] = serde_json::json!(run.placement.p99());
        v["gap_filled_pixels"] = serde_json::json!(run.gap_filled.count());
        v["gap_filled_max_error_px"] = serde_json::json!(run.gap_filled.max());
        v["seconds"] = serde_json::json!(seconds);
        let (w, h, fov) = lemi_eval::output_view(&manifest, &options);
        v["size"] = serde_json::json!([w, h]);
        v["fov_x_deg"] = serde_json::json!(fov);
        v["report"] = serde_json::json!(index);
        v["textures"] = serde_json::to_value(&run.textures)?;
        v["against"] = serde_json::to_value(&run.against)?;
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        let (w, h, fov) = lemi_eval::output_view(&manifest, &options);
        println!("lemi eval ({kind})");
        println!("adapter    {}", gpu.describe());
        println!(
            "views      {} in {} cells at {w}x{h}, {fov}° horizontal, in {seconds:.1} s ({:.2} s per view)",
            s.views,
            run.result.cells.len(),
            seconds / s.views.max(1) as f64
        );
        for c in &run.result.cells {
            println!(
                "cell {:<6} max {:.2} px, p99 {:.2} px, mean {:.3} px, {:.3} % above 1 px, {} crack pixels, FLIP {:.3}, coverage {:.4}",
                c.cell,
                c.summary.max_error_px,
                c.summary.p99_error_px,
                c.summary.mean_error_px,
                100.0 * c.summary.above_1px,
                c.summary.crack_pixels,
                c.summary.mean_flip,
                c.summary.coverage
            );
        }
        if let Some(split) = run.result.info.get("error split") {
            println!("split      {split}");
        }
        println!(
            "silhouette max {:.2} px, p99 {:.2} px (worst view {:.2} px), mean {:.3} px; coverage displacement max {:.2} px, p99 {:.2} px (worst view {:.2} px); false coverage {} pixels ({:.3} %)",
            s.silhouette_max_px,
            s.silhouette_pooled_p99_px,
            s.silhouette_p99_px,
            s.silhouette_mean_px,
            s.displacement_max_px,
            s.displacement_pooled_p99_px,
            s.displacement_p99_px,
            s.false_coverage_pixels,
            100.0 * s.false_coverage
        );
        if let (Some(px), Some(max), Some(above)) = (
            args.silhouette_floor,
            s.silhouette_floor_max_px,
            s.views_above_silhouette_floor,
        ) {
            println!(
                "floor      the geometry against itself turned by {px} px: silhouette max {max:.2} px; the impostor's maximum exceeds it in {above} of {} views",
                s.views
            );
        }
        if let Some(t) = &run.textures {
            println!("textures   {}", t.describe());
        }
        if let Some(a) = &run.against {
            println!("against    {}", a.describe());
        }
        println!("report     {}", index.display());
        println!("verdict    {verdict}");
    }
    let mut failed = Vec::new();
    if let Some(x) = args.require_max_px {
        if s.max_error_px as f64 > x {
            failed.push(format!(
                "maximum error {:.2} px exceeds --require-max-px {x}",
                s.max_error_px
            ));
        }
    }
    if let Some(x) = args.require_placement_max_px {
        if run.placement.max() as f64 > x {
            failed.push(format!(
                "placement error {:.2} px exceeds --require-placement-max-px {x}",
                run.placement.max()
            ));
        }
    }
    if args.require_no_cracks && s.crack_pixels > 0 {
        failed.push(format!(
            "{} crack pixels (--require-no-cracks)",
            s.crack_pixels
        ));
    }
    if let Some(x) = args.require_silhouette_p99 {
        if s.silhouette_p99_px as f64 > x {
            failed.push(format!(
                "silhouette distance p99 {:.2} px exceeds --require-silhouette-p99 {x}",
                s.silhouette_p99_px
            ));
        }
    }
    if let Some(x) = args.require_displacement_p99 {
        if s.displacement_p99_px as f64 > x {
            failed.push(format!(
                "coverage displacement p99 {:.2} px exceeds --require-displacement-p99 {x}",
                s.displacement_p99_px
            ));
        }
    }
    if let Some(x) = args.require_false_coverage {
        if s.false_coverage > x {
            failed.push(format!(
                "false coverage {:.5} exceeds --require-false-coverage {x}",
                s.false_coverage
            ));
        }
    }
    if let (Some(x), Some(a)) = (args.require_against_flip, &run.against) {
        if a.mean_flip as f64 > x {
            failed.push(format!(
                "mean FLIP {:.4} against {} exceeds --require-against-flip {x}",
                a.mean_flip,
                a.bundle.display()
            ));
        }
    }
    if !failed.is_empty() {
        eprintln!("error: certificate failed: {}", failed.join("; "));
        std::process::exit(2);
    }
    Ok(())
}
