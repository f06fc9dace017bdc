//! Tests of `builtin:interior`: parsing, determinism, budget, the layout (rooms, portals, building
//! box), the building standing clear of the city, the meshes (winding, no T-junction on a shared
//! plane), and brute-force rays: through every opening the way out is free, beside it the wall is
//! solid, and no ray leaves a room but through an opening.

use std::collections::HashMap;
use std::sync::OnceLock;

use glam::{DVec3, Vec3};
use lemi_core::Scene;
use lemi_scene::builtin::interior::{
    CEILING_Y, FLOOR_Y, INTERIOR_TRIANGLES, ROOM_MARGIN, WALL_THICKNESS,
};
use lemi_scene::builtin::{
    self, interior_layout, Builtin, BuiltinSpec, InteriorLayout, PortalKind,
    AVENUE_FREE_HALF_WIDTH, PLAZA_FREE_RADIUS,
};

fn build(spec: &str) -> Scene {
    match builtin::build(spec) {
        Ok(s) => s,
        Err(e) => panic!("{spec}: {e}"),
    }
}

fn spec(s: &str) -> BuiltinSpec {
    BuiltinSpec::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"))
}

fn layout() -> InteriorLayout {
    interior_layout(&spec("interior")).expect("interior has a layout")
}

/// One interior scene shared by the tests that only look at it.
fn scene() -> &'static Scene {
    static S: OnceLock<Scene> = OnceLock::new();
    S.get_or_init(|| build("interior:20k:1"))
}

/// Triangles of the meshes whose material name does (`true`) or does not start with `interior-`.
fn triangles(s: &Scene, interior: bool) -> Vec<[Vec3; 3]> {
    s.meshes
        .iter()
        .filter(|m| {
            s.materials[m.material as usize]
                .name
                .starts_with("interior-")
                == interior
        })
        .flat_map(|m| (0..m.triangle_count()).map(|t| m.triangle(t)))
        .collect()
}

fn v3(a: [f32; 3]) -> Vec3 {
    Vec3::from(a)
}

/// `n` directions spread evenly over the sphere (a golden-angle spiral).
fn sphere_directions(n: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            let a = golden * i as f64;
            DVec3::new(r * a.cos(), y, r * a.sin())
        })
        .collect()
}

/// The centre and the eight corners of the box `lo`–`hi`.
fn centre_and_corners(lo: DVec3, hi: DVec3) -> Vec<DVec3> {
    let mut eyes = vec![0.5 * (lo + hi)];
    for k in 0..8 {
        eyes.push(DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        ));
    }
    eyes
}

/// Möller–Trumbore: the ray parameter `t` where `o + t d` crosses the triangle, if it does.
fn ray_hit(o: DVec3, d: DVec3, tri: &[Vec3; 3]) -> Option<f64> {
    let [a, b, c] = tri.map(|p| p.as_dvec3());
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let s = o - a;
    let u = s.dot(p) / det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) / det)
}

#[test]
fn parses_interior_specs() {
    let d = spec("interior");
    assert_eq!(d.scene, Builtin::Interior);
    assert_eq!(d.normalized(), "builtin:interior:200000:1");
    let s = spec("interior:200k:3");
    assert_eq!(
        (s.scene, s.triangles, s.seed),
        (Builtin::Interior, 200_000, 3)
    );
    assert_eq!(spec("builtin:INTERIOR:10k").triangles, 10_000);
    assert!(Builtin::ALL.contains(&Builtin::Interior));
    assert_eq!(Builtin::Interior.name(), "interior");
    assert!(builtin::describe().contains("interior"));
    for name in ["city", "terrain", "forest"] {
        assert!(interior_layout(&spec(name)).is_none(), "{name}");
    }
    // The layout is the building's, whatever the budget and seed.
    assert_eq!(interior_layout(&spec("interior:50k:9")), Some(layout()));
    match BuiltinSpec::parse("interiors") {
        Err(e) => assert!(e.to_string().contains("interior"), "{e}"),
        Ok(_) => panic!("`interiors` accepted"),
    }
}

