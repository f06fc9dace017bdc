//! Wavefront OBJ + MTL reader on top of `tobj` (faces triangulated, one index per vertex), based on
//! the Wavefront OBJ and MTL specifications (Appendix B1/B2 of the Advanced Visualizer manual).
//!
//! Materials: `Kd` becomes the base colour factor and `map_Kd` the base colour texture, resolved
//! relative to the MTL file's directory (then the OBJ's). A missing or unreadable MTL library or
//! texture is a warning (counted in [`ImportReport`]), not an error. Texture coordinates are flipped
//! to a top-left origin (`v → 1 − v`) to match the row order of [`lemi_core::Texture`]. Vertex
//! colours (`v x y z r g b`) are taken as sRGB-encoded 0..1 values and converted to linear.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use lemi_core::{Material, Mesh, SceneBuilder, Vertex};

use super::{decode_texture, malformed, read_file, srgb8_to_linear8, ImportReport};
use crate::{LoadOptions, SceneError};

pub(super) fn load(
    path: &Path,
    options: &LoadOptions,
    builder: &mut SceneBuilder,
    report: &mut ImportReport,
) -> Result<(), SceneError> {
    let bytes = read_file(path)?;
    if let Some(e) = bad_face_index(&bytes) {
        return Err(malformed(path, format!("OBJ: {e}")));
    }
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    // Directories of the MTL libraries tobj asked for, to resolve texture paths.
    let mtl_dirs: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
    let mtl_errors: Mutex<Vec<String>> = Mutex::new(Vec::new());
    let tobj_options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, materials) =
        tobj::load_obj_buf(&mut bytes.as_slice(), &tobj_options, |mtl_path| {
            let full = dir.join(mtl_path);
            if let Ok(mut d) = mtl_dirs.lock() {
                d.push(full.parent().map(Path::to_path_buf).unwrap_or_default());
            }
            // Only a regular file: `mtllib /dev/zero` must not be an endless read.
            let r = if full.is_file() {
                match std::fs::read(&full) {
                    Ok(mtl) => match short_colour(&mtl) {
                        Some(line) => Err(format!(
                            "line {line}: a colour (Ka, Kd, Ks, Ke) needs three numbers"
                        )),
                        None => tobj::load_mtl_buf(&mut mtl.as_slice()).map_err(|e| e.to_string()),
                    },
                    Err(e) => Err(e.to_string()),
                }
            } else {
                Err(tobj::LoadError::OpenFileFailed.to_string())
            };
            match r {
                Ok(m) => Ok(m),
                Err(e) => {
                    if let Ok(mut errs) = mtl_errors.lock() {
                        errs.push(format!("material library {}: {e}", full.display()));
                    }
                    Err(tobj::LoadError::MaterialParseError)
                }
            }
        })
        .map_err(|e| malformed(path, format!("OBJ: {e}")))?;
    let mut dirs = mtl_dirs.into_inner().unwrap_or_default();
    dirs.push(dir.clone());
    for e in mtl_errors.into_inner().unwrap_or_default() {
        report.warn(path, e);
    }
    let materials = match materials {
        Ok(m) => m,
        Err(e) => {
            report.missing_materials += 1;
            report.warn(
                path,
                format!("materials not loaded ({e}); using the default material"),
            );
            Vec::new()
        }
    };

    // Scene materials, created on first use; `None` key is the file's default material.
    let mut material_map: HashMap<Option<usize>, u32> = HashMap::new();
    let mut texture_cache: HashMap<PathBuf, Option<u32>> = HashMap::new();
    for model in models {
        let m = model.mesh;
        let nverts = m.positions.len() / 3;
        if nverts == 0 || m.indices.is_empty() {
            continue;
        }
        let key = m.material_id.filter(|&i| i < materials.len());
        let material = match material_map.get(&key) {
            Some(&id) => id,
            None => {
                let mat = match key {
                    Some(i) => {
                        let src = &materials[i];
                        let kd = src.diffuse.unwrap_or([0.8, 0.8, 0.8]);
                        let texture = src.diffuse_texture.as_deref().and_then(|t| {
                            texture(path, t, &dirs, builder, report, &mut texture_cache)
                        });
                        Material {
                            name: src.name.clone(),
                            base_color: [kd[0], kd[1], kd[2], src.dissolve.unwrap_or(1.0)],
                            texture,
                        }
                    }
                    None => Material::default(),
                };
                let id = builder.add_material(mat);
                material_map.insert(key, id);
                id
            }
        };
        let mut vertices = Vec::with_capacity(nverts);
        for i in 0..nverts {
            let p = [
                m.positions[3 * i],
                m.positions[3 * i + 1],
                m.positions[3 * i + 2],
            ];
            let n = if m.normals.len() >= 3 * (i + 1) {
                [m.normals[3 * i], m.normals[3 * i + 1], m.normals[3 * i + 2]]
            } else {
                [0.0; 3]
            };
            let uv = if m.texcoords.len() >= 2 * (i + 1) {
                [m.texcoords[2 * i], 1.0 - m.texcoords[2 * i + 1]]
            } else {
                [0.0; 2]
            };
            let color = if m.vertex_color.len() >= 3 * (i + 1) {
                let c = |x: f32| srgb8_to_linear8((x * 255.0).round().clamp(0.0, 255.0) as u8);
                [
                    c(m.vertex_color[3 * i]),
                    c(m.vertex_color[3 * i + 1]),
                    c(m.vertex_color[3 * i + 2]),
                    255,
                ]
            } else {
                [255; 4]
            };
            vertices.push(Vertex::new(
                options.up.to_y_up(p),
                options.up.to_y_up(n),
                uv,
                color,
            ));
        }
        let mut indices = m.indices;
        indices.truncate(indices.len() / 3 * 3);
        builder.add_mesh(Mesh {
            material,
            vertices,
            indices,
        });
    }
    Ok(())
}

