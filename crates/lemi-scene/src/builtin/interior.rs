//! The `interior` built-in scene: the `city` of the same budget and seed, plus one small building
//! whose ground-floor rooms a viewer may stand in, seeing the street through windows and a door.
//!
//! It serves portal impostors (TR-186-2-02-04 sec. 3; Rafferty, Aliaga, Lastra 1998, "3D image
//! warping in architectural walkthroughs", replacing the geometry seen through a portal by an
//! image): each opening from a room to the outside is a [`Portal`], the room's walkable box
//! ([`Room`]) is its view cell, and what lies beyond the opening is the object to bake.
//!
//! **Where.** The building stands on the city's main avenue, east of the origin: outer walls
//! `x ∈ [12.0, 28.6]`, `z ∈ [−7.3, 7.3]`, on the ground (`y = 0`), eaves at 6.6 m, hipped roof to
//! 9.4 m. That place is free in every city: the city puts no building or tree within
//! `|z| <` [`AVENUE_FREE_HALF_WIDTH`] (15 m), nor within [`PLAZA_FREE_RADIUS`] (40 m) of the
//! origin: there it lays only ground at `y = 0` (cobbles, asphalt), which the building stands on.
//! The building's farthest corner is 29.5 m from the origin, its long sides 7.7 m inside the free
//! avenue's edges. The origin itself stays free (12 m from the west wall), so the spawn point of
//! [`super::BuiltinSpec::spawn_eye`] is unchanged; it faces the building's door.
//!
//! **Plan.** Two storeys high, one floor inside: four rooms of 8.0 × 7.0 m (west = −X, south = −Z)
//! around a cross of interior walls, floor at 0.15 m, ceiling at 3.15 m; the upper storey is a closed
//! void under the roof. Walls are 0.2 m thick solids. Every room has two outer walls with one
//! opening each: windows 1.2 × 1.4 m with the sill 0.9 m above the floor, and in the south-west
//! room's west wall the door, 1.0 × 2.2 m, facing the origin. Doorways of 1.0 × 2.2 m join
//! south-west to south-east, north-west to north-east and south-west to north-west. The layout
//! does not depend on the seed or the budget; the city does, and the triangle budget is the city's
//! (the building adds [`INTERIOR_TRIANGLES`] on top).
//!
//! **Meshes.** Each wall is a box with rectangular holes, cut into columns at the holes' edges and
//! rows at their sills and heads; every piece is triangulated with the vertices its neighbours put
//! on its sides (columns beside a window get the window's sill and head), so no vertex lies inside
//! another triangle's edge on a shared plane (no T-junction cracks): faces, reveals (the 0.2 m sides
//! of every opening), end caps and top caps close each wall. A wall has no face where it is sealed
//! by the surface it meets: none at an end that butts into another wall, none at its foot on the
//! ground. Floors carry the doorways' edges so thresholds meet them vertex to vertex.
//!
//! Materials follow the city's conventions (base colour × texture × vertex colour, UVs in metres
//! over tile size): `interior-facade` (the city's facade texture, painted windows on the closed
//! upper storey), `interior-roof`, `interior-plaster` (walls, reveals, ceilings) and
//! `interior-floor` (wooden boards).

use glam::{DVec3, Vec3};
use lemi_core::enclosure::{Doorway as EnclosedDoorway, Enclosure, Room as EnclosedRoom};
use lemi_core::{Aabb, Material, SceneBuilder};

#[cfg(doc)]
use super::{AVENUE_FREE_HALF_WIDTH, PLAZA_FREE_RADIUS};

use super::geom::{facade_u, facade_v, Buf, Emitter};
use super::rng::shade;
use super::textures;

/// Thickness of every wall (m).
pub const WALL_THICKNESS: f32 = 0.2;
/// Height of the floor's top above the ground (m).
pub const FLOOR_Y: f32 = 0.15;
/// Height of the rooms' ceilings (m): 3 m above the floor.
pub const CEILING_Y: f32 = 3.15;
/// Height of the eaves: the top of the walls (m).
pub const EAVES_Y: f32 = 6.6;
/// Rise of the hipped roof above the eaves (m).
pub const ROOF_RISE: f32 = 2.8;
/// Margin between a room's walls, floor or ceiling and its walkable box (m).
pub const ROOM_MARGIN: f32 = 0.3;
/// Triangles the building adds to the city.
pub const INTERIOR_TRIANGLES: u64 = 506;

