//! Tests of the built-in procedural scenes: spec parsing and errors, triangle budgets, determinism,
//! the city's free avenue and plaza (brute force over every triangle), spawn clearings, bounds,
//! winding, and colour/texture variety.

use std::collections::{BTreeSet, HashSet};
use std::hash::{DefaultHasher, Hash, Hasher};

use glam::Vec3;
use lemi_core::Scene;
use lemi_scene::builtin::{
    self, Builtin, BuiltinSpec, AVENUE_FREE_HALF_WIDTH, DEFAULT_SEED, DEFAULT_TRIANGLES,
    PLAZA_FREE_RADIUS, SPAWN_CLEAR_RADIUS,
};
use lemi_scene::SceneError;

fn build(spec: &str) -> Scene {
    match builtin::build(spec) {
        Ok(s) => s,
        Err(e) => panic!("{spec}: {e}"),
    }
}

/// A hash of every bit of geometry, colour and material assignment.
fn fingerprint(s: &Scene) -> u64 {
    let mut h = DefaultHasher::new();
    for m in &s.meshes {
        m.material.hash(&mut h);
        m.indices.hash(&mut h);
        for v in &m.vertices {
            for c in v.position.iter().chain(&v.normal).chain(&v.uv) {
                c.to_bits().hash(&mut h);
            }
            v.color.hash(&mut h);
        }
    }
    for t in &s.textures {
        t.rgba8.hash(&mut h);
    }
    h.finish()
}

fn material_named(s: &Scene, prefix: &str) -> HashSet<u32> {
    s.materials
        .iter()
        .enumerate()
        .filter(|(_, m)| m.name.starts_with(prefix))
        .map(|(i, _)| i as u32)
        .collect()
}

/// Horizontal distance from the origin to the triangle projected on the ground plane.
fn dist_xz_to_origin(t: &[Vec3; 3]) -> f32 {
    let p: Vec<glam::Vec2> = t.iter().map(|v| glam::Vec2::new(v.x, v.z)).collect();
    // Inside test (signs of the edge functions), for non-degenerate projections.
    let e = |a: glam::Vec2, b: glam::Vec2| (b - a).perp_dot(-a);
    let s = [e(p[0], p[1]), e(p[1], p[2]), e(p[2], p[0])];
    let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
    if area != 0.0 && (s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0)) {
        return 0.0;
    }
    let seg = |a: glam::Vec2, b: glam::Vec2| {
        let d = b - a;
        let t = if d.length_squared() > 0.0 {
            (-a).dot(d) / d.length_squared()
        } else {
            0.0
        };
        (a + d * t.clamp(0.0, 1.0)).length()
    };
    seg(p[0], p[1]).min(seg(p[1], p[2])).min(seg(p[2], p[0]))
}

#[test]
fn parses_specs_and_defaults() {
    let p = |s: &str| BuiltinSpec::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"));
    let d = p("city");
    assert_eq!(
        (d.scene, d.triangles, d.seed),
        (Builtin::City, DEFAULT_TRIANGLES, DEFAULT_SEED)
    );
    assert_eq!(d.normalized(), "builtin:city:200000:1");
    assert_eq!(p("city:200000").triangles, 200_000);
    assert_eq!(p("city:200k").triangles, 200_000);
    assert_eq!(p("terrain:1M:7").triangles, 1_000_000);
    assert_eq!(p("terrain:1M:7").seed, 7);
    assert_eq!(p("forest:1.5M").triangles, 1_500_000);
    assert_eq!(p("city::9").triangles, DEFAULT_TRIANGLES);
    assert_eq!(p("city::9").seed, 9);
    assert_eq!(
        p("builtin:forest:10k:0").normalized(),
        "builtin:forest:10000:0"
    );
    assert_eq!(p("city:100M").triangles, 100_000_000);
    assert_eq!(d.spawn_eye(), [0.0, 1.7, 0.0]);
}

