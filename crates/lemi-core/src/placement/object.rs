//! Layer placement for the layered impostor of one object seen from a box or shaft view cell.
//!
//! This work is based on: S. Jeschke, M. Wimmer, *An Error Metric for Layered Environment Map
//! Impostors*, TR-186-2-02-04, sec. 2.1.1 (one-texel layer spacing, eqs. 1-5, optimal reference
//! viewpoint) and sec. 2.1.2 (parallax errors: border between layers eq. 6, depth range in front of
//! the first and behind the last layer eq. 7 / `e_min`, the single-layer case `f ≥ b`).
//!
//! Coordinates follow the TR: all distances `t` are measured along the view axis **from the
//! view-cell border nearest the object**; the reference viewpoint lies `s` behind that border,
//! centred laterally. The impostor frustum (from the reference viewpoint) tightly fits the object's
//! near face of size `w` (x and y) at distance `t0`, so a texel at distance `t` is
//! `p = w (t + s) / (res (t0 + s))` wide. The x and y directions are treated independently for
//! texel movements (TR sec. 2.1.1) and jointly for parallax (TR Fig. 8: `r` is the distance to the
//! 3D corner of the near border).
//!
//! Placement runs near to far: the first layer sits `e_min(t0)` behind the object's near side
//! (eq. 7, by the symmetry of the parallax angle between a point and its projection); each next
//! layer is the nearer of the one-texel spacing `t + c(t)` (eqs. 2-5) and two parallax steps
//! (`b = t + e_min(t)`, then `b + e_min(b)`); when the one-texel spacing wins, the border is
//! eq. 6. The last layer is the first whose range `t + e_min(t)` reaches the object's far side;
//! beyond [`single_layer_distance`] (`f ≥ b`, `e_min` unbounded) one layer covers everything.
//!
//! Deviation from the TR: it assumes the largest parallax is seen from the cell border nearest the
//! object. That is false for a box whose reference viewpoint sits near its front (its far corners
//! are also checked) and for shafts, where viewpoints far behind the near border, where the shaft
//! is wide, see several α; for shafts [`shaft_reach`] bounds the parallax from the whole shaft
//! (exactly along its corner edge, for the rays of the frustum).

use super::{border_between, check_alpha, invalid, Bound, Layer, PlacementError, MAX_LAYERS};
use serde::{Deserialize, Serialize};

/// The view cell of an object impostor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectCell {
    /// A box: full width `n` in x and y (across the view axis) and full depth `m` along it.
    Box { width: [f64; 2], depth: f64 },
    /// A shaft (TR Fig. 2): apex angle `β` (radians, in x and y), apex on the view axis
    /// `apex_distance` beyond the near border (normally the centre of the object); the cell is the
    /// part of the shaft behind its near border, unbounded away from the object (the TR's), or
    /// reaching `reach` behind it (a room behind a portal).
    Shaft {
        apex_angle: f64,
        apex_distance: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        reach: Option<f64>,
    },
}

impl ObjectCell {
    /// Full width of the cell at its near border, x and y (`n`; for a shaft
    /// `2·apex_distance·tan(β/2)`).
    pub fn near_width(&self) -> [f64; 2] {
        match *self {
            ObjectCell::Box { width, .. } => width,
            ObjectCell::Shaft {
                apex_angle,
                apex_distance,
                ..
            } => [2.0 * apex_distance * (apex_angle / 2.0).tan(); 2],
        }
    }

    /// The TR's practical reference-viewpoint offset `s` (sec. 2.1.1): `0` for a box cell wider than
    /// the object in both directions (Fig. 5 (d), then optimal), otherwise `m/2` for a box and
    /// `n/2` (half the near-border width) for a shaft.
    pub fn recommended_s(&self, size: [f64; 2]) -> f64 {
        match *self {
            ObjectCell::Box { width, depth } => {
                if size[0] <= width[0] && size[1] <= width[1] {
                    0.0
                } else {
                    depth / 2.0
                }
            }
            ObjectCell::Shaft { .. } => self.near_width()[0] / 2.0,
        }
    }
}

