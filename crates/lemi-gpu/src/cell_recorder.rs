//! Recording the layers of one view cell: plan → classify → clip → crack-free GPU recording of
//! every (face, layer), the part of the bake that the certificate repeats to measure the depth of
//! every impostor texel.
//!
//! This work is based on *Layered Environment-Map Impostors for Arbitrary Scenes* (Jeschke,
//! Wimmer et al., Graphics Interface 2002, sec. 4–5) and Jeschke & Wimmer, TR-186-2-02-04
//! sec. 2.2 (crack-free layers):
//!
//! - **plan**: the layers of each baked face and the depth range each records
//!   ([`lemi_core::layering::plan_cell`], per `BakeParams::layering`);
//! - **classify**: the near list and, per (face, slab), the bin of triangles overlapping the range
//!   the layer records ([`lemi_core::classify::classify_slabs`]), so a layer submits only its bin;
//! - **record**: each bin is clipped to its slab on the CPU (canonical cuts: a border's cut is
//!   bit-identical in both adjacent layers) and drawn by [`LayerRecorder`] with conservative
//!   coverage; the cut edges' texels are flagged as clip-border texels
//!   ([`lemi_core::clip_border`]); the innermost layer is grown over the near geometry's texels
//!   just inside the near-field border ([`lemi_core::compress::close_near_seam`]).
//! - Schaufler's equidistant layering records with ordinary centre-sampled rasterization, flags no
//!   clip-border texels and does not close the near-field seam ([`Recording::of`]).

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use lemi_core::bundle::{BakeParams, Layering};
use lemi_core::cell::{CellId, ViewCell};
use lemi_core::classify::{classify_slabs, Classification, TriRef, TriangleBounds};
use lemi_core::clip::{clip_to_slab, ClipVertex};
use lemi_core::clip_border::mark_clip_borders;
use lemi_core::compress::{
    close_near_seam, mark_outline_fringe, CompressError, FaceLayers, LayerImage,
};
use lemi_core::layering::{plan_cell, CellPlan, LayeringError};
use lemi_core::parallax_error::{LayerDepths, TexelDepths};
use lemi_core::{Face, Scene};
use rayon::prelude::*;

use crate::recorder::{Coverage, RecordOptions};
use crate::{Gpu, GpuError, GpuMaterials, LayerRecorder, Lighting, MaterialRun};

/// How the layers of a layering are recorded and compressed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Recording {
    pub coverage: Coverage,
    /// Flag clip-border texels and close the near-field seam (the crack-free recording of the
    /// optimal bake).
    pub crack_free: bool,
    /// Whether the compression fills gaps (GI 2002 sec. 5.1).
    pub gap_fill: bool,
}