/// Loads a `map_Kd` texture (once per file), or warns and returns `None`.
fn texture(
    obj: &Path,
    spec: &str,
    dirs: &[PathBuf],
    builder: &mut SceneBuilder,
    report: &mut ImportReport,
    cache: &mut HashMap<PathBuf, Option<u32>>,
) -> Option<u32> {
    let Some(file) = resolve_texture(spec, dirs) else {
        report.missing_textures += 1;
        report.warn(obj, format!("texture `{spec}` not found"));
        return None;
    };
    if let Some(&t) = cache.get(&file) {
        return t;
    }
    let result = match std::fs::read(&file) {
        Ok(bytes) => match decode_texture(file.display().to_string(), &bytes) {
            Ok(tex) => Some(builder.add_texture(tex)),
            Err(e) => {
                report.missing_textures += 1;
                report.warn(obj, format!("texture {}: {e}", file.display()));
                None
            }
        },
        Err(e) => {
            report.missing_textures += 1;
            report.warn(obj, format!("texture {}: {e}", file.display()));
            None
        }
    };
    cache.insert(file, result);
    result
}

/// The file a texture statement of an MTL file names, if it exists: `map_Kd` (and the other maps)
/// may carry options before the file name (`-s 1 1 1 file.png`), so the whole value is tried
/// first, then its last word, each in `dirs` in order (the directories of the OBJ's MTL libraries,
/// then the OBJ's). Backslashes are read as path separators.
pub(crate) fn resolve_texture(spec: &str, dirs: &[PathBuf]) -> Option<PathBuf> {
    let mut names = vec![spec.trim().to_string()];
    if let Some(last) = spec.split_ascii_whitespace().last() {
        names.push(last.to_string());
    }
    names
        .iter()
        .flat_map(|n| dirs.iter().map(move |d| d.join(n.replace('\\', "/"))))
        .find(|p| p.is_file())
}

/// The MTL libraries an OBJ file names (`mtllib` statements), as written and resolved against the OBJ's
/// directory `dir` as the reader resolves them (the rest of the line is one file name, as `tobj`
/// reads it).
pub(crate) fn mtllib_paths(obj: &[u8], dir: &Path) -> Vec<(String, PathBuf)> {
    let mut out: Vec<(String, PathBuf)> = Vec::new();
    for line in obj.split(|&b| b == b'\n') {
        let line = String::from_utf8_lossy(line.strip_suffix(b"\r").unwrap_or(line));
        if line.split_whitespace().next() != Some("mtllib") {
            continue;
        }
        let name = line.split_once(' ').unwrap_or_default().1.trim();
        if name.is_empty() {
            continue;
        }
        if !out.iter().any(|(n, _)| n == name) {
            out.push((name.to_string(), dir.join(name)));
        }
    }
    out
}

/// The first line (1-based) of an MTL library whose colour statement (`Ka`, `Kd`, `Ks`, `Ke`)
/// has fewer than three values: tobj 4.0 panics on those (an `unwrap` on a 3-array) instead of
/// reporting them, so they are refused before it reads the library (found by AFL++ on the `obj`
/// target).
fn short_colour(mtl: &[u8]) -> Option<usize> {
    String::from_utf8_lossy(mtl)
        .lines()
        .enumerate()
        .find(|(_, line)| {
            let mut words = line.split_whitespace();
            matches!(words.next(), Some("Ka" | "Kd" | "Ks" | "Ke")) && words.count() < 3
        })
        .map(|(i, _)| i + 1)
}

/// The first face or polyline corner whose position, texture coordinate or normal index is 0 or
/// reaches past the elements defined before it (negative indices count back from the last one),
/// as a message naming the line. tobj 4.0 turns such an index into an arithmetic overflow (a
/// panic with overflow checks, a wrong read without) instead of an error (found by AFL++ on the
/// `obj` target, first in `f`, then in `l` statements, which tobj reads the same way), so both
/// are checked before it reads them.
fn bad_face_index(obj: &[u8]) -> Option<String> {
    let mut counts = [0u64; 3]; // v, vt, vn
    for (n, line) in String::from_utf8_lossy(obj).lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some(statement @ ("f" | "l")) => {
                let element = if statement == "f" { "face" } else { "line" };
                for corner in words {
                    for (kind, part) in corner.split('/').take(3).enumerate() {
                        if part.is_empty() {
                            continue;
                        }
                        let ok = part
                            .parse::<i64>()
                            .is_ok_and(|i| i != 0 && i.unsigned_abs() <= counts[kind]);
                        if !ok {
                            let what = ["position", "texture coordinate", "normal"][kind];
                            return Some(format!(
                                "line {}: {element} {what} index `{part}` is not one of the {} defined before it",
                                n + 1,
                                counts[kind]
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    None
}
