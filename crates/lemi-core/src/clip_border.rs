//! Clip-border texels: the texels of a layer image that a polygon's clipping edge passes through.
//!
//! This work is based on: TR-186-2-02-04 sec. 2.2 (Jeschke, Wimmer). A polygon crossing a slab
//! border is cut there and both adjacent layers record their part; the texels along the cut are
//! only partly covered by each part, so they must not hide anything behind them (hidden-texel
//! removal, GI 2002 sec. 5.2, treats them as non-occluding; see
//! [`crate::compress::hidden_texels`]). The cut edges lie on a border plane (constant depth along
//! the face axis), so they project to straight segments of the face image; every texel a segment
//! passes through is found exactly by a grid traversal (Amanatides & Woo, "A Fast Voxel Traversal
//! Algorithm for Ray Tracing", Eurographics 1987), in 2D.

use crate::clip::ClipVertex;
use crate::Face;
use glam::DVec2;

/// Marks in `mask` (`res × res`, row-major, row 0 at the top) every texel touched by an edge of the
/// clipped triangles `tris` (three vertices each, relative to the reference viewpoint) that lies on
/// one of the planes `depth = plane` for `plane` in `planes`. Returns the number of such edges.
pub fn mark_clip_borders(
    tris: &[ClipVertex],
    face: Face,
    planes: &[f64],
    res: u32,
    mask: &mut [bool],
) -> usize {
    let mut edges = 0;
    for tri in tris.chunks_exact(3) {
        for k in 0..3 {
            let (a, b) = (&tri[k], &tri[(k + 1) % 3]);
            if !is_clip_edge(a, b, face, planes) {
                continue;
            }
            let (Some(pa), Some(pb)) = (to_texel(face, a, res), to_texel(face, b, res)) else {
                continue;
            };
            traverse(pa, pb, res, mask);
            edges += 1;
        }
    }
    edges
}

/// Whether the edge `a`–`b` of a clipped triangle is a clipping edge on one of `planes` (depths
/// along `face`'s axis): both ends on the same plane. Exact comparison: the clipper snaps cut
/// vertices exactly onto the plane ([`crate::clip::clip_to_slab`]).
pub fn is_clip_edge(a: &ClipVertex, b: &ClipVertex, face: Face, planes: &[f64]) -> bool {
    let axis = face.forward();
    let (da, db) = (a.rel.dot(axis), b.rel.dot(axis));
    da == db && planes.contains(&da)
}

/// Face-image position in texel units (texel `(i, j)` spans `[i, i+1] × [j, j+1]`).
fn to_texel(face: Face, v: &ClipVertex, res: u32) -> Option<DVec2> {
    let (s, t, _) = face.project(v.rel)?;
    let r = res as f64;
    Some(DVec2::new((s + 1.0) * 0.5 * r, (t + 1.0) * 0.5 * r))
}

/// Marks every texel the closed segment `a`–`b` passes through (clipped to the image).
pub fn traverse(a: DVec2, b: DVec2, res: u32, mask: &mut [bool]) {
    let r = res as f64;
    // clip the segment to the image square (Liang–Barsky)
    let d = b - a;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-d.x, a.x), (d.x, r - a.x), (-d.y, a.y), (d.y, r - a.y)] {
        if p == 0.0 {
            if q < 0.0 {
                return;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    if t0 > t1 || !t0.is_finite() || !t1.is_finite() {
        return;
    }
    let (p, q) = (a + d * t0, a + d * t1);
    let max = res as i64 - 1;
    let cell = |v: f64| (v.floor() as i64).clamp(0, max);
    let (mut x, mut y) = (cell(p.x), cell(p.y));
    let (ex, ey) = (cell(q.x), cell(q.y));
    let dir = q - p;
    let step_x: i64 = if dir.x > 0.0 { 1 } else { -1 };
    let step_y: i64 = if dir.y > 0.0 { 1 } else { -1 };
    let next = |c: i64, s: i64| if s > 0 { (c + 1) as f64 } else { c as f64 };
    let mut t_max_x = if dir.x != 0.0 {
        (next(x, step_x) - p.x) / dir.x
    } else {
        f64::INFINITY
    };
    let mut t_max_y = if dir.y != 0.0 {
        (next(y, step_y) - p.y) / dir.y
    } else {
        f64::INFINITY
    };
    let t_dx = if dir.x != 0.0 {
        1.0 / dir.x.abs()
    } else {
        f64::INFINITY
    };
    let t_dy = if dir.y != 0.0 {
        1.0 / dir.y.abs()
    } else {
        f64::INFINITY
    };
    let w = res as usize;
    let limit = 4 * res as usize + 4;
    for _ in 0..limit {
        mask[y as usize * w + x as usize] = true;
        if x == ex && y == ey {
            break;
        }
        if t_max_x < t_max_y {
            x += step_x;
            t_max_x += t_dx;
        } else {
            y += step_y;
            t_max_y += t_dy;
        }
        if !(0..=max).contains(&x) || !(0..=max).contains(&y) {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Brute force: texels whose closed square the segment meets (sampled densely, which finds
    /// every texel the segment crosses by more than the sampling step).
    fn sampled(a: DVec2, b: DVec2, res: u32) -> Vec<bool> {
        let mut m = vec![false; (res * res) as usize];
        let n = 20_000;
        for i in 0..=n {
            let p = a + (b - a) * (i as f64 / n as f64);
            if p.x >= 0.0 && p.y >= 0.0 && p.x < res as f64 && p.y < res as f64 {
                m[p.y as usize * res as usize + p.x as usize] = true;
            }
        }
        m
    }

    #[test]
    fn horizontal_and_diagonal_segments() {
        let mut m = vec![false; 64];
        traverse(DVec2::new(0.5, 2.5), DVec2::new(7.5, 2.5), 8, &mut m);
        assert_eq!(m.iter().filter(|&&x| x).count(), 8);
        assert!((0..8).all(|x| m[2 * 8 + x]));
        let mut m = vec![false; 64];
        traverse(DVec2::new(-3.0, -3.0), DVec2::new(20.0, 20.5), 8, &mut m);
        assert!((0..8).all(|i| m[i * 8 + i]), "the diagonal is marked");
        let mut m = vec![false; 64];
        traverse(DVec2::new(-3.0, 9.0), DVec2::new(20.0, 9.0), 8, &mut m);
        assert!(m.iter().all(|&x| !x), "outside the image");
    }

    proptest! {
        /// The traversal marks every texel the segment crosses and nothing far from it.
        #[test]
        fn matches_dense_sampling(
            a in proptest::array::uniform2(-4.0f64..20.0),
            b in proptest::array::uniform2(-4.0f64..20.0),
        ) {
            let (a, b) = (DVec2::from_array(a), DVec2::from_array(b));
            let res = 16;
            let mut m = vec![false; 256];
            traverse(a, b, res, &mut m);
            let s = sampled(a, b, res);
            for i in 0..256 {
                if s[i] {
                    prop_assert!(m[i], "texel {} crossed but not marked", i);
                }
                if m[i] {
                    // marked texels lie within one texel diagonal of the segment
                    let c = DVec2::new((i % 16) as f64 + 0.5, (i / 16) as f64 + 0.5);
                    let d = b - a;
                    let t = if d.length_squared() > 0.0 {
                        ((c - a).dot(d) / d.length_squared()).clamp(0.0, 1.0)
                    } else { 0.0 };
                    prop_assert!((a + d * t - c).length() <= 0.7072);
                }
            }
        }
    }
}
