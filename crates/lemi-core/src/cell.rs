//! View cells: axis-aligned boxes the viewer may move in (GI 2002 sec. 3). The centre of a cell is
//! its reference viewpoint. A region is tiled into a grid of cells; a bake may take all of them, an
//! explicit subset, or a deterministic shard for scale-out.

use glam::{DVec3, IVec3};
use serde::{Deserialize, Serialize};

use crate::Aabb;

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
    pub fn id(&self) -> String {
        format!("{}_{}_{}", self.index.x, self.index.y, self.index.z)
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

/// Errors of cell-grid construction; each names the parameter at fault.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CellError {
    #[error("cell size must be a finite number > 0 (got {0})")]
    BadCellSize(f64),
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

/// A regular grid of cubic cells of side `cell_size` covering `region`. The region is grown to whole
/// cells symmetrically around its centre; along an axis whose extent is below one cell (e.g. the
/// eye-height range of a ground-level walk) there is exactly one layer of cells centred on it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellGrid {
    pub origin: DVec3,
    pub cell_size: f64,
    pub counts: IVec3,
}

impl CellGrid {
    pub fn tile(region: Aabb, cell_size: f64) -> Result<CellGrid, CellError> {
        if !(cell_size.is_finite() && cell_size > 0.0) {
            return Err(CellError::BadCellSize(cell_size));
        }
        let size = region.size();
        if !region.min.is_finite() || !region.max.is_finite() || size.min_element() < 0.0 {
            return Err(CellError::BadRegion {
                min: region.min.to_array(),
                max: region.max.to_array(),
            });
        }
        let n = (size / cell_size - 1e-9).ceil().max(DVec3::ONE);
        let total = n.x * n.y * n.z;
        if total > MAX_CELLS as f64 {
            return Err(CellError::TooManyCells(total as u64, MAX_CELLS));
        }
        let counts = n.as_ivec3();
        let origin = region.center() - 0.5 * cell_size * n;
        Ok(CellGrid {
            origin,
            cell_size,
            counts,
        })
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
        let half = DVec3::splat(0.5 * self.cell_size);
        Some(ViewCell {
            index,
            center: self.origin + (index.as_dvec3() + 0.5) * self.cell_size,
            half,
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
        let f = ((p - self.origin) / self.cell_size).floor();
        if !f.is_finite() {
            return None;
        }
        self.cell(f.as_ivec3())
    }

    /// Parses a cell id `x_y_z` and checks it is inside the grid.
    pub fn parse_id(&self, id: &str) -> Result<ViewCell, CellError> {
        let bad = || CellError::BadCellId(id.to_string());
        let parts: Vec<&str> = id.trim().split('_').collect();
        if parts.len() != 3 {
            return Err(bad());
        }
        let mut v = [0i32; 3];
        for (k, p) in parts.iter().enumerate() {
            v[k] = p.parse().map_err(|_| bad())?;
        }
        self.cell(IVec3::from_array(v)).ok_or_else(bad)
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
    fn rejects_bad_parameters() {
        let r = Aabb::new(DVec3::ZERO, DVec3::ONE);
        assert!(CellGrid::tile(r, 0.0).is_err());
        assert!(CellGrid::tile(r, f64::NAN).is_err());
        assert!(CellGrid::tile(r, -1.0).is_err());
        assert!(CellGrid::tile(Aabb::new(DVec3::ONE, DVec3::ZERO), 1.0).is_err());
        assert!(CellGrid::tile(Aabb::new(DVec3::ZERO, DVec3::splat(1e6)), 1.0).is_err());
    }
}
