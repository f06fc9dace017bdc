//! Image metrics on a pair of frames (reference = all geometry, test = the impostor image):
//!
//! - [`flip`]: NVIDIA's ꟻLIP perceptual difference (Andersson et al., "FLIP: A Difference Evaluator
//!   for Alternating Images", HPG 2020), computed by the reference C++ implementation through the
//!   `nv-flip` bindings, with the magma colour map of the paper for the heat map;
//! - [`psnr`]: peak signal-to-noise ratio over the R, G, B channels of the sRGB-encoded 8-bit values
//!   (peak 255), `10·log10(255² / MSE)`;
//! - [`ssim`]: the structural similarity index of Wang, Bovik, Sheikh & Simoncelli, "Image Quality
//!   Assessment: From Error Visibility to Structural Similarity", IEEE TIP 2004, as in their reference
//!   `ssim_index.m`: luma `Y = 0.299 R + 0.587 G + 0.114 B` of the 8-bit values, an 11×11 Gaussian
//!   window with σ = 1.5, `K1 = 0.01`, `K2 = 0.03`, `L = 255`, the SSIM map over the "valid" window
//!   positions (no padding) and its mean (MSSIM). No down-sampling is applied;
//! - [`coverage`] and [`crack_pixels`]: from the depth images (finite depth = geometry drawn);
//! - [`silhouettes`]: how far the test's coverage silhouette lies from the reference's (exact
//!   Euclidean distance transforms, Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled
//!   Functions", Theory of Computing 2012), and the pixels the test covers where the reference
//!   shows background.
//!
//! All colour metrics ignore alpha: the RGB of a background pixel is the clear colour, which is what
//! a viewer sees. Every function checks that both frames have the same size and consistent buffers and
//! returns [`EvalError`] otherwise; nothing here panics on bad input.

use lemi_gpu::Frame;

use crate::EvalError;

/// How many crack pixel positions [`CrackStats::first`] keeps.
pub const MAX_CRACK_SAMPLES: usize = 16;

/// The result of [`flip`].
#[derive(Clone, Debug, PartialEq)]
pub struct FlipResult {
    /// Mean of the per-pixel FLIP error (0 = identical, 1 = maximal), the single number the FLIP
    /// authors recommend reporting.
    pub mean: f32,
    /// The per-pixel FLIP error in `[0, 1]`, rows top to bottom.
    pub error: Vec<f32>,
    /// The error mapped through the magma colour map, RGBA8 (alpha 255), same size as the inputs.
    pub heatmap_rgba: Vec<u8>,
    pub width: u32,
    pub height: u32,
}

/// Pixel coverage of the two frames (finite depth = covered).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coverage {
    pub reference_covered: u64,
    pub test_covered: u64,
    /// Pixels covered in both.
    pub both: u64,
    /// `both / reference_covered`: the share of the reference's geometry pixels the test covers too;
    /// 1.0 when the reference covers none.
    pub share: f64,
}

/// The result of [`crack_pixels`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CrackStats {
    pub count: u64,
    /// The first (up to [`MAX_CRACK_SAMPLES`]) crack pixels `(x, y)` in row-major order.
    pub first: Vec<(u32, u32)>,
    /// One flag per pixel, row-major: `true` where a crack is.
    pub mask: Vec<bool>,
}

