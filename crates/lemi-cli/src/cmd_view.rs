//! `lemi view BUNDLE`: the interactive viewer, `lemi walk`'s replay with a person steering. A
//! window (winit) shows the current cell's near geometry plus its impostors, streamed exactly as
//! `lemi walk` streams them (`lemi-runtime`), or all geometry; an on-screen HUD shows the frame
//! rate, the cell and what is drawn; the camera flies or walks; a recorded path is the JSON that
//! `lemi walk --path` replays.
//!
//! Frames are rendered by the same offscreen renderers as `lemi walk` (read back to the CPU, on
//! every backend alike), the HUD and the layer colouring are drawn into that image, and
//! [`lemi_gpu::WindowSurface`] presents it. `--frames N` runs N frames and exits (for tests under
//! Xvfb); without a display the command fails with a message saying what to do.
//!
//! Controls: WASD move (shift: faster), drag with a mouse button or the arrow keys to look, Q/E
//! down/up (flying), F fly/walk (walking keeps the eye height), G impostors/all geometry, L layer
//! colouring, T texel filter of minified quads (footprint/nearest), R start/stop recording, Esc
//! quit. Every change of state is printed to stdout.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use glam::DVec3;
use lemi_core::bundle::Manifest;
use lemi_core::cell::CellId;
use lemi_gpu::{
    BackendChoice, Frame, GpuMaterials, GpuScene, ImpostorRenderer, Presented, RenderOptions,
    Renderer, TexelFilter, UploadOptions, WindowSurface,
};
use lemi_runtime::Streamer;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, KeyEvent, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use lemi_walk::controls::{FlyCamera, Held, MoveMode, Recording};
use lemi_walk::hud::{Hud, Line};
use lemi_walk::layer_tint::{self, CellLayers};

/// Open an interactive window on a bundle: fly/walk through it, HUD, toggles, path recording.
#[derive(clap::Args)]
pub struct Args {
    /// The bundle directory.
    pub bundle: PathBuf,
    /// Window size `WIDTHxHEIGHT` (physical pixels).
    #[arg(long, value_parser = lemi_core::camera::parse_size, default_value = "960x540")]
    pub size: (u32, u32),
    /// Render at this fraction of the window's pixels (the image is stretched to the window);
    /// below 1 for speed on a software rasterizer.
    #[arg(long, default_value_t = 1.0)]
    pub render_scale: f64,
    /// Horizontal field of view in degrees; default: the bake's output view (60° without one).
    #[arg(long)]
    pub fov: Option<f64>,
    /// Start position `x,y,z` (metres); default: the centre of the first baked cell.
    #[arg(long, value_parser = crate::cmd_render::parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Start heading in degrees (0 looks along −Z, 90 along +X).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub yaw: f64,
    /// Start pitch in degrees (positive looks up).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub pitch: f64,
    /// Walking speed (m/s; shift: 4x).
    #[arg(long, default_value_t = 2.0)]
    pub walk_speed: f64,
    /// Flying speed (m/s; shift: 4x).
    #[arg(long, default_value_t = 10.0)]
    pub fly_speed: f64,
    /// Start flying (default: walking at the start height).
    #[arg(long)]
    pub fly: bool,
    /// Start showing all geometry instead of the impostors (key G).
    #[arg(long)]
    pub geometry: bool,
    /// Start with the layer colouring on (key L).
    #[arg(long)]
    pub layers: bool,
    /// Where a recorded path is written (key R; `lemi-path` JSON for `lemi walk --path`);
    /// default BUNDLE/view-path.json.
    #[arg(long, value_name = "PATH.json")]
    pub record: Option<PathBuf>,
    /// Start recording at the first frame.
    #[arg(long)]
    pub record_now: bool,
    /// Frames per second written into a recorded path (the replay's rate).
    #[arg(long, default_value_t = 30.0)]
    pub record_fps: f64,
    /// Run this many frames, then exit (for scripted runs, e.g. under `xvfb-run`).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub frames: Option<u64>,
    /// On exit, also write the last frame as shown (with the HUD) to this PNG.
    #[arg(long, value_name = "PNG")]
    pub screenshot: Option<PathBuf>,
    /// Present as fast as possible instead of waiting for the display's refresh.
    #[arg(long)]
    pub no_vsync: bool,
    /// Cell cache budget in MiB (CPU + GPU bytes of streamed cells).
    #[arg(long, default_value_t = 512)]
    pub cache_mb: u64,
    /// Texture upload budget per frame in KiB.
    #[arg(long, default_value_t = 8192)]
    pub upload_kb: u64,
    /// Highest observer speed the prefetching plans for (m/s).
    #[arg(long, default_value_t = 12.0)]
    pub max_speed: f64,
    /// When the current cell is not ready: draw all geometry for that frame (fallback, the
    /// default here) or wait for it (block). Both count a stall.
    #[arg(long, value_enum, default_value = "fallback")]
    pub stall: crate::cmd_walk::StallArg,
    /// The scene, if it moved since the bake (checked against the bundle's fingerprint).
    #[arg(long = "scene", value_name = "SCENE")]
    pub scene_override: Vec<String>,
    /// An object impostor's bundle (`lemi bake-object`, repeatable) drawn with the bundle's cells,
    /// as in `lemi walk --with-object`: in every cell its view cell holds whole, the object is
    /// drawn as its impostor instead of its triangles; elsewhere as geometry.
    #[arg(long, value_name = "OBJECT_BUNDLE")]
    pub with_object: Vec<PathBuf>,
    /// GPU backend: auto, vulkan or gl.
    #[arg(long, default_value = "auto")]
    pub backend: String,
}

