//! The in-memory scene every stage works on: triangle meshes grouped by material, materials with a
//! base colour factor and an optional base colour texture, bounds and import statistics.
//!
//! Conventions: metres, right-handed, +Y up. Importers convert other up axes with
//! [`UpAxis::to_y_up`] before adding geometry, so every later stage can rely on +Y up.
//!
//! Validation happens once, in [`SceneBuilder::add_mesh`]: triangles with a non-finite vertex and
//! degenerate triangles (exactly zero area: repeated or collinear vertices, *not* merely small ones)
//! are dropped and counted, never fatal.
//!
//! [`Scene::extract`] copies a list of triangles ([`TriRef`]s, such as a cell's near list) out of
//! the scene as meshes of their own.

use bytemuck::{Pod, Zeroable};
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

use crate::classify::TriRef;

/// One vertex as the GPU consumes it (36 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    /// Unit normal. Importers without normals get flat normals from [`SceneBuilder`].
    pub normal: [f32; 3],
    pub uv: [f32; 2],
    /// Per-vertex colour, linear RGBA in 0..=255 (white when the source has none).
    pub color: [u8; 4],
}

impl Vertex {
    pub fn new(position: [f32; 3], normal: [f32; 3], uv: [f32; 2], color: [u8; 4]) -> Self {
        Self {
            position,
            normal,
            uv,
            color,
        }
    }
}

/// An indexed triangle list drawn with one material.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Index into [`Scene::materials`].
    pub material: u32,
    pub vertices: Vec<Vertex>,
    /// Three indices per triangle into `vertices`.
    pub indices: Vec<u32>,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Positions of triangle `t`.
    pub fn triangle(&self, t: usize) -> [Vec3; 3] {
        let i = &self.indices[3 * t..3 * t + 3];
        [
            Vec3::from(self.vertices[i[0] as usize].position),
            Vec3::from(self.vertices[i[1] as usize].position),
            Vec3::from(self.vertices[i[2] as usize].position),
        ]
    }
}

/// A material: base colour factor (linear RGBA) times an optional base colour texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Linear RGBA factor (glTF `baseColorFactor`, OBJ `Kd`).
    pub base_color: [f32; 4],
    /// Index into [`Scene::textures`].
    pub texture: Option<u32>,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".into(),
            base_color: [0.8, 0.8, 0.8, 1.0],
            texture: None,
        }
    }
}

/// A decoded base colour texture: tightly packed RGBA8, sRGB-encoded, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub rgba8: Vec<u8>,
}

/// An axis-aligned bounding box. `Aabb::EMPTY` has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    pub min: DVec3,
    pub max: DVec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    pub fn new(min: DVec3, max: DVec3) -> Self {
        Self { min, max }
    }

    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    pub fn grow(&mut self, p: DVec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    pub fn center(&self) -> DVec3 {
        0.5 * (self.min + self.max)
    }

    pub fn size(&self) -> DVec3 {
        self.max - self.min
    }

    pub fn contains(&self, p: DVec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }
}

/// What import did: counts a user wants to see in `lemi info`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneStats {
    /// Triangles kept in the scene.
    pub triangles: u64,
    pub vertices: u64,
    /// Triangles dropped because a vertex had a NaN or infinite coordinate.
    pub dropped_nonfinite: u64,
    /// Triangles dropped because they have exactly zero area.
    pub dropped_degenerate: u64,
    /// Triangles dropped because an index pointed past the vertex array.
    pub dropped_bad_index: u64,
    /// Source files that contributed geometry.
    pub files: u32,
}

/// A whole scene, ready for rendering and baking.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub bounds: Aabb,
    pub stats: SceneStats,
    /// Where the scene came from (paths or `builtin:` specs), for fingerprints and reports.
    pub sources: Vec<String>,
}

impl Default for Aabb {
    fn default() -> Self {
        Aabb::EMPTY
    }
}

impl Scene {
    pub fn triangle_count(&self) -> u64 {
        self.meshes.iter().map(|m| m.triangle_count() as u64).sum()
    }

