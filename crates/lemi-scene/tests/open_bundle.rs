//! [`lemi_scene::open_bundle`]: a bundle opens with the scene it was baked from, and only with it.

use lemi_core::bundle::{LayerTarget, SceneRef};
use lemi_core::UpAxis;
use lemi_scene::{fingerprint, open_bundle, OpenBundleError};
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
