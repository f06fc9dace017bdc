//! Opening a baked bundle for rendering: the manifest, the scene it was baked from (from the
//! manifest's sources or `--scene`, checked against the fingerprint), and one verified cell.

use std::path::Path;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use lemi_core::bundle::{manifest_path, CellFile, Manifest};
use lemi_core::cell::ViewCell;
use lemi_core::{Scene, UpAxis};

use crate::load::{load_scene, SceneArgs, UpArg};

/// Whether `path` is a bundle directory (holds `manifest.json`).
pub fn is_bundle(path: &str) -> bool {
    manifest_path(Path::new(path)).is_file()
}

/// The manifest and the scene of a bundle. `scene_override`: scene inputs to use instead of the
/// manifest's sources; they must have the bundle's fingerprint.
pub fn open(bundle: &Path, scene_override: &[String], quiet: bool) -> Result<(Manifest, Scene)> {
    let manifest = Manifest::read(bundle)?;
    let up = if manifest.scene.up == "z" {
        UpArg::Z
    } else {
        UpArg::Y
    };
    let sources = if scene_override.is_empty() {
        manifest.scene.sources.clone()
    } else {
        scene_override.to_vec()
    };
    let fp = lemi_scene::fingerprint(&sources, UpAxis::from(up)).with_context(|| {
        format!(
            "fingerprinting the scene of {} ({}); pass --scene if it moved",
            bundle.display(),
            sources.join(" ")
        )
    })?;
    if fp != manifest.scene.fingerprint {
        bail!(
            "the scene {} is not the one {} was baked from (fingerprint {} , the bundle says {}); \
             pass the original scene with --scene, or bake again",
            sources.join(" "),
            bundle.display(),
            &fp[..12.min(fp.len())],
            &manifest.scene.fingerprint[..12.min(manifest.scene.fingerprint.len())]
        );
    }
    let (scene, _) = load_scene(
        &SceneArgs {
            scenes: sources,
            up,
        },
        quiet,
    )?;
    Ok((manifest, scene))
}

/// The baked cell containing `eye`, read and verified against the manifest's hash.
pub fn cell_at(bundle: &Path, manifest: &Manifest, eye: DVec3) -> Result<(ViewCell, CellFile)> {
    let Some(cell) = manifest.grid.locate(eye) else {
        bail!(
            "the eye ({:.2}, {:.2}, {:.2}) is outside the baked region of {} (grid origin {:?}, {} m cells, {:?})",
            eye.x,
            eye.y,
            eye.z,
            bundle.display(),
            manifest.grid.origin.to_array(),
            manifest.grid.cell_size,
            manifest.grid.counts.to_array()
        );
    };
    let id = cell.id();
    let Some(entry) = manifest.cells.iter().find(|c| c.id == id) else {
        let baked: Vec<&str> = manifest.cells.iter().map(|c| c.id.as_str()).collect();
        bail!(
            "cell {id} (containing the eye) was not baked into {}; baked cells: {}",
            bundle.display(),
            baked.join(", ")
        );
    };
    let path = bundle.join(&entry.file);
    let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    if blake3::hash(&bytes).to_hex().as_str() != entry.blake3 {
        bail!(
            "{}: does not match the manifest's hash (changed or damaged after baking); bake it again",
            path.display()
        );
    }
    let file = CellFile::decode(&bytes).with_context(|| path.display().to_string())?;
    if file.header.params_hash != manifest.params_hash {
        bail!(
            "{}: baked with other parameters than the manifest's",
            path.display()
        );
    }
    Ok((cell, file))
}

/// The cell's reference viewpoint, a default eye for a bundle: the centre of the first baked cell.
pub fn first_cell_center(manifest: &Manifest) -> Option<DVec3> {
    let id = &manifest.cells.first()?.id;
    manifest.grid.parse_id(id).ok().map(|c| c.center)
}
