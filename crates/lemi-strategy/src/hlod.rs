//! The `hlod` strategy: what engines ship instead of impostors (Unreal Engine's HLOD, Simplygon,
//! Cesium 3D Tiles' screen-space-error LOD). A bundle baked with `lemi bake --strategy hlod`
//! stores, per cell, the far field as geometry simplified with meshoptimizer in distance bands
//! within the screen-space error `error_px · α` from anywhere in the cell (`lemi_core::hlod`).
//! A frame draws the cell's near geometry and its simplified far meshes with the reference
//! renderer (the same pipeline and shading as all geometry).
//!
//! Cells are loaded synchronously when the eye enters them (the first frame in a cell reads,
//! checks and uploads it: `stalled`), and the last [`HlodStrategy::CACHE_CELLS`] cells are kept.
//! Outside the grid, in an unbaked cell or a damaged one (warned once), the frame draws all
//! geometry (`fallback`). `near_triangles` is the near list's length, `far_primitives` the
//! simplified far triangles; `cache_bytes` the vertex and index bytes of the cells held, and the
//! report's `texture_bytes_per_cell` the far meshes' bytes per cell (geometry, not textures).
//!
//! # Error ([`crate::FrameRequest::measure_error`])
//! The frame is drawn a second time with every triangle of the scene (the reference). For a
//! pixel whose shown point `P` (its depth unprojected) lies outside the cell's near-field cube,
//! the error is the angle under which the distance from `P` to the reference surface is seen from
//! the eye, `asin(dist / |P − eye|)`, in units of the pixel's local angle (as the warp strategy
//! measures its own). The reference surface is reconstructed from the reference depth in a window
//! of ±[`ERROR_WINDOW`] pixels: two triangles per 2 × 2 block of reference points whose depths
//! differ by less than [`SILHOUETTE_RATIO`] (a larger jump is a silhouette, not a surface), and
//! the points themselves elsewhere. A pixel with no reference point in its window gets
//! [`ERROR_WINDOW`] (a lower bound: the shown surface lies at least that far from any original
//! one). Pixels that show background, or a point inside the near-field cube (near geometry), are
//! NaN; near triangles reaching out of the cube count as far pixels with their (zero) error.

