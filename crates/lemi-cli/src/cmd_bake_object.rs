//! `lemi bake-object SCENE… -o BUNDLE --view-cell box:…|shaft:… [--object x0,y0,z0,x1,y1,z1]
//! | --object-mesh NAME]`:
//! bakes the layered impostor of one object for a box- or shaft-shaped view cell
//! (TR-186-2-02-04 sec. 2.1-2.2; [`lemi_core::object_cell`], [`lemi_bake::object_bake`]). Without
//! `--object` the whole scene is the object. The bundle holds one cell whose near list is
//! everything else, so `lemi render`/`lemi eval` draw the object as impostor and the rest as
//! geometry, and the object as geometry from outside its view cell.
//!
//! `--portal cx,cy,cz,nx,ny,nz,width,height` (or `--portal all`: every opening of a
//! `builtin:interior` scene, one bundle each under `BUNDLE/portal-K`) bakes a portal impostor
//! instead (TR sec. 3): the view cell is the opening's shaft ([`Portal::view_cell`],
//! `--portal-angle`, `--portal-distance`), the object everything wholly in its frustum at least
//! `--near` beyond the opening ([`Portal::select`]) except the building (`--keep`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use indicatif::{ProgressBar, ProgressStyle};
use lemi_bake::object_bake::{bake_object, object_bake_params, write_object_bundle};
use lemi_core::bundle::SceneRef;
use lemi_core::classify::TriRef;
use lemi_core::compress::TextureFormat;
use lemi_core::enclosure::Enclosure;
use lemi_core::object_cell::{object_bounds, ObjectError, ObjectSetup, ObjectViewCell, Portal};
use lemi_core::{Aabb, Scene};
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
    #[arg(long, value_parser = crate::cmd_bake::parse_region, allow_hyphen_values = true, conflicts_with = "portal")]
    pub object: Option<Aabb>,
    /// The object: the triangles of one scene input, named by its path as given, its file name
    /// or its file name without extensions (`dragon` for `models/dragon.ply.gz`); with
    /// --object, only those of its triangles whose centroid lies in that box.
    #[arg(long, value_name = "NAME", conflicts_with = "portal")]
    pub object_mesh: Option<String>,
    /// The view cell: `box:x0,y0,z0,x1,y1,z1`, or `shaft:ax,ay,az,dx,dy,dz,angle_deg,min_distance`
    /// (apex, direction from the apex toward the viewer, full apex angle, the cell's distance
    /// from the apex).
    #[arg(
        long,
        value_name = "SPEC",
        allow_hyphen_values = true,
        required_unless_present = "portal",
        conflicts_with = "portal"
    )]
    pub view_cell: Option<String>,
    /// A portal impostor: the outside seen through the opening `cx,cy,cz,nx,ny,nz,width,height`
    /// (centre, outward normal, width along the wall, height), or `all`: one bundle per opening
    /// of a `builtin:interior` scene, in `BUNDLE/portal-K`.
    #[arg(long, value_name = "SPEC|all", allow_hyphen_values = true)]
    pub portal: Option<String>,
    /// Full apex angle of a portal's shaft cell, in degrees.
    #[arg(long, default_value_t = 90.0, requires = "portal")]
    pub portal_angle: f64,
    /// Distance of a portal's shaft cell from the opening (m): nearer, the geometry is drawn.
    #[arg(long, default_value_t = 1.5, requires = "portal")]
    pub portal_distance: f64,
    /// Farthest distance of a portal's shaft cell from the opening (m): the room's far side.
    /// Default with `--portal all`: the far side of the opening's room; otherwise unbounded (the
    /// TR's shaft, which needs many more layers: from far back in an endless shaft every depth
    /// shows parallax).
    #[arg(long, requires = "portal")]
    pub portal_max_distance: Option<f64>,
    /// What a portal impostor leaves to geometry beyond the opening (m). Default: the shaft
    /// cell's width at its far end (at 4 × --portal-distance when unbounded): the impostor
    /// starts one cell width beyond the opening.
    #[arg(long, requires = "portal")]
    pub near: Option<f64>,
    /// The room behind an opening given with --portal: its view cell is the part of the shaft
    /// inside this box `x0,y0,z0,x1,y1,z1` (default with `--portal all`: the opening's room;
    /// otherwise the whole shaft).
    #[arg(long, value_parser = crate::cmd_bake::parse_region, allow_hyphen_values = true, requires = "portal")]
    pub portal_room: Option<Aabb>,
    /// Triangles wholly inside this box `x0,y0,z0,x1,y1,z1` stay geometry (the building the
    /// rooms are in). Default with `--portal all`: the built-in building's box.
    #[arg(long, value_parser = crate::cmd_bake::parse_region, allow_hyphen_values = true, requires = "portal")]
    pub keep: Option<Aabb>,
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
    /// How the macro-textures are stored: bc1 (the default), bc7 or png (as `lemi bake`).
    #[arg(
        long,
        default_value = crate::cmd_bake::DEFAULT_TEXTURE_FORMAT.name(),
        value_parser = crate::cmd_bake::parse_texture_format
    )]
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

