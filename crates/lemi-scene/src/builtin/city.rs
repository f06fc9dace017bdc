//! The `city` built-in scene: an open historical city on a jittered street grid.
//!
//! Layout, from the centre outwards: a main avenue along the X axis (street 40 m wide with a cobbled
//! promenade in the middle), a cobbled central plaza around the origin, then blocks in order of a
//! noisy distance from the centre until the triangle budget is spent, so a bigger budget gives a
//! bigger city. Blocks hold perimeter buildings around courtyards (2–40 m high, flat, gabled, hipped
//! and pyramid roofs), or are parks, open squares with a monument, or a landmark (church tower up to
//! ~110 m). Streets are asphalt, pavements raised 0.15 m, trees line some streets and fill parks, and
//! meadows with trees surround the city to fill the exact budget.
//!
//! Contract (checked by the tests): no triangle of a building or tree within `|z| < 15 m` (the avenue)
//! or within 40 m of the origin (the plaza); ground at `y = 0`, pavements at 0.15 m, city centred on
//! the origin.

use std::collections::HashSet;

use lemi_core::{Material, SceneBuilder};

use super::geom::{emit_tiled, ground, roof, slab, walls, Emitter, Rect, Roof, BAY};
use super::rng::{hash, shade, srgb, unit_of, Noise, Rand};
use super::textures;
use super::trees::{self, Species, Tree};

/// Half-width of the free zone along the X axis (m).
pub const AVENUE_FREE_HALF_WIDTH: f32 = 15.0;
/// Radius of the free plaza around the origin (m).
pub const PLAZA_FREE_RADIUS: f32 = 40.0;

const AVENUE_WIDTH: f32 = 40.0;
const PROMENADE_HALF: f32 = 8.0;
const CENTRAL_PLAZA_DIST: f32 = 50.0;
const KERB: f32 = 0.15;
const MESH_TILE: f32 = 1000.0;
const MAX_BUILDING_H: f32 = 40.0;

const FACADE: usize = 0;
const ROOF: usize = 1;
const ASPHALT: usize = 2;
const COBBLE: usize = 3;
const PAVING: usize = 4;
const GRASS: usize = 5;
const TRUNK: usize = 6;
const FOLIAGE: usize = 7;
const MATERIALS: usize = 8;

const ASPHALT_TILE: f32 = 4.0;
const COBBLE_TILE: f32 = 2.0;
const GRASS_TILE: f32 = 3.0;

// Hash tags, so that independent decisions use independent streams.
const TAG_LINES: u64 = 0x11;
const TAG_JITTER: u64 = 0x12;
const TAG_BLOCK: u64 = 0x13;
const TAG_TREELINE: u64 = 0x14;
const TAG_OUTLINE: u64 = 0x15;
const TAG_OUTSKIRTS: u64 = 0x16;

/// One piece of the plan; each knows its exact triangle count.
#[derive(Clone, Copy, Debug)]
enum Prim {
    Ground {
        r: Rect,
        mat: usize,
        c: [u8; 4],
    },
    Slab {
        r: Rect,
        mat: usize,
        c: [u8; 4],
    },
    Building {
        r: Rect,
        y0: f32,
        y1: f32,
        roof: Roof,
        cf: [u8; 4],
        cr: [u8; 4],
    },
    /// Walls only (a plinth under a building): 8 triangles.
    Walls {
        r: Rect,
        y1: f32,
        c: [u8; 4],
    },
    Tree(Tree),
}

impl Prim {
    fn triangles(&self) -> u64 {
        match self {
            Prim::Ground { .. } => 2,
            Prim::Slab { .. } => 10,
            Prim::Building { roof, .. } => 8 + roof.triangles(),
            Prim::Walls { .. } => 8,
            Prim::Tree(t) => t.triangles(),
        }
    }

    fn anchor(&self) -> (f32, f32) {
        match self {
            Prim::Ground { r, .. }
            | Prim::Slab { r, .. }
            | Prim::Building { r, .. }
            | Prim::Walls { r, .. } => (r.cx(), r.cz()),
            Prim::Tree(t) => (t.x, t.z),
        }
    }

    fn emit(&self, e: &mut Emitter) {
        match *self {
            Prim::Ground { r, mat, c } => {
                let tile = match mat {
                    ASPHALT => ASPHALT_TILE,
                    COBBLE => COBBLE_TILE,
                    _ => GRASS_TILE,
                };
                ground(&mut e.bufs[mat], r, 0.0, tile, c)
            }
            Prim::Slab { r, mat, c } => slab(&mut e.bufs[mat], r, KERB, GRASS_TILE, c),
            Prim::Building {
                r,
                y0,
                y1,
                roof: kind,
                cf,
                cr,
            } => {
                walls(&mut e.bufs[FACADE], r, y0, y1, cf);
                let (f, rest) = e.bufs.split_at_mut(ROOF);
                roof(&mut f[FACADE], &mut rest[0], r, y1, kind, cf, cr);
            }
            Prim::Walls { r, y1, c } => walls(&mut e.bufs[FACADE], r, 0.0, y1, c),
            Prim::Tree(ref t) => {
                let (a, b) = e.bufs.split_at_mut(FOLIAGE);
                trees::emit(&mut a[TRUNK], &mut b[0], t);
            }
        }
    }
}

