//! Low-poly trees for the built-in scenes: a pentagonal trunk prism plus a crown of a few dozen
//! triangles (a jittered ellipsoid for broadleaf species, stacked cones for conifers), with per-vertex
//! colour variation so crowns differ in images.
//!
//! Triangle counts are fixed per species (`Tree::triangles`), which lets the generators size a scene
//! exactly before emitting it.

use glam::Vec3;

use super::geom::Buf;
use super::rng::{shade, Rand};

/// Tree species (shapes and colours).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Species {
    /// Round crown (oak, lime, plane tree).
    Broadleaf,
    /// Tall narrow crown.
    Poplar,
    /// White trunk, light elongated crown.
    Birch,
    /// Three stacked cones (spruce, fir).
    Spruce,
    /// Long bare trunk with a flat crown.
    Pine,
    /// A bush without trunk.
    Shrub,
}

/// One tree, standing at `(x, y, z)` (`y`: ground height at the trunk).
#[derive(Clone, Copy, Debug)]
pub struct Tree {
    pub x: f32,
    pub y: f32,
    pub z: f32,
    pub height: f32,
    /// Nominal crown radius; the crown never reaches further than [`Tree::reach`].
    pub radius: f32,
    pub species: Species,
    /// Base foliage colour (linear RGBA8).
    pub color: [u8; 4],
    /// Seeds the shape jitter and colour variation.
    pub key: u64,
    /// How far the trunk reaches below `y` (for sloped ground; 0 on flat ground).
    pub sink: f32,
}

const TRUNK_SIDES: usize = 5;
const JITTER: f32 = 0.12;

/// `(segments, rings)` of the ellipsoid crown of a species.
fn crown_grid(s: Species) -> (usize, usize) {
    match s {
        Species::Broadleaf | Species::Birch => (6, 4),
        Species::Poplar => (6, 5),
        Species::Pine => (6, 3),
        Species::Shrub => (5, 3),
        Species::Spruce => (0, 0),
    }
}

const SPRUCE_TIERS: usize = 3;
const SPRUCE_SIDES: usize = 7;

impl Tree {
    /// Exact number of triangles [`emit`] writes for this tree.
    pub fn triangles(&self) -> u64 {
        let trunk = if self.species == Species::Shrub {
            0
        } else {
            2 * TRUNK_SIDES as u64
        };
        let crown = match self.species {
            Species::Spruce => (SPRUCE_TIERS * (SPRUCE_SIDES + SPRUCE_SIDES - 2)) as u64,
            s => {
                let (seg, rings) = crown_grid(s);
                (2 * seg * (rings - 1)) as u64
            }
        };
        trunk + crown
    }

    /// Largest horizontal distance of any vertex from the trunk axis.
    pub fn reach(&self) -> f32 {
        self.radius * (1.0 + JITTER) + 0.01
    }
}

/// `n` points on the unit circle, starting at angle `phase` (radians), via `libm` for determinism.
fn circle(n: usize, phase: f32) -> impl Iterator<Item = (f32, f32)> {
    (0..n).map(move |k| {
        let a = phase + std::f32::consts::TAU * k as f32 / n as f32;
        (libm::cosf(a), libm::sinf(a))
    })
}

