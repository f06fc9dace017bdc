//! Known-answer tests of the image stages of GI 2002 sec. 5: gap filling (5.1), hidden-texel
//! removal (5.2) and micro-textures (5.3), on small hand-built layer images.

use glam::DVec3;
use lemi_core::compress::{
    analyze_micro_textures, copy_outlines, extract_micro_textures, fill_gaps, quad_corners,
    remove_hidden_texels, CompressError, GapSources, HiddenTexelOptions, LayerImage,
    MicroTextureOptions, TexelRect, FRINGE_ALPHA, TRANSPARENT,
};
use lemi_core::Face;
use proptest::prelude::*;

/// Colour of an ASCII-art texel: `.` is transparent, any other character opaque with that colour.
fn colour(c: char) -> [u8; 4] {
    if c == '.' {
        [0, 0, 0, 0]
    } else {
        [c as u8, 7, 9, 255]
    }
}

/// A layer image from ASCII art (one string per row).
fn art(rows: &[&str]) -> LayerImage {
    let res = rows.len() as u32;
    let mut img = LayerImage::new(res);
    for (y, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), rows.len(), "square art");
        for (x, c) in row.chars().enumerate() {
            let i = img.index(x as u32, y as u32);
            img.set_texel(i, colour(c));
        }
    }
    img
}

/// The image back as ASCII art.
fn to_art(img: &LayerImage) -> Vec<String> {
    (0..img.res)
        .map(|y| {
            (0..img.res)
                .map(|x| {
                    let t = img.texel(img.index(x, y));
                    if t[3] == 0 {
                        '.'
                    } else {
                        t[0] as char
                    }
                })
                .collect()
        })
        .collect()
}

/// `res × res` image with every texel in the inclusive square `[lo, hi]²` set to `c`.
fn square(res: u32, lo: u32, hi: u32, c: char) -> LayerImage {
    let mut img = LayerImage::new(res);
    for y in lo..=hi {
        for x in lo..=hi {
            let i = img.index(x, y);
            img.set_texel(i, colour(c));
        }
    }
    img
}

fn full(res: u32, c: char) -> LayerImage {
    square(res, 0, res - 1, c)
}

// ---------------------------------------------------------------- gap filling (sec. 5.1)

#[test]
fn gap_fill_copies_opaque_border_texels_onto_opaque_and_transparent_border_texels() {
    let near = art(&[
        "........", //
        "........", //
        "..aaa...", //
        "..aaa...", //
        "..aaa...", //
        "........", //
        "........", //
        "........",
    ]);
    // (3,3) lies behind the near interior texel: not a source, so it keeps its colour;
    // (2,4) is opaque behind a near border texel: overwritten
    let far = art(&[
        "........", //
        "........", //
        ".....bbb", //
        "...c.bbb", //
        "..d..bbb", //
        "........", //
        "........", //
        "........",
    ]);
    let mut layers = vec![near.clone(), far];
    let stats = fill_gaps(&mut layers, GapSources::AllBorder).unwrap();
    assert_eq!(layers[0], near, "the closer layer is not changed");
    // sources: the 8 ring texels of the near block. Targets in the far layer: opaque texels and
    // transparent texels with an opaque 8-neighbour. Ring texels (2,2),(3,2),(4,2),(2,3),(4,3),
    // (3,4),(4,4) are transparent neighbours of c, d or b; (2,4) is opaque d.
    assert_eq!(
        to_art(&layers[1]),
        [
            "........", //
            "........", //
            "..aaabbb", //
            "..acabbb", //
            "..aaabbb", //
            "........", //
            "........", //
            "........",
        ]
    );
    assert_eq!(stats.pairs, 1);
    assert_eq!(stats.source_texels, 8);
    assert_eq!(stats.filled, 7);
    assert_eq!(stats.overwritten, 1);
}

