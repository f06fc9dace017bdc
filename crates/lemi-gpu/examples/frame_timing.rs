//! Frame timing of the impostor renderer against the reference renderer (all geometry) on a baked
//! bundle: for every cell, views from the cell centre along +X, −X, +Z, −Z (1280×720, 60°
//! horizontal field of view unless told otherwise), each rendered in turn, alternating, by
//!
//! - `ImpostorRenderer::render` (near geometry + quads, with the readback of colour and depth),
//! - `ImpostorRenderer::render_no_readback` (the same passes, waited for, nothing read back),
//! - `Renderer::render` and `Renderer::render_no_readback` with the whole scene,
//! - `Renderer::render_culled` and `render_culled_no_readback` with the whole scene frustum-culled
//!   over its cluster hierarchy (`geometry-culled`, the baseline a speed-up is quoted against;
//!   its frames are compared with the unculled ones, which they must equal),
//!
//! and prints medians of the wall-clock times and of the GPU times from timestamp queries
//! (`last_gpu_ms`, when the adapter has them), and the mean process CPU time per frame (all
//! threads, which on a software rasterizer is the rendering work itself, and which other
//! processes on a shared machine disturb less than wall-clock time).
//!
//! ```text
//! cargo run --release -p lemi-gpu --example frame_timing -- [BUNDLE] [--reps N] [--cells K]
//!     [--size WxH] [--fov DEG] [--save DIR | --check DIR] [--no-geometry] [--parts] [--stats]
//!     [--texel-filter footprint|nearest] [--eye-at X,Y,Z] [--rgba8]
//! ```
//!
//! `BUNDLE` defaults to `/tmp/bw` (the scene is rebuilt from the manifest's sources). The views
//! look along the four horizontal axes from each cell's centre, or with `--eye-at X,Y,Z` from
//! the point that many half extents of the cell off it (`1,1,1`: a corner). Macro-textures stored
//! block-compressed are uploaded as stored where the adapter samples the format, as the runtime
//! does (before, this example always decoded them to RGBA8; `--rgba8` still does). `--cells K`
//! takes the first K cells, `--reps N` times every view N times. `--save DIR` writes every view's
//! frames (raw RGBA8 + f32 depth) to `DIR`; `--check DIR` compares the frames with those saved
//! earlier and prints how many pixels differ (to check that an optimisation changes no pixel).
//! `--no-geometry` skips the reference renderer; `--parts` also reports the GPU time of the
//! quads alone (`render_impostors_only`) and of the near geometry alone (drawn by the reference
//! renderer); `--stats` prints how much of each face image the quads cover, and with `--parts`
//! where their pixels go on screen: how many quads a pixel of the far field lies under, how many
//! quads lie wholly behind the near geometry, behind the whole frame's depth, and (alpha-tested
//! ones) behind the near geometry and the opaque quads: what culling quads against each could
//! leave out; and how many of them a depth tile map (the farthest depth of every 16×16 pixels,
//! what GPU occlusion culling tests against) would find hidden.
//!
//! What the GPU time measures on Mesa's lavapipe (Vulkan on llvmpipe): the rasterization itself,
//! not only command submission. The timestamp written at the end of the pass is taken when the
//! rasterizer threads have finished it, so the GPU time is 97–100 % of the wall-clock time of
//! `render_no_readback` (encode, submit, wait), and the output's last lines show the ratio.
//! `render` minus `render_no_readback` is the readback: copying colour and view depth to
//! buffers, mapping them and building the `Frame` (about 3 ms at 1280×720). llvmpipe's GL has no
//! timestamp queries (`gpu` shows `-`).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use lemi_core::bundle::Bundle;
use lemi_core::camera::{Camera, View};
use lemi_gpu::{
    BackendChoice, CullOptions, CulledGeometry, Frame, Gpu, GpuCulledScene, GpuGeometry, GpuScene,
    ImpostorCell, ImpostorCellData, ImpostorRenderer, RenderOptions, Renderer, TexelFilter,
    UploadOptions,
};

type Error = Box<dyn std::error::Error>;

