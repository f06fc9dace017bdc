//! A bundle whose manifest is damaged is a clear error at the start of `lemi walk` and
//! `lemi render` (naming `manifest.json` and what is wrong), never a panic or a walk over nothing.

mod common;

use common::{assert_clean_error_all, lemi, stderr, tmp};

#[test]
fn a_damaged_manifest_is_a_clear_error_at_start_of_walk_and_render() {
    let d = tmp("damage", "manifest");
    let bundle = d.join("bundle");
    let b = bundle.to_str().unwrap();
    let o = lemi(&[
        "bake",
        "builtin:city:20000",
        "--region",
        "0,1.7,-5,10,1.7,5",
        "--cell-size",
        "10",
        "--resolution",
        "32",
        "--layers",
        "4",
        "--alpha-deg",
        "0.5",
        "-o",
        b,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let manifest = bundle.join("manifest.json");
    let good = std::fs::read_to_string(&manifest).unwrap();
    // Edited with its checksum removed, so the checks behind the checksum are reached (a
    // manifest without one is read unchecked, as one written before the checksum was added).
    let at = good.rfind(",\n  \"checksum\"").expect("a checksum");
    let unchecked = format!("{}\n}}", &good[..at]);
    let edited = |from: &str, to: &str| {
        assert!(unchecked.contains(from), "{from} not in the manifest");
        unchecked.replacen(from, to, 1).into_bytes()
    };
    let damages: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", Vec::new(), "manifest.json"),
        (
            "truncated",
            good.as_bytes()[..good.len() / 2].to_vec(),
            "manifest.json",
        ),
        ("not JSON", b"\x00\x01garbage".to_vec(), "manifest.json"),
        (
            "one space more",
            good.replacen(": ", ":  ", 1).into_bytes(),
            "checksum mismatch",
        ),
        (
            "a parameter changed",
            edited("\"resolution\": 32", "\"resolution\": 33"),
            "params_hash",
        ),
        (
            "an unknown version",
            // a BC1 bundle (the default texture format) is version 8
            edited("\"version\": 8", "\"version\": 99"),
            "version",
        ),
        (
            "another format",
            edited("\"lemi-bundle\"", "\"lemi-bundles\""),
            "format",
        ),
    ];
    for (what, bytes, needle) in damages {
        std::fs::write(&manifest, &bytes).unwrap();
        let walk = lemi(&[
            "walk",
            b,
            "--auto",
            "--no-geometry",
            "--size",
            "32x18",
            "-o",
            d.join("walk").to_str().unwrap(),
        ]);
        assert_clean_error_all(&walk, &["manifest.json", needle]);
        assert!(
            !d.join("walk/frames.csv").exists(),
            "{what}: the walk must not start"
        );
        let render = lemi(&[
            "render",
            b,
            "--eye",
            "5,1.7,0",
            "--look",
            "50,1.7,0",
            "--size",
            "32x18",
            "-o",
            d.join("r.png").to_str().unwrap(),
        ]);
        assert_clean_error_all(&render, &["manifest.json", needle]);
    }
    let _ = std::fs::remove_dir_all(&d);
}
