//! Scene fingerprints: a hash of what a scene was built from, so a bundle can tell whether the
//! scene given at runtime is the one it was baked from.
//!
//! Hashed: each input in order; for a `builtin:` spec its text; for a file its bytes plus the bytes
//! of the side files it may reference (`.bin`, `.mtl` and images in the same directory); for a
//! directory every regular file below it, by sorted relative path. Absolute paths are not hashed, so
//! moving a scene keeps its fingerprint. The up axis is hashed too.

use std::path::{Path, PathBuf};

use lemi_core::UpAxis;

use crate::SceneError;

const SIDE_FILES: &[&str] = &["bin", "mtl", "png", "jpg", "jpeg"];

fn io_err(path: &Path, source: std::io::Error) -> SceneError {
    SceneError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn hash_file(h: &mut blake3::Hasher, name: &str, path: &Path) -> Result<(), SceneError> {
    let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
    h.update(name.as_bytes());
    h.update(&(bytes.len() as u64).to_le_bytes());
    h.update(&bytes);
    Ok(())
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), SceneError> {
    let rd = std::fs::read_dir(dir).map_err(|e| io_err(dir, e))?;
    for entry in rd {
        let entry = entry.map_err(|e| io_err(dir, e))?;
        let p = entry.path();
        let ft = entry.file_type().map_err(|e| io_err(&p, e))?;
        if ft.is_dir() {
            walk(&p, out)?;
        } else if p.is_file() {
            out.push(p);
        }
    }
    Ok(())
}

/// Hex BLAKE3 fingerprint of the inputs (see the module docs).
pub fn fingerprint(inputs: &[String], up: UpAxis) -> Result<String, SceneError> {
    let mut h = blake3::Hasher::new();
    h.update(b"lemi-scene-fingerprint-v1");
    h.update(match up {
        UpAxis::Y => b"up=y",
        UpAxis::Z => b"up=z",
    });
    for input in inputs {
        if let Some(spec) = input.strip_prefix("builtin:") {
            h.update(b"builtin:");
            h.update(spec.trim().as_bytes());
            continue;
        }
        let path = Path::new(input);
        let meta = std::fs::metadata(path).map_err(|e| io_err(path, e))?;
        if meta.is_dir() {
            let mut files = Vec::new();
            walk(path, &mut files)?;
            files.sort();
            for f in files {
                let rel = f
                    .strip_prefix(path)
                    .unwrap_or(&f)
                    .to_string_lossy()
                    .into_owned();
                hash_file(&mut h, &rel, &f)?;
            }
        } else {
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            hash_file(&mut h, &name, path)?;
            let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
            let dir = dir.unwrap_or(Path::new("."));
            let mut side: Vec<PathBuf> = std::fs::read_dir(dir)
                .map_err(|e| io_err(dir, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.is_file()
                        && p != path
                        && p.extension()
                            .and_then(|e| e.to_str())
                            .is_some_and(|e| SIDE_FILES.contains(&e.to_ascii_lowercase().as_str()))
                })
                .collect();
            side.sort();
            for f in side {
                let rel = f
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                hash_file(&mut h, &rel, &f)?;
            }
        }
    }
    Ok(h.finalize().to_hex().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changes_with_content_not_location() {
        let base = std::env::temp_dir().join(format!("lemi-fp-{}", std::process::id()));
        let a = base.join("a");
        let b = base.join("b");
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        std::fs::write(a.join("m.obj"), "v 0 0 0\n").unwrap();
        std::fs::write(b.join("m.obj"), "v 0 0 0\n").unwrap();
        let fa = fingerprint(&[a.join("m.obj").display().to_string()], UpAxis::Y).unwrap();
        let fb = fingerprint(&[b.join("m.obj").display().to_string()], UpAxis::Y).unwrap();
        assert_eq!(fa, fb);
        let fz = fingerprint(&[a.join("m.obj").display().to_string()], UpAxis::Z).unwrap();
        assert_ne!(fa, fz);
        std::fs::write(b.join("m.mtl"), "newmtl x\n").unwrap();
        let fb2 = fingerprint(&[b.join("m.obj").display().to_string()], UpAxis::Y).unwrap();
        assert_ne!(fa, fb2, "a side file changes the fingerprint");
        let fd = fingerprint(&[a.display().to_string()], UpAxis::Y).unwrap();
        std::fs::create_dir_all(a.join("sub")).unwrap();
        std::fs::write(a.join("sub/n.ply"), "ply\n").unwrap();
        let fd2 = fingerprint(&[a.display().to_string()], UpAxis::Y).unwrap();
        assert_ne!(
            fd, fd2,
            "a file deep in a directory changes the fingerprint"
        );
        assert!(fingerprint(&[base.join("missing.ply").display().to_string()], UpAxis::Y).is_err());
        let c1 = fingerprint(&["builtin:city:1000".into()], UpAxis::Y).unwrap();
        let c2 = fingerprint(&["builtin:city:2000".into()], UpAxis::Y).unwrap();
        assert_ne!(c1, c2);
        std::fs::remove_dir_all(&base).unwrap();
    }
}
