//! The `dynamic` strategy: per-object dynamically generated impostors (Schaufler, "Dynamically
//! generated impostors", 1995; as described in Akenine-Möller et al., *Real-Time Rendering*,
//! sec. 10.7.1, and cited by TR-186-2-02-04 for the texture resolution). Nothing is baked: a
//! `lemi` bundle only supplies the view-cell grid and, per cell, the near list (the same near
//! geometry every strategy draws); the far field is turned into billboards at run time.
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
//! about 10× on the procedural city). The cropped textures are packed on shelves into
//! macro-textures of at most [`ATLAS_MAX_SIZE`] per side (the bake's GI 2002 packer takes about
//! 30 ms for the 250 billboards of the city, too slow for every frame). The cell's near list (plus the too-close far triangles)
//! and one quad per billboard with an opaque texel are drawn by [`ImpostorRenderer`] in one
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

use std::collections::{HashMap, HashSet};

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{DMat4, DVec2, DVec3, DVec4};
use lemi_core::bundle::{Bundle, Quad};
use lemi_core::camera::{Camera, View};
use lemi_core::cell::{CellId, ViewCell};
use lemi_core::compress::MacroTexture;
use lemi_core::{Aabb, Face, Mesh, Scene};
use lemi_gpu::{
    Frame, Gpu, GpuGeometry, GpuMaterials, GpuScene, ImpostorCell, ImpostorRenderer, RenderOptions,
    Renderer, UploadOptions,
};
use serde::{Deserialize, Serialize};

use crate::{
    FrameRequest, Strategy, StrategyContext, StrategyError, StrategyFrame, StrategyKind,
    StrategyReport,
};