/// Wall planes along X, west to east: outer wall, room, interior wall, room, outer wall.
const XS: [f32; 6] = [12.0, 12.2, 20.2, 20.4, 28.4, 28.6];
/// Wall planes along Z, south to north.
const ZS: [f32; 6] = [-7.3, -7.1, -0.1, 0.1, 7.1, 7.3];
const WINDOW_W: f32 = 1.2;
const WINDOW_Y0: f32 = 1.05;
const WINDOW_Y1: f32 = 2.45;
const DOOR_W: f32 = 1.0;
const DOOR_Y1: f32 = 2.35;
/// Centre of the doorway between the two west rooms, along X.
const DOORWAY_WEST_X: f32 = 18.5;
/// Centres of the doorways between the south rooms and between the north rooms, along Z.
const DOORWAY_SOUTH_Z: f32 = -2.0;
const DOORWAY_NORTH_Z: f32 = 2.0;
/// Boards of the floor texture repeat every this many metres.
const FLOOR_TILE: f32 = 2.0;

// Buffers of the building, in the order its materials are added.
const FACADE: usize = 0;
const ROOF: usize = 1;
const PLASTER: usize = 2;
const FLOOR: usize = 3;
const MATERIALS: usize = 4;

/// One room's walkable inside: the box a viewer's eye may occupy ([`ROOM_MARGIN`] from its walls,
/// floor and ceiling).
#[derive(Clone, Debug, PartialEq)]
pub struct Room {
    /// `south-west`, `south-east`, `north-west` or `north-east` (west = −X, south = −Z).
    pub name: String,
    pub min: [f32; 3],
    pub max: [f32; 3],
}

/// What an opening to the outside is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PortalKind {
    Window,
    Door,
}

/// An opening from a room to the outside: a `width` × `height` rectangle in the plane of the
/// wall's outer face, centred on `center`, `outward` the unit axis-aligned normal pointing out of
/// the building. Everything beyond that plane, seen through the rectangle, is outside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Portal {
    /// Index into [`InteriorLayout::rooms`].
    pub room: usize,
    pub kind: PortalKind,
    /// Centre of the opening, on the plane of the wall's outer face.
    pub center: [f32; 3],
    /// Horizontal size of the opening, along the wall (m).
    pub width: f32,
    /// Vertical size of the opening (m).
    pub height: f32,
    /// Unit normal of the wall, pointing out of the building: one of ±X, ±Z.
    pub outward: [f32; 3],
}

/// A doorway between two rooms: a `width` × `height` rectangle centred on `center` in the plane of
/// one face of its wall, whose unit normal is `across` (±X or ±Z).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Doorway {
    /// Indices into [`InteriorLayout::rooms`].
    pub rooms: [usize; 2],
    pub center: [f32; 3],
    pub width: f32,
    pub height: f32,
    pub across: [f32; 3],
}

/// The building of `builtin:interior`: its rooms, its openings to the outside and its outer box.
#[derive(Clone, Debug, PartialEq)]
pub struct InteriorLayout {
    pub rooms: Vec<Room>,
    /// Every opening to the outside, ordered by room.
    pub portals: Vec<Portal>,
    /// The doorways between rooms.
    pub doorways: Vec<Doorway>,
    /// Corner of the building's bounding box (walls, floor, roof) with the smallest coordinates.
    pub building_min: [f32; 3],
    /// Corner of the building's bounding box with the largest coordinates.
    pub building_max: [f32; 3],
}

