//! How many layers a per-pixel layer lookup would visit: the measurement that decides whether a
//! far-field renderer that walks each pixel's ray through the layer planes (instead of rasterizing
//! the quads) could cost less on a software rasterizer. For every pixel of a cell's views where
//! the impostor frame shows a quad (not the near geometry, not the background), the ray through
//! the pixel's centre is met with the plane of every layer of every face, nearest first, keeping
//! the crossings inside their face's pyramid, until the first opaque texel (the one the frame
//! shows). Reported per view and over all: the layer planes crossed up to it (what a walk tests),
//! the crossings whose 8×8-texel tile of that layer holds any opaque texel (what a walk that
//! skips empty tiles fetches a texel for), and, for the background pixels, the planes a walk
//! crosses before it leaves the layers. Also how often the walk's first opaque texel agrees with
//! the frame's depth (a check of the walk).
//!
//! ```text
//! cargo run --release -p lemi-eval --example layer_march -- BUNDLE CELL_ID [--size WxH]
//! ```
//!
//! The views are the cell's centre looking along every evaluated direction, with `lemi eval`'s
//! camera (the bundle's output view unless `--size`).

mod common;

use anyhow::{anyhow, Context, Result};
use common::CellRenderers;
use glam::DVec3;
use lemi_core::camera::parse_size;
use lemi_core::cell::CellId;
use lemi_eval::{camera, output_view, EvalOptions};
use lemi_gpu::{BackendChoice, Gpu, RenderOptions};

/// Side in texels of the tiles whose emptiness a walk would know without fetching a texel.
const TILE: usize = 8;

/// The opaque texels of one layer of one face, and which of its tiles hold any.
struct Occupancy {
    texels: Vec<bool>,
    tiles: Vec<bool>,
}

