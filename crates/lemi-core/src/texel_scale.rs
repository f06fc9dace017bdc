//! An upper bound on how many texels of an impostor quad one output pixel spans, for a whole
//! group of quads and any eye, computed per frame in constant time. A renderer uses it to draw
//! with nearest texels, without any filter code, every group of quads whose texels are certainly
//! larger than the filter's threshold (`lemi_gpu`'s quad pipelines: the footprint filter takes
//! the texel under the pixel's centre wherever a texel spans two pixels or more, so where the
//! bound says so the two pipelines write the same pixels).
//!
//! # The bound
//! A quad lies in a plane with unit normal `n` at distance `D = |n·(P − R)|` from a chosen origin
//! `R` (a cell's reference viewpoint), its texels are squares of world size `t` at least (the
//! shorter of its edges over their texel counts; the edges are perpendicular). Seen from the eye
//! `E` through a perspective view whose pixels subtend at most `θ` radians (`1/F`, `F` the focal
//! length in pixels: a pixel step turns the ray by at most that, less off the axis), a pixel step
//! moves the ray's hit point `P` on the plane by at most `ρ·θ / c` (`ρ = |P − E|`, `c` the
//! cosine between the ray and `n`: the oblique projection of a turn perpendicular to the ray
//! stretches it by at most `1/c`), i.e. by at most `ρ²·θ / |n·(P − E)|` texels times `1/t`.
//! With `h = |E − R|`, `ρ ≤ |P − R| + h` and `|n·(P − E)| ≥ D − h`, so
//!
//! ```text
//! texels per pixel ≤ θ · (D/t) · (g + h/D)² / (1 − h/D),   g = |P − R| / D,   h < D
//! ```
//!
//! which grows with `g` and shrinks with `D`; over a group of quads it is therefore at most
//! [`TexelScale::texels_per_pixel`], made of the largest `D/t` and `g` and the smallest `D` of the
//! group (`g` is largest at a corner: `|P − R|` is convex). The bound holds for the pixel
//! differences a GPU takes (`dpdx`): a difference over one pixel step is at most the largest
//! derivative along it.

use glam::DVec3;

use crate::camera::View;

/// The largest `D/t` and `g` and the smallest `D` of a group of quads (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelScale {
    /// The largest ratio of a quad's plane distance from the origin to its texel size.
    pub distance_per_texel: f64,
    /// The largest distance of a quad's corner from the origin over its plane's distance (≥ 1).
    pub spread: f64,
    /// The smallest plane distance from the origin.
    pub min_distance: f64,
}

impl TexelScale {
    /// The bound of one quad with `corners` (in order around it, as drawn) whose texels span
    /// `texels` = `[w, h]` along the edges `corners[0] → corners[1]` and `corners[0] →
    /// corners[3]`, seen from around `origin`. `None` where the bound does not apply: a
    /// degenerate or non-rectangular quad, a plane through the origin, non-finite numbers.
    pub fn of_quad(origin: DVec3, corners: [DVec3; 4], texels: [f64; 2]) -> Option<TexelScale> {
        let (e1, e3) = (corners[1] - corners[0], corners[3] - corners[0]);
        let (l1, l3) = (e1.length(), e3.length());
        let n = e1.cross(e3).try_normalize()?;
        // perpendicular edges, and a planar quad (its fourth corner on the plane)
        let planar = (n.dot(corners[2] - corners[0])).abs() <= 1e-6 * (l1 + l3);
        if e1.dot(e3).abs() > 1e-4 * l1 * l3 || !planar {
            return None;
        }
        let t = (l1 / texels[0]).min(l3 / texels[1]);
        let d = n.dot(corners[0] - origin).abs();
        let far = corners
            .iter()
            .map(|c| c.distance(origin))
            .fold(0.0f64, f64::max);
        let s = TexelScale {
            distance_per_texel: d / t,
            spread: far / d,
            min_distance: d,
        };
        (t > 0.0 && d > 0.0 && s.distance_per_texel.is_finite() && s.spread.is_finite())
            .then_some(s)
    }

