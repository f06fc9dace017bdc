//! What a bake did, as a typed report: per cell (baked now or skipped as already baked) its
//! bytes, triangles, texels and seconds per stage (GI 2002 Table 2 and more), and the totals.
//! `lemi bake --json` prints it and `lemi compare` keeps it for every layered strategy.

use std::collections::BTreeMap;

use lemi_core::bundle::CellStats;
use lemi_core::cell::CellId;
use serde::Serialize;

use crate::{CellOutcome, RunSummary};

/// One cell's line of the report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CellReport {
    pub id: CellId,
    /// `baked` or `skipped (already baked)`.
    pub status: &'static str,
    pub seconds: f64,
    /// Bytes of the cell file.
    pub bytes: u64,
    pub raw_bytes: u64,
    pub macro_bytes: u64,
    pub png_bytes: u64,
    /// Bytes of the KTX2 macro-textures (block formats).
    pub ktx2_bytes: u64,
    /// Bytes of the stored macro-textures, PNG or KTX2.
    pub texture_bytes: u64,
    /// Bytes the macro-textures occupy in texture memory in their stored format.
    pub texture_memory_bytes: u64,
    pub far_triangles: u64,
    pub near_triangles: u64,
    pub submitted_triangles: u64,
    pub opaque_texels_recorded: u64,
    /// Texels the outline copies added (`BakeParams::outline_copies`).
    pub outline_copies: u64,
    /// Recorded texels marked as outline fringe (`BakeParams::outline_fringe`).
    pub outline_fringe: u64,
    /// Quads holding the outline fringe of a format without its alpha level (BC1, ETC1S).
    pub fringe_quads: u64,
    pub opaque_texels_after_hidden_removal: u64,
    pub micro_textures: u64,
    pub micro_fill_ratio: f64,
    pub macro_textures: u64,
    /// Seconds per stage (cells baked in this run only).
    pub stage_seconds: BTreeMap<String, f64>,
}

impl CellReport {
    fn new(id: CellId, status: &'static str, seconds: f64, bytes: u64, s: &CellStats) -> Self {
        CellReport {
            id,
            status,
            seconds,
            bytes,
            raw_bytes: s.raw_bytes,
            macro_bytes: s.macro_bytes,
            png_bytes: s.png_bytes,
            ktx2_bytes: s.ktx2_bytes,
            texture_bytes: s.texture_bytes(),
            texture_memory_bytes: s.texture_memory_bytes(),
            far_triangles: s.far_triangles,
            near_triangles: s.near_triangles,
            submitted_triangles: s.submitted_triangles,
            opaque_texels_recorded: s.opaque_texels_recorded,
            outline_copies: s.outline_copies,
            outline_fringe: s.outline_fringe,
            fringe_quads: s.fringe_quads,
            opaque_texels_after_hidden_removal: s.opaque_texels_after_hidden_removal,
            micro_textures: s.micro_textures,
            micro_fill_ratio: s.micro_fill_ratio,
            macro_textures: s.macro_textures,
            stage_seconds: s.seconds.iter().cloned().collect(),
        }
    }
}

/// The report of one [`crate::run`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BakeReport {
    pub per_cell: Vec<CellReport>,
    pub baked: usize,
    pub skipped: usize,
    /// Bytes of all cell files.
    pub bytes: u64,
    /// The cells' statistics added up (seconds per stage summed over the baked cells).
    pub total: CellStats,
}

impl RunSummary {
    /// The typed report of this run.
    pub fn report(&self) -> BakeReport {
        let mut r = BakeReport::default();
        for o in &self.outcomes {
            let line = match o {
                CellOutcome::Baked {
                    entry,
                    file,
                    seconds,
                } => {
                    r.baked += 1;
                    add(&mut r.total, &file.header.stats);
                    CellReport::new(entry.id, "baked", *seconds, entry.bytes, &file.header.stats)
                }
                CellOutcome::Skipped { entry, stats } => {
                    r.skipped += 1;
                    add(&mut r.total, stats);
                    CellReport::new(entry.id, "skipped (already baked)", 0.0, entry.bytes, stats)
                }
            };
            r.bytes += line.bytes;
            r.per_cell.push(line);
        }
        r
    }
}

/// Adds the statistics of a cell to a running total (seconds by stage name).
fn add(total: &mut CellStats, s: &CellStats) {
    total.far_triangles += s.far_triangles;
    total.near_triangles += s.near_triangles;
    total.submitted_triangles += s.submitted_triangles;
    total.raw_bytes += s.raw_bytes;
    total.opaque_texels_recorded += s.opaque_texels_recorded;
    total.opaque_texels_after_gap_fill += s.opaque_texels_after_gap_fill;
    total.outline_copies += s.outline_copies;
    total.outline_fringe += s.outline_fringe;
    total.fringe_quads += s.fringe_quads;
    total.opaque_texels_after_hidden_removal += s.opaque_texels_after_hidden_removal;
    total.micro_textures += s.micro_textures;
    total.macro_textures += s.macro_textures;
    total.macro_bytes += s.macro_bytes;
    total.png_bytes += s.png_bytes;
    total.ktx2_bytes += s.ktx2_bytes;
    total.block_bytes += s.block_bytes;
    for (k, v) in &s.seconds {
        match total.seconds.iter_mut().find(|(n, _)| n == k) {
            Some((_, t)) => *t += v,
            None => total.seconds.push((k.clone(), *v)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lemi_core::bundle::{cell_file_name, CellEntry};

    fn entry(id: &str, bytes: u64) -> CellEntry {
        let id: CellId = id.parse().expect("id");
        CellEntry {
            id,
            file: cell_file_name(id),
            bytes,
            blake3: String::new(),
        }
    }

    fn stats(far: u64, png: u64, stage: f64) -> CellStats {
        CellStats {
            far_triangles: far,
            png_bytes: png,
            seconds: vec![("record".into(), stage)],
            ..Default::default()
        }
    }

    #[test]
    fn baked_and_skipped_cells_add_up() {
        let skipped = CellOutcome::Skipped {
            entry: entry("0_0_0", 100),
            stats: Box::new(stats(10, 7, 0.0)),
        };
        let run = RunSummary {
            outcomes: vec![skipped],
            ..Default::default()
        };
        let r = run.report();
        assert_eq!((r.baked, r.skipped, r.bytes), (0, 1, 100));
        assert_eq!(r.per_cell[0].status, "skipped (already baked)");
        assert_eq!(r.total.far_triangles, 10);
        assert_eq!(r.total.png_bytes, 7);
        let mut b = stats(5, 3, 2.0);
        b.seconds.push(("png".into(), 0.5));
        let mut t = stats(0, 0, 1.5);
        t.seconds.clear();
        add(&mut t, &b);
        add(&mut t, &stats(1, 1, 1.0));
        assert_eq!(t.far_triangles, 6);
        assert_eq!(
            t.seconds,
            vec![("record".to_string(), 3.0), ("png".to_string(), 0.5)]
        );
    }
}
