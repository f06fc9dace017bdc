//! The web viewer in a real browser: `lemi serve BUNDLE` exports a small bake and serves the
//! viewer; Debian's Chromium, headless with SwiftShader's software WebGL (driven by
//! `web/tools/browser.mjs` through playwright-core), loads it at fixed cameras inside a cell and
//! takes a screenshot; `lemi render BUNDLE` renders the same cameras. The two must cover the same
//! pixels (≥ 99 % agreement) and look alike (mean FLIP below [`FLIP_BOUND`]). Also: the viewer's
//! port of the prediction rule lists the cells the runtime's does, in the same order; a BC1 bake
//! served with its KTX2 textures shows the same picture from the blocks as stored.
//!
//! Skips, with the reason printed, where node, the node packages (`npm ci` in `web/`) or the
//! browser are missing or the browser cannot start.

mod common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};

use common::{lemi, stderr, tmp};
use lemi_gpu::Frame;

/// The mean FLIP the browser's picture may differ by from lemi's own (at the view's pixels per
/// degree). The viewer draws what the runtime draws (the same texels unfiltered, the same alpha
/// test and 1/16-texel quad growth, the same shading formula for the near geometry), so only what
/// two rasterizers may do differently remains: the 8-bit rounding of the shaded near geometry
/// (lemi encodes sRGB in the render target, the page in its shader: about a third of the near
/// geometry's pixels differ by one step), pixel centres on triangle edges (SwiftShader and
/// lavapipe share no tie rule) and f32 rounding of interpolated texel coordinates (a texel
/// boundary crossing a pixel centre). Measured over the three views: 0.013–0.019, 70–90 % of it
/// from the one-step differences on the ground. Lemi against itself gives 0; lemi against itself
/// with the camera turned by 0.11° (one pixel) gives 0.057, as would a wrong texel, layer or
/// colour space, which move whole regions. The bound lies between the two.
const FLIP_BOUND: f32 = 0.03;

/// Two cells of the builtin city (the export tests' small bundle).
const SMALL: [&str; 11] = [
    "builtin:city:20k:3",
    "--region",
    "15,1.7,-5,35,1.7,5",
    "--cell-size",
    "10",
    "--resolution",
    "128",
    "--layers",
    "4",
    "--alpha-deg",
    "0.5",
];

/// `web/` with its node packages, node itself and the browser; `None` after a visible skip.
fn browser_tools() -> Option<PathBuf> {
    let web = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../web");
    if Command::new("node").arg("--version").output().is_err() {
        lemi_testkit::skip("node is not installed (.ci/run installs it)");
        return None;
    }
    for package in ["playwright-core", "three"] {
        if !web.join("node_modules").join(package).is_dir() {
            lemi_testkit::skip(&format!(
                "{}/node_modules/{package} missing (run `npm ci` in web/, as .ci/run does)",
                web.display()
            ));
            return None;
        }
    }
    let chromium = std::env::var("LEMI_CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    if !Path::new(&chromium).is_file() {
        lemi_testkit::skip(&format!(
            "{chromium} not found (apt-get install chromium, as .ci/run does)"
        ));
        return None;
    }
    Some(web)
}

/// `lemi serve` running; killed when dropped.
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `lemi serve ARGS --port 0` and returns it with the URL it prints.
fn serve(args: &[&str]) -> (Server, String) {
    let mut all: Vec<String> = vec!["serve".into()];
    all.extend(args.iter().map(|s| s.to_string()));
    all.extend(["--port".into(), "0".into()]);
    let mut child = common::spawn_lemi(&all);
    let stdout = child.stdout.take().unwrap();
    let mut line = String::new();
    BufReader::new(stdout).read_line(&mut line).unwrap();
    let server = Server(child);
    assert!(line.starts_with("http://"), "lemi serve printed `{line}`");
    (server, line.trim().to_string())
}