/// Writes the trunk into `trunk` and the crown into `crown`.
pub fn emit(trunk: &mut Buf, crown: &mut Buf, t: &Tree) {
    let mut rng = Rand::new(t.key);
    let base = Vec3::new(t.x, t.y, t.z);
    let (trunk_frac, trunk_r, trunk_c) = match t.species {
        Species::Broadleaf => (0.35, 0.035, super::rng::srgb(92, 70, 52)),
        Species::Poplar => (0.2, 0.035, super::rng::srgb(100, 84, 66)),
        Species::Birch => (0.4, 0.03, super::rng::srgb(226, 222, 210)),
        Species::Spruce => (0.15, 0.03, super::rng::srgb(84, 62, 46)),
        Species::Pine => (0.62, 0.03, super::rng::srgb(128, 84, 58)),
        Species::Shrub => (0.0, 0.0, [0; 4]),
    };
    let trunk_h = t.height * trunk_frac;
    if t.species != Species::Shrub {
        let r = (t.height * trunk_r).clamp(0.1, 0.45).min(0.5 * t.radius);
        let phase = rng.range(0.0, 1.2);
        let top = trunk_h + 0.25 * (t.height - trunk_h);
        let first = trunk.vertices.len() as u32;
        for (c, s) in circle(TRUNK_SIDES, phase) {
            let n = Vec3::new(c, 0.0, s);
            trunk.vert(
                base + Vec3::new(r * c, -t.sink, r * s),
                n,
                [0.0, 0.0],
                trunk_c,
            );
            trunk.vert(
                base + Vec3::new(0.6 * r * c, top, 0.6 * r * s),
                n,
                [0.0, 0.0],
                shade(trunk_c, 0.85),
            );
        }
        for k in 0..TRUNK_SIDES as u32 {
            let j = (k + 1) % TRUNK_SIDES as u32;
            let (b0, t0, b1, t1) = (
                first + 2 * k,
                first + 2 * k + 1,
                first + 2 * j,
                first + 2 * j + 1,
            );
            let out = trunk.vertices[b0 as usize].normal;
            let out = Vec3::from(out) + Vec3::from(trunk.vertices[b1 as usize].normal);
            trunk.tri(b0, b1, t1, out);
            trunk.tri(b0, t1, t0, out);
        }
    }
    if t.species == Species::Spruce {
        spruce_crown(crown, t, base, trunk_h, &mut rng);
    } else {
        ellipsoid_crown(crown, t, base, trunk_h, &mut rng);
    }
}

/// Per-vertex foliage colour: darker low in the crown, lighter on top, with random variation.
fn leaf_color(t: &Tree, rng: &mut Rand, up: f32) -> [u8; 4] {
    let f = (0.72 + 0.36 * up) * rng.range(0.88, 1.12);
    let c = shade(t.color, f);
    let g = rng.range(0.94, 1.06);
    [c[0], (c[1] as f32 * g).min(255.0) as u8, c[2], 255]
}

fn ellipsoid_crown(crown: &mut Buf, t: &Tree, base: Vec3, trunk_h: f32, rng: &mut Rand) {
    let (seg, rings) = crown_grid(t.species);
    let ry = 0.5 * (t.height - trunk_h);
    let centre = base + Vec3::new(0.0, trunk_h + ry, 0.0);
    let rad = Vec3::new(t.radius, ry, t.radius);
    let first = crown.vertices.len() as u32;
    let jit = |rng: &mut Rand| rng.range(1.0 - JITTER, 1.0 + JITTER);
    // Poles.
    let top = crown.vert(
        centre + Vec3::new(0.0, ry * jit(rng), 0.0),
        Vec3::Y,
        [0.0, 0.0],
        leaf_color(t, rng, 1.0),
    );
    let bottom = crown.vert(
        centre - Vec3::new(0.0, ry * jit(rng).min(1.0), 0.0),
        Vec3::NEG_Y,
        [0.0, 0.0],
        leaf_color(t, rng, 0.0),
    );
    let _ = first;
    let mut ring_start = Vec::with_capacity(rings - 1);
    for k in 1..rings {
        let theta = std::f32::consts::PI * k as f32 / rings as f32;
        let (st, ct) = (libm::sinf(theta), libm::cosf(theta));
        let phase = if k % 2 == 0 {
            std::f32::consts::PI / seg as f32
        } else {
            0.0
        };
        ring_start.push(crown.vertices.len() as u32);
        for (c, s) in circle(seg, phase) {
            let dir = Vec3::new(st * c, ct, st * s);
            let j = jit(rng);
            let p = centre + dir * rad * j;
            let c = leaf_color(t, rng, 0.5 + 0.5 * ct);
            crown.vert(p, dir, [0.0, 0.0], c);
        }
    }
    let seg32 = seg as u32;
    let centre_out = |crown: &Buf, i: u32| Vec3::from(crown.vertices[i as usize].position) - centre;
    for s in 0..seg32 {
        let (a, b) = (ring_start[0] + s, ring_start[0] + (s + 1) % seg32);
        let out = centre_out(crown, a) + centre_out(crown, b) + centre_out(crown, top);
        crown.tri(top, a, b, out);
        let last = ring_start[rings - 2];
        let (a, b) = (last + s, last + (s + 1) % seg32);
        let out = centre_out(crown, a) + centre_out(crown, b) + centre_out(crown, bottom);
        crown.tri(bottom, b, a, out);
    }
    for k in 0..rings - 2 {
        let (r0, r1) = (ring_start[k], ring_start[k + 1]);
        for s in 0..seg32 {
            let s1 = (s + 1) % seg32;
            let (a, b, c, d) = (r0 + s, r0 + s1, r1 + s, r1 + s1);
            let out = centre_out(crown, a)
                + centre_out(crown, b)
                + centre_out(crown, c)
                + centre_out(crown, d);
            crown.tri(a, b, d, out);
            crown.tri(a, d, c, out);
        }
    }
}

