//! `lemi render SCENE… --eye x,y,z --look x,y,z --fov 60 --size 1280x720 -o out.png`: renders a
//! scene with the GPU reference renderer (`lemi-gpu`) and writes the image, optionally the depth.
//!
//! `lemi render BUNDLE --eye … [--compare]`: renders what the runtime shows from a viewpoint inside
//! a baked cell: the cell's near geometry plus its impostor quads (alpha test, depth test). With
//! `--compare` the image is reference | impostor | difference side by side.
//!
//! Camera coordinates are lemi's world (+Y up, after any `--up z` conversion of the input), the same
//! coordinates `lemi info` prints. The view direction is `--look` (a point), `--dir` (a vector) or
//! `--yaw/--pitch` (degrees; yaw 0 looks along −Z, 90 along +X); with none of them the camera looks
//! at the centre of the scene, and without `--eye` it is placed to frame the whole scene.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use glam::DVec3;
use lemi_core::camera::Camera;
use lemi_gpu::{BackendChoice, Frame, Gpu, GpuScene, RenderOptions, Renderer, UploadOptions};
use serde_json::json;

use crate::load::{load_scene, SceneArgs};

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Eye position `x,y,z` (metres). Default: framing the whole scene from above and in front.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point to look at, `x,y,z`. Default: the centre of the scene.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true, conflicts_with_all = ["dir", "yaw", "pitch"])]
    pub look: Option<DVec3>,
    /// View direction `x,y,z` instead of --look.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true, conflicts_with_all = ["yaw", "pitch"])]
    pub dir: Option<DVec3>,
    /// Heading in degrees instead of --look (0 looks along −Z, 90 along +X).
    #[arg(long, allow_hyphen_values = true)]
    pub yaw: Option<f64>,
    /// Pitch in degrees with --yaw (positive looks up, within ±90).
    #[arg(long, allow_hyphen_values = true)]
    pub pitch: Option<f64>,
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 60.0)]
    pub fov: f64,
    /// Image size `WIDTHxHEIGHT`.
    #[arg(long, value_parser = lemi_core::camera::parse_size, default_value = "1280x720")]
    pub size: (u32, u32),
    /// Near-plane distance in metres (the far plane is at infinity).
    #[arg(long, default_value_t = lemi_core::camera::DEFAULT_NEAR)]
    pub near: f64,
    /// Output image (.png; .jpg drops alpha).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Also write the depth (distance along the view axis): `.pfm` stores exact f32 metres
    /// (background +inf), `.png` a 16-bit grey image scaled from the nearest (white) to the
    /// farthest (black) drawn depth, background 0.
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// GPU backend: auto (WGPU_BACKEND if set, else Vulkan then GL), vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Background colour `r,g,b,a` (sRGB bytes).
    #[arg(long, value_parser = parse_rgba, default_value = "0,0,0,0")]
    pub clear: [u8; 4],
    /// Render this many frames and report the median render time (for benchmarks; the image is
    /// the same every time).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub frames: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// With a BUNDLE: how impostor pixels take their colour from the texels: `footprint` (the
    /// default: where a texel spans less than two pixels, the mean of the opaque texels over the
    /// pixel's footprint, so minified far quads do not shimmer) or `nearest` (the texel under the
    /// pixel's centre, exactly as baked). Coverage is the same in both.
    #[arg(long, value_enum, default_value = "footprint")]
    pub texel_filter: TexelFilterArg,
    /// With a BUNDLE: write reference | impostor | difference side by side (difference: black where
    /// equal, the amplified colour difference elsewhere, red at crack pixels as `lemi eval` counts
    /// them).
    #[arg(long)]
    pub compare: bool,
    /// With a BUNDLE: the scene to use instead of the manifest's sources (must be the same scene:
    /// checked against the bundle's fingerprint).
    #[arg(long = "scene", value_name = "SCENE")]
    pub scene_override: Vec<String>,
    /// With a BUNDLE: an object bundle (`lemi bake-object`, baked from the same scene) whose
    /// impostor replaces its object in the cell's near geometry while the eye lies in its view
    /// cell (repeatable).
    #[arg(long = "with-object", value_name = "OBJECT_BUNDLE")]
    pub with_object: Vec<PathBuf>,
}

fn parse_numbers(s: &str, n: usize) -> Result<Vec<f64>, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e}"))?;
    if v.len() != n || v.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "`{s}`: expected {n} finite comma-separated numbers"
        ));
    }
    Ok(v)
}

/// `x,y,z` (three finite numbers), for every command's point flags.
pub(crate) fn parse_vec3(s: &str) -> Result<DVec3, String> {
    let v = parse_numbers(s, 3)?;
    Ok(DVec3::new(v[0], v[1], v[2]))
}

