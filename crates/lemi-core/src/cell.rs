//! View cells: axis-aligned boxes the viewer may move in (GI 2002 sec. 3). The centre of a cell is
//! its reference viewpoint. A region is tiled into a grid of cells; a bake may take all of them, an
//! explicit subset, or a deterministic shard for scale-out.

use std::fmt;
use std::str::FromStr;

use glam::{DVec3, IVec3};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::Aabb;

/// The identity of a view cell: its grid coordinates, written `x_y_z` (e.g. `3_0_-1`) in file
/// names, manifests, reports and `--cells`. Serialised as that string, so manifests and reports
/// read the same as when ids were plain strings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CellId([i32; 3]);

impl CellId {
    pub fn new(index: IVec3) -> CellId {
        CellId(index.to_array())
    }

    /// The grid coordinates.
    pub fn index(self) -> IVec3 {
        IVec3::from_array(self.0)
    }
}

impl fmt::Display for CellId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.0;
        write!(f, "{x}_{y}_{z}")
    }
}

impl FromStr for CellId {
    type Err = CellError;

    /// Parses `x_y_z` (surrounding white space allowed). Whether the cell lies in a grid is
    /// [`CellGrid::cell_of`]'s question.
    fn from_str(s: &str) -> Result<CellId, CellError> {
        let bad = || CellError::BadCellId(s.to_string());
        let mut parts = s.trim().split('_');
        let mut v = [0i32; 3];
        for c in &mut v {
            *c = parts.next().ok_or_else(bad)?.parse().map_err(|_| bad())?;
        }
        if parts.next().is_some() {
            return Err(bad());
        }
        Ok(CellId(v))
    }
}

impl PartialEq<str> for CellId {
    fn eq(&self, other: &str) -> bool {
        other.parse::<CellId>().is_ok_and(|o| o == *self)
    }
}

impl PartialEq<&str> for CellId {
    fn eq(&self, other: &&str) -> bool {
        *self == **other
    }
}

impl Serialize for CellId {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for CellId {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<CellId, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// One view cell.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewCell {
    /// Grid coordinates of the cell in its grid (unique within a bundle).
    pub index: IVec3,
    pub center: DVec3,
    /// Half extent per axis (`m` of the papers for a cubic cell).
    pub half: DVec3,
}

impl ViewCell {
    /// The stable identifier used in file names and `--cells`: `x_y_z` of the grid index.
    pub fn id(&self) -> CellId {
        CellId::new(self.index)
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::new(self.center - self.half, self.center + self.half)
    }

    /// The 8 corners.
    pub fn corners(&self) -> [DVec3; 8] {
        let mut out = [DVec3::ZERO; 8];
        for (k, o) in out.iter_mut().enumerate() {
            let sx = if k & 1 == 0 { -1.0 } else { 1.0 };
            let sy = if k & 2 == 0 { -1.0 } else { 1.0 };
            let sz = if k & 4 == 0 { -1.0 } else { 1.0 };
            *o = self.center + self.half * DVec3::new(sx, sy, sz);
        }
        out
    }
}

/// Viewpoints at which a cell's impostors are evaluated: the centre, the 8 corners, the 6 face
/// midpoints, the 12 edge midpoints and `random` interior points (deterministic from `seed`), each
/// with a label. Corners and borders are where the parallax error is largest (TR sec. 2.1).
pub fn eval_viewpoints(cell: &ViewCell, random: usize, seed: u64) -> Vec<(String, DVec3)> {
    let mut out = vec![("centre".to_string(), cell.center)];
    for (k, c) in cell.corners().iter().enumerate() {
        out.push((format!("corner {k}"), *c));
    }
    let h = cell.half;
    let axes = [DVec3::X, DVec3::Y, DVec3::Z];
    for (a, axis) in axes.iter().enumerate() {
        for sign in [-1.0, 1.0] {
            out.push((
                format!(
                    "face {}{}",
                    if sign < 0.0 { "-" } else { "+" },
                    ["x", "y", "z"][a]
                ),
                cell.center + *axis * h * sign,
            ));
        }
    }
    for a in 0..3 {
        // edges parallel to `axis`: the other two coordinates at ±half
        let (u, v) = (axes[(a + 1) % 3], axes[(a + 2) % 3]);
        for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            out.push((
                format!("edge {}{su:+}{sv:+}", ["x", "y", "z"][a]),
                cell.center + u * h * su + v * h * sv,
            ));
        }
    }
    let mut x = seed ^ 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for k in 0..random {
        let r = DVec3::new(next(), next(), next());
        out.push((format!("random {k}"), cell.center + h * r));
    }
    out
}