/// The result of [`silhouettes`].
#[derive(Clone, Debug, PartialEq)]
pub struct SilhouetteStats {
    /// Per silhouette pixel of either frame, the distance in pixels to the nearest silhouette pixel
    /// of the other (both directions pooled; `+∞` when the other frame has no silhouette).
    pub distances: crate::stats::PixelErrorStats,
    /// How far the coverage is displaced: per pixel of either frame's silhouette or covered by
    /// one frame only, the distance in pixels to the nearest pixel the other frame covers (0 where
    /// both cover it; `+∞` when the other frame covers nothing). Its maximum is the Hausdorff
    /// distance between the two coverage sets. Unlike [`Self::distances`] it does not see a
    /// change of topology as a far outline: a sub-pixel slit that one frame closes counts its
    /// pixels' distances to the closed slit's sides, not the slit's outline's distance to the
    /// nearest outline of the other frame.
    pub displacement: crate::stats::PixelErrorStats,
    /// Whether a distance may be overstated because the image ends: some pixel's distance (in
    /// [`Self::distances`] or [`Self::displacement`]) exceeds its distance to the frames' edge,
    /// beyond which the other frame may cover what the measurement cannot see. Measure such a
    /// view again on frames with a guard band ([`silhouettes_within`]).
    pub edge_bound: bool,
    /// Pixels the test covers where the reference shows background.
    pub false_coverage: u64,
}

/// nv-flip's default pixels per degree of visual angle (67: a 0.7 m wide 4K monitor at 0.7 m).
pub fn ppd_default() -> f32 {
    nv_flip::DEFAULT_PIXELS_PER_DEGREE
}

/// Pixels per degree for an observer `distance_m` metres from a monitor `monitor_width_m` metres wide
/// showing `resolution_x` pixels across (FLIP's own formula).
pub fn ppd_for_monitor(distance_m: f32, resolution_x: f32, monitor_width_m: f32) -> f32 {
    nv_flip::pixels_per_degree(distance_m, resolution_x, monitor_width_m)
}

/// Pixels per degree when the image is seen under the field of view it was rendered with: an
/// image `width_px` wide with horizontal field of view `hfov_deg` (the observer at the projection
/// centre). Uses the mean over the image, `width / fov`.
pub fn ppd_for_view(width_px: u32, hfov_deg: f32) -> f32 {
    if hfov_deg > 0.0 {
        width_px as f32 / hfov_deg
    } else {
        ppd_default()
    }
}

/// Checks that a frame's buffers match its size; returns the pixel count.
pub(crate) fn check_frame(frame: &Frame, what: &'static str) -> Result<usize, EvalError> {
    let n = frame.width as usize * frame.height as usize;
    if frame.rgba.len() != 4 * n {
        return Err(EvalError::BufferLength {
            what,
            width: frame.width,
            height: frame.height,
            expected: 4 * n,
            actual: frame.rgba.len(),
            unit: "RGBA bytes",
        });
    }
    if frame.depth.len() != n {
        return Err(EvalError::BufferLength {
            what,
            width: frame.width,
            height: frame.height,
            expected: n,
            actual: frame.depth.len(),
            unit: "depth values",
        });
    }
    Ok(n)
}

/// Checks that both frames are well formed and of one size; returns the pixel count.
pub(crate) fn check_pair(reference: &Frame, test: &Frame) -> Result<usize, EvalError> {
    if (reference.width, reference.height) != (test.width, test.height) {
        return Err(EvalError::SizeMismatch {
            what_a: "reference",
            a_width: reference.width,
            a_height: reference.height,
            what_b: "test",
            b_width: test.width,
            b_height: test.height,
        });
    }
    check_frame(reference, "reference frame")?;
    check_frame(test, "test frame")
}

fn rgb_of(frame: &Frame) -> Vec<u8> {
    frame
        .rgba
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect()
}

/// FLIP between `reference` and `test` at `ppd` pixels per degree ([`ppd_default`] if unsure).
/// An empty (0-pixel) pair gives mean 0 and empty maps.
pub fn flip(reference: &Frame, test: &Frame, ppd: f32) -> Result<FlipResult, EvalError> {
    let n = check_pair(reference, test)?;
    let (width, height) = (reference.width, reference.height);
    if n == 0 {
        return Ok(FlipResult {
            mean: 0.0,
            error: Vec::new(),
            heatmap_rgba: Vec::new(),
            width,
            height,
        });
    }
    let ppd = if ppd.is_finite() && ppd > 0.0 {
        ppd
    } else {
        ppd_default()
    };
    let ref_image = nv_flip::FlipImageRgb8::with_data(width, height, &rgb_of(reference));
    let test_image = nv_flip::FlipImageRgb8::with_data(width, height, &rgb_of(test));
    let error_map = nv_flip::flip(ref_image, test_image, ppd);
    let error = error_map.to_vec();
    let heat_rgb = error_map.apply_color_lut(&nv_flip::magma_lut()).to_vec();
    let heatmap_rgba = heat_rgb
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    let sum: f64 = error.iter().map(|&e| e as f64).sum();
    Ok(FlipResult {
        mean: (sum / n as f64) as f32,
        error,
        heatmap_rgba,
        width,
        height,
    })
}