impl Recording {
    pub fn of(layering: Layering) -> Recording {
        match layering {
            Layering::Optimal | Layering::Single | Layering::Hlod { .. } => Recording {
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

/// Why a cell's layers could not be recorded.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error(transparent)]
    Layering(#[from] LayeringError),
    #[error("cell {cell}: recording face {face} {}: {source}", layer.map_or("near field".to_string(), |k| format!("layer {k}")))]
    Gpu {
        cell: CellId,
        face: Face,
        /// `None`: the near geometry recorded to close the near-field seam.
        layer: Option<usize>,
        #[source]
        source: GpuError,
    },
    #[error("cell {cell}: face {face} layer {layer}: {source}")]
    Image {
        cell: CellId,
        face: Face,
        layer: usize,
        #[source]
        source: CompressError,
    },
}

/// What [`CellRecorder::record_layers`] produced.
pub struct RecordedLayers {
    /// Per face, its layer images (empty with `depths_only`).
    pub faces: Vec<FaceLayers>,
    /// Per face and layer, the per-texel depth along the face axis (only with `depths_only`).
    pub depths: Vec<Vec<TexelDepths>>,
    pub opaque_recorded: u64,
    /// Texels added to the innermost layers by [`close_near_seam`].
    pub near_seam_texels: u64,
    /// Outline texels marked as fringe (`BakeParams::outline_fringe`).
    pub outline_fringe: u64,
    pub clip_seconds: f64,
}

/// What [`CellRecorder::record_face`] produced for one face.
pub struct RecordedFace {
    /// The face's layer images (no images with `depths_only`).
    pub layers: FaceLayers,
    /// Per layer, the per-texel depth along the face axis (only with `depths_only`), stored
    /// where the layer recorded something.
    pub depths: Vec<TexelDepths>,
    pub opaque_recorded: u64,
    /// Texels added to the innermost layer by [`close_near_seam`].
    pub near_seam_texels: u64,
    /// Outline texels marked as fringe (`BakeParams::outline_fringe`).
    pub outline_fringe: u64,
    pub clip_seconds: f64,
}

/// What recording needs once per scene: the scene, its triangles' bounds, its materials on the
/// GPU and the layer recorder.
pub struct CellRecorder<'a> {
    pub scene: &'a Scene,
    pub params: BakeParams,
    pub lighting: Lighting,
    tris: TriangleBounds,
    materials: Arc<GpuMaterials>,
    recorder: LayerRecorder,
    /// Read back only the tiles a slab's triangles touch ([`RecordOptions::sparse`]; on by
    /// default, the layers are the same either way).
    pub sparse: bool,
}

/// The clipped triangles of one slab and their material runs.
struct Slab {
    vertices: Vec<ClipVertex>,
    runs: Vec<MaterialRun>,
}

impl<'a> CellRecorder<'a> {
    /// Prepares recording the cells of `scene` with `params` (whose values the caller has
    /// validated, e.g. with `BakeParams::validate`).
    pub fn new(
        gpu: &Gpu,
        scene: &'a Scene,
        params: BakeParams,
    ) -> Result<CellRecorder<'a>, GpuError> {
        let materials = Arc::new(GpuMaterials::upload(
            gpu,
            &scene.materials,
            &scene.textures,
        )?);
        let recorder = LayerRecorder::new(gpu, params.resolution)?;
        Ok(CellRecorder {
            scene,
            params,
            lighting: Lighting::default(),
            tris: TriangleBounds::new(scene),
            materials,
            recorder,
            sparse: true,
        })
    }

    /// Texels read back from the GPU so far ([`LayerRecorder::texels_read`]).
    pub fn texels_read(&self) -> u64 {
        self.recorder.texels_read()
    }

    /// The layers of `cell` and what each records, for these parameters and this scene.
    pub fn plan(&self, cell: &ViewCell) -> Result<CellPlan, LayeringError> {
        plan_cell(&self.params, cell, Some(&self.scene.bounds))
    }

    /// The near list and the per-(face, slab) bins of `cell` for `plan`.
    pub fn classify(&self, cell: &ViewCell, plan: &CellPlan) -> Classification {
        classify_slabs(
            &self.tris,
            cell.center,
            plan.near_field,
            &self.params.faces,
            &plan.slabs(),
        )
    }

    /// Records the layers of `cell` again and keeps only their per-texel depths along the face
    /// axis (for measuring the geometric error of a baked cell, `lemi_core::parallax_error`).
    /// The result is what the bake of the same cell recorded, before compression (same layering,
    /// same layers, same recorded depth ranges and coverage).
    pub fn record_depths(&self, cell: &ViewCell) -> Result<LayerDepths, RecordError> {
        let plan = self.plan(cell)?;
        self.record_depths_planned(cell, &plan)
    }

    /// [`CellRecorder::record_depths`] for layers already planned (an object impostor's plan in
    /// its canonical frame; the caller sets the result's `frame`).
    pub fn record_depths_planned(
        &self,
        cell: &ViewCell,
        plan: &CellPlan,
    ) -> Result<LayerDepths, RecordError> {
        let class = self.classify(cell, plan);
        let rec = self.record_layers(cell, plan, &class, true, &mut |_, _, _| {})?;
        Ok(LayerDepths {
            center: cell.center,
            res: self.params.resolution,
            faces: self.params.faces.clone(),
            distances: plan
                .faces
                .iter()
                .map(|f| f.placement.layers.iter().map(|l| l.distance).collect())
                .collect(),
            depth: rec.depths,
            frame: None,
            outline_copies: self.params.outline_copies,
        })
    }

    /// Clips and records every (face, layer) of a cell: the layer images with clip-border flags
    /// (or, with `depths_only`, only the per-texel depths). `on_layer(face, layer, layers)` is
    /// told before each layer is recorded. A bake that compresses face by face calls
    /// [`CellRecorder::record_face`] instead and holds one face's images at a time.
    pub fn record_layers(
        &self,
        cell: &ViewCell,
        plan: &CellPlan,
        class: &Classification,
        depths_only: bool,
        on_layer: &mut dyn FnMut(Face, usize, usize),
    ) -> Result<RecordedLayers, RecordError> {
        let mut out = RecordedLayers {
            faces: Vec::new(),
            depths: Vec::new(),
            opaque_recorded: 0,
            near_seam_texels: 0,
            outline_fringe: 0,
            clip_seconds: 0.0,
        };
        for slot in 0..plan.faces.len() {
            let face = self.record_face(cell, plan, class, slot, depths_only, on_layer)?;
            out.opaque_recorded += face.opaque_recorded;
            out.near_seam_texels += face.near_seam_texels;
            out.outline_fringe += face.outline_fringe;
            out.clip_seconds += face.clip_seconds;
            if depths_only {
                out.depths.push(face.depths);
            } else {
                out.faces.push(face.layers);
            }
        }
        Ok(out)
    }

    /// Clips and records the layers of the face in slot `slot` of `plan` (see
    /// [`CellRecorder::record_layers`]).
    pub fn record_face(
        &self,
        cell: &ViewCell,
        plan: &CellPlan,
        class: &Classification,
        slot: usize,
        depths_only: bool,
        on_layer: &mut dyn FnMut(Face, usize, usize),
    ) -> Result<RecordedFace, RecordError> {
        let center = cell.center;
        let res = self.params.resolution;
        let near_field = plan.near_field;
        let recording = Recording::of(self.params.layering);
        // which side of its layer's plane each texel's point lies on, for the outline copies
        let outline_copies = self.params.outline_copies && recording.crack_free && !depths_only;
        // conservative overshoot marked for the outline fringe, in the depth recording of the
        // certificate too (the marking changes which triangle wins a texel)
        let outline_fringe = self.params.outline_fringe && recording.crack_free;
        let face_plan = &plan.faces[slot];
        let face = face_plan.face;
        let placement = &face_plan.placement;
        let slabs = &face_plan.slabs;
        let n = placement.layers.len();
        let mut out = RecordedFace {
            layers: FaceLayers {
                face,
                distances: placement.layers.iter().map(|l| l.distance).collect(),
                layers: Vec::new(),
            },
            depths: Vec::new(),
            opaque_recorded: 0,
            near_seam_texels: 0,
            outline_fringe: 0,
            clip_seconds: 0.0,
        };
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
            on_layer(face, k, n);
            let (lo, hi) = (slabs.lo(k), slabs.hi(k));
            let near_plane = 0.5 * lo.min(near_field);
            let planes: Vec<f64> = [lo, hi].into_iter().filter(|p| p.is_finite()).collect();
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
                    &RecordOptions {
                        coverage: recording.coverage,
                        clip_planes: &planes,
                        depth: depths_only,
                        sparse: self.sparse,
                        side_plane: outline_copies.then_some(placement.layers[k].distance),
                        mark_overshoot: outline_fringe,
                    },
                )
                .map_err(|source| RecordError::Gpu {
                    cell: cell.id(),
                    face,
                    layer: Some(k),
                    source,
                })?;
            if depths_only {
                // one dense layer at a time: a cell's layers stored whole would not fit (17 GB
                // for 4 faces of 64 layers at 4096²)
                depths.push(TexelDepths::from_dense(res, &frame.depth));
                continue;
            }
            let mut border = vec![false; (res * res) as usize];
            let mut far_border = vec![false; (res * res) as usize];
            if recording.crack_free {
                if lo.is_finite() {
                    mark_clip_borders(&slab.vertices, face, &[lo], res, &mut border);
                }
                if hi.is_finite() {
                    mark_clip_borders(&slab.vertices, face, &[hi], res, &mut far_border);
                }
            }
            let content = frame.content;
            let overshoot = frame.overshoot;
            let image = LayerImage::from_parts_in(res, frame.rgba, border, far_border, content)
                .and_then(|image| image.with_behind_plane(frame.behind_plane))
                .and_then(|mut image| {
                    if outline_fringe {
                        out.outline_fringe += mark_outline_fringe(&mut image, &overshoot)?;
                    }
                    Ok(image)
                })
                .map_err(|source| RecordError::Image {
                    cell: cell.id(),
                    face,
                    layer: k,
                    source,
                })?;
            out.opaque_recorded += image.opaque_count();
            images.push(image);
        }
        if depths_only {
            out.depths = depths;
            return Ok(out);
        }
        if let Some(inner) = images.last_mut().filter(|_| recording.crack_free) {
            let along = cell.half.abs().dot(face.forward().abs());
            let near = self.prepare_slab(&class.near, center, face, along, near_field);
            let frame = self
                .recorder
                .record_with(
                    &self.materials,
                    DVec3::ZERO,
                    face,
                    &near.vertices,
                    &near.runs,
                    0.5 * along.max(1e-3),
                    &self.lighting,
                    &RecordOptions {
                        depth: false,
                        sparse: self.sparse,
                        ..Default::default()
                    },
                )
                .map_err(|source| RecordError::Gpu {
                    cell: cell.id(),
                    face,
                    layer: None,
                    source,
                })?;
            out.near_seam_texels += close_near_seam(inner, &frame.rgba);
        }
        out.layers.layers = images;
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
