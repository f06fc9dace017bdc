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
//! - the HLOD layering (`lemi_core::hlod`) stops after classification: the far field (every
//!   triangle not in the near list) is simplified with meshoptimizer in distance bands and stored
//!   in the cell's `hlod` section; nothing is recorded;
//! - the result is a [`CellFile`]: quads with world-space corners, PNG macro-textures, near list,
//!   statistics (GI 2002 Table 2 and more).

use std::time::Instant;

use lemi_core::bundle::{
    encode_png, BakeParams, CellFile, CellHeader, CellStats, HlodHeader, LayerInfo, Layering,
    MacroInfo, ParamsError, Quad,
};
use lemi_core::cell::ViewCell;
use lemi_core::classify::TriRef;
use lemi_core::compress::{
    compress_face, encode_basis, encode_blocks, pack_cell, write_ktx2, BlockFormat, CompressError,
    CompressOptions, FaceLayers, HiddenTexelOptions, MacroTexture, MicroTextureOptions,
    PackingOptions, Supercompression, TextureFormat,
};
use lemi_core::hlod::{simplify_far_field, HlodOptions};
use lemi_core::layering::CellPlan;
use lemi_core::parallax_error::LayerDepths;
use lemi_core::Face;
use lemi_core::Scene;
use lemi_gpu::cell_recorder::{CellRecorder, RecordError, Recording};
use lemi_gpu::Gpu;
use rayon::prelude::*;

use crate::BakeError;

/// What a baker needs once per scene: the layer recording of [`CellRecorder`] (scene, triangle
/// bounds, materials on the GPU, recorder) and the parameters.
pub struct Baker<'a> {
    recorder: CellRecorder<'a>,
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
    /// Encoding the macro-textures in the bundle's texture format (PNG, BC7, BC1).
    Encode(TextureFormat),
    /// Simplifying the far field (HLOD).
    Simplify,
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
            Stage::Encode(format) => write!(f, "{format}"),
            Stage::Simplify => write!(f, "simplify"),
        }
    }
}

impl<'a> Baker<'a> {
    /// Prepares baking `scene` with `params` (checked first): triangle bounds, materials on the
    /// GPU, recorder.
    pub fn new(gpu: &Gpu, scene: &'a Scene, params: BakeParams) -> Result<Baker<'a>, BakeError> {
        params.validate()?;
        map_large_buffers();
        let recorder = CellRecorder::new(gpu, scene, params).map_err(|source| BakeError::Gpu {
            what: "preparing the scene for recording (materials, layer recorder)",
            source,
        })?;
        Ok(Baker { recorder })
    }

    pub fn scene(&self) -> &'a Scene {
        self.recorder.scene
    }

    pub fn params(&self) -> &BakeParams {
        &self.recorder.params
    }

    /// Bakes one cell; `on_stage` is told when each stage starts.
    pub fn bake(
        &self,
        cell: &ViewCell,
        mut on_stage: impl FnMut(&Stage),
    ) -> Result<CellFile, BakeError> {
        on_stage(&Stage::Placement);
        let t = Instant::now();
        let plan = self.plan(cell)?;
        let seconds = vec![("placement".to_string(), t.elapsed().as_secs_f64())];
        self.bake_planned(cell, &plan, seconds, on_stage)
    }