/// Mean squared error over R, G, B (8-bit values); 0 for an empty pair.
pub fn mse_rgb(reference: &Frame, test: &Frame) -> Result<f64, EvalError> {
    let n = check_pair(reference, test)?;
    if n == 0 {
        return Ok(0.0);
    }
    let sum: u64 = reference
        .rgba
        .chunks_exact(4)
        .zip(test.rgba.chunks_exact(4))
        .map(|(a, b)| {
            (0..3)
                .map(|c| {
                    let d = a[c] as i64 - b[c] as i64;
                    (d * d) as u64
                })
                .sum::<u64>()
        })
        .sum();
    Ok(sum as f64 / (3 * n) as f64)
}

/// PSNR in dB from an RGB mean squared error (peak 255); `INFINITY` for `mse == 0`.
pub fn psnr_from_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

/// RGB mean squared error from a PSNR in dB (the inverse of [`psnr_from_mse`]); 0 for `INFINITY`.
pub fn mse_from_psnr(psnr: f64) -> f64 {
    if psnr.is_infinite() && psnr > 0.0 {
        0.0
    } else {
        255.0f64 * 255.0 / 10f64.powf(psnr / 10.0)
    }
}

/// PSNR in dB over R, G, B; `f64::INFINITY` for identical images (and for an empty pair).
pub fn psnr(reference: &Frame, test: &Frame) -> Result<f64, EvalError> {
    Ok(psnr_from_mse(mse_rgb(reference, test)?))
}

fn luma(frame: &Frame) -> Vec<f64> {
    frame
        .rgba
        .chunks_exact(4)
        .map(|p| 0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64)
        .collect()
}

