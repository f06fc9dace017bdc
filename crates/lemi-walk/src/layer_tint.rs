//! The viewer's layer debug colouring: every impostor pixel tinted by the layer it comes from.
//!
//! A post-pass on the read-back impostor frame: a pixel's view depth puts it at a world point;
//! an impostor pixel's point lies on a layer plane of the current cell. [`CellLayers::layer_of`]
//! finds that plane with the attribution of the parallax-error certificate
//! ([`LayerDepths::texel_of`], `lemi_core::parallax_error`), specialised for speed: a point on a
//! layer of face `f` lies in `f`'s 90° pyramid, so only the face of the point's dominant axis is
//! tried, and its layer distances are searched by bisection (a test checks both agree). The layer
//! distances come from the bake's placement of the cell ([`lemi_core::layering::place_cell_in`],
//! pure math on the manifest's parameters), so nothing is read from the cell file. Pixels on no layer plane (near geometry) are shown in grey, the background is
//! left as it is.

use glam::DVec3;
use lemi_core::bundle::BakeParams;
use lemi_core::camera::Camera;
use lemi_core::cell::ViewCell;
use lemi_core::parallax_error::LayerDepths;
use lemi_core::Face;

/// How close to a layer plane (relative to its distance) a pixel's point must be; the depth is
/// f32, see [`lemi_core::parallax_error::pixel_errors`].
pub const PLANE_TOLERANCE: f64 = 2e-4;

/// Colours of layers 0, 1, … (far to near), repeating.
pub const PALETTE: [[u8; 3]; 10] = [
    [230, 25, 75],
    [60, 180, 75],
    [255, 225, 25],
    [0, 130, 200],
    [245, 130, 48],
    [145, 30, 180],
    [70, 240, 240],
    [240, 50, 230],
    [210, 245, 60],
    [250, 190, 212],
];

/// The colour of layer `k`.
pub fn layer_color(k: usize) -> [u8; 3] {
    PALETTE[k % PALETTE.len()]
}

/// The layer planes of one cell.
#[derive(Clone, Debug, PartialEq)]
pub struct CellLayers {
    depths: LayerDepths,
    /// Per axis direction (`+X −X +Y −Y +Z −Z`, [`Face::index`]), the slot of that face in
    /// `depths.faces` if it was baked.
    slot_of_face: [Option<usize>; 6],
    /// The most layers of any face.
    pub max_layers: usize,
}

/// What [`CellLayers::tint`] counted.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TintStats {
    /// Pixels per layer index.
    pub per_layer: Vec<u64>,
    /// Drawn pixels on no layer plane (near geometry).
    pub other: u64,
}

impl CellLayers {
    /// The layers the bake placed for `cell` with `params`.
    pub fn of(
        params: &BakeParams,
        cell: &ViewCell,
        scene_bounds: &lemi_core::Aabb,
    ) -> Result<CellLayers, lemi_core::layering::LayeringError> {
        let placements = lemi_core::layering::place_cell_in(params, cell, scene_bounds)?;
        let distances: Vec<Vec<f64>> = placements
            .iter()
            .map(|p| p.layers.iter().map(|l| l.distance).collect())
            .collect();
        let mut slot_of_face = [None; 6];
        for (slot, f) in params.faces.iter().enumerate() {
            slot_of_face[f.index()] = Some(slot);
        }
        Ok(CellLayers {
            slot_of_face,
            max_layers: distances.iter().map(Vec::len).max().unwrap_or(0),
            depths: LayerDepths {
                center: cell.center,
                res: params.resolution.max(1),
                faces: params.faces.clone(),
                distances,
                depth: Vec::new(),
                frame: None,
                outline_copies: params.outline_copies,
            },
        })
    }

    /// The layer (index far to near) whose plane the world point `p` lies on, within a relative
    /// [`PLANE_TOLERANCE`]; `None` off every plane.
    pub fn layer_of(&self, p: DVec3) -> Option<usize> {
        let rel = self.depths.relative(p);
        let a = rel.abs();
        let (axis, d) = if a.x >= a.y && a.x >= a.z {
            (0, rel.x)
        } else if a.y >= a.z {
            (1, rel.y)
        } else {
            (2, rel.z)
        };
        if !(d.is_finite() && d != 0.0) {
            return None;
        }
        let face = Face::from_index(2 * axis + usize::from(d < 0.0))?;
        let dists = self
            .depths
            .distances
            .get(self.slot_of_face[face.index()]?)?;
        let d = d.abs();
        // distances are descending: the first one below d and the one before it are the closest
        let k = dists.partition_point(|&dk| dk >= d);
        [k.checked_sub(1), Some(k)]
            .into_iter()
            .flatten()
            .filter_map(|i| dists.get(i).map(|&dk| (i, (d - dk).abs() / dk)))
            .filter(|&(_, off)| off <= PLANE_TOLERANCE)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }

