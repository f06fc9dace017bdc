//! The eval job: for every evaluated cell of a bundle, viewpoints at the centre, the corners, the
//! face and edge midpoints and random interior points ([`lemi_core::cell::eval_viewpoints`]), view
//! directions covering every baked face and their diagonals
//! ([`lemi_core::cell::eval_directions`]), each rendered as reference (all geometry) and impostor
//! image (near geometry + quads) at the output view the bake assumed, compared by
//! [`crate::evaluate_view`] with the measured per-pixel parallax error
//! ([`lemi_core::parallax_error`]; the layers' per-texel depths are re-recorded for it).

use std::sync::Arc;

use glam::DVec3;
use lemi_core::bundle::{Bundle, CellFile, Manifest};
use lemi_core::camera::{Camera, View};
use lemi_core::cell::{eval_directions, eval_viewpoints, CellId, ViewCell};
use lemi_core::classify::TriRef;
use lemi_core::compress::TextureFormat;
use lemi_core::object_cell::{canonical_scene, complement};
use lemi_core::parallax_error::{pixel_errors, LayerDepths};
use lemi_core::Scene;
use lemi_gpu::{
    CellRecorder, Frame, Gpu, GpuMaterials, GpuScene, ImpostorCell, ImpostorRenderer,
    RenderOptions, Renderer, UploadOptions,
};

use crate::report::{BundleResult, CellResult, OutlineStats, WorstSet, WorstView};
use crate::{
    evaluate_view, ppd_for_view, silhouettes_within, EvalError, GuardBand, PixelErrorStats,
    WORST_PER_BUNDLE,
};

/// Which viewpoints of a cell to evaluate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewpointSet {
    /// Centre, 8 corners, 6 face midpoints, 12 edge midpoints and the random ones.
    Full,
    /// Centre and the 8 corners (and the random ones).
    Corners,
}

/// Parameters of an evaluation.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Cell ids to evaluate (`None`: every baked cell).
    pub cells: Option<Vec<CellId>>,
    pub set: ViewpointSet,
    /// Random interior viewpoints per cell.
    pub random_viewpoints: usize,
    pub seed: u64,
    /// Output size; default: the bake's output width at 16:9 (1280×720 without one).
    pub size: Option<(u32, u32)>,
    /// Horizontal field of view in degrees; default: the bake's (60° without one).
    pub fov_x_deg: Option<f64>,
    /// Background colour of both renders.
    pub clear: [u8; 4],
    /// Also measure each view's silhouette distance for the geometry against itself seen turned
    /// by this many pixels right and up ([`turned_camera`]): the floor the metric has for any
    /// renderer that moves points by that much (sub-pixel features that one sampling of the
    /// pixel grid shows and another does not). One more reference render per view.
    pub silhouette_floor_px: Option<f64>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            cells: None,
            set: ViewpointSet::Full,
            random_viewpoints: 4,
            seed: 1,
            size: None,
            fov_x_deg: None,
            clear: [150, 190, 235, 255],
            silhouette_floor_px: None,
        }
    }
}

/// The result of [`evaluate_bundle`].
pub struct EvalRun {
    pub result: BundleResult,
    pub worst: Vec<WorstView>,
    /// The error of pixels showing a layer's own texels: the placement's parallax error.
    pub placement: PixelErrorStats,
    /// The error of pixels showing texels filled from an adjacent layer: gap filling (GI 2002
    /// sec. 5.1) and, when the bake made them, outline copies.
    pub gap_filled: PixelErrorStats,
    /// What the evaluated cells take on disk and in texture memory (layered bundles).
    pub textures: Option<TextureFootprint>,
    /// The same views compared with another bake's ([`evaluate_bundle_against`]).
    pub against: Option<AgainstResult>,
}

/// What the evaluated cells of a layered bundle take, per cell: the cell file on disk, its
/// macro-textures as stored (PNG or KTX2), and the texture memory they occupy in their stored
/// format (RGBA8 for PNG, the blocks for BC7 and BC1).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TextureFootprint {
    pub format: TextureFormat,
    pub cells: u64,
    pub disk_bytes_per_cell: f64,
    pub texture_bytes_per_cell: f64,
    pub texture_memory_bytes_per_cell: f64,
}

