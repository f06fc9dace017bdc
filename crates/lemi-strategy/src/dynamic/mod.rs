//! The `dynamic` strategy: per-object dynamically generated impostors (Schaufler, "Dynamically
//! generated impostors", 1995; as described in Akenine-Möller et al., *Real-Time Rendering*,
//! sec. 10.7.1, and cited by TR-186-2-02-04 for the texture resolution). Nothing is baked: a
//! `lemi` bundle only supplies the view-cell grid and, per cell, the near list (the same near
//! geometry every strategy draws); the far field is turned into billboards at run time.
//!
//! The module's parts: `objects` groups the scene into objects and splits them for a cell,
//! `validity` holds the math of the paper (eq. 10.5, the validity angles), `atlas` dilates, crops
//! and packs the textures, `error` measures the per-pixel error.
//!
//! # Objects
//! The scene is a triangle soup. Every triangle goes to the cell of a uniform 3D grid of edge
//! [`DynamicOptions::object_size`] (default [`DEFAULT_OBJECT_SIZE`] = 50 m, about a city block:
//! a few buildings and their piece of ground) that holds its centroid; the triangles of one grid
//! cell are one *base object*, with the bounding box of its vertices, the box's centre `c` and the
//! radius `r` of the smallest sphere about `c` holding every vertex. Base objects are built once
//! per scene.
//!
//! Per view cell, the far field is every scene triangle that is not in the cell's near list. A
//! base object is used as it is when none of its triangles is near and every eye in the view cell
//! is at least [`DynamicOptions::min_distance_radii`] `= k` (default 2) radii from its centre: its
//! billboard then always lies well in front of the eye (its sphere subtends at most
//! `2·asin(1/k)`, 60° for `k = 2`). Otherwise its far triangles are split like an octree (on their
//! centroids, at most [`MAX_SPLIT_DEPTH`] levels) until each piece passes that test; pieces that
//! never do (a single large triangle just outside the near field, or the depth limit) are drawn as
//! geometry with the near list, and are counted in [`StrategyFrame::near_triangles`]. So objects
//! change only on a cell change; base objects untouched by the new cell keep their impostors (they
//! are still judged by the validity tests from the new eye). An object's triangles are uploaded to
//! the GPU when its first impostor is generated and kept (a base object's for the strategy's life),
//! and counted in [`StrategyFrame::cache_bytes`].
//!
//! # Billboards
//! An object's impostor is generated from the eye `e` at distance `d = |c − e|`: a square through
//! `c` facing `e`, of half side `h = r / sqrt(1 − (r/d)²)` so that it covers the sphere's
//! silhouette as seen from `e` (a square of half side `r` would not), textured with the object's
//! triangles rendered by [`Renderer`] from `e` with a symmetric frustum through the square's corners
//! (vertical field of view `2·asin(r/d)`), RGBA with alpha 0 where no geometry, and the view depth
//! of every texel (the true surface point it shows, for the error measurement). The billboard stays
//! fixed in the world until it is regenerated.
//!
//! Where two objects meet (a ground split between two grid cells), their billboards sample two
//! different texel grids and a pixel may hit a transparent texel in both: one-pixel cracks, an
//! artefact of the technique. [`DynamicOptions::dilate_texels`] (default 0) grows every texture
//! by that many texels (a transparent texel next to opaque ones takes the colour and depth of the
//! nearest); measured on the test scene at 128×96 and 320×240, one texel removes about 90 % of the
//! cracks but fattens silhouettes against the background, so that 2–3 % fewer pixels match the
//! reference.
//!
//! Texture resolution (RTR eq. 10.5, [`texture_resolution`]): `texres = screenres · objsize /
//! (2 · distance · tan(fov/2))` with `screenres` the output height in pixels, `fov` the output's
//! vertical field of view, `objsize = 2h` (the side of the textured square) and `distance = d`;
//! rounded up to a power of two and clamped to [`DynamicOptions::min_resolution`],
//! [`DynamicOptions::max_resolution`] (defaults 8 and 1024).
//!
//! # Validity (RTR sec. 10.7.1, Schaufler 1995)
//! From the current eye `e'` at distance `d' = |c − e'|` (see [`validity_angles`]):
//! - `β_trans`: the angle at `c` between `e − c` and `e' − c` (sideways motion, parallax);
//! - `β_size`: the apparent size change: for the extreme points of the object's bounding cube on
//!   the view axis (lateral offset `r`, depth `d ∓ r`), the angle between where they truly are
//!   (`atan(r / (d' ∓ r))`) and where the billboard shows them (`atan(r·d / ((d ∓ r)·d'))`);
//! - `β_tex`: the angle of one texel at the billboard's centre, `atan(2h / (texres · d'))`.
//!
//! They are compared with `β = β_scr`, the angle of the central output pixel, `atan(2·tan(fov/2)
//! / screenres)` (RTR's `fov/screenres`, exact at the image centre; with it `β_tex ≤ β_scr` holds
//! exactly when the texture has at least the resolution of eq. 10.5), times
//! [`DynamicOptions::beta_factor`], or [`DynamicOptions::beta_scr`] when set. Textures are made
//! at the resolution whose central texel subtends `β` ([`resolution_for_angle`]: eq. 10.5 itself
//! for `β = β_scr`, and still consistent with the `β_tex` test when `β` is scaled). An impostor
//! is regenerated when `β_trans` or `β_size` exceeds `β`, when `β_tex` does (the resolution
//! needed from the current eye is higher than the texture's; never above the maximum), or when
//! the resolution needed is lower (eq. 10.5 asks for another resolution either way). Only objects whose
//! billboard may be in the view frustum are checked and regenerated: an impostor that turned
//! invalid out of view is renewed when it comes into view; turning the head alone never
//! regenerates anything. The output view's changes (size, field of view) and lighting changes are
//! covered too (resolution and thresholds follow the view; a change of the render options drops
//! every impostor).
//!
//! # Drawing
//! Of every generated image only the rectangle of its opaque texels is kept, and only that part
//! of the square is drawn (a billboard's square covers its bounding sphere; the geometry, a flat
//! piece of ground say, often covers far less: cropping cuts the texels held and the fill by
//! about 10× on the procedural city). The cropped textures are packed on shelves (`etagere`'s
//! shelf allocator, tallest first) into macro-textures of at most [`ATLAS_MAX_SIZE`] per side
//! (the bake's GI 2002 packer takes about 30 ms for the 250 billboards of the city, too slow for
//! every frame). The cell's near list (plus the too-close far triangles) and one quad per
//! billboard with an opaque texel are drawn by [`ImpostorRenderer`] in one
//! pass: depth test, the quads alpha-tested (Schaufler's billboards have one depth, the plane's:
//! objects overlapping in depth can show visibility errors). The public `lemi-gpu` interface has
//! no way to change a few textures of an uploaded [`ImpostorCell`], so a frame that regenerated
//! anything packs and uploads the cell again (near geometry, quads and every macro-texture): that
//! cost, and the readback of every generated texture (colour and depth), are part of the frame
//! (a renderer writing impostors into a GPU-resident atlas would be faster; see
//! [`DynamicFrameStats`] for the split). Every current impostor is drawn (the GPU clips those
//! out of view), and counted in [`StrategyFrame::far_primitives`], as the layered strategies
//! draw and count every quad of their cell.
//!
//! # Error
//! With [`FrameRequest::measure_error`], every pixel that shows a billboard texel (found by
//! intersecting the pixel's ray with the billboards and matching the frame's depth) gets the
//! distance, in output pixels, between the projections from the current view of the texel's true
//! surface point (its depth at generation) and of the texel's centre on the billboard: the
//! parallax of the texel, exactly as `lemi_core::parallax_error` measures layered impostors, so
//! the strategies compare (it is 0 from the generation eye and does not count where inside a
//! magnified texel the pixel falls). A dilated texel shows the surface point of the texel its
//! colour came from. Near geometry and background pixels are `NaN`.

