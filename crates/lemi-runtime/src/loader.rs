//! The background cell loader: reads, verifies and decodes cell files off the render thread.
//!
//! This work is based on GI 2002 sec. 3, runtime step 2: impostors of adjacent view cells are
//! prefetched "in order to avoid varying frame rates". Everything that takes time and does not
//! need the GPU happens here: reading and checking the file with the bundle's one reader
//! ([`Bundle::verified_cell`]: size, BLAKE3 of the whole file, the container, the parameters hash,
//! the scene fingerprint, the cell's grid index), decoding the PNG macro-textures, copying the near triangles out of the scene and
//! laying out the quads' vertex arrays ([`ImpostorCellData::prepare`]). What is left for the render
//! thread is uploading.
//!
//! Plain `std`: worker threads, a `Mutex` + `Condvar` guarded request queue and an `mpsc` channel
//! for results. No crate is needed: the queue must be reordered and pruned on every request (a
//! channel cannot), and std's `mpsc` is crossbeam's channel since Rust 1.67.
//!
//! - **Prioritised**: [`Loader::want`] replaces the queue with the caller's list, most wanted
//!   first; cells no longer wanted are dropped from the queue (a cell being read is finished).
//! - **De-duplicated**: a cell queued, being read, or delivered but not yet received is never
//!   queued again.
//! - **Errors are values**: a missing, damaged or mismatched file is delivered as a
//!   [`RuntimeError::Cell`] naming the file; a panic while decoding (a bug) is caught and delivered
//!   the same way, so the walk never crashes.
//! - For tests, [`LoaderOptions::delay`] adds an artificial per-cell delay (interrupted on drop).

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, TryRecvError};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use lemi_core::bundle::{Bundle, CellFile, CellHeader, VerifiedCell};
use lemi_core::cell::CellId;
use lemi_core::Scene;
use lemi_gpu::impostor::ImpostorCellData;

use crate::RuntimeError;

/// How the loader works.
#[derive(Clone, Debug, PartialEq)]
pub struct LoaderOptions {
    /// Worker threads (at least 1).
    pub threads: usize,
    /// Artificial delay before reading each cell (for tests of slow storage).
    pub delay: Duration,
    /// Largest texture side of the adapter the cells are drawn on: the atlas pages of a cell's
    /// macro-textures are laid out for it ([`ImpostorCellData::prepare_for`]). The streamer sets
    /// it from its GPU.
    pub texture_side: u32,
    /// Whether the adapter samples the bundle's block-compressed macro-textures (BC7, BC1) as
    /// stored: they are then handed to the upload as they are
    /// ([`ImpostorCellData::with_blocks`]), else decoded to RGBA8. The streamer sets it from its
    /// GPU.
    pub block_formats: bool,
    /// Object impostors (object bundles' cells) to draw with the cells: an object whose view
    /// cell holds the whole of a cell replaces its triangles in that cell's near field
    /// ([`lemi_core::object_cell::compose_objects`]); elsewhere the object stays geometry, so no
    /// viewpoint of the cell sees an impostor outside its guarantee.
    pub objects: Arc<Vec<CellFile>>,
}

impl Default for LoaderOptions {
    fn default() -> Self {
        LoaderOptions {
            threads: 1,
            delay: Duration::ZERO,
            texture_side: lemi_gpu::DEFAULT_PAGE_SIDE,
            block_formats: false,
            objects: Arc::new(Vec::new()),
        }
    }
}

/// A cell read, verified and decoded, ready for [`lemi_gpu::ImpostorCell::begin_upload`].
pub struct DecodedCell {
    pub id: CellId,
    /// The cell file.
    pub path: PathBuf,
    /// The cell's header; its `quads` are in `data` (the header's list is left empty so as not to
    /// hold them twice).
    pub header: CellHeader,
    /// Near geometry, quad vertex arrays and macro-textures, checked against the scene.
    pub data: ImpostorCellData,
    /// Bytes held in main memory (`data.cpu_bytes()`).
    pub bytes: u64,
    /// Size of the cell file.
    pub file_bytes: u64,
    /// Seconds spent reading and decoding (the artificial delay included).
    pub seconds: f64,
}

impl std::fmt::Debug for DecodedCell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DecodedCell")
            .field("id", &self.id)
            .field("path", &self.path)
            .field("bytes", &self.bytes)
            .field("file_bytes", &self.file_bytes)
            .field("seconds", &self.seconds)
            .finish()
    }
}

