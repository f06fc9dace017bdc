//! The `forest` built-in scene: flat forest floor at `y = 0` (vertex-coloured moss, needles and earth
//! over a detail texture) with many trees of several species and sizes, grouped by a noise field
//! into spruce stands, broadleaf woods and birch groves, with clearings and undergrowth.
//!
//! The triangle budget sets the extent (about 1 tree per 25 m²). A clearing of 10 m around the origin
//! keeps the spawn point free: no plant reaches within 5 m of it.

use glam::Vec3;
use lemi_core::{Material, SceneBuilder};
use rayon::prelude::*;

use super::geom::{emit_tiled, Emitter};
use super::rng::{hash, shade, srgb, unit_of, Noise, Rand};
use super::textures;
use super::trees::{self, candidate, Candidate, Species, Tree};

const GROUND: usize = 0;
const TRUNK: usize = 1;
const FOLIAGE: usize = 2;
const MATERIALS: usize = 3;
/// Ground grid spacing (m) and cells per ground mesh.
const CELL: f32 = 8.0;
const CHUNK: usize = 64;
const DETAIL_TILE: f32 = 8.0;
/// Spacing of the jittered grid of tree candidates (m).
const STEP: f32 = 3.6;

fn floor_color(noise: &Noise, x: f32, z: f32, j: f32) -> [u8; 4] {
    let v = noise.fbm(x / 60.0, z / 60.0, 3);
    let c = if v > 0.25 {
        srgb(96, 110, 52)
    } else if v > -0.1 {
        srgb(110, 92, 60)
    } else {
        srgb(88, 76, 54)
    };
    shade(c, 0.9 + 0.2 * j)
}

fn emit_ground(
    n: usize,
    half: f32,
    ca: usize,
    cb: usize,
    noise: &Noise,
    seed: u64,
    e: &mut Emitter,
) {
    let buf = &mut e.bufs[GROUND];
    let a1 = (ca + CHUNK).min(n);
    let b1 = (cb + CHUNK).min(n);
    let w = (a1 - ca + 1) as u32;
    for b in cb..=b1 {
        for a in ca..=a1 {
            let p = Vec3::new(a as f32 * CELL - half, 0.0, b as f32 * CELL - half);
            let j = unit_of(hash(&[seed, 0x31, a as u64, b as u64]));
            let c = floor_color(noise, p.x, p.z, j);
            buf.vert(p, Vec3::Y, [p.x / DETAIL_TILE, p.z / DETAIL_TILE], c);
        }
    }
    for b in 0..(b1 - cb) as u32 {
        for a in 0..(a1 - ca) as u32 {
            let v00 = b * w + a;
            buf.tri(v00, v00 + w, v00 + w + 1, Vec3::Y);
            buf.tri(v00, v00 + w + 1, v00 + 1, Vec3::Y);
        }
    }
}

