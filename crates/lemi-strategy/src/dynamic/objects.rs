//! The far field as objects (see "Objects" in the module docs): the scene's triangles grouped by
//! a uniform grid into base objects, a view cell's far part of them, and octree pieces of the
//! objects too close to the cell for a billboard (Schaufler, "Dynamically generated impostors",
//! 1995, draws one impostor per object; the bounding-sphere distance test keeps every billboard
//! well in front of the eye). Also the object's impostor as generated.

use std::collections::{HashMap, HashSet};

use glam::DVec3;
use lemi_core::classify::TriRef;
use lemi_core::{Aabb, Mesh, Scene};
use lemi_gpu::GpuScene;

/// Octree levels a too-close object is split into at most.
pub const MAX_SPLIT_DEPTH: u32 = 8;

/// A group of far triangles drawn as one billboard.
pub(super) struct Object {
    pub(super) tris: Vec<[u32; 2]>,
    pub(super) bounds: Aabb,
    pub(super) centre: DVec3,
    pub(super) radius: f64,
    /// The object's triangles on the GPU (uploaded on first generation).
    pub(super) gpu: Option<GpuScene>,
    pub(super) impostor: Option<Impostor>,
}

/// One generated impostor.
pub(super) struct Impostor {
    pub(super) eye: DVec3,
    /// Distance from the generation eye to the centre (the billboard plane's view depth).
    pub(super) distance: f64,
    pub(super) half: f64,
    pub(super) res: u32,
    /// World corners of the whole `res × res` image: top-left, top-right, bottom-right,
    /// bottom-left.
    pub(super) corners: [DVec3; 4],
    /// The rectangle `[x, y, w, h]` of the image holding every opaque texel: only it is kept,
    /// stored and drawn (empty when nothing is opaque).
    pub(super) crop: [u32; 4],
    /// View depth (from `eye`) of every texel of `crop`, row-major, `INFINITY` where transparent.
    pub(super) depth: Vec<f32>,
    /// Per texel of `crop`, the texel (of `crop`) whose surface point it shows: itself, or for a
    /// dilated texel the opaque neighbour its colour came from; empty without dilation (every
    /// texel is its own).
    pub(super) source: Vec<u32>,
    /// sRGB RGBA of the texels of `crop`, row-major (empty when nothing is opaque).
    pub(super) rgba: Vec<u8>,
}

impl Impostor {
    /// World point of image texel-edge coordinates `(i, j)` (fractional) on the billboard.
    pub(super) fn point(&self, i: f64, j: f64) -> DVec3 {
        let [c0, c1, _, c3] = self.corners;
        let r = self.res as f64;
        c0 + (c1 - c0) * (i / r) + (c3 - c0) * (j / r)
    }

    /// Corners of the drawn (cropped) part.
    pub(super) fn crop_corners(&self) -> [DVec3; 4] {
        let [x, y, w, h] = self.crop.map(f64::from);
        [
            self.point(x, y),
            self.point(x + w, y),
            self.point(x + w, y + h),
            self.point(x, y + h),
        ]
    }
}

/// Which object: a scene-wide base object or one of the current cell's pieces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(super) enum ObjId {
    Base(u32),
    Local(u32),
}

/// A view cell's far field as objects.
pub(super) struct CellObjects {
    /// The billboard candidates: untouched base objects, then every piece of `local`.
    pub(super) active: Vec<ObjId>,
    /// Pieces of base objects split for this cell.
    pub(super) local: Vec<Object>,
    /// Far triangles too close to the cell for any billboard (drawn as geometry).
    pub(super) too_close: Vec<[u32; 2]>,
}