#[test]
fn same_spec_same_bits_and_the_city_is_the_city() {
    let a = build("interior:15k:11");
    let b = build("interior:15k:11");
    assert_eq!(a.meshes, b.meshes, "interior is not deterministic");
    assert_eq!(a.materials, b.materials);
    assert_eq!(a.textures, b.textures);
    // The city part is `builtin:city` of the same budget and seed, mesh for mesh.
    let city = build("city:15k:11");
    assert_eq!(a.meshes[..city.meshes.len()], city.meshes[..]);
    assert_eq!(a.materials[..city.materials.len()], city.materials[..]);
    assert!(a.meshes[city.meshes.len()..]
        .iter()
        .all(|m| a.materials[m.material as usize]
            .name
            .starts_with("interior-")));
    assert_eq!(
        a.triangle_count() - city.triangle_count(),
        INTERIOR_TRIANGLES
    );
}

#[test]
fn triangle_counts_follow_the_budget() {
    for n in [10_000u64, 100_000] {
        let s = build(&format!("interior:{n}:3"));
        let got = s.triangle_count() as f64;
        let err = (got - n as f64).abs() / n as f64;
        assert!(err <= 0.10, "interior:{n} gave {got} triangles");
        assert_eq!(s.stats.dropped_degenerate, 0);
        assert_eq!(s.stats.dropped_nonfinite, 0);
        assert_eq!(s.sources, vec![format!("builtin:interior:{n}:3")]);
    }
    assert_eq!(triangles(scene(), true).len() as u64, INTERIOR_TRIANGLES);
}

#[test]
fn portals_lie_on_their_rooms_walls_and_face_out() {
    let l = layout();
    assert_eq!(l.rooms.len(), 4);
    let doors = l.portals.iter().filter(|p| p.kind == PortalKind::Door);
    assert_eq!(doors.count(), 1);
    for (r, room) in l.rooms.iter().enumerate() {
        let n = l.portals.iter().filter(|p| p.room == r).count();
        assert!(n >= 1, "room {} has no portal", room.name);
    }
    for p in &l.portals {
        let room = &l.rooms[p.room];
        let out = v3(p.outward);
        assert_eq!(out.length(), 1.0, "{p:?}");
        let axis = out.abs().max_position();
        assert_ne!(axis, 1, "{p:?}: portals are in walls");
        let (lo, hi) = (v3(room.min), v3(room.max));
        let c = v3(p.center);
        // The outer face of the wall beyond the room's walkable box.
        let face = if out[axis] > 0.0 {
            hi[axis] + ROOM_MARGIN + WALL_THICKNESS
        } else {
            lo[axis] - ROOM_MARGIN - WALL_THICKNESS
        };
        assert!((c[axis] - face).abs() < 1e-4, "{p:?} is not on its wall");
        // ... which is the building's outer face on that side.
        let outer = if out[axis] > 0.0 {
            l.building_max[axis]
        } else {
            l.building_min[axis]
        };
        assert_eq!(c[axis], outer, "{p:?}");
        // Pointing away from the room.
        assert!((c - 0.5 * (lo + hi)).dot(out) > 0.0, "{p:?}");
        // Within the room's side of the wall: across, between its walls; up, floor to ceiling.
        let side = 2 - axis;
        let half = 0.5 * p.width;
        assert!(c[side] - half >= lo[side] - ROOM_MARGIN, "{p:?}");
        assert!(c[side] + half <= hi[side] + ROOM_MARGIN, "{p:?}");
        assert!(c.y - 0.5 * p.height >= FLOOR_Y - 1e-5, "{p:?}");
        assert!(c.y + 0.5 * p.height <= CEILING_Y, "{p:?}");
        let size = match p.kind {
            PortalKind::Window => (1.2, 1.4),
            PortalKind::Door => (1.0, 2.2),
        };
        assert!((p.width - size.0).abs() < 1e-5 && (p.height - size.1).abs() < 1e-5);
        if p.kind == PortalKind::Window {
            assert!(
                (c.y - 0.5 * p.height - (FLOOR_Y + 0.9)).abs() < 1e-5,
                "sill"
            );
        }
    }
}