/// Builds the forest into `b`; returns the half-extent (m).
pub fn build(seed: u64, triangles: u64, b: &mut SceneBuilder) -> f32 {
    // Ground 2 triangles per 64 m², trees ~40 triangles per ~27 m²: about 1.5 triangles per m².
    let side = (triangles as f64 / 1.5).sqrt();
    let n = (((side / CELL as f64) / 2.0).ceil() as usize * 2).max(8);
    let half = 0.5 * n as f32 * CELL;
    let tree_budget = triangles.saturating_sub(2 * (n * n) as u64);

    let stands = Noise::new(hash(&[seed, 0x32]));
    let clearings = Noise::new(hash(&[seed, 0x33]));
    let m = ((2.0 * half - 4.0) / STEP) as usize;
    let cands: Vec<Candidate> = (0..m)
        .into_par_iter()
        .flat_map_iter(|bz| {
            let clearings = &clearings;
            (0..m).filter_map(move |ax| {
                let key = hash(&[seed, 0x34, ax as u64, bz as u64]);
                let x = -half + 2.0 + STEP * (ax as f32 + 0.1 + 0.8 * unit_of(key));
                let z = -half + 2.0 + STEP * (bz as f32 + 0.1 + 0.8 * unit_of(key.rotate_left(29)));
                let r = (x * x + z * z).sqrt();
                let open = clearings.fbm(x / 140.0, z / 140.0, 3);
                let spawn = ((r - 10.0) / 15.0).clamp(0.0, 1.0);
                let d = (1.0 - 2.5 * (open - 0.25).max(0.0)).clamp(0.0, 1.0) * spawn;
                candidate(x, z, key, d)
            })
        })
        .collect();
    let (plants, _) = trees::fill(cands, tree_budget, |c| {
        let mut rng = Rand::new(c.key);
        let zone = stands.fbm(c.x / 180.0, c.z / 180.0, 2);
        let u = rng.unit();
        let (species, h, r) = if u < 0.18 {
            (Species::Shrub, rng.range(0.8, 2.2), rng.range(0.8, 1.8))
        } else if zone > 0.15 {
            if rng.chance(0.8) {
                (Species::Spruce, rng.range(10.0, 30.0), rng.range(2.0, 3.8))
            } else {
                (Species::Pine, rng.range(14.0, 26.0), rng.range(2.5, 4.0))
            }
        } else if zone < -0.2 && rng.chance(0.6) {
            (Species::Birch, rng.range(8.0, 18.0), rng.range(1.8, 3.0))
        } else if rng.chance(0.15) {
            (Species::Poplar, rng.range(14.0, 24.0), rng.range(1.5, 2.2))
        } else {
            (
                Species::Broadleaf,
                rng.range(8.0, 22.0),
                rng.range(2.5, 5.0),
            )
        };
        let color = match species {
            Species::Spruce | Species::Pine => {
                rng.pick(&[srgb(40, 76, 44), srgb(52, 88, 50), srgb(36, 66, 40)])
            }
            Species::Birch => rng.pick(&[srgb(120, 160, 70), srgb(150, 172, 76)]),
            Species::Shrub => rng.pick(&[srgb(88, 122, 56), srgb(106, 112, 48), srgb(70, 100, 50)]),
            _ => rng.pick(&[
                srgb(74, 124, 52),
                srgb(92, 140, 60),
                srgb(64, 110, 48),
                srgb(168, 140, 52),
            ]),
        };
        let t = Tree {
            x: c.x,
            y: 0.0,
            z: c.z,
            height: h,
            radius: r,
            species,
            color: shade(color, rng.range(0.9, 1.1)),
            key: c.key,
            sink: 0.0,
        };
        ((c.x * c.x + c.z * c.z).sqrt() - t.reach() > super::SPAWN_CLEAR_RADIUS + 0.5).then_some(t)
    });

    let detail = b.add_texture(textures::detail());
    let white = [1.0, 1.0, 1.0, 1.0];
    for (name, texture) in [
        ("forest-floor", Some(detail)),
        ("tree-trunk", None),
        ("tree-foliage", None),
    ] {
        b.add_material(Material {
            name: name.into(),
            base_color: white,
            texture,
        });
    }
    let floor = Noise::new(hash(&[seed, 0x35]));
    let chunks = n.div_ceil(CHUNK);
    let ground: Vec<_> = (0..chunks * chunks)
        .into_par_iter()
        .map(|k| {
            let mut e = Emitter::new(MATERIALS);
            emit_ground(
                n,
                half,
                (k % chunks) * CHUNK,
                (k / chunks) * CHUNK,
                &floor,
                seed,
                &mut e,
            );
            e.into_meshes()
        })
        .collect();
    for m in ground.into_iter().flatten() {
        b.add_mesh(m);
    }
    let anchors: Vec<(usize, (f32, f32))> = plants.iter().map(|t| (t.x, t.z)).enumerate().collect();
    let meshes = emit_tiled(
        &anchors,
        256.0,
        &|i, e| {
            let (a, c) = e.bufs.split_at_mut(FOLIAGE);
            trees::emit(&mut a[TRUNK], &mut c[0], &plants[i]);
        },
        MATERIALS,
    );
    for m in meshes {
        b.add_mesh(m);
    }
    half
}
