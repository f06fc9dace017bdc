//! Which view cells to have ready: the current cell, then the cells the viewer could reach within a
//! time horizon, soonest first.
//!
//! This work is based on the runtime of *Layered Environment-Map Impostors for Arbitrary Scenes*
//! (Jeschke, Wimmer et al., GI 2002, sec. 3, runtime step 2): "prefetch the geometry and
//! impostors of adjacent view cells … (assuming — as is common for most prefetching schemes — a
//! limited observer speed)".
//!
//! The limit is made explicit as two bounds on the observer, and every cell gets its **earliest
//! possible arrival time**, a lower bound under both:
//! - speed at most `s = max(max_speed, |v|)`: a cell at distance `d` is not reached before `d / s`;
//! - acceleration at most `a`: at time `t` the observer is within `a·t²/2` of `p + v·t` (where it
//!   would be if it kept its velocity), so the cell is not reached before the first `t` with
//!   `dist(cell, p + v·t) ≤ a·t²/2`.
//!
//! The arrival time is the larger of the two. Cells ahead (in the direction of motion) come first,
//! then cells to the side, cells behind last (the observer has to turn round); with `v = 0` the
//! order is by distance. A cell whose arrival time exceeds the horizon is not listed. Pure
//! functions, no I/O.

use glam::DVec3;
use lemi_core::cell::{CellGrid, ViewCell};
use lemi_core::Aabb;

/// The observer model and how far ahead to look.
#[derive(Clone, Debug, PartialEq)]
pub struct PredictOptions {
    /// Cells the observer may reach within this many seconds are listed.
    pub horizon_seconds: f64,
    /// The highest observer speed planned for (m/s); a faster current velocity raises it.
    pub max_speed: f64,
    /// The highest acceleration planned for (m/s²), turning included.
    pub max_acceleration: f64,
    /// At most this many cells are listed (the current cell included).
    pub max_cells: usize,
}

impl Default for PredictOptions {
    /// A walk-through: 2 s ahead, up to 10 m/s and 5 m/s², at most 27 cells.
    fn default() -> Self {
        PredictOptions {
            horizon_seconds: 2.0,
            max_speed: 10.0,
            max_acceleration: 5.0,
            max_cells: 27,
        }
    }
}

/// One cell to have ready.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prediction {
    pub cell: ViewCell,
    /// Earliest possible arrival (0 for the current cell).
    pub arrival_seconds: f64,
    /// Distance from the position to the cell's box (0 inside).
    pub distance: f64,
}

/// Bisection steps after sampling (the arrival time is exact to `horizon / SAMPLES / 2^STEPS`).
const BISECTION_STEPS: u32 = 40;
/// Samples of the horizon when looking for the first contact (a cell touched for less than
/// `horizon / SAMPLES` seconds by the reachable ball may be missed).
const SAMPLES: u32 = 128;
/// The most grid cells examined per call; beyond it the search radius shrinks.
const MAX_CANDIDATES: i64 = 100_000;

