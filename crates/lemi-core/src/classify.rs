//! Classification of a scene for one view cell (GI 2002 sec. 3 and 4): the **near list** (triangles
//! touching the near-field cube, drawn as geometry at runtime) and, for the far field, every triangle
//! binned to the (face, slab) pairs it overlaps, so that recording one layer submits only its bin.
//!
//! Slabs follow the placement: for a face, layers are ordered far to near and `borders[k]` is the near
//! border of layer `k` (descending; the last one is the near-field distance). Layer `k` records depths
//! `borders[k] ≤ d ≤ borders[k − 1]` (`borders[−1] = ∞`). Strategies whose layers record overlapping
//! depth ranges (Schaufler's layered impostors, `Layering::Equidistant`) give each layer its range
//! explicitly ([`Slabs`], [`classify_slabs`]); contiguous borders are the special case
//! [`Slabs::from_borders`], and [`classify`] is exactly [`classify_slabs`] of those. A triangle is
//! binned to every slab its depth
//! range along the face axis overlaps, if it may intersect the face's 90° pyramid (a conservative
//! test against the pyramid's four side planes). A triangle therefore appears in as many bins as slabs
//! it spans: total submissions stay a small multiple of the far triangles, never layers × scene.
//!
//! The per-triangle positions are computed once per scene ([`TriangleBounds`]) and shared by all
//! cells, together with an acceleration structure: the triangles sorted along a Morton (Z-order)
//! curve of their centroids (as the leaf level of a linear BVH: Lauterbach et al., "Fast BVH
//! Construction on GPUs", Eurographics 2009) and cut into clusters of [`CLUSTER_SIZE`] with their
//! bounding boxes. Per cell and face, a cluster outside the face's pyramid or inside the near field
//! is skipped whole, a cluster inside the pyramid and inside one slab is binned whole, and only the
//! remaining clusters are tested triangle by triangle. Far layers are thick, so most of a large
//! scene is binned a cluster at a time. The result equals the per-triangle scan
//! ([`classify_brute_force`]) as sets; bins and the near list are sorted, so it is deterministic.

use glam::DVec3;

use crate::{Face, Scene};

/// A triangle reference: mesh index and triangle index within the mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TriRef {
    pub mesh: u32,
    pub tri: u32,
}

/// Triangles per cluster of the acceleration structure.
pub const CLUSTER_SIZE: usize = 64;

/// A run of spatially close triangles (consecutive on the Morton curve) and its bounding box.
#[derive(Clone, Debug, PartialEq)]
pub struct Cluster {
    pub min: DVec3,
    pub max: DVec3,
    /// Range into [`TriangleBounds::refs`] / [`TriangleBounds::verts`].
    pub range: std::ops::Range<usize>,
}

/// Per-triangle vertex positions in f64, in Morton order of their centroids, and their clusters;
/// computed once per scene.
#[derive(Clone, Debug, Default)]
pub struct TriangleBounds {
    pub refs: Vec<TriRef>,
    pub verts: Vec<[DVec3; 3]>,
    pub clusters: Vec<Cluster>,
}

