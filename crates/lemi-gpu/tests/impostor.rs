//! Impostor renderer tests on whatever adapter wgpu finds (Mesa's lavapipe or llvmpipe in CI):
//! quads show their macro-texels bit-exactly, rotated micro-textures sample the same image, near
//! geometry matches the reference renderer bit for bit, depth test between both, bad input.
//! Without an adapter they fail with the install hint, unless `LEMI_SKIP_GPU_TESTS=1`.

use std::sync::Arc;

use glam::DVec3;
use lemi_core::bundle::Quad;
use lemi_core::camera::Camera;
use lemi_core::compress::MacroTexture;
use lemi_core::{Face, Material, Mesh, Scene, SceneBuilder, Texture, Vertex};
use lemi_gpu::{
    Frame, Gpu, GpuError, GpuMaterials, GpuScene, ImpostorCell, ImpostorCellData, ImpostorRenderer,
    RenderOptions, Renderer, TexelFilter, UploadOptions,
};
use lemi_testkit::gpu;

/// A 64×64, 90° camera at `eye` looking along −Z: a point at view depth `d` and offset `(x, y)`
/// from the axis lands at pixel `(32 + 32·x/d, 32 − 32·y/d)`.
fn camera_at(eye: DVec3) -> Camera {
    Camera::new(eye, -DVec3::Z, DVec3::Y, 90.0, 64, 64).expect("valid camera")
}

fn camera() -> Camera {
    camera_at(DVec3::ZERO)
}

/// A quad facing the camera at `z`, spanning `[x0, x1] × [y0, y1]` (+ `offset`), corners TL, TR,
/// BR, BL as seen by [`camera`].
fn quad(
    macro_index: u32,
    layer: u16,
    rect: [u32; 4],
    [x0, x1, y0, y1, z]: [f32; 5],
    offset: [f32; 3],
) -> Quad {
    let p = |x: f32, y: f32| [x + offset[0], y + offset[1], z + offset[2]];
    Quad {
        fringe: false,
        face: Face::NegZ,
        layer,
        texels: [0, 0, rect[2] as u16, rect[3] as u16],
        corners: [p(x0, y1), p(x1, y1), p(x1, y0), p(x0, y0)],
        macro_index,
        rect,
        rotated: false,
    }
}

/// A macro-texture filled with `fill`.
fn filled(width: u32, height: u32, fill: [u8; 4]) -> MacroTexture {
    MacroTexture {
        width,
        height,
        rgba: fill.repeat((width * height) as usize),
    }
}

fn put(m: &mut MacroTexture, x: u32, y: u32, c: [u8; 4]) {
    let i = 4 * (y * m.width + x) as usize;
    m.rgba[i..i + 4].copy_from_slice(&c);
}

fn empty_scene() -> Scene {
    let mut b = SceneBuilder::new();
    b.add_material(Material::default());
    b.finish()
}

fn materials(gpu: &Gpu, scene: &Scene) -> Arc<GpuMaterials> {
    Arc::new(GpuMaterials::upload(gpu, &scene.materials, &scene.textures).expect("materials"))
}

fn quads_cell(gpu: &Gpu, quads: &[Quad], macros: &[MacroTexture]) -> ImpostorCell {
    let scene = empty_scene();
    ImpostorCell::upload(gpu, materials(gpu, &scene), &scene, &[], quads, macros)
        .expect("upload cell")
}

/// The pixel centre coordinate `i + 0.5` → position in `[lo, hi]` split into `n` equal cells:
/// the cell index, or `None` outside or within 0.02 px of a cell border (ambiguous for nearest
/// sampling).
fn cell_of(i: u32, lo: f64, hi: f64, n: u32) -> Option<u32> {
    let c = i as f64 + 0.5;
    let t = (c - lo) / (hi - lo) * n as f64;
    let px_per_cell = (hi - lo) / n as f64;
    if t <= 0.0 || t >= n as f64 || (t - t.round()).abs() * px_per_cell < 0.02 {
        return None;
    }
    Some(t.floor() as u32)
}

/// The 4×4 test image: distinct colours, texel (1, 2) transparent, (2, 1) alpha 127 (discarded),
/// (0, 0) alpha 128 (outline fringe: not drawn over the background), (3, 3) alpha 192 (drawn
/// everywhere).
fn test_image(x: u32, y: u32) -> [u8; 4] {
    let rgb = [
        (10 + 60 * x) as u8,
        (20 + 55 * y) as u8,
        (5 + 17 * x + 31 * y) as u8,
    ];
    let a = match (x, y) {
        (1, 2) => 0,
        (2, 1) => 127,
        (0, 0) => 128,
        (3, 3) => 192,
        _ => 255,
    };
    [rgb[0], rgb[1], rgb[2], a]
}

fn drawn(c: [u8; 4]) -> [u8; 4] {
    [c[0], c[1], c[2], 255]
}

