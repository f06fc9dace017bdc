//! The `terrain` built-in scene: a height field of fractional Brownian motion over gradient noise
//! (Perlin 2002; fBm as in Musgrave, "Texturing & Modeling", ch. 16), coloured by height and slope
//! (sand, grass, alpine meadow, rock, snow), with trees and shrubs scattered where the ground is low
//! and gentle enough.
//!
//! The grid has a vertex at the origin and the height field is forced to exactly 0 there, flattening
//! smoothly within 60 m, so a viewer spawns on flat ground at `y = 0` with no plant within 5 m.
//! The triangle budget sets the extent: about 42 % goes to the ground at a fixed 4 m spacing, the rest
//! to plants.

use glam::Vec3;
use lemi_core::{Material, SceneBuilder};
use rayon::prelude::*;

use super::geom::{emit_tiled, Emitter};
use super::rng::{hash, shade, srgb, unit_of, Noise, Rand};
use super::textures;
use super::trees::{self, candidate, Candidate, Species, Tree};

/// Grid spacing of the height field (m).
pub const SPACING: f32 = 4.0;
const GROUND: usize = 0;
const TRUNK: usize = 1;
const FOLIAGE: usize = 2;
const MATERIALS: usize = 3;
/// Cells per side of one ground mesh.
const CHUNK: usize = 64;
const DETAIL_TILE: f32 = 8.0;
const SNOW_LINE: f32 = 40.0;
const TREE_LINE: f32 = 30.0;

struct Field {
    noise: Noise,
    warp: Noise,
    h0: f32,
}

impl Field {
    fn new(seed: u64) -> Field {
        let mut f = Field {
            noise: Noise::new(hash(&[seed, 0x21])),
            warp: Noise::new(hash(&[seed, 0x22])),
            h0: 0.0,
        };
        f.h0 = f.raw(0.0, 0.0);
        f
    }

    fn raw(&self, x: f32, z: f32) -> f32 {
        let hills = self.noise.fbm(x / 420.0, z / 420.0, 6);
        let broad = self.warp.fbm(x / 1600.0, z / 1600.0, 2);
        70.0 * hills + 40.0 * broad
    }

    /// Height at `(x, z)`: 0 at the origin, flattened smoothly within 60 m of it.
    fn height(&self, x: f32, z: f32) -> f32 {
        let r = (x * x + z * z).sqrt();
        let t = ((r - 10.0) / 50.0).clamp(0.0, 1.0);
        let s = t * t * (3.0 - 2.0 * t);
        (self.raw(x, z) - self.h0) * s
    }
}

/// The sampled height field: `(n + 3)²` heights with a one-sample border for normals.
struct Grid {
    n: usize,
    half: f32,
    h: Vec<f32>,
}

impl Grid {
    fn new(field: &Field, n: usize) -> Grid {
        let half = 0.5 * n as f32 * SPACING;
        let w = n + 3;
        let h: Vec<f32> = (0..w)
            .into_par_iter()
            .flat_map_iter(|b| {
                let z = (b as f32 - 1.0) * SPACING - half;
                (0..w).map(move |a| field.height((a as f32 - 1.0) * SPACING - half, z))
            })
            .collect();
        Grid { n, half, h }
    }

    /// Height of grid vertex `(a, b)`, `a, b` in `0..=n`.
    #[inline]
    fn at(&self, a: usize, b: usize) -> f32 {
        self.h[(b + 1) * (self.n + 3) + a + 1]
    }

    #[inline]
    fn at_border(&self, a: isize, b: isize) -> f32 {
        self.h[((b + 1) as usize) * (self.n + 3) + (a + 1) as usize]
    }

    fn pos(&self, a: usize, b: usize) -> Vec3 {
        Vec3::new(
            a as f32 * SPACING - self.half,
            self.at(a, b),
            b as f32 * SPACING - self.half,
        )
    }

    fn normal(&self, a: usize, b: usize) -> Vec3 {
        let (a, b) = (a as isize, b as isize);
        let dx = self.at_border(a + 1, b) - self.at_border(a - 1, b);
        let dz = self.at_border(a, b + 1) - self.at_border(a, b - 1);
        Vec3::new(-dx, 2.0 * SPACING, -dz).normalize()
    }

