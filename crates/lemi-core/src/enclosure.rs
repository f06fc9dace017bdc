//! A closed building seen from inside: what lies outside it is visible only through its openings
//! (cell-and-portal visibility, Luebke & Georges, "Portals and Mirrors", I3D 1995; Teller &
//! Séquin 1991).
//!
//! An [`Enclosure`] lists the building's bounds, its rooms (where a viewer may stand in each,
//! and **every** opening from it to the outside) and the doorways between rooms. From an eye in a
//! room, a ray that reaches a point outside the building leaves it through an opening of that
//! room, or passes a doorway into another room and leaves through one of its openings, and so
//! on; the point's pixel lies in the projection of every hole the ray passes.
//! [`Enclosure::window`] follows the doorways from the eye's room, cutting each room's
//! part of the view to the doorway's projection (each hole clipped to the view's near plane
//! first), and returns the smallest pixel rectangle holding every opening's part, with a
//! clip-space matrix of the sub-frustum through it: anything outside the building can be culled
//! against the sub-frustum and drawn with the rectangle as scissor, and the image does not change.
//!
//! What the caller must guarantee (the bake states it for `builtin:interior`): the building's walls,
//! floors and roof are opaque and closed but for the listed openings, every triangle of the
//! building lies wholly inside `bounds`, and the rooms lie inside the building. An opening left out
//! would hide what lies behind it; that is why only a bake that knows the whole building writes an
//! enclosure.

use glam::{DMat4, DVec2, DVec3, DVec4};
use serde::{Deserialize, Serialize};

use crate::camera::View;
use crate::Aabb;

/// A closed building with its openings (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Enclosure {
    /// Holds every triangle of the building.
    pub bounds: Aabb,
    /// Its rooms, closed but for their openings and doorways.
    pub rooms: Vec<Room>,
    /// Holes joining two rooms.
    pub doorways: Vec<Doorway>,
}

/// A room of an [`Enclosure`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Room {
    /// Where a viewer in the room may stand (inside the room, off its walls).
    pub walkable: Aabb,
    /// The room's inside: the box its walls', floor's and ceiling's inner faces bound. Every
    /// surface seen from the room other than through one of its holes touches it (its walls,
    /// floor and ceiling, the reveals of its holes, anything standing in it), and each of its
    /// doorways leads straight into the other room's inside. `None` when not known: then every
    /// surface of the building counts as seen from the room directly (no culling between rooms).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inside: Option<Aabb>,
    /// Every opening from the room to the outside, as its four corners in order around it, on
    /// one face of the wall (a ray through the hole passes through both faces' rectangles).
    pub openings: Vec<[DVec3; 4]>,
}

/// A hole in a wall between two rooms of an [`Enclosure`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Doorway {
    /// Indices of the two rooms into [`Enclosure::rooms`].
    pub rooms: [usize; 2],
    /// Its four corners in order around it, on one face of the wall.
    pub corners: [DVec3; 4],
}

/// The part of a view through which the outside can be seen ([`Enclosure::window`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    /// Pixel rectangle `[x0, y0, x1, y1)` inside the viewport, not empty.
    pub rect: [u32; 4],
    /// The view's `view_proj` followed by the map of the rectangle onto the whole clip volume: a
    /// box outside this clip volume ([`crate::frustum::classify_box`]) has no pixel in the
    /// rectangle.
    pub view_proj: DMat4,
}

/// Pixels added around the projected openings, for the rasterizer's rounding of vertices to its
/// sub-pixel grid (far above it).
const WINDOW_MARGIN_PX: f64 = 1.0;

