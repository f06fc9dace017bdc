//! Macro-texture packing (GI 2002 sec. 5.4): known answers for the sort and fill rules, and
//! properties on random rectangle sets (no overlap, all inside, power-of-two sizes, every pixel
//! copied, rotated ones included).

use lemi_core::compress::{
    analyze_block_sharing, analyze_packing, pack_micro_textures, pack_rects, pack_stacked,
    MacroPlacement, MicroTexture, Packing, PackingOptions, TexelRect,
};
use lemi_core::Face;
use proptest::prelude::*;

fn opts(max_size: u32) -> PackingOptions {
    PackingOptions {
        max_size,
        ..Default::default()
    }
}

fn at(macro_index: u32, x: u32, y: u32, rotated: bool) -> MacroPlacement {
    MacroPlacement {
        macro_index,
        x,
        y,
        rotated,
    }
}

#[test]
fn rotated_to_top_down_and_placed_bottom_left() {
    // (8×4) turns into 4×8; both 4×8: macro height 8, width 64/8 = 8, side by side
    let p = pack_rects(&[(4, 8), (8, 4)], &opts(64)).unwrap();
    assert_eq!(p.macro_sizes, vec![(8, 8)]);
    assert_eq!(p.placements, vec![at(0, 0, 0, false), at(0, 4, 0, true)]);
    let s = analyze_packing(&[(4, 8), (8, 4)], &p).unwrap();
    assert_eq!(s.efficiency, 1.0);
    assert_eq!(s.macro_bytes, 256);
}

#[test]
fn sorted_by_height_then_width_then_small_ones_fill_left_bottom() {
    // heights 16, 16, 8, 4 (after rotation); equal heights: narrower first.
    // area = 10·16 + 6·16 + 8·8 + 4·4 = 336 → height 16, width 336/16 = 21 → 32.
    // Phase 1 along the bottom: 6×16 at x 0, 10×16 at x 6, 8×8 at x 16, 4×4 at x 24: all fit.
    let sizes = [(10, 16), (16, 6), (8, 8), (4, 4)];
    let p = pack_rects(&sizes, &opts(256)).unwrap();
    assert_eq!(p.macro_sizes, vec![(32, 16)]);
    assert_eq!(
        p.placements,
        vec![
            at(0, 6, 0, false),
            at(0, 0, 0, true),
            at(0, 16, 0, false),
            at(0, 24, 0, false)
        ]
    );
    // two 16×16 fill a macro of 32 × 16 (area 640 / 16 = 40 → 64, capped at max_size 32); the
    // 8×8 ones find no space left and start a second macro-texture of height 8, width 128/8 = 16.
    let sizes = [(16, 16), (16, 16), (8, 8), (8, 8)];
    let p = pack_rects(&sizes, &opts(32)).unwrap();
    assert_eq!(p.macro_sizes, vec![(32, 16), (16, 8)]);
    assert_eq!(
        p.placements,
        vec![
            at(0, 0, 0, false),
            at(0, 16, 0, false),
            at(1, 0, 0, false),
            at(1, 8, 0, false)
        ]
    );
}

#[test]
fn the_left_bottom_phase_starts_with_the_smallest() {
    // 8×16, 4×4, 2×2: area 148 → height 16, width 148/16 → 10 → 16.
    // Phase 1: 8×16 at (0,0), then 4×4 fits on the bottom at (8,0), then 2×2 at (12,0).
    let p = pack_rects(&[(8, 16), (4, 4), (2, 2)], &opts(64)).unwrap();
    assert_eq!(
        p.placements,
        vec![at(0, 0, 0, false), at(0, 8, 0, false), at(0, 12, 0, false)]
    );
    // 4×16 (narrower, first), 8×16, 4×4, 2×2: area 212 → width 16. Phase 1 puts the first three
    // on the bottom row (x = 0, 4, 12); the 2×2 no longer fits at y = 0, which ends phase 1, and
    // phase 2 (left-bottom, smallest first) puts it at the leftmost free x = 12, lowest y = 4.
    let p = pack_rects(&[(8, 16), (4, 16), (4, 4), (2, 2)], &opts(64)).unwrap();
    assert_eq!(p.macro_sizes, vec![(16, 16)]);
    assert_eq!(
        p.placements,
        vec![
            at(0, 4, 0, false),
            at(0, 0, 0, false),
            at(0, 12, 0, false),
            at(0, 12, 4, false)
        ]
    );
}

