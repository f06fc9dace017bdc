//! Cameras and views: eye, orientation, projection, and the six cube-face views of a reference
//! viewpoint.
//!
//! Based on the standard pinhole camera of real-time rendering (view matrix × projection matrix,
//! Akenine-Möller et al., *Real-Time Rendering*, 4th ed., sec. 4.7.2) with a **reverse-Z projection and
//! an infinite far plane** (Reed, "Depth Precision Visualized", 2015; Upchurch & Desbrun, "Tightening
//! the Precision of Perspective Rendering", JGT 2012), so that km-sized scenes keep their depth
//! precision. The cube faces are the 90° frustums of a view cell's layers (Jeschke & Wimmer, GI 2002,
//! sec. 3: every layer of a face uses the same projection from the reference viewpoint).
//!
//! # Conventions
//! - World: metres, right-handed, +Y up (glTF 2.0's convention).
//! - View space: right-handed, the camera looks along −Z, +X is right, +Y is up.
//! - Clip space as wgpu/WebGPU/Vulkan/D3D: NDC x, y ∈ [−1, 1] with +y up, depth z ∈ [0, 1].
//! - **Reverse-Z, infinite far plane**: a point at view-space depth `d` (distance along the view axis,
//!   `d = −z_view > 0`) gets NDC depth `near / d`: 1 on the near plane, → 0 at infinity. The depth
//!   test keeps the *greater* value, the depth buffer clears to 0.
//! - Pixels: `(x, y)` with x to the right and y **down** from the top-left corner of the image; pixel
//!   `(i, j)` covers `[i, i+1) × [j, j+1)` and its centre is `(i + 0.5, j + 0.5)` (the GPU rasterizer's
//!   sample position). NDC ↔ pixel: `x = (ndc_x + 1)/2 · width`, `y = (1 − ndc_y)/2 · height`.
//! - All math is f64; [`View::gpu`] converts to f32 relative to the eye, so that a scene kilometres
//!   from the origin does not lose precision in the vertex shader.
//!
//! # Cube faces
//! [`View::cube_face`] is the 90° × 90° square view of a [`Face`] from a reference viewpoint, in the
//! one texel convention of [`crate::face`] (the GL/Vulkan cube-map table, mirrored when seen from
//! inside): texel `(i, j)` (column `i`, row `j` from the top) of a `Res × Res` face image sees the
//! direction `forward + s·right + t·down` with `(s, t)` = [`Face::texel_center`]`(i, j, Res)`
//! = `(−1 + (2i+1)/Res, −1 + (2j+1)/Res)`, and projects to pixel `(i + 0.5, j + 0.5)`. Its view
//! matrix has rows `right, −down, −forward`, a reflection when the face convention is mirrored;
//! the renderer never culls back faces, so that changes nothing but the winding.

use glam::{DMat3, DMat4, DVec2, DVec3, DVec4, Mat4, Vec3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::face::Face;

/// Near-plane distance used when a caller does not choose one (metres).
pub const DEFAULT_NEAR: f64 = 0.05;

/// A camera parameter that cannot make a view.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CameraError {
    #[error("camera eye position must be finite, got {0:?}")]
    Eye(DVec3),
    #[error("camera view direction must be finite and non-zero, got {0:?}")]
    Forward(DVec3),
    #[error("camera look-at point must differ from the eye position (both are {0:?})")]
    LookAtEye(DVec3),
    #[error("camera up vector must be finite and non-zero, got {0:?}")]
    Up(DVec3),
    #[error("vertical field of view must be in (0°, 180°), got {0}°")]
    Fov(f64),
    #[error("image size must be at least 1x1, got {0}x{1}")]
    Size(u32, u32),
    #[error("near plane must be finite and positive, got {0}")]
    Near(f64),
    #[error("yaw and pitch must be finite and pitch within [-90°, 90°], got yaw {0}°, pitch {1}°")]
    YawPitch(f64, f64),
}

/// A perspective camera: where it is, where it looks, and the image it makes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Eye position (world, metres).
    pub eye: DVec3,
    /// Unit view direction.
    pub forward: DVec3,
    /// Unit up vector, orthogonal to `forward`.
    pub up: DVec3,
    /// Vertical field of view in degrees, in (0, 180).
    pub fov_y_deg: f64,
    pub width: u32,
    pub height: u32,
    /// Near-plane distance (metres); the far plane is at infinity.
    pub near: f64,
}

