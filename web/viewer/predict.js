// Which view cells to have ready: the current cell, then the cells the viewer could reach within
// a time horizon, soonest first. A line-by-line port of lemi-runtime's rule
// (crates/lemi-runtime/src/predict.rs, GI 2002 sec. 3, runtime step 2), with the parameters
// cells.json records under `prediction`; the test `web_viewer_predicts_as_the_runtime` checks
// that both give the same cells in the same order.
//
// Every cell gets its earliest possible arrival time under two bounds on the observer: speed at
// most s = max(max_speed, |v|) (a cell at distance d is not reached before d / s), acceleration at
// most a (at time t the observer is within a·t²/2 of p + v·t). The arrival time is the larger of
// the two; cells beyond the horizon are not listed.

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const len = (a) => Math.sqrt(dot(a, a));
const finite = (a) => a.every(Number.isFinite);
const finiteOrZero = (x) => (Number.isFinite(x) ? Math.max(x, 0) : 0);

/// Euclidean distance from p to the box {min, max} (0 inside or on it).
export function distanceToBox(p, box) {
  const d = [0, 1, 2].map((i) => Math.max(box.min[i] - p[i], p[i] - box.max[i], 0));
  return len(d);
}

/// The grid cell (index triple) containing p, half-open on the upper side, or null.
export function locate(grid, p) {
  const f = [0, 1, 2].map((i) => Math.floor((p[i] - grid.origin[i]) / grid.step[i]));
  if (!f.every(Number.isFinite)) return null;
  if (f.some((v, i) => v < 0 || v >= grid.counts[i])) return null;
  return f;
}

export function cellBox(grid, index) {
  const min = [0, 1, 2].map((i) => grid.origin[i] + index[i] * grid.step[i]);
  const max = [0, 1, 2].map((i) => min[i] + grid.step[i]);
  const center = [0, 1, 2].map((i) => grid.origin[i] + (index[i] + 0.5) * grid.step[i]);
  return { min, max, center };
}

export function cellId(index) {
  return `${index[0]}_${index[1]}_${index[2]}`;
}

/// The earliest time (≤ horizon) an observer at p with velocity v can be inside box, or null.
export function earliestArrival(p, v, box, maxSpeed, maxAcceleration, horizon, rule) {
  const d0 = distanceToBox(p, box);
  if (d0 === 0) return 0;
  const vl = len(v);
  const s = Math.max(finiteOrZero(maxSpeed), vl);
  const a = finiteOrZero(maxAcceleration);
  const h = finiteOrZero(horizon);
  if (s <= 0 || !Number.isFinite(d0)) return null;
  const tSpeed = d0 / s;
  if (tSpeed > h || d0 > vl * h + 0.5 * a * h * h) return null;
  const f = (t) => distanceToBox(add(p, scale(v, t)), box) - 0.5 * a * t * t;
  let prev = 0;
  let hit = null;
  for (let k = 1; k <= rule.samples; k++) {
    const t = (h * k) / rule.samples;
    if (f(t) <= 0) {
      hit = [prev, t];
      break;
    }
    prev = t;
  }
  if (hit === null) return null;
  let [lo, hi] = hit;
  for (let i = 0; i < rule.bisection_steps; i++) {
    const mid = 0.5 * (lo + hi);
    if (f(mid) <= 0) hi = mid;
    else lo = mid;
  }
  const t = Math.max(hi, tSpeed);
  return t <= h ? t : null;
}

/// The grid index of p clamped to the grid.
function indexAt(grid, p) {
  return [0, 1, 2].map((i) => {
    const f = Math.floor((p[i] - grid.origin[i]) / grid.step[i]);
    return Math.min(Math.max(f, 0), Math.max(grid.counts[i] - 1, 0));
  });
}

const MAX_CANDIDATES = 100000;

/// Rust's f64::total_cmp for the numbers met here (finite): −0 before +0.
function totalCmp(a, b) {
  if (a < b) return -1;
  if (a > b) return 1;
  if (a === 0 && b === 0) return (Object.is(b, -0) ? 1 : 0) - (Object.is(a, -0) ? 1 : 0);
  return 0;
}

/// The cells to have ready at `position` moving with `velocity`: [{index, id, arrival, distance}],
/// the current cell first, then by arrival time, distance, how far the cell's centre lies in the
/// direction of motion, then grid index (y, z, x).
export function predict(position, velocity, grid, rule) {
  const count = grid.counts[0] * grid.counts[1] * grid.counts[2];
  if (!finite(position) || count <= 0 || rule.max_cells === 0) return [];
  const v = finite(velocity) ? velocity : [0, 0, 0];
  const h = finiteOrZero(rule.horizon_seconds);
  const a = finiteOrZero(rule.max_acceleration);
  const s = Math.max(finiteOrZero(rule.max_speed), len(v));
  let reach = Math.min(len(v) * h + 0.5 * a * h * h, s * h);
  if (!Number.isFinite(reach)) reach = 0;
  const current = locate(grid, position);
  let lo;
  let hi;
  for (;;) {
    lo = indexAt(grid, sub(position, [reach, reach, reach]));
    hi = indexAt(grid, add(position, [reach, reach, reach]));
    const n = [0, 1, 2].map((i) => Math.max(hi[i] - lo[i] + 1, 0));
    if (n[0] * n[1] * n[2] <= MAX_CANDIDATES || reach <= grid.step[0]) break;
    reach *= 0.5;
  }
  const isCurrent = (idx) => current !== null && idx[0] === current[0] && idx[1] === current[1] && idx[2] === current[2];
  const out = [];
  for (let y = lo[1]; y <= hi[1]; y++) {
    for (let z = lo[2]; z <= hi[2]; z++) {
      for (let x = lo[0]; x <= hi[0]; x++) {
        const index = [x, y, z];
        const box = cellBox(grid, index);
        const arrival = isCurrent(index) ? 0 : earliestArrival(position, v, box, s, a, h, rule);
        if (arrival !== null) {
          out.push({ index, id: cellId(index), arrival, distance: distanceToBox(position, box), center: box.center, current: isCurrent(index) });
        }
      }
    }
  }
  out.sort((p, q) =>
    (q.current - p.current)
    || totalCmp(p.arrival, q.arrival)
    || totalCmp(p.distance, q.distance)
    || totalCmp(dot(v, sub(q.center, position)), dot(v, sub(p.center, position)))
    || (p.index[1] - q.index[1]) || (p.index[2] - q.index[2]) || (p.index[0] - q.index[0]));
  return out.slice(0, rule.max_cells);
}
