//! Outline fringe: the texel that conservative recording grows an outline by, drawn only where
//! something lies behind it.
//!
//! Conservative recording (TR-186-2-02-04 sec. 2.2) covers every texel a triangle touches, so an
//! outline grows by up to a texel beyond the geometry's. Over a farther surface that growth is
//! what keeps the strip parallax uncovers beside the outline closed (no crack); over the
//! background it only fattens the silhouette: at matched resolution, silhouettes against the sky
//! lie up to a pixel and a half outside the geometry's, and one texel of false coverage lines
//! every skyline. Which of the two a texel lies over depends on the viewpoint (from one corner of
//! the cell a farther building stands behind a roof edge, from another the sky does), so the bake
//! cannot decide it; the runtime can, per pixel.
//!
//! This stage marks as *fringe* every conservative overshoot texel (covered, its centre inside no
//! triangle of the slab: `RecordOptions::mark_overshoot` of the recorder) that
//! - is not a clip-border texel (a cut must stay covered in both layers, TR sec. 2.2), and
//! - has an 8-neighbour in the same layer that a triangle covers at its centre, so the outline
//!   without its fringe is the one ordinary rasterization gives, and a feature no texel centre
//!   hits (a pole thinner than a texel) keeps its grown texels whole.
//!
//! A fringe texel keeps its colour and gets alpha [`FRINGE_ALPHA`]: opaque to every stage of
//! the compression (it is packed, and gap filling and the outline copies carry it like any
//! other texel) except hidden-texel removal, where it hides nothing (it may not be drawn). The
//! runtime draws the fully opaque texels first and the fringe texels after them, each only on a
//! pixel where something (near geometry or a quad) was drawn before; formats that cannot hold
//! the third alpha level (BC1's one-bit alpha) lose the mark, and the fringe is drawn like any
//! texel, as without this stage.

use super::layer_image::{FRINGE_ALPHA, FULL_ALPHA};
use super::{CompressError, LayerImage};

/// Marks the fringe texels of `layer` (see the module documentation): `overshoot` holds the
/// recorder's per-texel flags (`res²`). Returns the number of texels marked.
pub fn mark_outline_fringe(
    layer: &mut LayerImage,
    overshoot: &[bool],
) -> Result<u64, CompressError> {
    layer.validate()?;
    let res = layer.res;
    if overshoot.len() != layer.texel_count() {
        return Err(CompressError::Invalid(format!(
            "outline fringe of a {res}² layer given {} overshoot flags",
            overshoot.len()
        )));
    }
    let r = i64::from(res);
    // a texel a triangle covers at its centre
    let centre = |x: i64, y: i64| {
        (0..r).contains(&x) && (0..r).contains(&y) && {
            let j = (y * r + x) as usize;
            layer.is_opaque(j) && !overshoot[j]
        }
    };
    let fringe: Vec<usize> = layer
        .content_rows()
        .flatten()
        .filter(|&i| overshoot[i] && layer.is_opaque(i) && !layer.border[i])
        .filter(|&i| {
            let (x, y) = ((i % res as usize) as i64, (i / res as usize) as i64);
            (-1..=1).any(|dy| (-1..=1).any(|dx| (dx, dy) != (0, 0) && centre(x + dx, y + dy)))
        })
        .collect();
    for &i in &fringe {
        layer.rgba[4 * i + 3] = FRINGE_ALPHA;
    }
    const { assert!(FRINGE_ALPHA >= super::OPAQUE_ALPHA && FRINGE_ALPHA < FULL_ALPHA) };
    Ok(fringe.len() as u64)
}

/// Whether an alpha value (0..=255) marks a fringe texel: opaque, below [`FULL_ALPHA`].
pub fn is_fringe_alpha(a: u8) -> bool {
    (super::OPAQUE_ALPHA..FULL_ALPHA).contains(&a)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 8×8 layer: a 4×4 block of centre-covered texels at (2..6, 2..6) with a ring of overshoot
    /// around it, and a lone overshoot texel (a sub-texel feature) far from it.
    fn layer() -> (LayerImage, Vec<bool>) {
        let mut l = LayerImage::new(8);
        let mut over = vec![false; 64];
        for y in 1..7 {
            for x in 1..7 {
                let i = y * 8 + x;
                l.set_texel(i, [10, 20, 30, 255]);
                over[i] = !(2..6).contains(&x) || !(2..6).contains(&y);
            }
        }
        l.set_texel(7, [1, 2, 3, 255]);
        over[7] = true;
        (l, over)
    }

    #[test]
    fn the_grown_ring_is_fringe_a_lone_feature_and_clip_borders_are_not() {
        let (mut l, over) = layer();
        // one ring texel on a clipping edge
        l.border[8 + 3] = true;
        let marked = mark_outline_fringe(&mut l, &over).expect("marks");
        // the ring of 6×6 − 4×4 = 20 texels, less the clip-border one
        assert_eq!(marked, 19);
        for (i, &o) in over.iter().enumerate() {
            let a = l.texel(i)[3];
            let expect_fringe = o && i != 7 && i != 8 + 3;
            assert_eq!(is_fringe_alpha(a), expect_fringe, "texel {i}: alpha {a}");
            // colours are kept, and nothing is dropped
            assert_eq!(
                l.is_opaque(i),
                i == 7 || (i / 8 >= 1 && i / 8 < 7 && i % 8 >= 1 && i % 8 < 7)
            );
        }
    }

    #[test]
    fn bad_flags_are_refused() {
        let (mut l, _) = layer();
        let e = mark_outline_fringe(&mut l, &[true; 3]).expect_err("3 flags for 64 texels");
        assert!(e.to_string().contains("3 overshoot flags"), "{e}");
    }
}