/// Percentiles of counts.
fn summary(v: &mut [u32]) -> String {
    if v.is_empty() {
        return "-".into();
    }
    v.sort_unstable();
    let p = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    let mean = v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
    format!(
        "mean {mean:5.1} p50 {:3} p90 {:3} p99 {:3} max {:3} ({} px)",
        p(0.5),
        p(0.9),
        p(0.99),
        v[v.len() - 1],
        v.len()
    )
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        anyhow::bail!("usage: layer_march BUNDLE CELL_ID [--size WxH]");
    }
    let mut eval = EvalOptions::default();
    if let Some(i) = args.iter().position(|a| a == "--size") {
        let v = args.get(i + 1).context("--size WxH")?;
        eval.size = Some(parse_size(v).map_err(|e| anyhow!("--size {e}"))?);
    }
    let opened = lemi_scene::open_bundle(std::path::Path::new(&args[0]), &[], None)?;
    let (bundle, scene) = (opened.bundle, opened.scene);
    let id: CellId = args[1].parse().map_err(|e| anyhow!("{e}"))?;
    let file = bundle.cell(id)?;
    let macros = file.decode_macros()?;
    let header = &file.header;
    let res = header.resolution as usize;
    let tiles_per_side = res.div_ceil(TILE);
    // occupancy per face slot and layer (layer index as the quads count it: far to near)
    let mut occ: Vec<Vec<Occupancy>> = header
        .layers
        .iter()
        .map(|layers| {
            layers
                .iter()
                .map(|_| Occupancy {
                    texels: vec![false; res * res],
                    tiles: vec![false; tiles_per_side * tiles_per_side],
                })
                .collect()
        })
        .collect();
    for q in &header.quads {
        let slot = header
            .faces
            .iter()
            .position(|f| *f == q.face)
            .context("a quad of a face the cell does not have")?;
        let o = occ[slot]
            .get_mut(q.layer as usize)
            .context("a quad of a layer the face does not have")?;
        let m = macros
            .get(q.macro_index as usize)
            .context("a quad of a missing macro-texture")?;
        let [x0, y0, x1, y1] = q.texels.map(|v| v as u32);
        let [rx, ry, rw, _] = q.rect;
        for y in y0..y1 {
            for x in x0..x1 {
                let (u, v) = (x - x0, y - y0);
                let (mx, my) = if q.rotated {
                    (rx + rw - 1 - v, ry + u)
                } else {
                    (rx + u, ry + v)
                };
                let k = 4 * (my * m.width + mx) as usize + 3;
                if m.rgba.get(k).is_some_and(|&a| a >= 128) {
                    let i = y as usize * res + x as usize;
                    o.texels[i] = true;
                    o.tiles[(y as usize / TILE) * tiles_per_side + x as usize / TILE] = true;
                }
            }
        }
    }
    let center = header.quad_origin();
    let gpu = Gpu::new(BackendChoice::Auto)?;
    let r = CellRenderers::new(&gpu, &scene, &bundle, id)?;
    let (w, h, fov_x) = output_view(bundle.manifest(), &eval);
    let views = common::views((None, None), &bundle, id, |l| l == "centre")?;
    let options = RenderOptions::default();
    let (mut all_cross, mut all_fetch, mut all_sky) = (Vec::new(), Vec::new(), Vec::new());
    let (mut agree, mut checked, mut near_px) = (0u64, 0u64, 0u64);
    for (label, eye, dir) in &views {
        let cam = camera(*eye, *dir, fov_x, w, h)?;
        let view = cam.view();
        let frame = r.impostors.render(&r.cell, &view, &options)?;
        let quads = r
            .impostors
            .render_impostors_only(&r.cell, &view, &options)?;
        let d = dir.normalize();
        let right = d.cross(DVec3::Y).normalize();
        let up = right.cross(d);
        let tx = (0.5 * fov_x.to_radians()).tan();
        let ty = tx * h as f64 / w as f64;
        let (mut cross_v, mut fetch_v, mut sky_v) = (Vec::new(), Vec::new(), Vec::new());
        for py in 0..h as usize {
            for px in 0..w as usize {
                let i = py * w as usize + px;
                let (full, far) = (frame.depth[i], quads.depth[i]);
                let sky = !full.is_finite();
                let shows_quad = far.is_finite() && (full - far).abs() <= 1e-4 * far.max(1.0);
                if !(sky || shows_quad) {
                    near_px += 1;
                    continue;
                }
                let nx = 2.0 * (px as f64 + 0.5) / w as f64 - 1.0;
                let ny = 1.0 - 2.0 * (py as f64 + 0.5) / h as f64;
                let ray = (d + right * (nx * tx) + up * (ny * ty)).normalize();
                let e = *eye - center;
                // every layer plane the ray crosses inside its face's pyramid, nearest first
                let mut crossings: Vec<(f64, usize, usize, usize)> = Vec::new();
                for (slot, face) in header.faces.iter().enumerate() {
                    let a = face.forward();
                    let va = ray.dot(a);
                    if va <= 0.0 {
                        continue;
                    }
                    for (k, layer) in header.layers[slot].iter().enumerate() {
                        let t = (layer.distance - e.dot(a)) / va;
                        if t <= 0.0 {
                            continue;
                        }
                        let p = e + ray * t;
                        let z = p.dot(a);
                        let (s, tt) = (p.dot(face.right()) / z, p.dot(face.down()) / z);
                        if !((-1.0..1.0).contains(&s) && (-1.0..1.0).contains(&tt)) {
                            continue;
                        }
                        let xi = (((s + 1.0) * 0.5 * res as f64) as usize).min(res - 1);
                        let yi = (((tt + 1.0) * 0.5 * res as f64) as usize).min(res - 1);
                        crossings.push((t, slot, k, yi * res + xi));
                    }
                }
                crossings.sort_by(|a, b| a.0.total_cmp(&b.0));
                let (mut crossed, mut fetched, mut hit) = (0u32, 0u32, None);
                for &(t, slot, k, texel) in &crossings {
                    crossed += 1;
                    let o = &occ[slot][k];
                    let (xi, yi) = (texel % res, texel / res);
                    if o.tiles[(yi / TILE) * tiles_per_side + xi / TILE] {
                        fetched += 1;
                        if o.texels[texel] {
                            hit = Some(t);
                            break;
                        }
                    }
                }
                if sky {
                    sky_v.push(crossed);
                    continue;
                }
                checked += 1;
                if let Some(t) = hit {
                    let depth = t * ray.dot(d);
                    // the frame's depth is within the grown rim's reach of the walk's texel
                    if (depth - far as f64).abs() <= 0.02 * depth {
                        agree += 1;
                    }
                }
                cross_v.push(crossed);
                fetch_v.push(fetched);
            }
        }
        println!("{label}");
        println!("  far field: planes crossed {}", summary(&mut cross_v));
        println!("  far field: texels fetched {}", summary(&mut fetch_v));
        println!("  background: planes crossed {}", summary(&mut sky_v));
        all_cross.extend(cross_v);
        all_fetch.extend(fetch_v);
        all_sky.extend(sky_v);
    }
    println!(
        "all {} views ({w}x{h}): {} near-geometry pixels skipped",
        views.len(),
        near_px
    );
    println!("  far field: planes crossed {}", summary(&mut all_cross));
    println!("  far field: texels fetched {}", summary(&mut all_fetch));
    println!("  background: planes crossed {}", summary(&mut all_sky));
    println!(
        "  the walk's first opaque texel at the frame's depth (2 %): {agree} of {checked} far-field pixels"
    );
    Ok(())
}
