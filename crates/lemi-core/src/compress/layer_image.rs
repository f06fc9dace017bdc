//! The layer image every compression stage works on, and the 3×3 mask operations they share.
//!
//! This work is based on: GI 2002 sec. 5 (all layers of a face share one resolution and one
//! projection, so texel `(x, y)` is the same ray in every layer) and TR-186-2-02-04 sec. 2.2 (the
//! texels of a polygon's clipping edge are recorded in both adjacent layers: the *clip-border*
//! texels carried in [`LayerImage::border`]).
//!
//! A texel is opaque when its alpha is at least [`OPAQUE_ALPHA`]; the recorder writes 0 or 255,
//! and the outline fringe ([`super::outline_fringe`]) marks opaque texels that may be left undrawn
//! with [`FRINGE_ALPHA`], below [`FULL_ALPHA`]. Texels are
//! stored row-major, row 0 at the top of the face image (the convention of [`crate::face`]).

use super::{CompressError, TexelRect};

/// Smallest alpha value that counts as opaque (the recorder writes 0 or 255).
pub const OPAQUE_ALPHA: u8 = 128;

/// The alpha of a fringe texel ([`super::outline_fringe`]): opaque, but below [`FULL_ALPHA`]. Half
/// way between the two thresholds, so that a block format's alpha error (BC7 interpolates alpha
/// in steps of at most 37) keeps it in its band.
pub const FRINGE_ALPHA: u8 = 160;

/// Smallest alpha of a texel that is drawn wherever it lies (not a fringe texel), and that may
/// hide farther texels in hidden-texel removal.
pub const FULL_ALPHA: u8 = 192;

/// The fully transparent texel written by the stages that erase texels.
pub const TRANSPARENT: [u8; 4] = [0, 0, 0, 0];

/// One recorded `(face, layer)` image: `res × res` RGBA8 texels plus the clip-border flags.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LayerImage {
    /// Texels per side.
    pub res: u32,
    /// `res · res · 4` bytes, row-major, row 0 at the top.
    pub rgba: Vec<u8>,
    /// `res · res` flags: texel written by the clipping edge of a polygon cut at one of this
    /// layer's borders (TR sec. 2.2). Hidden-texel removal does not let these texels occlude.
    pub border: Vec<bool>,
    /// `res · res` flags, a subset of [`LayerImage::border`]: the texels of clipping edges on the
    /// layer's *far* border, the plane it shares with the next more distant layer, where a
    /// surface continues into that layer. Gap filling copies only these (see
    /// [`super::gap_fill`]).
    pub far_border: Vec<bool>,
    /// Every texel outside this rectangle is transparent black without clip-border flags, so
    /// the stages need not look there: the layer recorder reads back only the tiles its slab's
    /// triangles touch (GI 2002's layers are mostly empty at high resolution) and sets it to
    /// their bounding box. The whole image unless said otherwise; a stage that writes a texel
    /// outside it grows it first ([`LayerImage::include`]).
    pub content: TexelRect,
    /// `res · res` flags, or empty when the recorder was not asked: texel recorded from a point
    /// *behind* the layer's plane (farther from the view cell than the plane). `false` for a
    /// texel recorded in front of or on the plane and for a texel not recorded. The side of the
    /// plane on which parallax uncovers a recorded outline: [`super::gap_fill::copy_outlines`]
    /// copies it there.
    pub behind_plane: Vec<bool>,
}

impl LayerImage {
    /// A fully transparent image without clip-border texels.
    pub fn new(res: u32) -> Self {
        let n = res as usize * res as usize;
        LayerImage {
            res,
            rgba: vec![0; 4 * n],
            border: vec![false; n],
            far_border: vec![false; n],
            content: TexelRect::full(res),
            behind_plane: Vec::new(),
        }
    }

    /// Builds an image from its parts, checking the buffer sizes; `far_border` is the part of
    /// `border` on the layer's far border (see [`LayerImage::far_border`]; it is made a subset).
    pub fn from_parts(
        res: u32,
        rgba: Vec<u8>,
        border: Vec<bool>,
        far_border: Vec<bool>,
    ) -> Result<Self, CompressError> {
        let mut image = LayerImage {
            res,
            rgba,
            border,
            far_border,
            content: TexelRect::full(res),
            behind_plane: Vec::new(),
        };
        image.validate()?;
        image.merge_far_border();
        Ok(image)
    }