impl Camera {
    /// A camera at `eye` looking along `forward`, with `up` as the approximate image up (made
    /// orthogonal to `forward`). When `forward` is parallel to `up` the camera uses the up vector of a
    /// camera looking along −Z pitched by ±90°: looking down (along −up) −Z, looking up +Z. The near plane is [`DEFAULT_NEAR`]; change it with [`Camera::with_near`].
    pub fn new(
        eye: DVec3,
        forward: DVec3,
        up: DVec3,
        fov_y_deg: f64,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        if !eye.is_finite() {
            return Err(CameraError::Eye(eye));
        }
        if !forward.is_finite() || forward.length_squared() == 0.0 {
            return Err(CameraError::Forward(forward));
        }
        if !up.is_finite() || up.length_squared() == 0.0 {
            return Err(CameraError::Up(up));
        }
        if !(fov_y_deg > 0.0 && fov_y_deg < 180.0) {
            return Err(CameraError::Fov(fov_y_deg));
        }
        if width == 0 || height == 0 {
            return Err(CameraError::Size(width, height));
        }
        let f = forward.normalize();
        let u0 = up.normalize();
        // Gram–Schmidt: the part of `up` orthogonal to `forward`.
        let mut u = u0 - f * f.dot(u0);
        if u.length_squared() < 1e-20 {
            // Looking along ±up: as if pitched from looking along −Z.
            u = if f.dot(u0) > 0.0 { DVec3::Z } else { -DVec3::Z };
            u -= f * f.dot(u);
        }
        Ok(Camera {
            eye,
            forward: f,
            up: u.normalize(),
            fov_y_deg,
            width,
            height,
            near: DEFAULT_NEAR,
        })
    }

    /// A camera at `eye` looking at the point `target`.
    pub fn look_at(
        eye: DVec3,
        target: DVec3,
        up: DVec3,
        fov_y_deg: f64,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        if eye == target {
            return Err(CameraError::LookAtEye(eye));
        }
        Camera::new(eye, target - eye, up, fov_y_deg, width, height)
    }

    /// A camera at `eye` with +Y up, turned by `yaw_deg` about +Y and tilted by `pitch_deg`.
    /// Yaw 0 looks along −Z, yaw 90° along +X (clockwise seen from above, like a compass heading);
    /// pitch > 0 looks up, ±90° straight up/down:
    /// `forward = (sin yaw · cos pitch, sin pitch, −cos yaw · cos pitch)`.
    pub fn from_yaw_pitch(
        eye: DVec3,
        yaw_deg: f64,
        pitch_deg: f64,
        fov_y_deg: f64,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        if !yaw_deg.is_finite() || !(-90.0..=90.0).contains(&pitch_deg) {
            return Err(CameraError::YawPitch(yaw_deg, pitch_deg));
        }
        let (sy, cy) = yaw_deg.to_radians().sin_cos();
        let (sp, cp) = pitch_deg.to_radians().sin_cos();
        let forward = DVec3::new(sy * cp, sp, -cy * cp);
        // At ±90° pitch the up vector is the heading, so the image stays upright for any yaw.
        let up = if pitch_deg.abs() >= 90.0 {
            DVec3::new(-sy * sp, cp.max(0.0), cy * sp)
        } else {
            DVec3::Y
        };
        Camera::new(eye, forward, up, fov_y_deg, width, height)
    }

    /// The same camera with another near-plane distance.
    pub fn with_near(mut self, near: f64) -> Result<Camera, CameraError> {
        if !(near.is_finite() && near > 0.0) {
            return Err(CameraError::Near(near));
        }
        self.near = near;
        Ok(self)
    }

    /// Unit right vector: `forward × up`.
    pub fn right(&self) -> DVec3 {
        self.forward.cross(self.up)
    }

    /// Width / height.
    pub fn aspect(&self) -> f64 {
        self.width as f64 / self.height as f64
    }

    /// The view of this camera: view matrix, reverse-Z infinite projection, viewport.
    pub fn view(&self) -> View {
        let view = view_matrix(self.eye, self.forward, self.up);
        let proj =
            perspective_reverse_infinite(self.fov_y_deg.to_radians(), self.aspect(), self.near);
        View {
            view,
            proj,
            width: self.width,
            height: self.height,
        }
    }
}

