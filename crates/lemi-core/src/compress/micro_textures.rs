//! Micro-textures: cuts the opaque regions of a layer image into few, well-filled rectangles, each
//! becoming one textured impostor quad.
//!
//! This work is based on: GI 2002 sec. 5.3 (Jeschke, Wimmer et al.). The image is overlaid with a
//! regular grid (8×8-texel cells in the paper). While a cell that is not completely transparent is
//! left, one is chosen (here: the first in row-major order) and grown one cell row and/or column at a
//! time, in any of the 8 directions (diagonals add a row and a column), keeping a rectangle; each
//! step takes the direction with the best fraction of opaque texels, and growth stops when that
//! fraction would fall below the threshold or no direction adds a non-transparent cell. The
//! rectangle becomes a micro-texture and its cells are set to transparent.
//!
//! Details fixed here:
//! - texels of cells already taken by an earlier micro-texture count as transparent (the paper sets
//!   the cells to transparent) and are left transparent in the later micro-texture's pixels, so
//!   **every opaque texel lies in exactly one micro-texture** (checked by
//!   [`analyze_micro_textures`]); their quads may overlap only in transparent texels;
//! - ties between directions go to the one adding more opaque texels, then to the order
//!   E, S, W, N, SE, SW, NE, NW;
//! - the final rectangle is shrunk to the bounding box of the opaque texels it owns;
//! - every micro-texture of more than one grid cell has an opaque fraction ≥ the threshold;
//! - then (unless [`MicroTextureOptions::merge`] is off) micro-textures of the layer that share a
//!   whole edge are merged into one rectangle, left-right and top-bottom, as long as both are of
//!   one kind (all texels opaque, or not) and the union keeps an opaque fraction ≥ the threshold:
//!   the growth stops short of a neighbour whose first row or column is sparse, and more than
//!   half of a city layer's micro-textures then touch another along a whole edge. The union adds
//!   no texel (the two rectangles tile it exactly), so there are fewer, larger quads with the
//!   same texels: a software rasterizer spends about as much on setting up a small quad as on
//!   filling a few hundred pixels, and a GPU's cost per draw is a quad's too.
//!
//! A micro-texture knows its quad: [`MicroTexture::corners`] gives the 3D corners with the texel
//! convention of [`crate::face`].

use glam::DVec3;

use super::layer_image::LayerImage;
use super::CompressError;
use crate::face::Face;

/// Parameters of micro-texture extraction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MicroTextureOptions {
    /// Grid cell side in texels (the paper used 8).
    pub cell_size: u32,
    /// Minimum fraction of opaque texels (0..=1) a rectangle keeps while it grows.
    pub threshold: f64,
    /// Merge micro-textures that share a whole edge (see the module docs); off gives the paper's
    /// micro-textures unchanged.
    pub merge: bool,
}

impl Default for MicroTextureOptions {
    fn default() -> Self {
        MicroTextureOptions {
            cell_size: 8,
            threshold: 0.6,
            merge: true,
        }
    }
}

impl MicroTextureOptions {
    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), CompressError> {
        if self.cell_size == 0 {
            return Err(CompressError::BadOption {
                option: "micro-texture cell size",
                reason: "must be at least 1 texel".into(),
            });
        }
        if !(0.0..=1.0).contains(&self.threshold) {
            return Err(CompressError::BadOption {
                option: "micro-texture threshold",
                reason: format!("{} is not a fraction in [0, 1]", self.threshold),
            });
        }
        Ok(())
    }
}

