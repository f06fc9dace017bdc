//! Clipping triangles to the slab of one layer (the depth range between two borders along a face's
//! axis), for crack-free layer recording (TR-186-2-02-04 sec. 2.2): a polygon crossing a border is cut
//! there, and each adjacent layer records its part. The cut must lie at *identical* positions in both
//! layers, so every edge/plane intersection here is computed from the edge's endpoints in a canonical
//! order (by depth, then by position), never from the order in which the polygon walks the edge.
//! The same edge cut by the same plane therefore gives bit-identical vertices in both slabs.

use glam::DVec3;

use crate::{Face, Vertex};

/// A vertex during clipping: position relative to the reference viewpoint in f64, attributes as f32.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClipVertex {
    pub rel: DVec3,
    pub normal: [f32; 3],
    pub uv: [f32; 2],
    pub color: [f32; 4],
}

impl ClipVertex {
    pub fn from_vertex(v: &Vertex, center: DVec3) -> Self {
        let p = DVec3::new(
            v.position[0] as f64,
            v.position[1] as f64,
            v.position[2] as f64,
        );
        ClipVertex {
            rel: p - center,
            normal: v.normal,
            uv: v.uv,
            color: v.color.map(|c| c as f32),
        }
    }

    /// Back to a scene vertex at absolute position `center + rel`.
    pub fn to_vertex(&self, center: DVec3) -> Vertex {
        let p = (center + self.rel).as_vec3();
        Vertex {
            position: p.to_array(),
            normal: self.normal,
            uv: self.uv,
            color: self.color.map(|c| c.round().clamp(0.0, 255.0) as u8),
        }
    }

    fn lerp(a: &ClipVertex, b: &ClipVertex, t: f64) -> ClipVertex {
        let tf = t as f32;
        let l3 = |x: [f32; 3], y: [f32; 3]| [0, 1, 2].map(|k| x[k] + (y[k] - x[k]) * tf);
        ClipVertex {
            rel: a.rel + (b.rel - a.rel) * t,
            normal: l3(a.normal, b.normal),
            uv: [0, 1].map(|k| a.uv[k] + (b.uv[k] - a.uv[k]) * tf),
            color: [0, 1, 2, 3].map(|k| a.color[k] + (b.color[k] - a.color[k]) * tf),
        }
    }
}

/// Total order used to orient an edge canonically.
fn key(v: &ClipVertex, axis: DVec3) -> (f64, f64, f64, f64) {
    (v.rel.dot(axis), v.rel.x, v.rel.y, v.rel.z)
}

/// The point of edge `a`–`b` at depth `plane` along `axis`, computed identically for `a, b` and `b, a`.
fn cut(a: &ClipVertex, b: &ClipVertex, axis: DVec3, plane: f64) -> ClipVertex {
    let (p, q) = if key(a, axis) <= key(b, axis) {
        (a, b)
    } else {
        (b, a)
    };
    let dp = p.rel.dot(axis);
    let dq = q.rel.dot(axis);
    let t = ((plane - dp) / (dq - dp)).clamp(0.0, 1.0);
    let mut v = ClipVertex::lerp(p, q, t);
    // Snap the depth exactly onto the plane so both slabs agree on the cut even after rounding.
    let d = v.rel.dot(axis);
    v.rel += axis * (plane - d);
    v
}

/// A polygon vertex during clipping and the original triangle edge it lies on (`(i, i)` for an
/// original vertex). Every polygon edge that can cross a clipping plane is a piece of an original
/// edge, so cuts are always computed on original edges: identical in every slab.
#[derive(Clone, Copy)]
struct Node {
    v: ClipVertex,
    e: (u8, u8),
}

/// The original edge containing both nodes (they lie on a common original edge).
fn common_edge(a: &Node, b: &Node) -> (u8, u8) {
    let mut ids = [a.e.0, a.e.1, b.e.0, b.e.1];
    ids.sort_unstable();
    let lo = ids[0];
    let hi = ids[3];
    (lo, hi)
}

/// Keeps the part of `poly` with depth ≥ `plane` (`keep_above`) or ≤ `plane`.
fn clip_plane(
    tri: &[ClipVertex; 3],
    poly: &[Node],
    axis: DVec3,
    plane: f64,
    keep_above: bool,
    out: &mut Vec<Node>,
) {
    out.clear();
    let n = poly.len();
    let inside = |v: &ClipVertex| {
        let d = v.rel.dot(axis);
        if keep_above {
            d >= plane
        } else {
            d <= plane
        }
    };
    for i in 0..n {
        let a = &poly[i];
        let b = &poly[(i + 1) % n];
        let (ia, ib) = (inside(&a.v), inside(&b.v));
        if ia {
            out.push(*a);
        }
        if ia != ib {
            let e = common_edge(a, b);
            let v = cut(&tri[e.0 as usize], &tri[e.1 as usize], axis, plane);
            out.push(Node { v, e });
        }
    }
}

