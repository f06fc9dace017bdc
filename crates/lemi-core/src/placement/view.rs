//! The output view's side of the error metric: the allowed parallax angle α from the output
//! resolution and field of view, and impostor texture resolutions.
//!
//! This work is based on: GI 2002 sec. 4.3 ("an obvious choice for α is the minimal angle subtended
//! by a pixel in the output image"); *Real-Time Rendering* 3rd ed. sec. 10.7.1, eq. 10.5 and
//! Fig. 10.14 (`β_scr = fov/screenres`), Schaufler's resolution rule (`β_tex ≤ β_scr`).
//!
//! Pixel angles of a pinhole view with horizontal field of view `fov` across `width` pixels: the
//! image plane at distance 1 is `2·tan(fov/2)` wide, so a pixel is `2·tan(fov/2)/width` wide there.
//! The **centre** pixel subtends the largest angle, `2·atan(tan(fov/2)/width)`; the **edge** pixel
//! (the outermost column) the smallest, `atan(t) − atan(t·(1 − 2/width))` with `t = tan(fov/2)`.
//! The paper's α is the minimal one (edge), which keeps the parallax under one pixel everywhere.

use super::{check_alpha, invalid, PlacementError};
use serde::{Deserialize, Serialize};

/// Which output pixel α refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PixelChoice {
    /// The outermost pixel, the smallest angle (GI 2002 sec. 4.3: "the minimal angle"); default.
    #[default]
    Edge,
    /// The central pixel, the largest angle.
    Centre,
}

fn check_view(fov: f64, width: u32) -> Result<(), PlacementError> {
    if !fov.is_finite() || fov <= 0.0 || fov >= std::f64::consts::PI {
        return Err(invalid(
            "output_fov",
            fov,
            "the output field of view must be > 0 and < 180° (radians)",
        ));
    }
    if width == 0 {
        return Err(invalid("output_width", 0.0, "must be >= 1 pixel"));
    }
    Ok(())
}

/// Angle (radians) subtended by the central pixel of a view `fov` wide (radians) across `width`.
pub fn pixel_angle_centre(fov: f64, width: u32) -> Result<f64, PlacementError> {
    check_view(fov, width)?;
    Ok(2.0 * ((fov / 2.0).tan() / f64::from(width)).atan())
}

/// Angle (radians) subtended by the outermost pixel of a view `fov` wide across `width` pixels.
pub fn pixel_angle_edge(fov: f64, width: u32) -> Result<f64, PlacementError> {
    check_view(fov, width)?;
    let t = (fov / 2.0).tan();
    Ok(t.atan() - (t * (1.0 - 2.0 / f64::from(width))).atan())
}

/// α (radians) from the output view: the angle of one output pixel, the edge or centre one.
pub fn alpha_from_output_view(
    fov: f64,
    width: u32,
    pixel: PixelChoice,
) -> Result<f64, PlacementError> {
    let a = match pixel {
        PixelChoice::Edge => pixel_angle_edge(fov, width)?,
        PixelChoice::Centre => pixel_angle_centre(fov, width)?,
    };
    check_alpha(a)?;
    Ok(a)
}

/// The smallest face resolution `Res` whose central texel (the largest texel of a 90° face,
/// `2·atan(1/Res)`) subtends no more than the central output pixel: `Res ≥ width / tan(fov/2)`.
/// Below it, layer texels are magnified on screen and the one-pixel guarantee is only nominal.
/// (The rule of thumb `width · 90°/fov` is the small-angle form of the same rule.)
pub fn min_face_res_for_output_view(fov: f64, width: u32) -> Result<u32, PlacementError> {
    check_view(fov, width)?;
    let r = (f64::from(width) / (fov / 2.0).tan() - 1e-9).ceil();
    Ok(r.min(f64::from(u32::MAX)) as u32)
}

/// RTR eq. 10.5: the impostor texture resolution that does not exceed the screen resolution,
/// `texres = screenres · objsize / (2 · distance · tan(fov/2))`.
pub fn texres_rtr(
    screen_res: u32,
    object_size: f64,
    distance: f64,
    fov: f64,
) -> Result<f64, PlacementError> {
    check_view(fov, screen_res)?;
    if !object_size.is_finite() || object_size <= 0.0 {
        return Err(invalid("object_size", object_size, "must be > 0"));
    }
    if !distance.is_finite() || distance <= 0.0 {
        return Err(invalid("distance", distance, "must be > 0"));
    }
    // Eq. 10.5.
    Ok(f64::from(screen_res) * object_size / (2.0 * distance * (fov / 2.0).tan()))
}

/// Schaufler's rule (RTR Fig. 10.14, TR sec. 2.1.1): the smallest texture resolution whose texels,
/// seen from `min_distance` (the closest viewpoint), subtend at most `pixel_angle`
/// (`β_tex ≤ β_scr`): an object of size `object_size` facing the viewer needs
/// `res = ⌈object_size / (2·min_distance·tan(pixel_angle/2))⌉`.
pub fn schaufler_res(
    object_size: f64,
    min_distance: f64,
    pixel_angle: f64,
) -> Result<u32, PlacementError> {
    check_alpha(pixel_angle)?;
    if !object_size.is_finite() || object_size <= 0.0 {
        return Err(invalid("object_size", object_size, "must be > 0"));
    }
    if !min_distance.is_finite() || min_distance <= 0.0 {
        return Err(invalid("min_distance", min_distance, "must be > 0"));
    }
    let r = (object_size / (2.0 * min_distance * (pixel_angle / 2.0).tan())).ceil();
    if r > f64::from(u32::MAX) {
        return Err(invalid(
            "object_size",
            object_size,
            "needs a texture resolution beyond u32",
        ));
    }
    Ok((r as u32).max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_angles_bracket_the_linear_rule() {
        let fov = 60f64.to_radians();
        let (e, c) = (
            pixel_angle_edge(fov, 1280).unwrap(),
            pixel_angle_centre(fov, 1280).unwrap(),
        );
        assert!(e < fov / 1280.0 && fov / 1280.0 < c);
        // The edge pixel is cos²(fov/2) times the centre one to first order.
        assert!((e / c - (fov / 2.0).cos().powi(2)).abs() < 1e-3);
        // Summing every pixel of one half gives fov/2.
        let t = (fov / 2.0).tan();
        let sum: f64 = (0..640)
            .map(|i| {
                let (a, b) = (i as f64 / 640.0, (i + 1) as f64 / 640.0);
                (t * b).atan() - (t * a).atan()
            })
            .sum();
        assert!((sum - fov / 2.0).abs() < 1e-12);
    }

    #[test]
    fn texres_and_schaufler_agree_for_a_facing_object() {
        // An object filling the whole view needs the screen resolution.
        let fov = 60f64.to_radians();
        let d = 10.0;
        let size = 2.0 * d * (fov / 2.0).tan();
        assert!((texres_rtr(1000, size, d, fov).unwrap() - 1000.0).abs() < 1e-9);
        let r = schaufler_res(size, d, pixel_angle_centre(fov, 1000).unwrap()).unwrap();
        assert!((999..=1001).contains(&r), "{r}");
    }

    #[test]
    fn bad_views_are_errors() {
        assert!(pixel_angle_edge(0.0, 100).is_err());
        assert!(pixel_angle_edge(4.0, 100).is_err());
        assert!(pixel_angle_centre(1.0, 0).is_err());
        assert!(schaufler_res(-1.0, 1.0, 0.01).is_err());
        assert!(texres_rtr(100, 1.0, f64::NAN, 1.0).is_err());
    }
}
