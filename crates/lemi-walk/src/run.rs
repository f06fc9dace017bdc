//! [`walk`]: replays a camera path through a far-field strategy, then with all the geometry, and
//! measures every frame (Jeschke & Wimmer, GI 2002, sec. 6 and Figs. 8–9: frame times of the
//! impostor walkthrough against the geometry, cell switches, primitives per frame).
//!
//! The impostor pass is paced in real time: a frame that finishes before its time on the path
//! waits, so a strategy's background loader gets exactly the time a real walk would give it. When
//! frames take longer than the path's frame interval (software rendering at high resolution),
//! the loader gets more time than in real time; [`WalkSummary::slower_than_real_time_frames`]
//! counts those frames. The geometry passes render the same poses as fast as they can: all the
//! geometry with the reference renderer (`lemi_gpu::Renderer::render`, unculled), then the
//! `geometry-culled` baseline (`lemi_gpu::Renderer::render_culled`: the same renderer after
//! frustum culling Morton-ordered clusters, the same image), which is what a speed-up is quoted
//! against.
//!
//! Every pass times its frames as a runtime draws them: submitted, then waited for, without
//! copying the pixels back to the CPU (a runtime presents its frames; a readback would add the
//! same few milliseconds to both sides of every comparison, at 1280 × 720 on lavapipe 2-7 ms).
//! Only the impostor frames an observer asks for ([`WalkOptions::keep_frame`]) are read back.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use lemi_core::cell::CellGrid;
use lemi_core::Scene;
use lemi_gpu::{
    CullOptions, Frame, Gpu, GpuCulledScene, GpuScene, RenderOptions, Renderer, UploadOptions,
};
use lemi_strategy::{FrameRequest, Strategy, StrategyKind, StrategyReport};
use serde::{Deserialize, Serialize};

use crate::path::{CameraPath, Pose};
use crate::record::{write_csv, FrameRecord, FrameStats, Mode};
use crate::{plot, WalkError};

/// The sky colour both passes clear to.
pub const CLEAR: [u8; 4] = [150, 190, 235, 255];

/// Something that happened during [`walk`], for progress bars and frame dumps.
pub enum WalkEvent<'a> {
    /// The strategy is loading or preparing the first cells.
    Preloading,
    /// An impostor frame was drawn.
    Impostor {
        record: &'a FrameRecord,
        /// The frame's pixels, where [`WalkOptions::keep_frame`] asked for them (strategies that
        /// finish frames on the CPU give them always).
        frame: Option<&'a Frame>,
    },
    /// A frame of an all-geometry replay was drawn (unculled or geometry-culled: the record's
    /// mode tells).
    Geometry { record: &'a FrameRecord },
}

/// A function told of every [`WalkEvent`]; an error stops the walk ([`WalkError::Observer`]).
pub type Observer<'a> = dyn FnMut(WalkEvent<'_>) -> Result<(), String> + 'a;

/// What [`walk`] needs besides the strategy and the path.
pub struct WalkOptions<'a> {
    /// The device the strategy draws with; the geometry replay uses it too.
    pub gpu: &'a Gpu,
    /// The scene (all geometry, for the replay and the triangle counts).
    pub scene: &'a Scene,
    /// The bundle's cell grid (names the cell of each geometry frame).
    pub grid: &'a CellGrid,
    /// Frame size in pixels.
    pub size: (u32, u32),
    /// Horizontal field of view in degrees, in `(0, 180)`.
    pub fov_x_deg: f64,
    /// Also replay the path drawing all geometry, unculled.
    pub geometry: bool,
    /// Also replay the path drawing all geometry frustum culled (the `geometry-culled` baseline).
    pub culled: bool,
    /// How long the strategy may take to get the first cells ready.
    pub preload_timeout: Duration,
    /// Told of every frame (`None`: nobody listens).
    pub observer: Option<&'a mut Observer<'a>>,
    /// Which impostor frames (by index on the path) are read back for the observer; the rest are
    /// drawn and timed without a readback (`None`: none is read back).
    pub keep_frame: Option<&'a dyn Fn(u64) -> bool>,
}

