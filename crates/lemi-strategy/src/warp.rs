//! The `warp` strategy: depth-image warping of the far field, after a terrain-impostors report
//! ("Pre-recording Images" and "Warping Images", its sec. 2 and 3).
//!
//! # Recording ("pre-recording images", report sec. 2 and 5)
//! A cell's far field is recorded on the first frame that needs it (or by [`Strategy::preload`]):
//! at the cell's **sample point**, its centre (the reference viewpoint of the bundle), one image per
//! baked face (`manifest.params.faces`) at [`WarpStrategy::recording_resolution`] (by default
//! matched to the output view the bake assumed, so that a recorded pixel is no wider than an
//! output pixel at the view centre, as the report recorded images of the window's size), each
//! holding colour (sRGB RGBA8), linear view depth and the camera matrix
//! `CAM1 = PJ · MV` ([`FaceRecording::view`]). Only the **far field** is recorded: the scene
//! without the cell's near-list triangles, uploaded as a transient sub-scene and dropped after the
//! recording.
//!
//! **Border** (report sec. 5): every face is recorded enlarged so that the warped image has data
//! beyond the face's edges when the viewer moves off the sample point. [`WarpOptions::border`] is
//! the fraction of the face width added: a face spans `[−1, 1]` in tan space (width 2), the
//! recorded image spans `[−(1+b), 1+b]` (width `2 + 2b`, i.e. `b` of the face width more in total,
//! `b/2` of it on each side); the report's best value, "1/5 of the width of the original face", is
//! `b = 0.2`: half-extent 1.2 in tan space, a symmetric frustum of `2·atan(1.2) ≈ 100.4°`. With
//! a fixed number of pixels per face (`WarpOptions::resolution`), a larger border makes every
//! pixel larger (the report: a larger border means more holes); the matched default grows the
//! image with the border instead.
//!
//! # One frame (report sec. 3 and 4)
//! 1. The cell's near geometry (its near list, the same as every strategy's) is drawn with the
//!    reference [`Renderer`]: colour and view depth.
//! 2. **Forward mapping of the depths** (sec. 3.2): every source texel with a recorded depth is
//!    mapped with `T12 = CAM2 · CAM1⁻¹` (NDC of the face image → clip space of the output view,
//!    `w` divided out, viewport transform) to the output pixel containing it; each output pixel
//!    keeps the **nearest** depth (a z-buffer of packed `(depth, source texel)` words, atomic min,
//!    parallel over texels). The image used is the current cell's recording: the sample point
//!    nearest the eye is the current cell's centre. All faces are mapped (their bordered images
//!    overlap; the z-test keeps one sample per pixel).
//! 3. **Hole filling** (sec. 4, [`HoleFilling`]):
//!    - *8-neighbour*: an empty pixel with both pixels of an opposite pair of its 8 neighbours
//!      (left–right, up–down, or one of the two diagonals) filled is a one-pixel hole and gets that
//!      pair's depth: of the pairs, the one with the most similar depths; `1/depth` interpolated
//!      (exact on planes) when the pair's depths are within [`SAME_SURFACE_RATIO`], else the
//!      farther depth (a disocclusion sliver shows the background extended). Wider holes are left.
//!      A pixel that holds a sample of a farther surface seen *through* a one-pixel hole of a
//!      nearer one (both pixels of a pair nearer than it by more than [`SAME_SURFACE_RATIO`], and
//!      on one surface) is such a hole too: without this, magnified surfaces show lines of what
//!      lies behind them (an addition to the report, whose terrain hardly overlaps itself).
//!    - *outline*: then every empty pixel *enclosed by the warped region* is filled: one with a
//!      filled pixel to its left and right in its row **and** above and below in its column (the
//!      report's outline; within [`WarpOptions::max_outline_span`] if set), or one in a run of at
//!      most [`SHORT_RUN`] empty pixels between two filled ones in its row **or** its column (a
//!      magnified surface has whole rows and columns of holes, which are not enclosed both ways).
//!      The value comes from the shorter of its enclosing runs, by the same rule as above
//!      (interpolation on one surface, the farther depth across a discontinuity). Sky between
//!      towers (nothing above) is not enclosed; a short run that is filled over sky anyway is
//!      emptied again by the backward mapping, which finds no depth there in the source image.
//!      The pass is repeated (at most [`OUTLINE_PASSES`] times) while it fills pixels: the
//!      crossings of a row and a column of holes are enclosed only once both are filled.
//! 4. **Backward mapping of the image** (sec. 3.3): every output pixel with a depth (and not hidden
//!    by nearer near geometry) is mapped with `T21 = CAM1 · CAM2⁻¹` (its NDC and the NDC depth of
//!    its view depth) into the face image its depth came from (another face when it falls outside
//!    that one), and takes the colour of the **nearest texel** (the texel under the point; no
//!    bilinear blending, which mixes foreground and background colours at silhouettes). A texel
//!    without depth leaves the pixel empty: the source shows background there (this trims the
//!    half pixel by which nearest-depth splatting widens silhouettes).
//! 5. Composite: near pixel where its depth is nearer, else the warped far pixel, else the clear
//!    colour. CPU work (rayon); the cost depends on the output and recording sizes only.
//!
//! Outside the grid, in an unbaked cell or a damaged one (warned once), the frame draws all
//! geometry (`fallback`).
//!
//! # Error ([`crate::FrameRequest::measure_error`])
//! For a far pixel, the source texel whose colour it shows is unprojected with its recorded depth
//! to the true surface point `T`; the error is the angle between the pixel's ray (through its
//! centre) and the direction from the eye to `T`, divided by the **local** angle of that output
//! pixel (the geometric mean of the angles between the rays through the midpoints of its left and
//! right edges and of its top and bottom edges). To first order this is the distance in output
//! pixels between the pixel centre and the projection of `T`, lemi's layered error
//! (`lemi_core::parallax_error`). At the sample point it is only the resampling offset (at most
//! half a source texel diagonal); off it, magnification, hole filling and disocclusions add to it.
//! NaN for background and near-geometry pixels.
//!
//! # Bookkeeping
//! Recordings are kept for the last [`WarpOptions::cache_cells`] cells (LRU; `cache_bytes`:
//! their colour + depth plus the near geometry's vertex and index bytes). A frame that records
//! its cell waits for it: it is `stalled` and counts one `regeneration`; the recording time goes
//! to `prepare_seconds`. A recording made with other lighting or alpha cutoff than a frame asks
//! for is made again. `far_primitives` is the number of source texels forward-mapped (those with
//! a depth), `near_triangles` the length of the cell's near list. Recording builds the far
//! sub-scene on the CPU first (a transient copy of the far triangles).