/// View directions that cover every baked face: each face's axis and, between two baked faces at
/// right angles, the diagonal (where two faces' impostors meet on screen).
pub fn eval_directions(faces: &[crate::Face]) -> Vec<(String, DVec3)> {
    let mut out: Vec<(String, DVec3)> = faces
        .iter()
        .map(|f| (f.name().to_string(), f.forward()))
        .collect();
    for (i, a) in faces.iter().enumerate() {
        for b in &faces[i + 1..] {
            if a.forward().dot(b.forward()).abs() < 0.5 {
                out.push((
                    format!("{}{}", a.name(), b.name()),
                    (a.forward() + b.forward()).normalize(),
                ));
            }
        }
    }
    out
}

/// Errors of cell-grid construction; each names the parameter at fault.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CellError {
    #[error("cell size must be a finite number > 0 (got {0})")]
    BadCellSize(f64),
    #[error("cell height must be a finite number > 0 (got {0})")]
    BadCellHeight(f64),
    #[error("region must be finite with min < max on every axis (got min {min:?}, max {max:?})")]
    BadRegion { min: [f64; 3], max: [f64; 3] },
    #[error("region needs {0} cells, more than the limit of {1}; use a larger cell size or a smaller region")]
    TooManyCells(u64, u64),
    #[error("shard `{0}`: expected K/N with 0 <= K < N (e.g. 0/4)")]
    BadShard(String),
    #[error("cell `{0}`: expected grid coordinates x_y_z (e.g. 3_0_-1) of a cell in the region")]
    BadCellId(String),
}

/// The most cells a grid may have (a guard against absurd flags).
pub const MAX_CELLS: u64 = 1_000_000;

/// A regular grid of cells covering `region`: `cell_size` wide along X and Z, and `cell_height`
/// tall along Y (cubic cells when it is `None`). The region is grown to whole cells symmetrically
/// around its centre; along an axis whose extent is below one cell (e.g. the eye-height range of a
/// ground-level walk) there is exactly one layer of cells centred on it. Flat cells (a height of
/// the eye-height range, not the cell width) suit scenes walked on the ground: the viewer never
/// leaves that height range, so fewer layers reach a given near field and no viewpoint of the cell
/// lies underground.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellGrid {
    pub origin: DVec3,
    pub cell_size: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell_height: Option<f64>,
    pub counts: IVec3,
}

impl CellGrid {
    /// Cubic cells.
    pub fn tile(region: Aabb, cell_size: f64) -> Result<CellGrid, CellError> {
        CellGrid::tile_with_height(region, cell_size, None)
    }

    /// Cells `cell_size` wide and `cell_height` (default: `cell_size`) tall.
    pub fn tile_with_height(
        region: Aabb,
        cell_size: f64,
        cell_height: Option<f64>,
    ) -> Result<CellGrid, CellError> {
        if !(cell_size.is_finite() && cell_size > 0.0) {
            return Err(CellError::BadCellSize(cell_size));
        }
        if let Some(h) = cell_height {
            if !(h.is_finite() && h > 0.0) {
                return Err(CellError::BadCellHeight(h));
            }
        }
        let step = DVec3::new(cell_size, cell_height.unwrap_or(cell_size), cell_size);
        let size = region.size();
        if !region.min.is_finite() || !region.max.is_finite() || size.min_element() < 0.0 {
            return Err(CellError::BadRegion {
                min: region.min.to_array(),
                max: region.max.to_array(),
            });
        }
        let n = (size / step - 1e-9).ceil().max(DVec3::ONE);
        let total = n.x * n.y * n.z;
        if total > MAX_CELLS as f64 {
            return Err(CellError::TooManyCells(total as u64, MAX_CELLS));
        }
        let counts = n.as_ivec3();
        let origin = region.center() - 0.5 * step * n;
        Ok(CellGrid {
            origin,
            cell_size,
            cell_height,
            counts,
        })
    }

