//! Macro-texture packing: packs the micro-textures of a view cell into few power-of-two atlases.
//!
//! This work is based on: GI 2002 sec. 5.4 (Jeschke, Wimmer et al.), which uses a greedy packer:
//! 1. every micro-texture is rotated so that it is "top-down" (height ≥ width);
//! 2. the list is sorted by decreasing height, equal heights by increasing width;
//! 3. a new macro-texture gets the height of the first remaining micro-texture rounded up to a power
//!    of two, and the width `summed area of the remaining micro-textures / height`, rounded up to a
//!    power of two (here also at least the first one's width, and at most `max_size`);
//! 4. it is filled with the bottom-left rule (Chazelle) starting from the first of the list until the
//!    right border is reached, then the remaining space with the left-bottom rule starting from the
//!    last (smallest) micro-texture; what does not fit waits for the next macro-texture.
//!
//! "Bottom" is row 0 of the macro-texture here (mirroring does not change a packing). Phase 1 ends at
//! the first micro-texture that no longer fits on the bottom row. Free space is tracked as maximal
//! free rectangles, so both rules find the exact lowest-then-leftmost (resp. leftmost-then-lowest)
//! position where a rectangle fits. [`analyze_packing`] checks a packing: all inside, no overlap,
//! power-of-two sizes.
//!
//! A rotated micro-texture is turned 90° clockwise: its texel `(x, y)` of a `w × h` micro-texture
//! lands at `(px + h − 1 − y, py + x)`; see [`MacroPlacement::macro_texel`] and
//! [`MacroPlacement::macro_corners`].
//!
//! For a block-compressed format (`PackingOptions::block` = 4: BC7, BC1, KDFS secs. 21–22 encode
//! 4×4 texel blocks independently) every rectangle is packed with its size rounded up to a
//! multiple of the block side. All sizes, and the power-of-two macro sides (≥ 4), are then
//! multiples of it, so every corner of a maximal free rectangle and every position is too: each
//! micro-texture owns the whole blocks of its padded footprint, no block mixes two, and its own
//! texels keep their exact rectangle at the footprint's top-left. [`analyze_block_sharing`] checks it.
//!
//! **Stacks** (`PackingOptions::stack`, block formats): padding every micro-texture to whole
//! blocks costs most where they are thin. A grazing ground plane is cut by every slab into a
//! band one or two texels high across the face, and each band, a micro-texture of its own layer,
//! takes a whole block row: on a `builtin:city:1M` cell the micro-textures one texel thin take
//! 21 % of the padded texels for 5 % of the opaque ones. Micro-textures of one face whose texel
//! rectangles do not overlap in the face image can share its blocks instead: a *stack* is the
//! bounding rectangle of such micro-textures, holding each at its own place in the face image
//! (texels no member covers transparent), and the packer places and pads stacks instead of
//! micro-textures. A block of a stack is then a 4×4 patch of the face image as seen from the
//! cell's reference point, the image's own neighbouring texels (a band of ground and the next
//! slab's band above it), as coherent as a block of any texture; what padding was for stays
//! true: every member keeps its exact texel rectangle (the renderer clamps a quad's fetches to
//! it), and no block mixes two stacks. [`stack_rects`] builds the stacks greedily (below), a
//! pure function of the rectangles in their order, so a reader can derive them again
//! ([`pack_stacked`]).

use rayon::prelude::*;

use super::micro_textures::{MicroTexture, TexelRect};
use super::CompressError;

/// Parameters of macro-texture packing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PackingOptions {
    /// Largest macro-texture side (a power of two; GPUs guarantee 2048 on downlevel, 8192 usually).
    pub max_size: u32,
    /// Side of the texel blocks the macro-textures are encoded in: 1 (PNG, no alignment) or a
    /// power of two such as 4 (BC7, BC1): footprints are padded to, and placed on, multiples of it.
    pub block: u32,
    /// Sides that are not powers of two: a macro-texture's width is the remaining area over its
    /// height (not rounded up to a power of two), and once filled it is trimmed to the
    /// footprints it holds (its width to the rightmost footprint's right edge, its height to the
    /// topmost's), instead of the paper's power-of-two sides, which can double a texture. Every
    /// GPU lemi runs on samples textures of any size; the sides stay multiples of `block`.
    pub trim: bool,
    /// Pack micro-textures of one face in stacks that share blocks (see the module docs; only
    /// with `block` > 1): those whose shorter side is at most `stack` texels; 0: no stacks.
    /// Absent in the headers of cells written before it: 0.
    #[serde(default)]
    pub stack: u32,
}

