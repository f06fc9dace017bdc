//! Gap filling: closes the one-texel holes that open between a surface's parts in adjacent layers.
//!
//! This work is based on: GI 2002 sec. 5.1 (Jeschke, Wimmer et al., *Layered Environment-Map
//! Impostors for Arbitrary Scenes*). A continuous surface split between a closer layer and the next
//! more distant one can open a one-texel gap when the viewer moves, because adjacent layers shift by
//! up to one texel against each other (sec. 4.2, eq. 2). The paper closes it by
//!
//! > copying opaque texels that have at least one transparent neighbor (opaque border texels) of
//! > the current (closer) layer to texels at the same position in the next (more distant) layer,
//! > that are either opaque texels or transparent border texels (transparent texels that have at
//! > least one opaque neighbor).
//!
//! **Which texels are copied** ([`GapSources`]). Read literally, the rule copies *every* opaque
//! border texel, including the silhouettes of objects that end inside the closer slab: such a
//! texel is then also drawn one layer farther back, where it shows a point of slab `k` on layer
//! `k+1`'s plane, up to about three times α off (measured by the certificate), and fattens the
//! silhouette by the layers' relative shift. A gap, though, opens only where a surface continues
//! across the border between the two slabs, i.e. along the clipping edges on that border (TR sec.
//! 2.2). So by default ([`GapSources::FarClipEdges`]) only the opaque border texels that lie on a
//! clipping edge of the closer layer's *far* border ([`LayerImage::far_border`]) are copied: their
//! surface reaches the border plane, the near end of the more distant slab, whose points the
//! placement keeps within α of layer `k+1`. Both layers normally cover every texel a cut passes
//! through already (the recorder covers cuts conservatively), so this rule only *fills*: it copies
//! a cut's texel where the more distant layer lacks it, and leaves the more distant layer's own
//! texels as recorded (the paper overwrites them with the closer layer's colour, a sample of the
//! closer slab that can be far from the border on a grazing surface). [`GapSources::AllBorder`]
//! is the paper's rule as written, kept for comparison.
//!
//! Choices the paper leaves open, made here:
//! - *neighbour* means the 8-neighbourhood (the shift between layers can be diagonal); neighbours
//!   outside the face image are ignored (the surface may continue on the adjacent face);
//! - every pair `(k, k+1)` is evaluated on the images as they were *before* gap filling, so a
//!   copied texel is never copied on into a third layer, and the pairs are independent (parallel).
//!
//! The whole RGBA value (alpha included) is copied; clip-border flags are left as recorded.
//!
//! With the 8-neighbourhood this also performs the 2×2 diagonal fix of TR-186-2-02-04 sec. 2.2
//! (an 8-connected clipping line recorded in both layers leaves, in each 2×2 block, one texel only
//! in the closer and one only in the more distant layer; the closer one is an opaque border texel
//! next to the distant layer's line, so it is copied and the line becomes four-connected).

use rayon::prelude::*;

use super::layer_image::{all3x3_in, any3x3_in, common_res, LayerImage};
use super::CompressError;
use super::TexelRect;

/// Which opaque border texels of the closer layer gap filling copies (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GapSources {
    /// Those on a clipping edge of the closer layer's far border (the default).
    #[default]
    FarClipEdges,
    /// All of them, silhouettes included (GI 2002 sec. 5.1 read literally).
    AllBorder,
}

/// What gap filling did to one face's layer stack.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GapFillStats {
    /// Adjacent layer pairs processed.
    pub pairs: u64,
    /// Opaque border texels of the closer layers that [`GapSources`] selects (the candidate
    /// sources).
    pub source_texels: u64,
    /// Copies into transparent border texels (new opaque texels).
    pub filled: u64,
    /// Copies onto opaque texels (colour replaced by the closer layer's).
    pub overwritten: u64,
    /// Texels added by [`copy_outlines`] (a separate stage, counted here).
    pub outline_copies: u64,
}

impl GapFillStats {
    /// Sums two statistics.
    pub fn add(&mut self, o: &GapFillStats) {
        self.pairs += o.pairs;
        self.source_texels += o.source_texels;
        self.filled += o.filled;
        self.overwritten += o.overwritten;
        self.outline_copies += o.outline_copies;
    }
}

/// Texels to write into a layer: linear index and colour.
type Writes = Vec<(usize, [u8; 4])>;

/// Per-layer masks of sec. 5.1.
struct Masks {
    /// Opaque texels with at least one transparent (in-image) 8-neighbour.
    opaque_border: Vec<bool>,
    /// Opaque texels, or transparent texels with at least one opaque 8-neighbour: where a copy may go.
    target: Vec<bool>,
    /// Opaque texels.
    opaque: Vec<bool>,
}

