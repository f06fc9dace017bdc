//! The one-pixel guarantee of the layer placement, checked by brute force (GI 2002 sec. 4.2,
//! TR-186-2-02-04 sec. 2.1): for random cells, resolutions, α and layer counts, viewpoints all over
//! the view cell (corners, edge and face midpoints, random interior points) and every ray of the
//! face, (1) the parallax angle between a point of a layer's depth range and its projection on the
//! layer never exceeds α, and (2) no texel of a layer moves more than one texel against the texel
//! behind it in the next layer (the near texel's image still overlaps the far texel).
//!
//! The worst ray is found by a grid over the face followed by a local pattern search, so the
//! measured maximum is close to the true one; for cubes the tests also check that the bounds are
//! tight (the placement is not needlessly conservative).

use glam::DVec3;
use lemi_core::placement::{
    place_env_layers, place_object_layers, Bound, EnvParams, ObjectCell, ObjectParams,
    PlacementError, Target,
};
use proptest::prelude::*;

/// Angle between the directions `a` and `b`.
fn angle(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// Parallax angle seen from `v` between the point at depth `z` (may be infinite) on the ray
/// `(u.x, u.y, 1)` from the reference viewpoint (the origin) and its projection at depth `layer`.
fn parallax(v: DVec3, u: [f64; 2], z: f64, layer: f64) -> f64 {
    let d = DVec3::new(u[0], u[1], 1.0);
    let on_layer = d * layer - v;
    let point = if z.is_infinite() { d } else { d * z - v };
    angle(point, on_layer)
}

/// The largest parallax over rays `u ∈ [−k, k]` (per axis) from each viewpoint: a grid, then a
/// pattern search around the best grid ray.
fn max_parallax(views: &[DVec3], k: [f64; 2], z: f64, layer: f64) -> f64 {
    const N: usize = 9;
    let mut worst = 0.0f64;
    for &v in views {
        let mut best = (f64::NEG_INFINITY, [0.0, 0.0]);
        for i in 0..N {
            for j in 0..N {
                let u = [
                    k[0] * (2.0 * i as f64 / (N - 1) as f64 - 1.0),
                    k[1] * (2.0 * j as f64 / (N - 1) as f64 - 1.0),
                ];
                let a = parallax(v, u, z, layer);
                if a > best.0 {
                    best = (a, u);
                }
            }
        }
        let mut step = [k[0] / (N - 1) as f64, k[1] / (N - 1) as f64];
        for _ in 0..24 {
            let mut moved = false;
            for (dx, dy) in [
                (-1.0, 0.0),
                (1.0, 0.0),
                (0.0, -1.0),
                (0.0, 1.0),
                (-1.0, -1.0),
                (1.0, 1.0),
                (-1.0, 1.0),
                (1.0, -1.0),
            ] {
                let u = [
                    (best.1[0] + dx * step[0]).clamp(-k[0], k[0]),
                    (best.1[1] + dy * step[1]).clamp(-k[1], k[1]),
                ];
                let a = parallax(v, u, z, layer);
                if a > best.0 {
                    best = (a, u);
                    moved = true;
                }
            }
            if !moved {
                step = [step[0] / 2.0, step[1] / 2.0];
            }
        }
        worst = worst.max(best.0);
    }
    worst
}

/// Shift of a texel edge: the point at `e` (axis `axis`, the other coordinate `other`) of the
/// layer at depth `near`, seen from `v`, lands on the layer at depth `far` at this coordinate.
fn image_on_far(v: DVec3, axis: usize, e: f64, other: f64, near: f64, far: f64) -> f64 {
    let mut u = [other, other];
    u[axis] = e;
    let x = DVec3::new(u[0], u[1], 1.0) * near;
    let lambda = (far - v.z) / (near - v.z);
    let hit = v + (x - v) * lambda;
    [hit.x, hit.y][axis] / far
}

/// The largest texel movement (in texels) between the layers at `near` and `far` with `res`
/// texels over `[−k, k]`: for texel `[e0, e1]` the image of `e0` must stay `≤ e1` and the image of
/// `e1` `≥ e0`. The movement is affine in the texel position, so the end texels (plus a few
/// others) bound it. Returns `max(img(e0) − e0, e1 − img(e1)) / δ` (≤ 1 means no gap).
fn max_texel_shift(views: &[DVec3], k: [f64; 2], res: u32, near: f64, far: f64) -> f64 {
    let mut worst = 0.0f64;
    let last = res - 1;
    for axis in 0..2 {
        let delta = 2.0 * k[axis] / f64::from(res);
        let o = k[1 - axis];
        for &v in views {
            for t in [0, 1.min(last), res / 2, last.saturating_sub(1), last] {
                let e0 = -k[axis] + f64::from(t) * delta;
                let e1 = e0 + delta;
                for other in [-o, 0.0, o] {
                    let a = image_on_far(v, axis, e0, other, near, far) - e0;
                    let b = e1 - image_on_far(v, axis, e1, other, near, far);
                    worst = worst.max(a / delta).max(b / delta);
                }
            }
        }
    }
    worst
}

/// Viewpoints of a box `[−h, h]` (face frame: z along the face axis): the 27 corner/edge/face/centre
/// points and `extra` pseudo-random interior points.
fn box_views(h: DVec3, extra: u64, seed: u64) -> Vec<DVec3> {
    let mut v = Vec::new();
    for x in [-1.0, 0.0, 1.0] {
        for y in [-1.0, 0.0, 1.0] {
            for z in [-1.0, 0.0, 1.0] {
                v.push(h * DVec3::new(x, y, z));
            }
        }
    }
    let mut s = seed | 1;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for _ in 0..extra {
        v.push(h * DVec3::new(rnd(), rnd(), rnd()));
    }
    v
}

/// Viewpoints of a shaft cell exactly as `ObjectCell::Shaft` defines it (reference viewpoint at the
/// origin, z toward the object): the near border at `z = s`, the apex `apex_distance` beyond it,
/// the cell `z ≤ s`, `|x|, |y| ≤ (s + apex_distance − z)·tan(β/2)`, unbounded backwards. For each
/// back distance `μ` (on the near border, around the apex and object distances where the parallax
/// peaks, and far back) the corners and centre of the cross-section (on the near border also the
/// edge midpoints), plus random interior points with log-distributed `μ`. `far` is the object's far side (from the origin).
fn shaft_views(
    s: f64,
    apex_angle: f64,
    apex_distance: f64,
    reach: Option<f64>,
    far: f64,
    seed: u64,
) -> Vec<DVec3> {
    let limit = reach.unwrap_or(f64::INFINITY);
    let tan = (apex_angle / 2.0).tan();
    let scale = s + apex_distance;
    let cross = |mu: f64, x: f64, y: f64| {
        let z = s - mu;
        let hw = (s + apex_distance - z) * tan;
        DVec3::new(x * hw, y * hw, z)
    };
    let mut v = Vec::new();
    let mut backs = vec![0.0, 0.1 * scale, 1e4 * scale];
    for f in [0.3, 0.6, 1.0, 1.5, 2.5, 5.0, 30.0] {
        backs.push(f * scale);
        backs.push(f * far);
    }
    if let Some(r) = reach {
        backs.push(r);
        backs.push(0.5 * r);
    }
    for mu in backs.into_iter().filter(|&mu| mu <= limit) {
        // The parallax peaks on the cell's boundary, at its corner edges (the centre and, on the
        // near border, the edge midpoints check that).
        for (x, y) in [
            (-1.0, -1.0),
            (-1.0, 1.0),
            (1.0, -1.0),
            (1.0, 1.0),
            (0.0, 0.0),
        ] {
            v.push(cross(mu, x, y));
        }
        if mu == 0.0 {
            for (x, y) in [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)] {
                v.push(cross(mu, x, y));
            }
        }
    }
    let mut st = seed | 1;
    let mut rnd = || {
        st ^= st << 13;
        st ^= st >> 7;
        st ^= st << 17;
        (st >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..8 {
        let mu = (scale * (1e-2f64).powf(1.0 - 4.0 * rnd())).min(limit);
        v.push(cross(mu, 2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0));
    }
    v
}

const TOL: f64 = 1e-9;

/// Checks one environment-map placement; returns (worst parallax / α, worst texel shift).
fn check_env(p: &EnvParams, n: usize, seed: u64) -> Result<(f64, f64), TestCaseError> {
    let pl = place_env_layers(p, Target::Layers(n))
        .map_err(|e| TestCaseError::fail(format!("placement failed: {e}")))?;
    let h = DVec3::new(p.across[0], p.across[1], p.along);
    let views = box_views(h, 6, seed);
    let k = [1.0, 1.0];
    let mut worst_par = 0.0f64;
    for l in &pl.layers {
        for z in [l.far_border, l.near_border] {
            let a = max_parallax(&views, k, z, l.distance) / p.alpha;
            prop_assert!(
                a <= 1.0 + TOL,
                "parallax {a}·α at layer {} border {z} ({p:?})",
                l.distance
            );
            worst_par = worst_par.max(a);
        }
    }
    let mut worst_shift = 0.0f64;
    for w in pl.layers.windows(2) {
        let s = max_texel_shift(&views, k, p.res, w[1].distance, w[0].distance);
        prop_assert!(
            s <= 1.0 + TOL,
            "texel shift {s} between {} and {} ({p:?})",
            w[1].distance,
            w[0].distance
        );
        if w[1].bound_by == Bound::OneTexel {
            worst_shift = worst_shift.max(s);
        }
    }
    Ok((worst_par, worst_shift))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Cubic cells, 2D and 3D: never above α or one texel, and tight (the first layer's range to
    /// infinity and the near field reach α; one-texel-bound layers move exactly one texel).
    #[test]
    fn env_cube_keeps_the_guarantee(
        m in 0.5f64..20.0,
        res in 8u32..1024,
        alpha_deg in 0.01f64..3.0,
        n in 1usize..24,
        three_d in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let dim = if three_d { lemi_core::placement::Dim::Three } else { lemi_core::placement::Dim::Two };
        let p = EnvParams::cube(m, res, alpha_deg.to_radians(), dim);
        let (par, shift) = check_env(&p, n, seed)?;
        prop_assert!(par > 1.0 - 1e-4, "parallax bound not tight: {par}");
        let pl = place_env_layers(&p, Target::Layers(n)).map_err(|e| TestCaseError::fail(e.to_string()))?;
        if pl.layers.iter().any(|l| l.bound_by == Bound::OneTexel) {
            prop_assert!(shift > 1.0 - 1e-6, "one-texel bound not tight: {shift}");
        }
    }

    /// Box cells with different extents per axis (including flat ones): never above α or a texel.
    #[test]
    fn env_box_keeps_the_guarantee(
        hx in 0.0f64..10.0,
        hy in 0.0f64..10.0,
        hz in 0.0f64..10.0,
        res in 8u32..1024,
        alpha_deg in 0.01f64..3.0,
        n in 1usize..16,
        seed in any::<u64>(),
    ) {
        prop_assume!(hx + hy + hz > 0.1);
        let p = EnvParams::box_face(DVec3::new(hx, hy, hz), lemi_core::placement::Axis::Z, res, alpha_deg.to_radians());
        check_env(&p, n, seed)?;
    }

    /// Object impostors (TR sec. 2.1) from box and shaft view cells.
    #[test]
    fn object_keeps_the_guarantee(
        shaft in any::<bool>(),
        bounded in any::<bool>(),
        reach_frac in 0.01f64..3.0,
        nx in 0.5f64..20.0,
        ny in 0.0f64..20.0,
        m in 0.5f64..20.0,
        s_frac in 0.0f64..1.0,
        beta_deg in 5.0f64..90.0,
        t0 in 1.0f64..300.0,
        depth in 0.0f64..200.0,
        wx in 0.5f64..40.0,
        wy in 0.5f64..40.0,
        res in 8u32..512,
        alpha_deg in 0.02f64..2.0,
        seed in any::<u64>(),
    ) {
        let cell = if shaft {
            let apex_distance = t0 + depth / 2.0;
            ObjectCell::Shaft {
                apex_angle: beta_deg.to_radians(),
                apex_distance,
                reach: bounded.then_some(reach_frac * apex_distance),
            }
        } else {
            ObjectCell::Box { width: [nx, ny], depth: m }
        };
        let s = match cell {
            ObjectCell::Box { depth, .. } => s_frac * depth,
            ObjectCell::Shaft { .. } => s_frac * cell.near_width()[0],
        };
        // The TR's premise (sec. 2.1.1): the texture is never magnified, a texel subtends at most
        // α from the cell (Schaufler's rule); below it the one-texel spacing does not bound the
        // parallax between layers.
        let res = res.max(
            lemi_core::placement::schaufler_res(wx.max(wy), t0, alpha_deg.to_radians())
                .map_err(|e| TestCaseError::fail(e.to_string()))?,
        );
        let p = ObjectParams { cell, s, t0, depth, size: [wx, wy], res, alpha: alpha_deg.to_radians() };
        // A tiny object deep inside a very wide cell can need more than MAX_LAYERS layers (by the
        // one-texel spacing alone); that is a documented error, not a broken guarantee.
        let pl = match place_object_layers(&p) {
            Err(PlacementError::TooManyLayers { .. }) => return Ok(()),
            r => r.map_err(|e| TestCaseError::fail(e.to_string()))?,
        };
        // Viewpoints relative to the reference viewpoint; z toward the object.
        let views: Vec<DVec3> = match cell {
            ObjectCell::Box { width, depth } => {
                let c = DVec3::new(0.0, 0.0, s - depth / 2.0);
                box_views(DVec3::new(width[0] / 2.0, width[1] / 2.0, depth / 2.0), 6, seed)
                    .into_iter()
                    .map(|v| v + c)
                    .collect()
            }
            ObjectCell::Shaft { apex_angle, apex_distance, reach } => {
                shaft_views(s, apex_angle, apex_distance, reach, t0 + depth + s, seed)
            }
        };
        // Parallax and texel shifts are both checked from the whole cell (for a shaft: its near
        // border, the region behind it out to far beyond the object, random interior points).
        let k = [wx / (2.0 * (t0 + s)), wy / (2.0 * (t0 + s))];
        let picks: Vec<usize> = if pl.layers.len() <= 24 {
            (0..pl.layers.len()).collect()
        } else {
            let n = pl.layers.len();
            (0..8).chain(n / 2 - 4..n / 2 + 4).chain(n - 8..n).collect()
        };
        for &i in &picks {
            let l = pl.layers[i];
            for z in [l.near_border, l.far_border] {
                let a = max_parallax(&views, k, z + s, l.distance + s) / p.alpha;
                prop_assert!(a <= 1.0 + TOL, "parallax {a}·α at layer {i} ({l:?}) border {z} ({p:?})");
            }
            if i + 1 < pl.layers.len() {
                let far = pl.layers[i + 1].distance;
                let sh = max_texel_shift(&views, k, res, l.distance + s, far + s);
                prop_assert!(sh <= 1.0 + TOL, "texel shift {sh} between layers {i} and {} ({p:?})", i + 1);
            }
        }
    }
}