impl InteriorLayout {
    /// The building as an [`Enclosure`]: its box a millimetre larger (so that rounding keeps its
    /// walls inside), its rooms' walkable boxes and the rectangles of all its openings to the
    /// outside. The walls, floors, ceilings and roof close it but for those openings (the module
    /// docs), which is what an enclosure promises.
    pub fn enclosure(&self) -> Enclosure {
        let v = |a: [f32; 3]| DVec3::from_array(a.map(f64::from));
        // the corners of a rectangle in a vertical plane of normal `normal`
        let rect = |center: [f32; 3], normal: [f32; 3], width: f32, height: f32| {
            let c = v(center);
            let along = DVec3::Y.cross(v(normal)) * (0.5 * f64::from(width));
            let up = DVec3::Y * (0.5 * f64::from(height));
            [
                c - along - up,
                c + along - up,
                c + along + up,
                c - along + up,
            ]
        };
        Enclosure {
            bounds: Aabb::new(
                v(self.building_min) - DVec3::splat(1e-3),
                v(self.building_max) + DVec3::splat(1e-3),
            ),
            rooms: self
                .rooms
                .iter()
                .enumerate()
                .map(|(k, r)| EnclosedRoom {
                    walkable: Aabb::new(v(r.min), v(r.max)),
                    // the walkable box keeps ROOM_MARGIN from the walls', floor's and ceiling's
                    // inner faces
                    inside: Some(Aabb::new(
                        v(r.min) - DVec3::splat(f64::from(ROOM_MARGIN)),
                        v(r.max) + DVec3::splat(f64::from(ROOM_MARGIN)),
                    )),
                    openings: self
                        .portals
                        .iter()
                        .filter(|p| p.room == k)
                        .map(|p| rect(p.center, p.outward, p.width, p.height))
                        .collect(),
                })
                .collect(),
            doorways: self
                .doorways
                .iter()
                .map(|d| EnclosedDoorway {
                    rooms: d.rooms,
                    corners: rect(d.center, d.across, d.width, d.height),
                })
                .collect(),
        }
    }
}

/// The rooms and portals of a spec's building: `Some` for `builtin:interior` (whatever its budget
/// and seed: the building is the same), `None` for every other scene.
pub fn interior_layout(spec: &super::BuiltinSpec) -> Option<InteriorLayout> {
    (spec.scene == super::Builtin::Interior).then(layout)
}

/// Which way a wall runs.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Run {
    X,
    Z,
}

/// A rectangular hole through a wall: `a` along the wall, `y` up.
#[derive(Clone, Copy, Debug)]
struct Hole {
    a0: f32,
    a1: f32,
    y0: f32,
    y1: f32,
    kind: Option<PortalKind>,
    /// For openings to the outside: the room they belong to.
    room: usize,
}

/// A straight wall: a box `a0..a1` along its run, `c0..c1` across, `0..EAVES_Y` up, with holes.
#[derive(Clone, Debug)]
struct Wall {
    run: Run,
    a0: f32,
    a1: f32,
    c0: f32,
    c1: f32,
    holes: Vec<Hole>,
    /// End caps at `a0` and `a1` (walls that butt into another wall have none).
    caps: bool,
    /// Outer walls: the side facing out, −1 (the face at `c0`) or +1 (at `c1`); 0 inside.
    outside: i8,
    /// Where other walls butt into this one: `(a, side)`, side −1 at `c0`, +1 at `c1`.
    butts: Vec<(f32, i8)>,
}

impl Wall {
    /// World point of wall coordinates (along, up, across).
    fn at(&self, a: f32, y: f32, c: f32) -> Vec3 {
        match self.run {
            Run::X => Vec3::new(a, y, c),
            Run::Z => Vec3::new(c, y, a),
        }
    }
    fn along(&self) -> Vec3 {
        match self.run {
            Run::X => Vec3::X,
            Run::Z => Vec3::Z,
        }
    }
    fn across(&self) -> Vec3 {
        match self.run {
            Run::X => Vec3::Z,
            Run::Z => Vec3::X,
        }
    }
    /// Horizontal bands: outer walls change material at the ceiling height.
    fn bands(&self) -> Vec<f32> {
        if self.outside != 0 {
            vec![0.0, CEILING_Y, EAVES_Y]
        } else {
            vec![0.0, EAVES_Y]
        }
    }
}

/// Rooms as (name, x range index, z range index into [`XS`] / [`ZS`]).
const ROOMS: [(&str, usize, usize); 4] = [
    ("south-west", 1, 1),
    ("south-east", 3, 1),
    ("north-west", 1, 3),
    ("north-east", 3, 3),
];

/// Inner rectangle of room `r`: `(x0, x1, z0, z1)`, the faces of its walls.
fn room_rect(r: usize) -> (f32, f32, f32, f32) {
    let (_, i, j) = ROOMS[r];
    (XS[i], XS[i + 1], ZS[j], ZS[j + 1])
}

fn mid(a: f32, b: f32) -> f32 {
    0.5 * (a + b)
}

fn window(centre: f32, room: usize) -> Hole {
    Hole {
        a0: centre - 0.5 * WINDOW_W,
        a1: centre + 0.5 * WINDOW_W,
        y0: WINDOW_Y0,
        y1: WINDOW_Y1,
        kind: Some(PortalKind::Window),
        room,
    }
}