fn masks(layer: &LayerImage) -> Masks {
    let opaque = layer.opaque_mask();
    // (computed within the layer's content, and one texel around it for the neighbours)
    // all 8 in-image neighbours opaque (outside counts as opaque, i.e. is ignored)
    let interior = all3x3_in(&opaque, layer.res, true, &layer.content);
    // some in-image neighbour opaque (outside counts as transparent, i.e. is ignored)
    let near_opaque = any3x3_in(
        &opaque,
        layer.res,
        false,
        &layer.content.grown(1, layer.res),
    );
    let mut opaque_border = vec![false; opaque.len()];
    for i in layer.content_rows().flatten() {
        opaque_border[i] = opaque[i] && !interior[i];
    }
    let target = near_opaque; // opaque ⇒ near_opaque; transparent ∧ near_opaque = transparent border
    Masks {
        opaque_border,
        target,
        opaque,
    }
}

/// What gap filling writes into one face's layer stack: per adjacent pair `(k, k+1)` (nearest
/// first), the texels of layer `k+1` it sets (linear index) and the colour of layer `k` they
/// take, plus the statistics. [`fill_gaps`] applies it; tests use it to check every copied texel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GapFillPlan {
    /// `writes[k]`: the texels written into layer `k + 1`.
    pub writes: Vec<Vec<(usize, [u8; 4])>>,
    pub stats: GapFillStats,
}

/// Plans gap filling (GI 2002 sec. 5.1, sources chosen by `sources`) over one face's layers,
/// ordered **nearest first** (`layers[0]` is closest to the view cell), without changing them.
pub fn plan_gap_fill(
    layers: &[LayerImage],
    sources: GapSources,
) -> Result<GapFillPlan, CompressError> {
    if common_res(layers)?.is_none() || layers.len() < 2 {
        return Ok(GapFillPlan::default());
    }
    let all_masks: Vec<Masks> = layers.par_iter().map(masks).collect();
    // writes into layer k+1 from the original layer k
    let writes: Vec<(Writes, GapFillStats)> = (0..layers.len() - 1)
        .into_par_iter()
        .map(|k| {
            let (src, dst) = (&all_masks[k], &all_masks[k + 1]);
            let mut stats = GapFillStats {
                pairs: 1,
                ..Default::default()
            };
            let mut w = Vec::new();
            let far_border = &layers[k].far_border;
            for i in layers[k].content_rows().flatten() {
                let b = src.opaque_border[i];
                if !b || (sources == GapSources::FarClipEdges && !far_border[i]) {
                    continue;
                }
                stats.source_texels += 1;
                // the paper also overwrites opaque targets; along a cut both layers already
                // cover the texel, and the more distant layer's own sample is the one within α
                if dst.target[i] && !(sources == GapSources::FarClipEdges && dst.opaque[i]) {
                    if dst.opaque[i] {
                        stats.overwritten += 1;
                    } else {
                        stats.filled += 1;
                    }
                    w.push((i, layers[k].texel(i)));
                }
            }
            (w, stats)
        })
        .collect();
    let mut plan = GapFillPlan::default();
    for (w, s) in writes {
        plan.stats.add(&s);
        plan.writes.push(w);
    }
    Ok(plan)
}

/// Gap filling (GI 2002 sec. 5.1) over one face's layers, ordered **nearest first**
/// (`layers[0]` is closest to the view cell). Modifies the more distant layer of every pair.
pub fn fill_gaps(
    layers: &mut [LayerImage],
    sources: GapSources,
) -> Result<GapFillStats, CompressError> {
    let plan = plan_gap_fill(layers, sources)?;
    if plan.writes.is_empty() {
        return Ok(plan.stats);
    }
    let sources: Vec<TexelRect> = layers.iter().map(|l| l.content).collect();
    layers[1..]
        .par_iter_mut()
        .zip(plan.writes.par_iter().zip(&sources))
        .for_each(|(layer, (w, src))| {
            if !w.is_empty() {
                // the copies lie within the closer layer's content
                layer.include(src);
            }
            for &(i, rgba) in w {
                layer.set_texel(i, rgba);
            }
        });
    Ok(plan.stats)
}