use std::collections::{HashSet, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{DMat4, DVec2, DVec3, DVec4};
use lemi_core::bundle::{Bundle, CellFile};
use lemi_core::camera::{perspective_reverse_infinite, view_matrix_basis, View, DEFAULT_NEAR};
use lemi_core::cell::{CellId, ViewCell};
use lemi_core::classify::TriRef;
use lemi_core::{Face, Mesh, Scene, Vertex};
use lemi_gpu::{
    Frame, Gpu, GpuGeometry, GpuMaterials, GpuScene, Lighting, RenderOptions, Renderer,
    UploadOptions,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{
    FrameRequest, Strategy, StrategyContext, StrategyError, StrategyFrame, StrategyKind,
    StrategyReport,
};

/// Two depths whose ratio is at most this are taken for one surface by the hole filling (their
/// `1/depth` is interpolated); farther apart, the hole gets the farther depth.
pub const SAME_SURFACE_RATIO: f64 = 1.1;

/// Runs of empty pixels up to this long are filled by the outline method when enclosed in one
/// direction only (a row or a column of holes across a magnified surface).
pub const SHORT_RUN: usize = 3;

/// Passes of the outline method at most: a pass fills the rows and columns of holes across a
/// magnified surface, the next their crossings.
pub const OUTLINE_PASSES: usize = 4;

/// The largest accepted [`WarpOptions::border`] (half-extent 5 in tan space, a 157° frustum).
pub const MAX_BORDER: f64 = 4.0;

/// How holes of the forward-mapped depth image are filled (report sec. 4).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HoleFilling {
    /// No filling: only forward-mapped pixels are drawn.
    None,
    /// The 8-neighbour method only (one-pixel holes).
    Neighbours,
    /// The 8-neighbour method, then the outline method (the report's Fig. 12).
    #[default]
    NeighboursAndOutline,
}

/// Options of [`WarpStrategy`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WarpOptions {
    /// Fraction of the face width added to each recorded face (module docs): the recorded image
    /// spans `±(1 + border)` in tan space. Default 0.2, the report's 1/5. In `[0, 4]`.
    pub border: f64,
    pub hole_filling: HoleFilling,
    /// Longest run of empty pixels (in a row or column) the outline method fills; `None`: any
    /// enclosed run, as in the report.
    pub max_outline_span: Option<u32>,
    /// Cells whose recordings are kept (LRU), at least 1.
    pub cache_cells: usize,
    /// Pixels per recorded face side. `None` (default): matched to the output view the bake
    /// assumed (`output_width`, `output_fov_deg`), so that a recorded pixel is no wider than an
    /// output pixel at the view centre, as the report recorded images of the window's size
    /// (forward mapping from a smaller image leaves holes the hole filling cannot close); the
    /// bundle's resolution when the bake recorded no output view. At most 4096.
    pub resolution: Option<u32>,
}

impl Default for WarpOptions {
    fn default() -> Self {
        WarpOptions {
            border: 0.2,
            hole_filling: HoleFilling::default(),
            max_outline_span: None,
            cache_cells: 4,
            resolution: None,
        }
    }
}

impl WarpOptions {
    /// Checks the options; the error names the option, the accepted range and the value.
    pub fn validate(&self) -> Result<(), StrategyError> {
        let bad = |option: &'static str, message: String| StrategyError::BadOption {
            strategy: StrategyKind::Warp,
            option,
            message,
        };
        if !(self.border.is_finite() && (0.0..=MAX_BORDER).contains(&self.border)) {
            return Err(bad(
                "border",
                format!(
                    "must be a number in [0, {MAX_BORDER}] (the fraction of the face \
                     width added to each recorded face; 0.2, the report's 1/5, is the default), got {}",
                    self.border
                ),
            ));
        }
        if self.cache_cells == 0 || self.cache_cells > 4096 {
            return Err(bad(
                "cache_cells",
                format!(
                    "must be 1..=4096 (cells whose recordings are kept), got {}",
                    self.cache_cells
                ),
            ));
        }
        if let Some(r) = self.resolution {
            if !(8..=4096).contains(&r) {
                return Err(bad(
                    "resolution",
                    format!("must be 8..=4096 pixels per recorded face side, got {r}"),
                ));
            }
        }
        if self.max_outline_span == Some(0) {
            return Err(bad(
                "max_outline_span",
                "must be at least 1 pixel (or unset for no limit), got 0".into(),
            ));
        }
        Ok(())
    }

    /// Half-extent of a recorded face in tan space: `1 + border`.
    pub fn half_extent(&self) -> f64 {
        1.0 + self.border
    }
}