/// One impostor to bake: where it goes, its setup and the triangles it replaces.
struct Job {
    out: PathBuf,
    /// `object` or `portal K`, for messages.
    label: String,
    setup: ObjectSetup,
    object: Vec<TriRef>,
    bounds: Aabb,
}

/// The openings `--portal` names, each with the default of `--portal-max-distance` (the far
/// side of its room, for the built-in ones), the default of `--keep` for them, and, for `all`,
/// the building they are every opening of.
type PortalList = (Vec<(Portal, Option<f64>)>, Option<Aabb>, Option<Enclosure>);

fn portals_of(spec: &str, sources: &[String]) -> Result<PortalList> {
    if spec.trim() != "all" {
        return Ok((
            vec![(Portal::parse(spec).context("--portal")?, None)],
            None,
            None,
        ));
    }
    let layout = match sources {
        [one] => lemi_scene::builtin::BuiltinSpec::parse(one)
            .ok()
            .and_then(|s| lemi_scene::builtin::interior_layout(&s)),
        _ => None,
    };
    let Some(layout) = layout else {
        bail!(
            "--portal all: only a builtin:interior scene knows its openings (the scene is {}); \
             give each opening as --portal cx,cy,cz,nx,ny,nz,width,height",
            sources.join(" ")
        );
    };
    let portals: Vec<(Portal, Option<f64>)> = layout
        .portals
        .iter()
        .map(|p| {
            // the layout's f32 values as the decimals they were written as (to the micrometre)
            let m = |x: f32| (f64::from(x) * 1e6).round() / 1e6 + 0.0;
            let room = layout.rooms.get(p.room).map(|r| {
                Aabb::new(
                    DVec3::from_array(r.min.map(m)),
                    DVec3::from_array(r.max.map(m)),
                )
            });
            let portal = Portal {
                center: DVec3::from_array(p.center.map(m)),
                outward: DVec3::from_array(p.outward.map(m)),
                half: [0.5 * m(p.width), 0.5 * m(p.height)],
                room,
            };
            // the farthest corner of the room's walkable box behind the opening
            let far = room.map(|room| {
                lemi_core::object_cell::box_corners(&room)
                    .iter()
                    .map(|c| (portal.center - *c).dot(portal.outward))
                    .fold(0.0, f64::max)
            });
            (portal, far)
        })
        .collect();
    // every opening of the building is baked: a renderer may cull the outside to them
    let enclosure = layout.enclosure();
    enclosure
        .validate()
        .map_err(|e| anyhow::anyhow!("--portal all: the building's layout: {e}"))?;
    Ok((portals, Some(enclosure.bounds), Some(enclosure)))
}

