//! The validity math of dynamically generated impostors: the texture resolution of
//! Akenine-Möller, Haines & Hoffman, *Real-Time Rendering*, eq. 10.5, the billboard covering an
//! object's bounding sphere, Schaufler's validity angles (Schaufler, "Dynamically generated
//! impostors", 1995; RTR sec. 10.7.1) and the view-frustum test that decides which impostors are
//! checked at all. Every function here is pure (no GPU, no scene).

use glam::{DMat4, DVec3, DVec4};
use lemi_core::camera::View;

use crate::StrategyError;

/// The texture resolution of an impostor, Akenine-Möller, Haines & Hoffman, *Real-Time
/// Rendering*, eq. 10.5, before rounding: `screen_res · object_size / (2 · distance ·
/// tan(fov_y / 2))` (texels per side such that one texel covers about one output pixel).
pub fn texture_resolution_exact(
    screen_res: u32,
    fov_y: f64,
    object_size: f64,
    distance: f64,
) -> f64 {
    screen_res as f64 * object_size / (2.0 * distance * (0.5 * fov_y).tan())
}

/// *Real-Time Rendering* eq. 10.5 ([`texture_resolution_exact`]) rounded up to a power of two
/// and clamped to `[min, max]` (powers of two). Non-finite values (distance 0) give `max`.
pub fn texture_resolution(
    screen_res: u32,
    fov_y: f64,
    object_size: f64,
    distance: f64,
    min: u32,
    max: u32,
) -> u32 {
    round_resolution(
        texture_resolution_exact(screen_res, fov_y, object_size, distance),
        min,
        max,
    )
}

/// Rounds an exact resolution of eq. 10.5 (*Real-Time Rendering*) up to a power of two (ignoring
/// a relative excess of 1e-9, floating-point noise) and clamps it to `[min, max]`.
fn round_resolution(exact: f64, min: u32, max: u32) -> u32 {
    if !(exact.is_finite()) || exact >= max as f64 {
        return max;
    }
    let r = (exact * (1.0 - 1e-9)).ceil().max(1.0) as u32;
    r.next_power_of_two().clamp(min, max)
}

/// The texture resolution at which one texel of a billboard of side `object_size` seen head-on
/// from `distance` subtends the angle `beta` (*Real-Time Rendering* eq. 10.5 written for an
/// angle, the `β_tex` of sec. 10.7.1 solved for the resolution): `object_size / (distance · tan β)`, rounded and
/// clamped like [`texture_resolution`]. With `β = β_scr` of a view ([`view_angles`]) this is
/// eq. 10.5 for that view exactly (`tan β_scr = 2·tan(fov/2) / screenres`); the strategy uses it
/// so that a texture generated at this resolution passes the `β_tex` test also when `β` is scaled
/// or overridden.
pub fn resolution_for_angle(object_size: f64, distance: f64, beta: f64, min: u32, max: u32) -> u32 {
    round_resolution(object_size / (distance * beta.tan()), min, max)
}

/// The output view's vertical field of view (radians) and its central pixel's angle `β_scr`
/// (`atan(2·tan(fov/2) / height)`), from the projection's y scale: Schaufler's threshold
/// (Schaufler 1995; *Real-Time Rendering* sec. 10.7.1, there approximated as `fov/screenres`)
/// taken exactly at the image centre.
pub fn view_angles(view: &View) -> Result<(f64, f64), StrategyError> {
    let f = view.proj.y_axis.y;
    if !(f.is_finite() && f > 0.0) || view.height == 0 {
        return Err(StrategyError::Invalid(format!(
            "dynamic strategy: the output view is not a perspective view with a vertical field of view (projection y scale {f}, height {})",
            view.height
        )));
    }
    let fov = 2.0 * (1.0 / f).atan();
    Ok((fov, (2.0 / (f * view.height as f64)).atan()))
}

/// Half side of the billboard, through the sphere's centre and facing the eye, that covers the
/// silhouette of a sphere of radius `r` seen from distance `d > r`: the silhouette cone has half
/// angle `asin(r/d)`, so `h = d·tan(asin(r/d)) = r / sqrt(1 − (r/d)²)` (Schaufler 1995 sizes the
/// billboard to the object's bounding sphere; a square of half side `r` would cut it off).
pub fn billboard_half_size(radius: f64, distance: f64) -> f64 {
    let s = (radius / distance).min(1.0 - 1e-9);
    radius / (1.0 - s * s).sqrt()
}