/// The camera of a recorded face: from `center` along `face` (the cube-face basis of
/// [`View::cube_face`]), a symmetric reverse-Z infinite perspective whose image spans
/// `±half_extent` in tan space, `res × res` pixels. Texel `(i, j)` sees the direction
/// `face.point(s, t, 1)` with `(s, t) = half_extent · Face::texel_center(i, j, res)`.
pub fn recording_view(center: DVec3, face: Face, res: u32, half_extent: f64, near: f64) -> View {
    View {
        view: view_matrix_basis(center, face.right(), -face.down(), face.forward()),
        proj: perspective_reverse_infinite(2.0 * half_extent.atan(), 1.0, near),
        width: res,
        height: res,
    }
}

/// One recorded face image.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceRecording {
    pub face: Face,
    /// The camera; `view.view_proj()` is the report's `CAM1`.
    pub view: View,
    pub res: u32,
    /// sRGB RGBA8, row-major from the top.
    pub rgba: Vec<u8>,
    /// View depth along the face axis; `f32::INFINITY` where nothing was recorded.
    pub depth: Vec<f32>,
}

/// A cell's recording: one image per baked face, from the cell's centre.
#[derive(Clone, Debug, PartialEq)]
pub struct CellRecording {
    pub id: CellId,
    /// The sample point (the cell's centre).
    pub center: DVec3,
    /// `1 + border`.
    pub half_extent: f64,
    pub faces: Vec<FaceRecording>,
}

impl CellRecording {
    /// Bytes held (colour + depth).
    pub fn bytes(&self) -> u64 {
        self.faces
            .iter()
            .map(|f| (f.rgba.len() + 4 * f.depth.len()) as u64)
            .sum()
    }

    /// World position of source texel `id` (see [`WarpedImage::shown`]) at its recorded depth;
    /// `None` for a texel without depth.
    pub fn texel_point(&self, id: u32) -> Option<DVec3> {
        let (slot, idx) = self.split_id(id)?;
        let f = &self.faces[slot];
        let d = *f.depth.get(idx)? as f64;
        if !d.is_finite() {
            return None;
        }
        Some(self.center + d * self.texel_dir(f, idx))
    }

    /// `forward + s·right + t·down` of texel `idx` of face `f` (unit depth along the face axis).
    fn texel_dir(&self, f: &FaceRecording, idx: usize) -> DVec3 {
        let res = f.res as usize;
        let (s, t) = Face::texel_center((idx % res) as u32, (idx / res) as u32, f.res);
        f.face
            .point(s * self.half_extent, t * self.half_extent, 1.0)
    }

    fn split_id(&self, id: u32) -> Option<(usize, usize)> {
        let per = self.faces.first().map(|f| (f.res * f.res) as usize)?;
        let (slot, idx) = (id as usize / per, id as usize % per);
        (slot < self.faces.len()).then_some((slot, idx))
    }
}

/// The far field warped into an output view.
#[derive(Clone, Debug, PartialEq)]
pub struct WarpedImage {
    pub width: u32,
    pub height: u32,
    /// sRGB RGBA8 of the far field; alpha 0 where it has nothing (or near geometry hides it).
    pub rgba: Vec<u8>,
    /// View depth of the far field after hole filling; `f32::INFINITY` where empty.
    pub depth: Vec<f32>,
    /// Per pixel, the source texel whose colour it shows, as `face_slot · res² + row · res +
    /// column`; `u32::MAX` where none.
    pub shown: Vec<u32>,
    /// Source texels with a depth, forward-mapped.
    pub forward_mapped: u64,
    /// Output pixels that received a forward-mapped depth.
    pub splatted_pixels: u64,
    pub filled_neighbours: u64,
    pub filled_outline: u64,
}

const EMPTY: u64 = u64::MAX;

