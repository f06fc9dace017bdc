//! Axis-aligned boxes against a view's clip volume, the test frustum culling is made of (Assarsson
//! & Möller, "Optimized View Frustum Culling Algorithms for Bounding Boxes", JGT 5(1), 2000; here
//! in clip space, on the box's eight corners).
//!
//! The clip volume is wgpu's: `−w ≤ x ≤ w`, `−w ≤ y ≤ w`, `0 ≤ z ≤ w` (reverse-Z puts the near
//! plane at `z = w`; see [`crate::camera`]). A box is **outside** when all its corners lie beyond
//! one plane by a margin far above the f32 error of the GPU's vertex transform, so that nothing in
//! a culled box could have produced a single fragment: culling by this test never changes the
//! image. A box is **inside** when all its corners lie inside every plane by that margin, so every
//! point of it is inside (the clip volume is convex). Anything else **intersects**; a hierarchy
//! tests the children of such a box only.

use glam::{DMat4, DVec3};

use crate::Aabb;

/// Where a box lies relative to a clip volume ([`classify_box`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoxClip {
    /// Wholly beyond one plane (or empty): nothing in it can be drawn.
    Outside,
    /// Wholly inside every plane: everything in it is in view (up to occlusion).
    Inside,
    /// Neither (or too close to a plane to tell).
    Intersects,
}

/// The margin of a corner's plane values: relative to the size of its clip coordinates, so that it
/// stays far above f32 rounding at any distance.
fn margin(c: glam::DVec4) -> f64 {
    1e-4 * (c.x.abs() + c.y.abs() + c.z.abs() + c.w.abs()) + 1e-9
}

/// Classifies the box `[min, max]` against the clip volume of `view_proj` (see the module docs).
/// An empty box (`min > max` on some axis) is `Outside`; a box with a NaN or infinite coordinate is
/// `Intersects` (never culled).
pub fn classify_box(min: DVec3, max: DVec3, view_proj: &DMat4) -> BoxClip {
    if !min.cmple(max).all() {
        return if min.is_nan() || max.is_nan() {
            BoxClip::Intersects
        } else {
            BoxClip::Outside
        };
    }
    if !(min.is_finite() && max.is_finite()) {
        return BoxClip::Intersects;
    }
    let mut out = [true; 6];
    let mut inside = true;
    for i in 0..8 {
        let pick = |bit: usize, lo: f64, hi: f64| if i & bit == 0 { lo } else { hi };
        let p = DVec3::new(
            pick(1, min.x, max.x),
            pick(2, min.y, max.y),
            pick(4, min.z, max.z),
        );
        let c = *view_proj * p.extend(1.0);
        let m = margin(c);
        let planes = [c.w + c.x, c.w - c.x, c.w + c.y, c.w - c.y, c.z, c.w - c.z];
        for (o, v) in out.iter_mut().zip(planes) {
            // plane value ≥ −margin: possibly inside
            if v >= -m {
                *o = false;
            }
            if v < m {
                inside = false;
            }
        }
    }
    if out.iter().any(|&o| o) {
        BoxClip::Outside
    } else if inside {
        BoxClip::Inside
    } else {
        BoxClip::Intersects
    }
}

/// Whether the box `[min, max]` lies entirely outside one of the clip volume's planes of
/// `view_proj` by the margin (see the module docs), or is empty.
pub fn box_outside(min: DVec3, max: DVec3, view_proj: &DMat4) -> bool {
    classify_box(min, max, view_proj) == BoxClip::Outside
}