    /// The size of one cell per axis.
    pub fn step(&self) -> DVec3 {
        DVec3::new(
            self.cell_size,
            self.cell_height.unwrap_or(self.cell_size),
            self.cell_size,
        )
    }

    pub fn len(&self) -> usize {
        (self.counts.x * self.counts.y * self.counts.z) as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn cell(&self, index: IVec3) -> Option<ViewCell> {
        if index.cmplt(IVec3::ZERO).any() || index.cmpge(self.counts).any() {
            return None;
        }
        let step = self.step();
        Some(ViewCell {
            index,
            center: self.origin + (index.as_dvec3() + 0.5) * step,
            half: 0.5 * step,
        })
    }

    /// All cells in a fixed order (x fastest, then z, then y).
    pub fn cells(&self) -> Vec<ViewCell> {
        let mut out = Vec::with_capacity(self.len());
        for y in 0..self.counts.y {
            for z in 0..self.counts.z {
                for x in 0..self.counts.x {
                    if let Some(c) = self.cell(IVec3::new(x, y, z)) {
                        out.push(c);
                    }
                }
            }
        }
        out
    }

    /// The cell containing `p` (half-open on the upper side), if any.
    pub fn locate(&self, p: DVec3) -> Option<ViewCell> {
        let f = ((p - self.origin) / self.step()).floor();
        if !f.is_finite() {
            return None;
        }
        self.cell(f.as_ivec3())
    }

    /// Parses a cell id `x_y_z` and checks it is inside the grid.
    pub fn parse_id(&self, id: &str) -> Result<ViewCell, CellError> {
        self.cell_of(id.parse()?)
    }

    /// The cell with this id, if it lies inside the grid.
    pub fn cell_of(&self, id: CellId) -> Result<ViewCell, CellError> {
        self.cell(id.index())
            .ok_or_else(|| CellError::BadCellId(id.to_string()))
    }
}

/// A deterministic share of the cells: shard `k` of `n` takes every cell whose position in the
/// grid order is `k` modulo `n`, so shards are balanced and together cover every cell exactly once.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub k: u32,
    pub n: u32,
}

impl Shard {
    /// Parses `K/N`.
    pub fn parse(s: &str) -> Result<Shard, CellError> {
        let bad = || CellError::BadShard(s.to_string());
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let k: u32 = k.trim().parse().map_err(|_| bad())?;
        let n: u32 = n.trim().parse().map_err(|_| bad())?;
        if n == 0 || k >= n {
            return Err(bad());
        }
        Ok(Shard { k, n })
    }