/// Warps `rec` into `view` (module docs, steps 2–4). `near_depth`: the near geometry's view depths
/// (`INFINITY` for none); far pixels behind nearer near geometry are not backward-mapped and stay
/// empty in `rgba`/`shown` (their depth is kept).
pub fn warp(
    rec: &CellRecording,
    view: &View,
    hole_filling: HoleFilling,
    max_outline_span: Option<u32>,
    near_depth: Option<&[f32]>,
) -> WarpedImage {
    let (w, h) = (view.width as usize, view.height as usize);
    let n = w * h;
    let cam2 = view.view_proj();
    let mv2 = view.view;

    // Forward mapping of the depths: T12 = CAM2 · CAM1⁻¹ on (ndc1, z1, 1).
    let zbuf: Vec<AtomicU64> = (0..n).map(|_| AtomicU64::new(EMPTY)).collect();
    let mut forward_mapped = 0u64;
    for (slot, f) in rec.faces.iter().enumerate() {
        let inv_cam1 = f.view.view_proj().inverse();
        let t12 = cam2 * inv_cam1;
        let d12 = mv2 * inv_cam1;
        let proj1 = f.view.proj;
        let res = f.res as usize;
        let base = (slot * res * res) as u64;
        forward_mapped += f
            .depth
            .par_chunks(res)
            .enumerate()
            .map(|(j, row)| {
                let mut count = 0u64;
                for (i, &d) in row.iter().enumerate() {
                    if !(d.is_finite() && d > 0.0) {
                        continue;
                    }
                    count += 1;
                    let ndc1 = f
                        .view
                        .pixel_to_ndc(DVec2::new(i as f64 + 0.5, j as f64 + 0.5));
                    let h1 = DVec4::new(ndc1.x, ndc1.y, ndc_depth(&proj1, d as f64), 1.0);
                    let c2 = t12 * h1;
                    if c2.w <= 0.0 {
                        continue;
                    }
                    let p2 = view.ndc_to_pixel(DVec2::new(c2.x / c2.w, c2.y / c2.w));
                    if !(p2.x >= 0.0 && p2.y >= 0.0 && p2.x < w as f64 && p2.y < h as f64) {
                        continue;
                    }
                    let v2 = d12 * h1;
                    let d2 = -v2.z / v2.w;
                    if !(d2 > 0.0 && d2.is_finite()) {
                        continue;
                    }
                    let key = ((d2 as f32).to_bits() as u64) << 32
                        | (base + (j * res + i) as u64) & 0xffff_ffff;
                    let px = p2.y as usize * w + p2.x as usize;
                    zbuf[px].fetch_min(key, Ordering::Relaxed);
                }
                count
            })
            .sum::<u64>();
    }
    let mut depth = vec![f32::INFINITY; n];
    let mut src = vec![u32::MAX; n];
    let mut splatted = 0u64;
    for (k, z) in zbuf.into_iter().enumerate() {
        let z = z.into_inner();
        if z != EMPTY {
            depth[k] = f32::from_bits((z >> 32) as u32);
            src[k] = z as u32;
            splatted += 1;
        }
    }

    // Hole filling.
    let mut filled_neighbours = 0;
    let mut filled_outline = 0;
    if hole_filling != HoleFilling::None {
        filled_neighbours = fill_neighbours(&mut depth, &mut src, w, h);
    }
    if hole_filling == HoleFilling::NeighboursAndOutline {
        for _ in 0..OUTLINE_PASSES {
            let n = fill_outline(&mut depth, &mut src, w, h, max_outline_span);
            filled_outline += n;
            if n == 0 {
                break;
            }
        }
    }

    // Backward mapping of the image: T21 = CAM1 · CAM2⁻¹ on (ndc2, z2, 1).
    let inv_cam2 = cam2.inverse();
    let t21: Vec<DMat4> = rec
        .faces
        .iter()
        .map(|f| f.view.view_proj() * inv_cam2)
        .collect();
    let mut rgba = vec![0u8; 4 * n];
    let mut shown = vec![u32::MAX; n];
    rgba.par_chunks_mut(4 * w)
        .zip(shown.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (rgba_row, shown_row))| {
            for x in 0..w {
                let k = y * w + x;
                let d2 = depth[k];
                if !d2.is_finite() || near_depth.is_some_and(|nd| nd[k] <= d2) {
                    continue;
                }
                let ndc2 = view.pixel_to_ndc(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                let h2 = DVec4::new(ndc2.x, ndc2.y, ndc_depth(&view.proj, d2 as f64), 1.0);
                let Some(id) = backward(rec, &t21, h2, src[k]) else {
                    continue;
                };
                let Some((slot, idx)) = rec.split_id(id) else {
                    continue;
                };
                let c = &rec.faces[slot].rgba[4 * idx..4 * idx + 4];
                rgba_row[4 * x..4 * x + 4].copy_from_slice(&[c[0], c[1], c[2], 255]);
                shown_row[x] = id;
            }
        });
    WarpedImage {
        width: view.width,
        height: view.height,
        rgba,
        depth,
        shown,
        forward_mapped,
        splatted_pixels: splatted,
        filled_neighbours,
        filled_outline,
    }
}

/// NDC depth of view depth `d` under `proj` (a projection whose depth depends on view-space `z`
/// only, as every perspective and orthographic one).
fn ndc_depth(proj: &DMat4, d: f64) -> f64 {
    let c = *proj * DVec4::new(0.0, 0.0, -d, 1.0);
    c.z / c.w
}

/// The source texel a pixel with homogeneous NDC `h2` shows: the texel under the point in the
/// face of the pixel's own source texel `own`, or in another face when the point falls outside
/// that one (clamped to `own`'s face when it is in none); `None` when that texel recorded nothing
/// (the source shows background there).
fn backward(rec: &CellRecording, t21: &[DMat4], h2: DVec4, own: u32) -> Option<u32> {
    let (own_slot, _) = rec.split_id(own)?;
    let texel = |slot: usize, clamp: bool| -> Option<u32> {
        let f = &rec.faces[slot];
        let c1 = t21[slot] * h2;
        if c1.w <= 0.0 {
            return None;
        }
        let p1 = f.view.ndc_to_pixel(DVec2::new(c1.x / c1.w, c1.y / c1.w));
        let r = f.res as f64;
        let inside = p1.x >= 0.0 && p1.y >= 0.0 && p1.x < r && p1.y < r;
        if !(clamp || inside) {
            return None;
        }
        let res = f.res as i64;
        let ix = (p1.x.floor() as i64).clamp(0, res - 1);
        let iy = (p1.y.floor() as i64).clamp(0, res - 1);
        Some((slot as i64 * res * res + iy * res + ix) as u32)
    };
    let id = texel(own_slot, false)
        .or_else(|| {
            (0..rec.faces.len())
                .filter(|&s| s != own_slot)
                .find_map(|s| texel(s, false))
        })
        .or_else(|| texel(own_slot, true))?;
    rec.texel_point(id).is_some().then_some(id)
}