/// A texel rectangle `[x0, x1) × [y0, y1)` of a face image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TexelRect {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl TexelRect {
    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }
    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }
    pub fn area(&self) -> u64 {
        self.width() as u64 * self.height() as u64
    }
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x0 && x < self.x1 && y >= self.y0 && y < self.y1
    }

    /// The whole `res × res` image.
    pub fn full(res: u32) -> TexelRect {
        TexelRect {
            x0: 0,
            y0: 0,
            x1: res,
            y1: res,
        }
    }

    /// The empty rectangle.
    pub fn empty() -> TexelRect {
        TexelRect {
            x0: 0,
            y0: 0,
            x1: 0,
            y1: 0,
        }
    }

    /// Whether the rectangle holds no texel.
    pub fn is_empty(&self) -> bool {
        self.x1 <= self.x0 || self.y1 <= self.y0
    }

    /// Number of texels (0 when empty).
    pub fn texels(&self) -> u64 {
        if self.is_empty() {
            0
        } else {
            self.area()
        }
    }

    /// The smallest rectangle holding both.
    pub fn union(&self, o: &TexelRect) -> TexelRect {
        match (self.is_empty(), o.is_empty()) {
            (true, _) => *o,
            (_, true) => *self,
            _ => TexelRect {
                x0: self.x0.min(o.x0),
                y0: self.y0.min(o.y0),
                x1: self.x1.max(o.x1),
                y1: self.y1.max(o.y1),
            },
        }
    }

    /// The linear index ranges (row-major, `res` texels a row) of the rectangle's rows.
    pub fn rows(&self, res: u32) -> impl Iterator<Item = std::ops::Range<usize>> + use<> {
        let (r, c) = (res as usize, *self);
        let ys = if c.is_empty() {
            0..0
        } else {
            c.y0 as usize..c.y1 as usize
        };
        ys.map(move |y| y * r + c.x0 as usize..y * r + c.x1 as usize)
    }

    /// Grown by `by` texels on every side, clamped to a `res × res` image (empty stays empty).
    pub fn grown(&self, by: u32, res: u32) -> TexelRect {
        if self.is_empty() {
            return *self;
        }
        TexelRect {
            x0: self.x0.saturating_sub(by),
            y0: self.y0.saturating_sub(by),
            x1: self.x1.saturating_add(by).min(res),
            y1: self.y1.saturating_add(by).min(res),
        }
    }
}

/// One rectangle cut out of a layer image, and the impostor quad it becomes.
#[derive(Clone, Debug, PartialEq)]
pub struct MicroTexture {
    pub face: Face,
    /// Layer index within the face, nearest first.
    pub layer: u32,
    /// Layer distance from the reference viewpoint (metres).
    pub distance: f64,
    /// Resolution of the face image it was cut from.
    pub res: u32,
    /// Texels of the face image it covers.
    pub rect: TexelRect,
    /// `rect.width() · rect.height() · 4` RGBA bytes, row-major, row 0 at `rect.y0`.
    pub pixels: Vec<u8>,
}

impl MicroTexture {
    /// The quad's corners relative to the reference viewpoint: see [`quad_corners`].
    pub fn corners(&self) -> [DVec3; 4] {
        quad_corners(self.face, self.distance, self.res, self.rect)
    }

    /// Number of opaque texels.
    pub fn opaque_count(&self) -> u64 {
        self.pixels
            .chunks_exact(4)
            .filter(|p| p[3] >= super::OPAQUE_ALPHA)
            .count() as u64
    }
}

/// Corners of the impostor quad of texel rectangle `rect` on layer `distance` of face `face`,
/// relative to the reference viewpoint, in the order top-left, top-right, bottom-right, bottom-left
/// of the image (texel edges `(x0, y0)`, `(x1, y0)`, `(x1, y1)`, `(x0, y1)`). Texel edge `i` lies
/// at face coordinate `−1 + 2i/Res` and the point is `D · (forward + s · right + t · down)`
/// ([`Face::point`]).
pub fn quad_corners(face: Face, distance: f64, res: u32, rect: TexelRect) -> [DVec3; 4] {
    let e = |i: u32| Face::texel_edge(i as f64, res);
    [
        face.point(e(rect.x0), e(rect.y0), distance),
        face.point(e(rect.x1), e(rect.y0), distance),
        face.point(e(rect.x1), e(rect.y1), distance),
        face.point(e(rect.x0), e(rect.y1), distance),
    ]
}

