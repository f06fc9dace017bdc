//! How much the far field shimmers as the viewer turns, with and without the impostor renderer's
//! footprint filter ([`lemi_gpu::TexelFilter`]). For each view, `--frames` frames turn the camera
//! about the vertical by `--step-px` output pixels per frame; each frame is rendered
//!
//! - as the reference: all geometry at `k×` the output size, averaged down in linear light (an
//!   anti-aliased picture of what the far field should look like; its textures are mip-mapped);
//! - as impostors, with nearest texels and with the footprint filter;
//! - as all geometry at the output size (what the geometry renderer itself shows: its own
//!   shimmer is the baseline).
//!
//! Only the pixels where a quad is the visible surface are judged (the near geometry is the same
//! in both impostor frames). Printed per view and over all of them, in sRGB units (0–255):
//!
//! - `error`: mean |impostor − reference| of the pixels' luma, over the frames;
//! - `shimmer`: mean over the pixels (judged in every frame) of the standard deviation over the
//!   frames of that difference, `e_t = L_t − R_t`. A constant difference (a shading or
//!   compression offset) does not count; what counts is a difference that changes as the view
//!   moves by fractions of a pixel, which is what nearest sampling of minified texels does (a
//!   pixel jumps between the texels it skips) and what the eye sees as shimmer.
//!
//! ```text
//! cargo run --release -p lemi-eval --example shimmer -- BUNDLE CELL_ID \
//!     [--eye x,y,z --dir x,y,z] [--frames 8] [--step-px 0.25] [--k 4] [--size WxH]
//! ```
//!
//! The output view is the one the bundle was baked for (`--size` another: a smaller view than
//! the bake's minifies every quad).
//!
//! Without `--eye`, the cell's centre and two opposite corners, each looking along every
//! evaluated direction.

use anyhow::{anyhow, bail, Context, Result};
use glam::{DQuat, DVec3};
use lemi_core::camera::parse_size;
use lemi_core::cell::CellId;
use lemi_eval::{camera, output_view, EvalOptions};
use lemi_gpu::{BackendChoice, Frame, Gpu, RenderOptions, TexelFilter};

mod common;
use common::{vec3, CellRenderers};

fn to_linear(c: u8) -> f64 {
    let c = c as f64 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn to_srgb(l: f64) -> f64 {
    let c = if l <= 0.003_130_8 {
        l * 12.92
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    255.0 * c
}

/// Rec. 709 luma of sRGB-encoded RGB, in sRGB units.
fn luma(rgb: [f64; 3]) -> f64 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// Luma of every pixel of a frame.
fn lumas(f: &Frame) -> Vec<f64> {
    (f.rgba.chunks_exact(4))
        .map(|p| luma([p[0] as f64, p[1] as f64, p[2] as f64]))
        .collect()
}

/// Luma of a `k×` frame averaged down by `k×k` boxes in linear light.
fn downsampled_lumas(f: &Frame, k: u32) -> Vec<f64> {
    let (w, h) = (f.width / k, f.height / k);
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let mut sum = [0.0; 3];
            for dy in 0..k {
                for dx in 0..k {
                    let i = 4 * ((y * k + dy) * f.width + x * k + dx) as usize;
                    for (c, s) in sum.iter_mut().enumerate() {
                        *s += to_linear(f.rgba[i + c]);
                    }
                }
            }
            let n = (k * k) as f64;
            out.push(luma(sum.map(|s| to_srgb(s / n))));
        }
    }
    out
}

struct Setup {
    r: CellRenderers,
    fov_x: f64,
    size: (u32, u32),
    k: u32,
}

/// Sums over the judged pixels of one view's frames (index 0: nearest, 1: footprint, 2: the
/// geometry itself at the output size, whose own aliasing is the baseline).
#[derive(Default, Clone, Copy)]
struct Sums {
    pixels: f64,
    error: [f64; 2],
    shimmer: [f64; 3],
    shimmer_pixels: f64,
}

impl Sums {
    fn add(&mut self, o: &Sums) {
        self.pixels += o.pixels;
        self.shimmer_pixels += o.shimmer_pixels;
        for i in 0..2 {
            self.error[i] += o.error[i];
        }
        for i in 0..3 {
            self.shimmer[i] += o.shimmer[i];
        }
    }

    fn line(&self) -> String {
        let e = |i: usize| self.error[i] / self.pixels.max(1.0);
        let s = |i: usize| self.shimmer[i] / self.shimmer_pixels.max(1.0);
        format!(
            "error nearest {:6.2} footprint {:6.2} | shimmer geometry {:6.2} nearest {:6.2} footprint {:6.2} ({:.0} % of nearest) | {:.0} px judged",
            e(0),
            e(1),
            s(2),
            s(0),
            s(1),
            100.0 * s(1) / s(0).max(1e-9),
            self.shimmer_pixels
        )
    }
}

