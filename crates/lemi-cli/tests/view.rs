//! `lemi view`: the interactive window, run for a fixed number of frames under a virtual X server
//! (`xvfb-run`, Debian packages `xvfb xauth`; skipped with a printed reason when absent), and its
//! clean error without a display.

#[allow(dead_code)] // this suite runs the binary its own way; it shares the bakes' arguments
mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

fn lemi() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_lemi"));
    c.env("XDG_RUNTIME_DIR", std::env::temp_dir());
    c
}

fn text(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn tmp(name: &str) -> PathBuf {
    common::tmp("view", name)
}

/// A small bundle (2 cells with impostors), baked once for the tests of this file.
fn bundle() -> &'static Path {
    static BUNDLE: OnceLock<PathBuf> = OnceLock::new();
    BUNDLE.get_or_init(|| {
        let out = tmp("bundle").join("b");
        let o = lemi()
            .args([
                "bake",
                "builtin:city:20k:3",
                "--region",
                "15,1.7,-5,35,1.7,5",
                "--cell-size",
                "10",
                "--cell-height",
                "1",
                "--resolution",
                "64",
                "--near-field",
                "12",
                "--alpha-deg",
                "1",
                "-o",
            ])
            .arg(&out)
            .output()
            .expect("lemi runs");
        let (so, se) = text(&o);
        assert!(o.status.success(), "bake failed: {so}\n{se}");
        out
    })
}

fn which(tool: &str) -> bool {
    std::env::var_os("PATH").is_some_and(|paths| {
        std::env::split_paths(&paths).any(|d| {
            let p = d.join(tool);
            p.is_file()
        })
    })
}

#[test]
fn view_without_a_display_fails_cleanly() {
    let o = lemi()
        .arg("view")
        .arg(bundle())
        .args(["--frames", "5"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .output()
        .expect("lemi runs");
    let (so, se) = text(&o);
    assert_eq!(o.status.code(), Some(1), "stdout: {so}\nstderr: {se}");
    assert!(!se.contains("panicked"), "panic: {se}");
    for needle in ["needs a display", "DISPLAY", "xvfb-run"] {
        assert!(se.contains(needle), "error should mention `{needle}`: {se}");
    }
    // a bad flag is named too (before any window)
    let o = lemi()
        .arg("view")
        .arg(bundle())
        .args(["--render-scale", "0"])
        .output()
        .expect("lemi runs");
    let (_, se) = text(&o);
    assert!(!o.status.success() && se.contains("--render-scale"), "{se}");
}

#[test]
fn view_runs_frames_under_xvfb_and_records_a_path_walk_replays() {
    if !which("xvfb-run") {
        eprintln!("skipped: xvfb-run not found (Debian: apt-get install xvfb xauth)");
        return;
    }
    let d = tmp("xvfb");
    let rec = d.join("rec.json");
    let shot = d.join("shot.png");
    let o = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 800x600x24"])
        .arg(env!("CARGO_BIN_EXE_lemi"))
        .arg("view")
        .arg(bundle())
        .args([
            "--frames",
            "20",
            "--size",
            "320x180",
            "--layers",
            "--record-now",
        ])
        .arg("--record")
        .arg(&rec)
        .arg("--screenshot")
        .arg(&shot)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("xvfb-run runs");
    let (so, se) = text(&o);
    assert!(o.status.success(), "stdout: {so}\nstderr: {se}");
    assert!(!se.contains("panicked"), "panic: {se}");
    for needle in [
        "window    320x180 on ",
        "cell      0_0_0: impostors ready",
        "recording started",
        "recording stopped",
        "lemi view: 20 frames in ",
        "(--frames reached)",
    ] {
        assert!(
            so.contains(needle),
            "stdout should contain `{needle}`: {so}"
        );
    }
    // the last frame: the scene (many colours) and the HUD (its darkened box, light text)
    let img = image::open(&shot).expect("screenshot").to_rgba8();
    assert_eq!(img.dimensions(), (320, 180));
    let mut colours: Vec<[u8; 4]> = img.pixels().map(|p| p.0).collect();
    colours.sort_unstable();
    colours.dedup();
    assert!(colours.len() > 50, "{} colours", colours.len());
    // the recording replays
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rec).expect("recorded path")).unwrap();
    assert_eq!(v["format"], "lemi-path");
    assert!(v["keys"].as_array().is_some_and(|k| k.len() >= 2), "{v}");
    let o = lemi()
        .arg("walk")
        .arg(bundle())
        .arg("--path")
        .arg(&rec)
        .args(["--size", "64x36", "--no-geometry", "--json", "-o"])
        .arg(d.join("walk"))
        .output()
        .expect("lemi runs");
    let (so, se) = text(&o);
    assert!(
        o.status.success(),
        "walk --path of the recording: {so}\n{se}"
    );
    std::fs::remove_dir_all(&d).ok();
}