fn door(centre: f32, kind: Option<PortalKind>, room: usize) -> Hole {
    Hole {
        a0: centre - 0.5 * DOOR_W,
        a1: centre + 0.5 * DOOR_W,
        y0: FLOOR_Y,
        y1: DOOR_Y1,
        kind,
        room,
    }
}

/// The seven walls: four outer (south and north run the full length and are capped at the
/// corners; west and east butt into them), the interior wall along X between the outer west and
/// east walls, and two interior walls along Z butting into it.
fn walls() -> Vec<Wall> {
    let (xw, xe) = (mid(XS[1], XS[2]), mid(XS[3], XS[4]));
    let (zs, zn) = (mid(ZS[1], ZS[2]), mid(ZS[3], ZS[4]));
    let outer_x = |c0: f32, c1: f32, outside: i8, holes: Vec<Hole>| Wall {
        run: Run::X,
        a0: XS[0],
        a1: XS[5],
        c0,
        c1,
        holes,
        caps: true,
        outside,
        butts: vec![
            (XS[1], -outside),
            (XS[2], -outside),
            (XS[3], -outside),
            (XS[4], -outside),
        ],
    };
    let outer_z = |c0: f32, c1: f32, outside: i8, holes: Vec<Hole>| Wall {
        run: Run::Z,
        a0: ZS[1],
        a1: ZS[4],
        c0,
        c1,
        holes,
        caps: false,
        outside,
        butts: vec![(ZS[2], -outside), (ZS[3], -outside)],
    };
    let inner = |run: Run, a0: f32, a1: f32, c0: f32, c1: f32, holes: Vec<Hole>, butts| Wall {
        run,
        a0,
        a1,
        c0,
        c1,
        holes,
        caps: false,
        outside: 0,
        butts,
    };
    vec![
        outer_x(ZS[0], ZS[1], -1, vec![window(xw, 0), window(xe, 1)]),
        outer_x(ZS[4], ZS[5], 1, vec![window(xw, 2), window(xe, 3)]),
        outer_z(
            XS[0],
            XS[1],
            -1,
            vec![door(zs, Some(PortalKind::Door), 0), window(zn, 2)],
        ),
        outer_z(XS[4], XS[5], 1, vec![window(zs, 1), window(zn, 3)]),
        inner(
            Run::X,
            XS[1],
            XS[4],
            ZS[2],
            ZS[3],
            vec![door(DOORWAY_WEST_X, None, 0)],
            vec![(XS[2], -1), (XS[3], -1), (XS[2], 1), (XS[3], 1)],
        ),
        inner(
            Run::Z,
            ZS[1],
            ZS[2],
            XS[2],
            XS[3],
            vec![door(DOORWAY_SOUTH_Z, None, 0)],
            vec![],
        ),
        inner(
            Run::Z,
            ZS[3],
            ZS[4],
            XS[2],
            XS[3],
            vec![door(DOORWAY_NORTH_Z, None, 2)],
            vec![],
        ),
    ]
}

fn layout() -> InteriorLayout {
    let rooms = (0..ROOMS.len())
        .map(|r| {
            let (x0, x1, z0, z1) = room_rect(r);
            let m = ROOM_MARGIN;
            Room {
                name: ROOMS[r].0.to_string(),
                min: [x0 + m, FLOOR_Y + m, z0 + m],
                max: [x1 - m, CEILING_Y - m, z1 - m],
            }
        })
        .collect();
    let mut portals = Vec::new();
    for w in walls() {
        for h in &w.holes {
            let Some(kind) = h.kind else { continue };
            let c = if w.outside < 0 { w.c0 } else { w.c1 };
            let out = w.across() * w.outside as f32;
            portals.push(Portal {
                room: h.room,
                kind,
                center: w.at(mid(h.a0, h.a1), mid(h.y0, h.y1), c).to_array(),
                width: h.a1 - h.a0,
                height: h.y1 - h.y0,
                outward: out.to_array(),
            });
        }
    }
    portals.sort_by_key(|p| p.room);
    // the rooms on either side of each interior hole: those whose inner rectangle holds a point
    // half a wall beyond each face
    let mut doorways = Vec::new();
    for w in walls().iter().filter(|w| w.outside == 0) {
        for h in &w.holes {
            let a = mid(h.a0, h.a1);
            let room_at = |c: f32| {
                let p = w.at(a, FLOOR_Y + 1.0, c);
                (0..ROOMS.len()).find(|&r| {
                    let (x0, x1, z0, z1) = room_rect(r);
                    (x0..=x1).contains(&p.x) && (z0..=z1).contains(&p.z)
                })
            };
            let t = 0.5 * WALL_THICKNESS;
            if let (Some(r0), Some(r1)) = (room_at(w.c0 - t), room_at(w.c1 + t)) {
                doorways.push(Doorway {
                    rooms: [r0, r1],
                    center: w.at(a, mid(h.y0, h.y1), w.c0).to_array(),
                    width: h.a1 - h.a0,
                    height: h.y1 - h.y0,
                    across: w.across().to_array(),
                });
            }
        }
    }
    InteriorLayout {
        rooms,
        portals,
        doorways,
        building_min: [XS[0], 0.0, ZS[0]],
        building_max: [XS[5], EAVES_Y + ROOF_RISE, ZS[5]],
    }
}