#[test]
fn gap_fill_only_fills_next_to_the_distant_surface() {
    let near = art(&[
        "........", //
        "........", //
        "..aaa...", //
        "..aaa...", //
        "..aaa...", //
        "........", //
        "........", //
        "........",
    ]);
    let far = art(&[
        "........", //
        "........", //
        ".....bbb", //
        ".....bbb", //
        ".....bbb", //
        "........", //
        "........", //
        "........",
    ]);
    let mut layers = vec![near, far];
    let stats = fill_gaps(&mut layers, GapSources::AllBorder).unwrap();
    assert_eq!(
        to_art(&layers[1]),
        [
            "........", //
            "........", //
            "....abbb", //
            "....abbb", //
            "....abbb", //
            "........", //
            "........", //
            "........",
        ]
    );
    assert_eq!((stats.filled, stats.overwritten), (3, 0));
}

#[test]
fn gap_fill_works_on_the_recorded_images_pair_by_pair() {
    // layer 1's filled texel (4,3) is not copied on into layer 2; layer 1's own border texel
    // (5,3) is copied into layer 2, where (4,4) makes (5,3) a transparent border texel.
    let l0 = art(&[
        "........", //
        "........", //
        "..aaa...", //
        "..aaa...", //
        "..aaa...", //
        "........", //
        "........", //
        "........",
    ]);
    let l1 = art(&[
        "........", //
        "........", //
        "........", //
        ".....b..", //
        "........", //
        "........", //
        "........", //
        "........",
    ]);
    let l2 = art(&[
        "........", //
        "........", //
        "........", //
        "........", //
        "....c...", //
        "........", //
        "........", //
        "........",
    ]);
    let mut layers = vec![l0, l1, l2];
    fill_gaps(&mut layers, GapSources::AllBorder).unwrap();
    assert_eq!(
        to_art(&layers[1]),
        [
            "........", //
            "........", //
            "....a...", //
            "....ab..", //
            "....a...", //
            "........", //
            "........", //
            "........",
        ]
    );
    assert_eq!(
        to_art(&layers[2]),
        [
            "........", //
            "........", //
            "........", //
            ".....b..", //
            "....c...", //
            "........", //
            "........", //
            "........",
        ]
    );
}

#[test]
fn gap_fill_also_closes_the_diagonal_clip_edge_crack_of_the_tr() {
    // TR sec. 2.2, fig. 9 right: a polygon cut by a border along an 8-connected diagonal clipping
    // line, recorded in both layers (x == y); the near part is x ≥ y, the far part x ≤ y. In every
    // 2×2 block on the line the texel above it is only in the near layer and the one below only in
    // the far layer: a crack when moving diagonally. Gap filling copies the near texel above the
    // line into the far layer, making the far part four-connected (x ≤ y + 1).
    let res = 8u32;
    let (mut near, mut far) = (LayerImage::new(res), LayerImage::new(res));
    for y in 0..res {
        for x in 0..res {
            let i = near.index(x, y);
            if x >= y {
                near.set_texel(i, colour('n'));
            }
            if x <= y {
                far.set_texel(i, colour(if x == y { 'n' } else { 'f' }));
            }
            near.border[i] = x == y;
            far.border[i] = x == y;
        }
    }
    let mut layers = vec![near, far];
    fill_gaps(&mut layers, GapSources::AllBorder).unwrap();
    for y in 0..res {
        for x in 0..res {
            let t = layers[1].texel(layers[1].index(x, y));
            let want = if x <= y + 1 {
                colour(if x < y { 'f' } else { 'n' })
            } else {
                [0, 0, 0, 0]
            };
            assert_eq!(t, want, "({x},{y})");
        }
    }
}