impl Default for PackingOptions {
    fn default() -> Self {
        PackingOptions {
            max_size: 4096,
            block: 1,
            trim: false,
            stack: 0,
        }
    }
}

/// Where a micro-texture went.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MacroPlacement {
    /// Index of the macro-texture.
    pub macro_index: u32,
    /// Texel of the macro-texture where the footprint's top-left corner lies.
    pub x: u32,
    pub y: u32,
    /// Turned 90° clockwise (footprint `h × w` for a `w × h` micro-texture).
    pub rotated: bool,
}

impl MacroPlacement {
    /// Footprint `(width, height)` in the macro-texture of a `w × h` micro-texture.
    pub fn footprint(&self, w: u32, h: u32) -> (u32, u32) {
        if self.rotated {
            (h, w)
        } else {
            (w, h)
        }
    }

    /// Macro-texture texel of micro-texture texel `(x, y)` (micro-texture size `w × h`).
    pub fn macro_texel(&self, w: u32, h: u32, x: u32, y: u32) -> (u32, u32) {
        let _ = w;
        if self.rotated {
            (self.x + h - 1 - y, self.y + x)
        } else {
            (self.x + x, self.y + y)
        }
    }

    /// Macro-texture texel-edge coordinates of the micro-texture's corners top-left, top-right,
    /// bottom-right, bottom-left (the order of [`super::quad_corners`]); divide by the
    /// macro-texture size for texture coordinates.
    pub fn macro_corners(&self, w: u32, h: u32) -> [[u32; 2]; 4] {
        // micro-texture edge point (X, Y) maps to (x + X, y + Y), or rotated to (x + h − Y, y + X)
        let map = |xx: u32, yy: u32| {
            if self.rotated {
                [self.x + h - yy, self.y + xx]
            } else {
                [self.x + xx, self.y + yy]
            }
        };
        [map(0, 0), map(w, 0), map(w, h), map(0, h)]
    }
}

/// One packed atlas.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MacroTexture {
    pub width: u32,
    pub height: u32,
    /// `width · height · 4` RGBA bytes, row-major; unused texels are transparent.
    pub rgba: Vec<u8>,
}

/// A packing of rectangles: macro-texture sizes and one placement per input rectangle.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Packing {
    /// `(width, height)` of every macro-texture.
    pub macro_sizes: Vec<(u32, u32)>,
    /// One per input rectangle, in input order.
    pub placements: Vec<MacroPlacement>,
}

/// What a packing measures.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PackingStats {
    pub macro_textures: u64,
    pub micro_textures: u64,
    /// Texels of all micro-textures.
    pub micro_texels: u64,
    /// Texels of all macro-textures.
    pub macro_texels: u64,
    /// RGBA8 bytes of all macro-textures (before PNG).
    pub macro_bytes: u64,
    /// `micro_texels / macro_texels` (1 when empty).
    pub efficiency: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Rect {
    x: u32,
    y: u32,
    w: u32,
    h: u32,
}

impl Rect {
    fn x1(&self) -> u32 {
        self.x + self.w
    }
    fn y1(&self) -> u32 {
        self.y + self.h
    }
    fn overlaps(&self, o: &Rect) -> bool {
        self.x < o.x1() && o.x < self.x1() && self.y < o.y1() && o.y < self.y1()
    }
    fn contains(&self, o: &Rect) -> bool {
        o.x >= self.x && o.y >= self.y && o.x1() <= self.x1() && o.y1() <= self.y1()
    }
}

/// Free space of one macro-texture as the set of maximal free rectangles.
struct FreeSpace {
    free: Vec<Rect>,
}

impl FreeSpace {
    fn new(w: u32, h: u32) -> Self {
        FreeSpace {
            free: vec![Rect { x: 0, y: 0, w, h }],
        }
    }

    /// Best position by key among free rectangles that can hold `w × h` (every lexicographically
    /// smallest position of a fitting rectangle is a corner of some maximal free rectangle).
    fn find(&self, w: u32, h: u32, key: impl Fn(&Rect) -> (u32, u32)) -> Option<(u32, u32)> {
        self.free
            .iter()
            .filter(|f| f.w >= w && f.h >= h)
            .min_by_key(|f| key(f))
            .map(|f| (f.x, f.y))
    }

