//! The billboards' textures on their way to the GPU (see "Billboards" and "Drawing" in the module
//! docs): dilation against cracks, cropping to the opaque texels, and packing the cropped images
//! into macro-textures with one quad per billboard. The packing uses `etagere`'s shelf allocator
//! (the texture-atlas allocator of WebRender): it runs after every frame that regenerated an
//! impostor, so it must be fast; the bake's GI 2002 packer is too slow for that.

use etagere::{size2, AtlasAllocator};
use lemi_core::bundle::Quad;
use lemi_core::compress::MacroTexture;
use lemi_core::Face;

use super::objects::Impostor;

/// Largest side of a macro-texture the impostors are packed into (texels; a larger
/// `max_resolution` raises it).
pub const ATLAS_MAX_SIZE: u32 = 2048;

/// Dilates an impostor texture by `passes` texels: a transparent texel with an opaque neighbour
/// (8-neighbourhood; of several, the nearest) takes its colour and depth. Returns per texel the
/// texel whose surface point it shows (empty for no passes).
pub(super) fn dilate(rgba: &mut [u8], depth: &mut [f32], res: u32, passes: u32) -> Vec<u32> {
    let n = res as usize;
    if passes == 0 {
        return Vec::new();
    }
    let mut source: Vec<u32> = (0..(n * n) as u32).collect();
    for _ in 0..passes {
        let mut grown: Vec<(usize, usize)> = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let idx = j * n + i;
                if depth[idx].is_finite() {
                    continue;
                }
                let mut best: Option<usize> = None;
                for dj in -1i64..=1 {
                    for di in -1i64..=1 {
                        let (x, y) = (i as i64 + di, j as i64 + dj);
                        if (di, dj) == (0, 0) || x < 0 || y < 0 || x >= n as i64 || y >= n as i64 {
                            continue;
                        }
                        let k = y as usize * n + x as usize;
                        if depth[k].is_finite() && best.is_none_or(|b| depth[k] < depth[b]) {
                            best = Some(k);
                        }
                    }
                }
                if let Some(b) = best {
                    grown.push((idx, b));
                }
            }
        }
        if grown.is_empty() {
            break;
        }
        for (idx, b) in grown {
            depth[idx] = depth[b];
            source[idx] = source[b];
            rgba.copy_within(4 * b..4 * b + 4, 4 * idx);
        }
    }
    source
}

/// An impostor image cut down to the rectangle of its opaque texels.
pub(super) struct Cropped {
    /// `[x, y, w, h]` in the image; zero-sized when nothing is opaque.
    pub(super) rect: [u32; 4],
    pub(super) rgba: Vec<u8>,
    pub(super) depth: Vec<f32>,
    pub(super) source: Vec<u32>,
}

/// Cuts a `res × res` image (colour, depth, sources as from [`dilate`]) to its opaque texels.
pub(super) fn crop(rgba: &[u8], depth: &[f32], source: &[u32], res: u32) -> Cropped {
    let n = res as usize;
    let (mut x0, mut y0, mut x1, mut y1) = (n, n, 0, 0);
    for (k, z) in depth.iter().enumerate() {
        if z.is_finite() {
            let (x, y) = (k % n, k / n);
            x0 = x0.min(x);
            x1 = x1.max(x + 1);
            y0 = y0.min(y);
            y1 = y1.max(y + 1);
        }
    }
    if x1 <= x0 || y1 <= y0 {
        return Cropped {
            rect: [0; 4],
            rgba: Vec::new(),
            depth: Vec::new(),
            source: Vec::new(),
        };
    }
    let (w, h) = (x1 - x0, y1 - y0);
    let mut out = Cropped {
        rect: [x0 as u32, y0 as u32, w as u32, h as u32],
        rgba: Vec::with_capacity(4 * w * h),
        depth: Vec::with_capacity(w * h),
        source: Vec::with_capacity(if source.is_empty() { 0 } else { w * h }),
    };
    for y in y0..y1 {
        out.rgba
            .extend_from_slice(&rgba[4 * (y * n + x0)..4 * (y * n + x1)]);
        out.depth.extend_from_slice(&depth[y * n + x0..y * n + x1]);
        if !source.is_empty() {
            out.source
                .extend(source[y * n + x0..y * n + x1].iter().map(|&s| {
                    let (sx, sy) = (s as usize % n, s as usize / n);
                    ((sy - y0) * w + (sx - x0)) as u32
                }));
        }
    }
    out
}

/// Where a rectangle went: page, x, y.
pub(super) type Place = (usize, u32, u32);

