//! The checksummed container every bundle file uses, and atomic file writing.
//!
//! Layout (all integers little-endian; see `docs/FORMAT.md`):
//! ```text
//! magic      8 bytes   file kind, e.g. b"LEMICELL"
//! version    u32       container/format version (readers reject unknown versions)
//! header_len u64       then header_len bytes of UTF-8 JSON (the typed header)
//! blob_count u32       then per blob: name_len u16, name (UTF-8), len u64, bytes
//! checksum   32 bytes  BLAKE3 of everything before it
//! ```
//! BLAKE3 (the `blake3` crate) is fast enough to checksum hundreds of MB per second per core, which
//! keeps verification off the critical path of streaming; a CRC would not detect deliberate edits.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::Serialize;

/// A named binary payload (e.g. a PNG macro-texture).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Blob {
    pub name: String,
    pub data: Vec<u8>,
}

/// Why a container could not be read. Every message is meant to be shown with the file's path.
#[derive(Debug, thiserror::Error)]
pub enum ContainerError {
    #[error("not a lemi {expected} file (bad magic bytes)")]
    BadMagic { expected: String },
    #[error("format version {found} is not supported (this lemi reads version {supported})")]
    UnsupportedVersion { found: u32, supported: u32 },
    #[error("truncated: the file ends inside its {what}")]
    Truncated { what: &'static str },
    #[error("corrupt: checksum mismatch (the file was modified or damaged)")]
    ChecksumMismatch,
    #[error("corrupt header: {0}")]
    Header(String),
    #[error("cannot encode header: {0}")]
    Encode(String),
}

const HASH_LEN: usize = 32;

/// Encodes a container.
pub fn encode<H: Serialize>(
    magic: &[u8; 8],
    version: u32,
    header: &H,
    blobs: &[Blob],
) -> Result<Vec<u8>, ContainerError> {
    let json = serde_json::to_vec(header).map_err(|e| ContainerError::Encode(e.to_string()))?;
    let mut out = Vec::with_capacity(
        64 + json.len()
            + blobs
                .iter()
                .map(|b| b.data.len() + b.name.len() + 10)
                .sum::<usize>(),
    );
    out.extend_from_slice(magic);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(json.len() as u64).to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(&(blobs.len() as u32).to_le_bytes());
    for b in blobs {
        let name = b.name.as_bytes();
        let len = name.len().min(u16::MAX as usize);
        out.extend_from_slice(&(len as u16).to_le_bytes());
        out.extend_from_slice(&name[..len]);
        out.extend_from_slice(&(b.data.len() as u64).to_le_bytes());
        out.extend_from_slice(&b.data);
    }
    let hash = blake3::hash(&out);
    out.extend_from_slice(hash.as_bytes());
    Ok(out)
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], ContainerError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or(ContainerError::Truncated { what })?;
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u16(&mut self, what: &'static str) -> Result<u16, ContainerError> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    fn u32(&mut self, what: &'static str) -> Result<u32, ContainerError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&mut self, what: &'static str) -> Result<u64, ContainerError> {
        let b = self.take(8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }
}

/// Decodes and verifies a container of kind `magic` (named `kind` in errors) and `version`.
pub fn decode<H: DeserializeOwned>(
    magic: &[u8; 8],
    kind: &str,
    version: u32,
    data: &[u8],
) -> Result<(H, Vec<Blob>), ContainerError> {
    decode_versions(magic, kind, version..=version, data).map(|(_, h, b)| (h, b))
}

