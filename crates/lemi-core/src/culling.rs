//! The layout of a scene for frustum-culled drawing (the `geometry-culled` baseline: the whole scene
//! drawn as an ordinary renderer would at least draw it), GPU-free.
//!
//! Per material, the triangles are sorted along the Morton curve of their centroids (as the leaf
//! level of a linear BVH: Lauterbach et al., "Fast BVH Construction on GPUs", Eurographics 2009; the
//! same order the classification's clusters use, [`crate::classify::morton_code`]) and cut into
//! **clusters** of [`CullLayoutOptions::cluster_triangles`] consecutive triangles, clusters into
//! **groups** of [`CullLayoutOptions::group_clusters`], groups into **chunks**: vertex/index buffer
//! pairs within the buffer limits, one material each. Every chunk, group and cluster has the
//! bounding box of its vertices (the f32 positions, exactly as drawn).
//!
//! Per frame, [`CullHierarchy::cull`] walks the three levels with [`crate::frustum::classify_box`]:
//! a box outside the view is skipped with everything in it, a box inside is drawn whole, and only
//! the children of a box that intersects the view's border are tested. Consecutive kept index
//! ranges of a chunk merge into one draw. The culling test is conservative (see
//! [`crate::frustum`]), so the image is the one all the triangles would give; the order of the
//! kept triangles is the layout's order, materials in ascending order as in the unculled chunks.

use std::ops::Range;

use glam::{DMat4, DVec3};

use crate::classify::morton_code;
use crate::frustum::BoxClip;
use crate::{Aabb, Mesh, Vertex};

/// How [`CullLayout::build`] cuts the triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CullLayoutOptions {
    /// Triangles per cluster (the finest culling unit; at least 1).
    pub cluster_triangles: usize,
    /// Clusters per group (the middle level; at least 1).
    pub group_clusters: usize,
    /// Most vertices in one chunk (at least 3).
    pub max_vertices: usize,
    /// Most indices in one chunk (at least 3).
    pub max_indices: usize,
}

impl Default for CullLayoutOptions {
    fn default() -> Self {
        CullLayoutOptions {
            cluster_triangles: 128,
            group_clusters: 32,
            max_vertices: 1 << 22,
            max_indices: 3 << 22,
        }
    }
}

/// One chunk's vertices and indices, to upload.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChunkData {
    pub material: u32,
    pub vertices: Vec<Vertex>,
    pub indices: Vec<u32>,
}

/// A chunk's place in the hierarchy.
#[derive(Clone, Debug, PartialEq)]
pub struct ChunkNode {
    pub material: u32,
    pub bounds: Aabb,
    /// Range into [`CullHierarchy::groups`].
    pub groups: Range<usize>,
    pub index_count: u32,
}

/// Consecutive clusters of one chunk.
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterGroup {
    pub bounds: Aabb,
    /// Range into [`CullHierarchy::clusters`].
    pub clusters: Range<usize>,
}

/// Consecutive triangles of one chunk, close on the Morton curve.
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterBox {
    pub bounds: Aabb,
    /// Range into its chunk's indices (a multiple of 3 long).
    pub indices: Range<u32>,
}

/// The boxes of the three levels, kept after the chunks are uploaded.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CullHierarchy {
    pub chunks: Vec<ChunkNode>,
    pub groups: Vec<ClusterGroup>,
    pub clusters: Vec<ClusterBox>,
}

/// A layout: the hierarchy and the chunks' data (same order).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CullLayout {
    pub hierarchy: CullHierarchy,
    pub chunks: Vec<ChunkData>,
}

/// One draw of the culled frame: an index range of a chunk.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CullDraw {
    pub chunk: usize,
    pub indices: Range<u32>,
}

/// What [`CullHierarchy::cull`] kept.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CullList {
    /// In chunk order, each chunk's ranges ascending and not adjacent.
    pub draws: Vec<CullDraw>,
    /// Triangles in the draws.
    pub triangles: u64,
    /// Boxes tested (chunks, groups and clusters), the CPU cost of the frame's culling.
    pub boxes_tested: u64,
}

fn bounds_of(vertices: &[Vertex], indices: &[u32]) -> Aabb {
    let mut b = Aabb::EMPTY;
    for &i in indices {
        if let Some(v) = vertices.get(i as usize) {
            b.grow(DVec3::from(v.position.map(f64::from)));
        }
    }
    b
}