/// Colours of the building.
struct Look {
    outside: [u8; 4],
    inside: [u8; 4],
    ceiling: [u8; 4],
    wood: [u8; 4],
    roof: [u8; 4],
}

const LOOK: Look = Look {
    outside: [214, 170, 96, 255],
    inside: [238, 232, 218, 255],
    ceiling: [246, 244, 238, 255],
    wood: [172, 118, 72, 255],
    roof: [168, 72, 48, 255],
};

/// `lo`, the values of `v` strictly between `lo` and `hi`, and `hi`: sorted, without repeats.
fn span(lo: f32, hi: f32, v: impl IntoIterator<Item = f32>) -> Vec<f32> {
    let mut out: Vec<f32> = v.into_iter().filter(|&x| x > lo && x < hi).collect();
    out.push(lo);
    out.push(hi);
    out.sort_by(f32::total_cmp);
    out.dedup();
    out
}

/// Vertices along one side of a patch: (position along the side, vertex index).
type Chain = Vec<(f32, u32)>;

/// The rectangle `[u0, u1] × [v0, v1]` of a plane, `map` taking `(u, v)` to the world, triangulated
/// through the vertices its neighbours put on its sides: `left` (the `v` values on `u = u0`, sorted,
/// `v0` and `v1` included), `right` (on `u = u1`), `bottom` (the `u` values on `v = v0`) and `top`.
/// With extra vertices on two opposite sides at most, two chains are zipped together (n − 2
/// triangles for n vertices); otherwise it is a fan around the centre (n triangles).
#[allow(clippy::too_many_arguments)]
fn patch(
    buf: &mut Buf,
    map: &dyn Fn(f32, f32) -> Vec3,
    n: Vec3,
    uv: &dyn Fn(Vec3) -> [f32; 2],
    c: [u8; 4],
    left: &[f32],
    right: &[f32],
    bottom: &[f32],
    top: &[f32],
) {
    let (u0, u1) = (bottom[0], bottom[bottom.len() - 1]);
    let (v0, v1) = (left[0], left[left.len() - 1]);
    let mut vert = |u: f32, v: f32| {
        let p = map(u, v);
        buf.vert(p, n, uv(p), c)
    };
    let chains: Option<(Chain, Chain)> = if bottom.len() == 2 && top.len() == 2 {
        Some((
            left.iter().map(|&v| (v, vert(u0, v))).collect(),
            right.iter().map(|&v| (v, vert(u1, v))).collect(),
        ))
    } else if left.len() == 2 && right.len() == 2 {
        Some((
            bottom.iter().map(|&u| (u, vert(u, v0))).collect(),
            top.iter().map(|&u| (u, vert(u, v1))).collect(),
        ))
    } else {
        None
    };
    let mut tris = Vec::new();
    match chains {
        Some((p, q)) => {
            let (mut i, mut j) = (0, 0);
            while i + 1 < p.len() || j + 1 < q.len() {
                if j + 1 == q.len() || (i + 1 < p.len() && p[i + 1].0 <= q[j + 1].0) {
                    tris.push([p[i].1, p[i + 1].1, q[j].1]);
                    i += 1;
                } else {
                    tris.push([p[i].1, q[j + 1].1, q[j].1]);
                    j += 1;
                }
            }
        }
        None => {
            // Around the boundary, counter-clockwise in (u, v), each corner once.
            let mut ring: Vec<u32> = bottom.iter().map(|&u| vert(u, v0)).collect();
            ring.extend(right[1..].iter().map(|&v| vert(u1, v)));
            ring.extend(top[..top.len() - 1].iter().rev().map(|&u| vert(u, v1)));
            ring.extend(left[1..left.len() - 1].iter().rev().map(|&v| vert(u0, v)));
            let centre = vert(mid(u0, u1), mid(v0, v1));
            for k in 0..ring.len() {
                tris.push([centre, ring[k], ring[(k + 1) % ring.len()]]);
            }
        }
    }
    for [a, b, d] in tris {
        buf.tri(a, b, d, n);
    }
}

