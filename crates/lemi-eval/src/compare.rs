//! One view judged against its reference, as a picture: reference | test | difference side by
//! side ([`side_by_side`]) with the numbers of [`crate::image_metrics`] (PSNR, coverage, crack
//! pixels), for `lemi render BUNDLE --compare` and `lemi demo`. The crack pixels are those of
//! [`crate::crack_pixels`] with the tolerance the evaluation gives a layered cell
//! ([`layered_crack_tolerance`]: the farthest reference depth of the pixel's 3×3 neighbourhood
//! plus one layer's slab there, GI 2002 sec. 4), so a view shows the cracks `lemi eval` counts.

use image::{Rgba, RgbaImage};
use lemi_core::bundle::CellFile;
use lemi_core::cell::ViewCell;
use lemi_gpu::Frame;

use crate::image_metrics::{check_pair, coverage, crack_pixels, psnr, Coverage, CrackStats};
use crate::EvalError;

/// How much brighter the difference panel draws a colour difference.
pub const DIFFERENCE_GAIN: u8 = 4;

/// The result of [`side_by_side`].
pub struct SideBySide {
    /// `3w × h`: reference | test | difference (black where equal, the colour difference times
    /// [`DIFFERENCE_GAIN`] elsewhere, red at crack pixels), opaque.
    pub image: RgbaImage,
    /// Pixels whose colour or coverage differs at all.
    pub differing: u64,
    pub cracks: CrackStats,
    pub coverage: Coverage,
    /// PSNR over RGB in dB ([`crate::psnr`]; infinite when identical).
    pub psnr: f64,
}

impl SideBySide {
    /// One line: differing pixels, crack pixels, PSNR.
    pub fn summary(&self) -> String {
        let n = (self.image.width() / 3) as u64 * self.image.height() as u64;
        format!(
            "{} of {n} pixels differ ({:.2} %), {} crack pixels (a surface of the reference seen \
             through: background or something farther than a layer behind), PSNR {:.1} dB",
            self.differing,
            100.0 * self.differing as f64 / n.max(1) as f64,
            self.cracks.count,
            self.psnr
        )
    }
}

/// Compares `test` with `reference` (same size): the side-by-side image and its numbers;
/// `far_tolerance` as for [`crack_pixels`].
pub fn side_by_side(
    reference: &Frame,
    test: &Frame,
    far_tolerance: &dyn Fn(usize, f32) -> f32,
) -> Result<SideBySide, EvalError> {
    check_pair(reference, test)?;
    let cracks = crack_pixels(reference, test, far_tolerance)?;
    let coverage = coverage(reference, test)?;
    let psnr = psnr(reference, test)?;
    let (w, h) = (reference.width, reference.height);
    let mut image = RgbaImage::new(3 * w, h);
    let mut differing = 0;
    for (i, (r, t)) in reference
        .rgba
        .chunks_exact(4)
        .zip(test.rgba.chunks_exact(4))
        .enumerate()
    {
        let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
        let d: [u8; 3] = std::array::from_fn(|k| r[k].abs_diff(t[k]));
        let covered = |f: &Frame| f.depth[i].is_finite();
        if d != [0; 3] || covered(reference) != covered(test) {
            differing += 1;
        }
        let diff = if cracks.mask[i] {
            [255, 0, 0]
        } else {
            d.map(|v| v.saturating_mul(DIFFERENCE_GAIN))
        };
        image.put_pixel(x, y, Rgba([r[0], r[1], r[2], 255]));
        image.put_pixel(w + x, y, Rgba([t[0], t[1], t[2], 255]));
        image.put_pixel(2 * w + x, y, Rgba([diff[0], diff[1], diff[2], 255]));
    }
    Ok(SideBySide {
        image,
        differing,
        cracks,
        coverage,
        psnr,
    })
}

/// The depth range a layered cell's impostor may show beyond reference depth `r` before a pixel
/// counts as a crack: one layer's slab (the slab containing `r`, infinite for the farthest) plus
/// the cell's diagonal (the view depth from a viewpoint off the centre differs from the distance
/// to the centre by at most that); within the near field, the diagonal.
///
/// An object impostor's layers represent the whole object: a pixel may show any depth of it, so
/// the tolerance is the object's depth along the axis plus the cell's width and `2s` (the view
/// depth from a viewpoint in the cell differs from the canonical depth by at most that).
pub fn layer_slab_tolerance(file: &CellFile, cell: &ViewCell, r: f32) -> f32 {
    if let Some(o) = &file.header.object {
        let n = o.params.cell.near_width();
        return (o.params.depth + 2.0 * o.params.s + n[0].hypot(n[1])) as f32;
    }
    let diag = 2.0 * cell.half.length();
    let Some(layers) = file.header.layers.first() else {
        return f32::INFINITY;
    };
    let r = r as f64;
    if r < file.header.near_field {
        return diag as f32;
    }
    for l in layers {
        if r >= l.near_border {
            return if l.far_border >= f64::MAX {
                f32::INFINITY
            } else {
                (l.far_border - l.near_border + diag) as f32
            };
        }
    }
    diag as f32
}

