//! The geometric error of an impostor image, per pixel, in output pixels: how far from where it is
//! drawn the surface point an impostor pixel shows would really appear from this viewpoint.
//!
//! This work is based on: GI 2002 sec. 4 and TR-186-2-02-04 sec. 2.1, whose placement bounds the
//! parallax angle between a point and its image on the layer, seen from anywhere in the view cell,
//! by α (one output pixel). Here that bound is *measured*: an impostor pixel whose view depth is
//! `z` lies at a 3D point on a layer plane (face `f`, distance `D` from the reference viewpoint
//! `c`), inside texel `(i, j)`. That texel was recorded from `c` along the ray through its centre
//! `(s, t)`, with depth `d` along the face axis: the true surface point is
//! `T = c + d·(forward + s·right + t·down)`, and the impostor draws it at
//! `L = c + D·(forward + s·right + t·down)`. The error is the distance in output pixels between the
//! projections of `T` and `L` from this viewpoint: the parallax of the texel, independent of how
//! much the texel is magnified on screen (that is a resolution question, not a placement one).
//! Pixels that are not impostor texels (near geometry, background), whose texel has no recorded
//! depth, or whose true point is behind the eye get NaN.
//!
//! The runtime draws every quad grown by a thin rim (a fraction of a texel) that shows the quad's
//! edge texels; a pixel on such a rim lies geometrically in the neighbouring texel, which may be
//! transparent in that layer. Such a pixel is attributed to the texel the rim shows: the
//! neighbour with a depth of its own in the same layer whose grown square contains the point
//! (`rim_texels` of [`pixel_errors`]), before any fallback to the closer layer.
//!
//! A texel filled by gap filling (GI 2002 sec. 5.1) has no depth of its own: it was copied from the
//! next closer layer, so that layer's depth is used, and the pixel is flagged. Such a texel shows a
//! point of the closer slab drawn one layer too far (that is what closes the gap), so its error is
//! bounded by the parallax of two slabs, not one: the certificate reports it apart from the
//! placement error of the layers' own texels.

use glam::{DVec2, DVec3, DVec4};

use crate::camera::View;
use crate::Face;

/// Per-texel depths recorded at bake time: along the face axis, `f32::INFINITY` where the layer
/// recorded nothing.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LayerDepths {
    /// The reference viewpoint.
    pub center: DVec3,
    pub res: u32,
    pub faces: Vec<Face>,
    /// Per face (same order as `faces`), the layer distances far to near.
    pub distances: Vec<Vec<f64>>,
    /// Per face, per layer (far to near), the `res · res` texels' depths (row-major, row 0 at
    /// the top), stored in tiles where the layer recorded something.
    pub depth: Vec<Vec<TexelDepths>>,
    /// An object impostor's frame ([`crate::object_cell`]): the faces, distances and depths are
    /// then those of its canonical frame (reference viewpoint at the canonical origin, `center`
    /// unused), and world points are mapped by it.
    pub frame: Option<crate::object_cell::ObjectFrame>,
    /// The bake copied outline texels into adjacent layers (`BakeParams::outline_copies`,
    /// [`crate::compress::copy_outlines`]): a texel without a depth of its own or of the next
    /// closer layer may hold a copy from the next farther layer ([`LayerDepths::recorded_depth`]).
    pub outline_copies: bool,
}

/// One layer's per-texel depths, `f32::INFINITY` where nothing was recorded, kept in tiles of
/// [`TexelDepths::TILE`]² texels of which only those holding a recorded depth are stored: a
/// certificate holds every layer of a cell at once, which stored whole would take
/// `faces · layers · res² · 4` bytes (4.3 GB for 4 faces of 64 layers at 2048², 17 GB at 4096²),
/// while a slab's content touches a fraction of its face.
#[derive(Clone, Debug, Default)]
pub struct TexelDepths {
    res: u32,
    /// Row-major over `⌈res / TILE⌉²` tiles; a stored tile holds `TILE²` depths, row-major
    /// (texels past the layer's edge infinite).
    tiles: Vec<Option<Box<[f32]>>>,
}

impl TexelDepths {
    /// Side of a tile in texels.
    pub const TILE: u32 = 64;

    fn tiles_per_side(res: u32) -> usize {
        res.div_ceil(Self::TILE) as usize
    }