#[test]
fn oversized_and_empty_rectangles_are_errors() {
    assert!(pack_rects(&[(65, 3)], &opts(64)).is_err());
    assert!(pack_rects(&[(0, 3)], &opts(64)).is_err());
    assert!(pack_rects(&[(1, 1)], &opts(48)).is_err());
    assert_eq!(pack_rects(&[], &opts(64)).unwrap(), Packing::default());
}

#[test]
fn analyzer_catches_overlaps_and_bad_sizes() {
    let sizes = [(4, 4), (4, 4)];
    let overlap = Packing {
        macro_sizes: vec![(8, 8)],
        placements: vec![at(0, 0, 0, false), at(0, 3, 3, false)],
    };
    assert!(analyze_packing(&sizes, &overlap).is_err());
    let outside = Packing {
        macro_sizes: vec![(8, 8)],
        placements: vec![at(0, 0, 0, false), at(0, 5, 0, false)],
    };
    assert!(analyze_packing(&sizes, &outside).is_err());
    // a trimmed (not power-of-two) size is fine, an empty one is not
    let trimmed = Packing {
        macro_sizes: vec![(12, 4)],
        placements: vec![at(0, 0, 0, false), at(0, 4, 0, false)],
    };
    assert!(analyze_packing(&sizes, &trimmed).is_ok());
    let empty = Packing {
        macro_sizes: vec![(12, 4), (0, 4)],
        placements: vec![at(0, 0, 0, false), at(0, 4, 0, false)],
    };
    assert!(analyze_packing(&sizes, &empty).is_err());
}

fn micro(w: u32, h: u32, seed: u64) -> MicroTexture {
    let mut s = seed | 1;
    let mut pixels = Vec::with_capacity((w * h * 4) as usize);
    for _ in 0..w * h {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        let b = s.to_le_bytes();
        pixels.extend_from_slice(&[b[0], b[1], b[2], 255]);
    }
    MicroTexture {
        face: Face::PosX,
        layer: 0,
        distance: 1.0,
        res: 64,
        rect: TexelRect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        },
        pixels,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]
    #[test]
    fn packing_keeps_everything_inside_without_overlap_and_copies_every_pixel(
        sizes in prop::collection::vec((1u32..=40, 1u32..=40), 1..80),
        max_log in 6u32..9,
        seed in any::<u64>(),
    ) {
        let max = 1 << max_log;
        let micros: Vec<MicroTexture> = sizes.iter().enumerate()
            .map(|(i, &(w, h))| micro(w, h, seed.wrapping_add(i as u64)))
            .collect();
        let (macros, placements, stats) = pack_micro_textures(&micros, &opts(max)).unwrap();
        let packing = Packing {
            macro_sizes: macros.iter().map(|m| (m.width, m.height)).collect(),
            placements: placements.clone(),
        };
        prop_assert_eq!(analyze_packing(&sizes, &packing).unwrap(), stats);
        for m in &macros {
            prop_assert!(m.width.is_power_of_two() && m.height.is_power_of_two());
            prop_assert!(m.width <= max && m.height <= max);
        }
        for (mt, p) in micros.iter().zip(&placements) {
            let (w, h) = (mt.rect.width(), mt.rect.height());
            // top-down after rotation
            let (fw, fh) = p.footprint(w, h);
            prop_assert!(fh >= fw);
            prop_assert_eq!(p.rotated, w > h);
            let mac = &macros[p.macro_index as usize];
            let corners = p.macro_corners(w, h);
            for y in 0..h {
                for x in 0..w {
                    let (mx, my) = p.macro_texel(w, h, x, y);
                    let d = 4 * (my * mac.width + mx) as usize;
                    let s = 4 * (y * w + x) as usize;
                    prop_assert_eq!(&mac.rgba[d..d + 4], &mt.pixels[s..s + 4]);
                    // the texel centre, interpolated between the quad corners' texture coordinates,
                    // lands in the centre of that macro texel
                    let (u, v) = ((x as f64 + 0.5) / w as f64, (y as f64 + 0.5) / h as f64);
                    let lerp = |k: usize| {
                        let top = corners[0][k] as f64 * (1.0 - u) + corners[1][k] as f64 * u;
                        let bottom = corners[3][k] as f64 * (1.0 - u) + corners[2][k] as f64 * u;
                        top * (1.0 - v) + bottom * v
                    };
                    prop_assert!((lerp(0) - (mx as f64 + 0.5)).abs() < 1e-9);
                    prop_assert!((lerp(1) - (my as f64 + 0.5)).abs() < 1e-9);
                }
            }
        }
        // texels outside every footprint stay transparent
        let used: u64 = macros.iter().map(|m| m.rgba.chunks_exact(4).filter(|p| p[3] != 0).count() as u64).sum();
        prop_assert_eq!(used, stats.micro_texels);
    }
}

