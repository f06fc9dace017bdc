//! Compressed bakes through the certificate: a BC7, BC1, UASTC and ETC1S bake of one cell of a
//! small city, uploaded as stored (the Basis formats transcoded to BC7 and BC1) where the adapter
//! has BC (lavapipe does) and decoded to RGBA8 elsewhere, show no crack pixel from the cell's
//! centre and corners, and their mean FLIP against the reference stays within 0.01 of the PNG
//! bake's (0.02 for ETC1S); the pages hold a quarter (BC7, UASTC) and an eighth (BC1, ETC1S) of
//! the PNG bake's texture memory, give or take the block padding. Compared
//! with the PNG bake's frames of the same views (`lemi eval --against`), they change colours but
//! no pixel's coverage (the alpha test stays exact), and a bake compared with itself changes
//! nothing.
//!
//! Without an adapter the GPU tests fail with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.

use std::path::Path;
use std::sync::Arc;

use glam::DVec3;
use lemi_bake::{BakeJob, Baker};
use lemi_core::bundle::{BakeParams, Bundle, LayerTarget, SceneRef};
use lemi_core::cell::CellGrid;
use lemi_core::compress::{BlockFormat, TextureFormat};
use lemi_core::placement::{alpha_from_output_view, PixelChoice};
use lemi_core::{Aabb, Face, Scene};
use lemi_eval::{evaluate_bundle_against, EvalOptions, ViewpointSet};
use lemi_gpu::{Gpu, GpuMaterials, ImpostorCell};
use lemi_testkit::gpu;

const W: u32 = 256;
const H: u32 = 144;
const FOV: f64 = 60.0;

fn bake(gpu: &Gpu, scene: &Scene, dir: &Path, format: TextureFormat) -> Bundle {
    let alpha = alpha_from_output_view(FOV.to_radians(), W, PixelChoice::Edge).unwrap();
    let params = BakeParams {
        cell_size: 10.0,
        cell_height: None,
        resolution: 256,
        target: LayerTarget::Layers(24),
        faces: Face::HORIZONTAL.to_vec(),
        alpha,
        output_fov_deg: Some(FOV),
        output_width: Some(W),
        micro_grid: 8,
        micro_threshold: 0.6,
        layering: Default::default(),
        texture_format: format,
        outline_copies: false,
        outline_fringe: false,
    };
    let region = Aabb::new(DVec3::new(15.0, 1.7, -5.0), DVec3::new(25.0, 1.7, 5.0));
    let grid = CellGrid::tile(region, 10.0).unwrap();
    let job = BakeJob {
        bundle: dir.to_path_buf(),
        scene: SceneRef {
            sources: vec!["builtin:city:30k:2".into()],
            up: "y".into(),
            fingerprint: "test".into(),
            triangles: scene.triangle_count(),
        },
        params: params.clone(),
        cells: grid.cells(),
        grid,
        shard: None,
    };
    let baker = Baker::new(gpu, scene, params).unwrap();
    lemi_bake::run(&job, |c| baker.bake(c, |_| {}), |_, _, _| {}).unwrap();
    Bundle::open(dir).unwrap()
}

