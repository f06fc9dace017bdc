//! An interactive walk's camera: fly/walk movement from held keys, looking by mouse drag or arrow
//! keys, and path recording in the `lemi-path` format that [`crate::walk`] replays
//! ([`crate::path`]; yaw 0 looks along −Z, 90 along +X, pitch up positive).
//!
//! Pure state, no window: the viewer's event loop (`lemi view`) feeds it keys, mouse motion and
//! frame times, so the movement rules and the recording are unit-tested here.

use glam::DVec3;

use crate::{CameraPath, Key, Pose};

/// The highest pitch the viewer turns to (degrees); the path format allows ±90, but at ±90 the
/// heading is ambiguous to a person steering.
pub const MAX_PITCH_DEG: f64 = 89.0;

/// Degrees of turn per pixel of mouse drag.
pub const DRAG_DEG_PER_PX: f64 = 0.15;

/// Degrees per second the arrow keys turn.
pub const ARROW_DEG_PER_S: f64 = 90.0;

/// Speed factor while shift is held.
pub const FAST_FACTOR: f64 = 4.0;

/// Which movement keys are held.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Held {
    pub forward: bool,
    pub back: bool,
    pub left: bool,
    pub right: bool,
    pub up: bool,
    pub down: bool,
    pub fast: bool,
    pub turn_left: bool,
    pub turn_right: bool,
    pub look_up: bool,
    pub look_down: bool,
}

/// Fly (free 3D movement, Q/E down/up, W follows the pitch) or walk (horizontal movement at a
/// fixed eye height).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MoveMode {
    Fly,
    Walk,
}

/// The viewer's camera and how it moves.
#[derive(Clone, Debug, PartialEq)]
pub struct FlyCamera {
    pub eye: DVec3,
    /// Degrees, unwrapped (a recorded path then never turns the long way round).
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub mode: MoveMode,
    /// The eye height walking keeps (the height when walking was switched on).
    pub walk_height: f64,
    /// m/s walking and flying (shift: [`FAST_FACTOR`] times faster).
    pub walk_speed: f64,
    pub fly_speed: f64,
}

impl FlyCamera {
    pub fn new(eye: DVec3, yaw_deg: f64, pitch_deg: f64, mode: MoveMode) -> FlyCamera {
        FlyCamera {
            eye,
            yaw_deg,
            pitch_deg: pitch_deg.clamp(-MAX_PITCH_DEG, MAX_PITCH_DEG),
            mode,
            walk_height: eye.y,
            walk_speed: 2.0,
            fly_speed: 10.0,
        }
    }

    /// The pose now (velocity zero; the caller knows the frame's motion).
    pub fn pose(&self) -> Pose {
        Pose {
            eye: self.eye,
            yaw_deg: self.yaw_deg,
            pitch_deg: self.pitch_deg,
            velocity: DVec3::ZERO,
        }
    }

    /// Switches between fly and walk; walking keeps the current eye height.
    pub fn toggle_mode(&mut self) -> MoveMode {
        self.mode = match self.mode {
            MoveMode::Fly => {
                self.walk_height = self.eye.y;
                MoveMode::Walk
            }
            MoveMode::Walk => MoveMode::Fly,
        };
        self.mode
    }

    /// Turns by a mouse drag of `(dx, dy)` window pixels (right turns right, up looks up).
    pub fn drag(&mut self, dx: f64, dy: f64) {
        if dx.is_finite() && dy.is_finite() {
            self.turn(dx * DRAG_DEG_PER_PX, -dy * DRAG_DEG_PER_PX);
        }
    }

    fn turn(&mut self, yaw: f64, pitch: f64) {
        self.yaw_deg += yaw;
        self.pitch_deg = (self.pitch_deg + pitch).clamp(-MAX_PITCH_DEG, MAX_PITCH_DEG);
    }