    /// Nothing recorded in a `res²` layer.
    pub fn empty(res: u32) -> Self {
        let n = Self::tiles_per_side(res);
        Self {
            res,
            tiles: vec![None; n * n],
        }
    }

    /// Every texel of a `res²` layer at depth `d`.
    pub fn filled(res: u32, d: f32) -> Self {
        let mut out = Self::empty(res);
        for idx in 0..out.len() {
            out.set(idx, d);
        }
        out
    }

    /// The depths of a `res²` layer given row-major (`res · res` values; missing ones infinite).
    pub fn from_dense(res: u32, depth: &[f32]) -> Self {
        let mut out = Self::empty(res);
        let (t, r, n) = (Self::TILE as usize, res as usize, Self::tiles_per_side(res));
        for ty in 0..n {
            for tx in 0..n {
                let (x0, x1) = (tx * t, ((tx + 1) * t).min(r));
                let rows = ty * t..((ty + 1) * t).min(r);
                let row = |y: usize| depth.get(y * r + x0..y * r + x1).unwrap_or(&[]);
                if !rows.clone().any(|y| row(y).iter().any(|d| d.is_finite())) {
                    continue;
                }
                let mut tile = vec![f32::INFINITY; t * t].into_boxed_slice();
                for y in rows {
                    let src = row(y);
                    let dst = (y - ty * t) * t;
                    tile[dst..dst + src.len()].copy_from_slice(src);
                }
                out.tiles[ty * n + tx] = Some(tile);
            }
        }
        out
    }

    /// `res · res`, the texels of the layer.
    pub fn len(&self) -> usize {
        self.res as usize * self.res as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Where texel `idx` (row-major) lies: its tile and its place in the tile.
    fn locate(&self, idx: usize) -> Option<(usize, usize)> {
        if idx >= self.len() {
            return None;
        }
        let (r, t) = (self.res as usize, Self::TILE as usize);
        let (i, j) = (idx % r, idx / r);
        Some((
            (j / t) * Self::tiles_per_side(self.res) + i / t,
            (j % t) * t + i % t,
        ))
    }

    /// The depth of texel `idx` (row-major, `j · res + i`); `None` outside the layer,
    /// `f32::INFINITY` where nothing was recorded.
    pub fn get(&self, idx: usize) -> Option<f32> {
        let (tile, k) = self.locate(idx)?;
        Some(match &self.tiles[tile] {
            Some(d) => d[k],
            None => f32::INFINITY,
        })
    }

    /// Sets texel `idx` (row-major); ignored outside the layer.
    pub fn set(&mut self, idx: usize, d: f32) {
        let Some((tile, k)) = self.locate(idx) else {
            return;
        };
        let t = Self::TILE as usize;
        match &mut self.tiles[tile] {
            Some(tile) => tile[k] = d,
            None if d.is_finite() => {
                let mut new = vec![f32::INFINITY; t * t].into_boxed_slice();
                new[k] = d;
                self.tiles[tile] = Some(new);
            }
            None => {}
        }
    }

    /// How many texels recorded a depth.
    pub fn finite_count(&self) -> usize {
        self.tiles
            .iter()
            .flatten()
            .map(|t| t.iter().filter(|d| d.is_finite()).count())
            .sum()
    }

    /// The bytes the stored tiles take.
    pub fn stored_bytes(&self) -> usize {
        let t = Self::TILE as usize;
        self.tiles.iter().flatten().count() * t * t * std::mem::size_of::<f32>()
    }
}

/// Equal when every texel reads the same: a stored tile whose texels were all set back to
/// infinity equals one not stored.
impl PartialEq for TexelDepths {
    fn eq(&self, other: &Self) -> bool {
        let empty = |t: &[f32]| t.iter().all(|&d| d == f32::INFINITY);
        self.res == other.res
            && self
                .tiles
                .iter()
                .zip(&other.tiles)
                .all(|(a, b)| match (a, b) {
                    (Some(a), Some(b)) => a == b,
                    (Some(t), None) | (None, Some(t)) => empty(t),
                    (None, None) => true,
                })
    }
}

/// Which layer texel a world point on a layer plane belongs to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayerTexel {
    pub face_slot: usize,
    pub layer: usize,
    pub i: u32,
    pub j: u32,
    /// The point's depth along the face axis (≈ the layer distance).
    pub depth: f64,
    /// The point's position in the face image in texel units (`i ≤ u < i + 1`, `j ≤ v < j + 1`
    /// inside the image).
    pub u: f64,
    pub v: f64,
}