impl Enclosure {
    /// Checks that the enclosure is usable: finite, non-empty bounds and rooms inside them, at
    /// least one opening, every corner finite.
    pub fn validate(&self) -> Result<(), String> {
        let finite_box = |b: &Aabb| b.min.is_finite() && b.max.is_finite() && !b.is_empty();
        if !finite_box(&self.bounds) {
            return Err("the building's bounds are empty or not finite".into());
        }
        if self.rooms.is_empty() {
            return Err("it has no room".into());
        }
        for (k, r) in self.rooms.iter().enumerate() {
            let w = &r.walkable;
            if !finite_box(w) || !self.bounds.contains(w.min) || !self.bounds.contains(w.max) {
                return Err(format!(
                    "room {k} is empty, not finite or not inside the building's bounds"
                ));
            }
            if let Some(i) = &r.inside {
                if !finite_box(i) || !i.contains(w.min) || !i.contains(w.max) {
                    return Err(format!(
                        "the inside of room {k} is empty, not finite or does not hold its walkable box"
                    ));
                }
            }
            if r.openings.iter().flatten().any(|p| !p.is_finite()) {
                return Err(format!(
                    "room {k} has an opening with a corner that is not finite"
                ));
            }
        }
        for (k, d) in self.doorways.iter().enumerate() {
            if d.rooms.iter().any(|&r| r >= self.rooms.len()) || d.rooms[0] == d.rooms[1] {
                return Err(format!("doorway {k} does not join two of its rooms"));
            }
            if d.corners.iter().any(|p| !p.is_finite()) {
                return Err(format!("doorway {k} has a corner that is not finite"));
            }
        }
        Ok(())
    }

    /// Whether `eye` stands in one of the rooms (so that the outside is seen only through the
    /// openings).
    pub fn encloses(&self, eye: DVec3) -> bool {
        self.room_of(eye).is_some()
    }

    /// The first room whose walkable box holds `eye`.
    pub fn room_of(&self, eye: DVec3) -> Option<usize> {
        self.rooms.iter().position(|r| r.walkable.contains(eye))
    }

    /// The pixels of `view` through which anything outside the building can be seen from an eye
    /// in one of its rooms (Luebke & Georges: the projections of the eye's room's openings, and,
    /// through each doorway in view, those of the next room's openings and doorways cut to the
    /// doorway's projection, and so on), as one rectangle: `None` when no opening can be seen
    /// (then nothing outside is visible) or when the eye is in no room.
    pub fn window(&self, view: &View) -> Option<Window> {
        self.sight(view).and_then(|s| s.outside)
    }

    /// What an eye in one of the rooms can see, room by room (see [`Sight`]): `None` when the
    /// eye is in no room.
    pub fn sight(&self, view: &View) -> Option<Sight> {
        let eye = view.view.inverse().transform_point3(DVec3::ZERO);
        let room = self.room_of(eye)?;
        let view_proj = view.view_proj();
        let (w, h) = (view.width as f64, view.height as f64);
        let screen = Rect {
            lo: DVec2::ZERO,
            hi: DVec2::new(w, h),
        };
        let project = |corners: &[DVec3; 4]| -> Option<Rect> {
            let clip = corners.map(|p| view_proj * p.extend(1.0));
            let mut r: Option<Rect> = None;
            for c in clip_to_near(&clip) {
                let p = view.ndc_to_pixel(DVec2::new(c.x / c.w, c.y / c.w));
                r = Some(r.map_or(Rect { lo: p, hi: p }, |r| Rect {
                    lo: r.lo.min(p),
                    hi: r.hi.max(p),
                }));
            }
            r.map(|r| Rect {
                lo: r.lo - DVec2::splat(WINDOW_MARGIN_PX),
                hi: r.hi + DVec2::splat(WINDOW_MARGIN_PX),
            })
        };
        let join = |a: &mut Option<Rect>, b: Rect| *a = Some(a.map_or(b, |a| a.join(&b)));
        // depth-first over the rooms, never back into a room on the path
        let mut outside: Option<Rect> = None;
        let mut rooms: Vec<Option<Rect>> = vec![None; self.rooms.len()];
        rooms[room] = Some(screen);
        let mut stack = vec![(room, screen, 1u64 << room.min(63))];
        while let Some((r, clip, path)) = stack.pop() {
            for o in &self.rooms[r].openings {
                if let Some(seen) = project(o).and_then(|p| p.meet(&clip)) {
                    join(&mut outside, seen);
                }
            }
            for d in &self.doorways {
                let next = match d.rooms {
                    [a, b] if a == r => b,
                    [a, b] if b == r => a,
                    _ => continue,
                };
                if next >= 63 || path & (1 << next) != 0 {
                    continue;
                }
                if let Some(seen) = project(&d.corners).and_then(|p| p.meet(&clip)) {
                    join(&mut rooms[next], seen);
                    stack.push((next, seen, path | 1 << next));
                }
            }
        }
        Some(Sight {
            view: *view,
            room,
            rooms,
            outside: outside.and_then(|r| window_of(view, r)),
        })
    }
}

