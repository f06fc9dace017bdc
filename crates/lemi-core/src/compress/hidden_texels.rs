//! Hidden-texel removal: erases the texels of a layer that no viewpoint in the cell can see.
//!
//! This work is based on: GI 2002 sec. 5.2 (Jeschke, Wimmer et al.). From any viewpoint in the view
//! cell a texel of layer `k+1` moves by at most one texel against layer `k` (one-texel spacing,
//! sec. 4.2 eq. 2), so it is always hidden when the texel of layer `k` at the same position is
//! opaque and not a border texel, i.e. its whole 3×3 neighbourhood is opaque. The paper repeats, for
//! each pair of adjacent layers from the nearest outwards:
//!
//! > Mark texels in the more distant layer as hidden if they are behind opaque texels of the closer
//! > layer which are not border texels. If texels in the closer layer were already marked as hidden
//! > in the previous iteration, they must be interpreted as opaque in this iteration and set as
//! > transparent before proceeding to the next pair of layers.
//!
//! So with `cover_k = hidden_k ∪ opaque_k`, `hidden_{k+1} = {p : cover_k ⊇ 3×3(p)}`; transparent
//! texels can be marked hidden too, which carries occlusion through several layers (the shifts add
//! up: a texel two layers behind an opaque region two texels deep is hidden).
//!
//! Choices made here:
//! - neighbours outside the face image never occlude (the adjacent face is not known here), so a
//!   one-texel frame along the image edge is always kept;
//! - a texel on a polygon's clipping edge (TR sec. 2.2, [`LayerImage::border`]) is only partly
//!   covered by the closer layer; by default it does not occlude
//!   ([`HiddenTexelOptions::clip_border_occludes`] = `false`), a conservative addition to the paper.
//!
//! **The shift the cell allows, not one texel a pair** ([`remove_hidden_texels_in_cell`]). The
//! paper's rule assumes that adjacent layers move by one texel against each other, which is what
//! layers bound by the one-texel spacing do. Layers bound by the parallax α move less (at the
//! paper's settings, a third to a half of a texel), and a layering not placed by the metric
//! (equidistant layers) may move more. [`TexelShift`] gives the largest movement of a texel of
//! the layer at `F` against the layer at `N < F` from anywhere in the cell (the derivation of GI
//! 2002 eq. 2, per texel): from a viewpoint `a` along the face axis and `w` across it, a point at
//! face coordinate `c` of the far layer lands at `c + (F − N)(w − c·a) / (N(F − a))` on the near
//! one, so the movement in texels is at most
//!
//! ```text
//! T(N, F; c) = Res/2 · (F − N)/(N(F − s)) · (q + |c|·s)
//! ```
//!
//! per image axis (`s` the cell's half extent along the face axis, `q` across it along that image
//! axis; `c` the texel's edge farthest from the image centre). A texel is then hidden when every
//! texel within `⌈T⌉` of it along each axis is covered, and the cover chains through the layers
//! with the movements summed instead of rounded up pair by pair. Write `T = K(N, F)·w(c)` with
//! `K = Res/2 · (F − N)/(N(F − s))` and the per-axis weight `w = q + |c|·s` of the texel. With
//! `U_k` the texels of layer `k` that occlude (opaque or hidden) and `M_k(p)` the largest margin
//! `μ` such that the box of `⌈μ·w_x⌉ × ⌈μ·w_y⌉` texels around `p` lies in `U_k`, the margin
//!
//! ```text
//! μ_k(p) = max(M_k(p), μ_{k−1}(p) − K(k−1, k)),   texel p of layer k+1 hidden ⇔ μ_k(p) ≥ K(k, k+1)
//! ```
//!
//! is safe because `K` is subadditive along a chain of layers (`K(a, b) + K(b, c) ≥ K(a, c)`:
//! `F/(F − s)` falls with `F`). The boxes follow the movement's own shape: a cell 1 m high and
//! 10 m wide moves texels near the horizon a tenth as much up and down as sideways. With
//! `K ≡ w ≡ 1` it is the paper's rule exactly (a margin of two or more texels at `k−1` leaves a
//! whole 3×3 block hidden at `k`), so [`remove_hidden_texels`] is that case. The brute-force test
//! traces rays from viewpoints all over the cell to every removed texel.

use rayon::prelude::*;

use glam::DVec3;

use super::layer_image::{common_res, LayerImage, FULL_ALPHA, TRANSPARENT};
use super::CompressError;
use super::TexelRect;
use crate::face::Face;