/// One delivered request.
#[derive(Debug)]
pub struct Loaded {
    pub id: CellId,
    pub result: Result<DecodedCell, RuntimeError>,
}

#[derive(Default)]
struct State {
    /// Most wanted first.
    queue: Vec<CellId>,
    in_flight: HashSet<CellId>,
    /// Sent on the channel, not yet received.
    sent: HashSet<CellId>,
    shutdown: bool,
}

/// What every worker needs to load a cell.
struct Context {
    bundle: Bundle,
    scene: Arc<Scene>,
    delay: Duration,
    texture_side: u32,
    block_formats: bool,
    objects: Arc<Vec<CellFile>>,
}

struct Shared {
    state: Mutex<State>,
    wake: Condvar,
    ctx: Context,
}

impl Shared {
    /// The state, also after a worker panicked while holding the lock (the state stays
    /// consistent: every update is a single set or queue operation).
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The background loader. Dropping it stops and joins its threads.
pub struct Loader {
    shared: Arc<Shared>,
    results: Receiver<Loaded>,
    threads: Vec<JoinHandle<()>>,
}

impl Loader {
    /// Starts the workers for the cells of `bundle`. `scene` is the scene the bundle was baked
    /// from (near lists index its meshes).
    pub fn spawn(
        bundle: Bundle,
        scene: Arc<Scene>,
        options: LoaderOptions,
    ) -> Result<Loader, RuntimeError> {
        if options.threads == 0 || options.threads > 64 {
            return Err(RuntimeError::Options {
                option: "loader.threads",
                message: format!("must be 1..=64 (got {})", options.threads),
            });
        }
        let shared = Arc::new(Shared {
            state: Mutex::new(State::default()),
            wake: Condvar::new(),
            ctx: Context {
                bundle,
                scene,
                delay: options.delay,
                texture_side: options.texture_side,
                block_formats: options.block_formats,
                objects: options.objects.clone(),
            },
        });
        let (tx, results) = mpsc::channel();
        let mut threads = Vec::with_capacity(options.threads);
        for k in 0..options.threads {
            let (worker_shared, tx) = (shared.clone(), tx.clone());
            let spawned = std::thread::Builder::new()
                .name(format!("lemi-loader-{k}"))
                .spawn(move || worker(&worker_shared, &tx));
            match spawned {
                Ok(t) => threads.push(t),
                Err(e) => {
                    let loader = Loader {
                        shared,
                        results,
                        threads,
                    };
                    drop(loader);
                    return Err(RuntimeError::Loader(format!("could not be started: {e}")));
                }
            }
        }
        Ok(Loader {
            shared,
            results,
            threads,
        })
    }

    /// Replaces the queue with `ids`, most wanted first. Cells already queued, being read, or
    /// delivered but not yet received are not queued again; queued cells not in `ids` are
    /// dropped; repeated ids count once.
    pub fn want(&self, ids: &[CellId]) {
        let mut st = self.shared.lock();
        let mut seen = HashSet::new();
        let queue: Vec<CellId> = ids
            .iter()
            .copied()
            .filter(|id| seen.insert(*id) && !st.in_flight.contains(id) && !st.sent.contains(id))
            .collect();
        st.queue = queue;
        if !st.queue.is_empty() {
            self.shared.wake.notify_all();
        }
    }

    /// Whether `id` is queued, being read, or delivered and not yet received.
    pub fn is_pending(&self, id: CellId) -> bool {
        let st = self.shared.lock();
        st.queue.contains(&id) || st.in_flight.contains(&id) || st.sent.contains(&id)
    }

    /// Cells queued or being read.
    pub fn pending(&self) -> usize {
        let st = self.shared.lock();
        st.queue.len() + st.in_flight.len()
    }

    /// A delivered cell, if one is waiting.
    pub fn try_recv(&self) -> Result<Option<Loaded>, RuntimeError> {
        match self.results.try_recv() {
            Ok(l) => Ok(Some(self.received(l))),
            Err(TryRecvError::Empty) => Ok(None),
            Err(TryRecvError::Disconnected) => Err(gone()),
        }
    }

    /// Waits up to `timeout` for a delivered cell.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<Loaded>, RuntimeError> {
        match self.results.recv_timeout(timeout) {
            Ok(l) => Ok(Some(self.received(l))),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(gone()),
        }
    }

    fn received(&self, l: Loaded) -> Loaded {
        self.shared.lock().sent.remove(&l.id);
        l
    }
}

fn gone() -> RuntimeError {
    RuntimeError::Loader("stopped: every worker thread has exited".into())
}

