//! Classification of a scene for one view cell (GI 2002 sec. 3 and 4): the **near list** (triangles
//! touching the near-field cube, drawn as geometry at runtime) and, for the far field, every triangle
//! binned to the (face, slab) pairs it overlaps, so that recording one layer submits only its bin.
//!
//! Slabs follow the placement: for a face, layers are ordered far to near and `borders[k]` is the near
//! border of layer `k` (descending; the last one is the near-field distance). Layer `k` records depths
//! `borders[k] ≤ d ≤ borders[k − 1]` (`borders[−1] = ∞`). A triangle is binned to every slab its depth
//! range along the face axis overlaps, if it may intersect the face's 90° pyramid (a conservative
//! test against the pyramid's four side planes). A triangle therefore appears in as many bins as slabs
//! it spans: total submissions stay a small multiple of the far triangles, never layers × scene.
//!
//! The per-triangle bounds are computed once per scene ([`TriangleBounds`]) and shared by all cells;
//! the per-cell pass is a parallel linear scan over them.

use glam::DVec3;

use crate::{Face, Scene};

/// A triangle reference: mesh index and triangle index within the mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TriRef {
    pub mesh: u32,
    pub tri: u32,
}

/// Per-triangle vertex positions in f64, computed once per scene.
#[derive(Clone, Debug, Default)]
pub struct TriangleBounds {
    pub refs: Vec<TriRef>,
    pub verts: Vec<[DVec3; 3]>,
}

impl TriangleBounds {
    pub fn new(scene: &Scene) -> Self {
        let mut refs = Vec::with_capacity(scene.triangle_count() as usize);
        let mut verts = Vec::with_capacity(scene.triangle_count() as usize);
        for (mi, mesh) in scene.meshes.iter().enumerate() {
            for t in 0..mesh.triangle_count() {
                let p = mesh.triangle(t);
                refs.push(TriRef {
                    mesh: mi as u32,
                    tri: t as u32,
                });
                verts.push(p.map(|v| v.as_dvec3()));
            }
        }
        TriangleBounds { refs, verts }
    }

    pub fn len(&self) -> usize {
        self.refs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.refs.is_empty()
    }
}

/// The classification of one cell.
#[derive(Clone, Debug, Default)]
pub struct Classification {
    /// Triangles touching the near-field cube.
    pub near: Vec<TriRef>,
    /// `bins[face_slot][layer]`: triangles overlapping that slab, for each baked face in the order
    /// given to [`classify`].
    pub bins: Vec<Vec<Vec<TriRef>>>,
    /// Distinct triangles in at least one bin.
    pub far_triangles: u64,
    /// Sum of all bin sizes (what the recorder submits).
    pub submitted: u64,
}

/// Whether the triangle may intersect the 90° pyramid of `face` (conservative: false only if all
/// three vertices are outside the same side plane).
pub fn may_touch_pyramid(rel: &[DVec3; 3], face: Face) -> bool {
    let a = face.forward();
    let r = face.right();
    let d = face.down();
    // side planes: depth ± s-coordinate ≥ 0, depth ± t-coordinate ≥ 0
    for (axis, sign) in [(r, 1.0), (r, -1.0), (d, 1.0), (d, -1.0)] {
        if rel.iter().all(|p| p.dot(a) + sign * p.dot(axis) < 0.0) {
            return false;
        }
    }
    true
}

/// Range of layers `k` (far to near) whose slab overlaps depths `[lo, hi]`, given descending
/// near borders. Empty when the range lies inside the near field.
pub fn slab_range(borders: &[f64], lo: f64, hi: f64) -> std::ops::Range<usize> {
    // layer k covers [borders[k], borders[k-1]] (borders[-1] = ∞); layers with borders[k] <= hi
    // and borders[k-1] >= lo.
    let first = borders.partition_point(|&b| b > hi); // first k with borders[k] <= hi
                                                      // last k with borders[k-1] >= lo  ⇔  k - 1 < number of borders >= lo
    let n_ge_lo = borders.partition_point(|&b| b >= lo);
    let end = (n_ge_lo + 1).min(borders.len());
    first..end.max(first)
}