/// The world → view matrix of an eye with an orthonormal `forward`/`up` pair: rows are right, up and
/// −forward (view space looks along −Z), translation `−R·eye`.
pub fn view_matrix(eye: DVec3, forward: DVec3, up: DVec3) -> DMat4 {
    view_matrix_basis(eye, forward.cross(up), up, forward)
}

/// The world → view matrix of an eye with an orthonormal basis that need not be right-handed
/// (the cube-face convention is mirrored): rows `right`, `up`, `−forward`, translation `−R·eye`.
pub fn view_matrix_basis(eye: DVec3, right: DVec3, up: DVec3, forward: DVec3) -> DMat4 {
    let rot = DMat3::from_cols(right, up, -forward).transpose();
    let t = -(rot * eye);
    DMat4::from_cols(
        rot.x_axis.extend(0.0),
        rot.y_axis.extend(0.0),
        rot.z_axis.extend(0.0),
        t.extend(1.0),
    )
}

/// Reverse-Z perspective projection with an infinite far plane (Upchurch & Desbrun 2012, eq. for the
/// "infinite reversed" projection). With `f = 1 / tan(fov_y / 2)`:
/// `clip = (f/aspect · x, f · y, near, −z)`, so NDC depth is `near / d` for view depth `d = −z`.
pub fn perspective_reverse_infinite(fov_y_rad: f64, aspect: f64, near: f64) -> DMat4 {
    let f = 1.0 / (0.5 * fov_y_rad).tan();
    DMat4::from_cols(
        DVec4::new(f / aspect, 0.0, 0.0, 0.0),
        DVec4::new(0.0, f, 0.0, 0.0),
        DVec4::new(0.0, 0.0, 0.0, -1.0),
        DVec4::new(0.0, 0.0, near, 0.0),
    )
}

/// A general view: world → view matrix, view → clip projection and the viewport size in pixels.
///
/// Any invertible affine `view` and any projection that maps the visible region to NDC as wgpu does
/// works; the renderer never assumes more than that.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct View {
    /// World → view space.
    pub view: DMat4,
    /// View → clip space.
    pub proj: DMat4,
    pub width: u32,
    pub height: u32,
}

/// A world point mapped by a [`View`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected {
    /// Pixel coordinates (x right, y down, pixel centres at `i + 0.5`).
    pub pixel: DVec2,
    /// NDC depth (reverse-Z: larger is nearer).
    pub ndc_depth: f64,
    /// Distance along the view axis (`−z` in view space), the value a depth image stores.
    pub view_depth: f64,
}

/// A [`View`] converted for the GPU, relative to the eye (see [`View::gpu`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuView {
    /// The eye split as `hi + lo` so that `p − hi − lo` is accurate in f32 for world points far from
    /// the origin.
    pub eye_hi: Vec3,
    pub eye_lo: Vec3,
    /// Clip position of `p` is `clip_from_rel · (p − eye, 1)`: projection × view without translation.
    pub clip_from_rel: Mat4,
    /// View depth of `p` is `depth_axis · (p − eye)`.
    pub depth_axis: Vec3,
}

impl View {
    /// The eye position: the world point the view matrix maps to the origin.
    pub fn eye(&self) -> DVec3 {
        self.view.inverse().transform_point3(DVec3::ZERO)
    }

    /// Projection × view.
    pub fn view_proj(&self) -> DMat4 {
        self.proj * self.view
    }

    /// Distance of `p` along the view axis (`−z` in view space); negative behind the eye.
    pub fn view_depth(&self, p: DVec3) -> f64 {
        -self.view.transform_point3(p).z
    }

    /// Maps a world point to pixel coordinates and depth; `None` behind the eye (clip `w <= 0`).
    /// Points outside the viewport still get their (out-of-range) pixel coordinates.
    pub fn project(&self, p: DVec3) -> Option<Projected> {
        let v = self.view * p.extend(1.0);
        let c = self.proj * v;
        if c.w <= 0.0 {
            return None;
        }
        let ndc = c.truncate() / c.w;
        Some(Projected {
            pixel: self.ndc_to_pixel(DVec2::new(ndc.x, ndc.y)),
            ndc_depth: ndc.z,
            view_depth: -v.z,
        })
    }

    /// NDC `(x, y)` → pixel coordinates.
    pub fn ndc_to_pixel(&self, ndc: DVec2) -> DVec2 {
        DVec2::new(
            (ndc.x + 1.0) * 0.5 * self.width as f64,
            (1.0 - ndc.y) * 0.5 * self.height as f64,
        )
    }