/// Rectangles packed into pages.
#[derive(Debug)]
pub(super) struct Packing {
    /// Width and height of every page.
    pub(super) pages: Vec<(u32, u32)>,
    /// Per rectangle (input order), its page and position.
    pub(super) places: Vec<Place>,
}

/// Packs rectangles `(w, h)` (each at most `max_size` per side; zero-sized ones are placed at the
/// origin of the first page) into pages with `etagere`'s shelf allocator, tallest first (so that
/// similar heights share shelves), each into the first page with room, a new page when none has.
/// Pages are `max_size` wide or, when everything fits in less, the power of two near the square
/// root of the total area; each page is as tall as what it holds. `Err((w, h))` names a rectangle
/// that fits no page.
pub(super) fn pack(sizes: &[(u32, u32)], max_size: u32) -> Result<Packing, (u32, u32)> {
    let area: u64 = sizes.iter().map(|&(w, h)| w as u64 * h as u64).sum();
    let widest = sizes.iter().map(|s| s.0).max().unwrap_or(1);
    let width = ((area as f64).sqrt().ceil() as u32)
        .next_power_of_two()
        .max(widest)
        .min(max_size);
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(sizes[i].1), std::cmp::Reverse(sizes[i].0)));
    // per page: its allocator and the height used
    let mut pages: Vec<(AtlasAllocator, u32)> = Vec::new();
    let mut places = vec![(0usize, 0u32, 0u32); sizes.len()];
    let page_size = size2(width as i32, max_size as i32);
    for i in order {
        let (w, h) = sizes[i];
        if w == 0 || h == 0 {
            continue;
        }
        if w > width || h > max_size {
            return Err((w, h));
        }
        let size = size2(w as i32, h as i32);
        let mut placed = None;
        for (p, (atlas, _)) in pages.iter_mut().enumerate() {
            if let Some(a) = atlas.allocate(size) {
                placed = Some((p, a.rectangle.min));
                break;
            }
        }
        let (page, at) = match placed {
            Some(found) => found,
            None => {
                let mut atlas = AtlasAllocator::new(page_size);
                let a = atlas.allocate(size).ok_or((w, h))?;
                pages.push((atlas, 0));
                (pages.len() - 1, a.rectangle.min)
            }
        };
        let (x, y) = (at.x as u32, at.y as u32);
        places[i] = (page, x, y);
        pages[page].1 = pages[page].1.max(y + h);
    }
    Ok(Packing {
        pages: pages.into_iter().map(|(_, h)| (width, h)).collect(),
        places,
    })
}