fn spruce_crown(crown: &mut Buf, t: &Tree, base: Vec3, trunk_h: f32, rng: &mut Rand) {
    let span = t.height - trunk_h;
    // Tier k spans [bottom_k, bottom_k + tier_h); tiers overlap by a third.
    let tier_h = span / (1.0 + (SPRUCE_TIERS as f32 - 1.0) * 0.6);
    for k in 0..SPRUCE_TIERS {
        let y0 = trunk_h + k as f32 * 0.6 * tier_h;
        let r = t.radius * (1.0 - 0.27 * k as f32) * rng.range(0.93, 1.0);
        let apex_p = base + Vec3::new(0.0, y0 + tier_h, 0.0);
        let apex = crown.vert(apex_p, Vec3::Y, [0.0, 0.0], leaf_color(t, rng, 1.0));
        let ring = crown.vertices.len() as u32;
        let phase = rng.range(0.0, 0.9);
        let pts: Vec<(f32, f32)> = circle(SPRUCE_SIDES, phase).collect();
        for &(c, s) in &pts {
            let n = Vec3::new(c * tier_h, r, s * tier_h).normalize_or_zero();
            let p = base + Vec3::new(r * c, y0, r * s);
            let col = leaf_color(t, rng, 0.3 * k as f32);
            crown.vert(p, n, [0.0, 0.0], col);
        }
        let n = SPRUCE_SIDES as u32;
        for s in 0..n {
            let (a, b) = (ring + s, ring + (s + 1) % n);
            let out = Vec3::from(crown.vertices[a as usize].normal)
                + Vec3::from(crown.vertices[b as usize].normal);
            crown.tri(apex, a, b, out);
        }
        // Underside: a fan over separate downward-facing vertices.
        let cap = crown.vertices.len() as u32;
        for &(c, s) in &pts {
            let p = base + Vec3::new(r * c, y0, r * s);
            crown.vert(p, Vec3::NEG_Y, [0.0, 0.0], shade(t.color, 0.55));
        }
        for s in 1..n - 1 {
            crown.tri(cap, cap + s, cap + s + 1, Vec3::NEG_Y);
        }
    }
}

/// A place where a tree may grow, with its fill priority (lower first).
#[derive(Clone, Copy, Debug)]
pub struct Candidate {
    pub priority: f32,
    pub x: f32,
    pub z: f32,
    pub key: u64,
}

/// Makes a candidate whose priority is `u / density` for a uniform `u` from `key`: taking candidates
/// in priority order thins them evenly in proportion to the density. `None` where density is zero.
pub fn candidate(x: f32, z: f32, key: u64, density: f32) -> Option<Candidate> {
    if density.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let u = super::rng::unit_of(key.rotate_left(17)) + 1e-6;
    Some(Candidate {
        priority: u / density.min(1.0),
        x,
        z,
        key,
    })
}

/// Takes trees in priority order until `budget` triangles are used (within one small tree).
/// `make` turns a candidate into a tree or rejects it. Returns the trees and their triangles.
pub fn fill(
    mut cands: Vec<Candidate>,
    budget: u64,
    make: impl Fn(&Candidate) -> Option<Tree>,
) -> (Vec<Tree>, u64) {
    cands.sort_by(|a, b| a.priority.total_cmp(&b.priority).then(a.key.cmp(&b.key)));
    let mut out = Vec::new();
    let mut tris = 0;
    for c in &cands {
        if tris >= budget {
            break;
        }
        if let Some(t) = make(c) {
            let n = t.triangles();
            if tris + n > budget + 25 {
                continue;
            }
            tris += n;
            out.push(t);
        }
    }
    (out, tris)
}
