//! Built-in procedural scenes: `city`, `terrain`, `forest` and `interior` (the city plus a building
//! with rooms to stand in, see [`interior`]), each deterministic from a seed and sized by a triangle
//! budget (the budget sets the *extent*: a bigger city has more blocks, a bigger terrain or forest
//! covers more ground).
//!
//! Spec grammar (the text after `builtin:`): `NAME[:triangles[:seed]]`, where `triangles` is a plain
//! integer or a decimal with a `k` (thousand) or `M` (million) suffix (`200000`, `200k`, `1M`,
//! `1.5M`), between [`MIN_TRIANGLES`] and [`MAX_TRIANGLES`], default [`DEFAULT_TRIANGLES`]; `seed` is
//! a non-negative integer, default [`DEFAULT_SEED`]. An empty field takes its default (`city::7`).
//! The result has the requested triangle count to within a few percent (the tests hold it to ±10 %).
//!
//! Conventions: metres, +Y up, centred on the origin, ground height 0 at the origin in every scene
//! (see [`BuiltinSpec::ground_height_at_origin`], [`BuiltinSpec::spawn_eye`]). The same spec gives
//! bit-identical geometry on every run and machine: PCG-32 streams and SplitMix64 hashes seeded
//! from the spec, `libm` trigonometry, and parallel work merged in a fixed order.
//!
//! Rendering assumption: a fragment's colour is material base colour × texture × vertex colour;
//! UVs are in metres over each texture's tile size and expect repeat addressing.

mod city;
mod forest;
mod geom;
pub mod interior;
mod rng;
mod terrain;
mod textures;
mod trees;

use lemi_core::{Scene, SceneBuilder};

use crate::SceneError;

pub use city::{AVENUE_FREE_HALF_WIDTH, PLAZA_FREE_RADIUS};
pub use interior::{interior_layout, Doorway, InteriorLayout, Portal, PortalKind, Room};

/// Triangle budget when the spec gives none.
pub const DEFAULT_TRIANGLES: u64 = 200_000;
/// Seed when the spec gives none.
pub const DEFAULT_SEED: u64 = 1;
/// Smallest accepted triangle budget.
pub const MIN_TRIANGLES: u64 = 10_000;
/// Largest accepted triangle budget.
pub const MAX_TRIANGLES: u64 = 100_000_000;
/// Terrain and forest: no plant reaches within this horizontal distance of the origin (m).
pub const SPAWN_CLEAR_RADIUS: f32 = 5.0;
/// Eye height of a walking viewer above the ground (m).
pub const EYE_HEIGHT: f32 = 1.7;

/// The built-in scenes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Builtin {
    City,
    Terrain,
    Forest,
    /// The city with one building whose rooms look out on the avenue ([`interior`]).
    Interior,
}

impl Builtin {
    pub const ALL: [Builtin; 4] = [
        Builtin::City,
        Builtin::Terrain,
        Builtin::Forest,
        Builtin::Interior,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Builtin::City => "city",
            Builtin::Terrain => "terrain",
            Builtin::Forest => "forest",
            Builtin::Interior => "interior",
        }
    }
}

/// A parsed, validated built-in spec.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BuiltinSpec {
    pub scene: Builtin,
    pub triangles: u64,
    pub seed: u64,
}

impl BuiltinSpec {
    /// Parses `NAME[:triangles[:seed]]` (a leading `builtin:` is accepted too).
    pub fn parse(spec: &str) -> Result<BuiltinSpec, SceneError> {
        let bad = |message: String| SceneError::BadBuiltin {
            spec: spec.into(),
            message,
        };
        let body = spec.trim();
        let body = body.strip_prefix("builtin:").unwrap_or(body);
        let fields: Vec<&str> = body.split(':').collect();
        if fields.len() > 3 {
            return Err(bad(format!(
                "{} fields; expected NAME[:triangles[:seed]]",
                fields.len()
            )));
        }
        let name = fields[0].trim();
        let scene = match name.to_ascii_lowercase().as_str() {
            "city" => Builtin::City,
            "terrain" => Builtin::Terrain,
            "forest" => Builtin::Forest,
            "interior" => Builtin::Interior,
            "" => {
                return Err(bad(
                    "missing scene name (city, terrain, forest or interior)".into(),
                ))
            }
            _ => {
                return Err(bad(format!(
                    "unknown scene `{name}` (expected city, terrain, forest or interior)"
                )))
            }
        };
        let triangles = match fields.get(1).map(|s| s.trim()) {
            None | Some("") => DEFAULT_TRIANGLES,
            Some(t) => parse_triangles(t).map_err(bad)?,
        };
        let seed = match fields.get(2).map(|s| s.trim()) {
            None | Some("") => DEFAULT_SEED,
            Some(s) => s
                .parse::<u64>()
                .map_err(|_| bad(format!("seed `{s}` is not a non-negative integer")))?,
        };
        Ok(BuiltinSpec {
            scene,
            triangles,
            seed,
        })
    }