/// Street centre lines of one axis, generated outwards from street 0 (at 0) so that a line's place
/// does not depend on how many are generated.
struct Lines {
    /// Street `s` is at index `s + k`.
    centre: Vec<f32>,
    width: Vec<f32>,
    tree_lined: Vec<bool>,
    k: i64,
}

impl Lines {
    fn new(seed: u64, axis: u64, k: i64, first_width: f32, block: (f32, f32)) -> Lines {
        let n = (2 * k + 1) as usize;
        let mut centre = vec![0.0; n];
        let mut width = vec![0.0; n];
        let mut tree_lined = vec![false; n];
        width[k as usize] = first_width;
        tree_lined[k as usize] = true;
        for (side, dir) in [(1u64, 1i64), (2, -1)] {
            let mut rng = Rand::new(hash(&[seed, TAG_LINES, axis, side]));
            for step in 1..=k {
                let s = k + dir * step;
                let prev = (s - dir) as usize;
                let main = rng.chance(0.18);
                let w = if main {
                    rng.range(16.0, 22.0)
                } else {
                    rng.range(9.0, 14.0)
                };
                let b = rng.range(block.0, block.1);
                let s = s as usize;
                width[s] = w;
                let lined = rng.chance(0.6);
                tree_lined[s] = (main && lined) || rng.chance(0.06);
                centre[s] = centre[prev] + dir as f32 * (0.5 * width[prev] + b + 0.5 * w);
            }
        }
        Lines {
            centre,
            width,
            tree_lined,
            k,
        }
    }

    fn idx(&self, s: i64) -> usize {
        (s + self.k) as usize
    }
}

/// Which block is which.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Central,
    Buildings,
    Park,
    Square,
    Landmark,
}

struct City {
    seed: u64,
    x: Lines,
    z: Lines,
    district: Noise,
}

fn facade_palette() -> [[u8; 4]; 12] {
    [
        srgb(236, 224, 196),
        srgb(214, 170, 96),
        srgb(196, 112, 80),
        srgb(226, 182, 170),
        srgb(200, 200, 196),
        srgb(210, 190, 150),
        srgb(240, 238, 232),
        srgb(170, 190, 206),
        srgb(160, 82, 62),
        srgb(180, 210, 180),
        srgb(232, 206, 110),
        srgb(136, 120, 108),
    ]
}

fn pitched_roof_palette() -> [[u8; 4]; 6] {
    [
        srgb(168, 72, 48),
        srgb(184, 88, 56),
        srgb(130, 50, 40),
        srgb(110, 80, 60),
        srgb(72, 78, 88),
        srgb(96, 150, 130),
    ]
}

fn flat_roof_palette() -> [[u8; 4]; 3] {
    [srgb(120, 120, 118), srgb(78, 78, 80), srgb(150, 144, 130)]
}

fn leaf_palette() -> [[u8; 4]; 5] {
    [
        srgb(74, 124, 52),
        srgb(92, 140, 60),
        srgb(60, 104, 50),
        srgb(110, 142, 58),
        srgb(150, 130, 50),
    ]
}

impl City {
    fn new(seed: u64, k: i64) -> City {
        City {
            seed,
            x: Lines::new(seed, 0, k, 12.0, (55.0, 115.0)),
            z: Lines::new(seed, 1, k, AVENUE_WIDTH, (42.0, 90.0)),
            district: Noise::new(hash(&[seed, 0x17])),
        }
    }

    /// Centre of x-street `s` within block row `j` (streets jog a little from row to row).
    fn xc(&self, j: i64, s: i64) -> f32 {
        let base = self.x.centre[self.x.idx(s)];
        if s == 0 {
            return base;
        }
        let u = unit_of(hash(&[self.seed, TAG_JITTER, j as u64, s as u64]));
        base + 14.0 * (u - 0.5)
    }

    fn cell(&self, i: i64, j: i64) -> Rect {
        Rect::new(
            self.xc(j, i),
            self.z.centre[self.z.idx(j)],
            self.xc(j, i + 1),
            self.z.centre[self.z.idx(j + 1)],
        )
    }

    fn block(&self, i: i64, j: i64) -> Rect {
        let c = self.cell(i, j);
        Rect::new(
            c.x0 + 0.5 * self.x.width[self.x.idx(i)],
            c.z0 + 0.5 * self.z.width[self.z.idx(j)],
            c.x1 - 0.5 * self.x.width[self.x.idx(i + 1)],
            c.z1 - 0.5 * self.z.width[self.z.idx(j + 1)],
        )
    }

    /// True when something reaching `reach` metres around `(x, z)` stays out of the free zones.
    fn clear(x: f32, z: f32, reach: f32) -> bool {
        z.abs() - reach >= AVENUE_FREE_HALF_WIDTH + 0.5
            && (x * x + z * z).sqrt() - reach >= PLAZA_FREE_RADIUS + 0.5
    }