/// The GI 2002 sec. 5.4 packer written the slow way, on an occupancy grid: every position is tried,
/// so its bottom-left / left-bottom positions are exact by construction.
fn brute_pack(sizes: &[(u32, u32)], max: u32) -> Packing {
    let mut items: Vec<(usize, u32, u32, bool)> = sizes
        .iter()
        .enumerate()
        .map(|(i, &(w, h))| {
            if w > h {
                (i, h, w, true)
            } else {
                (i, w, h, false)
            }
        })
        .collect();
    items.sort_by(|a, b| b.2.cmp(&a.2).then(a.1.cmp(&b.1)).then(a.0.cmp(&b.0)));
    let mut out = Packing {
        macro_sizes: Vec::new(),
        placements: vec![at(0, 0, 0, false); sizes.len()],
    };
    while !items.is_empty() {
        let mi = out.macro_sizes.len() as u32;
        let h0 = items[0].2.next_power_of_two();
        let area: u64 = items.iter().map(|r| r.1 as u64 * r.2 as u64).sum();
        let w0 = (area.div_ceil(h0 as u64).next_power_of_two())
            .max(items[0].1.next_power_of_two() as u64)
            .min(max as u64) as u32;
        let mut grid = vec![false; (w0 * h0) as usize];
        let fits = |grid: &[bool], x: u32, y: u32, w: u32, h: u32| {
            x + w <= w0
                && y + h <= h0
                && (y..y + h).all(|yy| (x..x + w).all(|xx| !grid[(yy * w0 + xx) as usize]))
        };
        let mut placed = vec![false; items.len()];
        let mut put = |grid: &mut Vec<bool>, k: usize, x: u32, y: u32, placed: &mut Vec<bool>| {
            let (i, w, h, r) = items[k];
            for yy in y..y + h {
                for xx in x..x + w {
                    grid[(yy * w0 + xx) as usize] = true;
                }
            }
            placed[k] = true;
            out.placements[i] = at(mi, x, y, r);
        };
        let mut k = 0;
        while k < items.len() {
            let (_, w, h, _) = items[k];
            // bottom-left: lowest y, then lowest x
            let pos = (0..h0)
                .flat_map(|y| (0..w0).map(move |x| (x, y)))
                .find(|&(x, y)| fits(&grid, x, y, w, h));
            match pos {
                Some((x, 0)) => put(&mut grid, k, x, 0, &mut placed),
                _ => break,
            }
            k += 1;
        }
        for j in (k..items.len()).rev() {
            let (_, w, h, _) = items[j];
            // left-bottom: lowest x, then lowest y
            let pos = (0..w0)
                .flat_map(|x| (0..h0).map(move |y| (x, y)))
                .find(|&(x, y)| fits(&grid, x, y, w, h));
            if let Some((x, y)) = pos {
                put(&mut grid, j, x, y, &mut placed);
            }
        }
        out.macro_sizes.push((w0, h0));
        items = items
            .into_iter()
            .zip(placed)
            .filter(|(_, p)| !p)
            .map(|(r, _)| r)
            .collect();
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn packing_positions_equal_the_brute_force_rules(
        sizes in prop::collection::vec((1u32..=12, 1u32..=12), 1..30),
        max_log in 4u32..7,
    ) {
        let max = 1 << max_log;
        prop_assert_eq!(pack_rects(&sizes, &opts(max)).unwrap(), brute_pack(&sizes, max));
    }
}

/// Block-aligned packing as the bakes of block formats use it (trimmed sides).
fn block_opts(max_size: u32) -> PackingOptions {
    PackingOptions {
        max_size,
        block: 4,
        trim: true,
        stack: 0,
    }
}

#[test]
fn without_block_alignment_small_micro_textures_share_blocks() {
    // the control of the property below: 1×1 and 3×2 micro-textures packed tightly share 4×4 blocks
    let sizes = [(1, 1), (3, 2), (1, 1), (2, 3)];
    let p = pack_rects(&sizes, &opts(64)).unwrap();
    assert!(analyze_block_sharing(&sizes, &p, 4).shared_blocks > 0);
    let p = pack_rects(&sizes, &block_opts(64)).unwrap();
    let s = analyze_block_sharing(&sizes, &p, 4);
    assert_eq!((s.used_blocks, s.shared_blocks), (4, 0));
    assert!(pack_rects(
        &sizes,
        &PackingOptions {
            max_size: 64,
            block: 3,
            ..Default::default()
        }
    )
    .is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]
    #[test]
    fn block_aligned_packing_never_shares_a_block_and_keeps_every_texel(
        sizes in prop::collection::vec((1u32..=40, 1u32..=40), 1..80),
        max_log in 6u32..9,
        seed in any::<u64>(),
    ) {
        let max = 1 << max_log;
        let micros: Vec<MicroTexture> = sizes.iter().enumerate()
            .map(|(i, &(w, h))| micro(w, h, seed.wrapping_add(i as u64)))
            .collect();
        let (macros, placements, stats) = pack_micro_textures(&micros, &block_opts(max)).unwrap();
        let packing = Packing {
            macro_sizes: macros.iter().map(|m| (m.width, m.height)).collect(),
            placements: placements.clone(),
        };
        prop_assert_eq!(analyze_packing(&sizes, &packing).unwrap(), stats);
        prop_assert_eq!(analyze_block_sharing(&sizes, &packing, 4).shared_blocks, 0);
        for m in &macros {
            prop_assert!(m.width % 4 == 0 && m.height % 4 == 0);
        }
        for (mt, p) in micros.iter().zip(&placements) {
            let (w, h) = (mt.rect.width(), mt.rect.height());
            prop_assert!(p.x % 4 == 0 && p.y % 4 == 0);
            prop_assert_eq!(p.rotated, w > h);
            // the quad's own texels, exactly where its corners say
            let mac = &macros[p.macro_index as usize];
            let c = p.macro_corners(w, h);
            let (fw, fh) = p.footprint(w, h);
            let (xs, ys) = ([c[0][0], c[1][0], c[2][0], c[3][0]], [c[0][1], c[1][1], c[2][1], c[3][1]]);
            prop_assert_eq!((*xs.iter().min().unwrap(), *xs.iter().max().unwrap()), (p.x, p.x + fw));
            prop_assert_eq!((*ys.iter().min().unwrap(), *ys.iter().max().unwrap()), (p.y, p.y + fh));
            for y in 0..h {
                for x in 0..w {
                    let (mx, my) = p.macro_texel(w, h, x, y);
                    let d = 4 * (my * mac.width + mx) as usize;
                    let s = 4 * (y * w + x) as usize;
                    prop_assert_eq!(&mac.rgba[d..d + 4], &mt.pixels[s..s + 4]);
                }
            }
        }
        let used: u64 = macros.iter().map(|m| m.rgba.chunks_exact(4).filter(|p| p[3] != 0).count() as u64).sum();
        prop_assert_eq!(used, stats.micro_texels);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Packing without power-of-two sides (`PackingOptions::trim`): a valid packing whose
    /// macro-textures are cut to their footprints (some footprint touches each one's right and
    /// bottom edge), sides multiples of the block, no block shared.
    #[test]
    fn trimmed_packing_is_valid_and_cut_to_the_footprints(
        sizes in prop::collection::vec((1u32..=40, 1u32..=40), 1..80),
        max_log in 6u32..9,
        block in prop::sample::select(vec![1u32, 4]),
    ) {
        let max = 1 << max_log;
        let paper = PackingOptions { max_size: max, block, trim: false, stack: 0 };
        let trimmed = PackingOptions { trim: true, ..paper };
        let b = pack_rects(&sizes, &trimmed).unwrap();
        prop_assert!(analyze_packing(&sizes, &pack_rects(&sizes, &paper).unwrap()).is_ok());
        let stats = analyze_packing(&sizes, &b);
        prop_assert!(stats.is_ok(), "{:?}", stats);
        prop_assert_eq!(analyze_block_sharing(&sizes, &b, block).shared_blocks, 0);
        for (m, &(w, h)) in b.macro_sizes.iter().enumerate() {
            prop_assert!(w <= max && h <= max && w % block == 0 && h % block == 0);
            let footprints: Vec<(u32, u32)> = sizes.iter().zip(&b.placements)
                .filter(|(_, p)| p.macro_index as usize == m)
                .map(|(&(sw, sh), p)| {
                    let pad = |v: u32| v.div_ceil(block) * block;
                    let (fw, fh) = p.footprint(pad(sw), pad(sh));
                    (p.x + fw, p.y + fh)
                })
                .collect();
            prop_assert_eq!(footprints.iter().map(|f| f.0).max(), Some(w));
            prop_assert_eq!(footprints.iter().map(|f| f.1).max(), Some(h));
        }
    }
}

#[test]
fn trimmed_packing_uses_fewer_texels_than_powers_of_two() {
    // the city cells' micro-textures are many and small; so are these
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = |n: u32| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        1 + (seed % n as u64) as u32
    };
    let sizes: Vec<(u32, u32)> = (0..3000).map(|_| (rnd(12), rnd(12))).collect();
    for block in [1, 4] {
        let paper = PackingOptions {
            max_size: 4096,
            block,
            trim: false,
            stack: 0,
        };
        let trimmed = PackingOptions {
            trim: true,
            ..paper
        };
        let texels = |o: &PackingOptions| {
            let p = pack_rects(&sizes, o).unwrap();
            assert!(analyze_packing(&sizes, &p).is_ok());
            p.macro_sizes
                .iter()
                .map(|&(w, h)| w as u64 * h as u64)
                .sum::<u64>()
        };
        let (a, b) = (texels(&paper), texels(&trimmed));
        println!("block {block}: {a} texels in powers of two, {b} trimmed");
        assert!(b < a, "block {block}: {b} trimmed texels against {a}");
    }
}

/// Thin bands of a grazing ground plane, one per layer, each a texel or two high and stacked up
/// the face image (the case stacks are for), plus random rectangles on two faces.
fn stack_case(seed: u64, n: usize) -> Vec<MicroTexture> {
    let mut s = seed | 1;
    let mut rnd = |m: u32| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s % m as u64) as u32
    };
    let mut out = Vec::new();
    for layer in 0..n as u32 {
        // even layers: a band one row above the previous one; odd ones: anything
        let (face, x0, y0, w, h) = if layer % 2 == 0 {
            (Face::PosX, rnd(20), 200 - layer / 2, 100 + rnd(150), 1)
        } else {
            (Face::NegZ, rnd(200), rnd(240), 1 + rnd(30), 1 + rnd(12))
        };
        let mut m = micro(w, h, seed ^ layer as u64);
        m.face = face;
        m.layer = layer;
        m.rect = TexelRect {
            x0,
            y0,
            x1: x0 + w,
            y1: y0 + h,
        };
        out.push(m);
    }
    out
}