/// The default rule copies only the clip-edge texels of the closer layer's far border: a surface
/// cut at the border (a 4-connected supercover line, as the recorder covers cut edges, recorded in
/// both layers) keeps its copy, while the silhouette of an object ending inside the closer slab
/// (a block beside it) is no longer drawn again one layer farther back. The paper's rule copies
/// both.
#[test]
fn gap_fill_by_default_copies_only_far_border_clip_edges() {
    let near = art(&[
        "........", //
        ".aa.....", //
        ".aa.....", //
        "........", //
        "....nnnn", //
        "....nnnn", //
        "........", //
        "........",
    ]);
    let far = art(&[
        "........", //
        "...b....", //
        "...b....", //
        "........", //
        "........", //
        "....ffff", //
        "....ffff", //
        "....ffff",
    ]);
    let with_flags = |mut img: LayerImage, far_edge: bool| {
        // the cut at the border between the layers: row 5 from x = 4, in both layers
        for x in 4..8 {
            let i = img.index(x, 5);
            img.border[i] = true;
            img.far_border[i] = far_edge;
        }
        img
    };
    let (near, far) = (with_flags(near, true), with_flags(far, false));
    let mut layers = vec![near.clone(), far.clone()];
    let stats = fill_gaps(&mut layers, GapSources::FarClipEdges).unwrap();
    // the far layer already covers the cut (row 5): nothing is overwritten; the block's
    // silhouette (a) is not copied next to b, and row 4 (the near part's other border texels) is
    // not copied
    assert_eq!(to_art(&layers[1]), to_art(&far));
    assert_eq!(stats.source_texels, 4);
    assert_eq!((stats.filled, stats.overwritten), (0, 0));
    // where the far layer lost a texel of the cut, it is filled from the closer layer
    let mut holed = far.clone();
    let hole = holed.index(6, 5);
    holed.clear_texel(hole);
    let mut layers = vec![near.clone(), holed];
    let stats = fill_gaps(&mut layers, GapSources::FarClipEdges).unwrap();
    assert_eq!((stats.filled, stats.overwritten), (1, 0));
    assert_eq!(to_art(&layers[1])[5], "....ffnf");
    // the paper's rule also draws the block's silhouette and the near part's upper row again
    let mut paper = vec![near, far];
    let s = fill_gaps(&mut paper, GapSources::AllBorder).unwrap();
    assert!(s.filled >= 4, "{s:?}");
    assert_eq!(&to_art(&paper[1])[1][..4], "..ab");
}

/// `img` with behind-plane flags from ASCII art: `b` behind the layer's plane, anything else not.
fn with_sides(img: LayerImage, rows: &[&str]) -> LayerImage {
    let flags = rows
        .iter()
        .flat_map(|r| r.chars().map(|c| c == 'b'))
        .collect();
    img.with_behind_plane(flags).expect("one flag a texel")
}

#[test]
fn outline_copies_go_to_the_side_their_point_lies_on() {
    // nearest first: the middle layer's square has its left column behind its plane, the rest
    // in front of it (or on it)
    let near = art(&[
        "........", //
        "........", //
        "........", //
        "........", //
        "........", //
        "........", //
        "........", //
        "......nn", //
    ]);
    let mid = with_sides(
        art(&[
            "........", //
            ".mmmm...", //
            ".mmmm...", //
            ".mmmm...", //
            ".mmmm...", //
            "........", //
            "........", //
            "........", //
        ]),
        &[
            "........", //
            ".bf.....", //
            ".bff....", //
            ".bff....", //
            ".bfff...", //
            "........", //
            "........", //
            "........", //
        ],
    );
    let far = art(&[
        "........", //
        "........", //
        "........", //
        "........", //
        "ffff....", //
        "........", //
        "........", //
        "........", //
    ]);
    let mut layers = vec![near, mid, far];
    let added = copy_outlines(&mut layers).expect("copies");
    // the behind column goes farther, except where the farther layer is opaque already (row 4)
    assert_eq!(
        to_art(&layers[2]),
        [
            "........", //
            ".m......", //
            ".m......", //
            ".m......", //
            "ffff....", //
            "........", //
            "........", //
            "........", //
        ]
    );
    // the rest of the outline goes nearer; the interior (2..3, 2..3) stays; the near layer's
    // texels have no flags and send nothing
    assert_eq!(
        to_art(&layers[0]),
        [
            "........", //
            "..mmm...", //
            "....m...", //
            "....m...", //
            "..mmm...", //
            "........", //
            "........", //
            "......nn", //
        ]
    );
    assert_eq!(to_art(&layers[1])[1], ".mmmm...", "the source is unchanged");
    assert_eq!(added, 3 + 8);
    // every copy is a clip-border texel (it hides nothing); the recorded texels are not
    let i = layers[0].index(2, 1);
    assert!(layers[0].border[i] && layers[2].border[layers[2].index(1, 2)]);
    assert!(!layers[2].border[layers[2].index(0, 4)]);
    assert!(!layers[0].border[layers[0].index(6, 7)]);
    // copies are never copied on: a second pass sends only the recorded outlines again, which
    // find their targets taken
    assert_eq!(copy_outlines(&mut layers).expect("copies"), 0);
}