fn parse_rgba(s: &str) -> Result<[u8; 4], String> {
    let v: Vec<u8> = s
        .split(',')
        .map(|p| p.trim().parse::<u8>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e} (expected r,g,b,a bytes)"))?;
    v.try_into()
        .map_err(|_| format!("`{s}`: expected four comma-separated bytes r,g,b,a"))
}

/// The camera from the flags, with defaults taken from the scene bounds.
fn camera(args: &Args, bounds: &lemi_core::Aabb) -> anyhow::Result<Camera> {
    let (w, h) = args.size;
    let (center, radius) = if bounds.is_empty() {
        (DVec3::ZERO, 1.0)
    } else {
        (bounds.center(), (0.5 * bounds.size().length()).max(1e-3))
    };
    let eye = match args.eye {
        Some(e) => e,
        None => {
            // Far enough that the bounding sphere fits the vertical field of view.
            let dist = radius / (0.5 * args.fov.clamp(1.0, 179.0).to_radians()).sin();
            center + DVec3::new(0.0, 0.45, 1.0).normalize() * dist
        }
    };
    let cam = if args.yaw.is_some() || args.pitch.is_some() {
        Camera::from_yaw_pitch(
            eye,
            args.yaw.unwrap_or(0.0),
            args.pitch.unwrap_or(0.0),
            args.fov,
            w,
            h,
        )
        .context("--yaw/--pitch/--fov/--size")?
    } else if let Some(d) = args.dir {
        Camera::new(eye, d, DVec3::Y, args.fov, w, h).context("--dir/--eye/--fov/--size")?
    } else {
        let target = args.look.unwrap_or(center);
        Camera::look_at(eye, target, DVec3::Y, args.fov, w, h)
            .context("--look/--eye/--fov/--size")?
    };
    cam.with_near(args.near).context("--near")
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    if args.scene.scenes.len() == 1 && crate::bundle_view::is_bundle(&args.scene.scenes[0]) {
        return run_bundle(args, backend);
    }
    if args.compare || !args.scene_override.is_empty() {
        bail!("--compare and --scene need a bundle directory (one with manifest.json) as input");
    }
    if let Some(d) = &args.depth {
        depth_kind(d)?;
    }
    let (scene, load_seconds) = load_scene(&args.scene, args.json)?;
    let cam = camera(&args, &scene.bounds)?;
    let gpu = Gpu::new(backend)?;
    let t = Instant::now();
    let gpu_scene = GpuScene::upload(&gpu, &scene, &UploadOptions::default())
        .context("uploading the scene to the GPU")?;
    let upload_seconds = t.elapsed().as_secs_f64();
    let renderer = Renderer::new(&gpu)?;
    let options = RenderOptions {
        clear: args.clear,
        ..Default::default()
    };
    let view = cam.view();
    let (frame, render_seconds) = render_timed(args.frames, || {
        renderer
            .render(&gpu_scene, &view, &options)
            .context("rendering")
    })?;
    save_rgba(&frame, &args.output)?;
    if let Some(d) = &args.depth {
        save_depth(&frame, d)?;
    }
    if args.json {
        let out = json!({
            "output": args.output,
            "depth": args.depth,
            "adapter": gpu.info().name,
            "backend": format!("{:?}", gpu.info().backend),
            "triangles": scene.triangle_count(),
            "chunks": gpu_scene.geometry.chunks().len(),
            "width": frame.width,
            "height": frame.height,
            "eye": cam.eye.to_array(),
            "forward": cam.forward.to_array(),
            "fov_y_deg": cam.fov_y_deg,
            "covered_pixels": frame.covered_count(),
            "load_seconds": load_seconds,
            "upload_seconds": upload_seconds,
            "render_seconds": render_seconds,
            "frames": args.frames,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!("adapter    {}", gpu.describe());
    println!(
        "scene      {} triangles in {} GPU chunks",
        scene.triangle_count(),
        gpu_scene.geometry.chunks().len()
    );
    println!(
        "camera     eye ({:.3}, {:.3}, {:.3})  dir ({:.3}, {:.3}, {:.3})  fov {:.1}°  {}x{}",
        cam.eye.x,
        cam.eye.y,
        cam.eye.z,
        cam.forward.x,
        cam.forward.y,
        cam.forward.z,
        cam.fov_y_deg,
        cam.width,
        cam.height
    );
    println!(
        "covered    {} of {} pixels",
        frame.covered_count(),
        frame.width as u64 * frame.height as u64
    );
    println!(
        "time       load {load_seconds:.2} s, upload {upload_seconds:.2} s, render {render_seconds:.3} s{}",
        if args.frames > 1 {
            format!(" (median of {} frames)", args.frames)
        } else {
            String::new()
        }
    );
    println!("wrote      {}", args.output.display());
    if let Some(d) = &args.depth {
        println!("wrote      {}", d.display());
    }
    Ok(())
}

/// `lemi render BUNDLE`: the impostor view from inside a baked cell.
fn run_bundle(args: Args, backend: BackendChoice) -> anyhow::Result<()> {
    let bundle = PathBuf::from(&args.scene.scenes[0]);
    if args.depth.is_some() && args.compare {
        bail!("--depth and --compare cannot be combined");
    }
    let (opened, scene) = crate::bundle_view::open(&bundle, &args.scene_override, args.json)?;
    let mut args = args;
    if args.eye.is_none() {
        args.eye = opened.first_cell().map(|c| c.center);
        if args.look.is_none() && args.dir.is_none() && args.yaw.is_none() {
            args.dir = Some(DVec3::X);
        }
    }
    let cam = camera(&args, &scene.bounds)?;
    if let Some(o) = &opened.manifest().object {
        if !o.cell.contains(cam.eye) {
            return render_outside_object(
                &args,
                &bundle,
                &scene,
                &cam,
                backend,
                &o.cell.describe(),
            );
        }
    }
    let (cell, file) = opened
        .cell_at(cam.eye)
        .context("the eye must lie in a baked cell")?;
    let (file, objects) = with_objects(&opened, file, &args.with_object, cam.eye)?;
    let gpu = Gpu::new(backend)?;
    let t = Instant::now();
    let materials = std::sync::Arc::new(
        lemi_gpu::GpuMaterials::upload(&gpu, &scene.materials, &scene.textures)
            .context("uploading the scene's materials")?,
    );
    // block-compressed macro-textures as stored where the adapter has the format
    let impostor_cell = lemi_gpu::ImpostorCell::upload_file(&gpu, materials, &scene, &file)
        .with_context(|| format!("{}: uploading the cell", bundle.display()))?;
    let upload_seconds = t.elapsed().as_secs_f64();
    let mut renderer = lemi_gpu::ImpostorRenderer::new(&gpu)?;
    renderer.set_texel_filter(args.texel_filter.into());
    let options = RenderOptions {
        clear: args.clear,
        ..Default::default()
    };
    let view = cam.view();
    let (frame, render_seconds) = render_timed(args.frames, || {
        renderer
            .render(&impostor_cell, &view, &options)
            .context("rendering the impostor view")
    })?;
    let mut comparison = None;
    if args.compare {
        let gpu_scene = GpuScene::upload(&gpu, &scene, &UploadOptions::default())
            .context("uploading the scene for the reference view")?;
        let reference = Renderer::new(&gpu)?
            .render(&gpu_scene, &view, &options)
            .context("rendering the reference view")?;
        let tolerance = lemi_eval::layered_crack_tolerance(&reference, &file, &cell);
        let c = lemi_eval::side_by_side(&reference, &frame, &tolerance)
            .context("comparing the impostor view with the reference")?;
        save_image(&c.image, &args.output)?;
        comparison = Some(c);
    } else {
        save_rgba(&frame, &args.output)?;
        if let Some(d) = &args.depth {
            save_depth(&frame, d)?;
        }
    }
    if args.json {
        let mut out = json!({
            "output": args.output,
            "bundle": bundle,
            "cell": cell.id(),
            "adapter": gpu.info().name,
            "objects": objects,
            "near_triangles": impostor_cell.near_triangles(),
            "quads": impostor_cell.quad_count(),
            "texture_bytes": impostor_cell.texture_bytes(),
            "width": frame.width,
            "height": frame.height,
            "eye": cam.eye.to_array(),
            "forward": cam.forward.to_array(),
            "fov_y_deg": cam.fov_y_deg,
            "upload_seconds": upload_seconds,
            "render_seconds": render_seconds,
            "frames": args.frames,
        });
        if let Some(c) = &comparison {
            out["compare"] = json!({
                "differing_pixels": c.differing,
                "crack_pixels": c.cracks.count,
                "reference_covered": c.coverage.reference_covered,
                "impostor_covered": c.coverage.test_covered,
                "psnr_db": c.psnr,
            });
        }
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!("adapter    {}", gpu.describe());
    if !args.with_object.is_empty() {
        println!(
            "objects    {objects} of {} object impostors replace their objects here",
            args.with_object.len()
        );
    }
    println!(
        "cell       {} of {}: {} near triangles, {} impostor quads, {:.1} MB of macro-textures",
        cell.id(),
        bundle.display(),
        impostor_cell.near_triangles(),
        impostor_cell.quad_count(),
        impostor_cell.texture_bytes() as f64 / 1e6
    );
    println!(
        "camera     eye ({:.3}, {:.3}, {:.3})  dir ({:.3}, {:.3}, {:.3})  fov {:.1}°  {}x{}",
        cam.eye.x,
        cam.eye.y,
        cam.eye.z,
        cam.forward.x,
        cam.forward.y,
        cam.forward.z,
        cam.fov_y_deg,
        cam.width,
        cam.height
    );
    if let Some(c) = &comparison {
        println!("compare    {}", c.summary());
    }
    println!(
        "time       upload {upload_seconds:.2} s, impostor render {render_seconds:.3} s{}",
        if args.frames > 1 {
            format!(" (median of {} frames)", args.frames)
        } else {
            String::new()
        }
    );
    println!(
        "wrote      {}{}",
        args.output.display(),
        if args.compare {
            " (reference | impostor | difference)"
        } else {
            ""
        }
    );
    Ok(())
}

/// The cells of the object bundles `paths` (`--with-object`): each must be an object bundle
/// baked from the scene of `opened`, with its textures in the same format.
pub fn object_cells(
    opened: &lemi_core::bundle::Bundle,
    paths: &[PathBuf],
) -> anyhow::Result<Vec<lemi_core::bundle::CellFile>> {
    let mut cells = Vec::new();
    for path in paths {
        let b = lemi_core::bundle::Bundle::open(path)
            .with_context(|| format!("--with-object {}", path.display()))?;
        if b.manifest().object.is_none() {
            bail!(
                "--with-object {}: not an object bundle (bake it with lemi bake-object)",
                path.display()
            );
        }
        b.expect_scene(&opened.manifest().scene.fingerprint)
            .with_context(|| format!("--with-object {}", path.display()))?;
        let id = b.cell_ids().first().copied().ok_or_else(|| {
            anyhow::anyhow!("--with-object {}: the bundle has no cell", path.display())
        })?;
        let f = b
            .cell(id)
            .with_context(|| format!("--with-object {}", path.display()))?;
        let want = opened.manifest().params.texture_format;
        if f.header.texture_format != want {
            bail!(
                "--with-object {}: its textures are {}, the bundle's {} (bake both with the same --texture-format)",
                path.display(),
                f.header.texture_format,
                want
            );
        }
        cells.push(f);
    }
    Ok(cells)
}

/// The cell `file` of `opened` composed with the object bundles `paths` whose view cell holds
/// `eye` (`lemi_core::object_cell::compose_objects`), and how many were composed.
fn with_objects(
    opened: &lemi_core::bundle::Bundle,
    file: lemi_core::bundle::CellFile,
    paths: &[PathBuf],
    eye: DVec3,
) -> anyhow::Result<(lemi_core::bundle::CellFile, usize)> {
    if paths.is_empty() {
        return Ok((file, 0));
    }
    let cells: Vec<_> = object_cells(opened, paths)?
        .into_iter()
        .filter(|f| {
            f.header
                .object
                .as_ref()
                .is_some_and(|o| o.cell.contains(eye))
        })
        .collect();
    let refs: Vec<&lemi_core::bundle::CellFile> = cells.iter().collect();
    lemi_core::object_cell::compose_objects(&file, &refs)
        .map_err(|e| anyhow::anyhow!("--with-object: {e}"))
}

/// `lemi render OBJECT_BUNDLE` from outside the object impostor's view cell: the impostor's
/// guarantee does not hold there, so the whole scene, the object included, is drawn as geometry.
fn render_outside_object(
    args: &Args,
    bundle: &Path,
    scene: &lemi_core::Scene,
    cam: &Camera,
    backend: BackendChoice,
    cell: &str,
) -> anyhow::Result<()> {
    let gpu = Gpu::new(backend)?;
    let gpu_scene =
        GpuScene::upload(&gpu, scene, &UploadOptions::default()).context("uploading the scene")?;
    let options = RenderOptions {
        clear: args.clear,
        ..Default::default()
    };
    let view = cam.view();
    let renderer = Renderer::new(&gpu)?;
    let (frame, render_seconds) = render_timed(args.frames, || {
        renderer
            .render(&gpu_scene, &view, &options)
            .context("rendering")
    })?;
    save_rgba(&frame, &args.output)?;
    let note = format!(
        "the eye lies outside the object impostor's view cell {cell}: the object is drawn as \
         geometry (an impostor is never shown outside its guarantee)"
    );
    if args.json {
        let out = json!({
            "output": args.output,
            "bundle": bundle,
            "cell": null,
            "impostor": false,
            "note": note,
            "triangles": scene.triangle_count(),
            "eye": cam.eye.to_array(),
            "forward": cam.forward.to_array(),
            "render_seconds": render_seconds,
            "frames": args.frames,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!("adapter    {}", gpu.describe());
    println!("note       {note}");
    println!(
        "geometry   {} triangles, render {render_seconds:.3} s",
        scene.triangle_count()
    );
    println!("wrote      {}", args.output.display());
    Ok(())
}

/// Renders `frames` times; returns the last frame and the median time in seconds.
fn render_timed(
    frames: u32,
    mut render: impl FnMut() -> anyhow::Result<Frame>,
) -> anyhow::Result<(Frame, f64)> {
    let mut times = Vec::new();
    let mut frame = None;
    for _ in 0..frames.max(1) {
        let t = Instant::now();
        frame = Some(render()?);
        times.push(t.elapsed().as_secs_f64());
    }
    let frame = frame.context("no frame rendered")?;
    times.sort_by(f64::total_cmp);
    Ok((frame, times[times.len() / 2]))
}

fn save_image(img: &image::RgbaImage, path: &Path) -> anyhow::Result<()> {
    let ext = extension(path);
    let result = if ext == "jpg" || ext == "jpeg" {
        image::DynamicImage::ImageRgba8(img.clone())
            .to_rgb8()
            .save(path)
    } else {
        img.save(path)
    };
    result.with_context(|| format!("writing {} (-o)", path.display()))
}

fn save_rgba(frame: &Frame, path: &Path) -> anyhow::Result<()> {
    let img = image::RgbaImage::from_raw(frame.width, frame.height, frame.rgba.clone())
        .context("rendered image has the wrong size")?;
    let ext = extension(path);
    let result = if ext == "jpg" || ext == "jpeg" {
        image::DynamicImage::ImageRgba8(img).to_rgb8().save(path)
    } else {
        img.save(path)
    };
    result.with_context(|| format!("writing {} (-o)", path.display()))
}

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

#[derive(PartialEq)]
enum DepthKind {
    Pfm,
    Png,
}

fn depth_kind(path: &Path) -> anyhow::Result<DepthKind> {
    match extension(path).as_str() {
        "pfm" => Ok(DepthKind::Pfm),
        "png" => Ok(DepthKind::Png),
        other => bail!(
            "--depth {}: unsupported extension `{other}`; use .pfm (exact f32 metres) or .png \
             (16-bit, scaled)",
            path.display()
        ),
    }
}

fn save_depth(frame: &Frame, path: &Path) -> anyhow::Result<()> {
    let bytes = match depth_kind(path)? {
        DepthKind::Pfm => {
            // Portable float map: greyscale "Pf", little-endian (negative scale), rows bottom-up.
            let mut out = format!("Pf\n{} {}\n-1.0\n", frame.width, frame.height).into_bytes();
            for row in frame.depth.chunks(frame.width as usize).rev() {
                for d in row {
                    out.extend_from_slice(&d.to_le_bytes());
                }
            }
            std::fs::write(path, out)
        }
        DepthKind::Png => {
            let finite = frame.depth.iter().copied().filter(|d| d.is_finite());
            let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), d| {
                (a.min(d), b.max(d))
            });
            let span = (hi - lo).max(1e-12);
            let grey: Vec<u16> = frame
                .depth
                .iter()
                .map(|&d| {
                    if d.is_finite() {
                        // nearest white (65535) … farthest 1, background 0
                        1 + ((1.0 - (d - lo) / span) * 65534.0).round() as u16
                    } else {
                        0
                    }
                })
                .collect();
            let img: image::ImageBuffer<image::Luma<u16>, Vec<u16>> =
                image::ImageBuffer::from_raw(frame.width, frame.height, grey)
                    .context("depth image has the wrong size")?;
            return img
                .save(path)
                .with_context(|| format!("writing {} (--depth)", path.display()));
        }
    };
    bytes.with_context(|| format!("writing {} (--depth)", path.display()))
}

/// `--texel-filter`.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum TexelFilterArg {
    Footprint,
    Nearest,
}

impl From<TexelFilterArg> for lemi_gpu::TexelFilter {
    fn from(a: TexelFilterArg) -> Self {
        match a {
            TexelFilterArg::Footprint => lemi_gpu::TexelFilter::Footprint,
            TexelFilterArg::Nearest => lemi_gpu::TexelFilter::Nearest,
        }
    }
}
