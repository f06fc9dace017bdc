//! Cube faces and the one texel convention every stage shares.
//!
//! A layer of face `f` at distance `D` is the square `|s|, |t| ≤ 1` on the plane at distance `D`
//! from the reference viewpoint `c` along the face's forward axis:
//! `p(s, t) = c + D · (forward + s · right + t · down)`.
//! Texel `(i, j)` (column `i`, row `j`, rows top to bottom) of a `Res × Res` face image covers
//! `s ∈ [−1 + 2i/Res, −1 + 2(i+1)/Res]`, `t ∈ [−1 + 2j/Res, −1 + 2(j+1)/Res]`; its centre is at
//! `s = −1 + (2i + 1)/Res`.
//!
//! The axes follow the OpenGL / Vulkan / D3D cube-map convention (`right` = the `s` axis, `down` =
//! the `t` axis of the cube-map face table), so a layer image can be used as a cube-map face as is.
//! Seen from inside the cube this convention is mirrored (`right ≠ forward × up`), which matters only
//! for triangle winding; lemi never culls back faces.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// One of the six cube directions, in lemi's fixed order `+X −X +Y −Y +Z −Z`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Face {
    PosX,
    NegX,
    PosY,
    NegY,
    PosZ,
    NegZ,
}

impl Face {
    /// All faces in order.
    pub const ALL: [Face; 6] = [
        Face::PosX,
        Face::NegX,
        Face::PosY,
        Face::NegY,
        Face::PosZ,
        Face::NegZ,
    ];
    /// The four horizontal faces (the default for ground-level scenes, as in GI 2002).
    pub const HORIZONTAL: [Face; 4] = [Face::PosX, Face::NegX, Face::PosZ, Face::NegZ];

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn from_index(i: usize) -> Option<Face> {
        Face::ALL.get(i).copied()
    }

    /// Short name: `+X`, `-X`, …
    pub fn name(self) -> &'static str {
        ["+X", "-X", "+Y", "-Y", "+Z", "-Z"][self.index()]
    }

    /// Viewing direction of the face.
    pub fn forward(self) -> DVec3 {
        match self {
            Face::PosX => DVec3::X,
            Face::NegX => DVec3::NEG_X,
            Face::PosY => DVec3::Y,
            Face::NegY => DVec3::NEG_Y,
            Face::PosZ => DVec3::Z,
            Face::NegZ => DVec3::NEG_Z,
        }
    }

    /// Direction of increasing image column (`s`).
    pub fn right(self) -> DVec3 {
        match self {
            Face::PosX => DVec3::NEG_Z,
            Face::NegX => DVec3::Z,
            Face::PosY => DVec3::X,
            Face::NegY => DVec3::X,
            Face::PosZ => DVec3::X,
            Face::NegZ => DVec3::NEG_X,
        }
    }

    /// Direction of increasing image row (`t`, rows top to bottom).
    pub fn down(self) -> DVec3 {
        match self {
            Face::PosX | Face::NegX | Face::PosZ | Face::NegZ => DVec3::NEG_Y,
            Face::PosY => DVec3::Z,
            Face::NegY => DVec3::NEG_Z,
        }
    }

    /// Depth of `p` (relative to the reference viewpoint) along this face's axis.
    pub fn depth(self, rel: DVec3) -> f64 {
        rel.dot(self.forward())
    }

    /// `(s, t, depth)` of a point relative to the reference viewpoint; `s, t` in `[−1, 1]` when the
    /// point lies in this face's 90° pyramid. `None` when the point is not in front (depth ≤ 0).
    pub fn project(self, rel: DVec3) -> Option<(f64, f64, f64)> {
        let d = self.depth(rel);
        if d <= 0.0 || !d.is_finite() {
            return None;
        }
        Some((rel.dot(self.right()) / d, rel.dot(self.down()) / d, d))
    }

    /// The point at face coordinates `(s, t)` on the layer plane at `distance`, relative to the
    /// reference viewpoint.
    pub fn point(self, s: f64, t: f64, distance: f64) -> DVec3 {
        distance * (self.forward() + s * self.right() + t * self.down())
    }

    /// Face coordinate of texel edge `i` (0..=res) of a `res`-texel face.
    pub fn texel_edge(i: f64, res: u32) -> f64 {
        -1.0 + 2.0 * i / res as f64
    }

    /// Centre of texel `(i, j)` in face coordinates.
    pub fn texel_center(i: u32, j: u32, res: u32) -> (f64, f64) {
        (
            Face::texel_edge(i as f64 + 0.5, res),
            Face::texel_edge(j as f64 + 0.5, res),
        )
    }

    /// The face whose pyramid contains the direction `rel` (ties broken in face order).
    pub fn of_direction(rel: DVec3) -> Face {
        let a = rel.abs();
        if a.x >= a.y && a.x >= a.z {
            if rel.x >= 0.0 {
                Face::PosX
            } else {
                Face::NegX
            }
        } else if a.y >= a.z {
            if rel.y >= 0.0 {
                Face::PosY
            } else {
                Face::NegY
            }
        } else if rel.z >= 0.0 {
            Face::PosZ
        } else {
            Face::NegZ
        }
    }
}

impl std::fmt::Display for Face {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn axes_are_orthonormal_and_match_the_cube_map_table() {
        for f in Face::ALL {
            let (a, r, d) = (f.forward(), f.right(), f.down());
            assert_eq!(a.dot(r), 0.0);
            assert_eq!(a.dot(d), 0.0);
            assert_eq!(r.dot(d), 0.0);
            // cube maps are mirrored seen from inside: right == forward × down (not forward × up)
            assert_eq!(r, a.cross(d), "{f}");
        }
        // spot checks against the OpenGL table: +X: s = -rz/|rx|, t = -ry/|rx|
        let (s, t, d) = Face::PosX.project(DVec3::new(2.0, 1.0, -1.0)).unwrap();
        assert_eq!((s, t, d), (0.5, -0.5, 2.0));
        let (s, t, _) = Face::NegY.project(DVec3::new(1.0, -2.0, 1.0)).unwrap();
        assert_eq!((s, t), (0.5, -0.5));
    }

    proptest! {
        #[test]
        fn point_and_project_invert(fi in 0usize..6, s in -1.0f64..1.0, t in -1.0f64..1.0, d in 0.1f64..1e4) {
            let f = Face::ALL[fi];
            let p = f.point(s, t, d);
            let (s2, t2, d2) = f.project(p).unwrap();
            prop_assert!((s - s2).abs() < 1e-12 && (t - t2).abs() < 1e-12 && (d - d2).abs() < 1e-9 * d);
            prop_assert_eq!(Face::of_direction(f.point(s * 0.999, t * 0.999, d)), f);
        }
    }
}