/// The cells to have ready at `position` moving with `velocity`: the current cell first (if the
/// position is inside the grid), then every cell whose earliest arrival is within the horizon,
/// by arrival time, then distance, then how far the cell's centre lies in the direction of
/// motion, then grid index. A non-finite position gives no cells; a non-finite velocity counts as
/// zero.
pub fn predict(
    position: DVec3,
    velocity: DVec3,
    grid: &CellGrid,
    options: &PredictOptions,
) -> Vec<Prediction> {
    if !position.is_finite() || grid.is_empty() || options.max_cells == 0 {
        return Vec::new();
    }
    let v = if velocity.is_finite() {
        velocity
    } else {
        DVec3::ZERO
    };
    let h = finite_or_zero(options.horizon_seconds);
    let a = finite_or_zero(options.max_acceleration);
    let s = finite_or_zero(options.max_speed).max(v.length());
    // How far the observer may get within the horizon (both bounds hold).
    let mut reach = (v.length() * h + 0.5 * a * h * h).min(s * h);
    if !reach.is_finite() {
        reach = 0.0;
    }
    let current = grid.locate(position);
    let (lo, hi) = loop {
        let lo = index_at(grid, position - DVec3::splat(reach));
        let hi = index_at(grid, position + DVec3::splat(reach));
        let n = (hi - lo + 1).max(glam::I64Vec3::ZERO);
        if n.x * n.y * n.z <= MAX_CANDIDATES || reach <= grid.cell_size {
            break (lo, hi);
        }
        reach *= 0.5;
    };
    let mut out = Vec::new();
    for y in lo.y..=hi.y {
        for z in lo.z..=hi.z {
            for x in lo.x..=hi.x {
                let index = glam::IVec3::new(x as i32, y as i32, z as i32);
                let Some(cell) = grid.cell(index) else {
                    continue;
                };
                let bounds = cell.bounds();
                let arrival = if Some(cell) == current {
                    Some(0.0)
                } else {
                    earliest_arrival(position, v, &bounds, s, a, h)
                };
                if let Some(arrival_seconds) = arrival {
                    out.push(Prediction {
                        cell,
                        arrival_seconds,
                        distance: distance_to_box(position, &bounds),
                    });
                }
            }
        }
    }
    let is_current = |p: &Prediction| Some(p.cell) == current;
    out.sort_by(|p, q| {
        is_current(q)
            .cmp(&is_current(p))
            .then(p.arrival_seconds.total_cmp(&q.arrival_seconds))
            .then(p.distance.total_cmp(&q.distance))
            .then(
                v.dot(q.cell.center - position)
                    .total_cmp(&v.dot(p.cell.center - position)),
            )
            .then((p.cell.index.y, p.cell.index.z, p.cell.index.x).cmp(&(
                q.cell.index.y,
                q.cell.index.z,
                q.cell.index.x,
            )))
    });
    out.truncate(options.max_cells);
    out
}

/// The earliest time (≤ `horizon`) at which an observer at `p` with velocity `v`, speed at most
/// `max_speed` and acceleration at most `max_acceleration`, can be inside `bounds`; `None` if it
/// cannot within the horizon. See the module docs for the model.
pub fn earliest_arrival(
    p: DVec3,
    v: DVec3,
    bounds: &Aabb,
    max_speed: f64,
    max_acceleration: f64,
    horizon: f64,
) -> Option<f64> {
    let d0 = distance_to_box(p, bounds);
    if d0 == 0.0 {
        return Some(0.0);
    }
    let (s, a, h) = (
        finite_or_zero(max_speed).max(v.length()),
        finite_or_zero(max_acceleration),
        finite_or_zero(horizon),
    );
    // s is finite and >= 0 here
    if s <= 0.0 || !d0.is_finite() {
        return None;
    }
    let t_speed = d0 / s;
    if t_speed > h || d0 > v.length() * h + 0.5 * a * h * h {
        return None;
    }
    // f(t) = dist(bounds, p + v t) − a t²/2: first t with f(t) ≤ 0.
    let f = |t: f64| distance_to_box(p + v * t, bounds) - 0.5 * a * t * t;
    let mut prev = 0.0;
    let mut hit = None;
    for k in 1..=SAMPLES {
        let t = h * k as f64 / SAMPLES as f64;
        if f(t) <= 0.0 {
            hit = Some((prev, t));
            break;
        }
        prev = t;
    }
    let (mut lo, mut hi) = hit?;
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (lo + hi);
        if f(mid) <= 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let t = hi.max(t_speed);
    (t <= h).then_some(t)
}

/// Euclidean distance from `p` to the box (0 inside or on it).
pub fn distance_to_box(p: DVec3, b: &Aabb) -> f64 {
    let d = (b.min - p).max(p - b.max).max(DVec3::ZERO);
    d.length()
}

fn finite_or_zero(x: f64) -> f64 {
    if x.is_finite() {
        x.max(0.0)
    } else {
        0.0
    }
}

