//! The work of one view cell (GI 2002 sec. 3-5, TR-186-2-02-04 sec. 2.2): placement →
//! classification → crack-free GPU recording of every (face, layer) → compression → cell file.
//!
//! - **placement**: per baked face, `lemi_core::placement::place_env_layers` for the cell's extent
//!   along and across the face axis, then shaped by `BakeParams::layering` ([`layering`]: the
//!   optimal placement, one layer, or Schaufler's equidistant overlapping slabs);
//! - **classification**: `lemi_core::classify`: the near list and, per (face, slab), the bin of
//!   triangles overlapping the depth range the layer records, so recording a layer submits only
//!   its bin;
//! - **recording**: each bin's triangles are clipped to the slab on the CPU (canonical cuts, so a
//!   border's cut is bit-identical in both layers), then drawn with conservative coverage by
//!   [`lemi_gpu::LayerRecorder`]; the cut edges' texels are flagged as clip-border texels
//!   ([`crate::clip_border`]);
//! - **compression**: `lemi_core::compress::compress_cell` (gap fill, hidden texels, micro-textures,
//!   macro packing), then PNG per macro-texture;
//! - the equidistant layering (Schaufler 1998) records with ordinary centre-sampled rasterization
//!   ([`lemi_gpu::recorder::Coverage::CentreSampled`]), flags no clip-border texels, does not close
//!   the near-field seam and skips gap filling; everything else is the same pipeline, so sizes
//!   compare fairly;
//! - the result is a [`CellFile`]: quads with world-space corners, PNG macro-textures, near list,
//!   statistics (GI 2002 Table 2 and more).

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use lemi_core::bundle::{
    encode_png, BakeParams, CellFile, CellHeader, CellStats, LayerInfo, LayerTarget, Layering,
    MacroInfo, Quad,
};
use lemi_core::cell::ViewCell;
use lemi_core::classify::{classify_slabs, TriRef, TriangleBounds};
use lemi_core::clip::{clip_to_slab, ClipVertex};
use lemi_core::compress::{
    compress_cell, CompressOptions, FaceLayers, LayerImage, MicroTextureOptions,
};
use lemi_core::placement::Placement;
use lemi_core::{Aabb, Face, Scene};
use lemi_gpu::recorder::Coverage;
use lemi_gpu::{Gpu, GpuMaterials, LayerRecorder, Lighting, MaterialRun};
use rayon::prelude::*;

use crate::clip_border::mark_clip_borders;
use crate::BakeError;

pub use crate::layering::{plan_cell, CellPlan, FacePlan};

/// What a baker needs once per scene: the scene, its triangles in f64, its materials on the GPU and
/// the layer recorder.
pub struct Baker<'a> {
    pub scene: &'a Scene,
    pub params: BakeParams,
    pub lighting: Lighting,
    tris: TriangleBounds,
    materials: Arc<GpuMaterials>,
    recorder: LayerRecorder,
}

/// A stage of one cell, reported for progress.
#[derive(Clone, Debug, PartialEq)]
pub enum Stage {
    Placement,
    Classify,
    /// Recording layer `layer` of `layers` of face `face`.
    Record {
        face: Face,
        layer: usize,
        layers: usize,
    },
    Compress,
    Png,
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stage::Placement => write!(f, "placement"),
            Stage::Classify => write!(f, "classify"),
            Stage::Record {
                face,
                layer,
                layers,
            } => write!(f, "record {face} {}/{layers}", layer + 1),
            Stage::Compress => write!(f, "compress"),
            Stage::Png => write!(f, "png"),
        }
    }
}

/// The placement of every baked face of `cell`, for `params.layering` ([`layering`]). The
/// equidistant layering needs the scene's bounds: use [`place_cell_in`] (this is an error for it).
pub fn place_cell(params: &BakeParams, cell: &ViewCell) -> Result<Vec<Placement>, BakeError> {
    Ok(plan_cell(params, cell, None)?.placements())
}

/// [`place_cell`] for a scene with bounding box `scene_bounds` (what the bake places, for every
/// layering).
pub fn place_cell_in(
    params: &BakeParams,
    cell: &ViewCell,
    scene_bounds: &Aabb,
) -> Result<Vec<Placement>, BakeError> {
    Ok(plan_cell(params, cell, Some(scene_bounds))?.placements())
}