    /// Bottom-left rule: lowest, then leftmost.
    fn bottom_left(&self, w: u32, h: u32) -> Option<(u32, u32)> {
        self.find(w, h, |f| (f.y, f.x))
    }

    /// Left-bottom rule: leftmost, then lowest.
    fn left_bottom(&self, w: u32, h: u32) -> Option<(u32, u32)> {
        self.find(w, h, |f| (f.x, f.y))
    }

    fn place(&mut self, r: Rect) {
        let mut new = Vec::new();
        self.free.retain(|f| {
            if !f.overlaps(&r) {
                return true;
            }
            if r.x > f.x {
                new.push(Rect { w: r.x - f.x, ..*f });
            }
            if r.x1() < f.x1() {
                new.push(Rect {
                    x: r.x1(),
                    w: f.x1() - r.x1(),
                    ..*f
                });
            }
            if r.y > f.y {
                new.push(Rect { h: r.y - f.y, ..*f });
            }
            if r.y1() < f.y1() {
                new.push(Rect {
                    y: r.y1(),
                    h: f.y1() - r.y1(),
                    ..*f
                });
            }
            false
        });
        // old rectangles are maximal and pairwise non-nested, and a new one lies inside a removed
        // old one, so only the new ones can be redundant
        let mut keep = vec![true; new.len()];
        for i in 0..new.len() {
            let redundant = self.free.iter().any(|f| f.contains(&new[i]))
                || new.iter().enumerate().any(|(j, n)| {
                    j != i && keep[j] && n.contains(&new[i]) && (n != &new[i] || j < i)
                });
            keep[i] = !redundant;
        }
        self.free.extend(
            new.into_iter()
                .zip(keep)
                .filter(|(_, k)| *k)
                .map(|(n, _)| n),
        );
    }
}

/// Packs rectangles `(width, height)` with the GI 2002 sec. 5.4 algorithm.
pub fn pack_rects(
    sizes: &[(u32, u32)],
    options: &PackingOptions,
) -> Result<Packing, CompressError> {
    let max = options.max_size;
    if max == 0 || !max.is_power_of_two() {
        return Err(CompressError::BadOption {
            option: "macro-texture max size",
            reason: format!("{max} is not a power of two"),
        });
    }
    let block = options.block;
    if block == 0 || !block.is_power_of_two() || block > max {
        return Err(CompressError::BadOption {
            option: "macro-texture block size",
            reason: format!("{block} is not a power of two of at most the max size {max}"),
        });
    }
    let pad = |v: u32| v.div_ceil(block) * block;
    // (index, w, h, rotated) with h >= w after rotation
    let mut items: Vec<(usize, u32, u32, bool)> = Vec::with_capacity(sizes.len());
    for (i, &(w, h)) in sizes.iter().enumerate() {
        if w == 0 || h == 0 || w.max(h) > max {
            return Err(CompressError::Invalid(format!(
                "micro-texture {i} of {w}×{h} texels cannot be packed into macro-textures of at most {max}²"
            )));
        }
        // turned by the unpadded size, so a footprint stays top-down inside its padded one
        let rotated = w > h;
        let (w, h) = (pad(w), pad(h));
        items.push(if rotated {
            (i, h, w, true)
        } else {
            (i, w, h, false)
        });
    }
    items.sort_by(|a, b| b.2.cmp(&a.2).then(a.1.cmp(&b.1)).then(a.0.cmp(&b.0)));
    let mut placements = vec![
        MacroPlacement {
            macro_index: 0,
            x: 0,
            y: 0,
            rotated: false
        };
        sizes.len()
    ];
    let mut macro_sizes = Vec::new();
    let mut remaining = items;
    while let Some(&(_, w0, h0, _)) = remaining.first() {
        let mi = macro_sizes.len() as u32;
        let height = h0.next_power_of_two();
        let area: u64 = remaining.iter().map(|r| r.1 as u64 * r.2 as u64).sum();
        let width = if options.trim {
            // no power of two: the remaining area over the height (at least the first's width,
            // a multiple of the block side); what does not fit goes to the next macro-texture
            area.div_ceil(height as u64)
                .div_ceil(block as u64)
                .saturating_mul(block as u64)
                .max(w0 as u64)
        } else {
            area.div_ceil(height as u64)
                .next_power_of_two()
                .max(w0.next_power_of_two() as u64)
        }
        .min(max as u64) as u32;
        let mut space = FreeSpace::new(width, height);
        let mut placed = vec![false; remaining.len()];
        let mut put = |k: usize, x: u32, y: u32, space: &mut FreeSpace, placed: &mut [bool]| {
            let (i, w, h, rotated) = remaining[k];
            space.place(Rect { x, y, w, h });
            placed[k] = true;
            placements[i] = MacroPlacement {
                macro_index: mi,
                x,
                y,
                rotated,
            };
        };
        // phase 1: bottom-left rule from the first (tallest) until the right border is reached
        let mut k = 0;
        while k < remaining.len() {
            let (_, w, h, _) = remaining[k];
            match space.bottom_left(w, h) {
                Some((x, 0)) => put(k, x, 0, &mut space, &mut placed),
                _ => break,
            }
            k += 1;
        }
        // phase 2: left-bottom rule from the last (smallest) on
        let mut free_area: u64 = width as u64 * height as u64
            - placed
                .iter()
                .zip(&remaining)
                .filter(|(p, _)| **p)
                .map(|(_, r)| r.1 as u64 * r.2 as u64)
                .sum::<u64>();
        for j in (k..remaining.len()).rev() {
            let (_, w, h, _) = remaining[j];
            if (w as u64 * h as u64) > free_area {
                continue;
            }
            if let Some((x, y)) = space.left_bottom(w, h) {
                put(j, x, y, &mut space, &mut placed);
                free_area -= w as u64 * h as u64;
            }
        }
        let (width, height) = if options.trim {
            // every footprint's size and position is a multiple of the block side
            placed.iter().zip(&remaining).filter(|(p, _)| **p).fold(
                (0, 0),
                |(w, h), (_, &(i, fw, fh, _))| {
                    let p = &placements[i];
                    (w.max(p.x + fw), h.max(p.y + fh))
                },
            )
        } else {
            (width, height)
        };
        macro_sizes.push((width, height));
        remaining = remaining
            .into_iter()
            .zip(placed)
            .filter(|(_, p)| !p)
            .map(|(r, _)| r)
            .collect();
    }
    Ok(Packing {
        macro_sizes,
        placements,
    })
}