/// Checks that the frame shows `image(x, y)` (a `w × h` image) over pixels `[px0, px1] × [py0,
/// py1]`, texels with alpha < 192 (transparent or outline fringe, over nothing) show `clear`;
/// returns how many pixels were checked.
fn check_image(
    f: &Frame,
    [px0, px1, py0, py1]: [f64; 4],
    (w, h): (u32, u32),
    image: impl Fn(u32, u32) -> [u8; 4],
    clear: [u8; 4],
    depth: f32,
) -> usize {
    let mut checked = 0;
    for py in 0..f.height {
        for px in 0..f.width {
            let (Some(tx), Some(ty)) = (cell_of(px, px0, px1, w), cell_of(py, py0, py1, h)) else {
                continue;
            };
            let texel = image(tx, ty);
            let got = f.pixel(px, py).unwrap_or_default();
            let d = f.depth_at(px, py).unwrap_or(0.0);
            if texel[3] >= 192 {
                assert_eq!(got, drawn(texel), "pixel {px},{py} = texel {tx},{ty}");
                assert!(
                    ((d - depth) / depth).abs() < 1e-3,
                    "depth {d} at {px},{py}, expected {depth}"
                );
            } else {
                assert_eq!(got, clear, "transparent texel {tx},{ty} at pixel {px},{py}");
                assert_eq!(d, f32::INFINITY);
            }
            checked += 1;
        }
    }
    checked
}

#[test]
fn quad_shows_its_texels_exactly() {
    let Some(gpu) = gpu() else { return };
    eprintln!("adapter: {}", gpu.describe());
    // The 4x4 image sits at (2, 3) in an 8x8 macro-texture filled with another colour.
    let mut m = filled(8, 8, [255, 0, 255, 255]);
    for y in 0..4 {
        for x in 0..4 {
            put(&mut m, 2 + x, 3 + y, test_image(x, y));
        }
    }
    // [-2, 2]² at distance 5: pixels 19.2 ..= 44.8, 6.4 px per texel.
    let q = quad(0, 0, [2, 3, 4, 4], [-2.0, 2.0, -2.0, 2.0, -5.0], [0.0; 3]);
    let cell = quads_cell(&gpu, &[q], &[m]);
    assert_eq!(cell.quad_count(), 1);
    assert_eq!(cell.near_triangles(), 0);
    assert_eq!(cell.texture_bytes(), 8 * 8 * 4);
    // the quad, and the piece of it around its fringe texel (0, 0) for the fringe pass
    assert_eq!(cell.quad_draw_calls(), 2);
    let r = ImpostorRenderer::new(&gpu).expect("renderer");
    let clear = [7, 8, 9, 10];
    let opts = RenderOptions {
        clear,
        ..Default::default()
    };
    let f = r
        .render(&cell, &camera().view(), &opts)
        .expect("render impostors");
    let area = [19.2, 44.8, 19.2, 44.8];
    let checked = check_image(&f, area, (4, 4), test_image, clear, 5.0);
    assert!(checked > 400, "checked {checked} pixels");
    // The quad is grown by a sixteenth of a texel, but never shows the macro-texture around its
    // rectangle (magenta here): the fetch is clamped to the rectangle.
    assert!(
        f.rgba.chunks_exact(4).all(|p| p != [255, 0, 255, 255]),
        "a neighbouring macro-texel leaked into the quad"
    );
    // Outside the quad: background.
    for (x, y) in [(0, 0), (18, 32), (45, 32), (32, 18), (32, 45), (63, 63)] {
        assert_eq!(f.pixel(x, y), Some(clear), "background at {x},{y}");
        assert_eq!(f.depth_at(x, y), Some(f32::INFINITY));
    }
    // 26 x 26 pixels, minus the transparent, alpha-127 and fringe texels.
    let hidden = f.rgba.chunks_exact(4).filter(|p| *p == clear).count();
    assert_eq!(f.covered_count() + hidden, 64 * 64);
    assert!(f.covered_count() < 26 * 26 - 2 * 36 && f.covered_count() > 26 * 26 - 3 * 49);
    // Same image from render_impostors_only (there is no near geometry) and on a second call.
    let g = r
        .render_impostors_only(&cell, &camera().view(), &opts)
        .expect("render impostors only");
    assert_eq!(f, g);
}

/// The cell of `quads` over `macros` with its macro-textures as RGBA8 and, where the adapter
/// samples them, encoded to BC1 and to BC7 and uploaded as such (a format it cannot sample is
/// printed as skipped).
fn cells_in_formats(
    gpu: &Gpu,
    quads: &[Quad],
    macros: &[MacroTexture],
) -> Vec<(&'static str, ImpostorCell)> {
    use lemi_core::bundle::BlockMacro;
    use lemi_core::compress::BlockFormat;
    let scene = empty_scene();
    let mut cells = vec![("RGBA8", quads_cell(gpu, quads, macros))];
    for (name, format) in [("BC1", BlockFormat::Bc1), ("BC7", BlockFormat::Bc7)] {
        if !gpu.has_block_format(format) {
            eprintln!("SKIPPED the {name} case: this adapter does not sample {name}");
            continue;
        }
        let blocks = macros
            .iter()
            .map(|m| BlockMacro::encode(format, m).expect("encode"))
            .collect();
        let data = ImpostorCellData::prepare(&scene, &[], quads, macros.to_vec())
            .expect("prepare")
            .with_blocks(blocks)
            .expect("blocks");
        let mut pending =
            ImpostorCell::begin_upload(gpu, materials(gpu, &scene), data).expect("begin upload");
        pending.upload_step(gpu, u64::MAX).expect("upload");
        cells.push((name, pending.finish().expect("finish")));
    }
    cells
}

