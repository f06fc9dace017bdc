//! lemi-fuzz: one fuzz target per reader of user bytes, as plain functions.
//!
//! Every `fuzz_<target>(data)` hands `data` to a reader exactly as a user's file would reach it
//! (through a scratch directory where the reader takes a path) and ignores the result: a target
//! must only ever return, never panic, hang or allocate absurdly. The same functions run under a
//! coverage-guided fuzzer (`fuzz/afl/`, one binary per target, see `docs/RELIABILITY.md`) and in
//! the replay test (`tests/replay.rs`), which feeds them every file of `fuzz/corpus/<target>/` and
//! `fuzz/regressions/<target>/`.
//!
//! Readers whose errors are caught inside lemi (the importers turn a panic of a third-party parser
//! into an error, `lemi_scene::import`) still report the panic to the panic hook, which both the
//! fuzzer (abort) and the replay test (a failure) watch, so a caught panic is still found.
//!
//! [`CappedAlloc`] is the global allocator of the fuzz binaries and of the replay test: a single
//! allocation above [`MAX_ALLOCATION`] aborts with a message, so a reader that trusts a length
//! field is a crash, not a slow run.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::RefCell;
use std::path::{Path, PathBuf};

use lemi_core::bundle::{Bundle, CellFile, CELL_MAGIC};
use lemi_core::container;
use lemi_scene::{import::load_with_report, LoadOptions};

/// A fuzz target: a name (the folder under `fuzz/corpus/` and `fuzz/regressions/`, and the
/// binary under `fuzz/afl/`) and its function.
pub type Target = (&'static str, fn(&[u8]));

/// Every target, in the order `docs/RELIABILITY.md` lists them.
pub const TARGETS: &[Target] = &[
    ("ply", fuzz_ply),
    ("ply_gz", fuzz_ply_gz),
    ("obj", fuzz_obj),
    ("gltf", fuzz_gltf),
    ("container", fuzz_container),
    ("cell", fuzz_cell),
    ("manifest", fuzz_manifest),
    ("ktx2", fuzz_ktx2),
    #[cfg(feature = "camera-path")]
    ("camera_path", fuzz_camera_path),
];

/// The target called `name`.
pub fn target(name: &str) -> Option<fn(&[u8])> {
    TARGETS.iter().find(|(n, _)| *n == name).map(|&(_, f)| f)
}

/// A PLY file (ASCII, binary little- or big-endian), read by the scene importer.
pub fn fuzz_ply(data: &[u8]) {
    import_one("input.ply", data);
}

/// A gzip-compressed PLY file (`.ply.gz`): the bytes are the compressed file.
pub fn fuzz_ply_gz(data: &[u8]) {
    import_one("input.ply.gz", data);
}

/// An OBJ file and its MTL library: the bytes before the first NUL are `input.obj`, the bytes
/// after it `input.mtl` (absent without a NUL). The scratch directory also holds a 2×2 PNG,
/// `tex.png`, for `map_Kd`.
pub fn fuzz_obj(data: &[u8]) {
    let (obj, mtl) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], Some(&data[i + 1..])),
        None => (data, None),
    };
    with_scratch(|dir| {
        let mtl_path = dir.join("input.mtl");
        match mtl {
            Some(m) => write(&mtl_path, m),
            None => {
                let _ = std::fs::remove_file(&mtl_path);
            }
        }
        let path = dir.join("input.obj");
        write(&path, obj);
        let _ = load_with_report(&[path.display().to_string()], &LoadOptions::default());
    });
}

/// A glTF document: JSON (`data:` URIs, or `tex.png` of the scratch directory) or a GLB
/// container, told apart by the reader from its first bytes.
pub fn fuzz_gltf(data: &[u8]) {
    import_one("input.gltf", data);
}

/// The checksummed container every bundle file uses, with a free-form JSON header: first as
/// given (magic, version, truncation, checksum), then with the checksum recomputed so that the
/// header and blob parsing behind it is reached.
pub fn fuzz_container(data: &[u8]) {
    let _ = container::decode_versions::<serde_json::Value>(CELL_MAGIC, "cell", 0..=u32::MAX, data);
    if let Some(fixed) = with_valid_checksum(data) {
        let _ = container::decode_versions::<serde_json::Value>(
            CELL_MAGIC,
            "cell",
            0..=u32::MAX,
            &fixed,
        );
    }
}

/// A cell file: [`CellFile::decode`] as given and with its checksum recomputed, then the
/// macro-texture PNGs of a cell that decodes.
pub fn fuzz_cell(data: &[u8]) {
    let _ = CellFile::decode(data);
    if let Some(fixed) = with_valid_checksum(data) {
        if let Ok(cell) = CellFile::decode(&fixed) {
            let _ = cell.decode_macros();
        }
    }
}

/// A bundle's `manifest.json`, opened with [`Bundle::open`]; on success the bundle is queried as
/// the runtime does (its cells, the first cell, locating a point, reading a cell, which is absent
/// here).
pub fn fuzz_manifest(data: &[u8]) {
    with_scratch(|dir| {
        let bundle_dir = dir.join("bundle");
        if std::fs::create_dir_all(&bundle_dir).is_err() {
            return;
        }
        write(&lemi_core::bundle::manifest_path(&bundle_dir), data);
        let Ok(bundle) = Bundle::open(&bundle_dir) else {
            return;
        };
        let ids = bundle.cell_ids();
        if let Some(cell) = bundle.first_cell() {
            let _ = bundle.locate(cell.center);
            let _ = bundle.cell_at(cell.center);
        }
        for id in ids.into_iter().take(4) {
            let _ = bundle.cell_path(id);
            let _ = bundle.cell(id);
        }
    });
}

