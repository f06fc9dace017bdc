//! Layer placement: the error metric that decides where every impostor layer and border goes.
//!
//! This work is based on: S. Jeschke, M. Wimmer et al., *Layered Environment-Map Impostors for
//! Arbitrary Scenes*, Graphics Interface 2002, sec. 4.2-4.3 (eqs. 1-2; the published
//! text garbles them, the forms used here are re-derived and checked by brute force), and S. Jeschke, M. Wimmer, *An Error Metric for Layered Environment Map
//! Impostors*, TR-186-2-02-04, sec. 2.1 (eqs. 1-7). The object (single impostor) case of the TR
//! lives in [`object`]; the output-view helpers (α, texture resolution) in [`view`].
//!
//! Conventions: distances are measured from the view-cell centre (the reference viewpoint) along
//! the face axis, in metres, as `f64`. A view cell is a box; one face sees the cell through its
//! half extent `along` the face axis and its two half extents `across` it. A cube of half side `m`
//! is `along = m, across = [m, m]`; the paper's 2D case (the viewer moves in a horizontal square,
//! only the four horizontal faces are baked) is `across = [m, 0]`.
//!
//! The math (see `docs/PLACEMENT.md` for the derivation):
//! - parallax step (GI eq. 1, TR eq. 7 with `r`, `s`): from a known border (or layer) at `F` the
//!   next closer layer (or border) `N` is `1/N = [(1 + sin(β − α))/F + 2 sin α/ρ] / (1 + sin(β + α))`,
//!   with `s = along`, `r = |across|` (the lateral distance to the worst cell corner), `ρ = √(r² + s²)`
//!   and `β = atan2(r, s)`; for a cube this is the paper's `β = π/4` (2D) or `arctan √2` (3D),
//!   `ρ = √f · m`.
//! - one-texel spacing (GI eq. 2, TR eq. 2 with `n/2 = q = max(across)`, `w/(t0+s) = 2`):
//!   `P = F · Res·(q + s) / (2(F − s) + Res·(q + s))`; for a cube `P = Res·m·F / (F + (Res − 1)·m)`.
//! - border between two layers (TR eq. 6), which equals the geometric mean of `g(D) = D/(D − s)`.

pub mod object;
pub mod view;

use serde::{Deserialize, Serialize};

pub use object::{place_object_layers, ObjectCell, ObjectParams, ObjectPlacement};
pub use view::{
    alpha_from_output_view, min_face_res_for_output_view, pixel_angle_centre, pixel_angle_edge,
    schaufler_res, texres_rtr, PixelChoice,
};

/// The largest number of layers a placement may produce (a guard against absurd requests such as
/// a near field a micrometre outside the cell, which would need millions of layers).
pub const MAX_LAYERS: usize = 100_000;

/// Errors of the placement functions: a parameter is out of range. Each names the parameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlacementError {
    #[error("invalid placement parameter `{name}` = {value}: {reason}")]
    InvalidParameter {
        name: &'static str,
        value: f64,
        reason: &'static str,
    },
    #[error(
        "the requested near field {near_field} m lies inside the view cell (half extent {half_extent} m along the face axis); it must be farther from the centre"
    )]
    NearFieldInsideCell { near_field: f64, half_extent: f64 },
    #[error("the placement would need more than {limit} layers ({what})")]
    TooManyLayers { limit: usize, what: &'static str },
}

pub(crate) fn invalid(name: &'static str, value: f64, reason: &'static str) -> PlacementError {
    PlacementError::InvalidParameter {
        name,
        value,
        reason,
    }
}

/// Checks `0 < alpha < π/2` (radians).
pub(crate) fn check_alpha(alpha: f64) -> Result<(), PlacementError> {
    if !alpha.is_finite() || alpha <= 0.0 || alpha >= std::f64::consts::FRAC_PI_2 {
        return Err(invalid(
            "alpha",
            alpha,
            "the allowed parallax angle must be > 0 and < 90° (given in radians)",
        ));
    }
    Ok(())
}

pub(crate) fn check_extent(name: &'static str, v: f64) -> Result<(), PlacementError> {
    if !v.is_finite() || v < 0.0 {
        return Err(invalid(name, v, "a half extent must be finite and >= 0"));
    }
    Ok(())
}