/// Checks a packing of rectangles `sizes`: one placement per rectangle, each inside its
/// macro-texture, no two overlapping, non-zero macro sizes (powers of two unless trimmed,
/// [`PackingOptions::trim`]), no empty macro-texture. Returns the
/// statistics or the first violation.
pub fn analyze_packing(
    sizes: &[(u32, u32)],
    packing: &Packing,
) -> Result<PackingStats, CompressError> {
    let bad = |m: String| Err(CompressError::Invalid(m));
    if packing.placements.len() != sizes.len() {
        return bad(format!(
            "{} placements for {} micro-textures",
            packing.placements.len(),
            sizes.len()
        ));
    }
    for (m, &(w, h)) in packing.macro_sizes.iter().enumerate() {
        if w == 0 || h == 0 {
            return bad(format!("macro-texture {m} is {w}×{h}, empty"));
        }
    }
    let mut per_macro: Vec<Vec<(usize, Rect)>> = vec![Vec::new(); packing.macro_sizes.len()];
    for (i, (p, &(w, h))) in packing.placements.iter().zip(sizes).enumerate() {
        let Some(&(mw, mh)) = packing.macro_sizes.get(p.macro_index as usize) else {
            return bad(format!(
                "micro-texture {i} placed in a missing macro-texture"
            ));
        };
        let (fw, fh) = p.footprint(w, h);
        let r = Rect {
            x: p.x,
            y: p.y,
            w: fw,
            h: fh,
        };
        if r.x1() > mw || r.y1() > mh {
            return bad(format!(
                "micro-texture {i} at ({}, {}) size {fw}×{fh} leaves macro-texture {} of {mw}×{mh}",
                p.x, p.y, p.macro_index
            ));
        }
        per_macro[p.macro_index as usize].push((i, r));
    }
    for (m, rects) in per_macro.iter_mut().enumerate() {
        if rects.is_empty() {
            return bad(format!("macro-texture {m} is empty"));
        }
        // sweep in x: only rectangles whose x-ranges intersect need a full test
        rects.sort_by_key(|(_, r)| r.x);
        for a in 0..rects.len() {
            for b in a + 1..rects.len() {
                if rects[b].1.x >= rects[a].1.x1() {
                    break;
                }
                if rects[a].1.overlaps(&rects[b].1) {
                    return bad(format!(
                        "micro-textures {} and {} overlap in macro-texture {m}",
                        rects[a].0, rects[b].0
                    ));
                }
            }
        }
    }
    let micro_texels: u64 = sizes.iter().map(|&(w, h)| w as u64 * h as u64).sum();
    let macro_texels: u64 = packing
        .macro_sizes
        .iter()
        .map(|&(w, h)| w as u64 * h as u64)
        .sum();
    Ok(PackingStats {
        macro_textures: packing.macro_sizes.len() as u64,
        micro_textures: sizes.len() as u64,
        micro_texels,
        macro_texels,
        macro_bytes: 4 * macro_texels,
        efficiency: if macro_texels == 0 {
            1.0
        } else {
            micro_texels as f64 / macro_texels as f64
        },
    })
}