/// The depth (and source) a hole between two filled pixels `a` (at 0) and `b` (at 1) gets at
/// fraction `t`: `1/depth` interpolated on one surface, the farther one across a discontinuity.
fn between(a: (f32, u32), b: (f32, u32), t: f64) -> (f32, u32) {
    let (da, db) = (a.0 as f64, b.0 as f64);
    if da.max(db) <= SAME_SURFACE_RATIO * da.min(db) {
        let inv = (1.0 - t) / da + t / db;
        ((1.0 / inv) as f32, if t <= 0.5 { a.1 } else { b.1 })
    } else if da > db {
        a
    } else {
        b
    }
}

/// The 8-neighbour method: fills one-pixel holes (module docs). Returns the pixels filled.
fn fill_neighbours(depth: &mut [f32], src: &mut [u32], w: usize, h: usize) -> u64 {
    let (d0, s0) = (depth.to_vec(), src.to_vec());
    let at = |x: i64, y: i64| -> Option<(f32, u32)> {
        if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
            return None;
        }
        let k = y as usize * w + x as usize;
        d0[k].is_finite().then(|| (d0[k], s0[k]))
    };
    const PAIRS: [((i64, i64), (i64, i64)); 4] = [
        ((-1, 0), (1, 0)),
        ((0, -1), (0, 1)),
        ((-1, -1), (1, 1)),
        ((1, -1), (-1, 1)),
    ];
    let mut filled = 0;
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let k = y as usize * w + x as usize;
            // A filled pixel is a hole too when a farther surface shows through it: both pixels
            // of a pair are nearer (by more than SAME_SURFACE_RATIO) and on one surface.
            let own = d0[k] as f64;
            let mut best: Option<(f64, (f32, u32))> = None;
            for ((ax, ay), (bx, by)) in PAIRS {
                if let (Some(a), Some(b)) = (at(x + ax, y + ay), at(x + bx, y + by)) {
                    let (near, far) = (a.0.min(b.0) as f64, a.0.max(b.0) as f64);
                    let ratio = far / near;
                    let hole = !own.is_finite()
                        || (ratio <= SAME_SURFACE_RATIO && own > SAME_SURFACE_RATIO * far);
                    if hole && best.is_none_or(|(r, _)| ratio < r) {
                        best = Some((ratio, between(a, b, 0.5)));
                    }
                }
            }
            if let Some((_, (d, s))) = best {
                depth[k] = d;
                src[k] = s;
                filled += 1;
            }
        }
    }
    filled
}

/// For every pixel `i` of a line of `len` pixels (`filled(i)`), the nearest filled pixel before
/// and after it (`usize::MAX` for none).
fn bounds_along(len: usize, filled: impl Fn(usize) -> bool) -> (Vec<usize>, Vec<usize>) {
    let mut before = vec![usize::MAX; len];
    let mut after = vec![usize::MAX; len];
    let mut last = usize::MAX;
    for (i, b) in before.iter_mut().enumerate() {
        *b = last;
        if filled(i) {
            last = i;
        }
    }
    last = usize::MAX;
    for (i, a) in after.iter_mut().enumerate().rev() {
        *a = last;
        if filled(i) {
            last = i;
        }
    }
    (before, after)
}

/// The outline method: fills pixels enclosed by the warped region (module docs). Returns the
/// pixels filled.
fn fill_outline(
    depth: &mut [f32],
    src: &mut [u32],
    w: usize,
    h: usize,
    max_span: Option<u32>,
) -> u64 {
    let (d0, s0) = (depth.to_vec(), src.to_vec());
    let filled = |k: usize| d0[k].is_finite();
    let rows: Vec<(Vec<usize>, Vec<usize>)> = (0..h)
        .map(|y| bounds_along(w, |x| filled(y * w + x)))
        .collect();
    let cols: Vec<(Vec<usize>, Vec<usize>)> = (0..w)
        .map(|x| bounds_along(h, |y| filled(y * w + x)))
        .collect();
    let max_gap = max_span.map_or(usize::MAX, |m| m as usize);
    let mut count = 0;
    for (y, (before_x, after_x)) in rows.iter().enumerate() {
        for (x, (before_y, after_y)) in cols.iter().enumerate() {
            let k = y * w + x;
            if filled(k) {
                continue;
            }
            let (l, r) = (before_x[x], after_x[x]);
            let (u, d) = (before_y[y], after_y[y]);
            let none = usize::MAX;
            let row_gap = (l != none && r != none).then(|| r - l - 1);
            let col_gap = (u != none && d != none).then(|| d - u - 1);
            // Enclosed in both directions (the report's outline), or a short run in one.
            let ok = match (row_gap, col_gap) {
                (Some(a), Some(b)) => a.min(b) <= max_gap,
                (Some(g), None) | (None, Some(g)) => g <= SHORT_RUN,
                (None, None) => false,
            };
            if !ok {
                continue;
            }
            let value = if row_gap.unwrap_or(none) <= col_gap.unwrap_or(none) {
                let (a, b) = (y * w + l, y * w + r);
                between(
                    (d0[a], s0[a]),
                    (d0[b], s0[b]),
                    (x - l) as f64 / (r - l) as f64,
                )
            } else {
                let (a, b) = (u * w + x, d * w + x);
                between(
                    (d0[a], s0[a]),
                    (d0[b], s0[b]),
                    (y - u) as f64 / (d - u) as f64,
                )
            };
            depth[k] = value.0;
            src[k] = value.1;
            count += 1;
        }
    }
    count
}