/// Which constraint fixed the distance of a layer to the previous (farther) one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    /// The parallax angle α (GI eq. 1 / TR eq. 7); the first layer is always parallax-bound.
    Parallax,
    /// The one-texel spacing (GI eq. 2 / TR eqs. 2-5): adjacent layers shift by at most one texel.
    OneTexel,
}

impl std::fmt::Display for Bound {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Bound::Parallax => "parallax",
            Bound::OneTexel => "one-texel",
        })
    }
}

/// The 2D case (viewer moves in a horizontal square; 4 horizontal faces) or the 3D case (viewer
/// moves in a cube) of GI 2002 (`f = 2` or `f = 3`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dim {
    Two,
    Three,
}

/// A coordinate axis, the axis of a cube face (`+X`/`−X` are both `X`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    X,
    Y,
    Z,
}

/// Inputs of the environment-map placement of one face of a view cell.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EnvParams {
    /// Half extent of the view cell along the face axis (m); the paper's `m` (TR: `s`).
    pub along: f64,
    /// Half extents of the view cell across the face (the two other axes, m).
    pub across: [f64; 2],
    /// Texels per face side (`Res`), every face spans 90°.
    pub res: u32,
    /// Allowed parallax angle α (radians), normally one output pixel (see [`view`]).
    pub alpha: f64,
}

impl EnvParams {
    /// A cubic view cell of half side `half_side` (the paper's `m`), in the 2D or 3D case.
    pub fn cube(half_side: f64, res: u32, alpha: f64, dim: Dim) -> Self {
        let across = match dim {
            Dim::Two => [half_side, 0.0],
            Dim::Three => [half_side, half_side],
        };
        Self {
            along: half_side,
            across,
            res,
            alpha,
        }
    }

    /// One face axis of a box-shaped view cell with half extents `half_extents` (x, y, z).
    pub fn box_face(half_extents: glam::DVec3, axis: Axis, res: u32, alpha: f64) -> Self {
        let h = half_extents;
        let (along, across) = match axis {
            Axis::X => (h.x, [h.y, h.z]),
            Axis::Y => (h.y, [h.x, h.z]),
            Axis::Z => (h.z, [h.x, h.y]),
        };
        Self {
            along,
            across,
            res,
            alpha,
        }
    }

    /// Checks every parameter; see [`PlacementError`].
    pub fn validate(&self) -> Result<(), PlacementError> {
        check_extent("along", self.along)?;
        check_extent("across[0]", self.across[0])?;
        check_extent("across[1]", self.across[1])?;
        if self.along == 0.0 && self.across[0] == 0.0 && self.across[1] == 0.0 {
            return Err(invalid("along", 0.0, "the view cell has zero size"));
        }
        if self.res == 0 {
            return Err(invalid("res", 0.0, "the face resolution must be >= 1"));
        }
        check_alpha(self.alpha)
    }

    /// `s`, `r`, `ρ`, `β` of the parallax step: the worst viewpoint is the cell corner on the side
    /// of the face, `s` along the axis and `r` across it (TR sec. 2.1.2, Fig. 8).
    fn corner(&self) -> (f64, f64, f64, f64) {
        let s = self.along;
        let r = self.across[0].hypot(self.across[1]);
        (s, r, r.hypot(s), r.atan2(s))
    }
}

/// What to ask the placement for.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Target {
    /// A fixed number of layers; the near field follows.
    Layers(usize),
    /// A near-field distance from the centre (m); the fewest layers that reach it.
    NearField(f64),
}

/// One layer of one face: the quad at `distance`, recording the slab `[near_border, far_border)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    /// Distance of the layer from the cell centre along the face axis (m).
    pub distance: f64,
    /// Inner border of the slab it records (m from the centre).
    pub near_border: f64,
    /// Outer border of the slab (m from the centre); infinite for the farthest layer (`null` in
    /// JSON).
    #[serde(with = "crate::serde_inf::f64_or_inf")]
    pub far_border: f64,
    /// The constraint that fixed this layer's distance to the previous (farther) layer.
    pub bound_by: Bound,
}

