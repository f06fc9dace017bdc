//! `lemi compare` end to end on a small city: every strategy is baked (or built at run time),
//! walked along one path and evaluated at the same viewpoints; the tables name every strategy and
//! every strategy's image is recognisable; `--texture-formats` adds the `lemi` bake's rows per
//! texture format. Unknown strategy names are clear errors everywhere.

mod common;

use common::{assert_clean_error, lemi, stderr, tmp};

#[test]
fn unknown_strategy_names_are_rejected_clearly() {
    let o = lemi(&[
        "compare",
        "builtin:city:20k:3",
        "--strategies",
        "lemi,billboards",
    ]);
    assert_clean_error(&o, "unknown strategy `billboards`");
    assert_clean_error(&o, "lemi, cubemap, equidistant, warp, dynamic");
    let o = lemi(&["compare", "builtin:city:20k:3", "--strategies", "warp,warp"]);
    assert_clean_error(&o, "twice");
    // walk and eval check the name before touching the GPU
    let d = tmp("compare", "names");
    let bundle = d.join("bundle");
    let b = bundle.to_str().unwrap();
    let o = lemi(&[
        "bake",
        "builtin:city:20k:3",
        "--region",
        "15,1.7,-5,25,1.7,5",
        "--cell-size",
        "10",
        "--cell-height",
        "1",
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
    assert_clean_error(
        &lemi(&["walk", b, "--auto", "--strategy", "nailboards"]),
        "unknown strategy `nailboards`",
    );
    assert_clean_error(
        &lemi(&["eval", b, "--strategy", "Lemi2"]),
        "unknown strategy `Lemi2`",
    );
    // a layered strategy the bundle was not baked for
    assert_clean_error(
        &lemi(&["walk", b, "--auto", "--strategy", "cubemap"]),
        "lemi bake --strategy cubemap",
    );
}

#[test]
fn compare_runs_every_strategy_and_writes_the_tables() {
    let d = tmp("compare", "all");
    let out = d.join("cmp");
    let o = lemi(&[
        "compare",
        "builtin:city:20k:3",
        "--region",
        "15,1.7,-5,35,1.7,5",
        "--cell-size",
        "10",
        "--cell-height",
        "1",
        "--resolution",
        "64",
        "--layers",
        "6",
        "--output-width",
        "128",
        "--output-fov",
        "60",
        "--walk-size",
        "96x54",
        "--fps",
        "5",
        "--corners-only",
        "--eval-size",
        "96x54",
        "--texture-formats",
        "png,bc1",
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // `lemi` (baked with the default BC1 textures) and a PNG bake of it, each evaluated against
    // the reference, BC1 against the PNG bake too
    let formats = v["texture_formats"].as_array().unwrap();
    let names: Vec<&str> = formats
        .iter()
        .map(|f| f["format"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["png", "bc1"], "{v}");
    let (png, bc1) = (&formats[0], &formats[1]);
    for f in formats {
        assert!(f["errors"].as_array().unwrap().is_empty(), "{f}");
        assert_eq!(f["eval"]["textures"]["format"], f["format"], "{f}");
        assert_eq!(f["eval"]["crack_pixels"], 0, "{f}");
    }
    assert!(png["against_png"].is_null(), "{png}");
    assert!(
        png["bundle"].as_str().unwrap().ends_with("lemi-png"),
        "{png}"
    );
    assert!(
        bc1["bundle"].as_str().unwrap().ends_with("lemi"),
        "the lemi row's own bake: {bc1}"
    );
    assert_eq!(bc1["against_png"]["format"], "png", "{bc1}");
    assert_eq!(bc1["against_png"]["coverage_mismatch_pixels"], 0, "{bc1}");
    assert!(
        bc1["bake"]["per_cell"][0]["stage_seconds"]["bc1"].is_number(),
        "{bc1}"
    );
    assert!(
        png["bake"]["per_cell"][0]["stage_seconds"]["png"].is_number(),
        "{png}"
    );
    let rows = v["strategies"].as_array().unwrap();
    assert_eq!(
        rows[0]["eval"]["textures"]["format"], "bc1",
        "the bake's default"
    );
    let (png_memory, bc1_memory) = (
        png["eval"]["textures"]["texture_memory_bytes_per_cell"]
            .as_f64()
            .unwrap(),
        bc1["eval"]["textures"]["texture_memory_bytes_per_cell"]
            .as_f64()
            .unwrap(),
    );
    assert!(
        bc1_memory < png_memory / 2.0,
        "{png_memory} against {bc1_memory}"
    );
    let names: Vec<&str> = rows
        .iter()
        .map(|r| r["strategy"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["lemi", "cubemap", "equidistant", "warp", "dynamic"]);
    for r in rows {
        let name = r["strategy"].as_str().unwrap();
        assert!(r["errors"].as_array().unwrap().is_empty(), "{name}: {r}");
        let walk = &r["walk"];
        assert!(walk["frames"].as_u64().unwrap() > 5, "{name}: {walk}");
        assert!(walk["impostor_median_ms"].as_f64().unwrap() > 0.0, "{name}");
        let eval = &r["eval"];
        assert!(eval["views"].as_u64().unwrap() > 0, "{name}: {eval}");
        // recognisable: the mean FLIP against the all-geometry reference stays well below what an
        // empty sky (or a wrong image) gives
        let flip = eval["mean_flip"].as_f64().unwrap();
        assert!(flip < 0.35, "{name}: mean FLIP {flip}");
        assert!(eval["coverage"].as_f64().unwrap() > 0.8, "{name}: {eval}");
    }
    // the layered strategies report their bake; the optimal placement's error is the smallest
    for r in &rows[..3] {
        assert!(r["bake"]["cells"].as_u64().unwrap() >= 1, "{r}");
    }
    let lemi_max = rows[0]["eval"]["max_error_px"].as_f64().unwrap();
    assert!(lemi_max < 3.0, "lemi max error {lemi_max}");
    let md = std::fs::read_to_string(out.join("COMPARISON.md")).unwrap();
    for name in ["lemi", "cubemap", "equidistant", "warp", "dynamic"] {
        assert!(
            md.contains(&format!("| {name} |")),
            "{name} row missing:\n{md}"
        );
    }
    assert!(md.contains("lemi compare"), "the command is recorded");
    assert!(md.contains("## Texture formats of the `lemi` bake"), "{md}");
    assert_eq!(md.matches("| png |").count(), 1, "{md}");
    assert_eq!(md.matches("| bc1 |").count(), 1, "{md}");
    // speed-ups against geometry-culled, the unculled one beside; comparison.json carries both
    assert!(
        md.contains("speed-up vs culled | speed-up vs unculled"),
        "{md}"
    );
    let g = &v["geometry"];
    assert!(g["median_ms"].as_f64().unwrap() > 0.0, "{g}");
    assert!(g["culled_median_ms"].as_f64().unwrap() > 0.0, "{g}");
    let first = &rows[0]["walk"];
    assert!(
        first["speedup_culled_median"].as_f64().unwrap() > 0.0,
        "{first}"
    );
    assert!(
        first["culled_mean_triangles"].as_f64().unwrap() > 0.0,
        "{first}"
    );
    assert!(out.join("comparison.json").is_file());
    let svg = std::fs::read_to_string(out.join("frame_times.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("frame time"));
}
