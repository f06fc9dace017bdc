//! Where the layers of a cell go and what each records, per [`Layering`] (the far-field strategy of
//! a layered bundle, `BakeParams::layering`):
//!
//! - [`Layering::Optimal`] (lemi): [`place_env_layers`] for `params.target`
//!   (GI 2002 sec. 4, TR-186-2-02-04 sec. 2.1); each layer records its slab between its borders.
//! - [`Layering::Single`] (a conventional cube environment map): one layer per face, placed as the
//!   optimal placement places one layer (`Target::Layers(1)`, whatever `params.target` says), so the
//!   near field is where one layer puts it. Recorded like the optimal bake.
//! - [`Layering::Equidistant`] (Schaufler 1998, *Per-object image warping with layered impostors*,
//!   as summarised in TR-186-2-02-04 sec. 1 and 2.2): the optimal placement's number of layers and
//!   near field, but the `n + 1` borders spaced uniformly in depth between the near field and the
//!   farthest scene point along the face axis ([`farthest_along`], from the scene's bounding box),
//!   each layer's quad in the middle of its slab ([`equidistant_placement`]). Layer `k` records the
//!   depths of its slab extended by `overlap` × the slab depth on each side, so adjacent slabs
//!   overlap and a triangle in an overlap is recorded in both ([`recording_slabs`]); the extension
//!   stops at the near field (the near field is drawn as geometry, never as impostor) and the
//!   farthest layer records everything beyond its near bound (nothing of the scene lies beyond its
//!   far border; this only guards against rounding). When the scene does not extend beyond the near
//!   field on a face (its layers come out empty), the borders are spaced between the near field and
//!   twice the near field instead.
//!
//! The stored layer information (`LayerInfo`: distance, near and far border) is the [`Placement`];
//! what each layer records is its [`Slabs`] range. For the optimal and single layerings the two
//! coincide (`Slabs::from_borders`).

use crate::bundle::{BakeParams, LayerTarget, Layering};
use crate::cell::{CellId, ViewCell};
use crate::classify::Slabs;
use crate::placement::{
    place_env_layers, Axis, Bound, EnvParams, Layer, Placement, PlacementError, Target,
};
use crate::{Aabb, Face};
use glam::DVec3;

/// Why the layers of a cell cannot be planned.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LayeringError {
    #[error("cell {cell}: placing the layers of face {face}: {source}")]
    Placement {
        cell: CellId,
        face: Face,
        #[source]
        source: PlacementError,
    },
    #[error(
        "cell {cell}: the equidistant layering spaces its layers up to the farthest scene point: \
         placing them needs the scene's bounds"
    )]
    NeedsSceneBounds { cell: CellId },
}

/// The layers of one face and the depth range each records (same order, far to near).
#[derive(Clone, Debug, PartialEq)]
pub struct FacePlan {
    pub face: Face,
    /// Layer distances and borders, as stored in the cell header.
    pub placement: Placement,
    /// The depth range each layer records.
    pub slabs: Slabs,
}

/// The layers of every baked face of a cell.
#[derive(Clone, Debug, PartialEq)]
pub struct CellPlan {
    /// One per baked face, in `params.faces` order.
    pub faces: Vec<FacePlan>,
    /// The cell's near-field distance: the largest of the faces' (the near list is one cube).
    pub near_field: f64,
}

impl CellPlan {
    /// The placements, one per face.
    pub fn placements(&self) -> Vec<Placement> {
        self.faces.iter().map(|f| f.placement.clone()).collect()
    }

    /// The recorded slabs, one list per face (for [`crate::classify::classify_slabs`]).
    pub fn slabs(&self) -> Vec<Slabs> {
        self.faces.iter().map(|f| f.slabs.clone()).collect()
    }
}

/// The face axis as a placement axis.
pub fn axis_of(face: Face) -> Axis {
    match face {
        Face::PosX | Face::NegX => Axis::X,
        Face::PosY | Face::NegY => Axis::Y,
        Face::PosZ | Face::NegZ => Axis::Z,
    }
}