/// The display the window needs, or the error that says what to do without one.
fn check_display() -> Result<()> {
    let set = |v: &str| std::env::var_os(v).is_some_and(|s| !s.is_empty());
    if set("DISPLAY") || set("WAYLAND_DISPLAY") || set("WAYLAND_SOCKET") {
        return Ok(());
    }
    bail!(
        "lemi view opens a window and needs a display, but neither DISPLAY nor WAYLAND_DISPLAY is \
         set. Run it in a desktop session, or under a virtual X server: `xvfb-run -a lemi view \
         BUNDLE --frames 100` (Debian: `apt-get install xvfb xauth`); `lemi walk BUNDLE --auto` \
         replays a walk without a window"
    )
}

pub fn run(args: Args) -> Result<()> {
    let backend = BackendChoice::parse(&args.backend).context("--backend")?;
    for (flag, v) in [
        ("--walk-speed", args.walk_speed),
        ("--fly-speed", args.fly_speed),
        ("--max-speed", args.max_speed),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{flag} must be a positive number (got {v})");
        }
    }
    if !(1.0..=1000.0).contains(&args.record_fps) {
        bail!("--record-fps must be in 1..=1000 (got {})", args.record_fps);
    }
    if !(args.render_scale.is_finite() && args.render_scale > 0.0 && args.render_scale <= 4.0) {
        bail!(
            "--render-scale must be in (0, 4] (got {})",
            args.render_scale
        );
    }
    if let Some(f) = args.fov {
        if !(f.is_finite() && f > 0.0 && f < 180.0) {
            bail!("--fov must be in (0, 180) degrees (got {f})");
        }
    }
    if !args.yaw.is_finite() || !(-90.0..=90.0).contains(&args.pitch) {
        bail!(
            "--yaw must be finite and --pitch within [-90, 90] (got {}, {})",
            args.yaw,
            args.pitch
        );
    }
    check_display()?;
    let (bundle, scene) = crate::bundle_view::open(&args.bundle, &args.scene_override, false)?;
    let manifest = bundle.manifest().clone();
    // object impostors are checked before a window opens
    let objects = if args.with_object.is_empty() {
        Vec::new()
    } else {
        let kind = crate::strategy::kind_for(&manifest, None)?;
        if manifest.object.is_some() || !kind.is_layered() {
            bail!(
                "--with-object: object impostors are drawn with the cells of a layered \
                 environment-map bundle, and {} is not one",
                args.bundle.display()
            );
        }
        crate::cmd_render::object_cells(&bundle, &args.with_object)?
    };
    let event_loop = EventLoop::new().map_err(|e| {
        anyhow::anyhow!(
            "cannot open the display (DISPLAY={}, WAYLAND_DISPLAY={}): {e}; is the X server or \
             compositor running? Without one: `xvfb-run -a lemi view BUNDLE`",
            std::env::var("DISPLAY").unwrap_or_default(),
            std::env::var("WAYLAND_DISPLAY").unwrap_or_default()
        )
    })?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let eye = match args.eye {
        Some(e) => e,
        None => bundle
            .first_cell()
            .map(|c| c.center)
            .context("the bundle has no baked cells; pass --eye to look at its scene anyway")?,
    };
    let record_path = args
        .record
        .clone()
        .unwrap_or_else(|| args.bundle.join("view-path.json"));
    let mut camera = FlyCamera::new(
        eye,
        args.yaw,
        args.pitch,
        if args.fly {
            MoveMode::Fly
        } else {
            MoveMode::Walk
        },
    );
    camera.walk_speed = args.walk_speed;
    camera.fly_speed = args.fly_speed;
    let mut app = App {
        fov_x: args.fov.or(manifest.params.output_fov_deg).unwrap_or(60.0),
        args,
        backend,
        manifest,
        objects: Arc::new(objects),
        scene_bounds: scene.bounds,
        scene: Some(scene),
        camera,
        record_path,
        held: Held::default(),
        cursor: None,
        dragging: false,
        viewer: None,
        error: None,
        frames: 0,
        frame_ms: Vec::new(),
        started: None,
        recording: None,
        paths_written: Vec::new(),
        cells_seen: Vec::new(),
        last_frame: None,
        last_tick: None,
    };
    println!(
        "lemi view: {} ({} cells), start at ({:.2}, {:.2}, {:.2})",
        app.args.bundle.display(),
        app.manifest.cells.len(),
        eye.x,
        eye.y,
        eye.z
    );
    println!(
        "controls: WASD move (shift faster), drag or arrows look, Q/E down/up, F fly/walk, \
         G impostors/geometry, L layer colours, T texel filter, R record, Esc quit"
    );
    let run = event_loop.run_app(&mut app);
    // the recording is written whatever ended the loop
    if let Some(rec) = app.recording.take() {
        app.write_recording(rec);
    }
    if let Some(e) = app.error.take() {
        return Err(e);
    }
    run.context("the window's event loop failed")?;
    let Some(viewer) = app.viewer.as_ref() else {
        bail!("the window closed before the viewer started");
    };
    if let (Some(p), Some(f)) = (&app.args.screenshot, &app.last_frame) {
        image::RgbaImage::from_raw(f.width, f.height, f.rgba.clone())
            .context("the last frame has the wrong size")?
            .save(p)
            .with_context(|| format!("writing --screenshot {}", p.display()))?;
        println!("screenshot {}", p.display());
    }
    let secs = app.started.map_or(0.0, |t| t.elapsed().as_secs_f64());
    let mut ms = app.frame_ms.clone();
    ms.sort_by(f64::total_cmp);
    let median = ms.get(ms.len() / 2).copied();
    let stats = viewer.streamer.stats();
    let limit = match app.args.frames {
        Some(n) if app.frames >= n => " (--frames reached)",
        _ => "",
    };
    println!(
        "lemi view: {} frames in {secs:.1} s ({:.1} fps, median frame {}){limit}",
        app.frames,
        if secs > 0.0 {
            app.frames as f64 / secs
        } else {
            0.0
        },
        median.map_or("-".into(), |m| format!("{m:.1} ms"))
    );
    println!(
        "streaming: {} cells visited, {} stalls, {} fallback frames, {} loads, {} evictions",
        app.cells_seen.len(),
        stats.stalls,
        stats.fallback_frames,
        stats.loads,
        stats.evictions
    );
    for p in &app.paths_written {
        println!(
            "recorded  {} (replay: lemi walk BUNDLE --path FILE)",
            p.display()
        );
    }
    Ok(())
}

