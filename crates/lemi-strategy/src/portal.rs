//! Portal impostors at run time (TR-186-2-02-04 sec. 3; Rafferty, Aliaga, Lastra 1998): a scene
//! seen from inside a building, the outside behind each opening replaced by that opening's object
//! impostor ([`lemi_core::object_cell::Portal`], `lemi bake-object --portal`) wherever the viewer
//! stands in the opening's view cell, and drawn as geometry everywhere else.
//!
//! **What a frame draws.** Each portal bundle's cell lists as near field every triangle but its
//! object's, so a triangle's *signature* is the set of portals whose object holds it. The scene is
//! split by signature into classes (the triangles no portal replaces form one of them), each
//! uploaded as [`CulledGeometry`] (frustum culled per frame like the `geometry-culled` baseline).
//! At a viewpoint the *active* portals are those whose view cell holds it; the frame draws every
//! class no active portal replaces, culled to the view, and the quads of the active portals, all
//! depth-tested in one frame ([`ImpostorRenderer::render_composite`]). A triangle is therefore
//! drawn as geometry unless an impostor valid at the viewpoint represents it, and an impostor is
//! never drawn outside its view cell.
//!
//! **Only through the openings.** When the bake knew the whole building (`lemi bake-object
//! --portal all` records it as an [`Enclosure`] in every bundle), each class is split once more
//! into the triangles wholly inside the building and the rest. From an eye in one of its rooms
//! the rest, and every impostor (all lie outside), can be seen only through the openings, so they
//! are culled to the sub-frustum of [`Enclosure::window`] (the openings' part of the view, found
//! through the doorways between rooms) and drawn with it as scissor: the image does not change
//! (the test compares frames with and without), the triangles and quads drawn do. Without an
//! enclosure (openings given one by one, which may not be all of them) the outside is culled to
//! the whole view.
//!
//! **Only through the doorways.** Where the enclosure's rooms know their insides
//! ([`lemi_core::enclosure::Room::inside`]), the building's triangles are split by the rooms
//! whose inside they touch (walls, floor, ceiling, reveals); those touching none (outer faces,
//! roof) count as outside. From an eye in a room, the triangles of its own room are drawn over
//! the whole view, those of another room only through the doorways leading to it
//! ([`lemi_core::enclosure::Sight::window`], culled to its sub-frustum and scissored to it), and
//! a room out of sight not at all, as cell-and-portal renderers draw buildings (Luebke & Georges
//! 1995): on a software rasterizer the other rooms' walls behind the eye's room's cost as much
//! as visible ones.
//!
//! Why this shows every surface within the impostors' bound: a portal's object is everything
//! wholly inside its frustum beyond its near distance ([`Portal::select`]), and that frustum holds
//! every point any viewpoint of its cell sees through the opening, so from inside the cell every
//! ray through the opening meets either the building (geometry), triangles nearer than the object
//! or crossing the frustum's side (geometry), or the object (its layers, within α by the
//! placement). Rays through another opening may meet an active portal's layers too, but only inside
//! that portal's frustum, where the layers hold everything beyond the near distance: they show
//! what is there, within α, and geometry nearer along the ray stays nearer.
//!
//! [`Portal::select`]: lemi_core::object_cell::Portal::select

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use lemi_core::bundle::Bundle;
use lemi_core::classify::TriRef;
use lemi_core::enclosure::Enclosure;
use lemi_core::object_cell::{complement, ObjectSetup};
use lemi_core::Scene;
use lemi_gpu::{
    Composite, CullOptions, CulledGeometry, Gpu, GpuMaterials, ImpostorCell, ImpostorRenderer,
};

use crate::{FrameRequest, Strategy, StrategyError, StrategyFrame, StrategyKind, StrategyReport};

/// One portal impostor, resident.
struct PortalPart {
    setup: ObjectSetup,
    /// Its quads (uploaded without a near list).
    cell: ImpostorCell,
}

/// Where a class's triangles lie with respect to the enclosure, which says from where they
/// can be seen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Place {
    /// Touching the insides of these rooms (bit `r`: room `r`), seen from another room only
    /// through the doorways leading to them.
    Rooms(u64),
    /// In the building as far as known (no enclosure, or one whose rooms do not know their
    /// insides): drawn over the whole view.
    Building,
    /// Not wholly inside the enclosure's bounds, or inside but touching no room's inside (the
    /// building's outer faces, its roof): seen from its rooms only through its openings.
    Outside,
}

/// Triangles of one signature, culled per frame.
struct Class {
    /// Bit `k`: portal `k`'s object holds these triangles.
    mask: u64,
    place: Place,
    geometry: CulledGeometry,
}

/// Portal impostors of one scene, all resident (see the module docs).
pub struct PortalStrategy {
    portals: Vec<PortalPart>,
    classes: Vec<Class>,
    /// The building all portals are the openings of, when their bake knew it (every bundle
    /// records the same one): from its rooms the outside is drawn only through its openings.
    enclosure: Option<Enclosure>,
    materials: Arc<GpuMaterials>,
    renderer: ImpostorRenderer,
    total_triangles: u64,
    prepare_seconds: f64,
    texture_bytes: u64,
}