    fn rect_clear(r: &Rect) -> bool {
        r.min_abs_z() >= AVENUE_FREE_HALF_WIDTH + 0.5
            && r.dist_to_origin() >= PLAZA_FREE_RADIUS + 0.5
    }

    fn kind(&self, i: i64, j: i64, rng: &mut Rand) -> Kind {
        let u = rng.unit();
        if self.block(i, j).dist_to_origin() < CENTRAL_PLAZA_DIST {
            Kind::Central
        } else if (i, j) == (1, 0) {
            Kind::Landmark
        } else if u < 0.05 {
            Kind::Square
        } else if u < 0.12 {
            Kind::Park
        } else if u < 0.128 {
            Kind::Landmark
        } else {
            Kind::Buildings
        }
    }

    fn plan_block(&self, i: i64, j: i64, out: &mut Vec<Prim>) {
        let mut rng = Rand::new(hash(&[self.seed, TAG_BLOCK, i as u64, j as u64]));
        let cell = self.cell(i, j);
        let block = self.block(i, j);
        let kind = self.kind(i, j, &mut rng);
        let cobble = srgb(205, 196, 184);
        if matches!(kind, Kind::Central | Kind::Square) {
            out.push(Prim::Ground {
                r: cell,
                mat: COBBLE,
                c: cobble,
            });
        } else {
            let asphalt = [255; 4];
            if j == 0 || j == -1 {
                let (prom, road) = if j == 0 {
                    (
                        Rect::new(cell.x0, cell.z0, cell.x1, PROMENADE_HALF),
                        Rect::new(cell.x0, PROMENADE_HALF, cell.x1, cell.z1),
                    )
                } else {
                    (
                        Rect::new(cell.x0, -PROMENADE_HALF, cell.x1, cell.z1),
                        Rect::new(cell.x0, cell.z0, cell.x1, -PROMENADE_HALF),
                    )
                };
                out.push(Prim::Ground {
                    r: prom,
                    mat: COBBLE,
                    c: cobble,
                });
                out.push(Prim::Ground {
                    r: road,
                    mat: ASPHALT,
                    c: asphalt,
                });
            } else {
                out.push(Prim::Ground {
                    r: cell,
                    mat: ASPHALT,
                    c: asphalt,
                });
            }
        }
        let paving = shade(srgb(196, 190, 178), rng.range(0.92, 1.05));
        match kind {
            Kind::Central => self.plan_central(block, &mut rng, out),
            Kind::Square => self.plan_square(block, &mut rng, out),
            Kind::Park => {
                out.push(Prim::Slab {
                    r: block,
                    mat: GRASS,
                    c: shade([255; 4], rng.range(0.85, 1.0)),
                });
                self.plan_park(block.inset(3.0), &mut rng, out);
            }
            Kind::Landmark => {
                out.push(Prim::Slab {
                    r: block,
                    mat: PAVING,
                    c: paving,
                });
                self.street_trees(i, j, block, &mut rng, out);
                self.plan_landmark(block.inset(5.0), &mut rng, out);
            }
            Kind::Buildings => {
                out.push(Prim::Slab {
                    r: block,
                    mat: PAVING,
                    c: paving,
                });
                self.street_trees(i, j, block, &mut rng, out);
                let sidewalk = rng.range(4.0, 5.0);
                let c = block.cx() / 700.0;
                let d = block.cz() / 700.0;
                let district = 0.5 + 0.5 * self.district.fbm(c, d, 3);
                self.plan_buildings(block.inset(sidewalk), district, &mut rng, out);
            }
        }
    }

    fn tree(
        &self,
        x: f32,
        z: f32,
        species: Species,
        height: f32,
        radius: f32,
        rng: &mut Rand,
    ) -> Tree {
        let mut color = rng.pick(&leaf_palette());
        if species == Species::Spruce {
            color = shade(color, 0.75);
        }
        Tree {
            x,
            y: 0.0,
            z,
            height,
            radius,
            species,
            color,
            key: hash(&[self.seed, x.to_bits() as u64, z.to_bits() as u64]),
            sink: 0.0,
        }
    }

    fn push_tree(out: &mut Vec<Prim>, t: Tree) {
        if City::clear(t.x, t.z, t.reach()) {
            out.push(Prim::Tree(t));
        }
    }

