//! The HLOD far field: the baseline that engines ship (Unreal Engine's hierarchical LOD, Simplygon,
//! Cesium 3D Tiles' screen-space-error LOD). Per view cell, the far field is kept as geometry,
//! simplified in distance bands so that its screen-space error from anywhere in the cell stays
//! within the angle `θ = error_px · α` (α: the bake's allowed parallax angle, by default the angle of
//! one output pixel).
//!
//! This work is based on: M. Garland, P. Heckbert, "Surface Simplification Using Quadric Error
//! Metrics", SIGGRAPH 1997, as implemented by meshoptimizer's simplifier (A. Kapoulkine,
//! `meshopt_simplify`, through the `meshopt` crate); the screen-space error of a geometric error
//! as in the 3D Tiles 1.0 specification, "Geometric error" (`sse = error · height / (2 · distance ·
//! tan(fovy / 2))`, i.e. the angle `error / distance` in pixels).
//!
//! # Bands (eq. 1)
//! The far triangles of a cell are the triangles not in its near list. Each is given the distance
//! `d` between the cell box and its bounding box (a lower bound of the distance from any eye in the
//! cell to any of its points). With `d_0 = near_field − max(half)` (a far triangle lies outside the
//! near-field cube, so `d ≥ d_0`) and the band factor `f > 1`, band `k` holds the triangles with
//! `d_0 · f^k ≤ d < d_0 · f^(k+1)` (the last band used is unbounded in practice: `k` is capped at
//! [`MAX_BANDS`] − 1). Each band's triangles are extracted per source mesh (so per material) and
//! simplified separately.
//!
//! # Error bound (eq. 2)
//! A surface point displaced by at most `e` and seen from a distance of at least `d` turns by an
//! angle of at most `asin(e / d)`. So band `k`, nearest distance `d_k = d_0 · f^k`, is simplified
//! with the absolute error
//!
//! ```text
//! e_k = d_k · sin(θ),   θ = error_px · α                                   (eq. 2)
//! ```
//!
//! passed to meshoptimizer in world metres with `SimplifyOptions::ErrorAbsolute` (no conversion
//! to meshoptimizer's default error relative to the mesh extent, `target_error = e / extent`, is
//! needed; `meshopt::simplify_scale` is that extent). For the small angles in use `sin θ ≈ tan θ ≈
//! θ`; the sine is the exact bound. meshoptimizer's error is the quadric distance of the collapsed
//! vertices to the planes of the original triangles they absorbed, a close estimate of the
//! surface deviation but not a strict Hausdorff bound; the measured screen-space error is tested
//! against the bound with its slack stated (`tests/hlod.rs` of lemi-strategy).
//!
//! # Cracks and small parts
//! `SimplifyOptions::LockBorder` keeps every open edge in place, among them the edges cut between
//! two bands or two meshes, so adjacent bands of one continuous surface keep meeting exactly.
//! `SimplifyOptions::Prune` removes disconnected parts smaller than the error (the far buildings
//! of a city), whose removal moves what the pixel shows by less than the bound.

use glam::DVec3;
use meshopt::SimplifyOptions;

use crate::cell::ViewCell;
use crate::classify::TriRef;
use crate::{Mesh, Scene};

/// Bands per cell at most (a factor of 2 from a 1 cm border covers 10¹⁷ m).
pub const MAX_BANDS: usize = 64;
/// The largest accepted `error_px` (a multiple of α); beyond it the far field is a few boxes.
pub const MAX_ERROR_PX: f64 = 1024.0;
/// The largest accepted band factor.
pub const MAX_BAND_FACTOR: f64 = 64.0;

/// How a cell's far field is simplified.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HlodOptions {
    /// The screen-space error bound as a multiple of α (eq. 2).
    pub error_px: f64,
    /// Ratio of a band's far distance to its near distance (eq. 1).
    pub band_factor: f64,
}

impl Default for HlodOptions {
    fn default() -> Self {
        HlodOptions {
            error_px: 1.0,
            band_factor: 2.0,
        }
    }
}

