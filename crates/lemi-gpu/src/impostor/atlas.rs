//! Where a cell's macro-textures live on the GPU: packed into a few large textures (pages), so
//! that one bind group serves all quads of a page and a cell's far field is a handful of draw
//! calls whatever number of macro-textures the bake cut it into (GI 2002 sec. 5.4 packs
//! micro-textures into macro-textures to save texture memory and texture switches; this packs the
//! macro-textures once more, at upload, for draw calls).
//!
//! The packer is a guillotine packer, deterministic: the macro-textures sorted by decreasing
//! height (then width) each take the lowest, then leftmost free rectangle they fit in, and the
//! rest of that rectangle is cut into the part beside them (as high as they are) and the part
//! below (the whole width). The bake's macro-textures have power-of-two sides, which this fills
//! without gaps wherever the sizes allow. A page is as wide as the widest macro-texture or the
//! square root of the total area (a power of two), at most the adapter's texture side, and as
//! high as its content, at most that side; what does not fit opens a new page. Each page is its
//! own texture of exactly its used size, so the bytes resident are the packed area, not a fixed
//! page size.

use crate::GpuError;

/// Where one macro-texture went: page and top-left texel in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Place {
    pub(super) page: u32,
    pub(super) x: u32,
    pub(super) y: u32,
}

/// A packing of macro-textures into pages.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(super) struct Atlas {
    /// Page sizes `(width, height)` in texels.
    pub(super) pages: Vec<(u32, u32)>,
    /// One place per macro-texture, in the cell's order.
    pub(super) places: Vec<Place>,
}

impl Atlas {
    /// Texels of all pages.
    #[cfg(test)]
    pub(super) fn texels(&self) -> u64 {
        self.pages.iter().map(|&(w, h)| w as u64 * h as u64).sum()
    }
}

/// Packs rectangles of `sizes` (`(width, height)`, each at most `max_side` per side) into pages of
/// at most `max_side × max_side`. A zero or oversized rectangle is [`GpuError::Limit`] naming it.
pub(super) fn pack(sizes: &[(u32, u32)], max_side: u32) -> Result<Atlas, GpuError> {
    for (i, &(w, h)) in sizes.iter().enumerate() {
        if w == 0 || h == 0 || w > max_side || h > max_side {
            return Err(GpuError::Limit(format!(
                "macro-texture {i} is {w}x{h}, empty or larger than this adapter's textures ({max_side} per side)"
            )));
        }
    }
    let area: u64 = sizes.iter().map(|&(w, h)| w as u64 * h as u64).sum();
    let widest = sizes.iter().map(|s| s.0).max().unwrap_or(0);
    let square = ((area as f64).sqrt().ceil() as u64).next_power_of_two();
    let width = (square.min(max_side as u64) as u32).max(widest);
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| {
        (
            std::cmp::Reverse(sizes[i].1),
            std::cmp::Reverse(sizes[i].0),
            i,
        )
    });
    let mut atlas = Atlas {
        pages: Vec::new(),
        places: vec![
            Place {
                page: 0,
                x: 0,
                y: 0
            };
            sizes.len()
        ],
    };
    // The open page's free rectangles `[x, y, w, h]` (guillotine cuts of `width × max_side`).
    let mut free: Vec<[u32; 4]> = Vec::new();
    for i in order {
        let (w, h) = sizes[i];
        // the lowest, then leftmost free rectangle it fits in; else a new page
        let fits = |r: &[u32; 4]| w <= r[2] && h <= r[3];
        let pick = |free: &[[u32; 4]]| {
            (free.iter().enumerate())
                .filter(|(_, r)| fits(r))
                .min_by_key(|(_, r)| (r[1], r[0]))
                .map(|(k, _)| k)
        };
        let k = match pick(&free) {
            Some(k) => k,
            None => {
                atlas.pages.push((width, 0));
                free = vec![[0, 0, width, max_side]];
                0
            }
        };
        let [x, y, fw, fh] = free.swap_remove(k);
        let page = atlas.pages.len() as u32 - 1;
        atlas.places[i] = Place { page, x, y };
        if let Some(p) = atlas.pages.last_mut() {
            p.1 = p.1.max(y + h);
        }
        // cut the rest: beside it (as high as it) and below it (the whole width)
        if fw > w {
            free.push([x + w, y, fw - w, h]);
        }
        if fh > h {
            free.push([x, y + h, fw, fh - h]);
        }
    }
    Ok(atlas)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Every rectangle inside its page, no two overlapping.
    fn check(sizes: &[(u32, u32)], atlas: &Atlas, max_side: u32) {
        assert_eq!(atlas.places.len(), sizes.len());
        for &(w, h) in &atlas.pages {
            assert!(w <= max_side && h <= max_side, "page {w}x{h}");
        }
        for (i, (p, &(w, h))) in atlas.places.iter().zip(sizes).enumerate() {
            let &(pw, ph) = &atlas.pages[p.page as usize];
            assert!(
                p.x + w <= pw && p.y + h <= ph,
                "{i}: {p:?} {w}x{h} in {pw}x{ph}"
            );
            for (j, (q, &(v, g))) in atlas.places.iter().zip(sizes).enumerate().skip(i + 1) {
                let apart = p.page != q.page
                    || p.x + w <= q.x
                    || q.x + v <= p.x
                    || p.y + h <= q.y
                    || q.y + g <= p.y;
                assert!(apart, "{i} {p:?} {w}x{h} overlaps {j} {q:?} {v}x{g}");
            }
        }
    }

    #[test]
    fn power_of_two_macro_textures_pack_without_gaps() {
        // a typical cell: wide, low macro-textures of few heights
        let mut sizes = vec![(4096, 64); 3];
        sizes.extend([(4096, 32), (2048, 32), (2048, 16), (1024, 16), (1024, 16)]);
        sizes.push((1024, 8));
        sizes.extend([(512, 8); 4]);
        sizes.extend([(256, 4); 8]);
        let atlas = pack(&sizes, 8192).expect("pack");
        check(&sizes, &atlas, 8192);
        let area: u64 = sizes.iter().map(|&(w, h)| w as u64 * h as u64).sum();
        assert_eq!(atlas.pages.len(), 1);
        assert_eq!(atlas.texels(), area, "{:?}", atlas.pages);
    }

    #[test]
    fn pages_open_when_one_is_full_and_bad_sizes_are_errors() {
        let sizes = vec![(64, 64); 10];
        let atlas = pack(&sizes, 128).expect("pack");
        check(&sizes, &atlas, 128);
        assert_eq!(atlas.pages, vec![(128, 128), (128, 128), (128, 64)]);
        assert!(matches!(pack(&[(0, 4)], 128), Err(GpuError::Limit(_))));
        assert!(matches!(pack(&[(4, 129)], 128), Err(GpuError::Limit(_))));
        assert_eq!(pack(&[], 128).expect("empty"), Atlas::default());
    }

    proptest! {
        #[test]
        fn any_sizes_pack_inside_and_apart(
            sizes in prop::collection::vec((1u32..=200, 1u32..=200), 0..60),
            max_side in 200u32..=600,
        ) {
            let atlas = pack(&sizes, max_side).expect("pack");
            check(&sizes, &atlas, max_side);
            // no page holds less than a fifth of its area, except the last
            if atlas.pages.len() > 1 {
                let area: u64 = sizes.iter().map(|&(w, h)| w as u64 * h as u64).sum();
                prop_assert!(atlas.texels() <= 5 * area, "{} texels for {area}", atlas.texels());
            }
        }
    }
}