    /// The image with [`LayerImage::content`] narrowed to `content` (clamped to the image): the
    /// caller knows every texel outside it to be transparent black without clip-border flags.
    pub fn with_content(mut self, content: TexelRect) -> Self {
        let c = TexelRect {
            x0: content.x0.min(self.res),
            y0: content.y0.min(self.res),
            x1: content.x1.min(self.res),
            y1: content.y1.min(self.res),
        };
        self.content = if c.is_empty() { TexelRect::empty() } else { c };
        debug_assert!(
            (0..self.texel_count()).all(|i| {
                let (x, y) = (
                    (i % self.res as usize) as u32,
                    (i / self.res as usize) as u32,
                );
                self.content.contains(x, y)
                    || (self.texel(i) == TRANSPARENT && !self.border[i] && !self.far_border[i])
            }),
            "a texel outside the content rectangle is not empty"
        );
        self
    }

    /// Makes [`LayerImage::far_border`] a subset of [`LayerImage::border`] inside the content.
    fn merge_far_border(&mut self) {
        for i in self.content.rows(self.res).flatten() {
            self.border[i] |= self.far_border[i];
        }
    }

    /// [`LayerImage::from_parts`] for an image whose texels outside `content` are known to be
    /// empty (see [`LayerImage::with_content`]): the far-border merge looks only inside it.
    pub fn from_parts_in(
        res: u32,
        rgba: Vec<u8>,
        border: Vec<bool>,
        far_border: Vec<bool>,
        content: TexelRect,
    ) -> Result<Self, CompressError> {
        let mut image = LayerImage {
            res,
            rgba,
            border,
            far_border,
            content: TexelRect::full(res),
            behind_plane: Vec::new(),
        };
        image.validate()?;
        image = image.with_content(content);
        image.merge_far_border();
        Ok(image)
    }

    /// The image with the recorder's [`LayerImage::behind_plane`] flags (`res · res`, or empty).
    pub fn with_behind_plane(mut self, behind_plane: Vec<bool>) -> Result<Self, CompressError> {
        self.behind_plane = behind_plane;
        self.validate()?;
        Ok(self)
    }

    /// Grows [`LayerImage::content`] to hold `rect` (before writing texels there).
    pub fn include(&mut self, rect: &TexelRect) {
        self.content = self.content.union(rect);
    }

    /// Checks that the buffers match `res`.
    pub fn validate(&self) -> Result<(), CompressError> {
        let n = self.res as usize * self.res as usize;
        if self.content.x1 > self.res || self.content.y1 > self.res {
            return Err(CompressError::Invalid(format!(
                "layer image of resolution {} has content rectangle {:?} beyond it",
                self.res, self.content
            )));
        }
        if self.res == 0
            || self.rgba.len() != 4 * n
            || self.border.len() != n
            || self.far_border.len() != n
        {
            return Err(CompressError::BadImage {
                res: self.res,
                rgba_len: self.rgba.len(),
                border_len: self.border.len(),
                far_border_len: self.far_border.len(),
            });
        }
        if !(self.behind_plane.is_empty() || self.behind_plane.len() == n) {
            return Err(CompressError::Invalid(format!(
                "layer image of resolution {} has {} behind-plane flags, not {n}",
                self.res,
                self.behind_plane.len()
            )));
        }
        Ok(())
    }

    /// Number of texels (`res²`).
    pub fn texel_count(&self) -> usize {
        self.res as usize * self.res as usize
    }

