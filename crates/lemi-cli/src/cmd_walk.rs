//! `lemi walk BUNDLE (--auto | --path P)`: headless replay of a camera path through a baked region
//! (GI 2002 sec. 3 and 6, Figs. 8-9), with streaming impostors through a far-field strategy and
//! then with all geometry, unculled and geometry-culled (frustum culled over Morton-ordered
//! clusters, the baseline speed-ups are quoted against; [`lemi_walk::walk`] does all three, the
//! impostor pass paced in real time). Writes
//! `frames.csv`, `summary.json`, `plot.png` and `path.json`.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use lemi_gpu::{BackendChoice, Gpu, GpuMaterials};
use lemi_runtime::{StallPolicy, StreamerOptions};
use lemi_strategy::StrategyContext;
use lemi_walk::{auto_path, CameraPath, WalkEvent, WalkOptions};

/// Replay a camera path with streaming impostors and with all geometry; frame times, plots.
#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("path_source").required(true).args(["auto", "path"])))]
pub struct Args {
    /// The bundle directory, or a directory of portal bundles (`portal-K`, from
    /// `lemi bake-object --portal all`).
    pub bundle: PathBuf,
    /// Generate a walkthrough of every baked cell plus a flyover inside the baked region.
    #[arg(long)]
    pub auto: bool,
    /// Replay this camera path (`lemi-path` JSON, as `lemi view` records it).
    #[arg(long, value_name = "PATH.json")]
    pub path: Option<PathBuf>,
    /// Output size `WIDTHxHEIGHT`.
    #[arg(long, value_parser = lemi_core::camera::parse_size, default_value = "1280x720")]
    pub size: (u32, u32),
    /// Horizontal field of view in degrees; default: the bake's output view (60° without one).
    #[arg(long)]
    pub fov: Option<f64>,
    /// Walking speed of `--auto` (m/s).
    #[arg(long, default_value_t = 1.4)]
    pub walk_speed: f64,
    /// Flying speed of `--auto` (m/s).
    #[arg(long, default_value_t = 10.0)]
    pub fly_speed: f64,
    /// Frames per second of `--auto`.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Output directory (frames.csv, summary.json, plot.png, path.json); default BUNDLE/walk.
    #[arg(short = 'o', long = "out")]
    pub out: Option<PathBuf>,
    /// Also write every Nth impostor frame as PNG into this directory.
    #[arg(long)]
    pub frames_dir: Option<PathBuf>,
    /// With --frames-dir: write every Nth frame.
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..))]
    pub every: u64,
    /// Skip both all-geometry replays (unculled and geometry-culled).
    #[arg(long)]
    pub no_geometry: bool,
    /// Skip the unculled all-geometry replay (keep the geometry-culled one).
    #[arg(long)]
    pub no_unculled: bool,
    /// Skip the geometry-culled replay (keep the unculled one).
    #[arg(long)]
    pub no_culled: bool,
    /// Cell cache budget in MiB (CPU + GPU bytes of streamed cells).
    #[arg(long, default_value_t = 512)]
    pub cache_mb: u64,
    /// Texture upload budget per frame in KiB.
    #[arg(long, default_value_t = 8192)]
    pub upload_kb: u64,
    /// Highest observer speed the prefetching plans for (m/s).
    #[arg(long, default_value_t = 12.0)]
    pub max_speed: f64,
    /// When the current cell is not ready: wait for it (block) or draw all geometry for that
    /// frame (fallback). Both count a stall.
    #[arg(long, value_enum, default_value = "block")]
    pub stall: StallArg,
    /// The scene, if it moved since the bake (checked against the bundle's fingerprint).
    #[arg(long = "scene", value_name = "SCENE")]
    pub scene_override: Vec<String>,
    /// Far-field strategy: lemi, cubemap or equidistant (the strategy the bundle was baked for;
    /// default), warp or dynamic (built at run time from the bundle's cells and near lists).
    #[arg(long)]
    pub strategy: Option<String>,
    /// An object impostor's bundle (`lemi bake-object`, repeatable) drawn with the bundle's cells:
    /// in every cell its view cell holds whole, the object is drawn as its impostor instead of its
    /// triangles; elsewhere as geometry.
    #[arg(long, value_name = "OBJECT_BUNDLE")]
    pub with_object: Vec<PathBuf>,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum StallArg {
    Block,
    Fallback,
}

