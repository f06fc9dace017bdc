//! Scene fingerprints: a hash of what a scene was built from, so a bundle can tell whether the
//! scene given at runtime is the one it was baked from.
//!
//! **Scheme 2** (the current one; the fingerprint reads `v2:` and 64 hex digits of BLAKE3). Hashed
//! after the scheme's tag and the up axis, each input in order:
//! - a `builtin:` spec: its text;
//! - a scene file: its name and bytes, then what it references (each under the reference as
//!   written in the file, never an absolute path, so moving a scene keeps its fingerprint):
//!   - OBJ: every `mtllib` file, resolved as the reader resolves it (relative to the OBJ), then
//!     every texture map its materials name (`map_Kd`, `map_Ka`, `map_Ks`, `map_Ns`, `map_d`,
//!     `map_Bump`/`bump`), resolved as the reader resolves `map_Kd` (the whole value, then its
//!     last word, in the MTL files' directories, then the OBJ's);
//!   - glTF (`.gltf`, `.glb`): every buffer and image URI that is not a `data:` URI (those are in
//!     the file already, as are a GLB's embedded buffer and buffer-view images), percent-decoded
//!     and relative to the glTF file (`../` allowed);
//!   - PLY and `.ply.gz`: nothing else;
//! - a directory: every supported scene file below it, as the importer finds them (sorted, symlinked
//!   directories not followed), under its path relative to the directory, each with what it
//!   references as above.
//!
//! Nothing else is hashed: an image, `.bin` or `.mtl` beside a scene that the scene does not name
//! leaves the fingerprint alone. A referenced file the importer can do without (an MTL library, a
//! texture, a glTF image: it warns and goes on) is hashed as absent when it is missing, so that
//! adding it later, which changes the loaded scene, changes the fingerprint. A glTF buffer that
//! cannot be read is an error naming the glTF file and the buffer's file (the scene cannot be
//! loaded without it).
//!
//! **Scheme 1** (bundles baked before scheme 2; the fingerprint is bare hex): for a file input its
//! bytes plus every `.bin`, `.mtl`, `.png`, `.jpg` and `.jpeg` file in the same directory, used or
//! not; for a directory every regular file below it. [`fingerprint_with`] still computes it, so that
//! such a bundle opens as before (see `docs/FORMAT.md`).

use std::io::Read;
use std::path::{Path, PathBuf};

use lemi_core::UpAxis;

use crate::import::{collect_dir, gltf as gltf_import, kind_of, obj as obj_import, Kind};
use crate::SceneError;

/// A way of computing a scene fingerprint; a bundle records the one it was baked with in its
/// fingerprint's prefix (`v2:`), scheme 1 by none.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FingerprintScheme {
    /// Hashed the files beside a scene file too (bare hex).
    V1,
    /// Hashes what the scene references (`v2:` hex).
    V2,
}

impl FingerprintScheme {
    /// The scheme [`fingerprint`] uses.
    pub const CURRENT: FingerprintScheme = FingerprintScheme::V2;

    /// The scheme a recorded fingerprint was made with: `vN:` names it, no prefix is scheme 1;
    /// `None` for a scheme this lemi does not know (a newer one).
    pub fn of(fingerprint: &str) -> Option<FingerprintScheme> {
        match fingerprint.split_once(':') {
            None => Some(FingerprintScheme::V1),
            Some(("v2", _)) => Some(FingerprintScheme::V2),
            Some(_) => None,
        }
    }

    /// The scheme's number.
    pub fn number(self) -> u32 {
        match self {
            FingerprintScheme::V1 => 1,
            FingerprintScheme::V2 => 2,
        }
    }
}

/// The fingerprint of the inputs under the current scheme (see the module docs).
pub fn fingerprint(inputs: &[String], up: UpAxis) -> Result<String, SceneError> {
    fingerprint_with(inputs, up, FingerprintScheme::CURRENT)
}

