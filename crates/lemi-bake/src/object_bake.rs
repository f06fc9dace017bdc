//! The bake of one object impostor (TR-186-2-02-04 sec. 2.1.1-2.2, sec. 3): placement of the
//! object's planar layers for its box or shaft view cell ([`lemi_core::object_cell`]), then the
//! environment-map cell's pipeline unchanged ([`Baker::bake_planned`]) on the object's triangles
//! mapped to the canonical frame (the impostor frustum as cube face `+Z`): slab classification,
//! clipping with canonical cuts, conservative recording, gap fill, hidden texels, micro-textures,
//! macro packing, the texture format. The quads' corners are then mapped back to the world by the
//! frame, and the cell's near list becomes everything drawn as geometry in the cell: every scene
//! triangle but the object's.

use std::path::Path;
use std::time::Instant;

use lemi_core::bundle::{
    cell_file_name, BakeParams, CellEntry, CellFile, LayerTarget, Manifest, SceneRef,
    MANIFEST_FORMAT, OBJECT_BUNDLE_VERSION,
};
use lemi_core::cell::CellGrid;
use lemi_core::classify::TriRef;
use lemi_core::compress::TexelRect;
use lemi_core::container::write_atomic;
use lemi_core::object_cell::{canonical_scene, complement, ObjectError, ObjectSetup};
use lemi_core::placement::ObjectPlacement;
use lemi_core::{Face, Scene};
use lemi_gpu::Gpu;

use crate::{BakeError, Baker, Stage};

/// A baked object impostor.
pub struct ObjectBake {
    /// The cell file (its header's `object` section set, corners in the world).
    pub file: CellFile,
    /// The TR's layers, near to far, in TR coordinates (from the cell border nearest the object).
    pub placement: ObjectPlacement,
    /// Triangles of the object (replaced by the impostor).
    pub object_triangles: u64,
}

/// The bake parameters of an object impostor: one face (`+Z` of the canonical frame), its
/// resolution, α and output view, the layer count of the placement, and `base`'s compression
/// and texture settings. `cell_size` records the cell's largest width across the axis.
pub fn object_params(setup: &ObjectSetup, layers: usize, base: &BakeParams) -> BakeParams {
    let n = setup.params.cell.near_width();
    BakeParams {
        cell_size: n[0].max(n[1]).max(1e-6),
        cell_height: None,
        resolution: setup.params.res,
        target: LayerTarget::Layers(layers.max(1) as u32),
        faces: vec![Face::PosZ],
        alpha: setup.params.alpha,
        ..base.clone()
    }
}

/// The bake parameters of an object impostor as `lemi bake-object` makes them: [`object_params`]
/// on the defaults of a cell bake (micro-texture grid 8, threshold 0.6, default layering) with the
/// output view `fov_deg`/`width` the bundle records and `texture_format`.
pub fn object_bake_params(
    setup: &ObjectSetup,
    layers: usize,
    (fov_deg, width): (Option<f64>, Option<u32>),
    texture_format: lemi_core::compress::TextureFormat,
) -> BakeParams {
    let base = BakeParams {
        cell_size: 1.0,
        cell_height: None,
        resolution: setup.params.res,
        target: LayerTarget::Layers(1),
        faces: vec![Face::PosZ],
        alpha: setup.params.alpha,
        output_fov_deg: fov_deg,
        output_width: width,
        micro_grid: 8,
        micro_threshold: 0.6,
        layering: Default::default(),
        texture_format,
        outline_copies: false,
        outline_fringe: false,
    };
    object_params(setup, layers, &base)
}

/// Bakes the impostor of the triangles `object` of `scene` for `setup`, with `params` from
/// [`object_params`]; `on_stage` is told when each stage starts.
pub fn bake_object(
    gpu: &Gpu,
    scene: &Scene,
    object: &[TriRef],
    setup: &ObjectSetup,
    params: BakeParams,
    mut on_stage: impl FnMut(&Stage),
) -> Result<ObjectBake, BakeError> {
    on_stage(&Stage::Placement);
    let t = Instant::now();
    let placement = setup.place()?;
    let plan = setup.plan(&placement);
    let canonical = canonical_scene(scene, object, &setup.frame)
        .map_err(|e| BakeError::Object(ObjectError::Object(e.to_string())))?;
    let seconds = vec![("placement".to_string(), t.elapsed().as_secs_f64())];
    let baker = Baker::new(gpu, &canonical, params)?;
    let cell = setup.canonical_cell();
    let mut file = baker.bake_planned(&cell, &plan, seconds, &mut on_stage)?;
    file.header.object = Some(setup.clone());
    let header = &file.header;
    let corners: Vec<[[f32; 3]; 4]> = header
        .quads
        .iter()
        .map(|q| {
            let slot = header.faces.iter().position(|&f| f == q.face).unwrap_or(0);
            let distance = header.layers[slot][q.layer as usize].distance;
            let [x0, y0, x1, y1] = q.texels.map(u32::from);
            header.quad_corners(q.face, distance, TexelRect { x0, y0, x1, y1 })
        })
        .collect();
    for (q, c) in file.header.quads.iter_mut().zip(corners) {
        q.corners = c;
    }
    file.near = complement(scene, object);
    file.header.stats.near_triangles = file.near.len() as u64;
    Ok(ObjectBake {
        file,
        placement,
        object_triangles: object.len() as u64,
    })
}

/// Writes an object bundle: the cell file (`cells/0_0_0.lemicell`, atomically) with `scene`'s
/// fingerprint and the parameters' hash, then the manifest ([`OBJECT_BUNDLE_VERSION`], its
/// `object` section, a nominal one-cell grid centred on the reference viewpoint). Returns the
/// manifest and the cell file's size in bytes.
pub fn write_object_bundle(
    bundle: &Path,
    scene: SceneRef,
    params: &BakeParams,
    baked: &mut ObjectBake,
) -> Result<(Manifest, u64), BakeError> {
    let Some(setup) = baked.file.header.object.clone() else {
        return Err(BakeError::Object(ObjectError::Object(
            "the cell has no object section".into(),
        )));
    };
    let hash = params.hash();
    let cells_dir = bundle.join("cells");
    std::fs::create_dir_all(&cells_dir).map_err(|source| BakeError::Write {
        path: cells_dir.clone(),
        source,
        hint: String::new(),
    })?;
    let file = &mut baked.file;
    file.header.params_hash = hash.clone();
    file.header.scene_fingerprint = scene.fingerprint.clone();
    let id = file.header.cell.id();
    let bytes = file
        .encode()
        .map_err(|source| BakeError::Encode { cell: id, source })?;
    let path = bundle.join(cell_file_name(id));
    write_atomic(&path, &bytes).map_err(|source| BakeError::Write {
        path: path.clone(),
        source,
        hint: String::new(),
    })?;
    let size = params.cell_size;
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        version: OBJECT_BUNDLE_VERSION,
        generator: format!("lemi {}", env!("CARGO_PKG_VERSION")),
        scene,
        params: params.clone(),
        params_hash: hash,
        grid: CellGrid {
            origin: setup.frame.origin - glam::DVec3::splat(0.5 * size),
            cell_size: size,
            cell_height: None,
            counts: glam::IVec3::ONE,
        },
        cells: vec![CellEntry {
            id,
            file: cell_file_name(id),
            bytes: bytes.len() as u64,
            blake3: blake3::hash(&bytes).to_hex().to_string(),
        }],
        object: Some(setup),
    };
    manifest.write(bundle)?;
    Ok((manifest, bytes.len() as u64))
}