/// A frame chooses nearest texels for a draw call only where every texel of it spans two pixels
/// or more, where the footprint filter takes the texel under each pixel's centre anyway: the
/// frames with and without that choice are identical, and the choice is made where it can be.
#[test]
fn draws_of_magnified_quads_take_nearest_texels_with_the_same_pixels() {
    let Some(gpu) = gpu() else { return };
    let scene = empty_scene();
    let mats = materials(&gpu, &scene);
    let r = ImpostorRenderer::new(&gpu).expect("renderer");
    assert_eq!(r.texel_filter(), TexelFilter::Footprint);
    let opts = RenderOptions::default();
    let view = camera().view();
    // A checkerboard of n×n texels on [-1, 1]² at distance 2 (32 px across), seen from the
    // origin: n/32 texels a pixel at the centre, about 1.5 times that at the corners (the
    // bound: n/32 · 1.5). At n = 10 (0.31 .. 0.47) no pixel is filtered; at n = 24 (0.75 ..)
    // every one is, and the checkerboard turns grey where the nearest texel would not.
    for (n, nearest_expected) in [(10u32, true), (24, false)] {
        let mut m = filled(n, n, [0, 0, 0, 255]);
        for y in 0..n {
            for x in 0..n {
                if (x + y) % 2 == 0 {
                    put(&mut m, x, y, [255, 255, 255, 255]);
                }
            }
        }
        let q = quad(0, 0, [0, 0, n, n], [-1.0, 1.0, -1.0, 1.0, -2.0], [0.0; 3]);
        let cell = |seen_from: Option<lemi_gpu::SeenFrom>| {
            let data = ImpostorCellData::prepare_for(
                &scene,
                &[],
                std::slice::from_ref(&q),
                vec![m.clone()],
                8192,
                seen_from,
            )
            .expect("prepare");
            let mut pending = ImpostorCell::begin_upload(&gpu, mats.clone(), data).expect("begin");
            pending.upload_step(&gpu, u64::MAX).expect("upload");
            pending.finish().expect("finish")
        };
        let seen_from = lemi_gpu::SeenFrom {
            origin: DVec3::ZERO,
            reach: 0.0,
        };
        let (bounded, unbounded) = (cell(Some(seen_from)), cell(None));
        let chosen = r.render(&bounded, &view, &opts).expect("render");
        assert_eq!(
            r.last_quad_draws(),
            (1, u32::from(nearest_expected)),
            "n = {n}"
        );
        let filtered = r.render(&unbounded, &view, &opts).expect("render");
        assert_eq!(r.last_quad_draws(), (1, 0), "no origin, no bound: n = {n}");
        assert_eq!(
            chosen.rgba, filtered.rgba,
            "n = {n}: the choice changed pixels"
        );
        assert_eq!(chosen.depth, filtered.depth, "n = {n}");
        // the footprint filter does change this picture where texels are smaller than two
        // pixels: the test would see a wrong choice
        let mut nearest = ImpostorRenderer::new(&gpu).expect("renderer");
        nearest.set_texel_filter(TexelFilter::Nearest);
        let plain = nearest.render(&unbounded, &view, &opts).expect("render");
        assert_eq!(
            plain.rgba == filtered.rgba,
            nearest_expected,
            "n = {n}: nearest and filtered frames"
        );
    }
}

