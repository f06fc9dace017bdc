//! `lemi bake --texture-format png|bc7|bc1|uastc|etc1s`: each bakes through the binary, the
//! manifest records the format (only when not PNG, so PNG bundles keep their parameters and hash),
//! the JSON summary and the text summary give the bytes on disk, in texture memory and the encode
//! seconds per format; unknown names and HLOD with a block format are clear errors.

mod common;

use std::process::Output;

use common::{assert_clean_error_all, lemi, stderr, tmp};

/// One small cell of the builtin city: 64² texels, 4 layers.
const SMALL: [&str; 11] = [
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
];

fn bake(out: &str, extra: &[&str]) -> Output {
    let mut args = vec!["bake"];
    args.extend(SMALL);
    args.extend(["-o", out]);
    args.extend(extra);
    lemi(&args)
}

#[test]
fn every_texture_format_bakes_and_reports_its_bytes_and_seconds() {
    let d = tmp("cli-texture-format", "ok");
    let mut memory = Vec::new();
    for format in ["png", "bc7", "bc1", "uastc", "etc1s"] {
        let out = d.join(format);
        let o = bake(
            out.to_str().unwrap(),
            &["--texture-format", format, "--json"],
        );
        assert!(o.status.success(), "{format}: {}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["texture_format"], format, "{v}");
        for key in [
            "texture_bytes",
            "texture_memory_bytes",
            "encode_seconds",
            "png_bytes",
            "ktx2_bytes",
        ] {
            assert!(v[key].is_number(), "{format}: {key} missing: {v}");
        }
        let disk = v["texture_bytes"].as_u64().unwrap();
        assert!(disk > 0, "{v}");
        let (png, ktx2) = (
            v["png_bytes"].as_u64().unwrap(),
            v["ktx2_bytes"].as_u64().unwrap(),
        );
        assert_eq!(if format == "png" { png } else { ktx2 }, disk, "{v}");
        assert_eq!(if format == "png" { ktx2 } else { png }, 0, "{v}");
        assert!(v["stage_seconds"][format].is_number(), "{v}");
        assert!(v["per_cell"][0]["texture_memory_bytes"].is_number(), "{v}");
        memory.push(v["texture_memory_bytes"].as_u64().unwrap());
        eprintln!(
            "{format}: {disk} bytes on disk, {} in texture memory, encoded in {:.3} s",
            memory.last().unwrap(),
            v["encode_seconds"].as_f64().unwrap()
        );
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
        if format == "png" {
            assert!(m["params"].get("texture_format").is_none(), "{m}");
            assert_eq!(m["version"], 2);
        } else {
            assert_eq!(m["params"]["texture_format"], format, "{m}");
            assert_eq!(m["version"], 8);
        }
        // the text summary says it too
        let o = bake(out.to_str().unwrap(), &["--texture-format", format]);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains(&format!("textures   {format} per cell")),
            "{text}"
        );
    }
    // BC7: a byte a texel, BC1: half, against RGBA8's four (the packings differ a little: the
    // block formats pad micro-textures to 4×4 blocks)
    assert!(memory[1] < memory[0] / 2, "{memory:?}");
    assert!(memory[2] < memory[1], "{memory:?}");
    // UASTC is transcoded to BC7: the same packing (stacks), the same memory; ETC1S to BC1,
    // without stacks: at least BC1's
    assert_eq!(memory[3], memory[1], "{memory:?}");
    assert!(memory[4] >= memory[2], "{memory:?}");
}

#[test]
fn unknown_formats_are_clear_errors() {
    let d = tmp("cli-texture-format", "bad");
    let out = d.join("b");
    let out = out.to_str().unwrap();
    assert_clean_error_all(
        &bake(out, &["--texture-format", "dxt1"]),
        &["--texture-format", "dxt1", "png, bc7, bc1, uastc or etc1s"],
    );
    assert_clean_error_all(
        &bake(out, &["--texture-format", "bc7", "--strategy", "hlod"]),
        &["--texture-format bc7", "hlod"],
    );
}

#[test]
fn eval_against_the_png_bake_reports_the_formats_image_cost() {
    let d = tmp("cli-texture-format", "against");
    let (png, bc1, foreign) = (d.join("png"), d.join("bc1"), d.join("foreign"));
    let (png, bc1, foreign) = (
        png.to_str().unwrap(),
        bc1.to_str().unwrap(),
        foreign.to_str().unwrap(),
    );
    for (out, format) in [(png, "png"), (bc1, "bc1")] {
        let o = bake(out, &["--texture-format", format]);
        assert!(o.status.success(), "{format}: {}", stderr(&o));
    }
    let eval = |bundle: &str, extra: &[&str]| {
        let mut args = vec![
            "eval",
            bundle,
            "--corners-only",
            "--viewpoints",
            "0",
            "--size",
            "96x54",
        ];
        args.extend(extra);
        lemi(&args)
    };
    let o = eval(bc1, &["--against", png, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (t, a) = (&v["textures"], &v["against"]);
    assert_eq!(t["format"], "bc1", "{t}");
    assert!(
        t["texture_memory_bytes_per_cell"].as_f64().unwrap() > 0.0,
        "{t}"
    );
    assert_eq!(a["format"], "png", "{a}");
    assert_eq!(a["views"], v["views"], "{a}");
    assert_eq!(
        a["coverage_mismatch_pixels"], 0,
        "BC1 keeps the alpha test exact: {a}"
    );
    let flip = a["mean_flip"].as_f64().unwrap();
    assert!(flip > 0.0 && flip < 0.02, "{a}");
    // the text output says it, and the gate fails on a bound the format does not keep
    let o = eval(bc1, &["--against", png]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("against    ") && text.contains("textures   bc1"),
        "{text}"
    );
    let o = eval(bc1, &["--against", png, "--require-against-flip", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--require-against-flip"),
        "{}",
        stderr(&o)
    );
    // another scene's bake, a missing bundle and a gate without --against are clear errors
    // the same flags on another seed of the city
    let mut args = vec!["bake", "builtin:city:20k:4"];
    args.extend(&SMALL[1..]);
    args.extend(["-o", foreign]);
    let o = lemi(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_clean_error_all(
        &eval(bc1, &["--against", foreign]),
        &["--against", "another scene"],
    );
    let missing = d.join("missing");
    let missing = missing.to_str().unwrap();
    assert_clean_error_all(&eval(bc1, &["--against", missing]), &["--against", missing]);
    assert_clean_error_all(
        &eval(bc1, &["--require-against-flip", "0.01"]),
        &["--against"],
    );
}