/// What an eye in a room of an [`Enclosure`] can see ([`Enclosure::sight`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Sight {
    view: View,
    /// The room the eye stands in.
    pub room: usize,
    /// Per room, the part of the view (in pixels, before rounding) through which it can be seen:
    /// the whole view for the eye's room, the projections of the doorways leading to it for the
    /// others (each cut to the doorways before it), `None` for a room out of sight.
    rooms: Vec<Option<Rect>>,
    /// The part of the view through which the outside can be seen ([`Enclosure::window`]).
    pub outside: Option<Window>,
}

impl Sight {
    /// Whether the eye's room is among `rooms` (indices into [`Enclosure::rooms`]).
    pub fn sees_directly(&self, mut rooms: impl Iterator<Item = usize>) -> bool {
        rooms.any(|r| r == self.room)
    }

    /// The smallest window holding every pixel through which one of `rooms` can be seen: `None`
    /// when none of them can. Anything touching only those rooms' insides is seen in it alone.
    pub fn window(&self, rooms: impl Iterator<Item = usize>) -> Option<Window> {
        let mut union: Option<Rect> = None;
        for r in rooms.filter_map(|r| self.rooms.get(r).copied().flatten()) {
            union = Some(union.map_or(r, |u| u.join(&r)));
        }
        window_of(&self.view, union?)
    }
}

/// The whole pixels of `view` holding `r`, with the clip-space matrix of their sub-frustum:
/// `None` when no pixel is left.
fn window_of(view: &View, r: Rect) -> Option<Window> {
    let (w, h) = (view.width as f64, view.height as f64);
    let Rect { lo, hi } = r;
    let x0 = lo.x.floor().clamp(0.0, w);
    let y0 = lo.y.floor().clamp(0.0, h);
    let x1 = hi.x.ceil().clamp(0.0, w);
    let y1 = hi.y.ceil().clamp(0.0, h);
    if x0 >= x1 || y0 >= y1 {
        return None;
    }
    // NDC of the rectangle (y up), then the map of [a0, a1] onto [-1, 1] on both axes
    let a = view.pixel_to_ndc(DVec2::new(x0, y1));
    let b = view.pixel_to_ndc(DVec2::new(x1, y0));
    let (sx, sy) = (2.0 / (b.x - a.x), 2.0 / (b.y - a.y));
    let crop = DMat4::from_cols(
        DVec4::new(sx, 0.0, 0.0, 0.0),
        DVec4::new(0.0, sy, 0.0, 0.0),
        DVec4::new(0.0, 0.0, 1.0, 0.0),
        DVec4::new(-(a.x + b.x) * 0.5 * sx, -(a.y + b.y) * 0.5 * sy, 0.0, 1.0),
    );
    Some(Window {
        rect: [x0 as u32, y0 as u32, x1 as u32, y1 as u32],
        view_proj: crop * view.view_proj(),
    })
}

/// A pixel rectangle `[lo, hi]` (x right, y down).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Rect {
    lo: DVec2,
    hi: DVec2,
}

impl Rect {
    /// The intersection, `None` when empty.
    fn meet(&self, o: &Rect) -> Option<Rect> {
        let r = Rect {
            lo: self.lo.max(o.lo),
            hi: self.hi.min(o.hi),
        };
        (r.lo.x < r.hi.x && r.lo.y < r.hi.y).then_some(r)
    }

    /// The smallest rectangle holding both.
    fn join(&self, o: &Rect) -> Rect {
        Rect {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }
}

/// The polygon `clip` (clip-space corners in order) cut to the part in front of the near plane
/// (reverse-Z: `z ≤ w`, with `w > 0`), Sutherland–Hodgman against that one plane. The other planes
/// are not needed: the rectangle is clamped to the viewport afterwards.
fn clip_to_near(clip: &[DVec4; 4]) -> Vec<DVec4> {
    // distance to the near plane, positive in front; a small part of w keeps w > 0 after the cut
    let d = |c: &DVec4| c.w - c.z - 1e-9 * c.w.abs().max(1.0);
    let mut out = Vec::with_capacity(6);
    for i in 0..4 {
        let (a, b) = (clip[i], clip[(i + 1) % 4]);
        let (da, db) = (d(&a), d(&b));
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            out.push(a + (b - a) * (da / (da - db)));
        }
    }
    out.retain(|c| c.w > 0.0 && c.is_finite());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use proptest::prelude::*;