/// Runs the browser driver; `None` (after a visible skip) when the browser cannot start, else
/// whether the viewer succeeded and what the driver printed.
fn browser_run(web: &Path, url: &str, extra: &[&str]) -> Option<(bool, serde_json::Value)> {
    let o = Command::new("node")
        .arg(web.join("tools/browser.mjs"))
        .arg(url)
        .args(extra)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    let v: serde_json::Value = serde_json::from_str(text.trim())
        .unwrap_or_else(|e| panic!("browser.mjs printed `{text}` ({e}); stderr: {}", stderr(&o)));
    if o.status.code() == Some(3) {
        lemi_testkit::skip(&format!("{}", v["error"]));
        return None;
    }
    Some((o.status.success(), v))
}

/// Runs the browser driver; `None` (after a visible skip) when the browser cannot start.
fn browser(web: &Path, url: &str, extra: &[&str]) -> Option<serde_json::Value> {
    let (ok, v) = browser_run(web, url, extra)?;
    assert!(ok, "the viewer failed: {v}");
    Some(v)
}

/// Coverage agreement and mean FLIP of the browser's screenshot `shot` against lemi's render
/// `reference` of the same `w`×`h` view with vertical fov `fov_y` (degrees).
fn agreement(reference: &Path, shot: &Path, w: u32, h: u32, fov_y: f64) -> (f64, f32, String) {
    let (r, t) = (frame(reference), frame(shot));
    let c = lemi_eval::image_metrics::coverage(&r, &t).unwrap();
    let n = (w * h) as f64;
    let differing = (c.reference_covered - c.both) + (c.test_covered - c.both);
    let agreement = 1.0 - differing as f64 / n;
    let hfov = 2.0 * ((0.5 * fov_y.to_radians()).tan() * w as f64 / h as f64).atan();
    let ppd = lemi_eval::image_metrics::ppd_for_view(w, hfov.to_degrees() as f32);
    let flip = lemi_eval::image_metrics::flip(&r, &t, ppd).unwrap();
    let note = format!(
        "coverage agreement {:.4}% ({differing} of {n} pixels differ; lemi {} covered, browser {}), mean FLIP {:.5} at {ppd:.1} px/deg",
        100.0 * agreement,
        c.reference_covered,
        c.test_covered,
        flip.mean,
    );
    (agreement, flip.mean, note)
}