#[test]
fn outline_copies_need_the_recorders_sides_and_matching_images() {
    let mut layers = vec![square(8, 2, 5, 'a'), square(8, 1, 6, 'b')];
    assert_eq!(copy_outlines(&mut layers).expect("no flags"), 0);
    assert!(LayerImage::new(8)
        .with_behind_plane(vec![true; 63])
        .is_err());
    let mut mixed = vec![
        with_sides(square(8, 2, 5, 'a'), &["bbbbbbbb"; 8]),
        LayerImage::new(4),
    ];
    assert!(copy_outlines(&mut mixed).is_err());
}

#[test]
fn gap_fill_rejects_mixed_resolutions() {
    let mut layers = vec![LayerImage::new(8), LayerImage::new(4)];
    assert!(matches!(
        fill_gaps(&mut layers, GapSources::default()),
        Err(CompressError::ResolutionMismatch { layer: 1, .. })
    ));
    let mut bad = vec![LayerImage {
        res: 4,
        rgba: vec![0; 3],
        border: vec![false; 16],
        far_border: vec![false; 16],
        content: lemi_core::compress::TexelRect::full(4),
        behind_plane: Vec::new(),
    }];
    assert!(matches!(
        fill_gaps(&mut bad, GapSources::default()),
        Err(CompressError::BadImage { .. })
    ));
}

// ---------------------------------------------------------------- hidden texels (sec. 5.2)

fn count_opaque_in(img: &LayerImage, lo: u32, hi: u32) -> usize {
    let mut n = 0;
    for y in lo..=hi {
        for x in lo..=hi {
            n += usize::from(img.is_opaque(img.index(x, y)));
        }
    }
    n
}

#[test]
fn hidden_texels_behind_an_opaque_interior_are_removed() {
    // 5×5 block at 1..=5: its non-border texels are 2..=4, so exactly those 9 far texels go.
    let near = square(12, 1, 5, 'a');
    let mut layers = vec![near.clone(), full(12, 'b')];
    let stats = remove_hidden_texels(&mut layers, &HiddenTexelOptions::default()).unwrap();
    assert_eq!(layers[0], near);
    assert_eq!(stats.removed, 9);
    assert_eq!(stats.removed_per_layer, vec![0, 9]);
    assert_eq!(count_opaque_in(&layers[1], 2, 4), 0);
    assert_eq!(count_opaque_in(&layers[1], 1, 5), 25 - 9);
    assert_eq!(layers[1].opaque_count(), 144 - 9);
    assert_eq!(stats.opaque_before, 25 + 144);
    assert_eq!(stats.opaque_after, 25 + 144 - 9);
}