impl TextureFootprint {
    fn add(&mut self, disk: u64, stats: &lemi_core::bundle::CellStats) {
        let n = self.cells as f64;
        let mean = |old: f64, x: u64| (old * n + x as f64) / (n + 1.0);
        self.disk_bytes_per_cell = mean(self.disk_bytes_per_cell, disk);
        self.texture_bytes_per_cell = mean(self.texture_bytes_per_cell, stats.texture_bytes());
        self.texture_memory_bytes_per_cell = mean(
            self.texture_memory_bytes_per_cell,
            stats.texture_memory_bytes(),
        );
        self.cells += 1;
    }

    /// One line: format, disk, stored textures and texture memory per cell.
    pub fn describe(&self) -> String {
        format!(
            "{}: {:.0} KB per cell file, of it {:.0} KB of macro-textures, {:.0} KB of texture \
             memory per cell ({} cells)",
            self.format.name(),
            self.disk_bytes_per_cell / 1e3,
            self.texture_bytes_per_cell / 1e3,
            self.texture_memory_bytes_per_cell / 1e3,
            self.cells
        )
    }
}

/// The evaluated views of a bundle compared with the same views of another bake of the same
/// scene and cells (e.g. a block-compressed bake against its PNG bake): what the other bake's
/// frame would have shown instead. A texture format that keeps every texel's alpha exact
/// changes no pixel's coverage where both bakes pack their atlases alike; where the packings
/// differ (the block formats pad micro-textures to 4×4 blocks, PNG does not), a fragment on a
/// texel edge can still round to the neighbouring texel (about one pixel in ten million).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct AgainstResult {
    pub bundle: std::path::PathBuf,
    pub format: TextureFormat,
    pub views: u64,
    /// Mean over the views of the mean FLIP of this bake's frame against the other's.
    pub mean_flip: f32,
    pub max_flip: f32,
    /// PSNR over RGB pooled over the views (by mean squared error); `None`: identical frames.
    pub psnr: Option<f64>,
    /// Pixels whose colour differs at all.
    pub differing_pixels: u64,
    /// Pixels covered in one frame and not in the other.
    pub coverage_mismatch_pixels: u64,
    pub pixels: u64,
}

impl AgainstResult {
    /// One line: the image cost against the other bake.
    pub fn describe(&self) -> String {
        format!(
            "against {} ({}): mean FLIP {:.4} (max {:.4}), PSNR {}, {:.3} % of pixels differ, \
             {} pixels of changed coverage over {} views",
            self.bundle.display(),
            self.format.name(),
            self.mean_flip,
            self.max_flip,
            self.psnr
                .map_or("infinite (identical)".to_string(), |p| format!("{p:.2} dB")),
            100.0 * self.differing_pixels as f64 / self.pixels.max(1) as f64,
            self.coverage_mismatch_pixels,
            self.views
        )
    }
}

/// Accumulates [`AgainstResult`] view by view.
#[derive(Default)]
struct AgainstAcc {
    views: u64,
    flip_sum: f64,
    max_flip: f32,
    mse_sum: f64,
    differing: u64,
    coverage: u64,
    pixels: u64,
}

impl AgainstAcc {
    fn add(&mut self, other: &Frame, this: &Frame, ppd: f32) -> Result<(), EvalError> {
        let flip = crate::flip(other, this, ppd)?;
        self.flip_sum += flip.mean as f64;
        self.max_flip = self.max_flip.max(flip.mean);
        self.mse_sum += crate::mse_rgb(other, this)?;
        for (i, (a, b)) in other
            .rgba
            .chunks_exact(4)
            .zip(this.rgba.chunks_exact(4))
            .enumerate()
        {
            self.differing += u64::from(a[..3] != b[..3]);
            let covered = |f: &Frame| f.depth.get(i).is_some_and(|d| d.is_finite());
            self.coverage += u64::from(covered(other) != covered(this));
        }
        self.pixels += other.depth.len() as u64;
        self.views += 1;
        Ok(())
    }

    fn finish(self, bundle: &Bundle) -> AgainstResult {
        let n = self.views.max(1) as f64;
        let psnr = crate::psnr_from_mse(self.mse_sum / n);
        AgainstResult {
            bundle: bundle.dir().to_path_buf(),
            format: bundle.manifest().params.texture_format,
            views: self.views,
            mean_flip: (self.flip_sum / n) as f32,
            max_flip: self.max_flip,
            psnr: psnr.is_finite().then_some(psnr),
            differing_pixels: self.differing,
            coverage_mismatch_pixels: self.coverage,
            pixels: self.pixels,
        }
    }
}