impl<'a> WalkOptions<'a> {
    /// Options with the defaults: 1280 × 720, 60°, with both geometry replays, 60 s to preload.
    pub fn new(gpu: &'a Gpu, scene: &'a Scene, grid: &'a CellGrid) -> Self {
        WalkOptions {
            gpu,
            scene,
            grid,
            size: (1280, 720),
            fov_x_deg: 60.0,
            geometry: true,
            culled: true,
            preload_timeout: Duration::from_secs(60),
            observer: None,
            keep_frame: None,
        }
    }
}

/// `summary.json` of a walk: the frame statistics ([`FrameStats`], flattened: `frames`, `stalls`,
/// `cell_switches`, `impostor_median_ms`, …) and what the run knows besides.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WalkSummary {
    #[serde(flatten)]
    pub stats: FrameStats,
    /// Impostor frames (after the first) that started later than their time on the path.
    pub slower_than_real_time_frames: u64,
    /// Frame size `[width, height]`.
    pub size: [u32; 2],
    pub fov_x_deg: f64,
    /// The GPU adapter.
    pub adapter: String,
    pub strategy: StrategyKind,
    /// Cells loaded from disk, evicted, the most bytes the strategy held (its report).
    pub loads: u64,
    pub evictions: u64,
    pub peak_cache_bytes: u64,
    /// Impostors regenerated (dynamic) or far fields recorded at run time (warp).
    pub regenerations: u64,
    pub prepare_seconds: f64,
    pub prepared_cells: u64,
    pub texture_bytes_per_cell: f64,
    /// The strategy's warnings, frame by frame.
    pub warnings: Vec<String>,
    /// Where the walk's files were written, if they were.
    pub out: Option<PathBuf>,
}

impl WalkSummary {
    /// Writes the summary as pretty JSON, atomically.
    pub fn write_json(&self, path: &Path) -> Result<(), WalkError> {
        let mut text = serde_json::to_string_pretty(self).map_err(|source| WalkError::Json {
            what: "walk summary",
            path: path.to_path_buf(),
            source,
        })?;
        text.push('\n');
        lemi_core::container::write_atomic(path, text.as_bytes())
            .map_err(|e| WalkError::io("walk summary", path, e))
    }