#[test]
fn every_texture_format_renders_without_cracks_and_close_to_the_png_bake() {
    let Some(gpu) = gpu() else { return };
    let scene = lemi_scene::builtin::build("city:30k:2").unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let materials =
        Arc::new(GpuMaterials::upload(&gpu, &scene.materials, &scene.textures).unwrap());
    let options = EvalOptions {
        set: ViewpointSet::Corners,
        random_viewpoints: 0,
        size: Some((W, H)),
        ..Default::default()
    };
    let mut png = None;
    let mut png_bundle: Option<Bundle> = None;
    for format in TextureFormat::ALL {
        let bundle = bake(&gpu, &scene, &tmp.path().join(format.name()), format);
        let id = bundle.cell_ids()[0];
        let file = bundle.cell(id).unwrap();
        let cell = ImpostorCell::upload_file(&gpu, materials.clone(), &scene, &file).unwrap();
        let resident = cell.resident_texture_bytes();
        let direct = format.block().is_some_and(|b| gpu.has_block_format(b));
        assert_eq!(cell.texture_format().is_compressed(), direct, "{format}");
        // the block formats against the PNG bake, the PNG bake against itself (a known answer)
        let other = png_bundle.as_ref().unwrap_or(&bundle);
        let run =
            evaluate_bundle_against(&gpu, &bundle, &scene, Some(other), &options, |_, _, _| {})
                .unwrap();
        let t = run.textures.as_ref().expect("a layered bundle's footprint");
        assert_eq!((t.format, t.cells), (format, 1));
        assert_eq!(
            t.texture_memory_bytes_per_cell,
            file.header.stats.texture_memory_bytes() as f64
        );
        assert_eq!(
            t.disk_bytes_per_cell,
            bundle.entry(id).unwrap().bytes as f64
        );
        let a = run
            .against
            .as_ref()
            .expect("compared against the other bake");
        eprintln!("{format}: {}", a.describe());
        assert_eq!(a.views, 9 * 8);
        assert_eq!(
            a.coverage_mismatch_pixels, 0,
            "{format}: the alpha test is exact, so no pixel's coverage changes"
        );
        if format.is_png() {
            assert_eq!((a.differing_pixels, a.psnr, a.mean_flip), (0, None, 0.0));
            png_bundle = Some(bundle.clone());
        } else {
            assert!(
                a.differing_pixels > 0,
                "{format}: a lossy format changes colours"
            );
            // within the formats' colour error: an RMS error of 8 levels (the round trips on
            // hand-built images stay within 7-12 at worst per texel) over every pixel is 30 dB
            let psnr = a.psnr.unwrap_or(f64::INFINITY);
            assert!(
                psnr >= 30.0 && a.mean_flip > 0.0 && a.mean_flip < 0.05,
                "{format}: mean FLIP {}, PSNR {psnr} against the PNG bake",
                a.mean_flip
            );
        }
        let s = run.result.summary;
        eprintln!(
            "{format}: {} bytes stored, {resident} resident ({:?}), {} views, cracks {}, mean FLIP {:.4}, PSNR {:.2}",
            file.header.stats.texture_bytes(),
            cell.texture_format(),
            s.views,
            s.crack_pixels,
            s.mean_flip,
            s.psnr
        );
        assert_eq!(s.views, 9 * 8, "centre + 8 corners, 4 axes + 4 diagonals");
        assert_eq!(
            s.crack_pixels, 0,
            "{format}: no pixel where geometry is missing"
        );
        match png {
            None => png = Some((s.mean_flip, resident)),
            Some((flip, png_resident)) => {
                // ETC1S codes a block with one base colour and shared codebooks: the smallest
                // files, about twice BC1's colour error (round trips in `basis_universal`). BC1
                // stacks thin micro-textures (docs/COMPRESSION.md, "Stacks"): a block that held
                // one band and padding (three colours for four texels) holds four bands (four
                // colours for sixteen), which costs FLIP where the bands are textured: +0.0068
                // over PNG without stacks on this cell, +0.0101 with them, at 77 % of the memory
                let bound = match format {
                    TextureFormat::Etc1s => 0.02,
                    TextureFormat::Bc1 => 0.0125,
                    _ => 0.01,
                };
                assert!(
                    (s.mean_flip - flip).abs() <= bound,
                    "{format}: mean FLIP {} against the PNG bake's {flip}",
                    s.mean_flip
                );
                if direct {
                    // BC7 1 byte a texel, BC1 half, RGBA8 4; padding every micro-texture to
                    // whole 4×4 blocks adds up to half again on small micro-textures (1.52× on a
                    // city cell, docs/COMPRESSION.md), so at most a half and a quarter
                    let (num, den) = if format.block() == Some(BlockFormat::Bc7) {
                        (1, 2)
                    } else {
                        (1, 4)
                    };
                    assert!(
                        resident * den <= png_resident * num,
                        "{format}: {resident} resident bytes against the PNG bake's {png_resident}"
                    );
                }
            }
        }
    }
}
