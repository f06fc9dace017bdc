//! Cell streaming, once per frame: locate the current view cell, request the cells predicted from
//! position and velocity from the background [`Loader`], keep them in a byte-bounded LRU
//! [`Cache`], spread their texture uploads over frames under a per-frame byte budget, and say
//! whether the current cell can be drawn — counting every frame that had to wait for it (a
//! stall).
//!
//! This work is based on the runtime of GI 2002 sec. 3: "1. Determine the current view cell of the
//! observer. 2. Prefetch the geometry and impostors of adjacent view cells in order to avoid
//! varying frame rates (assuming … a limited observer speed). To amortize the cost of texture
//! downloads over several frames, prefetched impostor textures are downloaded to texture memory
//! in smaller chunks."
//!
//! Per frame ([`Streamer::frame`]):
//! 1. receive the cells the loader finished (a failed one is recorded with a warning and never
//!    requested again, see [`Streamer::clear_failures`]);
//! 2. predict the cells to have ready ([`crate::predict()`]: current cell, then by earliest possible
//!    arrival) and keep the longest prefix whose estimated sizes fit the cache budget (the
//!    current cell always); mark them used, least wanted first, so the LRU evicts what is not
//!    wanted before what is wanted least; ask the loader for those not cached;
//! 3. advance uploads in that order, current cell first, while the frame's upload budget lasts
//!    (see [`StreamerOptions::upload_budget_bytes_per_frame`]);
//! 4. if the current cell is not completely uploaded, the frame **stalls** (counted once):
//!    [`StallPolicy::Block`] waits for the loader and finishes the upload now,
//!    [`StallPolicy::Fallback`] reports a fallback (the caller draws all geometry this frame);
//! 5. evict least recently used cells until the cache is within budget (never the current cell).
//!
//! A cell is handed out ([`FrameState::ready`]) only as an [`ImpostorCell`], which exists only once
//! every texture row is written, so a partly uploaded cell can never be drawn.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use lemi_core::bundle::{Bundle, Manifest};
use lemi_core::cell::{CellGrid, CellId};
use lemi_core::Scene;
use lemi_gpu::impostor::PendingImpostorCell;
use lemi_gpu::{Gpu, GpuMaterials, ImpostorCell};

use crate::cache::Cache;
use crate::loader::{DecodedCell, Loaded, Loader, LoaderOptions};
use crate::predict::{predict, PredictOptions};
use crate::RuntimeError;

/// What a frame does when its cell is not ready.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StallPolicy {
    /// Wait for the loader and finish the upload in this frame (the frame is late, the image is
    /// right).
    #[default]
    Block,
    /// Do not wait: report a fallback, the caller draws the full geometry this frame.
    Fallback,
}

/// Streaming parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamerOptions {
    /// Bytes the cached cells may hold, main and GPU memory together (decoded cells count their
    /// CPU data, uploading cells both, uploaded cells their GPU textures and buffers).
    pub cache_budget_bytes: u64,
    /// Bytes uploaded per frame. A frame's first step always writes at least one texture row, and
    /// a cell's geometry (vertex and index buffers) is uploaded in one go when its upload begins,
    /// so a frame may exceed the budget by one row plus the geometry of a cell begun in it.
    pub upload_budget_bytes_per_frame: u64,
    /// How far ahead to predict (seconds); should exceed the time to load and upload a cell.
    pub horizon_seconds: f64,
    /// The highest observer speed planned for (m/s).
    pub max_speed: f64,
    /// The highest observer acceleration planned for (m/s²).
    pub max_acceleration: f64,
    /// At most this many predicted cells are considered per frame.
    pub max_predicted_cells: usize,
    pub stall_policy: StallPolicy,
    /// With [`StallPolicy::Block`], give up waiting for one cell after this long and fall back.
    pub max_block: Duration,
    pub loader: LoaderOptions,
}

impl Default for StreamerOptions {
    /// 256 MiB of cache, 4 MiB of uploads per frame, 2 s ahead at up to 10 m/s and 5 m/s², block.
    fn default() -> Self {
        StreamerOptions {
            cache_budget_bytes: 256 << 20,
            upload_budget_bytes_per_frame: 4 << 20,
            horizon_seconds: 2.0,
            max_speed: 10.0,
            max_acceleration: 5.0,
            max_predicted_cells: 27,
            stall_policy: StallPolicy::Block,
            max_block: Duration::from_secs(30),
            loader: LoaderOptions::default(),
        }
    }
}