    /// Moves for `dt` seconds with the keys `held`; returns the eye's velocity (m/s).
    pub fn step(&mut self, held: &Held, dt: f64) -> DVec3 {
        if !(dt.is_finite() && dt > 0.0) {
            return DVec3::ZERO;
        }
        let axis = |plus: bool, minus: bool| (plus as i32 - minus as i32) as f64;
        self.turn(
            axis(held.turn_right, held.turn_left) * ARROW_DEG_PER_S * dt,
            axis(held.look_up, held.look_down) * ARROW_DEG_PER_S * dt,
        );
        let (sy, cy) = self.yaw_deg.to_radians().sin_cos();
        let (sp, cp) = self.pitch_deg.to_radians().sin_cos();
        let right = DVec3::new(cy, 0.0, sy);
        let (forward, up, speed) = match self.mode {
            MoveMode::Fly => (
                DVec3::new(sy * cp, sp, -cy * cp),
                axis(held.up, held.down),
                self.fly_speed,
            ),
            MoveMode::Walk => (DVec3::new(sy, 0.0, -cy), 0.0, self.walk_speed),
        };
        let dir = forward * axis(held.forward, held.back)
            + right * axis(held.right, held.left)
            + DVec3::Y * up;
        let speed = if held.fast {
            speed * FAST_FACTOR
        } else {
            speed
        };
        let velocity = dir.normalize_or_zero() * speed;
        self.eye += velocity * dt;
        if self.mode == MoveMode::Walk {
            self.eye.y = self.walk_height;
        }
        velocity
    }
}

/// A path being recorded: one key per frame at most every `1 / (2 · fps)` seconds.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    pub fps: f64,
    /// Seconds since the recording started.
    pub t: f64,
    pub keys: Vec<Key>,
    /// The latest pose when it came too soon after the last key (kept so the path ends there).
    pending: Option<Key>,
}

impl Recording {
    /// Starts recording at `pose` (its first key, `t = 0`).
    pub fn start(fps: f64, pose: &Pose) -> Recording {
        let mut r = Recording {
            fps,
            t: 0.0,
            keys: Vec::new(),
            pending: None,
        };
        r.push_key(pose);
        r
    }

    fn key(&self, pose: &Pose) -> Key {
        Key {
            t: self.t,
            eye: pose.eye.to_array(),
            yaw_deg: pose.yaw_deg,
            pitch_deg: pose.pitch_deg,
        }
    }

    fn push_key(&mut self, pose: &Pose) {
        self.keys.push(self.key(pose));
        self.pending = None;
    }