#[test]
fn bad_specs_are_errors_naming_the_problem() {
    let cases = [
        ("", "missing"),
        ("town", "unknown scene `town`"),
        ("city:0", "positive"),
        ("city:5000", "minimum"),
        ("city:100.1M", "maximum"),
        ("city:1G", "not a number"),
        ("city:abc", "not a number"),
        ("city:NaN", "not a number"),
        ("city:inf", "not a number"),
        ("city:1e6", "not a number"),
        ("city:-5", "not a number"),
        ("city:1..5M", "not a number"),
        ("city:k", "not a number"),
        ("city:200k:x", "seed `x`"),
        ("city:200k:-1", "seed"),
        ("city:200k:1:2", "fields"),
    ];
    for (spec, needle) in cases {
        match builtin::build(spec) {
            Err(SceneError::BadBuiltin { spec: s, message }) => {
                assert_eq!(s, spec);
                assert!(message.contains(needle), "{spec}: {message}");
            }
            Err(e) => panic!("{spec}: wrong error {e}"),
            Ok(_) => panic!("{spec}: accepted"),
        }
    }
    assert!(!builtin::describe().is_empty());
}

#[test]
fn triangle_counts_follow_the_budget() {
    let mut sizes = vec![10_000u64, 100_000];
    if !cfg!(debug_assertions) {
        sizes.push(1_000_000);
    }
    for name in ["city", "terrain", "forest"] {
        for &n in &sizes {
            let s = build(&format!("{name}:{n}:3"));
            let got = s.triangle_count() as f64;
            let err = (got - n as f64).abs() / n as f64;
            assert!(err <= 0.10, "{name}:{n} gave {got} triangles");
            assert_eq!(s.stats.dropped_degenerate, 0, "{name}:{n}");
            assert_eq!(s.stats.dropped_nonfinite, 0, "{name}:{n}");
            assert_eq!(s.sources, vec![format!("builtin:{name}:{n}:3")]);
        }
        for seed in 20..28 {
            let got = build(&format!("{name}:25k:{seed}")).triangle_count();
            assert!(
                got.abs_diff(25_000) <= 2_500,
                "{name}:25k:{seed} gave {got}"
            );
        }
    }
}

#[test]
fn bigger_budgets_make_bigger_cities() {
    let small = build("city:20k:2").bounds.size();
    let large = build("city:200k:2").bounds.size();
    assert!(
        large.x > 2.0 * small.x && large.z > 2.0 * small.z,
        "{small} vs {large}"
    );
}

#[test]
fn same_spec_same_bits_other_seed_other_bits() {
    for name in ["city", "terrain", "forest"] {
        let a = fingerprint(&build(&format!("{name}:30k:11")));
        let b = fingerprint(&build(&format!("{name}:30k:11")));
        let c = fingerprint(&build(&format!("{name}:30k:12")));
        assert_eq!(a, b, "{name} is not deterministic");
        assert_ne!(a, c, "{name}: seeds 11 and 12 give the same scene");
    }
}

#[test]
fn city_keeps_avenue_and_plaza_free() {
    for seed in [1, 2, 3] {
        let s = build(&format!("city:150k:{seed}"));
        let mut tall = 0;
        for m in &s.meshes {
            for t in 0..m.triangle_count() {
                let tri = m.triangle(t);
                if tri.iter().all(|p| p.y <= 0.3) {
                    continue;
                }
                tall += 1;
                let zmin = tri.iter().map(|p| p.z).fold(f32::MAX, f32::min);
                let zmax = tri.iter().map(|p| p.z).fold(f32::MIN, f32::max);
                assert!(
                    zmin >= AVENUE_FREE_HALF_WIDTH || zmax <= -AVENUE_FREE_HALF_WIDTH,
                    "seed {seed}: triangle {tri:?} enters the avenue"
                );
                let d = dist_xz_to_origin(&tri);
                assert!(
                    d >= PLAZA_FREE_RADIUS,
                    "seed {seed}: {tri:?} at {d} m from the origin"
                );
            }
        }
        assert!(tall > 50_000, "seed {seed}: only {tall} raised triangles");
        // The avenue is really there: ground at y = 0 under the whole walkable strip.
        let b = s.bounds;
        assert!(b.min.x < -200.0 && b.max.x > 200.0);
    }
}