/// What micro-texture extraction produced.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MicroTextureStats {
    /// Micro-textures (= impostor quads).
    pub micro_textures: u64,
    /// Opaque texels of the input layers.
    pub opaque_texels: u64,
    /// Texels of all micro-textures (transparent ones included).
    pub texels: u64,
    /// `opaque_texels / texels` (1 when there are none).
    pub fill_ratio: f64,
}

impl MicroTextureStats {
    /// Sums two statistics.
    pub fn add(&mut self, o: &MicroTextureStats) {
        self.micro_textures += o.micro_textures;
        self.opaque_texels += o.opaque_texels;
        self.texels += o.texels;
        self.fill_ratio = ratio(self.opaque_texels, self.texels);
    }
}

fn ratio(a: u64, b: u64) -> f64 {
    if b == 0 {
        1.0
    } else {
        a as f64 / b as f64
    }
}

/// Growth directions `(dx0, dy0, dx1, dy1)` in cells: E, S, W, N, SE, SW, NE, NW.
const DIRECTIONS: [(i64, i64, i64, i64); 8] = [
    (0, 0, 1, 0),
    (0, 0, 0, 1),
    (-1, 0, 0, 0),
    (0, -1, 0, 0),
    (0, 0, 1, 1),
    (-1, 0, 0, 1),
    (0, -1, 1, 0),
    (-1, -1, 0, 0),
];