/// The world-space direction of the ray through pixel position `p` of a view whose inverse
/// view-projection is `inv`.
fn ray_dir(view: &View, inv: &DMat4, p: DVec2) -> DVec3 {
    let ndc = view.pixel_to_ndc(p);
    let a = *inv * DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
    let b = *inv * DVec4::new(ndc.x, ndc.y, 0.5, 1.0);
    (b.truncate() / b.w - a.truncate() / a.w).normalize()
}

fn angle(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// The per-pixel error of the far pixels of `warped` (module docs, "Error"); NaN where `far` is
/// false or the pixel shows no texel.
pub fn error_px(rec: &CellRecording, view: &View, warped: &WarpedImage, far: &[bool]) -> Vec<f32> {
    let (w, h) = (view.width as usize, view.height as usize);
    let inv = view.view_proj().inverse();
    let eye = view.eye();
    let mut out = vec![f32::NAN; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, e) in row.iter_mut().enumerate() {
            let k = y * w + x;
            if !far[k] {
                continue;
            }
            let Some(t) = rec.texel_point(warped.shown[k]) else {
                continue;
            };
            let (fx, fy) = (x as f64, y as f64);
            let ray = ray_dir(view, &inv, DVec2::new(fx + 0.5, fy + 0.5));
            let horizontal = angle(
                ray_dir(view, &inv, DVec2::new(fx, fy + 0.5)),
                ray_dir(view, &inv, DVec2::new(fx + 1.0, fy + 0.5)),
            );
            let vertical = angle(
                ray_dir(view, &inv, DVec2::new(fx + 0.5, fy)),
                ray_dir(view, &inv, DVec2::new(fx + 0.5, fy + 1.0)),
            );
            let pixel = (horizontal * vertical).sqrt();
            if pixel > 0.0 {
                *e = (angle(ray, t - eye) / pixel) as f32;
            }
        }
    });
    out
}

/// The scene split by a near list into (near meshes, far meshes), each through
/// [`Scene::extract`] in scene order (a repeated entry counts once); an entry naming no triangle of
/// the scene is an error.
fn split_scene(scene: &Scene, near: &[[u32; 2]]) -> Result<(Vec<Mesh>, Vec<Mesh>), String> {
    let mut near_refs: Vec<TriRef> = near.iter().map(|&p| TriRef::from(p)).collect();
    near_refs.sort_unstable();
    near_refs.dedup();
    let near_meshes = scene
        .extract(&near_refs)
        .map_err(|e| format!("{e}; is it the scene the bundle was baked from?"))?;
    let far_refs: Vec<TriRef> = scene
        .meshes
        .iter()
        .enumerate()
        .flat_map(|(m, mesh)| {
            (0..mesh.triangle_count() as u32).map(move |tri| TriRef {
                mesh: m as u32,
                tri,
            })
        })
        .filter(|r| near_refs.binary_search(r).is_err())
        .collect();
    let far_meshes = scene.extract(&far_refs).map_err(|e| e.to_string())?;
    Ok((near_meshes, far_meshes))
}

fn mesh_bytes(meshes: &[Mesh]) -> u64 {
    meshes
        .iter()
        .map(|m| (m.vertices.len() * std::mem::size_of::<Vertex>() + 4 * m.indices.len()) as u64)
        .sum()
}

/// A cached cell: its recording and its near geometry on the GPU.
struct Cached {
    rec: CellRecording,
    near: GpuScene,
    near_list_len: u64,
    near_bytes: u64,
    lighting: Lighting,
    alpha_cutoff: f32,
}

impl Cached {
    fn bytes(&self) -> u64 {
        self.rec.bytes() + self.near_bytes
    }
}

/// Depth-image warping of the far field (module docs).
pub struct WarpStrategy {
    gpu: Arc<Gpu>,
    bundle: Bundle,
    scene: Arc<Scene>,
    materials: Arc<GpuMaterials>,
    options: WarpOptions,
    /// Draws frames (output size).
    renderer: Renderer,
    /// Records faces (recording size); a second renderer keeps both sizes' targets.
    recorder: Renderer,
    full: Option<GpuScene>,
    /// Most recently used first.
    cache: VecDeque<Cached>,
    /// Cells that could not be read (warned once).
    failed: HashSet<CellId>,
    pending_warnings: Vec<String>,
    last_options: Option<RenderOptions>,
    report: StrategyReport,
    recorded_bytes: u64,
}