#[test]
fn bounds_are_sane_and_ground_is_at_zero() {
    for name in ["city", "terrain", "forest"] {
        let s = build(&format!("{name}:20k:5"));
        let b = s.bounds;
        assert!(b.min.is_finite() && b.max.is_finite(), "{name}");
        assert!(
            b.min.x < 0.0 && b.max.x > 0.0 && b.min.z < 0.0 && b.max.z > 0.0,
            "{name}"
        );
        // Centred on the origin.
        assert!((b.center().x.abs() / b.size().x) < 0.2, "{name}: {b:?}");
        assert!((b.center().z.abs() / b.size().z) < 0.2, "{name}: {b:?}");
        if name != "terrain" {
            assert_eq!(b.min.y, 0.0, "{name}: ground is not at y = 0");
        }
        assert!(b.max.y > 5.0 && b.max.y < 200.0, "{name}: {b:?}");
        // Some ground triangle covers the origin at height 0.
        let at_origin = s.meshes.iter().any(|m| {
            (0..m.triangle_count()).any(|t| {
                let tri = m.triangle(t);
                dist_xz_to_origin(&tri) == 0.0 && tri.iter().all(|p| p.y.abs() < 1e-3)
            })
        });
        assert!(at_origin, "{name}: no ground at y = 0 under the origin");
    }
}

#[test]
fn plants_keep_the_spawn_point_clear() {
    for name in ["terrain", "forest"] {
        for seed in [1, 4] {
            let s = build(&format!("{name}:60k:{seed}"));
            let plants: HashSet<u32> = material_named(&s, "tree-");
            assert_eq!(plants.len(), 2);
            let mut n = 0;
            for m in s.meshes.iter().filter(|m| plants.contains(&m.material)) {
                for t in 0..m.triangle_count() {
                    let d = dist_xz_to_origin(&m.triangle(t));
                    assert!(d >= SPAWN_CLEAR_RADIUS, "{name}:{seed}: plant at {d} m");
                    n += 1;
                }
            }
            assert!(n > 20_000, "{name}: only {n} plant triangles");
        }
    }
}

#[test]
fn faces_are_wound_with_their_normals() {
    for name in ["city", "terrain", "forest"] {
        let s = build(&format!("{name}:20k:8"));
        for m in &s.meshes {
            for t in 0..m.triangle_count() {
                let tri = m.triangle(t);
                let g = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
                let idx = &m.indices[3 * t..3 * t + 3];
                let n: Vec3 = idx
                    .iter()
                    .map(|&i| Vec3::from(m.vertices[i as usize].normal))
                    .sum();
                assert!(
                    g.dot(n) > 0.0,
                    "{name}: triangle {tri:?} faces against its normals"
                );
            }
        }
    }
}

#[test]
fn scenes_have_colour_and_texture_variety() {
    let s = build("city:50k:1");
    assert!(s.materials.len() <= 10, "{} materials", s.materials.len());
    assert!(s.textures.len() >= 3);
    for t in &s.textures {
        assert_eq!(
            t.rgba8.len(),
            (t.width * t.height * 4) as usize,
            "{}",
            t.name
        );
        let distinct: BTreeSet<&[u8]> = t.rgba8.chunks(4).collect();
        assert!(distinct.len() > 20, "{} is flat", t.name);
    }
    let colours = |prefix: &str| -> BTreeSet<[u8; 4]> {
        let mats = material_named(&s, prefix);
        s.meshes
            .iter()
            .filter(|m| mats.contains(&m.material))
            .flat_map(|m| m.vertices.iter().map(|v| v.color))
            .collect()
    };
    assert!(colours("city-facade").len() >= 30, "facade colours");
    assert!(colours("city-roof").len() >= 10, "roof colours");
    assert!(colours("tree-foliage").len() >= 100, "foliage colours");
    // Textured materials carry UVs that span many tiles (metres / tile size).
    for m in &s.meshes {
        let mat = &s.materials[m.material as usize];
        if mat.texture.is_some() && mat.name == "city-facade" {
            let umax = m.vertices.iter().map(|v| v.uv[0]).fold(0.0, f32::max);
            assert!(umax >= 1.0, "{}: u max {umax}", mat.name);
        }
    }
    // Building heights vary (2-40 m apart from landmarks) and some landmark rises above.
    let facade = material_named(&s, "city-facade");
    let mut tops = BTreeSet::new();
    for m in s.meshes.iter().filter(|m| facade.contains(&m.material)) {
        for v in &m.vertices {
            tops.insert((v.position[1] * 2.0) as i32);
        }
    }
    assert!(tops.len() > 30, "few distinct heights");
    assert!(
        s.bounds.max.y > 60.0,
        "no landmark: max y {}",
        s.bounds.max.y
    );
}