/// Normalised 1D Gaussian of `size` taps, σ = `sigma` (the 2D window is its outer product, which
/// equals MATLAB's `fspecial('gaussian', size, sigma)`).
fn gaussian(size: usize, sigma: f64) -> Vec<f64> {
    let c = (size as f64 - 1.0) / 2.0;
    let w: Vec<f64> = (0..size)
        .map(|i| {
            let x = i as f64 - c;
            (-x * x / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let s: f64 = w.iter().sum();
    w.into_iter().map(|v| v / s).collect()
}

/// "Valid" separable filtering of a `w × h` image with a `kx × ky` kernel (outer product).
fn filter_valid(img: &[f64], w: usize, h: usize, kx: &[f64], ky: &[f64]) -> Vec<f64> {
    let ow = w + 1 - kx.len();
    let oh = h + 1 - ky.len();
    let mut horiz = vec![0.0; ow * h];
    for y in 0..h {
        let row = &img[y * w..(y + 1) * w];
        for x in 0..ow {
            horiz[y * ow + x] = kx.iter().zip(&row[x..]).map(|(k, v)| k * v).sum();
        }
    }
    let mut out = vec![0.0; ow * oh];
    for (j, k) in ky.iter().enumerate() {
        for y in 0..oh {
            let src = &horiz[(y + j) * ow..(y + j + 1) * ow];
            let dst = &mut out[y * ow..(y + 1) * ow];
            for (d, s) in dst.iter_mut().zip(src) {
                *d += k * s;
            }
        }
    }
    out
}

/// Mean SSIM (Wang et al. 2004, see the module doc) of the luma of the two frames, in `[-1, 1]`;
/// 1 for identical images. Images smaller than 11 pixels in a dimension use a window truncated to
/// that dimension (Gaussian renormalised); an empty pair gives 1.
pub fn ssim(reference: &Frame, test: &Frame) -> Result<f64, EvalError> {
    let n = check_pair(reference, test)?;
    if n == 0 {
        return Ok(1.0);
    }
    const WINDOW: usize = 11;
    const SIGMA: f64 = 1.5;
    const L: f64 = 255.0;
    const C1: f64 = (0.01 * L) * (0.01 * L);
    const C2: f64 = (0.03 * L) * (0.03 * L);
    let (w, h) = (reference.width as usize, reference.height as usize);
    let kx = gaussian(WINDOW.min(w), SIGMA);
    let ky = gaussian(WINDOW.min(h), SIGMA);
    let x = luma(reference);
    let y = luma(test);
    let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
    let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
    let xy: Vec<f64> = x.iter().zip(&y).map(|(a, b)| a * b).collect();
    let mu_x = filter_valid(&x, w, h, &kx, &ky);
    let mu_y = filter_valid(&y, w, h, &kx, &ky);
    let e_xx = filter_valid(&xx, w, h, &kx, &ky);
    let e_yy = filter_valid(&yy, w, h, &kx, &ky);
    let e_xy = filter_valid(&xy, w, h, &kx, &ky);
    let mut sum = 0.0;
    for i in 0..mu_x.len() {
        let (mx, my) = (mu_x[i], mu_y[i]);
        let sxx = e_xx[i] - mx * mx;
        let syy = e_yy[i] - my * my;
        let sxy = e_xy[i] - mx * my;
        sum += ((2.0 * mx * my + C1) * (2.0 * sxy + C2))
            / ((mx * mx + my * my + C1) * (sxx + syy + C2));
    }
    Ok(sum / mu_x.len() as f64)
}

/// Coverage of the two frames by geometry (finite depth).
pub fn coverage(reference: &Frame, test: &Frame) -> Result<Coverage, EvalError> {
    check_pair(reference, test)?;
    let (mut reference_covered, mut test_covered, mut both) = (0u64, 0u64, 0u64);
    for (r, t) in reference.depth.iter().zip(&test.depth) {
        let (r, t) = (r.is_finite(), t.is_finite());
        reference_covered += r as u64;
        test_covered += t as u64;
        both += (r && t) as u64;
    }
    let share = if reference_covered == 0 {
        1.0
    } else {
        both as f64 / reference_covered as f64
    };
    Ok(Coverage {
        reference_covered,
        test_covered,
        both,
        share,
    })
}

/// Crack pixels: inside a surface of the reference (the pixel and its in-image 8 neighbours all have
/// finite depth), the test shows background (non-finite depth), or its depth exceeds the
/// reference's by more than `far_tolerance(pixel_index, reference_depth)` — the caller passes one
/// layer's depth range there, so a test surface "one layer too far" counts as seen through a crack.
/// A test depth *nearer* than the reference is never a crack. Silhouette pixels of the reference are
/// not judged: an impostor may move a silhouette by its allowed sub-pixel error, which the geometric
/// error measures; a crack is a hole where a surface continues. `pixel_index` is row-major
/// `y * width + x`.
pub fn crack_pixels(
    reference: &Frame,
    test: &Frame,
    far_tolerance: &dyn Fn(usize, f32) -> f32,
) -> Result<CrackStats, EvalError> {
    check_pair(reference, test)?;
    let width = reference.width.max(1) as usize;
    let mut mask = vec![false; reference.depth.len()];
    let mut first = Vec::new();
    let mut count = 0u64;
    let height = reference.depth.len() / width;
    let interior = |i: usize| {
        let (x, y) = ((i % width) as i64, (i / width) as i64);
        (-1..=1).all(|dy: i64| {
            (-1..=1).all(|dx: i64| {
                let (xx, yy) = (x + dx, y + dy);
                !((0..width as i64).contains(&xx) && (0..height as i64).contains(&yy))
                    || reference.depth[(yy as usize) * width + xx as usize].is_finite()
            })
        })
    };
    for (i, (&r, &t)) in reference.depth.iter().zip(&test.depth).enumerate() {
        if !r.is_finite() || !interior(i) {
            continue;
        }
        // A NaN tolerance or difference counts as a crack too (not provably within tolerance).
        let within = (t - r)
            .partial_cmp(&far_tolerance(i, r))
            .is_some_and(|o| o.is_le());
        let crack = !t.is_finite() || !within;
        if crack {
            mask[i] = true;
            count += 1;
            if first.len() < MAX_CRACK_SAMPLES {
                first.push(((i % width) as u32, (i / width) as u32));
            }
        }
    }
    Ok(CrackStats { count, first, mask })
}

/// Silhouette pixels of a coverage mask: covered pixels with a 4-neighbour inside the image that
/// is not covered (the image's own edge is not a silhouette).
fn silhouette_mask(covered: &[bool], w: usize, h: usize) -> Vec<bool> {
    let mut out = vec![false; covered.len()];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if !covered[i] {
                continue;
            }
            let open = (x > 0 && !covered[i - 1])
                || (x + 1 < w && !covered[i + 1])
                || (y > 0 && !covered[i - w])
                || (y + 1 < h && !covered[i + w]);
            out[i] = open;
        }
    }
    out
}

/// The exact squared Euclidean distance of every pixel to the nearest set pixel of `mask`
/// (`f64::INFINITY` everywhere if none is set): Felzenszwalb & Huttenlocher's lower envelope of
/// parabolas, once along the rows and once along the columns.
fn squared_distance_transform(mask: &[bool], w: usize, h: usize) -> Vec<f64> {
    let mut f: Vec<f64> = (mask.iter())
        .map(|&m| if m { 0.0 } else { f64::INFINITY })
        .collect();
    let mut line = Vec::new();
    let mut out = Vec::new();
    for x in 0..w {
        line.clear();
        line.extend((0..h).map(|y| f[y * w + x]));
        envelope_1d(&line, &mut out);
        for (y, &d) in out.iter().enumerate() {
            f[y * w + x] = d;
        }
    }
    for y in 0..h {
        line.clear();
        line.extend_from_slice(&f[y * w..(y + 1) * w]);
        envelope_1d(&line, &mut out);
        f[y * w..(y + 1) * w].copy_from_slice(&out);
    }
    f
}

/// One dimension of [`squared_distance_transform`]: `out[q] = min_p (q − p)² + f[p]`.
fn envelope_1d(f: &[f64], out: &mut Vec<f64>) {
    let n = f.len();
    out.clear();
    out.resize(n, f64::INFINITY);
    // parabolas with finite height; `v`: their vertices, `z`: where each one starts to be lowest
    let (mut v, mut z): (Vec<usize>, Vec<f64>) = (Vec::with_capacity(n), Vec::with_capacity(n + 1));
    for q in (0..n).filter(|&q| f[q].is_finite()) {
        let fq = f[q] + (q * q) as f64;
        loop {
            let Some(&p) = v.last() else {
                v.push(q);
                z.push(f64::NEG_INFINITY);
                break;
            };
            let s = (fq - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64));
            if z.last().is_some_and(|&zl| s <= zl) {
                v.pop();
                z.pop();
                continue;
            }
            v.push(q);
            z.push(s);
            break;
        }
    }
    if v.is_empty() {
        return;
    }
    let mut k = 0;
    for (q, o) in out.iter_mut().enumerate() {
        while k + 1 < v.len() && z[k + 1] < q as f64 {
            k += 1;
        }
        let d = q as f64 - v[k] as f64;
        *o = d * d + f[v[k]];
    }
}

