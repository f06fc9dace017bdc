//! The per-pixel geometric error of a frame drawn with billboards (see "Error" in the module
//! docs): the parallax, in output pixels, between where a texel's true surface point projects
//! and where its billboard shows it, measured as `lemi_core::parallax_error` measures layered
//! impostors (Jeschke, Wimmer & Schumann, "Layered environment-map impostors for arbitrary
//! scenes", GI 2002, sec. 4: the error of an impostor point is the parallax between its true
//! position and its image on the impostor plane), so the strategies compare.

use glam::{DVec2, DVec3, DVec4};
use lemi_core::camera::View;
use lemi_gpu::Frame;

use super::objects::Impostor;
use super::validity::frustum_planes;

/// The per-pixel error of `frame`, drawn from `view` with `billboards` (see the module docs): per
/// pixel that shows a billboard texel, the distance in output pixels between the projections of
/// the texel's true surface point `T = e + (L_s − e)·depth/d` (`e` the generation eye, `L_s` the
/// centre of the texel whose colour it shows on the plane at distance `d`) and of the texel's
/// centre `L` on the billboard; `NaN` elsewhere.
pub(super) fn measure_error(frame: &Frame, view: &View, billboards: &[&Impostor]) -> Vec<f32> {
    use rayon::prelude::*;
    let (w, h) = (frame.width as usize, frame.height as usize);
    let vp = view.view_proj();
    let inv = vp.inverse();
    let eye = view.eye();
    let depth_axis = -DVec3::new(view.view.x_axis.z, view.view.y_axis.z, view.view.z_axis.z);
    let project = |p: DVec3| -> Option<DVec2> {
        let c = vp * p.extend(1.0);
        (c.w > 0.0).then(|| view.ndc_to_pixel(DVec2::new(c.x / c.w, c.y / c.w)))
    };
    // per billboard: plane, edges and screen rectangle (x0, x1, y0, y1)
    struct Prepared<'a> {
        imp: &'a Impostor,
        normal: DVec3,
        centre: DVec3,
        du: DVec3,
        dv: DVec3,
        rect: (usize, usize, usize, usize),
    }
    let planes = frustum_planes(&vp);
    let prepared: Vec<Prepared> = billboards
        .iter()
        .filter(|imp| {
            // not wholly outside one plane of the view frustum
            let corners = imp.crop_corners();
            planes
                .iter()
                .all(|p| corners.iter().any(|c| p.truncate().dot(*c) + p.w >= 0.0))
        })
        .map(|imp| {
            let [c0, c1, c2, c3] = imp.corners;
            let centre = (c0 + c2) * 0.5;
            let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
            let mut behind = false;
            for c in imp.crop_corners() {
                match project(c) {
                    Some(p) => {
                        lo = lo.min(p);
                        hi = hi.max(p);
                    }
                    None => behind = true,
                }
            }
            let rect = if behind {
                (0, w, 0, h)
            } else {
                let clampx = |v: f64| (v.max(0.0) as usize).min(w);
                let clampy = |v: f64| (v.max(0.0) as usize).min(h);
                (
                    clampx(lo.x.floor() - 1.0),
                    clampx(hi.x.ceil() + 1.0),
                    clampy(lo.y.floor() - 1.0),
                    clampy(hi.y.ceil() + 1.0),
                )
            };
            Prepared {
                imp,
                normal: (imp.eye - centre).normalize(),
                centre,
                du: c1 - c0,
                dv: c3 - c0,
                rect,
            }
        })
        .collect();
    let mut out = vec![f32::NAN; w * h];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let mut best = vec![f32::INFINITY; w];
            let rays: Vec<DVec3> = (0..w)
                .map(|x| {
                    let ndc = view.pixel_to_ndc(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                    let p0 = inv * DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
                    let p1 = inv * DVec4::new(ndc.x, ndc.y, 0.5, 1.0);
                    p1.truncate() / p1.w - p0.truncate() / p0.w
                })
                .collect();
            for b in prepared.iter().filter(|b| b.rect.2 <= y && y < b.rect.3) {
                let imp = b.imp;
                let res = imp.res as usize;
                let c0 = imp.corners[0];
                let margin = 1.0 / 16.0 + 1e-6;
                let [cx, cy, cw, ch] = imp.crop.map(|v| v as usize);
                for x in b.rect.0..b.rect.1 {
                    let z = frame.depth[y * w + x];
                    if !z.is_finite() {
                        continue;
                    }
                    let dir = rays[x];
                    let denom = b.normal.dot(dir);
                    if denom.abs() < 1e-12 {
                        continue;
                    }
                    let t = b.normal.dot(b.centre - eye) / denom;
                    if t <= 0.0 {
                        continue;
                    }
                    let p = eye + dir * t;
                    let vd = depth_axis.dot(p - eye);
                    let score = ((vd - z as f64).abs() / (z as f64).max(1e-6)) as f32;
                    if score > 2e-4 || score >= best[x] {
                        continue;
                    }
                    // image texel coordinates, then the drawn (cropped) rectangle grown as the
                    // impostor renderer grows quads
                    let u = (p - c0).dot(b.du) / b.du.length_squared() * res as f64;
                    let v = (p - c0).dot(b.dv) / b.dv.length_squared() * res as f64;
                    let (fu, fv) = (u - cx as f64, v - cy as f64);
                    if fu < -margin
                        || fu > cw as f64 + margin
                        || fv < -margin
                        || fv > ch as f64 + margin
                    {
                        continue;
                    }
                    let ci = (fu.floor().max(0.0) as usize).min(cw - 1);
                    let cj = (fv.floor().max(0.0) as usize).min(ch - 1);
                    let k = cj * cw + ci;
                    if !imp.depth[k].is_finite() {
                        continue;
                    }
                    let (i, j) = (ci + cx, cj + cy);
                    // the true point of the texel whose colour this texel shows
                    let src = imp.source.get(k).map_or(k, |&s| s as usize);
                    let (si, sj) = (src % cw + cx, src / cw + cy);
                    let centre_of = |i: usize, j: usize| {
                        c0 + b.du * ((i as f64 + 0.5) / res as f64)
                            + b.dv * ((j as f64 + 0.5) / res as f64)
                    };
                    let l = centre_of(i, j);
                    let ls = centre_of(si, sj);
                    let truth = imp.eye + (ls - imp.eye) * (imp.depth[src] as f64 / imp.distance);
                    row[x] = match (project(truth), project(l)) {
                        (Some(q), Some(s)) => (q - s).length() as f32,
                        _ => f32::NAN,
                    };
                    best[x] = score;
                }
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use lemi_core::camera::Camera;

    /// A 2 m billboard 10 m down −Z, generated from the origin, 4 × 4 texels whose true surface
    /// points all lie 12 m deep.
    fn billboard() -> Impostor {
        let z = -10.0;
        Impostor {
            eye: DVec3::ZERO,
            distance: 10.0,
            half: 1.0,
            res: 4,
            corners: [
                DVec3::new(-1.0, 1.0, z),
                DVec3::new(1.0, 1.0, z),
                DVec3::new(1.0, -1.0, z),
                DVec3::new(-1.0, -1.0, z),
            ],
            crop: [0, 0, 4, 4],
            depth: vec![12.0; 16],
            source: Vec::new(),
            rgba: vec![255; 64],
        }
    }

    /// What a renderer draws of the billboard from `eye` looking down −Z (90°, 64²): depth 10
    /// where a pixel's ray meets the square.
    fn frame(eye: DVec3) -> (View, Frame) {
        let n = 64u32;
        let view = Camera::new(eye, -DVec3::Z, DVec3::Y, 90.0, n, n)
            .expect("camera")
            .view();
        let mut depth = vec![f32::INFINITY; (n * n) as usize];
        for y in 0..n {
            for x in 0..n {
                let ndc = view.pixel_to_ndc(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                // 90°: the ray through ndc meets z = eye.z − 10 at eye.xy + 10 · ndc
                let p = eye.truncate() + 10.0 * ndc;
                if p.x.abs() <= 1.0 && p.y.abs() <= 1.0 {
                    depth[(y * n + x) as usize] = 10.0;
                }
            }
        }
        let frame = Frame {
            width: n,
            height: n,
            rgba: vec![0; (4 * n * n) as usize],
            depth,
        };
        (view, frame)
    }

    #[test]
    fn no_error_from_the_generation_eye() {
        let imp = billboard();
        let (view, frame) = frame(DVec3::ZERO);
        let e = measure_error(&frame, &view, &[&imp]);
        let measured: Vec<f32> = e.iter().copied().filter(|v| !v.is_nan()).collect();
        // the square covers ndc ±0.1: 6 × 6 pixels
        assert_eq!(measured.len(), 36);
        assert!(measured.iter().all(|v| v.abs() < 1e-4), "{measured:?}");
        // background pixels are NaN
        assert!(e[0].is_nan());
    }

    #[test]
    fn sideways_the_error_is_the_texels_parallax() {
        // from 0.5 m to the right, a texel centre L = (x, y, −10) projects to ndc
        // ((x − 0.5)/10, y/10) and its true point T = 1.2·L to ((1.2x − 0.5)/12, y/12·1.2):
        // apart by 0.5/10 − 0.5/12 in ndc, times 32 pixels per ndc unit
        let imp = billboard();
        let (view, frame) = frame(DVec3::new(0.5, 0.0, 0.0));
        let e = measure_error(&frame, &view, &[&imp]);
        let measured: Vec<f32> = e.iter().copied().filter(|v| !v.is_nan()).collect();
        assert!(!measured.is_empty());
        let want = 32.0 * (0.05 - 0.5 / 12.0);
        for v in measured {
            assert!((v as f64 - want).abs() < 1e-3, "{v} vs {want}");
        }
    }
}
