//! The whole compression pipeline of GI 2002 sec. 5 on synthetic layer stacks: invariants
//! (nothing visible lost, every opaque texel in exactly one micro-texture, every micro-texture's
//! pixels in its macro-texture), determinism across thread counts. The full-size measurement is
//! an example: `cargo run --release -p lemi-core --example compress_synthetic_cell`.

use lemi_core::compress::{
    analyze_micro_textures, compress_cell, CompressError, CompressOptions, CompressedCell,
    FaceLayers, GapSources, LayerImage,
};
use lemi_core::Face;

mod common;
use common::synthetic::synthetic_cell;

/// Checks the outcome of [`compress_cell`] against the processed layers.
fn check(faces: &[FaceLayers], cell: &CompressedCell) {
    for f in faces {
        for (k, layer) in f.layers.iter().enumerate() {
            let micros: Vec<_> = cell
                .micro_textures
                .iter()
                .filter(|m| m.face == f.face && m.layer == k as u32)
                .cloned()
                .collect();
            assert!(micros.iter().all(|m| m.distance == f.distances[k]));
            analyze_micro_textures(layer, &micros).unwrap();
        }
    }
    assert_eq!(cell.placements.len(), cell.micro_textures.len());
    for (m, p) in cell.micro_textures.iter().zip(&cell.placements) {
        let mac = &cell.macro_textures[p.macro_index as usize];
        let (w, h) = (m.rect.width(), m.rect.height());
        for y in 0..h {
            for x in 0..w {
                let (mx, my) = p.macro_texel(w, h, x, y);
                let d = 4 * (my * mac.width + mx) as usize;
                let s = 4 * (y * w + x) as usize;
                assert_eq!(mac.rgba[d..d + 4], m.pixels[s..s + 4]);
            }
        }
    }
    let s = &cell.stats;
    assert_eq!(s.hidden.opaque_after, s.micro.opaque_texels);
    assert_eq!(s.micro.micro_textures, s.packing.micro_textures);
    assert_eq!(s.micro.texels, s.packing.micro_texels);
}

#[test]
fn pipeline_keeps_every_remaining_texel_and_is_deterministic() {
    // the paper's gap filling, which has texels to copy in the synthetic stacks (their cuts are
    // recorded in both layers, so the default rule finds no gap)
    let opts = CompressOptions {
        gap_sources: GapSources::AllBorder,
        ..Default::default()
    };
    let mut a = synthetic_cell(64, 12, 3, 7);
    let mut b = a.clone();
    let ca = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| compress_cell(&mut a, &opts))
        .unwrap();
    let cb = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap()
        .install(|| compress_cell(&mut b, &opts))
        .unwrap();
    assert_eq!(a, b);
    assert_eq!(ca, cb);
    check(&a, &ca);
    let s = &ca.stats;
    assert!(s.gap_fill.filled > 0 && s.hidden.removed > 0, "{s:?}");
    assert!(s.packing.macro_bytes < s.layer_bytes);
}

#[test]
fn far_first_input_gives_the_same_cell() {
    let opts = CompressOptions::default();
    let mut near_first = synthetic_cell(48, 6, 2, 11);
    let mut far_first = near_first.clone();
    for f in &mut far_first {
        f.layers.reverse();
        f.distances.reverse();
    }
    let a = compress_cell(&mut near_first, &opts).unwrap();
    let b = compress_cell(&mut far_first, &opts).unwrap();
    for (fa, fb) in near_first.iter().zip(&far_first) {
        let mut rev = fb.layers.clone();
        rev.reverse();
        assert_eq!(fa.layers, rev);
    }
    check(&far_first, &b);
    let key = |m: &lemi_core::compress::MicroTexture, n: u32| {
        (m.face, n, m.rect.x0, m.rect.y0, m.rect.x1, m.rect.y1)
    };
    let mut ka: Vec<_> = a.micro_textures.iter().map(|m| key(m, m.layer)).collect();
    let mut kb: Vec<_> = b
        .micro_textures
        .iter()
        .map(|m| key(m, 5 - m.layer))
        .collect();
    ka.sort();
    kb.sort();
    assert_eq!(ka, kb);
    assert_eq!(a.stats.hidden.removed, b.stats.hidden.removed);
    assert_eq!(a.stats.packing, b.stats.packing);
}

#[test]
fn pipeline_rejects_inconsistent_faces() {
    let mut faces = synthetic_cell(16, 3, 1, 1);
    faces[1].distances.swap(0, 1);
    assert!(matches!(
        compress_cell(&mut faces, &CompressOptions::default()),
        Err(CompressError::BadFace {
            face: Face::NegX,
            ..
        })
    ));
    let mut faces = synthetic_cell(16, 3, 1, 1);
    faces[0].distances.pop();
    assert!(compress_cell(&mut faces, &CompressOptions::default()).is_err());
    let mut faces = synthetic_cell(16, 3, 1, 1);
    faces[2].layers[1] = LayerImage::new(8);
    assert!(compress_cell(&mut faces, &CompressOptions::default()).is_err());
}