/// Totals since the streamer started.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StreamStats {
    pub frames: u64,
    /// Frames whose current cell was not ready when they needed it (waited for, or fallen back).
    pub stalls: u64,
    /// Frames that reported a fallback (stalls under [`StallPolicy::Fallback`], failed or unbaked
    /// cells, positions outside the grid).
    pub fallback_frames: u64,
    /// Cells the loader delivered decoded.
    pub loads: u64,
    /// Cells completely uploaded.
    pub uploads: u64,
    pub evictions: u64,
    /// Cells that could not be loaded or uploaded.
    pub failures: u64,
    pub uploaded_bytes: u64,
    /// Wall-clock seconds frames spent blocked ([`StallPolicy::Block`]).
    pub stall_seconds: f64,
    /// The most bytes the cache held at the end of a frame.
    pub peak_cache_bytes: u64,
    /// Simulated seconds (the sum of the frames' `dt`).
    pub seconds: f64,
}

/// What one frame should draw, and what streaming did.
pub struct FrameState<'a> {
    /// Frame number, from 1.
    pub frame: u64,
    /// The view cell containing the position (`None` outside the grid).
    pub current_cell: Option<CellId>,
    /// The current cell's impostors, only when completely uploaded.
    pub ready: Option<&'a ImpostorCell>,
    /// The current cell was not ready when this frame needed it (counted in `stats.stalls`).
    pub stalled: bool,
    /// Why the current cell cannot be shown this frame; the caller then draws all geometry.
    pub fallback: Option<String>,
    /// Warnings raised this frame (a damaged or mismatched cell, once per cell).
    pub warnings: Vec<String>,
    /// Cells the loader delivered this frame.
    pub loaded: Vec<CellId>,
    /// Cells evicted this frame.
    pub evicted: Vec<CellId>,
    /// Bytes in the cache at the end of the frame.
    pub cache_bytes: u64,
    /// Texture and geometry bytes uploaded this frame.
    pub uploaded_bytes_this_frame: u64,
    pub stats: StreamStats,
}

impl std::fmt::Debug for FrameState<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameState")
            .field("frame", &self.frame)
            .field("current_cell", &self.current_cell)
            .field("ready", &self.ready.is_some())
            .field("stalled", &self.stalled)
            .field("fallback", &self.fallback)
            .field("warnings", &self.warnings)
            .field("loaded", &self.loaded)
            .field("evicted", &self.evicted)
            .field("cache_bytes", &self.cache_bytes)
            .field("uploaded_bytes_this_frame", &self.uploaded_bytes_this_frame)
            .field("stats", &self.stats)
            .finish()
    }
}

/// Where a cached cell is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellState {
    /// Decoded in main memory, upload not begun.
    Decoded,
    /// Uploading: `uploaded` of `total` macro-texture bytes written.
    Uploading { uploaded: u64, total: u64 },
    /// Completely uploaded, drawable.
    Ready,
}

enum Slot {
    Decoded(Box<DecodedCell>),
    Uploading(Box<PendingImpostorCell>),
    Ready(Box<ImpostorCell>),
    /// Transient, while a cell changes state (never left in the cache).
    Moving,
}

impl Slot {
    fn bytes(&self) -> u64 {
        match self {
            Slot::Decoded(d) => d.bytes,
            Slot::Uploading(p) => p.cpu_bytes() + p.gpu_bytes(),
            Slot::Ready(c) => c.gpu_bytes(),
            Slot::Moving => 0,
        }
    }

    fn state(&self) -> Option<CellState> {
        match self {
            Slot::Decoded(_) => Some(CellState::Decoded),
            Slot::Uploading(p) => Some(CellState::Uploading {
                uploaded: p.uploaded_bytes(),
                total: p.texture_bytes(),
            }),
            Slot::Ready(_) => Some(CellState::Ready),
            Slot::Moving => None,
        }
    }
}

/// Streams the cells of one bundle. Dropping it stops the loader.
pub struct Streamer {
    gpu: Arc<Gpu>,
    materials: Arc<GpuMaterials>,
    grid: CellGrid,
    /// An object bundle's view cell: its one cell serves only viewpoints inside it.
    object: Option<lemi_core::object_cell::ObjectViewCell>,
    bundle: PathBuf,
    /// Baked cells: id → manifest file size.
    baked: HashMap<CellId, u64>,
    options: StreamerOptions,
    loader: Loader,
    loader_gone: bool,
    cache: Cache<CellId, Slot>,
    /// Cells that failed: id → message (naming the file).
    failed: HashMap<CellId, String>,
    /// The most bytes each cell was seen to hold (its admission estimate).
    sizes: HashMap<CellId, u64>,
    stats: StreamStats,
}