/// A 1-texel black and white checkerboard with a transparent square hole, shown minified (4
/// texels per pixel) and magnified (¼ texel per pixel), in each texture format. Minified, nearest
/// sampling shows every pixel black or white (the skipped texels are what makes a far field
/// shimmer as the viewer moves); the footprint filter shows the checkerboard's mean, mid grey in
/// linear light, and no colour of the hole's transparent texels. Both cover exactly the same
/// pixels, and magnified they draw the same image bit for bit.
#[test]
fn minified_quads_filter_their_footprint_and_keep_coverage() {
    let Some(gpu) = gpu() else { return };
    let side = 128;
    let mut m = filled(side, side, [0, 0, 0, 255]);
    for y in 0..side {
        for x in 0..side {
            let hole = (39..89).contains(&x) && (39..89).contains(&y);
            let white = (x + y) % 2 == 0;
            let c = if white {
                [255, 255, 255, 255]
            } else {
                [0, 0, 0, 255]
            };
            put(&mut m, x, y, if hole { [255, 0, 0, 0] } else { c });
        }
    }
    // [-1, 1]² at distance 2: pixels 16 ..= 48, 32 px for 128 texels (4 texels a pixel).
    let far = quad(
        0,
        0,
        [0, 0, side, side],
        [-1.0, 1.0, -1.0, 1.0, -2.0],
        [0.0; 3],
    );
    let near_quad = quad(0, 0, [0, 0, 16, 16], [-1.0, 1.0, -1.0, 1.0, -2.0], [0.0; 3]);
    let mut r = ImpostorRenderer::new(&gpu).expect("renderer");
    assert_eq!(r.texel_filter(), TexelFilter::Footprint, "the default");
    let opts = RenderOptions::default();
    let view = camera().view();
    for (format, cell) in cells_in_formats(&gpu, &[far], std::slice::from_ref(&m)) {
        r.set_texel_filter(TexelFilter::Footprint);
        let filtered = r.render(&cell, &view, &opts).expect("render");
        r.set_texel_filter(TexelFilter::Nearest);
        let nearest = r.render(&cell, &view, &opts).expect("render");
        // the same pixels covered, at the same depths
        assert_eq!(
            filtered.depth, nearest.depth,
            "{format}: coverage and depth must not change"
        );
        assert!(
            filtered.covered_count() > 32 * 32 - 12 * 12 - 2 * 32 * 2,
            "{format}: {}",
            filtered.covered_count()
        );
        // away from the quad's rim and the hole's, every pixel is the checkerboard's mean
        // (½ in linear light: sRGB 188) when filtered, black or white when not
        let (mut greys, mut extremes) = (0, 0);
        for py in 18..46u32 {
            for px in 18..46u32 {
                let in_hole_zone = (24..41).contains(&px) && (24..41).contains(&py);
                if in_hole_zone {
                    continue;
                }
                let f = filtered.pixel(px, py).expect("pixel");
                let n = nearest.pixel(px, py).expect("pixel");
                assert!(
                    f[..3].iter().all(|&c| (186..=190).contains(&c)),
                    "{format}: filtered pixel {px},{py} = {f:?}, expected mid grey"
                );
                greys += 1;
                assert!(
                    n[..3] == [0, 0, 0] || n[..3] == [255, 255, 255],
                    "{format}: nearest pixel {px},{py} = {n:?}"
                );
                extremes += 1;
            }
        }
        assert!(
            greys > 400 && extremes == greys,
            "{format}: {greys} {extremes}"
        );
        // next to the hole no colour of the clear texels comes in, nor does their black darken
        // the opaque texels' mean where they are transparent black (RGBA8, BC1): the opaque
        // texels a pixel beside the hole mixes are half white (sRGB 188), at its corners 3 to 4
        // in 7 (175 to 198); taking the clear ones as black makes the pixels beside it 165
        // (the hole starts at texel 39, off the pixels' 4-texel grid, so its edge cuts fetches)
        for py in 16..48u32 {
            for px in 16..48u32 {
                if let Some(p) = filtered.pixel(px, py).filter(|p| p[3] == 255) {
                    assert!(
                        p[0].abs_diff(p[1]) <= 1,
                        "{format}: pixel {px},{py} = {p:?} shows a clear texel's colour"
                    );
                    if format != "BC7" {
                        assert!(
                            p[0] >= 172,
                            "{format}: pixel {px},{py} = {p:?} is darkened by clear texels"
                        );
                    }
                }
            }
        }
        // magnified: the footprint filter is nearest sampling, bit for bit
        let cells = cells_in_formats(&gpu, &[near_quad], std::slice::from_ref(&m));
        let Some((_, cell)) = cells.iter().find(|(f, _)| *f == format) else {
            panic!("{format}: no magnified cell");
        };
        r.set_texel_filter(TexelFilter::Nearest);
        let nearest = r.render(cell, &view, &opts).expect("render");
        r.set_texel_filter(TexelFilter::Footprint);
        let filtered = r.render(cell, &view, &opts).expect("render");
        assert!(
            filtered == nearest,
            "{format}: a magnified quad must not change"
        );
    }
}