/// What [`analyze_block_sharing`] measures.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BlockSharingStats {
    /// Blocks holding texels of some micro-texture's footprint.
    pub used_blocks: u64,
    /// Of those, blocks holding texels of two or more footprints (0 for a block-aligned packing).
    pub shared_blocks: u64,
}

/// Counts the `block × block` texel blocks of the macro-textures that hold footprint texels of two
/// or more rectangles (`sizes`, unpadded). A packing made with `PackingOptions::block` = `block`
/// shares none.
pub fn analyze_block_sharing(
    sizes: &[(u32, u32)],
    packing: &Packing,
    block: u32,
) -> BlockSharingStats {
    use std::collections::HashMap;
    let block = block.max(1);
    let mut owner: HashMap<(u32, u32, u32), (usize, bool)> = HashMap::new();
    for (i, (p, &(w, h))) in packing.placements.iter().zip(sizes).enumerate() {
        let (fw, fh) = p.footprint(w, h);
        if fw == 0 || fh == 0 {
            continue;
        }
        for by in p.y / block..=(p.y + fh - 1) / block {
            for bx in p.x / block..=(p.x + fw - 1) / block {
                let e = owner.entry((p.macro_index, bx, by)).or_insert((i, false));
                if e.0 != i {
                    e.1 = true;
                }
            }
        }
    }
    BlockSharingStats {
        used_blocks: owner.len() as u64,
        shared_blocks: owner.values().filter(|(_, shared)| *shared).count() as u64,
    }
}

/// Micro-textures of one face image packed as one rectangle ([`PackingOptions::stack`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stack {
    /// The members' bounding rectangle in the face image.
    pub bbox: TexelRect,
    /// Indices of the member rectangles, in the order they joined.
    pub members: Vec<usize>,
}

/// Padded blocks of a `w × h` rectangle.
fn padded_blocks(r: &TexelRect, block: u32) -> i64 {
    (r.width().div_ceil(block) as i64) * (r.height().div_ceil(block) as i64)
}

fn disjoint(a: &TexelRect, b: &TexelRect) -> bool {
    a.x1 <= b.x0 || b.x1 <= a.x0 || a.y1 <= b.y0 || b.y1 <= a.y0
}

/// Side of the buckets of [`stack_rects`]' spatial index, in texels.
const STACK_BUCKET: u32 = 32;

/// The most stacks [`stack_rects`] looks at for one rectangle or stack (the first found), so
/// that a cell of many overlapping rectangles (a damaged or hostile file: the reader derives the
/// stacks) costs linear time. Real cells stay far below it (a `city:1M` cell: 220 on average).
const STACK_CANDIDATES: usize = 4096;

