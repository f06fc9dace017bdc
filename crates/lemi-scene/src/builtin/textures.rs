//! Procedural, seamlessly tiling RGBA8 sRGB textures for the built-in scenes: a facade with window
//! bays, asphalt, cobblestones (a periodic Voronoi pattern, Worley 1996, "A cellular texture basis
//! function"), grass, wooden floor boards, and a neutral detail texture for terrain and forest
//! floor.
//!
//! Textures do not depend on the scene seed: they are the same for every spec.

use lemi_core::Texture;

use super::rng::{hash, unit_of};

fn make(name: &str, size: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> Texture {
    let mut rgba8 = Vec::with_capacity((size * size * 4) as usize);
    for y in 0..size {
        for x in 0..size {
            let c = f(x, y);
            rgba8.extend_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    Texture {
        name: name.into(),
        width: size,
        height: size,
        rgba8,
    }
}

/// Per-pixel white noise in `[-1, 1)`.
fn grain(tag: u64, x: u32, y: u32) -> f32 {
    2.0 * unit_of(hash(&[tag, x as u64, y as u64])) - 1.0
}

/// Periodic value noise in `[0, 1)`: lattice of `cells` per texture side, bilinear with smoothstep.
fn value(tag: u64, size: u32, cells: u32, x: u32, y: u32) -> f32 {
    let fx = x as f32 * cells as f32 / size as f32;
    let fy = y as f32 * cells as f32 / size as f32;
    let (ix, iy) = (fx.floor() as u32, fy.floor() as u32);
    let (tx, ty) = (fx - ix as f32, fy - iy as f32);
    let s = |t: f32| t * t * (3.0 - 2.0 * t);
    let l = |i: u32, j: u32| unit_of(hash(&[tag, (i % cells) as u64, (j % cells) as u64]));
    let (a, b) = (l(ix, iy), l(ix + 1, iy));
    let (c, d) = (l(ix, iy + 1), l(ix + 1, iy + 1));
    let (u, v) = (s(tx), s(ty));
    let top = a + (b - a) * u;
    let bot = c + (d - c) * u;
    top + (bot - top) * v
}

fn clamp8(v: f32) -> u8 {
    v.clamp(0.0, 255.0) as u8
}

/// 256×256 facade covering 2 bays × 2 floors ([`super::geom::FACADE_TILE`] metres square). Walls are
/// near-white so the per-building vertex colour tints them; windows are dark glass in light frames.
pub fn facade() -> Texture {
    const N: u32 = 256;
    make("builtin-facade", N, |x, y| {
        let bx = x % 128;
        let fy = y % 128;
        let floor = y / 128;
        let bay = x / 128;
        let n = 6.0 * grain(1, x, y) + 10.0 * value(2, N, 16, x, y);
        let wall = [232.0 + n, 228.0 + n, 220.0 + n];
        // Window 1.4 m × 1.9 m (40 px per metre), frame 4 px, sill below.
        let (wx0, wx1, wy0, wy1) = (36, 92, 22, 98);
        let c = if (wx0..wx1).contains(&bx) && (wy0..wy1).contains(&fy) {
            let frame = bx < wx0 + 4 || bx >= wx1 - 4 || fy < wy0 + 4 || fy >= wy1 - 4;
            let mullion = (62..66).contains(&bx) || (50..53).contains(&fy);
            if frame || mullion {
                [214.0, 212.0, 204.0]
            } else if floor == 0 && bay == 1 && fy < 60 {
                // A window with drawn blinds.
                [180.0 + n, 170.0 + n, 150.0 + n]
            } else {
                let refl = 30.0 * (1.0 - (fy - wy0) as f32 / (wy1 - wy0) as f32);
                [46.0 + refl, 58.0 + refl, 74.0 + refl]
            }
        } else if (wx0 - 4..wx1 + 4).contains(&bx) && (wy1..wy1 + 6).contains(&fy) {
            [176.0, 172.0, 166.0]
        } else if fy >= 122 {
            // Floor band.
            [196.0 + n, 192.0 + n, 184.0 + n]
        } else {
            wall
        };
        c.map(clamp8)
    })
}

/// 128×128 asphalt, 4 m square.
pub fn asphalt() -> Texture {
    const N: u32 = 128;
    make("builtin-asphalt", N, |x, y| {
        let g = 72.0 + 14.0 * grain(3, x, y) + 16.0 * (value(4, N, 8, x, y) - 0.5);
        let speck = if unit_of(hash(&[5, x as u64, y as u64])) > 0.97 {
            40.0
        } else {
            0.0
        };
        let v = g + speck;
        [v, v, v + 3.0].map(clamp8)
    })
}

/// 256×256 cobblestones, 2 m square (10 × 10 stones).
pub fn cobblestone() -> Texture {
    const N: u32 = 256;
    const CELLS: i64 = 10;
    make("builtin-cobblestone", N, |x, y| {
        let px = x as f32 * CELLS as f32 / N as f32;
        let py = y as f32 * CELLS as f32 / N as f32;
        let (cx, cy) = (px.floor() as i64, py.floor() as i64);
        let (mut f1, mut f2, mut id) = (f32::MAX, f32::MAX, 0u64);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (gx, gy) = (cx + dx, cy + dy);
                let key = hash(&[6, gx.rem_euclid(CELLS) as u64, gy.rem_euclid(CELLS) as u64]);
                let jx = gx as f32 + 0.2 + 0.6 * unit_of(key);
                let jy = gy as f32 + 0.2 + 0.6 * unit_of(key.rotate_left(24));
                let d = (px - jx) * (px - jx) + (py - jy) * (py - jy);
                if d < f1 {
                    f2 = f1;
                    f1 = d;
                    id = key;
                } else if d < f2 {
                    f2 = d;
                }
            }
        }
        let edge = f2.sqrt() - f1.sqrt();
        let n = 8.0 * grain(7, x, y);
        if edge < 0.09 {
            [78.0 + n, 74.0 + n, 70.0 + n].map(clamp8)
        } else {
            let t = unit_of(id.rotate_left(48));
            let dome = (1.0 - f1.sqrt()).clamp(0.0, 1.0) * 30.0;
            let base = 118.0 + 50.0 * t + dome + n;
            [base + 6.0, base, base - 8.0 - 10.0 * t].map(clamp8)
        }
    })
}

/// 128×128 grass, 3 m square.
pub fn grass() -> Texture {
    const N: u32 = 128;
    make("builtin-grass", N, |x, y| {
        let v = value(8, N, 8, x, y);
        let g = 20.0 * grain(9, x, y);
        [
            70.0 + 30.0 * v + 0.4 * g,
            128.0 + 40.0 * v + g,
            48.0 + 16.0 * v + 0.3 * g,
        ]
        .map(clamp8)
    })
}

/// 128×128 neutral detail (light grey noise), 8 m square: multiplies the vertex colours of terrain
/// and forest floor.
pub fn detail() -> Texture {
    const N: u32 = 128;
    make("builtin-detail", N, |x, y| {
        let v = 214.0 + 26.0 * value(10, N, 16, x, y) + 12.0 * grain(11, x, y);
        [v, v, v].map(clamp8)
    })
}

/// 128×128 wooden floor boards, 2 m square: 8 boards 0.25 m wide running along `u`, each with its
/// own tone and one end joint per tile at its own place, dark gaps between boards, fine grain.
/// Near-white so the vertex colour gives the wood its colour.
pub fn planks() -> Texture {
    const N: u32 = 128;
    const BOARD: u32 = N / 8;
    make("builtin-planks", N, |x, y| {
        let board = (y / BOARD) as u64;
        let key = hash(&[12, board]);
        let joint = (unit_of(key) * N as f32) as u32;
        let tone = 22.0 * (unit_of(key.rotate_left(32)) - 0.5);
        let streak = 16.0 * value(13, N, 32, x / 8, y) + 6.0 * grain(14, x, y);
        let gap = y % BOARD == 0 || x == joint;
        let v = if gap { 120.0 } else { 206.0 + tone + streak };
        [v + 8.0, v, v - 10.0].map(clamp8)
    })
}
