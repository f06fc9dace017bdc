//! End-to-end tests of the `lemi` binary: real scenes in, real files out, and clear errors (never a
//! panic) for bad input.

mod common;

use common::{assert_clean_error, lemi, stderr, tmp};

#[test]
fn info_json_has_counts_and_bounds() {
    let o = lemi(&["info", "builtin:city:20k:3", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let tris = v["triangles"].as_u64().unwrap();
    assert!((18_000..=22_000).contains(&tris), "{tris}");
    let min = v["bounds"]["min"].as_array().unwrap();
    let max = v["bounds"]["max"].as_array().unwrap();
    assert_eq!(min.len(), 3);
    assert!(max[0].as_f64().unwrap() > min[0].as_f64().unwrap());
    assert_eq!(min[1].as_f64().unwrap(), 0.0, "city ground at y = 0");
}

#[test]
fn info_rejects_bad_inputs_by_name() {
    assert_clean_error(
        &lemi(&["info", "/nonexistent/scene.glb"]),
        "/nonexistent/scene.glb",
    );
    assert_clean_error(&lemi(&["info", "builtin:castle"]), "castle");
    assert_clean_error(&lemi(&["info", "builtin:city:0"]), "city:0");
    let d = tmp("cli", "garbage");
    let p = d.join("bad.ply");
    std::fs::write(
        &p,
        b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n",
    )
    .unwrap();
    assert_clean_error(&lemi(&["info", p.to_str().unwrap()]), "bad.ply");
    let o = lemi(&["info", "builtin:city:20k", "--up", "x"]);
    assert_clean_error(&o, "--up");
}

#[test]
fn render_writes_an_image_of_the_requested_size() {
    let d = tmp("cli", "render");
    let out = d.join("city.png");
    let o = lemi(&[
        "render",
        "builtin:city:20k",
        "--eye",
        "0,1.7,0",
        "--look",
        "100,5,0",
        "--size",
        "160x90",
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&out).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (160, 90));
    let covered = img.pixels().filter(|p| p[3] == 255).count();
    assert!(
        covered > 160 * 90 / 4,
        "the street view shows geometry: {covered}"
    );
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["covered_pixels"].as_u64().unwrap() as usize, covered);
}

#[test]
fn render_rejects_absurd_flags() {
    let d = tmp("cli", "render-bad");
    let out = d.join("x.png");
    let o = out.to_str().unwrap();
    assert_clean_error(
        &lemi(&["render", "builtin:city:20k", "--size", "0x10", "-o", o]),
        "--size",
    );
    assert_clean_error(
        &lemi(&["render", "builtin:city:20k", "--eye", "nan,0,0", "-o", o]),
        "--eye",
    );
    assert_clean_error(
        &lemi(&["render", "builtin:city:20k", "--fov", "200", "-o", o]),
        "fov",
    );
    assert_clean_error(
        &lemi(&[
            "render",
            "builtin:city:20k",
            "--texel-filter",
            "bilinear",
            "-o",
            o,
        ]),
        "--texel-filter",
    );
    assert!(!out.exists(), "nothing written on error");
}

#[test]
fn layers_reproduces_the_paper_and_rejects_bad_parameters() {
    let o = lemi(&[
        "layers",
        "--cell",
        "10",
        "--resolution",
        "512",
        "--layers",
        "64",
        "--alpha-deg",
        "0.1",
        "--2d",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let nf = v["near_field"].as_f64().unwrap();
    assert!(
        (nf - 42.0).abs() < 1.0,
        "GI 2002: 64 layers -> 42 m, got {nf}"
    );
    let layers = v["layers"].as_array().unwrap();
    assert_eq!(layers.len(), 64);
    for k in ["distance", "near_border", "far_border", "bound_by"] {
        assert!(layers[1].get(k).is_some(), "layer field {k}");
    }
    assert_clean_error(
        &lemi(&["layers", "--cell", "10", "--layers", "0"]),
        "--layers",
    );
    assert_clean_error(&lemi(&["layers", "--cell", "-1", "--layers", "4"]), "cell");
    assert_clean_error(
        &lemi(&["layers", "--cell", "10", "--near-field", "3"]),
        "near",
    );
}

/// The TR's Fig. 11 distances (m from the view cell to the dragon).
const TR_DISTANCES: [f64; 6] = [42.0, 59.0, 96.0, 142.0, 209.0, 563.0];

/// The TR's Fig. 11 setting as `lemi layers` object-mode flags: a 20 m object (20 m deep) at
/// `distance` from a 10 m cubic cell, α = the edge pixel of a 60° output view `width` px wide.
fn object_layers_json(distance: f64, width: u32, extra: &[&str]) -> serde_json::Value {
    let (d, w) = (distance.to_string(), width.to_string());
    let mut args = vec![
        "layers",
        "--object-distance",
        &d,
        "--object-size",
        "20",
        "--object-depth",
        "20",
        "--cell",
        "10",
        "--output-fov",
        "60",
        "--output-width",
        &w,
        "--json",
    ];
    args.extend(extra);
    let o = lemi(&args);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The placement `lemi bake-object` would make for the same cell and object, computed here
/// through the library: a box `[-5, 5]³` (or a shaft on its +X face) and the object beyond +X.
fn object_placement_in_process(
    distance: f64,
    width: u32,
    shaft_angle_deg: Option<f64>,
) -> (lemi_core::object_cell::ObjectSetup, usize) {
    use glam::DVec3;
    use lemi_core::object_cell::{ObjectSetup, ObjectViewCell};
    use lemi_core::placement::{alpha_from_output_view, place_object_layers, PixelChoice};
    let alpha =
        alpha_from_output_view(60f64.to_radians(), width, PixelChoice::Edge).expect("alpha");
    let object = lemi_core::Aabb::new(
        DVec3::new(5.0 + distance, -10.0, -10.0),
        DVec3::new(25.0 + distance, 10.0, 10.0),
    );
    let cell = match shaft_angle_deg {
        None => ObjectViewCell::Box {
            min: DVec3::splat(-5.0),
            max: DVec3::splat(5.0),
        },
        Some(a) => {
            let apex = 5.0 / (a.to_radians() / 2.0).tan();
            ObjectViewCell::Shaft {
                apex: DVec3::new(5.0 + apex, 0.0, 0.0),
                dir: DVec3::NEG_X,
                angle_deg: a,
                min_distance: apex,
                max_distance: None,
                within: None,
            }
        }
    };
    let setup = ObjectSetup::new(cell, object, None, alpha).expect("setup");
    let n = place_object_layers(&setup.params)
        .expect("placement")
        .layers
        .len();
    (setup, n)
}

#[test]
fn layers_object_mode_matches_the_placement_at_the_tr_distances() {
    let mut counts = Vec::new();
    for width in [256u32, 512, 1024] {
        let mut row = Vec::new();
        for d in TR_DISTANCES {
            let v = object_layers_json(d, width, &[]);
            let (setup, n) = object_placement_in_process(d, width, None);
            assert_eq!(v["mode"], "object");
            assert_eq!(v["cell"]["kind"], "box");
            assert_eq!(
                v["layer_count"].as_u64().unwrap() as usize,
                n,
                "{width} px, {d} m"
            );
            let layers = v["layers"].as_array().unwrap();
            assert_eq!(layers.len(), n);
            assert_eq!(
                v["resolution"].as_u64().unwrap(),
                u64::from(setup.params.res)
            );
            assert_eq!(v["resolution_source"], "schaufler");
            assert_eq!(
                v["s"].as_f64().unwrap(),
                5.0,
                "s = m/2 (object wider than the cell)"
            );
            assert!((v["t0"].as_f64().unwrap() - d).abs() < 1e-9);
            for k in ["distance", "near_border", "far_border", "bound_by"] {
                assert!(layers[0].get(k).is_some(), "layer field {k}");
            }
            // near to far, the last ending at the object's far side
            let far = layers.last().unwrap()["far_border"].as_f64().unwrap();
            assert!((far - (d + 20.0)).abs() < 1e-6, "{far}");
            row.push(n);
        }
        counts.push(row);
    }
    // The counts docs/PLACEMENT.md quotes (section "Trends").
    assert_eq!(counts[0], [14, 7, 3, 1, 1, 1], "256 px");
    assert_eq!(counts[1], [28, 15, 6, 3, 1, 1], "512 px");
    assert_eq!(counts[2], [56, 30, 12, 6, 3, 1], "1024 px");
    for row in &counts {
        assert!(
            row.windows(2).all(|w| w[0] >= w[1]),
            "falls with distance: {row:?}"
        );
        assert!(row[0] > row[5], "{row:?}");
    }
    for ((a, b), c) in counts[0].iter().zip(&counts[1]).zip(&counts[2]) {
        assert!(a <= b && b <= c, "grows with the output width: {counts:?}");
    }
    assert!(
        counts[0][0] < counts[1][0] && counts[1][0] < counts[2][0],
        "{counts:?}"
    );

    // An explicit resolution is used as given.
    let v = object_layers_json(42.0, 1024, &["--resolution", "512"]);
    assert_eq!(v["resolution"], 512);
    assert_eq!(v["resolution_source"], "explicit");

    // A shaft whose near border is the box's +X face.
    let v = object_layers_json(96.0, 1024, &["--shaft-angle", "30"]);
    let (setup, n) = object_placement_in_process(96.0, 1024, Some(30.0));
    assert_eq!(v["cell"]["kind"], "shaft");
    assert_eq!(v["layer_count"].as_u64().unwrap() as usize, n);
    assert_eq!(v["s"].as_f64().unwrap(), setup.params.s);
    assert!(v["cell"]["view_cell"]
        .as_str()
        .unwrap()
        .starts_with("shaft:"));

    // The table names the same count.
    let o = lemi(&[
        "layers",
        "--object-distance",
        "42",
        "--object-size",
        "20",
        "--cell",
        "10",
        "--output-fov",
        "60",
        "--output-width",
        "1024",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains(": 56 layers"), "{out}");
    assert!(out.contains("Schaufler's rule"), "{out}");
    assert!(out.contains("bound by"), "{out}");
}

#[test]
fn layers_object_mode_plots_fig12() {
    let d = tmp("cli", "layers-object-plot");
    let svg = d.join("fig12.svg");
    let v = object_layers_json(42.0, 1024, &["--plot", svg.to_str().unwrap()]);
    assert_eq!(v["layer_count"], 56);
    let text = std::fs::read_to_string(&svg).unwrap();
    let doc = roxmltree::Document::parse(&text).expect("the plot is well-formed XML");
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let labels: Vec<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("text"))
        .filter_map(|n| n.text().map(str::trim))
        .collect();
    for name in [
        "256 px",
        "512 px",
        "1024 px",
        "TR Fig. 11 (dragon, 10 m cell)",
        "42 m",
        "84 m",
        "168 m",
    ] {
        assert!(labels.contains(&name), "series `{name}` in {labels:?}");
    }
    assert!(labels.iter().any(|l| l.contains("object distance")));
    assert!(labels.iter().any(|l| l.contains("view-cell size")));
}

#[test]
fn layers_object_mode_rejects_bad_flags() {
    let base = ["layers", "--cell", "10"];
    let run = |extra: &[&str]| {
        let mut a = base.to_vec();
        a.extend(extra);
        lemi(&a)
    };
    for (extra, flag) in [
        (
            &["--object-distance", "nan", "--object-size", "20"][..],
            "--object-distance",
        ),
        (
            &["--object-distance", "0", "--object-size", "20"],
            "--object-distance",
        ),
        (
            &["--object-distance", "-1", "--object-size", "20"],
            "--object-distance",
        ),
        (
            &["--object-distance", "inf", "--object-size", "20"],
            "--object-distance",
        ),
        (
            &["--object-distance", "42", "--object-size", "0"],
            "--object-size",
        ),
        (
            &["--object-distance", "42", "--object-size", "nan"],
            "--object-size",
        ),
        (
            &[
                "--object-distance",
                "42",
                "--object-size",
                "20",
                "--object-depth",
                "nan",
            ],
            "--object-depth",
        ),
        (
            &[
                "--object-distance",
                "42",
                "--object-size",
                "20",
                "--shaft-angle",
                "180",
            ],
            "--shaft-angle",
        ),
        (
            &[
                "--object-distance",
                "42",
                "--object-size",
                "20",
                "--shaft-angle",
                "0",
            ],
            "--shaft-angle",
        ),
        (&["--object-distance", "42"], "--object-size"),
        (&["--object-size", "20"], "--object-distance"),
        (
            &["--shaft-angle", "30", "--layers", "4", "--resolution", "64"],
            "--shaft-angle",
        ),
    ] {
        assert_clean_error(&run(extra), flag);
    }
    // object-mode and env-mode flags mixed: both named
    for (extra, env_flag) in [
        (
            &[
                "--object-distance",
                "42",
                "--object-size",
                "20",
                "--layers",
                "4",
            ][..],
            "--layers",
        ),
        (
            &[
                "--object-distance",
                "42",
                "--object-size",
                "20",
                "--near-field",
                "50",
            ],
            "--near-field",
        ),
        (
            &["--object-distance", "42", "--object-size", "20", "--2d"],
            "--2d",
        ),
        (
            &["--object-size", "20", "--resolution", "64", "--layers", "4"],
            "--layers",
        ),
    ] {
        let o = run(extra);
        common::assert_clean_error_all(&o, &[env_flag]);
        let e = stderr(&o);
        assert!(e.contains("--object-"), "names the object flag: {e}");
    }
    // the env mode still needs its resolution and a target
    assert_clean_error(&run(&["--layers", "4"]), "--resolution");
    assert_clean_error(&run(&["--resolution", "64"]), "--layers");
}

/// `lemi bake` → `lemi render BUNDLE --compare`, resume, shards + merge, all through the binary.
#[test]
fn bake_render_compare_resume_and_merge() {
    let d = tmp("cli", "bake");
    let bundle = d.join("bundle");
    let b = bundle.to_str().unwrap();
    let common = [
        "builtin:city:20k:3",
        "--region",
        "15,1.7,-5,35,1.7,5",
        "--cell-size",
        "10",
        "--resolution",
        "64",
        "--layers",
        "6",
        "--alpha-deg",
        "0.5",
    ];
    let mut args = vec!["bake"];
    args.extend(common);
    args.extend(["-o", b, "--json"]);
    let o = lemi(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["cells"], 2);
    assert_eq!(v["baked"], 2);
    for key in [
        "seconds",
        "raw_bytes",
        "png_bytes",
        "far_triangles",
        "near_triangles",
        "submitted_triangles",
    ] {
        assert!(v[key].is_number(), "{key} missing: {v}");
        assert!(v["per_cell"][0][key].is_number(), "per-cell {key} missing");
    }
    let far = v["far_triangles"].as_u64().unwrap();
    let sub = v["submitted_triangles"].as_u64().unwrap();
    assert!(far > 0 && sub >= far && sub <= 7 * far, "{far} {sub}");
    // resume: nothing to do
    let o = lemi(&args);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["skipped"], 2, "{v}");

    // render from inside the first cell, with the comparison
    let png = d.join("cmp.png");
    let o = lemi(&[
        "render",
        b,
        "--eye",
        "16,1.7,-4",
        "--look",
        "100,5,-4",
        "--size",
        "160x90",
        "--compare",
        "--json",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["cell"], "0_0_0");
    assert!(v["quads"].as_u64().unwrap() > 0);
    assert!(v["compare"]["reference_covered"].as_u64().unwrap() > 0);
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (480, 90));

    // outside the baked region: a clear error
    let o = lemi(&[
        "render",
        b,
        "--eye",
        "500,1.7,0",
        "--look",
        "600,1.7,0",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert_clean_error(&o, "outside the baked region");
    // the wrong scene: a fingerprint mismatch
    let o = lemi(&[
        "render",
        b,
        "--scene",
        "builtin:city:20k:4",
        "--eye",
        "16,1.7,-4",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert_clean_error(&o, "not the one");

    // shards, then merge: the same manifest as the single run
    let sharded = d.join("sharded");
    let s = sharded.to_str().unwrap();
    for k in ["0/2", "1/2"] {
        let mut args = vec!["bake"];
        args.extend(common);
        args.extend(["-o", s, "--shard", k]);
        let o = lemi(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let o = lemi(&["bake", "--merge", s]);
    assert!(o.status.success(), "{}", stderr(&o));
    let a: serde_json::Value =
        serde_json::from_slice(&std::fs::read(bundle.join("manifest.json")).unwrap()).unwrap();
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(sharded.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(a, m);

    // a damaged cell file: a clear error naming it
    let cell = bundle.join("cells/0_0_0.lemicell");
    let mut bytes = std::fs::read(&cell).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x55;
    std::fs::write(&cell, &bytes).unwrap();
    let o = lemi(&[
        "render",
        b,
        "--eye",
        "16,1.7,-4",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert_clean_error(&o, "0_0_0.lemicell");
}

#[test]
fn bake_rejects_absurd_flags_by_name() {
    let d = tmp("cli", "bake-bad");
    let out = d.join("b");
    let o = out.to_str().unwrap();
    let base = ["bake", "builtin:city:20k:3", "-o", o];
    for (extra, needle) in [
        (vec!["--cell-size", "-3"], "--cell-size"),
        (vec!["--resolution", "3"], "--resolution"),
        (vec!["--layers", "0"], "--layers"),
        (vec!["--faces", "5"], "--faces"),
        (vec!["--shard", "3/2"], "3/2"),
        (vec!["--region", "1,2,3"], "six"),
        (vec!["--cells", "99_0_0"], "99_0_0"),
        (vec!["--near-field", "1"], "--near-field"),
        (vec!["--alpha-deg", "nan"], "--alpha-deg"),
        (vec!["--alpha-px", "0"], "--alpha-px"),
        (vec!["--alpha-px", "-1"], "--alpha-px"),
        (
            vec!["--strategy", "equidistant", "--outline-copies"],
            "--outline-copies",
        ),
        (
            vec!["--outline-fringe", "--strategy", "equidistant"],
            "--outline-fringe",
        ),
    ] {
        let mut args = base.to_vec();
        args.extend(extra);
        assert_clean_error(&lemi(&args), needle);
    }
    assert_clean_error(&lemi(&["bake", "--merge", o]), "shard");
}

/// `lemi walk --auto`: streams the cells along a generated path, replays it with all geometry and
/// writes the records, the summary and the plot; bad paths are clear errors.
#[test]
fn walk_auto_writes_records_summary_and_plot() {
    let d = tmp("cli", "walk");
    let bundle = d.join("bundle");
    let b = bundle.to_str().unwrap();
    let o = lemi(&[
        "bake",
        "builtin:city:20k:3",
        "--region",
        "15,1.7,-5,35,1.7,5",
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
    let out = d.join("walk");
    let o = lemi(&[
        "walk",
        b,
        "--auto",
        "--walk-speed",
        "10",
        "--fly-speed",
        "20",
        "--fps",
        "15",
        "--size",
        "64x36",
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for key in [
        "frames",
        "stalls",
        "cell_switches",
        "impostor_median_ms",
        "impostor_p99_ms",
        "geometry_median_ms",
        "geometry_p99_ms",
        "speedup_median",
    ] {
        assert!(!v[key].is_null(), "{key} missing: {v}");
    }
    assert!(v["frames"].as_u64().unwrap() > 10);
    assert!(v["cell_switches"].as_u64().unwrap() >= 1, "{v}");
    assert_eq!(v["stalls"], 0, "{v}");
    for f in ["frames.csv", "summary.json", "plot.png", "path.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert!(csv.lines().count() > 2 * 10, "impostor and geometry rows");
    // the written path replays; frames are timed without a readback, except the ones written
    // to --frames-dir, which are read back and written whole
    let frames_dir = d.join("frames");
    let o = lemi(&[
        "walk",
        b,
        "--path",
        out.join("path.json").to_str().unwrap(),
        "--size",
        "32x18",
        "--no-geometry",
        "--frames-dir",
        frames_dir.to_str().unwrap(),
        "--every",
        "4",
        "-o",
        d.join("walk2").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let n = v["frames"].as_u64().unwrap();
    let mut written: Vec<String> = std::fs::read_dir(&frames_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    let expected: Vec<String> = (0..n)
        .step_by(4)
        .map(|i| format!("frame-{i:06}.png"))
        .collect();
    assert_eq!(written, expected);
    for f in &written {
        let img = image::open(frames_dir.join(f)).unwrap().to_rgba8();
        assert_eq!(img.dimensions(), (32, 18), "{f}");
        // the city, not only the sky the frame is cleared to
        let sky = lemi_walk::CLEAR;
        assert!(img.pixels().any(|p| p.0 != sky), "{f} shows only the sky");
    }
    // bad input
    assert_clean_error(
        &lemi(&["walk", b, "--path", "/nonexistent/p.json"]),
        "p.json",
    );
    let bad = d.join("bad.json");
    std::fs::write(
        &bad,
        b"{\"format\": \"lemi-path\", \"version\": 1, \"fps\": 30, \"keys\": []}",
    )
    .unwrap();
    assert_clean_error(
        &lemi(&["walk", b, "--path", bad.to_str().unwrap()]),
        "bad.json",
    );
    assert_clean_error(&lemi(&["walk", b]), "--auto");
}

/// `lemi eval`: a quick certificate through the binary, its gates, and clear errors for bad input.
#[test]
fn eval_certificate_gates_and_bad_input() {
    let d = tmp("cli", "eval");
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
        "64",
        "--near-field",
        "12",
        "--alpha-deg",
        "1",
        "-o",
        b,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let quick = [
        "eval",
        b,
        "--corners-only",
        "--viewpoints",
        "0",
        "--size",
        "96x54",
    ];
    let mut args = quick.to_vec();
    args.push("--json");
    let o = lemi(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for key in [
        "views",
        "max_error_px",
        "p99_error_px",
        "crack_pixels",
        "mean_flip",
        "coverage",
        "cells",
    ] {
        assert!(!v[key].is_null(), "{key} missing");
    }
    assert_eq!(v["views"], 9 * 8);
    assert!(bundle.join("eval/index.html").is_file());
    // an impossible gate fails with status 2 and says why
    let mut args = quick.to_vec();
    args.extend(["--require-max-px", "0"]);
    let o = lemi(&args);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--require-max-px"), "{}", stderr(&o));
    let mut args = quick.to_vec();
    args.extend([
        "--require-silhouette-p99",
        "0",
        "--require-displacement-p99",
        "0",
        "--require-false-coverage",
        "0",
    ]);
    let o = lemi(&args);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--require-silhouette-p99"),
        "{}",
        stderr(&o)
    );
    assert!(
        stderr(&o).contains("--require-displacement-p99"),
        "{}",
        stderr(&o)
    );
    assert!(
        v["silhouette_p99_px"].is_number()
            && v["displacement_p99_px"].is_number()
            && v["false_coverage_pixels"].is_number(),
        "{v}"
    );
    // the p99 of all views' outline pixels pooled is never above the worst single view's (this
    // small bake's outlines lie pixels apart, so both are above 0)
    for (pooled, worst) in [
        ("silhouette_pooled_p99_px", "silhouette_p99_px"),
        ("displacement_pooled_p99_px", "displacement_p99_px"),
    ] {
        let (p, w) = (v[pooled].as_f64(), v[worst].as_f64());
        assert!(
            matches!((p, w), (Some(p), Some(w)) if p > 0.0 && p <= w),
            "{pooled} {p:?} against {worst} {w:?}: {v}"
        );
    }
    // bad input
    assert_clean_error(&lemi(&["eval", "/nonexistent/bundle"]), "manifest.json");
    assert_clean_error(&lemi(&["eval", b, "--cells", "9_0_0"]), "9_0_0");
    assert_clean_error(
        &lemi(&["eval", b, "--require-max-px", "nan"]),
        "--require-max-px",
    );
    assert_clean_error(
        &lemi(&["eval", b, "--require-silhouette-p99", "inf"]),
        "--require-silhouette-p99",
    );
    assert_clean_error(
        &lemi(&["eval", b, "--require-displacement-p99", "nan"]),
        "--require-displacement-p99",
    );
    assert_clean_error(
        &lemi(&["eval", b, "--require-false-coverage", "2"]),
        "--require-false-coverage",
    );
    for bad in ["0", "nan", "2"] {
        assert_clean_error(
            &lemi(&["eval", b, "--silhouette-floor", bad]),
            "--silhouette-floor",
        );
    }
    assert_clean_error(&lemi(&["eval", b, "--size", "0x10"]), "0x10");
    assert_clean_error(&lemi(&["eval", b, "--fov", "200"]), "--fov");
    // a damaged cell file
    let cell = bundle.join("cells/0_0_0.lemicell");
    let mut bytes = std::fs::read(&cell).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x55;
    std::fs::write(&cell, &bytes).unwrap();
    assert_clean_error(&lemi(&quick), "0_0_0.lemicell");
}

/// `lemi demo` (the README's main job), small: bakes a cell, writes the side-by-side picture at
/// the demo's output view (960×540, three panels), reports no crack pixels, and resumes on a
/// second run. Without `--resolution` the layers match the output view (a texel per pixel).
#[test]
fn demo_bakes_renders_and_resumes() {
    let d = tmp("cli", "demo");
    let args = [
        "demo",
        "--scene",
        "builtin:city:20k",
        "-o",
        d.to_str().unwrap(),
        "--cells",
        "1",
        "--resolution",
        "96",
        "--layers",
        "8",
    ];
    let o = lemi(&args);
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}\n{out}", stderr(&o));
    assert!(out.contains("96² layers for a 960×540, 60° view"), "{out}");
    assert!(out.contains(" 0 crack pixels"), "{out}");
    let img = image::open(d.join("compare.png")).unwrap();
    assert_eq!((img.width(), img.height()), (3 * 960, 540));
    let again = lemi(&args);
    let out = String::from_utf8_lossy(&again.stdout).into_owned();
    assert!(again.status.success(), "{}", stderr(&again));
    assert!(out.contains("1 skipped"), "resumes: {out}");
    // the resolution the demo bakes at without `--resolution`: a texel per pixel of its view
    assert_eq!(
        lemi_core::placement::min_face_res_for_output_view(60f64.to_radians(), 960).unwrap(),
        1663
    );
}