/// The crack tolerance of pixel `i` at reference depth `r`: a surface may move by its sub-pixel
/// error, so at a depth edge the test may show the farther neighbour; allowed is the farthest
/// reference depth `far` of the 3×3 neighbourhood plus `beyond(far)`.
pub fn neighbourhood_tolerance(
    reference: &Frame,
    i: usize,
    r: f32,
    beyond: impl Fn(f32) -> f32,
) -> f32 {
    let (w, h) = (reference.width as usize, reference.height as usize);
    if w == 0 {
        return beyond(r);
    }
    let (x, y) = (i % w, i / w);
    let mut far = r;
    for yy in y.saturating_sub(1)..(y + 2).min(h) {
        for xx in x.saturating_sub(1)..(x + 2).min(w) {
            if let Some(&d) = reference.depth.get(yy * w + xx) {
                far = far.max(d);
            }
        }
    }
    (far - r) + beyond(far)
}

/// The tolerance `lemi eval` gives the impostors of a layered cell, for [`side_by_side`]:
/// [`neighbourhood_tolerance`] with [`layer_slab_tolerance`].
pub fn layered_crack_tolerance<'a>(
    reference: &'a Frame,
    file: &'a CellFile,
    cell: &'a ViewCell,
) -> impl Fn(usize, f32) -> f32 + 'a {
    move |i, r| {
        neighbourhood_tolerance(reference, i, r, |far| layer_slab_tolerance(file, cell, far))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_metrics::tests::frame;

    #[test]
    fn side_by_side_marks_cracks_red_and_counts_like_the_metrics() {
        let reference = frame(8, 6, [100, 100, 100], 5.0);
        let mut test = frame(8, 6, [100, 100, 100], 5.0);
        // a hole inside the surface, and a pixel one shade lighter
        let hole = 3 * 8 + 4;
        test.depth[hole] = f32::INFINITY;
        test.rgba[4 * hole..4 * hole + 3].copy_from_slice(&[150, 190, 235]);
        test.rgba[4 * 9] = 101;
        let tol = |_: usize, _: f32| 1.0f32;
        let s = side_by_side(&reference, &test, &tol).unwrap();
        assert_eq!(s.image.dimensions(), (24, 6));
        assert_eq!(
            s.cracks.count,
            crack_pixels(&reference, &test, &tol).unwrap().count
        );
        assert_eq!(s.cracks.count, 1);
        assert_eq!(s.cracks.first, vec![(4, 3)]);
        assert_eq!(s.differing, 2);
        assert_eq!(s.psnr, psnr(&reference, &test).unwrap());
        assert_eq!(s.coverage.test_covered, 47);
        assert_eq!(s.image.get_pixel(16 + 4, 3).0, [255, 0, 0, 255]);
        assert_eq!(s.image.get_pixel(16 + 1, 1).0, [4, 0, 0, 255]);
        assert_eq!(s.image.get_pixel(16, 0).0, [0, 0, 0, 255]);
        assert_eq!(s.image.get_pixel(8 + 4, 3).0, [150, 190, 235, 255]);
        assert!(s.summary().contains("1 crack pixels"), "{}", s.summary());
        // identical: nothing differs
        let s = side_by_side(&reference, &reference, &tol).unwrap();
        assert_eq!((s.differing, s.cracks.count), (0, 0));
        assert!(s.psnr.is_infinite());
        // mismatched sizes are an error, not a panic
        assert!(side_by_side(&reference, &frame(4, 4, [0; 3], 1.0), &tol).is_err());
    }

    #[test]
    fn neighbourhood_tolerance_takes_the_farthest_neighbour() {
        let mut f = frame(3, 3, [0; 3], 2.0);
        f.depth[0] = 10.0;
        f.depth[8] = f32::INFINITY;
        // centre: the far corner is a neighbour (infinite depth: infinite tolerance)
        assert!(neighbourhood_tolerance(&f, 4, 2.0, |_| 0.5).is_infinite());
        // pixel 1 sees depth 10 at pixel 0, not the infinite corner
        assert_eq!(neighbourhood_tolerance(&f, 1, 2.0, |_| 0.5), 8.5);
        assert_eq!(
            neighbourhood_tolerance(&frame(0, 0, [0; 3], 1.0), 0, 1.0, |_| 0.5),
            0.5
        );
    }
}