/// Micro-texture extraction (GI 2002 sec. 5.3) from one layer image.
pub fn extract_micro_textures(
    image: &LayerImage,
    face: Face,
    layer: u32,
    distance: f64,
    options: &MicroTextureOptions,
) -> Result<(Vec<MicroTexture>, MicroTextureStats), CompressError> {
    image.validate()?;
    options.validate()?;
    let res = image.res as usize;
    let cs = options.cell_size as usize;
    let g = res.div_ceil(cs); // cells per side
    let cell_of = |x: usize, y: usize| (y / cs) * g + x / cs;
    let mut count = vec![0u64; g * g];
    let mut opaque_texels = 0u64;
    let c = image.content;
    for y in c.y0 as usize..c.y1 as usize {
        for x in c.x0 as usize..c.x1 as usize {
            if image.is_opaque(y * res + x) {
                count[cell_of(x, y)] += 1;
                opaque_texels += 1;
            }
        }
    }
    let area = |cx: usize, cy: usize| -> u64 {
        let w = (res - cx * cs).min(cs) as u64;
        let h = (res - cy * cs).min(cs) as u64;
        w * h
    };
    let mut owner: Vec<Option<u32>> = vec![None; g * g];
    let mut micros = Vec::new();
    let t = options.threshold;
    for start in 0..g * g {
        if count[start] == 0 || owner[start].is_some() {
            continue;
        }
        let free = |c: usize, owner: &[Option<u32>]| owner[c].is_none() && count[c] > 0;
        // rectangle in cells [x0, x1) × [y0, y1)
        let (mut x0, mut y0) = ((start % g) as i64, (start / g) as i64);
        let (mut x1, mut y1) = (x0 + 1, y0 + 1);
        let mut sum = count[start];
        let mut ar = area(start % g, start / g);
        loop {
            let mut best: Option<(u64, u64, [i64; 4])> = None; // (opaque, area, rect)
            for &(dx0, dy0, dx1, dy1) in &DIRECTIONS {
                let (nx0, ny0, nx1, ny1) = (x0 + dx0, y0 + dy0, x1 + dx1, y1 + dy1);
                if nx0 < 0 || ny0 < 0 || nx1 > g as i64 || ny1 > g as i64 {
                    continue;
                }
                let (mut add_sum, mut add_area, mut any_free) = (0u64, 0u64, false);
                for cy in ny0..ny1 {
                    for cx in nx0..nx1 {
                        if cx >= x0 && cx < x1 && cy >= y0 && cy < y1 {
                            continue;
                        }
                        let c = cy as usize * g + cx as usize;
                        add_area += area(cx as usize, cy as usize);
                        if free(c, &owner) {
                            any_free = true;
                            add_sum += count[c];
                        }
                    }
                }
                if !any_free {
                    continue;
                }
                let (s2, a2) = (sum + add_sum, ar + add_area);
                let better = match best {
                    None => true,
                    // fraction s2/a2 vs bs/ba, then more opaque texels added
                    Some((bs, ba, _)) => {
                        let (l, r) = (s2 as u128 * ba as u128, bs as u128 * a2 as u128);
                        l > r || (l == r && s2 > bs)
                    }
                };
                if better {
                    best = Some((s2, a2, [nx0, ny0, nx1, ny1]));
                }
            }
            match best {
                Some((s2, a2, r)) if s2 as f64 >= t * a2 as f64 => {
                    [x0, y0, x1, y1] = r;
                    sum = s2;
                    ar = a2;
                }
                _ => break,
            }
        }
        let id = micros.len() as u32;
        for cy in y0..y1 {
            for cx in x0..x1 {
                let c = cy as usize * g + cx as usize;
                if free(c, &owner) {
                    owner[c] = Some(id);
                }
            }
        }
        // bounding box of the owned opaque texels
        let (tx0, ty0) = (x0 as usize * cs, y0 as usize * cs);
        let (tx1, ty1) = ((x1 as usize * cs).min(res), (y1 as usize * cs).min(res));
        let owned = |x: usize, y: usize| owner[cell_of(x, y)] == Some(id);
        let (mut bx0, mut by0, mut bx1, mut by1) = (usize::MAX, usize::MAX, 0, 0);
        for y in ty0..ty1 {
            for x in tx0..tx1 {
                if owned(x, y) && image.is_opaque(y * res + x) {
                    bx0 = bx0.min(x);
                    by0 = by0.min(y);
                    bx1 = bx1.max(x + 1);
                    by1 = by1.max(y + 1);
                }
            }
        }
        let rect = TexelRect {
            x0: bx0 as u32,
            y0: by0 as u32,
            x1: bx1 as u32,
            y1: by1 as u32,
        };
        let mut pixels = Vec::with_capacity(rect.area() as usize * 4);
        for y in by0..by1 {
            for x in bx0..bx1 {
                let i = y * res + x;
                if owned(x, y) && image.is_opaque(i) {
                    pixels.extend_from_slice(&image.rgba[4 * i..4 * i + 4]);
                } else {
                    pixels.extend_from_slice(&super::TRANSPARENT);
                }
            }
        }
        micros.push(MicroTexture {
            face,
            layer,
            distance,
            res: image.res,
            rect,
            pixels,
        });
    }
    if options.merge {
        micros = merge_adjacent(micros, t);
    }
    let texels = micros.iter().map(|m| m.rect.area()).sum();
    let stats = MicroTextureStats {
        micro_textures: micros.len() as u64,
        opaque_texels,
        texels,
        fill_ratio: ratio(opaque_texels, texels),
    };
    Ok((micros, stats))
}