/// A KTX 2.0 macro-texture as a block-compressed cell stores it, read with
/// [`lemi_core::compress::read_ktx2`] (header, level index, data format descriptor, Zstandard
/// inflation); a file that reads has its first level decoded to RGBA, as the runtime does where
/// the adapter lacks the block format. The same bytes as a Basis Universal macro-texture (an
/// `etc1s` or `uastc` cell's): [`lemi_core::compress::transcode_basis`] (header, descriptor,
/// alpha fixes, the transcoder, the alpha-exact re-encoding).
pub fn fuzz_ktx2(data: &[u8]) {
    if let Ok(t) = lemi_core::compress::read_ktx2(data) {
        if let Some(level) = t.levels.first() {
            let _ = lemi_core::compress::decode_blocks(t.format, t.width, t.height, level);
        }
    }
    let _ = lemi_core::compress::transcode_basis(data);
}

/// A camera path (`lemi-path` JSON) read with [`lemi_walk::CameraPath::read`]; a path that reads is sampled
/// as a walk replays it (its first frames, each made into a camera).
#[cfg(feature = "camera-path")]
pub fn fuzz_camera_path(data: &[u8]) {
    with_scratch(|dir| {
        let path = dir.join("path.json");
        write(&path, data);
        let Ok(p) = lemi_walk::CameraPath::read(&path) else {
            return;
        };
        let _ = p.frame_count();
        for (_, _, pose) in p.frames().take(64) {
            let _ = pose.camera(60.0, 1280, 720);
        }
        let _ = p.sample(f64::MAX);
        let _ = p.sample(-1.0);
    });
}

/// Writes `data` to `name` in the scratch directory and imports it.
fn import_one(name: &str, data: &[u8]) {
    with_scratch(|dir| {
        let path = dir.join(name);
        write(&path, data);
        let _ = load_with_report(&[path.display().to_string()], &LoadOptions::default());
    });
}

fn write(path: &Path, data: &[u8]) {
    if let Err(e) = std::fs::write(path, data) {
        // Not the reader's fault: stop rather than fuzz a stale file.
        panic!("fuzz harness: cannot write {}: {e}", path.display());
    }
}

thread_local! {
    static SCRATCH: RefCell<Option<tempfile::TempDir>> = const { RefCell::new(None) };
}

/// Runs `f` with this thread's scratch directory (made on first use, with `tex.png`).
fn with_scratch(f: impl FnOnce(&Path)) {
    SCRATCH.with(|s| {
        let mut s = s.borrow_mut();
        if s.is_none() {
            let dir = match tempfile::Builder::new().prefix("lemi-fuzz-").tempdir() {
                Ok(d) => d,
                Err(e) => panic!("fuzz harness: cannot make a scratch directory: {e}"),
            };
            // A 2×2 PNG, what `map_Kd tex.png` and a glTF image `"uri": "tex.png"` find.
            if let Ok(png) = lemi_core::bundle::encode_png(&[200; 16], 2, 2) {
                write(&dir.path().join("tex.png"), &png);
            }
            *s = Some(dir);
        }
        if let Some(dir) = s.as_ref() {
            f(dir.path());
        }
    });
}

/// `data` with its last 32 bytes replaced by the BLAKE3 hash of the rest (the container's
/// checksum), or `None` when it is too short to hold one or already holds it.
pub fn with_valid_checksum(data: &[u8]) -> Option<Vec<u8>> {
    let body_len = data.len().checked_sub(32)?;
    let hash = blake3::hash(&data[..body_len]);
    if hash.as_bytes() == &data[body_len..] {
        return None;
    }
    let mut out = data.to_vec();
    out[body_len..].copy_from_slice(hash.as_bytes());
    Some(out)
}

/// The largest single allocation [`CappedAlloc`] allows: 1 GiB. No input a fuzzer makes (at most
/// a few MB) has a reason to need more; a reader that asks for more trusted a length field.
pub const MAX_ALLOCATION: usize = 1 << 30;

/// The system allocator, aborting with a message on any allocation above [`MAX_ALLOCATION`].
pub struct CappedAlloc;

#[cold]
fn too_big(size: usize) -> ! {
    use std::io::Write;
    // No formatting machinery that could allocate: digits into a stack buffer.
    let mut digits = [0u8; 20];
    let mut i = digits.len();
    let mut n = size;
    loop {
        i -= 1;
        digits[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    let mut err = std::io::stderr();
    let _ = err.write_all(b"lemi-fuzz: allocation of ");
    let _ = err.write_all(&digits[i..]);
    let _ = err.write_all(b" bytes is above the 1 GiB cap\n");
    std::process::abort();
}

// SAFETY: every call is forwarded unchanged to `System`, which upholds `GlobalAlloc`'s contract;
// the only addition is aborting before an oversized request reaches it.
unsafe impl GlobalAlloc for CappedAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > MAX_ALLOCATION {
            too_big(layout.size());
        }
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if layout.size() > MAX_ALLOCATION {
            too_big(layout.size());
        }
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated by `System` with `layout`.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > MAX_ALLOCATION {
            too_big(new_size);
        }
        // SAFETY: `ptr` was allocated by `System` with `layout`; forwarded unchanged.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// `<workspace>/fuzz`, where the corpora and regressions live.
pub fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz")
}
