//! `lemi`: the command-line front end. Each subcommand lives in its own `cmd_*.rs` file with an
//! `Args` struct and a `run` function; the libraries do the work.

mod bundle_view;
mod cmd_bake;
mod cmd_bake_object;
mod cmd_compare;
mod cmd_demo;
mod cmd_eval;
mod cmd_export;
mod cmd_info;
mod cmd_layers;
mod cmd_render;
mod cmd_serve;
mod cmd_view;
mod cmd_walk;
mod layers_object;
mod load;
mod strategy;
mod web;

use clap::{Parser, Subcommand};

/// Layered environment-map impostors for huge static scenes.
#[derive(Parser)]
#[command(name = "lemi", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The main job on the built-in default scene: bake a strip of cells, compare with the reference.
    Demo(cmd_demo::Args),
    /// Bake view cells into a bundle of layered impostors (resumable, shardable).
    Bake(cmd_bake::Args),
    /// Bake the layered impostor of one object for a box or shaft view cell (TR-186-2-02-04).
    #[command(name = "bake-object")]
    BakeObject(cmd_bake_object::Args),
    /// Measure a bundle's impostors against the geometry: the error certificate and report.
    Eval(cmd_eval::Args),
    /// Print triangle/material counts, bounds and import statistics of a scene.
    Info(cmd_info::Args),
    /// Render a scene with the reference renderer, or a bundle's impostor view (`--compare`: side by side).
    Render(cmd_render::Args),
    /// Replay a camera path through a bundle: streaming impostors vs. all geometry, frame times.
    Walk(cmd_walk::Args),
    /// Fly or walk through a bundle in a window: HUD, impostors/geometry and layer toggles, path recording.
    View(cmd_view::Args),
    /// Export a bundle to glTF 2.0: one .glb per view cell plus cells.json (engines, the web viewer).
    Export(cmd_export::Args),
    /// Open a bundle in the web viewer: export it, then serve the viewer on localhost.
    Serve(cmd_serve::Args),
    /// Compute the layer placement of a view cell (the error metric).
    Layers(cmd_layers::Args),
    /// Run every far-field strategy (lemi, cubemap, equidistant, warp, dynamic) on one scene: tables, plots.
    Compare(cmd_compare::Args),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => cmd_demo::run(a),
        Command::Info(a) => cmd_info::run(a),
        Command::Bake(a) => cmd_bake::run(a),
        Command::BakeObject(a) => cmd_bake_object::run(a),
        Command::Eval(a) => cmd_eval::run(a),
        Command::Render(a) => cmd_render::run(a),
        Command::Layers(a) => cmd_layers::run(a),
        Command::Walk(a) => cmd_walk::run(a),
        Command::View(a) => cmd_view::run(a),
        Command::Compare(a) => cmd_compare::run(a),
        Command::Export(a) => cmd_export::run(a),
        Command::Serve(a) => cmd_serve::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {}", error_chain(&e));
        std::process::exit(1);
    }
}

/// The error and its causes joined by `: `, leaving out a cause whose text the message already
/// shows (library errors often include their source in their own message).
fn error_chain(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if msg.contains(&text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&text);
    }
    msg
}