    /// Advances the clock by `dt` seconds and records `pose` there (a key when at least half a
    /// frame of the path's rate has passed since the last one; the end of the path in any case).
    pub fn advance(&mut self, dt: f64, pose: &Pose) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        self.t += dt;
        let last = self.keys.last().map_or(f64::NEG_INFINITY, |k| k.t);
        if self.t - last >= 0.5 / self.fps {
            self.push_key(pose);
        } else {
            self.pending = Some(self.key(pose));
        }
    }

    /// Seconds recorded.
    pub fn duration(&self) -> f64 {
        self.t
    }

    /// Poses the path will have.
    pub fn len(&self) -> usize {
        self.keys.len() + usize::from(self.pending.is_some())
    }

    /// No pose recorded yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The path, or `None` with fewer than 2 poses (nothing to replay).
    pub fn finish(mut self) -> Option<CameraPath> {
        if let Some(k) = self.pending.take() {
            self.keys.push(k);
        }
        (self.keys.len() >= 2).then(|| CameraPath::new(self.fps, self.keys))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn held(f: impl FnOnce(&mut Held)) -> Held {
        let mut h = Held::default();
        f(&mut h);
        h
    }

    #[test]
    fn w_moves_along_the_heading_of_the_path_convention() {
        let mut c = FlyCamera::new(DVec3::new(0.0, 1.7, 0.0), 90.0, 0.0, MoveMode::Walk);
        let v = c.step(&held(|h| h.forward = true), 1.0);
        assert!((v - DVec3::new(2.0, 0.0, 0.0)).length() < 1e-9, "{v}");
        assert!((c.eye - DVec3::new(2.0, 1.7, 0.0)).length() < 1e-9);
        // the camera the walk replay builds from the same pose looks the same way
        let cam = c.pose().camera(60.0, 64, 64).unwrap();
        assert!((cam.forward - DVec3::X).length() < 1e-9);
        // yaw 0 looks along −Z; D strafes to +X
        let mut c = FlyCamera::new(DVec3::ZERO, 0.0, 0.0, MoveMode::Walk);
        c.step(&held(|h| h.right = true), 0.5);
        assert!((c.eye - DVec3::new(1.0, 0.0, 0.0)).length() < 1e-9);
        c.step(&held(|h| h.forward = true), 0.5);
        assert!((c.eye - DVec3::new(1.0, 0.0, -1.0)).length() < 1e-9);
    }

    #[test]
    fn walking_keeps_the_eye_height_and_flying_follows_the_pitch() {
        let mut c = FlyCamera::new(DVec3::new(0.0, 1.7, 0.0), 0.0, 45.0, MoveMode::Walk);
        c.step(&held(|h| h.forward = true), 1.0);
        c.step(&held(|h| h.up = true), 1.0);
        assert_eq!(c.eye.y, 1.7);
        assert!((c.eye.z + 2.0).abs() < 1e-9, "walking ignores the pitch");
        assert_eq!(c.toggle_mode(), MoveMode::Fly);
        let before = c.eye;
        c.step(&held(|h| h.forward = true), 1.0);
        let d = c.eye - before;
        assert!((d.length() - 10.0).abs() < 1e-9);
        assert!((d.y - 10.0 * 45f64.to_radians().sin()).abs() < 1e-9);
        c.step(&held(|h| h.up = true), 0.1);
        assert!((c.eye.y - (before.y + d.y + 1.0)).abs() < 1e-9);
        // shift is faster; walking again keeps the height reached
        let y = c.eye.y;
        assert_eq!(c.toggle_mode(), MoveMode::Walk);
        let v = c.step(
            &held(|h| {
                h.forward = true;
                h.fast = true
            }),
            0.1,
        );
        assert!((v.length() - 2.0 * FAST_FACTOR).abs() < 1e-9);
        assert_eq!(c.eye.y, y);
    }

    #[test]
    fn dragging_turns_and_the_pitch_is_clamped() {
        let mut c = FlyCamera::new(DVec3::ZERO, 0.0, 0.0, MoveMode::Fly);
        c.drag(100.0, 0.0);
        assert!((c.yaw_deg - 100.0 * DRAG_DEG_PER_PX).abs() < 1e-9);
        c.drag(0.0, -100_000.0);
        assert_eq!(c.pitch_deg, MAX_PITCH_DEG);
        c.drag(f64::NAN, 1.0);
        assert!(c.yaw_deg.is_finite());
        c.step(&held(|h| h.turn_left = true), 1.0);
        assert!((c.yaw_deg - (100.0 * DRAG_DEG_PER_PX - ARROW_DEG_PER_S)).abs() < 1e-9);
    }

    #[test]
    fn a_recording_is_a_path_walk_replays() {
        let mut c = FlyCamera::new(DVec3::new(0.0, 1.7, 0.0), 0.0, 0.0, MoveMode::Walk);
        let mut rec = Recording::start(30.0, &c.pose());
        for _ in 0..90 {
            c.step(&held(|h| h.forward = true), 1.0 / 60.0);
            c.drag(1.0, 0.0);
            rec.advance(1.0 / 60.0, &c.pose());
        }
        assert!((rec.duration() - 1.5).abs() < 1e-9);
        // at most one key per half frame of the path's rate
        assert!(rec.len() <= 1 + 90 && rec.len() >= 40, "{}", rec.len());
        let path = rec.finish().expect("a path");
        path.validate().expect("valid");
        let dir = std::env::temp_dir().join(format!("lemi-view-rec-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("path.json");
        path.write(&file).unwrap();
        let back = CameraPath::read(&file).unwrap();
        assert_eq!(back, path);
        let end = back.sample(back.duration());
        assert!((end.eye - c.eye).length() < 1e-9);
        assert!((end.yaw_deg - c.yaw_deg).abs() < 1e-9);
        std::fs::remove_dir_all(&dir).ok();
        // a recording of one instant is no path
        assert!(Recording::start(30.0, &c.pose()).finish().is_none());
    }
}