/// Parameters of hidden-texel removal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HiddenTexelOptions {
    /// Let clip-border texels of the closer layer occlude (the paper's rule read literally with only
    /// image-space border texels). Default `false`: they do not.
    pub clip_border_occludes: bool,
    /// Half extents (x, y, z) of the view cell the layers were recorded for. With them a cell's
    /// compression removes what the movement between its layers allows
    /// ([`remove_hidden_texels_in_cell`]); without them, what the paper's one texel per pair of
    /// layers allows ([`remove_hidden_texels`]).
    pub cell_half: Option<DVec3>,
}

/// The largest movement of a face's texels between two layers, seen from anywhere in a box-shaped
/// view cell (see the module docs): `T(N, F; c) = Res/2 · (F − N)/(N(F − s)) · (q + |c|·s)` per
/// image axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelShift {
    /// Texels per side of the face image.
    pub res: u32,
    /// The cell's half extent along the face axis (`s`).
    pub along: f64,
    /// The cell's half extents across the face along the image's `s` (column) and `t` (row)
    /// axes (`q` of each axis).
    pub across: [f64; 2],
}

impl TexelShift {
    /// For face `face` of a box cell with half extents `half` (x, y, z) and `res`-texel images.
    pub fn of_face(face: Face, half: DVec3, res: u32) -> TexelShift {
        let extent = |axis: DVec3| axis.abs().dot(half);
        TexelShift {
            res,
            along: extent(face.forward()),
            across: [extent(face.right()), extent(face.down())],
        }
    }

    /// `Res/2 · (F − N)/(N(F − s))`, the factor of `(q + |c|·s)`: infinite when the far layer
    /// does not lie beyond the cell (`F ≤ s`) or the distances are not `0 < N < F`.
    pub fn factor(&self, near: f64, far: f64) -> f64 {
        if !(near > 0.0 && far > near && far > self.along) {
            return f64::INFINITY;
        }
        f64::from(self.res) / 2.0 * (far - near) / (near * (far - self.along))
    }

    /// `q + |c|·s` of every column (axis 0) or row (axis 1), `c` the texel's edge farthest from
    /// the image centre.
    fn weights(&self, axis: usize) -> Vec<f64> {
        (0..self.res)
            .map(|i| self.shift_weights(i, i)[axis])
            .collect()
    }

    /// The largest movement in texels of texel `(x, y)` of the layer at `far` against the layer at
    /// `near`, seen from anywhere in the cell, along the image's x and y axes.
    pub fn shift(&self, near: f64, far: f64, x: u32, y: u32) -> [f64; 2] {
        let k = self.factor(near, far);
        self.shift_weights(x, y).map(|w| k * w)
    }

    /// `q + |c|·s` of texel `(x, y)` along x and y, `c` its edge farthest from the image centre.
    fn shift_weights(&self, x: u32, y: u32) -> [f64; 2] {
        let edge = |i: u32| {
            Face::texel_edge(f64::from(i), self.res)
                .abs()
                .max(Face::texel_edge(f64::from(i + 1), self.res).abs())
        };
        [
            self.across[0] + edge(x) * self.along,
            self.across[1] + edge(y) * self.along,
        ]
    }
}

/// What hidden-texel removal did to one face's layer stack.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct HiddenTexelStats {
    /// Opaque texels before removal (all layers).
    pub opaque_before: u64,
    /// Opaque texels after removal.
    pub opaque_after: u64,
    /// Opaque texels made transparent.
    pub removed: u64,
    /// Texels marked hidden, transparent ones included.
    pub marked: u64,
    /// Opaque texels removed per layer (nearest first; in the caller's order in
    /// [`super::compress_cell`]).
    pub removed_per_layer: Vec<u64>,
}

impl HiddenTexelStats {
    /// Sums two statistics (per-layer counts are added position by position).
    pub fn add(&mut self, o: &HiddenTexelStats) {
        self.opaque_before += o.opaque_before;
        self.opaque_after += o.opaque_after;
        self.removed += o.removed;
        self.marked += o.marked;
        if self.removed_per_layer.len() < o.removed_per_layer.len() {
            self.removed_per_layer.resize(o.removed_per_layer.len(), 0);
        }
        for (a, b) in self.removed_per_layer.iter_mut().zip(&o.removed_per_layer) {
            *a += b;
        }
    }
}