    /// Tints the pixels of `rgba` (with view depths `depth`, rendered by `camera`) by layer.
    pub fn tint(&self, camera: &Camera, rgba: &mut [u8], depth: &[f32]) -> TintStats {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mut stats = TintStats {
            per_layer: vec![0; self.max_layers],
            other: 0,
        };
        if rgba.len() != 4 * w * h || depth.len() != w * h {
            return stats;
        }
        // The ray through a pixel centre, scaled to unit length along the view axis: the point at
        // view depth z is `eye + z · ray`.
        let tan_y = (0.5 * camera.fov_y_deg.to_radians()).tan();
        let tan_x = tan_y * camera.aspect();
        let right = camera.right();
        let up = right.cross(camera.forward);
        for y in 0..h {
            let ndc_y = 1.0 - 2.0 * (y as f64 + 0.5) / h as f64;
            for x in 0..w {
                let i = y * w + x;
                let z = depth[i];
                if !z.is_finite() {
                    continue;
                }
                let ndc_x = 2.0 * (x as f64 + 0.5) / w as f64 - 1.0;
                let ray: DVec3 = camera.forward + right * (ndc_x * tan_x) + up * (ndc_y * tan_y);
                let p = camera.eye + ray * z as f64;
                let px = &mut rgba[4 * i..4 * i + 3];
                match self.layer_of(p) {
                    Some(layer) => {
                        if let Some(n) = stats.per_layer.get_mut(layer) {
                            *n += 1;
                        }
                        let c = layer_color(layer);
                        for k in 0..3 {
                            px[k] = ((px[k] as u16 * 2 + c[k] as u16 * 3) / 5) as u8;
                        }
                    }
                    None => {
                        stats.other += 1;
                        let g = ((px[0] as u16 + px[1] as u16 + px[2] as u16) / 6) as u8;
                        px.copy_from_slice(&[g, g, g]);
                    }
                }
            }
        }
        stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lemi_core::bundle::LayerTarget;

    fn params() -> BakeParams {
        BakeParams {
            cell_size: 10.0,
            cell_height: None,
            resolution: 64,
            target: LayerTarget::Layers(4),
            faces: vec![Face::PosX, Face::NegX, Face::PosZ, Face::NegZ],
            alpha: 0.01,
            output_fov_deg: None,
            output_width: None,
            micro_grid: 8,
            micro_threshold: 0.6,
            layering: Default::default(),
            texture_format: Default::default(),
            outline_copies: false,
            outline_fringe: false,
        }
    }

    #[test]
    fn a_pixel_on_a_layer_plane_gets_that_layers_colour() {
        let cell = ViewCell {
            index: glam::IVec3::ZERO,
            center: DVec3::new(5.0, 1.7, 5.0),
            half: DVec3::splat(5.0),
        };
        let layers = CellLayers::of(
            &params(),
            &cell,
            &lemi_core::Aabb::new(DVec3::splat(-1e3), DVec3::splat(1e3)),
        )
        .unwrap();
        assert_eq!(layers.max_layers, 4);
        // look along +X from the centre: the +X face's layer k is the plane x = centre + D_k
        let cam = Camera::from_yaw_pitch(cell.center, 90.0, 0.0, 60.0, 8, 8).unwrap();
        let slot = params()
            .faces
            .iter()
            .position(|&f| f == Face::PosX)
            .unwrap();
        let dists = layers.depths.distances[slot].clone();
        for (k, d) in dists.iter().enumerate() {
            let mut rgba = vec![100u8; 4 * 64];
            let mut depth = vec![f32::INFINITY; 64];
            depth[3 * 8 + 4] = *d as f32; // one pixel on layer k
            depth[0] = (0.5 * (d + dists.get(k + 1).copied().unwrap_or(d * 0.5))) as f32;
            let stats = layers.tint(&cam, &mut rgba, &depth);
            assert_eq!(stats.per_layer[k], 1, "layer {k} at {d}: {stats:?}");
            assert_eq!(
                stats.other, 1,
                "the pixel between two planes is near geometry"
            );
            let c = layer_color(k);
            let i = 4 * (3 * 8 + 4);
            for ch in 0..3 {
                assert_eq!(rgba[i + ch], ((100 * 2 + c[ch] as u16 * 3) / 5) as u8);
            }
            assert_eq!(rgba[4 * 63], 100, "background untouched");
        }
    }

    #[test]
    fn the_fast_lookup_agrees_with_the_certificates_attribution() {
        let cell = ViewCell {
            index: glam::IVec3::ZERO,
            center: DVec3::new(-3.0, 1.7, 12.0),
            half: DVec3::new(5.0, 0.5, 5.0),
        };
        let mut p = params();
        p.target = LayerTarget::Layers(7);
        let layers = CellLayers::of(
            &p,
            &cell,
            &lemi_core::Aabb::new(DVec3::splat(-1e3), DVec3::splat(1e3)),
        )
        .unwrap();
        // deterministic pseudo-random points on the layer planes and between them
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut on_plane = 0;
        for _ in 0..5000 {
            let slot = (rnd() * p.faces.len() as f64) as usize % p.faces.len();
            let face = p.faces[slot];
            let dists = &layers.depths.distances[slot];
            let k = (rnd() * dists.len() as f64) as usize % dists.len();
            let (s, t) = (rnd() * 1.98 - 0.99, rnd() * 1.98 - 0.99);
            let d = if rnd() < 0.7 {
                dists[k]
            } else {
                dists[k] * (0.9 + 0.2 * rnd())
            };
            let x = cell.center + face.point(s, t, d);
            let fast = layers.layer_of(x);
            let slow = layers.depths.texel_of(x, PLANE_TOLERANCE).map(|t| t.layer);
            assert_eq!(fast, slow, "face {face:?} layer {k} d {d} s {s} t {t}");
            on_plane += usize::from(fast.is_some());
        }
        assert!(on_plane > 3000, "{on_plane}");
        // the vertical faces were not baked: nothing above the centre is a layer
        assert_eq!(
            layers.layer_of(cell.center + DVec3::new(0.1, 50.0, 0.2)),
            None
        );
    }
}