struct Args {
    bundle: PathBuf,
    reps: usize,
    cells: Option<usize>,
    width: u32,
    height: u32,
    fov_x: f64,
    save: Option<PathBuf>,
    check: Option<PathBuf>,
    /// Skip the reference renderer (for profiling the impostor frame).
    no_geometry: bool,
    /// Also time `render_impostors_only` (the quads without the near geometry).
    parts: bool,
    /// Print per face how much of the face image the quads cover (depth complexity in texels).
    stats: bool,
    /// How the impostor quads take their colour from their texels.
    texel_filter: TexelFilter,
    /// Where in its cell the eye is: a fraction of the cell's half extent per axis (0 0 0: the
    /// centre, 1 1 1: a corner).
    eye_at: DVec3,
    /// Upload block-compressed macro-textures decoded to RGBA8 instead of as stored.
    rgba8: bool,
}

fn parse_args() -> Result<Args, Error> {
    let mut a = Args {
        bundle: PathBuf::from("/tmp/bw"),
        reps: 3,
        cells: None,
        width: 1280,
        height: 720,
        fov_x: 60.0,
        save: None,
        check: None,
        no_geometry: false,
        parts: false,
        stats: false,
        texel_filter: TexelFilter::default(),
        eye_at: DVec3::ZERO,
        rgba8: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{arg} needs a value"));
        match arg.as_str() {
            "--reps" => a.reps = value()?.parse()?,
            "--cells" => a.cells = Some(value()?.parse()?),
            "--fov" => a.fov_x = value()?.parse()?,
            "--size" => {
                (a.width, a.height) =
                    lemi_core::camera::parse_size(&value()?).map_err(|e| format!("--size {e}"))?;
            }
            "--save" => a.save = Some(value()?.into()),
            "--check" => a.check = Some(value()?.into()),
            "--no-geometry" => a.no_geometry = true,
            "--parts" => a.parts = true,
            "--stats" => a.stats = true,
            "--rgba8" => a.rgba8 = true,
            "--eye-at" => {
                let v: Vec<f64> = (value()?.split(','))
                    .map(str::parse)
                    .collect::<Result<_, _>>()?;
                match v[..] {
                    [x, y, z] if v.iter().all(|c| c.abs() <= 1.0) => a.eye_at = DVec3::new(x, y, z),
                    _ => return Err("--eye-at wants x,y,z in [-1, 1]".into()),
                }
            }
            "--texel-filter" => {
                a.texel_filter = match value()?.as_str() {
                    "nearest" => TexelFilter::Nearest,
                    "footprint" => TexelFilter::Footprint,
                    v => return Err(format!("--texel-filter {v}: nearest or footprint").into()),
                }
            }
            "-h" | "--help" => {
                println!(
                    "frame_timing [BUNDLE] [--reps N] [--cells K] [--size WxH] [--fov DEG] \
                     [--save DIR | --check DIR] [--no-geometry] [--parts] [--stats] \
                     [--texel-filter footprint|nearest] [--eye-at X,Y,Z] [--rgba8]"
                );
                std::process::exit(0);
            }
            s if s.starts_with("--") => return Err(format!("unknown option {s}").into()),
            s => a.bundle = s.into(),
        }
    }
    if a.reps == 0 {
        return Err("--reps must be at least 1".into());
    }
    Ok(a)
}

fn median(v: &[f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    Some(if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    })
}

fn fmt(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.2}"))
}

/// Timings of one renderer.
#[derive(Default)]
struct Series {
    /// `render` wall-clock (with readback).
    wall: Vec<f64>,
    /// GPU time reported after `render`.
    gpu: Vec<f64>,
    /// `render_no_readback` wall-clock.
    no_readback: Vec<f64>,
    /// GPU time reported after `render_no_readback`.
    gpu_no_readback: Vec<f64>,
    /// Process CPU time (all threads, so the software rasterizer's too) of `render` and
    /// `render_no_readback`, summed, in ms: less sensitive than wall-clock to other processes
    /// on a shared machine. Clock-tick resolution per call, so only the mean over many is good.
    cpu: f64,
    cpu_no_readback: f64,
}

impl Series {
    fn row(&self, name: &str) -> String {
        let n = self.wall.len().max(1) as f64;
        format!(
            "{name:<10} {:>10} {:>10} {:>12} {:>12} {:>10} {:>12}   ({} frames)",
            fmt(median(&self.wall)),
            fmt(median(&self.gpu)),
            fmt(median(&self.no_readback)),
            fmt(median(&self.gpu_no_readback)),
            fmt(Some(self.cpu / n)),
            fmt(Some(self.cpu_no_readback / n)),
            self.wall.len()
        )
    }
}

