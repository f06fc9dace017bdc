//! [`lemi_scene::open_bundle`]: a bundle opens with the scene it was baked from, and only with it.

use lemi_core::bundle::{LayerTarget, SceneRef};
use lemi_core::UpAxis;
use lemi_scene::{fingerprint, fingerprint_with, open_bundle, FingerprintScheme, OpenBundleError};
use lemi_testkit::{manifest_without_cells, row_of_cells, small_params};

#[test]
fn a_bundle_opens_with_its_scene_and_refuses_another() {
    let dir = tempfile::tempdir().unwrap();
    let sources = vec!["builtin:city:10000:5".to_string()];
    let scene = SceneRef {
        sources: sources.clone(),
        up: "y".into(),
        fingerprint: fingerprint(&sources, UpAxis::Y).unwrap(),
        triangles: 0,
    };
    let params = small_params(32, LayerTarget::Layers(4));
    manifest_without_cells(params, row_of_cells(1), scene)
        .write(dir.path())
        .unwrap();

    let opened = open_bundle(dir.path(), &[], None).unwrap();
    assert!(opened.scene.triangle_count() > 0);
    assert_eq!(opened.bundle.manifest().scene.sources, sources);
    // the same scene named again is fine
    assert!(open_bundle(dir.path(), &sources, None).is_ok());

    let other = ["builtin:city:10000:6".to_string()];
    let e = open_bundle(dir.path(), &other, None).unwrap_err();
    assert!(matches!(e, OpenBundleError::WrongScene { .. }), "{e}");
    assert!(e.to_string().contains("builtin:city:10000:6"), "{e}");

    let missing = [dir.path().join("gone.glb").display().to_string()];
    let e = open_bundle(dir.path(), &missing, None).unwrap_err();
    assert!(matches!(e, OpenBundleError::Fingerprint { .. }), "{e}");

    let e = open_bundle(&dir.path().join("nothing"), &[], None).unwrap_err();
    assert!(matches!(e, OpenBundleError::Bundle(_)), "{e}");
}

const PLY: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
    property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
    end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";

/// A bundle baked before `v2:` fingerprints (scheme 1) still opens with its scene; an image saved
/// beside the scene since (which scheme 1 hashed) is refused with an error that says why and what
/// to do, while a bundle fingerprinted under scheme 2 ignores such a file.
#[test]
fn a_bundle_of_the_older_fingerprint_scheme_still_opens() {
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = dir.path().join("scene");
    std::fs::create_dir_all(&scene_dir).unwrap();
    let ply = scene_dir.join("s.ply");
    std::fs::write(&ply, PLY).unwrap();
    let sources = vec![ply.display().to_string()];
    let params = small_params(32, LayerTarget::Layers(4));
    let write = |bundle: &std::path::Path, scheme: FingerprintScheme| {
        std::fs::create_dir_all(bundle).unwrap();
        let scene = SceneRef {
            sources: sources.clone(),
            up: "y".into(),
            fingerprint: fingerprint_with(&sources, UpAxis::Y, scheme).unwrap(),
            triangles: 1,
        };
        manifest_without_cells(params.clone(), row_of_cells(1), scene)
            .write(bundle)
            .unwrap();
    };
    let old = dir.path().join("old");
    let new = dir.path().join("new");
    write(&old, FingerprintScheme::V1);
    write(&new, FingerprintScheme::V2);
    assert!(open_bundle(&old, &[], None).is_ok());
    assert!(open_bundle(&new, &[], None).is_ok());

    std::fs::write(scene_dir.join("screenshot.png"), b"an image").unwrap();
    assert!(open_bundle(&new, &[], None).is_ok(), "scheme 2 ignores it");
    let e = open_bundle(&old, &[], None).unwrap_err();
    assert!(
        matches!(
            e,
            OpenBundleError::WrongScene {
                scheme: FingerprintScheme::V1,
                ..
            }
        ),
        "{e}"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("scheme 1") && msg.contains("bake the bundle again"),
        "{msg}"
    );

    // a fingerprint of a scheme this lemi does not know
    let mut m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(new.join("manifest.json")).unwrap()).unwrap();
    m["scene"]["fingerprint"] = "v9:0123".into();
    // an edited manifest without its checksum is read unchecked, as one from before the checksum
    m.as_object_mut().unwrap().remove("checksum");
    std::fs::write(new.join("manifest.json"), m.to_string()).unwrap();
    let e = open_bundle(&new, &[], None).unwrap_err();
    assert!(matches!(e, OpenBundleError::UnknownScheme { .. }), "{e}");
    assert!(e.to_string().contains("v9:0123"), "{e}");
}