impl Setup {
    fn view(&mut self, eye: DVec3, dir: DVec3, frames: u32, step_px: f64) -> Result<Sums> {
        let (w, h) = self.size;
        let opts = RenderOptions::default();
        // one output pixel at the image centre, as an angle
        let px = (2.0 * (0.5 * self.fov_x.to_radians()).tan() / w as f64).atan();
        let mut sums = Sums::default();
        let n_px = (w * h) as usize;
        // per pixel: frames judged, and Σe, Σe² of nearest and footprint
        let mut count = vec![0u32; n_px];
        let mut moments = vec![[0.0f64; 6]; n_px];
        for t in 0..frames {
            let d = DQuat::from_rotation_y(px * step_px * t as f64) * dir;
            let view = camera(eye, d, self.fov_x, w, h)?.view();
            let big = camera(eye, d, self.fov_x, w * self.k, h * self.k)?.view();
            let reference =
                downsampled_lumas(&self.r.reference.render(&self.r.full, &big, &opts)?, self.k);
            self.r.impostors.set_texel_filter(TexelFilter::Nearest);
            let nearest = self.r.impostors.render(&self.r.cell, &view, &opts)?;
            let quads = self
                .r
                .impostors
                .render_impostors_only(&self.r.cell, &view, &opts)?;
            self.r.impostors.set_texel_filter(TexelFilter::Footprint);
            let footprint = self.r.impostors.render(&self.r.cell, &view, &opts)?;
            let (n, f) = (lumas(&nearest), lumas(&footprint));
            let geometry = lumas(&self.r.reference.render(&self.r.full, &view, &opts)?);
            for i in 0..n_px {
                // a quad is the visible surface: the quads-only frame has the full frame's depth
                let (a, b) = (nearest.depth[i], quads.depth[i]);
                if !(a.is_finite() && a == b) {
                    continue;
                }
                let (en, ef) = (n[i] - reference[i], f[i] - reference[i]);
                sums.pixels += 1.0;
                sums.error[0] += en.abs();
                sums.error[1] += ef.abs();
                count[i] += 1;
                let m = &mut moments[i];
                m[0] += en;
                m[1] += en * en;
                m[2] += ef;
                m[3] += ef * ef;
                let eg = geometry[i] - reference[i];
                m[4] += eg;
                m[5] += eg * eg;
            }
        }
        let sd = |sum: f64, sq: f64, n: f64| (sq / n - (sum / n).powi(2)).max(0.0).sqrt();
        for (c, m) in count.iter().zip(&moments) {
            if *c == frames {
                let n = frames as f64;
                sums.shimmer_pixels += 1.0;
                sums.shimmer[0] += sd(m[0], m[1], n);
                sums.shimmer[1] += sd(m[2], m[3], n);
                sums.shimmer[2] += sd(m[4], m[5], n);
            }
        }
        Ok(sums)
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        bail!("usage: shimmer BUNDLE CELL_ID [--eye x,y,z --dir x,y,z] [--frames 8] [--step-px 0.25] [--k 4] [--size WxH]");
    }
    let (mut eye, mut dir, mut frames, mut step_px, mut k) = (None, None, 8u32, 0.25f64, 4u32);
    let mut eval = EvalOptions::default();
    let mut i = 2;
    while i + 1 < args.len() {
        let v = &args[i + 1];
        match args[i].as_str() {
            "--eye" => eye = Some(vec3(v)?),
            "--dir" => dir = Some(vec3(v)?),
            "--frames" => frames = v.parse().context("--frames")?,
            "--step-px" => step_px = v.parse().context("--step-px")?,
            "--k" => k = v.parse().context("--k")?,
            "--size" => eval.size = Some(parse_size(v).map_err(|e| anyhow!("--size {e}"))?),
            f => bail!("unknown flag {f}"),
        }
        i += 2;
    }
    if frames < 2 || k == 0 {
        bail!("--frames must be at least 2 and --k at least 1");
    }
    let opened = lemi_scene::open_bundle(std::path::Path::new(&args[0]), &[], None)?;
    let (bundle, scene) = (opened.bundle, opened.scene);
    let id: CellId = args[1].parse().map_err(|e| anyhow!("{e}"))?;
    let gpu = Gpu::new(BackendChoice::Auto)?;
    let (w, h, fov_x) = output_view(bundle.manifest(), &eval);
    let mut setup = Setup {
        r: CellRenderers::new(&gpu, &scene, &bundle, id)?,
        fov_x,
        size: (w, h),
        k,
    };
    let views = common::views((eye, dir), &bundle, id, |l| {
        l == "centre" || l == "corner 0" || l == "corner 7"
    })?;
    println!(
        "{} views at {w}x{h}, {fov_x}° wide, {frames} frames turning {step_px} px a frame, reference at {k}x{k} samples",
        views.len()
    );
    let mut all = Sums::default();
    for (label, e, d) in &views {
        let s = setup.view(*e, *d, frames, step_px)?;
        println!("{label:28} {}", s.line());
        all.add(&s);
    }
    println!("{:28} {}", "all views", all.line());
    Ok(())
}
