//! `lemi bake --texture-format png|bc7|bc1`: each bakes through the binary, the manifest records
//! the format (only when not PNG, so PNG bundles keep their parameters and hash), the JSON summary
//! and the text summary give the bytes on disk, in texture memory and the encode seconds per
//! format; unknown names, the Basis formats not built here and HLOD with a block format are clear
//! errors.

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
    for format in ["png", "bc7", "bc1"] {
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
            assert_eq!(m["version"], 5);
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
}

#[test]
fn unknown_and_unavailable_formats_are_clear_errors() {
    let d = tmp("cli-texture-format", "bad");
    let out = d.join("b");
    let out = out.to_str().unwrap();
    assert_clean_error_all(
        &bake(out, &["--texture-format", "dxt1"]),
        &["--texture-format", "dxt1", "png, bc7 or bc1"],
    );
    assert_clean_error_all(
        &bake(out, &["--texture-format", "uastc"]),
        &["--texture-format", "uastc", "not available"],
    );
    assert_clean_error_all(
        &bake(out, &["--texture-format", "bc7", "--strategy", "hlod"]),
        &["--texture-format bc7", "hlod"],
    );
}