    /// The bound of a group: the largest `D/t` and spread, the smallest distance.
    pub fn merge(self, other: TexelScale) -> TexelScale {
        TexelScale {
            distance_per_texel: self.distance_per_texel.max(other.distance_per_texel),
            spread: self.spread.max(other.spread),
            min_distance: self.min_distance.min(other.min_distance),
        }
    }

    /// At most how many texels one pixel step spans on any quad of the group, for an eye `h` from
    /// the origin and pixels subtending at most `pixel_angle` radians (see the module docs);
    /// infinite where the eye is as far from the origin as the nearest plane (the bound does not
    /// hold there).
    pub fn texels_per_pixel(&self, h: f64, pixel_angle: f64) -> f64 {
        pixel_angle * self.factor(h)
    }

    /// [`TexelScale::texels_per_pixel`] over the pixel angle: `(D/t)·(g + h/D)²/(1 − h/D)`,
    /// growing with `h`.
    pub fn factor(&self, h: f64) -> f64 {
        let r = h / self.min_distance;
        // NaN (a non-finite eye) fails both tests
        let applies = (0.0..1.0).contains(&r) && h >= 0.0;
        if !applies {
            return f64::INFINITY;
        }
        self.distance_per_texel * (self.spread + r).powi(2) / (1.0 - r)
    }
}

/// Steps of [`TexelScaleTable`] between the origin and its reach.
const TABLE_STEPS: usize = 8;

/// The bound of a group of quads tabulated over the eye's distance from the origin, up to
/// `reach` (the farthest a viewpoint of the view cell is): the largest [`TexelScale::factor`] of
/// the group's quads at `TABLE_STEPS + 1` distances. Each quad's factor grows with the
/// distance, so the entry at the next tabulated distance at or beyond the eye's bounds every
/// quad; tighter than the group's merged [`TexelScale`], which combines the largest spread and
/// the smallest distance of different quads. Beyond `reach`, the merged bound.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelScaleTable {
    reach: f64,
    at: [f64; TABLE_STEPS + 1],
    all: TexelScale,
}

impl TexelScaleTable {
    /// The table of a group holding only `first`, over eyes up to `reach` from the origin.
    pub fn new(reach: f64, first: TexelScale) -> TexelScaleTable {
        let reach = if reach.is_finite() {
            reach.max(0.0)
        } else {
            0.0
        };
        TexelScaleTable {
            reach,
            at: std::array::from_fn(|i| first.factor(reach * i as f64 / TABLE_STEPS as f64)),
            all: first,
        }
    }

    /// Adds a quad to the group.
    pub fn add(&mut self, s: TexelScale) {
        for (i, v) in self.at.iter_mut().enumerate() {
            *v = v.max(s.factor(self.reach * i as f64 / TABLE_STEPS as f64));
        }
        self.all = self.all.merge(s);
    }

    /// At most how many texels one pixel step spans on any quad of the group, for an eye `h`
    /// from the origin and pixels subtending at most `pixel_angle` radians.
    /// Both the tabulated and the merged bound hold; this is the smaller.
    pub fn texels_per_pixel(&self, h: f64, pixel_angle: f64) -> f64 {
        let merged = self.all.texels_per_pixel(h, pixel_angle);
        let step = if h == 0.0 {
            0.0
        } else {
            (h / self.reach * TABLE_STEPS as f64).ceil()
        };
        if (0.0..=TABLE_STEPS as f64).contains(&step) {
            merged.min(pixel_angle * self.at[step as usize])
        } else {
            merged
        }
    }
}