/// Draws a scene with a tiny CPU rasterizer (texture × vertex colour × Lambert) into a PNG, for a
/// person to look at: `LEMI_BUILTIN_PNG=/tmp cargo test -p lemi-scene --test builtin -- --ignored`.
#[test]
#[ignore = "writes pictures for a person to look at; set LEMI_BUILTIN_PNG=DIR and run with -- --ignored"]
fn draw_pictures() {
    let Some(dir) = std::env::var_os("LEMI_BUILTIN_PNG") else {
        eprintln!("set LEMI_BUILTIN_PNG to a directory to write pictures");
        return;
    };
    let dir = std::path::PathBuf::from(dir);
    for spec in ["city:200k:1", "terrain:200k:1", "forest:200k:1"] {
        let s = build(spec);
        let half = (s.bounds.size().x.max(s.bounds.size().z) * 0.5) as f32;
        let top = move |p: Vec3| Some((p.x / half, p.z / half, -p.y));
        let eye = Vec3::new(0.0, 1.7, 0.0);
        let persp = move |p: Vec3| {
            // Looking along +X, 90° horizontal field of view.
            let d = p - eye;
            (d.x > 0.1).then(|| (d.z / d.x, -d.y / d.x, d.x))
        };
        let name = spec.replace(':', "_");
        println!("{spec}: bounds {:?}", s.bounds);
        raster(&s, &top, 1024, &dir.join(format!("{name}_top.png")));
        raster(&s, &persp, 1024, &dir.join(format!("{name}_eye.png")));
    }
    // The interior: from the plaza towards the door, and from each room through its openings.
    let spec = "interior:200k:1";
    let s = build(spec);
    let look = |eye: Vec3, f: Vec3| {
        let r = f.cross(Vec3::Y);
        move |p: Vec3| {
            let d = p - eye;
            let z = d.dot(f);
            (z > 0.1).then(|| (d.dot(r) / z, -d.y / z, z))
        }
    };
    let mut views = vec![("plaza".to_string(), Vec3::new(0.0, 1.7, -3.6), Vec3::X)];
    if let Some(l) = builtin::interior_layout(&BuiltinSpec::parse(spec).expect("spec")) {
        for (i, p) in l.portals.iter().enumerate() {
            let room = &l.rooms[p.room];
            let eye = 0.5 * (Vec3::from(room.min) + Vec3::from(room.max));
            views.push((format!("{}_{i}", room.name), eye, Vec3::from(p.outward)));
        }
    }
    for (what, eye, f) in views {
        let path = dir.join(format!("interior_{what}.png"));
        raster(&s, &look(eye, f), 768, &path);
    }
}