/// Groups rectangles `(face, rect)` (a face's key and a texel rectangle of its image) into stacks
/// whose members do not overlap, so that padding the stacks to `block`-sided blocks takes fewer
/// blocks than padding the rectangles; a rectangle whose shorter side exceeds `thickest` texels
/// stays alone. Greedy and deterministic:
/// 1. rectangles are taken by face, then by decreasing area (ties in input order); each joins
///    the stack of its face whose padded blocks its joining lowers most (ties: the older stack),
///    provided it overlaps no member and the stack's sides stay within `max_side`, or starts one;
/// 2. then, repeatedly until nothing changes, each stack (oldest first) is merged with the
///    neighbour that saves most blocks under the same conditions.
///
/// Only stacks whose rectangle comes within `block − 1` texels of the other can save a block
/// (two rectangles `block` or more apart need at least their blocks together), so candidates are
/// found through a bucket grid of the faces' images.
pub fn stack_rects(
    rects: &[(u32, TexelRect)],
    block: u32,
    max_side: u32,
    thickest: u32,
) -> Vec<Stack> {
    let block = block.max(1);
    let mut order: Vec<usize> = (0..rects.len()).collect();
    order.sort_by_key(|&i| (rects[i].0, std::cmp::Reverse(rects[i].1.texels()), i));
    let mut stacks: Vec<(u32, Stack)> = Vec::new();
    let mut alive: Vec<bool> = Vec::new();
    // the bucket grid: per face key (dense, as given), buckets of the image row by row
    let faces = rects.iter().map(|r| r.0 as usize + 1).max().unwrap_or(0);
    let mut extent = vec![(0u32, 0u32); faces];
    for (f, r) in rects {
        let e = &mut extent[*f as usize];
        *e = (e.0.max(r.x1), e.1.max(r.y1));
    }
    // a reach of up to `block − 1` texels past the image is clamped to its last bucket
    let grid: Vec<(u32, u32)> = extent
        .iter()
        .map(|&(w, h)| {
            (
                w.div_ceil(STACK_BUCKET).max(1),
                h.div_ceil(STACK_BUCKET).max(1),
            )
        })
        .collect();
    let mut index: Vec<Vec<Vec<usize>>> = grid
        .iter()
        .map(|&(nx, ny)| vec![Vec::new(); nx as usize * ny as usize])
        .collect();
    let reach = |r: &TexelRect| TexelRect {
        x0: r.x0.saturating_sub(block - 1),
        y0: r.y0.saturating_sub(block - 1),
        x1: r.x1 + block - 1,
        y1: r.y1 + block - 1,
    };
    let buckets = |face: u32, r: &TexelRect| {
        let (nx, ny) = grid[face as usize];
        let bx0 = (r.x0 / STACK_BUCKET).min(nx - 1);
        let bx1 = ((r.x1.max(r.x0 + 1) - 1) / STACK_BUCKET).min(nx - 1);
        let by0 = (r.y0 / STACK_BUCKET).min(ny - 1);
        let by1 = ((r.y1.max(r.y0 + 1) - 1) / STACK_BUCKET).min(ny - 1);
        (by0..=by1).flat_map(move |by| (bx0..=bx1).map(move |bx| (by * nx + bx) as usize))
    };
    // adds `id` to the buckets of `r` that those of `old` (its rectangle before it grew) lack
    let register = |index: &mut Vec<Vec<Vec<usize>>>,
                    face: u32,
                    old: Option<&TexelRect>,
                    r: &TexelRect,
                    id: usize| {
        let had: Vec<usize> = old.map(|o| buckets(face, o).collect()).unwrap_or_default();
        for b in buckets(face, r) {
            if had.binary_search(&b).is_err() {
                index[face as usize][b].push(id);
            }
        }
    };
    // stamp[id] == query: already a candidate of this query
    let mut stamp: Vec<u32> = Vec::new();
    let mut query = 0u32;
    let mut candidates = |index: &Vec<Vec<Vec<usize>>>,
                          stamp: &mut Vec<u32>,
                          alive: &[bool],
                          face: u32,
                          r: &TexelRect| {
        query += 1;
        stamp.resize(alive.len(), 0);
        let mut c = Vec::new();
        'buckets: for b in buckets(face, &reach(r)) {
            for &id in &index[face as usize][b] {
                if alive[id] && stamp[id] != query {
                    stamp[id] = query;
                    c.push(id);
                    if c.len() == STACK_CANDIDATES {
                        break 'buckets;
                    }
                }
            }
        }
        c.sort_unstable();
        c
    };
    let fits = |u: &TexelRect| u.width() <= max_side && u.height() <= max_side;
    // 1. every rectangle joins the best stack or starts one
    // stacks that hold a rectangle thicker than `thickest` take nothing else
    let mut fixed: Vec<bool> = Vec::new();
    for &i in &order {
        let (face, r) = rects[i];
        let mut best: Option<(i64, usize)> = None;
        let lone = r.width().min(r.height()) > thickest;
        for id in candidates(&index, &mut stamp, &alive, face, &r) {
            if lone || fixed[id] {
                continue;
            }
            let s = &stacks[id].1;
            let u = s.bbox.union(&r);
            let gain =
                padded_blocks(&s.bbox, block) + padded_blocks(&r, block) - padded_blocks(&u, block);
            if gain <= 0 || !fits(&u) || best.is_some_and(|(g, _)| g >= gain) {
                continue;
            }
            if s.members.iter().all(|&m| disjoint(&rects[m].1, &r)) {
                best = Some((gain, id));
            }
        }
        match best {
            Some((_, id)) => {
                let s = &mut stacks[id].1;
                let old = s.bbox;
                s.bbox = s.bbox.union(&r);
                s.members.push(i);
                let bbox = s.bbox;
                register(&mut index, face, Some(&old), &bbox, id);
            }
            None => {
                let id = stacks.len();
                stacks.push((
                    face,
                    Stack {
                        bbox: r,
                        members: vec![i],
                    },
                ));
                alive.push(true);
                fixed.push(lone);
                register(&mut index, face, None, &r, id);
            }
        }
    }
    // 2. stacks merge with their best neighbour while that saves blocks
    // a pair of stacks neither of which changed was already refused: after the first pass only
    // stacks that grew look for a neighbour (one that grew is looked at from its own side)
    let mut dirty = vec![true; stacks.len()];
    loop {
        let mut merged = false;
        let mut grew = vec![false; stacks.len()];
        for id in 0..stacks.len() {
            if !alive[id] || !dirty[id] || fixed[id] {
                continue;
            }
            let face = stacks[id].0;
            let a = stacks[id].1.bbox;
            let mut best: Option<(i64, usize)> = None;
            for other in candidates(&index, &mut stamp, &alive, face, &a) {
                if other == id || !alive[other] || fixed[other] {
                    continue;
                }
                let b = &stacks[other].1;
                let u = a.union(&b.bbox);
                let gain = padded_blocks(&a, block) + padded_blocks(&b.bbox, block)
                    - padded_blocks(&u, block);
                if gain <= 0 || !fits(&u) || best.is_some_and(|(g, _)| g >= gain) {
                    continue;
                }
                // only members inside the other's rectangle can overlap one of its members
                let near_b: Vec<&TexelRect> = b
                    .members
                    .iter()
                    .map(|&n| &rects[n].1)
                    .filter(|r| !disjoint(r, &a))
                    .collect();
                let ok = near_b.is_empty()
                    || stacks[id]
                        .1
                        .members
                        .iter()
                        .map(|&m| &rects[m].1)
                        .filter(|r| !disjoint(r, &b.bbox))
                        .all(|r| near_b.iter().all(|n| disjoint(r, n)));
                if ok {
                    best = Some((gain, other));
                }
            }
            if let Some((_, other)) = best {
                let taken = std::mem::take(&mut stacks[other].1.members);
                alive[other] = false;
                let b = stacks[other].1.bbox;
                let s = &mut stacks[id].1;
                let old = s.bbox;
                s.bbox = s.bbox.union(&b);
                s.members.extend(taken);
                let bbox = s.bbox;
                register(&mut index, face, Some(&old), &bbox, id);
                grew[id] = true;
                merged = true;
            }
        }
        if !merged {
            break;
        }
        dirty = grew;
    }
    stacks
        .into_iter()
        .zip(alive)
        .filter(|(_, a)| *a)
        .map(|((_, s), _)| s)
        .collect()
}