#[test]
fn stacks_take_fewer_blocks_for_thin_bands_and_none_without_blocks() {
    let micros = stack_case(7, 120);
    let (_, _, plain) = pack_micro_textures(&micros, &block_opts(1024)).unwrap();
    let stacked_opts = PackingOptions {
        stack: 1024,
        ..block_opts(1024)
    };
    let (_, _, stacked) = pack_micro_textures(&micros, &stacked_opts).unwrap();
    assert!(
        (stacked.macro_texels as f64) < 0.8 * plain.macro_texels as f64,
        "{} against {}",
        stacked.macro_texels,
        plain.macro_texels
    );
    // without blocks there is nothing to share: stacking is off
    let p1 = pack_stacked(&face_rects(&micros), &opts(1024)).unwrap();
    let p2 = pack_stacked(
        &face_rects(&micros),
        &PackingOptions {
            stack: 1024,
            ..opts(1024)
        },
    )
    .unwrap();
    assert_eq!(p1, p2);
    assert_eq!(p1.stacks.len(), micros.len());
}

fn face_rects(micros: &[MicroTexture]) -> Vec<(u32, TexelRect)> {
    micros
        .iter()
        .map(|m| (m.face.index() as u32, m.rect))
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Stacks hold micro-textures of one face whose rectangles do not overlap; no block holds
    /// texels of two stacks; every micro-texture's texels are where its placement says (turned
    /// stacks included), and its rectangle's texels are its own.
    #[test]
    fn stacked_packing_keeps_every_micro_textures_texels(
        seed in 1u64..u64::MAX,
        n in 1usize..160,
        thickest in prop::sample::select(vec![1u32, 2, 512]),
    ) {
        let micros = stack_case(seed, n);
        let options = PackingOptions { stack: thickest, ..block_opts(512) };
        let rects = face_rects(&micros);
        let p = pack_stacked(&rects, &options).unwrap();
        let mut seen = vec![false; micros.len()];
        for s in &p.stacks {
            for (k, &a) in s.members.iter().enumerate() {
                prop_assert!(!seen[a]);
                seen[a] = true;
                let (fa, ra) = rects[a];
                prop_assert!(ra.x0 >= s.bbox.x0 && ra.x1 <= s.bbox.x1 && ra.y0 >= s.bbox.y0 && ra.y1 <= s.bbox.y1);
                for &b in &s.members[k + 1..] {
                    let (fb, rb) = rects[b];
                    prop_assert_eq!(fa, fb);
                    prop_assert!(ra.x1 <= rb.x0 || rb.x1 <= ra.x0 || ra.y1 <= rb.y0 || rb.y1 <= ra.y0);
                }
            }
        }
        prop_assert!(seen.iter().all(|s| *s));
        // a rectangle thicker than `thickest` stays alone
        for s in &p.stacks {
            if s.members.len() > 1 {
                for &m in &s.members {
                    let r = rects[m].1;
                    prop_assert!(r.width().min(r.height()) <= thickest);
                }
            }
        }
        let sizes: Vec<(u32, u32)> = p.stacks.iter().map(|s| (s.bbox.width(), s.bbox.height())).collect();
        prop_assert_eq!(analyze_block_sharing(&sizes, &p.stack_packing, 4).shared_blocks, 0);
        let (macros, placements, _) = pack_micro_textures(&micros, &options).unwrap();
        prop_assert_eq!(&placements, &p.packing.placements);
        for (m, pl) in micros.iter().zip(&placements) {
            let (w, h) = (m.rect.width(), m.rect.height());
            let mt = &macros[pl.macro_index as usize];
            for y in 0..h {
                for x in 0..w {
                    let (mx, my) = pl.macro_texel(w, h, x, y);
                    let d = 4 * (my * mt.width + mx) as usize;
                    let s = 4 * (y * w + x) as usize;
                    prop_assert_eq!(&mt.rgba[d..d + 4], &m.pixels[s..s + 4]);
                }
            }
        }
    }
}

#[test]
fn overlapping_rectangles_never_stack_and_many_of_them_stay_cheap() {
    // a damaged or hostile cell: the reader derives the stacks of whatever rectangles it lists;
    // each looks at a bounded number of stacks, so 20,000 on one spot take linear time
    let r = TexelRect {
        x0: 10,
        y0: 10,
        x1: 14,
        y1: 11,
    };
    let rects = vec![(0u32, r); 20_000];
    let options = PackingOptions {
        stack: 4096,
        ..block_opts(4096)
    };
    let p = pack_stacked(&rects, &options).unwrap();
    assert_eq!(p.stacks.len(), rects.len());
}