    pub fn select<T: Clone>(&self, items: &[T]) -> Vec<T> {
        items
            .iter()
            .enumerate()
            .filter(|(i, _)| (*i as u64) % self.n as u64 == self.k as u64)
            .map(|(_, c)| c.clone())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_a_strip_at_eye_height() {
        let region = Aabb::new(DVec3::new(-20.0, 1.7, -5.0), DVec3::new(20.0, 1.7, 5.0));
        let g = CellGrid::tile(region, 10.0).unwrap();
        assert_eq!(g.counts, IVec3::new(4, 1, 1));
        let cells = g.cells();
        assert_eq!(cells.len(), 4);
        assert!((cells[0].center - DVec3::new(-15.0, 1.7, 0.0)).length() < 1e-12);
        assert_eq!(cells[3].id(), "3_0_0");
        assert_eq!(g.locate(DVec3::new(-14.0, 2.0, 1.0)), Some(cells[0]));
        assert_eq!(g.locate(DVec3::new(100.0, 2.0, 1.0)), None);
        assert_eq!(g.parse_id("2_0_0").unwrap(), cells[2]);
        assert!(g.parse_id("9_0_0").is_err());
        assert!(g.parse_id("a_b").is_err());
        assert!(g.parse_id("1_0_0_0").is_err());
        assert!(g.parse_id("1__0").is_err());
    }

    #[test]
    fn cell_ids_print_parse_and_serialise_as_x_y_z() {
        let id = CellId::new(IVec3::new(3, 0, -1));
        assert_eq!(id.to_string(), "3_0_-1");
        assert_eq!(" 3_0_-1 ".parse::<CellId>().unwrap(), id);
        assert_eq!(id, "3_0_-1");
        assert_ne!(id, "3_0_1");
        assert_eq!(serde_json::to_string(&id).unwrap(), "\"3_0_-1\"");
        assert_eq!(serde_json::from_str::<CellId>("\"3_0_-1\"").unwrap(), id);
        for bad in ["", "3_0", "3_0_x", "3_0_-1_2", "3.5_0_0", "99999999999_0_0"] {
            assert!(bad.parse::<CellId>().is_err(), "{bad}");
        }
        assert!(serde_json::from_str::<CellId>("\"nope\"").is_err());
    }

    #[test]
    fn flat_cells_tile_the_eye_height_range() {
        let region = Aabb::new(DVec3::new(0.0, 1.2, 0.0), DVec3::new(30.0, 2.2, 10.0));
        let g = CellGrid::tile_with_height(region, 10.0, Some(1.0)).unwrap();
        assert_eq!(g.counts, IVec3::new(3, 1, 1));
        let c = g.cells()[1];
        assert!((c.center - DVec3::new(15.0, 1.7, 5.0)).length() < 1e-12);
        assert_eq!(c.half, DVec3::new(5.0, 0.5, 5.0));
        assert_eq!(g.locate(DVec3::new(12.0, 2.1, 3.0)), Some(c));
        assert_eq!(g.locate(DVec3::new(12.0, 2.3, 3.0)), None);
        assert!(CellGrid::tile_with_height(region, 10.0, Some(0.0)).is_err());
        // a cubic grid serialises without the field (manifests of cubic bakes are unchanged)
        let cubic = CellGrid::tile(region, 10.0).unwrap();
        assert!(!serde_json::to_string(&cubic)
            .unwrap()
            .contains("cell_height"));
    }

    #[test]
    fn shards_partition_the_cells() {
        let items: Vec<u32> = (0..17).collect();
        let mut all: Vec<u32> = (0..3)
            .flat_map(|k| Shard { k, n: 3 }.select(&items))
            .collect();
        all.sort();
        assert_eq!(all, items);
        assert!(Shard::parse("3/3").is_err());
        assert!(Shard::parse("1/0").is_err());
        assert!(Shard::parse("x").is_err());
        assert_eq!(Shard::parse("1/4").unwrap(), Shard { k: 1, n: 4 });
    }

    #[test]
    fn eval_viewpoints_and_directions() {
        let c = ViewCell {
            index: IVec3::ZERO,
            center: DVec3::new(5.0, 1.7, 5.0),
            half: DVec3::splat(5.0),
        };
        let v = eval_viewpoints(&c, 4, 1);
        assert_eq!(v.len(), 1 + 8 + 6 + 12 + 4);
        let b = c.bounds();
        for (label, p) in &v {
            let inside = p.cmpge(b.min - 1e-9).all() && p.cmple(b.max + 1e-9).all();
            assert!(inside, "{label} {p}");
        }
        // edge midpoints lie on exactly two cell planes
        for (_, p) in v.iter().filter(|(l, _)| l.starts_with("edge")) {
            let on = (*p - c.center).abs().cmpeq(DVec3::splat(5.0));
            assert_eq!(on.bitmask().count_ones(), 2);
        }
        let d = eval_directions(&crate::Face::HORIZONTAL);
        assert_eq!(d.len(), 4 + 4, "4 axes and 4 horizontal diagonals");
        let d = eval_directions(&crate::Face::ALL);
        assert_eq!(d.len(), 6 + 12);
    }

    #[test]
    fn rejects_bad_parameters() {
        let r = Aabb::new(DVec3::ZERO, DVec3::ONE);
        assert!(CellGrid::tile(r, 0.0).is_err());
        assert!(CellGrid::tile(r, f64::NAN).is_err());
        assert!(CellGrid::tile(r, -1.0).is_err());
        assert!(CellGrid::tile(Aabb::new(DVec3::ONE, DVec3::ZERO), 1.0).is_err());
        assert!(CellGrid::tile(Aabb::new(DVec3::ZERO, DVec3::splat(1e6)), 1.0).is_err());
    }
}