/// A plain quad `[u0, u1] × [v0, v1]` of a plane.
fn plain(
    buf: &mut Buf,
    map: &dyn Fn(f32, f32) -> Vec3,
    n: Vec3,
    uv: &dyn Fn(Vec3) -> [f32; 2],
    c: [u8; 4],
    (u0, u1): (f32, f32),
    (v0, v1): (f32, f32),
) {
    patch(
        buf,
        map,
        n,
        uv,
        c,
        &[v0, v1],
        &[v0, v1],
        &[u0, u1],
        &[u0, u1],
    );
}

fn no_uv(_: Vec3) -> [f32; 2] {
    [0.0, 0.0]
}

fn floor_uv(p: Vec3) -> [f32; 2] {
    [p.x / FLOOR_TILE, p.z / FLOOR_TILE]
}

/// Emits one wall: its two faces piece by piece, the reveals of its holes, its caps.
fn emit_wall(w: &Wall, e: &mut Emitter) {
    let bands = w.bands();
    // Per band: the column lines, and per column the row lines (band edges, holes' sills, heads).
    let mut ulines: Vec<Vec<f32>> = Vec::new();
    let mut cuts: Vec<Vec<Vec<f32>>> = Vec::new();
    for b in 0..bands.len() - 1 {
        let (y0, y1) = (bands[b], bands[b + 1]);
        let inside: Vec<&Hole> = w
            .holes
            .iter()
            .filter(|h| h.y0 >= y0 && h.y1 <= y1)
            .collect();
        let u = span(w.a0, w.a1, inside.iter().flat_map(|h| [h.a0, h.a1]));
        let c = u
            .windows(2)
            .map(|s| {
                span(
                    y0,
                    y1,
                    inside
                        .iter()
                        .filter(|h| h.a0 <= s[0] && s[1] <= h.a1)
                        .flat_map(|h| [h.y0, h.y1]),
                )
            })
            .collect();
        ulines.push(u);
        cuts.push(c);
    }
    let top_band = bands.len() - 2;
    let along = w.along();
    let across = w.across();
    // Caps and reveals: the outer colour on outer walls.
    let trim = if w.outside != 0 {
        shade(LOOK.outside, 0.9)
    } else {
        LOOK.inside
    };
    // The face at c0 faces −across, the one at c1 faces +across.
    for (side, c, n) in [(-1i8, w.c0, -across), (1, w.c1, across)] {
        let map = |a: f32, y: f32| w.at(a, y, c);
        let ext_len = match w.run {
            Run::X => XS[5] - XS[0],
            Run::Z => ZS[5] - ZS[0],
        };
        let ext0 = match w.run {
            Run::X => XS[0],
            Run::Z => ZS[0],
        };
        let facade_uv = |p: Vec3| {
            let a = match w.run {
                Run::X => p.x,
                Run::Z => p.z,
            };
            [facade_u(ext_len, (a - ext0) / ext_len), facade_v(p.y)]
        };
        let butts: Vec<f32> = w
            .butts
            .iter()
            .filter(|b| b.1 == side)
            .map(|b| b.0)
            .collect();
        for b in 0..bands.len() - 1 {
            let (y0, y1) = (bands[b], bands[b + 1]);
            let outside = w.outside == side;
            let (buf, colour, uv): (usize, [u8; 4], &dyn Fn(Vec3) -> [f32; 2]) =
                match (outside, b == top_band && w.outside != 0) {
                    (true, true) => (FACADE, LOOK.outside, &facade_uv),
                    (true, false) => (PLASTER, trim, &no_uv),
                    (false, _) => (PLASTER, LOOK.inside, &no_uv),
                };
            let u = &ulines[b];
            for k in 0..u.len() - 1 {
                let (ua, ub) = (u[k], u[k + 1]);
                let col = &cuts[b][k];
                for r in 0..col.len() - 1 {
                    let (ya, yb) = (col[r], col[r + 1]);
                    let hole = w
                        .holes
                        .iter()
                        .any(|h| h.a0 <= ua && ub <= h.a1 && h.y0 <= ya && yb <= h.y1);
                    if hole {
                        continue;
                    }
                    let edge = |kk: Option<usize>| {
                        let mut v: Vec<f32> = col.clone();
                        if let Some(kk) = kk {
                            v.extend_from_slice(&cuts[b][kk]);
                        }
                        span(ya, yb, v)
                    };
                    let left = edge(k.checked_sub(1));
                    let right = edge((k + 1 < u.len() - 1).then_some(k + 1));
                    let bottom = if ya == y0 && b > 0 {
                        span(ua, ub, ulines[b - 1].iter().copied())
                    } else {
                        vec![ua, ub]
                    };
                    let top = if yb == y1 && b + 1 < bands.len() - 1 {
                        span(ua, ub, ulines[b + 1].iter().copied())
                    } else if yb == y1 {
                        span(ua, ub, butts.iter().copied())
                    } else {
                        vec![ua, ub]
                    };
                    patch(
                        &mut e.bufs[buf],
                        &map,
                        n,
                        uv,
                        colour,
                        &left,
                        &right,
                        &bottom,
                        &top,
                    );
                }
            }
        }
    }
    let plaster = &mut e.bufs[PLASTER];
    // End caps: at each end, one quad per piece of the end column.
    if w.caps {
        for b in 0..bands.len() - 1 {
            let u = &ulines[b];
            for (a, k, n) in [(w.a0, 0, -along), (w.a1, u.len() - 2, along)] {
                let col = &cuts[b][k];
                for r in 0..col.len() - 1 {
                    let map = |c: f32, y: f32| w.at(a, y, c);
                    plain(
                        plaster,
                        &map,
                        n,
                        &no_uv,
                        trim,
                        (w.c0, w.c1),
                        (col[r], col[r + 1]),
                    );
                }
            }
        }
    }
    // Top cap over the top band's columns, with the vertices of walls butting in on each side.
    {
        let map = |a: f32, c: f32| w.at(a, EAVES_Y, c);
        let u = &ulines[top_band];
        let side_vs = |s: i8| {
            span(
                w.a0,
                w.a1,
                u.iter()
                    .copied()
                    .chain(w.butts.iter().filter(|b| b.1 == s).map(|b| b.0)),
            )
        };
        let (lo, hi) = (side_vs(-1), side_vs(1));
        // In the (a, c) plane: `left`/`right` are the ends (no extras), `bottom` is c0, `top` c1.
        patch(
            plaster,
            &map,
            Vec3::Y,
            &no_uv,
            trim,
            &[w.c0, w.c1],
            &[w.c0, w.c1],
            &lo,
            &hi,
        );
    }
    // Reveals: the four sides of every hole through the wall's thickness.
    for h in &w.holes {
        let jamb = |a: f32| move |c: f32, y: f32| w.at(a, y, c);
        let flat = |y: f32| move |a: f32, c: f32| w.at(a, y, c);
        let plaster = &mut e.bufs[PLASTER];
        plain(
            plaster,
            &jamb(h.a0),
            along,
            &no_uv,
            trim,
            (w.c0, w.c1),
            (h.y0, h.y1),
        );
        plain(
            plaster,
            &jamb(h.a1),
            -along,
            &no_uv,
            trim,
            (w.c0, w.c1),
            (h.y0, h.y1),
        );
        plain(
            plaster,
            &flat(h.y1),
            -Vec3::Y,
            &no_uv,
            trim,
            (h.a0, h.a1),
            (w.c0, w.c1),
        );
        // A door's sill is a threshold, floored like the rooms.
        if h.y0 == FLOOR_Y {
            let floor = &mut e.bufs[FLOOR];
            plain(
                floor,
                &flat(h.y0),
                Vec3::Y,
                &floor_uv,
                LOOK.wood,
                (h.a0, h.a1),
                (w.c0, w.c1),
            );
        } else {
            plain(
                plaster,
                &flat(h.y0),
                Vec3::Y,
                &no_uv,
                trim,
                (h.a0, h.a1),
                (w.c0, w.c1),
            );
        }
    }
}