/// Inputs of the object placement (TR sec. 2.1.1, Fig. 4 left).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ObjectParams {
    pub cell: ObjectCell,
    /// `s`: distance from the reference viewpoint to the cell border nearest the object.
    pub s: f64,
    /// `t0`: distance from that border to the object's near side.
    pub t0: f64,
    /// Extent of the object along the view axis (its far side is at `t0 + depth`); may be infinite.
    pub depth: f64,
    /// `w`: width (x) and height (y) of the object's near face; the impostor frustum fits it.
    pub size: [f64; 2],
    /// `res`: texels across the impostor in each direction (see [`super::schaufler_res`]).
    pub res: u32,
    /// α, the allowed parallax angle (radians).
    pub alpha: f64,
}

/// The layers of an object impostor, **near to far**; distances are the TR's `t` (from the cell
/// border nearest the object). The last layer's `far_border` is the object's far side.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectPlacement {
    pub layers: Vec<Layer>,
    /// Beyond this distance one layer represents everything behind it (`f ≥ b`); infinite if never.
    #[serde(with = "crate::serde_inf::f64_or_inf")]
    pub single_layer_beyond: f64,
    pub params: ObjectParams,
}

impl ObjectParams {
    pub fn validate(&self) -> Result<(), PlacementError> {
        check_alpha(self.alpha)?;
        if self.res == 0 {
            return Err(invalid("res", 0.0, "the impostor resolution must be >= 1"));
        }
        if !self.t0.is_finite() || self.t0 <= 0.0 {
            return Err(invalid(
                "t0",
                self.t0,
                "the object must lie in front of the cell (t0 > 0)",
            ));
        }
        if self.depth.is_nan() || self.depth < 0.0 {
            return Err(invalid(
                "depth",
                self.depth,
                "the object depth must be >= 0",
            ));
        }
        for (name, w) in [("size[0]", self.size[0]), ("size[1]", self.size[1])] {
            if !w.is_finite() || w <= 0.0 {
                return Err(invalid(name, w, "the object size must be finite and > 0"));
            }
        }
        if !self.s.is_finite() || self.s < 0.0 {
            return Err(invalid(
                "s",
                self.s,
                "the reference viewpoint must be inside the cell (s >= 0)",
            ));
        }
        match self.cell {
            ObjectCell::Box { width, depth } => {
                for (name, v) in [
                    ("width[0]", width[0]),
                    ("width[1]", width[1]),
                    ("depth", depth),
                ] {
                    if !v.is_finite() || v < 0.0 {
                        return Err(invalid(name, v, "a view-cell size must be finite and >= 0"));
                    }
                }
                if self.s > depth {
                    return Err(invalid(
                        "s",
                        self.s,
                        "the reference viewpoint must be inside the cell (s <= cell depth)",
                    ));
                }
            }
            ObjectCell::Shaft {
                apex_angle,
                apex_distance,
                reach,
            } => {
                if let Some(r) = reach {
                    if !(r.is_finite() && r > 0.0) {
                        return Err(invalid(
                            "reach",
                            r,
                            "a bounded shaft must reach a positive, finite distance behind its near border",
                        ));
                    }
                }
                if !apex_angle.is_finite()
                    || apex_angle <= 0.0
                    || apex_angle >= std::f64::consts::PI
                {
                    return Err(invalid(
                        "apex_angle",
                        apex_angle,
                        "the shaft apex angle must be > 0 and < 180°",
                    ));
                }
                if !apex_distance.is_finite() || apex_distance <= 0.0 {
                    return Err(invalid(
                        "apex_distance",
                        apex_distance,
                        "the shaft apex must lie beyond its near border",
                    ));
                }
            }
        }
        Ok(())
    }

