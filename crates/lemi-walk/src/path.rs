//! Camera paths of a walk: the JSON file that `lemi walk --path` replays and the interactive
//! viewer records, its validation, sampling at the path's frame rate, and the automatic
//! walkthrough + flyover of `lemi walk --auto` that stays inside the baked view cells (GI 2002
//! sec. 3: the impostors of a cell are valid only while the viewer is inside it; the paper's
//! Figs. 8–9 measure such a walkthrough).
//!
//! # Format (`lemi-path`, version 1)
//! ```json
//! {
//!   "format": "lemi-path",
//!   "version": 1,
//!   "fps": 30,
//!   "keys": [
//!     { "t": 0.0, "eye": [0.0, 1.7, 0.0], "yaw_deg": 0.0,  "pitch_deg": 0.0 },
//!     { "t": 2.5, "eye": [3.5, 1.7, 0.0], "yaw_deg": 90.0, "pitch_deg": -5.0 }
//!   ]
//! }
//! ```
//! - `format` must be `"lemi-path"` and `version` must be `1` (other versions are rejected).
//! - `fps`: frames per second of the replay, a number in `1..=1000`. Frame `i` is at
//!   `t = keys[0].t + i / fps`, for every such `t` up to the last key's time.
//! - `keys`: at least 2 key poses with strictly increasing times `t` (seconds, finite).
//!   - `eye`: the eye position in world metres (right-handed, +Y up).
//!   - `yaw_deg`: the heading in degrees, the convention of
//!     [`lemi_core::camera::Camera::from_yaw_pitch`]: yaw 0 looks along −Z, 90 along +X
//!     (clockwise seen from above, like a compass), any finite value.
//!   - `pitch_deg`: degrees above the horizon, within `[-90, 90]` (positive looks up).
//! - Unknown fields are ignored, so a writer may add its own (e.g. a `"note"`).
//!
//! Between two keys the pose is interpolated **linearly**: the eye along the segment, the pitch
//! linearly, the yaw along the **shorter arc** (so `350` → `10` turns 20° through north, and a turn
//! of more than 180° needs intermediate keys). At a key's time the pose is exactly the key's. Before
//! the first key and after the last the camera holds still.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::Path;

use glam::DVec3;
use lemi_core::camera::{Camera, CameraError};
use lemi_core::cell::{CellGrid, ViewCell};
use serde::{Deserialize, Serialize};

use crate::WalkError;

/// The `format` string of a camera path file.
pub const FORMAT: &str = "lemi-path";
/// The version this code reads and writes.
pub const VERSION: u32 = 1;
/// The most frames a path may have (a guard against absurd durations; 3.8 days at 30 fps).
pub const MAX_FRAMES: u64 = 10_000_000;

/// One key pose of a path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Key {
    /// Seconds.
    pub t: f64,
    /// World position of the eye (metres).
    pub eye: [f64; 3],
    pub yaw_deg: f64,
    pub pitch_deg: f64,
}

/// A camera path: key poses sampled at `fps`. See the module doc for the file format.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraPath {
    pub format: String,
    pub version: u32,
    pub fps: f64,
    pub keys: Vec<Key>,
}

/// The camera at one instant of a path.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    pub eye: DVec3,
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    /// Eye velocity (m/s): the slope of the segment the instant lies on (at a key, the segment
    /// that starts there; at the last key, the last segment); zero outside the path's time span.
    pub velocity: DVec3,
}

/// What is wrong with a path (or with the input of [`auto_path`]); each names the field at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("`format` is `{0}`, expected `{FORMAT}`")]
    Format(String),
    #[error("`version` {0} is not supported (this lemi reads version {VERSION})")]
    Version(u32),
    #[error("`fps` must be a number in 1..=1000, got {0}")]
    Fps(f64),
    #[error("`keys` needs at least 2 key poses, got {0}")]
    TooFewKeys(usize),
    #[error("`keys[{key}].{field}` must be a finite number, got {value}")]
    NonFinite {
        key: usize,
        field: String,
        value: f64,
    },
    #[error("`keys[{key}].pitch_deg` must be within [-90, 90], got {value}")]
    Pitch { key: usize, value: f64 },
    #[error(
        "`keys[{key}].t` = {t} must be greater than `keys[{prev}].t` = {prev_t} (times must increase)",
        prev = key - 1
    )]
    NotIncreasing { key: usize, t: f64, prev_t: f64 },
    #[error("the path has {frames} frames ({seconds} s at {fps} fps), more than the limit of {MAX_FRAMES}")]
    TooLong { frames: f64, seconds: f64, fps: f64 },
    #[error("no baked cells to walk through")]
    NoCells,
    #[error("baked cell {0} is not a cell of the grid")]
    CellNotInGrid(String),
    #[error("{name} must be a finite speed > 0 (m/s), got {value}")]
    Speed { name: &'static str, value: f64 },
}

impl Pose {
    /// The unit view direction: `(sin yaw · cos pitch, sin pitch, −cos yaw · cos pitch)`.
    pub fn forward(&self) -> DVec3 {
        let (sy, cy) = self.yaw_deg.to_radians().sin_cos();
        let (sp, cp) = self.pitch_deg.to_radians().sin_cos();
        DVec3::new(sy * cp, sp, -cy * cp)
    }