/// Classifies the scene for a cell with reference viewpoint `center`, near-field distance
/// `near_field`, baked `faces` and per-face descending near borders `borders[face_slot]`.
pub fn classify(
    tris: &TriangleBounds,
    center: DVec3,
    near_field: f64,
    faces: &[Face],
    borders: &[Vec<f64>],
) -> Classification {
    assert_eq!(faces.len(), borders.len(), "one border list per face");
    let mut out = Classification {
        near: Vec::new(),
        bins: borders.iter().map(|b| vec![Vec::new(); b.len()]).collect(),
        far_triangles: 0,
        submitted: 0,
    };
    for (r, v) in tris.refs.iter().zip(&tris.verts) {
        let rel = v.map(|p| p - center);
        let lo = rel[0].min(rel[1]).min(rel[2]);
        let hi = rel[0].max(rel[1]).max(rel[2]);
        if lo.cmple(DVec3::splat(near_field)).all() && hi.cmpge(DVec3::splat(-near_field)).all() {
            out.near.push(*r);
        }
        let mut far = false;
        for (slot, &face) in faces.iter().enumerate() {
            let a = face.forward();
            let d = rel.map(|p| p.dot(a));
            let dmax = d[0].max(d[1]).max(d[2]);
            if dmax < near_field || !may_touch_pyramid(&rel, face) {
                continue;
            }
            let dmin = d[0].min(d[1]).min(d[2]);
            for k in slab_range(&borders[slot], dmin, dmax) {
                out.bins[slot][k].push(*r);
                out.submitted += 1;
                far = true;
            }
        }
        if far {
            out.far_triangles += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Mesh, SceneBuilder, Vertex};

    #[test]
    fn slab_ranges() {
        let b = [100.0, 50.0, 20.0, 10.0];
        assert_eq!(slab_range(&b, 200.0, 300.0), 0..1);
        assert_eq!(slab_range(&b, 60.0, 70.0), 1..2);
        assert_eq!(slab_range(&b, 15.0, 120.0), 0..4);
        assert_eq!(slab_range(&b, 1.0, 5.0).len(), 0);
        assert_eq!(slab_range(&b, 5.0, 12.0), 3..4);
        assert_eq!(slab_range(&b, 50.0, 50.0), 1..3);
    }

    fn quad_scene(z: f32, x0: f32, x1: f32) -> Scene {
        let v = |x: f32, y: f32| Vertex::new([x, y, z], [0.0; 3], [0.0; 2], [255; 4]);
        let mut b = SceneBuilder::new();
        b.add_mesh(Mesh {
            material: 0,
            vertices: vec![v(x0, -1.0), v(x1, -1.0), v(x1, 1.0), v(x0, 1.0)],
            indices: vec![0, 1, 2, 0, 2, 3],
        });
        b.finish()
    }

    #[test]
    fn bins_match_brute_force_sampling() {
        // a wall at z = 30 from x = -5 to 80: in the +Z pyramid for |x| <= 30, in +X beyond
        let scene = quad_scene(30.0, -5.0, 80.0);
        let tb = TriangleBounds::new(&scene);
        let borders = vec![60.0, 40.0, 25.0, 12.0];
        let faces = [Face::PosX, Face::PosZ, Face::NegX, Face::NegZ];
        let c = classify(&tb, DVec3::ZERO, 12.0, &faces, &vec![borders.clone(); 4]);
        assert!(c.near.is_empty());
        // brute force: sample points of the wall, find (face, slab); each must be in a bin holding
        // its triangle
        for i in 0..=200 {
            for j in 0..=10 {
                let p = DVec3::new(-5.0 + 85.0 * i as f64 / 200.0, -1.0 + 0.2 * j as f64, 30.0);
                let f = Face::of_direction(p);
                let Some(slot) = faces.iter().position(|&x| x == f) else {
                    continue;
                };
                let d = f.depth(p);
                let k = borders.iter().position(|&b| b <= d).unwrap();
                // which triangle holds p: the quad's diagonal from (x0,-1) to (x1,1)
                let t = (p.y + 1.0) / 2.0 <= (p.x + 5.0) / 85.0;
                let tri = if t { 0 } else { 1 };
                assert!(
                    c.bins[slot][k].contains(&TriRef { mesh: 0, tri }),
                    "point {p} face {f} layer {k}"
                );
            }
        }
        assert!(c.bins[2].iter().all(|b| b.is_empty()), "-X sees nothing");
        assert_eq!(c.far_triangles, 2);
        assert!(c.submitted <= 2 * 8);
    }

    #[test]
    fn near_list_holds_what_touches_the_near_cube() {
        let scene = quad_scene(5.0, -1.0, 1.0);
        let tb = TriangleBounds::new(&scene);
        let c = classify(&tb, DVec3::ZERO, 10.0, &[Face::PosZ], &[vec![20.0, 10.0]]);
        assert_eq!(c.near.len(), 2);
        assert_eq!(c.submitted, 0);
    }
}