pub fn run(args: Args) -> Result<()> {
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    for (flag, v) in [
        ("--walk-speed", args.walk_speed),
        ("--fly-speed", args.fly_speed),
        ("--max-speed", args.max_speed),
        ("--fps", args.fps),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{flag} must be a positive number (got {v})");
        }
    }
    if let Some(f) = args.fov {
        if !(f.is_finite() && f > 0.0 && f < 180.0) {
            bail!("--fov must be in (0, 180) degrees (got {f})");
        }
    }
    let portals = portal_bundles(&args.bundle)?;
    if !portals.is_empty() && !args.with_object.is_empty() {
        bail!(
            "--with-object: {} holds portal impostors, which are drawn on their own",
            args.bundle.display()
        );
    }
    if !portals.is_empty() && args.strategy.is_some() {
        bail!(
            "--strategy: {} holds portal impostors, drawn as they were baked",
            args.bundle.display()
        );
    }
    let first = portals.first().unwrap_or(&args.bundle);
    let (bundle, scene) = crate::bundle_view::open(first, &args.scene_override, args.json)?;
    let manifest = bundle.manifest().clone();
    let mut others = Vec::new();
    for dir in portals.iter().skip(1) {
        let b = lemi_core::bundle::Bundle::open(dir)
            .with_context(|| format!("opening the portal bundle {}", dir.display()))?;
        if b.manifest().scene.fingerprint != manifest.scene.fingerprint {
            bail!(
                "{} was baked from another scene than {}",
                dir.display(),
                first.display()
            );
        }
        others.push(b);
    }
    let path = match &args.path {
        Some(p) => CameraPath::read(p)?,
        None if !portals.is_empty() => {
            let setups: Vec<_> = std::iter::once(&bundle)
                .chain(&others)
                .filter_map(|b| b.manifest().object.clone())
                .collect();
            portal_path(&setups, args.walk_speed, args.fps).context("--auto")?
        }
        None => {
            let baked: Vec<_> = (manifest.cells.iter())
                .filter_map(|c| manifest.grid.cell_of(c.id).ok())
                .collect();
            auto_path(
                &manifest.grid,
                &baked,
                args.walk_speed,
                args.fly_speed,
                args.fps,
            )
            .context("--auto")?
        }
    };
    let out = args.out.clone().unwrap_or_else(|| args.bundle.join("walk"));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    if let Some(d) = &args.frames_dir {
        std::fs::create_dir_all(d)
            .with_context(|| format!("creating --frames-dir {}", d.display()))?;
    }
    path.write(&out.join("path.json"))?;

    let gpu = Arc::new(Gpu::new(backend)?);
    let scene = Arc::new(scene);
    let materials = Arc::new(
        GpuMaterials::upload(&gpu, &scene.materials, &scene.textures)
            .context("uploading the scene's materials")?,
    );
    let ctx = StrategyContext {
        gpu: gpu.clone(),
        bundle: bundle.clone(),
        scene: scene.clone(),
        materials,
    };
    let (kind, mut strategy): (_, Box<dyn lemi_strategy::Strategy>) = if portals.is_empty() {
        let kind = crate::strategy::kind_for(&manifest, args.strategy.as_deref())?;
        let mut streamer =
            streamer_options(args.cache_mb, args.upload_kb, args.max_speed, args.stall);
        if !args.with_object.is_empty() {
            if !kind.is_layered() {
                bail!("--with-object: object impostors are drawn with layered bundles, not {kind}");
            }
            streamer.loader.objects =
                Arc::new(crate::cmd_render::object_cells(&bundle, &args.with_object)?);
        }
        (kind, lemi_strategy::open(&ctx, kind, streamer)?)
    } else {
        let mut all = vec![bundle.clone()];
        all.extend(others);
        let s =
            lemi_strategy::portal::PortalStrategy::new(&gpu, &scene, ctx.materials.clone(), &all)
                .context("uploading the portal impostors")?;
        (lemi_strategy::StrategyKind::Lemi, Box::new(s))
    };

    let unculled = !args.no_geometry && !args.no_unculled;
    let culled = !args.no_geometry && !args.no_culled;
    let n = path.frame_count();
    let bar = if args.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(n * (1 + u64::from(unculled) + u64::from(culled)))
    };
    bar.set_style(
        ProgressStyle::with_template("{elapsed:>4} [{bar:30}] {pos}/{len} frames  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    // only the frames written to --frames-dir are read back; the rest are timed as a runtime
    // draws them
    let keep_frame = |index: u64| args.frames_dir.is_some() && index % args.every == 0;
    let mut observe = |event: WalkEvent<'_>| -> Result<(), String> {
        match event {
            WalkEvent::Preloading => bar.set_message("preloading the first cells"),
            WalkEvent::Impostor { record, frame } => {
                if let (Some(d), Some(frame)) = (&args.frames_dir, frame) {
                    // warp gives every frame's pixels; only the kept ones are written
                    if keep_frame(record.frame) {
                        let p = d.join(format!("frame-{:06}.png", record.frame));
                        image::RgbaImage::from_raw(frame.width, frame.height, frame.rgba.clone())
                            .ok_or("frame has the wrong size")?
                            .save(&p)
                            .map_err(|e| format!("writing {}: {e}", p.display()))?;
                    }
                }
                bar.inc(1);
                let cell = record.cell.as_deref().unwrap_or("-");
                bar.set_message(format!("impostors, cell {cell}"));
            }
            WalkEvent::Geometry { record } => {
                bar.inc(1);
                bar.set_message(match record.mode {
                    lemi_walk::Mode::Culled => "all geometry, culled",
                    _ => "all geometry",
                });
            }
        }
        Ok(())
    };
    let (w, h) = args.size;
    let fov_x = args.fov.or(manifest.params.output_fov_deg).unwrap_or(60.0);
    let mut run = lemi_walk::walk(
        strategy.as_mut(),
        &path,
        WalkOptions {
            size: args.size,
            fov_x_deg: fov_x,
            geometry: unculled,
            culled,
            observer: Some(&mut observe),
            keep_frame: Some(&keep_frame),
            ..WalkOptions::new(&gpu, &scene, &manifest.grid)
        },
    )?;
    drop(strategy);
    bar.finish_and_clear();
    run.summary.out = Some(out.clone());
    run.write_files(&out)?;
    let s = &run.summary;
    if args.json {
        println!("{}", serde_json::to_string_pretty(s)?);
        return Ok(());
    }
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    let ms = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.1} ms"));
    let times = |x: Option<f64>| x.map_or("-".to_string(), |s| format!("{s:.1}x"));
    let st = &s.stats;
    println!("lemi walk");
    println!("adapter    {}", s.adapter);
    println!(
        "path       {} frames at {} fps ({:.1} s), {w}x{h}, {fov_x}° horizontal",
        st.frames,
        path.fps,
        path.duration()
    );
    println!(
        "{:<10} median {}, p99 {}; {} cell switches, {} stalls, {} loads, {} evictions, {} regenerations, peak cache {:.1} MB",
        kind.name(),
        ms(st.impostor_median_ms),
        ms(st.impostor_p99_ms),
        st.cell_switches,
        st.stalls,
        s.loads,
        s.evictions,
        s.regenerations,
        s.peak_cache_bytes as f64 / 1e6
    );
    if culled {
        println!(
            "culled     median {}, p99 {}, {:.0} triangles/frame; speed-up of the median {}",
            ms(st.culled_median_ms),
            ms(st.culled_p99_ms),
            st.culled_mean_triangles.unwrap_or(0.0),
            times(st.speedup_culled_median)
        );
    }
    if unculled {
        println!(
            "unculled   median {}, p99 {}; speed-up of the median {}",
            ms(st.geometry_median_ms),
            ms(st.geometry_p99_ms),
            times(st.speedup_median)
        );
    }
    if st.impostor_gpu_median_ms.is_some()
        || st.geometry_gpu_median_ms.is_some()
        || st.culled_gpu_median_ms.is_some()
    {
        println!(
            "gpu time   median {} ({}), {} (geometry-culled), {} (unculled); speed-up {} (culled), {} (unculled)",
            ms(st.impostor_gpu_median_ms),
            kind.name(),
            ms(st.culled_gpu_median_ms),
            ms(st.geometry_gpu_median_ms),
            times(st.speedup_culled_gpu_median),
            times(st.speedup_gpu_median)
        );
    }
    if s.slower_than_real_time_frames > 0 {
        println!(
            "note       {} frames took longer than the path's frame interval: the loader had more time than in real time",
            s.slower_than_real_time_frames
        );
    }
    println!(
        "wrote      {} (frames.csv, summary.json, plot.png, path.json)",
        out.display()
    );
    Ok(())
}

