//! `lemi bake-object`: an object of the built-in city baked for a box view cell reports its
//! layers, bytes and seconds as JSON; `lemi render` shows it as impostor inside the cell and as
//! geometry outside; `lemi eval` certifies it with the same gates as cell bundles; bad view
//! cells and objects are clear errors naming the flag.

mod common;

use common::{assert_clean_error_all, lemi, stderr, tmp, AVENUE_CELL, AVENUE_OBJECT};

const SCENE: &str = "builtin:city:20k:3";
/// City buildings between x = 100 and 300 m (walls and roofs, not the ground).
const OBJECT: &str = "100,0.5,-100,300,80,100";
/// A box on the free avenue, 50 m in front of them.
const CELL: &str = "box:40,1,-5,50,4,5";

fn json(o: &std::process::Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", stderr(o));
    serde_json::from_slice(&o.stdout).expect("JSON on stdout")
}

#[test]
fn an_object_bakes_renders_inside_and_outside_and_is_certified() {
    let d = tmp("cli-object", "ok");
    let bundle = d.join("bundle");
    let b = bundle.to_str().unwrap();
    let o = lemi(&[
        "bake-object",
        SCENE,
        "-o",
        b,
        "--object",
        OBJECT,
        "--view-cell",
        CELL,
        "--output-width",
        "256",
        "--json",
    ]);
    let r = json(&o);
    let layers = r["layer_count"].as_u64().expect("layer_count");
    assert!(layers > 1, "{r}");
    assert_eq!(r["layers"].as_array().map(Vec::len), Some(layers as usize));
    assert!(r["object_triangles"].as_u64().unwrap() > 100, "{r}");
    assert!(r["geometry_triangles"].as_u64().unwrap() > 100, "{r}");
    assert!(r["cell_bytes"].as_u64().unwrap() > 0, "{r}");
    assert!(r["bake_seconds"].as_f64().unwrap() > 0.0, "{r}");
    assert!((r["t0"].as_f64().unwrap() - 50.0).abs() < 10.0, "{r}");

    // inside the cell: the impostor's quads; outside: the object as geometry
    let png = d.join("in.png");
    let inside = json(&lemi(&[
        "render",
        b,
        "--eye",
        "41,1.5,-4",
        "--look",
        "200,10,0",
        "--size",
        "160x90",
        "-o",
        png.to_str().unwrap(),
        "--json",
    ]));
    assert!(inside["quads"].as_u64().unwrap() > 0, "{inside}");
    let outside = json(&lemi(&[
        "render",
        b,
        "--eye",
        "30,1.5,0",
        "--look",
        "200,10,0",
        "--size",
        "160x90",
        "-o",
        png.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(outside["impostor"], false, "{outside}");
    assert!(
        outside["note"].as_str().unwrap().contains("outside"),
        "{outside}"
    );

    // --with-object takes object bundles only, onto a cell bundle
    let o = lemi(&[
        "render",
        b,
        "--eye",
        "41,1.5,-4",
        "--look",
        "200,10,0",
        "--size",
        "160x90",
        "-o",
        png.to_str().unwrap(),
        "--with-object",
        "/nonexistent-object-bundle",
    ]);
    assert_clean_error_all(&o, &["--with-object", "/nonexistent-object-bundle"]);
    let o = lemi(&[
        "render",
        b,
        "--eye",
        "41,1.5,-4",
        "--look",
        "200,10,0",
        "--size",
        "160x90",
        "-o",
        png.to_str().unwrap(),
        "--with-object",
        b,
    ]);
    assert_clean_error_all(
        &o,
        &["--with-object", "cannot take further object impostors"],
    );

    // the certificate, with the same gates as cell bundles
    let e = lemi(&[
        "eval",
        b,
        "--corners-only",
        "--viewpoints",
        "1",
        "--require-no-cracks",
        "--require-max-px",
        "1.5",
        "--json",
    ]);
    let e = json(&e);
    let text = e.to_string();
    assert!(text.contains("0_0_0"), "{text}");
}

#[test]
fn bad_view_cells_and_objects_are_clear_errors_naming_the_flag() {
    let d = tmp("cli-object", "bad");
    let b = d.join("bundle");
    let b = b.to_str().unwrap();
    let run = |object: &str, cell: &str| {
        lemi(&[
            "bake-object",
            SCENE,
            "-o",
            b,
            "--object",
            object,
            "--view-cell",
            cell,
            "--output-width",
            "256",
        ])
    };
    // an empty box
    assert_clean_error_all(
        &run(OBJECT, "box:40,1,-5,50,1,5"),
        &["--view-cell", "empty"],
    );
    // an apex angle of 180° and more, or none
    for angle in ["180", "200", "0"] {
        let cell = format!("shaft:200,10,0,-1,0,0,{angle},100");
        assert_clean_error_all(&run(OBJECT, &cell), &["--view-cell", "apex angle"]);
    }
    // the object inside (overlapping) the cell
    assert_clean_error_all(
        &run(OBJECT, "box:90,0,-120,320,90,120"),
        &["--view-cell/--object", "not outside the view cell"],
    );
    // a shaft whose cell reaches into the object
    assert_clean_error_all(
        &run(OBJECT, "shaft:200,10,0,-1,0,0,30,20"),
        &["--view-cell/--object", "reaches"],
    );
    // malformed specs and an object box with no triangle
    assert_clean_error_all(&run(OBJECT, "cone:1,2,3"), &["--view-cell", "cone"]);
    assert_clean_error_all(&run(OBJECT, "box:1,2,3"), &["--view-cell", "6"]);
    assert_clean_error_all(
        &run(OBJECT, "shaft:1,2,3,0,0,0,30,5"),
        &["--view-cell", "direction"],
    );
    assert_clean_error_all(
        &run("5000,0,5000,5001,1,5001", CELL),
        &["--object", "no triangle"],
    );
    assert_clean_error_all(&run("1,2,nan,3,4,5", CELL), &["--object"]);
    // --object-mesh names a scene input
    let o = lemi(&[
        "bake-object",
        SCENE,
        "-o",
        b,
        "--object-mesh",
        "dragon",
        "--view-cell",
        CELL,
    ]);
    assert_clean_error_all(&o, &["--object-mesh", "dragon", SCENE]);
    assert!(!std::path::Path::new(b).join("manifest.json").exists());
    let o = lemi(&[
        "bake-object",
        SCENE,
        "-o",
        b,
        "--object-mesh",
        SCENE,
        "--object",
        OBJECT,
        "--view-cell",
        CELL,
        "--output-width",
        "128",
        "--resolution",
        "64",
        "--json",
    ]);
    let r = json(&o);
    assert!(r["object_triangles"].as_u64().unwrap() > 100, "{r}");
}

/// `lemi walk --with-object`: an object impostor whose view cell holds a whole cell of an
/// environment-map bundle replaces the object's triangles in that cell's near field while the
/// walk streams it: the frames draw the object's quads and fewer triangles than without it.
#[test]
fn a_walk_draws_an_object_impostor_in_the_cells_its_view_cell_holds() {
    let d = tmp("cli-object", "walk");
    let cells = d.join("cells");
    let object = d.join("object");
    let (c, o) = (cells.to_str().unwrap(), object.to_str().unwrap());
    // one 10 m cell on the avenue, one layer (a near field far out, holding the buildings),
    // and the buildings from a view cell holding that cell whole
    let bake = lemi(&[&["bake"], AVENUE_CELL, &["-o", c]].concat());
    assert!(bake.status.success(), "{}", stderr(&bake));
    json(&lemi(
        &[&["bake-object"], AVENUE_OBJECT, &["-o", o, "--json"]].concat(),
    ));
    let walk = |with: bool, out: &str| {
        let dir = d.join(out);
        let mut args = vec![
            "walk",
            c,
            "--auto",
            "--size",
            "96x64",
            "--fps",
            "4",
            "--no-geometry",
            "-o",
            dir.to_str().unwrap(),
            "--json",
        ];
        if with {
            args.extend_from_slice(&["--with-object", o]);
        }
        let s = json(&lemi(&args));
        assert_eq!(s["stalls"].as_u64(), Some(0), "{s}");
        let csv = std::fs::read_to_string(dir.join("frames.csv")).expect("frames.csv");
        let head = csv.lines().next().expect("header").split(',');
        let col = |name: &str| head.clone().position(|h| h == name).expect(name);
        let (tri, quads) = (col("near_triangles"), col("impostor_quads"));
        let rows: Vec<Vec<u64>> = csv
            .lines()
            .skip(1)
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                vec![f[tri].parse().unwrap(), f[quads].parse().unwrap()]
            })
            .collect();
        let max = |i: usize| rows.iter().map(|r| r[i]).max().unwrap_or(0);
        (max(0), max(1))
    };
    let (tri_without, quads_without) = walk(false, "walk-without");
    let (tri_with, quads_with) = walk(true, "walk-with");
    assert!(
        quads_with > quads_without,
        "{quads_with} quads with, {quads_without} without"
    );
    assert!(
        tri_with < tri_without,
        "{tri_with} triangles with, {tri_without} without"
    );
    // only layered bundles take object impostors
    let o2 = lemi(&[
        "walk",
        c,
        "--auto",
        "--strategy",
        "dynamic",
        "--with-object",
        o,
    ]);
    assert_clean_error_all(&o2, &["--with-object"]);
}
