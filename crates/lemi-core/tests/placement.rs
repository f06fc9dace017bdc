//! Layer placement against the papers' figures (GI 2002 sec. 4.3, Table 1), the layer-count trends
//! of TR-186-2-02-04 sec. 2.3 / Fig. 12, and error handling of bad parameters.

use lemi_core::placement::{
    alpha_from_output_view, min_face_res_for_output_view, place_env_layers, place_object_layers,
    Bound, Dim, EnvParams, ObjectCell, ObjectParams, PixelChoice, Placement, PlacementError,
    Target,
};

fn deg(d: f64) -> f64 {
    d.to_radians()
}

fn env(m: f64, res: u32, alpha_deg: f64, dim: Dim, target: Target) -> Placement {
    match place_env_layers(&EnvParams::cube(m, res, deg(alpha_deg), dim), target) {
        Ok(p) => p,
        Err(e) => panic!("placement failed: {e}"),
    }
}

fn layers_for(m: f64, res: u32, alpha_deg: f64, near: f64) -> usize {
    env(m, res, alpha_deg, Dim::Two, Target::NearField(near))
        .layers
        .len()
}

/// GI 2002 sec. 4.3: 512², 10 m cell, 64 layers → near field at 42 m (from the centre).
#[test]
fn paper_64_layers_10m_cell_near_field_42m() {
    for dim in [Dim::Two, Dim::Three] {
        let p = env(5.0, 512, 0.1, dim, Target::Layers(64));
        assert_eq!(p.layers.len(), 64);
        assert!(
            (p.near_field - 42.0).abs() < 0.5,
            "{dim:?}: {}",
            p.near_field
        );
    }
}

/// GI 2002 Table 1: 14 m cell, 64 layers → near-field cube side 118 m (59 m from the centre).
#[test]
fn paper_table1_14m_cell_near_field_side_118m() {
    for dim in [Dim::Two, Dim::Three] {
        let p = env(7.0, 512, 0.1, dim, Target::Layers(64));
        assert!(
            (2.0 * p.near_field - 118.0).abs() < 1.0,
            "{dim:?}: {}",
            p.near_field
        );
    }
}

/// GI 2002 sec. 4.3: one layer → near field at 1738 m. The paper does not state α; the papers'
/// README names α ≈ 0.1° in the 2D case (the paper baked the 4 horizontal faces). 0.1° gives
/// 1732 m; α = 0.09963° reproduces 1738 m exactly.
#[test]
fn paper_one_layer_near_field_1738m() {
    let p = env(5.0, 512, 0.1, Dim::Two, Target::Layers(1));
    assert!(
        (p.near_field - 1738.0).abs() < 0.01 * 1738.0,
        "{}",
        p.near_field
    );
    let exact = env(5.0, 512, 0.09963, Dim::Two, Target::Layers(1));
    assert!(
        (exact.near_field - 1738.0).abs() < 1.0,
        "{}",
        exact.near_field
    );
    // In 3D the same α puts it much farther: the paper's number is the 2D case.
    let p3 = env(5.0, 512, 0.1, Dim::Three, Target::Layers(1));
    assert!(p3.near_field > 2000.0, "{}", p3.near_field);
}

/// Asking for a near field returns the fewest layers that reach it.
#[test]
fn near_field_target_is_the_inverse_of_layer_count() {
    let by_count = env(5.0, 512, 0.1, Dim::Three, Target::Layers(64));
    let by_near = env(
        5.0,
        512,
        0.1,
        Dim::Three,
        Target::NearField(by_count.near_field),
    );
    assert_eq!(by_near.layers.len(), 64);
    let fewer = env(5.0, 512, 0.1, Dim::Three, Target::Layers(63));
    assert!(fewer.near_field > by_count.near_field);
    let by_near = env(5.0, 512, 0.1, Dim::Three, Target::NearField(42.0));
    assert!(by_near.near_field <= 42.0);
    let one_less = env(
        5.0,
        512,
        0.1,
        Dim::Three,
        Target::Layers(by_near.layers.len() - 1),
    );
    assert!(one_less.near_field > 42.0);
}