/// A cell's macro-textures are packed at upload into atlas pages; a quad finds its texels there
/// through its macro-texture's offset. Spread over many small pages (each at most 32 texels a
/// side: two here) the same quads render exactly as from one page, in more draw calls (one per face, kind
/// and page), and each page holds only what it needs.
#[test]
fn quads_render_the_same_from_one_atlas_page_or_many() {
    let Some(gpu) = gpu() else { return };
    // Four macro-textures of distinct patterns and sizes; a quad on each, at its own depth (no
    // two quads at equal depth, so the draw order decides no pixel).
    let sizes = [(13u32, 9u32), (32, 16), (9, 21), (16, 32)];
    let macros: Vec<MacroTexture> = (sizes.iter().enumerate())
        .map(|(k, &(w, h))| {
            let mut m = filled(w, h, [0, 0, 0, 255]);
            for y in 0..h {
                for x in 0..w {
                    let a = if (x + 2 * y + k as u32) % 11 == 0 {
                        0
                    } else {
                        255
                    };
                    put(
                        &mut m,
                        x,
                        y,
                        [(40 * k as u32 + 7 * x) as u8, (9 * y) as u8, 200, a],
                    );
                }
            }
            m
        })
        .collect();
    let quads: Vec<Quad> = (sizes.iter().enumerate())
        .map(|(k, &(w, h))| {
            let (x0, y0) = (-3.0 + 3.0 * (k % 2) as f32, -3.0 + 3.0 * (k / 2) as f32);
            let z = -5.0 - k as f32;
            quad(
                k as u32,
                k as u16,
                [0, 0, w, h],
                [x0, x0 + 2.9, y0, y0 + 2.9, z],
                [0.0; 3],
            )
        })
        .collect();
    let scene = empty_scene();
    let mats = materials(&gpu, &scene);
    let upload = |side: u32| {
        let data = ImpostorCellData::prepare_for(&scene, &[], &quads, macros.clone(), side, None)
            .expect("prepare");
        let mut pending = ImpostorCell::begin_upload(&gpu, mats.clone(), data).expect("begin");
        while !pending.upload_step(&gpu, 256).expect("upload step") {}
        pending.finish().expect("finish")
    };
    let (one, many) = (upload(8192), upload(32));
    assert_eq!(one.atlas_pages(), 1);
    assert_eq!(many.atlas_pages(), 2);
    assert!(many.quad_draw_calls() > one.quad_draw_calls());
    let data: u64 = macros.iter().map(|m| m.rgba.len() as u64).sum();
    for c in [&one, &many] {
        assert_eq!(c.texture_bytes(), data);
        assert!(c.resident_texture_bytes() >= data);
    }
    // the gaps of the packing stay below the data itself
    assert!(
        one.resident_texture_bytes() <= 2 * data,
        "{}",
        one.resident_texture_bytes()
    );
    let r = ImpostorRenderer::new(&gpu).expect("renderer");
    let opts = RenderOptions::default();
    let view = camera().view();
    let (a, b) = (
        r.render(&one, &view, &opts).expect("render one page"),
        r.render(&many, &view, &opts).expect("render many pages"),
    );
    assert!(a.covered_count() > 600, "{}", a.covered_count());
    assert!(a == b, "the cell renders differently from many atlas pages");
}

#[test]
fn quads_far_from_the_origin_stay_put() {
    let Some(gpu) = gpu() else { return };
    let mut m = filled(4, 4, [0; 4]);
    for y in 0..4 {
        for x in 0..4 {
            put(&mut m, x, y, test_image(x, y));
        }
    }
    let offset = [12_288.37, 512.61, -20_480.29];
    let q = quad(0, 0, [0, 0, 4, 4], [-2.0, 2.0, -2.0, 2.0, -5.0], offset);
    let cell = quads_cell(&gpu, &[q], &[m]);
    let eye = DVec3::new(offset[0] as f64, offset[1] as f64, offset[2] as f64);
    let f = ImpostorRenderer::new(&gpu)
        .and_then(|r| {
            r.render_impostors_only(&cell, &camera_at(eye).view(), &RenderOptions::default())
        })
        .expect("render");
    let checked = check_image(
        &f,
        [19.2, 44.8, 19.2, 44.8],
        (4, 4),
        test_image,
        [0; 4],
        5.0,
    );
    assert!(checked > 400);
}

#[test]
fn rotated_quad_samples_the_same_image() {
    let Some(gpu) = gpu() else { return };
    // A 3 x 5 micro-texture (w x h).
    let (w, h) = (3u32, 5u32);
    let micro = |x: u32, y: u32| [(20 + 70 * x) as u8, (15 + 45 * y) as u8, 99, 255];
    // Unrotated at (1, 2) in an 8x8 macro; rotated (footprint 5 x 3) at (2, 4) in another:
    // micro texel (x, y) lands at (h - 1 - y, x).
    let mut plain = filled(8, 8, [0, 0, 0, 255]);
    let mut turned = filled(8, 8, [255, 255, 255, 255]);
    for y in 0..h {
        for x in 0..w {
            put(&mut plain, 1 + x, 2 + y, micro(x, y));
            put(&mut turned, 2 + (h - 1 - y), 4 + x, micro(x, y));
        }
    }
    // x in [-1.5, 1.5], y in [-2.5, 2.5] at 5: pixels 22.4..41.6 by 16..48, 6.4 px per texel.
    let extent = [-1.5, 1.5, -2.5, 2.5, -5.0];
    let q_plain = quad(0, 0, [1, 2, w, h], extent, [0.0; 3]);
    let q_turned = Quad {
        macro_index: 1,
        rect: [2, 4, h, w],
        rotated: true,
        ..q_plain
    };
    let r = ImpostorRenderer::new(&gpu).expect("renderer");
    let opts = RenderOptions::default();
    let view = camera().view();
    let a = r
        .render(&quads_cell(&gpu, &[q_plain], &[plain]), &view, &opts)
        .expect("render plain");
    // The rotated one as macro 1 of two, to exercise the macro index too.
    let b = r
        .render(
            &quads_cell(&gpu, &[q_turned], &[filled(2, 2, [1; 4]), turned]),
            &view,
            &opts,
        )
        .expect("render rotated");
    let checked = check_image(&a, [22.4, 41.6, 16.0, 48.0], (w, h), micro, [0; 4], 5.0);
    assert!(checked > 400, "checked {checked}");
    assert_eq!(a.covered_count(), b.covered_count());
    assert!(a == b, "the rotated quad renders differently");
}