mod atlas;
mod error;
mod objects;
mod validity;

use std::collections::{HashMap, HashSet};

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use lemi_core::bundle::Bundle;
use lemi_core::camera::{Camera, View};
use lemi_core::cell::{CellId, ViewCell};
use lemi_core::Scene;
use lemi_gpu::{
    Frame, Gpu, GpuGeometry, GpuMaterials, GpuScene, ImpostorCell, ImpostorRenderer, RenderOptions,
    Renderer, UploadOptions,
};
use serde::{Deserialize, Serialize};

use crate::{
    FrameRequest, Strategy, StrategyContext, StrategyError, StrategyFrame, StrategyKind,
    StrategyReport,
};

pub use atlas::ATLAS_MAX_SIZE;
pub use objects::MAX_SPLIT_DEPTH;
pub use validity::{
    billboard_half_size, resolution_for_angle, texture_resolution, texture_resolution_exact,
    validity_angles, view_angles, ValidityAngles,
};

use atlas::{crop, dilate, macro_textures, Cropped};
use error::measure_error;
use objects::{base_objects, cell_objects, extract_meshes, CellObjects, Impostor, ObjId, Object};
use validity::{frustum_planes, sphere_visible};

/// Default edge of the object grid (m): a city block, a few buildings per object.
pub const DEFAULT_OBJECT_SIZE: f64 = 50.0;
/// Largest texture resolution an option may ask for.
pub const MAX_TEXTURE_RESOLUTION: u32 = 8192;