/// CPU time of this process (user + system, all threads) in ms, from `/proc/self/stat`; 0 where
/// that does not exist.
fn cpu_ms() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // Linux reports these in USER_HZ = 100 ticks per second.
    (ticks(11) + ticks(12)) * 10.0
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn frame_bytes(f: &Frame) -> Vec<u8> {
    let mut out = f.rgba.clone();
    for d in &f.depth {
        out.extend_from_slice(&d.to_le_bytes());
    }
    out
}

/// Pixels whose colour or depth bits differ between `f` and the saved `bytes`.
fn differing_pixels(f: &Frame, bytes: &[u8]) -> usize {
    let n = f.rgba.len() / 4;
    if bytes.len() != 8 * n {
        return n;
    }
    let (c, d) = bytes.split_at(4 * n);
    (0..n)
        .filter(|&i| {
            f.rgba[4 * i..4 * i + 4] != c[4 * i..4 * i + 4]
                || f.depth[i].to_le_bytes() != d[4 * i..4 * i + 4]
        })
        .count()
}

/// Screen pixels inside quad `q` in `view`, with its nearest and farthest view depth.
fn quad_pixels(q: &lemi_core::bundle::Quad, view: &View) -> Option<(Vec<usize>, f64, f64)> {
    let (w, h) = (view.width as usize, view.height as usize);
    let p: Vec<_> = (q.corners.iter())
        .filter_map(|c| view.project(DVec3::from_array(c.map(f64::from))))
        .collect();
    if p.len() < 4 {
        return None;
    }
    let nearest = p.iter().map(|p| p.view_depth).fold(f64::INFINITY, f64::min);
    let farthest = p.iter().map(|p| p.view_depth).fold(0.0, f64::max);
    let lo = p
        .iter()
        .fold(glam::DVec2::splat(f64::INFINITY), |a, p| a.min(p.pixel));
    let hi = p
        .iter()
        .fold(glam::DVec2::splat(f64::NEG_INFINITY), |a, p| a.max(p.pixel));
    let (x0, y0) = (
        lo.x.floor().max(0.0) as usize,
        lo.y.floor().max(0.0) as usize,
    );
    let (x1, y1) = (
        (hi.x.ceil().max(0.0) as usize).min(w),
        (hi.y.ceil().max(0.0) as usize).min(h),
    );
    let sign = (p[1].pixel - p[0].pixel)
        .perp_dot(p[2].pixel - p[0].pixel)
        .signum();
    let mut px = Vec::new();
    for y in y0..y1 {
        for x in x0..x1 {
            let c = glam::DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            if (0..4).all(|i| {
                let (a, b) = (p[i].pixel, p[(i + 1) % 4].pixel);
                (b - a).perp_dot(c - a) * sign >= 0.0
            }) {
                px.push(y * w + x);
            }
        }
    }
    Some((px, nearest, farthest))
}

/// Alpha-tested quads wholly behind the near geometry and the opaque quads (each opaque quad
/// taken at its farthest depth): what culling them after drawing those would leave out.
fn alpha_behind_opaque(
    quads: &[lemi_core::bundle::Quad],
    opaque: &[bool],
    view: &View,
    near: &Frame,
    name: &str,
) {
    let mut occ: Vec<f64> = near.depth.iter().map(|&d| d as f64).collect();
    for (q, _) in quads.iter().zip(opaque).filter(|(_, &o)| o) {
        if let Some((px, _, far)) = quad_pixels(q, view) {
            for i in px {
                occ[i] = occ[i].min(far);
            }
        }
    }
    let (mut n, mut area, mut cn, mut carea) = (0u64, 0u64, 0u64, 0u64);
    for (q, _) in quads.iter().zip(opaque).filter(|(_, &o)| !o) {
        if let Some((px, nearest, _)) = quad_pixels(q, view) {
            if px.is_empty() {
                continue;
            }
            n += 1;
            area += px.len() as u64;
            if px.iter().all(|&i| occ[i] < nearest * (1.0 - 1e-4)) {
                cn += 1;
                carea += px.len() as u64;
            }
        }
    }
    println!(
        "  {name}: {n} alpha-tested quads on screen ({:.2} Mpx); {cn} ({:.2} Mpx) wholly behind \
         the near geometry and the opaque quads",
        area as f64 / 1e6,
        carea as f64 / 1e6
    );
}