    fn street_trees(&self, i: i64, j: i64, block: Rect, rng: &mut Rand, out: &mut Vec<Prim>) {
        let lined = |lines: &Lines, s: i64| lines.tree_lined[lines.idx(s)];
        let inset = 2.0;
        // (lined?, start, end, fixed coordinate, along x?)
        let sides = [
            (
                lined(&self.z, j),
                block.x0,
                block.x1,
                block.z0 + inset,
                true,
            ),
            (
                lined(&self.z, j + 1),
                block.x0,
                block.x1,
                block.z1 - inset,
                true,
            ),
            (
                lined(&self.x, i),
                block.z0,
                block.z1,
                block.x0 + inset,
                false,
            ),
            (
                lined(&self.x, i + 1),
                block.z0,
                block.z1,
                block.x1 - inset,
                false,
            ),
        ];
        let species = if unit_of(hash(&[self.seed, TAG_TREELINE, i as u64, j as u64])) < 0.2 {
            Species::Poplar
        } else {
            Species::Broadleaf
        };
        for (is_lined, a0, a1, fixed, along_x) in sides {
            if !is_lined {
                continue;
            }
            let mut a = a0 + 6.0;
            while a < a1 - 6.0 {
                let (x, z) = if along_x { (a, fixed) } else { (fixed, a) };
                let h = rng.range(7.0, 11.0);
                let r = if species == Species::Poplar {
                    rng.range(1.3, 1.7)
                } else {
                    rng.range(1.6, 2.2)
                };
                let h = if species == Species::Poplar {
                    h + 4.0
                } else {
                    h
                };
                let t = self.tree(x, z, species, h, r, rng);
                City::push_tree(out, t);
                a += rng.range(11.0, 14.0);
            }
        }
    }

    fn plan_central(&self, block: Rect, rng: &mut Rand, out: &mut Vec<Prim>) {
        // Trees along the rim of the plaza, where they stay clear of the free zones.
        let step = 12.0;
        let mut edges = Vec::new();
        let mut a = block.x0 + 4.0;
        while a < block.x1 - 4.0 {
            edges.push((a, block.z0 + 4.0));
            edges.push((a, block.z1 - 4.0));
            a += step;
        }
        let mut a = block.z0 + 4.0 + step;
        while a < block.z1 - 4.0 - step * 0.5 {
            edges.push((block.x0 + 4.0, a));
            edges.push((block.x1 - 4.0, a));
            a += step;
        }
        for (x, z) in edges {
            let t = self.tree(
                x,
                z,
                Species::Broadleaf,
                rng.range(8.0, 12.0),
                rng.range(2.0, 2.8),
                rng,
            );
            City::push_tree(out, t);
        }
    }

    fn plan_square(&self, block: Rect, rng: &mut Rand, out: &mut Vec<Prim>) {
        if rng.chance(0.6) {
            let s = rng.range(1.4, 2.2);
            let r = Rect::new(
                block.cx() - s,
                block.cz() - s,
                block.cx() + s,
                block.cz() + s,
            );
            if City::rect_clear(&r) {
                out.push(Prim::Building {
                    r,
                    y0: 0.0,
                    y1: rng.range(5.0, 12.0),
                    roof: Roof::Pyramid { h: 2.0 * s },
                    cf: srgb(200, 196, 186),
                    cr: srgb(180, 176, 168),
                });
            }
        }
        if rng.chance(0.7) {
            let b = block.inset(4.0);
            for (x, z) in [(b.x0, b.z0), (b.x1, b.z0), (b.x0, b.z1), (b.x1, b.z1)] {
                let t = self.tree(
                    x,
                    z,
                    Species::Broadleaf,
                    rng.range(7.0, 10.0),
                    rng.range(2.0, 2.6),
                    rng,
                );
                City::push_tree(out, t);
            }
        }
    }

    fn plan_park(&self, area: Rect, rng: &mut Rand, out: &mut Vec<Prim>) {
        let step = 13.0;
        let nx = (area.w() / step).floor().max(1.0) as i32;
        let nz = (area.d() / step).floor().max(1.0) as i32;
        let (sx, sz) = (area.w() / nx as f32, area.d() / nz as f32);
        for a in 0..nx {
            for b in 0..nz {
                let u = rng.unit();
                let x = area.x0 + sx * (a as f32 + rng.range(0.25, 0.75));
                let z = area.z0 + sz * (b as f32 + rng.range(0.25, 0.75));
                let (species, h, r) = if u < 0.32 {
                    (
                        Species::Broadleaf,
                        rng.range(8.0, 16.0),
                        rng.range(2.5, 4.0),
                    )
                } else if u < 0.44 {
                    (Species::Spruce, rng.range(9.0, 18.0), rng.range(2.2, 3.2))
                } else if u < 0.52 {
                    (Species::Birch, rng.range(8.0, 13.0), rng.range(1.8, 2.6))
                } else if u < 0.58 {
                    (Species::Poplar, rng.range(12.0, 18.0), rng.range(1.4, 1.9))
                } else if u < 0.64 {
                    (Species::Shrub, rng.range(1.2, 2.2), rng.range(1.0, 1.8))
                } else {
                    continue;
                };
                let r = r.min(0.5 * sx.min(sz));
                let t = self.tree(x, z, species, h, r, rng);
                City::push_tree(out, t);
            }
        }
    }