/// Builds the layout incrementally (see [`CullLayout::build`]).
struct Builder {
    options: CullLayoutOptions,
    layout: CullLayout,
    current: ChunkData,
    /// Start (in `layout.hierarchy.groups`) of the current chunk's groups.
    chunk_groups: usize,
    /// Start (in `clusters`) of the current group's clusters.
    group_clusters: usize,
    /// Start (in `current.indices`) of the current cluster.
    cluster_start: usize,
    /// Per global vertex: its index in the current chunk, valid when `stamp` equals `generation`.
    remap: Vec<u32>,
    stamp: Vec<u64>,
    generation: u64,
}

impl Builder {
    fn close_cluster(&mut self) {
        let end = self.current.indices.len();
        if end == self.cluster_start {
            return;
        }
        let bounds = bounds_of(
            &self.current.vertices,
            &self.current.indices[self.cluster_start..],
        );
        self.layout.hierarchy.clusters.push(ClusterBox {
            bounds,
            indices: self.cluster_start as u32..end as u32,
        });
        self.cluster_start = end;
        if self.layout.hierarchy.clusters.len() - self.group_clusters >= self.options.group_clusters
        {
            self.close_group();
        }
    }

    fn close_group(&mut self) {
        let h = &mut self.layout.hierarchy;
        let end = h.clusters.len();
        if end == self.group_clusters {
            return;
        }
        let bounds = h.clusters[self.group_clusters..]
            .iter()
            .fold(Aabb::EMPTY, |b, c| b.union(&c.bounds));
        h.groups.push(ClusterGroup {
            bounds,
            clusters: self.group_clusters..end,
        });
        self.group_clusters = end;
    }

    fn close_chunk(&mut self) {
        self.close_cluster();
        self.close_group();
        if self.current.indices.is_empty() {
            self.current.vertices.clear();
            return;
        }
        let h = &mut self.layout.hierarchy;
        let end = h.groups.len();
        let bounds = h.groups[self.chunk_groups..]
            .iter()
            .fold(Aabb::EMPTY, |b, g| b.union(&g.bounds));
        let material = self.current.material;
        h.chunks.push(ChunkNode {
            material,
            bounds,
            groups: self.chunk_groups..end,
            index_count: self.current.indices.len() as u32,
        });
        self.chunk_groups = end;
        let data = std::mem::replace(
            &mut self.current,
            ChunkData {
                material,
                ..Default::default()
            },
        );
        self.layout.chunks.push(data);
        self.cluster_start = 0;
        self.generation += 1;
    }

    /// Appends one triangle (global vertex ids `g`, vertices `v`) of material `material`.
    fn push(&mut self, material: u32, g: [usize; 3], v: [&Vertex; 3]) {
        if material != self.current.material {
            self.close_chunk();
            self.current.material = material;
        }
        let new = (0..3)
            .filter(|&k| self.stamp[g[k]] != self.generation && !g[..k].contains(&g[k]))
            .count();
        if self.current.vertices.len() + new > self.options.max_vertices
            || self.current.indices.len() + 3 > self.options.max_indices
        {
            self.close_chunk();
        }
        for k in 0..3 {
            if self.stamp[g[k]] != self.generation {
                self.stamp[g[k]] = self.generation;
                self.remap[g[k]] = self.current.vertices.len() as u32;
                self.current.vertices.push(*v[k]);
            }
            self.current.indices.push(self.remap[g[k]]);
        }
        if self.current.indices.len() - self.cluster_start >= 3 * self.options.cluster_triangles {
            self.close_cluster();
        }
    }
}

