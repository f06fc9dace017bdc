//! `lemi bake-object SCENE… -o BUNDLE --view-cell box:…|shaft:… [--object x0,y0,z0,x1,y1,z1]
//! | --object-mesh NAME]`:
//! bakes the layered impostor of one object for a box- or shaft-shaped view cell
//! (TR-186-2-02-04 sec. 2.1-2.2; [`lemi_core::object_cell`], [`lemi_bake::object_bake`]). Without
//! `--object` the whole scene is the object. The bundle holds one cell whose near list is
//! everything else, so `lemi render`/`lemi eval` draw the object as impostor and the rest as
//! geometry, and the object as geometry from outside its view cell.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use indicatif::{ProgressBar, ProgressStyle};
use lemi_bake::object_bake::{bake_object, object_params, write_object_bundle};
use lemi_core::bundle::{BakeParams, LayerTarget, SceneRef};
use lemi_core::classify::TriRef;
use lemi_core::compress::TextureFormat;
use lemi_core::object_cell::{object_bounds, ObjectError, ObjectSetup, ObjectViewCell};
use lemi_core::{Aabb, Face, Scene};
use lemi_gpu::{BackendChoice, Gpu};
use serde_json::json;

use crate::cmd_bake::{absolute_sources, alpha_of, human};
use crate::load::{load_scene_with_report, SceneArgs, UpArg};

/// Bake the layered impostor of one object for a box or shaft view cell.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// The bundle directory to write (created if missing).
    #[arg(short = 'o', long = "out", value_name = "BUNDLE")]
    pub out: PathBuf,
    /// The object: the triangles whose centroid lies in this box `x0,y0,z0,x1,y1,z1` (scene
    /// coordinates after --up). Default: the whole scene.
    #[arg(long, value_parser = crate::cmd_bake::parse_region, allow_hyphen_values = true)]
    pub object: Option<Aabb>,
    /// The object: the triangles of one scene input, named by its path as given, its file name
    /// or its file name without extensions (`dragon` for `models/dragon.ply.gz`); with
    /// --object, only those of its triangles whose centroid lies in that box.
    #[arg(long, value_name = "NAME")]
    pub object_mesh: Option<String>,
    /// The view cell: `box:x0,y0,z0,x1,y1,z1`, or `shaft:ax,ay,az,dx,dy,dz,angle_deg,min_distance`
    /// (apex, direction from the apex toward the viewer, full apex angle, the cell's distance
    /// from the apex).
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
    pub view_cell: String,
    /// Texels across the impostor. Default: Schaufler's rule (a texel of the object's near face
    /// subtends α from the nearest viewpoint of the cell).
    #[arg(long)]
    pub resolution: Option<u32>,
    /// Horizontal field of view of the output view in degrees (α = its edge pixel).
    #[arg(long, conflicts_with = "alpha_deg")]
    pub output_fov: Option<f64>,
    /// Width of the output view in pixels.
    #[arg(long, conflicts_with = "alpha_deg")]
    pub output_width: Option<u32>,
    /// Allowed parallax angle α in degrees instead of an output view.
    #[arg(long, allow_hyphen_values = true)]
    pub alpha_deg: Option<f64>,
    /// How the macro-textures are stored: png, bc7 or bc1 (as `lemi bake`).
    #[arg(long, default_value = "png", value_parser = crate::cmd_bake::parse_texture_format)]
    pub texture_format: TextureFormat,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The triangles of the meshes `meshes` of `scene` whose centroid lies in `region` (all of them
/// without one).
fn select(scene: &Scene, meshes: std::ops::Range<usize>, region: Option<&Aabb>) -> Vec<TriRef> {
    let mut out = Vec::new();
    for (m, mesh) in scene.meshes.iter().enumerate() {
        if !meshes.contains(&m) {
            continue;
        }
        for t in 0..mesh.triangle_count() {
            let keep = match region {
                None => true,
                Some(r) => {
                    let c = mesh
                        .triangle(t)
                        .iter()
                        .fold(DVec3::ZERO, |a, v| a + v.as_dvec3())
                        / 3.0;
                    r.contains(c)
                }
            };
            if keep {
                out.push(TriRef {
                    mesh: m as u32,
                    tri: t as u32,
                });
            }
        }
    }
    out
}

/// The flag an object-setup error is about.
fn flag_of(e: &ObjectError) -> &'static str {
    match e {
        ObjectError::ViewCell(_) => "--view-cell",
        ObjectError::Object(_) => "--object",
        ObjectError::Overlap(_) => "--view-cell/--object",
        ObjectError::Placement(_) => "--view-cell/--object/--resolution/--output-width",
    }
}