/// [`decode`] accepting any version in `versions`; returns the version found too.
pub fn decode_versions<H: DeserializeOwned>(
    magic: &[u8; 8],
    kind: &str,
    versions: std::ops::RangeInclusive<u32>,
    data: &[u8],
) -> Result<(u32, H, Vec<Blob>), ContainerError> {
    if data.len() < 8 || &data[..8] != magic {
        if data.len() < 8 && magic.starts_with(data) {
            return Err(ContainerError::Truncated {
                what: "magic bytes",
            });
        }
        return Err(ContainerError::BadMagic {
            expected: kind.to_string(),
        });
    }
    let mut r = Reader { data, pos: 8 };
    let found = r.u32("version")?;
    if !versions.contains(&found) {
        return Err(ContainerError::UnsupportedVersion {
            found,
            supported: *versions.end(),
        });
    }
    if data.len() < 12 + HASH_LEN {
        return Err(ContainerError::Truncated { what: "header" });
    }
    let body = &data[..data.len() - HASH_LEN];
    let stored = &data[data.len() - HASH_LEN..];
    let actual = blake3::hash(body);
    if actual.as_bytes() != stored {
        // Distinguish a cut-off file from a modified one where we can: parse what is there.
        let mut probe = Reader { data, pos: 12 };
        walk(&mut probe)?;
        if probe.pos + HASH_LEN > data.len() {
            return Err(ContainerError::Truncated { what: "checksum" });
        }
        return Err(ContainerError::ChecksumMismatch);
    }
    let mut r = Reader {
        data: body,
        pos: 12,
    };
    let hlen = r.u64("header length")?;
    let hjson = r.take(
        usize::try_from(hlen).map_err(|_| ContainerError::Truncated { what: "header" })?,
        "header",
    )?;
    let header: H =
        serde_json::from_slice(hjson).map_err(|e| ContainerError::Header(e.to_string()))?;
    let n = r.u32("blob count")?;
    let mut blobs = Vec::new();
    for _ in 0..n {
        let nl = r.u16("blob name length")? as usize;
        let name = String::from_utf8_lossy(r.take(nl, "blob name")?).into_owned();
        let len = r.u64("blob length")?;
        let len = usize::try_from(len).map_err(|_| ContainerError::Truncated { what: "blob" })?;
        let data = r.take(len, "blob")?.to_vec();
        blobs.push(Blob { name, data });
    }
    if r.pos != body.len() {
        return Err(ContainerError::Header(
            "trailing bytes after the last blob".into(),
        ));
    }
    Ok((found, header, blobs))
}