/// Options of the dynamic strategy.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DynamicOptions {
    /// Edge of the uniform grid (m) whose cells group triangles (by centroid) into objects.
    pub object_size: f64,
    /// The validity threshold `β_scr` in radians; `None`: the angle of the central output pixel.
    pub beta_scr: Option<f64>,
    /// Factor on `β_scr` (1: regenerate as soon as an error may exceed one pixel).
    pub beta_factor: f64,
    /// Smallest texture resolution (a power of two).
    pub min_resolution: u32,
    /// Largest texture resolution (a power of two, at most [`MAX_TEXTURE_RESOLUTION`] and the
    /// adapter's texture limit).
    pub max_resolution: u32,
    /// An object is a billboard only if every eye of the view cell is at least this many of its
    /// bounding radii from its centre (> 1); closer objects are split, see the module docs.
    pub min_distance_radii: f64,
    /// Texels by which every impostor texture is dilated (0..=4, default 0: Schaufler's plain
    /// images): transparent texels next to opaque ones take their neighbour's colour, so that
    /// neighbouring billboards overlap instead of leaving cracks where their texel grids meet, at
    /// the price of silhouettes one texel fatter (see the module docs).
    pub dilate_texels: u32,
}

impl Default for DynamicOptions {
    fn default() -> Self {
        DynamicOptions {
            object_size: DEFAULT_OBJECT_SIZE,
            beta_scr: None,
            beta_factor: 1.0,
            min_resolution: 8,
            max_resolution: 1024,
            min_distance_radii: 2.0,
            dilate_texels: 0,
        }
    }
}

impl DynamicOptions {
    /// Checks the options; the error ([`StrategyError::BadOption`]) names the option, its value
    /// and what it must be.
    pub fn validate(&self) -> Result<(), StrategyError> {
        let bad = |option: &'static str, message: String| {
            Err(StrategyError::BadOption {
                strategy: StrategyKind::Dynamic,
                option,
                message,
            })
        };
        if !(self.object_size.is_finite() && self.object_size > 0.0) {
            return bad(
                "object_size",
                format!("must be a finite length > 0 m (got {})", self.object_size),
            );
        }
        if let Some(b) = self.beta_scr {
            if !(b.is_finite() && b > 0.0 && b < std::f64::consts::FRAC_PI_2) {
                return bad(
                    "beta_scr",
                    format!("must be an angle in (0, π/2) radians (got {b})"),
                );
            }
        }
        if !(self.beta_factor.is_finite() && self.beta_factor > 0.0) {
            return bad(
                "beta_factor",
                format!("must be finite and > 0 (got {})", self.beta_factor),
            );
        }
        for (name, v) in [
            ("min_resolution", self.min_resolution),
            ("max_resolution", self.max_resolution),
        ] {
            if v == 0 || !v.is_power_of_two() || v > MAX_TEXTURE_RESOLUTION {
                return bad(
                    name,
                    format!("must be a power of two in 1..={MAX_TEXTURE_RESOLUTION} (got {v})"),
                );
            }
        }
        if self.min_resolution > self.max_resolution {
            return bad(
                "min_resolution",
                format!(
                    "({}) must not exceed max_resolution ({})",
                    self.min_resolution, self.max_resolution
                ),
            );
        }
        if !(self.min_distance_radii.is_finite() && self.min_distance_radii > 1.0) {
            return bad(
                "min_distance_radii",
                format!(
                    "must be finite and > 1 (the eye must stay outside an object's bounding sphere; got {})",
                    self.min_distance_radii
                ),
            );
        }
        if self.dilate_texels > 4 {
            return bad(
                "dilate_texels",
                format!("must be 0..=4 (got {})", self.dilate_texels),
            );
        }
        Ok(())
    }
}