/// Layers run far to near, borders are contiguous, the first is parallax-bound, both bounds occur.
#[test]
fn layers_are_ordered_and_contiguous() {
    let p = env(5.0, 512, 0.1, Dim::Three, Target::Layers(64));
    assert!(p.layers[0].far_border.is_infinite());
    assert_eq!(p.layers[0].bound_by, Bound::Parallax);
    for w in p.layers.windows(2) {
        assert!(w[0].distance > w[1].distance);
        assert_eq!(w[0].near_border, w[1].far_border);
    }
    for l in &p.layers {
        assert!(l.near_border < l.distance && l.distance < l.far_border);
    }
    assert_eq!(p.near_field, p.layers[63].near_border);
    assert!(p.near_field > 5.0);
    assert!(p.layers.iter().any(|l| l.bound_by == Bound::OneTexel));
}

/// The JSON form round-trips; the infinite far border of the first layer is `null`.
#[test]
fn json_round_trip() {
    let p = env(5.0, 512, 0.1, Dim::Two, Target::Layers(8));
    let json = match serde_json::to_string(&p) {
        Ok(j) => j,
        Err(e) => panic!("{e}"),
    };
    assert!(json.contains("\"far_border\":null"));
    assert!(json.contains("\"bound_by\":\"parallax\""));
    let back: Placement = match serde_json::from_str(&json) {
        Ok(b) => b,
        Err(e) => panic!("{e}"),
    };
    assert_eq!(back.layers.len(), p.layers.len());
    assert_eq!(back.params, p.params);
    for (a, b) in back.layers.iter().zip(&p.layers) {
        assert!((a.distance - b.distance).abs() < 1e-12 * b.distance);
        assert!((a.near_border - b.near_border).abs() < 1e-12 * b.near_border);
        assert!(
            a.far_border == b.far_border
                || (a.far_border - b.far_border).abs() < 1e-12 * b.far_border
        );
        assert_eq!(a.bound_by, b.bound_by);
    }
}

/// TR sec. 2.3, Fig. 12: the layer count falls roughly hyperbolically with distance, grows roughly
/// linearly with the view-cell size and with the resolution.
#[test]
fn layer_count_trends() {
    // Distance: n(d) strictly falls and n(d)·d stays within a factor 1.5.
    let ds = [20.0, 40.0, 80.0, 160.0, 320.0];
    let ns: Vec<usize> = ds.iter().map(|&d| layers_for(5.0, 512, 0.05, d)).collect();
    assert!(ns.windows(2).all(|w| w[0] > w[1]), "{ns:?}");
    let prod: Vec<f64> = ds.iter().zip(&ns).map(|(d, &n)| d * n as f64).collect();
    let (lo, hi) = min_max(&prod);
    assert!(hi / lo < 1.5, "n·d {prod:?}");
    // View-cell size: n grows, n/m within a factor 1.3.
    let ms = [1.0, 2.0, 4.0, 8.0, 16.0];
    let ns: Vec<usize> = ms
        .iter()
        .map(|&m| layers_for(m, 512, 0.05, 200.0))
        .collect();
    assert!(ns.windows(2).all(|w| w[0] < w[1]), "{ns:?}");
    let ratio: Vec<f64> = ms.iter().zip(&ns).map(|(m, &n)| n as f64 / m).collect();
    let (lo, hi) = min_max(&ratio);
    assert!(hi / lo < 1.3, "n/m {ratio:?}");
    // Resolution: n grows, n/Res within a factor 1.3 (the TR varies the output resolution, so
    // Res and α = 60°/Res change together).
    let rs = [256u32, 512, 1024, 2048];
    let ns: Vec<usize> = rs
        .iter()
        .map(|&r| layers_for(5.0, r, 60.0 / f64::from(r), 100.0))
        .collect();
    assert!(ns.windows(2).all(|w| w[0] < w[1]), "{ns:?}");
    let ratio: Vec<f64> = rs
        .iter()
        .zip(&ns)
        .map(|(&r, &n)| n as f64 / f64::from(r))
        .collect();
    let (lo, hi) = min_max(&ratio);
    assert!(hi / lo < 1.3, "n/Res {ratio:?}");
}