    /// The viewpoints where the parallax peaks, as (lateral distance `r` from the axis, axial
    /// offset `z` from the reference viewpoint toward the object): the 3D corners of the cell's
    /// near border (TR sec. 2.1.2, Fig. 8) and, for a box, those of its far border, which dominate
    /// when the reference viewpoint sits near the front (small `s`, deep cell).
    fn critical_views(&self) -> Vec<(f64, f64)> {
        let n = self.cell.near_width();
        let r = (n[0] / 2.0).hypot(n[1] / 2.0);
        match self.cell {
            ObjectCell::Box { depth, .. } => vec![(r, self.s), (r, self.s - depth)],
            ObjectCell::Shaft { .. } => vec![(r, self.s)],
        }
    }
}

/// TR eq. 7 minimised over the view direction (`φ_min = ½·arctan(s/r)`): the depth range `e_min`
/// behind (equivalently, by symmetry, in front of) a plane at distance `t` from a viewpoint that
/// lies `r` to the side of the reference viewpoint and `s` in front of it. Infinite when `f ≥ b`.
pub fn e_min_eq7(t: f64, r: f64, s: f64, alpha: f64) -> f64 {
    let a = alpha;
    // e_min = 2t·sin α·(t + s) / (r·cos α − (2t + s)·sin α + √(r² + s²)).
    let den = r * a.cos() - (2.0 * t + s) * a.sin() + r.hypot(s);
    if den <= 0.0 {
        f64::INFINITY
    } else {
        2.0 * t * a.sin() * (t + s) / den
    }
}

/// The depth range behind (and, by symmetry, the range in front reaching) a plane at distance `t`
/// (TR coordinates) within which the parallax stays below α from the whole cell: `e_min` (eq. 7)
/// of every critical viewpoint, the smallest; for a shaft also the exact range seen from the
/// whole shaft ([`shaft_reach`]). Infinite when one layer suffices.
pub fn e_min(t: f64, p: &ObjectParams) -> f64 {
    let front = p
        .critical_views()
        .into_iter()
        .map(|(r, z)| e_min_eq7(t + p.s - z, r, z, p.alpha))
        .fold(f64::INFINITY, f64::min);
    match p.cell {
        ObjectCell::Box { .. } => front,
        ObjectCell::Shaft { .. } => shaft_reach_capped(t, t + front, p) - t,
    }
}

/// The number of frustum rays [`shaft_reach`] checks (evenly spaced over the frustum diagonal).
const SHAFT_RAYS: usize = 33;

/// One frustum ray `(u, 1)` of the shaft check in the plane through the reference viewpoint and the
/// shaft's corner edge (TR Fig. 8): the viewpoints `V(μ) = (r0 + μ·r0/A, s − μ)`, `μ ≥ 0` behind
/// the near border, written in the ray's frame as `a(μ) = a0 + a1·μ` along the ray and
/// `h(μ) = h0 + h1·μ` across it; `len` is `|(u, 1)|`.
struct ShaftRay {
    a0: f64,
    a1: f64,
    h0: f64,
    h1: f64,
    len: f64,
}