/// The geometric error split into own and filled (gap-filled or copied) texels.
struct Breakdown {
    cell: String,
    own: PixelErrorStats,
    gap: PixelErrorStats,
}

impl Breakdown {
    fn describe(&self) -> String {
        let n = (self.own.count() + self.gap.count()).max(1) as f64;
        format!(
            "layers' own texels: max {:.2} px, p99 {:.2} px over {} pixels; gap-filled or copied \
             texels: {:.2} % of impostor pixels, max {:.2} px, p99 {:.2} px",
            self.own.max(),
            self.own.p99(),
            self.own.count(),
            100.0 * self.gap.count() as f64 / n,
            self.gap.max(),
            self.gap.p99()
        )
    }
}

fn err(m: impl Into<String>) -> EvalError {
    EvalError::Job(m.into())
}

/// Output size and horizontal fov of an evaluation.
pub fn output_view(manifest: &Manifest, options: &EvalOptions) -> (u32, u32, f64) {
    let fov = options
        .fov_x_deg
        .or(manifest.params.output_fov_deg)
        .unwrap_or(60.0);
    let (w, h) = options.size.unwrap_or_else(|| {
        let w = manifest.params.output_width.unwrap_or(1280);
        (w, (w * 9 / 16).max(1))
    });
    (w, h, fov)
}

/// A camera at `eye` looking along `dir` with horizontal fov `fov_x` (degrees), as the
/// evaluation places it.
pub fn camera(eye: DVec3, dir: DVec3, fov_x: f64, w: u32, h: u32) -> Result<Camera, EvalError> {
    let fov_y = 2.0
        * ((0.5 * fov_x.to_radians()).tan() * h as f64 / w as f64)
            .atan()
            .to_degrees();
    Camera::new(eye, dir, world_up(dir), fov_y, w, h).map_err(|e| err(format!("camera: {e}")))
}

/// The guard band of a view whose outline distances reach the image's edge
/// ([`SilhouetteStats::edge_bound`]): distances up to this many pixels are then exact at the edge
/// too, larger ones may still be overstated there (never understated). The silhouette aims are
/// about 1-2 px; 8 px measures what lies between.
pub const GUARD_BAND_PX: u32 = 8;

/// The camera of [`camera`] with a guard band: `band.px` more pixels on every side of the
/// `band.width × band.height` view of horizontal field of view `fov_x` (degrees), at the same focal
/// length, so that the view's pixels are the frame's `[px, px + width) × [px, px + height)`.
pub fn guard_band_camera(
    eye: DVec3,
    dir: DVec3,
    fov_x: f64,
    band: GuardBand,
) -> Result<Camera, EvalError> {
    let (w, g) = (f64::from(band.width), f64::from(band.px));
    let wide_fov_x = 2.0
        * ((0.5 * fov_x.to_radians()).tan() * (w + 2.0 * g) / w)
            .atan()
            .to_degrees();
    camera(
        eye,
        dir,
        wide_fov_x,
        band.width + 2 * band.px,
        band.height + 2 * band.px,
    )
}

/// The up vector [`camera`] builds its frame with: +Y, or +Z for a direction near the vertical.
fn world_up(dir: DVec3) -> DVec3 {
    if dir.normalize().y.abs() > 0.9 {
        DVec3::Z
    } else {
        DVec3::Y
    }
}

/// The camera of [`camera`] turned so that the image moves by `px` pixels right and `px` up at
/// its centre (elsewhere by that much within the turn's distortion, a few tens of percent at the
/// edges of a 60° view), without moving the eye: the same scene sampled at another phase of the
/// pixel grid.
pub fn turned_camera(
    eye: DVec3,
    dir: DVec3,
    fov_x: f64,
    w: u32,
    h: u32,
    px: f64,
) -> Result<Camera, EvalError> {
    if !px.is_finite() || w == 0 {
        return Err(err(format!("cannot turn a {w} px wide view by {px} px")));
    }
    let d = dir.normalize();
    let right = d.cross(world_up(d)).normalize();
    let up = right.cross(d);
    // px pixels of the image plane at distance 1
    let t = px * 2.0 * (0.5 * fov_x.to_radians()).tan() / f64::from(w);
    camera(eye, d - t * right - t * up, fov_x, w, h)
}