    fn plan_landmark(&self, inner: Rect, rng: &mut Rand, out: &mut Vec<Prim>) {
        let stone = rng.pick(&[
            srgb(214, 200, 170),
            srgb(190, 186, 178),
            srgb(200, 170, 140),
        ]);
        let roof_c = rng.pick(&[srgb(96, 150, 130), srgb(72, 78, 88)]);
        let s = rng.range(10.0, 15.0).min(0.8 * inner.w().min(inner.d()));
        let along_x = inner.w() >= inner.d();
        let (long, short) = if along_x {
            (inner.w(), inner.d())
        } else {
            (inner.d(), inner.w())
        };
        let with_nave = long >= s + 30.0 && short >= 16.0;
        // Tower footprint: at the start of the long axis with a nave, else in the middle.
        let (tx, tz) = if with_nave {
            if along_x {
                (inner.x0 + 0.5 * s, inner.cz())
            } else {
                (inner.cx(), inner.z0 + 0.5 * s)
            }
        } else {
            (inner.cx(), inner.cz())
        };
        let tower = Rect::new(tx - 0.5 * s, tz - 0.5 * s, tx + 0.5 * s, tz + 0.5 * s);
        let body_h = rng.range(40.0, 68.0);
        let belfry_h = rng.range(8.0, 12.0);
        let b = 0.35 * s;
        let belfry = Rect::new(tx - b, tz - b, tx + b, tz + b);
        let spire = rng.range(15.0, 30.0);
        let mut parts = vec![
            Prim::Building {
                r: tower,
                y0: 0.0,
                y1: body_h,
                roof: Roof::Flat,
                cf: stone,
                cr: shade(stone, 0.8),
            },
            Prim::Building {
                r: belfry,
                y0: body_h,
                y1: body_h + belfry_h,
                roof: Roof::Pyramid { h: spire },
                cf: stone,
                cr: roof_c,
            },
        ];
        if with_nave {
            let len = (long - s - 2.0).min(rng.range(35.0, 50.0));
            let wid = (short - 2.0).min(rng.range(14.0, 18.0));
            let nave = if along_x {
                Rect::new(tower.x1, tz - 0.5 * wid, tower.x1 + len, tz + 0.5 * wid)
            } else {
                Rect::new(tx - 0.5 * wid, tower.z1, tx + 0.5 * wid, tower.z1 + len)
            };
            parts.push(Prim::Building {
                r: nave,
                y0: 0.0,
                y1: rng.range(14.0, 20.0),
                roof: Roof::Gable { h: 0.45 * wid },
                cf: stone,
                cr: roof_c,
            });
        }
        for p in parts {
            if let Prim::Building { r, .. } = p {
                if City::rect_clear(&r) {
                    out.push(p);
                }
            }
        }
    }

    /// Cuts `[a0, a1]` into lots 6–20 m wide, sometimes separated by a narrow alley.
    fn lots(a0: f32, a1: f32, rng: &mut Rand) -> Vec<(f32, f32)> {
        let mut v = Vec::new();
        let mut a = a0;
        while a1 - a >= 4.0 {
            let mut w = rng.range(6.0, 20.0);
            if a1 - (a + w) < 6.0 {
                w = a1 - a;
            }
            v.push((a, a + w));
            a += w;
            if rng.chance(0.12) {
                a += rng.range(1.0, 2.5);
            }
        }
        v
    }

    fn plan_buildings(&self, inner: Rect, district: f32, rng: &mut Rand, out: &mut Vec<Prim>) {
        if !inner.is_valid() {
            return;
        }
        let bd = rng.range(9.0, 15.0);
        let palette = facade_palette();
        let block_colors = [rng.pick(&palette), rng.pick(&palette), rng.pick(&palette)];
        let base_floors = 2.0 + 7.0 * district.clamp(0.0, 1.0);
        let mut lot_rects = Vec::new();
        if inner.w() < 2.0 * bd + 8.0 || inner.d() < 2.0 * bd + 8.0 {
            let along_x = inner.w() >= inner.d();
            let (l0, l1, d0, d1) = if along_x {
                (inner.x0, inner.x1, inner.z0, inner.z1)
            } else {
                (inner.z0, inner.z1, inner.x0, inner.x1)
            };
            let depth = d1 - d0;
            let rows: Vec<(f32, f32)> = if depth > 28.0 {
                let m = 0.5 * (d0 + d1);
                vec![(d0, m - 1.0), (m + 1.0, d1)]
            } else {
                vec![(d0, d1)]
            };
            for (r0, r1) in rows {
                for (a, b) in City::lots(l0, l1, rng) {
                    let back = rng.range(0.0, 2.0).min(0.3 * (r1 - r0));
                    let (r0b, r1b) = if r0 == d0 {
                        (r0, r1 - back)
                    } else {
                        (r0 + back, r1)
                    };
                    lot_rects.push(if along_x {
                        Rect::new(a, r0b, b, r1b)
                    } else {
                        Rect::new(r0b, a, r1b, b)
                    });
                }
            }
        } else {
            let dmax = bd + 2.0;
            for (a, b) in City::lots(inner.x0, inner.x1, rng) {
                let d = bd + rng.range(-2.0, 2.0);
                lot_rects.push(Rect::new(a, inner.z0, b, inner.z0 + d));
                let d = bd + rng.range(-2.0, 2.0);
                lot_rects.push(Rect::new(a, inner.z1 - d, b, inner.z1));
            }
            let (z0, z1) = (inner.z0 + dmax + 0.5, inner.z1 - dmax - 0.5);
            for (a, b) in City::lots(z0, z1, rng) {
                let d = bd + rng.range(-2.0, 2.0);
                lot_rects.push(Rect::new(inner.x0, a, inner.x0 + d, b));
                let d = bd + rng.range(-2.0, 2.0);
                lot_rects.push(Rect::new(inner.x1 - d, a, inner.x1, b));
            }
            let court = Rect::new(
                inner.x0 + dmax + 2.0,
                z0 + 2.0,
                inner.x1 - dmax - 2.0,
                z1 - 2.0,
            );
            if court.w() > 14.0 && court.d() > 14.0 {
                let u = rng.unit();
                if u < 0.35 {
                    let r = (0.25 * court.w().min(court.d())).min(3.5);
                    let t = self.tree(
                        court.cx(),
                        court.cz(),
                        Species::Broadleaf,
                        rng.range(7.0, 12.0),
                        r,
                        rng,
                    );
                    City::push_tree(out, t);
                } else if u < 0.6 {
                    let (w, d) = (rng.range(4.0, 8.0), rng.range(3.0, 6.0));
                    let r = Rect::new(
                        court.cx() - w,
                        court.cz() - d,
                        court.cx() + w,
                        court.cz() + d,
                    );
                    if City::rect_clear(&r) {
                        out.push(Prim::Building {
                            r,
                            y0: 0.0,
                            y1: rng.range(2.2, 3.2),
                            roof: Roof::Flat,
                            cf: rng.pick(&block_colors),
                            cr: rng.pick(&flat_roof_palette()),
                        });
                    }
                }
            }
        }
        for r in lot_rects {
            if r.w() < 2.5 || r.d() < 2.5 || !City::rect_clear(&r) {
                continue;
            }
            self.building(r, base_floors, &block_colors, rng, out);
        }
    }