/// The same trends for the object impostor (TR Fig. 11/12: a 20 m dragon, 10 m cell).
#[test]
fn object_layer_count_trends() {
    let count = |t0: f64, n: f64, res: u32| {
        let p = ObjectParams {
            cell: ObjectCell::Box {
                width: [n, n],
                depth: n,
            },
            s: n / 2.0,
            t0,
            depth: 20.0,
            size: [20.0, 20.0],
            res,
            alpha: deg(0.05),
        };
        match place_object_layers(&p) {
            Ok(pl) => pl.layers.len(),
            Err(e) => panic!("{e}"),
        }
    };
    let ts = [42.0, 59.0, 96.0, 142.0, 209.0];
    let ns: Vec<usize> = ts.iter().map(|&t| count(t, 10.0, 512)).collect();
    assert!(ns.windows(2).all(|w| w[0] > w[1]), "{ns:?}");
    assert_eq!(count(5000.0, 10.0, 512), 1);
    let ns: Vec<usize> = [5.0, 10.0, 20.0]
        .iter()
        .map(|&n| count(96.0, n, 512))
        .collect();
    assert!(ns.windows(2).all(|w| w[0] < w[1]), "{ns:?}");
    let ns: Vec<usize> = [256u32, 512, 1024]
        .iter()
        .map(|&r| count(96.0, 10.0, r))
        .collect();
    assert!(ns.windows(2).all(|w| w[0] < w[1]), "{ns:?}");
}

fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

fn is_err(r: Result<Placement, PlacementError>) -> bool {
    r.is_err()
}