/// Floors (with the doorways' edges on their sides) and ceilings of the rooms.
fn emit_rooms(walls: &[Wall], e: &mut Emitter) {
    for r in 0..ROOMS.len() {
        let (x0, x1, z0, z1) = room_rect(r);
        // Edges of thresholds on each side of the room: walls running along the side whose face
        // is the room's side.
        let on = |run: Run, c: f32, lo: f32, hi: f32| {
            let v = walls
                .iter()
                .filter(|w| w.run == run && (w.c0 == c || w.c1 == c))
                .flat_map(|w| w.holes.iter().filter(|h| h.y0 == FLOOR_Y))
                .flat_map(|h| [h.a0, h.a1]);
            span(lo, hi, v)
        };
        let map = |x: f32, z: f32| Vec3::new(x, FLOOR_Y, z);
        patch(
            &mut e.bufs[FLOOR],
            &map,
            Vec3::Y,
            &floor_uv,
            LOOK.wood,
            &on(Run::Z, x0, z0, z1),
            &on(Run::Z, x1, z0, z1),
            &on(Run::X, z0, x0, x1),
            &on(Run::X, z1, x0, x1),
        );
        let map = |x: f32, z: f32| Vec3::new(x, CEILING_Y, z);
        plain(
            &mut e.bufs[PLASTER],
            &map,
            -Vec3::Y,
            &no_uv,
            LOOK.ceiling,
            (x0, x1),
            (z0, z1),
        );
    }
}