impl WarpStrategy {
    /// The strategy over the bundle of `ctx` (its grid, near lists, faces and resolution).
    pub fn new(ctx: &StrategyContext, options: WarpOptions) -> Result<WarpStrategy, StrategyError> {
        options.validate()?;
        let res = ctx.bundle.manifest().params.resolution;
        if res == 0 || ctx.bundle.manifest().params.faces.is_empty() {
            return Err(StrategyError::Invalid(format!(
                "{}: the bundle has no faces or a zero resolution to record",
                ctx.bundle.dir().display()
            )));
        }
        let faces = ctx.bundle.manifest().params.faces.len() as u64;
        if faces * (res as u64) * (res as u64) > u32::MAX as u64 {
            return Err(StrategyError::Invalid(format!(
                "resolution {res} with {faces} faces is too large to warp"
            )));
        }
        Ok(WarpStrategy {
            gpu: ctx.gpu.clone(),
            bundle: ctx.bundle.clone(),
            scene: ctx.scene.clone(),
            materials: ctx.materials.clone(),
            options,
            renderer: Renderer::new(&ctx.gpu)?,
            recorder: Renderer::new(&ctx.gpu)?,
            full: None,
            cache: VecDeque::new(),
            failed: HashSet::new(),
            pending_warnings: Vec::new(),
            last_options: None,
            report: StrategyReport::default(),
            recorded_bytes: 0,
        })
    }

    /// Pixels per recorded face side (see [`WarpOptions::resolution`]).
    pub fn recording_resolution(&self) -> u32 {
        let p = &self.bundle.manifest().params;
        let matched = match (p.output_width, p.output_fov_deg) {
            (Some(w), Some(fov)) if w > 0 && fov > 0.0 && fov < 180.0 => {
                let per_tan = 0.5 * w as f64 / (0.5 * fov.to_radians()).tan();
                Some((2.0 * self.options.half_extent() * per_tan).ceil() as u32)
            }
            _ => None,
        };
        let max = self.gpu.limits().max_texture_dimension_2d.min(4096);
        self.options
            .resolution
            .or(matched)
            .unwrap_or(p.resolution)
            .clamp(8, max.max(8))
    }

    pub fn options(&self) -> &WarpOptions {
        &self.options
    }

    /// The recording of cell `id`, if cached.
    pub fn recording(&self, id: &str) -> Option<&CellRecording> {
        self.cache.iter().find(|c| c.rec.id == id).map(|c| &c.rec)
    }

    fn cache_bytes(&self) -> u64 {
        self.cache.iter().map(Cached::bytes).sum()
    }

    /// Uploads all geometry on first need (fallback frames).
    fn ensure_full(&mut self) -> Result<(), StrategyError> {
        if self.full.is_none() {
            let geometry =
                GpuGeometry::upload(&self.gpu, &self.scene.meshes, &UploadOptions::default())?;
            self.full = Some(GpuScene::from_parts(self.materials.clone(), geometry)?);
        }
        Ok(())
    }

    /// Reads and verifies cell `cell`'s file through the bundle's reader; `Ok(None)` when the cell
    /// was not baked.
    fn read_cell(&self, cell: &ViewCell) -> Result<Option<CellFile>, String> {
        let id = cell.id();
        if self.bundle.entry(id).is_none() {
            return Ok(None);
        }
        self.bundle
            .cell(id)
            .map(Some)
            .map_err(|e| format!("cell {id}: {e}; drawing all geometry"))
    }

    /// Makes sure cell `cell` is recorded with `options`' shading; returns its cache slot (moved
    /// to the front) and whether it was recorded now, or `None` when it cannot be (unbaked or
    /// damaged: the frame falls back).
    fn ensure(
        &mut self,
        cell: &ViewCell,
        options: &RenderOptions,
    ) -> Result<Option<bool>, StrategyError> {
        let id = cell.id();
        if let Some(pos) = self.cache.iter().position(|c| c.rec.id == id) {
            let c = &self.cache[pos];
            if c.lighting == options.lighting && c.alpha_cutoff == options.alpha_cutoff {
                let c = self.cache.remove(pos).expect("found above");
                self.cache.push_front(c);
                return Ok(Some(false));
            }
            self.cache.remove(pos);
        }
        if self.failed.contains(&id) {
            return Ok(None);
        }
        let t0 = Instant::now();
        let file = match self.read_cell(cell) {
            Ok(Some(f)) => f,
            Ok(None) => return Ok(None),
            Err(m) => {
                self.failed.insert(id);
                self.pending_warnings.push(m);
                return Ok(None);
            }
        };
        self.report.loads += 1;
        let (near_meshes, far_meshes) = match split_scene(&self.scene, &file.near) {
            Ok(s) => s,
            Err(m) => {
                self.pending_warnings
                    .push(format!("cell {id}: {m}; drawing all geometry"));
                self.failed.insert(id);
                return Ok(None);
            }
        };
        let rec = {
            let geometry = GpuGeometry::upload(&self.gpu, &far_meshes, &UploadOptions::default())?;
            drop(far_meshes);
            let far = GpuScene::from_parts(self.materials.clone(), geometry)?;
            let res = self.recording_resolution();
            let half_extent = self.options.half_extent();
            let record_options = RenderOptions {
                clear: [0; 4],
                ..*options
            };
            let mut faces = Vec::with_capacity(self.bundle.manifest().params.faces.len());
            for &face in &self.bundle.manifest().params.faces {
                let view = recording_view(cell.center, face, res, half_extent, DEFAULT_NEAR);
                let Frame { rgba, depth, .. } =
                    self.recorder.render(&far, &view, &record_options)?;
                faces.push(FaceRecording {
                    face,
                    view,
                    res,
                    rgba,
                    depth,
                });
            }
            CellRecording {
                id,
                center: cell.center,
                half_extent,
                faces,
            }
        };
        let near_bytes = mesh_bytes(&near_meshes);
        let geometry = GpuGeometry::upload(&self.gpu, &near_meshes, &UploadOptions::default())?;
        let near = GpuScene::from_parts(self.materials.clone(), geometry)?;
        self.report.prepare_seconds += t0.elapsed().as_secs_f64();
        self.report.prepared_cells += 1;
        self.recorded_bytes += rec.bytes();
        self.cache.push_front(Cached {
            rec,
            near,
            near_list_len: file.near.len() as u64,
            near_bytes,
            lighting: options.lighting,
            alpha_cutoff: options.alpha_cutoff,
        });
        while self.cache.len() > self.options.cache_cells {
            self.cache.pop_back();
            self.report.evictions += 1;
        }
        self.report.peak_bytes = self.report.peak_bytes.max(self.cache_bytes());
        Ok(Some(true))
    }

