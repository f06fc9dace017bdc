//! Looks closely at the silhouettes of one view of a bundle: renders the reference (all geometry)
//! and the impostor frame at the output size and at `k×` that size (the same camera), and prints
//! the silhouette distances of [`lemi_eval::silhouettes`] at both (at `k×`, divided by `k`: the
//! outlines of both renderers at sub-pixel precision). Writes `coverage.png` (1×: grey = both
//! cover, red = only the impostor, blue = only the reference) for the view.
//!
//!     cargo run --release -p lemi-eval --example silhouette_probe -- BUNDLE CELL_ID \
//!         --eye x,y,z --dir x,y,z [--k 4] [--out DIR]
//!
//! Without `--eye`, the corners and the centre of the cell, each looking along every evaluated
//! direction, and the five worst views by the 1× p99 are printed.
//!
//! `--jitter PX` measures what the silhouette distance gives for the geometry itself: instead of
//! the `k×` frames, each view's reference is compared with the reference of the same eye turned
//! by `PX` pixels right and `PX` up (every point of the image moved by about `PX` along both
//! axes, no parallax), next to the impostor's numbers, and the maxima over all views are printed.

use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use glam::DVec3;
use lemi_core::cell::CellId;
use lemi_eval::{camera, output_view, silhouettes, EvalOptions};
use lemi_gpu::{BackendChoice, Frame, Gpu, RenderOptions};

mod common;
use common::{vec3, CellRenderers};

struct Probe {
    r: CellRenderers,
    fov_x: f64,
    size: (u32, u32),
}

struct Views {
    reference: Frame,
    impostor: Frame,
}

impl Probe {
    /// The reference from `eye` looking along `dir`, turned by `px` pixels
    /// ([`lemi_eval::turned_camera`]).
    fn turned_reference(&self, eye: DVec3, dir: DVec3, px: f64) -> Result<Frame> {
        let (w, h) = self.size;
        let view = lemi_eval::turned_camera(eye, dir, self.fov_x, w, h, px)?.view();
        Ok(self
            .r
            .reference
            .render(&self.r.full, &view, &RenderOptions::default())?)
    }

    fn render(&self, eye: DVec3, dir: DVec3, k: u32) -> Result<Views> {
        let view = camera(eye, dir, self.fov_x, self.size.0 * k, self.size.1 * k)?.view();
        let options = RenderOptions::default();
        Ok(Views {
            reference: self.r.reference.render(&self.r.full, &view, &options)?,
            impostor: self.r.impostors.render(&self.r.cell, &view, &options)?,
        })
    }
}

/// (p99, max, mean) of the silhouette distances, the false coverage and (p99, max) of the
/// displacement, in output pixels.
fn summary(v: &Views, k: u32) -> Result<(f32, f32, f32, u64, f32, f32)> {
    let s = silhouettes(&v.reference, &v.impostor)?;
    let (d, m) = (&s.distances, &s.displacement);
    let k = k as f32;
    Ok((
        d.p99() / k,
        d.max() / k,
        d.mean() as f32 / k,
        s.false_coverage,
        m.p99() / k,
        m.max() / k,
    ))
}

