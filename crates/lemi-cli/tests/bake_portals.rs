//! `lemi bake-object --portal`: the outside seen through every opening of `builtin:interior`
//! baked as a portal impostor for the opening's shaft (bounded by its room), one bundle each;
//! `lemi render` shows it from inside its shaft and the geometry nearer the opening; `lemi eval`
//! certifies it within a pixel and without cracks; bad portal flags are clear errors naming the
//! flag.

mod common;

use common::{assert_clean_error_all, lemi, stderr, tmp};

const SCENE: &str = "builtin:interior:20k:1";

fn json(o: &std::process::Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", stderr(o));
    serde_json::from_slice(&o.stdout).expect("JSON on stdout")
}

#[test]
fn every_opening_bakes_renders_from_its_room_and_is_certified() {
    let d = tmp("cli-portals", "ok");
    let out = d.join("portals");
    let o = out.to_str().unwrap();
    let r = json(&lemi(&[
        "bake-object",
        SCENE,
        "-o",
        o,
        "--portal",
        "all",
        "--portal-angle",
        "60",
        "--output-width",
        "128",
        "--json",
    ]));
    let reports = r.as_array().expect("one report per opening");
    // seven windows and the door
    assert_eq!(reports.len(), 8, "{r}");
    for (k, p) in reports.iter().enumerate() {
        assert!(
            out.join(format!("portal-{k}/manifest.json")).exists(),
            "{p}"
        );
        assert!(p["layer_count"].as_u64().unwrap() >= 1, "{p}");
        assert!(p["object_triangles"].as_u64().unwrap() > 0, "{p}");
        assert!(p["portal"].as_str().is_some(), "{p}");
        // bounded by the room: the shaft has a far end
        assert!(
            p["view_cell"]["max_distance"].as_f64().unwrap() > 1.5,
            "{p}"
        );
    }
    // portal 0: the south-west room's south window, facing -Z at x = 16.2
    assert!(
        reports[0]["portal"].as_str().unwrap().starts_with("16.2"),
        "{}",
        reports[0]
    );
    let b = out.join("portal-0");
    let b = b.to_str().unwrap();
    let png = d.join("view.png");
    let render = |eye: &str| {
        json(&lemi(&[
            "render",
            b,
            "--eye",
            eye,
            "--look",
            "16.2,1.75,-40",
            "--size",
            "160x90",
            "-o",
            png.to_str().unwrap(),
            "--json",
        ]))
    };
    // 4.3 m behind the window, in its shaft: the impostor
    let inside = render("16.2,1.75,-3.0");
    assert!(inside["quads"].as_u64().unwrap() > 0, "{inside}");
    // 0.8 m from the window, nearer than the shaft's near end: geometry
    let near = render("16.2,1.75,-6.5");
    assert_eq!(near["impostor"], false, "{near}");

    let e = json(&lemi(&[
        "eval",
        b,
        "--corners-only",
        "--viewpoints",
        "2",
        "--size",
        "128x128",
        "--fov",
        "60",
        "--require-no-cracks",
        "--require-max-px",
        "1.0",
        "--json",
    ]));
    assert!(e.to_string().contains("0_0_0"), "{e}");

    // the walk through every shaft, against all geometry
    let walk = d.join("walk");
    let s = json(&lemi(&[
        "walk",
        o,
        "--auto",
        "--size",
        "96x64",
        "--fps",
        "4",
        "-o",
        walk.to_str().unwrap(),
        "--json",
    ]));
    assert!(s["frames"].as_u64().unwrap() > 8, "{s}");
    assert_eq!(s["stalls"].as_u64(), Some(0), "{s}");
    assert_eq!(s["loads"].as_u64(), Some(8), "{s}");
    assert!(s["impostor_median_ms"].as_f64().is_some(), "{s}");
    assert!(s["culled_median_ms"].as_f64().is_some(), "{s}");
    assert!(walk.join("frames.csv").exists());
    // a walk with --strategy makes no sense here
    let o2 = lemi(&["walk", o, "--auto", "--strategy", "warp"]);
    assert_clean_error_all(&o2, &["--strategy", "portal"]);
}

#[test]
fn bad_portal_flags_are_clear_errors_naming_the_flag() {
    let d = tmp("cli-portals", "bad");
    let b = d.join("bundle");
    let b = b.to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["bake-object", SCENE, "-o", b, "--output-width", "128"];
        args.extend_from_slice(extra);
        lemi(&args)
    };
    // only the built-in interior knows its openings
    let o = lemi(&[
        "bake-object",
        "builtin:city:20k:1",
        "-o",
        b,
        "--portal",
        "all",
    ]);
    assert_clean_error_all(&o, &["--portal all", "builtin:interior"]);
    assert_clean_error_all(&run(&["--portal", "1,2,3"]), &["--portal", "8"]);
    assert_clean_error_all(
        &run(&["--portal", "16.2,1.75,-7.3,0,0,0,1.2,1.4"]),
        &["--portal", "normal"],
    );
    assert_clean_error_all(
        &run(&["--portal", "16.2,1.75,-7.3,0,0,-1,0,1.4"]),
        &["--portal", "width"],
    );
    assert_clean_error_all(
        &run(&["--portal", "all", "--portal-angle", "180"]),
        &["--portal-angle", "apex angle"],
    );
    assert_clean_error_all(
        &run(&["--portal", "all", "--portal-max-distance", "1"]),
        &["--portal-max-distance", "far end"],
    );
    assert_clean_error_all(&run(&["--portal", "all", "--near", "nan"]), &["--near"]);
    // nothing beyond the opening to replace
    assert_clean_error_all(
        &run(&["--portal", "all", "--near", "100000"]),
        &["--portal", "nothing"],
    );
    // a portal and a view cell are two different impostors
    let o = run(&["--portal", "all", "--view-cell", "box:0,0,0,1,1,1"]);
    assert_clean_error_all(&o, &["--view-cell", "--portal"]);
    assert!(!std::path::Path::new(b).join("manifest.json").exists());
}
