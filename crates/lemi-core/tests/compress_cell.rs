//! The whole compression pipeline of GI 2002 sec. 5 on synthetic layer stacks: invariants
//! (nothing visible lost, every opaque texel in exactly one micro-texture, every micro-texture's
//! pixels in its macro-texture), determinism across thread counts, and (ignored by default) a
//! full-size measurement: `cargo test --release -p lemi-core --test compress_cell -- --ignored
//! --nocapture`.

use std::time::Instant;

use image::ImageEncoder;

use lemi_core::compress::{
    analyze_micro_textures, compress_cell, extract_micro_textures, fill_gaps, pack_micro_textures,
    remove_hidden_texels, CompressError, CompressOptions, CompressedCell, FaceLayers, LayerImage,
};
use lemi_core::Face;

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        // splitmix64
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

/// A synthetic layer stack of one face, nearest first: a ground plane split into bands between
/// the layers (rows below the horizon, nearest layers at the bottom, the shared clip-edge row
/// recorded in both layers and flagged as clip border, TR sec. 2.2) plus random discs ("objects")
/// in every layer, and a far backdrop over the upper half in the last layer.
fn synthetic_face(face: Face, res: u32, layers: usize, blobs: usize, seed: u64) -> FaceLayers {
    let mut rng = Rng(seed);
    let r = res as u64;
    let horizon = res / 2;
    // ground row where layer k's band ends (k = 0 at the bottom)
    let band = |k: usize| -> u32 {
        let f = 1.0 - k as f64 / layers as f64;
        horizon + ((res - horizon) as f64 * f * f) as u32
    };
    let mut images = Vec::with_capacity(layers);
    for k in 0..layers {
        let mut img = LayerImage::new(res);
        let (lo, hi) = (band(k + 1), band(k).min(res - 1));
        let ground = [60, 90 + (k % 50) as u8, 40, 255];
        for y in lo..=hi {
            for x in 0..res {
                let i = img.index(x, y);
                img.set_texel(i, ground);
                img.border[i] = (y == lo && k + 1 < layers) || (y == hi && k > 0);
            }
        }
        for _ in 0..blobs {
            let (cx, cy) = (rng.below(r), rng.below(r / 2 + 8));
            let rad = 2 + rng.below(r / 12);
            let c = rng.next().to_le_bytes();
            for y in cy.saturating_sub(rad)..(cy + rad + 1).min(r) {
                for x in cx.saturating_sub(rad)..(cx + rad + 1).min(r) {
                    if x.abs_diff(cx).pow(2) + y.abs_diff(cy).pow(2) <= rad * rad {
                        let i = img.index(x as u32, y as u32);
                        img.set_texel(i, [c[0], c[1], c[2], 255]);
                    }
                }
            }
        }
        if k + 1 == layers {
            for y in 0..horizon {
                for x in 0..res {
                    let i = img.index(x, y);
                    img.set_texel(i, [120, 140, 200, 255]);
                }
            }
        }
        images.push(img);
    }
    FaceLayers {
        face,
        distances: (0..layers).map(|k| 40.0 * 1.05f64.powi(k as i32)).collect(),
        layers: images,
    }
}

fn synthetic_cell(res: u32, layers: usize, blobs: usize, seed: u64) -> Vec<FaceLayers> {
    Face::HORIZONTAL
        .iter()
        .enumerate()
        .map(|(i, &f)| synthetic_face(f, res, layers, blobs, seed + i as u64))
        .collect()
}

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
    let opts = CompressOptions::default();
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

/// Full-size measurement: 4 faces × 64 layers × 512², as in GI 2002 sec. 6 (Table 2).
#[test]
#[ignore = "measurement; run with --release -- --ignored --nocapture"]
fn measure_synthetic_cell() {
    for threshold in [0.4, 0.6, 0.8] {
        let mut faces = synthetic_cell(512, 64, 4, 42);
        let mut opts = CompressOptions::default();
        opts.micro.threshold = threshold;
        // each stage alone first, for its time
        let mut copy = faces.clone();
        let t = Instant::now();
        for f in &mut copy {
            fill_gaps(&mut f.layers).unwrap();
        }
        let t_gap = t.elapsed().as_secs_f64();
        let t = Instant::now();
        for f in &mut copy {
            remove_hidden_texels(&mut f.layers, &opts.hidden).unwrap();
        }
        let t_hidden = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mut micros = Vec::new();
        for f in &copy {
            for (k, l) in f.layers.iter().enumerate() {
                micros.extend(
                    extract_micro_textures(l, f.face, k as u32, f.distances[k], &opts.micro)
                        .unwrap()
                        .0,
                );
            }
        }
        let t_micro = t.elapsed().as_secs_f64();
        let t = Instant::now();
        pack_micro_textures(&micros, &opts.packing).unwrap();
        let t_pack = t.elapsed().as_secs_f64();
        println!(
            "threshold {threshold}: stages one after the other: gap fill {t_gap:.3} s, hidden {t_hidden:.3} s, micro {t_micro:.3} s, packing {t_pack:.3} s"
        );
        let t = Instant::now();
        let cell = compress_cell(&mut faces, &opts).unwrap();
        let dt = t.elapsed();
        let s = &cell.stats;
        println!(
            "  compress_cell: {:.2} s on {} threads",
            dt.as_secs_f64(),
            rayon::current_num_threads()
        );
        println!(
            "  layers: {} bytes ({:.1} MB)",
            s.layer_bytes,
            s.layer_bytes as f64 / 1e6
        );
        println!("  gap fill: {:?}", s.gap_fill);
        println!(
            "  hidden: opaque {} -> {} (removed {}, {:.1}%)",
            s.hidden.opaque_before,
            s.hidden.opaque_after,
            s.hidden.removed,
            100.0 * s.hidden.removed as f64 / s.hidden.opaque_before as f64
        );
        println!(
            "  micro: {} micro-textures, {} texels, fill ratio {:.3}",
            s.micro.micro_textures, s.micro.texels, s.micro.fill_ratio
        );
        println!(
            "  packing: {} macro-textures, {} bytes ({:.2} MB), efficiency {:.3}",
            s.packing.macro_textures,
            s.packing.macro_bytes,
            s.packing.macro_bytes as f64 / 1e6,
            s.packing.efficiency
        );
        let t = Instant::now();
        let png: usize = cell
            .macro_textures
            .iter()
            .map(|m| {
                let mut bytes = Vec::new();
                image::codecs::png::PngEncoder::new(&mut bytes)
                    .write_image(&m.rgba, m.width, m.height, image::ExtendedColorType::Rgba8)
                    .map(|_| bytes.len())
                    .unwrap_or(0)
            })
            .sum();
        println!(
            "  PNG (image crate defaults): {png} bytes ({:.2} MB) in {:.2} s",
            png as f64 / 1e6,
            t.elapsed().as_secs_f64()
        );
        check(&faces, &cell);
    }
}