    /// Bakes one cell whose layers are already planned (an environment-map cell's
    /// [`Baker::plan`], or an object impostor's plan in its canonical frame,
    /// `lemi_core::object_cell`); `seconds` holds the stages timed so far.
    pub fn bake_planned(
        &self,
        cell: &ViewCell,
        plan: &CellPlan,
        mut seconds: Vec<(String, f64)>,
        mut on_stage: impl FnMut(&Stage),
    ) -> Result<CellFile, BakeError> {
        let center = cell.center;
        let params = &self.recorder.params;
        let res = params.resolution;
        let near_field = plan.near_field;

        on_stage(&Stage::Classify);
        let t = Instant::now();
        let class = self.recorder.classify(cell, plan);
        seconds.push(("classify".into(), t.elapsed().as_secs_f64()));

        if let Layering::Hlod {
            error_px,
            band_factor,
        } = params.layering
        {
            return self.bake_hlod(
                cell,
                plan,
                &class.near,
                HlodOptions {
                    error_px,
                    band_factor,
                },
                seconds,
                &mut on_stage,
            );
        }

        let options = compress_options(params, cell);
        // face by face: record a face's layers while the previous face is compressed to
        // micro-textures on another thread, then drop its images (at most two faces' layers in
        // memory, not the cell's; the GPU recording and the CPU stages overlap)
        let compress_err = |source| BakeError::Compress {
            cell: cell.id(),
            source,
        };
        let (mut record_s, mut clip_s) = (0.0, 0.0);
        let (mut opaque_recorded, mut outline_fringe) = (0, 0);
        let (compressed_faces, compress_s) = std::thread::scope(|scope| {
            // a rendezvous channel: the recorder waits until the compressor takes the face
            let (tx, rx) = std::sync::mpsc::sync_channel::<FaceLayers>(0);
            let options = &options;
            let compressor = scope.spawn(move || {
                let mut faces = Vec::new();
                let mut seconds = 0.0;
                for mut layers in rx {
                    let t = Instant::now();
                    faces.push(compress_face(&mut layers, options)?);
                    drop(layers);
                    seconds += t.elapsed().as_secs_f64();
                }
                Ok::<_, CompressError>((faces, seconds))
            });
            let recorded = (|| {
                for slot in 0..plan.faces.len() {
                    let t = Instant::now();
                    let rec = self.recorder.record_face(
                        cell,
                        plan,
                        &class,
                        slot,
                        false,
                        &mut |face, layer, layers| {
                            on_stage(&Stage::Record {
                                face,
                                layer,
                                layers,
                            })
                        },
                    )?;
                    record_s += t.elapsed().as_secs_f64() - rec.clip_seconds;
                    clip_s += rec.clip_seconds;
                    opaque_recorded += rec.opaque_recorded;
                    outline_fringe += rec.outline_fringe;
                    if tx.send(rec.layers).is_err() {
                        // the compressor stopped on an error: its result says which
                        break;
                    }
                }
                drop(tx);
                on_stage(&Stage::Compress);
                Ok::<_, BakeError>(())
            })();
            let compressed = compressor.join().map_err(|_| BakeError::Compress {
                cell: cell.id(),
                source: CompressError::Invalid("the compression thread panicked".into()),
            });
            recorded?;
            compressed?.map_err(compress_err)
        })?;
        let mut compress_s = compress_s;
        seconds.push(("clip".into(), clip_s));
        seconds.push(("record".into(), record_s));
        let t = Instant::now();
        let compressed = pack_cell(compressed_faces, &options).map_err(compress_err)?;
        compress_s += t.elapsed().as_secs_f64();
        seconds.push(("compress".into(), compress_s));

        let format = params.texture_format;
        on_stage(&Stage::Encode(format));
        let t = Instant::now();
        let encode_err = |source| BakeError::Encode {
            cell: cell.id(),
            source,
        };
        let (macro_blobs, block_bytes): (Vec<Vec<u8>>, u64) = match format.block() {
            None => (
                compressed
                    .macro_textures
                    .par_iter()
                    .map(|m| encode_png(&m.rgba, m.width, m.height))
                    .collect::<Result<_, _>>()
                    .map_err(encode_err)?,
                0,
            ),
            Some(block) => {
                let encode = |m: &MacroTexture| -> Result<(Vec<u8>, u64), CompressError> {
                    if let Some(basis) = format.basis() {
                        let (ktx2, stats) = encode_basis(basis, m.width, m.height, &m.rgba)?;
                        return Ok((ktx2, stats.block_bytes));
                    }
                    let (blocks, stats) = encode_blocks(block, m.width, m.height, &m.rgba)?;
                    let ktx2 =
                        write_ktx2(block, m.width, m.height, &[blocks], Supercompression::Zstd)
                            .map_err(|e| CompressError::Invalid(e.to_string()))?;
                    Ok((ktx2, stats.bytes))
                };
                // one macro-texture per thread (the Basis encoder runs single-threaded, see
                // `encode_basis`)
                let encoded: Result<Vec<(Vec<u8>, u64)>, CompressError> =
                    compressed.macro_textures.par_iter().map(encode).collect();
                let encoded = encoded.map_err(|source| BakeError::Compress {
                    cell: cell.id(),
                    source,
                })?;
                let bytes = encoded.iter().map(|e| e.1).sum();
                (encoded.into_iter().map(|e| e.0).collect(), bytes)
            }
        };
        seconds.push((format.name().into(), t.elapsed().as_secs_f64()));

        let quads: Vec<Quad> = compressed
            .micro_textures
            .iter()
            .zip(&compressed.placements)
            .enumerate()
            .map(|(i, (m, p))| {
                let (fw, fh) = p.footprint(m.rect.width(), m.rect.height());
                Quad {
                    // the fringe micro-textures come last
                    fringe: i + compressed.fringe_micro_textures >= compressed.micro_textures.len(),
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
                name: match format {
                    TextureFormat::Png => format!("macro{i}.png"),
                    _ => format!("macro{i}.ktx2"),
                },
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
            outline_copies: s.gap_fill.outline_copies,
            outline_fringe,
            fringe_quads: compressed.fringe_micro_textures as u64,
            opaque_texels_after_hidden_removal: s.hidden.opaque_after,
            micro_textures: s.micro.micro_textures,
            micro_fill_ratio: s.micro.fill_ratio,
            macro_textures: s.packing.macro_textures,
            macro_bytes: s.packing.macro_bytes,
            png_bytes: if format.is_png() {
                macro_blobs.iter().map(|p| p.len() as u64).sum()
            } else {
                0
            },
            ktx2_bytes: if format.is_png() {
                0
            } else {
                macro_blobs.iter().map(|p| p.len() as u64).sum()
            },
            block_bytes,
            seconds,
        };
        let layers = layer_infos(plan);
        Ok(CellFile {
            header: CellHeader {
                fringe_quads: compressed.fringe_micro_textures as u64,
                cell: *cell,
                params_hash: params.hash(),
                scene_fingerprint: String::new(),
                resolution: res,
                near_field,
                faces: params.faces.clone(),
                layers,
                quads,
                macros,
                texture_format: format,
                stats,
                hlod: None,
                object: None,
                // block formats: stored as version 8, their quads' places and stacks derived on reading
                packing: format.block().map(|_| options.packing),
            },
            near: class.near.iter().map(|r| [r.mesh, r.tri]).collect(),
            macro_blobs,
        })
    }

    /// The HLOD cell (`lemi_core::hlod`): the near list and the far field simplified in
    /// distance bands, no layers recorded (the header keeps the placement's layers, which fixed
    /// the near field).
    fn bake_hlod(
        &self,
        cell: &ViewCell,
        plan: &CellPlan,
        near: &[TriRef],
        options: HlodOptions,
        mut seconds: Vec<(String, f64)>,
        on_stage: &mut impl FnMut(&Stage),
    ) -> Result<CellFile, BakeError> {
        let params = &self.recorder.params;
        on_stage(&Stage::Simplify);
        let t = Instant::now();
        let far = simplify_far_field(
            self.recorder.scene,
            cell,
            plan.near_field,
            near,
            params.alpha,
            &options,
        )
        .map_err(ParamsError::from)?;
        seconds.push(("simplify".into(), t.elapsed().as_secs_f64()));
        let hlod = HlodHeader::of(&far, &options);
        let stats = CellStats {
            far_triangles: far.source_triangles(),
            near_triangles: near.len() as u64,
            submitted_triangles: far.triangles(),
            raw_bytes: hlod.mesh_bytes(),
            seconds,
            ..Default::default()
        };
        Ok(CellFile {
            header: CellHeader {
                fringe_quads: 0,
                cell: *cell,
                params_hash: params.hash(),
                scene_fingerprint: String::new(),
                resolution: params.resolution,
                near_field: plan.near_field,
                faces: params.faces.clone(),
                layers: layer_infos(plan),
                quads: Vec::new(),
                macros: Vec::new(),
                stats,
                hlod: Some(hlod),
                object: None,
                texture_format: Default::default(),
                packing: None,
            },
            near: near.iter().map(|r| [r.mesh, r.tri]).collect(),
            macro_blobs: Vec::new(),
        })
    }

    /// The layers of `cell` and what each records, for this baker's parameters and scene (what
    /// [`Baker::bake`] and [`Baker::record_depths`] use).
    pub fn plan(&self, cell: &ViewCell) -> Result<CellPlan, BakeError> {
        Ok(self.recorder.plan(cell)?)
    }

    /// The per-texel depths of the layers of `cell` as the bake records them
    /// ([`CellRecorder::record_depths`]).
    pub fn record_depths(&self, cell: &ViewCell) -> Result<LayerDepths, BakeError> {
        Ok(self.recorder.record_depths(cell)?)
    }
}

/// The placement's layers of every face as stored.
/// The compression options a bake with `params` uses for `cell` (gap filling by the layering,
/// hidden-texel removal by the movement between the cell's layers, the micro-grid, block-aligned
/// and trimmed packing for block formats).
pub fn compress_options(params: &BakeParams, cell: &ViewCell) -> CompressOptions {
    CompressOptions {
        hidden: HiddenTexelOptions {
            cell_half: Some(cell.half),
            ..Default::default()
        },
        gap_fill: Recording::of(params.layering).gap_fill,
        outline_copies: params.outline_copies && Recording::of(params.layering).crack_free,
        // a format without the fringe's alpha level keeps it as quads of its own
        fringe_quads: params.outline_fringe && !params.texture_format.keeps_fringe(),
        micro: MicroTextureOptions {
            cell_size: params.micro_grid,
            threshold: params.micro_threshold,
            ..Default::default()
        },
        packing: PackingOptions {
            // a block format: no 4×4 block mixes two micro-textures
            block: if params.texture_format.block().is_some() {
                4
            } else {
                1
            },
            // no texture doubled for the few footprints that overflow a power of two
            trim: true,
            // micro-textures of a face share blocks in stacks (version 8 cells): with BC1 only
            // those at most half a block thin, whose padding wasted half of every block, since
            // a BC1 block's four colours then serve all the texels it holds; BC7's (and
            // UASTC's) partitions serve two or three regions of a block, so with them every
            // micro-texture may join; ETC1S (one base colour a block, shared codebooks; its
            // point is the disk, which it meets without) does not stack (docs/COMPRESSION.md,
            // "Stacks")
            stack: match (params.texture_format, params.texture_format.block()) {
                (TextureFormat::Etc1s, _) => 0,
                (_, Some(BlockFormat::Bc1)) => 2,
                (_, Some(BlockFormat::Bc7)) => PackingOptions::default().max_size,
                (_, None) => 0,
            },
            ..Default::default()
        },
        ..Default::default()
    }
}

/// Makes every allocation of 1 MiB or more a fresh mapping of the C library's allocator (glibc
/// on Linux; elsewhere nothing to do). A layer image is `Res²` texels of which the recorder
/// writes only the tiles its slab's triangles touch (7 % of them on a `builtin:city:1M` cell at
/// 2048²), and a fresh zeroed mapping costs neither time nor memory for the pages never written.
/// glibc's default, a threshold that rises to the size of the largest buffer freed, instead
/// serves the next layer's buffer from the heap and zeroes all of it: measured on that cell,
/// 3.4 GB of peak memory instead of 1.35 GB.
fn map_large_buffers() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        static ONCE: std::sync::Once = std::sync::Once::new();
        // SAFETY: mallopt only changes the allocator's parameters; it is called once, before
        // the bake allocates its layer buffers.
        ONCE.call_once(|| unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 20);
        });
    }
}

fn layer_infos(plan: &CellPlan) -> Vec<Vec<LayerInfo>> {
    plan.faces
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
        .collect()
}

impl From<RecordError> for BakeError {
    fn from(e: RecordError) -> BakeError {
        BakeError::Record(Box::new(e))
    }
}