    /// Pixel coordinates → NDC `(x, y)`.
    pub fn pixel_to_ndc(&self, pixel: DVec2) -> DVec2 {
        DVec2::new(
            2.0 * pixel.x / self.width as f64 - 1.0,
            1.0 - 2.0 * pixel.y / self.height as f64,
        )
    }

    /// The world-space ray through a pixel position: `(origin, unit direction)`. For a perspective
    /// view the origin is the eye. Use `pixel + 0.5` for the centre of pixel `(i, j)`.
    pub fn pixel_ray(&self, pixel: DVec2) -> (DVec3, DVec3) {
        let ndc = self.pixel_to_ndc(pixel);
        let inv = self.view_proj().inverse();
        // Two points on the ray: NDC depth 1 (near plane) and 0.5 (farther, still finite).
        let a = inv * DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
        let b = inv * DVec4::new(ndc.x, ndc.y, 0.5, 1.0);
        let a = a.truncate() / a.w;
        let b = b.truncate() / b.w;
        let dir = (b - a).normalize();
        // For perspective views every ray starts at the eye.
        let eye = self.eye();
        if (a - eye).cross(dir).length() <= 1e-9 * (1.0 + (a - eye).length()) {
            (eye, dir)
        } else {
            (a, dir)
        }
    }

    /// Pixel coordinates and view depth → world point (inverse of [`View::project`]).
    pub fn unproject(&self, pixel: DVec2, view_depth: f64) -> DVec3 {
        let ndc = self.pixel_to_ndc(pixel);
        // View-space point on the ray with z = −view_depth: solve the projection for x, y.
        let inv_proj = self.proj.inverse();
        let a = inv_proj * DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
        let b = inv_proj * DVec4::new(ndc.x, ndc.y, 0.5, 1.0);
        let a = a.truncate() / a.w;
        let b = b.truncate() / b.w;
        let t = (-view_depth - a.z) / (b.z - a.z);
        let v = a + (b - a) * t;
        self.view.inverse().transform_point3(v)
    }

    /// The view in f32, relative to the eye: the vertex shader computes `p − eye_hi − eye_lo` before
    /// any matrix, so the large translation never meets f32 rounding in a product.
    pub fn gpu(&self) -> GpuView {
        let eye = self.eye();
        let eye_hi = eye.as_vec3();
        let eye_lo = (eye - eye_hi.as_dvec3()).as_vec3();
        let mut rot = self.view;
        rot.w_axis = DVec4::W;
        let clip_from_rel = (self.proj * rot).as_mat4();
        let depth_axis = -DVec3::new(rot.x_axis.z, rot.y_axis.z, rot.z_axis.z);
        GpuView {
            eye_hi,
            eye_lo,
            clip_from_rel,
            depth_axis: depth_axis.as_vec3(),
        }
    }

    /// The 90° × 90° square view of cube face `face` from `center` with a `res × res` image and near
    /// plane `near` (reverse-Z, infinite far plane). Texel `(i, j)` sees the direction
    /// `face.point(s, t, 1)` with `(s, t) = Face::texel_center(i, j, res)` (module docs).
    pub fn cube_face(center: DVec3, face: Face, res: u32, near: f64) -> View {
        let view = view_matrix_basis(center, face.right(), -face.down(), face.forward());
        let proj = perspective_reverse_infinite(std::f64::consts::FRAC_PI_2, 1.0, near);
        View {
            view,
            proj,
            width: res,
            height: res,
        }
    }
}