#[test]
fn rooms_are_disjoint_and_inside_the_building() {
    let l = layout();
    let (bmin, bmax) = (v3(l.building_min), v3(l.building_max));
    for (i, a) in l.rooms.iter().enumerate() {
        let (lo, hi) = (v3(a.min), v3(a.max));
        assert!(lo.cmplt(hi).all(), "{a:?}");
        assert!(lo.cmpgt(bmin).all() && hi.cmplt(bmax).all(), "{a:?}");
        let size = hi - lo + 2.0 * ROOM_MARGIN;
        assert!((6.0..=10.0).contains(&size.x) && (6.0..=10.0).contains(&size.z));
        assert!((size.y - 3.0).abs() < 1e-4, "{a:?}");
        for b in &l.rooms[i + 1..] {
            let overlap = lo.cmplt(v3(b.max)).all() && v3(b.min).cmplt(hi).all();
            assert!(!overlap, "{a:?} overlaps {b:?}");
        }
    }
    // The building is where the rustdoc says, in the city's free avenue and plaza.
    assert_eq!(l.building_min, [12.0, 0.0, -7.3]);
    assert_eq!(l.building_max, [28.6, 9.4, 7.3]);
    assert!(bmax.z < AVENUE_FREE_HALF_WIDTH && bmin.z > -AVENUE_FREE_HALF_WIDTH);
    assert!(Vec3::new(bmax.x, 0.0, bmax.z).length() < PLAZA_FREE_RADIUS);
    // Every interior triangle is inside the building box, and the box is tight.
    let mut seen = (Vec3::MAX, Vec3::MIN);
    for t in triangles(scene(), true) {
        for p in t {
            assert!(p.cmpge(bmin).all() && p.cmple(bmax).all(), "{p}");
            seen = (seen.0.min(p), seen.1.max(p));
        }
    }
    assert_eq!(seen, (bmin, bmax));
}

#[test]
fn the_building_stands_clear_of_the_city() {
    let l = layout();
    let (bmin, bmax) = (v3(l.building_min), v3(l.building_max));
    for seed in [1, 2, 3] {
        let s = if seed == 1 {
            scene()
        } else {
            &build(&format!("interior:20k:{seed}"))
        };
        let mut ground = 0;
        for t in triangles(s, false) {
            let lo = t[0].min(t[1]).min(t[2]);
            let hi = t[0].max(t[1]).max(t[2]);
            if hi.y < 0.01 {
                ground += 1;
                continue;
            }
            let overlap = lo.cmplt(bmax).all() && bmin.cmplt(hi).all();
            assert!(!overlap, "seed {seed}: city triangle {t:?} in the building");
        }
        assert!(ground > 0);
    }
}

#[test]
fn faces_are_wound_with_their_normals() {
    let s = scene();
    for m in &s.meshes {
        if !s.materials[m.material as usize]
            .name
            .starts_with("interior-")
        {
            continue;
        }
        for t in 0..m.triangle_count() {
            let tri = m.triangle(t);
            let g = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
            let n: Vec3 = m.indices[3 * t..3 * t + 3]
                .iter()
                .map(|&i| Vec3::from(m.vertices[i as usize].normal))
                .sum();
            assert!(g.dot(n) > 0.0, "{tri:?} faces against its normals");
        }
    }
}

/// No vertex lies inside an edge of a triangle that shares its plane and facing: adjoining pieces
/// of one surface meet vertex to vertex, so rasterization leaves no pinholes along their seams.
#[test]
fn no_t_junctions_on_shared_planes() {
    let tris = triangles(scene(), true);
    // Group by plane: quantized unit normal and offset.
    let key = |t: &[Vec3; 3]| {
        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        let q = |x: f32| (x * 1e4).round() as i64;
        (q(n.x), q(n.y), q(n.z), q(n.dot(t[0])))
    };
    let mut planes: HashMap<_, Vec<[Vec3; 3]>> = HashMap::new();
    for t in &tris {
        planes.entry(key(t)).or_default().push(*t);
    }
    let mut seams = 0;
    for group in planes.values() {
        let verts: Vec<Vec3> = group.iter().flatten().copied().collect();
        for t in group {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let len = (b - a).length();
                for &v in &verts {
                    let s = (v - a).dot(b - a) / (len * len);
                    let off = (a + (b - a) * s - v).length();
                    if s > 1e-4 && s < 1.0 - 1e-4 && off < 1e-4 {
                        panic!("vertex {v} inside edge {a}–{b} of {t:?}");
                    }
                }
                seams += 1;
            }
        }
    }
    assert!(seams > 1000);
}