/// `lemi view --with-object`: an object impostor whose view cell holds the bundle's cells whole is
/// composed into them (more quads, fewer near triangles in the first cell than without it), and
/// bad object bundles are clean errors naming the flag.
#[test]
fn view_composes_an_object_impostor_into_the_cells_it_serves() {
    if !which("xvfb-run") {
        eprintln!("skipped: xvfb-run not found (Debian: apt-get install xvfb xauth)");
        return;
    }
    let d = tmp("with-object");
    let (cells, object) = (d.join("cells"), d.join("object"));
    // one 10 m cell on the avenue with one layer (its near field far out, holding the
    // buildings), and those buildings as an object impostor from a box holding the cell whole
    // (the setting of `lemi walk --with-object`'s test)
    for (command, args, out) in [
        ("bake", common::AVENUE_CELL, &cells),
        ("bake-object", common::AVENUE_OBJECT, &object),
    ] {
        let o = lemi()
            .arg(command)
            .args(args)
            .arg("-o")
            .arg(out)
            .output()
            .expect("lemi runs");
        let (so, se) = text(&o);
        assert!(o.status.success(), "{command}: {so}\n{se}");
    }
    let view = |bundle: &Path, extra: &[&std::ffi::OsStr]| {
        let o = Command::new("xvfb-run")
            .args(["-a", "-s", "-screen 0 800x600x24"])
            .arg(env!("CARGO_BIN_EXE_lemi"))
            .arg("view")
            .arg(bundle)
            .args(["--frames", "3", "--size", "160x90"])
            .args(extra)
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .output()
            .expect("xvfb-run runs");
        let (so, se) = text(&o);
        assert!(!se.contains("panicked"), "panic: {se}");
        (o.status.success(), so, se)
    };
    // "cell      0_0_0: impostors ready (Q quads, T near triangles)"
    let counts = |so: &str| -> (u64, u64) {
        let line = so
            .lines()
            .find(|l| l.contains("0_0_0: impostors ready"))
            .unwrap_or_else(|| panic!("no ready line: {so}"));
        let n: Vec<u64> = line
            .split(['(', ' ', ','])
            .filter_map(|w| w.parse().ok())
            .collect();
        (n[0], n[1])
    };
    let (ok, so, se) = view(&cells, &[]);
    assert!(ok, "{so}\n{se}");
    let (quads, tris) = counts(&so);
    let (ok, so, se) = view(&cells, &["--with-object".as_ref(), object.as_os_str()]);
    assert!(ok, "{so}\n{se}");
    let (quads_with, tris_with) = counts(&so);
    assert!(
        quads_with > quads,
        "{quads_with} quads with, {quads} without"
    );
    assert!(
        tris_with < tris,
        "{tris_with} triangles with, {tris} without"
    );
    // an object bundle is not a bundle of cells to compose into; a missing one is named
    for (bundle, extra) in [
        (object.as_path(), object.as_os_str()),
        (cells.as_path(), "/nonexistent-object-bundle".as_ref()),
    ] {
        let (ok, so, se) = view(bundle, &["--with-object".as_ref(), extra]);
        assert!(!ok, "accepted: {so}");
        assert!(se.contains("--with-object"), "{se}");
    }
    std::fs::remove_dir_all(&d).ok();
}