/// Everything that needs the window's device.
struct Viewer {
    window: Arc<Window>,
    surface: WindowSurface,
    streamer: Streamer,
    impostor_renderer: ImpostorRenderer,
    renderer: Renderer,
    full: GpuScene,
    total_triangles: u64,
    options: RenderOptions,
    hud: Hud,
    show_geometry: bool,
    show_layers: bool,
    layers: HashMap<CellId, Option<CellLayers>>,
    last_cell: Option<Option<CellId>>,
    last_ready: bool,
    stalls: u64,
    fps: f64,
    fps_window: (Instant, u64),
    smoothed_ms: f64,
    title_at: Instant,
}

struct App {
    args: Args,
    backend: BackendChoice,
    manifest: Manifest,
    /// Object impostors composed into the cells they serve (`--with-object`).
    objects: Arc<Vec<lemi_core::bundle::CellFile>>,
    fov_x: f64,
    /// Moved into the viewer when the window exists.
    scene: Option<lemi_core::Scene>,
    /// The scene's bounds (equidistant layers are placed by them).
    scene_bounds: lemi_core::Aabb,
    camera: FlyCamera,
    record_path: PathBuf,
    held: Held,
    /// The cursor position (last seen) and whether a mouse button is held (dragging looks).
    cursor: Option<(f64, f64)>,
    dragging: bool,
    viewer: Option<Viewer>,
    error: Option<anyhow::Error>,
    frames: u64,
    frame_ms: Vec<f64>,
    started: Option<Instant>,
    recording: Option<Recording>,
    paths_written: Vec<PathBuf>,
    cells_seen: Vec<CellId>,
    last_frame: Option<Frame>,
    last_tick: Option<Instant>,
}