    /// Height of the triangulated surface at `(x, z)` (each cell split along its (0,0)–(1,1)
    /// diagonal, as emitted).
    fn surface(&self, x: f32, z: f32) -> f32 {
        let fx = ((x + self.half) / SPACING).clamp(0.0, self.n as f32 - 1e-3);
        let fz = ((z + self.half) / SPACING).clamp(0.0, self.n as f32 - 1e-3);
        let (a, b) = (fx.floor() as usize, fz.floor() as usize);
        let (u, v) = (fx - a as f32, fz - b as f32);
        let (h00, h10) = (self.at(a, b), self.at(a + 1, b));
        let (h01, h11) = (self.at(a, b + 1), self.at(a + 1, b + 1));
        if v >= u {
            h00 + v * (h01 - h00) + u * (h11 - h01)
        } else {
            h00 + u * (h10 - h00) + v * (h11 - h10)
        }
    }

    fn color(&self, p: Vec3, n: Vec3, jitter: f32) -> [u8; 4] {
        let h = p.y + 4.0 * jitter;
        let flat = n.y;
        let c = if h > SNOW_LINE && flat > 0.8 {
            srgb(240, 242, 246)
        } else if flat < 0.72 || h > SNOW_LINE - 4.0 {
            srgb(128, 120, 110)
        } else if flat < 0.8 {
            srgb(120, 118, 82)
        } else if h < -30.0 {
            srgb(196, 180, 132)
        } else if h < -16.0 {
            srgb(120, 140, 70)
        } else if h > 22.0 {
            srgb(132, 140, 80)
        } else if h > 6.0 {
            srgb(98, 138, 60)
        } else {
            srgb(84, 128, 54)
        };
        shade(c, 0.92 + 0.12 * jitter)
    }

    /// Ground meshes in chunks of `CHUNK × CHUNK` cells.
    fn emit_chunk(&self, ca: usize, cb: usize, e: &mut Emitter, seed: u64) {
        let buf = &mut e.bufs[GROUND];
        let a1 = (ca + CHUNK).min(self.n);
        let b1 = (cb + CHUNK).min(self.n);
        let w = (a1 - ca + 1) as u32;
        for b in cb..=b1 {
            for a in ca..=a1 {
                let p = self.pos(a, b);
                let n = self.normal(a, b);
                let j = unit_of(hash(&[seed, 0x23, a as u64, b as u64]));
                let c = self.color(p, n, j);
                buf.vert(p, n, [p.x / DETAIL_TILE, p.z / DETAIL_TILE], c);
            }
        }
        for b in 0..(b1 - cb) as u32 {
            for a in 0..(a1 - ca) as u32 {
                let v00 = b * w + a;
                let (v10, v01, v11) = (v00 + 1, v00 + w, v00 + w + 1);
                buf.tri(v00, v01, v11, Vec3::Y);
                buf.tri(v00, v11, v10, Vec3::Y);
            }
        }
    }
}

fn leaf(seed: u64, key: u64, species: Species) -> [u8; 4] {
    let mut rng = Rand::new(hash(&[seed, key]));
    let c = match species {
        Species::Spruce | Species::Pine => {
            rng.pick(&[srgb(46, 84, 46), srgb(56, 92, 52), srgb(40, 72, 44)])
        }
        Species::Birch => rng.pick(&[srgb(120, 160, 70), srgb(150, 170, 70)]),
        Species::Shrub => rng.pick(&[srgb(90, 120, 56), srgb(110, 110, 50)]),
        _ => rng.pick(&[
            srgb(74, 124, 52),
            srgb(92, 140, 60),
            srgb(170, 140, 50),
            srgb(160, 80, 40),
        ]),
    };
    shade(c, rng.range(0.9, 1.1))
}