impl CullLayout {
    /// Lays out the triangles of `meshes` (see the module docs). Triangles with an index past their
    /// mesh's vertex array are skipped. Deterministic: ties on the Morton curve keep input order.
    pub fn build(meshes: &[Mesh], options: &CullLayoutOptions) -> CullLayout {
        let options = CullLayoutOptions {
            cluster_triangles: options.cluster_triangles.max(1),
            group_clusters: options.group_clusters.max(1),
            max_vertices: options.max_vertices.max(3),
            max_indices: options.max_indices.max(3),
        };
        // Centroids of the valid triangles, and the box their codes are quantized in.
        let mut tris: Vec<(u32, u32, DVec3)> = Vec::new(); // (mesh, triangle, centroid)
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for (mi, mesh) in meshes.iter().enumerate() {
            let n = mesh.vertices.len();
            for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
                if tri.iter().any(|&i| i as usize >= n) {
                    continue;
                }
                let c = tri.iter().fold(DVec3::ZERO, |a, &i| {
                    a + DVec3::from(mesh.vertices[i as usize].position.map(f64::from))
                }) / 3.0;
                lo = lo.min(c);
                hi = hi.max(c);
                tris.push((mi as u32, t as u32, c));
            }
        }
        let scale = (hi - lo).max(DVec3::splat(1e-9));
        let mut keyed: Vec<(u32, u64, u32, u32)> = tris
            .iter()
            .map(|&(m, t, c)| {
                (
                    meshes[m as usize].material,
                    morton_code((c - lo) / scale),
                    m,
                    t,
                )
            })
            .collect();
        keyed.sort_unstable();
        let mut base = Vec::with_capacity(meshes.len());
        let mut total = 0usize;
        for m in meshes {
            base.push(total);
            total += m.vertices.len();
        }
        let mut b = Builder {
            options,
            layout: CullLayout::default(),
            current: ChunkData {
                material: keyed.first().map_or(0, |k| k.0),
                ..Default::default()
            },
            chunk_groups: 0,
            group_clusters: 0,
            cluster_start: 0,
            remap: vec![0; total],
            stamp: vec![0; total],
            generation: 1,
        };
        for &(material, _, m, t) in &keyed {
            let mesh = &meshes[m as usize];
            let tri = &mesh.indices[3 * t as usize..3 * t as usize + 3];
            let g = [0, 1, 2].map(|k| base[m as usize] + tri[k] as usize);
            let v = [0, 1, 2].map(|k| &mesh.vertices[tri[k] as usize]);
            b.push(material, g, v);
        }
        b.close_chunk();
        b.layout
    }

    pub fn triangle_count(&self) -> u64 {
        self.chunks.iter().map(|c| c.indices.len() as u64 / 3).sum()
    }
}

impl CullHierarchy {
    /// The draws of the boxes not outside the clip volume of `view_proj` (see the module docs).
    pub fn cull(&self, view_proj: &DMat4) -> CullList {
        let mut list = CullList::default();
        let keep = |list: &mut CullList, chunk: usize, r: Range<u32>| {
            list.triangles += u64::from(r.end - r.start) / 3;
            match list.draws.last_mut() {
                Some(d) if d.chunk == chunk && d.indices.end == r.start => d.indices.end = r.end,
                _ => list.draws.push(CullDraw { chunk, indices: r }),
            }
        };
        for (ci, chunk) in self.chunks.iter().enumerate() {
            list.boxes_tested += 1;
            match chunk.bounds.clip(view_proj) {
                BoxClip::Outside => continue,
                BoxClip::Inside => {
                    keep(&mut list, ci, 0..chunk.index_count);
                    continue;
                }
                BoxClip::Intersects => {}
            }
            for group in &self.groups[chunk.groups.clone()] {
                list.boxes_tested += 1;
                let clusters = &self.clusters[group.clusters.clone()];
                match group.bounds.clip(view_proj) {
                    BoxClip::Outside => continue,
                    BoxClip::Inside => {
                        if let (Some(first), Some(last)) = (clusters.first(), clusters.last()) {
                            keep(&mut list, ci, first.indices.start..last.indices.end);
                        }
                        continue;
                    }
                    BoxClip::Intersects => {}
                }
                for cluster in clusters {
                    list.boxes_tested += 1;
                    if cluster.bounds.clip(view_proj) != BoxClip::Outside {
                        keep(&mut list, ci, cluster.indices.clone());
                    }
                }
            }
        }
        list
    }

