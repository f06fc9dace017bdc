//! Synthetic layer stacks for the compression pipeline (shared by the `compress_cell` tests and
//! the `compress_synthetic_cell` example).

use lemi_core::compress::{FaceLayers, LayerImage};
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
pub fn synthetic_face(face: Face, res: u32, layers: usize, blobs: usize, seed: u64) -> FaceLayers {
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
                // the row shared with the next more distant layer is this layer's far border
                img.far_border[i] = y == lo && k + 1 < layers;
                img.border[i] = img.far_border[i] || (y == hi && k > 0);
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

/// The four horizontal faces of a synthetic cell.
pub fn synthetic_cell(res: u32, layers: usize, blobs: usize, seed: u64) -> Vec<FaceLayers> {
    Face::HORIZONTAL
        .iter()
        .enumerate()
        .map(|(i, &f)| synthetic_face(f, res, layers, blobs, seed + i as u64))
        .collect()
}