/// Where the quads' rasterized pixels go (`--stats --parts`): how many quads are on screen, how
/// many are not wholly behind the depth of `behind` (the near geometry's frame, or the whole
/// frame's), and per pixel of the far field, how many quads cover it.
fn quad_overdraw(quads: &[lemi_core::bundle::Quad], view: &View, behind: &Frame, name: &str) {
    let (w, h) = (view.width as usize, view.height as usize);
    let mut count = vec![0u16; w * h];
    let (mut total, mut hidden) = (0u64, 0u64);
    let (mut visible_quads, mut visible_area, mut on_screen) = (0u64, 0u64, 0u64);
    // what occlusion culling against a depth tile map of `behind` could leave out: the farthest
    // depth per 16-pixel tile, a quad culled where its nearest depth lies beyond that of every
    // tile its pixels touch
    const TILE: usize = 16;
    let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let mut far = vec![0f32; tw * th];
    for (i, d) in behind.depth.iter().enumerate() {
        let t = (i / w / TILE) * tw + (i % w) / TILE;
        far[t] = far[t].max(*d);
    }
    let (mut tile_culled, mut tile_culled_area) = (0u64, 0u64);
    for q in quads {
        let Some((px, nearest, _)) = quad_pixels(q, view) else {
            continue;
        };
        if px.is_empty() {
            continue;
        }
        on_screen += 1;
        total += px.len() as u64;
        let mut seen = false;
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for i in px.iter().copied() {
            if f64::from(behind.depth[i]) < nearest * (1.0 - 1e-4) {
                hidden += 1;
            } else {
                count[i] = count[i].saturating_add(1);
                seen = true;
            }
            x0 = x0.min(i % w / TILE);
            x1 = x1.max(i % w / TILE);
            y0 = y0.min(i / w / TILE);
            y1 = y1.max(i / w / TILE);
        }
        if seen {
            visible_quads += 1;
            visible_area += px.len() as u64;
        }
        let tiles_hide = (y0..=y1)
            .all(|ty| (x0..=x1).all(|tx| f64::from(far[ty * tw + tx]) < nearest * (1.0 - 1e-4)));
        if tiles_hide {
            tile_culled += 1;
            tile_culled_area += px.len() as u64;
        }
    }
    println!(
        "  {name}: a 16-px depth tile map would cull {tile_culled} of {on_screen} quads ({:.2} Mpx)",
        tile_culled_area as f64 / 1e6
    );
    let open: Vec<u16> = count.iter().copied().filter(|&c| c > 0).collect();
    let layers: u64 = open.iter().map(|&c| u64::from(c)).sum();
    println!(
        "  {name}: {on_screen} quads on screen cover {:.2} Mpx ({:.2} x the view), {:.0} % of it \
         behind the depth; {visible_quads} quads not wholly behind it cover {:.2} Mpx; the rest \
         lies on {:.0} % of the view, {:.2} quads deep on average",
        total as f64 / 1e6,
        total as f64 / (w * h) as f64,
        100.0 * hidden as f64 / total.max(1) as f64,
        visible_area as f64 / 1e6,
        100.0 * open.len() as f64 / (w * h) as f64,
        layers as f64 / open.len().max(1) as f64
    );
}

fn save_or_check(args: &Args, name: &str, f: &Frame, diffs: &mut Vec<(String, usize)>) {
    if let Some(dir) = &args.save {
        let _ = std::fs::create_dir_all(dir);
        if let Err(e) = std::fs::write(dir.join(name), frame_bytes(f)) {
            eprintln!("warning: saving {name}: {e}");
        }
    }
    if let Some(dir) = &args.check {
        match std::fs::read(dir.join(name)) {
            Ok(b) => diffs.push((name.to_string(), differing_pixels(f, &b))),
            Err(e) => eprintln!("warning: no saved {name}: {e}"),
        }
    }
}

fn view(eye: DVec3, dir: DVec3, args: &Args) -> Result<View, Error> {
    let aspect = args.width as f64 / args.height as f64;
    let fov_y = 2.0 * ((args.fov_x.to_radians() / 2.0).tan() / aspect).atan();
    Ok(Camera::new(
        eye,
        dir,
        DVec3::Y,
        fov_y.to_degrees(),
        args.width,
        args.height,
    )?
    .view())
}