/// Why impostors were regenerated (counts).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RegenerationReasons {
    /// The object had no impostor (first seen, new cell, options changed).
    pub new: u64,
    /// `β_trans > β`.
    pub trans: u64,
    /// `β_size > β` (and not `β_trans`).
    pub size: u64,
    /// `β_tex > β`: texels magnified, a higher resolution is needed (and neither of the above).
    pub tex: u64,
    /// Eq. 10.5 asks for a lower resolution (and none of the angles exceeds `β`).
    pub resolution: u64,
}

impl RegenerationReasons {
    pub fn total(&self) -> u64 {
        self.new + self.trans + self.size + self.tex + self.resolution
    }

    fn add(&mut self, o: &RegenerationReasons) {
        self.new += o.new;
        self.trans += o.trans;
        self.size += o.size;
        self.tex += o.tex;
        self.resolution += o.resolution;
    }
}

/// What the last frame did and where its time went.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DynamicFrameStats {
    /// Objects of the current cell (billboard candidates).
    pub objects: usize,
    /// Of those, pieces of base objects split for this cell (too close or cut by the near field).
    pub pieces: usize,
    /// Objects whose billboard may be in the view frustum (checked for validity).
    pub visible: usize,
    /// Billboards drawn (with at least one opaque texel).
    pub billboards: usize,
    /// Far triangles drawn as geometry because they are too close for a billboard.
    pub far_geometry_triangles: u64,
    pub reasons: RegenerationReasons,
    /// Seconds: loading the cell and building its objects (cell changes only).
    pub cell_seconds: f64,
    /// Seconds: rendering and reading back regenerated impostors, cropping them.
    pub generation_seconds: f64,
    /// Seconds: packing and uploading the cell (near geometry, quads, macro-textures) after a
    /// change.
    pub upload_seconds: f64,
    /// Seconds: drawing and reading back the frame.
    pub draw_seconds: f64,
    /// Seconds: measuring the error (with `measure_error`).
    pub error_seconds: f64,
    /// Texels kept of the current cell's impostors (their opaque rectangles).
    pub texels: u64,
}

/// The current view cell's far field.
struct CellState {
    id: CellId,
    near: Vec<[u32; 2]>,
    /// Entries of `near` that came from the cell file (the rest are too-close far triangles).
    listed_near: usize,
    active: Vec<ObjId>,
    local: Vec<Object>,
    /// Peak macro-texture bytes on the GPU while in this cell.
    peak_texture_bytes: u64,
}

// ---------------------------------------------------------------------------------------------
// the strategy

/// Schaufler's dynamically generated impostors, one billboard per far object.
pub struct DynamicStrategy {
    gpu: Arc<Gpu>,
    bundle: Bundle,
    scene: Arc<Scene>,
    materials: Arc<GpuMaterials>,
    options: DynamicOptions,
    base: Vec<Object>,
    cell: Option<CellState>,
    /// One reference renderer per texture resolution (each keeps its render targets).
    renderers: HashMap<u32, Renderer>,
    impostors: ImpostorRenderer,
    drawn: Option<ImpostorCell>,
    dirty: bool,
    /// The render options impostors were generated with (clear colour ignored).
    generated_with: Option<RenderOptions>,
    full: Option<GpuScene>,
    fallback_renderer: Option<Renderer>,
    /// Cells that failed to load (warned once, then drawn as geometry).
    failed: HashSet<CellId>,
    last: DynamicFrameStats,
    totals: RegenerationReasons,
    report: StrategyReport,
    texture_bytes_sum: u64,
    cells_left: u64,
}

impl DynamicStrategy {
    /// Groups the scene of `ctx` into objects (see the module docs); the bundle of `ctx` gives
    /// the view cells and their near lists. Bad options are [`StrategyError::BadOption`].
    pub fn new(
        ctx: &StrategyContext,
        options: DynamicOptions,
    ) -> Result<DynamicStrategy, StrategyError> {
        options.validate()?;
        let max_dim = ctx.gpu.limits().max_texture_dimension_2d;
        if options.max_resolution > max_dim {
            return Err(StrategyError::BadOption {
                strategy: StrategyKind::Dynamic,
                option: "max_resolution",
                message: format!(
                    "({}) is larger than this adapter's textures ({max_dim} per side)",
                    options.max_resolution
                ),
            });
        }
        let base = base_objects(&ctx.scene, options.object_size);
        Ok(DynamicStrategy {
            gpu: ctx.gpu.clone(),
            bundle: ctx.bundle.clone(),
            scene: ctx.scene.clone(),
            materials: ctx.materials.clone(),
            options,
            base,
            cell: None,
            renderers: HashMap::new(),
            impostors: ImpostorRenderer::new(&ctx.gpu)?,
            drawn: None,
            dirty: true,
            generated_with: None,
            full: None,
            fallback_renderer: None,
            failed: HashSet::new(),
            last: DynamicFrameStats::default(),
            totals: RegenerationReasons::default(),
            report: StrategyReport::default(),
            texture_bytes_sum: 0,
            cells_left: 0,
        })
    }