#[test]
fn hidden_texels_next_to_a_hole_or_a_clip_border_texel_are_kept() {
    // 7×7 block at 1..=7: 25 non-border texels 2..=6. A hole at (4,4) makes its 3×3
    // neighbourhood visible: 25 − 9 = 16 removed.
    let mut near = square(12, 1, 7, 'a');
    let hole = near.index(4, 4);
    near.clear_texel(hole);
    let mut layers = vec![near, full(12, 'b')];
    let stats = remove_hidden_texels(&mut layers, &HiddenTexelOptions::default()).unwrap();
    assert_eq!(stats.removed, 16);
    for y in 3..=5 {
        for x in 3..=5 {
            assert!(layers[1].is_opaque(layers[1].index(x, y)), "({x},{y}) kept");
        }
    }

    // a clip-border texel at (4,4) occludes only when allowed to
    let mut near = square(12, 1, 7, 'a');
    let i = near.index(4, 4);
    near.border[i] = true;
    let mut layers = vec![near.clone(), full(12, 'b')];
    let stats = remove_hidden_texels(&mut layers, &HiddenTexelOptions::default()).unwrap();
    assert_eq!(stats.removed, 16);
    let mut layers = vec![near, full(12, 'b')];
    let literal = HiddenTexelOptions {
        clip_border_occludes: true,
        ..Default::default()
    };
    let stats = remove_hidden_texels(&mut layers, &literal).unwrap();
    assert_eq!(stats.removed, 25);

    // an outline fringe texel at (4,4) hides nothing (the runtime may leave it undrawn): its
    // 3×3 neighbourhood behind stays, as behind a hole
    let mut near = square(12, 1, 7, 'a');
    let i = near.index(4, 4);
    near.rgba[4 * i + 3] = FRINGE_ALPHA;
    let mut layers = vec![near, full(12, 'b')];
    let stats = remove_hidden_texels(&mut layers, &literal).unwrap();
    assert_eq!(stats.removed, 16);
    assert!(layers[1].is_opaque(layers[1].index(4, 4)));
}

#[test]
fn hidden_marks_chain_through_transparent_layers() {
    // layer 1 is empty, but its texels behind layer 0's interior (2..=6) are marked hidden and
    // count as opaque for the next pair: layer 2 loses the interior of that, 3..=5.
    let mut layers = vec![square(12, 1, 7, 'a'), LayerImage::new(12), full(12, 'c')];
    let stats = remove_hidden_texels(&mut layers, &HiddenTexelOptions::default()).unwrap();
    assert_eq!(stats.removed_per_layer, vec![0, 0, 9]);
    assert_eq!(stats.marked, 25 + 9);
    assert_eq!(count_opaque_in(&layers[2], 3, 5), 0);
    assert_eq!(layers[2].opaque_count(), 144 - 9);
}

#[test]
fn removed_texels_still_occlude_the_next_pair() {
    // layer 1 loses 2..=6 but still counts as fully opaque for layer 2, whose whole interior
    // (everything but the one-texel frame at the image edge) is hidden.
    let mut layers = vec![square(12, 1, 7, 'a'), full(12, 'b'), full(12, 'c')];
    let stats = remove_hidden_texels(&mut layers, &HiddenTexelOptions::default()).unwrap();
    assert_eq!(stats.removed_per_layer, vec![0, 25, 100]);
    assert_eq!(layers[2].opaque_count(), 144 - 100);
    assert_eq!(count_opaque_in(&layers[2], 1, 10), 0);
}

/// Brute force of sec. 5.2 for random stacks: a texel of layer k+j (j ≥ 1) is removed exactly when
/// every texel within j texels (Chebyshev) of it, inside the image, is covered, where "covered"
/// chains through the layers as the paper describes.
fn brute_hidden(layers: &[LayerImage]) -> Vec<Vec<bool>> {
    let res = layers[0].res as i64;
    let n = (res * res) as usize;
    let mut hidden = vec![vec![false; n]; layers.len()];
    for k in 0..layers.len() - 1 {
        for y in 0..res {
            for x in 0..res {
                let mut all = true;
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (nx, ny) = (x + dx, y + dy);
                        if nx < 0 || ny < 0 || nx >= res || ny >= res {
                            all = false;
                            continue;
                        }
                        let i = (ny * res + nx) as usize;
                        let l = &layers[k];
                        all &= hidden[k][i] || (l.is_opaque(i) && !l.border[i]);
                    }
                }
                hidden[k + 1][(y * res + x) as usize] = all;
            }
        }
    }
    hidden
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn hidden_removal_matches_brute_force(
        res in 3u32..14,
        nl in 2usize..5,
        seed in any::<u64>(),
    ) {
        let mut s = seed | 1;
        let mut next = move || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
        let layers: Vec<LayerImage> = (0..nl).map(|_| {
            let mut img = LayerImage::new(res);
            for i in 0..img.texel_count() {
                let r = next();
                if r % 8 != 0 { img.set_texel(i, [1 + (r >> 8) as u8 % 200, 2, 3, 255]); }
                img.border[i] = (r >> 20) % 11 == 0;
            }
            img
        }).collect();
        let expected = brute_hidden(&layers);
        let mut out = layers.clone();
        let stats = remove_hidden_texels(&mut out, &HiddenTexelOptions::default()).unwrap();
        let mut removed = 0;
        for (k, exp) in expected.iter().enumerate() {
            for (i, &hidden) in exp.iter().enumerate() {
                if hidden {
                    prop_assert_eq!(out[k].texel(i), [0, 0, 0, 0]);
                    removed += u64::from(layers[k].is_opaque(i));
                } else {
                    prop_assert_eq!(out[k].texel(i), layers[k].texel(i));
                }
            }
        }
        prop_assert_eq!(stats.removed, removed);
    }
}