/// The fingerprint of the inputs under `scheme` (to check a bundle baked with an older one).
pub fn fingerprint_with(
    inputs: &[String],
    up: UpAxis,
    scheme: FingerprintScheme,
) -> Result<String, SceneError> {
    match scheme {
        FingerprintScheme::V1 => fingerprint_v1(inputs, up),
        FingerprintScheme::V2 => fingerprint_v2(inputs, up),
    }
}

fn io_err(path: &Path, source: std::io::Error) -> SceneError {
    SceneError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Hashes a length-prefixed field (so no two sequences of fields hash alike).
fn field(h: &mut blake3::Hasher, bytes: &[u8]) {
    h.update(&(bytes.len() as u64).to_le_bytes());
    h.update(bytes);
}

/// Hashes a file's contents (length-prefixed) without holding it in memory; `Err` when it cannot
/// be opened or read, or is not a regular file.
fn hash_contents(h: &mut blake3::Hasher, path: &Path) -> std::io::Result<()> {
    let file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(std::io::Error::other("not a regular file"));
    }
    let len = meta.len();
    let mut contents = blake3::Hasher::new();
    let copied = std::io::copy(&mut file.take(len), &mut contents)?;
    if copied != len {
        return Err(std::io::Error::other(
            "the file changed size while it was read",
        ));
    }
    h.update(&len.to_le_bytes());
    h.update(contents.finalize().as_bytes());
    Ok(())
}

/// Hashes a file a scene file references, under the reference as written. A missing or unreadable
/// file is hashed as absent, or, if `required`, an error naming both files.
fn hash_reference(
    h: &mut blake3::Hasher,
    referrer: &Path,
    reference: &str,
    path: &Path,
    required: bool,
) -> Result<(), SceneError> {
    h.update(b"ref");
    field(h, reference.as_bytes());
    let mut inner = blake3::Hasher::new();
    match hash_contents(&mut inner, path) {
        Ok(()) => {
            h.update(b"present");
            h.update(inner.finalize().as_bytes());
            Ok(())
        }
        Err(e) if required => Err(SceneError::Malformed {
            path: referrer.to_path_buf(),
            message: format!(
                "references `{reference}` ({}), which cannot be read: {e}",
                path.display()
            ),
        }),
        Err(_) => {
            h.update(b"absent");
            Ok(())
        }
    }
}

/// Hashes one scene file (under `name`) and what it references.
fn hash_scene_file(h: &mut blake3::Hasher, name: &str, path: &Path) -> Result<(), SceneError> {
    h.update(b"scene-file");
    field(h, name.as_bytes());
    match kind_of(path) {
        Some(Kind::Obj) => {
            let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
            field(h, &bytes);
            hash_obj_references(h, path, &bytes)
        }
        Some(Kind::Gltf | Kind::Glb) => {
            let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
            field(h, &bytes);
            hash_gltf_references(h, path, &bytes)
        }
        // PLY, `.ply.gz` (and, for a file input, anything else, which the importer refuses)
        Some(Kind::Ply | Kind::PlyGz) | None => hash_contents(h, path).map_err(|e| io_err(path, e)),
    }
}