impl ShaftRay {
    /// Whether the segment between the depths `l` and `z` (from the reference viewpoint, `z > l`,
    /// `z` may be infinite) on this ray subtends at most α (`ta = tan α`) from every `V(μ)`. With
    /// `λ = ℓ − a` the distances along the ray from the foot of `V`, the subtended angle is
    /// `atan(|h|·(ℓ_z − ℓ_l) / (h² + λ_l·λ_z))` (the difference of the two view angles, TR Fig. 7
    /// right), so the condition `tan α·(h² + λ_l·λ_z) − |h|·(ℓ_z − ℓ_l) ≥ 0` is a quadratic in `μ`
    /// (once for each sign of `h`) whose minimum over `0 ≤ μ ≤ reach` lies at its vertex or at an
    /// end.
    fn holds(&self, l: f64, z: f64, ta: f64, reach: f64) -> bool {
        let ll = l * self.len;
        let lam0 = ll - self.a0;
        for sigma in [1.0, -1.0] {
            if z.is_infinite() {
                // Divided by ℓ_z → ∞: tan α·λ_l(μ) − σ·h(μ) ≥ 0, affine in μ.
                let f0 = ta * lam0 - sigma * self.h0;
                let f1 = -ta * self.a1 - sigma * self.h1;
                let end = if reach.is_finite() {
                    f0 + f1 * reach
                } else {
                    f1
                };
                if f0 < 0.0 || end < 0.0 {
                    return false;
                }
                continue;
            }
            let lz = z * self.len;
            let dz = lz - ll;
            let mz0 = lz - self.a0;
            let c2 = ta * (self.h1 * self.h1 + self.a1 * self.a1);
            let c1 = ta * (2.0 * self.h0 * self.h1 - self.a1 * (lam0 + mz0)) - sigma * self.h1 * dz;
            let c0 = ta * (self.h0 * self.h0 + lam0 * mz0) - sigma * self.h0 * dz;
            let vertex = if c2 > 0.0 {
                -c1 / (2.0 * c2)
            } else {
                f64::INFINITY
            };
            let min = if vertex > 0.0 && vertex < reach {
                c0 - c1 * c1 / (4.0 * c2)
            } else if reach.is_finite() {
                c0.min(c0 + reach * (c1 + reach * c2))
            } else {
                c0
            };
            if min < 0.0 {
                return false;
            }
        }
        true
    }
}

/// The far end (TR coordinates) of the depth range behind a plane at `t` that keeps the parallax
/// within α from **every** viewpoint of a shaft cell, not only from its near border. The TR assumes
/// the largest parallax occurs on the near border (sec. 2.1.2, "because the impostor appears in
/// maximum magnification"), but in a narrow shaft a viewpoint far behind it, where the shaft is
/// much wider, sees several α. The check runs in the plane of the shaft's corner edge (TR Fig. 8,
/// `r0` = distance of the near-border corner from the axis), over all viewpoints of that edge
/// (`μ ≥ 0`, exact per ray, see [`ShaftRay::holds`]) and [`SHAFT_RAYS`] rays spanning the frustum
/// diagonal `|u| ≤ √(kx² + ky²)` (a superset of the frustum's rays in that plane). Unlike eq. 7 it
/// considers only rays inside the frustum, which keeps the range from collapsing for far
/// viewpoints. Bisection on `1/z`, rounded toward the near side. Infinite when the whole ray behind
/// `t` stays within α. For a box cell: `t + e_min(t)`.
pub fn shaft_reach(t: f64, p: &ObjectParams) -> f64 {
    if matches!(p.cell, ObjectCell::Box { .. }) {
        return t + e_min(t, p);
    }
    shaft_reach_capped(t, f64::INFINITY, p)
}