/// The jobs of `--portal`: one per opening, each replacing what lies wholly in its frustum beyond
/// `--near` (default `4 s − d`, see `Args::near`).
fn portal_jobs(args: &Args, spec: &str, scene: &Scene, alpha: f64) -> Result<Vec<Job>> {
    let (portals, default_keep, enclosure) = portals_of(spec, &args.scene.scenes)?;
    let keep = args.keep.or(default_keep).unwrap_or(Aabb::EMPTY);
    if let Some(n) = args.near {
        if !(n.is_finite() && n >= 0.0) {
            bail!("--near must be a distance of 0 m or more, got {n}");
        }
    }
    let (angle, d) = (args.portal_angle, args.portal_distance);
    let many = portals.len() > 1 || spec.trim() == "all";
    let mut jobs = Vec::new();
    for (k, (portal, room_far)) in portals.iter().enumerate() {
        let max = args.portal_max_distance.or(*room_far);
        let portal = &Portal {
            room: args.portal_room.or(portal.room),
            ..*portal
        };
        let label = if many {
            format!("portal {k}")
        } else {
            "portal".to_string()
        };
        let bad = |e: ObjectError| {
            let flag = match e {
                ObjectError::ViewCell(_) => {
                    "--portal/--portal-angle/--portal-distance/--portal-max-distance"
                }
                _ => "--portal/--near/--keep",
            };
            anyhow::anyhow!("{flag}: {label} ({}): {e}", portal.describe())
        };
        portal.view_cell(angle, d, max).map_err(bad)?;
        let frame = portal.frame(angle, d).map_err(bad)?;
        let tan = (0.5 * angle.to_radians()).tan();
        let near = args.near.unwrap_or(2.0 * tan * max.unwrap_or(4.0 * d));
        let object = portal.select(&frame, scene, &keep, near);
        if object.is_empty() {
            bail!(
                "--portal: nothing lies wholly in the frustum of {label} ({}) {near} m or more \
                 beyond it (outside --keep): there is nothing to replace",
                portal.describe()
            );
        }
        let bounds = object_bounds(scene, &object);
        let mut setup =
            ObjectSetup::through_portal(portal, angle, d, max, bounds, args.resolution, alpha)
                .map_err(bad)?;
        setup.enclosure = enclosure.clone();
        let out = if many {
            args.out.join(format!("portal-{k}"))
        } else {
            args.out.clone()
        };
        jobs.push(Job {
            out,
            label,
            setup,
            object,
            bounds,
        });
    }
    Ok(jobs)
}

/// The job of `--view-cell` with `--object`/`--object-mesh`.
fn object_job(
    args: &Args,
    view_cell: &str,
    scene: &Scene,
    report: &lemi_scene::import::ImportReport,
    alpha: f64,
) -> Result<Job> {
    let cell = ObjectViewCell::parse(view_cell).context("--view-cell")?;
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
    let object = select(scene, meshes, args.object.as_ref());
    if object.is_empty() {
        bail!(
            "--object/--object-mesh: no triangle of the scene has its centroid in the box {}",
            args.object
                .map(|b| format!("{:?} to {:?}", b.min.to_array(), b.max.to_array()))
                .unwrap_or_default()
        );
    }
    let bounds = object_bounds(scene, &object);
    let setup = ObjectSetup::new(cell, bounds, args.resolution, alpha)
        .map_err(|e| anyhow::anyhow!("{}: {e}", flag_of(&e)))?;
    Ok(Job {
        out: args.out.clone(),
        label: "object".into(),
        setup,
        object,
        bounds,
    })
}