/// Walks the structure after the version without a checksum, to tell truncation from corruption.
fn walk(r: &mut Reader<'_>) -> Result<(), ContainerError> {
    let hlen = r.u64("header length")?;
    r.take(
        usize::try_from(hlen).map_err(|_| ContainerError::Truncated { what: "header" })?,
        "header",
    )?;
    let n = r.u32("blob count")?;
    for _ in 0..n {
        let nl = r.u16("blob name length")? as usize;
        r.take(nl, "blob name")?;
        let len = r.u64("blob length")?;
        r.take(
            usize::try_from(len).map_err(|_| ContainerError::Truncated { what: "blob" })?,
            "blob",
        )?;
    }
    Ok(())
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, flushed and synced,
/// then renamed over `path` (and the directory synced, so the rename survives a crash). A reader
/// sees either the old file or the complete new one, never a part.
///
/// Several writers may write the same path at once (two processes baking the same shard on shared
/// storage, threads of one process): each writes its own temporary file, named
/// `.<name>.<pid>.<random>.tmp` and created exclusively (`O_EXCL`, so a name taken by anyone else,
/// e.g. a process with the same pid in another container, is never shared but retried), and the
/// last rename wins whole.
///
/// The writer holds an exclusive `flock` on its temporary file from creating it until after the
/// rename; the kernel drops it when the process ends, however it ends. A process killed while
/// writing leaves its temporary file behind, unlocked: [`remove_stale_temp_files`] removes it.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let (tmp, mut f) = create_temp(dir, &name)?;
    let result = (|| {
        // Best effort: a file system without locks (some network mounts) still gets the file;
        // its temporary files are then never taken for stale.
        let _ = try_lock(&f);
        f.write_all(bytes)?;
        f.sync_all()?;
        // Renamed while still open (and locked), so no one takes it for stale before it is gone.
        std::fs::rename(&tmp, path)
    })();
    drop(f);
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result?;
    // Best effort: not every platform or file system can sync a directory.
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Whether `name` is that of a temporary file of [`write_atomic`]: `.<name>.<pid>.<random>.tmp`.
pub fn is_temp_file_name(name: &str) -> bool {
    let Some(inner) = name.strip_prefix('.').and_then(|n| n.strip_suffix(".tmp")) else {
        return false;
    };
    let mut parts = inner.rsplitn(3, '.');
    let (Some(random), Some(pid), Some(target)) = (parts.next(), parts.next(), parts.next()) else {
        return false;
    };
    random.len() == 16
        && random.bytes().all(|b| b.is_ascii_hexdigit())
        && !pid.is_empty()
        && pid.bytes().all(|b| b.is_ascii_digit())
        && !target.is_empty()
}

/// Removes the temporary files of [`write_atomic`] in `dir` that a writer killed while writing
/// left behind: those last modified before `before` (when the caller started; a writer locks its
/// file as soon as it has created it) that no process holds locked. A file being written by
/// another process (another shard on shared storage) is locked and kept. Returns how many were
/// removed. On a file system without locks nothing is removed; elsewhere than Unix neither.
pub fn remove_stale_temp_files(
    dir: &Path,
    before: std::time::SystemTime,
) -> std::io::Result<usize> {
    let mut removed = 0;
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        if !is_temp_file_name(&entry.file_name().to_string_lossy()) {
            continue;
        }
        let path = entry.path();
        let old = entry
            .metadata()
            .and_then(|m| m.modified())
            .is_ok_and(|t| t < before);
        if !old {
            continue;
        }
        // Gone already (renamed or removed by its writer): nothing to do.
        let Ok(f) = std::fs::File::open(&path) else {
            continue;
        };
        if try_lock(&f).unwrap_or(false) {
            match std::fs::remove_file(&path) {
                Ok(()) => removed += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
    }
    Ok(removed)
}

/// Takes an exclusive `flock` on `f` without waiting: `Ok(true)` if taken, `Ok(false)` if
/// another open file holds one.
#[cfg(unix)]
fn try_lock(f: &std::fs::File) -> std::io::Result<bool> {
    use std::os::unix::io::AsRawFd;
    // SAFETY: flock on a file descriptor `f` owns and keeps open for the call.
    if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error();
    if e.kind() == std::io::ErrorKind::WouldBlock {
        Ok(false)
    } else {
        Err(e)
    }
}

#[cfg(not(unix))]
fn try_lock(_: &std::fs::File) -> std::io::Result<bool> {
    Err(std::io::Error::other("no flock here"))
}

/// Creates a new temporary file for [`write_atomic`] in `dir`, with a name no other writer holds.
fn create_temp(dir: &Path, name: &str) -> std::io::Result<(PathBuf, std::fs::File)> {
    use std::hash::{BuildHasher, Hasher};
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let mut last_err = None;
    for _ in 0..16 {
        // `RandomState` is seeded from the operating system's randomness per process; the counter
        // and the time tell apart the names of one process.
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u64(COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed));
        if let Ok(t) = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH) {
            h.write_u128(t.as_nanos());
        }
        let tmp = dir.join(format!(
            ".{name}.{}.{:016x}.tmp",
            std::process::id(),
            h.finish()
        ));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
        {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last_err = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last_err.unwrap_or_else(|| std::io::Error::other("no free temporary file name")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const M: &[u8; 8] = b"LEMITEST";

    fn sample() -> Vec<u8> {
        let blobs = vec![
            Blob {
                name: "a.png".into(),
                data: vec![1, 2, 3],
            },
            Blob {
                name: "b".into(),
                data: vec![],
            },
        ];
        encode(M, 1, &serde_json::json!({"cell": "0_0_0", "n": 5}), &blobs).unwrap()
    }

    #[test]
    fn round_trips() {
        let bytes = sample();
        let (h, blobs): (serde_json::Value, _) = decode(M, "test", 1, &bytes).unwrap();
        assert_eq!(h["n"], 5);
        assert_eq!(blobs.len(), 2);
        assert_eq!(blobs[0].data, vec![1, 2, 3]);
    }

    #[test]
    fn rejects_bad_files_with_the_right_reason() {
        let bytes = sample();
        let r = decode::<serde_json::Value>(M, "test", 2, &bytes);
        assert!(matches!(
            r,
            Err(ContainerError::UnsupportedVersion {
                found: 1,
                supported: 2
            })
        ));
        let r = decode::<serde_json::Value>(b"LEMIELSE", "else", 1, &bytes);
        assert!(matches!(r, Err(ContainerError::BadMagic { .. })));
        let r = decode::<serde_json::Value>(M, "test", 1, &bytes[..bytes.len() - 10]);
        assert!(matches!(r, Err(ContainerError::Truncated { .. })), "{r:?}");
        let mut flipped = bytes.clone();
        flipped[20] ^= 0x40;
        let r = decode::<serde_json::Value>(M, "test", 1, &flipped);
        assert!(matches!(r, Err(ContainerError::ChecksumMismatch)), "{r:?}");
    }

    proptest! {
        #[test]
        fn never_panics_on_damage(cut in 0usize..200, flip in 0usize..200, bit in 0u8..8) {
            let bytes = sample();
            let mut d = bytes[..cut.min(bytes.len())].to_vec();
            if let Some(b) = d.get_mut(flip) {
                *b ^= 1 << bit;
            }
            let r = decode::<serde_json::Value>(M, "test", 1, &d);
            if d != bytes {
                prop_assert!(r.is_err());
            }
        }
    }

    #[test]
    fn atomic_write_replaces_whole_file() {
        let dir = std::env::temp_dir().join(format!("lemi-container-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("x.bin");
        write_atomic(&p, b"first").unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn temp_file_names_are_recognised() {
        assert!(is_temp_file_name(
            ".0_0_0.lemicell.1234.0123456789abcdef.tmp"
        ));
        assert!(is_temp_file_name(".manifest.json.7.fedcba9876543210.tmp"));
        assert!(!is_temp_file_name("0_0_0.lemicell"));
        assert!(!is_temp_file_name(".0_0_0.lemicell.tmp"));
        assert!(!is_temp_file_name(".x.12a.0123456789abcdef.tmp"));
        assert!(!is_temp_file_name(".x.12.0123456789abcdeg.tmp"));
        assert!(!is_temp_file_name("..12.0123456789abcdef.tmp"));
    }

    /// A temporary file left by a writer that died is removed; one a live writer holds locked,
    /// one newer than the cut-off and any other file are kept.
    #[test]
    fn only_stale_unlocked_temp_files_are_removed() {
        let dir = std::env::temp_dir().join(format!("lemi-container-s-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let stale = dir.join(".a.lemicell.1.0123456789abcdef.tmp");
        let live = dir.join(".b.lemicell.2.0123456789abcdef.tmp");
        let other = dir.join("c.lemicell");
        for p in [&stale, &live, &other] {
            std::fs::write(p, b"x").unwrap();
        }
        let writer = std::fs::File::open(&live).unwrap();
        assert!(try_lock(&writer).unwrap());
        // nothing is older than a cut-off in the past
        let past = std::time::SystemTime::UNIX_EPOCH;
        assert_eq!(remove_stale_temp_files(&dir, past).unwrap(), 0);
        let later = std::time::SystemTime::now() + std::time::Duration::from_secs(1);
        assert_eq!(remove_stale_temp_files(&dir, later).unwrap(), 1);
        assert!(!stale.exists() && live.exists() && other.exists());
        drop(writer);
        assert_eq!(remove_stale_temp_files(&dir, later).unwrap(), 1);
        assert!(!live.exists() && other.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Many writers of one path at once (as two processes baking the same shard, or threads):
    /// none fails, the file is one writer's bytes whole, and no temporary file is left.
    #[test]
    fn concurrent_atomic_writes_of_one_path_never_mix() {
        let dir = std::env::temp_dir().join(format!("lemi-container-c-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("cell.lemicell");
        let contents: Vec<Vec<u8>> = (0..8u8).map(|i| vec![i; 200_000 + i as usize]).collect();
        for _ in 0..5 {
            std::thread::scope(|s| {
                for c in &contents {
                    let p = &p;
                    s.spawn(move || write_atomic(p, c).unwrap());
                }
            });
            let got = std::fs::read(&p).unwrap();
            assert!(
                contents.contains(&got),
                "a mix of writers: {} bytes",
                got.len()
            );
        }
        let names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec!["cell.lemicell".to_string()]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