/// Per-frame scratch: what happened, for [`FrameState`].
#[derive(Default)]
struct Events {
    warnings: Vec<String>,
    loaded: Vec<CellId>,
    uploaded: u64,
}

impl Streamer {
    /// A streamer for the bundle in `bundle_dir` with its `manifest`. `scene` must be the scene the
    /// bundle was baked from (checking it against the manifest's fingerprint is the caller's job,
    /// as `lemi render` does); `materials` its materials on `gpu`.
    ///
    /// Errors: options out of range (named), a manifest whose grid is unusable, whose cell ids lie
    /// outside its grid, or whose `params_hash` is not the hash of its `params`.
    pub fn new(
        gpu: Arc<Gpu>,
        manifest: Manifest,
        bundle_dir: &Path,
        scene: Arc<Scene>,
        materials: Arc<GpuMaterials>,
        options: StreamerOptions,
    ) -> Result<Streamer, RuntimeError> {
        validate(&options)?;
        let manifest_path = lemi_core::bundle::manifest_path(bundle_dir);
        let bad = |message: String| RuntimeError::Manifest {
            path: manifest_path.clone(),
            message,
        };
        let g = &manifest.grid;
        if !(g.cell_size.is_finite() && g.cell_size > 0.0 && g.origin.is_finite())
            || g.counts.min_element() < 1
            || g.len() as u64 > lemi_core::cell::MAX_CELLS
        {
            return Err(bad(format!(
                "unusable grid (origin {:?}, cell size {}, counts {:?})",
                g.origin.to_array(),
                g.cell_size,
                g.counts.to_array()
            )));
        }
        let mut baked = HashMap::new();
        for e in &manifest.cells {
            if let Err(err) = g.cell_of(e.id) {
                return Err(bad(err.to_string()));
            }
            baked.insert(e.id, e.bytes);
        }
        let grid = manifest.grid.clone();
        let object = manifest.object.as_ref().map(|o| o.cell);
        let block_formats = match manifest.params.texture_format.block() {
            Some(format) if !gpu.has_block_format(format) => {
                eprintln!(
                    "warning: this adapter cannot sample {} textures: the bundle's \
                     macro-textures are decoded to RGBA8 ({}x their texture memory)",
                    format.texture_format(),
                    64 / format.block_bytes()
                );
                false
            }
            Some(_) => true,
            None => false,
        };
        let bundle =
            Bundle::from_manifest(bundle_dir, manifest).map_err(|e| bad(e.kind.to_string()))?;
        let loader = Loader::spawn(
            bundle,
            scene,
            LoaderOptions {
                texture_side: gpu.limits().max_texture_dimension_2d,
                block_formats,
                ..options.loader.clone()
            },
        )?;
        Ok(Streamer {
            gpu,
            materials,
            grid,
            object,
            bundle: bundle_dir.to_path_buf(),
            baked,
            cache: Cache::new(options.cache_budget_bytes),
            options,
            loader,
            loader_gone: false,
            failed: HashMap::new(),
            sizes: HashMap::new(),
            stats: StreamStats::default(),
        })
    }

    pub fn options(&self) -> &StreamerOptions {
        &self.options
    }

    pub fn grid(&self) -> &CellGrid {
        &self.grid
    }

    pub fn bundle_dir(&self) -> &Path {
        &self.bundle
    }

    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// Bytes the cache holds now.
    pub fn cache_bytes(&self) -> u64 {
        self.cache.total_bytes()
    }

    /// The cached cells and their states, least recently used first.
    pub fn cached_cells(&self) -> Vec<(CellId, CellState)> {
        self.cache
            .lru_order()
            .into_iter()
            .filter_map(|id| Some((*id, self.cache.get(id)?.state()?)))
            .collect()
    }

    /// The cells that failed, with their messages (each naming the file), sorted by id.
    pub fn failed_cells(&self) -> Vec<(CellId, String)> {
        let mut v: Vec<(CellId, String)> =
            self.failed.iter().map(|(k, m)| (*k, m.clone())).collect();
        v.sort();
        v
    }

    /// Forgets the failures, so that those cells are requested again (e.g. after re-baking them).
    pub fn clear_failures(&mut self) {
        self.failed.clear();
    }