/// What the evaluation asks of the images it judges: one view of one cell at a time.
pub trait CellRenderer {
    /// Gets ready to render views of `cell` (called once per cell, before its views).
    fn begin_cell(&mut self, cell: &ViewCell) -> Result<(), EvalError>;
    /// Renders the current cell from `view` with the eye at `eye`.
    fn render(&mut self, view: &View, eye: DVec3) -> Result<RenderedView, EvalError>;
    /// The depth a pixel may show beyond the farthest reference depth `far` of its 3×3
    /// neighbourhood before it counts as a crack ([`crate::image_metrics::crack_pixels`]);
    /// `f32::INFINITY`: only pixels showing background where the reference has a surface.
    fn crack_tolerance(&self, far: f32) -> f32;
}

/// One rendered view and its measured geometric error.
pub struct RenderedView {
    pub frame: Frame,
    /// Per pixel (row-major): the geometric error in output pixels, NaN where it does not apply
    /// or was not measured.
    pub error_px: Vec<f32>,
    /// Per pixel: whether it shows a gap-filled texel (layered impostors), if known.
    pub gap_filled: Option<Vec<bool>>,
}

/// The layered impostors of a bundle's cells, with their geometric error measured against the
/// layers' per-texel depths, re-recorded for every cell.
struct LayeredCells<'a> {
    gpu: &'a Gpu,
    bundle: &'a Bundle,
    scene: &'a Scene,
    materials: Arc<GpuMaterials>,
    renderer: ImpostorRenderer,
    /// Re-records the layers' depths to measure the geometric error (`None`: frames only).
    recorder: Option<CellRecorder<'a>>,
    render_options: RenderOptions,
    current: Option<(ViewCell, CellFile, ImpostorCell, Option<LayerDepths>)>,
    footprint: TextureFootprint,
}

impl CellRenderer for LayeredCells<'_> {
    fn begin_cell(&mut self, cell: &ViewCell) -> Result<(), EvalError> {
        let id = cell.id();
        let gpu_err = |what: String| move |e: lemi_gpu::GpuError| err(format!("{what}: {e}"));
        self.current = None;
        let file = self.bundle.cell(id).map_err(|e| err(e.to_string()))?;
        // block-compressed macro-textures as the runtime uploads them: as stored where the
        // adapter has the format
        let gpu_cell =
            ImpostorCell::upload_file(self.gpu, self.materials.clone(), self.scene, &file)
                .map_err(gpu_err(format!("uploading cell {id}")))?;
        let depths = match (&self.recorder, &self.bundle.manifest().object) {
            (None, _) => None,
            (Some(recorder), None) => Some(recorder.record_depths(cell)),
            (Some(recorder), Some(o)) => {
                let placement = o.place().map_err(|e| err(format!("cell {id}: {e}")))?;
                Some(
                    recorder
                        .record_depths_planned(&o.canonical_cell(), &o.plan(&placement))
                        .map(|d| LayerDepths {
                            frame: Some(o.frame),
                            ..d
                        }),
                )
            }
        }
        .transpose()
        .map_err(|e| err(format!("cell {id}: {e}")))?;
        let disk = self.bundle.entry(id).map_or(0, |e| e.bytes);
        self.footprint.add(disk, &file.header.stats);
        self.current = Some((*cell, file, gpu_cell, depths));
        Ok(())
    }

    fn render(&mut self, view: &View, _eye: DVec3) -> Result<RenderedView, EvalError> {
        let Some((_, _, gpu_cell, depths)) = &self.current else {
            return Err(err("no cell to render (begin_cell was not called)"));
        };
        let frame = self
            .renderer
            .render(gpu_cell, view, &self.render_options)
            .map_err(|e| err(format!("impostor render: {e}")))?;
        let Some(depths) = depths else {
            let n = frame.depth.len();
            return Ok(RenderedView {
                frame,
                error_px: vec![f32::NAN; n],
                gap_filled: None,
            });
        };
        let geometric = pixel_errors(
            view,
            &frame.depth,
            depths,
            1e-4,
            lemi_gpu::impostor::QUAD_GROWTH_TEXELS,
        );
        Ok(RenderedView {
            frame,
            error_px: geometric.error_px,
            gap_filled: Some(geometric.gap_filled),
        })
    }

    fn crack_tolerance(&self, far: f32) -> f32 {
        match &self.current {
            Some((cell, file, _, _)) => crate::compare::layer_slab_tolerance(file, cell, far),
            None => f32::INFINITY,
        }
    }
}