/// Merges micro-textures of one layer that share a whole edge (see the module docs), until none
/// is left to merge; the result keeps the order of each merged group's first member.
fn merge_adjacent(micros: Vec<MicroTexture>, threshold: f64) -> Vec<MicroTexture> {
    struct Part {
        first: usize,
        opaque: u64,
        micro: MicroTexture,
    }
    let full = |p: &Part| p.opaque == p.micro.rect.area();
    let mut parts: Vec<Part> = (micros.into_iter().enumerate())
        .map(|(first, micro)| Part {
            first,
            opaque: micro.opaque_count(),
            micro,
        })
        .collect();
    loop {
        let before = parts.len();
        for across in [true, false] {
            // neighbours along the merge direction come next to each other in this order
            parts.sort_by_key(|p| {
                let r = p.micro.rect;
                if across {
                    (r.y0, r.y1, r.x0)
                } else {
                    (r.x0, r.x1, r.y0)
                }
            });
            let mut merged: Vec<Part> = Vec::with_capacity(parts.len());
            for b in parts {
                let Some(a) = merged.last_mut() else {
                    merged.push(b);
                    continue;
                };
                let (ra, rb) = (a.micro.rect, b.micro.rect);
                let touch = if across {
                    ra.y0 == rb.y0 && ra.y1 == rb.y1 && ra.x1 == rb.x0
                } else {
                    ra.x0 == rb.x0 && ra.x1 == rb.x1 && ra.y1 == rb.y0
                };
                let (opaque, area) = (a.opaque + b.opaque, ra.area() + rb.area());
                if !(touch && full(a) == full(&b) && opaque as f64 >= threshold * area as f64) {
                    merged.push(b);
                    continue;
                }
                let pixels = if across {
                    let (wa, wb) = (4 * ra.width() as usize, 4 * rb.width() as usize);
                    let mut p = Vec::with_capacity(a.micro.pixels.len() + b.micro.pixels.len());
                    for (row_a, row_b) in
                        (a.micro.pixels.chunks_exact(wa)).zip(b.micro.pixels.chunks_exact(wb))
                    {
                        p.extend_from_slice(row_a);
                        p.extend_from_slice(row_b);
                    }
                    p
                } else {
                    let mut p = std::mem::take(&mut a.micro.pixels);
                    p.extend_from_slice(&b.micro.pixels);
                    p
                };
                a.micro.pixels = pixels;
                a.micro.rect = TexelRect {
                    x0: ra.x0,
                    y0: ra.y0,
                    x1: rb.x1,
                    y1: rb.y1,
                };
                a.opaque = opaque;
                a.first = a.first.min(b.first);
            }
            parts = merged;
        }
        if parts.len() == before {
            break;
        }
    }
    parts.sort_by_key(|p| p.first);
    parts.into_iter().map(|p| p.micro).collect()
}

/// Checks micro-textures against the layer image they were cut from: every rectangle inside the
/// image with a matching pixel buffer, every opaque texel of the image opaque in **exactly one**
/// micro-texture with its colour, and no opaque micro-texture texel that is transparent in the image.
/// Returns the statistics, or the first violation found.
pub fn analyze_micro_textures(
    image: &LayerImage,
    micros: &[MicroTexture],
) -> Result<MicroTextureStats, CompressError> {
    image.validate()?;
    let res = image.res as usize;
    let mut covered = vec![0u32; res * res];
    for (m, micro) in micros.iter().enumerate() {
        let r = micro.rect;
        if r.x0 >= r.x1 || r.y0 >= r.y1 || r.x1 as usize > res || r.y1 as usize > res {
            return Err(CompressError::Invalid(format!(
                "micro-texture {m}: rectangle {r:?} is empty or outside the {res}² image"
            )));
        }
        if micro.pixels.len() as u64 != r.area() * 4 {
            return Err(CompressError::Invalid(format!(
                "micro-texture {m}: {} pixel bytes for a {}×{} rectangle",
                micro.pixels.len(),
                r.width(),
                r.height()
            )));
        }
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                let j = ((y - r.y0) * r.width() + (x - r.x0)) as usize;
                let p = &micro.pixels[4 * j..4 * j + 4];
                if p[3] < super::OPAQUE_ALPHA {
                    continue;
                }
                let i = y as usize * res + x as usize;
                if p != &image.rgba[4 * i..4 * i + 4] {
                    return Err(CompressError::Invalid(format!(
                        "micro-texture {m}: texel ({x}, {y}) differs from the layer image"
                    )));
                }
                covered[i] += 1;
            }
        }
    }
    for (i, &c) in covered.iter().enumerate() {
        let want = u32::from(image.is_opaque(i));
        if c != want {
            return Err(CompressError::Invalid(format!(
                "texel ({}, {}) is opaque in {c} micro-textures, expected {want}",
                i % res,
                i / res
            )));
        }
    }
    let opaque_texels = image.opaque_count();
    let texels = micros.iter().map(|m| m.rect.area()).sum();
    Ok(MicroTextureStats {
        micro_textures: micros.len() as u64,
        opaque_texels,
        texels,
        fill_ratio: ratio(opaque_texels, texels),
    })
}