/// A packing of rectangles through stacks: the stacks, the stacks' packing, and one placement
/// per rectangle (a member's place and turn inside its stack's).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StackedPacking {
    pub stacks: Vec<Stack>,
    /// The packing of the stacks' rectangles, in the order of `stacks`.
    pub stack_packing: Packing,
    /// One placement per input rectangle; `macro_sizes` those of `stack_packing`.
    pub packing: Packing,
}

/// Packs rectangles `(face, rect)` of face images: with [`PackingOptions::stack`] (and blocks)
/// in the stacks of [`stack_rects`], else each alone, which is exactly [`pack_rects`] on their
/// sizes. Readers derive quads' places with it, so it is part of the cell format (version 8).
pub fn pack_stacked(
    rects: &[(u32, TexelRect)],
    options: &PackingOptions,
) -> Result<StackedPacking, CompressError> {
    let stacks = if options.stack > 0 && options.block > 1 {
        stack_rects(rects, options.block, options.max_size, options.stack)
    } else {
        rects
            .iter()
            .enumerate()
            .map(|(i, &(_, r))| Stack {
                bbox: r,
                members: vec![i],
            })
            .collect()
    };
    let sizes: Vec<(u32, u32)> = stacks
        .iter()
        .map(|s| (s.bbox.width(), s.bbox.height()))
        .collect();
    let stack_packing = pack_rects(&sizes, options)?;
    let mut placements = vec![
        MacroPlacement {
            macro_index: 0,
            x: 0,
            y: 0,
            rotated: false,
        };
        rects.len()
    ];
    for (s, p) in stacks.iter().zip(&stack_packing.placements) {
        for &m in &s.members {
            let r = rects[m].1;
            let (dx, dy) = (r.x0 - s.bbox.x0, r.y0 - s.bbox.y0);
            // the stack's texel (X, Y) lies at (x + X, y + Y), or turned at (x + H − 1 − Y, y + X)
            placements[m] = if p.rotated {
                MacroPlacement {
                    macro_index: p.macro_index,
                    x: p.x + s.bbox.height() - dy - r.height(),
                    y: p.y + dx,
                    rotated: true,
                }
            } else {
                MacroPlacement {
                    macro_index: p.macro_index,
                    x: p.x + dx,
                    y: p.y + dy,
                    rotated: false,
                }
            };
        }
    }
    let packing = Packing {
        macro_sizes: stack_packing.macro_sizes.clone(),
        placements,
    };
    Ok(StackedPacking {
        stacks,
        stack_packing,
        packing,
    })
}