/// Evaluates the cells of a bundle. `progress(done, total, what)` is called before every view.
pub fn evaluate_bundle(
    gpu: &Gpu,
    bundle: &Bundle,
    scene: &Scene,
    options: &EvalOptions,
    progress: impl FnMut(usize, usize, &str),
) -> Result<EvalRun, EvalError> {
    evaluate_bundle_against(gpu, bundle, scene, None, options, progress)
}

/// Checks that `other` is another bake of `bundle`'s scene with every cell `options` evaluates,
/// so that the same views of both can be compared.
fn check_against(bundle: &Bundle, other: &Bundle, ids: &[CellId]) -> Result<(), EvalError> {
    let (a, b) = (bundle.manifest(), other.manifest());
    let what = other.dir().display();
    if a.scene.fingerprint != b.scene.fingerprint {
        return Err(err(format!(
            "{what} was baked from another scene (fingerprint {} against {}): only bakes of the \
             same scene can be compared",
            b.scene.fingerprint, a.scene.fingerprint
        )));
    }
    if a.grid != b.grid || a.object != b.object {
        return Err(err(format!(
            "{what} has other view cells than {}: only bakes of the same cells can be compared",
            bundle.dir().display()
        )));
    }
    if let Some(id) = ids.iter().find(|id| other.entry(**id).is_none()) {
        return Err(err(format!("{what} has no cell {id}")));
    }
    Ok(())
}

/// Evaluates the cells of a bundle like [`evaluate_bundle`] and, with `against`, renders the
/// same views with that other bake of the same scene and cells and compares the frames
/// ([`EvalRun::against`]): the image cost of, e.g., a block-compressed texture format against
/// the lossless PNG bake.
pub fn evaluate_bundle_against(
    gpu: &Gpu,
    bundle: &Bundle,
    scene: &Scene,
    against: Option<&Bundle>,
    options: &EvalOptions,
    progress: impl FnMut(usize, usize, &str),
) -> Result<EvalRun, EvalError> {
    let materials = Arc::new(
        GpuMaterials::upload(gpu, &scene.materials, &scene.textures)
            .map_err(|e| err(format!("uploading materials: {e}")))?,
    );
    let manifest = bundle.manifest();
    if let Some(other) = against {
        let ids = options.cells.clone().unwrap_or_else(|| bundle.cell_ids());
        check_against(bundle, other, &ids)?;
    }
    // an object bundle's layers are re-recorded from the object's triangles (every one its cell
    // does not draw as geometry) in its canonical frame
    let object_scene = match &manifest.object {
        None => None,
        Some(o) => {
            let id = bundle
                .cell_ids()
                .first()
                .copied()
                .ok_or_else(|| err("the object bundle has no cell"))?;
            let file = bundle.cell(id).map_err(|e| err(e.to_string()))?;
            let drawn: Vec<TriRef> = file
                .near
                .iter()
                .map(|&[mesh, tri]| TriRef { mesh, tri })
                .collect();
            let object: Vec<TriRef> = complement(scene, &drawn)
                .into_iter()
                .map(|[mesh, tri]| TriRef { mesh, tri })
                .collect();
            Some(
                canonical_scene(scene, &object, &o.frame)
                    .map_err(|e| err(format!("cell {id}: {e}")))?,
            )
        }
    };
    let recorder = CellRecorder::new(
        gpu,
        object_scene.as_ref().unwrap_or(scene),
        manifest.params.clone(),
    )
    .map_err(|e| err(format!("preparing to re-record depths: {e}")))?;
    let mut cells = LayeredCells::new(
        gpu,
        bundle,
        scene,
        materials.clone(),
        Some(recorder),
        options,
    )?;
    let mut other = match against {
        Some(b) => Some(LayeredCells::new(gpu, b, scene, materials, None, options)?),
        None => None,
    };
    let (mut run, acc) = evaluate_views(
        gpu,
        bundle,
        scene,
        options,
        &mut cells,
        other.as_mut().map(|o| o as &mut dyn CellRenderer),
        progress,
    )?;
    run.against = against.map(|b| acc.finish(b));
    run.textures = Some(cells.footprint.clone());
    if let Some(t) = &run.textures {
        run.result.info.insert("textures".into(), t.describe());
    }
    if let Some(a) = &run.against {
        run.result.info.insert("against".into(), a.describe());
    }
    Ok(run)
}