/// Spreads the low 21 bits of `v` to every third bit (for 63-bit 3D Morton codes).
fn spread3(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// The 63-bit 3D Morton (Z-order) code of a point given in the unit cube (coordinates clamped to
/// `[0, 1]`, quantized to 21 bits each; x in the lowest bit). NaN maps to 0.
pub fn morton_code(unit: DVec3) -> u64 {
    let q = (unit.clamp(DVec3::ZERO, DVec3::ONE) * 2_097_151.0).as_u64vec3();
    spread3(q.x) | spread3(q.y) << 1 | spread3(q.z) << 2
}

impl TriangleBounds {
    pub fn new(scene: &Scene) -> Self {
        use rayon::prelude::*;
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
        // Morton order of the centroids within the scene's bounding box
        let (lo, hi) = verts.iter().flatten().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(a, b), p| (a.min(*p), b.max(*p)),
        );
        let scale = (hi - lo).max(DVec3::splat(1e-9));
        let mut keyed: Vec<(u64, usize)> = verts
            .par_iter()
            .enumerate()
            .map(|(i, v)| (morton_code(((v[0] + v[1] + v[2]) / 3.0 - lo) / scale), i))
            .collect();
        keyed.par_sort_unstable();
        let refs: Vec<TriRef> = keyed.iter().map(|&(_, i)| refs[i]).collect();
        let verts: Vec<[DVec3; 3]> = keyed.iter().map(|&(_, i)| verts[i]).collect();
        let clusters = (0..verts.len())
            .step_by(CLUSTER_SIZE)
            .map(|start| {
                let range = start..(start + CLUSTER_SIZE).min(verts.len());
                let (min, max) = verts[range.clone()].iter().flatten().fold(
                    (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                    |(a, b), p| (a.min(*p), b.max(*p)),
                );
                Cluster { min, max, range }
            })
            .collect();
        TriangleBounds {
            refs,
            verts,
            clusters,
        }
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

/// The depth ranges (along the face axis, from the reference viewpoint) that the layers of one face
/// record, far to near: layer `k` records `lo(k) ≤ d ≤ hi(k)`. Both bounds are non-increasing in
/// `k` and the ranges leave no gap (`lo(k) ≤ hi(k + 1)`); adjacent ranges may overlap, so a
/// triangle in an overlap is binned to both layers.
#[derive(Clone, Debug, PartialEq)]
pub struct Slabs {
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl Slabs {
    /// The contiguous slabs of descending near borders `borders` (layer `k` records
    /// `[borders[k], borders[k − 1]]`, `borders[−1] = ∞`): what [`classify`] uses.
    pub fn from_borders(borders: &[f64]) -> Slabs {
        let hi = std::iter::once(f64::INFINITY)
            .chain(borders.iter().copied())
            .take(borders.len())
            .collect();
        Slabs {
            lo: borders.to_vec(),
            hi,
        }
    }

    /// Slabs with explicit ranges `(lo, hi)`, far to near. Errors (saying which layer) unless every
    /// bound is a number, `lo ≤ hi`, both bounds are non-increasing and no depth between two
    /// adjacent ranges is left out.
    pub fn new(ranges: &[(f64, f64)]) -> Result<Slabs, String> {
        for (k, &(lo, hi)) in ranges.iter().enumerate() {
            if lo.is_nan() || hi.is_nan() || lo > hi {
                return Err(format!(
                    "slab {k}: the range [{lo}, {hi}] is not an interval"
                ));
            }
            if let Some(&(plo, phi)) = k.checked_sub(1).map(|p| &ranges[p]) {
                if lo > plo || hi > phi {
                    return Err(format!(
                        "slab {k}: [{lo}, {hi}] is not nearer than slab {} [{plo}, {phi}]",
                        k - 1
                    ));
                }
                if hi < plo {
                    return Err(format!(
                        "slab {k}: a gap between its far bound {hi} and the near bound {plo} of slab {}",
                        k - 1
                    ));
                }
            }
        }
        Ok(Slabs {
            lo: ranges.iter().map(|r| r.0).collect(),
            hi: ranges.iter().map(|r| r.1).collect(),
        })
    }

    /// Number of slabs (layers).
    pub fn len(&self) -> usize {
        self.lo.len()
    }

    pub fn is_empty(&self) -> bool {
        self.lo.is_empty()
    }

    /// The near bound of slab `k`.
    pub fn lo(&self, k: usize) -> f64 {
        self.lo[k]
    }

    /// The far bound of slab `k` (`∞` for an unbounded farthest slab).
    pub fn hi(&self, k: usize) -> f64 {
        self.hi[k]
    }

    /// Range of layers `k` whose slab overlaps depths `[lo, hi]` (for [`Slabs::from_borders`] the
    /// same as [`slab_range`]).
    pub fn range(&self, lo: f64, hi: f64) -> std::ops::Range<usize> {
        // lo(k) and hi(k) are non-increasing: the layers with lo(k) <= hi and hi(k) >= lo are
        // consecutive
        let first = self.lo.partition_point(|&b| b > hi);
        let end = self.hi.partition_point(|&b| b >= lo);
        first..end.max(first)
    }
}

/// How a box relates to a face's pyramid: outside one side plane, inside all four, or neither.
fn box_vs_pyramid(corners: &[DVec3; 8], face: Face) -> (bool, bool) {
    let a = face.forward();
    let r = face.right();
    let d = face.down();
    let mut inside = true;
    for (axis, sign) in [(r, 1.0), (r, -1.0), (d, 1.0), (d, -1.0)] {
        let side = |p: &DVec3| p.dot(a) + sign * p.dot(axis);
        if corners.iter().all(|p| side(p) < 0.0) {
            return (true, false);
        }
        inside &= corners.iter().all(|p| side(p) >= 0.0);
    }
    (false, inside)
}

/// Classifies the scene for a cell with reference viewpoint `center`, near-field distance
/// `near_field`, baked `faces` and per-face descending near borders `borders[face_slot]`, using the
/// clusters of [`TriangleBounds`] (see the module docs). Panics if `faces` and `borders` differ in
/// length (a programming error, not user input).
pub fn classify(
    tris: &TriangleBounds,
    center: DVec3,
    near_field: f64,
    faces: &[Face],
    borders: &[Vec<f64>],
) -> Classification {
    assert_eq!(faces.len(), borders.len(), "one border list per face");
    let slabs: Vec<Slabs> = borders.iter().map(|b| Slabs::from_borders(b)).collect();
    classify_slabs(tris, center, near_field, faces, &slabs)
}

/// [`classify`] with explicit (possibly overlapping) slab ranges per face, `slabs[face_slot]`.
/// Panics if `faces` and `slabs` differ in length.
pub fn classify_slabs(
    tris: &TriangleBounds,
    center: DVec3,
    near_field: f64,
    faces: &[Face],
    slabs: &[Slabs],
) -> Classification {
    assert_eq!(faces.len(), slabs.len(), "one slab list per face");
    let mut out = Classification {
        near: Vec::new(),
        bins: slabs.iter().map(|b| vec![Vec::new(); b.len()]).collect(),
        far_triangles: 0,
        submitted: 0,
    };
    let nf = DVec3::splat(near_field);
    let mut far = [false; CLUSTER_SIZE];
    for cl in &tris.clusters {
        let (lo, hi) = (cl.min - center, cl.max - center);
        let refs = &tris.refs[cl.range.clone()];
        let verts = &tris.verts[cl.range.clone()];
        far[..refs.len()].fill(false);
        // near list: skip the per-triangle test when the box misses the near cube
        if lo.cmple(nf).all() && hi.cmpge(-nf).all() {
            for (r, v) in refs.iter().zip(verts) {
                let rel = v.map(|p| p - center);
                let tlo = rel[0].min(rel[1]).min(rel[2]);
                let thi = rel[0].max(rel[1]).max(rel[2]);
                if tlo.cmple(nf).all() && thi.cmpge(-nf).all() {
                    out.near.push(*r);
                }
            }
        }
        let corners: [DVec3; 8] = std::array::from_fn(|k| {
            DVec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            )
        });
        for (slot, &face) in faces.iter().enumerate() {
            let a = face.forward();
            let ds = corners.map(|p| p.dot(a));
            let dmax = ds.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let dmin = ds.iter().copied().fold(f64::INFINITY, f64::min);
            if dmax < near_field {
                continue;
            }
            let (outside, inside) = box_vs_pyramid(&corners, face);
            if outside {
                continue;
            }
            let face_slabs = &slabs[slot];
            let range = face_slabs.range(dmin, dmax);
            if inside
                && dmin >= near_field
                && range.len() == 1
                && dmin >= face_slabs.lo(range.start)
                && dmax <= face_slabs.hi(range.start)
            {
                // the whole cluster lies in one slab of this face (and in no other)
                out.bins[slot][range.start].extend_from_slice(refs);
                out.submitted += refs.len() as u64;
                far[..refs.len()].fill(true);
                continue;
            }
            for (i, (r, v)) in refs.iter().zip(verts).enumerate() {
                let rel = v.map(|p| p - center);
                let d = rel.map(|p| p.dot(a));
                let tmax = d[0].max(d[1]).max(d[2]);
                if tmax < near_field || !may_touch_pyramid(&rel, face) {
                    continue;
                }
                let tmin = d[0].min(d[1]).min(d[2]);
                for k in face_slabs.range(tmin, tmax) {
                    out.bins[slot][k].push(*r);
                    out.submitted += 1;
                    far[i] = true;
                }
            }
        }
        out.far_triangles += far[..refs.len()].iter().filter(|&&f| f).count() as u64;
    }
    out.near.sort_unstable();
    for face in &mut out.bins {
        for bin in face {
            bin.sort_unstable();
        }
    }
    out
}

/// The same classification by a plain scan over every triangle (the reference the clustered
/// [`classify`] is tested against).
pub fn classify_brute_force(
    tris: &TriangleBounds,
    center: DVec3,
    near_field: f64,
    faces: &[Face],
    borders: &[Vec<f64>],
) -> Classification {
    assert_eq!(faces.len(), borders.len(), "one border list per face");
    let slabs: Vec<Slabs> = borders.iter().map(|b| Slabs::from_borders(b)).collect();
    classify_slabs_brute_force(tris, center, near_field, faces, &slabs)
}

/// The plain scan of [`classify_brute_force`] with explicit slab ranges (the reference for
/// [`classify_slabs`]). Each triangle is tested against every slab one by one.
pub fn classify_slabs_brute_force(
    tris: &TriangleBounds,
    center: DVec3,
    near_field: f64,
    faces: &[Face],
    slabs: &[Slabs],
) -> Classification {
    assert_eq!(faces.len(), slabs.len(), "one slab list per face");
    let mut out = Classification {
        near: Vec::new(),
        bins: slabs.iter().map(|b| vec![Vec::new(); b.len()]).collect(),
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
            let face_slabs = &slabs[slot];
            for k in (0..face_slabs.len())
                .filter(|&k| face_slabs.lo(k) <= dmax && face_slabs.hi(k) >= dmin)
            {
                out.bins[slot][k].push(*r);
                out.submitted += 1;
                far = true;
            }
        }
        if far {
            out.far_triangles += 1;
        }
    }
    out.near.sort_unstable();
    for face in &mut out.bins {
        for bin in face {
            bin.sort_unstable();
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

    /// Many scattered triangles, most small, every tenth large (deterministic).
    fn scattered_scene() -> Scene {
        let mut b = SceneBuilder::new();
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f32 / (1u64 << 53) as f32
        };
        for m in 0..4 {
            let mut vertices = Vec::new();
            let mut indices = Vec::new();
            for t in 0..3000u32 {
                let c = [
                    rnd() * 400.0 - 200.0,
                    rnd() * 60.0 - 10.0,
                    rnd() * 400.0 - 200.0,
                ];
                let size = if t % 10 == 0 { 40.0 } else { 2.0 };
                for _ in 0..3 {
                    let p = [
                        c[0] + size * (rnd() - 0.5),
                        c[1] + size * (rnd() - 0.5),
                        c[2] + size * (rnd() - 0.5),
                    ];
                    vertices.push(Vertex::new(p, [0.0, 1.0, 0.0], [0.0; 2], [255; 4]));
                }
                indices.extend([3 * t, 3 * t + 1, 3 * t + 2]);
            }
            b.add_mesh(Mesh {
                material: m % 2,
                vertices,
                indices,
            });
        }
        b.finish()
    }

    /// Clustered classification equals the per-triangle scan on a scattered scene of many
    /// triangles, from several centres (near, far, inside the scene).
    #[test]
    fn clusters_match_the_brute_force_scan() {
        let scene = scattered_scene();
        let tb = TriangleBounds::new(&scene);
        assert_eq!(
            tb.clusters.iter().map(|c| c.range.len()).sum::<usize>(),
            tb.len()
        );
        let borders = vec![300.0, 150.0, 80.0, 50.0, 35.0, 25.0, 18.0, 12.0];
        for faces in [&Face::HORIZONTAL[..], &Face::ALL[..]] {
            let bl = vec![borders.clone(); faces.len()];
            for c in [
                DVec3::new(0.0, 1.7, 0.0),
                DVec3::new(150.0, 5.0, -90.0),
                DVec3::new(-400.0, 0.0, 0.0),
            ] {
                let fast = classify(&tb, c, 12.0, faces, &bl);
                let slow = classify_brute_force(&tb, c, 12.0, faces, &bl);
                assert_eq!(fast.near, slow.near);
                assert_eq!(fast.bins, slow.bins);
                assert_eq!(fast.far_triangles, slow.far_triangles);
                assert_eq!(fast.submitted, slow.submitted);
                assert!(fast.far_triangles > 0);
            }
        }
    }

    #[test]
    fn near_list_holds_what_touches_the_near_cube() {
        let scene = quad_scene(5.0, -1.0, 1.0);
        let tb = TriangleBounds::new(&scene);
        let c = classify(&tb, DVec3::ZERO, 10.0, &[Face::PosZ], &[vec![20.0, 10.0]]);
        assert_eq!(c.near.len(), 2);
        assert_eq!(c.submitted, 0);
    }

    #[test]
    fn contiguous_slabs_are_the_border_ranges() {
        let b = [100.0, 50.0, 20.0, 10.0];
        let slabs = Slabs::from_borders(&b);
        assert_eq!(slabs.len(), 4);
        assert_eq!(slabs.hi(0), f64::INFINITY);
        assert_eq!((slabs.lo(2), slabs.hi(2)), (20.0, 50.0));
        let probes = [
            0.0, 1.0, 5.0, 10.0, 12.0, 20.0, 35.0, 50.0, 70.0, 100.0, 300.0,
        ];
        for &lo in &probes {
            for &hi in probes.iter().filter(|&&h| h >= lo) {
                assert_eq!(slabs.range(lo, hi), slab_range(&b, lo, hi), "[{lo}, {hi}]");
            }
        }
        assert!(Slabs::from_borders(&[]).is_empty());
    }

    #[test]
    fn overlapping_slabs_bin_a_triangle_in_the_overlap_twice() {
        // slabs [40, ∞), [20, 45], [10, 25]: overlaps [40, 45] and [20, 25]
        let slabs = Slabs::new(&[(40.0, f64::INFINITY), (20.0, 45.0), (10.0, 25.0)]).unwrap();
        assert_eq!(slabs.range(42.0, 43.0), 0..2);
        assert_eq!(slabs.range(30.0, 35.0), 1..2);
        assert_eq!(slabs.range(21.0, 22.0), 1..3);
        assert_eq!(slabs.range(11.0, 12.0), 2..3);
        assert_eq!(slabs.range(1.0, 5.0).len(), 0);
        for (z, bins) in [(42.0f32, vec![0, 1]), (30.0, vec![1]), (22.0, vec![1, 2])] {
            let tb = TriangleBounds::new(&quad_scene(z, -1.0, 1.0));
            for c in [
                classify_slabs(
                    &tb,
                    DVec3::ZERO,
                    10.0,
                    &[Face::PosZ],
                    std::slice::from_ref(&slabs),
                ),
                classify_slabs_brute_force(
                    &tb,
                    DVec3::ZERO,
                    10.0,
                    &[Face::PosZ],
                    std::slice::from_ref(&slabs),
                ),
            ] {
                let holding: Vec<usize> = (0..3).filter(|&k| !c.bins[0][k].is_empty()).collect();
                assert_eq!(holding, bins, "quad at z = {z}");
                assert_eq!(c.far_triangles, 2);
                assert_eq!(c.submitted, 2 * bins.len() as u64);
            }
        }
    }

    #[test]
    fn slab_ranges_that_are_not_nested_layers_are_rejected() {
        assert!(Slabs::new(&[(10.0, 5.0)]).unwrap_err().contains("slab 0"));
        assert!(Slabs::new(&[(f64::NAN, 5.0)]).is_err());
        // a gap between 30 and 40
        let e = Slabs::new(&[(40.0, 100.0), (10.0, 30.0)]).unwrap_err();
        assert!(e.contains("gap"), "{e}");
        // not ordered far to near
        assert!(Slabs::new(&[(10.0, 30.0), (20.0, 100.0)]).is_err());
        assert!(Slabs::new(&[]).unwrap().is_empty());
    }

    /// With overlapping slabs the clustered classification still equals the scan, and with zero
    /// overlap it equals the classification by borders.
    #[test]
    fn overlapping_clusters_match_the_brute_force_scan() {
        let scene = scattered_scene();
        let tb = TriangleBounds::new(&scene);
        let (near, far) = (12.0, 300.0);
        let n = 8;
        let depth = (far - near) / n as f64;
        for overlap in [0.0, 0.1, 0.5, 1.0] {
            let ranges: Vec<(f64, f64)> = (0..n)
                .map(|k| {
                    let b0 = near + depth * (n - 1 - k) as f64;
                    let b1 = b0 + depth;
                    let lo = (b0 - overlap * depth).max(near);
                    let hi = if k == 0 {
                        f64::INFINITY
                    } else {
                        b1 + overlap * depth
                    };
                    (lo, hi)
                })
                .collect();
            let slabs = Slabs::new(&ranges).unwrap();
            let faces = &Face::ALL[..];
            let sl = vec![slabs; faces.len()];
            for c in [DVec3::new(0.0, 1.7, 0.0), DVec3::new(150.0, 5.0, -90.0)] {
                let fast = classify_slabs(&tb, c, near, faces, &sl);
                let slow = classify_slabs_brute_force(&tb, c, near, faces, &sl);
                assert_eq!(fast.near, slow.near);
                assert_eq!(fast.bins, slow.bins, "overlap {overlap}");
                assert_eq!(fast.far_triangles, slow.far_triangles);
                assert_eq!(fast.submitted, slow.submitted);
                assert!(fast.far_triangles > 0);
                if overlap == 0.0 {
                    let borders: Vec<f64> = ranges.iter().map(|r| r.0).collect();
                    let by_borders = classify(&tb, c, near, faces, &vec![borders; faces.len()]);
                    assert_eq!(by_borders.bins, fast.bins);
                    assert_eq!(by_borders.submitted, fast.submitted);
                } else {
                    assert!(fast.submitted > fast.far_triangles);
                }
            }
        }
    }
}
