//! `lemi info SCENE… [--up z] [--json]`: counts, bounds and import statistics of a scene.

use serde_json::json;

use crate::load::{load_scene, SceneArgs};

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let (scene, seconds) = load_scene(&args.scene, args.json)?;
    let s = &scene.stats;
    let b = scene.bounds;
    let textured = scene
        .materials
        .iter()
        .filter(|m| m.texture.is_some())
        .count();
    if args.json {
        let out = json!({
            "sources": scene.sources,
            "triangles": s.triangles,
            "vertices": s.vertices,
            "meshes": scene.meshes.len(),
            "materials": scene.materials.len(),
            "textured_materials": textured,
            "textures": scene.textures.len(),
            "bounds": { "min": b.min.to_array(), "max": b.max.to_array() },
            "dropped": {
                "nonfinite": s.dropped_nonfinite,
                "degenerate": s.dropped_degenerate,
                "bad_index": s.dropped_bad_index,
            },
            "files": s.files,
            "load_seconds": seconds,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let size = b.size();
    println!("scene      {}", scene.sources.join(" "));
    println!("triangles  {}", s.triangles);
    println!("vertices   {}", s.vertices);
    println!(
        "meshes     {}   materials {} ({} textured)   textures {}",
        scene.meshes.len(),
        scene.materials.len(),
        textured,
        scene.textures.len()
    );
    println!(
        "bounds     min ({:.3}, {:.3}, {:.3})  max ({:.3}, {:.3}, {:.3})",
        b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z
    );
    println!("size       {:.3} x {:.3} x {:.3} m", size.x, size.y, size.z);
    println!(
        "dropped    {} non-finite, {} degenerate (zero area), {} bad index",
        s.dropped_nonfinite, s.dropped_degenerate, s.dropped_bad_index
    );
    println!("loaded in  {seconds:.2} s");
    Ok(())
}