impl Aabb {
    /// [`classify_box`] of this box.
    pub fn clip(&self, view_proj: &DMat4) -> BoxClip {
        classify_box(self.min, self.max, view_proj)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use proptest::prelude::*;

    fn view_proj() -> DMat4 {
        Camera::new(
            DVec3::new(10.0, 0.0, 0.0),
            -DVec3::Z,
            DVec3::Y,
            90.0,
            64,
            64,
        )
        .expect("camera")
        .view()
        .view_proj()
    }

    fn b(min: [f64; 3], max: [f64; 3]) -> (DVec3, DVec3) {
        let o = DVec3::new(10.0, 0.0, 0.0);
        (DVec3::from_array(min) + o, DVec3::from_array(max) + o)
    }

    #[test]
    fn boxes_are_culled_only_when_wholly_outside() {
        let vp = view_proj();
        let c = |(min, max): (DVec3, DVec3)| classify_box(min, max, &vp);
        // in front, straddling the left edge, around the eye
        assert_eq!(c(b([-1.0, -1.0, -6.0], [1.0, 1.0, -5.0])), BoxClip::Inside);
        assert_eq!(
            c(b([-9.0, -1.0, -5.0], [-4.0, 1.0, -5.0])),
            BoxClip::Intersects
        );
        assert_eq!(
            c(b([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0])),
            BoxClip::Intersects
        );
        // a plane seen edge-on at the frustum's side (x = −z, 45° left): kept
        assert_eq!(
            c(b([-5.0, -1.0, -5.0], [-5.0, 1.0, -5.0])),
            BoxClip::Intersects
        );
        // behind the eye, wholly left, above, right
        for (min, max) in [
            ([-1.0, -1.0, 2.0], [1.0, 1.0, 3.0]),
            ([-9.0, -1.0, -5.0], [-6.0, 1.0, -5.0]),
            ([-1.0, 6.0, -5.0], [1.0, 8.0, -5.0]),
            ([6.0, -1.0, -5.0], [9.0, 1.0, -5.0]),
        ] {
            assert_eq!(c(b(min, max)), BoxClip::Outside, "{min:?} {max:?}");
        }
        assert!(Aabb::EMPTY.clip(&vp) == BoxClip::Outside);
        assert!(box_outside(Aabb::EMPTY.min, Aabb::EMPTY.max, &vp));
        // non-finite boxes are never culled
        let nan = DVec3::splat(f64::NAN);
        assert_eq!(classify_box(nan, nan, &vp), BoxClip::Intersects);
        let inf = DVec3::splat(f64::INFINITY);
        assert_eq!(classify_box(-inf, inf, &vp), BoxClip::Intersects);
    }

    /// Strictly inside the clip volume (by a relative margin well above the test's).
    fn clearly_inside(vp: &DMat4, p: DVec3) -> bool {
        let c = *vp * p.extend(1.0);
        let m = 1e-3 * c.w.abs();
        c.w > 0.0
            && [c.w + c.x, c.w - c.x, c.w + c.y, c.w - c.y, c.z, c.w - c.z]
                .iter()
                .all(|&v| v > m)
    }

    /// In the closed clip volume.
    fn in_clip(vp: &DMat4, p: DVec3) -> bool {
        let c = *vp * p.extend(1.0);
        [c.w + c.x, c.w - c.x, c.w + c.y, c.w - c.y, c.z, c.w - c.z]
            .iter()
            .all(|&v| v >= 0.0)
    }

    proptest! {
        /// Against brute force on random cameras and boxes: a point of the box clearly in view
        /// means the box is not culled; an `Outside` box has no point in the clip volume; every
        /// point of an `Inside` box is in it.
        #[test]
        fn random_boxes_against_sampled_points(
            eye in prop::array::uniform3(-50.0f64..50.0),
            yaw in -180.0f64..180.0,
            pitch in -80.0f64..80.0,
            fov in 20.0f64..120.0,
            lo in prop::array::uniform3(-60.0f64..60.0),
            size in prop::array::uniform3(0.0f64..40.0),
            samples in prop::collection::vec(prop::array::uniform3(0.0f64..=1.0), 64),
        ) {
            let (y, p) = (yaw.to_radians(), pitch.to_radians());
            let forward = DVec3::new(y.sin() * p.cos(), p.sin(), -y.cos() * p.cos());
            let vp = Camera::new(DVec3::from_array(eye), forward, DVec3::Y, fov, 64, 48)
                .expect("camera")
                .view()
                .view_proj();
            let min = DVec3::from_array(lo);
            let max = min + DVec3::from_array(size);
            let class = classify_box(min, max, &vp);
            let corners = (0..8).map(|i| {
                DVec3::new(
                    if i & 1 == 0 { 0.0 } else { 1.0 },
                    if i & 2 == 0 { 0.0 } else { 1.0 },
                    if i & 4 == 0 { 0.0 } else { 1.0 },
                )
            });
            for s in samples.iter().map(|s| DVec3::from_array(*s)).chain(corners) {
                let q = min + s * (max - min);
                if class == BoxClip::Outside {
                    prop_assert!(!in_clip(&vp, q), "culled box has {q} in view");
                }
                if class == BoxClip::Inside {
                    prop_assert!(in_clip(&vp, q), "inside box has {q} out of view");
                }
                if clearly_inside(&vp, q) {
                    prop_assert!(class != BoxClip::Outside);
                }
            }
        }
    }
}