/// Schaufler's validity angles of an impostor generated from `gen_eye` (radians), seen from
/// `eye` (Schaufler, "Dynamically generated impostors", 1995; *Real-Time Rendering*
/// sec. 10.7.1); see the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidityAngles {
    /// `β_trans`: sideways motion (parallax).
    pub trans: f64,
    /// `β_size`: the apparent size change (motion towards or away from the object).
    pub size: f64,
    /// `β_tex`: the angle one texel subtends.
    pub tex: f64,
}

/// The validity angles (Schaufler 1995; *Real-Time Rendering* sec. 10.7.1) of the impostor of an
/// object (centre, bounding radius) generated from `gen_eye` with a billboard of half side `half`
/// and `res` texels per side, seen from `eye`: `β_trans` the angle at the centre between the two
/// eyes, `β_size` the larger angular error of the bounding cube's front and back extreme points,
/// `β_tex` the angle of one texel at the billboard's centre.
pub fn validity_angles(
    gen_eye: DVec3,
    eye: DVec3,
    centre: DVec3,
    radius: f64,
    half: f64,
    res: u32,
) -> ValidityAngles {
    let a = gen_eye - centre;
    let b = eye - centre;
    let trans = a.cross(b).length().atan2(a.dot(b));
    let (dg, dc) = (a.length(), b.length());
    let size = [1.0f64, -1.0]
        .iter()
        .map(|&s| {
            let shown = (radius * dg / ((dg - s * radius) * dc)).atan();
            let truth = (radius / (dc - s * radius)).atan();
            (shown - truth).abs()
        })
        .fold(0.0, f64::max);
    let tex = (2.0 * half / (res as f64 * dc)).atan();
    ValidityAngles { trans, size, tex }
}

/// The side planes and the near plane of a reverse-Z view-projection, as `(normal, offset)` with
/// unit normals pointing inside (Gribb & Hartmann, "Fast extraction of viewing frustum planes
/// from the world-view-projection matrix", 2001: the side planes are row 3 ± row 0 and
/// row 3 ± row 1; with reverse Z (depth 1 at the near plane) the near plane is row 3 − row 2, and
/// the far plane is left out).
pub(crate) fn frustum_planes(vp: &DMat4) -> Vec<DVec4> {
    let (r0, r1, r2, r3) = (vp.row(0), vp.row(1), vp.row(2), vp.row(3));
    [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 - r2]
        .into_iter()
        .filter_map(|p| {
            let l = p.truncate().length();
            (l > 0.0 && l.is_finite()).then(|| p / l)
        })
        .collect()
}