impl LayerDepths {
    /// The world point `x` relative to the reference viewpoint, in the frame the faces are in.
    pub fn relative(&self, x: DVec3) -> DVec3 {
        match &self.frame {
            Some(f) => f.to_canonical(x),
            None => x - self.center,
        }
    }

    /// The world point of the point `rel` relative to the reference viewpoint (inverse of
    /// [`LayerDepths::relative`]).
    pub fn world(&self, rel: DVec3) -> DVec3 {
        match &self.frame {
            Some(f) => f.to_world(rel),
            None => self.center + rel,
        }
    }

    /// The layer texel that the world point `x` lies on (within a relative `tolerance` of a layer
    /// plane and inside its face's image), if any.
    pub fn texel_of(&self, x: DVec3, tolerance: f64) -> Option<LayerTexel> {
        let rel = self.relative(x);
        let mut best: Option<(f64, LayerTexel)> = None;
        for (slot, &face) in self.faces.iter().enumerate() {
            let Some((s, t, d)) = face.project(rel) else {
                continue;
            };
            let lim = 1.0 + 1e-6;
            if s.abs() > lim || t.abs() > lim {
                continue;
            }
            let dists = self.distances.get(slot)?;
            // the layer whose plane is closest (distances are descending)
            for (k, &dk) in dists.iter().enumerate() {
                let off = (d - dk).abs() / dk;
                if off <= tolerance && best.as_ref().is_none_or(|(b, _)| off < *b) {
                    let r = self.res as f64;
                    let (u, v) = ((s + 1.0) * 0.5 * r, (t + 1.0) * 0.5 * r);
                    let i = (u.floor() as i64).clamp(0, self.res as i64 - 1);
                    let j = (v.floor() as i64).clamp(0, self.res as i64 - 1);
                    best = Some((
                        off,
                        LayerTexel {
                            face_slot: slot,
                            layer: k,
                            i: i as u32,
                            j: j as u32,
                            depth: d,
                            u,
                            v,
                        },
                    ));
                }
            }
        }
        best.map(|(_, t)| t)
    }

    /// The texel a quad drawn grown by `rim` texels shows at `t`'s point: `t` itself when it
    /// recorded a depth in its layer, else the 8-neighbour with a depth of its own whose square
    /// grown by `rim` contains the point (the nearest one), else `t`.
    pub fn displayed_texel(&self, t: &LayerTexel, rim: f64) -> LayerTexel {
        let Some(depths) = self
            .depth
            .get(t.face_slot)
            .and_then(|layers| layers.get(t.layer))
        else {
            return *t;
        };
        let res = self.res as i64;
        let has_depth = |i: i64, j: i64| {
            (0..res).contains(&i)
                && (0..res).contains(&j)
                && depths
                    .get((j * res + i) as usize)
                    .is_some_and(f32::is_finite)
        };
        if has_depth(t.i as i64, t.j as i64) || rim <= 0.0 {
            return *t;
        }
        let mut best: Option<(f64, i64, i64)> = None;
        for dj in -1..=1 {
            for di in -1..=1 {
                let (i, j) = (t.i as i64 + di, t.j as i64 + dj);
                if (di, dj) == (0, 0) || !has_depth(i, j) {
                    continue;
                }
                // distance from the point to the neighbour's square, per axis
                let off = |p: f64, lo: i64| (lo as f64 - p).max(p - (lo + 1) as f64).max(0.0);
                let d = off(t.u, i).max(off(t.v, j));
                if d <= rim && best.is_none_or(|(b, _, _)| d < b) {
                    best = Some((d, i, j));
                }
            }
        }
        match best {
            Some((_, i, j)) => LayerTexel {
                i: i as u32,
                j: j as u32,
                ..*t
            },
            None => *t,
        }
    }