    /// Two rooms side by side, 10 × 3 × 8 m each, in a building of 0.2 m walls: A (x 0 to 10)
    /// with a door in its −Z wall, B (x 10.2 to 20.2) with a window in its +X wall, and a
    /// doorway in the wall between them.
    fn enclosure() -> Enclosure {
        let rect = |x0: f64, x1: f64, y0: f64, y1: f64, z0: f64, z1: f64| {
            if x0 == x1 {
                [
                    DVec3::new(x0, y0, z0),
                    DVec3::new(x0, y0, z1),
                    DVec3::new(x0, y1, z1),
                    DVec3::new(x0, y1, z0),
                ]
            } else {
                [
                    DVec3::new(x0, y0, z0),
                    DVec3::new(x1, y0, z0),
                    DVec3::new(x1, y1, z0),
                    DVec3::new(x0, y1, z0),
                ]
            }
        };
        Enclosure {
            bounds: Aabb::new(DVec3::new(-0.2, 0.0, -0.2), DVec3::new(20.4, 3.2, 8.2)),
            rooms: vec![
                Room {
                    walkable: Aabb::new(DVec3::new(0.3, 0.3, 0.3), DVec3::new(9.7, 2.7, 7.7)),
                    inside: Some(Aabb::new(DVec3::ZERO, DVec3::new(10.0, 3.0, 8.0))),
                    openings: vec![rect(2.0, 3.0, 0.0, 2.2, -0.2, -0.2)],
                },
                Room {
                    walkable: Aabb::new(DVec3::new(10.5, 0.3, 0.3), DVec3::new(19.9, 2.7, 7.7)),
                    inside: Some(Aabb::new(
                        DVec3::new(10.2, 0.0, 0.0),
                        DVec3::new(20.2, 3.0, 8.0),
                    )),
                    openings: vec![rect(20.4, 20.4, 1.0, 2.4, 3.0, 4.2)],
                },
            ],
            doorways: vec![Doorway {
                rooms: [0, 1],
                corners: rect(10.0, 10.0, 0.0, 2.2, 5.0, 6.0),
            }],
        }
    }

    /// Where the segment from `a` to `b` crosses the plane `x = x`, if it does.
    fn cross_x(a: DVec3, b: DVec3, x: f64) -> Option<DVec3> {
        let t = (x - a.x) / (b.x - a.x);
        (0.0..=1.0).contains(&t).then(|| a + (b - a) * t)
    }

    fn view(eye: DVec3, dir: DVec3, fov: f64) -> View {
        Camera::new(eye, dir, DVec3::Y, fov, 320, 200)
            .expect("camera")
            .view()
    }

    /// The pixel where `view` shows `p`: `None` outside the view or nearer than 0.2 to the eye.
    fn pixel_of(view: &View, p: DVec3) -> Option<DVec2> {
        let pr = view.project(p)?;
        let (x, y) = (pr.pixel.x, pr.pixel.y);
        ((0.0..view.width as f64).contains(&x)
            && (0.0..view.height as f64).contains(&y)
            && pr.view_depth >= 0.2)
            .then_some(pr.pixel)
    }

    /// Whether `w` holds `pixel` and its frustum keeps a small box around `p`.
    fn holds(w: &Window, pixel: DVec2, p: DVec3) -> bool {
        let [x0, y0, x1, y1] = w.rect.map(f64::from);
        let r = DVec3::splat(1e-3);
        (x0..=x1).contains(&pixel.x)
            && (y0..=y1).contains(&pixel.y)
            && !crate::frustum::box_outside(p - r, p + r, &w.view_proj)
    }