    /// The canonical form, e.g. `builtin:city:200000:1`, stored in [`Scene::sources`].
    pub fn normalized(&self) -> String {
        format!(
            "builtin:{}:{}:{}",
            self.scene.name(),
            self.triangles,
            self.seed
        )
    }

    /// Ground height at the origin: 0 in every built-in scene (the terrain is pinned there).
    pub fn ground_height_at_origin(&self) -> f32 {
        0.0
    }

    /// Eye position of a viewer standing at the origin: `(0, EYE_HEIGHT, 0)`. In the city this is
    /// the middle of the free plaza on the main avenue (in `interior` too, facing the building's
    /// door 12 m to the east); in terrain and forest it is a clearing.
    pub fn spawn_eye(&self) -> [f32; 3] {
        [0.0, self.ground_height_at_origin() + EYE_HEIGHT, 0.0]
    }
}

/// Parses a triangle count: digits with at most one `.`, optionally followed by `k` or `M`.
fn parse_triangles(t: &str) -> Result<u64, String> {
    let (num, mult) = match t.chars().last() {
        Some('k' | 'K') => (&t[..t.len() - 1], 1e3),
        Some('m' | 'M') => (&t[..t.len() - 1], 1e6),
        _ => (t, 1.0),
    };
    let digits = num.chars().filter(|c| c.is_ascii_digit()).count();
    let dots = num.chars().filter(|&c| c == '.').count();
    if digits == 0 || dots > 1 || digits + dots != num.len() {
        return Err(format!(
            "triangle count `{t}` is not a number (examples: 200000, 200k, 1.5M)"
        ));
    }
    let v = num
        .parse::<f64>()
        .map_err(|_| format!("triangle count `{t}` is not a number"))?
        * mult;
    if !v.is_finite() || v.round() < 1.0 {
        return Err(format!("triangle count `{t}` must be positive"));
    }
    if v.round() < MIN_TRIANGLES as f64 {
        return Err(format!(
            "triangle count `{t}` is below the minimum of {MIN_TRIANGLES}"
        ));
    }
    if v.round() > MAX_TRIANGLES as f64 {
        return Err(format!(
            "triangle count `{t}` is above the maximum of {MAX_TRIANGLES}"
        ));
    }
    Ok(v.round() as u64)
}

/// One-paragraph help text listing the scenes and defaults.
pub fn describe() -> &'static str {
    "Built-in scenes: builtin:NAME[:triangles[:seed]], triangles as 200000, 200k or 1.5M \
     (10k to 100M, default 200k), seed a non-negative integer (default 1).\n\
     \x20 city     open historical city centred on the origin: street grid, blocks of 2-40 m \
     buildings with flat/gabled/hipped roofs, landmark towers, plazas, parks, street trees; a free \
     avenue |z| < 15 m along X and a free plaza of radius 40 m at the origin. More triangles, more \
     blocks (1M: about 4.7 km of city in 6.5 km of meadows).\n\
     \x20 terrain  fBm height field (0 at the origin) coloured by height and slope, with trees and \
     shrubs; about 42% of the triangles are ground at 4 m spacing.\n\
     \x20 forest   flat forest floor with spruce, pine, broadleaf, birch, poplar and shrubs, clearings.\n\
     \x20 interior the city plus a two-storey building on the avenue 12 m east of the \
     origin (x 12 to 28.6 m, |z| < 7.3 m): four ground-floor rooms joined by doorways, with windows and a \
     door to the street, for portal impostors.\n\
     All: metres, +Y up, ground height 0 at the origin, no plant or building within 5 m of it."
}

/// Builds a built-in scene from the part of the spec after `builtin:`, e.g. `city:100000:7`.
pub fn build(spec: &str) -> Result<Scene, SceneError> {
    let parsed = BuiltinSpec::parse(spec)?;
    build_spec(&parsed)
}

/// Builds a parsed spec (its triangle count is checked against the limits again).
pub fn build_spec(spec: &BuiltinSpec) -> Result<Scene, SceneError> {
    if !(MIN_TRIANGLES..=MAX_TRIANGLES).contains(&spec.triangles) {
        return Err(SceneError::BadBuiltin {
            spec: spec.normalized(),
            message: format!(
                "triangle count {} is outside {MIN_TRIANGLES}..={MAX_TRIANGLES}",
                spec.triangles
            ),
        });
    }
    let mut b = SceneBuilder::new();
    b.add_source(spec.normalized());
    match spec.scene {
        Builtin::City => {
            city::build(spec.seed, spec.triangles, &mut b);
        }
        Builtin::Terrain => {
            terrain::build(spec.seed, spec.triangles, &mut b);
        }
        Builtin::Forest => {
            forest::build(spec.seed, spec.triangles, &mut b);
        }
        Builtin::Interior => {
            city::build(spec.seed, spec.triangles, &mut b);
            interior::build(&mut b);
        }
    }
    let scene = b.finish();
    if scene.triangle_count() == 0 {
        return Err(SceneError::Empty {
            inputs: spec.normalized(),
        });
    }
    Ok(scene)
}
