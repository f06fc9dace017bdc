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
//! the third alpha level (BC1's one-bit alpha, ETC1S) keep it another way: before micro-texture
//! extraction [`split_outline_fringe`] takes the fringe texels out of their layer into an image
//! of their own, fully opaque, whose micro-textures become *fringe quads* (the last
//! [`crate::bundle::CellHeader::fringe_quads`] quads of the cell); the runtime draws those in the
//! fringe pass only, and a reader that does not know them draws them as ordinary quads (today's
//! image without this stage).

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

/// Side in texels of the grid that cuts fringe images into micro-textures
/// ([`split_outline_fringe`]): fringe texels lie along outlines, one texel wide, so the bake's
/// grid of 8 would give quads of one texel in eight; 4 is the runtime's piece of the alpha-marked
/// fringe and a BC1 block.
pub const FRINGE_GRID: u32 = 4;

/// Takes the fringe texels (alpha in [`super::OPAQUE_ALPHA`]..[`FULL_ALPHA`]) out of `layer`
/// (they become transparent there) into an image of their own, where they are fully opaque
/// ([`FULL_ALPHA`] or more: their alpha raised to 255) and everything else is transparent; its
/// content rectangle is their bounding box. `None` when the layer has none. For formats that
/// cannot hold the fringe level (see the module documentation).
pub fn split_outline_fringe(layer: &mut LayerImage) -> Result<Option<LayerImage>, CompressError> {
    layer.validate()?;
    let res = layer.res;
    let fringe: Vec<usize> = layer
        .content_rows()
        .flatten()
        .filter(|&i| is_fringe_alpha(layer.rgba[4 * i + 3]))
        .collect();
    if fringe.is_empty() {
        return Ok(None);
    }
    let mut image = LayerImage::new(res);
    let mut bounds = super::TexelRect::empty();
    for &i in &fringe {
        let mut t = layer.texel(i);
        t[3] = 255;
        image.set_texel(i, t);
        layer.clear_texel(i);
        let (x, y) = ((i % res as usize) as u32, (i / res as usize) as u32);
        bounds = bounds.union(&super::TexelRect {
            x0: x,
            y0: y,
            x1: x + 1,
            y1: y + 1,
        });
    }
    Ok(Some(image.with_content(bounds)))
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
    fn split_takes_the_fringe_texels_into_an_opaque_image_of_their_own() {
        let (mut l, over) = layer();
        mark_outline_fringe(&mut l, &over).expect("marks");
        let before = l.clone();
        let fringe = split_outline_fringe(&mut l)
            .expect("valid layer")
            .expect("fringe texels");
        for i in 0..64 {
            let t = before.texel(i);
            if is_fringe_alpha(t[3]) {
                assert_eq!(fringe.texel(i), [t[0], t[1], t[2], 255], "texel {i}");
                assert!(!l.is_opaque(i), "texel {i} left in the layer");
            } else {
                assert_eq!(fringe.texel(i)[3], 0, "texel {i} in the fringe image");
                assert_eq!(l.texel(i), t, "texel {i} changed");
            }
        }
        // the bounding box of the ring
        assert_eq!(
            fringe.content,
            crate::compress::TexelRect {
                x0: 1,
                y0: 1,
                x1: 7,
                y1: 7
            }
        );
        // nothing left to split, and an unmarked layer has none
        assert_eq!(split_outline_fringe(&mut l), Ok(None));
        assert_eq!(split_outline_fringe(&mut layer().0), Ok(None));
    }

    #[test]
    fn bad_flags_are_refused() {
        let (mut l, _) = layer();
        let e = mark_outline_fringe(&mut l, &[true; 3]).expect_err("3 flags for 64 texels");
        assert!(e.to_string().contains("3 overshoot flags"), "{e}");
    }
}
