//! File import: glTF 2.0 (`.gltf`, `.glb`), OBJ + MTL, PLY (ASCII, binary LE/BE, `.ply.gz`) and
//! built-in specs, composed into one [`Scene`] through [`SceneBuilder`].
//!
//! Based on the file format specifications (Khronos glTF 2.0; Wavefront OBJ/MTL; Turk's PLY
//! polygon file format) and lemi's conventions (metres, right-handed, +Y up): every reader converts the input's up axis
//! with [`lemi_core::UpAxis::to_y_up`] before handing geometry to [`SceneBuilder::add_mesh`], which
//! validates triangles (non-finite, degenerate, bad index: dropped and counted) and fills in flat
//! normals where a file has none (readers pass zero normals then).
//!
//! Inputs are processed in the order given; a directory contributes every supported file below it
//! (recursively, symlinked directories not followed) in sorted path order, so loads are
//! deterministic. Problems that do not stop a file from loading (a missing MTL, a missing texture,
//! skipped point/line primitives) are collected as warnings in [`ImportReport`].

pub(crate) mod gltf;
pub(crate) mod obj;
mod ply;

use std::path::{Path, PathBuf};

use lemi_core::{Scene, SceneBuilder};

use crate::{LoadOptions, SceneError};

/// What an import noticed without failing: returned by [`load_with_report`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportReport {
    /// Human-readable warnings, each naming its file.
    pub warnings: Vec<String>,
    /// glTF primitives that were skipped because they are points or lines.
    pub skipped_primitives: u64,
    /// OBJ files whose MTL library could not be loaded (their faces use a default material).
    pub missing_materials: u64,
    /// Textures that could not be read or decoded (their materials keep only the colour factor).
    pub missing_textures: u64,
    /// Which meshes of the scene each input file (or `builtin:` spec) became, in load order:
    /// what `lemi bake-object --object-mesh` selects an object by.
    pub parts: Vec<ScenePart>,
}

/// The meshes one input file (or `builtin:` spec) of a scene became.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScenePart {
    /// The file's path (a file found in a directory input: its path below it), or the spec.
    pub name: String,
    /// Its meshes, a range of `Scene::meshes`.
    pub meshes: std::ops::Range<usize>,
}

impl ScenePart {
    /// Whether `name` names this part: its path as given, its file name, or its file name
    /// without the extensions (`dragon` for `models/dragon.ply.gz`).
    pub fn is_named(&self, name: &str) -> bool {
        let path = Path::new(&self.name);
        let file = path.file_name().map(|f| f.to_string_lossy().into_owned());
        let stem = file
            .as_deref()
            .and_then(|f| f.split('.').next())
            .map(str::to_owned);
        self.name == name || file.as_deref() == Some(name) || stem.as_deref() == Some(name)
    }
}

impl ImportReport {
    pub(crate) fn warn(&mut self, path: &Path, message: impl std::fmt::Display) {
        self.warnings.push(format!("{}: {message}", path.display()));
    }
}

/// The supported file kinds, recognised by extension (case-insensitive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Gltf,
    Glb,
    Obj,
    Ply,
    PlyGz,
}

pub(crate) fn kind_of(path: &Path) -> Option<Kind> {
    let name = path.file_name()?.to_str()?.to_ascii_lowercase();
    if name.ends_with(".ply.gz") {
        Some(Kind::PlyGz)
    } else if name.ends_with(".ply") {
        Some(Kind::Ply)
    } else if name.ends_with(".gltf") {
        Some(Kind::Gltf)
    } else if name.ends_with(".glb") {
        Some(Kind::Glb)
    } else if name.ends_with(".obj") {
        Some(Kind::Obj)
    } else {
        None
    }
}

/// Loads and composes every input into one scene (see the crate docs for what an input may be).
pub fn load(inputs: &[String], options: &LoadOptions) -> Result<Scene, SceneError> {
    load_with_report(inputs, options).map(|(scene, _)| scene)
}