fn tri(p: [[f32; 3]; 3], color: [u8; 4]) -> [Vertex; 3] {
    // A tilted normal so that the lighting is not trivial.
    p.map(|p| Vertex::new(p, [0.3, 0.5, 0.81], [p[0], p[1]], color))
}

/// Mesh 0 (material 0, textured): triangles 0 (left) and 1 (right); mesh 1 (material 1): one
/// triangle at the bottom. No two overlap on screen.
fn two_triangle_scene() -> Scene {
    let mut b = SceneBuilder::new();
    let mut rgba = Vec::new();
    for i in 0..16u32 {
        rgba.extend_from_slice(&[(i * 16) as u8, (255 - i * 13) as u8, 128, 255]);
    }
    let t = b.add_texture(Texture {
        name: "ramp".into(),
        width: 4,
        height: 4,
        rgba8: rgba,
    });
    b.add_material(Material {
        name: "textured".into(),
        base_color: [0.9, 0.7, 0.5, 1.0],
        texture: Some(t),
    });
    b.add_material(Material {
        name: "blue".into(),
        base_color: [0.1, 0.2, 0.9, 1.0],
        texture: None,
    });
    let left = tri(
        [[-3.0, -1.0, -5.0], [-0.5, -1.0, -6.0], [-2.0, 3.0, -4.0]],
        [255, 200, 180, 255],
    );
    let right = tri(
        [[0.5, -1.0, -5.5], [3.0, -0.5, -5.0], [1.5, 3.0, -7.0]],
        [200, 255, 220, 255],
    );
    let bottom = tri(
        [[-2.0, -4.0, -5.0], [2.0, -4.0, -5.0], [0.0, -1.5, -5.0]],
        [255; 4],
    );
    let mut m0: Vec<Vertex> = left.to_vec();
    m0.extend_from_slice(&right);
    b.add_mesh(Mesh {
        material: 0,
        vertices: m0,
        indices: vec![0, 1, 2, 3, 4, 5],
    });
    b.add_mesh(Mesh {
        material: 1,
        vertices: bottom.to_vec(),
        indices: vec![0, 1, 2],
    });
    b.finish()
}

#[test]
fn near_geometry_matches_the_reference_renderer() {
    let Some(gpu) = gpu() else { return };
    let scene = two_triangle_scene();
    let mats = materials(&gpu, &scene);
    let view = camera().view();
    let opts = RenderOptions::default();
    let reference = Renderer::new(&gpu)
        .and_then(|r| {
            let gs = GpuScene::upload(&gpu, &scene, &UploadOptions::default())?;
            r.render(&gs, &view, &opts)
        })
        .expect("reference render");
    let r = ImpostorRenderer::new(&gpu).expect("renderer");
    for near in [vec![[0u32, 1u32]], vec![[0, 1], [1, 0]]] {
        let cell =
            ImpostorCell::upload(&gpu, mats.clone(), &scene, &near, &[], &[]).expect("upload cell");
        assert_eq!(cell.near_triangles(), near.len() as u64);
        assert_eq!(cell.quad_count(), 0);
        let f = r.render(&cell, &view, &opts).expect("render");
        let mut same = 0;
        for y in 0..64 {
            for x in 0..64 {
                let got = (f.pixel(x, y), f.depth_at(x, y));
                let want = (reference.pixel(x, y), reference.depth_at(x, y));
                let left_half = x < 32 && y < 40; // where triangle (0, 0) is
                if got.1.is_some_and(f32::is_finite) {
                    assert_eq!(got.0, want.0, "pixel {x},{y} differs from the reference");
                    assert_eq!(
                        got.1.map(f32::to_bits),
                        want.1.map(f32::to_bits),
                        "depth {x},{y}"
                    );
                    assert!(!left_half, "triangle (0, 0) is not in the near list");
                    same += 1;
                } else if want.1.is_some_and(f32::is_finite) {
                    // Only triangle (0, 0), and (1, 0) when not listed, are missing.
                    assert!(
                        left_half || (near.len() == 1 && y >= 40),
                        "missing pixel {x},{y}"
                    );
                }
            }
        }
        assert!(same > 100, "{same} pixels compared");
        // Without near geometry nothing is drawn.
        let empty = r
            .render_impostors_only(&cell, &view, &opts)
            .expect("render impostors only");
        assert_eq!(empty.covered_count(), 0);
    }
}