impl Drop for Loader {
    fn drop(&mut self) {
        self.shared.lock().shutdown = true;
        self.shared.wake.notify_all();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

fn worker(shared: &Shared, tx: &Sender<Loaded>) {
    loop {
        let id = {
            let mut st = shared.lock();
            loop {
                if st.shutdown {
                    return;
                }
                if !st.queue.is_empty() {
                    break;
                }
                st = shared.wake.wait(st).unwrap_or_else(|p| p.into_inner());
            }
            let id = st.queue.remove(0);
            st.in_flight.insert(id);
            id
        };
        let t0 = Instant::now();
        if !shared.ctx.delay.is_zero() {
            let st = shared.lock();
            let (st, _) = shared
                .wake
                .wait_timeout_while(st, shared.ctx.delay, |s| !s.shutdown)
                .unwrap_or_else(|p| p.into_inner());
            if st.shutdown {
                return;
            }
        }
        let result =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load(&shared.ctx, id, t0)))
                .unwrap_or_else(|panic| {
                    let what = panic
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_else(|| "unknown panic".into());
                    Err(cell_error(
                        &shared.ctx,
                        id,
                        format!("decoding failed unexpectedly (a bug in lemi): {what}"),
                    ))
                });
        {
            let mut st = shared.lock();
            st.in_flight.remove(&id);
            st.sent.insert(id);
        }
        if tx.send(Loaded { id, result }).is_err() {
            return;
        }
    }
}

fn cell_error(ctx: &Context, id: CellId, message: String) -> RuntimeError {
    RuntimeError::Cell {
        id,
        path: ctx.bundle.cell_path(id),
        message,
    }
}

/// `file` (cell `id`) with the object impostors whose view cell holds the whole cell
/// ([`LoaderOptions::objects`]).
fn with_objects(ctx: &Context, id: CellId, file: CellFile) -> Result<CellFile, String> {
    if ctx.objects.is_empty() {
        return Ok(file);
    }
    let cell = ctx
        .bundle
        .manifest()
        .grid
        .cell_of(id)
        .map_err(|e| e.to_string())?;
    // view cells are convex (a box, a shaft, a shaft clipped to a box): the corners decide
    let corners = lemi_core::object_cell::box_corners(&lemi_core::Aabb::new(
        cell.center - cell.half,
        cell.center + cell.half,
    ));
    let holding: Vec<&CellFile> = ctx
        .objects
        .iter()
        .filter(|o| {
            o.header
                .object
                .as_ref()
                .is_some_and(|s| corners.iter().all(|c| s.cell.contains(*c)))
        })
        .collect();
    if holding.is_empty() {
        return Ok(file);
    }
    lemi_core::object_cell::compose_objects(&file, &holding)
        .map(|(f, _)| f)
        .map_err(|e| format!("with object impostors: {e}"))
}

/// Reads, verifies (through the bundle's one reader) and decodes one cell.
fn load(ctx: &Context, id: CellId, t0: Instant) -> Result<DecodedCell, RuntimeError> {
    let err = |m: String| cell_error(ctx, id, m);
    let VerifiedCell { file, entry } =
        ctx.bundle
            .verified_cell(id)
            .map_err(|e| RuntimeError::Cell {
                id,
                path: e.path,
                message: e.kind.to_string(),
            })?;
    let path = ctx.bundle.cell_path(id);
    let file = with_objects(ctx, id, file).map_err(err)?;
    let blocks = match file.block_macros() {
        Ok(Some(b)) if ctx.block_formats => Some(b),
        Ok(_) => None,
        Err(e) => return Err(err(e.to_string())),
    };
    let macros = file.decode_macros().map_err(|e| err(e.to_string()))?;
    let CellFile {
        mut header, near, ..
    } = file;
    let quads = std::mem::take(&mut header.quads);
    let seen_from = Some(lemi_gpu::SeenFrom::of(&header));
    let data = ImpostorCellData::prepare_for(
        &ctx.scene,
        &near,
        &quads,
        macros,
        ctx.texture_side,
        seen_from,
    )
    .map_err(|e| {
        err(format!(
            "does not fit the scene it is drawn with: {e} (is it the scene the bundle was baked from?)"
        ))
    })?;
    let data = match blocks {
        Some(b) => data.with_blocks(b).map_err(|e| err(e.to_string()))?,
        None => data,
    };
    Ok(DecodedCell {
        id,
        path,
        header,
        bytes: data.cpu_bytes(),
        data,
        file_bytes: entry.bytes,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
