//! Object impostors: one object (a landmark, a statue, the street behind a portal) seen from a box-
//! or shaft-shaped view cell, its layers placed by the TR's object placement
//! ([`crate::placement::object`]) and recorded by the same crack-free pipeline as the cube layers
//! of an environment-map cell.
//!
//! This work is based on: S. Jeschke, M. Wimmer, *An Error Metric for Layered Environment Map
//! Impostors*, TR-186-2-02-04, sec. 2.1.1 (the impostor frustum fits the object's near face seen
//! from the reference viewpoint, which lies `s` behind the cell border nearest the object, centred
//! across the view axis), sec. 3 (portal impostors; Rafferty et al. 1998).
//!
//! **The object frame.** The TR's layers are planes across the view axis at distances `t + s`
//! from the reference viewpoint, seen through a frustum of half-angle tangents `kx`, `ky`. The
//! affine map [`ObjectFrame::to_canonical`] takes the world to the frame of cube face `+Z`: the
//! reference viewpoint to the origin, the view axis to `+Z` (depths unchanged), the impostor's
//! right and down directions to `+X` and `−Y`, divided by `kx` and `ky`. The frustum becomes the
//! face's 90° pyramid and every layer a square `|s|, |t| ≤ 1` of that face at the layer's depth,
//! so placement, slab classification, clipping to slabs (planes map to planes), conservative
//! recording, compression and the quad records are the environment map's, unchanged; a quad's
//! corners go back to the world with [`ObjectFrame::to_world`] (a rectangle across the axis stays a
//! rectangle: the map only scales the quad's own two directions). Normals are not mapped: shading
//! sees the world's normals and light.
//!
//! **Which axis.** For a box cell the view axis is the coordinate axis along which the object
//! lies wholly beyond the cell (the largest gap if several); the reference viewpoint is centred
//! on the cell's cross-section and the frustum is symmetric about the axis, wide enough for every
//! corner of the object's box (an object off the axis gets a wider frustum, never a clipped one).
//! For a shaft the axis is the shaft's own, pointing from the viewer to the apex.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::cell::ViewCell;
use crate::classify::{Slabs, TriRef};
use crate::enclosure::Enclosure;
use crate::layering::{CellPlan, FacePlan};
use crate::placement::{
    place_object_layers, schaufler_res, EnvParams, Layer, ObjectCell, ObjectParams,
    ObjectPlacement, Placement,
};
use crate::scene::ExtractError;
use crate::{Aabb, Face, Scene};

/// Why an object impostor cannot be set up; the message says which input is wrong and why (the
/// command line adds the flag's name).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ObjectError {
    /// The view cell specification is malformed or degenerate.
    #[error("view cell: {0}")]
    ViewCell(String),
    /// The object (its box or its triangles) is unusable.
    #[error("object: {0}")]
    Object(String),
    /// The object and the view cell overlap, or the object is not in front of the cell.
    #[error("the object is not outside the view cell: {0}")]
    Overlap(String),
    /// The placement refused the resulting parameters.
    #[error("placing the object's layers: {0}")]
    Placement(#[from] crate::placement::PlacementError),
}

/// The region a viewer of an object impostor may occupy (TR Fig. 2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum ObjectViewCell {
    /// An axis-aligned box.
    Box { min: DVec3, max: DVec3 },
    /// A square shaft with its apex at `apex` opening along the unit direction `dir` (from the
    /// apex toward the viewer) with full apex angle `angle_deg` in both directions across it; the
    /// cell is the part of the shaft at least `min_distance` from the apex along `dir`, and at
    /// most `max_distance` (unbounded away from the apex without it, as the TR's shafts).
    Shaft {
        apex: DVec3,
        dir: DVec3,
        angle_deg: f64,
        min_distance: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        max_distance: Option<f64>,
        /// The part of the shaft inside this box only (a portal's room: viewpoints under the
        /// floor or beyond a side wall are not served). The placement is the whole shaft's, so
        /// the guarantee holds in any part of it.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        within: Option<Aabb>,
    },
}

/// The right and down directions of a view axis `forward` (unit): down is the world's −Y made
/// orthogonal to `forward` (−Z when looking straight up or down), right = forward × down, the
/// handedness of the cube faces ([`Face`]).
fn basis(forward: DVec3) -> (DVec3, DVec3) {
    let up = if forward.y.abs() > 0.9 {
        DVec3::Z * forward.y.signum()
    } else {
        DVec3::Y
    };
    let down = (forward * up.dot(forward) - up).normalize();
    (forward.cross(down), down)
}