/// How the layers of `layering` are recorded and compressed.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Recording {
    coverage: Coverage,
    /// Flag clip-border texels and close the near-field seam (the crack-free recording of the
    /// optimal bake).
    crack_free: bool,
    gap_fill: bool,
}

impl Recording {
    fn of(layering: Layering) -> Recording {
        match layering {
            Layering::Optimal | Layering::Single => Recording {
                coverage: Coverage::Conservative,
                crack_free: true,
                gap_fill: true,
            },
            Layering::Equidistant { .. } => Recording {
                coverage: Coverage::CentreSampled,
                crack_free: false,
                gap_fill: false,
            },
        }
    }
}

impl<'a> Baker<'a> {
    /// Prepares baking `scene` with `params`: triangle bounds, materials on the GPU, recorder.
    pub fn new(gpu: &Gpu, scene: &'a Scene, params: BakeParams) -> Result<Baker<'a>, BakeError> {
        validate_params(&params)?;
        let gpu_err = |what: &str| {
            let what = what.to_string();
            move |e: lemi_gpu::GpuError| BakeError::Invalid(format!("{what}: {e}"))
        };
        let materials = Arc::new(
            GpuMaterials::upload(gpu, &scene.materials, &scene.textures)
                .map_err(gpu_err("uploading the scene's materials"))?,
        );
        let recorder = LayerRecorder::new(gpu, params.resolution)
            .map_err(gpu_err("creating the layer recorder"))?;
        Ok(Baker {
            scene,
            params,
            lighting: Lighting::default(),
            tris: TriangleBounds::new(scene),
            materials,
            recorder,
        })
    }

    /// Bakes one cell; `on_stage` is told when each stage starts.
    pub fn bake(
        &self,
        cell: &ViewCell,
        mut on_stage: impl FnMut(&Stage),
    ) -> Result<CellFile, BakeError> {
        let cell_err = |message: String| BakeError::Cell {
            cell: cell.id(),
            message,
        };
        let mut seconds: Vec<(String, f64)> = Vec::new();
        let center = cell.center;
        let params = &self.params;
        let res = params.resolution;

        on_stage(&Stage::Placement);
        let t = Instant::now();
        let plan = self.plan(cell)?;
        let near_field = plan.near_field;
        seconds.push(("placement".into(), t.elapsed().as_secs_f64()));

        on_stage(&Stage::Classify);
        let t = Instant::now();
        let class = classify_slabs(&self.tris, center, near_field, &params.faces, &plan.slabs());
        seconds.push(("classify".into(), t.elapsed().as_secs_f64()));

        let t_record = Instant::now();
        let rec = self.record_layers(cell, &plan, &class, false, &mut on_stage)?;
        let mut faces = rec.faces;
        let opaque_recorded = rec.opaque_recorded;
        let record_s = t_record.elapsed().as_secs_f64();
        seconds.push(("clip".into(), rec.clip_seconds));
        seconds.push(("record".into(), record_s - rec.clip_seconds));

        on_stage(&Stage::Compress);
        let t = Instant::now();
        let options = CompressOptions {
            gap_fill: Recording::of(params.layering).gap_fill,
            micro: MicroTextureOptions {
                cell_size: params.micro_grid,
                threshold: params.micro_threshold,
            },
            ..Default::default()
        };
        let compressed = compress_cell(&mut faces, &options)
            .map_err(|e| cell_err(format!("compressing: {e}")))?;
        drop(faces);
        seconds.push(("compress".into(), t.elapsed().as_secs_f64()));

        on_stage(&Stage::Png);
        let t = Instant::now();
        let pngs: Vec<Vec<u8>> = compressed
            .macro_textures
            .par_iter()
            .map(|m| encode_png(&m.rgba, m.width, m.height))
            .collect::<Result<_, _>>()
            .map_err(|e| cell_err(e.to_string()))?;
        seconds.push(("png".into(), t.elapsed().as_secs_f64()));

        let quads: Vec<Quad> = compressed
            .micro_textures
            .iter()
            .zip(&compressed.placements)
            .map(|(m, p)| {
                let (fw, fh) = p.footprint(m.rect.width(), m.rect.height());
                Quad {
                    face: m.face,
                    layer: m.layer as u16,
                    texels: [m.rect.x0, m.rect.y0, m.rect.x1, m.rect.y1].map(|v| v as u16),
                    corners: m.corners().map(|c| (center + c).as_vec3().to_array()),
                    macro_index: p.macro_index,
                    rect: [p.x, p.y, fw, fh],
                    rotated: p.rotated,
                }
            })
            .collect();
        let macros: Vec<MacroInfo> = compressed
            .macro_textures
            .iter()
            .enumerate()
            .map(|(i, m)| MacroInfo {
                name: format!("macro{i}.png"),
                width: m.width,
                height: m.height,
            })
            .collect();
        let s = &compressed.stats;
        let stats = CellStats {
            far_triangles: class.far_triangles,
            near_triangles: class.near.len() as u64,
            submitted_triangles: class.submitted,
            raw_bytes: s.layer_bytes,
            opaque_texels_recorded: opaque_recorded,
            opaque_texels_after_gap_fill: s.hidden.opaque_before,
            opaque_texels_after_hidden_removal: s.hidden.opaque_after,
            micro_textures: s.micro.micro_textures,
            micro_fill_ratio: s.micro.fill_ratio,
            macro_textures: s.packing.macro_textures,
            macro_bytes: s.packing.macro_bytes,
            png_bytes: pngs.iter().map(|p| p.len() as u64).sum(),
            seconds,
        };
        let layers = plan
            .faces
            .iter()
            .map(|f| {
                f.placement
                    .layers
                    .iter()
                    .map(|l| LayerInfo {
                        distance: l.distance,
                        near_border: l.near_border,
                        far_border: if l.far_border.is_finite() {
                            l.far_border
                        } else {
                            f64::MAX
                        },
                    })
                    .collect()
            })
            .collect();
        Ok(CellFile {
            header: CellHeader {
                cell: *cell,
                params_hash: params.hash(),
                scene_fingerprint: String::new(),
                resolution: res,
                near_field,
                faces: params.faces.clone(),
                layers,
                quads,
                macros,
                stats,
            },
            near: class.near.iter().map(|r| [r.mesh, r.tri]).collect(),
            pngs,
        })
    }

    /// The layers of `cell` and what each records, for this baker's parameters and scene (what
    /// [`Baker::bake`] and [`Baker::record_depths`] use).
    pub fn plan(&self, cell: &ViewCell) -> Result<CellPlan, BakeError> {
        plan_cell(&self.params, cell, Some(&self.scene.bounds))
    }

    /// Records the layers of `cell` again and keeps only their per-texel depths along the face
    /// axis (for measuring the geometric error of a baked cell, `lemi_core::parallax_error`). The
    /// result is what the bake of the same cell recorded, before compression (same layering, same
    /// layers, same recorded depth ranges and coverage).
    pub fn record_depths(
        &self,
        cell: &ViewCell,
    ) -> Result<lemi_core::parallax_error::LayerDepths, BakeError> {
        let plan = self.plan(cell)?;
        let class = classify_slabs(
            &self.tris,
            cell.center,
            plan.near_field,
            &self.params.faces,
            &plan.slabs(),
        );
        let rec = self.record_layers(cell, &plan, &class, true, &mut |_| {})?;
        Ok(lemi_core::parallax_error::LayerDepths {
            center: cell.center,
            res: self.params.resolution,
            faces: self.params.faces.clone(),
            distances: plan
                .faces
                .iter()
                .map(|f| f.placement.layers.iter().map(|l| l.distance).collect())
                .collect(),
            depth: rec.depths,
        })
    }

    /// Clips and records every (face, layer) of a cell: the layer images with clip-border flags
    /// (or, with `depths_only`, only the per-texel depths).
    fn record_layers(
        &self,
        cell: &ViewCell,
        plan: &CellPlan,
        class: &lemi_core::classify::Classification,
        depths_only: bool,
        on_stage: &mut dyn FnMut(&Stage),
    ) -> Result<Recorded, BakeError> {
        let cell_err = |message: String| BakeError::Cell {
            cell: cell.id(),
            message,
        };
        let center = cell.center;
        let res = self.params.resolution;
        let near_field = plan.near_field;
        let recording = Recording::of(self.params.layering);
        let mut out = Recorded {
            faces: Vec::new(),
            depths: Vec::new(),
            opaque_recorded: 0,
            near_seam_texels: 0,
            clip_seconds: 0.0,
        };
        for (slot, face_plan) in plan.faces.iter().enumerate() {
            let face = face_plan.face;
            let placement = &face_plan.placement;
            let slabs = &face_plan.slabs;
            let n = placement.layers.len();
            // clip every slab of this face on the CPU, in parallel (to the depth range the layer
            // records: its slab, or for overlapping slabs the extended range)
            let t = Instant::now();
            let prepared: Vec<Slab> = (0..n)
                .into_par_iter()
                .map(|k| {
                    self.prepare_slab(&class.bins[slot][k], center, face, slabs.lo(k), slabs.hi(k))
                })
                .collect();
            out.clip_seconds += t.elapsed().as_secs_f64();
            let mut images = Vec::with_capacity(n);
            let mut depths = Vec::with_capacity(n);
            for (k, slab) in prepared.into_iter().enumerate() {
                on_stage(&Stage::Record {
                    face,
                    layer: k,
                    layers: n,
                });
                let (lo, hi) = (slabs.lo(k), slabs.hi(k));
                let near_plane = 0.5 * lo.min(near_field);
                let frame = self
                    .recorder
                    .record_with(
                        &self.materials,
                        DVec3::ZERO,
                        face,
                        &slab.vertices,
                        &slab.runs,
                        near_plane,
                        &self.lighting,
                        recording.coverage,
                    )
                    .map_err(|e| cell_err(format!("recording face {face} layer {k}: {e}")))?;
                if depths_only {
                    depths.push(frame.depth);
                    continue;
                }
                let mut border = vec![false; (res * res) as usize];
                if recording.crack_free {
                    let planes: Vec<f64> = [lo, hi].into_iter().filter(|p| p.is_finite()).collect();
                    mark_clip_borders(&slab.vertices, face, &planes, res, &mut border);
                }
                let image = LayerImage::from_parts(res, frame.rgba, border)
                    .map_err(|e| cell_err(format!("face {face} layer {k}: {e}")))?;
                out.opaque_recorded += image.opaque_count();
                images.push(image);
            }
            if depths_only {
                out.depths.push(depths);
            } else {
                if let Some(inner) = images.last_mut().filter(|_| recording.crack_free) {
                    let along = cell.half.abs().dot(face.forward().abs());
                    let near = self.prepare_slab(&class.near, center, face, along, near_field);
                    let frame = self
                        .recorder
                        .record(
                            &self.materials,
                            DVec3::ZERO,
                            face,
                            &near.vertices,
                            &near.runs,
                            0.5 * along.max(1e-3),
                            &self.lighting,
                        )
                        .map_err(|e| cell_err(format!("recording face {face} near field: {e}")))?;
                    out.near_seam_texels += close_near_seam(inner, &frame.rgba);
                }
                out.faces.push(FaceLayers {
                    face,
                    distances: placement.layers.iter().map(|l| l.distance).collect(),
                    layers: images,
                });
            }
        }
        Ok(out)
    }

    /// Clips the triangles of one bin to the slab `[near, far]` of `face`, sorted by material, with
    /// positions relative to `center`.
    fn prepare_slab(&self, bin: &[TriRef], center: DVec3, face: Face, near: f64, far: f64) -> Slab {
        let meshes = &self.scene.meshes;
        let mut refs: Vec<TriRef> = bin.to_vec();
        refs.sort_by_key(|r| (meshes[r.mesh as usize].material, r.mesh, r.tri));
        let mut vertices: Vec<ClipVertex> = Vec::with_capacity(3 * refs.len());
        let mut runs: Vec<MaterialRun> = Vec::new();
        for r in &refs {
            let mesh = &meshes[r.mesh as usize];
            let i = 3 * r.tri as usize;
            let Some(idx) = mesh.indices.get(i..i + 3) else {
                continue;
            };
            let Some(tri) = idx
                .iter()
                .map(|&v| mesh.vertices.get(v as usize))
                .collect::<Option<Vec<_>>>()
            else {
                continue;
            };
            let tri = [0, 1, 2].map(|k| ClipVertex::from_vertex(tri[k], center));
            let first = (vertices.len() / 3) as u32;
            let added = clip_to_slab(&tri, face, near, far, &mut vertices) as u32;
            if added == 0 {
                continue;
            }
            match runs.last_mut() {
                Some(run) if run.material == mesh.material => run.count += added,
                _ => runs.push(MaterialRun {
                    material: mesh.material,
                    first,
                    count: added,
                }),
            }
        }
        Slab { vertices, runs }
    }
}

/// What [`Baker::record_layers`] produced.
struct Recorded {
    faces: Vec<FaceLayers>,
    depths: Vec<Vec<Vec<f32>>>,
    opaque_recorded: u64,
    /// Texels added to the innermost layers by [`close_near_seam`].
    near_seam_texels: u64,
    clip_seconds: f64,
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
    let res = inner.res as usize;
    if near.len() != inner.rgba.len() {
        return 0;
    }
    let opaque = inner.opaque_mask();
    let touches = lemi_core::compress::layer_image::any3x3(&opaque, inner.res, false);
    let mut added = 0;
    for i in 0..res * res {
        if !opaque[i] && touches[i] && near[4 * i + 3] >= 128 {
            let c = [near[4 * i], near[4 * i + 1], near[4 * i + 2], 255];
            inner.set_texel(i, c);
            inner.border[i] = true;
            added += 1;
        }
    }
    added
}

/// The clipped triangles of one slab and their material runs.
struct Slab {
    vertices: Vec<ClipVertex>,
    runs: Vec<MaterialRun>,
}

/// Checks the parameters a user controls before any work starts.
pub fn validate_params(p: &BakeParams) -> Result<(), BakeError> {
    let bad = |m: String| Err(BakeError::Invalid(m));
    if !(p.cell_size.is_finite() && p.cell_size > 0.0) {
        return bad(format!(
            "--cell-size must be a positive number of metres (got {})",
            p.cell_size
        ));
    }
    if let Some(h) = p.cell_height {
        if !(h.is_finite() && h > 0.0) {
            return bad(format!(
                "--cell-height must be a positive number of metres (got {h})"
            ));
        }
    }
    if !(16..=8192).contains(&p.resolution) {
        return bad(format!(
            "--resolution must be between 16 and 8192 texels (got {})",
            p.resolution
        ));
    }
    if p.faces.is_empty() {
        return bad("no faces to bake".into());
    }
    if !(p.alpha.is_finite() && p.alpha > 0.0 && p.alpha < 0.5) {
        return bad(format!(
            "the parallax angle must be in (0, 0.5) radians (got {})",
            p.alpha
        ));
    }
    match p.target {
        LayerTarget::Layers(n) if n == 0 || n > 4096 => {
            return bad(format!("--layers must be between 1 and 4096 (got {n})"))
        }
        LayerTarget::NearField(d) if !(d.is_finite() && d > 0.5 * p.cell_size) => {
            return bad(format!(
                "--near-field must be a distance beyond the cell's half size {} m (got {d})",
                0.5 * p.cell_size
            ))
        }
        _ => {}
    }
    if p.micro_grid == 0 || p.micro_grid > p.resolution {
        return bad(format!(
            "the micro-texture grid must be 1..={} texels (got {})",
            p.resolution, p.micro_grid
        ));
    }
    if !(0.0..=1.0).contains(&p.micro_threshold) {
        return bad(format!(
            "the micro-texture threshold must be in [0, 1] (got {})",
            p.micro_threshold
        ));
    }
    if let Layering::Equidistant { overlap } = p.layering {
        if !(overlap.is_finite() && (0.0..=1.0).contains(&overlap)) {
            return bad(format!(
                "the equidistant layering's `overlap` (--overlap) must be a fraction of a slab's \
                 depth in [0, 1] (got {overlap})"
            ));
        }
    }
    Ok(())
}
