//! What the lemi-eval examples share: `x,y,z` arguments, a cell's scene and impostors on the GPU
//! with both renderers, and the views of a cell they look at.
// each example uses a part of it
#![allow(dead_code)]

use std::sync::Arc;

use anyhow::{anyhow, bail, Context, Result};
use glam::DVec3;
use lemi_core::cell::{eval_directions, eval_viewpoints, CellId};
use lemi_core::Face;
use lemi_gpu::{
    Gpu, GpuMaterials, GpuScene, ImpostorCell, ImpostorRenderer, Renderer, UploadOptions,
};

/// `x,y,z` as a vector.
pub fn vec3(s: &str) -> Result<DVec3> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("`{s}` is not x,y,z"))?;
    match v[..] {
        [x, y, z] => Ok(DVec3::new(x, y, z)),
        _ => bail!("`{s}` is not x,y,z"),
    }
}

/// One cell of a bundle on the GPU: the whole scene for the reference, the cell's impostors and
/// near geometry, and a renderer for each.
pub struct CellRenderers {
    pub full: GpuScene,
    pub reference: Renderer,
    pub impostors: ImpostorRenderer,
    pub cell: ImpostorCell,
}

impl CellRenderers {
    pub fn new(
        gpu: &Gpu,
        scene: &lemi_core::Scene,
        bundle: &lemi_core::bundle::Bundle,
        id: CellId,
    ) -> Result<CellRenderers> {
        let materials = Arc::new(GpuMaterials::upload(
            gpu,
            &scene.materials,
            &scene.textures,
        )?);
        let file = bundle.cell(id)?;
        Ok(CellRenderers {
            full: GpuScene::upload(gpu, scene, &UploadOptions::default())?,
            reference: Renderer::new(gpu)?,
            impostors: ImpostorRenderer::new(gpu)?,
            cell: ImpostorCell::upload_file(gpu, materials, scene, &file)?,
        })
    }
}

/// The views to look at, `(label, eye, direction)`: the given one, or the cell's evaluated
/// viewpoints whose label `keep` accepts, each looking along every evaluated direction.
pub fn views(
    given: (Option<DVec3>, Option<DVec3>),
    bundle: &lemi_core::bundle::Bundle,
    id: CellId,
    keep: impl Fn(&str) -> bool,
) -> Result<Vec<(String, DVec3, DVec3)>> {
    let manifest = bundle.manifest();
    let faces: &[Face] = &manifest.params.faces;
    match given {
        (Some(e), Some(d)) => Ok(vec![("given".into(), e, d)]),
        (None, None) => {
            let cell_box = manifest.grid.cell_of(id).map_err(|e| anyhow!("{e}"))?;
            let mut v = Vec::new();
            for (l, e) in eval_viewpoints(&cell_box, 0, 1) {
                if keep(&l) {
                    for (dl, d) in eval_directions(faces) {
                        v.push((format!("{l}, looking {dl}"), e, d));
                    }
                }
            }
            Ok(v)
        }
        _ => bail!("give both --eye and --dir, or neither"),
    }
}