/// A hipped roof over the outer walls, its ridge along X. The slopes' eaves meet the south and
/// north walls corner to corner; the hips' eaves carry the corners of the caps and butting walls
/// they meet (`ZS[1]`, `ZS[4]`).
fn emit_roof(e: &mut Emitter) {
    let buf = &mut e.bufs[ROOF];
    let (x0, x1, z0, z1) = (XS[0], XS[5], ZS[0], ZS[5]);
    let inset = 0.5 * (z1 - z0);
    let (y, yr, zm) = (EAVES_Y, EAVES_Y + ROOF_RISE, mid(z0, z1));
    let (r0, r1) = (Vec3::new(x0 + inset, yr, zm), Vec3::new(x1 - inset, yr, zm));
    let c = LOOK.roof;
    let zero = [[0.0; 2]; 4];
    buf.quad(
        [Vec3::new(x0, y, z0), Vec3::new(x1, y, z0), r1, r0],
        zero,
        Vec3::new(0.0, 1.0, -1.0),
        c,
    );
    buf.quad(
        [Vec3::new(x1, y, z1), Vec3::new(x0, y, z1), r0, r1],
        zero,
        Vec3::new(0.0, 1.0, 1.0),
        c,
    );
    for (x, apex, s) in [(x0, r0, -1.0f32), (x1, r1, 1.0)] {
        let n = (Vec3::new(x, y, z1) - apex)
            .cross(Vec3::new(x, y, z0) - apex)
            .normalize_or_zero();
        let n = if n.x * s < 0.0 { -n } else { n };
        let a = buf.vert(apex, n, [0.0; 2], c);
        let base: Vec<u32> = [ZS[0], ZS[1], ZS[4], ZS[5]]
            .iter()
            .map(|&z| buf.vert(Vec3::new(x, y, z), n, [0.0; 2], c))
            .collect();
        for k in 0..base.len() - 1 {
            buf.tri(a, base[k], base[k + 1], n);
        }
    }
}

/// Adds the building's materials and meshes to `b` (after the city's, whose facade texture it
/// shares).
pub fn build(b: &mut SceneBuilder) {
    let city_facade = b
        .materials()
        .iter()
        .find(|m| m.name == "city-facade")
        .and_then(|m| m.texture);
    let facade = match city_facade {
        Some(t) => t,
        None => b.add_texture(textures::facade()),
    };
    let floor = b.add_texture(textures::planks());
    let white = [1.0, 1.0, 1.0, 1.0];
    let m = |name: &str, texture: Option<u32>| Material {
        name: name.into(),
        base_color: white,
        texture,
    };
    let base = b.add_material(m("interior-facade", Some(facade)));
    b.add_material(m("interior-roof", None));
    b.add_material(m("interior-plaster", None));
    b.add_material(m("interior-floor", Some(floor)));
    let mut e = Emitter::new(MATERIALS);
    let walls = walls();
    for w in &walls {
        emit_wall(w, &mut e);
    }
    emit_rooms(&walls, &mut e);
    emit_roof(&mut e);
    for mut mesh in e.into_meshes() {
        mesh.material += base;
        b.add_mesh(mesh);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_building_has_the_documented_triangle_count() {
        let mut b = SceneBuilder::new();
        build(&mut b);
        let s = b.finish();
        assert_eq!(s.triangle_count(), INTERIOR_TRIANGLES);
        assert_eq!(s.stats.dropped_degenerate, 0);
    }
}