/// Grey: both cover; red: only the impostor; blue: only the reference.
fn coverage_png(v: &Views, path: &std::path::Path) -> Result<()> {
    let mut img = image::RgbImage::new(v.reference.width, v.reference.height);
    for (i, px) in img.pixels_mut().enumerate() {
        let (r, t) = (
            v.reference.depth[i].is_finite(),
            v.impostor.depth[i].is_finite(),
        );
        *px = image::Rgb(match (r, t) {
            (true, true) => [128, 128, 128],
            (false, true) => [255, 0, 0],
            (true, false) => [0, 80, 255],
            (false, false) => [0, 0, 0],
        });
    }
    img.save(path)?;
    Ok(())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        bail!(
            "usage: silhouette_probe BUNDLE CELL_ID [--eye x,y,z --dir x,y,z] [--k 4] [--out DIR]"
        );
    }
    let (mut eye, mut dir, mut k, mut out) = (None, None, 4u32, PathBuf::from("silhouette-probe"));
    let mut jitter: Option<f64> = None;
    let mut i = 2;
    while i + 1 < args.len() {
        match args[i].as_str() {
            "--eye" => eye = Some(vec3(&args[i + 1])?),
            "--dir" => dir = Some(vec3(&args[i + 1])?),
            "--k" => k = args[i + 1].parse().context("--k")?,
            "--out" => out = PathBuf::from(&args[i + 1]),
            "--jitter" => jitter = Some(args[i + 1].parse().context("--jitter")?),
            f => bail!("unknown flag {f}"),
        }
        i += 2;
    }
    let opened = lemi_scene::open_bundle(std::path::Path::new(&args[0]), &[], None)?;
    let (bundle, scene) = (opened.bundle, opened.scene);
    let id: CellId = args[1].parse().map_err(|e| anyhow!("{e}"))?;
    let gpu = Gpu::new(BackendChoice::Auto)?;
    let (w, h, fov_x) = output_view(bundle.manifest(), &EvalOptions::default());
    let probe = Probe {
        r: CellRenderers::new(&gpu, &scene, &bundle, id)?,
        fov_x,
        size: (w, h),
    };
    let views = common::views((eye, dir), &bundle, id, |l| {
        l == "centre" || l.starts_with("corner")
    })?;
    if let Some(px) = jitter {
        return jitter_table(&probe, &views, px, &out);
    }
    let mut rows = Vec::new();
    for (label, e, d) in &views {
        let one = probe.render(*e, *d, 1)?;
        let s1 = summary(&one, 1)?;
        let kx = probe.render(*e, *d, k)?;
        let sk = summary(&kx, k)?;
        if views.len() == 1 {
            std::fs::create_dir_all(&out)?;
            coverage_png(&kx, &out.join(format!("coverage-{k}x.png")))?;
        }
        println!(
            "{label:32} 1x: p99 {:5.2} max {:6.2} mean {:5.3} false {:6} displ p99 {:5.2} max {:6.2} | {k}x: p99 {:5.2} max {:6.2} displ p99 {:5.2} max {:6.2}",
            s1.0, s1.1, s1.2, s1.3, s1.4, s1.5, sk.0, sk.1, sk.4, sk.5
        );
        rows.push((s1.0, label.clone(), *e, *d, one));
    }
    rows.sort_by(|a, b| b.0.total_cmp(&a.0));
    std::fs::create_dir_all(&out)?;
    for (n, (p99, label, e, d, v)) in rows.iter().take(5).enumerate() {
        let path = out.join(format!("coverage-{n}.png"));
        coverage_png(v, &path)?;
        println!(
            "worst {n}: {label} (eye {e}, dir {d}) p99 {p99:.2} → {}",
            path.display()
        );
    }
    Ok(())
}

/// `--jitter`: per view, the silhouette numbers of the impostor and of the reference turned by
/// `px` pixels, both against the reference; then their maxima and how many views exceed 2 px.
fn jitter_table(
    probe: &Probe,
    views: &[(String, DVec3, DVec3)],
    px: f64,
    out: &std::path::Path,
) -> Result<()> {
    let mut worst: Option<(f32, String, Views)> = None;
    let (mut imp_max, mut ref_max) = (0f32, 0f32);
    let (mut imp_over, mut ref_over) = (0, 0);
    let (mut imp_false, mut ref_false) = (0u64, 0u64);
    for (label, e, d) in views {
        let one = probe.render(*e, *d, 1)?;
        let imp = summary(&one, 1)?;
        let turned = Views {
            reference: one.reference.clone(),
            impostor: probe.turned_reference(*e, *d, px)?,
        };
        let geo = summary(&turned, 1)?;
        println!(
            "{label:32} impostor: p99 {:5.2} max {:6.2} false {:6} displ max {:5.2} | geometry turned {px} px: p99 {:5.2} max {:6.2} false {:6} displ max {:5.2}",
            imp.0, imp.1, imp.3, imp.5, geo.0, geo.1, geo.3, geo.5
        );
        if worst.as_ref().is_none_or(|w| geo.1 > w.0) {
            worst = Some((geo.1, format!("{label} (eye {e}, dir {d})"), turned));
        }
        imp_max = imp_max.max(imp.1);
        ref_max = ref_max.max(geo.1);
        imp_over += usize::from(imp.1 > 2.0);
        ref_over += usize::from(geo.1 > 2.0);
        imp_false += imp.3;
        ref_false += geo.3;
    }
    println!(
        "{} views: silhouette distance max {imp_max:.2} px (views above 2 px: {imp_over}, false coverage {imp_false} px) for the impostor, {ref_max:.2} px ({ref_over}, {ref_false} px) for the geometry turned by {px} px",
        views.len()
    );
    if let Some((max, label, v)) = worst {
        std::fs::create_dir_all(out)?;
        let path = out.join("coverage-turned.png");
        coverage_png(&v, &path)?;
        println!(
            "worst turned: {label}, max {max:.2} px → {}",
            path.display()
        );
    }
    Ok(())
}