#[test]
fn near_geometry_and_quads_hide_each_other() {
    let Some(gpu) = gpu() else { return };
    let red = [220, 30, 40, 255];
    let m = filled(4, 4, red);
    let r = ImpostorRenderer::new(&gpu).expect("renderer");
    let opts = RenderOptions::default();
    let view = camera().view();
    // A small triangle around the view axis at `tz`, a big quad at `qz`.
    let run = |tz: f32, qz: f32| -> Frame {
        let mut b = SceneBuilder::new();
        b.add_material(Material {
            name: "white".into(),
            base_color: [1.0; 4],
            texture: None,
        });
        b.add_mesh(Mesh {
            material: 0,
            vertices: tri(
                [[-1.0, -1.0, tz], [1.0, -1.0, tz], [0.0, 1.0, tz]],
                [255; 4],
            )
            .to_vec(),
            indices: vec![0, 1, 2],
        });
        let scene = b.finish();
        let q = quad(0, 0, [0, 0, 4, 4], [-4.0, 4.0, -4.0, 4.0, qz], [0.0; 3]);
        let cell = ImpostorCell::upload(
            &gpu,
            materials(&gpu, &scene),
            &scene,
            &[[0, 0]],
            &[q],
            std::slice::from_ref(&m),
        )
        .expect("upload");
        r.render(&cell, &view, &opts).expect("render")
    };
    // Triangle in front: the centre is the triangle, the rim the quad.
    let f = run(-3.0, -6.0);
    let centre = f.pixel(32, 32).unwrap_or_default();
    assert_ne!(centre, red);
    assert!((f.depth_at(32, 32).unwrap_or(0.0) - 3.0).abs() < 1e-3);
    assert_eq!(f.pixel(32, 14), Some(red));
    assert!((f.depth_at(32, 14).unwrap_or(0.0) - 6.0).abs() < 1e-3);
    // Quad in front: red everywhere it covers, at its depth.
    let g = run(-6.0, -3.0);
    assert_eq!(g.pixel(32, 32), Some(red));
    assert!((g.depth_at(32, 32).unwrap_or(0.0) - 3.0).abs() < 1e-3);
    assert!(g
        .rgba
        .chunks_exact(4)
        .all(|p| p == red || p == [0, 0, 0, 0]));
    // Quads among themselves: the nearer wins whatever the layer order says.
    let green = [30, 200, 60, 255];
    let mut two = filled(8, 4, red);
    for y in 0..4 {
        for x in 4..8 {
            put(&mut two, x, y, green);
        }
    }
    for (near_layer, far_layer) in [(1, 0), (0, 1)] {
        let near_q = quad(
            0,
            near_layer,
            [4, 0, 4, 4],
            [-1.0, 1.0, -1.0, 1.0, -3.0],
            [0.0; 3],
        );
        let far_q = quad(
            0,
            far_layer,
            [0, 0, 4, 4],
            [-4.0, 4.0, -4.0, 4.0, -6.0],
            [0.0; 3],
        );
        let cell = quads_cell(&gpu, &[far_q, near_q], std::slice::from_ref(&two));
        let f = r.render(&cell, &view, &opts).expect("render");
        assert_eq!(f.pixel(32, 32), Some(green));
        assert_eq!(f.pixel(32, 14), Some(red));
    }
}

#[test]
fn bad_input_is_an_error() {
    let Some(gpu) = gpu() else { return };
    let scene = two_triangle_scene();
    let mats = materials(&gpu, &scene);
    let m = filled(8, 8, [255; 4]);
    let ok_quad = quad(0, 0, [0, 0, 8, 8], [-1.0, 1.0, -1.0, 1.0, -5.0], [0.0; 3]);
    let upload = |near: &[[u32; 2]], quads: &[Quad], macros: &[MacroTexture]| {
        ImpostorCell::upload(&gpu, mats.clone(), &scene, near, quads, macros)
    };
    assert!(upload(&[[0, 1], [1, 0]], &[ok_quad], std::slice::from_ref(&m)).is_ok());
    let invalid = |r: Result<ImpostorCell, GpuError>, needle: &str| match r {
        Err(GpuError::Invalid(msg)) => assert!(msg.contains(needle), "{msg} lacks {needle}"),
        Err(e) => panic!("expected Invalid containing {needle}, got {e}"),
        Ok(_) => panic!("expected Invalid containing {needle}, got Ok"),
    };
    // the near list's errors are the scene's typed extraction errors, with the same messages
    let bad_near = |r: Result<ImpostorCell, GpuError>, needle: &str| match r {
        Err(GpuError::Extract(e)) => {
            let msg = e.to_string();
            assert!(msg.contains(needle), "{msg} lacks {needle}");
            assert_eq!(GpuError::Extract(e).to_string(), msg);
        }
        Err(e) => panic!("expected a near list error containing {needle}, got {e}"),
        Ok(_) => panic!("expected a near list error containing {needle}, got Ok"),
    };
    let ms = std::slice::from_ref(&m);
    bad_near(upload(&[[0, 0], [2, 0]], &[], &[]), "mesh 2, triangle 0");
    bad_near(upload(&[[1, 1]], &[], &[]), "mesh 1, triangle 1");
    bad_near(upload(&[[u32::MAX, u32::MAX]], &[], &[]), "4294967295");
    let q = Quad {
        macro_index: 1,
        ..ok_quad
    };
    invalid(upload(&[], &[q], ms), "macro-texture 1");
    invalid(upload(&[], &[ok_quad], &[]), "macro-texture 0");
    for rect in [
        [1, 0, 8, 8],
        [0, 4, 8, 5],
        [u32::MAX, 0, 1, 1],
        [0, 0, 0, 1],
    ] {
        let q = Quad { rect, ..ok_quad };
        invalid(upload(&[], &[q], ms), "rectangle");
    }
    let mut q = ok_quad;
    q.corners[2][1] = f32::NAN;
    invalid(upload(&[], &[q], ms), "non-finite");
    let short = MacroTexture {
        width: 8,
        height: 8,
        rgba: vec![0; 10],
    };
    invalid(upload(&[], &[ok_quad], &[short]), "bytes");
    let zero = MacroTexture {
        width: 0,
        height: 8,
        rgba: Vec::new(),
    };
    invalid(upload(&[], &[], &[zero]), "macro-texture 0");
    // A near list naming a mesh whose material was not uploaded.
    let few = Arc::new(GpuMaterials::upload(&gpu, &scene.materials[1..], &[]).expect("one"));
    assert!(ImpostorCell::upload(&gpu, few, &scene, &[[1, 0]], &[], &[]).is_err());
}