    /// A building on lot `r`: optional darker plinth, walls, roof, and a chimney on pitched roofs
    /// or a stair house on tall flat ones.
    fn building(
        &self,
        r: Rect,
        base_floors: f32,
        colors: &[[u8; 4]; 3],
        rng: &mut Rand,
        out: &mut Vec<Prim>,
    ) {
        let wall_h = if rng.chance(0.04) {
            rng.range(2.2, 3.2)
        } else {
            let floors = (base_floors + rng.range(-2.5, 2.5))
                .round()
                .clamp(1.0, 11.0);
            floors * BAY + rng.range(0.3, 0.9)
        };
        let short = r.w().min(r.d());
        let long = r.w().max(r.d());
        let u = rng.unit();
        let pitch = rng.range(0.45, 0.9);
        let max_roof = (MAX_BUILDING_H - wall_h - 0.05).max(0.0);
        let h = (0.5 * short * pitch).min(max_roof);
        let roof_kind = if wall_h > 20.0 {
            if u < 0.75 || h < 1.0 {
                Roof::Flat
            } else {
                Roof::Hip { h }
            }
        } else if h < 1.0 || u < 0.3 {
            Roof::Flat
        } else if u < 0.75 {
            Roof::Gable { h }
        } else if long < 1.2 * short {
            Roof::Pyramid { h }
        } else {
            Roof::Hip { h }
        };
        let cf = shade(
            if rng.chance(0.6) {
                rng.pick(colors)
            } else {
                rng.pick(&facade_palette())
            },
            rng.range(0.9, 1.06),
        );
        let cr = if roof_kind == Roof::Flat {
            rng.pick(&flat_roof_palette())
        } else if rng.chance(0.03) {
            pitched_roof_palette()[5]
        } else {
            rng.pick(&pitched_roof_palette()[..5])
        };
        let plinth = if wall_h > 7.0 && rng.chance(0.6) {
            let ph = rng.range(3.4, 4.4);
            out.push(Prim::Walls {
                r,
                y1: ph,
                c: shade(cf, rng.range(0.62, 0.8)),
            });
            ph
        } else {
            0.0
        };
        out.push(Prim::Building {
            r,
            y0: plinth,
            y1: wall_h,
            roof: roof_kind,
            cf,
            cr: shade(cr, rng.range(0.9, 1.08)),
        });
        let extra = match roof_kind {
            Roof::Gable { h } | Roof::Hip { h } if rng.chance(0.6) => {
                // A chimney near the ridge, rising from the eaves through the roof.
                let s = 0.45;
                let (t, o) = (rng.range(0.25, 0.75), rng.range(-0.2, 0.2));
                let (cx, cz) = if r.w() >= r.d() {
                    (r.x0 + t * r.w(), r.cz() + o * r.d())
                } else {
                    (r.cx() + o * r.w(), r.z0 + t * r.d())
                };
                let top = (wall_h + h + rng.range(0.6, 1.4)).min(MAX_BUILDING_H);
                Some((
                    Rect::new(cx - s, cz - s, cx + s, cz + s),
                    top,
                    srgb(120, 70, 56),
                ))
            }
            Roof::Flat if wall_h > 9.0 && short > 9.0 && rng.chance(0.5) => {
                let (w, d) = (rng.range(1.5, 2.5), rng.range(1.5, 2.5));
                let cx = rng.range(r.x0 + 1.0 + w, r.x1 - 1.0 - w);
                let cz = rng.range(r.z0 + 1.0 + d, r.z1 - 1.0 - d);
                let top = (wall_h + rng.range(2.4, 3.0)).min(MAX_BUILDING_H);
                Some((
                    Rect::new(cx - w, cz - d, cx + w, cz + d),
                    top,
                    shade(cf, 0.8),
                ))
            }
            _ => None,
        };
        if let Some((rect, top, c)) = extra {
            if top > wall_h + 0.5 {
                out.push(Prim::Building {
                    r: rect,
                    y0: wall_h,
                    y1: top,
                    roof: Roof::Flat,
                    cf: c,
                    cr: shade(c, 0.7),
                });
            }
        }
    }
}

