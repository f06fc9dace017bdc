//! [`StrategyKind::for_bundle`]: which strategy a bundle can serve, checked on the manifest alone.

use lemi_core::bundle::{BakeParams, LayerTarget, Layering, Manifest, SceneRef};
use lemi_strategy::{StrategyError, StrategyKind};
use lemi_testkit::{manifest_without_cells, row_of_cells, small_params};

fn manifest(layering: Layering) -> Manifest {
    let params = BakeParams {
        layering,
        ..small_params(32, LayerTarget::Layers(4))
    };
    let scene = SceneRef {
        sources: vec!["builtin:test".into()],
        up: "y".into(),
        fingerprint: "0".into(),
        triangles: 0,
    };
    manifest_without_cells(params, row_of_cells(1), scene)
}

#[test]
fn a_bundle_serves_its_own_strategy_and_lemi_bundles_serve_the_run_time_ones() {
    use StrategyKind::*;
    let lemi = manifest(Layering::Optimal);
    let cube = manifest(Layering::Single);
    assert_eq!(StrategyKind::for_bundle(&lemi, None).unwrap(), Lemi);
    assert_eq!(StrategyKind::for_bundle(&cube, None).unwrap(), Cubemap);
    for k in [Lemi, Warp, Dynamic] {
        assert_eq!(StrategyKind::for_bundle(&lemi, Some(k)).unwrap(), k);
    }
    assert!(matches!(
        StrategyKind::for_bundle(&lemi, Some(Cubemap)),
        Err(StrategyError::NotBakedFor {
            requested: Cubemap,
            baked: Lemi
        })
    ));
    let e = StrategyKind::for_bundle(&cube, Some(Warp)).unwrap_err();
    assert!(matches!(
        e,
        StrategyError::NeedsLemiBundle {
            requested: Warp,
            baked: Cubemap
        }
    ));
    assert!(e.to_string().contains("`lemi` bundle"), "{e}");
}