/// Outline fringe texels (alpha between the two alpha tests) are drawn only over a pixel where
/// something was drawn before them: over a farther quad they show (with their own colour and
/// depth), over the background they do not. In RGBA8 and BC7, which keep the third alpha level;
/// BC1's one-bit alpha loses the mark, and its fringe is drawn everywhere, as conservative
/// recording made it.
#[test]
fn fringe_texels_show_only_over_something_drawn() {
    let Some(gpu) = gpu() else { return };
    let back_colour = [0, 255, 0, 255];
    let fringe = [255, 0, 0, lemi_core::compress::FRINGE_ALPHA];
    // the back quad: [-8, 0] × [-8, 8] at distance 8, the left half of the view
    let mut macros = vec![filled(4, 4, back_colour)];
    // the front quad: 8×4 texels on [-2, 2] × [-1, 1] at distance 5 (pixels 19.2 ..= 44.8
    // across, 3.2 px a texel), all fringe but one fully opaque texel column at its right edge
    let mut front = filled(8, 4, fringe);
    for y in 0..4 {
        put(&mut front, 7, y, [0, 0, 255, 255]);
    }
    macros.push(front);
    let quads = [
        quad(0, 0, [0, 0, 4, 4], [-8.0, 0.0, -8.0, 8.0, -8.0], [0.0; 3]),
        quad(1, 1, [0, 0, 8, 4], [-2.0, 2.0, -1.0, 1.0, -5.0], [0.0; 3]),
    ];
    let r = ImpostorRenderer::new(&gpu).expect("renderer");
    let clear = [7, 8, 9, 10];
    let opts = RenderOptions {
        clear,
        ..Default::default()
    };
    for (name, cell) in cells_in_formats(&gpu, &quads, &macros) {
        let f = r.render(&cell, &camera().view(), &opts).expect("render");
        let keeps_mark = name != "BC1";
        // over the back quad (x < 32): the fringe, at the front quad's depth
        for x in [22, 26, 29] {
            let got = f.pixel(x, 32).unwrap_or_default();
            assert_eq!(
                got,
                drawn(fringe),
                "{name}: fringe over the back quad at {x}"
            );
            let d = f.depth_at(x, 32).unwrap_or(0.0);
            assert!((d - 5.0).abs() < 1e-3, "{name}: depth {d} at {x}");
        }
        // over the background (32 ≤ x < 41.6): nothing, unless the format lost the mark
        for x in [34, 37, 40] {
            let got = f.pixel(x, 32).unwrap_or_default();
            if keeps_mark {
                assert_eq!(got, clear, "{name}: fringe over the background at {x}");
                assert_eq!(f.depth_at(x, 32), Some(f32::INFINITY));
            } else {
                assert_eq!(got, drawn(fringe), "{name}: BC1 draws the fringe at {x}");
            }
        }
        // the opaque column over the background is drawn in every format
        let d = f.depth_at(43, 32).unwrap_or(0.0);
        assert!(
            (d - 5.0).abs() < 1e-3,
            "{name}: the opaque column, depth {d}"
        );
        // the back quad beside the front one, and the background beyond both
        assert_eq!(f.pixel(10, 32), Some(back_colour), "{name}");
        assert_eq!(f.pixel(50, 32), Some(clear), "{name}");
        // the fringe pass draws again only the draw calls with fringe texels
        assert_eq!(
            r.last_quad_draws().0,
            3,
            "{name}: two draw calls and one fringe draw"
        );
    }
}
