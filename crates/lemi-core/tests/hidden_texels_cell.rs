//! Hidden-texel removal with the movement the view cell allows (`remove_hidden_texels_in_cell`),
//! checked by brute force: rays from viewpoints all over the cell to every point of every removed
//! texel must meet an opaque texel of a nearer layer that is still there.

use glam::DVec3;
use lemi_core::compress::{
    remove_hidden_texels, remove_hidden_texels_in_cell, HiddenTexelOptions, LayerImage, TexelShift,
};
use lemi_core::placement::{one_texel_step, EnvParams};
use lemi_core::Face;
use proptest::prelude::*;

const OPAQUE: [u8; 4] = [200, 100, 50, 255];

/// A deterministic stream of 64-bit values from `seed` (xorshift64).
fn xorshift(seed: u64) -> impl FnMut() -> u64 {
    let mut s = seed | 1;
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    }
}

/// Viewpoints spread over the cell of half extents `half` around the origin: its 8 corners, the
/// centres of its 6 sides and a few points inside (deterministic from `seed`).
fn viewpoints(half: DVec3, seed: u64) -> Vec<DVec3> {
    let mut v = Vec::new();
    for i in 0..8 {
        let s = |b: u32| if i & (1 << b) != 0 { 1.0 } else { -1.0 };
        v.push(half * DVec3::new(s(0), s(1), s(2)));
    }
    for a in 0..3 {
        for sign in [-1.0, 1.0] {
            let mut p = DVec3::ZERO;
            p[a] = sign * half[a];
            v.push(p);
        }
    }
    let mut bits = xorshift(seed);
    let mut next = move || (bits() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
    for _ in 0..6 {
        v.push(half * DVec3::new(next(), next(), next()));
    }
    v
}

/// Whether the ray from `eye` through the point at face coordinates `(s, t)` of the layer at
/// `distances[j]` meets an opaque texel (not a clip-border one) of a nearer layer.
fn covered(
    layers: &[LayerImage],
    distances: &[f64],
    face: Face,
    eye: DVec3,
    j: usize,
    (s, t): (f64, f64),
) -> bool {
    let res = layers[0].res;
    let p = face.point(s, t, distances[j]);
    let (ep, pp) = (face.depth(eye), face.depth(p));
    (0..j).any(|i| {
        let x = eye + (p - eye) * ((distances[i] - ep) / (pp - ep));
        let (u, v) = (
            x.dot(face.right()) / distances[i],
            x.dot(face.down()) / distances[i],
        );
        let (tx, ty) = (
            ((u + 1.0) * res as f64 / 2.0).floor(),
            ((v + 1.0) * res as f64 / 2.0).floor(),
        );
        if tx < 0.0 || ty < 0.0 || tx >= res as f64 || ty >= res as f64 {
            return false;
        }
        let k = layers[i].index(tx as u32, ty as u32);
        layers[i].is_opaque(k) && !layers[i].border[k]
    })
}

/// Every texel that was opaque in `before` and is gone in `after` is hidden from every viewpoint
/// of the cell: a 4×4 grid of points inside it (inset from its edges) is covered from each.
fn check_hidden(
    before: &[LayerImage],
    after: &[LayerImage],
    distances: &[f64],
    face: Face,
    half: DVec3,
    seed: u64,
) -> Result<usize, String> {
    let res = before[0].res;
    let eyes = viewpoints(half, seed);
    let mut removed = 0;
    for j in 1..before.len() {
        for y in 0..res {
            for x in 0..res {
                let i = before[j].index(x, y);
                if !before[j].is_opaque(i) || after[j].is_opaque(i) {
                    continue;
                }
                removed += 1;
                for eye in &eyes {
                    for a in 0..4 {
                        for b in 0..4 {
                            let f = |n: u32, c: u32| {
                                Face::texel_edge(n as f64 + 0.001 + 0.998 * c as f64 / 3.0, res)
                            };
                            if !covered(after, distances, face, *eye, j, (f(x, a), f(y, b))) {
                                return Err(format!(
                                    "texel ({x}, {y}) of layer {j} was removed but is seen from \
                                     {eye} through ({a}, {b})"
                                ));
                            }
                        }
                    }
                }
            }
        }
    }
    Ok(removed)
}

/// `n` layers of `res`² texels: each holds a few opaque rectangles (half the image wide on
/// average) with a few holes, the farthest is opaque all over, and a few opaque texels are
/// clip-border texels.
fn random_layers(res: u32, n: usize, seed: u64) -> Vec<LayerImage> {
    let mut next = xorshift(seed);
    (0..n)
        .map(|k| {
            let mut img = LayerImage::new(res);
            let rects = if k + 1 == n { 0 } else { 3 };
            for _ in 0..rects {
                let (x0, y0) = ((next() % res as u64) as u32, (next() % res as u64) as u32);
                let (w, h) = (
                    1 + (next() % res as u64) as u32,
                    1 + (next() % res as u64) as u32,
                );
                for y in y0..(y0 + h).min(res) {
                    for x in x0..(x0 + w).min(res) {
                        let i = img.index(x, y);
                        img.set_texel(i, OPAQUE);
                    }
                }
            }
            for i in 0..img.texel_count() {
                let r = next();
                if k + 1 == n {
                    img.set_texel(i, OPAQUE);
                }
                if r % 37 == 0 {
                    img.clear_texel(i);
                }
                img.border[i] = img.is_opaque(i) && (r >> 20) % 29 == 0;
            }
            img
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(160))]
    /// Random stacks in random box cells, with layers from a hair to far apart (movements from a
    /// tenth of a texel to several texels a pair): nothing removed is seen from the cell, and
    /// where every pair moves by at most one texel, at least the paper's texels go.
    #[test]
    fn removed_texels_are_hidden_from_the_whole_cell(
        res in 8u32..24,
        n in 2usize..5,
        face_index in 0usize..6,
        half in (0.2f64..3.0, 0.2f64..3.0, 0.2f64..3.0),
        first in 1.2f64..6.0,
        ratios in prop::collection::vec(1.01f64..1.8, 4),
        seed in any::<u64>(),
    ) {
        let face = Face::from_index(face_index).unwrap();
        let half = DVec3::new(half.0, half.1, half.2);
        let shift = TexelShift::of_face(face, half, res);
        let mut distances = vec![first * shift.along];
        for r in ratios.iter().take(n - 1) {
            let d = distances.last().unwrap() * r;
            distances.push(d);
        }
        let layers = random_layers(res, n, seed);
        let mut out = layers.clone();
        let options = HiddenTexelOptions::default();
        let stats = remove_hidden_texels_in_cell(&mut out, &distances, &shift, &options).unwrap();
        let removed = check_hidden(&layers, &out, &distances, face, half, seed)
            .map_err(TestCaseError::fail)?;
        prop_assert_eq!(removed as u64, stats.removed);
        // every pair moving by at most a texel: a superset of the paper's rule
        let most = distances
            .windows(2)
            .flat_map(|w| {
                let s = &shift;
                (0..res).map(move |x| s.shift(w[0], w[1], x, x)[0].max(s.shift(w[0], w[1], x, x)[1]))
            })
            .fold(0.0f64, f64::max);
        if most <= 1.0 {
            let mut paper = layers.clone();
            remove_hidden_texels(&mut paper, &options).unwrap();
            for (p, o) in paper.iter().zip(&out) {
                for i in 0..p.texel_count() {
                    prop_assert!(p.is_opaque(i) || !o.is_opaque(i), "the paper's rule removes a texel this one keeps");
                }
            }
        }
    }
}

/// `n` layers of `res`² texels: an opaque square `side × side` in the nearest, the farthest opaque
/// all over, nothing between.
fn occluder_and_backdrop(res: u32, n: usize, side: std::ops::Range<u32>) -> Vec<LayerImage> {
    let mut layers = vec![LayerImage::new(res); n];
    for y in side.clone() {
        for x in side.clone() {
            let i = layers[0].index(x, y);
            layers[0].set_texel(i, OPAQUE);
        }
    }
    for i in 0..layers[n - 1].texel_count() {
        layers[n - 1].set_texel(i, OPAQUE);
    }
    layers
}

/// A 2D-case street cell (10 × 1 × 10 m) at the paper's settings: an occluder 24 texels wide at
/// 300 m in front of a full background 10 layers behind (parallax-bound spacing, a third to half a
/// texel a pair). The paper's rule keeps a 10-texel rim of the background around the occluder's
/// silhouette; the cell's own movement keeps what it needs, about half of that, and the brute
/// force shows every removed texel hidden from the cell.
#[test]
fn parallax_bound_layers_lose_more_hidden_texels_than_one_texel_a_pair() {
    let (res, half) = (64u32, DVec3::new(5.0, 0.5, 5.0));
    let face = Face::PosX;
    let shift = TexelShift::of_face(face, half, res);
    assert_eq!((shift.along, shift.across), (5.0, [5.0, 0.5]));
    // parallax-bound layers about 3 % apart, as the placement puts them at 300 m
    let distances: Vec<f64> = (0..11).map(|k| 300.0 * 1.03f64.powi(k)).collect();
    let layers = occluder_and_backdrop(res, 11, 20..44);
    let options = HiddenTexelOptions::default();
    let mut paper = layers.clone();
    let by_paper = remove_hidden_texels(&mut paper, &options).unwrap();
    let mut cell = layers.clone();
    let by_cell = remove_hidden_texels_in_cell(&mut cell, &distances, &shift, &options).unwrap();
    // the paper: 10 pairs, one texel each: the background's hidden square is 24 − 2·10 = 4 wide
    assert_eq!(by_paper.removed, 4 * 4);
    assert!(
        by_cell.removed >= 10 * 10,
        "the cell's movement removes {} texels",
        by_cell.removed
    );
    let removed = check_hidden(&layers, &cell, &distances, face, half, 7).unwrap();
    assert_eq!(removed as u64, by_cell.removed);
}

/// Layers placed farther apart than the metric allows (two texels a pair): the paper's rule
/// removes background texels that a corner of the cell sees; the cell's movement keeps them.
#[test]
fn layers_moving_more_than_a_texel_keep_what_the_cell_sees() {
    let (res, half) = (32u32, DVec3::splat(2.0));
    let face = Face::NegZ;
    let shift = TexelShift::of_face(face, half, res);
    let distances = [6.0, 9.0];
    assert!(shift.shift(6.0, 9.0, 16, 16)[0] > 2.0);
    let layers = occluder_and_backdrop(res, 2, 8..24);
    let options = HiddenTexelOptions::default();
    let mut paper = layers.clone();
    remove_hidden_texels(&mut paper, &options).unwrap();
    assert!(check_hidden(&layers, &paper, &distances, face, half, 3).is_err());
    let mut cell = layers.clone();
    let stats = remove_hidden_texels_in_cell(&mut cell, &distances, &shift, &options).unwrap();
    assert!(stats.removed > 0);
    check_hidden(&layers, &cell, &distances, face, half, 3).unwrap();
}

/// The movement is GI 2002 eq. 2's: a layer at the one-texel step of `F` moves by exactly one
/// texel at the image edge, for cubes and boxes.
#[test]
fn the_movement_is_one_texel_at_the_one_texel_step() {
    for (half, face) in [
        (DVec3::splat(5.0), Face::PosX),
        (DVec3::new(5.0, 0.5, 5.0), Face::PosZ),
        (DVec3::new(1.0, 2.0, 3.0), Face::NegY),
    ] {
        for far in [40.0, 300.0, 5000.0] {
            let shift = TexelShift::of_face(face, half, 512);
            let params = EnvParams {
                along: shift.along,
                across: [shift.across[0], shift.across[1]],
                res: 512,
                alpha: 1e-3,
            };
            let near = one_texel_step(far, &params);
            let [x, y] = shift.shift(near, far, 0, 0);
            let edge = x.max(y);
            assert!((edge - 1.0).abs() < 1e-9, "{face:?} {far}: {edge}");
            // smaller towards the image centre
            let [cx, cy] = shift.shift(near, far, 256, 256);
            assert!(cx < x && cy < y);
        }
    }
}

#[test]
fn mismatched_distances_are_an_error() {
    let mut layers = vec![LayerImage::new(8), LayerImage::new(8)];
    let shift = TexelShift::of_face(Face::PosX, DVec3::ONE, 8);
    let e =
        remove_hidden_texels_in_cell(&mut layers, &[3.0], &shift, &HiddenTexelOptions::default())
            .unwrap_err();
    assert!(e.to_string().contains("1 distances"), "{e}");
}
