//! What the CLI test suites share: running the binary, its stderr, a scratch directory, and the
//! check that a failure is a clean error (non-zero exit, no panic, the message names the problem).

use std::path::PathBuf;
use std::process::{Command, Output};

/// The command `lemi ARGS`, with `XDG_RUNTIME_DIR` set (so Mesa stays quiet), not yet started.
pub fn lemi_command<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_lemi"));
    c.args(args).env("XDG_RUNTIME_DIR", std::env::temp_dir());
    c
}

/// Runs `lemi ARGS` and waits for it.
pub fn lemi(args: &[&str]) -> Output {
    lemi_command(args).output().expect("the lemi binary runs")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A fresh directory for one test, named after the suite, the process and `name`.
pub fn tmp(suite: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("lemi-{suite}-{}-{name}", std::process::id()));
    // process ids repeat: what an earlier run with this id left (a bundle `lemi bake` would skip
    // as already baked) must not leak into this one
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The command failed cleanly, and its stderr mentions every one of `needles`.
pub fn assert_clean_error_all(o: &Output, needles: &[&str]) {
    let e = stderr(o);
    assert!(!o.status.success(), "expected failure, stderr: {e}");
    assert_ne!(o.status.code(), Some(0));
    assert!(!e.contains("panicked"), "panic: {e}");
    for needle in needles {
        assert!(e.contains(needle), "error should mention `{needle}`: {e}");
    }
}

/// The command failed cleanly, and its stderr mentions `needle`.
#[allow(dead_code)] // not every suite checks a single message
pub fn assert_clean_error(o: &Output, needle: &str) {
    assert_clean_error_all(o, &[needle]);
}

/// Every file below `dir` (relative path → bytes), leaving out `shards/` (the shard records, the
/// merge's input) and nothing else: temporary files left behind would show as differences.
#[allow(dead_code)] // not every suite compares bundles
pub fn bundle_files(dir: &std::path::Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    fn walk(
        root: &std::path::Path,
        d: &std::path::Path,
        out: &mut std::collections::BTreeMap<String, Vec<u8>>,
    ) {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            if p.is_dir() {
                if rel != "shards" {
                    walk(root, &p, out);
                }
            } else {
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    let mut out = std::collections::BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// The two bundles hold the same files with the same bytes (apart from `shards/`).
#[allow(dead_code)]
pub fn assert_same_bundle(expected: &std::path::Path, got: &std::path::Path) {
    let a = bundle_files(expected);
    let b = bundle_files(got);
    let names_a: Vec<&String> = a.keys().collect();
    let names_b: Vec<&String> = b.keys().collect();
    assert_eq!(
        names_a,
        names_b,
        "{} and {} hold other files",
        expected.display(),
        got.display()
    );
    assert!(
        a.contains_key("manifest.json"),
        "no manifest in {}",
        expected.display()
    );
    for (name, bytes) in &a {
        assert!(
            &b[name] == bytes,
            "{name} differs between {} and {}",
            expected.display(),
            got.display()
        );
    }
}

/// Starts `lemi ARGS` without waiting (for processes that must run at the same time).
#[allow(dead_code)]
pub fn spawn_lemi(args: &[String]) -> std::process::Child {
    lemi_command(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the lemi binary starts")
}

/// Six 10 m cells of a small built-in city with small layers: a few seconds per bake (the
/// suites that kill, race or shard bakes).
#[allow(dead_code)] // not every suite bakes these cells
pub const SIX_CELLS: &[&str] = &[
    "builtin:city:20000",
    "--region",
    "0,1.7,-10,30,1.7,10",
    "--cell-size",
    "10",
    "--resolution",
    "32",
    "--layers",
    "4",
    "--alpha-deg",
    "0.5",
];

/// One 10 m cell on the avenue of a small built-in city with one layer (its near field far out,
/// holding the buildings), for composing object impostors into it (`--with-object`).
#[allow(dead_code)]
pub const AVENUE_CELL: &[&str] = &[
    "builtin:city:20k:3",
    "--region",
    "40,1.7,-5,50,1.7,5",
    "--cell-size",
    "10",
    "--resolution",
    "64",
    "--layers",
    "1",
    "--alpha-deg",
    "0.5",
];

/// The buildings 100 m and more down the avenue of [`AVENUE_CELL`]'s city as an object impostor,
/// from a box view cell holding that cell whole.
#[allow(dead_code)]
pub const AVENUE_OBJECT: &[&str] = &[
    "builtin:city:20k:3",
    "--object",
    "100,0.5,-100,300,80,100",
    "--view-cell",
    "box:34,-4,-6,56,7,6",
    "--alpha-deg",
    "0.5",
];