/// An HLOD option out of range; [`HlodError::option`] names the [`HlodOptions`] field.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HlodError {
    #[error("the HLOD error bound must be a positive multiple of the parallax angle, at most {MAX_ERROR_PX} (got {0})")]
    ErrorPx(f64),
    #[error("the HLOD band factor must be a number in (1, {MAX_BAND_FACTOR}] (got {0})")]
    BandFactor(f64),
    #[error("the HLOD bound {error_px} α is not an angle below 90° (α = {alpha} rad)")]
    Angle { error_px: f64, alpha: f64 },
}

impl HlodError {
    /// The [`HlodOptions`] field at fault.
    pub fn option(&self) -> &'static str {
        match self {
            HlodError::ErrorPx(_) | HlodError::Angle { .. } => "error_px",
            HlodError::BandFactor(_) => "band_factor",
        }
    }
}

impl HlodOptions {
    /// Checks the options for a bake with parallax angle `alpha` (radians).
    pub fn validate(&self, alpha: f64) -> Result<(), HlodError> {
        if !(self.error_px.is_finite() && self.error_px > 0.0 && self.error_px <= MAX_ERROR_PX) {
            return Err(HlodError::ErrorPx(self.error_px));
        }
        if !(self.band_factor.is_finite()
            && self.band_factor > 1.0
            && self.band_factor <= MAX_BAND_FACTOR)
        {
            return Err(HlodError::BandFactor(self.band_factor));
        }
        let theta = self.error_px * alpha;
        if !(theta.is_finite() && theta > 0.0 && theta < std::f64::consts::FRAC_PI_2) {
            return Err(HlodError::Angle {
                error_px: self.error_px,
                alpha,
            });
        }
        Ok(())
    }
}

/// One distance band of a simplified far field.
#[derive(Clone, Debug, PartialEq)]
pub struct HlodBand {
    /// Nearest distance from the cell box of the band's triangles (`d_k`, eq. 1).
    pub near: f64,
    /// Band's far distance (`d_k · f`); the band of index [`MAX_BANDS`] − 1 is unbounded
    /// (`f64::MAX`).
    pub far: f64,
    /// The absolute error the band was simplified with (`e_k`, eq. 2), metres.
    pub error_bound: f64,
    /// The largest error meshoptimizer reports for the band's meshes, metres.
    pub result_error: f64,
    /// Triangles of the band before simplification.
    pub source_triangles: u64,
    /// The simplified meshes, one per source mesh with triangles left, compacted (only the
    /// vertices the indices use).
    pub meshes: Vec<Mesh>,
}

impl HlodBand {
    pub fn triangles(&self) -> u64 {
        self.meshes.iter().map(|m| m.triangle_count() as u64).sum()
    }
}

/// A cell's simplified far field, bands near to far.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HlodFarField {
    pub bands: Vec<HlodBand>,
}

impl HlodFarField {
    /// Triangles after simplification.
    pub fn triangles(&self) -> u64 {
        self.bands.iter().map(HlodBand::triangles).sum()
    }

    /// Far triangles before simplification.
    pub fn source_triangles(&self) -> u64 {
        self.bands.iter().map(|b| b.source_triangles).sum()
    }

    /// Every simplified mesh, bands near to far.
    pub fn meshes(&self) -> impl Iterator<Item = &Mesh> {
        self.bands.iter().flat_map(|b| b.meshes.iter())
    }
}

/// Distance between the box `center ± half` and the box `lo..hi` (0 if they overlap).
pub fn box_distance(center: DVec3, half: DVec3, lo: DVec3, hi: DVec3) -> f64 {
    let gap = (lo - (center + half))
        .max((center - half) - hi)
        .max(DVec3::ZERO);
    gap.length()
}

/// The nearest distance of band `k` (eq. 1).
pub fn band_near(d0: f64, factor: f64, k: usize) -> f64 {
    d0 * factor.powi(k as i32)
}

/// The band of a triangle at distance `d` from the cell box (eq. 1), `0..MAX_BANDS`.
pub fn band_of(d: f64, d0: f64, factor: f64) -> usize {
    if d <= d0 || !d.is_finite() {
        return if d.is_finite() { 0 } else { MAX_BANDS - 1 };
    }
    let mut k = ((d / d0).ln() / factor.ln()).floor().max(0.0) as usize;
    // guard the logarithm's rounding: band k must start at or before d
    while k > 0 && band_near(d0, factor, k) > d {
        k -= 1;
    }
    k.min(MAX_BANDS - 1)
}

