//! Geometry writers shared by the built-in scenes: per-material vertex/index buffers, ground quads,
//! raised slabs, building walls with window-bay UVs, and flat, gabled, hipped and pyramid roofs.
//!
//! Every face is wound counter-clockwise seen from outside (glTF's front face) and carries a flat
//! normal; UVs are in metres divided by the texture's tile size, so textures keep a physical scale.

use glam::Vec3;
use lemi_core::{Mesh, Vertex};
use rayon::prelude::*;

/// Metres covered by one repetition of the facade texture (2 window bays × 2 floors).
pub const FACADE_TILE: f32 = 6.4;
/// Width of one window bay and height of one floor, in metres.
pub const BAY: f32 = 3.2;

/// Vertices and indices for one material.
#[derive(Default)]
pub struct Buf {
    pub vertices: Vec<Vertex>,
    pub indices: Vec<u32>,
}

impl Buf {
    #[inline]
    pub fn vert(&mut self, p: Vec3, n: Vec3, uv: [f32; 2], c: [u8; 4]) -> u32 {
        self.vertices
            .push(Vertex::new(p.to_array(), n.to_array(), uv, c));
        (self.vertices.len() - 1) as u32
    }

    #[inline]
    fn pos(&self, i: u32) -> Vec3 {
        Vec3::from(self.vertices[i as usize].position)
    }

    /// Adds triangle `(a, b, c)`, wound counter-clockwise as seen from the side `facing` points to.
    #[inline]
    pub fn tri(&mut self, a: u32, b: u32, c: u32, facing: Vec3) {
        let (pa, pb, pc) = (self.pos(a), self.pos(b), self.pos(c));
        if (pb - pa).cross(pc - pa).dot(facing) >= 0.0 {
            self.indices.extend_from_slice(&[a, b, c]);
        } else {
            self.indices.extend_from_slice(&[a, c, b]);
        }
    }

    /// A planar quad (corners in order around it) with a flat normal oriented towards `hint`.
    pub fn quad(&mut self, p: [Vec3; 4], uv: [[f32; 2]; 4], hint: Vec3, c: [u8; 4]) {
        let mut n = (p[2] - p[0]).cross(p[3] - p[1]).normalize_or_zero();
        if n.dot(hint) < 0.0 {
            n = -n;
        }
        let i: [u32; 4] = std::array::from_fn(|k| self.vert(p[k], n, uv[k], c));
        self.tri(i[0], i[1], i[2], n);
        self.tri(i[0], i[2], i[3], n);
    }

    /// A flat triangle with its normal oriented towards `hint`.
    pub fn flat_tri(&mut self, p: [Vec3; 3], uv: [[f32; 2]; 3], hint: Vec3, c: [u8; 4]) {
        let mut n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        if n.dot(hint) < 0.0 {
            n = -n;
        }
        let i: [u32; 3] = std::array::from_fn(|k| self.vert(p[k], n, uv[k], c));
        self.tri(i[0], i[1], i[2], n);
    }
}

/// One buffer per material of a scene.
pub struct Emitter {
    pub bufs: Vec<Buf>,
}

impl Emitter {
    pub fn new(materials: usize) -> Self {
        Emitter {
            bufs: (0..materials).map(|_| Buf::default()).collect(),
        }
    }

    /// One mesh per non-empty buffer, in material order.
    pub fn into_meshes(self) -> Vec<Mesh> {
        self.bufs
            .into_iter()
            .enumerate()
            .filter(|(_, b)| !b.indices.is_empty())
            .map(|(m, b)| Mesh {
                material: m as u32,
                vertices: b.vertices,
                indices: b.indices,
            })
            .collect()
    }
}

/// An axis-aligned rectangle of the ground plane (`x0 < x1`, `z0 < z1`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    pub x0: f32,
    pub z0: f32,
    pub x1: f32,
    pub z1: f32,
}

impl Rect {
    pub fn new(x0: f32, z0: f32, x1: f32, z1: f32) -> Self {
        Rect { x0, z0, x1, z1 }
    }
    pub fn w(&self) -> f32 {
        self.x1 - self.x0
    }
    pub fn d(&self) -> f32 {
        self.z1 - self.z0
    }
    pub fn cx(&self) -> f32 {
        0.5 * (self.x0 + self.x1)
    }
    pub fn cz(&self) -> f32 {
        0.5 * (self.z0 + self.z1)
    }
    pub fn inset(&self, m: f32) -> Rect {
        Rect::new(self.x0 + m, self.z0 + m, self.x1 - m, self.z1 - m)
    }
    pub fn is_valid(&self) -> bool {
        self.x1 > self.x0 && self.z1 > self.z0
    }
    /// Horizontal distance from the origin to the nearest point of the rectangle.
    pub fn dist_to_origin(&self) -> f32 {
        let dx = (self.x0.max(0.0)).max(-self.x1);
        let dz = (self.z0.max(0.0)).max(-self.z1);
        (dx * dx + dz * dz).sqrt()
    }
    /// Smallest |z| over the rectangle.
    pub fn min_abs_z(&self) -> f32 {
        if self.z0 <= 0.0 && self.z1 >= 0.0 {
            0.0
        } else {
            self.z0.abs().min(self.z1.abs())
        }
    }
}