    #[test]
    fn openings_out_of_view_give_no_window_and_one_ahead_a_tight_one() {
        let e = enclosure();
        assert!(e.validate().is_ok());
        let eye = DVec3::new(5.0, 1.7, 4.0);
        assert_eq!(e.room_of(eye), Some(0));
        assert!(!e.encloses(DVec3::new(30.0, 1.7, 4.0)));
        // looking at A's +Z wall: no opening, no doorway in view
        assert_eq!(e.window(&view(eye, DVec3::Z, 60.0)), None);
        // looking at A's door: a rectangle below the screen's centre
        let w = e.window(&view(eye, DVec3::new(-0.5, -0.3, -1.0), 60.0));
        assert!(w.is_some());
        // looking through the doorway towards B's window: only what both let through
        let eye = DVec3::new(2.0, 1.7, 6.5);
        let v = view(eye, DVec3::X, 40.0);
        let w = e.window(&v).expect("B's window through the doorway");
        let [x0, y0, x1, y1] = w.rect;
        assert!(x1 - x0 < 60 && y1 - y0 < 80, "{:?}", w.rect);
        // the sub-frustum culls a box beside that window and keeps one behind it
        let beside = Aabb::new(DVec3::new(40.0, 1.0, 14.0), DVec3::new(41.0, 2.0, 15.0));
        let behind = Aabb::new(DVec3::new(40.0, 1.6, -0.1), DVec3::new(41.0, 1.8, 0.9));
        assert!(!crate::frustum::box_outside(
            beside.min,
            beside.max,
            &v.view_proj()
        ));
        assert!(crate::frustum::box_outside(
            beside.min,
            beside.max,
            &w.view_proj
        ));
        assert!(!crate::frustum::box_outside(
            behind.min,
            behind.max,
            &w.view_proj
        ));
        // from B, looking at the doorway's wall, A's door is out of sight through it
        let eye = DVec3::new(15.0, 1.7, 5.5);
        assert_eq!(e.window(&view(eye, -DVec3::X, 30.0)), None);
    }

    #[test]
    fn an_opening_crossing_the_near_plane_is_clipped_not_dropped() {
        let e = enclosure();
        // beside B's window, looking along the wall: its near corners are behind the eye
        let eye = DVec3::new(19.8, 1.7, 2.0);
        assert!(e
            .window(&view(eye, DVec3::new(0.3, 0.0, 1.0), 90.0))
            .is_some());
        let bad = Enclosure {
            rooms: vec![],
            ..enclosure()
        };
        assert!(bad.validate().unwrap_err().contains("no room"));
        let bad = Enclosure {
            doorways: vec![Doorway {
                rooms: [0, 2],
                corners: enclosure().doorways[0].corners,
            }],
            ..enclosure()
        };
        assert!(bad.validate().unwrap_err().contains("doorway 0"));
        let mut bad = enclosure();
        bad.rooms[1].inside = Some(Aabb::new(DVec3::splat(11.0), DVec3::splat(12.0)));
        assert!(bad.validate().unwrap_err().contains("inside of room 1"));
    }

    #[test]
    fn the_eyes_room_is_seen_whole_and_the_next_only_through_the_doorway() {
        let e = enclosure();
        // in A, looking at the doorway to B
        let v = view(DVec3::new(4.0, 1.7, 5.5), DVec3::X, 60.0);
        let s = e.sight(&v).expect("in a room");
        assert_eq!(s.room, 0);
        assert!(s.sees_directly([0, 1].into_iter()));
        assert!(!s.sees_directly([1].into_iter()));
        assert_eq!(
            s.window([0].into_iter()).map(|w| w.rect),
            Some([0, 0, 320, 200])
        );
        let [x0, y0, x1, y1] = s
            .window([1].into_iter())
            .expect("B through the doorway")
            .rect;
        assert!(
            x1 - x0 < 60 && y1 - y0 < 120 && x0 > 100,
            "{:?}",
            [x0, y0, x1, y1]
        );
        assert_eq!(
            s.window([0, 1].into_iter()).map(|w| w.rect),
            Some([0, 0, 320, 200])
        );
        assert_eq!(s.window(std::iter::empty()), None);
        assert_eq!(s.outside, e.window(&v));
        // looking at A's +Z wall: B is out of sight
        let s = e
            .sight(&view(DVec3::new(4.0, 1.7, 5.5), DVec3::Z, 60.0))
            .expect("in A");
        assert_eq!(s.window([1].into_iter()), None);
        // outside every room: no sight
        assert!(e
            .sight(&view(DVec3::new(30.0, 1.7, 4.0), DVec3::X, 60.0))
            .is_none());
    }