impl App {
    fn fail(&mut self, event_loop: &ActiveEventLoop, e: anyhow::Error) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }

    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let (w, h) = self.args.size;
        let window = Arc::new(
            event_loop
                .create_window(
                    Window::default_attributes()
                        .with_title("lemi view")
                        .with_inner_size(PhysicalSize::new(w, h)),
                )
                .context("creating the window")?,
        );
        let size = window.inner_size();
        let surface = WindowSurface::new(
            window.clone(),
            event_loop.owned_display_handle(),
            self.backend,
            size.width.max(1),
            size.height.max(1),
            !self.args.no_vsync,
        )
        .context("opening the GPU for the window")?;
        let gpu = surface.gpu().clone();
        println!(
            "window    {}x{} on {} ({})",
            size.width,
            size.height,
            gpu.describe(),
            surface.describe()
        );
        let scene = Arc::new(self.scene.take().context("the scene was already used")?);
        let materials = Arc::new(
            GpuMaterials::upload(&gpu, &scene.materials, &scene.textures)
                .context("uploading the scene's materials")?,
        );
        let a = &self.args;
        let mut options =
            crate::cmd_walk::streamer_options(a.cache_mb, a.upload_kb, a.max_speed, a.stall);
        options.loader.objects = self.objects.clone();
        let mut streamer = Streamer::new(
            gpu.clone(),
            self.manifest.clone(),
            &self.args.bundle,
            scene.clone(),
            materials,
            options,
        )?;
        let full = GpuScene::upload(&gpu, &scene, &UploadOptions::default())
            .context("uploading the scene (all geometry)")?;
        for w in streamer
            .preload(self.camera.eye, DVec3::ZERO, Duration::from_secs(60))
            .context("preloading the first cells")?
        {
            eprintln!("warning: {w}");
        }
        let hud = Hud::new();
        if hud.font_path().is_none() {
            println!("hud       no font found (install fonts-dejavu-core): numbers in the title");
        }
        let now = Instant::now();
        self.viewer = Some(Viewer {
            window,
            surface,
            streamer,
            impostor_renderer: ImpostorRenderer::new(&gpu)?,
            renderer: Renderer::new(&gpu)?,
            full,
            total_triangles: scene.triangle_count(),
            options: RenderOptions {
                clear: [150, 190, 235, 255],
                ..Default::default()
            },
            hud,
            show_geometry: self.args.geometry,
            show_layers: self.args.layers,
            layers: HashMap::new(),
            last_cell: None,
            last_ready: false,
            stalls: 0,
            fps: 0.0,
            fps_window: (now, 0),
            smoothed_ms: 0.0,
            title_at: now,
        });
        println!(
            "mode      {}, {}, layer colours {}",
            if self.args.geometry {
                "all geometry"
            } else {
                "impostors"
            },
            self.mode_text(),
            if self.args.layers { "on" } else { "off" }
        );
        if self.args.record_now {
            self.toggle_recording();
        }
        self.started = Some(Instant::now());
        Ok(())
    }

    fn mode_text(&self) -> String {
        match self.camera.mode {
            MoveMode::Fly => "flying".into(),
            MoveMode::Walk => format!("walking (eye height {:.2} m)", self.camera.walk_height),
        }
    }

    fn toggle_recording(&mut self) {
        match self.recording.take() {
            None => {
                self.recording = Some(Recording::start(self.args.record_fps, &self.camera.pose()));
                println!(
                    "recording started (R stops it; written to {})",
                    self.record_path.display()
                );
            }
            Some(rec) => self.write_recording(rec),
        }
    }

    fn write_recording(&mut self, rec: Recording) {
        let (keys, secs) = (rec.len(), rec.duration());
        let Some(path) = rec.finish() else {
            println!("recording stopped: too short to replay (fewer than 2 poses), not written");
            return;
        };
        match path.write(&self.record_path) {
            Ok(()) => {
                println!(
                    "recording stopped: {keys} poses, {secs:.1} s, written to {}",
                    self.record_path.display()
                );
                self.paths_written.push(self.record_path.clone());
            }
            Err(e) => {
                let e = anyhow::Error::new(e).context("writing the recorded path");
                eprintln!("error: {}", crate::error_chain(&e));
                if self.error.is_none() {
                    self.error = Some(e);
                }
            }
        }
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, event: &KeyEvent) {
        let PhysicalKey::Code(code) = event.physical_key else {
            return;
        };
        let down = event.state == ElementState::Pressed;
        let h = &mut self.held;
        match code {
            KeyCode::KeyW => h.forward = down,
            KeyCode::KeyS => h.back = down,
            KeyCode::KeyA => h.left = down,
            KeyCode::KeyD => h.right = down,
            KeyCode::KeyE | KeyCode::Space => h.up = down,
            KeyCode::KeyQ | KeyCode::KeyC => h.down = down,
            KeyCode::ShiftLeft | KeyCode::ShiftRight => h.fast = down,
            KeyCode::ArrowLeft => h.turn_left = down,
            KeyCode::ArrowRight => h.turn_right = down,
            KeyCode::ArrowUp => h.look_up = down,
            KeyCode::ArrowDown => h.look_down = down,
            _ => {}
        }
        if !down || event.repeat {
            return;
        }
        match code {
            KeyCode::Escape => {
                println!("quit (Esc)");
                event_loop.exit();
            }
            KeyCode::KeyF => {
                self.camera.toggle_mode();
                println!("camera    {}", self.mode_text());
            }
            KeyCode::KeyR => self.toggle_recording(),
            KeyCode::KeyG => {
                if let Some(v) = self.viewer.as_mut() {
                    v.show_geometry = !v.show_geometry;
                    println!(
                        "mode      {}",
                        if v.show_geometry {
                            "all geometry"
                        } else {
                            "impostors"
                        }
                    );
                }
            }
            KeyCode::KeyT => {
                if let Some(v) = self.viewer.as_mut() {
                    let next = match v.impostor_renderer.texel_filter() {
                        TexelFilter::Footprint => TexelFilter::Nearest,
                        TexelFilter::Nearest => TexelFilter::Footprint,
                    };
                    v.impostor_renderer.set_texel_filter(next);
                    println!(
                        "texels    {}",
                        match next {
                            TexelFilter::Footprint => "filtered where minified (footprint)",
                            TexelFilter::Nearest => "nearest, as baked",
                        }
                    );
                }
            }
            KeyCode::KeyL => {
                if let Some(v) = self.viewer.as_mut() {
                    v.show_layers = !v.show_layers;
                    println!(
                        "layers    colouring {}",
                        if v.show_layers {
                            "on (impostor pixels tinted by layer, near geometry grey)"
                        } else {
                            "off"
                        }
                    );
                }
            }
            _ => {}
        }
    }

    /// One frame: move, stream, render, HUD, present, record.
    fn frame(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let Some(v) = self.viewer.as_mut() else {
            return Ok(());
        };
        let t_frame = Instant::now();
        // seconds since the previous frame (at most 0.25: a hitch does not jump the camera)
        let dt = self
            .last_tick
            .map_or(0.0, |t| t_frame.duration_since(t).as_secs_f64().min(0.25));
        self.last_tick = Some(t_frame);
        let velocity = self.camera.step(&self.held, dt);
        let (ww, wh) = v.surface.size();
        let rw = ((ww as f64 * self.args.render_scale).round() as u32).clamp(1, 16384);
        let rh = ((wh as f64 * self.args.render_scale).round() as u32).clamp(1, 16384);
        let fov_y = 2.0
            * ((0.5 * self.fov_x.to_radians()).tan() * rh as f64 / rw as f64)
                .atan()
                .to_degrees();
        let pose = self.camera.pose();
        let camera = pose.camera(fov_y, rw, rh).context("the viewer's camera")?;
        let view = camera.view();
        let state = v.streamer.frame(pose.eye, velocity, dt.max(1e-6));
        for w in &state.warnings {
            eprintln!("warning: {w}");
        }
        let cell = state.current_cell;
        let ready = state.ready.is_some();
        if state.stalled {
            v.stalls += 1;
        }
        let (mut frame, drew_impostors, detail) = match (state.ready, v.show_geometry) {
            (Some(c), false) => (
                v.impostor_renderer
                    .render(c, &view, &v.options)
                    .context("rendering an impostor frame")?,
                true,
                format!(
                    "{} quads, {} near triangles",
                    c.quad_count(),
                    c.near_triangles()
                ),
            ),
            _ => (
                v.renderer
                    .render(&v.full, &view, &v.options)
                    .context("rendering all geometry")?,
                false,
                format!("{} triangles", v.total_triangles),
            ),
        };
        let fallback = state.fallback.clone();
        drop(state);
        // state changes on stdout
        if v.last_cell.as_ref() != Some(&cell) || v.last_ready != ready {
            match (&cell, ready) {
                (Some(id), true) => println!("cell      {id}: impostors ready ({detail})"),
                (Some(id), false) => println!(
                    "cell      {id}: not ready, drawing all geometry{}",
                    fallback
                        .as_deref()
                        .map_or(String::new(), |f| format!(" ({f})"))
                ),
                (None, _) => println!("cell      none: outside the baked cells, all geometry"),
            }
            if let Some(id) = cell {
                if !self.cells_seen.contains(&id) {
                    self.cells_seen.push(id);
                }
            }
            v.last_cell = Some(cell);
            v.last_ready = ready;
        }
        // layer colouring
        let mut legend = Vec::new();
        let mut layer_note = String::new();
        if v.show_layers {
            match (&cell, drew_impostors) {
                (Some(id), true) => {
                    let manifest = &self.manifest;
                    let bounds = self.scene_bounds;
                    let entry = v.layers.entry(*id).or_insert_with(|| {
                        manifest
                            .grid
                            .cell_of(*id)
                            .map_err(anyhow::Error::from)
                            .and_then(|c| {
                                CellLayers::of(&manifest.params, &c, &bounds)
                                    .map_err(anyhow::Error::from)
                            })
                            .map_err(|e| eprintln!("warning: layers of cell {id}: {e:#}"))
                            .ok()
                    });
                    if let Some(l) = entry {
                        let s = l.tint(&camera, &mut frame.rgba, &frame.depth);
                        let n = l.max_layers.min(layer_tint::PALETTE.len());
                        legend = (0..n).map(layer_tint::layer_color).collect();
                        let shown = s.per_layer.iter().filter(|&&n| n > 0).count();
                        layer_note = format!(
                            "layers: {} per face ({shown} in view), colours far to near{}",
                            l.max_layers,
                            if l.max_layers > n { ", repeating" } else { "" }
                        );
                    }
                }
                _ => layer_note = "layers: only with impostors (G)".into(),
            }
        }
        // HUD
        let ms_now = 1e3 * t_frame.elapsed().as_secs_f64();
        v.smoothed_ms = if v.smoothed_ms == 0.0 {
            ms_now
        } else {
            0.9 * v.smoothed_ms + 0.1 * ms_now
        };
        let (t0, n0) = v.fps_window;
        let since = t0.elapsed().as_secs_f64();
        if since >= 0.5 {
            v.fps = (self.frames + 1 - n0) as f64 / since;
            v.fps_window = (Instant::now(), self.frames + 1);
        }
        let what = match (&cell, drew_impostors) {
            (_, true) => format!("impostors: {detail}"),
            (Some(_), false) if v.show_geometry => format!("all geometry (G): {detail}"),
            (Some(_), false) => format!("not ready, all geometry: {detail}"),
            (None, false) => format!("outside the baked cells: {detail}"),
        };
        let mut lines = vec![
            Line::new(format!(
                "{:.1} fps  {:.1} ms  {rw}x{rh}",
                v.fps, v.smoothed_ms
            )),
            Line::new(format!(
                "cell {}  {what}",
                cell.map_or("-".to_string(), |c| c.to_string())
            )),
            Line::new(format!(
                "[G] {}  [F] {}  [L] layers {}  stalls {}",
                if v.show_geometry {
                    "geometry"
                } else {
                    "impostors"
                },
                match self.camera.mode {
                    MoveMode::Fly => "fly",
                    MoveMode::Walk => "walk",
                },
                if v.show_layers { "on" } else { "off" },
                v.stalls
            )),
            Line::new(format!(
                "eye {:.1} {:.1} {:.1}  yaw {:.0}  pitch {:.0}",
                pose.eye.x,
                pose.eye.y,
                pose.eye.z,
                pose.yaw_deg.rem_euclid(360.0),
                pose.pitch_deg
            )),
        ];
        if let Some(r) = &self.recording {
            lines.push(Line::colored(
                format!("[R] REC {:.1} s, {} poses", r.duration(), r.len()),
                [255, 80, 80],
            ));
        } else {
            lines.push(Line::new("[R] record"));
        }
        if !layer_note.is_empty() {
            lines.push(Line::new(layer_note));
        }
        v.hud.draw(&mut frame.rgba, rw, rh, &lines, &legend);
        if v.title_at.elapsed() >= Duration::from_millis(500) {
            v.window.set_title(&format!(
                "lemi view - {:.1} fps - cell {}",
                v.fps,
                cell.map_or("-".to_string(), |c| c.to_string())
            ));
            v.title_at = Instant::now();
        }
        match v
            .surface
            .present(&frame.rgba, rw, rh)
            .context("presenting the frame")?
        {
            Presented::Shown => {}
            Presented::Skipped(why) => {
                if self.frames == 0 {
                    println!("present   skipped a frame: {why}");
                }
            }
        }
        if let Some(r) = self.recording.as_mut() {
            r.advance(dt, &pose);
        }
        self.frames += 1;
        self.frame_ms.push(1e3 * t_frame.elapsed().as_secs_f64());
        self.last_frame = Some(frame);
        if self.args.frames.is_some_and(|n| self.frames >= n) {
            event_loop.exit();
        }
        Ok(())
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.viewer.is_some() || self.error.is_some() {
            return;
        }
        if let Err(e) = self.start(event_loop) {
            self.fail(event_loop, e);
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => {
                println!("quit (window closed)");
                event_loop.exit();
            }
            WindowEvent::Resized(size) => {
                if let Some(v) = self.viewer.as_mut() {
                    if let Err(e) = v.surface.resize(size.width, size.height) {
                        self.fail(event_loop, anyhow::Error::from(e).context("resizing"));
                    }
                }
            }
            WindowEvent::Focused(false) => {
                self.held = Held::default();
                self.dragging = false;
            }
            WindowEvent::KeyboardInput { event, .. } => self.key(event_loop, &event),
            WindowEvent::MouseInput { state, button, .. } => {
                if matches!(
                    button,
                    MouseButton::Left | MouseButton::Right | MouseButton::Middle
                ) {
                    self.dragging = state == ElementState::Pressed;
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let (true, Some((x, y))) = (self.dragging, self.cursor) {
                    self.camera.drag(position.x - x, position.y - y);
                }
                self.cursor = Some((position.x, position.y));
            }
            WindowEvent::CursorLeft { .. } => self.cursor = None,
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.frame(event_loop) {
                    self.fail(event_loop, e);
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(v) = &self.viewer {
            v.window.request_redraw();
        }
    }
}