    /// Loads and uploads the cells wanted at `position` (the current cell and the predicted ones
    /// that fit the cache) before a walk starts, ignoring the upload budget — a loading screen, not
    /// counted as stalls or frames. Returns the warnings of cells that failed. Gives up after
    /// `timeout` with [`RuntimeError::Loader`].
    pub fn preload(
        &mut self,
        position: DVec3,
        velocity: DVec3,
        timeout: Duration,
    ) -> Result<Vec<String>, RuntimeError> {
        let t0 = Instant::now();
        let mut ev = Events::default();
        let current = self.locate(position);
        loop {
            self.receive(&mut ev);
            let wanted = self.wanted(position, velocity, current);
            self.request(&wanted);
            self.upload(&wanted, u64::MAX, &mut ev);
            let done = wanted.iter().all(|id| {
                self.failed.contains_key(id) || matches!(self.cache.get(id), Some(Slot::Ready(_)))
            });
            if done {
                let keep: Vec<&CellId> = current.iter().collect();
                let evicted = self.cache.evict_to_budget(&keep);
                self.stats.evictions += evicted.len() as u64;
                return Ok(ev.warnings);
            }
            if self.loader_gone {
                return Err(RuntimeError::Loader(
                    "stopped before the preload finished".into(),
                ));
            }
            let left = timeout.saturating_sub(t0.elapsed());
            if left.is_zero() {
                return Err(RuntimeError::Loader(format!(
                    "did not deliver the cells around the start within {:.1} s",
                    timeout.as_secs_f64()
                )));
            }
            match self
                .loader
                .recv_timeout(left.min(Duration::from_millis(50)))
            {
                Ok(Some(l)) => self.accept(l, &mut ev),
                Ok(None) => {}
                Err(e) => {
                    self.loader_gone = true;
                    ev.warnings.push(format!("warning: {e}"));
                }
            }
        }
    }

    /// One frame at `position` moving with `velocity` (m/s); `dt` is the frame's duration in
    /// seconds (only accumulated in [`StreamStats::seconds`]). See the module docs for what it
    /// does.
    pub fn frame(&mut self, position: DVec3, velocity: DVec3, dt: f64) -> FrameState<'_> {
        self.stats.frames += 1;
        if dt.is_finite() && dt > 0.0 {
            self.stats.seconds += dt;
        }
        let mut ev = Events::default();
        let current = self.locate(position);
        self.receive(&mut ev);
        let wanted = self.wanted(position, velocity, current);
        self.request(&wanted);
        self.upload(&wanted, self.options.upload_budget_bytes_per_frame, &mut ev);