    pub fn options(&self) -> &DynamicOptions {
        &self.options
    }

    /// Base objects of the scene (grid cells holding triangles).
    pub fn base_objects(&self) -> usize {
        self.base.len()
    }

    /// What the last frame did.
    pub fn last_frame(&self) -> &DynamicFrameStats {
        &self.last
    }

    /// Regenerations so far, by reason.
    pub fn reasons(&self) -> RegenerationReasons {
        self.totals
    }

    fn object(&self, id: ObjId) -> Option<&Object> {
        match id {
            ObjId::Base(i) => self.base.get(i as usize),
            ObjId::Local(i) => self.cell.as_ref()?.local.get(i as usize),
        }
    }

    /// Makes `cell` the current cell: reads its near list and builds its objects. `Ok(false)`
    /// when it already was.
    fn enter_cell(&mut self, cell: &ViewCell) -> Result<bool, String> {
        let id = cell.id();
        if self.cell.as_ref().is_some_and(|c| c.id == id) {
            return Ok(false);
        }
        let t0 = Instant::now();
        let file = self.bundle.cell(id).map_err(|e| e.to_string())?;
        let near_field = file.header.near_field;
        if !(near_field.is_finite() && near_field >= 0.0) {
            return Err(format!(
                "cell {id}: near-field distance {near_field} is not a finite distance"
            ));
        }
        for (k, &[m, t]) in file.near.iter().enumerate() {
            let ok = self
                .scene
                .meshes
                .get(m as usize)
                .is_some_and(|mesh| (t as usize) < mesh.triangle_count());
            if !ok {
                return Err(format!(
                    "cell {id}: near list entry {k} (mesh {m}, triangle {t}) is not in the scene (is it the scene the bundle was baked from?)"
                ));
            }
        }
        self.leave_cell();
        let CellObjects {
            active,
            local,
            too_close,
        } = cell_objects(
            &self.scene,
            &mut self.base,
            &file.near,
            cell.center,
            near_field,
            &cell.bounds(),
            self.options.min_distance_radii,
        );
        let listed_near = file.near.len();
        let mut near = file.near;
        near.extend(too_close);
        self.cell = Some(CellState {
            id,
            near,
            listed_near,
            active,
            local,
            peak_texture_bytes: 0,
        });
        self.dirty = true;
        let s = t0.elapsed().as_secs_f64();
        self.last.cell_seconds += s;
        self.report.prepare_seconds += s;
        self.report.prepared_cells += 1;
        Ok(true)
    }

    /// Forgets the current cell (its local objects and their impostors).
    fn leave_cell(&mut self) {
        if let Some(mut c) = self.cell.take() {
            for obj in &mut c.local {
                obj.impostor = None;
            }
            self.texture_bytes_sum += c.peak_texture_bytes;
            self.cells_left += 1;
        }
        self.drawn = None;
        self.dirty = true;
    }