/// The largest angle (radians) one pixel step turns a view's ray by: `1/F` for a perspective
/// projection without skew whose focal lengths are `F` pixels (the smaller of the two axes') and
/// a rigid view matrix. `None` for anything else (orthographic, skewed or scaled views), where no
/// bound is claimed.
pub fn pixel_angle(view: &View) -> Option<f64> {
    let p = view.proj;
    let perspective = p.x_axis.y == 0.0
        && p.x_axis.w == 0.0
        && p.y_axis.x == 0.0
        && p.y_axis.w == 0.0
        && p.z_axis.w == -1.0
        && p.w_axis.w == 0.0;
    let m = view.view;
    let (a, b, c) = (
        m.x_axis.truncate(),
        m.y_axis.truncate(),
        m.z_axis.truncate(),
    );
    let unit = |v: DVec3| (v.length() - 1.0).abs() < 1e-9;
    let rigid = unit(a)
        && unit(b)
        && unit(c)
        && a.dot(b).abs() < 1e-9
        && a.dot(c).abs() < 1e-9
        && b.dot(c).abs() < 1e-9;
    let fx = p.x_axis.x.abs() * 0.5 * view.width as f64;
    let fy = p.y_axis.y.abs() * 0.5 * view.height as f64;
    let f = fx.min(fy);
    (perspective && rigid && f.is_finite() && f > 0.0).then(|| 1.0 / f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use glam::DVec2;
    use proptest::prelude::*;

    /// The texel coordinates of the hit of the ray through `pixel` on the quad's plane, in texels
    /// along its two edges from corner 0 (`None` behind the eye or parallel).
    fn texel_at(
        view: &View,
        corners: &[DVec3; 4],
        texels: [f64; 2],
        pixel: DVec2,
    ) -> Option<DVec2> {
        let (o, d) = view.pixel_ray(pixel);
        let (e1, e3) = (corners[1] - corners[0], corners[3] - corners[0]);
        let n = e1.cross(e3).normalize();
        let den = n.dot(d);
        if den.abs() < 1e-12 {
            return None;
        }
        let s = n.dot(corners[0] - o) / den;
        if s <= 0.0 {
            return None;
        }
        let q = o + d * s - corners[0];
        Some(DVec2::new(
            q.dot(e1) / e1.length_squared() * texels[0],
            q.dot(e3) / e3.length_squared() * texels[1],
        ))
    }

    /// A quad of a cube-map face layer: face axis `axis`, `D` from the origin, texel rectangle
    /// `[x0, y0, x1, y1]` of a `res`² face image.
    fn face_quad(origin: DVec3, axis: usize, d: f64, res: f64, rect: [f64; 4]) -> [DVec3; 4] {
        let (f, r, u) = match axis {
            0 => (DVec3::X, DVec3::NEG_Z, DVec3::NEG_Y),
            1 => (DVec3::NEG_Z, DVec3::NEG_X, DVec3::NEG_Y),
            _ => (DVec3::Z, DVec3::X, DVec3::NEG_Y),
        };
        let at = |x: f64, y: f64| {
            origin + d * (f + r * (-1.0 + 2.0 * x / res) + u * (-1.0 + 2.0 * y / res))
        };
        [
            at(rect[0], rect[1]),
            at(rect[2], rect[1]),
            at(rect[2], rect[3]),
            at(rect[0], rect[3]),
        ]
    }

    proptest! {
        /// Brute force: the texel step of every pixel step measured on random quads of cube-map
        /// layers, from random eyes around the origin looking in random directions, never exceeds
        /// the bound of a group holding the quad.
        #[test]
        fn measured_texel_steps_stay_within_the_bound(
            axis in 0usize..3,
            d in 5.0f64..500.0,
            res in 64.0f64..2048.0,
            x0 in 0.0f64..0.9, y0 in 0.0f64..0.9, w in 0.02f64..0.1, hgt in 0.02f64..0.1,
            eye in prop::array::uniform3(-4.0f64..4.0),
            yaw in -180.0f64..180.0, pitch in -80.0f64..80.0,
            fov in 20.0f64..110.0,
            size in prop::array::uniform2(64u32..1600),
            samples in prop::collection::vec((0.0f64..1.0, 0.0f64..1.0), 16),
        ) {
            let origin = DVec3::new(100.0, -20.0, 3000.0);
            let rect = [x0 * res, y0 * res, (x0 + w) * res, (y0 + hgt) * res];
            let texels = [rect[2] - rect[0], rect[3] - rect[1]];
            let corners = face_quad(origin, axis, d, res, rect);
            let own = TexelScale::of_quad(origin, corners, texels).expect("a face quad");
            // a group: this quad and one of another layer farther out at the face's centre
            let other = face_quad(origin, axis, 3.0 * d, res, [0.5 * res, 0.5 * res, 0.5 * res + 8.0, 0.5 * res + 8.0]);
            let group = own.merge(TexelScale::of_quad(origin, other, [8.0, 8.0]).expect("quad"));
            let e = origin + DVec3::from_array(eye);
            let camera = Camera::from_yaw_pitch(e, yaw, pitch, fov, size[0], size[1]).expect("camera");
            let view = camera.view();
            let theta = pixel_angle(&view).expect("a perspective view");
            let bound = group.texels_per_pixel(e.distance(origin), theta);
            prop_assert!(own.texels_per_pixel(e.distance(origin), theta) <= bound);
            for (a, b) in samples {
                // a point of the quad, projected, then one pixel step along each axis
                let p = corners[0] + (corners[1] - corners[0]) * a + (corners[3] - corners[0]) * b;
                let Some(at) = view.project(p) else { continue };
                for step in [DVec2::X, DVec2::Y] {
                    let (Some(t0), Some(t1)) = (
                        texel_at(&view, &corners, texels, at.pixel),
                        texel_at(&view, &corners, texels, at.pixel + step),
                    ) else {
                        continue;
                    };
                    let moved = t0.distance(t1);
                    prop_assert!(moved <= bound * (1.0 + 1e-6), "{moved} texels > bound {bound}");
                }
            }
        }
    }

    proptest! {
        /// The tabulated bound of a group is at least every member's own bound, for any eye
        /// distance, within the reach and beyond it, and never above the merged bound.
        #[test]
        fn the_table_bounds_every_quad_of_its_group(
            quads in prop::collection::vec((5.0f64..500.0, 64.0f64..2048.0, 0.0f64..0.9, 0.0f64..0.9), 1..12),
            reach in 0.0f64..8.0,
            h in 0.0f64..10.0,
        ) {
            let origin = DVec3::new(-7.0, 2.0, 40.0);
            let scales: Vec<TexelScale> = quads
                .iter()
                .map(|&(d, res, x, y)| {
                    let rect = [x * res, y * res, x * res + 8.0, y * res + 8.0];
                    TexelScale::of_quad(origin, face_quad(origin, 0, d, res, rect), [8.0, 8.0]).expect("quad")
                })
                .collect();
            let mut table = TexelScaleTable::new(reach, scales[0]);
            let mut all = scales[0];
            for s in &scales[1..] {
                table.add(*s);
                all = all.merge(*s);
            }
            let bound = table.texels_per_pixel(h, 1e-3);
            for s in &scales {
                let own = s.texels_per_pixel(h, 1e-3);
                prop_assert!(own <= bound, "{own} > {bound}");
            }
            prop_assert!(bound <= all.texels_per_pixel(h, 1e-3));
        }
    }

    #[test]
    fn the_bound_is_tight_at_a_face_centre() {
        // from the origin, looking at the centre of a 512² face layer with a 60° view 1280 px wide:
        // a texel spans F·2/Res pixels there, i.e. Res/(2F) texels a pixel
        let origin = DVec3::ZERO;
        let corners = face_quad(origin, 1, 100.0, 512.0, [255.0, 255.0, 257.0, 257.0]);
        let s = TexelScale::of_quad(origin, corners, [2.0, 2.0]).expect("quad");
        let camera = Camera::from_yaw_pitch(origin, 0.0, 0.0, 60.0, 1280, 720).expect("cam");
        let theta = pixel_angle(&camera.view()).expect("perspective");
        let exact = 256.0 * theta;
        let bound = s.texels_per_pixel(0.0, theta);
        assert!(
            bound >= exact && bound < exact * 1.0001,
            "{bound} vs {exact}"
        );
        // the eye as far out as the nearest plane: no bound
        assert_eq!(s.texels_per_pixel(100.0, theta), f64::INFINITY);
        // a sheared quad has none either
        let mut skew = corners;
        skew[1].y += 0.5;
        skew[2].y += 0.5;
        assert_eq!(TexelScale::of_quad(origin, skew, [2.0, 2.0]), None);
    }
}