    /// Reads a summary [`WalkSummary::write_json`] wrote.
    pub fn read_json(path: &Path) -> Result<WalkSummary, WalkError> {
        let text =
            std::fs::read_to_string(path).map_err(|e| WalkError::io("walk summary", path, e))?;
        serde_json::from_str(&text).map_err(|source| WalkError::Json {
            what: "walk summary",
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Everything a walk measured.
#[derive(Clone, Debug)]
pub struct WalkRun {
    /// One record per frame of the impostor pass.
    pub impostor: Vec<FrameRecord>,
    /// One record per frame of the unculled geometry replay (empty without it).
    pub geometry: Vec<FrameRecord>,
    /// One record per frame of the geometry-culled replay (empty without it).
    pub culled: Vec<FrameRecord>,
    pub summary: WalkSummary,
    /// The strategy's totals at the end of the impostor pass.
    pub report: StrategyReport,
}

impl WalkRun {
    /// Writes `frames.csv` (impostor rows, then geometry rows, then geometry-culled rows),
    /// `summary.json` and `plot.png` into `dir` (which must exist).
    pub fn write_files(&self, dir: &Path) -> Result<(), WalkError> {
        let mut all = self.impostor.clone();
        all.extend(self.geometry.iter().cloned());
        all.extend(self.culled.iter().cloned());
        write_csv(&dir.join("frames.csv"), &all)?;
        self.summary.write_json(&dir.join("summary.json"))?;
        plot::write_plot(&dir.join("plot.png"), &self.impostor, &self.geometry)
    }
}

/// The vertical field of view (degrees) of a horizontal one at `width × height`.
fn fov_y_of(fov_x_deg: f64, (w, h): (u32, u32)) -> f64 {
    2.0 * ((0.5 * fov_x_deg.to_radians()).tan() * h as f64 / w as f64)
        .atan()
        .to_degrees()
}

fn view_of(
    frame: u64,
    pose: &Pose,
    fov_y: f64,
    (w, h): (u32, u32),
) -> Result<lemi_core::camera::View, WalkError> {
    pose.camera(fov_y, w, h)
        .map(|c| c.view())
        .map_err(|source| WalkError::Camera { frame, source })
}

/// Walks `path`: the impostor pass through `strategy` (real-time paced, see the module doc), then,
/// with [`WalkOptions::geometry`], the same poses with all geometry, and with
/// [`WalkOptions::culled`] with all geometry frustum culled; one [`FrameRecord`] per frame and the
/// [`WalkSummary`].
pub fn walk(
    strategy: &mut dyn Strategy,
    path: &CameraPath,
    mut options: WalkOptions<'_>,
) -> Result<WalkRun, WalkError> {
    let (w, h) = options.size;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(WalkError::Options(format!(
            "frame size {w}x{h}: width and height must be 1..=16384"
        )));
    }
    let fov_x = options.fov_x_deg;
    if !(fov_x.is_finite() && fov_x > 0.0 && fov_x < 180.0) {
        return Err(WalkError::Options(format!(
            "field of view {fov_x}°: must be in (0, 180) degrees"
        )));
    }
    path.validate()
        .map_err(|source| WalkError::Options(format!("the camera path: {source}")))?;
    let fov_y = fov_y_of(fov_x, options.size);
    let kind = strategy.kind();
    let gpu = options.gpu;
    let scene = options.scene;
    let mut notify = |event: WalkEvent<'_>| -> Result<(), WalkError> {
        match options.observer.as_mut() {
            Some(f) => f(event).map_err(WalkError::Observer),
            None => Ok(()),
        }
    };
    let gpu_err = |what: &str| {
        let what = what.to_string();
        move |source| WalkError::Gpu { what, source }
    };
    let strategy_err = |what: String| {
        move |source| WalkError::Strategy {
            what,
            strategy: kind.name(),
            source,
        }
    };
    let render_options = RenderOptions {
        clear: CLEAR,
        ..Default::default()
    };
    // All geometry, for the replays (resident during the impostor pass too, as it always was).
    let replay = if options.geometry {
        Some(
            GpuScene::upload(gpu, scene, &UploadOptions::default())
                .map_err(gpu_err("uploading the scene for the geometry replay"))?,
        )
    } else {
        None
    };
    let culled_replay = if options.culled {
        let materials = match &replay {
            Some(full) => full.materials.clone(),
            None => std::sync::Arc::new(
                lemi_gpu::GpuMaterials::upload(gpu, &scene.materials, &scene.textures).map_err(
                    gpu_err("uploading the materials for the geometry-culled replay"),
                )?,
            ),
        };
        let geometry = lemi_gpu::CulledGeometry::upload(gpu, scene, &CullOptions::default())
            .map_err(gpu_err(
                "uploading the scene for the geometry-culled replay",
            ))?;
        Some(
            GpuCulledScene::from_parts(materials, geometry)
                .map_err(gpu_err("the geometry-culled scene"))?,
        )
    } else {
        None
    };
    let renderer = if replay.is_some() || culled_replay.is_some() {
        Some(Renderer::new(gpu).map_err(gpu_err("the reference renderer"))?)
    } else {
        None
    };
    let total_triangles = scene.triangle_count();
    let frames: Vec<(u64, f64, Pose)> = path.frames().collect();
    if let Some((_, _, first)) = frames.first() {
        notify(WalkEvent::Preloading)?;
        strategy
            .preload(first.eye, first.velocity, options.preload_timeout)
            .map_err(strategy_err("preloading the first cells".into()))?;
    }

    let dt = 1.0 / path.fps;
    let mut impostor = Vec::with_capacity(frames.len());
    let mut warnings = Vec::new();
    let mut slow_frames = 0u64;
    let mut last_cell: Option<lemi_core::cell::CellId> = None;
    let mut regenerations = 0u64;
    let start = Instant::now();
    let t0 = frames.first().map_or(0.0, |f| f.1);
    for (index, t, pose) in &frames {
        // real-time pacing: this frame starts at its time on the path
        let due = Duration::from_secs_f64((t - t0).max(0.0));
        match due.checked_sub(start.elapsed()) {
            Some(wait) => std::thread::sleep(wait),
            None if *index > 0 => slow_frames += 1,
            None => {}
        }
        let view = view_of(*index, pose, fov_y, options.size)?;
        let t_frame = Instant::now();
        let f = strategy
            .frame(&FrameRequest {
                eye: pose.eye,
                velocity: pose.velocity,
                dt,
                view: &view,
                options: &render_options,
                measure_error: false,
                read_back: options.keep_frame.is_some_and(|keep| keep(*index)),
            })
            .map_err(strategy_err(format!("rendering frame {index}")))?;
        let cpu_ms = 1e3 * t_frame.elapsed().as_secs_f64();
        warnings.extend(f.warnings.iter().cloned());
        let switch = *index > 0 && f.cell != last_cell;
        last_cell = f.cell;
        regenerations += f.regenerations;
        let record = FrameRecord {
            frame: *index,
            t: *t,
            mode: Mode::Impostor,
            cpu_ms,
            gpu_ms: f.gpu_ms,
            near_triangles: f.near_triangles,
            impostor_quads: f.far_primitives,
            total_triangles: if f.fallback {
                total_triangles
            } else {
                f.near_triangles
            },
            cell: f.cell.map(|c| c.to_string()),
            cell_switch: switch,
            stalled: f.stalled,
            cache_bytes: f.cache_bytes,
            fallback: f.fallback,
        };
        notify(WalkEvent::Impostor {
            record: &record,
            frame: f.frame.as_ref(),
        })?;
        impostor.push(record);
    }
    let report = strategy.report();

    // one record of an all-geometry replay (unculled or culled): no impostors, no streaming
    let replay_record =
        |index: u64, t: f64, mode: Mode, eye, started: Instant, gpu_ms, tris| FrameRecord {
            frame: index,
            t,
            mode,
            cpu_ms: 1e3 * started.elapsed().as_secs_f64(),
            gpu_ms,
            near_triangles: 0,
            impostor_quads: 0,
            total_triangles: tris,
            cell: options.grid.locate(eye).map(|c| c.id().to_string()),
            cell_switch: false,
            stalled: false,
            cache_bytes: 0,
            fallback: false,
        };
    let mut geometry = Vec::new();
    if let (Some(full), Some(renderer)) = (&replay, &renderer) {
        for (index, t, pose) in &frames {
            let view = view_of(*index, pose, fov_y, options.size)?;
            let t_frame = Instant::now();
            renderer
                .render_frame(full, &view, &render_options, false)
                .map_err(gpu_err(&format!("rendering geometry frame {index}")))?;
            let record = replay_record(
                *index,
                *t,
                Mode::Geometry,
                pose.eye,
                t_frame,
                renderer.last_gpu_ms(),
                total_triangles,
            );
            notify(WalkEvent::Geometry { record: &record })?;
            geometry.push(record);
        }
    }
    let mut culled = Vec::new();
    if let (Some(scene), Some(renderer)) = (&culled_replay, &renderer) {
        for (index, t, pose) in &frames {
            let view = view_of(*index, pose, fov_y, options.size)?;
            let t_frame = Instant::now();
            let (_, stats) = renderer
                .render_culled_frame(scene, &view, &render_options, false)
                .map_err(gpu_err(&format!("rendering geometry-culled frame {index}")))?;
            let record = replay_record(
                *index,
                *t,
                Mode::Culled,
                pose.eye,
                t_frame,
                renderer.last_gpu_ms(),
                stats.triangles,
            );
            notify(WalkEvent::Geometry { record: &record })?;
            culled.push(record);
        }
    }
    let summary = WalkSummary {
        stats: FrameStats::of_all(&impostor, &geometry, &culled),
        slower_than_real_time_frames: slow_frames,
        size: [w, h],
        fov_x_deg: fov_x,
        adapter: gpu.describe(),
        strategy: kind,
        loads: report.loads,
        evictions: report.evictions,
        peak_cache_bytes: report.peak_bytes,
        regenerations,
        prepare_seconds: report.prepare_seconds,
        prepared_cells: report.prepared_cells,
        texture_bytes_per_cell: report.texture_bytes_per_cell,
        warnings,
        out: None,
    };
    Ok(WalkRun {
        impostor,
        geometry,
        culled,
        summary,
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::tests::rec;

    fn summary() -> WalkSummary {
        let imp: Vec<FrameRecord> = (0..10).map(|i| rec(i, Mode::Impostor, 5.0)).collect();
        let geo: Vec<FrameRecord> = (0..10).map(|i| rec(i, Mode::Geometry, 20.0)).collect();
        let culled: Vec<FrameRecord> = (0..10).map(|i| rec(i, Mode::Culled, 10.0)).collect();
        WalkSummary {
            stats: FrameStats::of_all(&imp, &geo, &culled),
            slower_than_real_time_frames: 1,
            size: [64, 36],
            fov_x_deg: 60.0,
            adapter: "test".into(),
            strategy: StrategyKind::Lemi,
            loads: 2,
            evictions: 0,
            peak_cache_bytes: 1 << 20,
            regenerations: 0,
            prepare_seconds: 0.0,
            prepared_cells: 0,
            texture_bytes_per_cell: 0.0,
            warnings: vec![],
            out: Some("walk".into()),
        }
    }

    #[test]
    fn summary_json_has_the_keys_of_summary_json_and_round_trips() {
        let s = summary();
        let v = serde_json::to_value(&s).unwrap();
        for k in [
            "frames",
            "geometry_frames",
            "stalls",
            "cell_switches",
            "impostor_median_ms",
            "impostor_p99_ms",
            "geometry_median_ms",
            "geometry_p99_ms",
            "speedup_median",
            "culled_median_ms",
            "culled_p99_ms",
            "culled_mean_triangles",
            "speedup_culled_median",
            "impostor_mean_fps",
            "geometry_mean_fps",
            "impostor",
            "geometry",
            "slower_than_real_time_frames",
            "size",
            "fov_x_deg",
            "adapter",
            "loads",
            "evictions",
            "peak_cache_bytes",
            "regenerations",
            "prepare_seconds",
            "prepared_cells",
            "texture_bytes_per_cell",
            "warnings",
            "out",
        ] {
            assert!(v.get(k).is_some_and(|x| !x.is_null()), "{k}");
        }
        assert_eq!(v["strategy"], "lemi");
        assert_eq!(v["speedup_median"], 4.0);
        assert_eq!(v["speedup_culled_median"], 2.0);
        assert_eq!(v["size"], serde_json::json!([64, 36]));
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("summary.json");
        s.write_json(&f).unwrap();
        assert_eq!(WalkSummary::read_json(&f).unwrap(), s);
        std::fs::write(&f, "{}").unwrap();
        let e = WalkSummary::read_json(&f).unwrap_err().to_string();
        assert!(e.contains("summary.json"), "{e}");
    }

    #[test]
    fn fov_conversion() {
        assert!((fov_y_of(90.0, (100, 100)) - 90.0).abs() < 1e-9);
        assert!(fov_y_of(60.0, (1280, 720)) < 60.0);
    }
}