use std::collections::{HashSet, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use glam::{DMat4, DVec2, DVec3};
use lemi_core::bundle::Bundle;
use lemi_core::camera::View;
use lemi_core::cell::{CellId, ViewCell};
use lemi_core::classify::TriRef;
use lemi_core::{Mesh, Scene, Vertex};
use lemi_gpu::{Gpu, GpuGeometry, GpuMaterials, GpuScene, Renderer, UploadOptions};
use rayon::prelude::*;

use crate::{
    FrameRequest, Strategy, StrategyContext, StrategyError, StrategyFrame, StrategyKind,
    StrategyReport,
};

/// Half size, in pixels, of the window searched for the reference surface (module docs).
pub const ERROR_WINDOW: usize = 4;
/// Largest ratio of the depths of a 2 × 2 block of reference points that is still one surface.
pub const SILHOUETTE_RATIO: f64 = 1.5;

/// A loaded cell.
struct Cached {
    id: CellId,
    cell: ViewCell,
    near_field: f64,
    scene: GpuScene,
    near_triangles: u64,
    far_triangles: u64,
    far_bytes: u64,
    bytes: u64,
}

/// The HLOD far field of a bundle baked for it (module docs).
pub struct HlodStrategy {
    gpu: Arc<Gpu>,
    bundle: Bundle,
    scene: Arc<Scene>,
    materials: Arc<GpuMaterials>,
    renderer: Renderer,
    full: GpuScene,
    total_triangles: u64,
    cache: VecDeque<Cached>,
    warned: HashSet<CellId>,
    loads: u64,
    evictions: u64,
    stalls: u64,
    peak_bytes: u64,
    far_bytes: u64,
    prepare_seconds: f64,
}

impl HlodStrategy {
    /// Cells kept loaded.
    pub const CACHE_CELLS: usize = 4;

    /// Opens the bundle of `ctx`, which must have been baked with `--strategy hlod`.
    pub fn new(ctx: &StrategyContext) -> Result<HlodStrategy, StrategyError> {
        let baked = crate::layered::bundle_strategy(ctx.bundle.manifest());
        if baked != StrategyKind::Hlod {
            return Err(StrategyError::NotBakedFor {
                requested: StrategyKind::Hlod,
                baked,
            });
        }
        let full = GpuScene::upload(&ctx.gpu, &ctx.scene, &UploadOptions::default())?;
        Ok(HlodStrategy {
            gpu: ctx.gpu.clone(),
            bundle: ctx.bundle.clone(),
            scene: ctx.scene.clone(),
            materials: ctx.materials.clone(),
            renderer: Renderer::new(&ctx.gpu)?,
            full,
            total_triangles: ctx.scene.triangle_count(),
            cache: VecDeque::new(),
            warned: HashSet::new(),
            loads: 0,
            evictions: 0,
            stalls: 0,
            peak_bytes: 0,
            far_bytes: 0,
            prepare_seconds: 0.0,
        })
    }

    fn bytes(&self) -> u64 {
        self.cache.iter().map(|c| c.bytes).sum()
    }

    /// Reads, checks and uploads cell `cell`: its near triangles and its simplified far meshes.
    fn load(&self, cell: &ViewCell) -> Result<Cached, String> {
        let file = self.bundle.cell(cell.id()).map_err(|e| e.to_string())?;
        let hlod = file.header.hlod.as_ref().ok_or_else(|| {
            format!(
                "cell {}: no simplified far field (not an HLOD cell)",
                cell.id()
            )
        })?;
        let near_refs: Vec<TriRef> = file.near.iter().map(|&p| TriRef::from(p)).collect();
        let near = self
            .scene
            .extract(&near_refs)
            .map_err(|e| format!("{e}; is it the scene the bundle was baked from?"))?;
        let materials = self.scene.materials.len() as u32;
        if let Some(m) = hlod.meshes().find(|m| m.material >= materials) {
            return Err(format!(
                "cell {}: a simplified mesh uses material {} of {materials}; is it the scene the bundle was baked from?",
                cell.id(),
                m.material
            ));
        }
        let far_bytes = hlod.mesh_bytes();
        let geometry = GpuGeometry::upload(
            &self.gpu,
            near.iter().chain(hlod.meshes()),
            &UploadOptions::default(),
        )
        .map_err(|e| e.to_string())?;
        Ok(Cached {
            id: cell.id(),
            cell: *cell,
            near_field: file.header.near_field,
            scene: GpuScene {
                materials: self.materials.clone(),
                geometry,
            },
            near_triangles: near_refs.len() as u64,
            far_triangles: hlod.triangles(),
            far_bytes,
            bytes: far_bytes + mesh_bytes(&near),
        })
    }

    /// The cached cell `id`, loading it (and evicting the oldest) if needed; `None` with a
    /// warning (once per cell) if it cannot be read.
    fn cell(&mut self, cell: &ViewCell, warnings: &mut Vec<String>) -> (Option<usize>, bool) {
        let id = cell.id();
        if let Some(i) = self.cache.iter().position(|c| c.id == id) {
            return (Some(i), false);
        }
        if self.warned.contains(&id) || self.bundle.entry(id).is_none() {
            return (None, false);
        }
        let t = std::time::Instant::now();
        match self.load(cell) {
            Ok(c) => {
                self.prepare_seconds += t.elapsed().as_secs_f64();
                self.loads += 1;
                self.far_bytes += c.far_bytes;
                if self.cache.len() >= Self::CACHE_CELLS {
                    self.cache.pop_front();
                    self.evictions += 1;
                }
                self.cache.push_back(c);
                self.peak_bytes = self.peak_bytes.max(self.bytes());
                (Some(self.cache.len() - 1), true)
            }
            Err(e) => {
                warnings.push(format!("hlod: {e}; drawing all geometry there"));
                self.warned.insert(id);
                (None, true)
            }
        }
    }
}

fn mesh_bytes(meshes: &[Mesh]) -> u64 {
    meshes
        .iter()
        .map(|m| (m.vertices.len() * std::mem::size_of::<Vertex>() + 4 * m.indices.len()) as u64)
        .sum()
}

impl Strategy for HlodStrategy {
    fn kind(&self) -> StrategyKind {
        StrategyKind::Hlod
    }

    fn preload(
        &mut self,
        eye: DVec3,
        _velocity: DVec3,
        _timeout: Duration,
    ) -> Result<(), StrategyError> {
        if let Ok(cell) = self.bundle.locate(eye) {
            let mut warnings = Vec::new();
            self.cell(&cell, &mut warnings);
        }
        Ok(())
    }

    fn frame(&mut self, r: &FrameRequest<'_>) -> Result<StrategyFrame, StrategyError> {
        let mut warnings = Vec::new();
        let located = self.bundle.locate(r.eye).ok();
        let (slot, stalled) = match &located {
            Some(cell) => self.cell(cell, &mut warnings),
            None => (None, false),
        };
        if stalled {
            self.stalls += 1;
        }
        let cell = located.map(|c| c.id());
        let (frame, near, far, fallback) = match slot.and_then(|i| self.cache.get(i)) {
            Some(c) => (
                self.renderer
                    .render_frame(&c.scene, r.view, r.options, r.needs_pixels())?,
                c.near_triangles,
                c.far_triangles,
                false,
            ),
            None => (
                self.renderer
                    .render_frame(&self.full, r.view, r.options, r.needs_pixels())?,
                self.total_triangles,
                0,
                true,
            ),
        };
        let gpu_ms = self.renderer.last_gpu_ms();
        let error_px = match frame.as_ref().filter(|_| r.measure_error) {
            None => None,
            Some(frame) => match slot.and_then(|i| self.cache.get(i)) {
                Some(c) => {
                    let reference = self.renderer.render(&self.full, r.view, r.options)?;
                    let center = c.cell.center;
                    let nf = c.near_field;
                    Some(error_px(r.view, &frame.depth, &reference.depth, |p| {
                        (p - center).abs().max_element() > nf
                    }))
                }
                None => Some(vec![f32::NAN; frame.depth.len()]),
            },
        };
        Ok(StrategyFrame {
            frame,
            cell,
            near_triangles: near,
            far_primitives: far,
            stalled,
            fallback,
            cache_bytes: self.bytes(),
            regenerations: 0,
            warnings,
            gpu_ms,
            error_px,
        })
    }

    fn report(&self) -> StrategyReport {
        StrategyReport {
            prepare_seconds: self.prepare_seconds,
            prepared_cells: self.loads,
            regenerations: 0,
            stalls: self.stalls,
            loads: self.loads,
            evictions: self.evictions,
            peak_bytes: self.peak_bytes,
            texture_bytes_per_cell: if self.loads > 0 {
                self.far_bytes as f64 / self.loads as f64
            } else {
                0.0
            },
        }
    }
}

/// The world-space direction of the ray through pixel position `p` of a view whose inverse
/// view-projection is `inv`.
fn ray_dir(view: &View, inv: &DMat4, p: DVec2) -> DVec3 {
    let ndc = view.pixel_to_ndc(p);
    let a = *inv * glam::DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
    let b = *inv * glam::DVec4::new(ndc.x, ndc.y, 0.5, 1.0);
    (b.truncate() / b.w - a.truncate() / a.w).normalize()
}

fn angle(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// Closest point to `p` on the triangle `a b c` (Ericson, "Real-Time Collision Detection",
/// sec. 5.1.5), as a distance.
pub fn point_triangle_distance(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (p - (a + ab * v)).length();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + ac * w)).length();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).length();
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (p - (a + ab * v + ac * w)).length()
}

