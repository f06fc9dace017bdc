//! Shared scene arguments and loading with progress, used by every subcommand that takes `SCENE…`.

use std::time::Instant;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use lemi_core::{Scene, UpAxis};

/// `SCENE…` plus `--up`.
#[derive(clap::Args, Debug, Clone)]
pub struct SceneArgs {
    /// Scene inputs: files (.gltf .glb .obj .ply .ply.gz), directories (searched recursively), or
    /// built-in scenes `builtin:NAME[:triangles[:seed]]` with NAME one of city, terrain, forest,
    /// interior.
    #[arg(required = true, value_name = "SCENE")]
    pub scenes: Vec<String>,
    /// Up axis of the input files; lemi works in +Y up and converts Z-up data at import.
    #[arg(long, value_enum, default_value = "y")]
    pub up: UpArg,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum UpArg {
    Y,
    Z,
}

impl From<UpArg> for UpAxis {
    fn from(u: UpArg) -> Self {
        match u {
            UpArg::Y => UpAxis::Y,
            UpArg::Z => UpAxis::Z,
        }
    }
}

/// Loads the scene, showing a progress bar on stderr when it is a terminal; returns the scene and
/// the load time in seconds.
pub fn load_scene(args: &SceneArgs, quiet: bool) -> anyhow::Result<(Scene, f64)> {
    load_scene_with_report(args, quiet).map(|(scene, _, seconds)| (scene, seconds))
}

/// [`load_scene`], with the import's report (which meshes each input became).
pub fn load_scene_with_report(
    args: &SceneArgs,
    quiet: bool,
) -> anyhow::Result<(Scene, lemi_scene::import::ImportReport, f64)> {
    let (bar, progress) = progress_bar(quiet);
    let options = lemi_scene::LoadOptions {
        up: args.up.into(),
        progress: Some(progress),
    };
    let t = Instant::now();
    let (scene, report) = lemi_scene::import::load_with_report(&args.scenes, &options)
        .with_context(|| format!("loading {}", args.scenes.join(" ")))?;
    bar.finish_and_clear();
    print_warnings(&report);
    Ok((scene, report, t.elapsed().as_secs_f64()))
}

/// The spinner of a scene load (hidden if `quiet`) and the progress callback that drives it.
pub fn progress_bar(quiet: bool) -> (ProgressBar, lemi_scene::ProgressFn) {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new_spinner()
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} {elapsed:>4} {msg} {pos}/{len}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_message("loading");
    let cb_bar = bar.clone();
    let progress = std::sync::Arc::new(move |what: &str, done, total| {
        cb_bar.set_message(what.to_string());
        cb_bar.set_length(total);
        cb_bar.set_position(done);
    });
    (bar, progress)
}

/// Prints the import's warnings on stderr.
pub fn print_warnings(report: &lemi_scene::import::ImportReport) {
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
}

/// A `--cells` id (`x_y_z`) of `grid`, or an error naming the flag and the grid's ids.
pub fn parse_cell_flag(
    grid: &lemi_core::cell::CellGrid,
    id: &str,
) -> anyhow::Result<lemi_core::cell::ViewCell> {
    grid.parse_id(id).with_context(|| {
        format!(
            "--cells: the grid has {}x{}x{} cells (ids 0_0_0 to {}_{}_{})",
            grid.counts.x,
            grid.counts.y,
            grid.counts.z,
            grid.counts.x - 1,
            grid.counts.y - 1,
            grid.counts.z - 1
        )
    })
}