/// A ground quad at height `y` facing up, UV = position / `tile` metres.
pub fn ground(buf: &mut Buf, r: Rect, y: f32, tile: f32, c: [u8; 4]) {
    let p = [
        Vec3::new(r.x0, y, r.z0),
        Vec3::new(r.x0, y, r.z1),
        Vec3::new(r.x1, y, r.z1),
        Vec3::new(r.x1, y, r.z0),
    ];
    let uv = p.map(|q| [q.x / tile, q.z / tile]);
    buf.quad(p, uv, Vec3::Y, c);
}

/// A raised slab (kerbed pavement, park lawn): top quad plus four sides, 10 triangles.
pub fn slab(buf: &mut Buf, r: Rect, h: f32, tile: f32, c: [u8; 4]) {
    ground(buf, r, h, tile, c);
    let side_c = super::rng::shade(c, 0.8);
    for (a, b, n) in sides(r) {
        let p = [
            Vec3::new(a.0, 0.0, a.1),
            Vec3::new(b.0, 0.0, b.1),
            Vec3::new(b.0, h, b.1),
            Vec3::new(a.0, h, a.1),
        ];
        let len = ((b.0 - a.0).abs() + (b.1 - a.1).abs()) / tile;
        buf.quad(
            p,
            [[0.0, 0.0], [len, 0.0], [len, -h / tile], [0.0, -h / tile]],
            n,
            side_c,
        );
    }
}

/// A side of a rectangle: `(start, end, outward normal)`.
type Side = ((f32, f32), (f32, f32), Vec3);

/// The four sides of a rectangle.
fn sides(r: Rect) -> [Side; 4] {
    [
        ((r.x0, r.z0), (r.x1, r.z0), Vec3::NEG_Z),
        ((r.x1, r.z0), (r.x1, r.z1), Vec3::X),
        ((r.x1, r.z1), (r.x0, r.z1), Vec3::Z),
        ((r.x0, r.z1), (r.x0, r.z0), Vec3::NEG_X),
    ]
}

/// Facade `u` for a wall of length `len` at parameter `t` in `[0, 1]`: a whole number of window bays
/// fits the wall, so windows never get cut at a corner.
#[inline]
pub fn facade_u(len: f32, t: f32) -> f32 {
    let bays = (len / BAY + 0.5).floor().max(1.0);
    t * bays * BAY / FACADE_TILE
}

/// Facade `v`: metres above the street divided by the tile height (texture rows run downwards).
#[inline]
pub fn facade_v(y: f32) -> f32 {
    -y / FACADE_TILE
}

/// The four walls of a box from `y0` to `y1`: 8 triangles.
pub fn walls(facade: &mut Buf, r: Rect, y0: f32, y1: f32, c: [u8; 4]) {
    for (a, b, n) in sides(r) {
        let len = (b.0 - a.0).abs() + (b.1 - a.1).abs();
        let u1 = facade_u(len, 1.0);
        let p = [
            Vec3::new(a.0, y0, a.1),
            Vec3::new(b.0, y0, b.1),
            Vec3::new(b.0, y1, b.1),
            Vec3::new(a.0, y1, a.1),
        ];
        let (v0, v1) = (facade_v(y0), facade_v(y1));
        facade.quad(p, [[0.0, v0], [u1, v0], [u1, v1], [0.0, v1]], n, c);
    }
}

/// Roof shapes on top of a box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Roof {
    /// One quad: 2 triangles.
    Flat,
    /// Ridge along the longer side at `h` above the eaves: 2 slopes + 2 gable ends, 6 triangles.
    Gable { h: f32 },
    /// Hipped roof, ridge along the longer side: 2 trapezoids + 2 triangles, 6 triangles.
    Hip { h: f32 },
    /// Four triangles meeting at the apex.
    Pyramid { h: f32 },
}

impl Roof {
    pub fn triangles(&self) -> u64 {
        match self {
            Roof::Flat => 2,
            Roof::Gable { .. } | Roof::Hip { .. } => 6,
            Roof::Pyramid { .. } => 4,
        }
    }
}

