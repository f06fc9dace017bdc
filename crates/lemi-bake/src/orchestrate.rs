//! Which cells to bake and where results go: resumable runs, deterministic shards
//! (`--shard K/N`, for Kubernetes Indexed Jobs or Slurm arrays) and the merge step that writes the
//! manifest from the shards' records. Every file is written atomically.

use std::path::{Path, PathBuf};
use std::time::Instant;

use lemi_core::bundle::{
    cell_file_name, read_cell_file, version_for, BakeParams, BundleError, CellCheck, CellEntry,
    CellFile, CellStats, Manifest, ParamsError, SceneRef, MANIFEST_FORMAT,
};
use lemi_core::cell::{CellGrid, CellId, Shard, ViewCell};
use lemi_core::compress::CompressError;
use lemi_core::container::write_atomic;
use lemi_core::container::ContainerError;
use lemi_core::layering::LayeringError;
use lemi_gpu::cell_recorder::RecordError;
use serde::{Deserialize, Serialize};

/// Errors of the bake job; each names the file, cell or parameter at fault.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error(transparent)]
    Bundle(#[from] BundleError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file or directory of the bundle could not be written; `hint` says why where the error
    /// tells (disk full, read-only, the directory deleted) and what to do.
    #[error("{path}: cannot write: {source}{hint}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
        hint: String,
    },
    /// A bake parameter out of range ([`ParamsError::parameter`] names it).
    #[error(transparent)]
    Params(#[from] ParamsError),
    #[error(transparent)]
    Layering(#[from] LayeringError),
    /// An object impostor's view cell, object or placement is unusable.
    #[error(transparent)]
    Object(#[from] lemi_core::object_cell::ObjectError),
    #[error(transparent)]
    Record(Box<RecordError>),
    #[error("{what}: {source}")]
    Gpu {
        what: &'static str,
        #[source]
        source: lemi_gpu::GpuError,
    },
    #[error("cell {cell}: compressing: {source}")]
    Compress {
        cell: CellId,
        #[source]
        source: CompressError,
    },
    /// Encoding a macro-texture or the cell file.
    #[error("cell {cell}: {source}")]
    Encode {
        cell: CellId,
        #[source]
        source: ContainerError,
    },
    #[error("{}: {source}", path.display())]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}: not a lemi shard record: {source}", path.display())]
    NotAShardRecord {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}: no shard records (*.json) to merge", dir.display())]
    NoShardRecords { dir: PathBuf },
    #[error("{} disagrees with {} (scene, parameters, cells or shard count differ)", path.display(), first.display())]
    ShardsDisagree { path: PathBuf, first: PathBuf },
    #[error("{}: shards {} have not been baked yet", dir.display(), missing.join(", "))]
    ShardsMissing { dir: PathBuf, missing: Vec<String> },
    #[error("cell {id} is in no shard record")]
    CellInNoShard { id: CellId },
    /// A shard's cell file is not the one its record lists.
    #[error("{}: does not match its shard record (changed after baking): {}", source.path.display(), source.kind)]
    ShardRecord { source: BundleError },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> BakeError + '_ {
    move |source| BakeError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The error of writing `path` (a file, or a directory being created) in the bundle `bundle`,
/// with what it means for the bake: cells already written are complete and kept (every file is
/// written whole or not at all), so the same command run again resumes.
fn write_error(bundle: &Path, path: &Path) -> impl FnOnce(std::io::Error) -> BakeError {
    let (bundle, path) = (bundle.to_path_buf(), path.to_path_buf());
    move |source| {
        use std::io::ErrorKind;
        let resume = "; cells already written are complete and kept: run the same command again \
                      to resume";
        let hint = match source.kind() {
            ErrorKind::StorageFull | ErrorKind::FileTooLarge | ErrorKind::QuotaExceeded => {
                format!(" (the disk is full or a file size limit was reached){resume}")
            }
            ErrorKind::ReadOnlyFilesystem | ErrorKind::PermissionDenied => {
                format!(" (the bundle directory is read-only or not writable){resume}")
            }
            ErrorKind::NotFound if !bundle.is_dir() => format!(
                " (the bundle directory {} no longer exists: it was deleted or moved during the \
                 bake; run the same command again to bake it anew)",
                bundle.display()
            ),
            ErrorKind::NotFound => {
                let dir = path.parent().unwrap_or(&bundle);
                format!(
                    " ({} no longer exists: it was deleted or moved during the bake){resume}",
                    dir.display()
                )
            }
            _ => String::new(),
        };
        BakeError::Write { path, source, hint }
    }
}

/// [`Manifest::write`]'s error as a [`write_error`].
fn manifest_write_error(bundle: &Path) -> impl FnOnce(BundleError) -> BakeError + '_ {
    move |e| match e.kind {
        lemi_core::bundle::BundleErrorKind::Io(source) => write_error(bundle, &e.path)(source),
        _ => BakeError::Bundle(e),
    }
}

/// Removes the temporary files that runs killed while writing left in the bundle (best effort:
/// a directory that cannot be listed is left as it is). Returns how many were removed.
fn remove_stale_temp_files(bundle: &Path, started: std::time::SystemTime) -> usize {
    [
        bundle.to_path_buf(),
        bundle.join("cells"),
        bundle.join("shards"),
    ]
    .iter()
    .filter(|d| d.is_dir())
    .map(|d| lemi_core::container::remove_stale_temp_files(d, started).unwrap_or(0))
    .sum()
}

/// What to bake and where.
#[derive(Clone, Debug)]
pub struct BakeJob {
    pub bundle: PathBuf,
    pub scene: SceneRef,
    pub params: BakeParams,
    pub grid: CellGrid,
    /// Cells of the bundle (all of the grid, or the explicit `--cells` list).
    pub cells: Vec<ViewCell>,
    /// This run's share of `cells`, if sharded; a sharded run records its cells in
    /// `shards/K-of-N.json` and leaves the manifest to [`merge`].
    pub shard: Option<Shard>,
}

/// A shard's record of what it baked (`shards/K-of-N.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShardRecord {
    pub shard: Shard,
    pub scene: SceneRef,
    pub params: BakeParams,
    pub params_hash: String,
    pub grid: CellGrid,
    /// Every cell of the bundle (so merge knows the full list).
    pub all_cells: Vec<CellId>,
    pub cells: Vec<CellEntry>,
}

/// What happened to one cell.
#[derive(Clone, Debug)]
pub enum CellOutcome {
    Baked {
        entry: CellEntry,
        file: Box<CellFile>,
        seconds: f64,
    },
    /// Intact from an earlier identical run; `stats` are its file's.
    Skipped {
        entry: CellEntry,
        stats: Box<CellStats>,
    },
}

/// The result of [`run`].
#[derive(Clone, Debug, Default)]
pub struct RunSummary {
    pub outcomes: Vec<CellOutcome>,
    pub seconds: f64,
    /// Where the manifest (or, for a shard, the shard record) went.
    pub record: PathBuf,
    /// Temporary files removed that runs killed while writing had left behind.
    pub stale_temp_files_removed: usize,
}

fn entry_for(id: CellId, bytes: &[u8]) -> CellEntry {
    CellEntry {
        id,
        file: cell_file_name(id),
        bytes: bytes.len() as u64,
        blake3: blake3::hash(bytes).to_hex().to_string(),
    }
}

/// Checks a cell file already on disk: returns its entry if it is intact and was baked from the same
/// scene with the same parameters for the same cell (index, centre and extent: a region moved by a
/// fraction of a cell keeps the ids but not the reference viewpoints), so a resumed bake skips it.
fn existing(bundle: &Path, cell: &ViewCell, job: &BakeJob, hash: &str) -> Option<CellOutcome> {
    let id = cell.id();
    let check = CellCheck {
        id,
        entry: None,
        params_hash: hash,
        scene_fingerprint: &job.scene.fingerprint,
        cell: Some(cell),
    };
    read_cell_file(&bundle.join(cell_file_name(id)), &check)
        .ok()
        .map(|v| CellOutcome::Skipped {
            entry: v.entry,
            stats: Box::new(v.file.header.stats),
        })
}

/// Bakes the job's cells with `bake_cell`, skipping intact cells of an earlier identical run,
/// writing each cell file atomically as soon as it is done, and finally the manifest (or, for a
/// shard, its record). `on_cell` is told about every cell as it finishes (for progress).
pub fn run(
    job: &BakeJob,
    mut bake_cell: impl FnMut(&ViewCell) -> Result<CellFile, BakeError>,
    mut on_cell: impl FnMut(usize, usize, &CellOutcome),
) -> Result<RunSummary, BakeError> {
    let t0 = Instant::now();
    let started = std::time::SystemTime::now();
    let hash = job.params.hash();
    let cells_dir = job.bundle.join("cells");
    std::fs::create_dir_all(&cells_dir).map_err(write_error(&job.bundle, &cells_dir))?;
    let mine: Vec<ViewCell> = match job.shard {
        Some(s) => s.select(&job.cells),
        None => job.cells.clone(),
    };
    let mut outcomes = Vec::with_capacity(mine.len());
    for (i, cell) in mine.iter().enumerate() {
        let outcome = if let Some(skipped) = existing(&job.bundle, cell, job, &hash) {
            skipped
        } else {
            let t = Instant::now();
            let mut file = bake_cell(cell)?;
            file.header.params_hash = hash.clone();
            file.header.scene_fingerprint = job.scene.fingerprint.clone();
            let bytes = file.encode().map_err(|source| BakeError::Encode {
                cell: cell.id(),
                source,
            })?;
            let path = job.bundle.join(cell_file_name(cell.id()));
            write_atomic(&path, &bytes).map_err(write_error(&job.bundle, &path))?;
            CellOutcome::Baked {
                entry: entry_for(cell.id(), &bytes),
                file: Box::new(file),
                seconds: t.elapsed().as_secs_f64(),
            }
        };
        on_cell(i, mine.len(), &outcome);
        outcomes.push(outcome);
    }
    let entries: Vec<CellEntry> = outcomes
        .iter()
        .map(|o| match o {
            CellOutcome::Baked { entry, .. } | CellOutcome::Skipped { entry, .. } => entry.clone(),
        })
        .collect();
    let record = match job.shard {
        None => {
            let manifest = Manifest {
                format: MANIFEST_FORMAT.into(),
                version: version_for(&job.params),
                generator: format!("lemi {}", env!("CARGO_PKG_VERSION")),
                scene: job.scene.clone(),
                params: job.params.clone(),
                params_hash: hash,
                grid: job.grid.clone(),
                cells: entries,
                object: None,
            };
            manifest
                .write(&job.bundle)
                .map_err(manifest_write_error(&job.bundle))?;
            lemi_core::bundle::manifest_path(&job.bundle)
        }
        Some(s) => {
            let rec = ShardRecord {
                shard: s,
                scene: job.scene.clone(),
                params: job.params.clone(),
                params_hash: hash,
                grid: job.grid.clone(),
                all_cells: job.cells.iter().map(|c| c.id()).collect(),
                cells: entries,
            };
            let dir = job.bundle.join("shards");
            std::fs::create_dir_all(&dir).map_err(write_error(&job.bundle, &dir))?;
            let path = dir.join(format!("{}-of-{}.json", s.k, s.n));
            let json = serde_json::to_vec_pretty(&rec).map_err(|source| BakeError::Json {
                path: path.clone(),
                source,
            })?;
            write_atomic(&path, &json).map_err(write_error(&job.bundle, &path))?;
            path
        }
    };
    Ok(RunSummary {
        outcomes,
        seconds: t0.elapsed().as_secs_f64(),
        record,
        stale_temp_files_removed: remove_stale_temp_files(&job.bundle, started),
    })
}

/// `lemi bake --merge BUNDLE`: reads every shard record, checks that they agree (scene, parameters,
/// grid, shard count) and that every shard is present, verifies every cell file against its
/// recorded hash, and writes the manifest. The result equals the manifest of a single run.
pub fn merge(bundle: &Path) -> Result<Manifest, BakeError> {
    let started = std::time::SystemTime::now();
    let dir = bundle.join("shards");
    let rd = std::fs::read_dir(&dir).map_err(io(&dir))?;
    let mut records: Vec<(PathBuf, ShardRecord)> = Vec::new();
    for e in rd {
        let e = e.map_err(io(&dir))?;
        let p = e.path();
        if p.extension().and_then(|x| x.to_str()) != Some("json") {
            continue;
        }
        let bytes = std::fs::read(&p).map_err(io(&p))?;
        let rec: ShardRecord =
            serde_json::from_slice(&bytes).map_err(|source| BakeError::NotAShardRecord {
                path: p.clone(),
                source,
            })?;
        records.push((p, rec));
    }
    let Some((first_path, first)) = records.first().cloned() else {
        return Err(BakeError::NoShardRecords { dir });
    };
    let n = first.shard.n;
    let mut seen = vec![false; n as usize];
    for (p, r) in &records {
        let same = r.params_hash == first.params_hash
            && r.scene.fingerprint == first.scene.fingerprint
            && r.grid == first.grid
            && r.all_cells == first.all_cells
            && r.shard.n == n;
        if !same {
            return Err(BakeError::ShardsDisagree {
                path: p.clone(),
                first: first_path.clone(),
            });
        }
        if let Some(s) = seen.get_mut(r.shard.k as usize) {
            *s = true;
        }
    }
    let missing: Vec<String> = seen
        .iter()
        .enumerate()
        .filter(|(_, s)| !**s)
        .map(|(k, _)| format!("{k}/{n}"))
        .collect();
    if !missing.is_empty() {
        return Err(BakeError::ShardsMissing { dir, missing });
    }
    let mut by_id = std::collections::HashMap::new();
    for (_, r) in &records {
        for c in &r.cells {
            by_id.insert(c.id, c.clone());
        }
    }
    let mut cells = Vec::with_capacity(first.all_cells.len());
    for id in &first.all_cells {
        let entry = by_id.get(id).ok_or(BakeError::CellInNoShard { id: *id })?;
        let check = CellCheck {
            id: *id,
            entry: Some(entry),
            params_hash: &first.params_hash,
            scene_fingerprint: &first.scene.fingerprint,
            cell: None,
        };
        read_cell_file(&bundle.join(&entry.file), &check)
            .map_err(|source| BakeError::ShardRecord { source })?;
        cells.push(entry.clone());
    }
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        version: version_for(&first.params),
        object: None,
        generator: format!("lemi {}", env!("CARGO_PKG_VERSION")),
        scene: first.scene.clone(),
        params: first.params.clone(),
        params_hash: first.params_hash.clone(),
        grid: first.grid.clone(),
        cells,
    };
    manifest
        .write(bundle)
        .map_err(manifest_write_error(bundle))?;
    remove_stale_temp_files(bundle, started);
    Ok(manifest)
}