/// Bad parameters are errors, never panics or NaN.
#[test]
fn bad_parameters_are_errors() {
    let ok = EnvParams::cube(5.0, 512, deg(0.1), Dim::Three);
    let t = Target::Layers(4);
    assert!(place_env_layers(&ok, t).is_ok());
    for m in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(
            is_err(place_env_layers(
                &EnvParams::cube(m, 512, deg(0.1), Dim::Three),
                t
            )),
            "m = {m}"
        );
    }
    for a in [0.0, -0.1, 90.0, 120.0, f64::NAN] {
        assert!(
            is_err(place_env_layers(
                &EnvParams::cube(5.0, 512, deg(a), Dim::Two),
                t
            )),
            "α = {a}"
        );
    }
    assert!(is_err(place_env_layers(
        &EnvParams::cube(5.0, 0, deg(0.1), Dim::Two),
        t
    )));
    assert!(is_err(place_env_layers(&ok, Target::Layers(0))));
    assert!(is_err(place_env_layers(&ok, Target::Layers(usize::MAX))));
    for d in [5.0, 4.0, 0.0, -3.0, f64::NAN, f64::INFINITY] {
        assert!(
            is_err(place_env_layers(&ok, Target::NearField(d))),
            "near field {d}"
        );
    }
    assert!(matches!(
        place_env_layers(&ok, Target::NearField(2.0)),
        Err(PlacementError::NearFieldInsideCell { .. })
    ));
    // A near field a hair outside the cell needs absurdly many layers: an error, not a hang.
    let fine = EnvParams::cube(5.0, 1 << 16, deg(0.1), Dim::Three);
    assert!(matches!(
        place_env_layers(&fine, Target::NearField(5.0 + 1e-12)),
        Err(PlacementError::TooManyLayers { .. })
    ));
    let mut bad_box = ok;
    bad_box.across = [-1.0, 2.0];
    assert!(is_err(place_env_layers(&bad_box, t)));
    assert!(alpha_from_output_view(0.0, 1280, PixelChoice::Edge).is_err());
    assert!(alpha_from_output_view(deg(60.0), 0, PixelChoice::Centre).is_err());
    assert!(min_face_res_for_output_view(deg(200.0), 1280).is_err());
    // Object parameters.
    let obj = ObjectParams {
        cell: ObjectCell::Box {
            width: [10.0, 10.0],
            depth: 10.0,
        },
        s: 5.0,
        t0: 50.0,
        depth: 20.0,
        size: [20.0, 20.0],
        res: 256,
        alpha: deg(0.1),
    };
    assert!(place_object_layers(&obj).is_ok());
    let mutations: [fn(&mut ObjectParams); 10] = [
        |p| p.t0 = 0.0,
        |p| p.size[1] = -2.0,
        |p| p.res = 0,
        |p| p.alpha = 0.0,
        |p| p.s = 11.0,
        |p| p.s = -1.0,
        |p| p.depth = f64::NAN,
        |p| {
            p.cell = ObjectCell::Shaft {
                apex_angle: 0.0,
                apex_distance: 10.0,
                reach: None,
            }
        },
        |p| {
            p.cell = ObjectCell::Shaft {
                apex_angle: 0.5,
                apex_distance: 10.0,
                reach: Some(f64::NAN),
            }
        },
        |p| {
            p.cell = ObjectCell::Box {
                width: [f64::INFINITY, 1.0],
                depth: 10.0,
            }
        },
    ];
    for (i, f) in mutations.iter().enumerate() {
        let mut p = obj;
        f(&mut p);
        assert!(place_object_layers(&p).is_err(), "mutation {i}");
    }
    // From far back in a shaft no layer keeps points at infinity within α: an infinitely deep
    // object is an error there, while a box cell represents it with one far layer.
    let mut p = obj;
    p.depth = f64::INFINITY;
    assert!(place_object_layers(&p).is_ok());
    p.cell = ObjectCell::Shaft {
        apex_angle: deg(10.0),
        apex_distance: 60.0,
        reach: None,
    };
    assert!(place_object_layers(&p).is_err());
    // a bounded shaft (a room behind a portal) sees points at infinity within α from far enough
    p.cell = ObjectCell::Shaft {
        apex_angle: deg(10.0),
        apex_distance: 60.0,
        reach: Some(30.0),
    };
    let bounded = place_object_layers(&p).expect("a bounded shaft takes an infinitely deep object");
    assert!(bounded.single_layer_beyond.is_finite());
    p.depth = 20.0;
    p.cell = ObjectCell::Shaft {
        apex_angle: deg(10.0),
        apex_distance: 60.0,
        reach: None,
    };
    let unbounded = place_object_layers(&p).expect("finite depth");
    p.cell = ObjectCell::Shaft {
        apex_angle: deg(10.0),
        apex_distance: 60.0,
        reach: Some(30.0),
    };
    let bounded = place_object_layers(&p).expect("finite depth, bounded");
    assert!(
        bounded.layers.len() <= unbounded.layers.len(),
        "{} layers for the bounded shaft, {} for the unbounded one",
        bounded.layers.len(),
        unbounded.layers.len()
    );
}

/// The output-view helpers: the default view (60°, 1280 px) and the resolution warning threshold.
#[test]
fn output_view_alpha() {
    let e = alpha_from_output_view(deg(60.0), 1280, PixelChoice::Edge).unwrap_or(f64::NAN);
    let c = alpha_from_output_view(deg(60.0), 1280, PixelChoice::Centre).unwrap_or(f64::NAN);
    assert!(
        (e.to_degrees() - 0.03878).abs() < 1e-4,
        "{}",
        e.to_degrees()
    );
    assert!(
        (c.to_degrees() - 0.05168).abs() < 1e-4,
        "{}",
        c.to_degrees()
    );
    // A 90° output view at Res pixels needs a face of at least Res texels.
    assert_eq!(min_face_res_for_output_view(deg(90.0), 512).ok(), Some(512));
    assert_eq!(
        min_face_res_for_output_view(deg(60.0), 1280).ok(),
        Some(2218)
    );
}