        let mut stalled = false;
        let mut fallback = None;
        match current {
            None => {
                fallback = Some(format!(
                    "the position ({:.2}, {:.2}, {:.2}) is outside the bundle's view cells",
                    position.x, position.y, position.z
                ))
            }
            Some(id) if !self.baked.contains_key(&id) => {
                fallback = Some(format!("cell {id} was not baked into the bundle"))
            }
            Some(id) => {
                if let Some(m) = self.failed.get(&id) {
                    fallback = Some(m.clone());
                } else if !matches!(self.cache.get(&id), Some(Slot::Ready(_))) {
                    stalled = true;
                    self.stats.stalls += 1;
                    match self.options.stall_policy {
                        StallPolicy::Block => {
                            let t0 = Instant::now();
                            if let Err(m) = self.block_on(id, &mut ev) {
                                fallback = Some(m);
                            }
                            self.stats.stall_seconds += t0.elapsed().as_secs_f64();
                        }
                        StallPolicy::Fallback => {
                            let state = match self.cache.get(&id).and_then(Slot::state) {
                                Some(CellState::Uploading { uploaded, total }) => {
                                    format!("uploading, {uploaded} of {total} texture bytes")
                                }
                                Some(CellState::Decoded) => "decoded, upload not begun".into(),
                                _ => "loading".into(),
                            };
                            fallback = Some(format!("cell {id} is not ready yet ({state})"));
                        }
                    }
                }
            }
        }
        if fallback.is_some() {
            self.stats.fallback_frames += 1;
        }
        let keep: Vec<&CellId> = current.iter().collect();
        let evicted: Vec<CellId> = self
            .cache
            .evict_to_budget(&keep)
            .into_iter()
            .map(|e| e.id)
            .collect();
        self.stats.evictions += evicted.len() as u64;
        self.stats.uploaded_bytes += ev.uploaded;
        let cache_bytes = self.cache.total_bytes();
        self.stats.peak_cache_bytes = self.stats.peak_cache_bytes.max(cache_bytes);
        let ready = match current.and_then(|id| self.cache.get(&id)) {
            Some(Slot::Ready(c)) if fallback.is_none() => Some(&**c),
            _ => None,
        };
        FrameState {
            frame: self.stats.frames,
            current_cell: current,
            ready,
            stalled,
            fallback,
            warnings: ev.warnings,
            loaded: ev.loaded,
            evicted,
            cache_bytes,
            uploaded_bytes_this_frame: ev.uploaded,
            stats: self.stats,
        }
    }

    /// The cells to have ready, most wanted first: the current cell (if baked and not failed),
    /// then the predicted ones while their estimated sizes fit the cache budget.
    /// The cell serving `position` (see `Manifest::locate`).
    fn locate(&self, position: DVec3) -> Option<CellId> {
        match &self.object {
            Some(o) => o
                .contains(position)
                .then(|| self.grid.cell(glam::IVec3::ZERO))
                .flatten()
                .map(|c| c.id()),
            None => self.grid.locate(position).map(|c| c.id()),
        }
    }

    fn wanted(&self, position: DVec3, velocity: DVec3, current: Option<CellId>) -> Vec<CellId> {
        let o = &self.options;
        let popts = PredictOptions {
            horizon_seconds: o.horizon_seconds,
            max_speed: o.max_speed,
            max_acceleration: o.max_acceleration,
            max_cells: o.max_predicted_cells,
        };
        let mut wanted = Vec::new();
        let mut sum = 0u64;
        for p in predict(position, velocity, &self.grid, &popts) {
            let id = p.cell.id();
            if !self.baked.contains_key(&id) || self.failed.contains_key(&id) {
                continue;
            }
            let est = self.estimate(id);
            if Some(id) != current && sum.saturating_add(est) > o.cache_budget_bytes {
                break;
            }
            sum = sum.saturating_add(est);
            wanted.push(id);
        }
        wanted
    }

    /// The bytes a cell is expected to hold at its peak: what it was seen to hold, else the
    /// largest cell seen so far, else its file size.
    fn estimate(&self, id: CellId) -> u64 {
        if let Some(&s) = self.sizes.get(&id) {
            return s;
        }
        match self.sizes.values().max() {
            Some(&s) => s,
            None => self.baked.get(&id).copied().unwrap_or(0),
        }
    }

    /// Marks the wanted cells used (least wanted first) and asks the loader for the missing ones.
    fn request(&mut self, wanted: &[CellId]) {
        for id in wanted.iter().rev() {
            self.cache.touch(id);
        }
        let missing: Vec<CellId> = wanted
            .iter()
            .copied()
            .filter(|id| !self.cache.contains(id))
            .collect();
        self.loader.want(&missing);
    }

    /// Receives everything the loader has delivered.
    fn receive(&mut self, ev: &mut Events) {
        while !self.loader_gone {
            match self.loader.try_recv() {
                Ok(Some(l)) => self.accept(l, ev),
                Ok(None) => break,
                Err(e) => {
                    self.loader_gone = true;
                    ev.warnings.push(format!("warning: {e}"));
                }
            }
        }
    }

    fn accept(&mut self, l: Loaded, ev: &mut Events) {
        match l.result {
            Ok(d) => {
                self.stats.loads += 1;
                ev.loaded.push(l.id);
                let bytes = d.bytes;
                self.note_size(l.id, bytes);
                self.cache.insert(l.id, Slot::Decoded(Box::new(d)), bytes);
            }
            Err(e) => self.fail(l.id, e.to_string(), ev),
        }
    }

    fn fail(&mut self, id: CellId, message: String, ev: &mut Events) {
        ev.warnings.push(format!(
            "warning: {message}; cell {id} falls back to geometry"
        ));
        self.stats.failures += 1;
        self.cache.remove(&id);
        self.failed.insert(id, message);
    }

    fn note_size(&mut self, id: CellId, bytes: u64) {
        let s = self.sizes.entry(id).or_insert(0);
        *s = (*s).max(bytes);
    }

    /// Advances the uploads of the wanted cells in order within `budget` bytes; the first step
    /// always happens.
    fn upload(&mut self, wanted: &[CellId], budget: u64, ev: &mut Events) {
        let mut used = 0u64;
        for id in wanted {
            if used > 0 && used >= budget {
                break;
            }
            used += self.upload_cell(*id, budget.saturating_sub(used), ev);
        }
        ev.uploaded += used;
    }

    /// Advances one cell's upload by up to `budget` bytes (at least one row); returns the bytes
    /// uploaded (texture rows plus the geometry of a begun upload).
    fn upload_cell(&mut self, id: CellId, budget: u64, ev: &mut Events) -> u64 {
        let Some(slot) = self.cache.get_mut(&id) else {
            return 0;
        };
        if matches!(slot, Slot::Ready(_) | Slot::Moving) {
            return 0;
        }
        let mut used = 0;
        let mut pending = match std::mem::replace(slot, Slot::Moving) {
            Slot::Decoded(d) => {
                let DecodedCell { data, .. } = *d;
                match ImpostorCell::begin_upload(&self.gpu, self.materials.clone(), data) {
                    Ok(p) => {
                        used += p.geometry_bytes();
                        Box::new(p)
                    }
                    Err(e) => {
                        self.upload_failed(id, e, ev);
                        return used;
                    }
                }
            }
            Slot::Uploading(p) => p,
            other => {
                *slot = other;
                return 0;
            }
        };
        let before = pending.uploaded_bytes();
        let step = if used > 0 && used >= budget {
            // the geometry took this cell's share of the budget; rows follow next frame
            Ok(pending.is_complete())
        } else {
            pending.upload_step(&self.gpu, budget - used)
        };
        used += pending.uploaded_bytes() - before;
        let next = match step {
            Ok(true) => match pending.finish() {
                Ok(cell) => {
                    self.stats.uploads += 1;
                    Slot::Ready(Box::new(cell))
                }
                Err(e) => {
                    self.upload_failed(id, e, ev);
                    return used;
                }
            },
            Ok(false) => Slot::Uploading(pending),
            Err(e) => {
                self.upload_failed(id, e, ev);
                return used;
            }
        };
        let bytes = next.bytes();
        if let Some(slot) = self.cache.get_mut(&id) {
            *slot = next;
        }
        self.cache.set_bytes(&id, bytes);
        self.note_size(id, bytes);
        used
    }

    fn upload_failed(&mut self, id: CellId, e: lemi_gpu::GpuError, ev: &mut Events) {
        let path = self.bundle.join(lemi_core::bundle::cell_file_name(id));
        let err = RuntimeError::Cell {
            id,
            path,
            message: format!("uploading to the GPU failed: {e}"),
        };
        self.fail(id, err.to_string(), ev);
    }

    /// Waits until the current cell is decoded and finishes its upload (a stall under
    /// [`StallPolicy::Block`]); `Err` with the reason if it fails or the wait times out.
    fn block_on(&mut self, id: CellId, ev: &mut Events) -> Result<(), String> {
        let t0 = Instant::now();
        loop {
            if let Some(m) = self.failed.get(&id) {
                return Err(m.clone());
            }
            match self.cache.get(&id) {
                Some(Slot::Ready(_)) => return Ok(()),
                Some(_) => {
                    ev.uploaded += self.upload_cell(id, u64::MAX, ev);
                    continue;
                }
                None => {}
            }
            if self.loader_gone {
                return Err(format!(
                    "cell {id} cannot be loaded: the background loader stopped"
                ));
            }
            if !self.loader.is_pending(id) {
                // e.g. evicted by an earlier frame's insertions: ask again, first
                self.loader.want(&[id]);
            }
            let left = self.options.max_block.saturating_sub(t0.elapsed());
            if left.is_zero() {
                return Err(format!(
                    "cell {id} did not load within {:.1} s",
                    self.options.max_block.as_secs_f64()
                ));
            }
            match self.loader.recv_timeout(left) {
                Ok(Some(l)) => self.accept(l, ev),
                Ok(None) => {}
                Err(e) => {
                    self.loader_gone = true;
                    ev.warnings.push(format!("warning: {e}"));
                }
            }
        }
    }
}

fn validate(o: &StreamerOptions) -> Result<(), RuntimeError> {
    let bad =
        |option: &'static str, message: String| Err(RuntimeError::Options { option, message });
    if o.upload_budget_bytes_per_frame == 0 {
        return bad("upload_budget_bytes_per_frame", "must be > 0 bytes".into());
    }
    for (option, v) in [
        ("horizon_seconds", o.horizon_seconds),
        ("max_speed", o.max_speed),
        ("max_acceleration", o.max_acceleration),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return bad(option, format!("must be a finite number >= 0 (got {v})"));
        }
    }
    if o.max_predicted_cells == 0 {
        return bad("max_predicted_cells", "must be at least 1".into());
    }
    Ok(())
}