/// Compares the coverage silhouettes of the two frames (finite depth = covered): for every
/// silhouette pixel of each frame, its distance in pixels to the nearest silhouette pixel of the
/// other (pooled; an impostor whose outlines sit where the geometry's do has distances of 0), and
/// the false-coverage pixels (the test shows something where the reference shows background).
pub fn silhouettes(reference: &Frame, test: &Frame) -> Result<SilhouetteStats, EvalError> {
    check_pair(reference, test)?;
    let whole = GuardBand {
        px: 0,
        width: reference.width,
        height: reference.height,
    };
    silhouettes_within(reference, test, whole)
}

/// The part of a frame that is the output view, inside a band of `px` pixels on every side: frames
/// rendered with the output view's focal length and `2·px` more pixels across and down, so that
/// the output view's pixels are those at `[px, px + width) × [px, px + height)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GuardBand {
    pub px: u32,
    pub width: u32,
    pub height: u32,
}

/// [`silhouettes`] of the output view inside frames with a guard band (`band`): the distances are
/// taken to the other frame's outlines and coverage anywhere in the frames, and kept for the
/// pixels of the output view only. A distance of up to `band.px` is then exact even at the output
/// view's edge, where [`silhouettes`] on frames of the output size alone cannot see that the
/// other frame covers a pixel just beyond it (and overstates the distance).
pub fn silhouettes_within(
    reference: &Frame,
    test: &Frame,
    band: GuardBand,
) -> Result<SilhouetteStats, EvalError> {
    check_pair(reference, test)?;
    let (w, h) = (reference.width as usize, reference.height as usize);
    let (g, iw, ih) = (band.px as usize, band.width as usize, band.height as usize);
    if g + iw > w || g + ih > h {
        return Err(EvalError::Job(format!(
            "a {iw}x{ih} view inside a guard band of {g} px does not fit a {w}x{h} frame"
        )));
    }
    let inside = |i: usize| (g..g + iw).contains(&(i % w)) && (g..g + ih).contains(&(i / w));
    // how far a pixel lies from the nearest pixel beyond the frame
    let to_edge = |i: usize| {
        let (x, y) = (i % w, i / w);
        (x + 1).min(y + 1).min(w - x).min(h - y) as f32
    };
    let covered = |f: &Frame| f.depth.iter().map(|d| d.is_finite()).collect::<Vec<bool>>();
    let (rc, tc) = (covered(reference), covered(test));
    let false_coverage = (0..w * h).filter(|&i| inside(i) && !rc[i] && tc[i]).count() as u64;
    let (re, te) = (silhouette_mask(&rc, w, h), silhouette_mask(&tc, w, h));
    let (rd, td) = (
        squared_distance_transform(&re, w, h),
        squared_distance_transform(&te, w, h),
    );
    let mut edge_bound = false;
    let mut keep = |values: &mut Vec<f32>, i: usize, d2: f64| {
        let d = d2.sqrt() as f32;
        edge_bound |= d > to_edge(i);
        values.push(d);
    };
    let mut values = Vec::new();
    for i in (0..w * h).filter(|&i| inside(i)) {
        if te[i] {
            keep(&mut values, i, rd[i]);
        }
        if re[i] {
            keep(&mut values, i, td[i]);
        }
    }
    let (rcd, tcd) = (
        squared_distance_transform(&rc, w, h),
        squared_distance_transform(&tc, w, h),
    );
    let mut displaced = Vec::new();
    for i in (0..w * h).filter(|&i| inside(i)) {
        match (rc[i], tc[i]) {
            (true, false) => keep(&mut displaced, i, tcd[i]),
            (false, true) => keep(&mut displaced, i, rcd[i]),
            _ if re[i] || te[i] => displaced.push(0.0),
            _ => {}
        }
    }
    Ok(SilhouetteStats {
        distances: crate::stats::PixelErrorStats::from_values(&values),
        displacement: crate::stats::PixelErrorStats::from_values(&displaced),
        edge_bound,
        false_coverage,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A `w × h` frame of one colour at one depth.
    pub(crate) fn frame(w: u32, h: u32, rgb: [u8; 3], depth: f32) -> Frame {
        let n = (w * h) as usize;
        Frame {
            width: w,
            height: h,
            rgba: (0..n).flat_map(|_| [rgb[0], rgb[1], rgb[2], 255]).collect(),
            depth: vec![depth; n],
        }
    }

    #[test]
    fn gaussian_is_normalised_and_symmetric() {
        let g = gaussian(11, 1.5);
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        for i in 0..11 {
            assert!((g[i] - g[10 - i]).abs() < 1e-15);
        }
        assert!(g[5] > g[4]);
    }

    #[test]
    fn filter_valid_of_constant_is_constant() {
        let img = vec![3.0; 20 * 15];
        let k = gaussian(11, 1.5);
        let out = filter_valid(&img, 20, 15, &k, &k);
        assert_eq!(out.len(), 10 * 5);
        assert!(out.iter().all(|v| (v - 3.0).abs() < 1e-12));
    }

    #[test]
    fn ssim_of_constant_offset_matches_luminance_term() {
        // Flat images: σ = 0, so SSIM = (2 μx μy + C1) / (μx² + μy² + C1).
        let a = frame(16, 16, [100, 100, 100], 1.0);
        let b = frame(16, 16, [120, 120, 120], 1.0);
        let c1 = (0.01f64 * 255.0).powi(2);
        let (mx, my) = (100.0f64, 120.0f64);
        let expected = (2.0 * mx * my + c1) / (mx * mx + my * my + c1);
        let s = ssim(&a, &b).unwrap();
        assert!((s - expected).abs() < 1e-9, "{s} vs {expected}");
    }

    #[test]
    fn tiny_images_do_not_panic() {
        let a = frame(1, 1, [0, 0, 0], 1.0);
        let b = frame(1, 1, [255, 255, 255], f32::INFINITY);
        assert!(ssim(&a, &b).unwrap() < 0.1);
        assert!(psnr(&a, &b).unwrap().abs() < 1e-12);
        assert!(flip(&a, &b, ppd_default()).unwrap().mean > 0.0);
        let e = frame(0, 0, [0, 0, 0], 1.0);
        assert_eq!(ssim(&e, &e).unwrap(), 1.0);
        assert_eq!(flip(&e, &e, 67.0).unwrap().mean, 0.0);
        assert_eq!(coverage(&e, &e).unwrap().share, 1.0);
    }

    #[test]
    fn malformed_buffers_are_errors() {
        let mut a = frame(4, 4, [0, 0, 0], 1.0);
        let b = a.clone();
        a.depth.pop();
        assert!(matches!(
            coverage(&a, &b),
            Err(EvalError::BufferLength { .. })
        ));
        a.depth.push(1.0);
        a.rgba.pop();
        assert!(matches!(psnr(&a, &b), Err(EvalError::BufferLength { .. })));
    }

    #[test]
    fn psnr_mse_round_trip() {
        for mse in [0.5, 1.0, 100.0, 65025.0] {
            assert!((mse_from_psnr(psnr_from_mse(mse)) - mse).abs() < 1e-9 * mse);
        }
        assert_eq!(mse_from_psnr(f64::INFINITY), 0.0);
    }

    proptest::proptest! {
        /// The distance transform is exact: equal to the brute-force nearest set pixel.
        #[test]
        fn distance_transform_matches_brute_force(
            w in 1usize..20,
            h in 1usize..15,
            bits in proptest::collection::vec(proptest::bool::weighted(0.08), 300),
        ) {
            let mask: Vec<bool> = bits[..w * h].to_vec();
            let got = squared_distance_transform(&mask, w, h);
            for y in 0..h {
                for x in 0..w {
                    let want = (0..w * h)
                        .filter(|&k| mask[k])
                        .map(|k| {
                            let (dx, dy) = ((k % w) as f64 - x as f64, (k / w) as f64 - y as f64);
                            dx * dx + dy * dy
                        })
                        .fold(f64::INFINITY, f64::min);
                    proptest::prop_assert_eq!(got[y * w + x], want, "({}, {})", x, y);
                }
            }
        }
    }
}