/// The per-pixel error of a frame with view depths `shown` against the reference depths
/// `reference` of the same view (module docs, "Error"); `far(P)` tells whether a shown point
/// is measured.
pub fn error_px(
    view: &View,
    shown: &[f32],
    reference: &[f32],
    far: impl Fn(DVec3) -> bool + Sync,
) -> Vec<f32> {
    let (w, h) = (view.width as usize, view.height as usize);
    let inv = view.view_proj().inverse();
    let eye = view.eye();
    let point = |depth: &[f32], x: usize, y: usize| -> Option<(DVec3, f64)> {
        let d = *depth.get(y * w + x)?;
        d.is_finite().then(|| {
            let p = view.unproject(DVec2::new(x as f64 + 0.5, y as f64 + 0.5), d as f64);
            (p, d as f64)
        })
    };
    let refs: Vec<Option<(DVec3, f64)>> = (0..w * h)
        .into_par_iter()
        .map(|k| point(reference, k % w, k / w))
        .collect();
    let at = |x: usize, y: usize| refs[y * w + x];
    let mut out = vec![f32::NAN; w * h];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, e) in row.iter_mut().enumerate() {
                let Some((p, _)) = point(shown, x, y) else {
                    continue;
                };
                if !far(p) {
                    continue;
                }
                let (fx, fy) = (x as f64, y as f64);
                let horizontal = angle(
                    ray_dir(view, &inv, DVec2::new(fx, fy + 0.5)),
                    ray_dir(view, &inv, DVec2::new(fx + 1.0, fy + 0.5)),
                );
                let vertical = angle(
                    ray_dir(view, &inv, DVec2::new(fx + 0.5, fy)),
                    ray_dir(view, &inv, DVec2::new(fx + 0.5, fy + 1.0)),
                );
                let pixel = (horizontal * vertical).sqrt();
                if pixel <= 0.0 {
                    continue;
                }
                let (x0, x1) = (
                    x.saturating_sub(ERROR_WINDOW),
                    (x + ERROR_WINDOW).min(w - 1),
                );
                let (y0, y1) = (
                    y.saturating_sub(ERROR_WINDOW),
                    (y + ERROR_WINDOW).min(h - 1),
                );
                let mut best = f64::INFINITY;
                for yy in y0..=y1 {
                    for xx in x0..=x1 {
                        let Some((a, da)) = at(xx, yy) else {
                            continue;
                        };
                        best = best.min((p - a).length());
                        if xx == x1 || yy == y1 {
                            continue;
                        }
                        let (Some((b, db)), Some((c, dc)), Some((d, dd))) =
                            (at(xx + 1, yy), at(xx, yy + 1), at(xx + 1, yy + 1))
                        else {
                            continue;
                        };
                        let lo = da.min(db).min(dc).min(dd);
                        let hi = da.max(db).max(dc).max(dd);
                        if hi <= lo * SILHOUETTE_RATIO {
                            best = best
                                .min(point_triangle_distance(p, a, b, c))
                                .min(point_triangle_distance(p, b, d, c));
                        }
                    }
                }
                let dist = (p - eye).length();
                *e = if best.is_finite() && dist > 0.0 {
                    ((best / dist).min(1.0).asin() / pixel) as f32
                } else {
                    ERROR_WINDOW as f32
                };
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_triangle_distance_regions() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        let d = |p: DVec3| point_triangle_distance(p, a, b, c);
        assert!((d(DVec3::new(0.2, 0.2, 3.0)) - 3.0).abs() < 1e-12); // face
        assert!((d(DVec3::new(-1.0, -1.0, 0.0)) - 2f64.sqrt()).abs() < 1e-12); // vertex a
        assert!((d(DVec3::new(0.5, -2.0, 0.0)) - 2.0).abs() < 1e-12); // edge ab
        assert!((d(DVec3::new(1.0, 1.0, 0.0)) - 0.5f64.sqrt()).abs() < 1e-12); // edge bc
        assert!((d(DVec3::new(3.0, 0.0, 0.0)) - 2.0).abs() < 1e-12); // vertex b
    }
}