/// Default edge of the object grid (m): a city block, a few buildings per object.
pub const DEFAULT_OBJECT_SIZE: f64 = 50.0;
/// Largest texture resolution an option may ask for.
pub const MAX_TEXTURE_RESOLUTION: u32 = 8192;
/// Largest side of a macro-texture the impostors are packed into (texels; a larger
/// `max_resolution` raises it).
pub const ATLAS_MAX_SIZE: u32 = 2048;
/// Octree levels a too-close object is split into at most.
pub const MAX_SPLIT_DEPTH: u32 = 8;

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
    /// Checks the options; the error names the option, its value and what it must be.
    pub fn validate(&self) -> Result<(), StrategyError> {
        let bad = |m: String| Err(StrategyError::Invalid(format!("dynamic strategy: {m}")));
        if !(self.object_size.is_finite() && self.object_size > 0.0) {
            return bad(format!(
                "object_size must be a finite length > 0 m (got {})",
                self.object_size
            ));
        }
        if let Some(b) = self.beta_scr {
            if !(b.is_finite() && b > 0.0 && b < std::f64::consts::FRAC_PI_2) {
                return bad(format!(
                    "beta_scr must be an angle in (0, π/2) radians (got {b})"
                ));
            }
        }
        if !(self.beta_factor.is_finite() && self.beta_factor > 0.0) {
            return bad(format!(
                "beta_factor must be finite and > 0 (got {})",
                self.beta_factor
            ));
        }
        for (name, v) in [
            ("min_resolution", self.min_resolution),
            ("max_resolution", self.max_resolution),
        ] {
            if v == 0 || !v.is_power_of_two() || v > MAX_TEXTURE_RESOLUTION {
                return bad(format!(
                    "{name} must be a power of two in 1..={MAX_TEXTURE_RESOLUTION} (got {v})"
                ));
            }
        }
        if self.min_resolution > self.max_resolution {
            return bad(format!(
                "min_resolution ({}) must not exceed max_resolution ({})",
                self.min_resolution, self.max_resolution
            ));
        }
        if !(self.min_distance_radii.is_finite() && self.min_distance_radii > 1.0) {
            return bad(format!(
                "min_distance_radii must be finite and > 1 (the eye must stay outside an object's bounding sphere; got {})",
                self.min_distance_radii
            ));
        }
        if self.dilate_texels > 4 {
            return bad(format!(
                "dilate_texels must be 0..=4 (got {})",
                self.dilate_texels
            ));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// the math of the paper

/// RTR eq. 10.5 before rounding: `screen_res · object_size / (2 · distance · tan(fov_y / 2))`.
pub fn texture_resolution_exact(
    screen_res: u32,
    fov_y: f64,
    object_size: f64,
    distance: f64,
) -> f64 {
    screen_res as f64 * object_size / (2.0 * distance * (0.5 * fov_y).tan())
}

/// RTR eq. 10.5 rounded up to a power of two and clamped to `[min, max]` (powers of two).
/// Non-finite values (distance 0) give `max`.
pub fn texture_resolution(
    screen_res: u32,
    fov_y: f64,
    object_size: f64,
    distance: f64,
    min: u32,
    max: u32,
) -> u32 {
    round_resolution(
        texture_resolution_exact(screen_res, fov_y, object_size, distance),
        min,
        max,
    )
}

/// Rounds up to a power of two (ignoring a relative excess of 1e-9, floating-point noise) and
/// clamps.
fn round_resolution(exact: f64, min: u32, max: u32) -> u32 {
    if !(exact.is_finite()) || exact >= max as f64 {
        return max;
    }
    let r = (exact * (1.0 - 1e-9)).ceil().max(1.0) as u32;
    r.next_power_of_two().clamp(min, max)
}

/// The texture resolution at which one texel of a billboard of side `object_size` seen head-on
/// from `distance` subtends the angle `beta`: `object_size / (distance · tan β)`, rounded and
/// clamped like [`texture_resolution`]. With `β = β_scr` of a view ([`view_angles`]) this is
/// eq. 10.5 for that view exactly (`tan β_scr = 2·tan(fov/2) / screenres`); the strategy uses it
/// so that a texture generated at this resolution passes the `β_tex` test also when `β` is scaled
/// or overridden.
pub fn resolution_for_angle(object_size: f64, distance: f64, beta: f64, min: u32, max: u32) -> u32 {
    round_resolution(object_size / (distance * beta.tan()), min, max)
}

/// The output view's vertical field of view (radians) and its central pixel's angle `β_scr`
/// (`atan(2·tan(fov/2) / height)`), from the projection's y scale.
pub fn view_angles(view: &View) -> Result<(f64, f64), StrategyError> {
    let f = view.proj.y_axis.y;
    if !(f.is_finite() && f > 0.0) || view.height == 0 {
        return Err(StrategyError::Invalid(format!(
            "dynamic strategy: the output view is not a perspective view with a vertical field of view (projection y scale {f}, height {})",
            view.height
        )));
    }
    let fov = 2.0 * (1.0 / f).atan();
    Ok((fov, (2.0 / (f * view.height as f64)).atan()))
}

/// Half side of the billboard that covers a sphere of radius `r` seen from distance `d > r`.
pub fn billboard_half_size(radius: f64, distance: f64) -> f64 {
    let s = (radius / distance).min(1.0 - 1e-9);
    radius / (1.0 - s * s).sqrt()
}

/// Schaufler's validity angles of an impostor generated from `gen_eye` (radians), seen from
/// `eye`; see the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidityAngles {
    pub trans: f64,
    pub size: f64,
    pub tex: f64,
}

/// The validity angles of the impostor of an object (centre, bounding radius) generated from
/// `gen_eye` with a billboard of half side `half` and `res` texels per side, seen from `eye`.
pub fn validity_angles(
    gen_eye: DVec3,
    eye: DVec3,
    centre: DVec3,
    radius: f64,
    half: f64,
    res: u32,
) -> ValidityAngles {
    let a = gen_eye - centre;
    let b = eye - centre;
    let trans = a.cross(b).length().atan2(a.dot(b));
    let (dg, dc) = (a.length(), b.length());
    let size = [1.0f64, -1.0]
        .iter()
        .map(|&s| {
            let shown = (radius * dg / ((dg - s * radius) * dc)).atan();
            let truth = (radius / (dc - s * radius)).atan();
            (shown - truth).abs()
        })
        .fold(0.0, f64::max);
    let tex = (2.0 * half / (res as f64 * dc)).atan();
    ValidityAngles { trans, size, tex }
}

// ---------------------------------------------------------------------------------------------
// objects

/// A group of far triangles drawn as one billboard.
struct Object {
    tris: Vec<[u32; 2]>,
    bounds: Aabb,
    centre: DVec3,
    radius: f64,
    /// The object's triangles on the GPU (uploaded on first generation).
    gpu: Option<GpuScene>,
    impostor: Option<Impostor>,
}

/// One generated impostor.
struct Impostor {
    eye: DVec3,
    /// Distance from the generation eye to the centre (the billboard plane's view depth).
    distance: f64,
    half: f64,
    res: u32,
    /// World corners of the whole `res × res` image: top-left, top-right, bottom-right,
    /// bottom-left.
    corners: [DVec3; 4],
    /// The rectangle `[x, y, w, h]` of the image holding every opaque texel: only it is kept,
    /// stored and drawn (empty when nothing is opaque).
    crop: [u32; 4],
    /// View depth (from `eye`) of every texel of `crop`, row-major, `INFINITY` where transparent.
    depth: Vec<f32>,
    /// Per texel of `crop`, the texel (of `crop`) whose surface point it shows: itself, or for a
    /// dilated texel the opaque neighbour its colour came from; empty without dilation (every
    /// texel is its own).
    source: Vec<u32>,
    /// sRGB RGBA of the texels of `crop`, row-major (empty when nothing is opaque).
    rgba: Vec<u8>,
}

impl Impostor {
    /// World point of image texel-edge coordinates `(i, j)` (fractional) on the billboard.
    fn point(&self, i: f64, j: f64) -> DVec3 {
        let [c0, c1, _, c3] = self.corners;
        let r = self.res as f64;
        c0 + (c1 - c0) * (i / r) + (c3 - c0) * (j / r)
    }

    /// Corners of the drawn (cropped) part.
    fn crop_corners(&self) -> [DVec3; 4] {
        let [x, y, w, h] = self.crop.map(f64::from);
        [
            self.point(x, y),
            self.point(x + w, y),
            self.point(x + w, y + h),
            self.point(x, y + h),
        ]
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

/// Which object: a scene-wide base object or one of the current cell's pieces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum ObjId {
    Base(u32),
    Local(u32),
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
    /// the view cells and their near lists. Bad options are [`StrategyError::Invalid`] naming the
    /// option.
    pub fn new(
        ctx: &StrategyContext,
        options: DynamicOptions,
    ) -> Result<DynamicStrategy, StrategyError> {
        options.validate()?;
        let max_dim = ctx.gpu.limits().max_texture_dimension_2d;
        if options.max_resolution > max_dim {
            return Err(StrategyError::Invalid(format!(
                "dynamic strategy: max_resolution {} is larger than this adapter's textures ({max_dim} per side)",
                options.max_resolution
            )));
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
        let near_set: HashSet<[u32; 2]> = file.near.iter().copied().collect();
        let cube = Aabb::new(
            cell.center - DVec3::splat(near_field),
            cell.center + DVec3::splat(near_field),
        );
        let bounds = cell.bounds();
        let k = self.options.min_distance_radii;
        let mut active = Vec::new();
        let mut local = Vec::new();
        let mut leftovers = Vec::new();
        for (i, obj) in self.base.iter_mut().enumerate() {
            let touches = boxes_overlap(&obj.bounds, &cube, 1e-6 * (1.0 + near_field));
            let far: Vec<[u32; 2]> = if touches {
                obj.tris
                    .iter()
                    .copied()
                    .filter(|t| !near_set.contains(t))
                    .collect()
            } else {
                Vec::new()
            };
            let untouched = !touches || far.len() == obj.tris.len();
            if untouched && box_distance(&bounds, obj.centre) >= k * obj.radius {
                active.push(ObjId::Base(i as u32));
                continue;
            }
            obj.impostor = None;
            let far = if untouched { obj.tris.clone() } else { far };
            split(&self.scene, far, &bounds, k, 0, &mut local, &mut leftovers);
        }
        for i in 0..local.len() {
            active.push(ObjId::Local(i as u32));
        }
        let listed_near = file.near.len();
        let mut near = file.near;
        near.extend(leftovers);
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

    /// Packs the billboards' textures into macro-textures ([`shelf_pack`]) and uploads them with
    /// the current cell's near geometry and one quad per billboard.
    fn upload(&mut self) -> Result<(), StrategyError> {
        let Some(cell) = &self.cell else {
            return Ok(());
        };
        let billboards = self.billboards();
        let sizes: Vec<(u32, u32)> = billboards.iter().map(|i| (i.crop[2], i.crop[3])).collect();
        let max_size = ATLAS_MAX_SIZE.max(self.options.max_resolution);
        let (pages, places) = shelf_pack(&sizes, max_size);
        let mut macros: Vec<MacroTexture> = pages
            .iter()
            .map(|&(w, h)| MacroTexture {
                width: w,
                height: h,
                rgba: vec![0; 4 * w as usize * h as usize],
            })
            .collect();
        let mut quads = Vec::with_capacity(billboards.len());
        for (imp, &(page, px, py)) in billboards.iter().zip(&places) {
            let [x, y, w, h] = imp.crop;
            let m = &mut macros[page];
            let (mw, row) = (m.width as usize, 4 * w as usize);
            for ty in 0..h as usize {
                let d = 4 * ((py as usize + ty) * mw + px as usize);
                m.rgba[d..d + row].copy_from_slice(&imp.rgba[ty * row..(ty + 1) * row]);
            }
            quads.push(Quad {
                face: Face::PosZ,
                // far to near, so the renderer draws near billboards first
                layer: (u16::MAX as f64 - imp.distance.min(u16::MAX as f64)) as u16,
                texels: [x, y, x + w, y + h].map(|v| v as u16),
                corners: imp.crop_corners().map(|c| c.as_vec3().to_array()),
                macro_index: page as u32,
                rect: [px, py, w, h],
                rotated: false,
            });
        }
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
                        self.failed.insert(id.clone());
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
                frame,
                cell: id.map(|i| i.to_string()),
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
            Some(d) => self.impostors.render(d, r.view, r.options)?,
            None => return Err(StrategyError::Invalid("dynamic: cell not uploaded".into())),
        };
        self.last.draw_seconds = t0.elapsed().as_secs_f64();
        let billboards = self.billboards();
        let t0 = Instant::now();
        let error_px = r
            .measure_error
            .then(|| measure_error(&frame, r.view, &billboards));
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
            cell: id.map(|i| i.to_string()),
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

// ---------------------------------------------------------------------------------------------
// helpers

/// Triangle positions in f64; `None` when an index is out of range.
fn triangle(scene: &Scene, [m, t]: [u32; 2]) -> Option<[DVec3; 3]> {
    let mesh = scene.meshes.get(m as usize)?;
    let idx = mesh.indices.get(3 * t as usize..3 * t as usize + 3)?;
    let mut out = [DVec3::ZERO; 3];
    for (o, &i) in out.iter_mut().zip(idx) {
        *o = DVec3::from(mesh.vertices.get(i as usize)?.position.map(f64::from));
    }
    Some(out)
}

/// The scene's triangles grouped by the grid cell of their centroid (see the module docs), in
/// grid order. Triangles with out-of-range or non-finite vertices are left out.
fn base_objects(scene: &Scene, size: f64) -> Vec<Object> {
    let mut groups: HashMap<[i64; 3], Vec<[u32; 2]>> = HashMap::new();
    for (m, mesh) in scene.meshes.iter().enumerate() {
        for t in 0..mesh.triangle_count() {
            let r = [m as u32, t as u32];
            let Some(v) = triangle(scene, r) else {
                continue;
            };
            let c = (v[0] + v[1] + v[2]) / 3.0;
            if !c.is_finite() {
                continue;
            }
            let key = (c / size).floor().to_array().map(|x| x as i64);
            groups.entry(key).or_default().push(r);
        }
    }
    let mut keys: Vec<[i64; 3]> = groups.keys().copied().collect();
    keys.sort_unstable();
    keys.into_iter()
        .filter_map(|k| groups.remove(&k))
        .filter_map(|tris| make_object(scene, tris))
        .collect()
}

/// An object of `tris` with its bounds and bounding sphere; `None` without triangles.
fn make_object(scene: &Scene, tris: Vec<[u32; 2]>) -> Option<Object> {
    let mut bounds = Aabb::EMPTY;
    for &r in &tris {
        for p in triangle(scene, r)? {
            bounds.grow(p);
        }
    }
    if tris.is_empty() || bounds.is_empty() {
        return None;
    }
    let centre = bounds.center();
    let mut radius: f64 = 0.0;
    for &r in &tris {
        for p in triangle(scene, r)? {
            radius = radius.max((p - centre).length());
        }
    }
    Some(Object {
        tris,
        bounds,
        centre,
        radius: radius.max(1e-6),
        gpu: None,
        impostor: None,
    })
}

/// Splits `tris` (octree on centroids) until every piece is at least `k` bounding radii from
/// every point of `cell`; pieces that cannot be split further go to `geometry`.
fn split(
    scene: &Scene,
    tris: Vec<[u32; 2]>,
    cell: &Aabb,
    k: f64,
    depth: u32,
    objects: &mut Vec<Object>,
    geometry: &mut Vec<[u32; 2]>,
) {
    let Some(obj) = make_object(scene, tris.clone()) else {
        return;
    };
    if box_distance(cell, obj.centre) >= k * obj.radius {
        objects.push(obj);
        return;
    }
    if tris.len() <= 1 || depth >= MAX_SPLIT_DEPTH {
        geometry.extend(tris);
        return;
    }
    let centroids: Vec<DVec3> = tris
        .iter()
        .map(|&r| triangle(scene, r).map_or(DVec3::ZERO, |v| (v[0] + v[1] + v[2]) / 3.0))
        .collect();
    let mut cb = Aabb::EMPTY;
    for &c in &centroids {
        cb.grow(c);
    }
    let mid = cb.center();
    let mut children: [Vec<[u32; 2]>; 8] = Default::default();
    for (&r, c) in tris.iter().zip(&centroids) {
        let i =
            (c.x > mid.x) as usize | ((c.y > mid.y) as usize) << 1 | ((c.z > mid.z) as usize) << 2;
        children[i].push(r);
    }
    if children.iter().filter(|c| !c.is_empty()).count() <= 1 {
        // every centroid in one place: no split separates them
        geometry.extend(tris);
        return;
    }
    for child in children {
        if !child.is_empty() {
            split(scene, child, cell, k, depth + 1, objects, geometry);
        }
    }
}

/// Distance from `p` to the box (0 inside).
fn box_distance(b: &Aabb, p: DVec3) -> f64 {
    (b.min - p).max(p - b.max).max(DVec3::ZERO).length()
}

fn boxes_overlap(a: &Aabb, b: &Aabb, eps: f64) -> bool {
    (a.min - eps).cmple(b.max).all() && (b.min - eps).cmple(a.max).all()
}

/// Copies triangles out of the scene, one mesh per source mesh (re-indexed).
fn extract_meshes(scene: &Scene, tris: &[[u32; 2]]) -> Vec<Mesh> {
    let mut order = tris.to_vec();
    order.sort_unstable();
    let mut out = Vec::new();
    for group in order.chunk_by(|a, b| a[0] == b[0]) {
        let Some(src) = scene.meshes.get(group[0][0] as usize) else {
            continue;
        };
        let mut remap: HashMap<u32, u32> = HashMap::new();
        let mut mesh = Mesh {
            material: src.material,
            vertices: Vec::new(),
            indices: Vec::with_capacity(3 * group.len()),
        };
        for &[_, t] in group {
            let Some(idx) = src.indices.get(3 * t as usize..3 * t as usize + 3) else {
                continue;
            };
            if idx.iter().any(|&i| i as usize >= src.vertices.len()) {
                continue;
            }
            for &i in idx {
                let n = *remap.entry(i).or_insert_with(|| {
                    mesh.vertices.push(src.vertices[i as usize]);
                    mesh.vertices.len() as u32 - 1
                });
                mesh.indices.push(n);
            }
        }
        if !mesh.indices.is_empty() {
            out.push(mesh);
        }
    }
    out
}

/// The side planes and the near plane of a reverse-Z view-projection (Gribb & Hartmann), as
/// `(normal, offset)` with unit normals pointing inside.
fn frustum_planes(vp: &DMat4) -> Vec<DVec4> {
    let (r0, r1, r2, r3) = (vp.row(0), vp.row(1), vp.row(2), vp.row(3));
    [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 - r2]
        .into_iter()
        .filter_map(|p| {
            let l = p.truncate().length();
            (l > 0.0 && l.is_finite()).then(|| p / l)
        })
        .collect()
}

fn sphere_visible(planes: &[DVec4], c: DVec3, r: f64) -> bool {
    planes.iter().all(|p| p.truncate().dot(c) + p.w >= -r)
}

/// Where a rectangle went: page, x, y.
type Place = (usize, u32, u32);

/// Packs rectangles `(w, h)` (each at most `max_size` per side) into pages on shelves: tallest
/// first, left to right, a new shelf when a row is full, a new page when a page would pass
/// `max_size`. Pages are `max_size` wide or, when everything fits in less, the power of two near
/// the square root of the total area; each page is as tall as its shelves. Returns the page sizes
/// and per rectangle (input order) its page and position. Fast (a sort), because it runs on every
/// upload; on the procedural city it fills about 80 % of the pages.
fn shelf_pack(sizes: &[(u32, u32)], max_size: u32) -> (Vec<(u32, u32)>, Vec<Place>) {
    let area: u64 = sizes.iter().map(|&(w, h)| w as u64 * h as u64).sum();
    let widest = sizes.iter().map(|s| s.0).max().unwrap_or(1);
    let width = ((area as f64).sqrt().ceil() as u32)
        .next_power_of_two()
        .max(widest)
        .min(max_size);
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(sizes[i].1), std::cmp::Reverse(sizes[i].0)));
    let mut pages: Vec<(u32, u32)> = Vec::new();
    let mut places = vec![(0usize, 0u32, 0u32); sizes.len()];
    // the current shelf: y, height, next x
    let (mut shelf_y, mut shelf_h, mut x) = (0u32, 0u32, 0u32);
    for i in order {
        let (w, h) = sizes[i];
        if pages.is_empty() || x + w > width {
            // a new shelf, on a new page if it does not fit
            let y = shelf_y + shelf_h;
            if pages.is_empty() || y + h > max_size {
                pages.push((width, 0));
                shelf_y = 0;
            } else {
                shelf_y = y;
            }
            shelf_h = h;
            x = 0;
        }
        let page = pages.len() - 1;
        places[i] = (page, x, shelf_y);
        x += w;
        pages[page].1 = pages[page].1.max(shelf_y + h);
    }
    (pages, places)
}

/// An impostor image cut down to the rectangle of its opaque texels.
struct Cropped {
    /// `[x, y, w, h]` in the image; zero-sized when nothing is opaque.
    rect: [u32; 4],
    rgba: Vec<u8>,
    depth: Vec<f32>,
    source: Vec<u32>,
}

/// Cuts a `res × res` image (colour, depth, sources as from [`dilate`]) to its opaque texels.
fn crop(rgba: &[u8], depth: &[f32], source: &[u32], res: u32) -> Cropped {
    let n = res as usize;
    let (mut x0, mut y0, mut x1, mut y1) = (n, n, 0, 0);
    for (k, z) in depth.iter().enumerate() {
        if z.is_finite() {
            let (x, y) = (k % n, k / n);
            x0 = x0.min(x);
            x1 = x1.max(x + 1);
            y0 = y0.min(y);
            y1 = y1.max(y + 1);
        }
    }
    if x1 <= x0 || y1 <= y0 {
        return Cropped {
            rect: [0; 4],
            rgba: Vec::new(),
            depth: Vec::new(),
            source: Vec::new(),
        };
    }
    let (w, h) = (x1 - x0, y1 - y0);
    let mut out = Cropped {
        rect: [x0 as u32, y0 as u32, w as u32, h as u32],
        rgba: Vec::with_capacity(4 * w * h),
        depth: Vec::with_capacity(w * h),
        source: Vec::with_capacity(if source.is_empty() { 0 } else { w * h }),
    };
    for y in y0..y1 {
        out.rgba
            .extend_from_slice(&rgba[4 * (y * n + x0)..4 * (y * n + x1)]);
        out.depth.extend_from_slice(&depth[y * n + x0..y * n + x1]);
        if !source.is_empty() {
            out.source
                .extend(source[y * n + x0..y * n + x1].iter().map(|&s| {
                    let (sx, sy) = (s as usize % n, s as usize / n);
                    ((sy - y0) * w + (sx - x0)) as u32
                }));
        }
    }
    out
}

/// Dilates an impostor texture by `passes` texels: a transparent texel with an opaque neighbour
/// (8-neighbourhood; of several, the nearest) takes its colour and depth. Returns per texel the
/// texel whose surface point it shows (empty for no passes).
fn dilate(rgba: &mut [u8], depth: &mut [f32], res: u32, passes: u32) -> Vec<u32> {
    let n = res as usize;
    if passes == 0 {
        return Vec::new();
    }
    let mut source: Vec<u32> = (0..(n * n) as u32).collect();
    for _ in 0..passes {
        let mut grown: Vec<(usize, usize)> = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let idx = j * n + i;
                if depth[idx].is_finite() {
                    continue;
                }
                let mut best: Option<usize> = None;
                for dj in -1i64..=1 {
                    for di in -1i64..=1 {
                        let (x, y) = (i as i64 + di, j as i64 + dj);
                        if (di, dj) == (0, 0) || x < 0 || y < 0 || x >= n as i64 || y >= n as i64 {
                            continue;
                        }
                        let k = y as usize * n + x as usize;
                        if depth[k].is_finite() && best.is_none_or(|b| depth[k] < depth[b]) {
                            best = Some(k);
                        }
                    }
                }
                if let Some(b) = best {
                    grown.push((idx, b));
                }
            }
        }
        if grown.is_empty() {
            break;
        }
        for (idx, b) in grown {
            depth[idx] = depth[b];
            source[idx] = source[b];
            rgba.copy_within(4 * b..4 * b + 4, 4 * idx);
        }
    }
    source
}

/// The per-pixel error of a frame (see the module docs).
fn measure_error(frame: &Frame, view: &View, billboards: &[&Impostor]) -> Vec<f32> {
    use rayon::prelude::*;
    let (w, h) = (frame.width as usize, frame.height as usize);
    let vp = view.view_proj();
    let inv = vp.inverse();
    let eye = view.eye();
    let depth_axis = -DVec3::new(view.view.x_axis.z, view.view.y_axis.z, view.view.z_axis.z);
    let project = |p: DVec3| -> Option<DVec2> {
        let c = vp * p.extend(1.0);
        (c.w > 0.0).then(|| view.ndc_to_pixel(DVec2::new(c.x / c.w, c.y / c.w)))
    };
    // per billboard: plane, edges and screen rectangle (x0, x1, y0, y1)
    struct Prepared<'a> {
        imp: &'a Impostor,
        normal: DVec3,
        centre: DVec3,
        du: DVec3,
        dv: DVec3,
        rect: (usize, usize, usize, usize),
    }
    let planes = frustum_planes(&vp);
    let prepared: Vec<Prepared> = billboards
        .iter()
        .filter(|imp| {
            // not wholly outside one plane of the view frustum
            let corners = imp.crop_corners();
            planes
                .iter()
                .all(|p| corners.iter().any(|c| p.truncate().dot(*c) + p.w >= 0.0))
        })
        .map(|imp| {
            let [c0, c1, c2, c3] = imp.corners;
            let centre = (c0 + c2) * 0.5;
            let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
            let mut behind = false;
            for c in imp.crop_corners() {
                match project(c) {
                    Some(p) => {
                        lo = lo.min(p);
                        hi = hi.max(p);
                    }
                    None => behind = true,
                }
            }
            let rect = if behind {
                (0, w, 0, h)
            } else {
                let clampx = |v: f64| (v.max(0.0) as usize).min(w);
                let clampy = |v: f64| (v.max(0.0) as usize).min(h);
                (
                    clampx(lo.x.floor() - 1.0),
                    clampx(hi.x.ceil() + 1.0),
                    clampy(lo.y.floor() - 1.0),
                    clampy(hi.y.ceil() + 1.0),
                )
            };
            Prepared {
                imp,
                normal: (imp.eye - centre).normalize(),
                centre,
                du: c1 - c0,
                dv: c3 - c0,
                rect,
            }
        })
        .collect();
    let mut out = vec![f32::NAN; w * h];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let mut best = vec![f32::INFINITY; w];
            let rays: Vec<DVec3> = (0..w)
                .map(|x| {
                    let ndc = view.pixel_to_ndc(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                    let p0 = inv * DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
                    let p1 = inv * DVec4::new(ndc.x, ndc.y, 0.5, 1.0);
                    p1.truncate() / p1.w - p0.truncate() / p0.w
                })
                .collect();
            for b in prepared.iter().filter(|b| b.rect.2 <= y && y < b.rect.3) {
                let imp = b.imp;
                let res = imp.res as usize;
                let c0 = imp.corners[0];
                let margin = 1.0 / 16.0 + 1e-6;
                let [cx, cy, cw, ch] = imp.crop.map(|v| v as usize);
                for x in b.rect.0..b.rect.1 {
                    let z = frame.depth[y * w + x];
                    if !z.is_finite() {
                        continue;
                    }
                    let dir = rays[x];
                    let denom = b.normal.dot(dir);
                    if denom.abs() < 1e-12 {
                        continue;
                    }
                    let t = b.normal.dot(b.centre - eye) / denom;
                    if t <= 0.0 {
                        continue;
                    }
                    let p = eye + dir * t;
                    let vd = depth_axis.dot(p - eye);
                    let score = ((vd - z as f64).abs() / (z as f64).max(1e-6)) as f32;
                    if score > 2e-4 || score >= best[x] {
                        continue;
                    }
                    // image texel coordinates, then the drawn (cropped) rectangle grown as the
                    // impostor renderer grows quads
                    let u = (p - c0).dot(b.du) / b.du.length_squared() * res as f64;
                    let v = (p - c0).dot(b.dv) / b.dv.length_squared() * res as f64;
                    let (fu, fv) = (u - cx as f64, v - cy as f64);
                    if fu < -margin
                        || fu > cw as f64 + margin
                        || fv < -margin
                        || fv > ch as f64 + margin
                    {
                        continue;
                    }
                    let ci = (fu.floor().max(0.0) as usize).min(cw - 1);
                    let cj = (fv.floor().max(0.0) as usize).min(ch - 1);
                    let k = cj * cw + ci;
                    if !imp.depth[k].is_finite() {
                        continue;
                    }
                    let (i, j) = (ci + cx, cj + cy);
                    // the true point of the texel whose colour this texel shows
                    let src = imp.source.get(k).map_or(k, |&s| s as usize);
                    let (si, sj) = (src % cw + cx, src / cw + cy);
                    let centre_of = |i: usize, j: usize| {
                        c0 + b.du * ((i as f64 + 0.5) / res as f64)
                            + b.dv * ((j as f64 + 0.5) / res as f64)
                    };
                    let l = centre_of(i, j);
                    let ls = centre_of(si, sj);
                    let truth = imp.eye + (ls - imp.eye) * (imp.depth[src] as f64 / imp.distance);
                    row[x] = match (project(truth), project(l)) {
                        (Some(q), Some(s)) => (q - s).length() as f32,
                        _ => f32::NAN,
                    };
                    best[x] = score;
                }
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shelves_hold_every_rectangle_without_overlap() {
        let sizes: Vec<(u32, u32)> = (0..200u32)
            .map(|i| (1 + (i * 37) % 300, 1 + (i * 53) % 200))
            .chain([(512, 512), (512, 3), (1, 512)])
            .collect();
        let (pages, places) = shelf_pack(&sizes, 512);
        assert!(pages.len() > 1);
        let mut used: Vec<Vec<bool>> = pages
            .iter()
            .map(|&(w, h)| {
                assert!(w <= 512 && h <= 512);
                vec![false; (w * h) as usize]
            })
            .collect();
        for (&(w, h), &(p, x, y)) in sizes.iter().zip(&places) {
            let (pw, ph) = pages[p];
            assert!(
                x + w <= pw && y + h <= ph,
                "{w}x{h} at {x},{y} in {pw}x{ph}"
            );
            for j in y..y + h {
                for i in x..x + w {
                    let k = (j * pw + i) as usize;
                    assert!(!used[p][k], "overlap at page {p} ({i}, {j})");
                    used[p][k] = true;
                }
            }
        }
        let (pages, places) = shelf_pack(&[], 512);
        assert!(pages.is_empty() && places.is_empty());
    }
}