pub fn run(args: Args) -> Result<()> {
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    let (alpha, fov, width) = alpha_of(args.alpha_deg, None, args.output_fov, args.output_width)?;
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
    if let Some(spec) = &args.view_cell {
        ObjectViewCell::parse(spec).context("--view-cell")?;
    }
    if let Some(spec) = &args.portal {
        if spec.trim() != "all" {
            Portal::parse(spec).context("--portal")?;
        }
        for (flag, v) in [
            ("--portal-angle", args.portal_angle),
            ("--portal-distance", args.portal_distance),
            (
                "--portal-max-distance",
                args.portal_max_distance.unwrap_or(1.0),
            ),
        ] {
            if !v.is_finite() {
                bail!("{flag} must be a finite number, got {v}");
            }
        }
    }
    let sources = absolute_sources(&args.scene.scenes);
    let scene_args = SceneArgs {
        scenes: sources.clone(),
        up: args.scene.up,
    };
    let (scene, report, load_seconds) = load_scene_with_report(&scene_args, args.json)?;
    let jobs = match (&args.portal, &args.view_cell) {
        (Some(spec), _) => portal_jobs(&args, spec, &scene, alpha)?,
        (None, Some(cell)) => vec![object_job(&args, cell, &scene, &report, alpha)?],
        (None, None) => bail!("give --view-cell (an object impostor) or --portal"),
    };
    for job in &jobs {
        if !(lemi_core::bundle::MIN_RESOLUTION..=lemi_core::bundle::MAX_RESOLUTION)
            .contains(&job.setup.params.res)
        {
            bail!(
                "{}: Schaufler's rule asks for {} texels across the impostor, outside {}..={}; \
                 give --resolution, or a coarser output view (--output-width)",
                job.label,
                job.setup.params.res,
                lemi_core::bundle::MIN_RESOLUTION,
                lemi_core::bundle::MAX_RESOLUTION
            );
        }
    }
    let fingerprint = lemi_scene::fingerprint(&sources, args.scene.up.into())
        .context("fingerprinting the scene")?;
    let gpu = Gpu::new(backend)?;
    let scene_ref = SceneRef {
        sources,
        up: match args.scene.up {
            UpArg::Y => "y".into(),
            UpArg::Z => "z".into(),
        },
        fingerprint,
        triangles: scene.triangle_count(),
    };
    let mut reports = Vec::new();
    for (k, job) in jobs.iter().enumerate() {
        let r = bake_job(
            &args,
            job,
            &gpu,
            &scene,
            &scene_ref,
            (fov, width),
            (k, jobs.len()),
            load_seconds,
        )?;
        reports.push(r);
    }
    if args.json {
        let out = match &reports[..] {
            [one] if args.portal.as_deref().map(str::trim) != Some("all") => one.clone(),
            _ => serde_json::Value::Array(reports),
        };
        println!("{}", serde_json::to_string_pretty(&out)?);
    }
    Ok(())
}

/// Bakes and writes one job; prints its summary (unless `--json`) and returns its JSON report.
#[allow(clippy::too_many_arguments)]
fn bake_job(
    args: &Args,
    job: &Job,
    gpu: &Gpu,
    scene: &Scene,
    scene_ref: &SceneRef,
    (fov, width): (Option<f64>, Option<u32>),
    (k, of): (usize, usize),
    load_seconds: f64,
) -> Result<serde_json::Value> {
    let setup = &job.setup;
    let bounds = job.bounds;
    let placement = setup
        .place()
        .map_err(|e| anyhow::anyhow!("{}: {}: {e}", job.label, flag_of(&e)))?;
    let params = object_bake_params(
        setup,
        placement.layers.len(),
        (fov, width),
        args.texture_format,
    );
    params
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: {e} (the object's setup)", job.label))?;
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
    let what = if of > 1 {
        format!("{} ({}/{of})", job.label, k + 1)
    } else {
        job.label.clone()
    };
    let baked = bake_object(gpu, scene, &job.object, setup, params.clone(), |stage| {
        bar.set_message(format!("{what} impostor: {stage}"))
    });
    bar.finish_and_clear();
    let mut baked = baked.with_context(|| {
        format!(
            "baking the {} impostor into {}",
            job.label,
            job.out.display()
        )
    })?;
    let bake_seconds = t.elapsed().as_secs_f64();
    let (_, cell_bytes) = write_object_bundle(&job.out, scene_ref.clone(), &params, &mut baked)
        .with_context(|| format!("writing {}", job.out.display()))?;
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
    let report = json!({
        "bundle": job.out,
        "view_cell": setup.cell,
        "portal": setup.portal.map(|p| p.describe()),
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
    if args.json {
        return Ok(report);
    }
    if of > 1 {
        println!("--- {} of {of}: {}", k + 1, job.label);
    }
    if let Some(portal) = &setup.portal {
        println!("portal     {}", portal.describe());
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
    println!("wrote      {}", job.out.display());
    Ok(report)
}