/// [`shaft_reach`], but at most `cap` (returned at once when the whole shaft allows it, which
/// saves the bisection when eq. 7 from the near border is the binding bound).
fn shaft_reach_capped(t: f64, cap: f64, p: &ObjectParams) -> f64 {
    let ObjectCell::Shaft {
        apex_distance,
        reach,
        ..
    } = p.cell
    else {
        return cap;
    };
    let reach = reach.unwrap_or(f64::INFINITY);
    let s = p.s;
    let n = p.cell.near_width();
    let r0 = (n[0] / 2.0).hypot(n[1] / 2.0);
    let grow = r0 / apex_distance;
    let kx = p.size[0] / (2.0 * (p.t0 + s));
    let ky = p.size[1] / (2.0 * (p.t0 + s));
    let kd = kx.hypot(ky);
    let rays: [ShaftRay; SHAFT_RAYS] = std::array::from_fn(|i| {
        // The extreme rays first: they bind most often, and `all` stops at the first failure.
        let j = if i % 2 == 0 {
            i / 2
        } else {
            SHAFT_RAYS - 1 - i / 2
        };
        let u = kd * (2.0 * j as f64 / (SHAFT_RAYS - 1) as f64 - 1.0);
        let len = u.hypot(1.0);
        // V(μ) = (r0 + grow·μ, s − μ); a = V·(u, 1)/len, h = V × (u, 1)/len.
        ShaftRay {
            a0: (u * r0 + s) / len,
            a1: (u * grow - 1.0) / len,
            h0: (r0 - u * s) / len,
            h1: (grow + u) / len,
            len,
        }
    });
    let ta = p.alpha.tan();
    let l = t + s;
    let ok = |z: f64| rays.iter().all(|r| r.holds(l, z, ta, reach));
    if ok(cap + s) {
        return cap;
    }
    // Feasible for x = l/z ∈ [x*, 1] and x* > l/(cap + s): bisection, keeping the feasible end.
    let (mut lo, mut hi) = (l / (cap + s), 1.0f64);
    while hi - lo > 1e-13 * hi {
        let mid = 0.5 * (lo + hi);
        if ok(l / mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    l / hi - s
}

/// The distance (TR coordinates) beyond which one layer represents the whole rest of the object:
/// where the denominator of `e_min` vanishes for every critical viewpoint (`f ≥ b`),
/// `t = ((r·cos α + √(r² + s²))/sin α − s) / 2` from that viewpoint (eq. 7). For a shaft also the
/// whole shaft must allow an infinite range ([`shaft_reach`]), otherwise this is infinite.
pub fn single_layer_distance(p: &ObjectParams) -> f64 {
    let a = p.alpha;
    let front = p
        .critical_views()
        .into_iter()
        .map(|(r, z)| ((r * a.cos() + r.hypot(z)) / a.sin() - z) / 2.0 + z - p.s)
        .fold(f64::NEG_INFINITY, f64::max);
    match p.cell {
        ObjectCell::Box { .. } => front,
        // From far back in the shaft a point at infinity and its projection on a layer are seen
        // about the angle between the ray and the shaft edge apart: one layer suffices only where
        // the exact check allows an infinite range, which is rare.
        ObjectCell::Shaft { reach, .. } => {
            let start = front.max(p.t0);
            let infinite = |t: f64| shaft_reach(t, p).is_infinite();
            if infinite(start) {
                return front;
            }
            if reach.is_none() {
                return f64::INFINITY;
            }
            // A bounded shaft: a far enough plane keeps points at infinity within α from every
            // viewpoint (the farthest lateral one at distance h sees them within h/t); the
            // nearest such plane, by doubling and bisection (the range only grows with t).
            let mut hi = start.max(1e-9);
            let mut steps = 0;
            while !infinite(hi) {
                hi *= 2.0;
                steps += 1;
                if steps > 200 || !hi.is_finite() {
                    return f64::INFINITY;
                }
            }
            let mut lo = hi / 2.0;
            while hi - lo > 1e-9 * hi {
                let mid = 0.5 * (lo + hi);
                if infinite(mid) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            hi
        }
    }
}

/// `c = t_num / den` with a non-positive denominator meaning "no constraint".
fn spacing(num: f64, den: f64) -> f64 {
    if den <= 0.0 {
        f64::INFINITY
    } else {
        num / den
    }
}

/// The one-texel spacing `c(t)` of one direction (TR eqs. 2-5): the distance from a layer at `t`
/// to the next one such that, from anywhere in the cell, no texel moves more than one texel
/// against the texel behind it. `n`, `w` are the cell's near width and the object's size in that
/// direction. Infinite when the boundary lines never reach the cell.
pub fn one_texel_spacing_1d(t: f64, n: f64, w: f64, p: &ObjectParams) -> f64 {
    let (s, t0) = (p.s, p.t0);
    let res = f64::from(p.res);
    let k = res / (2.0 * (t + s));
    // Eq. 2 (right boundary line, box and shaft): c_r = t / ((res/(2(t+s)))·(n(t0+s)/w + s) − 1).
    let c_r = spacing(t, k * (n * (t0 + s) / w + s) - 1.0);
    let c_l = match p.cell {
        ObjectCell::Box { depth: m, .. } => {
            let layer_half_width = w * (t + s) / (2.0 * (t0 + s));
            if layer_half_width > n / 2.0 {
                // Eq. 3 (lower corner): c_l = (t + m) / ((res/(2(t+s)))·(n(t0+s)/w + (m − s)(1 − 2/res)) − 1).
                spacing(
                    t + m,
                    k * (n * (t0 + s) / w + (m - s) * (1.0 - 2.0 / res)) - 1.0,
                )
            } else {
                // Eq. 4 (upper corner): c_h = t / ((res/(2(t+s)))·(n(t0+s)/w + s(2/res − 1)) − 1).
                spacing(t, k * (n * (t0 + s) / w + s * (2.0 / res - 1.0)) - 1.0)
            }
        }
        ObjectCell::Shaft {
            apex_angle,
            reach: None,
            ..
        } => {
            // Eq. 5: c_s = (t + s) / (res·(1/2 + ((t0 + s)/w)·tan(β/2)) − 1).
            spacing(
                t + s,
                res * (0.5 + (t0 + s) / w * (apex_angle / 2.0).tan()) - 1.0,
            )
        }
        ObjectCell::Shaft {
            apex_angle,
            reach: Some(reach),
            ..
        } => {
            // A bounded shaft: eqs. 2-5 come from one condition, that no viewpoint `V` of the
            // cell sees a texel of the layer at `a = t + s` (from the reference viewpoint) move
            // more than a texel against the layer at `a + c`. For the frustum ray of lateral slope
            // `u` (|u| ≤ k = w/(2(t0 + s))) the two points' shift seen from `V = (v, z)` is
            // `c·(u·z − v)/(a − z)`, at most `c·(k|z| + |v|)/(a − z)`; against `τ·a` with
            // `τ = w/(res·(t0 + s))`, one texel at `a` (TR convention, eq. 2):
            // `c ≤ τ·a·(a − z) / (k|z| + |v| − τ·a)`. Along the cell's edge (`|v|` growing
            // linearly from n/2 with μ, `z = s − μ`) this ratio of affine functions of μ is
            // monotone between μ = 0, the kink μ = s and μ = reach, so those three bound it; at
            // μ = 0 it is eq. 2, for reach → ∞ it tends to eq. 5.
            let k = w / (2.0 * (t0 + s));
            let tau = w / (res * (t0 + s));
            let a = t + s;
            let grow = (apex_angle / 2.0).tan();
            let mut c = f64::INFINITY;
            for mu in [0.0, s.min(reach), reach] {
                let z = s - mu;
                let v = n / 2.0 + grow * mu;
                c = c.min(spacing(tau * a * (a - z), k * z.abs() + v - tau * a));
            }
            c
        }
    };
    c_r.min(c_l)
}

/// The one-texel spacing of both directions: the smaller of x and y (TR sec. 2.1.1).
pub fn one_texel_spacing(t: f64, p: &ObjectParams) -> f64 {
    let n = p.cell.near_width();
    one_texel_spacing_1d(t, n[0], p.size[0], p).min(one_texel_spacing_1d(t, n[1], p.size[1], p))
}

/// Places the layers of one object impostor (TR sec. 2.1), near to far.
pub fn place_object_layers(p: &ObjectParams) -> Result<ObjectPlacement, PlacementError> {
    p.validate()?;
    let end = p.t0 + p.depth;
    let single_layer_beyond = single_layer_distance(p);
    if end.is_infinite() && single_layer_beyond.is_infinite() {
        return Err(invalid(
            "depth",
            p.depth,
            "an infinitely deep object needs infinitely many layers from this cell (from far back in a shaft no layer keeps the points at infinity within α); give a finite depth",
        ));
    }
    let s = p.s;
    let mut layers: Vec<Layer> = Vec::new();
    // Eq. 7 from the object's near side: the first layer's front range reaches t0.
    let first = p.t0 + e_min(p.t0, p);
    let (mut t, mut near_border, mut bound_by) = if first.is_finite() {
        (first.min(end), p.t0, Bound::Parallax)
    } else {
        (p.t0, p.t0, Bound::Parallax)
    };
    loop {
        let reach = t + e_min(t, p);
        if reach >= end || !reach.is_finite() {
            layers.push(Layer {
                distance: t,
                near_border,
                far_border: end,
                bound_by,
            });
            break;
        }
        if layers.len() + 1 >= MAX_LAYERS {
            return Err(PlacementError::TooManyLayers {
                limit: MAX_LAYERS,
                what: "for this object",
            });
        }
        // Two parallax steps (eq. 7) against the one-texel spacing (eqs. 2-5): the nearer wins.
        let by_parallax = {
            let e = e_min(reach, p);
            if e.is_finite() {
                reach + e
            } else {
                f64::INFINITY
            }
        };
        let by_texel = t + one_texel_spacing(t, p);
        let (next, border, next_bound) = if by_texel < by_parallax {
            // Eq. 6 (distances from the reference viewpoint are t + s).
            (
                by_texel,
                border_between(t + s, by_texel + s, s) - s,
                Bound::OneTexel,
            )
        } else if by_parallax.is_finite() {
            (by_parallax, reach, Bound::Parallax)
        } else {
            // Behind `reach` one layer represents everything: put it right there.
            (reach, reach, Bound::Parallax)
        };
        layers.push(Layer {
            distance: t,
            near_border,
            far_border: border,
            bound_by,
        });
        t = next;
        near_border = border;
        bound_by = next_bound;
    }
    Ok(ObjectPlacement {
        layers,
        single_layer_beyond,
        params: *p,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::placement::{parallax_step, Dim, EnvParams};

    #[test]
    fn e_min_is_the_env_parallax_step() {
        // The env-map cube is the box case with s = m, r = corner distance across the face.
        for dim in [Dim::Two, Dim::Three] {
            let m = 5.0;
            let env = EnvParams::cube(m, 512, 0.002, dim);
            let width = match dim {
                Dim::Two => [2.0 * m, 0.0],
                Dim::Three => [2.0 * m, 2.0 * m],
            };
            let p = ObjectParams {
                cell: ObjectCell::Box {
                    width,
                    depth: 2.0 * m,
                },
                s: m,
                t0: 10.0,
                depth: 100.0,
                size: [1.0, 1.0],
                res: 64,
                alpha: 0.002,
            };
            for t in [2.0, 20.0, 200.0] {
                let behind = t + e_min(t, &p);
                // env: from the far plane (distance from the centre) back to the near one.
                let near = parallax_step(behind + m, &env) - m;
                assert!((near - t).abs() < 1e-8 * t, "{dim:?} {t}: {near}");
            }
        }
    }

    #[test]
    fn eq4_equals_eq2_for_s_zero() {
        let p = ObjectParams {
            cell: ObjectCell::Box {
                width: [10.0, 10.0],
                depth: 10.0,
            },
            s: 0.0,
            t0: 50.0,
            depth: 20.0,
            size: [4.0, 4.0],
            res: 128,
            alpha: 0.001,
        };
        let res = 128.0;
        let (t, n, w, t0) = (60.0, 10.0, 4.0, 50.0);
        let c_r = t / (res / (2.0 * t) * (n * t0 / w) - 1.0);
        assert!((one_texel_spacing_1d(t, n, w, &p) - c_r).abs() < 1e-12 * c_r);
    }
}