/// The plan of a whole city: every primitive plus the extent (for the report).
struct Plan {
    prims: Vec<Prim>,
    triangles: u64,
    blocks: usize,
}

fn plan(seed: u64, budget: u64) -> Plan {
    let est_blocks = budget as f64 / 400.0 + 16.0;
    let mut k = ((est_blocks.sqrt() * 0.8).ceil() as i64 + 4).max(6);
    // Reserve a few percent for the meadow trees that fill the budget exactly.
    let block_budget = budget - budget / 25;
    loop {
        if let Some(p) = plan_with(seed, budget, block_budget, k) {
            return p;
        }
        k *= 2;
    }
}

fn plan_with(seed: u64, budget: u64, block_budget: u64, k: i64) -> Option<Plan> {
    let city = City::new(seed, k);
    let outline = Noise::new(hash(&[seed, TAG_OUTLINE]));
    let mut cand: Vec<(f32, i64, i64)> = Vec::with_capacity((4 * k * k) as usize);
    for j in -k..k {
        for i in -k..k {
            let c = city.cell(i, j);
            let (x, z) = (c.cx(), c.cz());
            let r = (x * x + z * z).sqrt();
            let key = r * (1.0 + 0.3 * outline.fbm(x / 900.0, z / 900.0, 3));
            cand.push((key, i, j));
        }
    }
    cand.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut prims = Vec::new();
    let mut tris = 0u64;
    let mut accepted = HashSet::new();
    let mut block = Vec::new();
    for &(_, i, j) in &cand {
        block.clear();
        city.plan_block(i, j, &mut block);
        let t: u64 = block.iter().map(Prim::triangles).sum();
        if tris + t / 2 > block_budget && !accepted.is_empty() {
            break;
        }
        if i.abs() >= k - 1 || j.abs() >= k - 1 {
            return None;
        }
        tris += t;
        prims.extend_from_slice(&block);
        accepted.insert((i, j));
    }
    if accepted.len() == cand.len() {
        return None;
    }
    let blocks = accepted.len();
    // The rectangle of cells that hold city blocks; other cells in it and a frame around it are meadow.
    let (imin, imax) = accepted
        .iter()
        .fold((i64::MAX, i64::MIN), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let (jmin, jmax) = accepted
        .iter()
        .fold((i64::MAX, i64::MIN), |a, p| (a.0.min(p.1), a.1.max(p.1)));
    let grass = [255u8; 4];
    let mut x0 = f32::MAX;
    let mut x1 = f32::MIN;
    for j in jmin..=jmax {
        x0 = x0.min(city.xc(j, imin));
        x1 = x1.max(city.xc(j, imax + 1));
    }
    let z0 = city.z.centre[city.z.idx(jmin)];
    let z1 = city.z.centre[city.z.idx(jmax + 1)];
    let meadow = |r: Rect, prims: &mut Vec<Prim>, tris: &mut u64| {
        if r.is_valid() {
            prims.push(Prim::Ground {
                r,
                mat: GRASS,
                c: grass,
            });
            *tris += 2;
        }
    };
    for j in jmin..=jmax {
        for i in imin..=imax {
            if !accepted.contains(&(i, j)) {
                meadow(city.cell(i, j), &mut prims, &mut tris);
            }
        }
        let (zb0, zb1) = (
            city.z.centre[city.z.idx(j)],
            city.z.centre[city.z.idx(j + 1)],
        );
        meadow(
            Rect::new(x0, zb0, city.xc(j, imin), zb1),
            &mut prims,
            &mut tris,
        );
        meadow(
            Rect::new(city.xc(j, imax + 1), zb0, x1, zb1),
            &mut prims,
            &mut tris,
        );
    }
    let margin = (0.2 * (x1 - x0).max(z1 - z0)).max(150.0);
    let (fx0, fx1, fz0, fz1) = (x0 - margin, x1 + margin, z0 - margin, z1 + margin);
    for r in [
        Rect::new(fx0, fz0, fx1, z0),
        Rect::new(fx0, z1, fx1, fz1),
        Rect::new(fx0, z0, x0, z1),
        Rect::new(x1, z0, fx1, z1),
    ] {
        meadow(r, &mut prims, &mut tris);
    }
    // Meadow trees fill the rest of the budget, densest where a noise field says "wood".
    if tris < budget {
        let wood = Noise::new(hash(&[seed, TAG_OUTSKIRTS]));
        let step = 14.0;
        let nx = ((fx1 - fx0) / step) as i64;
        let nz = ((fz1 - fz0) / step) as i64;
        let band_of = |z: f32| -> Option<i64> {
            if z < z0 || z >= z1 {
                return None;
            }
            let lo = city.z.idx(jmin);
            let hi = city.z.idx(jmax + 1);
            let p = city.z.centre[lo..=hi].partition_point(|&c| c <= z);
            Some(jmin + p as i64 - 1)
        };
        let mut cands: Vec<(f32, f32, f32, u64)> = Vec::new();
        for b in 0..nz {
            for a in 0..nx {
                let h = hash(&[seed, TAG_OUTSKIRTS, a as u64, b as u64]);
                let x = fx0 + step * (a as f32 + 0.15 + 0.7 * unit_of(h));
                let z = fz0 + step * (b as f32 + 0.15 + 0.7 * unit_of(h.rotate_left(21)));
                if let Some(j) = band_of(z) {
                    if x >= x0 && x < x1 {
                        let i = (imin..=imax)
                            .find(|&i| x < city.xc(j, i + 1))
                            .unwrap_or(imax);
                        if accepted.contains(&(i, j)) {
                            continue;
                        }
                        // Keep off the streets of neighbouring blocks.
                        let c = city.cell(i, j).inset(8.0);
                        if !(c.is_valid() && x > c.x0 && x < c.x1 && z > c.z0 && z < c.z1) {
                            continue;
                        }
                    }
                }
                let d = (0.45 + 1.1 * wood.fbm(x / 300.0, z / 300.0, 3)).clamp(0.03, 1.0);
                let prio = (unit_of(h.rotate_left(42)) + 1e-6) / d;
                cands.push((prio, x, z, h));
            }
        }
        cands.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.3.cmp(&b.3)));
        for &(_, x, z, h) in &cands {
            if tris >= budget {
                break;
            }
            let mut rng = Rand::new(h);
            let u = rng.unit();
            let (species, ht, r) = if u < 0.45 {
                (
                    Species::Broadleaf,
                    rng.range(7.0, 16.0),
                    rng.range(2.5, 4.5),
                )
            } else if u < 0.7 {
                (Species::Spruce, rng.range(8.0, 20.0), rng.range(2.0, 3.5))
            } else if u < 0.85 {
                (Species::Birch, rng.range(8.0, 14.0), rng.range(1.8, 2.8))
            } else {
                (Species::Shrub, rng.range(1.0, 2.4), rng.range(1.0, 2.0))
            };
            let t = city.tree(x, z, species, ht, r, &mut rng);
            if !City::clear(t.x, t.z, t.reach()) {
                continue;
            }
            let n = t.triangles();
            if tris + n > budget + 25 {
                continue;
            }
            tris += n;
            prims.push(Prim::Tree(t));
        }
    }
    Some(Plan {
        prims,
        triangles: tris,
        blocks,
    })
}