    proptest! {
        /// Every point outside the building seen through an opening from an eye in a room, the
        /// ray passing the doorway where the opening is the other room's, projects into the
        /// window, and a box around it is not culled by the window's frustum.
        #[test]
        fn what_is_seen_through_an_opening_lies_in_the_window(
            in_b in any::<bool>(), ex in 0.0f64..1.0, ey in 0.3f64..2.7, ez in 0.3f64..7.7,
            yaw in 0.0f64..std::f64::consts::TAU, pitch in -1.2f64..1.2,
            fov in 20.0f64..120.0,
            which in 0usize..2, u in 0.0f64..1.0, v in 0.0f64..1.0, t in 1.0f64..50.0,
        ) {
            let e = enclosure();
            let ex = if in_b { 10.5 + 9.4 * ex } else { 0.3 + 9.4 * ex };
            let eye = DVec3::new(ex, ey, ez);
            let dir = DVec3::new(yaw.cos() * pitch.cos(), pitch.sin(), yaw.sin() * pitch.cos());
            let view = view(eye, dir, fov);
            let [a, b, _, d] = e.rooms[which].openings[0];
            let q = a + (b - a) * u + (d - a) * v;
            if which != usize::from(in_b) {
                // the other room's opening: seen only through the doorway (z 5 to 6, y to 2.2)
                let through = |x: f64| cross_x(eye, q, x)
                    .is_some_and(|c| (5.0..=6.0).contains(&c.z) && c.y <= 2.2);
                if !(through(10.0) && through(10.2)) {
                    return Ok(());
                }
            }
            let p = eye + (q - eye) * t;
            let Some(pixel) = pixel_of(&view, p) else { return Ok(()) };
            let w = e.window(&view);
            prop_assert!(w.is_some(), "a visible point outside but no window");
            let w = w.unwrap();
            prop_assert!(holds(&w, pixel, p), "pixel {pixel} outside the window {:?}", w.rect);
        }

        /// Every point of the other room's inside that an eye sees through the doorway (the ray
        /// passing the hole in both faces of the wall) projects into that room's window, and a
        /// box around it is not culled by the window's frustum.
        #[test]
        fn what_is_seen_of_the_next_room_lies_in_its_window(
            in_b in any::<bool>(), ex in 0.0f64..1.0, ey in 0.3f64..2.7, ez in 0.3f64..7.7,
            yaw in 0.0f64..std::f64::consts::TAU, pitch in -1.2f64..1.2,
            fov in 20.0f64..120.0,
            px in 0.0f64..1.0, py in 0.0f64..1.0, pz in 0.0f64..1.0,
        ) {
            let e = enclosure();
            let ex = if in_b { 10.5 + 9.4 * ex } else { 0.3 + 9.4 * ex };
            let eye = DVec3::new(ex, ey, ez);
            let dir = DVec3::new(yaw.cos() * pitch.cos(), pitch.sin(), yaw.sin() * pitch.cos());
            let view = view(eye, dir, fov);
            let other = usize::from(!in_b);
            let inside = e.rooms[other].inside.expect("inside");
            let p = inside.min + (inside.max - inside.min) * DVec3::new(px, py, pz);
            let through = |x: f64| cross_x(eye, p, x)
                .is_some_and(|c| (5.0..=6.0).contains(&c.z) && c.y <= 2.2);
            if !(through(10.0) && through(10.2)) {
                return Ok(());
            }
            let Some(pixel) = pixel_of(&view, p) else { return Ok(()) };
            let s = e.sight(&view).expect("in a room");
            prop_assert_eq!(s.room, 1 - other);
            let w = s.window([other].into_iter());
            prop_assert!(w.is_some(), "a visible point of the other room but no window");
            let w = w.unwrap();
            prop_assert!(holds(&w, pixel, p), "pixel {pixel} outside the window {:?}", w.rect);
        }
    }
}