pub fn run(args: Args) -> Result<()> {
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    let cell = ObjectViewCell::parse(&args.view_cell).context("--view-cell")?;
    let (alpha, fov, width) = alpha_of(args.alpha_deg, args.output_fov, args.output_width)?;
    if let Some(r) = args.resolution {
        let range = lemi_core::bundle::MIN_RESOLUTION..=lemi_core::bundle::MAX_RESOLUTION;
        if !range.contains(&r) {
            bail!(
                "--resolution must be between {} and {} texels, got {r}",
                range.start(),
                range.end()
            );
        }
    }
    let sources = absolute_sources(&args.scene.scenes);
    let scene_args = SceneArgs {
        scenes: sources.clone(),
        up: args.scene.up,
    };
    let (scene, report, load_seconds) = load_scene_with_report(&scene_args, args.json)?;
    let meshes = match &args.object_mesh {
        None => 0..scene.meshes.len(),
        Some(name) => {
            let parts: Vec<_> = report.parts.iter().filter(|p| p.is_named(name)).collect();
            match parts[..] {
                [part] => part.meshes.clone(),
                [] => bail!(
                    "--object-mesh: no scene input is named `{name}` (inputs: {})",
                    report
                        .parts
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                _ => bail!(
                    "--object-mesh: `{name}` names {} scene inputs ({}); give its path",
                    parts.len(),
                    parts
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        }
    };
    let object = select(&scene, meshes, args.object.as_ref());
    if object.is_empty() {
        bail!(
            "--object/--object-mesh: no triangle of the scene has its centroid in the box {}",
            args.object
                .map(|b| format!("{:?} to {:?}", b.min.to_array(), b.max.to_array()))
                .unwrap_or_default()
        );
    }
    let bounds = object_bounds(&scene, &object);
    let setup = ObjectSetup::new(cell, bounds, args.resolution, alpha)
        .map_err(|e| anyhow::anyhow!("{}: {e}", flag_of(&e)))?;
    if !(lemi_core::bundle::MIN_RESOLUTION..=lemi_core::bundle::MAX_RESOLUTION)
        .contains(&setup.params.res)
    {
        bail!(
            "Schaufler's rule asks for {} texels across the impostor, outside {}..={}; give \
             --resolution, or a coarser output view (--output-width)",
            setup.params.res,
            lemi_core::bundle::MIN_RESOLUTION,
            lemi_core::bundle::MAX_RESOLUTION
        );
    }
    let placement = setup
        .place()
        .map_err(|e| anyhow::anyhow!("{}: {e}", flag_of(&e)))?;
    let base = BakeParams {
        cell_size: 1.0,
        cell_height: None,
        resolution: setup.params.res,
        target: LayerTarget::Layers(1),
        faces: vec![Face::PosZ],
        alpha,
        output_fov_deg: fov,
        output_width: width,
        micro_grid: 8,
        micro_threshold: 0.6,
        layering: Default::default(),
        texture_format: args.texture_format,
    };
    let params = object_params(&setup, placement.layers.len(), &base);
    params
        .validate()
        .map_err(|e| anyhow::anyhow!("{e} (the object's setup)"))?;
    let fingerprint = lemi_scene::fingerprint(&sources, args.scene.up.into())
        .context("fingerprinting the scene")?;
    let gpu = Gpu::new(backend)?;
    let bar = if args.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new_spinner()
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} {elapsed:>4} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let t = Instant::now();
    let baked = bake_object(&gpu, &scene, &object, &setup, params.clone(), |stage| {
        bar.set_message(format!("object impostor: {stage}"))
    });
    bar.finish_and_clear();
    let mut baked =
        baked.with_context(|| format!("baking the object impostor into {}", args.out.display()))?;
    let bake_seconds = t.elapsed().as_secs_f64();
    let scene_ref = SceneRef {
        sources,
        up: match args.scene.up {
            UpArg::Y => "y".into(),
            UpArg::Z => "z".into(),
        },
        fingerprint,
        triangles: scene.triangle_count(),
    };
    let (_, cell_bytes) = write_object_bundle(&args.out, scene_ref, &params, &mut baked)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let p = &setup.params;
    let header = &baked.file.header;
    let stats = &header.stats;
    let layers: Vec<serde_json::Value> = baked
        .placement
        .layers
        .iter()
        .map(|l| {
            json!({
                "t": l.distance,
                "near_border": l.near_border,
                "far_border": l.far_border,
                "from_reference_viewpoint": l.distance + p.s,
                "bound_by": l.bound_by,
            })
        })
        .collect();
    if args.json {
        let out = json!({
            "bundle": args.out,
            "view_cell": setup.cell,
            "object_bounds": [bounds.min.to_array(), bounds.max.to_array()],
            "object_triangles": baked.object_triangles,
            "geometry_triangles": baked.file.near.len(),
            "reference_viewpoint": setup.frame.origin.to_array(),
            "axis": setup.frame.forward.to_array(),
            "s": p.s,
            "t0": p.t0,
            "object_depth": p.depth,
            "object_size": p.size,
            "resolution": p.res,
            "alpha_deg": p.alpha.to_degrees(),
            "output_fov_deg": fov,
            "output_width": width,
            "layer_count": layers.len(),
            "single_layer_beyond": if baked.placement.single_layer_beyond.is_finite() { Some(baked.placement.single_layer_beyond) } else { None },
            "layers": layers,
            "quads": header.quads.len(),
            "macro_textures": header.macros.len(),
            "texture_format": args.texture_format.name(),
            "texture_bytes": stats.texture_bytes(),
            "cell_bytes": cell_bytes,
            "load_seconds": load_seconds,
            "bake_seconds": bake_seconds,
            "stage_seconds": stats.seconds.iter().map(|(k, v)| (k.clone(), json!(v))).collect::<serde_json::Map<_, _>>(),
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "object     {} triangles, box {:?} to {:?}; {} triangles stay geometry",
        baked.object_triangles,
        bounds.min.to_array(),
        bounds.max.to_array(),
        baked.file.near.len()
    );
    println!(
        "view cell  {}; axis {:?}, reference viewpoint {:?} (s = {:.3} m), object from t0 = {:.3} m, {:.3} m deep",
        setup.cell.describe(),
        setup.frame.forward.to_array(),
        setup.frame.origin.to_array(),
        p.s,
        p.t0,
        p.depth
    );
    println!(
        "layers     {} at t = {} m ({}² texels, α = {:.4}°)",
        layers.len(),
        baked
            .placement
            .layers
            .iter()
            .map(|l| format!("{:.2}", l.distance))
            .collect::<Vec<_>>()
            .join(", "),
        p.res,
        p.alpha.to_degrees()
    );
    println!(
        "output     {} quads in {} macro-textures ({}), cell file {}",
        header.quads.len(),
        header.macros.len(),
        args.texture_format.name(),
        human(cell_bytes as f64)
    );
    println!("time       load {load_seconds:.1} s, bake {bake_seconds:.1} s");
    println!("wrote      {}", args.out.display());
    Ok(())
}