/// `lemi render BUNDLE` of one view into `out`.
fn render(bundle: &Path, eye: &str, dir: &str, fov_y: f64, (w, h): (u32, u32), out: &Path) {
    let o = lemi(&[
        "render",
        bundle.to_str().unwrap(),
        "--eye",
        eye,
        "--dir",
        dir,
        "--fov",
        &fov_y.to_string(),
        "--size",
        &format!("{w}x{h}"),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "render: {}", stderr(&o));
}

/// A PNG as a frame: covered where alpha is not 0.
fn frame(path: &Path) -> Frame {
    let img = image::open(path).unwrap().to_rgba8();
    let (width, height) = img.dimensions();
    let rgba = img.into_raw();
    let depth = rgba
        .chunks_exact(4)
        .map(|p| if p[3] > 0 { 1.0 } else { f32::INFINITY })
        .collect();
    // background black in both (the screenshot's transparent pixels may hold any colour)
    let rgba = rgba
        .chunks_exact(4)
        .flat_map(|p| {
            if p[3] > 0 {
                [p[0], p[1], p[2], 255]
            } else {
                [0; 4]
            }
        })
        .collect();
    Frame {
        width,
        height,
        rgba,
        depth,
    }
}

#[test]
fn the_browser_shows_what_lemi_renders() {
    let Some(web) = browser_tools() else { return };
    let d = tmp("web", "viewer");
    let bundle = d.join("b");
    let mut args = vec!["bake"];
    args.extend(SMALL);
    args.extend(["-o", bundle.to_str().unwrap()]);
    let o = lemi(&args);
    assert!(o.status.success(), "bake: {}", stderr(&o));
    // one command from the bake to the served viewer
    let site = d.join("site");
    let (_server, url) = serve(&[bundle.to_str().unwrap(), "-o", site.to_str().unwrap()]);
    assert!(site.join("cells.json").is_file() && site.join("index.html").is_file());
    assert!(site.join("vendor/three/build/three.module.js").is_file());
    let (w, h) = (960u32, 540u32);
    let fov_y = 60.0f64;
    let views = [
        ("along-x", "18,1.7,-2", "1,0,0"),
        ("oblique", "22,2.5,3", "0.6,-0.1,-0.8"),
        ("back", "27,1.7,1", "-1,0.05,0.2"),
    ];
    for (name, eye, dir) in views {
        let shot = d.join(format!("{name}-browser.png"));
        let page =
            format!("{url}?size={w}x{h}&hud=0&transparent=1&fov={fov_y}&eye={eye}&dir={dir}");
        let Some(v) = browser(
            &web,
            &page,
            &[
                "--screenshot",
                shot.to_str().unwrap(),
                "--size",
                &format!("{w}x{h}"),
            ],
        ) else {
            return;
        };
        let reference = d.join(format!("{name}-lemi.png"));
        render(&bundle, eye, dir, fov_y, (w, h), &reference);
        assert_eq!(v["texture_formats"], serde_json::json!(["RGBA8"]), "{v}");
        // lemi serve sends the cells gzip-encoded and the browser decodes them
        let (fetched, sent) = (
            v["fetched_bytes"].as_f64().unwrap_or(0.0),
            v["transferred_bytes"].as_f64().unwrap_or(0.0),
        );
        assert!(
            sent > 0.0 && sent < fetched,
            "{name}: {sent} bytes sent for {fetched} fetched"
        );
        let t = frame(&shot);
        let (agreement, flip, note) = agreement(&reference, &shot, w, h, fov_y);
        eprintln!("{name}: {note} ({})", v["renderer"]);
        assert!(agreement >= 0.99, "{name}: coverage agreement {agreement}");
        assert!(flip < FLIP_BOUND, "{name}: mean FLIP {flip} ≥ {FLIP_BOUND}");
        if name == "along-x" {
            // the layer colouring (key L, `tint=1`): the same pixels covered, the impostors
            // tinted by layer, the near geometry grey
            let tinted = d.join("along-x-tinted.png");
            browser(
                &web,
                &format!("{page}&tint=1"),
                &[
                    "--screenshot",
                    tinted.to_str().unwrap(),
                    "--size",
                    &format!("{w}x{h}"),
                ],
            )
            .expect("the browser started a moment ago");
            let tt = frame(&tinted);
            let c = lemi_eval::image_metrics::coverage(&t, &tt).unwrap();
            assert_eq!(c.reference_covered, c.both, "tinting changes no coverage");
            assert_eq!(c.test_covered, c.both, "tinting changes no coverage");
            let changed = t
                .rgba
                .chunks_exact(4)
                .zip(tt.rgba.chunks_exact(4))
                .filter(|(a, b)| a[3] > 0 && a != b)
                .count();
            assert!(
                changed as f64 > 0.5 * c.both as f64,
                "{changed} of {} covered pixels tinted",
                c.both
            );
        }
    }
}

/// A BC1 bake served with its KTX2 textures as stored (`lemi serve --textures ktx2`): the browser
/// uploads the blocks (three.js's KTX2Loader, Zstandard inflated in the page) and shows what
/// `lemi render` shows from the same blocks (lavapipe samples BC1 too).
#[test]
fn the_browser_shows_a_bc1_bake_from_its_ktx2_blocks() {
    browser_shows_ktx2("bc1", &["BC1"]);
}

/// An ETC1S bake served with its Basis Universal KTX2 files (`KHR_texture_basisu`): three.js
/// transcodes them in the page with the vendored Basis transcoder (to BC7 or BC3 here), and the
/// picture covers what `lemi render` covers (lemi transcodes the same files to BC1).
#[test]
fn the_browser_shows_an_etc1s_bake_through_the_basis_transcoder() {
    browser_shows_ktx2("etc1s", &["BC7", "BC3"]);
}

/// The small bake with `bake_extra`, exported and served by `lemi serve` with `serve_extra`:
/// the test directory, the bundle, the export directory, the server and its URL.
fn bake_and_serve(
    name: &str,
    bake_extra: &[&str],
    serve_extra: &[&str],
) -> (PathBuf, PathBuf, PathBuf, Server, String) {
    let d = tmp("web", name);
    let bundle = d.join("b");
    let mut args = vec!["bake"];
    args.extend(SMALL);
    args.extend(bake_extra);
    args.extend(["-o", bundle.to_str().unwrap()]);
    let o = lemi(&args);
    assert!(o.status.success(), "bake: {}", stderr(&o));
    let site = d.join("site");
    let mut args = vec![bundle.to_str().unwrap(), "-o", site.to_str().unwrap()];
    args.extend(serve_extra);
    let (server, url) = serve(&args);
    (d, bundle, site, server, url)
}

/// The viewer at `url` from the camera of the `along-x` view, screenshot against `lemi render
/// bundle` of the same camera: the page's state (`Err` when the page failed), or `None` after a
/// visible skip.
fn along_x_against_lemi(
    web: &Path,
    url: &str,
    d: &Path,
    bundle: &Path,
    label: &str,
) -> Option<Result<serde_json::Value, serde_json::Value>> {
    let (w, h, fov_y) = (960u32, 540u32, 60.0f64);
    let (eye, dir) = ("18,1.7,-2", "1,0,0");
    let shot = d.join(format!("{label}-browser.png"));
    let page = format!("{url}?size={w}x{h}&hud=0&transparent=1&fov={fov_y}&eye={eye}&dir={dir}");
    let size = format!("{w}x{h}");
    let (ok, v) = browser_run(
        web,
        &page,
        &["--screenshot", shot.to_str().unwrap(), "--size", &size],
    )?;
    if !ok {
        return Some(Err(v));
    }
    let reference = d.join(format!("{label}-lemi.png"));
    render(bundle, eye, dir, fov_y, (w, h), &reference);
    let (agreement, flip, note) = agreement(&reference, &shot, w, h, fov_y);
    eprintln!("{label}: {note} ({})", v["renderer"]);
    assert!(agreement >= 0.99, "{label}: coverage agreement {agreement}");
    assert!(
        flip < FLIP_BOUND,
        "{label}: mean FLIP {flip} ≥ {FLIP_BOUND}"
    );
    Some(Ok(v))
}

/// `format`'s bake through `lemi serve --textures ktx2` in the browser, against `lemi render`;
/// `uploaded` lists the block formats the page may upload.
fn browser_shows_ktx2(format: &str, uploaded: &[&str]) {
    let Some(web) = browser_tools() else { return };
    let (d, bundle, site, _server, url) = bake_and_serve(
        &format!("ktx2-{format}"),
        &["--texture-format", format],
        &["--textures", "ktx2"],
    );
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(site.join("cells.json")).unwrap()).unwrap();
    assert_eq!(index["textures"], "ktx2", "{index}");
    assert!(site
        .join("vendor/three/examples/jsm/loaders/KTX2Loader.js")
        .is_file());
    let Some(result) = along_x_against_lemi(&web, &url, &d, &bundle, &format!("ktx2 {format}"))
    else {
        return;
    };
    let v = match result {
        Ok(v) => v,
        Err(v) => {
            let error = v["error"].as_str().unwrap_or_default();
            // a browser without the block format gets the viewer's clear message, nothing else
            assert!(
                error.contains("which this browser lacks"),
                "the viewer failed: {v}"
            );
            lemi_testkit::skip(&format!("this browser cannot sample {format}: {error}"));
            return;
        }
    };
    // the blocks were uploaded in a block format, not decoded to RGBA8
    let got = v["texture_formats"].as_array().cloned().unwrap_or_default();
    assert!(
        !got.is_empty()
            && got
                .iter()
                .all(|f| uploaded.contains(&f.as_str().unwrap_or(""))),
        "{format}: {v}"
    );
    // `--textures` on an export directory is a clear error (the textures are chosen at export)
    let o = lemi(&[
        "serve",
        site.to_str().unwrap(),
        "--textures",
        "ktx2",
        "--port",
        "0",
    ]);
    common::assert_clean_error_all(&o, &["--textures", "export directory"]);
}