/// The far field of the view cell `cell` (its box) whose near list is `near` and whose near field
/// reaches `near_field` from `centre` (see the module docs): a base object is used as it is when
/// none of its triangles is near and every point of `cell` is at least `k` of its bounding radii
/// from its centre; otherwise its far triangles are [`split`] (and its impostor dropped).
pub(super) fn cell_objects(
    scene: &Scene,
    base: &mut [Object],
    near: &[[u32; 2]],
    centre: DVec3,
    near_field: f64,
    cell: &Aabb,
    k: f64,
) -> CellObjects {
    let near_set: HashSet<[u32; 2]> = near.iter().copied().collect();
    let cube = Aabb::new(
        centre - DVec3::splat(near_field),
        centre + DVec3::splat(near_field),
    );
    let mut active = Vec::new();
    let mut local = Vec::new();
    let mut too_close = Vec::new();
    for (i, obj) in base.iter_mut().enumerate() {
        let touches = boxes_overlap(&obj.bounds, &cube, 1e-6 * (1.0 + near_field));
        let far: Vec<[u32; 2]> = if touches {
            obj.tris
                .iter()
                .copied()
                .filter(|t| !near_set.contains(t))
                .collect()
        } else {
            Vec::new()
        };
        let untouched = !touches || far.len() == obj.tris.len();
        if untouched && box_distance(cell, obj.centre) >= k * obj.radius {
            active.push(ObjId::Base(i as u32));
            continue;
        }
        obj.impostor = None;
        let far = if untouched { obj.tris.clone() } else { far };
        split(scene, far, cell, k, 0, &mut local, &mut too_close);
    }
    for i in 0..local.len() {
        active.push(ObjId::Local(i as u32));
    }
    CellObjects {
        active,
        local,
        too_close,
    }
}

/// Triangle positions in f64; `None` when an index is out of range.
fn triangle(scene: &Scene, [m, t]: [u32; 2]) -> Option<[DVec3; 3]> {
    let mesh = scene.meshes.get(m as usize)?;
    let idx = mesh.indices.get(3 * t as usize..3 * t as usize + 3)?;
    let mut out = [DVec3::ZERO; 3];
    for (o, &i) in out.iter_mut().zip(idx) {
        *o = DVec3::from(mesh.vertices.get(i as usize)?.position.map(f64::from));
    }
    Some(out)
}

/// The scene's triangles grouped by the grid cell of their centroid (see the module docs), in
/// grid order. Triangles with out-of-range or non-finite vertices are left out.
pub(super) fn base_objects(scene: &Scene, size: f64) -> Vec<Object> {
    let mut groups: HashMap<[i64; 3], Vec<[u32; 2]>> = HashMap::new();
    for (m, mesh) in scene.meshes.iter().enumerate() {
        for t in 0..mesh.triangle_count() {
            let r = [m as u32, t as u32];
            let Some(v) = triangle(scene, r) else {
                continue;
            };
            let c = (v[0] + v[1] + v[2]) / 3.0;
            if !c.is_finite() {
                continue;
            }
            let key = (c / size).floor().to_array().map(|x| x as i64);
            groups.entry(key).or_default().push(r);
        }
    }
    let mut keys: Vec<[i64; 3]> = groups.keys().copied().collect();
    keys.sort_unstable();
    keys.into_iter()
        .filter_map(|k| groups.remove(&k))
        .filter_map(|tris| make_object(scene, tris))
        .collect()
}

/// An object of `tris` with its bounds and bounding sphere; `None` without triangles.
fn make_object(scene: &Scene, tris: Vec<[u32; 2]>) -> Option<Object> {
    let mut bounds = Aabb::EMPTY;
    for &r in &tris {
        for p in triangle(scene, r)? {
            bounds.grow(p);
        }
    }
    if tris.is_empty() || bounds.is_empty() {
        return None;
    }
    let centre = bounds.center();
    let mut radius: f64 = 0.0;
    for &r in &tris {
        for p in triangle(scene, r)? {
            radius = radius.max((p - centre).length());
        }
    }
    Some(Object {
        tris,
        bounds,
        centre,
        radius: radius.max(1e-6),
        gpu: None,
        impostor: None,
    })
}