    /// The camera of this pose (via [`Camera::from_yaw_pitch`]).
    pub fn camera(&self, fov_y_deg: f64, width: u32, height: u32) -> Result<Camera, CameraError> {
        Camera::from_yaw_pitch(
            self.eye,
            self.yaw_deg,
            self.pitch_deg,
            fov_y_deg,
            width,
            height,
        )
    }

    fn of(key: &Key, velocity: DVec3) -> Pose {
        Pose {
            eye: DVec3::from_array(key.eye),
            yaw_deg: key.yaw_deg,
            pitch_deg: key.pitch_deg,
            velocity,
        }
    }
}

/// `d` wrapped into `[-180, 180]` degrees.
fn wrap_deg(d: f64) -> f64 {
    d - 360.0 * (d / 360.0).round()
}

impl CameraPath {
    /// A path of the current format and version.
    pub fn new(fps: f64, keys: Vec<Key>) -> CameraPath {
        CameraPath {
            format: FORMAT.to_string(),
            version: VERSION,
            fps,
            keys,
        }
    }

    /// Checks everything the module doc promises: format, version, fps, at least 2 keys, finite
    /// numbers, pitch range, strictly increasing times, and at most [`MAX_FRAMES`] frames.
    pub fn validate(&self) -> Result<(), PathError> {
        if self.format != FORMAT {
            return Err(PathError::Format(self.format.clone()));
        }
        if self.version != VERSION {
            return Err(PathError::Version(self.version));
        }
        if !(1.0..=1000.0).contains(&self.fps) {
            return Err(PathError::Fps(self.fps));
        }
        if self.keys.len() < 2 {
            return Err(PathError::TooFewKeys(self.keys.len()));
        }
        for (i, k) in self.keys.iter().enumerate() {
            let fields = [
                ("t".to_string(), k.t),
                ("eye[0]".to_string(), k.eye[0]),
                ("eye[1]".to_string(), k.eye[1]),
                ("eye[2]".to_string(), k.eye[2]),
                ("yaw_deg".to_string(), k.yaw_deg),
                ("pitch_deg".to_string(), k.pitch_deg),
            ];
            for (field, value) in fields {
                if !value.is_finite() {
                    return Err(PathError::NonFinite {
                        key: i,
                        field,
                        value,
                    });
                }
            }
            if !(-90.0..=90.0).contains(&k.pitch_deg) {
                return Err(PathError::Pitch {
                    key: i,
                    value: k.pitch_deg,
                });
            }
            if i > 0 && k.t <= self.keys[i - 1].t {
                return Err(PathError::NotIncreasing {
                    key: i,
                    t: k.t,
                    prev_t: self.keys[i - 1].t,
                });
            }
        }
        let seconds = self.duration();
        let frames = (seconds * self.fps).floor() + 1.0;
        if frames.is_nan() || frames > MAX_FRAMES as f64 {
            return Err(PathError::TooLong {
                frames,
                seconds,
                fps: self.fps,
            });
        }
        Ok(())
    }

    /// Reads and validates a path file; errors name the file and the field.
    pub fn read(path: &Path) -> Result<CameraPath, WalkError> {
        let text =
            std::fs::read_to_string(path).map_err(|e| WalkError::io("camera path", path, e))?;
        let json = |source| WalkError::Json {
            what: "camera path",
            path: path.to_path_buf(),
            source,
        };
        let bad = |source| WalkError::Path {
            path: path.to_path_buf(),
            source,
        };
        // The header first, so that another format or version gets its own message rather than
        // an error about a field that version may not have.
        #[derive(Deserialize)]
        struct Header {
            format: Option<String>,
            version: Option<u32>,
        }
        let header: Header = serde_json::from_str(&text).map_err(json)?;
        match header.format.as_deref() {
            Some(FORMAT) => {}
            Some(other) => return Err(bad(PathError::Format(other.to_string()))),
            None => {
                return Err(WalkError::NotAPath {
                    path: path.to_path_buf(),
                })
            }
        }
        if let Some(v) = header.version.filter(|&v| v != VERSION) {
            return Err(bad(PathError::Version(v)));
        }
        let p: CameraPath = serde_json::from_str(&text).map_err(json)?;
        p.validate().map_err(bad)?;
        Ok(p)
    }

    /// Validates and writes the path as pretty JSON, atomically (temporary file + rename).
    pub fn write(&self, path: &Path) -> Result<(), WalkError> {
        self.validate().map_err(|source| WalkError::Path {
            path: path.to_path_buf(),
            source,
        })?;
        let mut text = serde_json::to_string_pretty(self).map_err(|source| WalkError::Json {
            what: "camera path",
            path: path.to_path_buf(),
            source,
        })?;
        text.push('\n');
        lemi_core::container::write_atomic(path, text.as_bytes())
            .map_err(|e| WalkError::io("camera path", path, e))
    }

    /// Seconds from the first key to the last (0 for fewer than 2 keys).
    pub fn duration(&self) -> f64 {
        match (self.keys.first(), self.keys.last()) {
            (Some(a), Some(b)) => b.t - a.t,
            _ => 0.0,
        }
    }