// ---------------------------------------------------------------- micro-textures (sec. 5.3)

/// The paper's micro-textures (no merging of neighbours).
fn opts(cell_size: u32, threshold: f64) -> MicroTextureOptions {
    MicroTextureOptions {
        cell_size,
        threshold,
        merge: false,
    }
}

fn rect(x0: u32, y0: u32, x1: u32, y1: u32) -> TexelRect {
    TexelRect { x0, y0, x1, y1 }
}

#[test]
fn a_full_image_is_one_micro_texture_and_an_empty_one_none() {
    let img = full(16, 'a');
    let (m, s) = extract_micro_textures(&img, Face::PosX, 3, 50.0, &opts(8, 0.6)).unwrap();
    assert_eq!(m.len(), 1);
    assert_eq!(m[0].rect, rect(0, 0, 16, 16));
    assert_eq!(
        (m[0].face, m[0].layer, m[0].distance),
        (Face::PosX, 3, 50.0)
    );
    assert_eq!(m[0].pixels, img.rgba);
    assert_eq!((s.micro_textures, s.opaque_texels, s.texels), (1, 256, 256));
    let (m, s) =
        extract_micro_textures(&LayerImage::new(16), Face::PosX, 0, 1.0, &opts(8, 0.6)).unwrap();
    assert!(m.is_empty());
    assert_eq!(s.fill_ratio, 1.0);
}

#[test]
fn separated_blobs_give_tight_separate_micro_textures() {
    let mut img = square(32, 1, 3, 'a');
    for y in 26..=28 {
        for x in 26..=28 {
            let i = img.index(x, y);
            img.set_texel(i, colour('b'));
        }
    }
    let (m, _) = extract_micro_textures(&img, Face::NegZ, 0, 1.0, &opts(8, 0.0)).unwrap();
    let rects: Vec<_> = m.iter().map(|m| m.rect).collect();
    // even with threshold 0 a cell only grows towards non-transparent cells
    assert_eq!(rects, vec![rect(1, 1, 4, 4), rect(26, 26, 29, 29)]);
    analyze_micro_textures(&img, &m).unwrap();
}

/// 16² image, 8-texel cells: cell (0,0) full (64), cell (1,0) one column (8), cell (0,1) top half
/// (32), cell (1,1) empty.
fn growth_image() -> LayerImage {
    let mut img = LayerImage::new(16);
    for y in 0..16 {
        for x in 0..16 {
            if (x < 8 && y < 12) || (x == 8 && y < 8) {
                let i = img.index(x, y);
                img.set_texel(i, colour('g'));
            }
        }
    }
    img
}