/// Splits `tris` (octree on centroids) until every piece is at least `k` bounding radii from
/// every point of `cell`; pieces that cannot be split further go to `geometry`.
fn split(
    scene: &Scene,
    tris: Vec<[u32; 2]>,
    cell: &Aabb,
    k: f64,
    depth: u32,
    objects: &mut Vec<Object>,
    geometry: &mut Vec<[u32; 2]>,
) {
    let Some(obj) = make_object(scene, tris.clone()) else {
        return;
    };
    if box_distance(cell, obj.centre) >= k * obj.radius {
        objects.push(obj);
        return;
    }
    if tris.len() <= 1 || depth >= MAX_SPLIT_DEPTH {
        geometry.extend(tris);
        return;
    }
    let centroids: Vec<DVec3> = tris
        .iter()
        .map(|&r| triangle(scene, r).map_or(DVec3::ZERO, |v| (v[0] + v[1] + v[2]) / 3.0))
        .collect();
    let mut cb = Aabb::EMPTY;
    for &c in &centroids {
        cb.grow(c);
    }
    let mid = cb.center();
    let mut children: [Vec<[u32; 2]>; 8] = Default::default();
    for (&r, c) in tris.iter().zip(&centroids) {
        let i =
            (c.x > mid.x) as usize | ((c.y > mid.y) as usize) << 1 | ((c.z > mid.z) as usize) << 2;
        children[i].push(r);
    }
    if children.iter().filter(|c| !c.is_empty()).count() <= 1 {
        // every centroid in one place: no split separates them
        geometry.extend(tris);
        return;
    }
    for child in children {
        if !child.is_empty() {
            split(scene, child, cell, k, depth + 1, objects, geometry);
        }
    }
}

/// Distance from `p` to the box (0 inside).
fn box_distance(b: &Aabb, p: DVec3) -> f64 {
    (b.min - p).max(p - b.max).max(DVec3::ZERO).length()
}

fn boxes_overlap(a: &Aabb, b: &Aabb, eps: f64) -> bool {
    (a.min - eps).cmple(b.max).all() && (b.min - eps).cmple(a.max).all()
}