/// The portal bundles in `dir` (`portal-0`, `portal-1`, … in order), or none when `dir` is a
/// bundle itself or holds no `portal-K` bundle.
fn portal_bundles(dir: &std::path::Path) -> Result<Vec<PathBuf>> {
    if dir.join("manifest.json").exists() || !dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut found: Vec<(u32, PathBuf)> = Vec::new();
    let entries = std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))?;
    for e in entries {
        let e = e.with_context(|| format!("reading {}", dir.display()))?;
        let name = e.file_name().to_string_lossy().to_string();
        if let Some(k) = name
            .strip_prefix("portal-")
            .and_then(|k| k.parse::<u32>().ok())
        {
            if e.path().join("manifest.json").exists() {
                found.push((k, e.path()));
            }
        }
    }
    found.sort();
    Ok(found.into_iter().map(|(_, p)| p).collect())
}

/// A walk through portal impostors' view cells: for each, from the far end of its shaft (or 4
/// near-border distances back when unbounded) toward its near end, along its axis at `speed`,
/// looking out through the opening; a jump of one frame to the next.
fn portal_path(
    setups: &[lemi_core::object_cell::ObjectSetup],
    speed: f64,
    fps: f64,
) -> Result<CameraPath> {
    let mut keys = Vec::new();
    let mut t = 0.0;
    for setup in setups {
        let lemi_core::object_cell::ObjectViewCell::Shaft {
            apex,
            dir,
            min_distance,
            max_distance,
            ..
        } = setup.cell
        else {
            bail!("only portal impostors (shaft view cells) have an automatic walk; give --path");
        };
        let far = max_distance.unwrap_or(4.0 * min_distance) * 0.98;
        let near = min_distance * 1.02;
        if far <= near {
            continue;
        }
        let yaw = (-dir.x).atan2(dir.z).to_degrees();
        for (k, along) in [far, near].into_iter().enumerate() {
            if k == 1 {
                t += (far - near) / speed;
            } else if !keys.is_empty() {
                t += 1.0 / fps;
            }
            let eye = apex + dir * along;
            keys.push(lemi_walk::Key {
                t,
                eye: eye.to_array(),
                yaw_deg: yaw,
                pitch_deg: 0.0,
            });
        }
    }
    let path = CameraPath::new(fps, keys);
    path.validate().context("the portal walk")?;
    Ok(path)
}

/// The streaming runtime's options from the flags of `walk` and `view`: cache budget (MiB),
/// upload budget per frame (KiB), the highest speed prefetching plans for, the stall policy.
pub fn streamer_options(
    cache_mb: u64,
    upload_kb: u64,
    max_speed: f64,
    stall: StallArg,
) -> StreamerOptions {
    StreamerOptions {
        cache_budget_bytes: cache_mb.saturating_mul(1 << 20),
        upload_budget_bytes_per_frame: upload_kb.saturating_mul(1 << 10),
        max_speed,
        stall_policy: match stall {
            StallArg::Block => StallPolicy::Block,
            StallArg::Fallback => StallPolicy::Fallback,
        },
        ..Default::default()
    }
}