impl PortalStrategy {
    /// Most portals one strategy takes (a signature is a 64-bit mask).
    pub const MAX_PORTALS: usize = 64;

    /// Uploads the portal impostors `bundles` (object bundles of `scene`, e.g. the
    /// `portal-K` bundles of `lemi bake-object --portal all`) and the scene split by signature.
    pub fn new(
        gpu: &Arc<Gpu>,
        scene: &Scene,
        materials: Arc<GpuMaterials>,
        bundles: &[Bundle],
    ) -> Result<PortalStrategy, StrategyError> {
        let t = Instant::now();
        if bundles.is_empty() || bundles.len() > Self::MAX_PORTALS {
            return Err(StrategyError::Invalid(format!(
                "{} portal bundles: give 1 to {}",
                bundles.len(),
                Self::MAX_PORTALS
            )));
        }
        let mut signature: Vec<Vec<u64>> = scene
            .meshes
            .iter()
            .map(|m| vec![0; m.triangle_count()])
            .collect();
        let mut portals = Vec::with_capacity(bundles.len());
        let mut texture_bytes = 0;
        for (k, bundle) in bundles.iter().enumerate() {
            let what = bundle.dir().display().to_string();
            let setup = bundle.manifest().object.clone().ok_or_else(|| {
                StrategyError::Invalid(format!("{what}: not an object impostor's bundle"))
            })?;
            let id =
                bundle.cell_ids().first().copied().ok_or_else(|| {
                    StrategyError::Invalid(format!("{what}: the bundle has no cell"))
                })?;
            let file = bundle
                .cell(id)
                .map_err(|e| StrategyError::Invalid(format!("{what}: {e}")))?;
            let drawn: Vec<TriRef> = file
                .near
                .iter()
                .map(|&[mesh, tri]| TriRef { mesh, tri })
                .collect();
            for [m, t] in complement(scene, &drawn) {
                if let Some(s) = signature
                    .get_mut(m as usize)
                    .and_then(|v| v.get_mut(t as usize))
                {
                    *s |= 1 << k;
                }
            }
            let mut quads_only = file.clone();
            quads_only.near.clear();
            let cell = ImpostorCell::upload_file(gpu, materials.clone(), scene, &quads_only)?;
            texture_bytes += cell.texture_bytes();
            portals.push(PortalPart { setup, cell });
        }
        let enclosure = portals
            .first()
            .and_then(|p| p.setup.enclosure.clone())
            .filter(|e| {
                e.validate().is_ok()
                    && portals
                        .iter()
                        .all(|p| p.setup.enclosure.as_ref() == Some(e))
            });
        let mut by_mask: HashMap<(u64, Place), Vec<TriRef>> = HashMap::new();
        for (m, tris) in signature.iter().enumerate() {
            for (t, &mask) in tris.iter().enumerate() {
                let place = enclosure
                    .as_ref()
                    .map_or(Place::Building, |e| place(e, &scene.meshes[m].triangle(t)));
                by_mask.entry((mask, place)).or_default().push(TriRef {
                    mesh: m as u32,
                    tri: t as u32,
                });
            }
        }
        let mut keys: Vec<(u64, Place)> = by_mask.keys().copied().collect();
        keys.sort_unstable();
        let mut classes = Vec::with_capacity(keys.len());
        for (mask, place) in keys {
            let tris = &by_mask[&(mask, place)];
            let meshes = scene
                .extract(tris)
                .map_err(|e| StrategyError::Invalid(e.to_string()))?;
            let part = Scene {
                meshes,
                ..Default::default()
            };
            classes.push(Class {
                mask,
                place,
                geometry: CulledGeometry::upload(gpu, &part, &CullOptions::default())?,
            });
        }
        Ok(PortalStrategy {
            portals,
            classes,
            enclosure,
            materials,
            renderer: ImpostorRenderer::new(gpu)?,
            total_triangles: scene.triangle_count(),
            prepare_seconds: t.elapsed().as_secs_f64(),
            texture_bytes,
        })
    }

    /// The portals whose view cell holds `eye`, as a mask.
    pub fn active(&self, eye: DVec3) -> u64 {
        self.portals
            .iter()
            .enumerate()
            .filter(|(_, p)| p.setup.cell.contains(eye))
            .fold(0, |m, (k, _)| m | 1 << k)
    }

    /// Whether the portals know their building ([`Enclosure`]), so that from its rooms the
    /// outside is drawn only through its openings.
    pub fn has_enclosure(&self) -> bool {
        self.enclosure.is_some()
    }

    /// The same strategy drawing the outside over the whole view from the rooms too (for
    /// comparisons: the image is the same, the work is not).
    pub fn without_enclosure(mut self) -> PortalStrategy {
        self.enclosure = None;
        self
    }

    /// How many signature classes the scene was split into.
    pub fn class_count(&self) -> usize {
        self.classes.len()
    }
}