/// The placement of one face: layers far to near, and the near-field distance (the innermost
/// border; everything closer is rendered as geometry).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    pub layers: Vec<Layer>,
    pub near_field: f64,
    pub params: EnvParams,
}

impl Placement {
    /// The slab a point at `distance` from the centre (along the face axis) belongs to: `Some(i)`
    /// for layer `i` (far to near), `None` for the near field (also for NaN).
    pub fn slab_of(&self, distance: f64) -> Option<usize> {
        if distance.is_nan() || distance < self.near_field {
            return None;
        }
        let i = self.layers.partition_point(|l| l.near_border > distance);
        (i < self.layers.len()).then_some(i)
    }

    /// All borders far to near, starting with infinity and ending with the near field
    /// (`layers.len() + 1` values).
    pub fn borders(&self) -> Vec<f64> {
        let mut b = Vec::with_capacity(self.layers.len() + 1);
        b.push(f64::INFINITY);
        b.extend(self.layers.iter().map(|l| l.near_border));
        b
    }
}

/// GI 2002 eq. 1 (restored; TR eq. 7 with `s`, `r`): from a border (or layer) at `far` the next
/// closer layer (or border) such that the parallax angle between the two, seen from anywhere in
/// the cell, is at most α. `far` may be infinite.
pub fn parallax_step(far: f64, params: &EnvParams) -> f64 {
    let (_s, _r, rho, beta) = params.corner();
    let a = params.alpha;
    let inv_far = if far.is_infinite() { 0.0 } else { 1.0 / far };
    // Eq. 1: 1/F' = [(1 + sin(β − α))/F + 2 sin α/ρ] / (1 + sin(β + α)).
    let inv = ((1.0 + (beta - a).sin()) * inv_far + 2.0 * a.sin() / rho) / (1.0 + (beta + a).sin());
    1.0 / inv
}

/// GI 2002 eq. 2 (TR eq. 2, generalised to a box): the closest distance behind which a layer at
/// `far` shifts by at most one texel against it, seen from anywhere in the cell.
pub fn one_texel_step(far: f64, params: &EnvParams) -> f64 {
    let s = params.along;
    let q = params.across[0].max(params.across[1]);
    let res = f64::from(params.res);
    // Eq. 2: P = F·Res·(q + s) / (2(F − s) + Res·(q + s)); cube: P = Res·m·F / (F + (Res − 1)·m).
    far * res * (q + s) / (2.0 * (far - s) + res * (q + s))
}

/// TR eq. 6: the border between a near layer at `near` and a far layer at `far` (distances from
/// the reference viewpoint) that splits the parallax equally; `s` is the distance from the
/// reference viewpoint to the view-cell border on the side of the layers.
pub fn border_between(near: f64, far: f64, s: f64) -> f64 {
    let (tn, tf) = (near - s, far - s);
    // Eq. 6: d = (−t_n² − t_n·s + √(t_f·t_n·(t_f + s)·(t_n + s))) / (t_n + t_f + s).
    let d = (-tn * tn - tn * s + (tf * tn * (tf + s) * (tn + s)).sqrt()) / (tn + tf + s);
    near + d
}

/// Environment-map placement of one face (GI 2002 sec. 4.2): layers far to near and the near field.
pub fn place_env_layers(params: &EnvParams, target: Target) -> Result<Placement, PlacementError> {
    params.validate()?;
    let mut layers: Vec<Layer> = Vec::new();
    match target {
        Target::Layers(n) => {
            if n == 0 {
                return Err(invalid("layers", 0.0, "at least one layer is needed"));
            }
            if n > MAX_LAYERS {
                return Err(PlacementError::TooManyLayers {
                    limit: MAX_LAYERS,
                    what: "requested layer count",
                });
            }
            while layers.len() < n {
                push_layer(&mut layers, params);
            }
        }
        Target::NearField(d) => {
            if !d.is_finite() {
                return Err(invalid("near_field", d, "must be a finite distance"));
            }
            if d <= params.along {
                return Err(PlacementError::NearFieldInsideCell {
                    near_field: d,
                    half_extent: params.along,
                });
            }
            loop {
                push_layer(&mut layers, params);
                let last = layers.len() - 1;
                if layers[last].near_border <= d {
                    break;
                }
                if layers.len() >= MAX_LAYERS {
                    return Err(PlacementError::TooManyLayers {
                        limit: MAX_LAYERS,
                        what: "to reach the requested near field",
                    });
                }
            }
        }
    }
    let near_field = layers.last().map_or(f64::INFINITY, |l| l.near_border);
    Ok(Placement {
        layers,
        near_field,
        params: *params,
    })
}