/// Closes the seam between the near geometry and the innermost layer: the near geometry is drawn
/// exactly, the innermost layer with up to α of parallax, so a surface crossing the near-field
/// border can open a gap of up to a pixel between them (found by the no-crack test). Gap filling
/// (GI 2002 sec. 5.1) closes such gaps between two layers; here the near field plays the closer
/// layer: every transparent texel of the innermost layer that touches one of its opaque texels
/// (8-neighbourhood) and where the near geometry just inside the border (recorded into `near`, the
/// same face projection) is opaque takes the near geometry's colour. The added texels are flagged
/// as clip-border texels, so they never hide farther layers. Returns the number of texels added.
pub fn close_near_seam(inner: &mut LayerImage, near: &[u8]) -> u64 {
    if near.len() != inner.rgba.len() {
        return 0;
    }
    let opaque = inner.opaque_mask();
    let around = inner.content.grown(1, inner.res);
    let touches = any3x3_in(&opaque, inner.res, false, &around);
    inner.include(&around);
    let mut added = 0;
    for i in inner.content_rows().flatten() {
        if !opaque[i] && touches[i] && near[4 * i + 3] >= 128 {
            let c = [near[4 * i], near[4 * i + 1], near[4 * i + 2], 255];
            inner.set_texel(i, c);
            inner.border[i] = true;
            added += 1;
        }
    }
    added
}

/// Outline copies: the strips that parallax uncovers beside an outline, closed from the side
/// where they open.
///
/// Conservative recording grows every outline by up to a texel, which covers the strip that an
/// outline, moved by the parallax the placement allows (up to α), uncovers beside it, but not
/// always: a sub-texel feature, or an outline whose point lies far from its layer's plane, can
/// still uncover a pixel of background or of a farther layer ("crack pixels" of the
/// certificate, a few per `builtin:city:1M` cell at 2048²). This stage copies every outline
/// texel of a layer (opaque, with a transparent 8-neighbour) into the same texel of *one*
/// adjacent layer, where that layer is transparent, flagged as a clip-border texel (it hides
/// nothing):
/// - into the **farther** layer when the texel's recorded point lies behind its layer's plane
///   ([`LayerImage::behind_plane`]): drawn on the plane, the point moves with the viewer less
///   than it should, so its outline uncovers the strip beside it towards which the farther layer
///   moves; the copy on the farther layer moves further, into that strip;
/// - into the **nearer** layer when the point lies in front of (or on) its plane: there the
///   outline moves too far and the nearer layer's copy covers the strip it leaves.
///
/// From the reference viewpoint a copy lies exactly behind or in front of its source and is not
/// seen; from elsewhere it shows beside the source by the two layers' relative shift, which is
/// at least the point's own parallax against its layer. Its error is at most that shift: 2α
/// where the placement bounds both layers by α (the bound test in `lemi-bake/tests/no_cracks.rs`).
///
/// `layers` nearest first, after gap filling (whose texels are not recorded, so
/// [`LayerImage::behind_plane`] is `false` for them: a gap-filled texel is copied towards the
/// nearer layer it came from, where it is opaque, so it adds nothing). A layer without
/// behind-plane flags sends no copies. Outlines are those of the layers as they come in (a copy
/// is never copied on). Returns the number of texels added.
pub fn copy_outlines(layers: &mut [LayerImage]) -> Result<u64, CompressError> {
    if common_res(layers)?.is_none() || layers.len() < 2 {
        return Ok(0);
    }
    // per layer: its outline texels as (index, colour, into the farther layer)
    let outlines: Vec<Vec<(usize, [u8; 4], bool)>> = layers
        .par_iter()
        .map(|l| {
            if l.behind_plane.is_empty() {
                return Vec::new();
            }
            let opaque = l.opaque_mask();
            let inner = all3x3_in(&opaque, l.res, true, &l.content);
            l.content_rows()
                .flatten()
                .filter(|&i| opaque[i] && !inner[i])
                .map(|i| (i, l.texel(i), l.behind_plane[i]))
                .collect()
        })
        .collect();
    let contents: Vec<TexelRect> = layers.iter().map(|l| l.content).collect();
    let n = layers.len();
    let added: u64 = layers
        .par_iter_mut()
        .enumerate()
        .map(|(m, layer)| {
            let mut added = 0;
            // the nearer layer's copies first (sent farther), then the farther layer's (sent
            // nearer); where both would write a texel, the first one stays
            let sources = [
                (m.checked_sub(1), true),
                ((m + 1 < n).then_some(m + 1), false),
            ];
            for (src, into_farther) in sources {
                let Some(src) = src else { continue };
                let mut grown = false;
                for &(i, c, behind) in &outlines[src] {
                    if behind != into_farther || layer.texel(i)[3] != 0 {
                        continue;
                    }
                    if !grown {
                        // the copies lie within the source layer's content
                        layer.include(&contents[src]);
                        grown = true;
                    }
                    layer.set_texel(i, c);
                    layer.border[i] = true;
                    added += 1;
                }
            }
            added
        })
        .sum();
    Ok(added)
}