#[test]
fn openings_are_open_and_walls_beside_them_are_solid() {
    let l = layout();
    let tris = triangles(scene(), true);
    let hits = |o: DVec3, d: DVec3| -> Vec<f64> {
        tris.iter()
            .filter_map(|t| ray_hit(o, d, t))
            .filter(|&t| t > 1e-6)
            .collect()
    };
    let mut solid = 0;
    for p in &l.portals {
        let room = &l.rooms[p.room];
        let o = (0.5 * (v3(room.min) + v3(room.max))).as_dvec3();
        let c = v3(p.center).as_dvec3();
        // Through the opening: nothing of the building in the way, out to infinity.
        let h = hits(o, c - o);
        assert!(h.is_empty(), "{} to {p:?}: hits at t = {h:?}", room.name);
        // Beside it, at its centre height, 1 m past its edge: the wall.
        let out = v3(p.outward);
        let side = Vec3::new(out.z, 0.0, out.x).as_dvec3();
        for s in [-1.0, 1.0] {
            let target = c + side * s * (0.5 * p.width as f64 + 1.0);
            let (lo, hi) = (v3(room.min).as_dvec3(), v3(room.max).as_dvec3());
            let m = ROOM_MARGIN as f64;
            let axis = if side.x != 0.0 { 0 } else { 2 };
            let in_room = target[axis] > lo[axis] - m && target[axis] < hi[axis] + m;
            let in_opening = l.portals.iter().any(|q| {
                let qc = v3(q.center).as_dvec3();
                q.outward == p.outward && (target[axis] - qc[axis]).abs() < 0.5 * q.width as f64
            });
            if !in_room || in_opening {
                continue;
            }
            let h = hits(o, target - o);
            assert!(
                h.iter().any(|&t| t <= 1.0 + 1e-6),
                "{} toward the wall beside {p:?}: no wall (hits {h:?})",
                room.name
            );
            solid += 1;
        }
    }
    assert!(solid >= l.portals.len(), "only {solid} solid checks");
}

/// The rooms are closed but for their openings: from the centre and the corners of every room's
/// walkable box, a ray in any direction hits the building, or leaves its outline through a portal
/// (maybe another room's, after a doorway).
#[test]
fn rooms_are_closed_but_for_their_portals() {
    let l = layout();
    let tris = triangles(scene(), true);
    let dirs = sphere_directions(600);
    let (bmin, bmax) = (v3(l.building_min).as_dvec3(), v3(l.building_max).as_dvec3());
    let mut out = 0;
    for room in &l.rooms {
        for o in centre_and_corners(v3(room.min).as_dvec3(), v3(room.max).as_dvec3()) {
            for &d in &dirs {
                if tris
                    .iter()
                    .any(|t| ray_hit(o, d, t).is_some_and(|t| t > 1e-6))
                {
                    continue;
                }
                // Where the ray leaves the building's outline, it must be inside an opening.
                let exit = [(0, d.x), (2, d.z)]
                    .into_iter()
                    .filter(|&(_, v)| v != 0.0)
                    .map(|(a, v)| {
                        let face = if v > 0.0 { bmax[a] } else { bmin[a] };
                        ((face - o[a]) / v, a, v.signum())
                    })
                    .min_by(|x, y| x.0.total_cmp(&y.0));
                let Some((t, axis, sign)) = exit else {
                    panic!("{}: vertical ray {d} escapes", room.name);
                };
                let q = o + d * t;
                let through = l.portals.iter().any(|p| {
                    let (c, w) = (v3(p.center).as_dvec3(), v3(p.outward).as_dvec3());
                    let side = DVec3::new(w.z, 0.0, w.x);
                    w[axis] == sign
                        && (q - c).dot(side).abs() <= 0.5 * p.width as f64 + 1e-9
                        && (q.y - c.y).abs() <= 0.5 * p.height as f64 + 1e-9
                });
                assert!(through, "{}: ray from {o} along {d} escapes", room.name);
                out += 1;
            }
        }
    }
    assert!(out > 0, "no ray left through a portal");
}