/// Builds the terrain into `b`; returns the half-extent (m).
pub fn build(seed: u64, triangles: u64, b: &mut SceneBuilder) -> f32 {
    let ground_tris = triangles as f64 * 0.42;
    let n = (((ground_tris / 2.0).sqrt() / 2.0).round() as usize * 2).max(32);
    let field = Field::new(seed);
    let grid = Grid::new(&field, n);
    let veg_budget = triangles.saturating_sub(2 * (n * n) as u64);

    // Plant candidates on a jittered 6 m grid, denser in woods, none on steep, high or spawn ground.
    let wood = Noise::new(hash(&[seed, 0x24]));
    let step = 6.0;
    let m = ((2.0 * grid.half - 8.0) / step) as usize;
    let cands: Vec<Candidate> = (0..m)
        .into_par_iter()
        .flat_map_iter(|bz| {
            let (grid, wood) = (&grid, &wood);
            (0..m).filter_map(move |ax| {
                let key = hash(&[seed, 0x25, ax as u64, bz as u64]);
                let x = -grid.half + 4.0 + step * (ax as f32 + 0.1 + 0.8 * unit_of(key));
                let z = -grid.half
                    + 4.0
                    + step * (bz as f32 + 0.1 + 0.8 * unit_of(key.rotate_left(29)));
                let y = grid.surface(x, z);
                let (ga, gb) = (
                    ((x + grid.half) / SPACING).round() as usize,
                    ((z + grid.half) / SPACING).round() as usize,
                );
                let flat = grid.normal(ga.min(grid.n), gb.min(grid.n)).y;
                let r = (x * x + z * z).sqrt();
                if flat < 0.82 || y > TREE_LINE || r < 12.0 {
                    return None;
                }
                let d = (0.35 + 1.2 * wood.fbm(x / 260.0, z / 260.0, 3)).clamp(0.04, 1.0);
                candidate(x, z, key, d)
            })
        })
        .collect();
    let (plants, _) = trees::fill(cands, veg_budget, |c| {
        let mut rng = Rand::new(c.key);
        let y = grid.surface(c.x, c.z);
        let u = rng.unit();
        let high = ((y + 10.0) / (TREE_LINE + 10.0)).clamp(0.0, 1.0);
        let (species, h, r) = if u < 0.22 {
            (Species::Shrub, rng.range(1.0, 2.5), rng.range(0.9, 2.0))
        } else if rng.unit() < 0.25 + 0.6 * high {
            if rng.chance(0.7) {
                (Species::Spruce, rng.range(8.0, 22.0), rng.range(2.0, 3.6))
            } else {
                (Species::Pine, rng.range(12.0, 22.0), rng.range(2.5, 4.0))
            }
        } else if rng.chance(0.25) {
            (Species::Birch, rng.range(8.0, 15.0), rng.range(1.8, 2.8))
        } else {
            (
                Species::Broadleaf,
                rng.range(7.0, 17.0),
                rng.range(2.5, 4.5),
            )
        };
        let t = Tree {
            x: c.x,
            y,
            z: c.z,
            height: h,
            radius: r,
            species,
            color: leaf(seed, c.key, species),
            key: c.key,
            sink: 0.4,
        };
        ((c.x * c.x + c.z * c.z).sqrt() - t.reach() > super::SPAWN_CLEAR_RADIUS + 0.5).then_some(t)
    });

    let detail = b.add_texture(textures::detail());
    let white = [1.0, 1.0, 1.0, 1.0];
    for (name, texture) in [
        ("terrain-ground", Some(detail)),
        ("tree-trunk", None),
        ("tree-foliage", None),
    ] {
        b.add_material(Material {
            name: name.into(),
            base_color: white,
            texture,
        });
    }
    let chunks = n.div_ceil(CHUNK);
    let ground_meshes: Vec<_> = (0..chunks * chunks)
        .into_par_iter()
        .map(|k| {
            let mut e = Emitter::new(MATERIALS);
            grid.emit_chunk((k % chunks) * CHUNK, (k / chunks) * CHUNK, &mut e, seed);
            e.into_meshes()
        })
        .collect();
    for m in ground_meshes.into_iter().flatten() {
        b.add_mesh(m);
    }
    let anchors: Vec<(usize, (f32, f32))> = plants.iter().map(|t| (t.x, t.z)).enumerate().collect();
    let meshes = emit_tiled(
        &anchors,
        CHUNK as f32 * SPACING,
        &|i, e| {
            let (a, c) = e.bufs.split_at_mut(FOLIAGE);
            trees::emit(&mut a[TRUNK], &mut c[0], &plants[i]);
        },
        MATERIALS,
    );
    for m in meshes {
        b.add_mesh(m);
    }
    grid.half
}