/// Materials and textures of the city, in the order of the material constants above.
fn materials(b: &mut SceneBuilder) {
    let facade = b.add_texture(textures::facade());
    let asphalt = b.add_texture(textures::asphalt());
    let cobble = b.add_texture(textures::cobblestone());
    let grass = b.add_texture(textures::grass());
    let white = [1.0, 1.0, 1.0, 1.0];
    let m = |name: &str, texture: Option<u32>| Material {
        name: name.into(),
        base_color: white,
        texture,
    };
    let ids = [
        b.add_material(m("city-facade", Some(facade))),
        b.add_material(m("city-roof", None)),
        b.add_material(m("city-asphalt", Some(asphalt))),
        b.add_material(m("city-cobblestone", Some(cobble))),
        b.add_material(m("city-paving", None)),
        b.add_material(m("city-grass", Some(grass))),
        b.add_material(m("tree-trunk", None)),
        b.add_material(m("tree-foliage", None)),
    ];
    debug_assert_eq!(ids, [0, 1, 2, 3, 4, 5, 6, 7]);
}

/// Builds the city into `b`; returns the number of city blocks.
pub fn build(seed: u64, triangles: u64, b: &mut SceneBuilder) -> usize {
    let plan = plan(seed, triangles);
    debug_assert!(plan.triangles > 0);
    materials(b);
    let anchors: Vec<(usize, (f32, f32))> =
        plan.prims.iter().map(Prim::anchor).enumerate().collect();
    let prims = &plan.prims;
    let meshes = emit_tiled(&anchors, MESH_TILE, &|i, e| prims[i].emit(e), MATERIALS);
    for m in meshes {
        b.add_mesh(m);
    }
    plan.blocks
}