    /// Linear index of texel `(x, y)`.
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.res as usize + x as usize
    }

    /// RGBA of the texel with linear index `i`.
    pub fn texel(&self, i: usize) -> [u8; 4] {
        let p = &self.rgba[4 * i..4 * i + 4];
        [p[0], p[1], p[2], p[3]]
    }

    /// Writes the texel with linear index `i`.
    pub fn set_texel(&mut self, i: usize, rgba: [u8; 4]) {
        self.rgba[4 * i..4 * i + 4].copy_from_slice(&rgba);
    }

    /// Whether the texel with linear index `i` is opaque.
    pub fn is_opaque(&self, i: usize) -> bool {
        self.rgba[4 * i + 3] >= OPAQUE_ALPHA
    }

    /// Makes a texel transparent (and clears its clip-border flags).
    pub fn clear_texel(&mut self, i: usize) {
        self.set_texel(i, TRANSPARENT);
        self.border[i] = false;
        self.far_border[i] = false;
    }

    /// The linear index ranges of the rows of [`LayerImage::content`].
    pub fn content_rows(&self) -> impl Iterator<Item = std::ops::Range<usize>> + use<> {
        self.content.rows(self.res)
    }

    /// Number of opaque texels.
    pub fn opaque_count(&self) -> u64 {
        self.content_rows()
            .map(|row| {
                self.rgba[4 * row.start..4 * row.end]
                    .chunks_exact(4)
                    .filter(|p| p[3] >= OPAQUE_ALPHA)
                    .count() as u64
            })
            .sum()
    }

    /// One flag per texel: opaque or not.
    pub fn opaque_mask(&self) -> Vec<bool> {
        let mut mask = vec![false; self.texel_count()];
        for row in self.content_rows() {
            for (m, p) in mask[row.clone()]
                .iter_mut()
                .zip(self.rgba[4 * row.start..4 * row.end].chunks_exact(4))
            {
                *m = p[3] >= OPAQUE_ALPHA;
            }
        }
        mask
    }
}

/// Checks that all images are valid and share one resolution; returns it (`None` when empty).
pub fn common_res(layers: &[LayerImage]) -> Result<Option<u32>, CompressError> {
    let mut res = None;
    for (k, layer) in layers.iter().enumerate() {
        layer.validate()?;
        match res {
            None => res = Some(layer.res),
            Some(r) if r != layer.res => {
                return Err(CompressError::ResolutionMismatch {
                    layer: k,
                    expected: r,
                    found: layer.res,
                })
            }
            Some(_) => {}
        }
    }
    Ok(res)
}

/// 3×3 "all" of a `res × res` mask: `out[p]` is true when `mask` is true on `p` and on all its
/// 8 neighbours. Neighbours outside the image count as `outside`.
pub fn all3x3(mask: &[bool], res: u32, outside: bool) -> Vec<bool> {
    reduce3x3(mask, res, outside, true)
}

/// 3×3 "any" of a `res × res` mask: `out[p]` is true when `mask` is true on `p` or on one of its
/// 8 neighbours. Neighbours outside the image count as `outside`.
pub fn any3x3(mask: &[bool], res: u32, outside: bool) -> Vec<bool> {
    reduce3x3(mask, res, outside, false)
}

/// [`all3x3`] computed only inside `rect` (false elsewhere): equal to it everywhere when `rect`
/// holds every true texel of `mask` (an eroded mask lies within the mask).
pub fn all3x3_in(mask: &[bool], res: u32, outside: bool, rect: &TexelRect) -> Vec<bool> {
    reduce3x3_in::<true>(mask, res as usize, outside, rect)
}

/// [`any3x3`] computed only inside `rect` (false elsewhere): equal to it everywhere when `rect`
/// holds every true texel of `mask` grown by one texel and `outside` is false.
pub fn any3x3_in(mask: &[bool], res: u32, outside: bool, rect: &TexelRect) -> Vec<bool> {
    reduce3x3_in::<false>(mask, res as usize, outside, rect)
}

fn reduce3x3_in<const ALL: bool>(
    mask: &[bool],
    r: usize,
    outside: bool,
    rect: &TexelRect,
) -> Vec<bool> {
    let mut out = vec![false; r * r];
    if rect.is_empty() || r == 0 {
        return out;
    }
    let (x0, x1) = (rect.x0 as usize, (rect.x1 as usize).min(r));
    let (y0, y1) = (rect.y0 as usize, (rect.y1 as usize).min(r));
    let w = x1 - x0;
    // horizontal pass over the rows y0 - 1 ..= y1 (those inside the image), columns x0..x1
    let hy0 = y0.saturating_sub(1);
    let hy1 = (y1 + 1).min(r);
    let mut h = vec![false; (hy1 - hy0) * w];
    for (hrow, y) in h.chunks_exact_mut(w).zip(hy0..hy1) {
        let row = &mask[y * r..(y + 1) * r];
        let at = |x: isize| -> bool {
            if x < 0 || x as usize >= r {
                outside
            } else {
                row[x as usize]
            }
        };
        for (o, x) in hrow.iter_mut().zip(x0..x1) {
            let x = x as isize;
            *o = op3::<ALL>(at(x - 1), row[x as usize], at(x + 1));
        }
    }
    let pad = vec![outside; w];
    for y in y0..y1 {
        let hrow = |yy: isize| -> &[bool] {
            if yy < 0 || yy as usize >= r {
                &pad
            } else {
                let k = yy as usize - hy0;
                &h[k * w..(k + 1) * w]
            }
        };
        let (up, mid, down) = (hrow(y as isize - 1), hrow(y as isize), hrow(y as isize + 1));
        for (i, o) in out[y * r + x0..y * r + x1].iter_mut().enumerate() {
            *o = op3::<ALL>(up[i], mid[i], down[i]);
        }
    }
    out
}