/// The macro-textures holding the billboards' cropped images ([`pack`]ed into pages of at most
/// `max_size` per side) and one quad per billboard (in the order of `billboards`), ready for the
/// impostor renderer. `Err((w, h))` names an image larger than `max_size`.
pub(super) fn macro_textures(
    billboards: &[&Impostor],
    max_size: u32,
) -> Result<(Vec<MacroTexture>, Vec<Quad>), (u32, u32)> {
    let sizes: Vec<(u32, u32)> = billboards.iter().map(|i| (i.crop[2], i.crop[3])).collect();
    let Packing { pages, places } = pack(&sizes, max_size)?;
    let mut macros: Vec<MacroTexture> = pages
        .iter()
        .map(|&(w, h)| MacroTexture {
            width: w,
            height: h,
            rgba: vec![0; 4 * w as usize * h as usize],
        })
        .collect();
    let mut quads = Vec::with_capacity(billboards.len());
    for (imp, &(page, px, py)) in billboards.iter().zip(&places) {
        let [x, y, w, h] = imp.crop;
        if let Some(m) = macros.get_mut(page) {
            let (mw, row) = (m.width as usize, 4 * w as usize);
            for ty in 0..h as usize {
                let d = 4 * ((py as usize + ty) * mw + px as usize);
                m.rgba[d..d + row].copy_from_slice(&imp.rgba[ty * row..(ty + 1) * row]);
            }
        }
        quads.push(Quad {
            fringe: false,
            face: Face::PosZ,
            // far to near, so the renderer draws near billboards first
            layer: (u16::MAX as f64 - imp.distance.min(u16::MAX as f64)) as u16,
            texels: [x, y, x + w, y + h].map(|v| v as u16),
            corners: imp.crop_corners().map(|c| c.as_vec3().to_array()),
            macro_index: page as u32,
            rect: [px, py, w, h],
            rotated: false,
        });
    }
    Ok((macros, quads))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_holds_every_rectangle_without_overlap() {
        let sizes: Vec<(u32, u32)> = (0..200u32)
            .map(|i| (1 + (i * 37) % 300, 1 + (i * 53) % 200))
            .chain([(512, 512), (512, 3), (1, 512)])
            .collect();
        let Packing { pages, places } = pack(&sizes, 512).expect("packed");
        assert!(pages.len() > 1);
        let mut used: Vec<Vec<bool>> = pages
            .iter()
            .map(|&(w, h)| {
                assert!(w <= 512 && h <= 512);
                vec![false; (w * h) as usize]
            })
            .collect();
        for (&(w, h), &(p, x, y)) in sizes.iter().zip(&places) {
            let (pw, ph) = pages[p];
            assert!(
                x + w <= pw && y + h <= ph,
                "{w}x{h} at {x},{y} in {pw}x{ph}"
            );
            for j in y..y + h {
                for i in x..x + w {
                    let k = (j * pw + i) as usize;
                    assert!(!used[p][k], "overlap at page {p} ({i}, {j})");
                    used[p][k] = true;
                }
            }
        }
        let Packing { pages, places } = pack(&[], 512).expect("nothing to pack");
        assert!(pages.is_empty() && places.is_empty());
        assert_eq!(
            pack(&[(8, 8), (600, 4)], 512).map(|_| ()).unwrap_err(),
            (600, 4)
        );
    }

    #[test]
    fn small_sets_share_one_page_near_their_area() {
        // 64 squares of 16: 128² texels of area, one 128-wide page
        let Packing { pages, places } = pack(&[(16, 16); 64], 2048).expect("packed");
        assert_eq!(pages, vec![(128, 128)]);
        assert!(places.iter().all(|p| p.0 == 0));
    }

    #[test]
    fn crop_keeps_the_opaque_rectangle_and_remaps_sources() {
        // 4 × 4, opaque texels at (1, 1) and (2, 2)
        let n = 4;
        let mut depth = vec![f32::INFINITY; n * n];
        let mut rgba = vec![0u8; 4 * n * n];
        for (x, y) in [(1, 1), (2, 2)] {
            depth[y * n + x] = 3.0;
            rgba[4 * (y * n + x)..4 * (y * n + x) + 4].copy_from_slice(&[9, 9, 9, 255]);
        }
        let c = crop(&rgba, &depth, &[], n as u32);
        assert_eq!(c.rect, [1, 1, 2, 2]);
        assert_eq!(c.depth, vec![3.0, f32::INFINITY, f32::INFINITY, 3.0]);
        assert_eq!(&c.rgba[..4], &[9, 9, 9, 255]);
        assert!(c.source.is_empty());
        // with sources (every texel its own): indices of the cropped rectangle
        let source: Vec<u32> = (0..(n * n) as u32).collect();
        assert_eq!(
            crop(&rgba, &depth, &source, n as u32).source,
            vec![0, 1, 2, 3]
        );
        // nothing opaque: empty
        let empty = crop(&rgba, &[f32::INFINITY; 16], &[], n as u32);
        assert_eq!(empty.rect, [0; 4]);
        assert!(empty.rgba.is_empty() && empty.depth.is_empty());
    }

    #[test]
    fn dilation_grows_by_a_texel_from_the_nearest_neighbour() {
        // 3 × 3: (0, 1) at depth 5 and (2, 1) at depth 2; the middle column takes depth 2
        let n = 3;
        let mut depth = vec![f32::INFINITY; n * n];
        let mut rgba = vec![0u8; 4 * n * n];
        depth[3] = 5.0;
        rgba[12..16].copy_from_slice(&[1, 1, 1, 255]);
        depth[5] = 2.0;
        rgba[20..24].copy_from_slice(&[2, 2, 2, 255]);
        let source = dilate(&mut rgba, &mut depth, n as u32, 1);
        assert!(depth.iter().all(|z| z.is_finite()));
        assert_eq!(depth[4], 2.0);
        assert_eq!(source[4], 5);
        assert_eq!(&rgba[16..20], &[2, 2, 2, 255]);
        // the left column grows from (0, 1)
        assert_eq!((depth[0], source[0]), (5.0, 3));
        assert_eq!(source[3], 3);
        // no passes: nothing changes and no sources
        let mut d = vec![f32::INFINITY; 4];
        assert!(dilate(&mut [0; 16], &mut d, 2, 0).is_empty());
        assert!(d.iter().all(|z| z.is_infinite()));
    }
}