    /// Checks the visible objects' impostors from `eye` and regenerates the invalid ones.
    fn update(
        &mut self,
        eye: DVec3,
        view: &View,
        options: &RenderOptions,
    ) -> Result<RegenerationReasons, StrategyError> {
        let (_, pixel) = view_angles(view)?;
        let beta = self.options.beta_scr.unwrap_or(pixel) * self.options.beta_factor;
        let gen_options = RenderOptions {
            clear: [0; 4],
            ..*options
        };
        if self.generated_with.is_some_and(|o| o != gen_options) {
            // Other lighting or alpha cutoff: every impostor is stale.
            for obj in &mut self.base {
                obj.impostor = None;
            }
            if let Some(c) = &mut self.cell {
                for obj in &mut c.local {
                    obj.impostor = None;
                }
            }
            self.dirty = true;
        }
        self.generated_with = Some(gen_options);
        let Some(cell) = &self.cell else {
            return Ok(RegenerationReasons::default());
        };
        let planes = frustum_planes(&view.view_proj());
        let k = self.options.min_distance_radii;
        // A billboard's corners lie within √2·h of its centre, h ≤ r / sqrt(1 − 1/k²).
        let cull_factor = std::f64::consts::SQRT_2 / (1.0 - 1.0 / (k * k)).sqrt();
        let (min_res, max_res) = (self.options.min_resolution, self.options.max_resolution);
        let mut reasons = RegenerationReasons::default();
        let mut todo: Vec<(ObjId, u32)> = Vec::new();
        let mut visible = 0;
        for &id in &cell.active {
            let Some(obj) = self.object(id) else {
                continue;
            };
            if !sphere_visible(&planes, obj.centre, cull_factor * obj.radius) {
                continue;
            }
            visible += 1;
            let d = (obj.centre - eye).length();
            let half = billboard_half_size(obj.radius, d);
            let res = resolution_for_angle(2.0 * half, d, beta, min_res, max_res);
            match &obj.impostor {
                None => reasons.new += 1,
                Some(imp) => {
                    let a =
                        validity_angles(imp.eye, eye, obj.centre, obj.radius, imp.half, imp.res);
                    if a.trans > beta {
                        reasons.trans += 1;
                    } else if a.size > beta {
                        reasons.size += 1;
                    } else if res > imp.res {
                        // β_tex > β: texels magnified (compared as resolutions, which is the
                        // same test without the floating-point noise at the boundary)
                        reasons.tex += 1;
                    } else if res < imp.res {
                        reasons.resolution += 1;
                    } else {
                        continue;
                    }
                }
            }
            todo.push((id, res));
        }
        self.last.visible = visible;
        if todo.is_empty() {
            return Ok(reasons);
        }
        let t0 = Instant::now();
        todo.sort_by_key(|&(id, res)| (res, id));
        for (id, res) in todo {
            self.generate(id, eye, res, &gen_options)?;
        }
        self.dirty = true;
        let s = t0.elapsed().as_secs_f64();
        self.last.generation_seconds += s;
        self.report.prepare_seconds += s;
        Ok(reasons)
    }