    /// Frames [`CameraPath::frames`] yields: `floor(duration · fps) + 1` (0 for an empty path or
    /// a bad fps).
    pub fn frame_count(&self) -> u64 {
        if self.keys.is_empty() || !(self.fps > 0.0 && self.fps.is_finite()) {
            return 0;
        }
        let n = (self.duration() * self.fps + 1e-9).floor();
        if n.is_finite() && n >= 0.0 {
            (n as u64).saturating_add(1)
        } else {
            0
        }
    }

    /// The pose at time `t` (seconds), see the module doc. Never panics, even on an unvalidated
    /// path (no keys: the default pose).
    pub fn sample(&self, t: f64) -> Pose {
        let k = &self.keys;
        let n = k.len();
        if n == 0 {
            return Pose::default();
        }
        let seg_velocity = |i: usize| -> DVec3 {
            if i + 1 >= n {
                return DVec3::ZERO;
            }
            let dt = k[i + 1].t - k[i].t;
            if dt > 0.0 {
                (DVec3::from_array(k[i + 1].eye) - DVec3::from_array(k[i].eye)) / dt
            } else {
                DVec3::ZERO
            }
        };
        if n == 1 || t.is_nan() || t <= k[0].t {
            let v = if n > 1 && t == k[0].t {
                seg_velocity(0)
            } else {
                DVec3::ZERO
            };
            return Pose::of(&k[0], v);
        }
        if t >= k[n - 1].t {
            let v = if t == k[n - 1].t {
                seg_velocity(n - 2)
            } else {
                DVec3::ZERO
            };
            return Pose::of(&k[n - 1], v);
        }
        // k[i].t <= t < k[i + 1].t
        let i = k
            .partition_point(|key| key.t <= t)
            .saturating_sub(1)
            .min(n - 2);
        let (a, b) = (&k[i], &k[i + 1]);
        let v = seg_velocity(i);
        let dt = b.t - a.t;
        let f = if dt > 0.0 { (t - a.t) / dt } else { 0.0 };
        if f <= 0.0 {
            return Pose::of(a, v);
        }
        let ea = DVec3::from_array(a.eye);
        let eb = DVec3::from_array(b.eye);
        Pose {
            eye: ea + (eb - ea) * f,
            yaw_deg: a.yaw_deg + f * wrap_deg(b.yaw_deg - a.yaw_deg),
            pitch_deg: a.pitch_deg + f * (b.pitch_deg - a.pitch_deg),
            velocity: v,
        }
    }

    /// Every frame of the replay: `(frame index, t, pose)` with `t = keys[0].t + index / fps`.
    pub fn frames(&self) -> impl Iterator<Item = (u64, f64, Pose)> + '_ {
        let t0 = self.keys.first().map_or(0.0, |k| k.t);
        let fps = self.fps;
        (0..self.frame_count()).map(move |i| {
            let t = t0 + i as f64 / fps;
            (i, t, self.sample(t))
        })
    }
}

// ---------------------------------------------------------------------------------------------
// The automatic walkthrough + flyover.

/// Seconds between keys of the walk (more keys are added at every corner).
const WALK_KEY_DT: f64 = 0.5;
/// Seconds between keys of the flyover (its view sweeps, so keys are denser).
const FLY_KEY_DT: f64 = 0.1;
/// How fast the walker turns on the spot at a dead end (degrees per second) ...
const TURN_RATE_DEG: f64 = 90.0;
/// ... wherever the heading would otherwise change by more than this between two keys (degrees).
const MAX_TURN_DEG: f64 = 20.0;
/// How fast the flyover's view sweeps around (degrees per second): a full turn in 12 s.
const SWEEP_RATE_DEG: f64 = 30.0;
/// The flyover's view nods up and down by this much (degrees) ...
const NOD_DEG: f64 = 10.0;
/// ... with this period (seconds).
const NOD_PERIOD: f64 = 7.0;
/// The flyover flies this fraction of a half cell above the cell centres.
const FLY_LIFT: f64 = 0.45;
/// Corners are rounded with a radius of at most this fraction of a half cell, which keeps every
/// rounded corner inside the cell of its vertex (lift + radius < 1 half cell).
const CORNER: f64 = 0.45;
/// A cell with no baked neighbour is toured by a square of this fraction of its half extent.
const LOOP: f64 = 0.4;

#[derive(Clone, Copy, PartialEq)]
enum Motion {
    Walk,
    Fly,
}

/// A polyline of the automatic path, walked or flown; `jump_before`: not connected to the previous
/// piece through baked cells (another connected component of the baked cells).
struct Piece {
    mode: Motion,
    points: Vec<DVec3>,
    jump_before: bool,
}

/// A vertex of a rounded polyline with its unit tangent; two vertices at the same place stand for
/// a turn on the spot.
#[derive(Clone, Copy)]
struct Vtx {
    p: DVec3,
    tan: DVec3,
}

type Idx = [i32; 3];

const NEIGHBOURS: [Idx; 6] = [
    [1, 0, 0],
    [-1, 0, 0],
    [0, 1, 0],
    [0, -1, 0],
    [0, 0, 1],
    [0, 0, -1],
];