fn raster(
    s: &Scene,
    proj: &dyn Fn(Vec3) -> Option<(f32, f32, f32)>,
    n: u32,
    path: &std::path::Path,
) {
    let mut img = vec![[140u8, 180, 230]; (n * n) as usize];
    let mut depth = vec![f32::MAX; (n * n) as usize];
    let light = Vec3::new(0.4, 0.8, 0.3).normalize();
    for m in &s.meshes {
        let mat = &s.materials[m.material as usize];
        let tex = mat.texture.map(|t| &s.textures[t as usize]);
        for t in 0..m.triangle_count() {
            let idx = &m.indices[3 * t..3 * t + 3];
            let v: Vec<_> = idx.iter().map(|&i| m.vertices[i as usize]).collect();
            let Some(p) = v
                .iter()
                .map(|v| proj(Vec3::from(v.position)))
                .collect::<Option<Vec<_>>>()
            else {
                continue;
            };
            let sx =
                |q: (f32, f32, f32)| ((q.0 * 0.5 + 0.5) * n as f32, (q.1 * 0.5 + 0.5) * n as f32);
            let a = sx(p[0]);
            let b = sx(p[1]);
            let c = sx(p[2]);
            let area = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
            if area.abs() < 1e-9 {
                continue;
            }
            let x0 = a.0.min(b.0).min(c.0).floor().max(0.0) as i64;
            let x1 = a.0.max(b.0).max(c.0).ceil().min(n as f32 - 1.0) as i64;
            let y0 = a.1.min(b.1).min(c.1).floor().max(0.0) as i64;
            let y1 = a.1.max(b.1).max(c.1).ceil().min(n as f32 - 1.0) as i64;
            let nrm = Vec3::from(v[0].normal);
            let lit = 0.35 + 0.65 * nrm.dot(light).max(0.0);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                    let w0 = ((b.0 - px) * (c.1 - py) - (b.1 - py) * (c.0 - px)) / area;
                    let w1 = ((c.0 - px) * (a.1 - py) - (c.1 - py) * (a.0 - px)) / area;
                    let w2 = 1.0 - w0 - w1;
                    if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                        continue;
                    }
                    let z = w0 * p[0].2 + w1 * p[1].2 + w2 * p[2].2;
                    let k = (y as u32 * n + x as u32) as usize;
                    if z >= depth[k] {
                        continue;
                    }
                    depth[k] = z;
                    let mut col: [f32; 3] = std::array::from_fn(|ch| {
                        (w0 * v[0].color[ch] as f32
                            + w1 * v[1].color[ch] as f32
                            + w2 * v[2].color[ch] as f32)
                            / 255.0
                    });
                    if let Some(tx) = tex {
                        let u = w0 * v[0].uv[0] + w1 * v[1].uv[0] + w2 * v[2].uv[0];
                        let vv = w0 * v[0].uv[1] + w1 * v[1].uv[1] + w2 * v[2].uv[1];
                        let ix = ((u.rem_euclid(1.0)) * tx.width as f32) as u32 % tx.width;
                        let iy = ((vv.rem_euclid(1.0)) * tx.height as f32) as u32 % tx.height;
                        let o = ((iy * tx.width + ix) * 4) as usize;
                        for (ch, c) in col.iter_mut().enumerate() {
                            let srgb = tx.rgba8[o + ch] as f32 / 255.0;
                            *c *= srgb.powf(2.2);
                        }
                    }
                    img[k] = col.map(|c| ((c * lit).clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0) as u8);
                }
            }
        }
    }
    let flat: Vec<u8> = img.into_iter().flatten().collect();
    let buf = image::RgbImage::from_raw(n, n, flat).expect("image size");
    buf.save(path).expect("write png");
    println!("wrote {}", path.display());
}

proptest::proptest! {
    /// Any text is either a valid spec or a `BadBuiltin` error, never a panic.
    #[test]
    fn parsing_never_panics(s in "\\PC{0,24}") {
        match BuiltinSpec::parse(&s) {
            Ok(p) => proptest::prop_assert!((10_000..=100_000_000).contains(&p.triangles)),
            Err(e) => {
                let bad = matches!(e, SceneError::BadBuiltin { .. });
                proptest::prop_assert!(bad, "wrong error kind: {}", e)
            }
        }
    }

    /// Counts in range round-trip through plain, `k` and `M` forms.
    #[test]
    fn counts_round_trip(n in 10_000u64..=100_000_000, seed in proptest::prelude::any::<u64>()) {
        let p = BuiltinSpec::parse(&format!("forest:{n}:{seed}")).map_err(|e| proptest::test_runner::TestCaseError::fail(e.to_string()))?;
        proptest::prop_assert_eq!((p.triangles, p.seed), (n, seed));
        let k = BuiltinSpec::parse(&format!("city:{}k", n / 1000)).map_err(|e| proptest::test_runner::TestCaseError::fail(e.to_string()))?;
        proptest::prop_assert_eq!(k.triangles, n / 1000 * 1000);
        let m = BuiltinSpec::parse(&format!("city:{}M", n as f64 / 1e6)).map_err(|e| proptest::test_runner::TestCaseError::fail(e.to_string()))?;
        proptest::prop_assert_eq!(m.triangles, n);
    }
}