    /// The recorded depth of a texel, or that of the next closer layer (a gap-filled texel or
    /// an outline copied farther), and whether it came from another layer. With
    /// [`LayerDepths::outline_copies`], a texel with neither takes the depth of the next farther
    /// layer where that layer's point lies in front of its plane, the only points
    /// [`crate::compress::copy_outlines`] copies nearer. (Crediting every such texel to the
    /// farther layer would also take the innermost layer's near-field seam texels, which show
    /// the near geometry, for copies, and report errors they do not have.)
    pub fn recorded_depth(&self, t: &LayerTexel) -> Option<(f64, bool)> {
        let layers = self.depth.get(t.face_slot)?;
        let idx = t.j as usize * self.res as usize + t.i as usize;
        let own_or_closer = layers
            .get(t.layer..)?
            .iter()
            .take(2)
            .enumerate()
            .filter_map(|(k, l)| l.get(idx).map(|d| (k, d)))
            .find(|(_, d)| d.is_finite())
            .map(|(k, d)| (d as f64, k > 0));
        if own_or_closer.is_some() || !self.outline_copies {
            return own_or_closer;
        }
        // far to near: the farther layer is the previous one
        let farther = t.layer.checked_sub(1)?;
        let plane = *self.distances.get(t.face_slot)?.get(farther)?;
        let d = layers.get(farther)?.get(idx)?;
        (d.is_finite() && (d as f64) < plane).then_some((d as f64, true))
    }
}

/// How far beyond a quad's exact grown rim a GPU may still cover a pixel centre, in texels: GPUs
/// snap vertices to 8 sub-pixel bits (Vulkan's `subPixelPrecisionBits`; lavapipe, llvmpipe and
/// desktop GPUs report 8), so a rasterized edge may pass up to 1/256 px beyond its exact
/// position, which is 1/64 texel wherever a texel spans at least ¼ px. A pixel that the depth
/// buffer puts on a layer and that lies within this distance of the rim of a texel with a depth
/// was drawn by that texel's quad (its own texel, without a depth, is transparent and drew
/// nothing): measuring it as a gap-filled texel, as an exact test would, took the depth of
/// another surface and reported errors of 1.7–1.9 px for pixels displayed within α.
pub const RASTER_SLACK_TEXELS: f64 = 1.0 / 64.0;

/// What [`pixel_errors`] measured.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParallaxErrors {
    /// Per pixel, the error in pixels; NaN where not an impostor texel (see module docs).
    pub error_px: Vec<f32>,
    /// Per pixel, whether it shows a texel filled from an adjacent layer (its true point is that
    /// layer's): a gap-filled texel, or an outline copy.
    pub gap_filled: Vec<bool>,
    /// Pixels attributed to a layer texel.
    pub impostor_pixels: u64,
    /// Of those, pixels whose texel (and the next closer one) recorded no depth.
    pub without_depth: u64,
}