fn add(a: Idx, b: Idx) -> Idx {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Shortest route (in cells, 6-neighbourhood) from `a` to `b` through `cells`, both ends included.
fn bfs(cells: &HashMap<Idx, ViewCell>, a: Idx, b: Idx) -> Option<Vec<Idx>> {
    if a == b {
        return Some(vec![a]);
    }
    let mut prev: HashMap<Idx, Idx> = HashMap::new();
    let mut queue = VecDeque::from([a]);
    prev.insert(a, a);
    while let Some(c) = queue.pop_front() {
        for d in NEIGHBOURS {
            let n = add(c, d);
            if cells.contains_key(&n) && !prev.contains_key(&n) {
                prev.insert(n, c);
                if n == b {
                    let mut route = vec![b];
                    let mut x = b;
                    while x != a {
                        x = prev[&x];
                        route.push(x);
                    }
                    route.reverse();
                    return Some(route);
                }
                queue.push_back(n);
            }
        }
    }
    None
}

/// A route through `targets` in order, each consecutive pair joined by a shortest route.
fn route_through(cells: &HashMap<Idx, ViewCell>, targets: &[Idx]) -> Vec<Idx> {
    let mut route: Vec<Idx> = Vec::new();
    for &t in targets {
        match route.last() {
            None => route.push(t),
            Some(&last) => {
                // Targets are all in one connected component, so a route exists.
                if let Some(r) = bfs(cells, last, t) {
                    route.extend_from_slice(&r[1..]);
                }
            }
        }
    }
    route
}

/// A square tour inside one cell (centre `c` plus `lift`), from its centre and back.
fn local_loop(c: DVec3, half: f64, lift: DVec3) -> Vec<DVec3> {
    let a = LOOP * half;
    let q = c + lift;
    vec![
        q,
        q + DVec3::new(0.0, 0.0, -a),
        q + DVec3::new(a, 0.0, -a),
        q + DVec3::new(a, 0.0, a),
        q + DVec3::new(-a, 0.0, a),
        q + DVec3::new(-a, 0.0, -a),
        q + DVec3::new(0.0, 0.0, -a),
        q,
    ]
}

/// The polyline with its corners rounded by quadratic Bézier arcs (inside the triangle of the
/// corner and its two neighbours on the legs, hence inside the corner's cell) and U-turns made
/// turns on the spot.
fn round_corners(points: &[DVec3], r_max: f64) -> Vec<Vtx> {
    let mut pts: Vec<DVec3> = Vec::with_capacity(points.len());
    for &p in points {
        if pts.last().is_none_or(|&q: &DVec3| (q - p).length() > 1e-9) {
            pts.push(p);
        }
    }
    if pts.len() < 2 {
        return pts
            .iter()
            .map(|&p| Vtx {
                p,
                tan: DVec3::ZERO,
            })
            .collect();
    }
    let mut out = vec![Vtx {
        p: pts[0],
        tan: (pts[1] - pts[0]).normalize(),
    }];
    for i in 1..pts.len() - 1 {
        let (a, p, b) = (pts[i - 1], pts[i], pts[i + 1]);
        let (din, dout) = ((p - a).normalize(), (b - p).normalize());
        let cos = din.dot(dout);
        if cos > 1.0 - 1e-9 {
            continue; // straight on
        }
        if cos < -1.0 + 1e-9 {
            out.push(Vtx { p, tan: din });
            out.push(Vtx { p, tan: dout });
            continue;
        }
        let r = r_max
            .min(0.45 * (p - a).length())
            .min(0.45 * (b - p).length());
        let (s0, s1) = (p - din * r, p + dout * r);
        const N: usize = 8;
        for j in 0..=N {
            let s = j as f64 / N as f64;
            let q = s0 * (1.0 - s) * (1.0 - s) + p * 2.0 * s * (1.0 - s) + s1 * s * s;
            let d = (p - s0) * 2.0 * (1.0 - s) + (s1 - p) * 2.0 * s;
            out.push(Vtx {
                p: q,
                tan: d.normalize_or_zero(),
            });
        }
    }
    let n = pts.len();
    out.push(Vtx {
        p: pts[n - 1],
        tan: (pts[n - 1] - pts[n - 2]).normalize(),
    });
    out
}

/// The compass heading (yaw, degrees) of a direction, if it has a horizontal part.
fn heading(d: DVec3) -> Option<f64> {
    (d.x.hypot(d.z) > 1e-6).then(|| d.x.atan2(-d.z).to_degrees())
}

/// The cells in serpentine order: layer by layer in Y (from the top when `down`), within a layer
/// rows along axis `fast` stepping along axis `mid`, every other row (and every other layer's
/// row order) reversed, so consecutive cells of a full grid are neighbours.
fn serpentine(cells: &[Idx], mid: usize, fast: usize, down: bool) -> Vec<Idx> {
    let mut layers: BTreeMap<i32, BTreeMap<i32, Vec<Idx>>> = BTreeMap::new();
    for &c in cells {
        let y = if down { -c[1] } else { c[1] };
        layers
            .entry(y)
            .or_default()
            .entry(c[mid])
            .or_default()
            .push(c);
    }
    let mut out = Vec::with_capacity(cells.len());
    let mut row_no = 0usize;
    for (layer_no, rows) in layers.into_values().enumerate() {
        let mut rows: Vec<Vec<Idx>> = rows.into_values().collect();
        if layer_no % 2 == 1 {
            rows.reverse();
        }
        for mut row in rows {
            row.sort_by_key(|c| c[fast]);
            if row_no % 2 == 1 {
                row.reverse();
            }
            out.extend(row);
            row_no += 1;
        }
    }
    out
}

/// An automatic path through the baked cells, at `fps`:
///
/// 1. a **walkthrough** at `walk_speed` (m/s, e.g. 1.4) through every baked cell's centre (the
///    reference viewpoints, at the eye height the grid was made for), in serpentine order per
///    connected group of cells (rows along X, stepping along Z, then up a layer), joined by
///    shortest routes through baked cells, corners rounded, looking ahead along the motion and
///    turning on the spot at dead ends;
/// 2. a **flyover** at `fly_speed` (e.g. 10): up by 0.45 half cell from where the walk ended, then
///    a serpentine along the other axis (columns along Z), while the view sweeps around (a full
///    turn every 12 s) and nods ±10°.
///
/// Every point of the path is inside the union of the baked cells' boxes: straight legs join
/// centres of face-adjacent cells, rounded corners stay in their cell. Separate groups of baked
/// cells (not face-connected) are joined by a jump between two frames, so no frame is outside.
/// A group of one cell is toured by a small square inside it.
pub fn auto_path(
    grid: &CellGrid,
    baked: &[ViewCell],
    walk_speed: f64,
    fly_speed: f64,
    fps: f64,
) -> Result<CameraPath, PathError> {
    for (name, value) in [("walk speed", walk_speed), ("fly speed", fly_speed)] {
        if !(value.is_finite() && value > 0.0) {
            return Err(PathError::Speed { name, value });
        }
    }
    if !(1.0..=1000.0).contains(&fps) {
        return Err(PathError::Fps(fps));
    }
    if baked.is_empty() {
        return Err(PathError::NoCells);
    }
    let mut cells: HashMap<Idx, ViewCell> = HashMap::new();
    for c in baked {
        let ok = grid.cell(c.index).is_some_and(|g| {
            (g.center - c.center).abs().max_element() <= 1e-6 * grid.cell_size.max(1.0)
                && (g.half - c.half).abs().max_element() <= 1e-6 * grid.cell_size.max(1.0)
        });
        if !ok {
            return Err(PathError::CellNotInGrid(c.id().to_string()));
        }
        cells.insert(c.index.to_array(), *c);
    }
    let half = 0.5 * grid.cell_size;

    // Connected groups, in the order of their first cell (y, then z, then x).
    let mut order: Vec<Idx> = cells.keys().copied().collect();
    order.sort_by_key(|i| (i[1], i[2], i[0]));
    let mut group_of: HashMap<Idx, usize> = HashMap::new();
    let mut groups: Vec<Vec<Idx>> = Vec::new();
    for &start in &order {
        if group_of.contains_key(&start) {
            continue;
        }
        let g = groups.len();
        let mut members = vec![start];
        group_of.insert(start, g);
        let mut queue = VecDeque::from([start]);
        while let Some(c) = queue.pop_front() {
            for d in NEIGHBOURS {
                let n = add(c, d);
                if cells.contains_key(&n) && !group_of.contains_key(&n) {
                    group_of.insert(n, g);
                    members.push(n);
                    queue.push_back(n);
                }
            }
        }
        groups.push(members);
    }

    let centre = |i: &Idx| cells[i].center;
    // flat cells (`--cell-height`) are lower than wide: lift by their own vertical half extent
    let lift = DVec3::Y * (FLY_LIFT * 0.5 * grid.step().y);
    let mut pieces: Vec<Piece> = Vec::new();

    // 1. The walk: serpentine rows along X, stepping along Z, layer by layer in Y.
    let mut walk_end: Option<Idx> = None;
    for (g, members) in groups.iter().enumerate() {
        let targets = serpentine(members, 2, 0, false);
        let points = if targets.len() == 1 {
            local_loop(centre(&targets[0]), half, DVec3::ZERO)
        } else {
            route_through(&cells, &targets).iter().map(centre).collect()
        };
        walk_end = targets.last().copied();
        pieces.push(Piece {
            mode: Motion::Walk,
            points,
            jump_before: g > 0,
        });
    }

    // 2. The flyover: from the walk's end up, then serpentine columns along Z, stepping along X;
    // the group the walk ended in first, then the others.
    let last_group = groups.len() - 1;
    let fly_groups = std::iter::once(last_group).chain(0..last_group);
    for (n, g) in fly_groups.enumerate() {
        let mut targets = serpentine(&groups[g], 0, 2, true);
        let mut points = Vec::new();
        if n == 0 {
            if let Some(end) = walk_end {
                points.push(centre(&end));
                if targets.len() > 1 {
                    targets.insert(0, end);
                }
            }
        }
        if targets.len() == 1 {
            points.extend(local_loop(centre(&targets[0]), half, lift));
        } else {
            points.extend(
                route_through(&cells, &targets)
                    .iter()
                    .map(|i| centre(i) + lift),
            );
        }
        pieces.push(Piece {
            mode: Motion::Fly,
            points,
            jump_before: n > 0,
        });
    }

    // 3. Keys.
    let mut keys: Vec<Key> = Vec::new();
    let mut yaw = 0.0f64;
    let mut fly_t0: Option<(f64, f64)> = None; // (time, yaw) where the flyover began
    let push = |keys: &mut Vec<Key>, t: f64, p: DVec3, yaw: f64, pitch: f64| {
        if keys.last().is_none_or(|k: &Key| t > k.t) {
            keys.push(Key {
                t,
                eye: p.to_array(),
                yaw_deg: wrap_deg(yaw),
                pitch_deg: pitch,
            });
        }
    };
    for piece in &pieces {
        let vtx = round_corners(&piece.points, CORNER * half);
        let Some(first) = vtx.first() else { continue };
        let speed = match piece.mode {
            Motion::Walk => walk_speed,
            Motion::Fly => fly_speed,
        };
        let key_dt = match piece.mode {
            Motion::Walk => WALK_KEY_DT,
            Motion::Fly => FLY_KEY_DT,
        };
        let mut t = keys.last().map_or(0.0, |k| k.t);
        if piece.mode == Motion::Fly && fly_t0.is_none() {
            fly_t0 = Some((t, yaw));
        }
        let view = |t: f64, tan: DVec3, yaw: f64| -> (f64, f64) {
            match fly_t0 {
                Some((t0, y0)) if piece.mode == Motion::Fly => {
                    let s = t - t0;
                    (
                        y0 + SWEEP_RATE_DEG * s,
                        -NOD_DEG * (std::f64::consts::TAU * s / NOD_PERIOD).sin(),
                    )
                }
                _ => (heading(tan).map_or(yaw, |h| yaw + wrap_deg(h - yaw)), 0.0),
            }
        };
        if let Some(last) = keys.last().copied() {
            if piece.jump_before {
                // Hold until a frame time, jump half a frame later: no frame sees the jump.
                let tb = (last.t * fps - 1e-9).ceil() / fps;
                if tb > last.t {
                    push(
                        &mut keys,
                        tb,
                        DVec3::from_array(last.eye),
                        last.yaw_deg,
                        last.pitch_deg,
                    );
                }
                t = tb.max(last.t) + 0.5 / fps;
                let (y, pitch) = view(t, first.tan, yaw);
                yaw = y;
                push(&mut keys, t, first.p, yaw, pitch);
            }
        } else {
            let (y, pitch) = view(t, first.tan, heading(first.tan).unwrap_or(0.0));
            yaw = y;
            push(&mut keys, t, first.p, yaw, pitch);
        }
        for w in vtx.windows(2) {
            let (u, v) = (w[0], w[1]);
            let len = (v.p - u.p).length();
            let steps = if len <= 1e-12 {
                0
            } else {
                (len / (speed * key_dt)).ceil().max(1.0) as usize
            };
            if piece.mode == Motion::Walk {
                // Turn on the spot where the heading ahead differs by much: at dead ends (a
                // reversal turns clockwise) and where a vertical leg meets a horizontal one.
                let ahead = if steps == 0 {
                    v.tan
                } else {
                    let s = 1.0 / steps as f64;
                    u.tan * (1.0 - s) + v.tan * s
                };
                if let Some(h) = heading(ahead) {
                    let d = wrap_deg(h - yaw);
                    let d = if d.abs() > 179.0 { 180.0 } else { d };
                    if d.abs() > MAX_TURN_DEG {
                        let n = (d.abs() / MAX_TURN_DEG).ceil() as usize;
                        let (y0, dt) = (yaw, d.abs() / TURN_RATE_DEG / n as f64);
                        for j in 1..=n {
                            t += dt;
                            yaw = y0 + d * j as f64 / n as f64;
                            push(&mut keys, t, u.p, yaw, 0.0);
                        }
                    }
                }
            }
            for j in 1..=steps {
                let s = j as f64 / steps as f64;
                t += len / speed / steps as f64;
                let p = u.p + (v.p - u.p) * s;
                let tan = (u.tan * (1.0 - s) + v.tan * s).normalize_or_zero();
                let (y, pitch) = view(t, tan, yaw);
                yaw = y;
                push(&mut keys, t, p, yaw, pitch);
            }
        }
    }
    if keys.len() < 2 {
        // Cannot happen with at least one cell (its tour has length), but never panic.
        return Err(PathError::TooFewKeys(keys.len()));
    }
    let path = CameraPath::new(fps, keys);
    path.validate()?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::IVec3;
    use lemi_core::Aabb;

    fn key(t: f64, eye: [f64; 3], yaw: f64, pitch: f64) -> Key {
        Key {
            t,
            eye,
            yaw_deg: yaw,
            pitch_deg: pitch,
        }
    }

    fn two_keys() -> CameraPath {
        CameraPath::new(
            30.0,
            vec![
                key(0.0, [0.0, 1.7, 0.0], 350.0, 0.0),
                key(2.0, [4.0, 1.7, -2.0], 10.0, 20.0),
                key(3.0, [4.0, 1.7, -2.0], 10.0, 20.0),
            ],
        )
    }

    #[test]
    fn validation_names_the_field() {
        assert_eq!(two_keys().validate(), Ok(()));
        let mut p = two_keys();
        p.format = "other".into();
        assert_eq!(p.validate(), Err(PathError::Format("other".into())));
        let mut p = two_keys();
        p.version = 2;
        assert_eq!(p.validate(), Err(PathError::Version(2)));
        for fps in [0.5, 1001.0, f64::NAN] {
            let mut p = two_keys();
            p.fps = fps;
            assert!(matches!(p.validate(), Err(PathError::Fps(_))), "{fps}");
        }
        let mut p = two_keys();
        p.keys.truncate(1);
        assert_eq!(p.validate(), Err(PathError::TooFewKeys(1)));
        let mut p = two_keys();
        p.keys[1].eye[2] = f64::INFINITY;
        let e = p.validate().unwrap_err();
        assert!(e.to_string().contains("keys[1].eye[2]"), "{e}");
        let mut p = two_keys();
        p.keys[2].pitch_deg = 91.0;
        assert!(matches!(p.validate(), Err(PathError::Pitch { key: 2, .. })));
        let mut p = two_keys();
        p.keys[2].t = 2.0;
        let e = p.validate().unwrap_err();
        assert_eq!(
            e.to_string(),
            "`keys[2].t` = 2 must be greater than `keys[1].t` = 2 (times must increase)"
        );
        let mut p = two_keys();
        p.keys[2].t = 1e9;
        assert!(matches!(p.validate(), Err(PathError::TooLong { .. })));
    }

    #[test]
    fn sampling_is_exact_at_keys_and_linear_between() {
        let p = two_keys();
        for k in &p.keys {
            let s = p.sample(k.t);
            assert_eq!(s.eye.to_array(), k.eye);
            assert_eq!(s.yaw_deg, k.yaw_deg);
            assert_eq!(s.pitch_deg, k.pitch_deg);
        }
        let s = p.sample(1.0);
        assert!((s.eye - DVec3::new(2.0, 1.7, -1.0)).length() < 1e-12);
        // 350 -> 10 goes the short way, through 360.
        assert!((s.yaw_deg - 360.0).abs() < 1e-12, "{}", s.yaw_deg);
        assert!((s.pitch_deg - 10.0).abs() < 1e-12);
        assert!((s.velocity - DVec3::new(2.0, 0.0, -1.0)).length() < 1e-12);
        assert_eq!(p.sample(2.5).velocity, DVec3::ZERO);
        // Outside the time span the camera holds still.
        assert_eq!(p.sample(-1.0).eye.to_array(), p.keys[0].eye);
        assert_eq!(p.sample(9.0).velocity, DVec3::ZERO);
        assert_eq!(p.sample(f64::NAN).eye.to_array(), p.keys[0].eye);
        // Frames at 30 fps over 3 s: 91, the last at the last key.
        let frames: Vec<_> = p.frames().collect();
        assert_eq!(frames.len(), 91);
        assert_eq!(p.frame_count(), 91);
        assert_eq!(frames[30].0, 30);
        assert!((frames[30].1 - 1.0).abs() < 1e-12);
        assert_eq!(frames[90].2.eye.to_array(), p.keys[2].eye);
        // Forward and the camera follow the yaw/pitch convention.
        let f = Pose {
            yaw_deg: 90.0,
            ..Pose::default()
        };
        assert!((f.forward() - DVec3::X).length() < 1e-12);
        let cam = p.sample(0.0).camera(60.0, 8, 8).unwrap();
        assert!((cam.forward - p.sample(0.0).forward()).length() < 1e-12);
        // An unvalidated path never panics.
        let empty = CameraPath::new(30.0, vec![]);
        assert_eq!(empty.sample(1.0), Pose::default());
        assert_eq!(empty.frames().count(), 0);
    }

    #[test]
    fn read_write_round_trip_and_errors_name_the_file() {
        let dir = std::env::temp_dir().join(format!("lemi-walk-path-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("p.json");
        let p = two_keys();
        p.write(&file).unwrap();
        assert_eq!(CameraPath::read(&file).unwrap(), p);
        // The documented example reads, with integer numbers and unknown fields.
        std::fs::write(
            &file,
            r#"{ "format": "lemi-path", "version": 1, "fps": 30, "note": "x",
                 "keys": [ { "t": 0, "eye": [0, 1.7, 0], "yaw_deg": 0, "pitch_deg": 0 },
                           { "t": 2.5, "eye": [3.5, 1.7, 0], "yaw_deg": 90, "pitch_deg": -5 } ] }"#,
        )
        .unwrap();
        let q = CameraPath::read(&file).unwrap();
        assert_eq!(q.frame_count(), 76);
        let cases = [
            (
                r#"{"format": "lemi-path", "version": 2, "keys": 3}"#,
                "version` 2",
            ),
            (
                r#"{"format": "lemi-bundle", "version": 1}"#,
                "`format` is `lemi-bundle`",
            ),
            (r#"{"version": 1}"#, "no `format`"),
            (
                r#"{"format": "lemi-path", "version": 1, "fps": 30, "keys": [{"t": 0}]}"#,
                "eye",
            ),
            (
                r#"{"format": "lemi-path", "version": 1, "fps": 0, "keys": []}"#,
                "`fps`",
            ),
            ("not json", "expected"),
        ];
        for (text, want) in cases {
            std::fs::write(&file, text).unwrap();
            let e = format!("{:#}", CameraPath::read(&file).unwrap_err());
            assert!(e.contains("p.json"), "{e}");
            assert!(e.contains(want), "{e} (wanted {want})");
        }
        let e = format!(
            "{:#}",
            CameraPath::read(&dir.join("missing.json")).unwrap_err()
        );
        assert!(e.contains("missing.json"), "{e}");
        let mut bad = two_keys();
        bad.fps = 0.0;
        assert!(bad.write(&file).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Checks the auto path of `baked`: every frame inside a baked cell, every baked cell visited,
    /// speed and turn rate bounded except at the jumps between groups.
    fn check_auto(grid: &CellGrid, baked: &[ViewCell], jumps: usize) -> CameraPath {
        let (walk, fly, fps) = (1.4, 10.0, 30.0);
        let p = auto_path(grid, baked, walk, fly, fps).unwrap();
        p.validate().unwrap();
        let eps = 1e-9 * grid.cell_size;
        let inside = |e: DVec3| {
            baked.iter().any(|c| {
                let b = c.bounds();
                Aabb::new(b.min - eps, b.max + eps).contains(e)
            })
        };
        let mut visited = std::collections::HashSet::new();
        let mut prev: Option<Pose> = None;
        let mut big_moves = 0;
        for (i, _, pose) in p.frames() {
            assert!(inside(pose.eye), "frame {i} at {:?} is outside", pose.eye);
            if let Some(c) = grid.locate(pose.eye) {
                visited.insert(c.id());
            }
            if let Some(q) = prev {
                let step = (pose.eye - q.eye).length();
                if step > fly / fps * 1.001 {
                    big_moves += 1;
                } else {
                    let turn = wrap_deg(pose.yaw_deg - q.yaw_deg).abs();
                    assert!(turn < 12.0, "frame {i} turns {turn}°");
                    assert!((pose.pitch_deg - q.pitch_deg).abs() < 1.0);
                }
            }
            prev = Some(pose);
        }
        assert_eq!(big_moves, jumps);
        for c in baked {
            assert!(visited.contains(&c.id()), "cell {} not visited", c.id());
        }
        // The walk comes first and is slow, the flyover is faster.
        let speeds: Vec<f64> = p.frames().map(|f| f.2.velocity.length()).collect();
        assert!((speeds[1] - walk).abs() < 0.2 * walk, "{}", speeds[1]);
        assert!(speeds.iter().any(|&s| (s - fly).abs() < 1e-6 * fly));
        p
    }

    #[test]
    fn auto_path_strip_and_full_grid() {
        let region = Aabb::new(DVec3::new(0.0, 1.5, 0.0), DVec3::new(40.0, 1.9, 24.0));
        let grid = CellGrid::tile(region, 8.0).unwrap();
        let all = grid.cells();
        assert_eq!(all.len(), 15);
        check_auto(&grid, &all, 0);
        // A strip of cells along X.
        let strip: Vec<ViewCell> = all.iter().filter(|c| c.index.z == 1).copied().collect();
        let p = check_auto(&grid, &strip, 0);
        // The walk looks along +X (yaw 90) on its first leg.
        assert!((wrap_deg(p.sample(1.0).yaw_deg - 90.0)).abs() < 1e-9);
        // A single cell.
        check_auto(&grid, &all[7..8], 0);
        // Flat cells (1 m of eye height): the flyover stays inside them too.
        let flat = CellGrid::tile_with_height(region, 8.0, Some(1.0)).unwrap();
        check_auto(&flat, &flat.cells(), 0);
    }

    #[test]
    fn auto_path_irregular_groups_and_layers() {
        let region = Aabb::new(DVec3::ZERO, DVec3::new(20.0, 8.0, 20.0));
        let grid = CellGrid::tile(region, 4.0).unwrap();
        // An L shape with a dead end on layer 0, a cell above it on layer 1, and a lone cell.
        let ids = [
            [0, 0, 0],
            [1, 0, 0],
            [2, 0, 0],
            [2, 0, 1],
            [2, 0, 2],
            [1, 0, 2],
            [3, 0, 0],
            [0, 0, 4],
            [2, 1, 2],
            [4, 1, 4],
        ];
        let baked: Vec<ViewCell> = ids
            .iter()
            .map(|i| grid.cell(IVec3::from_array(*i)).unwrap())
            .collect();
        // Three groups: each jump is seen once by the walk and once by the flyover.
        check_auto(&grid, &baked, 4);
    }

    #[test]
    fn auto_path_rejects_bad_input() {
        let grid = CellGrid::tile(Aabb::new(DVec3::ZERO, DVec3::splat(8.0)), 4.0).unwrap();
        let cells = grid.cells();
        assert_eq!(
            auto_path(&grid, &[], 1.4, 10.0, 30.0),
            Err(PathError::NoCells)
        );
        assert!(matches!(
            auto_path(&grid, &cells, 0.0, 10.0, 30.0),
            Err(PathError::Speed { .. })
        ));
        assert!(matches!(
            auto_path(&grid, &cells, 1.4, f64::NAN, 30.0),
            Err(PathError::Speed { .. })
        ));
        assert!(matches!(
            auto_path(&grid, &cells, 1.4, 10.0, 0.0),
            Err(PathError::Fps(_))
        ));
        let mut stray = cells[0];
        stray.index = IVec3::new(9, 9, 9);
        assert_eq!(
            auto_path(&grid, &[stray], 1.4, 10.0, 30.0),
            Err(PathError::CellNotInGrid("9_9_9".into()))
        );
    }
}