    /// Copies the triangles `tris` out of the scene: one mesh per referenced source mesh, in
    /// ascending source-mesh order, each with its source's material, only the vertices its
    /// triangles use (re-indexed in order of first use) and its triangles in list order. A
    /// reference past the meshes or past its mesh's triangles is an [`ExtractError`] naming the
    /// first such entry (every entry is checked before anything is copied); a triangle whose vertex
    /// indices are out of range is skipped (a [`SceneBuilder`] scene has none), and a mesh left
    /// without triangles is left out. Duplicate references copy a triangle twice.
    pub fn extract(&self, tris: &[TriRef]) -> Result<Vec<Mesh>, ExtractError> {
        for (entry, &TriRef { mesh: m, tri: t }) in tris.iter().enumerate() {
            let Some(mesh) = self.meshes.get(m as usize) else {
                return Err(ExtractError::NoMesh {
                    entry,
                    mesh: m,
                    tri: t,
                    meshes: self.meshes.len(),
                });
            };
            if t as usize >= mesh.triangle_count() {
                return Err(ExtractError::NoTriangle {
                    entry,
                    mesh: m,
                    tri: t,
                    triangles: mesh.triangle_count(),
                });
            }
        }
        let mut order: Vec<TriRef> = tris.to_vec();
        order.sort_by_key(|r| r.mesh); // stable: list order within a mesh
        let mut out = Vec::new();
        let mut remap: Vec<u32> = Vec::new();
        for group in order.chunk_by(|a, b| a.mesh == b.mesh) {
            let Some(src) = group.first().and_then(|r| self.meshes.get(r.mesh as usize)) else {
                continue;
            };
            remap.clear();
            remap.resize(src.vertices.len(), u32::MAX);
            let mut mesh = Mesh {
                material: src.material,
                vertices: Vec::new(),
                indices: Vec::with_capacity(group.len() * 3),
            };
            for r in group {
                let t = r.tri as usize;
                let Some(tri) = src.indices.get(3 * t..3 * t + 3) else {
                    continue;
                };
                if tri.iter().any(|&i| i as usize >= src.vertices.len()) {
                    continue;
                }
                for &i in tri {
                    let i = i as usize;
                    if remap[i] == u32::MAX {
                        remap[i] = mesh.vertices.len() as u32;
                        mesh.vertices.push(src.vertices[i]);
                    }
                    mesh.indices.push(remap[i]);
                }
            }
            if !mesh.indices.is_empty() {
                out.push(mesh);
            }
        }
        Ok(out)
    }
}

/// A triangle reference [`Scene::extract`] cannot resolve. `entry` is its position in the list;
/// the messages call the list a near list, as a cell file stores one
/// ([`crate::bundle::CellFile::near`]).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ExtractError {
    /// `mesh` is not below `meshes`, the scene's mesh count.
    #[error(
        "near list entry {entry} (mesh {mesh}, triangle {tri}) names a mesh past the scene's \
         {meshes} meshes"
    )]
    NoMesh {
        entry: usize,
        mesh: u32,
        tri: u32,
        meshes: usize,
    },
    /// `tri` is not below `triangles`, the triangle count of mesh `mesh`.
    #[error(
        "near list entry {entry} (mesh {mesh}, triangle {tri}) names a triangle past mesh \
         {mesh}'s {triangles} triangles"
    )]
    NoTriangle {
        entry: usize,
        mesh: u32,
        tri: u32,
        triangles: usize,
    },
}

/// `[mesh, tri]`, the form a cell file stores its near list in.
impl From<[u32; 2]> for TriRef {
    fn from([mesh, tri]: [u32; 2]) -> TriRef {
        TriRef { mesh, tri }
    }
}

impl From<TriRef> for [u32; 2] {
    fn from(r: TriRef) -> [u32; 2] {
        [r.mesh, r.tri]
    }
}

/// The up axis of source data. lemi works in +Y up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum UpAxis {
    #[default]
    Y,
    Z,
}

impl UpAxis {
    /// Maps a point or direction of this up axis to +Y up. For Z-up, `(x, y, z) -> (x, z, -y)`:
    /// a rotation of -90° about X, as glTF exporters do.
    #[inline]
    pub fn to_y_up(self, v: [f32; 3]) -> [f32; 3] {
        match self {
            UpAxis::Y => v,
            UpAxis::Z => [v[0], v[2], -v[1]],
        }
    }
}