/// The first band's distance from the cell box: the near-field cube's border (eq. 1), at least
/// a millimetre.
pub fn first_band_distance(cell: &ViewCell, near_field: f64) -> f64 {
    (near_field - cell.half.max_element()).max(1e-3)
}

/// The far field of `cell` simplified in distance bands (module docs): every triangle of `scene`
/// not in `near`, for the parallax angle `alpha` (radians) and the near-field distance
/// `near_field` the cell was baked with. The options are checked first.
pub fn simplify_far_field(
    scene: &Scene,
    cell: &ViewCell,
    near_field: f64,
    near: &[TriRef],
    alpha: f64,
    options: &HlodOptions,
) -> Result<HlodFarField, HlodError> {
    use rayon::prelude::*;
    options.validate(alpha)?;
    let theta = options.error_px * alpha;
    let d0 = first_band_distance(cell, near_field);
    let f = options.band_factor;
    let mut is_near: Vec<Vec<bool>> = scene
        .meshes
        .iter()
        .map(|m| vec![false; m.triangle_count()])
        .collect();
    for r in near {
        if let Some(slot) = is_near
            .get_mut(r.mesh as usize)
            .and_then(|m| m.get_mut(r.tri as usize))
        {
            *slot = true;
        }
    }
    let mut per_band: Vec<Vec<TriRef>> = vec![Vec::new(); MAX_BANDS];
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        for (t, &near) in is_near[mi].iter().enumerate() {
            if near {
                continue;
            }
            let p = mesh.triangle(t).map(|v| v.as_dvec3());
            let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            if !(lo.is_finite() && hi.is_finite()) {
                continue;
            }
            let d = box_distance(cell.center, cell.half, lo, hi);
            per_band[band_of(d, d0, f)].push(TriRef {
                mesh: mi as u32,
                tri: t as u32,
            });
        }
    }
    let bands: Vec<(usize, Vec<TriRef>)> = per_band
        .into_iter()
        .enumerate()
        .filter(|(_, refs)| !refs.is_empty())
        .collect();
    let bands = bands
        .into_par_iter()
        .map(|(k, refs)| {
            let near = band_near(d0, f, k);
            let far = if k + 1 == MAX_BANDS {
                f64::MAX
            } else {
                band_near(d0, f, k + 1)
            };
            let error_bound = near * theta.sin();
            // every reference comes from the scene's own meshes, so extraction cannot fail
            let meshes = scene.extract(&refs).unwrap_or_default();
            let mut result_error = 0.0f64;
            let meshes: Vec<Mesh> = meshes
                .into_iter()
                .filter_map(|m| {
                    let (s, e) = simplify_mesh(&m, error_bound);
                    result_error = result_error.max(e);
                    (s.triangle_count() > 0).then_some(s)
                })
                .collect();
            HlodBand {
                near,
                far,
                error_bound,
                result_error,
                source_triangles: refs.len() as u64,
                meshes,
            }
        })
        .collect();
    Ok(HlodFarField { bands })
}