    fn fallback_frame(
        &mut self,
        r: &FrameRequest<'_>,
        cell: Option<CellId>,
        warnings: Vec<String>,
    ) -> Result<StrategyFrame, StrategyError> {
        let triangles = self.scene.triangle_count();
        self.ensure_full()?;
        let full = self.full.as_ref().expect("uploaded above");
        let frame = self.renderer.render(full, r.view, r.options)?;
        let n = frame.depth.len();
        Ok(StrategyFrame {
            frame: Some(frame),
            cell,
            near_triangles: triangles,
            far_primitives: 0,
            stalled: false,
            fallback: true,
            cache_bytes: self.cache_bytes(),
            regenerations: 0,
            gpu_ms: None,
            warnings,
            error_px: r.measure_error.then(|| vec![f32::NAN; n]),
        })
    }
}

impl Strategy for WarpStrategy {
    fn kind(&self) -> StrategyKind {
        StrategyKind::Warp
    }

    /// Records the cell containing `eye` (synchronously; `velocity` and `timeout` are not used),
    /// with the shading of the last frame, or the default one before any frame.
    fn preload(
        &mut self,
        eye: DVec3,
        _velocity: DVec3,
        _timeout: Duration,
    ) -> Result<(), StrategyError> {
        if let Some(cell) = self.bundle.manifest().grid.locate(eye) {
            let options = self.last_options.unwrap_or_default();
            self.ensure(&cell, &options)?;
        }
        Ok(())
    }

    fn frame(&mut self, r: &FrameRequest<'_>) -> Result<StrategyFrame, StrategyError> {
        self.last_options = Some(*r.options);
        let located = self.bundle.manifest().grid.locate(r.eye);
        let cell_id = located.as_ref().map(|c| c.id());
        let recorded_now = match &located {
            Some(cell) => self.ensure(cell, r.options)?,
            None => None,
        };
        let warnings = std::mem::take(&mut self.pending_warnings);
        let Some(recorded_now) = recorded_now else {
            return self.fallback_frame(r, cell_id, warnings);
        };
        if recorded_now {
            self.report.stalls += 1;
            self.report.regenerations += 1;
        }
        let cached = self.cache.front().expect("ensured above");
        let mut frame = self.renderer.render(&cached.near, r.view, r.options)?;
        let warped = warp(
            &cached.rec,
            r.view,
            self.options.hole_filling,
            self.options.max_outline_span,
            Some(&frame.depth),
        );
        let n = frame.depth.len();
        let mut far = vec![false; n];
        for (k, is_far) in far.iter_mut().enumerate() {
            if warped.shown[k] != u32::MAX && warped.depth[k] < frame.depth[k] {
                frame.depth[k] = warped.depth[k];
                frame.rgba[4 * k..4 * k + 4].copy_from_slice(&warped.rgba[4 * k..4 * k + 4]);
                *is_far = true;
            }
        }
        let error_px = r
            .measure_error
            .then(|| error_px(&cached.rec, r.view, &warped, &far));
        Ok(StrategyFrame {
            frame: Some(frame),
            cell: cell_id,
            near_triangles: cached.near_list_len,
            far_primitives: warped.forward_mapped,
            stalled: recorded_now,
            fallback: false,
            cache_bytes: self.cache_bytes(),
            regenerations: recorded_now as u64,
            gpu_ms: None,
            warnings,
            error_px,
        })
    }

    /// Totals. `regenerations` and `stalls`: far fields recorded during frames (a frame waits for
    /// its recording); `loads`: cell files read; `texture_bytes_per_cell`: the recorded colour and
    /// depth of one cell, what a GPU implementation would hold as textures.
    fn report(&self) -> StrategyReport {
        StrategyReport {
            texture_bytes_per_cell: if self.report.prepared_cells > 0 {
                self.recorded_bytes as f64 / self.report.prepared_cells as f64
            } else {
                0.0
            },
            ..self.report.clone()
        }
    }
}