impl<'a> LayeredCells<'a> {
    fn new(
        gpu: &'a Gpu,
        bundle: &'a Bundle,
        scene: &'a Scene,
        materials: Arc<GpuMaterials>,
        recorder: Option<CellRecorder<'a>>,
        options: &EvalOptions,
    ) -> Result<Self, EvalError> {
        Ok(LayeredCells {
            gpu,
            bundle,
            scene,
            materials,
            renderer: ImpostorRenderer::new(gpu)
                .map_err(|e| err(format!("impostor renderer: {e}")))?,
            recorder,
            render_options: RenderOptions {
                clear: options.clear,
                ..Default::default()
            },
            current: None,
            footprint: TextureFootprint {
                format: bundle.manifest().params.texture_format,
                ..Default::default()
            },
        })
    }
}

/// A labelled viewpoint and the labelled view directions judged from it.
pub type EvalViewpoint = (String, DVec3, Vec<(String, DVec3)>);

/// The viewpoints of `cell` and the directions judged from each, with labels: for a cell of an
/// environment-map bundle its centre, corners, midpoints and random points
/// ([`eval_viewpoints`]), each looking along every baked face and their diagonals
/// ([`eval_directions`]); for an object bundle the viewpoints over its box or shaft
/// ([`lemi_core::object_cell::ObjectViewCell::eval_viewpoints`]), each looking at the object's
/// centre. [`ViewpointSet::Corners`] keeps the centres, corners and random points.
pub fn eval_views(
    manifest: &Manifest,
    cell: &ViewCell,
    options: &EvalOptions,
) -> Vec<EvalViewpoint> {
    let (points, directions) = match &manifest.object {
        Some(o) => (
            o.cell
                .eval_viewpoints(options.random_viewpoints, options.seed),
            None,
        ),
        None => (
            eval_viewpoints(cell, options.random_viewpoints, options.seed),
            Some(eval_directions(&manifest.params.faces)),
        ),
    };
    points
        .into_iter()
        .filter(|(l, _)| {
            options.set == ViewpointSet::Full
                || l.ends_with("centre")
                || l.contains("corner")
                || l.starts_with("random")
        })
        .map(|(label, eye)| {
            let dirs = match (&directions, &manifest.object) {
                (Some(d), _) => d.clone(),
                (None, Some(o)) => vec![(
                    "at the object".to_string(),
                    (o.object_centre() - eye).normalize_or(o.frame.forward),
                )],
                (None, None) => Vec::new(),
            };
            (label, eye, dirs)
        })
        .collect()
}

/// Evaluates the cells of a bundle as `renderer` draws them (any far-field strategy): the same
/// viewpoints, directions, output view and metrics as [`evaluate_bundle`].
pub fn evaluate_with(
    gpu: &Gpu,
    bundle: &Bundle,
    scene: &Scene,
    options: &EvalOptions,
    renderer: &mut dyn CellRenderer,
    progress: impl FnMut(usize, usize, &str),
) -> Result<EvalRun, EvalError> {
    evaluate_views(gpu, bundle, scene, options, renderer, None, progress).map(|(run, _)| run)
}