/// An OBJ's MTL libraries and the texture maps their materials name.
fn hash_obj_references(h: &mut blake3::Hasher, obj: &Path, bytes: &[u8]) -> Result<(), SceneError> {
    let dir = obj.parent().unwrap_or(Path::new(""));
    let libs = obj_import::mtllib_paths(bytes, dir);
    // Texture lookup directories, as the reader has them: the libraries', then the OBJ's.
    let mut dirs: Vec<PathBuf> = libs
        .iter()
        .map(|(_, p)| p.parent().map(Path::to_path_buf).unwrap_or_default())
        .collect();
    dirs.push(dir.to_path_buf());
    let mut maps: Vec<String> = Vec::new();
    for (name, path) in &libs {
        h.update(b"mtllib");
        field(h, name.as_bytes());
        let mtl = std::fs::metadata(path)
            .ok()
            .filter(|m| m.is_file())
            .and_then(|_| std::fs::read(path).ok());
        let Some(mtl) = mtl else {
            h.update(b"absent");
            continue;
        };
        field(h, &mtl);
        // An MTL file that does not parse gives the reader no materials, so no textures.
        if let Ok((materials, _)) = tobj::load_mtl_buf(&mut mtl.as_slice()) {
            for m in materials {
                let named = [
                    m.diffuse_texture,
                    m.ambient_texture,
                    m.specular_texture,
                    m.shininess_texture,
                    m.dissolve_texture,
                    m.normal_texture,
                ];
                for spec in named.into_iter().flatten() {
                    if !maps.contains(&spec) {
                        maps.push(spec);
                    }
                }
            }
        }
    }
    for spec in maps {
        match obj_import::resolve_texture(&spec, &dirs) {
            Some(path) => hash_reference(h, obj, &spec, &path, false)?,
            None => {
                h.update(b"ref");
                field(h, spec.as_bytes());
                h.update(b"absent");
            }
        }
    }
    Ok(())
}

/// A glTF file's buffer and image URIs that name files (`data:` URIs are in the file already).
fn hash_gltf_references(
    h: &mut blake3::Hasher,
    path: &Path,
    bytes: &[u8],
) -> Result<(), SceneError> {
    let parsed = gltf_import::parse(bytes).map_err(|e| SceneError::Malformed {
        path: path.to_path_buf(),
        message: format!("glTF: {e}"),
    })?;
    let dir = path.parent().unwrap_or(Path::new(""));
    for buffer in parsed.document.buffers() {
        if let gltf::buffer::Source::Uri(uri) = buffer.source() {
            match gltf_import::uri_path(dir, uri) {
                Ok(None) => {}
                Ok(Some(file)) => hash_reference(h, path, uri, &file, true)?,
                Err(e) => {
                    return Err(SceneError::Malformed {
                        path: path.to_path_buf(),
                        message: format!("buffer {} (`{uri}`): {e}", buffer.index()),
                    })
                }
            }
        }
    }
    for image in &parsed.document.as_json().images {
        let Some(uri) = &image.uri else { continue };
        match gltf_import::uri_path(dir, uri) {
            Ok(None) => {}
            Ok(Some(file)) => hash_reference(h, path, uri, &file, false)?,
            // the importer skips such an image with a warning
            Err(_) => {
                h.update(b"ref");
                field(h, uri.as_bytes());
                h.update(b"unsupported");
            }
        }
    }
    Ok(())
}

/// A path relative to a directory input, with `/` separators on every platform.
fn relative_name(file: &Path, dir: &Path) -> String {
    let rel = file.strip_prefix(dir).unwrap_or(file);
    rel.components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join("/")
}

fn fingerprint_v2(inputs: &[String], up: UpAxis) -> Result<String, SceneError> {
    let mut h = blake3::Hasher::new();
    h.update(b"lemi-scene-fingerprint-v2");
    h.update(match up {
        UpAxis::Y => b"up=y",
        UpAxis::Z => b"up=z",
    });
    for input in inputs {
        if let Some(spec) = input.strip_prefix("builtin:") {
            h.update(b"builtin");
            field(&mut h, spec.trim().as_bytes());
            continue;
        }
        let path = Path::new(input);
        let meta = std::fs::metadata(path).map_err(|e| io_err(path, e))?;
        if meta.is_dir() {
            let mut files = Vec::new();
            collect_dir(path, &mut files)?;
            files.sort();
            h.update(b"dir");
            h.update(&(files.len() as u64).to_le_bytes());
            for f in files {
                hash_scene_file(&mut h, &relative_name(&f, path), &f)?;
            }
        } else {
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            hash_scene_file(&mut h, &name, path)?;
        }
    }
    Ok(format!("v2:{}", h.finalize().to_hex()))
}