/// The largest depth along `face`'s axis, from `center`, of any point of `bounds` (a corner of the
/// box); `NEG_INFINITY` for an empty box.
pub fn farthest_along(bounds: &Aabb, center: DVec3, face: Face) -> f64 {
    if !(bounds.min.cmple(bounds.max).all()) {
        return f64::NEG_INFINITY;
    }
    let a = face.forward();
    (0..8)
        .map(|k| {
            let p = DVec3::new(
                if k & 1 == 0 {
                    bounds.min.x
                } else {
                    bounds.max.x
                },
                if k & 2 == 0 {
                    bounds.min.y
                } else {
                    bounds.max.y
                },
                if k & 4 == 0 {
                    bounds.min.z
                } else {
                    bounds.max.z
                },
            );
            (p - center).dot(a)
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Schaufler's equidistant layers: as many as `optimal` has, the same near field, the borders
/// spaced uniformly between the near field and `farthest` (the farthest scene depth along the face
/// axis), every layer in the middle of its slab; far to near, the farthest layer's far border is
/// `farthest` (finite). If `farthest` is not beyond the near field (or not finite), the borders
/// span the near field to twice the near field (the layers then record nothing). A far end barely
/// beyond the near field is pushed out to `near_field · (1 + 10⁻⁶)` so the layers stay distinct.
pub fn equidistant_placement(optimal: &Placement, farthest: f64) -> Placement {
    let n = optimal.layers.len().max(1);
    let near = optimal.near_field;
    let far = if farthest.is_finite() && farthest > near {
        farthest.max(near * (1.0 + 1e-6))
    } else {
        2.0 * near
    };
    let depth = (far - near) / n as f64;
    // border i (near to far): i = 0 is the near field, i = n the far end
    let border = |i: usize| {
        if i == n {
            far
        } else {
            near + depth * i as f64
        }
    };
    let layers = (0..n)
        .map(|k| {
            let i = n - 1 - k;
            let (lo, hi) = (border(i), border(i + 1));
            Layer {
                distance: 0.5 * (lo + hi),
                near_border: lo,
                far_border: hi,
                // no bound fixes an equidistant layer; keep what fixed the optimal one
                bound_by: optimal
                    .layers
                    .get(k)
                    .map_or(Bound::Parallax, |l| l.bound_by),
            }
        })
        .collect();
    Placement {
        layers,
        near_field: near,
        params: optimal.params,
    }
}

/// What each layer of `placement` records. Without `overlap`: exactly its slab (the optimal and
/// single layerings). With `overlap = o`: the slab `[near, far]` of depth `h` extended to
/// `[max(near − o·h, near field), far + o·h]`, and the farthest layer unbounded beyond.
pub fn recording_slabs(placement: &Placement, overlap: Option<f64>) -> Slabs {
    let Some(o) = overlap else {
        let borders: Vec<f64> = placement.layers.iter().map(|l| l.near_border).collect();
        return Slabs::from_borders(&borders);
    };
    let ranges: Vec<(f64, f64)> = placement
        .layers
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let h = l.far_border - l.near_border;
            let lo = (l.near_border - o * h).max(placement.near_field);
            let hi = if k == 0 {
                f64::INFINITY
            } else {
                l.far_border + o * h
            };
            (lo, hi)
        })
        .collect();
    // uniform slabs extended symmetrically are nested far to near without gaps
    Slabs::new(&ranges).unwrap_or_else(|_| {
        Slabs::from_borders(
            &placement
                .layers
                .iter()
                .map(|l| l.near_border)
                .collect::<Vec<_>>(),
        )
    })
}

/// The optimal placement of every baked face for `target` (`Layers(1)` for the single layering).
fn optimal_placements(
    params: &BakeParams,
    cell: &ViewCell,
    target: Target,
) -> Result<Vec<Placement>, LayeringError> {
    params
        .faces
        .iter()
        .map(|&face| {
            let env =
                EnvParams::box_face(cell.half, axis_of(face), params.resolution, params.alpha);
            place_env_layers(&env, target).map_err(|source| LayeringError::Placement {
                cell: cell.id(),
                face,
                source,
            })
        })
        .collect()
}

/// The layers of every baked face of `cell` and what each records, for `params.layering`.
/// `scene_bounds` is needed by the equidistant layering (the farthest scene point), ignored by the
/// others; without it the equidistant layering is an error.
pub fn plan_cell(
    params: &BakeParams,
    cell: &ViewCell,
    scene_bounds: Option<&Aabb>,
) -> Result<CellPlan, LayeringError> {
    let target = match (params.layering, params.target) {
        (Layering::Single, _) => Target::Layers(1),
        (_, LayerTarget::Layers(n)) => Target::Layers(n as usize),
        (_, LayerTarget::NearField(d)) => Target::NearField(d),
    };
    let optimal = optimal_placements(params, cell, target)?;
    let faces: Vec<FacePlan> = match params.layering {
        Layering::Optimal | Layering::Single | Layering::Hlod { .. } => params
            .faces
            .iter()
            .zip(optimal)
            .map(|(&face, placement)| FacePlan {
                face,
                slabs: recording_slabs(&placement, None),
                placement,
            })
            .collect(),
        Layering::Equidistant { overlap } => {
            let Some(bounds) = scene_bounds else {
                return Err(LayeringError::NeedsSceneBounds { cell: cell.id() });
            };
            params
                .faces
                .iter()
                .zip(optimal)
                .map(|(&face, opt)| {
                    let placement =
                        equidistant_placement(&opt, farthest_along(bounds, cell.center, face));
                    FacePlan {
                        face,
                        slabs: recording_slabs(&placement, Some(overlap)),
                        placement,
                    }
                })
                .collect()
        }
    };
    let near_field = faces
        .iter()
        .map(|f| f.placement.near_field)
        .fold(0.0f64, f64::max);
    Ok(CellPlan { faces, near_field })
}

/// The placement of every baked face of `cell`, for `params.layering`. The equidistant layering
/// needs the scene's bounds: use [`place_cell_in`] (this is an error for it).
pub fn place_cell(params: &BakeParams, cell: &ViewCell) -> Result<Vec<Placement>, LayeringError> {
    Ok(plan_cell(params, cell, None)?.placements())
}

/// [`place_cell`] for a scene with bounding box `scene_bounds` (what the bake places, for every
/// layering).
pub fn place_cell_in(
    params: &BakeParams,
    cell: &ViewCell,
    scene_bounds: &Aabb,
) -> Result<Vec<Placement>, LayeringError> {
    Ok(plan_cell(params, cell, Some(scene_bounds))?.placements())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::IVec3;

    fn params(layering: Layering) -> BakeParams {
        BakeParams {
            cell_size: 10.0,
            cell_height: None,
            resolution: 64,
            target: LayerTarget::Layers(4),
            faces: Face::HORIZONTAL.to_vec(),
            alpha: 0.02,
            output_fov_deg: None,
            output_width: None,
            micro_grid: 8,
            micro_threshold: 0.6,
            layering,
            texture_format: Default::default(),
            outline_copies: false,
            outline_fringe: false,
        }
    }

    fn cell() -> ViewCell {
        ViewCell {
            index: IVec3::ZERO,
            center: DVec3::new(5.0, 1.7, 5.0),
            half: DVec3::splat(5.0),
        }
    }

    #[test]
    fn farthest_scene_depth_along_each_face() {
        let b = Aabb::new(
            DVec3::new(-100.0, 0.0, -50.0),
            DVec3::new(300.0, 20.0, 80.0),
        );
        let c = DVec3::new(10.0, 1.0, 0.0);
        assert_eq!(farthest_along(&b, c, Face::PosX), 290.0);
        assert_eq!(farthest_along(&b, c, Face::NegX), 110.0);
        assert_eq!(farthest_along(&b, c, Face::PosZ), 80.0);
        assert_eq!(farthest_along(&b, c, Face::NegZ), 50.0);
        assert_eq!(farthest_along(&b, c, Face::PosY), 19.0);
        assert_eq!(
            farthest_along(&Aabb::EMPTY, c, Face::PosX),
            f64::NEG_INFINITY
        );
    }

    #[test]
    fn optimal_and_single_record_their_slabs() {
        let opt = plan_cell(&params(Layering::Optimal), &cell(), None).unwrap();
        assert_eq!(opt.faces.len(), 4);
        for f in &opt.faces {
            assert_eq!(f.placement.layers.len(), 4);
            for (k, l) in f.placement.layers.iter().enumerate() {
                assert_eq!(
                    (f.slabs.lo(k), f.slabs.hi(k)),
                    (l.near_border, l.far_border)
                );
            }
        }
        let single = plan_cell(&params(Layering::Single), &cell(), None).unwrap();
        let env = EnvParams::box_face(cell().half, Axis::X, 64, 0.02);
        let one = place_env_layers(&env, Target::Layers(1)).unwrap();
        for f in &single.faces {
            assert_eq!(f.placement, one);
            assert_eq!(f.slabs.len(), 1);
        }
        assert_eq!(single.near_field, one.near_field);
        assert!(single.near_field > opt.near_field);
    }

    #[test]
    fn equidistant_layers_are_uniform_between_the_near_field_and_the_farthest_point() {
        let p = params(Layering::Equidistant { overlap: 0.25 });
        let c = cell();
        // the scene reaches 500 m beyond the centre along +X, only 20 m along -X
        let bounds = Aabb::new(
            DVec3::new(-15.0, 0.0, -300.0),
            DVec3::new(505.0, 30.0, 305.0),
        );
        assert!(plan_cell(&p, &c, None).is_err(), "needs the bounds");
        let plan = plan_cell(&p, &c, Some(&bounds)).unwrap();
        let opt = plan_cell(&params(Layering::Optimal), &c, None).unwrap();
        assert_eq!(plan.near_field, opt.near_field);
        for (f, o) in plan.faces.iter().zip(&opt.faces) {
            let pl = &f.placement;
            let n = pl.layers.len();
            assert_eq!(n, o.placement.layers.len());
            assert_eq!(pl.near_field, o.placement.near_field);
            let far = farthest_along(&bounds, c.center, f.face);
            let end = if far > pl.near_field {
                far
            } else {
                2.0 * pl.near_field
            };
            let h = (end - pl.near_field) / n as f64;
            assert_eq!(pl.layers[0].far_border, end);
            assert_eq!(pl.layers[n - 1].near_border, pl.near_field);
            for (k, l) in pl.layers.iter().enumerate() {
                assert!(
                    (l.far_border - l.near_border - h).abs() < 1e-9 * end,
                    "{l:?}"
                );
                assert!((l.distance - 0.5 * (l.near_border + l.far_border)).abs() < 1e-9 * end);
                let (lo, hi) = (f.slabs.lo(k), f.slabs.hi(k));
                let want_lo = (l.near_border - 0.25 * h).max(pl.near_field);
                assert!((lo - want_lo).abs() < 1e-9 * end);
                if k == 0 {
                    assert_eq!(hi, f64::INFINITY);
                } else {
                    assert!((hi - (l.far_border + 0.25 * h)).abs() < 1e-9 * end);
                }
            }
            for w in pl.layers.windows(2) {
                assert_eq!(w[0].near_border, w[1].far_border);
                assert!(w[0].distance > w[1].distance);
            }
        }
        // -X: the scene ends at 20 m, inside the ~49 m near field: the fallback span
        let negx = &plan.faces[1];
        assert_eq!(negx.face, Face::NegX);
        assert_eq!(negx.placement.layers[0].far_border, 2.0 * plan.near_field);
    }

    #[test]
    fn zero_overlap_records_exactly_the_slabs() {
        let p = params(Layering::Equidistant { overlap: 0.0 });
        let bounds = Aabb::new(DVec3::splat(-400.0), DVec3::splat(400.0));
        let plan = plan_cell(&p, &cell(), Some(&bounds)).unwrap();
        for f in &plan.faces {
            let exact = recording_slabs(&f.placement, None);
            for k in 0..f.slabs.len() {
                assert_eq!(f.slabs.lo(k), exact.lo(k));
                assert_eq!(f.slabs.hi(k), exact.hi(k));
            }
        }
    }
}