/// Simplifies one mesh to the absolute error `error` (metres) with meshoptimizer
/// (`ErrorAbsolute | LockBorder | Prune`, no triangle target) and compacts its vertices; returns
/// the mesh and the error meshoptimizer reports.
pub fn simplify_mesh(mesh: &Mesh, error: f64) -> (Mesh, f64) {
    let positions: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| v.position).collect();
    let mut result_error = 0.0f32;
    let indices = meshopt::simplify_decoder(
        &mesh.indices,
        &positions,
        0,
        error as f32,
        SimplifyOptions::ErrorAbsolute | SimplifyOptions::LockBorder | SimplifyOptions::Prune,
        Some(&mut result_error),
    );
    let mut remap = vec![u32::MAX; mesh.vertices.len()];
    let mut out = Mesh {
        material: mesh.material,
        vertices: Vec::new(),
        indices: Vec::with_capacity(indices.len()),
    };
    for i in indices {
        let Some(slot) = remap.get_mut(i as usize) else {
            continue;
        };
        if *slot == u32::MAX {
            *slot = out.vertices.len() as u32;
            out.vertices.push(mesh.vertices[i as usize]);
        }
        out.indices.push(*slot);
    }
    out.indices.truncate(out.indices.len() / 3 * 3);
    (out, f64::from(result_error))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_double_from_the_border() {
        assert_eq!(band_of(5.0, 10.0, 2.0), 0);
        assert_eq!(band_of(10.0, 10.0, 2.0), 0);
        assert_eq!(band_of(19.9, 10.0, 2.0), 0);
        assert_eq!(band_of(20.0, 10.0, 2.0), 1);
        assert_eq!(band_of(80.0, 10.0, 2.0), 3);
        assert_eq!(band_of(f64::INFINITY, 10.0, 2.0), MAX_BANDS - 1);
        assert_eq!(band_of(1e300, 1e-3, 2.0), MAX_BANDS - 1);
        for d in [10.0, 13.0, 40.0, 1234.5] {
            let k = band_of(d, 10.0, 3.0);
            assert!(band_near(10.0, 3.0, k) <= d && d < band_near(10.0, 3.0, k + 1));
        }
    }

    #[test]
    fn box_distance_is_the_gap() {
        let c = DVec3::ZERO;
        let h = DVec3::splat(1.0);
        assert_eq!(
            box_distance(c, h, DVec3::splat(-0.5), DVec3::splat(0.5)),
            0.0
        );
        let d = box_distance(c, h, DVec3::new(4.0, 5.0, -1.0), DVec3::new(5.0, 6.0, 1.0));
        assert!((d - 5.0).abs() < 1e-12, "{d}"); // gaps 3 and 4
    }

    #[test]
    fn bad_options_name_their_field() {
        let ok = HlodOptions::default();
        assert!(ok.validate(0.001).is_ok());
        for (o, field) in [
            (
                HlodOptions {
                    error_px: f64::NAN,
                    ..ok
                },
                "error_px",
            ),
            (
                HlodOptions {
                    error_px: 0.0,
                    ..ok
                },
                "error_px",
            ),
            (
                HlodOptions {
                    error_px: -1.0,
                    ..ok
                },
                "error_px",
            ),
            (
                HlodOptions {
                    error_px: 1e9,
                    ..ok
                },
                "error_px",
            ),
            (
                HlodOptions {
                    band_factor: 1.0,
                    ..ok
                },
                "band_factor",
            ),
            (
                HlodOptions {
                    band_factor: f64::INFINITY,
                    ..ok
                },
                "band_factor",
            ),
        ] {
            assert_eq!(o.validate(0.001).unwrap_err().option(), field, "{o:?}");
        }
        let e = HlodOptions {
            error_px: 1000.0,
            ..ok
        }
        .validate(0.01);
        assert!(matches!(e, Err(HlodError::Angle { .. })), "{e:?}");
    }

    #[test]
    fn a_flat_grid_collapses_within_its_error_and_keeps_its_border() {
        // a 10 x 10 grid of quads on y = 0: flat, so it simplifies to few triangles with no error
        let n = 10;
        let mut vertices = Vec::new();
        for z in 0..=n {
            for x in 0..=n {
                vertices.push(crate::Vertex::new(
                    [x as f32, 0.0, z as f32],
                    [0.0, 1.0, 0.0],
                    [0.0, 0.0],
                    [255; 4],
                ));
            }
        }
        let mut indices = Vec::new();
        for z in 0..n {
            for x in 0..n {
                let i = z * (n + 1) + x;
                indices.extend_from_slice(&[i, i + n + 1, i + 1, i + 1, i + n + 1, i + n + 2]);
            }
        }
        let mesh = Mesh {
            material: 3,
            vertices,
            indices,
        };
        let (s, e) = simplify_mesh(&mesh, 0.01);
        assert!(
            s.triangle_count() < mesh.triangle_count(),
            "{}",
            s.triangle_count()
        );
        assert!(e <= 0.01, "{e}");
        assert_eq!(s.material, 3);
        // the locked border keeps every border vertex
        let border =
            |p: [f32; 3]| p[0] == 0.0 || p[2] == 0.0 || p[0] == n as f32 || p[2] == n as f32;
        let kept = s.vertices.iter().filter(|v| border(v.position)).count();
        assert_eq!(kept, 4 * n as usize);
        assert!(s.indices.iter().all(|&i| (i as usize) < s.vertices.len()));
    }
}