/// Appends the next closer layer and fixes the border between it and the previous one. The last
/// layer's `near_border` is provisionally the parallax limit (eq. 1 applied to it), which is the
/// near field if no further layer follows.
fn push_layer(layers: &mut Vec<Layer>, params: &EnvParams) {
    let Some(prev) = layers.last().copied() else {
        let distance = parallax_step(f64::INFINITY, params);
        layers.push(Layer {
            distance,
            near_border: parallax_step(distance, params),
            far_border: f64::INFINITY,
            bound_by: Bound::Parallax,
        });
        return;
    };
    // Eq. 1 twice (layer → border → layer) against eq. 2; the farther one wins.
    let parallax_border = prev.near_border;
    let by_parallax = parallax_step(parallax_border, params);
    let by_texel = one_texel_step(prev.distance, params);
    let (distance, border, bound_by) = if by_texel > by_parallax {
        let b = border_between(by_texel, prev.distance, params.along);
        (by_texel, b, Bound::OneTexel)
    } else {
        (by_parallax, parallax_border, Bound::Parallax)
    };
    if let Some(last) = layers.last_mut() {
        last.near_border = border;
    }
    layers.push(Layer {
        distance,
        near_border: parallax_step(distance, params),
        far_border: border,
        bound_by,
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq6_is_the_geometric_mean_of_g() {
        let s = 5.0;
        let g = |d: f64| d / (d - s);
        for (near, far) in [(6.0, 9.0), (40.0, 41.0), (100.0, 1000.0)] {
            let b = border_between(near, far, s);
            let gb = (g(near) * g(far)).sqrt();
            assert!((g(b) - gb).abs() < 1e-9 * gb, "{near} {far}: {b}");
        }
    }

    #[test]
    fn eq2_matches_the_cube_form() {
        let (m, res) = (5.0, 512.0);
        let p = EnvParams::cube(m, 512, 0.001, Dim::Three);
        for f in [6.0, 42.0, 1000.0] {
            let want = res * m * f / (f + (res - 1.0) * m);
            assert!((one_texel_step(f, &p) - want).abs() < 1e-9 * want);
        }
    }

    #[test]
    fn eq1_matches_the_g_form_of_the_readme() {
        // g(F') = λ g(F), λ = [cos(φ − α/2) / cos(φ + α/2)]², φ = π/4 − β/2.
        for dim in [Dim::Two, Dim::Three] {
            let (m, alpha) = (5.0, 0.01);
            let p = EnvParams::cube(m, 512, alpha, dim);
            let beta = match dim {
                Dim::Two => std::f64::consts::FRAC_PI_4,
                Dim::Three => 2f64.sqrt().atan(),
            };
            let phi = std::f64::consts::FRAC_PI_4 - beta / 2.0;
            let lambda = ((phi - alpha / 2.0).cos() / (phi + alpha / 2.0).cos()).powi(2);
            let g = |d: f64| d / (d - m);
            for f in [7.0, 50.0, 3000.0] {
                let n = parallax_step(f, &p);
                assert!((g(n) - lambda * g(f)).abs() < 1e-9 * g(n), "{dim:?} {f}");
            }
        }
    }

    #[test]
    fn slab_of_bins_by_border() {
        let p = EnvParams::cube(5.0, 512, 0.1f64.to_radians(), Dim::Two);
        let pl = place_env_layers(&p, Target::Layers(10)).unwrap();
        assert_eq!(pl.slab_of(1e12), Some(0));
        assert_eq!(pl.slab_of(pl.near_field - 1e-9), None);
        assert_eq!(pl.slab_of(f64::NAN), None);
        for (i, l) in pl.layers.iter().enumerate() {
            assert_eq!(pl.slab_of(l.distance), Some(i));
            assert_eq!(pl.slab_of(l.near_border), Some(i));
        }
    }
}