/// The near list's triangles as one mesh per source mesh.
fn near_meshes(scene: &lemi_core::Scene, near: &[[u32; 2]]) -> Vec<lemi_core::Mesh> {
    let mut out: Vec<lemi_core::Mesh> = Vec::new();
    let mut sorted = near.to_vec();
    sorted.sort_by_key(|p| p[0]);
    for group in sorted.chunk_by(|a, b| a[0] == b[0]) {
        let Some(src) = scene.meshes.get(group[0][0] as usize) else {
            continue;
        };
        let mut mesh = lemi_core::Mesh {
            material: src.material,
            vertices: Vec::new(),
            indices: Vec::new(),
        };
        for &[_, t] in group {
            for &i in src
                .indices
                .get(3 * t as usize..3 * t as usize + 3)
                .unwrap_or(&[])
            {
                mesh.indices.push(mesh.vertices.len() as u32);
                mesh.vertices.push(src.vertices[i as usize]);
            }
        }
        out.push(mesh);
    }
    out
}

fn opaque_quads(cell: &ImpostorCell) -> String {
    format!("{} opaque", cell.opaque_quad_count())
}

fn main() -> Result<(), Error> {
    let args = parse_args()?;
    let gpu = Gpu::new(BackendChoice::Auto)?;
    println!(
        "adapter: {}; timestamp queries: {}",
        gpu.describe(),
        gpu.has_timestamps()
    );
    let bundle = Bundle::open(&args.bundle)?;
    let manifest = bundle.manifest();
    let t = Instant::now();
    let scene = lemi_scene::load(&manifest.scene.sources, &lemi_scene::LoadOptions::default())?;
    println!(
        "scene {} ({} triangles) loaded in {:.1} s",
        manifest.scene.sources.join(" "),
        scene.triangle_count(),
        t.elapsed().as_secs_f64()
    );
    let all = GpuScene::upload(&gpu, &scene, &UploadOptions::default())?;
    // the same scene frustum-culled over its cluster hierarchy: the baseline a speed-up is
    // quoted against
    let culled = if args.no_geometry {
        None
    } else {
        let geometry = CulledGeometry::upload(&gpu, &scene, &CullOptions::default())?;
        Some(GpuCulledScene::from_parts(
            Arc::clone(&all.materials),
            geometry,
        )?)
    };
    let materials = Arc::clone(&all.materials);
    let mut impostors = ImpostorRenderer::new(&gpu)?;
    impostors.set_texel_filter(args.texel_filter);

    let reference = Renderer::new(&gpu)?;
    let options = RenderOptions::default();
    let dirs = [
        ("px", DVec3::X),
        ("nx", -DVec3::X),
        ("pz", DVec3::Z),
        ("nz", -DVec3::Z),
    ];
    let (mut imp, mut geo) = (Series::default(), Series::default());
    let (mut cul, mut culled_triangles) = (Series::default(), Vec::new());
    let (mut quads_only, mut near_only) = (Vec::new(), Vec::new());
    // per cell with --parts: id, quads-only GPU times, far-field pixel shares of its views
    let mut per_cell: Vec<(lemi_core::cell::CellId, Vec<f64>, Vec<f64>)> = Vec::new();
    let mut diffs = Vec::new();
    let cells = args.cells.unwrap_or(manifest.cells.len());
    for entry in manifest.cells.iter().take(cells) {
        let file = bundle.cell(entry.id)?;
        let macros = file.decode_macros()?;
        // as the runtime lays a cell out: with its origin, so that draw calls whose texels
        // span two pixels or more take nearest texels (the same pixels)
        let data = ImpostorCellData::prepare_for(
            &scene,
            &file.near,
            &file.header.quads,
            macros.clone(),
            gpu.limits().max_texture_dimension_2d,
            Some(lemi_gpu::SeenFrom::of(&file.header)),
        )?;
        // block-compressed macro-textures go to the GPU as stored where the adapter samples
        // them, as the runtime uploads them (`--rgba8`: decoded)
        let data = match file.block_macros()? {
            Some(b) if !args.rgba8 && b.first().is_some_and(|m| gpu.has_block_format(m.format)) => {
                data.with_blocks(b)?
            }
            _ => data,
        };
        let mut pending = ImpostorCell::begin_upload(&gpu, Arc::clone(&materials), data)?;
        pending.upload_step(&gpu, u64::MAX)?;
        let cell = pending.finish()?;
        if entry.id == manifest.cells[0].id {
            println!("macro-textures uploaded as {:?}", cell.texture_format());
        }
        let eye = file.header.cell.center + file.header.cell.half * args.eye_at;
        // The near geometry alone, as a scene for the reference renderer (same shading).
        let near_scene = if args.parts {
            let meshes = near_meshes(&scene, &file.near);
            let geometry = GpuGeometry::upload(&gpu, &meshes, &UploadOptions::default())?;
            Some(GpuScene::from_parts(Arc::clone(&materials), geometry)?)
        } else {
            None
        };
        if args.stats {
            let res = file.header.resolution as f64;
            for f in &file.header.faces {
                let qs: Vec<_> = file.header.quads.iter().filter(|q| q.face == *f).collect();
                let area: f64 = qs.iter().map(|q| (q.rect[2] * q.rect[3]) as f64).sum();
                let mut opaque_texels = 0u64;
                for q in &qs {
                    let m = &macros[q.macro_index as usize];
                    for y in q.rect[1]..q.rect[1] + q.rect[3] {
                        for x in q.rect[0]..q.rect[0] + q.rect[2] {
                            if m.rgba[(4 * (y * m.width + x) + 3) as usize] >= 128 {
                                opaque_texels += 1;
                            }
                        }
                    }
                }
                // quads sharing a whole edge with another quad of their layer (mergeable
                // without adding a transparent texel)
                let mut edges = std::collections::HashMap::new();
                for q in &qs {
                    let [x0, y0, x1, y1] = q.texels;
                    edges.insert((q.layer, 0u8, x1, y0, y1), ());
                    edges.insert((q.layer, 1u8, y1, x0, x1), ());
                }
                let mergeable = (qs.iter())
                    .filter(|q| {
                        let [x0, y0, x1, y1] = q.texels;
                        edges.contains_key(&(q.layer, 0u8, x0, y0, y1))
                            || edges.contains_key(&(q.layer, 1u8, y0, x0, x1))
                    })
                    .count();
                println!("  face {f:?}: {mergeable} quads share a whole edge with another one");
                println!(
                    "  face {f:?}: {} quads covering {:.2} x the face's texels, {:.2} x in opaque \
                     texels",
                    qs.len(),
                    area / (res * res),
                    opaque_texels as f64 / (res * res),
                );
            }
        }
        let mut cell_imp = Vec::new();
        let (mut cell_quads, mut cell_shares) = (Vec::new(), Vec::new());
        for (dname, dir) in dirs {
            let v = view(eye, dir, &args)?;
            if args.stats {
                // quads with a corner in front of the eye and inside the view (an estimate of
                // the quads the rasterizer sets up), and their mean area on screen
                let vp = v.view_proj();
                let (mut n, mut px) = (0usize, 0.0f64);
                for q in &file.header.quads {
                    let ndc: Vec<glam::DVec3> = (q.corners.iter())
                        .map(|c| vp * DVec3::from_array(c.map(f64::from)).extend(1.0))
                        .filter(|c| c.w > 0.0)
                        .map(|c| c.truncate() / c.w)
                        .collect();
                    if ndc.len() == 4 && ndc.iter().any(|c| c.x.abs() <= 1.0 && c.y.abs() <= 1.0) {
                        n += 1;
                        let s = |c: &glam::DVec3| {
                            glam::DVec2::new(c.x * args.width as f64, c.y * args.height as f64)
                                / 2.0
                        };
                        let (a, b, c, d) = (s(&ndc[0]), s(&ndc[1]), s(&ndc[2]), s(&ndc[3]));
                        px += ((c - a).perp_dot(d - b)).abs() / 2.0;
                    }
                }
                println!(
                    "  view {dname}: {n} quads in view, {:.0} px each on average",
                    px / n.max(1) as f64
                );
            }
            // Warm-up (pipelines, targets) and the frames to save or check.
            let f = impostors.render(&cell, &v, &options)?;
            if args.stats {
                let (draws, nearest) = impostors.last_quad_draws();
                println!("  view {dname}: {draws} quad draw calls, {nearest} of them with nearest texels");
            }
            if let Some(near) = &near_scene {
                // far-field pixels: drawn in the impostor frame, not by the near geometry (quads
                // lie beyond the near field, never in front of it)
                let n = reference.render(near, &v, &options)?;
                if args.stats {
                    quad_overdraw(&file.header.quads, &v, &n, &format!("{dname} (near)"));
                    quad_overdraw(&file.header.quads, &v, &f, "  (whole frame)");
                    let opaque: Vec<bool> = (file.header.quads.iter())
                        .map(|q| {
                            let m = &macros[q.macro_index as usize];
                            let [x, y, rw, rh] = q.rect;
                            (y..y + rh).all(|yy| {
                                (x..x + rw)
                                    .all(|xx| m.rgba[(4 * (yy * m.width + xx) + 3) as usize] >= 128)
                            })
                        })
                        .collect();
                    alpha_behind_opaque(&file.header.quads, &opaque, &v, &n, dname);
                }
                let far = f.covered_count().saturating_sub(n.covered_count());
                cell_shares.push(far as f64 / (f.width as f64 * f.height as f64));
            }
            save_or_check(
                &args,
                &format!("{}_{dname}_imp.bin", entry.id),
                &f,
                &mut diffs,
            );
            if !args.no_geometry {
                let g = reference.render(&all, &v, &options)?;
                let name = format!("{}_{dname}_geo.bin", entry.id);
                save_or_check(&args, &name, &g, &mut diffs);
                if let Some(c) = &culled {
                    // culling never changes the image
                    let (cg, _) = reference.render_culled(c, &v, &options)?;
                    diffs.push((
                        format!("{name} (culled)"),
                        differing_pixels(&g, &frame_bytes(&cg)),
                    ));
                }
            }
            for _ in 0..args.reps {
                let (t, c) = (Instant::now(), cpu_ms());
                let f = impostors.render(&cell, &v, &options)?;
                imp.cpu += cpu_ms() - c;
                imp.wall.push(ms_since(t));
                cell_imp.push(ms_since(t));
                drop(f);
                imp.gpu.extend(impostors.last_gpu_ms());
                let (t, c) = (Instant::now(), cpu_ms());
                impostors.render_no_readback(&cell, &v, &options)?;
                imp.cpu_no_readback += cpu_ms() - c;
                imp.no_readback.push(ms_since(t));
                imp.gpu_no_readback.extend(impostors.last_gpu_ms());
                if let Some(near) = &near_scene {
                    impostors.render_impostors_only(&cell, &v, &options)?;
                    quads_only.extend(impostors.last_gpu_ms());
                    cell_quads.extend(impostors.last_gpu_ms());
                    reference.render_no_readback(near, &v, &options)?;
                    near_only.extend(reference.last_gpu_ms());
                }
                if args.no_geometry {
                    continue;
                }
                let (t, c) = (Instant::now(), cpu_ms());
                let g = reference.render(&all, &v, &options)?;
                geo.cpu += cpu_ms() - c;
                geo.wall.push(ms_since(t));
                drop(g);
                geo.gpu.extend(reference.last_gpu_ms());
                let (t, c) = (Instant::now(), cpu_ms());
                reference.render_no_readback(&all, &v, &options)?;
                geo.cpu_no_readback += cpu_ms() - c;
                geo.no_readback.push(ms_since(t));
                geo.gpu_no_readback.extend(reference.last_gpu_ms());
                if let Some(c) = &culled {
                    let (t, cpu) = (Instant::now(), cpu_ms());
                    let (g, stats) = reference.render_culled(c, &v, &options)?;
                    cul.cpu += cpu_ms() - cpu;
                    cul.wall.push(ms_since(t));
                    drop(g);
                    cul.gpu.extend(reference.last_gpu_ms());
                    culled_triangles.push(stats.triangles as f64);
                    let (t, cpu) = (Instant::now(), cpu_ms());
                    reference.render_culled_no_readback(c, &v, &options)?;
                    cul.cpu_no_readback += cpu_ms() - cpu;
                    cul.no_readback.push(ms_since(t));
                    cul.gpu_no_readback.extend(reference.last_gpu_ms());
                }
            }
        }
        if near_scene.is_some() {
            per_cell.push((entry.id, cell_quads, cell_shares));
        }
        println!(
            "cell {:>7}: {:>6} near triangles, {:>6} quads ({}) in {:>3} draws; impostor frame \
             median {} ms",
            entry.id,
            cell.near_triangles(),
            cell.quad_count(),
            opaque_quads(&cell),
            cell.quad_draw_calls(),
            fmt(median(&cell_imp))
        );
    }
    println!(
        "\nmedians in ms over {cells} cells x 4 views x {} reps, {}x{}, {}° horizontal fov",
        args.reps, args.width, args.height, args.fov_x
    );
    println!(
        "{:<10} {:>10} {:>10} {:>12} {:>12} {:>10} {:>12}",
        "", "render", "gpu", "no-readback", "gpu(no-rb)", "cpu", "cpu(no-rb)"
    );
    println!("{}", imp.row("impostor"));
    println!("{}", geo.row("geometry"));
    println!("{}", cul.row("culled"));
    if let Some(t) = median(&culled_triangles) {
        println!("culled geometry: median {t:.0} triangles submitted per frame");
    }
    if args.parts {
        println!(
            "gpu time of the parts: quads only (render_impostors_only) {} ms, near geometry only \
             {} ms",
            fmt(median(&quads_only)),
            fmt(median(&near_only))
        );
        if let (Some(i), Some(n)) = (median(&imp.gpu_no_readback), median(&near_only)) {
            println!(
                "impostor frame / near geometry only (gpu time): {:.2}x",
                i / n
            );
        }
        // the far field's cost per cell against its far-field pixels, and between neighbours
        // whose far-field pixel shares are within 10 % of each other
        let mut worst: Option<(f64, String)> = None;
        for (id, q, sh) in &per_cell {
            let share = sh.iter().sum::<f64>() / sh.len().max(1) as f64;
            println!(
                "  cell {id}: quads {} ms (gpu median), far-field pixels {:.1} %",
                fmt(median(q)),
                100.0 * share
            );
        }
        for (a, qa, sa) in &per_cell {
            for (b, qb, sb) in &per_cell {
                let d = (a.index() - b.index()).abs().element_sum();
                let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
                let (sa, sb) = (mean(sa), mean(sb));
                if d != 1 || (sa - sb).abs() > 0.1 * sa.max(sb) {
                    continue;
                }
                if let (Some(ta), Some(tb)) = (median(qa), median(qb)) {
                    let r = ta / tb;
                    if worst.as_ref().is_none_or(|w| r > w.0) {
                        worst = Some((r, format!("{a} vs {b}")));
                    }
                }
            }
        }
        if let Some((r, pair)) = worst {
            println!(
                "largest far-field cost ratio between neighbours of similar far-field pixels: \
                 {r:.2}x ({pair})"
            );
        }
    }
    if let (Some(i), Some(g)) = (median(&imp.wall), median(&geo.wall)) {
        println!("speed-up (render, with readback): {:.2}x", g / i);
    }
    if let (Some(i), Some(g)) = (median(&imp.no_readback), median(&geo.no_readback)) {
        println!("speed-up (no readback):           {:.2}x", g / i);
    }
    if let (Some(i), Some(g)) = (median(&imp.gpu), median(&geo.gpu)) {
        println!("speed-up (gpu time):              {:.2}x", g / i);
    }
    if let (Some(i), Some(g)) = (median(&imp.wall), median(&cul.wall)) {
        println!(
            "speed-up over culled geometry (render, with readback): {:.2}x",
            g / i
        );
    }
    if let (Some(i), Some(g)) = (median(&imp.gpu), median(&cul.gpu)) {
        println!(
            "speed-up over culled geometry (gpu time):              {:.2}x",
            g / i
        );
    }
    for (name, s) in [("impostor", &imp), ("geometry", &geo)] {
        if let (Some(w), Some(n), Some(gp)) = (
            median(&s.wall),
            median(&s.no_readback),
            median(&s.gpu_no_readback),
        ) {
            println!(
                "{name}: readback costs {:.2} ms; gpu time is {:.0}% of the no-readback wall time",
                w - n,
                100.0 * gp / n
            );
        }
    }
    if !diffs.is_empty() {
        let bad: Vec<_> = diffs.iter().filter(|(_, n)| *n > 0).collect();
        println!(
            "\ncheck: {} frames compared, {} differ",
            diffs.len(),
            bad.len()
        );
        for (name, n) in bad {
            println!("  {name}: {n} pixels differ");
        }
    }
    Ok(())
}