/// Packs micro-textures (GI 2002 sec. 5.4) and copies their pixels into the macro-textures.
/// Returns the macro-textures, one placement per micro-texture (input order) and the statistics.
pub fn pack_micro_textures(
    micros: &[MicroTexture],
    options: &PackingOptions,
) -> Result<(Vec<MacroTexture>, Vec<MacroPlacement>, PackingStats), CompressError> {
    for (i, m) in micros.iter().enumerate() {
        let r = m.rect;
        if r.x1 < r.x0 || r.y1 < r.y0 || m.pixels.len() as u64 != 4 * r.area() {
            return Err(CompressError::Invalid(format!(
                "micro-texture {i}: rectangle {r:?} does not match its {} pixel bytes",
                m.pixels.len()
            )));
        }
    }
    let rects: Vec<(u32, TexelRect)> = micros
        .iter()
        .map(|m| (m.face.index() as u32, m.rect))
        .collect();
    let stacked = pack_stacked(&rects, options)?;
    let stack_sizes: Vec<(u32, u32)> = stacked
        .stacks
        .iter()
        .map(|s| (s.bbox.width(), s.bbox.height()))
        .collect();
    let mut stats = analyze_packing(&stack_sizes, &stacked.stack_packing)?;
    if options.block > 1 {
        let sharing = analyze_block_sharing(&stack_sizes, &stacked.stack_packing, options.block);
        if sharing.shared_blocks > 0 {
            return Err(CompressError::Invalid(format!(
                "{} of {} texel blocks of {}² hold two micro-textures or stacks",
                sharing.shared_blocks, sharing.used_blocks, options.block
            )));
        }
    }
    stats.micro_textures = micros.len() as u64;
    stats.micro_texels = micros.iter().map(|m| m.rect.area()).sum();
    stats.efficiency = if stats.macro_texels == 0 {
        1.0
    } else {
        stats.micro_texels as f64 / stats.macro_texels as f64
    };
    let packing = stacked.packing;
    let mut by_macro: Vec<Vec<usize>> = vec![Vec::new(); packing.macro_sizes.len()];
    for (i, p) in packing.placements.iter().enumerate() {
        by_macro[p.macro_index as usize].push(i);
    }
    let macros = packing
        .macro_sizes
        .par_iter()
        .zip(by_macro.par_iter())
        .map(|(&(mw, mh), members)| {
            let mut rgba = vec![0u8; mw as usize * mh as usize * 4];
            for &i in members {
                let (m, p) = (&micros[i], &packing.placements[i]);
                let (w, h) = (m.rect.width(), m.rect.height());
                for y in 0..h {
                    for x in 0..w {
                        let (mx, my) = p.macro_texel(w, h, x, y);
                        let s = 4 * (y * w + x) as usize;
                        let d = 4 * (my as usize * mw as usize + mx as usize);
                        rgba[d..d + 4].copy_from_slice(&m.pixels[s..s + 4]);
                    }
                }
            }
            MacroTexture {
                width: mw,
                height: mh,
                rgba,
            }
        })
        .collect();
    Ok((macros, packing.placements, stats))
}