    /// Triangles in all chunks.
    pub fn triangle_count(&self) -> u64 {
        self.chunks
            .iter()
            .map(|c| u64::from(c.index_count) / 3)
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    /// An `n × n` grid of unit quads on the ground (y = 0), two materials in a checkerboard, one
    /// mesh per row (so vertices are shared within a row).
    fn ground(n: u32) -> Vec<Mesh> {
        let mut meshes = Vec::new();
        for z in 0..n {
            for material in 0..2 {
                let mut vertices = Vec::new();
                let mut indices = Vec::new();
                for x in (0..n).filter(|x| (x + z) % 2 == material) {
                    let b = vertices.len() as u32;
                    for (dx, dz) in [(0, 0), (1, 0), (1, 1), (0, 1)] {
                        vertices.push(Vertex::new(
                            [(x + dx) as f32, 0.0, (z + dz) as f32],
                            [0.0, 1.0, 0.0],
                            [0.0, 0.0],
                            [255; 4],
                        ));
                    }
                    indices.extend([b, b + 1, b + 2, b, b + 2, b + 3]);
                }
                meshes.push(Mesh {
                    vertices,
                    indices,
                    material,
                });
            }
        }
        meshes
    }

    fn options(cluster: usize, group: usize) -> CullLayoutOptions {
        CullLayoutOptions {
            cluster_triangles: cluster,
            group_clusters: group,
            ..Default::default()
        }
    }

    #[test]
    fn layout_keeps_every_triangle_once_with_tight_boxes() {
        let meshes = ground(16);
        let small = CullLayoutOptions {
            max_vertices: 100,
            max_indices: 90,
            ..options(4, 3)
        };
        for o in [options(8, 4), small, options(1, 1)] {
            let l = CullLayout::build(&meshes, &o);
            assert_eq!(l.triangle_count(), 512);
            assert_eq!(l.hierarchy.triangle_count(), 512);
            let mut seen: Vec<[[u32; 3]; 3]> = Vec::new();
            for (node, data) in l.hierarchy.chunks.iter().zip(&l.chunks) {
                assert_eq!(node.material, data.material);
                assert!(
                    data.vertices.len() <= o.max_vertices && data.indices.len() <= o.max_indices
                );
                assert_eq!(node.index_count as usize, data.indices.len());
                // the clusters of a chunk tile its indices in order
                let mut next = 0;
                for g in &l.hierarchy.groups[node.groups.clone()] {
                    assert!(g.clusters.len() <= o.group_clusters);
                    for c in &l.hierarchy.clusters[g.clusters.clone()] {
                        assert_eq!(c.indices.start, next);
                        next = c.indices.end;
                        assert!(c.indices.len() <= 3 * o.cluster_triangles);
                        let b = bounds_of(
                            &data.vertices,
                            &data.indices[c.indices.start as usize..c.indices.end as usize],
                        );
                        assert_eq!(b, c.bounds);
                        assert!(g.bounds.union(&c.bounds) == g.bounds);
                        assert!(node.bounds.union(&c.bounds) == node.bounds);
                    }
                }
                assert_eq!(next, node.index_count);
                for t in data.indices.chunks_exact(3) {
                    seen.push(
                        [0, 1, 2].map(|k| data.vertices[t[k] as usize].position.map(|c| c as u32)),
                    );
                }
            }
            // materials ascending, as the unculled chunks draw them
            assert!(l.chunks.windows(2).all(|w| w[0].material <= w[1].material));
            seen.sort();
            seen.dedup();
            assert_eq!(seen.len(), 512);
        }
        // no triangles, no chunks
        assert_eq!(
            CullLayout::build(&[], &options(8, 4)),
            CullLayout::default()
        );
    }

    #[test]
    fn cull_keeps_what_is_in_view_and_merges_ranges() {
        let l = CullLayout::build(&ground(32), &options(8, 4));
        let h = &l.hierarchy;
        let view = |eye: DVec3, target: DVec3| {
            Camera::look_at(eye, target, DVec3::Y, 60.0, 64, 48)
                .expect("camera")
                .view()
                .view_proj()
        };
        // from high above, everything: one draw per chunk
        let all = h.cull(&view(
            DVec3::new(16.0, 200.0, 16.001),
            DVec3::new(16.0, 0.0, 16.0),
        ));
        assert_eq!(all.triangles, 2048);
        assert_eq!(all.draws.len(), h.chunks.len());
        // looking down at one corner: a part, and every triangle of a kept draw in range
        let part = h.cull(&view(
            DVec3::new(2.0, 3.0, 2.001),
            DVec3::new(2.0, 0.0, 2.0),
        ));
        assert!(
            part.triangles > 0 && part.triangles < 2048 / 4,
            "{}",
            part.triangles
        );
        assert!(part.boxes_tested < (h.chunks.len() + h.groups.len() + h.clusters.len()) as u64);
        for w in part.draws.windows(2) {
            assert!(w[0].chunk < w[1].chunk || w[0].indices.end < w[1].indices.start);
        }
        // looking away into the sky: nothing
        let none = h.cull(&view(
            DVec3::new(16.0, 5.0, 16.0),
            DVec3::new(16.0, 100.0, 16.001),
        ));
        assert_eq!(none.triangles, 0);
        assert!(none.draws.is_empty());
    }

    #[test]
    fn bad_indices_are_skipped() {
        let mut meshes = ground(2);
        meshes[0].indices.extend([0, 1, 99]);
        let l = CullLayout::build(&meshes, &options(8, 4));
        assert_eq!(l.triangle_count(), 8);
    }
}