/// [`evaluate_with`], and with `against` the same views rendered by it and compared with
/// `renderer`'s frames ([`EvalRun::against`]).
fn evaluate_views(
    gpu: &Gpu,
    bundle: &Bundle,
    scene: &Scene,
    options: &EvalOptions,
    renderer: &mut dyn CellRenderer,
    mut against: Option<&mut dyn CellRenderer>,
    mut progress: impl FnMut(usize, usize, &str),
) -> Result<(EvalRun, AgainstAcc), EvalError> {
    let manifest = bundle.manifest();
    let ids: Vec<CellId> = match &options.cells {
        Some(c) => c.clone(),
        None => bundle.cell_ids(),
    };
    if ids.is_empty() {
        return Err(err(format!(
            "{}: no cells to evaluate",
            bundle.dir().display()
        )));
    }
    let (w, h, fov_x) = output_view(manifest, options);
    if w == 0 || h == 0 || !(fov_x > 0.0 && fov_x < 180.0) {
        return Err(err(format!(
            "output view {w}x{h} with {fov_x}° horizontal fov is not usable"
        )));
    }
    let ppd = ppd_for_view(w, fov_x as f32);
    let gpu_err = |what: &str| {
        let what = what.to_string();
        move |e: lemi_gpu::GpuError| err(format!("{what}: {e}"))
    };
    let full = GpuScene::upload(gpu, scene, &UploadOptions::default())
        .map_err(gpu_err("uploading the scene"))?;
    let reference_renderer = Renderer::new(gpu).map_err(gpu_err("reference renderer"))?;
    let render_options = RenderOptions {
        clear: options.clear,
        ..Default::default()
    };
    let mut cells = Vec::with_capacity(ids.len());
    let mut worst = WorstSet::new(WORST_PER_BUNDLE);
    let mut points_per_cell = Vec::new();
    let mut breakdown = Vec::new();
    let mut against_acc = AgainstAcc::default();
    for id in &ids {
        let cell = manifest
            .grid
            .cell_of(*id)
            .map_err(|e| err(format!("--cells: {e}")))?;
        points_per_cell.push((cell, eval_views(manifest, &cell, options)));
    }
    let total: usize = points_per_cell.iter().map(|(_, p)| p.len()).sum();
    let mut done = 0;
    for (cell, points) in &points_per_cell {
        let id = cell.id().to_string();
        progress(done, total, &format!("cell {id}: preparing"));
        renderer.begin_cell(cell)?;
        if let Some(a) = against.as_deref_mut() {
            a.begin_cell(cell)?;
        }
        let mut stats = PixelErrorStats::new();
        let mut own = PixelErrorStats::new();
        let mut gap = PixelErrorStats::new();
        let mut outlines = OutlineStats::default();
        let mut views = Vec::new();
        for (label, eye, directions) in points {
            for (dname, dir) in directions {
                progress(done, total, &format!("cell {id}: {label}, looking {dname}"));
                done += 1;
                let cam = camera(*eye, *dir, fov_x, w, h)?;
                let view = cam.view();
                let reference = reference_renderer
                    .render(&full, &view, &render_options)
                    .map_err(gpu_err("reference render"))?;
                let rendered = renderer.render(&view, *eye)?;
                if let Some(a) = against.as_deref_mut() {
                    let other = a.render(&view, *eye)?;
                    against_acc.add(&other.frame, &rendered.frame, ppd)?;
                }
                match &rendered.gap_filled {
                    Some(g) => {
                        for (e, &g) in rendered.error_px.iter().zip(g) {
                            if g {
                                gap.add(*e);
                            } else {
                                own.add(*e);
                            }
                        }
                    }
                    None => {
                        for e in &rendered.error_px {
                            own.add(*e);
                        }
                    }
                }
                let impostor = rendered.frame;
                let tol = |i: usize, r: f32| {
                    crate::compare::neighbourhood_tolerance(&reference, i, r, |far| {
                        renderer.crack_tolerance(far)
                    })
                };
                let mut e = evaluate_view(&reference, &impostor, &rendered.error_px, &tol, ppd)?;
                if e.silhouette.edge_bound {
                    // a distance at the image's edge may reach beyond it: measure the outlines
                    // again in frames a guard band wider (the same focal length)
                    let band = GuardBand {
                        px: GUARD_BAND_PX,
                        width: w,
                        height: h,
                    };
                    let wide = guard_band_camera(*eye, *dir, fov_x, band)?.view();
                    let reference = reference_renderer
                        .render(&full, &wide, &render_options)
                        .map_err(gpu_err("reference render"))?;
                    let impostor = renderer.render(&wide, *eye)?.frame;
                    e.silhouette = silhouettes_within(&reference, &impostor, band)?;
                }
                let floor = match options.silhouette_floor_px {
                    Some(px) => {
                        let turned = turned_camera(*eye, *dir, fov_x, w, h, px)?.view();
                        let turned = reference_renderer
                            .render(&full, &turned, &render_options)
                            .map_err(gpu_err("reference render"))?;
                        Some(crate::image_metrics::silhouettes(&reference, &turned)?)
                    }
                    None => None,
                };
                stats.merge(&e.error);
                outlines.silhouette.merge(&e.silhouette.distances);
                outlines.displacement.merge(&e.silhouette.displacement);
                let label = format!("{label}, looking {dname}");
                let mut r = e.result(&id, &label, eye.to_array(), dir.to_array());
                r.silhouette_floor = floor.map(|f| crate::ErrorSummary::of(&f.distances));
                worst.offer(&r, || WorstView {
                    label: format!("cell {id}, {label}"),
                    reference,
                    impostor,
                    flip_heatmap: e.flip.heatmap_rgba.clone(),
                });
                views.push(r);
            }
        }
        breakdown.push(Breakdown {
            cell: id.clone(),
            own,
            gap,
        });
        cells.push(CellResult::new(id, views, stats).with_outline_stats(outlines));
    }
    let mut own = PixelErrorStats::new();
    let mut gap = PixelErrorStats::new();
    for b in &breakdown {
        own.merge(&b.own);
        gap.merge(&b.gap);
    }
    let mut result = BundleResult::new(cells)
        .with_info("bundle", bundle.dir().display().to_string())
        .with_info("output view", format!("{w}x{h}, {fov_x}° horizontal"))
        .with_info("scene", manifest.scene.sources.join(" "))
        .with_info("adapter", gpu.describe());
    for b in &breakdown {
        result = result.with_info(format!("cell {}: error split", b.cell), b.describe());
    }
    let total = Breakdown {
        cell: "all".into(),
        own,
        gap,
    };
    result = result.with_info("error split", total.describe());
    let run = EvalRun {
        result,
        worst: worst.into_worst_views(),
        placement: total.own,
        gap_filled: total.gap,
        textures: None,
        against: None,
    };
    Ok((run, against_acc))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    /// A camera turned by `px` pixels moves the image centre's point by `px` right and `px` up,
    /// and the points of a 60° view by that much within 40 % (a turn moves a point's pixel by
    /// `1 + x²` times as much along its axis and `x·y` times across it, `x`, `y` its tangents).
    #[test]
    fn a_turned_camera_moves_the_image_by_its_pixels() {
        let (eye, dir) = (DVec3::new(3.0, 1.7, -2.0), DVec3::new(0.6, -0.1, 0.8));
        for (fov, w, h) in [(60.0, 1280, 720), (90.0, 64, 48)] {
            let view = camera(eye, dir, fov, w, h).expect("camera").view();
            for px in [0.1, 0.5, -0.25] {
                let turned = turned_camera(eye, dir, fov, w, h, px)
                    .expect("camera")
                    .view();
                let moved = |p: DVec3| {
                    let (a, b) = (view.project(p)?, turned.project(p)?);
                    Some(b.pixel - a.pixel)
                };
                let centre = moved(eye + 50.0 * dir.normalize()).expect("in view");
                assert!(
                    (centre - DVec2::new(px, -px)).abs().max_element() < 1e-2 * px.abs(),
                    "{fov}° {w}x{h} by {px}: {centre:?}"
                );
                for k in 0..50 {
                    let t = f64::from(k);
                    let p = eye
                        + 40.0 * dir
                        + DVec3::new(13.0 * (0.7 * t).sin(), 9.0 * (1.3 * t).cos(), 5.0 * t.sin());
                    let Some(d) = moved(p) else { continue };
                    for c in [d.x, -d.y] {
                        assert!(c / px >= 0.6 && c / px <= 1.4, "{d:?} for {px}");
                    }
                }
            }
        }
        assert!(turned_camera(eye, dir, 60.0, 0, 10, 0.1).is_err());
        assert!(turned_camera(eye, dir, 60.0, 10, 10, f64::NAN).is_err());
    }

    /// The guard band's camera sees every point where the view's camera does, `px` pixels right
    /// and down (same focal length, same centre), including points beyond the view's edges.
    #[test]
    fn a_guard_band_camera_shifts_pixels_by_its_band() {
        let (eye, dir) = (DVec3::new(3.0, 1.7, -2.0), DVec3::new(0.6, -0.1, 0.8));
        for (fov, w, h) in [(60.0, 960, 540), (90.0, 64, 48), (33.75, 1280, 720)] {
            let band = GuardBand {
                px: GUARD_BAND_PX,
                width: w,
                height: h,
            };
            let view = camera(eye, dir, fov, w, h).expect("camera").view();
            let wide = guard_band_camera(eye, dir, fov, band)
                .expect("camera")
                .view();
            let g = f64::from(GUARD_BAND_PX);
            for k in 0..50 {
                let t = f64::from(k);
                let p = eye
                    + 40.0 * dir
                    + DVec3::new(13.0 * (0.7 * t).sin(), 9.0 * (1.3 * t).cos(), 5.0 * t.sin());
                let (Some(a), Some(b)) = (view.project(p), wide.project(p)) else {
                    continue;
                };
                let d = (b.pixel - a.pixel - DVec2::splat(g)).abs();
                assert!(
                    d.max_element() < 1e-6,
                    "{fov}° {w}x{h}: {:?} vs {:?}",
                    a.pixel,
                    b.pixel
                );
            }
        }
    }
}
