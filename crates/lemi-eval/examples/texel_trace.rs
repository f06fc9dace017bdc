//! Traces one output pixel of an impostor view to the layer texels behind it: the ray through the
//! pixel's centre from `--eye` is met with the plane of every quad of the cell, and each quad it
//! passes through is printed far to near with its layer (distance and slab), the texel of the
//! face image and of the macro-texture the ray meets, and that texel's colour and alpha (the
//! texels ±`--around` to either side along the face image's rows too, with `|` at the quad's
//! rectangle border). What silhouette and crack questions come down to: which layer shows the
//! pixel, which texel, and where its outline lies.
//!
//! ```text
//! cargo run --release -p lemi-eval --example texel_trace -- BUNDLE CELL_ID \
//!     --eye x,y,z --dir x,y,z --pixel x,y [--size WxH] [--around 3]
//! ```
//!
//! The camera is `lemi eval`'s: the bundle's output view (`--size` another), up +Y.

use anyhow::{anyhow, bail, Context, Result};
use glam::DVec3;
use lemi_core::camera::parse_size;
use lemi_core::cell::CellId;
use lemi_eval::{camera, output_view, EvalOptions};

mod common;
use common::vec3;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        bail!("usage: texel_trace BUNDLE CELL_ID --eye x,y,z --dir x,y,z --pixel x,y [--size WxH] [--around 3]");
    }
    let (mut eye, mut dir, mut pixel, mut around) = (None, None, None, 3i64);
    let mut eval = EvalOptions::default();
    let mut i = 2;
    while i + 1 < args.len() {
        let v = &args[i + 1];
        match args[i].as_str() {
            "--eye" => eye = Some(vec3(v)?),
            "--dir" => dir = Some(vec3(v)?),
            "--pixel" => {
                let (x, y) = v.split_once(',').context("--pixel x,y")?;
                pixel = Some((x.parse::<f64>()?, y.parse::<f64>()?));
            }
            "--size" => eval.size = Some(parse_size(v).map_err(|e| anyhow!("--size {e}"))?),
            "--around" => around = v.parse().context("--around")?,
            f => bail!("unknown flag {f}"),
        }
        i += 2;
    }
    let (Some(eye), Some(dir), Some((px, py))) = (eye, dir, pixel) else {
        bail!("--eye, --dir and --pixel are needed");
    };
    let bundle = lemi_core::bundle::Bundle::open(std::path::Path::new(&args[0]))?;
    let id: CellId = args[1].parse().map_err(|e| anyhow!("{e}"))?;
    let (w, h, fov_x) = output_view(bundle.manifest(), &eval);
    let cam = camera(eye, dir, fov_x, w, h)?;
    // the ray through the pixel's centre
    let d = dir.normalize();
    let right = d.cross(DVec3::Y).normalize();
    let up = right.cross(d);
    let tx = (0.5 * fov_x.to_radians()).tan();
    let ty = tx * h as f64 / w as f64;
    let nx = 2.0 * (px + 0.5) / w as f64 - 1.0;
    let ny = 1.0 - 2.0 * (py + 0.5) / h as f64;
    let ray = (d + right * (nx * tx) + up * (ny * ty)).normalize();
    let _ = cam;
    let file = bundle.cell(id)?;
    let macros = file.decode_macros()?;
    let header = &file.header;
    println!(
        "cell {id}: reference viewpoint {}, resolution {}, near field {:.2} m; ray {ray:.5} from {eye}",
        lemi_core::bundle::reference_viewpoint(&header.cell),
        header.resolution,
        header.near_field
    );
    let mut hits = Vec::new();
    for q in &header.quads {
        let c: Vec<DVec3> = q
            .corners
            .iter()
            .map(|c| DVec3::from(c.map(f64::from)))
            .collect();
        let n = (c[1] - c[0]).cross(c[3] - c[0]);
        let denom = n.dot(ray);
        if denom.abs() < 1e-12 {
            continue;
        }
        let t = n.dot(c[0] - eye) / denom;
        if t <= 0.0 {
            continue;
        }
        let p = eye + ray * t;
        // (s, t) of p in the quad: corners (s0,t0) (s1,t0) (s1,t1) (s0,t1)
        let es = c[1] - c[0];
        let et = c[3] - c[0];
        let s = (p - c[0]).dot(es) / es.length_squared();
        let tt = (p - c[0]).dot(et) / et.length_squared();
        let [x0, y0, x1, y1] = q.texels.map(f64::from);
        let (fx, fy) = (x0 + s * (x1 - x0), y0 + tt * (y1 - y0));
        // within the quad or up to `around` texels beside it
        let margin = around as f64;
        if !(fy >= y0 - margin && fy < y1 + margin && fx >= x0 - margin && fx < x1 + margin) {
            continue;
        }
        hits.push((t, *q, fx, fy, p));
    }
    hits.sort_by(|a, b| b.0.total_cmp(&a.0));
    let face_index = |f| header.faces.iter().position(|g| *g == f);
    for (t, q, fx, fy, p) in hits {
        let layer = face_index(q.face).and_then(|fi| header.layers[fi].get(q.layer as usize));
        let [x0, y0, x1, y1] = q.texels.map(i64::from);
        let inside = fx >= x0 as f64 && fx < x1 as f64 && fy >= y0 as f64 && fy < y1 as f64;
        println!(
            "{} face {:?} layer {} (distance {:.3}, slab {:.3}..{}) at {t:.3} m, point {p:.3}; face texel ({fx:.3}, {fy:.3}) in quad texels [{x0}, {y0}, {x1}, {y1}]",
            if inside { "HIT " } else { "near" },
            q.face,
            q.layer,
            layer.map_or(f64::NAN, |l| l.distance),
            layer.map_or(f64::NAN, |l| l.near_border),
            layer.map_or("?".to_string(), |l| if l.far_border >= f64::MAX { "inf".into() } else { format!("{:.3}", l.far_border) }),
        );
        // the texels along the row, from the quad's own macro-texture rectangle
        let m = &macros[q.macro_index as usize];
        let (tyi, txi) = (fy.floor() as i64, fx.floor() as i64);
        let mut row = String::new();
        for x in (txi - around)..=(txi + around) {
            if x == x0 {
                row.push('|');
            }
            if x < x0 || x >= x1 || tyi < y0 || tyi >= y1 {
                row.push_str(" ---------- ");
            } else {
                // face texel → macro texel (undo a rotation)
                let (u, v) = ((x - x0) as u32, (tyi - y0) as u32);
                let [rx, ry, rw, _] = q.rect;
                let (mx, my) = if q.rotated {
                    (rx + rw - 1 - v, ry + u)
                } else {
                    (rx + u, ry + v)
                };
                let k = 4 * (my * m.width + mx) as usize;
                let t = &m.rgba[k..k + 4];
                let mark = if x == txi { '*' } else { ' ' };
                row.push_str(&format!(
                    "{mark}{:02x}{:02x}{:02x}/{:3} ",
                    t[0], t[1], t[2], t[3]
                ));
            }
            if x + 1 == x1 {
                row.push('|');
            }
        }
        println!(
            "      row {tyi}, texels {}..={}: {row}",
            txi - around,
            txi + around
        );
    }
    Ok(())
}