    /// Renders the impostor of object `id` from `eye` at `res`² texels.
    fn generate(
        &mut self,
        id: ObjId,
        eye: DVec3,
        res: u32,
        options: &RenderOptions,
    ) -> Result<(), StrategyError> {
        let dilate_texels = self.options.dilate_texels;
        let DynamicStrategy {
            gpu,
            scene,
            materials,
            base,
            cell,
            renderers,
            ..
        } = self;
        let obj = match id {
            ObjId::Base(i) => base.get_mut(i as usize),
            ObjId::Local(i) => cell.as_mut().and_then(|c| c.local.get_mut(i as usize)),
        };
        let Some(obj) = obj else {
            return Ok(());
        };
        obj.impostor = None;
        if obj.gpu.is_none() {
            let meshes = extract_meshes(scene, &obj.tris);
            let geometry = GpuGeometry::upload(gpu, &meshes, &UploadOptions::default())?;
            obj.gpu = Some(GpuScene::from_parts(materials.clone(), geometry)?);
        }
        let d = (obj.centre - eye).length();
        let half = billboard_half_size(obj.radius, d);
        let fov_deg = 2.0 * (half / d).atan().to_degrees();
        let near = (0.5 * (d - obj.radius)).max(1e-4 * d).max(1e-6);
        let camera = Camera::look_at(eye, obj.centre, DVec3::Y, fov_deg, res, res)
            .and_then(|c| c.with_near(near))
            .map_err(|e| {
                StrategyError::Invalid(format!("dynamic strategy: impostor camera: {e}"))
            })?;
        let renderer = match renderers.entry(res) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(e) => e.insert(Renderer::new(gpu)?),
        };
        let Some(geometry) = obj.gpu.as_ref() else {
            return Ok(());
        };
        let frame = renderer.render(geometry, &camera.view(), options)?;
        let (right, up) = (camera.right(), camera.up);
        let corners = [
            obj.centre + half * (up - right),
            obj.centre + half * (up + right),
            obj.centre + half * (-up + right),
            obj.centre + half * (-up - right),
        ];
        let Frame {
            mut rgba,
            mut depth,
            ..
        } = frame;
        let source = dilate(&mut rgba, &mut depth, res, dilate_texels);
        let Cropped {
            rect: crop,
            rgba,
            depth,
            source,
        } = crop(&rgba, &depth, &source, res);
        obj.impostor = Some(Impostor {
            eye,
            distance: d,
            half,
            res,
            corners,
            crop,
            depth,
            source,
            rgba,
        });
        Ok(())
    }

    /// The billboards to draw: the current cell's impostors with an opaque texel.
    fn billboards(&self) -> Vec<&Impostor> {
        let Some(cell) = &self.cell else {
            return Vec::new();
        };
        cell.active
            .iter()
            .filter_map(|&id| self.object(id)?.impostor.as_ref())
            .filter(|imp| imp.crop[2] > 0)
            .collect()
    }

    /// Packs the billboards' textures into macro-textures ([`atlas::macro_textures`]) and uploads
    /// them with the current cell's near geometry and one quad per billboard.
    fn upload(&mut self) -> Result<(), StrategyError> {
        let Some(cell) = &self.cell else {
            return Ok(());
        };
        let billboards = self.billboards();
        let max_size = ATLAS_MAX_SIZE.max(self.options.max_resolution);
        let (macros, quads) = macro_textures(&billboards, max_size).map_err(|(w, h)| {
            StrategyError::Invalid(format!(
                "dynamic strategy: an impostor texture of {w}×{h} texels does not fit a macro-texture of {max_size}² texels"
            ))
        })?;
        let drawn = ImpostorCell::upload(
            &self.gpu,
            self.materials.clone(),
            &self.scene,
            &cell.near,
            &quads,
            &macros,
        )?;
        self.drawn = Some(drawn);
        self.dirty = false;
        Ok(())
    }

    /// Bytes held for the far field: impostor textures and texel depths (CPU), the uploaded cell
    /// (GPU: macro-textures, near geometry, quads), object geometry (GPU).
    fn cache_bytes(&self) -> u64 {
        let geometry = |o: &Object| -> u64 {
            o.gpu.as_ref().map_or(0, |g| {
                g.geometry
                    .chunks()
                    .iter()
                    .map(|c| c.vertices.size() + c.indices.size())
                    .sum()
            })
        };
        let depth = |o: &Object| -> u64 {
            o.impostor.as_ref().map_or(0, |i| {
                (i.rgba.len() + 4 * (i.depth.len() + i.source.len())) as u64
            })
        };
        let objects = self
            .base
            .iter()
            .chain(self.cell.iter().flat_map(|c| c.local.iter()));
        let held: u64 = objects.map(|o| geometry(o) + depth(o)).sum();
        held + self.drawn.as_ref().map_or(0, |d| d.gpu_bytes())
    }

    /// All geometry, for frames without a cell.
    fn fallback(&mut self, r: &FrameRequest<'_>) -> Result<Frame, StrategyError> {
        if self.full.is_none() {
            let geometry =
                GpuGeometry::upload(&self.gpu, &self.scene.meshes, &UploadOptions::default())?;
            self.full = Some(GpuScene::from_parts(self.materials.clone(), geometry)?);
        }
        if self.fallback_renderer.is_none() {
            self.fallback_renderer = Some(Renderer::new(&self.gpu)?);
        }
        match (&self.fallback_renderer, &self.full) {
            (Some(renderer), Some(full)) => Ok(renderer.render(full, r.view, r.options)?),
            _ => Err(StrategyError::Invalid("fallback renderer missing".into())),
        }
    }
}

impl Strategy for DynamicStrategy {
    fn kind(&self) -> StrategyKind {
        StrategyKind::Dynamic
    }

    /// Loads the cell of `eye` and builds its objects. Impostors need the output view, so they
    /// are generated by the first frame.
    fn preload(
        &mut self,
        eye: DVec3,
        _velocity: DVec3,
        _timeout: Duration,
    ) -> Result<(), StrategyError> {
        let Some(cell) = self.bundle.manifest().grid.locate(eye) else {
            return Ok(());
        };
        if self.failed.contains(&cell.id()) {
            return Ok(());
        }
        if let Err(e) = self.enter_cell(&cell) {
            self.failed.insert(cell.id());
            return Err(StrategyError::Invalid(e));
        }
        Ok(())
    }