/// Hidden-texel removal (GI 2002 sec. 5.2) over one face's layers, ordered **nearest first**,
/// with the paper's one texel of movement between adjacent layers. Hidden texels become fully
/// transparent.
pub fn remove_hidden_texels(
    layers: &mut [LayerImage],
    options: &HiddenTexelOptions,
) -> Result<HiddenTexelStats, CompressError> {
    let Some(res) = common_res(layers)? else {
        return Ok(HiddenTexelStats::default());
    };
    let ones = vec![1.0; res as usize];
    let factors = vec![1.0; layers.len().saturating_sub(1)];
    remove(layers, &factors, [&ones, &ones], options)
}

/// Hidden-texel removal over one face's layers, ordered **nearest first** at `distances` from the
/// reference viewpoint, with the movement between layers the cell allows ([`TexelShift`]; see the
/// module docs): removes at least what [`remove_hidden_texels`] removes wherever adjacent layers
/// move by at most one texel, more where they move less, and stays safe where they move more.
pub fn remove_hidden_texels_in_cell(
    layers: &mut [LayerImage],
    distances: &[f64],
    shift: &TexelShift,
    options: &HiddenTexelOptions,
) -> Result<HiddenTexelStats, CompressError> {
    let Some(res) = common_res(layers)? else {
        return Ok(HiddenTexelStats::default());
    };
    if distances.len() != layers.len() || res != shift.res {
        return Err(CompressError::Invalid(format!(
            "hidden-texel removal: {} layers of {res}² texels, but {} distances and a shift for \
             {}² texels",
            layers.len(),
            distances.len(),
            shift.res
        )));
    }
    let factors: Vec<f64> = distances
        .windows(2)
        .map(|w| shift.factor(w[0], w[1]))
        .collect();
    let (wx, wy) = (shift.weights(0), shift.weights(1));
    remove(layers, &factors, [&wx, &wy], options)
}

/// The removal with movement at most `factors[k] · weights[0][x]` texels along x and
/// `factors[k] · weights[1][y]` along y between layers `k` and `k + 1` (see the module docs).
fn remove(
    layers: &mut [LayerImage],
    factors: &[f64],
    weights: [&[f64]; 2],
    options: &HiddenTexelOptions,
) -> Result<HiddenTexelStats, CompressError> {
    let Some(res) = common_res(layers)? else {
        return Ok(HiddenTexelStats::default());
    };
    let r = res as usize;
    let mut stats = HiddenTexelStats {
        removed_per_layer: vec![0; layers.len()],
        ..Default::default()
    };
    stats.opaque_before = layers.par_iter().map(|l| l.opaque_count()).sum();
    // no margin beyond what all the movements together can use needs measuring
    let total: f64 = factors.iter().filter(|f| f.is_finite()).sum();
    let widest = weights[0]
        .iter()
        .chain(weights[1])
        .fold(0.0f64, |a, &w| a.max(w));
    let cap = (total * widest).ceil().min(f64::from(res)) as i32 + 1;
    let n = layers[0].texel_count();
    // the margin μ of the layers so far (negative: not covered); every covered texel lies in
    // `g_rect`
    let mut g = vec![-1.0f64; n];
    // the margins of the layer after, written inside its region only; -1 elsewhere (two
    // buffers of `n` for the whole face, not one per layer: at 2048² a layer's margins are
    // 32 MB, which the system would otherwise zero 255 times a face)
    let mut next = vec![-1.0f64; n];
    let (mut d, mut half_run) = (Vec::new(), Vec::new());
    let mut g_rect = TexelRect::empty();
    let mut hidden = vec![false; n];
    let count = layers.len();
    for (k, layer) in layers.iter_mut().enumerate() {
        // layer k's hidden texels: μ_{k−1} ≥ K(k−1, k)
        let mut hidden_rect = TexelRect::empty();
        if k > 0 {
            let step = factors[k - 1];
            for row in g_rect.rows(res) {
                for i in row {
                    let h = g[i] >= 0.0 && g[i] >= step;
                    hidden[i] = h;
                    if h {
                        let (x, y) = ((i % r) as u32, (i / r) as u32);
                        hidden_rect = hidden_rect.union(&TexelRect {
                            x0: x,
                            y0: y,
                            x1: x + 1,
                            y1: y + 1,
                        });
                        stats.marked += 1;
                        if layer.is_opaque(i) {
                            stats.removed += 1;
                            stats.removed_per_layer[k] += 1;
                        }
                        // already empty texels are left alone (their pages need not be written)
                        if layer.texel(i) != TRANSPARENT || layer.border[i] || layer.far_border[i] {
                            layer.clear_texel(i);
                        }
                    }
                }
            }
        }
        if k + 1 == count {
            break;
        }
        // U_k: hidden, or opaque (and not a clip-border texel unless those occlude); its margin
        let region = hidden_rect.union(&layer.content);
        box_margin(
            &region,
            r,
            weights,
            cap,
            |i| {
                hidden[i]
                    || (layer.rgba[4 * i + 3] >= FULL_ALPHA
                        && (options.clip_border_occludes || !layer.border[i]))
            },
            &mut half_run,
            &mut d,
        );
        let w = region.width() as usize;
        let step = if k > 0 { factors[k - 1] } else { 0.0 };
        for (y, row) in region.rows(res).enumerate() {
            for (x, i) in row.enumerate() {
                let carried = if k > 0 && g[i] >= 0.0 {
                    g[i] - step
                } else {
                    -1.0
                };
                next[i] = d[y * w + x].max(carried);
            }
        }
        // hidden marks of layer k are done with, and so are the margins μ_{k−1}: clear both
        // inside the old rectangle (where alone they were set), so that `g` is −1 outside its
        // rectangle once it becomes `next`
        for row in g_rect.rows(res) {
            for i in row {
                hidden[i] = false;
                g[i] = -1.0;
            }
        }
        std::mem::swap(&mut g, &mut next);
        g_rect = region;
    }
    stats.opaque_after = stats.opaque_before - stats.removed;
    Ok(stats)
}