/// Separable 3×3 min (`all`) or max (`any`) filter with a constant outside value.
fn reduce3x3(mask: &[bool], res: u32, outside: bool, all: bool) -> Vec<bool> {
    if all {
        reduce3x3_with::<true>(mask, res as usize, outside)
    } else {
        reduce3x3_with::<false>(mask, res as usize, outside)
    }
}

#[inline(always)]
fn op3<const ALL: bool>(a: bool, b: bool, c: bool) -> bool {
    if ALL {
        a & b & c
    } else {
        a | b | c
    }
}

fn reduce3x3_with<const ALL: bool>(mask: &[bool], r: usize, outside: bool) -> Vec<bool> {
    // horizontal pass
    let mut h = vec![false; r * r];
    for (hrow, row) in h.chunks_exact_mut(r).zip(mask.chunks_exact(r)) {
        if r == 1 {
            hrow[0] = op3::<ALL>(outside, row[0], outside);
            continue;
        }
        hrow[0] = op3::<ALL>(outside, row[0], row[1]);
        for (o, w) in hrow[1..r - 1].iter_mut().zip(row.windows(3)) {
            *o = op3::<ALL>(w[0], w[1], w[2]);
        }
        hrow[r - 1] = op3::<ALL>(row[r - 2], row[r - 1], outside);
    }
    // vertical pass
    let pad = vec![outside; r];
    let mut out = vec![false; r * r];
    for (y, orow) in out.chunks_exact_mut(r).enumerate() {
        let up = if y == 0 {
            &pad[..]
        } else {
            &h[(y - 1) * r..y * r]
        };
        let mid = &h[y * r..(y + 1) * r];
        let down = if y + 1 == r {
            &pad[..]
        } else {
            &h[(y + 1) * r..(y + 2) * r]
        };
        for (((o, &a), &b), &c) in orow.iter_mut().zip(up).zip(mid).zip(down) {
            *o = op3::<ALL>(a, b, c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reduce3x3_matches_brute_force() {
        let res = 7u32;
        let mask: Vec<bool> = (0..49).map(|i| (i * 37 + i / 3) % 5 != 0).collect();
        for outside in [false, true] {
            let all = all3x3(&mask, res, outside);
            let any = any3x3(&mask, res, outside);
            for y in 0..7i32 {
                for x in 0..7i32 {
                    let mut a = true;
                    let mut o = false;
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let (nx, ny) = (x + dx, y + dy);
                            let v = if (0..7).contains(&nx) && (0..7).contains(&ny) {
                                mask[(ny * 7 + nx) as usize]
                            } else {
                                outside
                            };
                            a &= v;
                            o |= v;
                        }
                    }
                    assert_eq!(all[(y * 7 + x) as usize], a);
                    assert_eq!(any[(y * 7 + x) as usize], o);
                    for rect in [
                        TexelRect::full(res),
                        TexelRect {
                            x0: 1,
                            y0: 2,
                            x1: 6,
                            y1: 5,
                        },
                    ] {
                        let inside = rect.contains(x as u32, y as u32);
                        let k = (y * 7 + x) as usize;
                        assert_eq!(all3x3_in(&mask, res, outside, &rect)[k], a && inside);
                        assert_eq!(any3x3_in(&mask, res, outside, &rect)[k], o && inside);
                    }
                }
            }
        }
    }
}
