//! `lemi bake --strategy`: the equidistant and cubemap strategies bake through the binary (the
//! manifest records the layering, the summary names the strategy), and strategies that are not
//! baked, unknown names and bad `--overlap` values are clear errors with a non-zero exit code.

mod common;

use std::process::Output;

use common::{assert_clean_error_all, lemi, stderr, tmp};

/// One small cell of the builtin city: 64² texels, 4 layers.
const SMALL: [&str; 13] = [
    "builtin:city:20k:3",
    "--region",
    "15,1.7,-5,25,1.7,5",
    "--cell-size",
    "10",
    "--resolution",
    "64",
    "--layers",
    "4",
    "--alpha-deg",
    "0.5",
    "--micro-grid",
    "8",
];

fn bake(out: &str, extra: &[&str]) -> Output {
    let mut args = vec!["bake"];
    args.extend(SMALL);
    args.extend(["-o", out]);
    args.extend(extra);
    lemi(&args)
}

fn manifest_params(bundle: &std::path::Path) -> serde_json::Value {
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(bundle.join("manifest.json")).unwrap()).unwrap();
    m["params"].clone()
}

#[test]
fn equidistant_and_cubemap_bake_and_say_so() {
    let d = tmp("cli-strategy", "ok");
    let equi = d.join("equi");
    let o = bake(
        equi.to_str().unwrap(),
        &["--strategy", "equidistant", "--overlap", "0.25", "--json"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["strategy"], "equidistant", "{v}");
    assert_eq!(v["baked"], 1, "{v}");
    // textures in the default format, BC1
    assert_eq!(v["texture_format"], "bc1", "{v}");
    assert!(v["texture_bytes"].as_u64().unwrap() > 0, "{v}");
    let p = manifest_params(&equi);
    assert_eq!(p["layering"]["equidistant"]["overlap"], 0.25, "{p}");

    // the default overlap, text summary
    let equi2 = d.join("equi2");
    let o = bake(equi2.to_str().unwrap(), &["--strategy", "equidistant"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("strategy   equidistant"), "{text}");
    assert_eq!(
        manifest_params(&equi2)["layering"]["equidistant"]["overlap"],
        0.1
    );

    let cube = d.join("cube");
    let o = bake(cube.to_str().unwrap(), &["--strategy", "cubemap", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["strategy"], "cubemap");
    assert_eq!(manifest_params(&cube)["layering"], "single");
    // one layer per face in the cell file
    let cell = std::fs::read(cube.join("cells/0_0_0.lemicell")).unwrap();
    let file = lemi_core::bundle::CellFile::decode(&cell).unwrap();
    assert!(file.header.layers.iter().all(|l| l.len() == 1));

    // the default strategy is lemi, and its parameters carry no layering (unchanged hash)
    let lemi_b = d.join("lemi");
    let o = bake(lemi_b.to_str().unwrap(), &["--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["strategy"], "lemi");
    assert!(manifest_params(&lemi_b).get("layering").is_none());
}

#[test]
fn strategies_that_are_not_baked_and_bad_overlaps_are_clear_errors() {
    let d = tmp("cli-strategy", "bad");
    let out = d.join("b");
    let o = out.to_str().unwrap();
    for (extra, needles) in [
        (
            vec!["--strategy", "warp"],
            vec!["warp", "not baked", "lemi walk/eval"],
        ),
        (
            vec!["--strategy", "dynamic"],
            vec!["dynamic", "not baked", "--strategy"],
        ),
        (
            vec!["--strategy", "nonsense"],
            vec![
                "unknown --strategy `nonsense`",
                "lemi, cubemap, equidistant",
            ],
        ),
        (
            vec!["--strategy", "equidistant", "--overlap", "-1"],
            vec!["--overlap", "-1"],
        ),
        (
            vec!["--strategy", "equidistant", "--overlap", "2"],
            vec!["--overlap", "[0, 1]"],
        ),
        (
            vec!["--strategy", "equidistant", "--overlap", "nan"],
            vec!["--overlap"],
        ),
        (vec!["--overlap", "0.2"], vec!["--overlap", "equidistant"]),
        (
            vec!["--strategy", "cubemap", "--overlap", "0.2"],
            vec!["--overlap", "equidistant"],
        ),
    ] {
        let out = bake(o, &extra);
        assert_clean_error_all(&out, &needles);
    }
    assert!(
        !out.join("manifest.json").exists(),
        "nothing is baked after an error"
    );
}

#[test]
fn hlod_bakes_and_bad_simplification_flags_are_clear_errors() {
    let d = tmp("cli-strategy", "hlod");
    let ok = d.join("ok");
    let o = bake(
        ok.to_str().unwrap(),
        &["--strategy", "hlod", "--hlod-error-px", "2", "--json"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["strategy"], "hlod", "{v}");
    let p = manifest_params(&ok);
    assert_eq!(p["layering"]["hlod"]["error_px"], 2.0, "{p}");
    assert_eq!(p["layering"]["hlod"]["band_factor"], 2.0, "{p}");
    let cell = std::fs::read(ok.join("cells/0_0_0.lemicell")).unwrap();
    let file = lemi_core::bundle::CellFile::decode(&cell).unwrap();
    let h = file.header.hlod.expect("an hlod section");
    assert!(
        h.triangles() > 0 && h.triangles() < h.source_triangles,
        "{h:?}"
    );
    assert!(file.header.quads.is_empty());

    let bad = d.join("bad");
    let o = bad.to_str().unwrap();
    for (extra, needles) in [
        (
            vec!["--hlod-error-px", "nan"],
            vec!["--hlod-error-px", "NaN"],
        ),
        (
            vec!["--hlod-error-px", "0"],
            vec!["--hlod-error-px", "positive"],
        ),
        (vec!["--hlod-error-px", "-1"], vec!["--hlod-error-px", "-1"]),
        (
            vec!["--hlod-error-px", "1e9"],
            vec!["--hlod-error-px", "at most"],
        ),
        (
            vec!["--hlod-band-factor", "1"],
            vec!["--hlod-band-factor", "(1, 64]"],
        ),
        (
            vec!["--hlod-band-factor", "inf"],
            vec!["--hlod-band-factor"],
        ),
    ] {
        let mut args = vec!["--strategy", "hlod"];
        args.extend(extra);
        assert_clean_error_all(&bake(o, &args), &needles);
    }
    assert_clean_error_all(
        &bake(o, &["--hlod-error-px", "2"]),
        &["--hlod-error-px", "only applies to --strategy hlod"],
    );
    assert!(!bad.join("manifest.json").exists());
}