/// Clips triangle `tri` (relative positions) to `near ≤ depth ≤ far` along `face`'s axis and appends
/// the result as a triangle fan to `out` (three vertices per triangle). `far` may be `f64::INFINITY`.
/// Returns the number of triangles appended.
pub fn clip_to_slab(
    tri: &[ClipVertex; 3],
    face: Face,
    near: f64,
    far: f64,
    out: &mut Vec<ClipVertex>,
) -> usize {
    let axis = face.forward();
    let depths = tri.map(|v| v.rel.dot(axis));
    let (lo, hi) = (
        depths.iter().copied().fold(f64::INFINITY, f64::min),
        depths.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );
    if hi < near || lo > far {
        return 0;
    }
    if lo >= near && hi <= far {
        out.extend_from_slice(tri);
        return 1;
    }
    let mut a: Vec<Node> = (0..3u8)
        .map(|i| Node {
            v: tri[i as usize],
            e: (i, i),
        })
        .collect();
    let mut b = Vec::with_capacity(5);
    if lo < near {
        clip_plane(tri, &a, axis, near, true, &mut b);
        std::mem::swap(&mut a, &mut b);
    }
    if hi > far {
        clip_plane(tri, &a, axis, far, false, &mut b);
        std::mem::swap(&mut a, &mut b);
    }
    if a.len() < 3 {
        return 0;
    }
    for k in 1..a.len() - 1 {
        out.push(a[0].v);
        out.push(a[k].v);
        out.push(a[k + 1].v);
    }
    a.len() - 2
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cv(p: [f64; 3]) -> ClipVertex {
        ClipVertex {
            rel: DVec3::from_array(p),
            normal: [0.0, 1.0, 0.0],
            uv: [p[0] as f32, p[2] as f32],
            color: [255.0; 4],
        }
    }

    fn area(v: &[ClipVertex]) -> f64 {
        v.chunks_exact(3)
            .map(|t| 0.5 * (t[1].rel - t[0].rel).cross(t[2].rel - t[0].rel).length())
            .sum()
    }

    #[test]
    fn inside_triangle_is_kept_whole_and_outside_dropped() {
        let t = [
            cv([5.0, 0.0, 0.0]),
            cv([6.0, 1.0, 0.0]),
            cv([5.5, 0.0, 1.0]),
        ];
        let mut out = Vec::new();
        assert_eq!(clip_to_slab(&t, Face::PosX, 4.0, 7.0, &mut out), 1);
        assert_eq!(&out[..], &t[..]);
        out.clear();
        assert_eq!(clip_to_slab(&t, Face::PosX, 7.0, 9.0, &mut out), 0);
        assert_eq!(
            clip_to_slab(&t, Face::NegX, 1.0, f64::INFINITY, &mut out),
            0
        );
    }

    proptest! {
        /// Slabs that partition the depth axis partition the triangle: areas add up, every vertex lies
        /// in its slab, and cut vertices on a shared border are bit-identical in both slabs.
        #[test]
        fn slabs_partition_triangles(
            p in proptest::array::uniform3(proptest::array::uniform3(-50.0f64..50.0)),
            mut borders in proptest::collection::vec(-40.0f64..40.0, 1..6),
            fi in 0usize..6,
        ) {
            let face = Face::ALL[fi];
            let tri = p.map(cv);
            let a0 = 0.5 * (tri[1].rel - tri[0].rel).cross(tri[2].rel - tri[0].rel).length();
            prop_assume!(a0 > 1e-3);
            borders.sort_by(f64::total_cmp);
            borders.dedup();
            let mut edges = vec![f64::NEG_INFINITY];
            edges.extend(borders.iter().copied());
            edges.push(f64::INFINITY);
            let axis = face.forward();
            let mut total = 0.0;
            let mut per_slab = Vec::new();
            for w in edges.windows(2) {
                let mut out = Vec::new();
                clip_to_slab(&tri, face, w[0], w[1], &mut out);
                for v in &out {
                    let d = v.rel.dot(axis);
                    prop_assert!(d >= w[0] - 1e-9 && d <= w[1] + 1e-9);
                }
                total += area(&out);
                per_slab.push(out);
            }
            prop_assert!((total - a0).abs() <= 1e-9 * a0.max(1.0), "{} vs {}", total, a0);
            for (k, b) in borders.iter().enumerate() {
                let on = |vs: &Vec<ClipVertex>| {
                    let mut s: Vec<[u64; 3]> = vs.iter()
                        .filter(|v| v.rel.dot(axis) == *b)
                        .map(|v| v.rel.to_array().map(f64::to_bits))
                        .collect();
                    s.sort();
                    s.dedup();
                    s
                };
                let below = on(&per_slab[k]);
                let above = on(&per_slab[k + 1]);
                if !below.is_empty() && !above.is_empty() {
                    prop_assert_eq!(below, above);
                }
            }
        }
    }
}