/// Cells exported with `KHR_meshopt_compression` and the vertex codec's version 1 (`lemi serve
/// --geometry meshopt-v1`): three.js decodes them to the picture `lemi render` draws.
#[test]
fn the_browser_reads_khr_meshopt_compression() {
    let Some(web) = browser_tools() else { return };
    let (d, bundle, site, _server, url) =
        bake_and_serve("meshopt-v1", &[], &["--geometry", "meshopt-v1"]);
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(site.join("cells.json")).unwrap()).unwrap();
    assert_eq!(index["geometry"], "meshopt-v1", "{index}");
    if let Some(Err(v)) = along_x_against_lemi(&web, &url, &d, &bundle, "meshopt-v1") {
        panic!("the viewer failed: {v}");
    }
    // `--geometry` on an export directory is a clear error (the geometry is chosen at export)
    let o = lemi(&[
        "serve",
        site.to_str().unwrap(),
        "--geometry",
        "plain",
        "--port",
        "0",
    ]);
    common::assert_clean_error_all(&o, &["--geometry", "export directory"]);
}

#[test]
fn the_viewer_predicts_as_the_runtime() {
    let web = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../web");
    if Command::new("node").arg("--version").output().is_err() {
        lemi_testkit::skip("node is not installed (.ci/run installs it)");
        return;
    }
    use glam::DVec3;
    use lemi_core::cell::CellGrid;
    use lemi_core::Aabb;
    // 7 × 2 × 5 cells of 10 m × 4 m, off the origin
    let grid = CellGrid::tile_with_height(
        Aabb::new(DVec3::new(-30.0, 0.5, -20.0), DVec3::new(38.0, 7.5, 27.0)),
        10.0,
        Some(4.0),
    )
    .unwrap();
    let options = lemi_runtime::PredictOptions::default();
    let rule = lemi_export::PredictionRule {
        horizon_seconds: options.horizon_seconds,
        max_speed: options.max_speed,
        max_acceleration: options.max_acceleration,
        max_cells: options.max_cells,
        ..Default::default()
    };
    // positions inside, on borders and outside; standing, walking, running, flying up
    let mut cases = Vec::new();
    let mut seed = 7u64;
    let mut rand = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for k in 0..60 {
        let p = DVec3::new(
            -40.0 + 90.0 * rand(),
            -2.0 + 12.0 * rand(),
            -30.0 + 70.0 * rand(),
        );
        let p = if k % 7 == 0 { p.round() } else { p }; // on cell borders too
        let speed = [0.0, 1.5, 5.0, 14.0][k % 4];
        let v = DVec3::new(rand() - 0.5, 0.2 * (rand() - 0.5), rand() - 0.5).normalize() * speed;
        cases.push((p, v));
    }
    let input = serde_json::json!({
        "grid": {
            "origin": grid.origin.to_array(),
            "step": grid.step().to_array(),
            "counts": grid.counts.to_array(),
        },
        "rule": rule,
        "cases": cases.iter().map(|(p, v)| serde_json::json!({
            "position": p.to_array(), "velocity": v.to_array()
        })).collect::<Vec<_>>(),
    });
    let mut child = Command::new("node")
        .arg(web.join("tools/predict_cases.mjs"))
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.to_string().as_bytes())
        .unwrap();
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let js: Vec<Vec<String>> = serde_json::from_slice(&o.stdout).unwrap();
    let mut listed = 0;
    for ((p, v), js) in cases.iter().zip(&js) {
        let rust: Vec<String> = lemi_runtime::predict(*p, *v, &grid, &options)
            .iter()
            .map(|c| c.cell.id().to_string())
            .collect();
        assert_eq!(&rust, js, "at {p} moving {v}");
        listed += rust.len();
    }
    assert!(listed > 100, "the cases list cells ({listed})");
}