const SIDE_FILES: &[&str] = &["bin", "mtl", "png", "jpg", "jpeg"];

fn hash_file_v1(h: &mut blake3::Hasher, name: &str, path: &Path) -> Result<(), SceneError> {
    let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
    h.update(name.as_bytes());
    h.update(&(bytes.len() as u64).to_le_bytes());
    h.update(&bytes);
    Ok(())
}

fn walk_all(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), SceneError> {
    let rd = std::fs::read_dir(dir).map_err(|e| io_err(dir, e))?;
    for entry in rd {
        let entry = entry.map_err(|e| io_err(dir, e))?;
        let p = entry.path();
        let ft = entry.file_type().map_err(|e| io_err(&p, e))?;
        if ft.is_dir() {
            walk_all(&p, out)?;
        } else if p.is_file() {
            out.push(p);
        }
    }
    Ok(())
}

/// Scheme 1 (see the module docs): kept so that bundles baked with it still open.
fn fingerprint_v1(inputs: &[String], up: UpAxis) -> Result<String, SceneError> {
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
            walk_all(path, &mut files)?;
            files.sort();
            for f in files {
                let rel = f
                    .strip_prefix(path)
                    .unwrap_or(&f)
                    .to_string_lossy()
                    .into_owned();
                hash_file_v1(&mut h, &rel, &f)?;
            }
        } else {
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            hash_file_v1(&mut h, &name, path)?;
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
                hash_file_v1(&mut h, &rel, &f)?;
            }
        }
    }
    Ok(h.finalize().to_hex().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn fp(path: &Path) -> String {
        fingerprint(&[path.display().to_string()], UpAxis::Y).unwrap()
    }

    const PLY: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
        property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
        end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";

    /// A triangle OBJ naming `mats/m.mtl`, whose material names `../tex/wood.png` (relative to
    /// the MTL's directory) with an option before it.
    fn write_obj(dir: &Path) -> PathBuf {
        fs::create_dir_all(dir.join("mats")).unwrap();
        fs::create_dir_all(dir.join("tex")).unwrap();
        fs::write(
            dir.join("m.obj"),
            "mtllib mats/m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl wood\nf 1 2 3\n",
        )
        .unwrap();
        fs::write(
            dir.join("mats/m.mtl"),
            "newmtl wood\nKd 1 1 1\nmap_Kd -s 1 1 1 ../tex/wood.png\n",
        )
        .unwrap();
        fs::write(dir.join("tex/wood.png"), b"wood pixels").unwrap();
        dir.join("m.obj")
    }

    /// A triangle glTF whose buffer is `buf uri` (percent-encoded, maybe with `../`) and whose one
    /// image is `tex.png`; plus a `data:` image.
    fn write_gltf(dir: &Path, name: &str, buffer_uri: &str, buffer_file: &Path) -> PathBuf {
        let positions: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.]
            .iter()
            .flat_map(|f| f.to_le_bytes())
            .collect();
        fs::create_dir_all(buffer_file.parent().unwrap()).unwrap();
        fs::write(buffer_file, &positions).unwrap();
        fs::write(dir.join("tex.png"), b"texture pixels").unwrap();
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
            "bufferViews":[{{"buffer":0,"byteLength":36}}],
            "buffers":[{{"uri":"{buffer_uri}","byteLength":36}}],
            "images":[{{"uri":"tex.png"}},{{"uri":"data:image/png;base64,AAAA"}}]}}"#
        );
        let path = dir.join(name);
        fs::write(&path, json).unwrap();
        path
    }

    #[test]
    fn fingerprints_name_their_scheme() {
        let f = fingerprint(&["builtin:city:1000".into()], UpAxis::Y).unwrap();
        assert!(f.starts_with("v2:") && f.len() == 3 + 64, "{f}");
        assert_eq!(FingerprintScheme::of(&f), Some(FingerprintScheme::V2));
        let old = fingerprint_with(
            &["builtin:city:1000".into()],
            UpAxis::Y,
            FingerprintScheme::V1,
        )
        .unwrap();
        assert_eq!(old.len(), 64);
        assert_eq!(FingerprintScheme::of(&old), Some(FingerprintScheme::V1));
        assert_eq!(FingerprintScheme::of("v9:abc"), None);
        let c2 = fingerprint(&["builtin:city:2000".into()], UpAxis::Y).unwrap();
        assert_ne!(f, c2);
    }

    #[test]
    fn changes_with_content_and_up_axis_not_location() {
        let base = tempfile::tempdir().unwrap();
        let a = base.path().join("a");
        let b = base.path().join("b");
        let oa = write_obj(&a);
        let ob = write_obj(&b);
        assert_eq!(fp(&oa), fp(&ob));
        assert_eq!(fp(&a), fp(&b), "a moved directory keeps its fingerprint");
        let fz = fingerprint(&[oa.display().to_string()], UpAxis::Z).unwrap();
        assert_ne!(fp(&oa), fz);
        fs::write(
            &ob,
            "mtllib mats/m.mtl\nv 0 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\n",
        )
        .unwrap();
        assert_ne!(fp(&oa), fp(&ob));
        // a path relative to the working directory gives what the absolute one gives
        let cwd = std::env::current_dir().unwrap();
        let ups = cwd.components().count().saturating_sub(1);
        let abs = oa.canonicalize().unwrap();
        let rel = Path::new(&"../".repeat(ups)).join(abs.strip_prefix("/").unwrap());
        assert!(rel.is_relative());
        assert_eq!(fp(&rel), fp(&oa));
        assert!(fingerprint(
            &[base.path().join("missing.ply").display().to_string()],
            UpAxis::Y
        )
        .is_err());
    }

    #[test]
    fn unrelated_files_beside_a_scene_leave_it_alone() {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path();
        fs::write(dir.join("s.ply"), PLY).unwrap();
        let obj = write_obj(&dir.join("o"));
        let gltf = write_gltf(&dir.join("g"), "s.gltf", "s.bin", &dir.join("g/s.bin"));
        let before = [fp(&dir.join("s.ply")), fp(&obj), fp(&gltf)];
        for sub in [dir.to_path_buf(), dir.join("o"), dir.join("g")] {
            fs::write(sub.join("screenshot.png"), b"a screenshot").unwrap();
            fs::write(sub.join("photo.jpg"), b"a photo").unwrap();
            fs::write(sub.join("other.bin"), b"another buffer").unwrap();
            fs::write(sub.join("other.mtl"), "newmtl x\n").unwrap();
        }
        let after = [fp(&dir.join("s.ply")), fp(&obj), fp(&gltf)];
        assert_eq!(before, after);
        // ... which scheme 1 did not leave alone
        let v1 = |p: &Path| {
            fingerprint_with(&[p.display().to_string()], UpAxis::Y, FingerprintScheme::V1).unwrap()
        };
        let v1_before = v1(&dir.join("s.ply"));
        fs::write(dir.join("another.png"), b"x").unwrap();
        assert_ne!(v1_before, v1(&dir.join("s.ply")));
    }

    #[test]
    fn referenced_files_change_it() {
        let d = tempfile::tempdir().unwrap();
        let obj = write_obj(&d.path().join("o"));
        let f0 = fp(&obj);
        fs::write(d.path().join("o/tex/wood.png"), b"other pixels").unwrap();
        let f1 = fp(&obj);
        assert_ne!(f0, f1, "the texture map");
        fs::write(
            d.path().join("o/mats/m.mtl"),
            "newmtl wood\nKd 1 0 1\nmap_Kd -s 1 1 1 ../tex/wood.png\n",
        )
        .unwrap();
        let f2 = fp(&obj);
        assert_ne!(f1, f2, "the MTL file");
        fs::remove_file(d.path().join("o/tex/wood.png")).unwrap();
        let f3 = fp(&obj);
        assert_ne!(f2, f3, "a texture gone (the importer warns and goes on)");
        fs::remove_file(d.path().join("o/mats/m.mtl")).unwrap();
        assert_ne!(f3, fp(&obj), "the MTL file gone");

        let g = d.path().join("g");
        let gltf = write_gltf(&g, "s.gltf", "s.bin", &g.join("s.bin"));
        let g0 = fp(&gltf);
        fs::write(g.join("s.bin"), [7u8; 36]).unwrap();
        let g1 = fp(&gltf);
        assert_ne!(g0, g1, "the buffer");
        fs::write(g.join("tex.png"), b"new texture").unwrap();
        let g2 = fp(&gltf);
        assert_ne!(g1, g2, "the image");
        fs::remove_file(g.join("tex.png")).unwrap();
        assert_ne!(g2, fp(&gltf), "an image gone");
    }

    #[test]
    fn gltf_uris_percent_encoded_relative_and_broken() {
        let d = tempfile::tempdir().unwrap();
        let g = d.path().join("scene/sub");
        fs::create_dir_all(&g).unwrap();
        let gltf = write_gltf(
            &g,
            "s.gltf",
            "../../bufs/my%20buffer.bin",
            &d.path().join("bufs/my buffer.bin"),
        );
        let f0 = fp(&gltf);
        fs::write(d.path().join("bufs/my buffer.bin"), [1u8; 36]).unwrap();
        assert_ne!(f0, fp(&gltf), "the percent-decoded, `../` buffer is hashed");
        // a missing buffer: an error naming the glTF file and the buffer's
        fs::remove_file(d.path().join("bufs/my buffer.bin")).unwrap();
        let e = fingerprint(&[gltf.display().to_string()], UpAxis::Y)
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.gltf") && e.contains("my buffer.bin"), "{e}");
        // URIs the importer refuses are errors for buffers, never panics
        for uri in [
            "http://example.com/b.bin",
            "%FF%FE.bin",
            "",
            "../../../../../../../x",
        ] {
            let p = write_gltf(&g, "t.gltf", uri, &g.join("unused.bin"));
            let r = fingerprint(&[p.display().to_string()], UpAxis::Y);
            assert!(r.is_err(), "{uri}: {r:?}");
        }
        // a file that is not glTF at all: an error naming it
        fs::write(g.join("bad.gltf"), b"{not json").unwrap();
        let e = fingerprint(&[g.join("bad.gltf").display().to_string()], UpAxis::Y)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.gltf"), "{e}");
    }

    #[test]
    fn a_directory_hashes_its_scene_files_and_their_references() {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path().join("scene");
        write_obj(&dir.join("houses"));
        fs::write(dir.join("ground.ply"), PLY).unwrap();
        let f0 = fp(&dir);
        fs::write(dir.join("notes.png"), b"not referenced").unwrap();
        fs::write(dir.join("houses/extra.bin"), b"not referenced").unwrap();
        assert_eq!(f0, fp(&dir), "files no scene file references");
        fs::write(dir.join("houses/tex/wood.png"), b"repainted").unwrap();
        let f1 = fp(&dir);
        assert_ne!(f0, f1, "a texture an OBJ below references");
        fs::create_dir_all(dir.join("deep/er")).unwrap();
        fs::write(dir.join("deep/er/n.ply"), PLY).unwrap();
        let f2 = fp(&dir);
        assert_ne!(f1, f2, "a scene file deep below");
        fs::rename(dir.join("deep/er/n.ply"), dir.join("deep/er/m.ply")).unwrap();
        assert_ne!(f2, fp(&dir), "a scene file renamed");
    }
}
