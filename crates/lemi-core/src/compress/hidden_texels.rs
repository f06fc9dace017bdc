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

use rayon::prelude::*;

use super::layer_image::{all3x3_in, common_res, LayerImage, OPAQUE_ALPHA, TRANSPARENT};
use super::CompressError;
use super::TexelRect;

/// Parameters of hidden-texel removal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HiddenTexelOptions {
    /// Let clip-border texels of the closer layer occlude (the paper's rule read literally with only
    /// image-space border texels). Default `false`: they do not.
    pub clip_border_occludes: bool,
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

/// Hidden-texel removal (GI 2002 sec. 5.2) over one face's layers, ordered **nearest first**.
/// Hidden texels become fully transparent.
pub fn remove_hidden_texels(
    layers: &mut [LayerImage],
    options: &HiddenTexelOptions,
) -> Result<HiddenTexelStats, CompressError> {
    let Some(res) = common_res(layers)? else {
        return Ok(HiddenTexelStats::default());
    };
    let mut stats = HiddenTexelStats {
        removed_per_layer: vec![0; layers.len()],
        ..Default::default()
    };
    stats.opaque_before = layers.par_iter().map(|l| l.opaque_count()).sum();
    let n = layers[0].texel_count();
    let mut hidden = vec![false; n]; // the nearest layer is never hidden
                                     // every hidden texel lies within this rectangle: the union of the nearer layers' content
    let mut hidden_rect = TexelRect::empty();
    let count = layers.len();
    for (k, layer) in layers.iter_mut().enumerate() {
        let next = if k + 1 < count {
            // texels of layer k that occlude: hidden (interpreted as opaque) or opaque; none
            // outside the nearer layers' content and this layer's
            let region = hidden_rect.union(&layer.content);
            let mut cover = vec![false; n];
            for i in region.rows(res).flatten() {
                cover[i] = hidden[i]
                    || (layer.rgba[4 * i + 3] >= OPAQUE_ALPHA
                        && (options.clip_border_occludes || !layer.border[i]));
            }
            Some((all3x3_in(&cover, res, false, &region), region))
        } else {
            None
        };
        // erase layer k's hidden texels before going on to the next pair
        for i in hidden_rect.rows(res).flatten() {
            if hidden[i] {
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
        if let Some((h, region)) = next {
            hidden = h;
            hidden_rect = region;
        }
    }
    stats.opaque_after = stats.opaque_before - stats.removed;
    Ok(stats)
}