    fn frame(&mut self, r: &FrameRequest<'_>) -> Result<StrategyFrame, StrategyError> {
        self.last = DynamicFrameStats::default();
        let mut warnings = Vec::new();
        let located = self.bundle.manifest().grid.locate(r.eye);
        let id = located.map(|c| c.id());
        let mut stalled = false;
        let mut ok = false;
        if let (Some(cell), Some(id)) = (located, &id) {
            if !self.failed.contains(id) {
                match self.enter_cell(&cell) {
                    Ok(changed) => {
                        stalled = changed;
                        ok = true;
                    }
                    Err(e) => {
                        warnings.push(format!("{e}; drawing all geometry in this cell"));
                        self.failed.insert(*id);
                        self.leave_cell();
                    }
                }
            }
        } else {
            self.leave_cell();
        }
        if !ok {
            let t0 = Instant::now();
            let frame = self.fallback(r)?;
            self.last.draw_seconds = t0.elapsed().as_secs_f64();
            self.report.stalls += 1;
            let n = frame.depth.len();
            let cache_bytes = self.cache_bytes();
            self.report.peak_bytes = self.report.peak_bytes.max(cache_bytes);
            return Ok(StrategyFrame {
                frame: Some(frame),
                cell: id,
                near_triangles: self.scene.triangle_count(),
                far_primitives: 0,
                stalled: true,
                fallback: true,
                cache_bytes,
                regenerations: 0,
                gpu_ms: None,
                warnings,
                error_px: r.measure_error.then(|| vec![f32::NAN; n]),
            });
        }
        let reasons = self.update(r.eye, r.view, r.options)?;
        self.totals.add(&reasons);
        self.report.regenerations += reasons.total();
        if self.dirty || self.drawn.is_none() {
            let t0 = Instant::now();
            self.upload()?;
            self.last.upload_seconds = t0.elapsed().as_secs_f64();
        }
        let t0 = Instant::now();
        let frame = match &self.drawn {
            Some(d) => self
                .impostors
                .render_frame(d, r.view, r.options, r.needs_pixels())?,
            None => return Err(StrategyError::Invalid("dynamic: cell not uploaded".into())),
        };
        self.last.draw_seconds = t0.elapsed().as_secs_f64();
        let billboards = self.billboards();
        let t0 = Instant::now();
        let error_px = frame
            .as_ref()
            .filter(|_| r.measure_error)
            .map(|f| measure_error(f, r.view, &billboards));
        let n_billboards = billboards.len();
        self.last.error_seconds = t0.elapsed().as_secs_f64();
        let texels: u64 = self
            .cell
            .iter()
            .flat_map(|c| c.active.iter())
            .filter_map(|&id| self.object(id)?.impostor.as_ref())
            .map(|i| i.crop[2] as u64 * i.crop[3] as u64)
            .sum();
        let (near_triangles, far_geometry, objects, pieces) = match &self.cell {
            Some(c) => (
                c.near.len() as u64,
                (c.near.len() - c.listed_near) as u64,
                c.active.len(),
                c.local.len(),
            ),
            None => (0, 0, 0, 0),
        };
        self.last.pieces = pieces;
        self.last.reasons = reasons;
        self.last.billboards = n_billboards;
        self.last.far_geometry_triangles = far_geometry;
        self.last.objects = objects;
        self.last.texels = texels;
        if stalled {
            self.report.stalls += 1;
        }
        let cache_bytes = self.cache_bytes();
        self.report.peak_bytes = self.report.peak_bytes.max(cache_bytes);
        let texture_bytes = self.drawn.as_ref().map_or(0, |d| d.texture_bytes());
        if let Some(c) = &mut self.cell {
            c.peak_texture_bytes = c.peak_texture_bytes.max(texture_bytes);
        }
        Ok(StrategyFrame {
            frame,
            cell: id,
            near_triangles,
            far_primitives: n_billboards as u64,
            stalled,
            fallback: false,
            cache_bytes,
            regenerations: reasons.total(),
            gpu_ms: None,
            warnings,
            error_px,
        })
    }

    fn report(&self) -> StrategyReport {
        let mut r = self.report.clone();
        let (sum, n) = match &self.cell {
            Some(c) => (
                self.texture_bytes_sum + c.peak_texture_bytes,
                self.cells_left + 1,
            ),
            None => (self.texture_bytes_sum, self.cells_left),
        };
        r.texture_bytes_per_cell = if n > 0 { sum as f64 / n as f64 } else { 0.0 };
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_options_name_the_option_as_a_field() {
        let e = DynamicOptions {
            dilate_texels: 9,
            ..Default::default()
        }
        .validate()
        .expect_err("refused");
        assert!(
            matches!(
                &e,
                StrategyError::BadOption {
                    strategy: StrategyKind::Dynamic,
                    option: "dilate_texels",
                    message,
                } if message == "must be 0..=4 (got 9)"
            ),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "dynamic option `dilate_texels` must be 0..=4 (got 9)"
        );
    }
}