/// Copies triangles out of the scene ([`Scene::extract`]), one mesh per source mesh (re-indexed),
/// in scene order; entries naming no triangle of the scene are left out.
pub(super) fn extract_meshes(scene: &Scene, tris: &[[u32; 2]]) -> Vec<Mesh> {
    let mut refs: Vec<TriRef> = tris
        .iter()
        .map(|&p| TriRef::from(p))
        .filter(|r| {
            scene
                .meshes
                .get(r.mesh as usize)
                .is_some_and(|m| (r.tri as usize) < m.triangle_count())
        })
        .collect();
    refs.sort_unstable();
    // every entry names a triangle of the scene (checked above), so this cannot fail
    scene.extract(&refs).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use lemi_core::Vertex;

    /// One mesh of unit right triangles, one at each corner.
    fn scene(corners: &[[f32; 3]]) -> Scene {
        let mut mesh = Mesh::default();
        for (k, c) in corners.iter().enumerate() {
            for d in [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
                let p = [c[0] + d[0], c[1] + d[1], c[2] + d[2]];
                mesh.vertices
                    .push(Vertex::new(p, [0.0, 0.0, 1.0], [0.0; 2], [255; 4]));
            }
            mesh.indices
                .extend([3 * k as u32, 3 * k as u32 + 1, 3 * k as u32 + 2]);
        }
        Scene {
            meshes: vec![mesh],
            ..Default::default()
        }
    }

    #[test]
    fn box_distance_and_overlap() {
        let b = Aabb::new(DVec3::ZERO, DVec3::splat(2.0));
        assert_eq!(box_distance(&b, DVec3::ONE), 0.0);
        assert!((box_distance(&b, DVec3::new(5.0, 1.0, 1.0)) - 3.0).abs() < 1e-12);
        assert!((box_distance(&b, DVec3::new(5.0, 6.0, 1.0)) - 5.0).abs() < 1e-12);
        let touching = Aabb::new(DVec3::new(2.0, 0.0, 0.0), DVec3::splat(3.0));
        assert!(boxes_overlap(&b, &touching, 0.0));
        let apart = Aabb::new(DVec3::new(2.5, 0.0, 0.0), DVec3::splat(3.0));
        assert!(!boxes_overlap(&b, &apart, 0.1));
        assert!(boxes_overlap(&b, &apart, 0.6));
    }

    #[test]
    fn objects_group_triangles_by_grid_cell_with_a_bounding_sphere() {
        // two triangles in grid cell (0, 0, 0) of edge 10, one in (2, 0, 0)
        let s = scene(&[[1.0, 1.0, 1.0], [5.0, 1.0, 1.0], [21.0, 1.0, 1.0]]);
        let objects = base_objects(&s, 10.0);
        assert_eq!(objects.len(), 2);
        assert_eq!(objects[0].tris, vec![[0, 0], [0, 1]]);
        assert_eq!(objects[1].tris, vec![[0, 2]]);
        let o = &objects[0];
        // box x ∈ [1, 6], y ∈ [1, 2], z = 1: centre (3.5, 1.5, 1); the farthest vertices are
        // (1, 1, 1) and (6, 1, 1), 2.5 · √(1 + 0.04) away
        assert!((o.centre - DVec3::new(3.5, 1.5, 1.0)).length() < 1e-6);
        let r = (2.5f64 * 2.5 + 0.5 * 0.5).sqrt();
        assert!((o.radius - r).abs() < 1e-6, "{}", o.radius);
        // a triangle outside the scene's index range is left out
        assert!(make_object(&s, vec![[0, 7]]).is_none());
        assert!(make_object(&s, Vec::new()).is_none());
    }

    #[test]
    fn a_close_object_is_split_until_its_pieces_are_far_enough() {
        // a row of triangles from x = 2 to x = 62 near a cell at the origin
        let corners: Vec<[f32; 3]> = (0..16).map(|i| [2.0 + 4.0 * i as f32, 0.0, 0.0]).collect();
        let s = scene(&corners);
        let cell = Aabb::new(DVec3::splat(-1.0), DVec3::splat(1.0));
        let tris: Vec<[u32; 2]> = (0..16).map(|t| [0, t]).collect();
        let (mut objects, mut geometry) = (Vec::new(), Vec::new());
        split(&s, tris, &cell, 3.0, 0, &mut objects, &mut geometry);
        assert!(objects.len() > 1);
        for o in &objects {
            assert!(box_distance(&cell, o.centre) >= 3.0 * o.radius);
        }
        // every triangle is in exactly one piece or drawn as geometry
        let mut all: Vec<[u32; 2]> = objects.iter().flat_map(|o| o.tris.clone()).collect();
        all.extend(&geometry);
        all.sort_unstable();
        assert_eq!(all, (0..16).map(|t| [0, t]).collect::<Vec<_>>());
        // the nearest triangle (x from 2 to 3, radius √0.5, 1.5 from the cell) cannot be 3 radii
        // away on its own
        assert!(geometry.contains(&[0, 0]));
    }

    #[test]
    fn cell_objects_keep_far_objects_and_split_near_ones() {
        let s = scene(&[[1.0, 1.0, 1.0], [5.0, 1.0, 1.0], [101.0, 1.0, 1.0]]);
        let mut base = base_objects(&s, 10.0);
        let cell = Aabb::new(DVec3::splat(-1.0), DVec3::splat(1.0));
        // triangle 0 is near: object 0 is split into its far part, object 1 is far
        let c = cell_objects(&s, &mut base, &[[0, 0]], DVec3::ZERO, 3.0, &cell, 2.0);
        assert_eq!(c.active[0], ObjId::Base(1));
        let mut far: Vec<[u32; 2]> = c.local.iter().flat_map(|o| o.tris.clone()).collect();
        far.extend(&c.too_close);
        assert_eq!(far, vec![[0, 1]]);
        assert_eq!(c.active.len(), 1 + c.local.len());
    }

    #[test]
    fn extracted_meshes_are_reindexed() {
        let s = scene(&[[0.0; 3], [5.0, 0.0, 0.0], [9.0, 0.0, 0.0]]);
        let m = extract_meshes(&s, &[[0, 2], [0, 0], [0, 9], [3, 0]]);
        assert_eq!(m.len(), 1);
        assert_eq!(m[0].indices, vec![0, 1, 2, 3, 4, 5]);
        assert_eq!(m[0].vertices[0].position, [0.0; 3]);
        assert_eq!(m[0].vertices[3].position, [9.0, 0.0, 0.0]);
    }
}