fn numbers(body: &str, n: usize, what: &str) -> Result<Vec<f64>, String> {
    let v: Vec<f64> = body
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{body}`: {e} (expected {what})"))?;
    if v.len() != n {
        return Err(format!(
            "`{body}`: {} numbers, expected {n}: {what}",
            v.len()
        ));
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(format!("`{body}`: every number must be finite ({what})"));
    }
    Ok(v)
}

impl ObjectViewCell {
    /// Parses `box:x0,y0,z0,x1,y1,z1` or `shaft:ax,ay,az,dx,dy,dz,angle_deg,min_distance` and
    /// checks it ([`ObjectViewCell::validate`]).
    pub fn parse(spec: &str) -> Result<ObjectViewCell, ObjectError> {
        let bad = |m: String| ObjectError::ViewCell(m);
        let (kind, body) = spec.split_once(':').ok_or_else(|| {
            bad(format!(
                "`{spec}`: expected box:x0,y0,z0,x1,y1,z1 or shaft:ax,ay,az,dx,dy,dz,angle_deg,min_distance"
            ))
        })?;
        let cell = match kind.trim().to_ascii_lowercase().as_str() {
            "box" => {
                let v =
                    numbers(body, 6, "the two opposite corners x0,y0,z0,x1,y1,z1").map_err(bad)?;
                let (a, b) = (DVec3::new(v[0], v[1], v[2]), DVec3::new(v[3], v[4], v[5]));
                ObjectViewCell::Box {
                    min: a.min(b),
                    max: a.max(b),
                }
            }
            "shaft" => {
                let what = "apex ax,ay,az, direction dx,dy,dz toward the viewer, apex angle in degrees, distance of the cell from the apex[, its far end's distance]";
                let n = body.split(',').count();
                let v = numbers(body, if n == 9 { 9 } else { 8 }, what).map_err(bad)?;
                let dir = DVec3::new(v[3], v[4], v[5]);
                ObjectViewCell::Shaft {
                    apex: DVec3::new(v[0], v[1], v[2]),
                    dir: if dir.length() > 0.0 {
                        dir.normalize()
                    } else {
                        dir
                    },
                    angle_deg: v[6],
                    min_distance: v[7],
                    max_distance: v.get(8).copied(),
                    within: None,
                }
            }
            k => return Err(bad(format!("`{k}` is not a view-cell kind (box or shaft)"))),
        };
        cell.validate()?;
        Ok(cell)
    }

    /// Checks the cell: a box with positive size along every axis; a shaft with a finite apex, a
    /// non-zero direction, an apex angle strictly between 0° and 180° and a positive distance.
    pub fn validate(&self) -> Result<(), ObjectError> {
        let bad = |m: String| Err(ObjectError::ViewCell(m));
        match *self {
            ObjectViewCell::Box { min, max } => {
                if !min.is_finite() || !max.is_finite() {
                    return bad("the box's corners must be finite".into());
                }
                let size = max - min;
                if size.min_element() <= 0.0 {
                    return bad(format!(
                        "the box {:?} to {:?} is empty (size {:?}); it needs a positive size along x, y and z",
                        min.to_array(),
                        max.to_array(),
                        size.to_array()
                    ));
                }
            }
            ObjectViewCell::Shaft {
                apex,
                dir,
                angle_deg,
                min_distance,
                max_distance,
                within,
            } => {
                if let Some(b) = within {
                    if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
                        return bad(
                            "the box the shaft is clipped to must be finite and not empty".into(),
                        );
                    }
                }
                if let Some(max) = max_distance {
                    if !(max.is_finite() && max > min_distance) {
                        return bad(format!(
                            "the shaft's far end {max} must be finite and farther from the apex than its near end {min_distance}"
                        ));
                    }
                }
                if !apex.is_finite() {
                    return bad("the shaft's apex must be finite".into());
                }
                if !dir.is_finite() || (dir.length() - 1.0).abs() > 1e-9 {
                    return bad("the shaft's direction must be a non-zero vector".into());
                }
                if !(angle_deg.is_finite() && angle_deg > 0.0 && angle_deg < 180.0) {
                    return bad(format!(
                        "the shaft's apex angle {angle_deg}° must be more than 0° and less than 180°"
                    ));
                }
                if !(min_distance.is_finite() && min_distance > 0.0) {
                    return bad(format!(
                        "the cell's distance from the apex {min_distance} must be positive"
                    ));
                }
            }
        }
        Ok(())
    }

    /// The cell as the flag that gives it (`box:…` or `shaft:…`).
    pub fn describe(&self) -> String {
        let v = |p: DVec3| format!("{},{},{}", p.x, p.y, p.z);
        match *self {
            ObjectViewCell::Box { min, max } => format!("box:{},{}", v(min), v(max)),
            ObjectViewCell::Shaft {
                apex,
                dir,
                angle_deg,
                min_distance,
                max_distance,
                ..
            } => format!(
                "shaft:{},{},{angle_deg},{min_distance}{}",
                v(apex),
                v(dir),
                max_distance.map(|m| format!(",{m}")).unwrap_or_default()
            ),
        }
    }

    /// Whether the viewpoint `p` lies in the cell (borders included).
    pub fn contains(&self, p: DVec3) -> bool {
        match *self {
            ObjectViewCell::Box { min, max } => Aabb::new(min, max).contains(p),
            ObjectViewCell::Shaft {
                apex,
                dir,
                angle_deg,
                min_distance,
                max_distance,
                within,
            } => {
                if within.is_some_and(|b| !b.contains(p)) {
                    return false;
                }
                let r = p - apex;
                let along = r.dot(dir);
                if along.is_nan() || along < min_distance || max_distance.is_some_and(|m| along > m)
                {
                    return false;
                }
                let (right, down) = basis(-dir);
                let reach = along * (0.5 * angle_deg.to_radians()).tan();
                r.dot(right).abs() <= reach && r.dot(down).abs() <= reach
            }
        }
    }

    /// Viewpoints at which the impostor is judged, each with a label: for a box the centre, the 8
    /// corners, the 6 face and 12 edge midpoints and `random` interior points
    /// ([`crate::cell::eval_viewpoints`]); for a shaft the corners, edge midpoints and centre of
    /// its near border and of cross-sections 1, 4 and 16 near-border widths farther back (where
    /// the TR's near-border assumption fails, see [`crate::placement::object::shaft_reach`]) and
    /// `random` points between the near border and the farthest of those, all nudged 10⁻⁹ of
    /// their distance inside.
    pub fn eval_viewpoints(&self, random: usize, seed: u64) -> Vec<(String, DVec3)> {
        match *self {
            ObjectViewCell::Box { min, max } => {
                let cell = ViewCell {
                    index: glam::IVec3::ZERO,
                    center: 0.5 * (min + max),
                    half: 0.5 * (max - min),
                };
                crate::cell::eval_viewpoints(&cell, random, seed)
            }
            ObjectViewCell::Shaft {
                apex,
                dir,
                angle_deg,
                min_distance,
                max_distance,
                within,
            } => {
                // a point of the shaft's cross-section moved into `within` (clamped, which keeps
                // it in the cross-section when the box holds the axis point), if it is then in
                // the cell
                let cell = *self;
                let fit = move |p: DVec3| -> Option<DVec3> {
                    let q = match within {
                        Some(b) => p.clamp(b.min, b.max),
                        None => p,
                    };
                    cell.contains(q).then_some(q)
                };
                let (right, down) = basis(-dir);
                let tan = (0.5 * angle_deg.to_radians()).tan() * (1.0 - 1e-9);
                let near_width = 2.0 * min_distance * tan;
                let at = |along: f64, u: f64, v: f64| {
                    apex + dir * along + (right * u + down * v) * (along * tan)
                };
                let mut out = Vec::new();
                let near = min_distance * (1.0 + 1e-9);
                // a bounded shaft: its near border, middle and far border
                let sections: Vec<(&str, f64)> = match max_distance {
                    Some(max) => {
                        let depth = (max * (1.0 - 1e-9) - near).max(0.0);
                        vec![
                            ("near border", 0.0),
                            ("middle", 0.5 * depth),
                            ("far border", depth),
                        ]
                    }
                    None => [
                        ("near border", 0.0),
                        ("1 width back", near_width),
                        ("4 widths back", 4.0 * near_width),
                        ("16 widths back", 16.0 * near_width),
                    ]
                    .to_vec(),
                };
                let farthest = sections.last().map_or(0.0, |s| s.1);
                for (name, back) in sections {
                    let along = near + back;
                    let mut push = |label: String, p: DVec3| {
                        if let Some(q) = fit(p) {
                            out.push((label, q));
                        }
                    };
                    push(format!("{name} centre"), at(along, 0.0, 0.0));
                    for (k, (u, v)) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                        .into_iter()
                        .enumerate()
                    {
                        push(format!("{name} corner {k}"), at(along, u, v));
                    }
                    for (k, (u, v)) in [(0.0, -1.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)]
                        .into_iter()
                        .enumerate()
                    {
                        push(format!("{name} edge {k}"), at(along, u, v));
                    }
                }
                let mut x = seed ^ 0x9e37_79b9_7f4a_7c15;
                let mut next = move || {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    (x >> 11) as f64 / (1u64 << 53) as f64
                };
                for k in 0..random {
                    // rejection sampling inside `within` (64 tries, then the clamped point)
                    for attempt in 0..64 {
                        let along = near + farthest * next();
                        let (u, v) = (2.0 * next() - 1.0, 2.0 * next() - 1.0);
                        let p = at(along, u, v);
                        if within.is_none_or(|b| b.contains(p)) || attempt == 63 {
                            if let Some(q) = fit(p) {
                                out.push((format!("random {k}"), q));
                            }
                            break;
                        }
                    }
                }
                out
            }
        }
    }
}

/// The affine map between the world and the canonical frame of an object impostor (see the
/// module docs): `origin` is the reference viewpoint, `forward` the view axis, `right`/`down` the
/// impostor's column and row directions, `tan` the frustum's half-angle tangents across them.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectFrame {
    pub origin: DVec3,
    pub forward: DVec3,
    pub right: DVec3,
    pub down: DVec3,
    pub tan: [f64; 2],
}

impl ObjectFrame {
    /// The canonical point of the world point `p` (face `+Z`: right `+X`, down `−Y`).
    pub fn to_canonical(&self, p: DVec3) -> DVec3 {
        let r = p - self.origin;
        DVec3::new(
            r.dot(self.right) / self.tan[0],
            -r.dot(self.down) / self.tan[1],
            r.dot(self.forward),
        )
    }

    /// The world point of the canonical point `c` (inverse of [`ObjectFrame::to_canonical`]).
    pub fn to_world(&self, c: DVec3) -> DVec3 {
        self.origin + self.right * (c.x * self.tan[0]) - self.down * (c.y * self.tan[1])
            + self.forward * c.z
    }

    /// Checks that the frame is a usable map (finite, orthonormal axes, positive tangents): a
    /// damaged file must not produce NaN corners.
    pub fn validate(&self) -> Result<(), String> {
        let axes = [self.forward, self.right, self.down];
        if !self.origin.is_finite() || axes.iter().any(|a| !a.is_finite()) {
            return Err("the object frame is not finite".into());
        }
        for (i, a) in axes.iter().enumerate() {
            if (a.length() - 1.0).abs() > 1e-6 {
                return Err(format!("object frame axis {i} is not a unit vector"));
            }
            for b in &axes[i + 1..] {
                if a.dot(*b).abs() > 1e-6 {
                    return Err("the object frame's axes are not orthogonal".into());
                }
            }
        }
        if !self.tan.iter().all(|t| t.is_finite() && *t > 0.0) {
            return Err("the object frame's frustum tangents must be positive".into());
        }
        Ok(())
    }
}

/// A rectangular opening from a room to the outside (TR sec. 3, portal impostors; Rafferty et al.
/// 1998): centred on `center`, in the plane through it across `outward` (the unit normal pointing
/// out of the room, toward what the impostor shows), with half sizes `half` along the right and
/// down directions of a view along `outward` (for a vertical wall: half the width along the wall,
/// half the height).
///
/// **Its impostor.** The view cell is the shaft with its apex at the opening's centre opening into
/// the room ([`Portal::view_cell`]: apex angle β, at least `min_distance` from the opening), the
/// reference viewpoint `s` = `min_distance`·tan(β/2) behind its near border (the TR's shaft
/// choice). A viewpoint `v` of the shaft sees beyond the opening only along `w − v` for `w` in the
/// opening; across the axis such a ray rises at most tan(β/2) + half/`min_distance` per unit of
/// depth (the farthest lateral viewpoint at the near border looking past the far edge), and a
/// point of the ray beyond the opening, seen from the reference viewpoint (which lies on the axis
/// behind all of that), rises less. So the frustum with those tangents ([`Portal::frame`]) holds
/// everything any viewpoint of the cell can see through the opening, whatever lies beyond it: the
/// object is whatever lies wholly in that frustum beyond a near distance ([`Portal::select`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Portal {
    pub center: DVec3,
    pub outward: DVec3,
    pub half: [f64; 2],
    /// The room behind the opening, where its viewers stand: the view cell is the shaft's part
    /// inside it (`None`: the whole shaft).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub room: Option<Aabb>,
}

impl Portal {
    /// Parses `cx,cy,cz,nx,ny,nz,width,height` (the opening's centre, its outward normal, its
    /// width along the wall and its height) and checks it ([`Portal::validate`]).
    pub fn parse(spec: &str) -> Result<Portal, ObjectError> {
        let v = numbers(
            spec,
            8,
            "the opening's centre cx,cy,cz, its outward normal nx,ny,nz, its width and height",
        )
        .map_err(ObjectError::ViewCell)?;
        let n = DVec3::new(v[3], v[4], v[5]);
        let p = Portal {
            center: DVec3::new(v[0], v[1], v[2]),
            outward: if n.length() > 0.0 { n.normalize() } else { n },
            half: [0.5 * v[6], 0.5 * v[7]],
            room: None,
        };
        p.validate()?;
        Ok(p)
    }

    /// Checks the opening: finite, a unit normal, a positive width and height.
    pub fn validate(&self) -> Result<(), ObjectError> {
        let bad = |m: String| Err(ObjectError::ViewCell(m));
        if !self.center.is_finite() {
            return bad("the portal's centre must be finite".into());
        }
        if !self.outward.is_finite() || (self.outward.length() - 1.0).abs() > 1e-9 {
            return bad("the portal's outward normal must be a non-zero vector".into());
        }
        if !self.half.iter().all(|h| h.is_finite() && *h > 0.0) {
            return bad(format!(
                "the portal's width and height {} x {} must be positive",
                2.0 * self.half[0],
                2.0 * self.half[1]
            ));
        }
        Ok(())
    }

    /// The opening as the flag that gives it (`cx,cy,cz,nx,ny,nz,width,height`).
    pub fn describe(&self) -> String {
        let (c, n) = (self.center, self.outward);
        format!(
            "{},{},{},{},{},{},{},{}",
            c.x,
            c.y,
            c.z,
            n.x,
            n.y,
            n.z,
            2.0 * self.half[0],
            2.0 * self.half[1]
        )
    }

    /// The opening's four corners (world).
    pub fn corners(&self) -> [DVec3; 4] {
        let (right, down) = basis(self.outward);
        [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .map(|(u, v)| self.center + right * (u * self.half[0]) + down * (v * self.half[1]))
    }

    /// The shaft cell of the opening: apex at its centre, opening into the room (against
    /// `outward`) with apex angle `angle_deg`, from `min_distance` on, to `max_distance` (the
    /// room's far side) if given.
    pub fn view_cell(
        &self,
        angle_deg: f64,
        min_distance: f64,
        max_distance: Option<f64>,
    ) -> Result<ObjectViewCell, ObjectError> {
        self.validate()?;
        let cell = ObjectViewCell::Shaft {
            apex: self.center,
            dir: -self.outward,
            angle_deg,
            min_distance,
            max_distance,
            within: self.room,
        };
        cell.validate()?;
        Ok(cell)
    }

    /// The impostor's frame for the shaft cell of [`Portal::view_cell`] (see the type's docs).
    pub fn frame(&self, angle_deg: f64, min_distance: f64) -> Result<ObjectFrame, ObjectError> {
        self.view_cell(angle_deg, min_distance, None)?;
        let forward = self.outward;
        let (right, down) = basis(forward);
        let t = (0.5 * angle_deg.to_radians()).tan();
        let s = ObjectCell::Shaft {
            apex_angle: angle_deg.to_radians(),
            apex_distance: min_distance,
            reach: None,
        }
        .recommended_s([0.0, 0.0]);
        Ok(ObjectFrame {
            origin: self.center - forward * (min_distance + s),
            forward,
            right,
            down,
            tan: self
                .half
                .map(|h| (t + h / min_distance) * (1.0 + FRUSTUM_SLACK)),
        })
    }

    /// The triangles of `scene` a portal impostor with `frame` ([`Portal::frame`]) replaces:
    /// every one lying wholly in the frustum and at least `near` beyond the opening's plane,
    /// except those wholly inside `keep` (the building the rooms belong to, drawn as geometry).
    /// A triangle reaching out of the frustum or nearer than `near` stays geometry (it may be
    /// seen through another opening, or from where the impostor does not serve).
    pub fn select(
        &self,
        frame: &ObjectFrame,
        scene: &Scene,
        keep: &Aabb,
        near: f64,
    ) -> Vec<TriRef> {
        let plane = (self.center - frame.origin).dot(frame.forward) + near.max(0.0);
        let mut out = Vec::new();
        for (m, mesh) in scene.meshes.iter().enumerate() {
            for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
                let mut kept = true;
                let mut inside = true;
                for &i in tri {
                    let Some(v) = mesh.vertices.get(i as usize) else {
                        inside = false;
                        continue;
                    };
                    let p = DVec3::from_array(v.position.map(f64::from));
                    kept &= keep.contains(p);
                    let c = frame.to_canonical(p);
                    inside &= c.z >= plane && c.x.abs() <= c.z && c.y.abs() <= c.z;
                }
                if inside && !kept {
                    out.push(TriRef {
                        mesh: m as u32,
                        tri: t as u32,
                    });
                }
            }
        }
        out
    }
}

/// An object impostor's setup: the view cell, the object's box, the frame and the TR's placement
/// inputs ([`ObjectParams`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectSetup {
    pub cell: ObjectViewCell,
    /// The object's bounding box (world).
    pub object: Aabb,
    pub frame: ObjectFrame,
    pub params: ObjectParams,
    /// For a portal impostor ([`ObjectSetup::through_portal`]): the opening the outside is seen
    /// through; the frustum is then set by the opening and the shaft, not by the object's box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub portal: Option<Portal>,
    /// For a portal impostor of a building whose every opening was baked together
    /// (`lemi bake-object --portal all`): the whole building, so that a renderer may restrict
    /// the outside to the openings' part of the view ([`Enclosure`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub enclosure: Option<Enclosure>,
}

/// Depth of the frustum's near plane in front of the object's near side, relative, so that no
/// triangle of the object is classified into the near field by rounding.
const NEAR_SLACK: f64 = 1e-6;
/// Relative widening of the frustum beyond the object's outermost corner (rounding).
const FRUSTUM_SLACK: f64 = 1e-6;

impl ObjectSetup {
    /// Sets up the impostor of the object whose box is `object` for `cell`, with `alpha` the
    /// allowed parallax angle and `res` the texels across the impostor (`None`: Schaufler's
    /// rule, [`schaufler_res`], for the object's near face seen from the cell's nearest point).
    pub fn new(
        cell: ObjectViewCell,
        object: Aabb,
        res: Option<u32>,
        alpha: f64,
    ) -> Result<ObjectSetup, ObjectError> {
        cell.validate()?;
        if object.is_empty() || !object.min.is_finite() || !object.max.is_finite() {
            return Err(ObjectError::Object(
                "it has no finite extent (no triangles selected?)".into(),
            ));
        }
        let corners = box_corners(&object);
        // the axis, the reference viewpoint (s behind the near border) and the TR's cell
        let (forward, near_border_point, s_of, tr_cell) = match cell {
            ObjectViewCell::Box { min, max } => {
                // the axis along which the object lies wholly beyond the cell, largest gap first
                let mut best: Option<(f64, DVec3)> = None;
                for a in 0..3 {
                    let e = DVec3::AXES[a];
                    for (gap, dir) in [(object.min[a] - max[a], e), (min[a] - object.max[a], -e)] {
                        if gap > 0.0 && best.is_none_or(|(g, _)| gap > g) {
                            best = Some((gap, dir));
                        }
                    }
                }
                let Some((_, forward)) = best else {
                    return Err(ObjectError::Overlap(format!(
                        "the object's box {:?} to {:?} overlaps the view cell {:?} to {:?} along every axis; an object impostor needs the object wholly beyond one side of the cell",
                        object.min.to_array(),
                        object.max.to_array(),
                        min.to_array(),
                        max.to_array()
                    )));
                };
                let (right, down) = basis(forward);
                let size = max - min;
                let width = [size.dot(right).abs(), size.dot(down).abs()];
                let depth = size.dot(forward).abs();
                let centre = 0.5 * (min + max);
                let near_border = centre + forward * (0.5 * depth);
                let obj_size = object.size();
                let obj_w = [obj_size.dot(right).abs(), obj_size.dot(down).abs()];
                let tr = ObjectCell::Box { width, depth };
                let s = tr.recommended_s(obj_w);
                (forward, near_border, s, tr)
            }
            ObjectViewCell::Shaft {
                apex,
                dir,
                angle_deg,
                min_distance,
                max_distance,
                ..
            } => {
                let tr = ObjectCell::Shaft {
                    apex_angle: angle_deg.to_radians(),
                    apex_distance: min_distance,
                    reach: max_distance.map(|m| m - min_distance),
                };
                let s = tr.recommended_s([0.0, 0.0]);
                (-dir, apex + dir * min_distance, s, tr)
            }
        };
        let (right, down) = basis(forward);
        let origin = near_border_point - forward * s_of;
        // the symmetric frustum through the reference viewpoint holding every corner
        let mut tan = [0.0f64; 2];
        for c in &corners {
            let r = *c - origin;
            let d = r.dot(forward);
            tan[0] = tan[0].max(r.dot(right).abs() / d);
            tan[1] = tan[1].max(r.dot(down).abs() / d);
        }
        // a flat object (a facade seen edge-on) still needs a frustum with some width
        let floor = 1e-6 * (tan[0].max(tan[1])).max(1e-9);
        let tan = tan.map(|t| t.max(floor) * (1.0 + FRUSTUM_SLACK));
        let frame = ObjectFrame {
            origin,
            forward,
            right,
            down,
            tan,
        };
        ObjectSetup::assemble(cell, object, frame, s_of, tr_cell, None, res, alpha)
    }

    /// Sets up the impostor of what is seen through `portal` (TR sec. 3: portal impostors) from
    /// its shaft cell ([`Portal::view_cell`]): the frame is [`Portal::frame`], set by the opening
    /// and the shaft alone, and `object` is the box of the triangles it replaces
    /// ([`Portal::select`]), which must lie wholly beyond the opening's plane.
    #[allow(clippy::too_many_arguments)]
    pub fn through_portal(
        portal: &Portal,
        angle_deg: f64,
        min_distance: f64,
        max_distance: Option<f64>,
        object: Aabb,
        res: Option<u32>,
        alpha: f64,
    ) -> Result<ObjectSetup, ObjectError> {
        let cell = portal.view_cell(angle_deg, min_distance, max_distance)?;
        let frame = portal.frame(angle_deg, min_distance)?;
        let tr_cell = ObjectCell::Shaft {
            apex_angle: angle_deg.to_radians(),
            apex_distance: min_distance,
            reach: max_distance.map(|m| m - min_distance),
        };
        let s = tr_cell.recommended_s([0.0, 0.0]);
        if !object.is_empty() {
            let plane = s + min_distance;
            let near = box_corners(&object)
                .iter()
                .map(|c| (*c - frame.origin).dot(frame.forward))
                .fold(f64::INFINITY, f64::min);
            if near.is_nan() || near < plane * (1.0 - NEAR_SLACK) {
                return Err(ObjectError::Overlap(format!(
                    "the object's box {:?} to {:?} reaches {:.3} m behind the portal's plane",
                    object.min.to_array(),
                    object.max.to_array(),
                    plane - near
                )));
            }
        }
        ObjectSetup::assemble(cell, object, frame, s, tr_cell, Some(*portal), res, alpha)
    }

    /// The setup of `object` seen through `frame` (its frustum already chosen) from `cell`: the
    /// TR's `t0` and depth from the object's box, the impostor's size at its near side and the
    /// resolution (`None`: Schaufler's rule).
    #[allow(clippy::too_many_arguments)]
    fn assemble(
        cell: ObjectViewCell,
        object: Aabb,
        frame: ObjectFrame,
        s_of: f64,
        tr_cell: ObjectCell,
        portal: Option<Portal>,
        res: Option<u32>,
        alpha: f64,
    ) -> Result<ObjectSetup, ObjectError> {
        if object.is_empty() || !object.min.is_finite() || !object.max.is_finite() {
            return Err(ObjectError::Object(
                "it has no finite extent (no triangles selected?)".into(),
            ));
        }
        let depths: Vec<f64> = box_corners(&object)
            .iter()
            .map(|c| (*c - frame.origin).dot(frame.forward))
            .collect();
        let near = depths.iter().copied().fold(f64::INFINITY, f64::min);
        let far = depths.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let t0 = near - s_of;
        if t0.is_nan() || t0 <= 0.0 {
            return Err(ObjectError::Overlap(format!(
                "the object's box {:?} to {:?} reaches {:.3} m into the view cell (its nearest point must lie beyond the cell's border nearest it)",
                object.min.to_array(),
                object.max.to_array(),
                -t0
            )));
        }
        let size = frame.tan.map(|t| 2.0 * (t0 + s_of) * t);
        let res = match res {
            Some(r) => r,
            None => schaufler_res(size[0].max(size[1]), t0, alpha)?,
        };
        let params = ObjectParams {
            cell: tr_cell,
            s: s_of,
            t0,
            depth: far - near,
            size,
            res,
            alpha,
        };
        params.validate()?;
        Ok(ObjectSetup {
            cell,
            object,
            frame,
            params,
            portal,
            enclosure: None,
        })
    }

    /// The TR's layers for this setup (near to far, TR coordinates).
    pub fn place(&self) -> Result<ObjectPlacement, ObjectError> {
        Ok(place_object_layers(&self.params)?)
    }

    /// The canonical view cell the bake records from: centred on the reference viewpoint (the
    /// canonical origin), with the cell's half widths across and `s` along the axis (only its
    /// centre enters the recording: there is no near geometry to seam).
    pub fn canonical_cell(&self) -> ViewCell {
        let n = self.params.cell.near_width();
        ViewCell {
            index: glam::IVec3::ZERO,
            center: DVec3::ZERO,
            half: DVec3::new(0.5 * n[0], 0.5 * n[1], self.params.s.max(1e-9)),
        }
    }

    /// The recording plan of `placement` in the canonical frame: one face (`+Z`), its layers far
    /// to near at depths `t + s` from the reference viewpoint, each recording its slab between the
    /// TR's borders (the nearest from just in front of the object, the farthest unbounded), and a
    /// near field just in front of the object (it holds nothing of the object).
    pub fn plan(&self, placement: &ObjectPlacement) -> CellPlan {
        let s = self.params.s;
        let near_field = (self.params.t0 + s) * (1.0 - NEAR_SLACK);
        let n = placement.layers.len();
        let layers: Vec<Layer> = placement
            .layers
            .iter()
            .enumerate()
            .rev()
            .map(|(k, l)| Layer {
                distance: l.distance + s,
                near_border: if k == 0 {
                    near_field
                } else {
                    l.near_border + s
                },
                far_border: if k + 1 == n {
                    f64::INFINITY
                } else {
                    l.far_border + s
                },
                bound_by: l.bound_by,
            })
            .collect();
        let borders: Vec<f64> = layers.iter().map(|l| l.near_border).collect();
        let half = self.params.cell.near_width();
        CellPlan {
            faces: vec![FacePlan {
                face: Face::PosZ,
                placement: Placement {
                    layers,
                    near_field,
                    params: EnvParams {
                        along: s,
                        across: [0.5 * half[0], 0.5 * half[1]],
                        res: self.params.res,
                        alpha: self.params.alpha,
                    },
                },
                slabs: Slabs::from_borders(&borders),
            }],
            near_field,
        }
    }

    /// A point to look at from the cell: the centre of the object's box, or for a portal
    /// impostor the point on the axis at the object's near side (looking through the opening).
    pub fn object_centre(&self) -> DVec3 {
        match self.portal {
            Some(_) => self.frame.origin + self.frame.forward * (self.params.t0 + self.params.s),
            None => self.object.center(),
        }
    }
}

/// The bounding box of the triangles `object` of `scene` (references past the scene are skipped:
/// the caller built the list from the scene).
pub fn object_bounds(scene: &Scene, object: &[TriRef]) -> Aabb {
    let mut b = Aabb::EMPTY;
    for r in object {
        let Some(mesh) = scene.meshes.get(r.mesh as usize) else {
            continue;
        };
        let i = 3 * r.tri as usize;
        for &v in mesh.indices.get(i..i + 3).unwrap_or(&[]) {
            if let Some(v) = mesh.vertices.get(v as usize) {
                b.grow(glam::DVec3::from_array(v.position.map(f64::from)));
            }
        }
    }
    b
}

/// The triangles `object` of `scene` in the canonical frame of `frame` (positions mapped, normals,
/// texture coordinates, colours and materials as they are).
pub fn canonical_scene(
    scene: &Scene,
    object: &[TriRef],
    frame: &ObjectFrame,
) -> Result<Scene, ExtractError> {
    let mut meshes = scene.extract(object)?;
    let mut bounds = Aabb::EMPTY;
    for mesh in &mut meshes {
        for v in &mut mesh.vertices {
            let c = frame.to_canonical(glam::DVec3::from_array(v.position.map(f64::from)));
            bounds.grow(c);
            v.position = c.as_vec3().to_array();
        }
    }
    Ok(Scene {
        meshes,
        materials: scene.materials.clone(),
        textures: scene.textures.clone(),
        bounds,
        stats: scene.stats.clone(),
        sources: scene.sources.clone(),
    })
}

/// Every triangle of `scene` not in `object` (in any order; references to no triangle of the
/// scene are ignored), in scene order. Linear in the scene's and the object's triangles: one flag
/// per triangle, no sort (a portal walk takes the complement of a near list of most of a city
/// once per opening).
pub fn complement(scene: &Scene, object: &[TriRef]) -> Vec<[u32; 2]> {
    let mut first = Vec::with_capacity(scene.meshes.len() + 1);
    let mut total = 0usize;
    for mesh in &scene.meshes {
        first.push(total);
        total += mesh.triangle_count();
    }
    first.push(total);
    let mut taken = vec![false; total];
    for r in object {
        let (m, t) = (r.mesh as usize, r.tri as usize);
        if let (Some(&start), Some(&end)) = (first.get(m), first.get(m + 1)) {
            if t < end - start {
                taken[start + t] = true;
            }
        }
    }
    let mut out = Vec::with_capacity(total.saturating_sub(object.len()));
    for (m, mesh) in scene.meshes.iter().enumerate() {
        let start = first[m];
        for t in 0..mesh.triangle_count() {
            if !taken[start + t] {
                out.push([m as u32, t as u32]);
            }
        }
    }
    out
}

/// A cell as drawn from a viewpoint with object impostors (GI 2002's near field, TR sec. 3): each
/// of `objects` (an object bundle's cell file) whose object has triangles in `base`'s near list
/// replaces them: they leave the near list, its quads and macro-textures join `base`'s (macro
/// indices renumbered). The caller passes only the objects whose view cell holds the viewpoint
/// (outside it an object stays geometry). Quads carry world corners, so the result draws as one
/// cell; its layers and faces stay `base`'s (the objects' quads keep their own layer numbers,
/// which order them within their draw calls only). Errors when an object's texture format
/// differs from `base`'s, or `base` is itself an object cell. Returns the composed cell and how
/// many objects were composed.
pub fn compose_objects(
    base: &crate::bundle::CellFile,
    objects: &[&crate::bundle::CellFile],
) -> Result<(crate::bundle::CellFile, usize), String> {
    if base.header.object.is_some() {
        return Err("an object bundle's cell cannot take further object impostors".into());
    }
    let mut out = base.clone();
    let mut composed = 0;
    for (k, o) in objects.iter().enumerate() {
        if o.header.object.is_none() {
            return Err(format!("object {k}: not an object impostor's cell"));
        }
        if o.header.texture_format != base.header.texture_format {
            return Err(format!(
                "object {k}: its textures are {}, the cell's {} (bake both with the same --texture-format)",
                o.header.texture_format, base.header.texture_format
            ));
        }
        // the object's triangles are those its cell does not draw as geometry
        let drawn: std::collections::HashSet<[u32; 2]> = o.near.iter().copied().collect();
        let before = out.near.len();
        out.near.retain(|t| drawn.contains(t));
        if out.near.len() == before {
            // the object is not in this cell's near field: the layers already show it
            continue;
        }
        composed += 1;
        let offset = out.header.macros.len() as u32;
        for (i, (m, blob)) in o.header.macros.iter().zip(&o.macro_blobs).enumerate() {
            let mut m = m.clone();
            m.name = format!("object{k}-{i}-{}", m.name);
            out.header.macros.push(m);
            out.macro_blobs.push(blob.clone());
        }
        out.header
            .quads
            .extend(o.header.quads.iter().map(|q| crate::bundle::Quad {
                macro_index: q.macro_index + offset,
                ..*q
            }));
    }
    Ok((out, composed))
}

/// The 8 corners of a box.
pub fn box_corners(b: &Aabb) -> [DVec3; 8] {
    std::array::from_fn(|k| {
        DVec3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn dragon_box(distance: f64) -> (ObjectViewCell, Aabb) {
        // a 10 m cubic cell at the origin, a 20 m object whose near side is `distance` from
        // the cell's border along +X
        let cell = ObjectViewCell::Box {
            min: DVec3::splat(-5.0),
            max: DVec3::splat(5.0),
        };
        let object = Aabb::new(
            DVec3::new(5.0 + distance, -10.0, -10.0),
            DVec3::new(25.0 + distance, 10.0, 10.0),
        );
        (cell, object)
    }

    #[test]
    fn box_setup_matches_the_tr_geometry() {
        let (cell, object) = dragon_box(42.0);
        let setup = ObjectSetup::new(cell, object, Some(512), 1e-3).expect("setup");
        let f = &setup.frame;
        assert!((f.forward - DVec3::X).length() < 1e-12);
        // the object (20 m) is wider than the cell (10 m): s = m/2
        assert_eq!(setup.params.s, 5.0);
        assert!((setup.params.t0 - 42.0).abs() < 1e-9);
        assert!((setup.params.depth - 20.0).abs() < 1e-9);
        // frustum fits the near face: half width 10 m at t0 + s = 47 m
        assert!((f.tan[0] - 10.0 / 47.0).abs() < 1e-5, "{:?}", f.tan);
        assert!((setup.params.size[0] - 20.0).abs() < 1e-4);
        assert_eq!(f.origin, DVec3::ZERO);
    }

    #[test]
    fn overlapping_and_malformed_cells_are_refused() {
        let cell = ObjectViewCell::Box {
            min: DVec3::splat(-5.0),
            max: DVec3::splat(5.0),
        };
        let inside = Aabb::new(DVec3::splat(-1.0), DVec3::splat(1.0));
        assert!(matches!(
            ObjectSetup::new(cell, inside, Some(64), 1e-3),
            Err(ObjectError::Overlap(_))
        ));
        for bad in [
            "box:0,0,0,1,0,1",
            "box:0,0,0,1,1",
            "box:0,0,0,1,1,nan",
            "shaft:0,0,0,0,0,1,180,5",
            "shaft:0,0,0,0,0,1,0,5",
            "shaft:0,0,0,0,0,0,30,5",
            "shaft:0,0,0,0,0,1,30,-1",
            "cone:0,0,0",
            "box",
        ] {
            let e = ObjectViewCell::parse(bad).expect_err(bad);
            assert!(matches!(e, ObjectError::ViewCell(_)), "{bad}: {e}");
        }
        // a shaft whose cell reaches into the object
        let shaft = ObjectViewCell::parse("shaft:0,0,0,1,0,0,30,2").expect("shaft");
        assert!(matches!(
            ObjectSetup::new(
                shaft,
                Aabb::new(DVec3::splat(-5.0), DVec3::splat(5.0)),
                Some(64),
                1e-3
            ),
            Err(ObjectError::Overlap(_))
        ));
    }

    #[test]
    fn shaft_contains_its_eval_viewpoints_and_not_the_apex_side() {
        let shaft = ObjectViewCell::parse("shaft:10,2,-3,0.3,0.2,1,40,25").expect("shaft");
        for (label, p) in shaft.eval_viewpoints(8, 3) {
            assert!(shaft.contains(p), "{label} {p}");
        }
        assert!(!shaft.contains(DVec3::new(10.0, 2.0, -3.0)));
        let ObjectViewCell::Shaft { dir, .. } = shaft else {
            unreachable!()
        };
        // beyond the side of the shaft at the near border
        let (right, _) = basis(-dir);
        let p = DVec3::new(10.0, 2.0, -3.0) + dir * 30.0 + right * 30.0;
        assert!(!shaft.contains(p));
    }

    #[test]
    fn plan_is_far_to_near_in_canonical_depths() {
        let (cell, object) = dragon_box(96.0);
        let setup = ObjectSetup::new(cell, object, Some(512), 5e-4).expect("setup");
        let placement = setup.place().expect("placement");
        let plan = setup.plan(&placement);
        let layers = &plan.faces[0].placement.layers;
        assert_eq!(layers.len(), placement.layers.len());
        for w in layers.windows(2) {
            assert!(w[0].distance > w[1].distance);
            assert_eq!(w[0].near_border, w[1].far_border);
        }
        let nearest = layers.last().expect("a layer");
        assert!(nearest.near_border < setup.params.t0 + setup.params.s);
        assert!(layers[0].far_border.is_infinite());
        for l in layers {
            assert!(l.near_border <= l.distance && l.distance <= l.far_border);
        }
    }

    #[test]
    fn portal_setup_and_selection() {
        // a 1.2 x 1.4 m window in a wall facing -Z, a shaft of 90 degrees from 1.5 m
        let portal = Portal::parse("5,1.75,-7.3,0,0,-1,1.2,1.4").expect("portal");
        let frame = portal.frame(90.0, 1.5).expect("frame");
        assert!((frame.forward - DVec3::NEG_Z).length() < 1e-12);
        assert!(
            (frame.tan[0] - (1.0 + 0.6 / 1.5)).abs() < 1e-5,
            "{:?}",
            frame.tan
        );
        assert!(
            (frame.tan[1] - (1.0 + 0.7 / 1.5)).abs() < 1e-5,
            "{:?}",
            frame.tan
        );
        // s = 1.5 m: the reference viewpoint 3 m behind the opening, on its axis
        assert!((frame.origin - DVec3::new(5.0, 1.75, -4.3)).length() < 1e-9);
        for bad in [
            "5,1.75,-7.3,0,0,0,1.2,1.4",
            "5,1.75,-7.3,0,0,-1,0,1.4",
            "1,2,3",
        ] {
            assert!(Portal::parse(bad).is_err(), "{bad}");
        }
        assert!(portal.view_cell(180.0, 1.5, None).is_err());
        assert!(portal.view_cell(90.0, 0.0, None).is_err());
        assert!(portal.view_cell(90.0, 1.5, Some(1.0)).is_err());
        // one triangle far out on the axis, one reaching out of the frustum, one inside the
        // kept building, one nearer than `near`
        let tri = |a: [f32; 3], b: [f32; 3], c: [f32; 3]| {
            let v = |p: [f32; 3]| crate::Vertex::new(p, [0.0, 1.0, 0.0], [0.0; 2], [255; 4]);
            crate::Mesh {
                vertices: vec![v(a), v(b), v(c)],
                indices: vec![0, 1, 2],
                ..Default::default()
            }
        };
        let scene = Scene {
            meshes: vec![
                tri([4.0, 0.0, -40.0], [6.0, 0.0, -40.0], [5.0, 3.0, -41.0]),
                tri([4.0, 0.0, -20.0], [90.0, 0.0, -20.0], [5.0, 3.0, -21.0]),
                tri([4.0, 0.0, -5.0], [6.0, 0.0, -5.0], [5.0, 3.0, -6.0]),
                tri([4.0, 0.0, -9.0], [6.0, 0.0, -9.0], [5.0, 3.0, -9.5]),
            ],
            ..Default::default()
        };
        let building = Aabb::new(DVec3::new(0.0, 0.0, -7.3), DVec3::new(10.0, 6.0, 0.0));
        let object = portal.select(&frame, &scene, &building, 3.0);
        assert_eq!(object, vec![TriRef { mesh: 0, tri: 0 }]);
        let bounds = object_bounds(&scene, &object);
        let setup = ObjectSetup::through_portal(&portal, 90.0, 1.5, Some(8.0), bounds, None, 2e-3)
            .expect("setup");
        assert_eq!(setup.portal, Some(portal));
        assert!((setup.params.t0 - (40.0 - 7.3 + 1.5)).abs() < 1e-6);
        // serialised without a portal, read back as None (older object bundles)
        let json = serde_json::to_string(&setup).expect("json");
        let back: ObjectSetup = serde_json::from_str(&json).expect("back");
        assert_eq!(back, setup);
        // clipped to the room: viewpoints under the floor or in the next room are not in the cell,
        // and every judged viewpoint is in the room
        let room = Aabb::new(DVec3::new(12.5, 0.45, -6.8), DVec3::new(19.9, 2.85, -0.4));
        let roomed = Portal {
            center: DVec3::new(16.2, 1.75, -7.3),
            room: Some(room),
            ..portal
        };
        let cell = roomed.view_cell(90.0, 1.5, Some(6.9)).expect("cell");
        assert!(cell.contains(DVec3::new(16.2, 1.75, -3.0)));
        assert!(
            !cell.contains(DVec3::new(16.2, -0.5, -1.0)),
            "under the floor"
        );
        assert!(
            !cell.contains(DVec3::new(21.0, 1.75, -1.0)),
            "beyond the side wall"
        );
        let views = cell.eval_viewpoints(16, 5);
        assert!(views.len() >= 16 + 3, "{}", views.len());
        for (label, p) in &views {
            assert!(room.contains(*p) && cell.contains(*p), "{label} {p}");
        }
        // an object behind the opening's plane is refused
        let behind = Aabb::new(DVec3::new(4.0, 0.0, -7.0), DVec3::new(6.0, 1.0, -6.0));
        assert!(matches!(
            ObjectSetup::through_portal(&portal, 90.0, 1.5, None, behind, None, 2e-3),
            Err(ObjectError::Overlap(_))
        ));
    }

    proptest! {
        #[test]
        fn the_complement_is_every_triangle_not_taken(
            sizes in proptest::collection::vec(0usize..40, 0..6),
            taken in proptest::collection::vec((0u32..8, 0u32..50), 0..120),
        ) {
            let mut b = crate::SceneBuilder::new();
            b.add_material(crate::Material::default());
            for &n in &sizes {
                // triangle k: (3k, 0), (3k + 1, 1), (3k + 2, 0), none degenerate
                let v = |i: usize| {
                    let y = if i % 3 == 1 { 1.0 } else { 0.0 };
                    crate::Vertex::new([i as f32, y, 1.0], [0.0, 0.0, 1.0], [0.0; 2], [255; 4])
                };
                b.add_mesh(crate::Mesh {
                    material: 0,
                    vertices: (0..3 * n).map(v).collect(),
                    indices: (0..3 * n as u32).collect(),
                });
            }
            let scene = b.finish();
            prop_assert_eq!(scene.triangle_count(), sizes.iter().sum::<usize>() as u64);
            let object: Vec<TriRef> = taken.iter().map(|&(mesh, tri)| TriRef { mesh, tri }).collect();
            // brute force: every triangle of the scene, in order, unless some reference names it
            let mut expected = Vec::new();
            for (m, mesh) in scene.meshes.iter().enumerate() {
                for t in 0..mesh.triangle_count() as u32 {
                    if !object.iter().any(|r| r.mesh == m as u32 && r.tri == t) {
                        expected.push([m as u32, t]);
                    }
                }
            }
            prop_assert_eq!(complement(&scene, &object), expected);
        }

        #[test]
        fn everything_seen_through_a_portal_lies_in_its_frustum(
            nx in -1.0f64..1.0, ny in -1.0f64..1.0, nz in -1.0f64..1.0,
            hw in 0.1f64..3.0, hh in 0.1f64..3.0,
            angle in 10.0f64..160.0, dmin in 0.2f64..10.0,
            along in 0.0f64..40.0, u in -1.0f64..1.0, v in -1.0f64..1.0,
            a in -1.0f64..1.0, b in -1.0f64..1.0, lambda in 1.0f64..1e4,
        ) {
            let n = DVec3::new(nx, ny, nz);
            prop_assume!(n.length() > 0.1);
            let portal = Portal { center: DVec3::new(1.0, 2.0, 3.0), outward: n.normalize(), half: [hw, hh], room: None };
            let frame = portal.frame(angle, dmin).expect("frame");
            // a viewpoint of the shaft cell, a point of the opening, a point beyond it on the ray
            let (right, down) = basis(portal.outward);
            let reach = (dmin + along) * (0.5 * angle.to_radians()).tan();
            let eye = portal.center - portal.outward * (dmin + along) + (right * u + down * v) * reach;
            let cell = portal.view_cell(angle, dmin, None).expect("cell");
            prop_assert!(cell.contains(eye * (1.0 - 1e-12) + portal.center * 1e-12) || (u.abs().max(v.abs()) > 0.999));
            let w = portal.center + right * (a * hw) + down * (b * hh);
            let x = eye + (w - eye) * lambda;
            let c = frame.to_canonical(x);
            prop_assert!(c.z > 0.0);
            prop_assert!(c.x.abs() <= c.z * (1.0 + 1e-9) && c.y.abs() <= c.z * (1.0 + 1e-9), "{c}");
        }

        #[test]
        fn frame_maps_invert_and_the_object_lies_in_the_pyramid(
            dx in -1.0f64..1.0, dy in -1.0f64..1.0, dz in -1.0f64..1.0,
            angle in 5.0f64..170.0, dist in 1.0f64..50.0,
            half in 0.5f64..20.0, back in 0.1f64..30.0,
        ) {
            let dir = DVec3::new(dx, dy, dz);
            prop_assume!(dir.length() > 0.1);
            let dir = dir.normalize();
            let apex = DVec3::new(3.0, -2.0, 7.0);
            let spec = format!(
                "shaft:{},{},{},{},{},{},{angle},{dist}",
                apex.x, apex.y, apex.z, dir.x, dir.y, dir.z
            );
            let shaft = ObjectViewCell::parse(&spec).expect("shaft");
            // an object around the apex, wholly beyond the near border
            let object = Aabb::new(apex - DVec3::splat(half.min(0.9 * dist / 1.8)), apex + DVec3::splat(half.min(0.9 * dist / 1.8)));
            let setup = ObjectSetup::new(shaft, object, Some(256), 1e-3).expect("setup");
            let f = setup.frame;
            prop_assert!(f.validate().is_ok());
            for c in box_corners(&object) {
                let q = f.to_canonical(c);
                prop_assert!((f.to_world(q) - c).length() < 1e-9 * (1.0 + c.length()));
                // inside the +Z face's 90° pyramid and beyond the near field
                prop_assert!(q.x.abs() <= q.z * (1.0 + 1e-9) && q.y.abs() <= q.z * (1.0 + 1e-9));
                prop_assert!(q.z >= setup.params.t0 + setup.params.s - 1e-9);
            }
            // the reference viewpoint lies in the cell, s behind its near border
            let eye = f.origin + dir * 1e-9 * dist;
            prop_assert!(shaft.contains(eye) || setup.params.s == 0.0);
            let _ = back;
            // a canonical layer square maps to the frustum cross-section
            let p = f.to_world(Face::PosZ.point(1.0, -1.0, 10.0));
            let r = p - f.origin;
            prop_assert!((r.dot(f.right) / r.dot(f.forward) - f.tan[0]).abs() < 1e-9);
            prop_assert!((r.dot(f.down) / r.dot(f.forward) + f.tan[1]).abs() < 1e-9);
        }
    }
}