#[test]
fn growth_takes_the_best_direction_and_stops_at_the_threshold() {
    let img = growth_image();
    // from cell (0,0): E gives 72/128 = 0.5625, S 96/128 = 0.75, SE 104/256 = 0.406.
    // Threshold 0.6: grow S, then E would give 104/256 < 0.6: stop. Cell (1,0) is left alone.
    let (m, s) = extract_micro_textures(&img, Face::PosZ, 0, 1.0, &opts(8, 0.6)).unwrap();
    let rects: Vec<_> = m.iter().map(|m| m.rect).collect();
    assert_eq!(rects, vec![rect(0, 0, 8, 12), rect(8, 0, 9, 8)]);
    assert_eq!(s.opaque_texels, 104);
    assert_eq!(s.texels, 96 + 8);
    // threshold 0.4: S, then E at 104/256 = 0.406 ≥ 0.4: one micro-texture, shrunk to 9 × 12
    let (m, s) = extract_micro_textures(&img, Face::PosZ, 0, 1.0, &opts(8, 0.4)).unwrap();
    let rects: Vec<_> = m.iter().map(|m| m.rect).collect();
    assert_eq!(rects, vec![rect(0, 0, 9, 12)]);
    assert_eq!(s.texels, 108);
    analyze_micro_textures(&img, &m).unwrap();
}

#[test]
fn micro_texture_options_are_checked() {
    let img = full(8, 'a');
    for o in [opts(0, 0.5), opts(8, 1.5), opts(8, f64::NAN)] {
        assert!(matches!(
            extract_micro_textures(&img, Face::PosX, 0, 1.0, &o),
            Err(CompressError::BadOption { .. })
        ));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]
    /// Every opaque texel is in exactly one micro-texture (checked by the analyzer), and every
    /// micro-texture larger than one grid cell keeps an opaque fraction ≥ the threshold.
    #[test]
    fn micro_textures_cover_every_opaque_texel_once_and_respect_the_threshold(
        res in 1u32..48,
        cell in 1u32..12,
        threshold in 0.0f64..=1.0,
        density in 0u64..8,
        blobs in 0u32..4,
        merge in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let mut s = seed | 1;
        let mut next = move || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
        let mut img = LayerImage::new(res);
        for i in 0..img.texel_count() {
            if next() % 8 < density { img.set_texel(i, [(next() % 256) as u8, 1, 2, 255]); }
        }
        for _ in 0..blobs {
            let (cx, cy, r) = (next() % res as u64, next() % res as u64, 1 + next() % 10);
            for y in 0..res as u64 { for x in 0..res as u64 {
                if x.abs_diff(cx).pow(2) + y.abs_diff(cy).pow(2) <= r * r {
                    let i = img.index(x as u32, y as u32);
                    img.set_texel(i, [9, 9, 9, 255]);
                }
            }}
        }
        let o = MicroTextureOptions { merge, ..opts(cell, threshold) };
        let (m, stats) = extract_micro_textures(&img, Face::PosY, 0, 1.0, &o).unwrap();
        let checked = analyze_micro_textures(&img, &m).unwrap();
        prop_assert_eq!(checked, stats);
        if merge {
            // merging only joins rectangles that tile their union: fewer micro-textures, the
            // same texels
            let (paper, paper_stats) =
                extract_micro_textures(&img, Face::PosY, 0, 1.0, &opts(cell, threshold)).unwrap();
            prop_assert!(m.len() <= paper.len());
            prop_assert_eq!(stats.texels, paper_stats.texels);
        }
        for micro in &m {
            let r = micro.rect;
            let one_cell = r.x0 / cell == (r.x1 - 1) / cell && r.y0 / cell == (r.y1 - 1) / cell;
            prop_assert!(micro.opaque_count() > 0);
            prop_assert!(one_cell || micro.opaque_count() as f64 >= threshold * r.area() as f64,
                "{:?} fill {} < {}", r, micro.opaque_count() as f64 / r.area() as f64, threshold);
        }
    }
}