/// Whether a sphere (centre `c`, radius `r`) is not wholly outside one of `planes` (from
/// [`frustum_planes`]): the conservative sphere–frustum test (the signed distance of the centre
/// to every plane is at least `−r`; Gribb & Hartmann 2001, as above).
pub(crate) fn sphere_visible(planes: &[DVec4], c: DVec3, r: f64) -> bool {
    planes.iter().all(|p| p.truncate().dot(c) + p.w >= -r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lemi_core::camera::Camera;

    fn view_90(width: u32, height: u32) -> View {
        Camera::new(DVec3::ZERO, -DVec3::Z, DVec3::Y, 90.0, width, height)
            .expect("camera")
            .view()
    }

    #[test]
    fn eq_10_5_exact() {
        // 90° (tan 45° = 1), 1000 px: a 4 m object at 20 m needs 1000 · 4 / 40 = 100 texels
        let fov = std::f64::consts::FRAC_PI_2;
        let r = texture_resolution_exact(1000, fov, 4.0, 20.0);
        assert!((r - 100.0).abs() < 1e-9, "{r}");
        // twice as far: half the texels
        assert!((texture_resolution_exact(1000, fov, 4.0, 40.0) - 50.0).abs() < 1e-9);
    }

    #[test]
    fn eq_10_5_rounded_and_clamped() {
        let fov = std::f64::consts::FRAC_PI_2;
        assert_eq!(texture_resolution(1000, fov, 4.0, 20.0, 8, 1024), 128);
        // exactly a power of two stays (64 texels)
        assert_eq!(texture_resolution(1000, fov, 4.0, 31.25, 8, 1024), 64);
        assert_eq!(texture_resolution(1000, fov, 4.0, 1e6, 8, 1024), 8);
        assert_eq!(texture_resolution(1000, fov, 4.0, 0.0, 8, 256), 256);
    }

    #[test]
    fn rounding_ignores_floating_point_noise() {
        assert_eq!(round_resolution(64.0 * (1.0 + 1e-12), 1, 1024), 64);
        assert_eq!(round_resolution(64.001, 1, 1024), 128);
        assert_eq!(round_resolution(0.0, 1, 1024), 1);
        assert_eq!(round_resolution(3.0, 16, 1024), 16);
        assert_eq!(round_resolution(f64::NAN, 16, 1024), 1024);
        assert_eq!(round_resolution(5000.0, 16, 1024), 1024);
    }

    #[test]
    fn resolution_for_the_pixel_angle_is_eq_10_5() {
        let v = view_90(200, 200);
        let (fov, beta) = view_angles(&v).expect("angles");
        for d in [2.0, 9.0, 33.0, 120.0] {
            assert_eq!(
                resolution_for_angle(6.0, d, beta, 1, 4096),
                texture_resolution(200, fov, 6.0, d, 1, 4096),
                "{d}"
            );
        }
        // a larger angle asks for fewer texels
        assert!(
            resolution_for_angle(6.0, 9.0, 4.0 * beta, 1, 4096)
                < resolution_for_angle(6.0, 9.0, beta, 1, 4096)
        );
    }

    #[test]
    fn view_angles_of_a_perspective_view() {
        let (fov, beta) = view_angles(&view_90(400, 300)).expect("angles");
        assert!((fov - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // 2 · tan 45° / 300 px
        assert!((beta - (2.0f64 / 300.0).atan()).abs() < 1e-12);
        let mut bad = view_90(400, 300);
        bad.height = 0;
        let e = view_angles(&bad).expect_err("no height").to_string();
        assert!(e.contains("dynamic strategy"), "{e}");
    }

    #[test]
    fn billboard_covers_the_silhouette() {
        // r = 5 at d = 13: half angle asin(5/13), tangent 5/12 → h = 13 · 5/12
        assert!((billboard_half_size(5.0, 13.0) - 65.0 / 12.0).abs() < 1e-12);
        // far away it tends to r
        assert!((billboard_half_size(1.0, 1e6) - 1.0).abs() < 1e-9);
        // at or inside the sphere it stays finite
        assert!(billboard_half_size(1.0, 0.5).is_finite());
    }

    #[test]
    fn validity_angles_of_simple_motions() {
        let c = DVec3::new(0.0, 0.0, -50.0);
        // moving on a circle about the centre by 0.1 rad: β_trans = 0.1, no size change
        let e2 = c + 50.0 * DVec3::new(0.1f64.sin(), 0.0, 0.1f64.cos());
        let a = validity_angles(DVec3::ZERO, e2, c, 2.0, 2.0, 32);
        assert!((a.trans - 0.1).abs() < 1e-12, "{a:?}");
        assert!(a.size.abs() < 1e-12, "{a:?}");
        // β_tex: one texel of a 4 m, 32-texel billboard at 50 m
        assert!((a.tex - (4.0f64 / (32.0 * 50.0)).atan()).abs() < 1e-12);
        // moving away by 50 m: the front point (2 m aside at 48 m) is shown at
        // atan(2 · 50 / (48 · 100)) but lies at atan(2 / 98)
        let b = validity_angles(DVec3::ZERO, DVec3::new(0.0, 0.0, 50.0), c, 2.0, 2.0, 32);
        let front = ((100.0f64 / 4800.0).atan() - (2.0f64 / 98.0).atan()).abs();
        let back = ((100.0f64 / 5200.0).atan() - (2.0f64 / 102.0).atan()).abs();
        assert!((b.size - front.max(back)).abs() < 1e-12, "{b:?}");
        assert!(b.trans.abs() < 1e-12);
    }

    #[test]
    fn frustum_planes_and_spheres() {
        let v = view_90(100, 100);
        let planes = frustum_planes(&v.view_proj());
        assert_eq!(planes.len(), 5);
        for p in &planes {
            assert!((p.truncate().length() - 1.0).abs() < 1e-9);
        }
        // in front, behind, beside (90°: the side planes are at 45°)
        assert!(sphere_visible(&planes, DVec3::new(0.0, 0.0, -10.0), 0.1));
        assert!(!sphere_visible(&planes, DVec3::new(0.0, 0.0, 10.0), 1.0));
        assert!(!sphere_visible(&planes, DVec3::new(20.0, 0.0, -10.0), 1.0));
        // beside, but large enough to reach into the view
        assert!(sphere_visible(&planes, DVec3::new(20.0, 0.0, -10.0), 8.0));
    }
}