impl Strategy for PortalStrategy {
    /// Portal impostors are lemi's layered impostors of objects.
    fn kind(&self) -> StrategyKind {
        StrategyKind::Lemi
    }

    /// Everything is resident from the start: nothing to load.
    fn preload(
        &mut self,
        _eye: DVec3,
        _velocity: DVec3,
        _timeout: Duration,
    ) -> Result<(), StrategyError> {
        Ok(())
    }

    fn frame(&mut self, r: &FrameRequest<'_>) -> Result<StrategyFrame, StrategyError> {
        let active = self.active(r.eye);
        let view_proj = r.view.view_proj();
        // from a room of the building: the other rooms show only through the doorways, the
        // outside only through the openings (`window` is `Some(None)` when none is in view)
        let sight = self
            .enclosure
            .as_ref()
            .filter(|e| e.encloses(r.eye))
            .and_then(|e| e.sight(r.view));
        let window = sight.as_ref().map(|s| s.outside);
        let mut parts = Composite::default();
        let mut near_triangles = 0;
        for class in self.classes.iter().filter(|c| c.mask & active == 0) {
            // the window the class is drawn in: `None` for the whole view
            let seen_in = match (class.place, &sight) {
                (_, None) | (Place::Building, _) => None,
                (Place::Outside, Some(s)) => match s.outside {
                    Some(w) => Some(w),
                    None => continue,
                },
                (Place::Rooms(bits), Some(s)) => {
                    let rooms = (0..64).filter(move |r| bits & (1 << r) != 0);
                    if s.sees_directly(rooms.clone()) {
                        None
                    } else {
                        match s.window(rooms) {
                            Some(w) => Some(w),
                            None => continue,
                        }
                    }
                }
            };
            let list = class
                .geometry
                .cull(seen_in.as_ref().map_or(&view_proj, |w| &w.view_proj));
            near_triangles += list.triangles;
            let chunks = class.geometry.chunks();
            let ranges = list
                .draws
                .iter()
                .filter_map(|d| chunks.get(d.chunk).map(|c| (c, d.indices.clone())));
            match seen_in {
                None => parts.geometry.extend(ranges),
                Some(_) if class.place == Place::Outside => parts.windowed.extend(ranges),
                Some(w) => match parts.scissored.iter_mut().find(|(s, _)| s.rect == w.rect) {
                    Some((_, group)) => group.extend(ranges),
                    None => parts.scissored.push((w, ranges.collect())),
                },
            }
        }
        parts.window = window.flatten();
        if !matches!(window, Some(None)) {
            parts.cells = self
                .portals
                .iter()
                .enumerate()
                .filter(|(k, _)| active & (1 << k) != 0)
                .map(|(_, p)| &p.cell)
                .collect();
        }
        let quads = parts.cells.iter().map(|c| c.quad_count() as u64).sum();
        let frame = self.renderer.render_composite(
            &parts,
            &self.materials,
            r.view,
            r.options,
            r.needs_pixels(),
        )?;
        Ok(StrategyFrame {
            frame,
            cell: None,
            near_triangles,
            far_primitives: quads,
            stalled: false,
            fallback: active == 0,
            cache_bytes: self.texture_bytes,
            regenerations: 0,
            warnings: Vec::new(),
            gpu_ms: self.renderer.last_gpu_ms(),
            error_px: None,
        })
    }

    fn report(&self) -> StrategyReport {
        StrategyReport {
            prepare_seconds: self.prepare_seconds,
            prepared_cells: self.portals.len() as u64,
            regenerations: 0,
            stalls: 0,
            loads: self.portals.len() as u64,
            evictions: 0,
            peak_bytes: self.texture_bytes,
            texture_bytes_per_cell: self.texture_bytes as f64 / self.portals.len().max(1) as f64,
        }
    }
}

/// Where a triangle of the scene lies with respect to the building `e` (see [`Place`]).
fn place(e: &Enclosure, tri: &[glam::Vec3; 3]) -> Place {
    let [a, b, c] = tri.map(|v| v.as_dvec3());
    if [a, b, c].iter().any(|&v| !e.bounds.contains(v)) {
        return Place::Outside;
    }
    if e.rooms.len() > 64 || e.rooms.iter().any(|r| r.inside.is_none()) {
        return Place::Building;
    }
    // touching a room's inside: the triangle's box meets it, within a rounding margin of the
    // building's size (f32 vertices on the inside's faces)
    let tol = 1e-5 * (e.bounds.max - e.bounds.min).length();
    let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
    let bits = e
        .rooms
        .iter()
        .enumerate()
        .filter(|(_, r)| {
            r.inside.as_ref().is_some_and(|i| {
                (lo - i.max).max_element() <= tol && (i.min - hi).max_element() <= tol
            })
        })
        .fold(0u64, |m, (k, _)| m | 1 << k);
    if bits == 0 {
        Place::Outside
    } else {
        Place::Rooms(bits)
    }
}

impl std::fmt::Debug for PortalStrategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PortalStrategy")
            .field("portals", &self.portals.len())
            .field("classes", &self.classes.len())
            .field("total_triangles", &self.total_triangles)
            .finish()
    }
}