#[test]
fn the_building_shares_the_city_facade_texture() {
    let s = scene();
    let texture = |name: &str| {
        let m = s.materials.iter().find(|m| m.name == name);
        m.and_then(|m| m.texture)
            .unwrap_or_else(|| panic!("{name}"))
    };
    assert_eq!(texture("interior-facade"), texture("city-facade"));
    let floor = &s.textures[texture("interior-floor") as usize];
    let distinct: std::collections::BTreeSet<&[u8]> = floor.rgba8.chunks(4).collect();
    assert!(distinct.len() > 20, "flat floor texture");
    assert_eq!(s.textures.len(), 5, "city's four and the floor boards");
}

/// Each room's `inside` in the enclosure is what the strategy culls rooms by: from the centre and
/// the corners of every room's walkable box, the first surface a ray meets before it leaves the
/// room's inside box touches that box, and a ray that leaves the box first leaves it through one
/// of the room's holes (an opening or a doorway).
#[test]
fn what_a_room_sees_directly_touches_its_inside() {
    let l = layout();
    let e = l.enclosure();
    assert!(e.validate().is_ok());
    let tris = triangles(scene(), true);
    let dirs = sphere_directions(600);
    let tol = 1e-4;
    let touches = |t: &[Vec3; 3], b: &lemi_core::Aabb| {
        let lo = t[0].min(t[1]).min(t[2]).as_dvec3();
        let hi = t[0].max(t[1]).max(t[2]).as_dvec3();
        (lo - b.max).max_element() <= tol && (b.min - hi).max_element() <= tol
    };
    // the holes of a room as (centre, across-axis, half width along the wall, half height)
    let holes = |k: usize| -> Vec<(DVec3, usize, f64, f64)> {
        let mut h: Vec<_> = l
            .portals
            .iter()
            .filter(|p| p.room == k)
            .map(|p| (v3(p.center), v3(p.outward), p.width, p.height))
            .collect();
        h.extend(
            l.doorways
                .iter()
                .filter(|d| d.rooms.contains(&k))
                .map(|d| (v3(d.center), v3(d.across), d.width, d.height)),
        );
        h.into_iter()
            .map(|(c, n, w, ht)| {
                let axis = if n.x.abs() > 0.5 { 0 } else { 2 };
                (c.as_dvec3(), axis, 0.5 * w as f64, 0.5 * ht as f64)
            })
            .collect()
    };
    let (mut direct, mut through) = (0, 0);
    for (k, room) in e.rooms.iter().enumerate() {
        let inside = room.inside.expect("builtin rooms know their inside");
        for o in centre_and_corners(room.walkable.min, room.walkable.max) {
            for &d in &dirs {
                // where the ray leaves the inside box, and through which face
                let (t_exit, axis) = (0..3)
                    .filter(|&a| d[a] != 0.0)
                    .map(|a| {
                        let face = if d[a] > 0.0 {
                            inside.max[a]
                        } else {
                            inside.min[a]
                        };
                        ((face - o[a]) / d[a], a)
                    })
                    .min_by(|x, y| x.0.total_cmp(&y.0))
                    .expect("a direction");
                let first = tris
                    .iter()
                    .filter_map(|t| ray_hit(o, d, t).filter(|&s| s > 1e-6).map(|s| (s, t)))
                    .min_by(|x, y| x.0.total_cmp(&y.0));
                if let Some((s, t)) = first.filter(|(s, _)| *s <= t_exit + tol) {
                    assert!(
                        touches(t, &inside),
                        "room {k}: from {o} along {d} the first surface, at {s}, does not touch \
                         its inside {inside:?}"
                    );
                    direct += 1;
                    continue;
                }
                let q = o + d * t_exit;
                let hole = holes(k).into_iter().any(|(c, across, hw, hh)| {
                    let along = 2 - across;
                    across == axis
                        && (q[along] - c[along]).abs() <= hw + tol
                        && (q.y - c.y).abs() <= hh + tol
                });
                assert!(
                    hole,
                    "room {k}: the ray from {o} along {d} leaves the inside at {q} not through a hole"
                );
                through += 1;
            }
        }
    }
    assert!(
        direct > 0 && through > 0,
        "{direct} direct, {through} through holes"
    );
}