/// The geometric error of every pixel of an impostor image with view depths `depth` rendered from
/// `view` (see the module docs). `tolerance`: how close to a layer plane (relative to its distance)
/// a pixel's point must be to count as that layer's; the impostor renderer's depth is f32, so
/// about `1e-4` is right. `rim_texels`: how far the renderer grows every quad beyond its texels
/// (a pixel within [`RASTER_SLACK_TEXELS`] more of a texel's rim counts as on it; 0: no rim).
pub fn pixel_errors(
    view: &View,
    depth: &[f32],
    layers: &LayerDepths,
    tolerance: f64,
    rim_texels: f64,
) -> ParallaxErrors {
    let (w, h) = (view.width as usize, view.height as usize);
    let mut out = ParallaxErrors {
        error_px: vec![f32::NAN; w * h],
        gap_filled: vec![false; w * h],
        ..Default::default()
    };
    let inv_proj = view.proj.inverse();
    let inv_view = view.view.inverse();
    let vp = view.view_proj();
    // 0: quads drawn exactly, no rim to attribute
    let rim = if rim_texels > 0.0 {
        rim_texels + RASTER_SLACK_TEXELS
    } else {
        0.0
    };
    for (idx, &z) in depth.iter().enumerate().take(w * h) {
        if !z.is_finite() || z <= 0.0 {
            continue;
        }
        let pixel = DVec2::new((idx % w) as f64 + 0.5, (idx / w) as f64 + 0.5);
        let ndc = view.pixel_to_ndc(pixel);
        let a = inv_proj * DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
        let b = inv_proj * DVec4::new(ndc.x, ndc.y, 0.5, 1.0);
        let (a, b) = (a.truncate() / a.w, b.truncate() / b.w);
        let t = (-(z as f64) - a.z) / (b.z - a.z);
        let x = inv_view.transform_point3(a + (b - a) * t);
        let Some(texel) = layers.texel_of(x, tolerance) else {
            continue;
        };
        let texel = layers.displayed_texel(&texel, rim);
        out.impostor_pixels += 1;
        let Some((d, from_closer)) = layers.recorded_depth(&texel) else {
            out.without_depth += 1;
            continue;
        };
        let face = layers.faces[texel.face_slot];
        let (s, t) = Face::texel_center(texel.i, texel.j, layers.res);
        let dk = layers.distances[texel.face_slot][texel.layer];
        let project = |p: DVec3| {
            let c = vp * p.extend(1.0);
            (c.w > 0.0).then(|| view.ndc_to_pixel(DVec2::new(c.x / c.w, c.y / c.w)))
        };
        let (Some(q), Some(l)) = (
            project(layers.world(face.point(s, t, d))),
            project(layers.world(face.point(s, t, dk))),
        ) else {
            continue;
        };
        out.error_px[idx] = (q - l).length() as f32;
        out.gap_filled[idx] = from_closer;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use proptest::prelude::*;

    proptest! {
        /// The tiled depths read back exactly what a dense layer holds, store only tiles with a
        /// recorded depth, and take writes.
        #[test]
        fn texel_depths_equal_the_dense_layer(
            res in 1u32..200,
            spots in proptest::collection::vec((0usize..40_000, 0.5f32..1e4), 0..40),
            writes in proptest::collection::vec((0usize..40_000, prop_oneof![Just(f32::INFINITY), 1.0f32..100.0]), 0..20),
        ) {
            let n = (res * res) as usize;
            let mut dense = vec![f32::INFINITY; n];
            for &(k, d) in &spots {
                dense[k % n] = d;
            }
            let mut sparse = TexelDepths::from_dense(res, &dense);
            prop_assert_eq!(sparse.len(), n);
            for (k, &d) in dense.iter().enumerate() {
                prop_assert_eq!(sparse.get(k), Some(d));
            }
            prop_assert_eq!(sparse.get(n), None);
            prop_assert_eq!(sparse.finite_count(), dense.iter().filter(|d| d.is_finite()).count());
            // at most one tile per recorded texel, none for an empty layer
            let t = (TexelDepths::TILE * TexelDepths::TILE) as usize * 4;
            prop_assert!(sparse.stored_bytes() <= t * sparse.finite_count());
            for &(k, d) in &writes {
                sparse.set(k % n, d);
                dense[k % n] = d;
            }
            prop_assert_eq!(sparse, TexelDepths::from_dense(res, &dense));
        }
    }

    #[test]
    fn a_sparse_layer_stores_only_its_touched_tiles() {
        let res = 4096u32;
        let mut dense = vec![f32::INFINITY; (res * res) as usize];
        // a horizontal band of content 100 texels tall, as a slab of a street
        for j in 2000..2100 {
            for i in 0..res as usize {
                dense[j * res as usize + i] = 150.0;
            }
        }
        let d = TexelDepths::from_dense(res, &dense);
        // rows 2000..2100 fall into tile rows 31 (1984..2048) and 32, 64 tiles each
        assert_eq!(d.stored_bytes(), 2 * 64 * 64 * 64 * 4);
        assert_eq!(d.finite_count(), 100 * 4096);
        assert_eq!(d.get(2050 * 4096 + 7), Some(150.0));
        assert_eq!(d.get(10), Some(f32::INFINITY));
        assert_eq!(TexelDepths::empty(res).stored_bytes(), 0);
    }

    /// One +Z layer at distance `big_d` recording a surface at depth `d` everywhere.
    fn flat(res: u32, big_d: f64, d: f32) -> LayerDepths {
        LayerDepths {
            center: DVec3::ZERO,
            res,
            faces: vec![Face::PosZ],
            distances: vec![vec![big_d]],
            depth: vec![vec![TexelDepths::filled(res, d)]],
            frame: None,
            outline_copies: false,
        }
    }

    /// With outline copies, a texel with no depth of its own or of the closer layer is credited
    /// to the farther layer only where that layer's point lies in front of its plane (the points
    /// copied nearer); without them, or behind the plane, it has no recorded depth.
    #[test]
    fn outline_copies_are_credited_to_the_farther_layer_in_front_of_its_plane() {
        let res = 4;
        let mut far = TexelDepths::empty(res);
        far.set(0, 90.0); // in front of the far layer's plane at 100
        far.set(1, 110.0); // behind it
        let mut near = TexelDepths::empty(res);
        near.set(2, 55.0);
        let mut layers = LayerDepths {
            center: DVec3::ZERO,
            res,
            faces: vec![Face::PosZ],
            distances: vec![vec![100.0, 50.0]],
            depth: vec![vec![far, near]],
            frame: None,
            outline_copies: false,
        };
        let texel = |layer: usize, i: u32| LayerTexel {
            face_slot: 0,
            layer,
            i,
            j: 0,
            depth: 50.0,
            u: i as f64 + 0.5,
            v: 0.5,
        };
        assert_eq!(layers.recorded_depth(&texel(1, 0)), None);
        layers.outline_copies = true;
        assert_eq!(layers.recorded_depth(&texel(1, 0)), Some((90.0, true)));
        assert_eq!(
            layers.recorded_depth(&texel(1, 1)),
            None,
            "behind: never copied nearer"
        );
        assert_eq!(
            layers.recorded_depth(&texel(1, 2)),
            Some((55.0, false)),
            "its own"
        );
        // the far layer's texel without a depth takes the closer layer's (gap filling)
        assert_eq!(layers.recorded_depth(&texel(0, 2)), Some((55.0, true)));
        assert_eq!(
            layers.recorded_depth(&texel(0, 3)),
            None,
            "no farther layer"
        );
    }

    /// The impostor depth image of the plane z = `big_d` seen by a camera looking along +Z.
    fn plane_depth(view: &View, big_d: f64) -> Vec<f32> {
        vec![big_d as f32; (view.width * view.height) as usize]
    }

    #[test]
    fn no_error_from_the_reference_viewpoint_or_for_a_point_on_the_layer() {
        let cam = Camera::new(DVec3::ZERO, DVec3::Z, DVec3::Y, 60.0, 64, 48).unwrap();
        let v = cam.view();
        let e = pixel_errors(
            &v,
            &plane_depth(&v, 100.0),
            &flat(32, 100.0, 60.0),
            1e-4,
            0.0,
        );
        assert_eq!(e.impostor_pixels, 64 * 48);
        assert!(e.error_px.iter().all(|&x| x < 1e-3), "from the centre");
        let cam = Camera::new(DVec3::new(2.0, 1.0, 0.0), DVec3::Z, DVec3::Y, 60.0, 64, 48).unwrap();
        let v = cam.view();
        let e = pixel_errors(
            &v,
            &plane_depth(&v, 100.0),
            &flat(32, 100.0, 100.0),
            1e-4,
            0.0,
        );
        assert!(e.error_px.iter().all(|&x| x < 1e-3), "surface on the layer");
    }

    /// A viewpoint moved by `e` sideways sees a point at depth `d` drawn on a layer at `D` shifted
    /// by `f · e · (1/d − 1/D)` pixels (`f` the focal length in pixels): the closed form.
    #[test]
    fn sideways_offset_matches_the_closed_form_one_pixel_shift() {
        let (w, h, fov_y) = (200u32, 100u32, 40.0f64);
        let f = 0.5 * h as f64 / (0.5 * fov_y.to_radians()).tan();
        let (big_d, d) = (200.0, 50.0);
        // choose e so the shift is exactly one pixel
        let e = 1.0 / (f * (1.0 / d - 1.0 / big_d));
        let cam = Camera::new(DVec3::new(e, 0.0, 0.0), DVec3::Z, DVec3::Y, fov_y, w, h).unwrap();
        let v = cam.view();
        let r = pixel_errors(
            &v,
            &plane_depth(&v, big_d),
            &flat(64, big_d, d as f32),
            1e-4,
            0.0,
        );
        let vals: Vec<f32> = r.error_px.iter().copied().filter(|x| !x.is_nan()).collect();
        assert_eq!(vals.len(), (w * h) as usize);
        for x in vals {
            assert!((x - 1.0).abs() < 2e-3, "{x}");
        }
        // twice the offset: two pixels
        let cam = Camera::new(
            DVec3::new(2.0 * e, 0.0, 0.0),
            DVec3::Z,
            DVec3::Y,
            fov_y,
            w,
            h,
        )
        .unwrap();
        let v = cam.view();
        let r = pixel_errors(
            &v,
            &plane_depth(&v, big_d),
            &flat(64, big_d, d as f32),
            1e-4,
            0.0,
        );
        assert!(r.error_px.iter().all(|&x| (x - 2.0).abs() < 4e-3));
    }

    #[test]
    fn background_near_geometry_and_missing_depth_are_not_measured() {
        let cam = Camera::new(DVec3::ZERO, DVec3::Z, DVec3::Y, 60.0, 8, 8).unwrap();
        let v = cam.view();
        let mut z = plane_depth(&v, 100.0);
        z[0] = f32::INFINITY; // background
        z[1] = 30.0; // near geometry, on no layer plane
        let mut layers = flat(4, 100.0, 60.0);
        // texel (0, 0) of the layer recorded nothing: pixel (7, 7) of this view lies in texel (3, 3)
        layers.depth[0][0].set(3 * 4 + 3, f32::INFINITY);
        let r = pixel_errors(&v, &z, &layers, 1e-4, 0.0);
        assert!(r.error_px[0].is_nan() && r.error_px[1].is_nan());
        assert_eq!(r.impostor_pixels, 62);
        assert!(r.without_depth > 0);
    }

    #[test]
    fn gap_filled_texels_use_the_closer_layer() {
        let mut l = flat(4, 100.0, 60.0);
        l.distances[0] = vec![100.0, 50.0];
        l.depth[0].push(TexelDepths::filled(4, 40.0));
        l.depth[0][0].set(5, f32::INFINITY);
        let t = LayerTexel {
            face_slot: 0,
            layer: 0,
            i: 1,
            j: 1,
            depth: 100.0,
            u: 1.5,
            v: 1.5,
        };
        assert_eq!(l.recorded_depth(&t), Some((40.0, true)));
        let t = LayerTexel { i: 2, ..t };
        assert_eq!(l.recorded_depth(&t), Some((60.0, false)));
    }

    /// A point on the rim of a quad, just inside a texel that is transparent in its layer, shows
    /// the quad's edge texel: it is measured with that texel's depth, not the closer layer's.
    #[test]
    fn rim_pixels_are_attributed_to_the_texel_the_rim_shows() {
        let mut l = flat(4, 100.0, 60.0);
        l.distances[0] = vec![100.0, 50.0];
        l.depth[0].push(TexelDepths::filled(4, 40.0));
        // texel (2, 1) of the far layer is transparent; (1, 1) recorded 60 m
        l.depth[0][0].set(4 + 2, f32::INFINITY);
        let t = LayerTexel {
            face_slot: 0,
            layer: 0,
            i: 2,
            j: 1,
            depth: 100.0,
            u: 2.03,
            v: 1.5,
        };
        let shown = l.displayed_texel(&t, 1.0 / 16.0);
        assert_eq!((shown.i, shown.j), (1, 1));
        assert_eq!(l.recorded_depth(&shown), Some((60.0, false)));
        // farther inside the transparent texel than the rim: a gap-filled texel of the closer layer
        let deep = LayerTexel { u: 2.3, ..t };
        let shown = l.displayed_texel(&deep, 1.0 / 16.0);
        assert_eq!((shown.i, shown.j), (2, 1));
        assert_eq!(l.recorded_depth(&shown), Some((40.0, true)));
        // just past the exact rim, where a GPU's snapped edge may still cover the pixel centre:
        // the neighbour's once the rasterizer's slack is allowed, as pixel_errors does
        let past = LayerTexel {
            u: 2.0 + 1.0 / 16.0 + 1.0 / 256.0,
            ..t
        };
        assert_eq!(l.displayed_texel(&past, 1.0 / 16.0).i, 2);
        let shown = l.displayed_texel(&past, 1.0 / 16.0 + RASTER_SLACK_TEXELS);
        assert_eq!((shown.i, shown.j), (1, 1));
        // a texel with a depth of its own is itself
        let own = LayerTexel { i: 1, u: 1.97, ..t };
        assert_eq!(l.displayed_texel(&own, 1.0 / 16.0), own);
    }
}