/// Collects meshes, validating every triangle, and finishes into a [`Scene`].
#[derive(Debug, Default)]
pub struct SceneBuilder {
    scene: Scene,
}

impl SceneBuilder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a material and returns its index.
    pub fn add_material(&mut self, material: Material) -> u32 {
        self.scene.materials.push(material);
        (self.scene.materials.len() - 1) as u32
    }

    /// Adds a texture and returns its index.
    pub fn add_texture(&mut self, texture: Texture) -> u32 {
        self.scene.textures.push(texture);
        (self.scene.textures.len() - 1) as u32
    }

    pub fn add_source(&mut self, source: impl Into<String>) {
        self.scene.sources.push(source.into());
        self.scene.stats.files += 1;
    }

    pub fn materials(&self) -> &[Material] {
        &self.scene.materials
    }

    /// Adds an indexed triangle list. Triangles with an out-of-range index, a non-finite vertex or
    /// exactly zero area are dropped and counted. Zero-length or non-finite normals are replaced by the
    /// triangle's flat normal. Returns the number of triangles kept.
    ///
    /// If `mesh.material` does not name an existing material, a default material is added for it.
    pub fn add_mesh(&mut self, mut mesh: Mesh) -> u64 {
        if mesh.material as usize >= self.scene.materials.len() {
            mesh.material = self.add_material(Material::default());
        }
        let stats = &mut self.scene.stats;
        let n = mesh.vertices.len();
        let mut kept: Vec<u32> = Vec::with_capacity(mesh.indices.len());
        let mut bad_normal = vec![false; n];
        let mut flat_normal = vec![[0f32; 3]; n];
        for tri in mesh.indices.chunks_exact(3) {
            if tri.iter().any(|&i| i as usize >= n) {
                stats.dropped_bad_index += 1;
                continue;
            }
            let p = [
                mesh.vertices[tri[0] as usize].position,
                mesh.vertices[tri[1] as usize].position,
                mesh.vertices[tri[2] as usize].position,
            ];
            if p.iter().flatten().any(|c| !c.is_finite()) {
                stats.dropped_nonfinite += 1;
                continue;
            }
            let a = DVec3::from(p[0].map(f64::from));
            let b = DVec3::from(p[1].map(f64::from));
            let c = DVec3::from(p[2].map(f64::from));
            let cross = (b - a).cross(c - a);
            if cross == DVec3::ZERO {
                stats.dropped_degenerate += 1;
                continue;
            }
            let fnormal = cross.normalize().as_vec3().to_array();
            for &i in tri {
                let v = &mesh.vertices[i as usize];
                let nl = Vec3::from(v.normal);
                if (!nl.is_finite() || nl.length_squared() < 1e-12) && !bad_normal[i as usize] {
                    bad_normal[i as usize] = true;
                    flat_normal[i as usize] = fnormal;
                }
            }
            kept.extend_from_slice(tri);
        }
        for (i, v) in mesh.vertices.iter_mut().enumerate() {
            if bad_normal[i] {
                v.normal = flat_normal[i];
            } else {
                let nl = Vec3::from(v.normal).normalize();
                v.normal = nl.to_array();
            }
            if !v.uv[0].is_finite() || !v.uv[1].is_finite() {
                v.uv = [0.0, 0.0];
            }
        }
        mesh.indices = kept;
        let tris = mesh.triangle_count() as u64;
        if tris == 0 {
            return 0;
        }
        for &i in &mesh.indices {
            let p = mesh.vertices[i as usize].position;
            self.scene
                .bounds
                .grow(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
        }
        stats.triangles += tris;
        stats.vertices += mesh.vertices.len() as u64;
        self.scene.meshes.push(mesh);
        tris
    }

    /// Merges another finished scene into this one (materials and textures are re-indexed).
    pub fn append_scene(&mut self, other: Scene) {
        let mat_base = self.scene.materials.len() as u32;
        let tex_base = self.scene.textures.len() as u32;
        self.scene.textures.extend(other.textures);
        for mut m in other.materials {
            m.texture = m.texture.map(|t| t + tex_base);
            self.scene.materials.push(m);
        }
        for mut mesh in other.meshes {
            mesh.material += mat_base;
            self.scene.meshes.push(mesh);
        }
        let s = &mut self.scene.stats;
        s.triangles += other.stats.triangles;
        s.vertices += other.stats.vertices;
        s.dropped_nonfinite += other.stats.dropped_nonfinite;
        s.dropped_degenerate += other.stats.dropped_degenerate;
        s.dropped_bad_index += other.stats.dropped_bad_index;
        s.files += other.stats.files;
        self.scene.bounds = self.scene.bounds.union(&other.bounds);
        self.scene.sources.extend(other.sources);
    }

    /// Triangles kept so far.
    pub fn triangle_count(&self) -> u64 {
        self.scene.stats.triangles
    }

    /// Meshes so far.
    pub fn mesh_count(&self) -> usize {
        self.scene.meshes.len()
    }

    /// Finishes the scene. Callers decide whether an empty scene is an error
    /// (`lemi-scene` reports it as one, naming the inputs).
    pub fn finish(self) -> Scene {
        self.scene
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(p: [f32; 3]) -> Vertex {
        Vertex::new(p, [0.0; 3], [0.0; 2], [255; 4])
    }

    #[test]
    fn drops_and_counts_bad_triangles() {
        let mut b = SceneBuilder::new();
        let mesh = Mesh {
            material: 0,
            vertices: vec![
                v([0.0, 0.0, 0.0]),
                v([1.0, 0.0, 0.0]),
                v([0.0, 1.0, 0.0]),
                v([f32::NAN, 0.0, 0.0]),
                v([2.0, 0.0, 0.0]),
                // a tiny but real triangle must be kept
                v([1e-7, 1e-7, 0.0]),
            ],
            indices: vec![0, 1, 2, 0, 1, 3, 0, 1, 4, 0, 1, 1, 0, 1, 9, 0, 5, 1],
        };
        assert_eq!(b.add_mesh(mesh), 2);
        let s = b.finish();
        assert_eq!(s.stats.triangles, 2);
        assert_eq!(s.stats.dropped_nonfinite, 1);
        assert_eq!(s.stats.dropped_degenerate, 2);
        assert_eq!(s.stats.dropped_bad_index, 1);
        assert_eq!(s.materials.len(), 1);
        // flat normal assigned where the source had none
        assert_eq!(s.meshes[0].vertices[0].normal, [0.0, 0.0, 1.0]);
        assert_eq!(s.bounds.min, DVec3::ZERO);
        assert_eq!(s.bounds.max, DVec3::new(1.0, 1.0, 0.0));
    }

    /// Three meshes (materials 7, 8, 9) of `n` triangles each, every vertex at a distinct
    /// position, vertices shared between neighbouring triangles.
    fn strip_scene(n: u32) -> Scene {
        let meshes = (0..3u32)
            .map(|m| Mesh {
                material: 7 + m,
                vertices: (0..n + 2)
                    .map(|k| v([k as f32, m as f32, (k % 2) as f32]))
                    .collect(),
                indices: (0..n).flat_map(|t| [t, t + 1, t + 2]).collect(),
            })
            .collect();
        Scene {
            meshes,
            ..Scene::default()
        }
    }

    fn positions(mesh: &Mesh) -> Vec<[[f32; 3]; 3]> {
        mesh.indices
            .chunks_exact(3)
            .map(|t| [0, 1, 2].map(|k| mesh.vertices[t[k] as usize].position))
            .collect()
    }

    #[test]
    fn extract_copies_the_listed_triangles_per_mesh() {
        let scene = strip_scene(4);
        let r = |mesh, tri| TriRef { mesh, tri };
        let out = scene
            .extract(&[r(2, 3), r(0, 1), r(2, 0), r(0, 2), r(0, 1)])
            .expect("valid list");
        assert_eq!(out.len(), 2);
        // ascending source-mesh order, the source's material
        assert_eq!((out[0].material, out[1].material), (7, 9));
        // list order within a mesh, vertices re-indexed in order of first use, shared ones once
        assert_eq!(out[0].indices, [0, 1, 2, 1, 2, 3, 0, 1, 2]);
        assert_eq!(out[0].vertices.len(), 4);
        assert_eq!(out[1].indices, [0, 1, 2, 3, 4, 5]);
        let src = &scene.meshes;
        let src2 = positions(&src[2]);
        assert_eq!(positions(&out[1]), [src2[3], src2[0]]);
        assert_eq!(out[0].vertices[0], src[0].vertices[1]);
        assert!(scene.extract(&[]).expect("empty list").is_empty());
    }

    #[test]
    fn extract_skips_triangles_with_bad_vertex_indices() {
        let mut scene = strip_scene(2);
        scene.meshes[1].indices[3..6].copy_from_slice(&[0, 1, 99]);
        let r = |mesh, tri| TriRef { mesh, tri };
        let out = scene.extract(&[r(1, 1), r(1, 0)]).expect("in range");
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].indices, [0, 1, 2]);
        // a mesh whose listed triangles are all skipped is left out
        assert!(scene.extract(&[r(1, 1)]).expect("in range").is_empty());
    }

    #[test]
    fn extract_names_the_first_bad_entry() {
        let scene = strip_scene(4);
        let r = |mesh, tri| TriRef { mesh, tri };
        assert_eq!(
            scene.extract(&[r(0, 0), r(3, 1), r(0, 9)]).err(),
            Some(ExtractError::NoMesh {
                entry: 1,
                mesh: 3,
                tri: 1,
                meshes: 3
            })
        );
        let e = scene.extract(&[r(1, 4)]).expect_err("past the triangles");
        assert_eq!(
            e,
            ExtractError::NoTriangle {
                entry: 0,
                mesh: 1,
                tri: 4,
                triangles: 4
            }
        );
        assert_eq!(
            e.to_string(),
            "near list entry 0 (mesh 1, triangle 4) names a triangle past mesh 1's 4 triangles"
        );
        let e = scene
            .extract(&[r(u32::MAX, u32::MAX)])
            .expect_err("past the meshes");
        assert_eq!(
            e.to_string(),
            "near list entry 0 (mesh 4294967295, triangle 4294967295) names a mesh past the \
             scene's 3 meshes"
        );
        assert!(Scene::default().extract(&[r(0, 0)]).is_err());
    }

    #[test]
    fn tri_refs_convert_to_and_from_pairs() {
        let r = TriRef { mesh: 5, tri: 9 };
        assert_eq!(<[u32; 2]>::from(r), [5, 9]);
        assert_eq!(TriRef::from([5, 9]), r);
    }

    proptest::proptest! {
        /// The extracted triangles are exactly the listed ones, grouped by ascending source mesh
        /// and in list order within one, with identical vertex positions; no vertex is unused.
        #[test]
        fn extract_yields_exactly_the_listed_triangles(
            n in 1u32..12,
            list in proptest::collection::vec((0u32..3, 0u32..64), 0..40),
        ) {
            let scene = strip_scene(n);
            let refs: Vec<TriRef> =
                list.iter().map(|&(mesh, t)| TriRef { mesh, tri: t % n }).collect();
            let out = scene.extract(&refs).expect("valid list");
            let mut want: Vec<(u32, [[f32; 3]; 3])> = refs
                .iter()
                .map(|r| {
                    let src = &scene.meshes[r.mesh as usize];
                    let t = 3 * r.tri as usize;
                    let tri = [0, 1, 2].map(|k| src.vertices[src.indices[t + k] as usize].position);
                    (src.material, tri)
                })
                .collect();
            want.sort_by_key(|w| w.0);
            let got: Vec<(u32, [[f32; 3]; 3])> = out
                .iter()
                .flat_map(|m| positions(m).into_iter().map(move |t| (m.material, t)))
                .collect();
            proptest::prop_assert_eq!(got, want);
            for m in &out {
                let mut used = vec![false; m.vertices.len()];
                for &i in &m.indices {
                    used[i as usize] = true;
                }
                proptest::prop_assert!(used.iter().all(|&u| u));
            }
        }
    }

    #[test]
    fn z_up_maps_to_y_up() {
        assert_eq!(UpAxis::Z.to_y_up([0.0, 0.0, 1.0]), [0.0, 1.0, 0.0]);
        assert_eq!(UpAxis::Z.to_y_up([0.0, 1.0, 0.0]), [0.0, 0.0, -1.0]);
        assert_eq!(UpAxis::Y.to_y_up([1.0, 2.0, 3.0]), [1.0, 2.0, 3.0]);
    }
}