/// Over `rect` (row-major, `rect.width()` a row): for texels in the set `member`, the margin
/// `μ = max over b of min(M_b / w_x, b / w_y)`, where `M_b` is the largest `a` such that the
/// texels `[x − a, x + a] × [y − b, y + b]` all lie in the set, and `w_x = weights[0][x]`,
/// `w_y = weights[1][y]` (image coordinates): a movement of up to `μ·w_x` texels along x and
/// `μ·w_y` along y stays inside the set. `-1` outside the set; texels outside `rect` or the
/// image are not in it; `M_b` is counted up to `cap`.
/// The result goes to `out` (`rect.width() × rect.height()`, row-major); `half_run` is scratch.
/// Both keep their memory from one call to the next: at 2048² a layer's margins are up to 32 MB,
/// which fresh allocations would make the system zero again for every layer.
fn box_margin(
    rect: &TexelRect,
    r: usize,
    weights: [&[f64]; 2],
    cap: i32,
    member: impl Fn(usize) -> bool + Sync,
    half_run: &mut Vec<i32>,
    out: &mut Vec<f64>,
) {
    out.clear();
    if rect.is_empty() {
        return;
    }
    let (w, h) = (rect.width() as usize, rect.height() as usize);
    let (x0, y0) = (rect.x0 as usize, rect.y0 as usize);
    // the horizontal half-run of every texel: the largest a with [x − a, x + a] in the set
    // (−1 outside it), from the runs to the left and to the right (every entry is written)
    half_run.clear();
    half_run.resize(w * h, -1);
    half_run.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let mut run = vec![0i32; w];
        let mut left = 0;
        for (x, run) in run.iter_mut().enumerate() {
            left = if member((y0 + y) * r + x0 + x) {
                (left + 1).min(cap + 1)
            } else {
                0
            };
            *run = left;
        }
        let mut right = 0;
        for x in (0..w).rev() {
            right = if run[x] > 0 {
                (right + 1).min(cap + 1)
            } else {
                0
            };
            row[x] = run[x].min(right) - 1;
        }
    });
    // rows are independent: in parallel (a face's layers are a chain, so this is where the
    // second core helps)
    out.resize(w * h, -1.0);
    let half_run = &*half_run;
    out.par_chunks_mut(w).enumerate().for_each(|(y, out_row)| {
        let wy = weights[1][y0 + y];
        for x in 0..w {
            let m0 = half_run[y * w + x];
            if m0 < 0 {
                continue;
            }
            let wx = weights[0][x0 + x];
            let mut m = m0;
            let mut best = 0.0f64;
            let mut b = 0usize;
            loop {
                let by_x = f64::from(m) / wx;
                let by_y = b as f64 / wy;
                best = best.max(by_x.min(by_y));
                if by_y >= by_x {
                    break;
                }
                b += 1;
                if b > y || y + b >= h {
                    break;
                }
                m = m
                    .min(half_run[(y - b) * w + x])
                    .min(half_run[(y + b) * w + x]);
                if m < 0 {
                    break;
                }
            }
            out_row[x] = best;
        }
    });
}