/// An image size `WIDTHxHEIGHT` (each 1..=16384), for every command's and example's `--size`.
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}`: expected WIDTHxHEIGHT, e.g. 1280x720"))?;
    let w: u32 = w.trim().parse().map_err(|e| format!("`{s}`: width: {e}"))?;
    let h: u32 = h
        .trim()
        .parse()
        .map_err(|e| format!("`{s}`: height: {e}"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("`{s}`: width and height must be 1..=16384"));
    }
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_absurd_ones_are_errors() {
        assert_eq!(parse_size("1280x720"), Ok((1280, 720)));
        assert_eq!(parse_size(" 64 X 36 "), Ok((64, 36)));
        for bad in ["1280", "0x720", "1280x0", "99999x10", "axb", "12x-3", ""] {
            let e = parse_size(bad).unwrap_err();
            assert!(e.contains(&format!("`{bad}`")), "{bad}: {e}");
        }
    }

    use proptest::prelude::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
    }

    #[test]
    fn camera_looking_down_minus_z_projects_by_hand() {
        // fov 90°, 200x100: f = 1, aspect 2. The point (1, 0.5, -2) has x/d = 0.5, y/d = 0.25:
        // ndc x = 0.5 / 2 = 0.25, ndc y = 0.25 → pixel (125, 37.5), NDC depth near/d.
        let c = Camera::new(DVec3::ZERO, -DVec3::Z, DVec3::Y, 90.0, 200, 100).unwrap();
        let p = c.view().project(DVec3::new(1.0, 0.5, -2.0)).unwrap();
        assert!(close(p.pixel.x, 125.0, 1e-12), "{:?}", p);
        assert!(close(p.pixel.y, 37.5, 1e-12), "{:?}", p);
        assert!(close(p.view_depth, 2.0, 1e-12));
        assert!(close(p.ndc_depth, DEFAULT_NEAR / 2.0, 1e-12));
        assert!(c.view().project(DVec3::new(0.0, 0.0, 1.0)).is_none());
        assert!(close(c.view().eye().length(), 0.0, 1e-12));
    }

    #[test]
    fn yaw_pitch_convention() {
        let c = Camera::from_yaw_pitch(DVec3::ZERO, 90.0, 0.0, 60.0, 4, 4).unwrap();
        assert!((c.forward - DVec3::X).length() < 1e-12);
        let c = Camera::from_yaw_pitch(DVec3::ZERO, 0.0, 90.0, 60.0, 4, 4).unwrap();
        assert!((c.forward - DVec3::Y).length() < 1e-12);
        assert!((c.up - DVec3::Z).length() < 1e-12);
        let c = Camera::from_yaw_pitch(DVec3::ZERO, 0.0, -90.0, 60.0, 4, 4).unwrap();
        assert!((c.up + DVec3::Z).length() < 1e-12);
        assert!(Camera::from_yaw_pitch(DVec3::ZERO, 0.0, 91.0, 60.0, 4, 4).is_err());
    }

    #[test]
    fn bad_parameters_are_errors() {
        let e = DVec3::ZERO;
        assert!(matches!(
            Camera::new(e, DVec3::ZERO, DVec3::Y, 60.0, 4, 4),
            Err(CameraError::Forward(_))
        ));
        assert!(matches!(
            Camera::new(e, DVec3::X, DVec3::Y, 180.0, 4, 4),
            Err(CameraError::Fov(_))
        ));
        assert!(matches!(
            Camera::new(e, DVec3::X, DVec3::Y, 60.0, 0, 4),
            Err(CameraError::Size(0, 4))
        ));
        assert!(matches!(
            Camera::look_at(e, e, DVec3::Y, 60.0, 4, 4),
            Err(CameraError::LookAtEye(_))
        ));
        assert!(Camera::new(DVec3::splat(f64::NAN), DVec3::X, DVec3::Y, 60.0, 4, 4).is_err());
        let c = Camera::new(e, DVec3::X, DVec3::Y, 60.0, 4, 4).unwrap();
        assert!(c.with_near(0.0).is_err());
        // Looking straight down with +Y up falls back to -Z up, like the -Y face.
        let c = Camera::new(e, -DVec3::Y, DVec3::Y, 60.0, 4, 4).unwrap();
        assert_eq!(c.up, -DVec3::Z);
    }

    #[test]
    fn gpu_view_matches_f64_far_from_origin() {
        let eye = DVec3::new(12_345.678, 250.25, -9_876.5);
        let c = Camera::look_at(
            eye,
            eye + DVec3::new(100.0, -3.0, 40.0),
            DVec3::Y,
            60.0,
            1280,
            720,
        )
        .unwrap();
        let v = c.view();
        let g = v.gpu();
        let p = eye + DVec3::new(90.0, -2.0, 35.0);
        let rel = (p.as_vec3() - g.eye_hi) - g.eye_lo;
        let clip = g.clip_from_rel * rel.extend(1.0);
        let ndc = clip.truncate() / clip.w;
        let expect = v.project(p.as_vec3().as_dvec3()).unwrap();
        let px = v.ndc_to_pixel(DVec2::new(ndc.x as f64, ndc.y as f64));
        assert!(
            (px - expect.pixel).length() < 0.05,
            "{px:?} vs {:?}",
            expect.pixel
        );
        let d = g.depth_axis.dot(rel) as f64;
        assert!(close(d, expect.view_depth, 1e-5));
    }

    fn unit_dir() -> impl Strategy<Value = DVec3> {
        (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0)
            .prop_filter("non-zero", |(x, y, z)| x * x + y * y + z * z > 0.01)
            .prop_map(|(x, y, z)| DVec3::new(x, y, z).normalize())
    }

    proptest! {
        /// A point projects to the pixel computed by hand from the camera basis, and the pixel's ray
        /// and unprojection lead back to it.
        #[test]
        fn project_matches_hand_computation_and_back(
            eye in (-5e3f64..5e3, -100.0f64..1e3, -5e3f64..5e3),
            fwd in unit_dir(),
            fov in 10.0f64..150.0,
            w in 1u32..4000, h in 1u32..4000,
            a in -0.95f64..0.95, b in -0.95f64..0.95, d in 0.1f64..5e4,
        ) {
            let eye = DVec3::new(eye.0, eye.1, eye.2);
            prop_assume!(fwd.cross(DVec3::Y).length() > 1e-3);
            let c = Camera::new(eye, fwd, DVec3::Y, fov, w, h).unwrap();
            let tan_y = (0.5 * fov.to_radians()).tan();
            let tan_x = tan_y * w as f64 / h as f64;
            // A point at depth d whose NDC is (a, b) by construction.
            let p = eye + c.forward * d + c.right() * (a * tan_x * d) + c.up * (b * tan_y * d);
            let v = c.view();
            let pr = v.project(p).unwrap();
            let hand = DVec2::new((a + 1.0) / 2.0 * w as f64, (1.0 - b) / 2.0 * h as f64);
            prop_assert!((pr.pixel - hand).length() < 1e-6 * (w.max(h) as f64), "{:?} vs {:?}", pr.pixel, hand);
            prop_assert!(close(pr.view_depth, d, 1e-9));
            prop_assert!(close(pr.ndc_depth, c.near / d, 1e-9));
            let (o, dir) = v.pixel_ray(pr.pixel);
            prop_assert!((o - eye).length() < 1e-6 * (1.0 + eye.length()));
            let to_p = (p - eye).normalize();
            prop_assert!(dir.dot(to_p) > 1.0 - 1e-9);
            let back = v.unproject(pr.pixel, pr.view_depth);
            prop_assert!((back - p).length() < 1e-6 * (1.0 + p.length()));
        }

        /// Texel centres of a cube face project to exactly the texel centre and map back.
        #[test]
        fn cube_face_texel_convention(
            fi in 0usize..6, res in 1u32..2048, fi_u in 0.0f64..1.0, fj_v in 0.0f64..1.0,
            c in (-1e3f64..1e3, -1e3f64..1e3, -1e3f64..1e3), dist in 0.5f64..1e4,
        ) {
            let face = Face::from_index(fi).unwrap();
            let i = ((fi_u * res as f64) as u32).min(res - 1);
            let j = ((fj_v * res as f64) as u32).min(res - 1);
            let center = DVec3::new(c.0, c.1, c.2);
            let (s, t) = Face::texel_center(i, j, res);
            let dir = face.point(s, t, 1.0);
            let v = View::cube_face(center, face, res, 0.1);
            let p = center + dir * dist;
            let pr = v.project(p).unwrap();
            let tol = 1e-7 * res as f64;
            prop_assert!((pr.pixel - DVec2::new(i as f64 + 0.5, j as f64 + 0.5)).length() < tol, "{:?}", pr.pixel);
            prop_assert!(close(pr.view_depth, dist, 1e-9));
            let (s2, t2, d2) = face.project(p - center).unwrap();
            prop_assert!((s2 - s).abs() < 1e-9 && (t2 - t).abs() < 1e-9 && close(d2, dist, 1e-9));
            let (o, ray) = v.pixel_ray(pr.pixel);
            prop_assert!((o - center).length() < 1e-6 * (1.0 + center.length()));
            prop_assert!(ray.dot(dir.normalize()) > 1.0 - 1e-9);
            prop_assert_eq!(Face::of_direction(face.forward() + 0.5 * (dir - face.forward())), face);
        }
    }
}