/// Like [`load`], and also returns the warnings and counts of what was skipped.
pub fn load_with_report(
    inputs: &[String],
    options: &LoadOptions,
) -> Result<(Scene, ImportReport), SceneError> {
    let mut builder = SceneBuilder::new();
    let mut report = ImportReport::default();
    for input in inputs {
        if let Some(spec) = input.strip_prefix("builtin:") {
            progress(options, input, 0, 0);
            let scene = crate::builtin::build(spec)?;
            let first = builder.mesh_count();
            builder.append_scene(scene);
            report.parts.push(ScenePart {
                name: input.clone(),
                meshes: first..builder.mesh_count(),
            });
            continue;
        }
        let path = PathBuf::from(input);
        let meta = std::fs::metadata(&path).map_err(|source| SceneError::Io {
            path: path.clone(),
            source,
        })?;
        let files = if meta.is_dir() {
            let mut files = Vec::new();
            collect_dir(&path, &mut files)?;
            files.sort();
            files
        } else {
            vec![path]
        };
        let total = files.len() as u64;
        for (i, file) in files.iter().enumerate() {
            progress(options, &file.display().to_string(), i as u64, total);
            let first = builder.mesh_count();
            load_file(file, options, &mut builder, &mut report)?;
            report.parts.push(ScenePart {
                name: file.display().to_string(),
                meshes: first..builder.mesh_count(),
            });
        }
    }
    let scene = builder.finish();
    if scene.triangle_count() == 0 {
        return Err(SceneError::Empty {
            inputs: inputs.join(", "),
        });
    }
    Ok((scene, report))
}

fn progress(options: &LoadOptions, what: &str, done: u64, total: u64) {
    if let Some(cb) = &options.progress {
        cb(what, done, total);
    }
}

/// Every supported file below `dir`, recursively (symlinked directories are not followed, so
/// cycles cannot occur).
pub(crate) fn collect_dir(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), SceneError> {
    let io = |source| SceneError::Io {
        path: dir.to_path_buf(),
        source,
    };
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let entry = entry.map_err(io)?;
        let path = entry.path();
        let ft = entry.file_type().map_err(|source| SceneError::Io {
            path: path.clone(),
            source,
        })?;
        if ft.is_dir() {
            collect_dir(&path, out)?;
        } else if kind_of(&path).is_some()
            && (ft.is_file() || std::fs::metadata(&path).is_ok_and(|m| m.is_file()))
        {
            out.push(path);
        }
    }
    Ok(())
}

/// Loads one file into `builder`.
fn load_file(
    path: &Path,
    options: &LoadOptions,
    builder: &mut SceneBuilder,
    report: &mut ImportReport,
) -> Result<(), SceneError> {
    let kind = kind_of(path).ok_or_else(|| SceneError::Unsupported {
        path: path.to_path_buf(),
    })?;
    let before = builder.triangle_count();
    // The readers are written not to panic on any input; this is a backstop for the third-party
    // parsers they call, so that a bug there still ends as an error naming the file.
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match kind {
        Kind::Gltf | Kind::Glb => gltf::load(path, options, builder, report),
        Kind::Obj => obj::load(path, options, builder, report),
        Kind::Ply => ply::load(path, false, options, builder, report),
        Kind::PlyGz => ply::load(path, true, options, builder, report),
    }));
    match result {
        Ok(r) => r?,
        Err(_) => {
            return Err(malformed(
                path,
                "the file could not be parsed (reader failure)",
            ));
        }
    }
    if builder.triangle_count() > before {
        builder.add_source(path.display().to_string());
    }
    Ok(())
}

/// Reads a whole file, naming it in the error.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, SceneError> {
    std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads a file that another file references (a glTF buffer or image, an OBJ's MTL library). Only
/// a regular file is read: the reference comes from the file's bytes, and a device or a pipe
/// (`/dev/zero`, `/dev/stdin`) would be an endless read or a hang rather than an error.
pub(crate) fn read_referenced(path: &Path) -> std::io::Result<Vec<u8>> {
    if !std::fs::metadata(path)?.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file",
        ));
    }
    std::fs::read(path)
}

pub(crate) fn malformed(path: &Path, message: impl Into<String>) -> SceneError {
    SceneError::Malformed {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Converts an sRGB-encoded 8-bit channel to a linear 8-bit channel (IEC 61966-2-1 transfer
/// function), for vertex colours stored in display encoding (PLY, OBJ).
pub(crate) fn srgb8_to_linear8(c: u8) -> u8 {
    let s = c as f32 / 255.0;
    let l = if s <= 0.04045 {
        s / 12.92
    } else {
        ((s + 0.055) / 1.055).powf(2.4)
    };
    (l * 255.0).round().clamp(0.0, 255.0) as u8
}

/// Decodes an image file's bytes into an RGBA8 sRGB [`lemi_core::Texture`].
pub(crate) fn decode_texture(
    name: String,
    bytes: &[u8],
) -> Result<lemi_core::Texture, image::ImageError> {
    let img = image::load_from_memory(bytes)?.to_rgba8();
    Ok(lemi_core::Texture {
        name,
        width: img.width(),
        height: img.height(),
        rgba8: img.into_raw(),
    })
}