#[test]
fn neighbours_sharing_a_whole_edge_merge_into_one_micro_texture() {
    // A full 8×8 cell, and the next cell holding only its first column (8 opaque texels): the
    // growth east stops (72 / 128 < 0.6), the second micro-texture shrinks to that column, and
    // the two tile a fully opaque 9×8 rectangle.
    let mut img = LayerImage::new(16);
    for y in 0..8 {
        for x in 0..9 {
            let i = img.index(x, y);
            img.set_texel(i, [x as u8, y as u8, 7, 255]);
        }
    }
    let (paper, _) = extract_micro_textures(&img, Face::PosX, 0, 1.0, &opts(8, 0.6)).unwrap();
    assert_eq!(paper.len(), 2);
    assert_eq!(paper[1].rect, rect(8, 0, 9, 8));
    let merged_opts = MicroTextureOptions {
        merge: true,
        ..opts(8, 0.6)
    };
    let (m, stats) = extract_micro_textures(&img, Face::PosX, 0, 1.0, &merged_opts).unwrap();
    assert_eq!(m.len(), 1);
    assert_eq!(m[0].rect, rect(0, 0, 9, 8));
    assert_eq!(stats.texels, 72);
    assert_eq!(analyze_micro_textures(&img, &m).unwrap(), stats);
    // row-major pixels of the union, row 0 first
    for y in 0..8u32 {
        for x in 0..9u32 {
            let k = 4 * (y * 9 + x) as usize;
            assert_eq!(
                m[0].pixels[k..k + 4],
                [x as u8, y as u8, 7, 255],
                "({x}, {y})"
            );
        }
    }
    // one fully opaque and one partly transparent neighbour stay apart (the runtime draws the
    // two kinds with different pipelines), as do neighbours whose union would be too sparse
    let i = img.index(8, 3);
    img.set_texel(i, TRANSPARENT);
    let (m, _) = extract_micro_textures(&img, Face::PosX, 0, 1.0, &merged_opts).unwrap();
    assert_eq!(m.len(), 2);
}

#[test]
fn analyzer_catches_double_and_missing_coverage() {
    let img = full(8, 'a');
    let (mut m, _) = extract_micro_textures(&img, Face::PosX, 0, 1.0, &opts(4, 0.9)).unwrap();
    let dup = m[0].clone();
    m.push(dup);
    assert!(analyze_micro_textures(&img, &m).is_err());
    m.truncate(m.len() - 2);
    assert!(analyze_micro_textures(&img, &m).is_err());
}

// ---------------------------------------------------------------- quads

fn close(a: DVec3, b: DVec3) -> bool {
    (a - b).length() < 1e-12
}

#[test]
fn quad_corners_follow_the_texel_edge_convention() {
    // +X: right = −Z, down = −Y. Full face at D = 10: top-left (10, 10, 10).
    let c = quad_corners(Face::PosX, 10.0, 4, rect(0, 0, 4, 4));
    let want = [
        DVec3::new(10.0, 10.0, 10.0),
        DVec3::new(10.0, 10.0, -10.0),
        DVec3::new(10.0, -10.0, -10.0),
        DVec3::new(10.0, -10.0, 10.0),
    ];
    for (a, b) in c.iter().zip(want) {
        assert!(close(*a, b), "{a} vs {b}");
    }
    // texel columns 1..2, rows 2..3 of 4: s ∈ [−0.5, 0], t ∈ [0, 0.5]
    let c = quad_corners(Face::PosX, 10.0, 4, rect(1, 2, 2, 3));
    assert!(close(c[0], DVec3::new(10.0, 0.0, 5.0)));
    assert!(close(c[2], DVec3::new(10.0, -5.0, 0.0)));
    // every face: the centre of a texel's quad projects back to that texel
    for f in Face::ALL {
        let (res, x, y) = (16u32, 5u32, 11u32);
        let q = quad_corners(f, 3.0, res, rect(x, y, x + 1, y + 1));
        let centre = (q[0] + q[2]) / 2.0;
        let (s, t, d) = f.project(centre).unwrap();
        assert!((d - 3.0).abs() < 1e-12);
        assert_eq!(((s + 1.0) / 2.0 * res as f64).floor() as u32, x, "{f}");
        assert_eq!(((t + 1.0) / 2.0 * res as f64).floor() as u32, y, "{f}");
    }
}