/// A roof on the box `r` whose eaves are at `y`. Gable ends go to the facade buffer.
pub fn roof(
    facade: &mut Buf,
    roofs: &mut Buf,
    r: Rect,
    y: f32,
    kind: Roof,
    cf: [u8; 4],
    cr: [u8; 4],
) {
    // Work in a frame where the ridge runs along local x: (a, b) = (along, across).
    let along_x = r.w() >= r.d();
    let to_world = |a: f32, yy: f32, b: f32| {
        if along_x {
            Vec3::new(a, yy, b)
        } else {
            Vec3::new(b, yy, a)
        }
    };
    let (a0, a1, b0, b1) = if along_x {
        (r.x0, r.x1, r.z0, r.z1)
    } else {
        (r.z0, r.z1, r.x0, r.x1)
    };
    let bm = 0.5 * (b0 + b1);
    let am = 0.5 * (a0 + a1);
    let across_neg = to_world(0.0, 0.0, -1.0);
    let along_neg = to_world(-1.0, 0.0, 0.0);
    let zero_uv = [[0.0, 0.0]; 4];
    match kind {
        Roof::Flat => {
            let p = [
                to_world(a0, y, b0),
                to_world(a1, y, b0),
                to_world(a1, y, b1),
                to_world(a0, y, b1),
            ];
            roofs.quad(p, zero_uv, Vec3::Y, cr);
        }
        Roof::Gable { h } | Roof::Hip { h } => {
            let inset = if matches!(kind, Roof::Hip { .. }) {
                (0.5 * (b1 - b0)).min(0.5 * (a1 - a0) * 0.9)
            } else {
                0.0
            };
            let yr = y + h;
            let (r0, r1) = (a0 + inset, a1 - inset);
            for (be, s) in [(b0, -1.0f32), (b1, 1.0)] {
                let p = [
                    to_world(a0, y, be),
                    to_world(a1, y, be),
                    to_world(r1, yr, bm),
                    to_world(r0, yr, bm),
                ];
                roofs.quad(p, zero_uv, Vec3::Y - s * across_neg, cr);
            }
            for (ae, re, s) in [(a0, r0, 1.0f32), (a1, r1, -1.0)] {
                let p = [
                    to_world(ae, y, b0),
                    to_world(ae, y, b1),
                    to_world(re, yr, bm),
                ];
                if inset > 0.0 {
                    roofs.flat_tri(p, [[0.0, 0.0]; 3], Vec3::Y + s * along_neg, cr);
                } else {
                    let len = b1 - b0;
                    let u1 = facade_u(len, 1.0);
                    let uv = [
                        [0.0, facade_v(y)],
                        [u1, facade_v(y)],
                        [0.5 * u1, facade_v(yr)],
                    ];
                    facade.flat_tri(p, uv, s * along_neg, cf);
                }
            }
        }
        Roof::Pyramid { h } => {
            let apex = to_world(am, y + h, bm);
            let c = [
                to_world(a0, y, b0),
                to_world(a1, y, b0),
                to_world(a1, y, b1),
                to_world(a0, y, b1),
            ];
            let centre = to_world(am, y, bm);
            for k in 0..4 {
                let (p, q) = (c[k], c[(k + 1) % 4]);
                let out = (0.5 * (p + q) - centre).normalize_or_zero() + Vec3::Y * 0.1;
                roofs.flat_tri([p, q, apex], [[0.0, 0.0]; 3], out, cr);
            }
        }
    }
}

/// Emits `prims` grouped into square tiles of `tile` metres (one mesh per tile and material),
/// in parallel, in a fixed tile order.
pub fn emit_tiled(
    prims: &[(usize, (f32, f32))],
    tile: f32,
    all: &(dyn Fn(usize, &mut Emitter) + Sync),
    materials: usize,
) -> Vec<Mesh> {
    let mut keyed: Vec<((i64, i64), usize)> = prims
        .iter()
        .map(|&(idx, (x, z))| (((z / tile).floor() as i64, (x / tile).floor() as i64), idx))
        .collect();
    keyed.sort_by_key(|&(k, idx)| (k, idx));
    let mut groups: Vec<&[((i64, i64), usize)]> = Vec::new();
    let mut start = 0;
    for n in 1..=keyed.len() {
        if n == keyed.len() || keyed[n].0 != keyed[start].0 {
            groups.push(&keyed[start..n]);
            start = n;
        }
    }
    groups
        .par_iter()
        .map(|g| {
            let mut e = Emitter::new(materials);
            for &(_, idx) in g.iter() {
                all(idx, &mut e);
            }
            e.into_meshes()
        })
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect()
}