/// Grid index of `p`, clamped to the grid (as i64 so that far-away points do not overflow).
fn index_at(grid: &CellGrid, p: DVec3) -> glam::I64Vec3 {
    // the cell's extent per axis (cells need not be cubes)
    let step = grid
        .cell(glam::IVec3::ZERO)
        .map_or(DVec3::splat(grid.cell_size), |c| 2.0 * c.half);
    let f = ((p - grid.origin) / step).floor();
    let max = (grid.counts - 1).as_dvec3();
    f.clamp(DVec3::ZERO, max.max(DVec3::ZERO)).as_i64vec3()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::IVec3;

    /// 5 × 1 × 5 cells of 10 m, cell (2, 0, 2) centred on the origin at eye height.
    fn grid() -> CellGrid {
        CellGrid::tile(
            Aabb::new(DVec3::new(-25.0, 1.7, -25.0), DVec3::new(25.0, 1.7, 25.0)),
            10.0,
        )
        .unwrap()
    }

    fn ids(p: &[Prediction]) -> Vec<String> {
        p.iter().map(|p| p.cell.id().to_string()).collect()
    }

    fn centre() -> DVec3 {
        DVec3::new(0.0, 1.7, 0.0)
    }

    #[test]
    fn standing_still_lists_neighbours_by_distance() {
        let o = PredictOptions {
            horizon_seconds: 2.0,
            max_speed: 10.0,
            max_acceleration: 5.0,
            max_cells: 100,
        };
        let p = predict(centre(), DVec3::ZERO, &grid(), &o);
        assert_eq!(p[0].cell.index, IVec3::new(2, 0, 2));
        assert_eq!(p[0].arrival_seconds, 0.0);
        // 4 face neighbours at 5 m: t = max(5/10, sqrt(2·5/5)) = sqrt(2)
        let faces: Vec<String> = ids(&p[1..5]);
        for id in ["1_0_2", "3_0_2", "2_0_1", "2_0_3"] {
            assert!(faces.contains(&id.to_string()), "{faces:?}");
        }
        for q in &p[1..5] {
            assert!((q.arrival_seconds - 2f64.sqrt()).abs() < 1e-9, "{q:?}");
        }
        // 4 diagonal neighbours at 5·√2 m: t = sqrt(2·7.07/5) ≈ 1.68 s
        assert_eq!(p.len(), 9, "{:?}", ids(&p));
        for q in &p[5..] {
            assert!((q.arrival_seconds - (2.0 * 50f64.sqrt() / 5.0).sqrt()).abs() < 1e-9);
        }
    }

    #[test]
    fn moving_lists_the_direction_of_motion_first() {
        let o = PredictOptions {
            horizon_seconds: 6.0,
            max_speed: 12.0,
            max_acceleration: 4.0,
            max_cells: 100,
        };
        let p = predict(centre(), DVec3::new(10.0, 0.0, 0.0), &grid(), &o);
        let order = ids(&p);
        assert_eq!(order[0], "2_0_2");
        assert_eq!(order[1], "3_0_2", "the cell ahead comes first: {order:?}");
        let pos = |id: &str| order.iter().position(|x| x == id).unwrap_or(usize::MAX);
        // two ahead before the sides; the sides before the one behind
        assert!(pos("4_0_2") < pos("2_0_3"), "{order:?}");
        assert!(pos("2_0_3") < pos("1_0_2"), "{order:?}");
        assert!(pos("3_0_3") < pos("1_0_3"), "{order:?}");
        // ahead: 5 m at 10 m/s → the acceleration bound d − v t = a t²/2 gives
        // t = (−v + sqrt(v² + 2 a d)) / a, the speed bound 5/12
        let t_ahead = (-10.0 + (100.0f64 + 2.0 * 4.0 * 5.0).sqrt()) / 4.0;
        assert!((p[1].arrival_seconds - t_ahead.max(5.0 / 12.0)).abs() < 1e-9);
        // behind: the observer must come back: a t²/2 = 5 + v t
        let t_behind = (10.0 + (100.0f64 + 2.0 * 4.0 * 5.0).sqrt()) / 4.0;
        let behind = p.iter().find(|q| q.cell.id() == "1_0_2").unwrap();
        assert!((behind.arrival_seconds - t_behind).abs() < 1e-9);
        // at 10 m/s with 4 m/s², the cell beside the current one takes longer than those ahead
        let side = p.iter().find(|q| q.cell.id() == "2_0_3").unwrap();
        assert!(side.arrival_seconds > 4.0 && side.arrival_seconds < t_behind);
        // a shorter horizon drops what is behind and beside
        let short = PredictOptions {
            horizon_seconds: 3.0,
            ..o
        };
        let p = predict(centre(), DVec3::new(10.0, 0.0, 0.0), &grid(), &short);
        assert!(p.iter().all(|q| q.cell.index.x >= 2), "{:?}", ids(&p));
    }

    #[test]
    fn earliest_arrival_is_the_larger_lower_bound() {
        let b = Aabb::new(DVec3::new(10.0, -1.0, -1.0), DVec3::new(20.0, 1.0, 1.0));
        // at rest, 10 m away: acceleration bound sqrt(2·10/a), speed bound 10/s
        let t = earliest_arrival(DVec3::ZERO, DVec3::ZERO, &b, 100.0, 5.0, 10.0).unwrap();
        assert!((t - 2.0).abs() < 1e-9, "{t}");
        let t = earliest_arrival(DVec3::ZERO, DVec3::ZERO, &b, 2.0, 5.0, 10.0).unwrap();
        assert!((t - 5.0).abs() < 1e-12, "{t}");
        // no acceleration: straight at it at 4 m/s → 2.5 s, away from it → never
        let t = earliest_arrival(DVec3::ZERO, DVec3::X * 4.0, &b, 4.0, 0.0, 10.0).unwrap();
        assert!((t - 2.5).abs() < 1e-9, "{t}");
        assert_eq!(
            earliest_arrival(DVec3::ZERO, -DVec3::X * 4.0, &b, 4.0, 0.0, 10.0),
            None
        );
        // beyond the horizon
        assert_eq!(
            earliest_arrival(DVec3::ZERO, DVec3::ZERO, &b, 100.0, 5.0, 1.9),
            None
        );
        // inside
        assert_eq!(
            earliest_arrival(DVec3::new(15.0, 0.0, 0.0), DVec3::ZERO, &b, 0.0, 0.0, 0.0),
            Some(0.0)
        );
        assert_eq!(distance_to_box(DVec3::new(7.0, 5.0, 0.0), &b), 5.0);
    }

    #[test]
    fn odd_inputs_give_sensible_answers() {
        let g = grid();
        let o = PredictOptions::default();
        assert!(predict(DVec3::NAN, DVec3::ZERO, &g, &o).is_empty());
        // NaN velocity counts as zero
        assert_eq!(
            predict(centre(), DVec3::NAN, &g, &o),
            predict(centre(), DVec3::ZERO, &g, &o)
        );
        // outside the grid: no current cell, but the cells one may reach
        let p = predict(DVec3::new(-27.0, 1.7, 0.0), DVec3::X * 5.0, &g, &o);
        assert!(!p.is_empty());
        assert!(p[0].arrival_seconds > 0.0);
        assert_eq!(p[0].cell.index, IVec3::new(0, 0, 2));
        // far away: nothing
        assert!(predict(DVec3::splat(1e9), DVec3::ZERO, &g, &o).is_empty());
        // zero horizon: the current cell only; max_cells truncates after the current cell
        let zero = PredictOptions {
            horizon_seconds: 0.0,
            ..o.clone()
        };
        assert_eq!(ids(&predict(centre(), DVec3::X, &g, &zero)), vec!["2_0_2"]);
        let two = PredictOptions { max_cells: 2, ..o };
        assert_eq!(
            ids(&predict(centre(), DVec3::X * 8.0, &g, &two)),
            vec!["2_0_2", "3_0_2"]
        );
        // absurd horizons do not enumerate the world
        let huge = PredictOptions {
            horizon_seconds: 1e12,
            max_speed: 1e12,
            max_acceleration: 1e12,
            max_cells: 5,
        };
        assert_eq!(predict(centre(), DVec3::ZERO, &g, &huge).len(), 5);
    }
}
