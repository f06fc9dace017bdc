//! Per-frame records of a walk, their CSV file (`frames.csv`), and the frame-time statistics (the
//! numbers behind GI 2002 Figs. 8–9: frame times of the impostor and the all-geometry replay of
//! the same path, primitives per frame, cell switches and stalls).
//!
//! # Frame time
//! The statistics use [`FrameRecord::cpu_ms`], the wall-clock time of the whole frame on the CPU.
//! The walk waits for every frame's GPU work to finish (without copying the pixels back, as a
//! runtime that presents its frames; only the frames an observer keeps are read back, and warp
//! finishes its frames on the CPU), so that time includes the GPU's work on the frame.
//! [`FrameRecord::gpu_ms`] is the GPU time from timestamp queries when the caller has them
//! (`None` otherwise); its medians are reported beside.
//!
//! # Percentiles
//! Nearest rank: of `n` sorted values `x[1] ≤ … ≤ x[n]`, the p-th percentile is `x[⌈p/100 · n⌉]`
//! (the first value for `p = 0`). The median is the 50th percentile, so of an even number of
//! values it is the lower of the two middle ones. Non-finite times are left out of the statistics.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::WalkError;

/// Which renderer drew a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Near geometry plus the current cell's impostors.
    Impostor,
    /// All the scene's geometry, unculled (the second baseline).
    Geometry,
    /// All the scene's geometry, frustum culled over a cluster hierarchy
    /// (`lemi_gpu::Renderer::render_culled`): what an ordinary renderer would at least do, the
    /// baseline a speed-up is quoted against.
    #[serde(rename = "geometry-culled")]
    Culled,
}

impl Mode {
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Impostor => "impostor",
            Mode::Geometry => "geometry",
            Mode::Culled => "geometry-culled",
        }
    }
}

/// What one frame of a replay did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Frame index on the path.
    pub frame: u64,
    /// Path time (seconds).
    pub t: f64,
    pub mode: Mode,
    /// Wall-clock time of the frame (ms), until the GPU finished it (see the module doc).
    pub cpu_ms: f64,
    /// GPU time of the frame (ms) from timestamp queries, if available.
    pub gpu_ms: Option<f64>,
    /// Near-field triangles drawn (impostor mode; 0 in geometry mode).
    pub near_triangles: u64,
    /// Impostor quads drawn (impostor mode; 0 in geometry mode).
    pub impostor_quads: u64,
    /// Triangles submitted in the frame: near triangles + 2 per quad in impostor mode, every
    /// triangle of the scene in geometry mode, those of the clusters in view in geometry-culled
    /// mode.
    pub total_triangles: u64,
    /// Id of the view cell the eye is in, if any.
    pub cell: Option<String>,
    /// The cell differs from the previous frame's.
    pub cell_switch: bool,
    /// The frame waited for a cell that was not resident yet.
    pub stalled: bool,
    /// Bytes held by the cell cache after the frame.
    pub cache_bytes: u64,
    /// The frame was drawn without impostors (e.g. outside every baked cell, or while the cell
    /// was loading): all geometry instead.
    pub fallback: bool,
}

impl FrameRecord {
    /// Primitives drawn: near triangles + impostor quads in impostor mode, total triangles in
    /// the geometry modes (the bottom panel of the plot).
    pub fn primitives(&self) -> u64 {
        match self.mode {
            Mode::Impostor => self.near_triangles + self.impostor_quads,
            Mode::Geometry | Mode::Culled => self.total_triangles,
        }
    }
}

/// The CSV columns, in order.
pub const CSV_COLUMNS: [&str; 13] = [
    "frame",
    "t",
    "mode",
    "cpu_ms",
    "gpu_ms",
    "near_triangles",
    "impostor_quads",
    "total_triangles",
    "cell",
    "cell_switch",
    "stalled",
    "cache_bytes",
    "fallback",
];

/// One row of `frames.csv`: the fields of [`FrameRecord`] in [`CSV_COLUMNS`] order, numbers in
/// Rust's shortest round-trip form (`40`, not `40.0`), booleans as `0`/`1`.
#[derive(Serialize, Deserialize)]
struct CsvRow {
    frame: u64,
    #[serde(with = "shortest")]
    t: f64,
    mode: Mode,
    #[serde(with = "shortest")]
    cpu_ms: f64,
    #[serde(with = "shortest_opt")]
    gpu_ms: Option<f64>,
    near_triangles: u64,
    impostor_quads: u64,
    total_triangles: u64,
    cell: Option<String>,
    #[serde(with = "bit")]
    cell_switch: bool,
    #[serde(with = "bit")]
    stalled: bool,
    cache_bytes: u64,
    #[serde(with = "bit")]
    fallback: bool,
}

impl From<&FrameRecord> for CsvRow {
    fn from(r: &FrameRecord) -> Self {
        CsvRow {
            frame: r.frame,
            t: r.t,
            mode: r.mode,
            cpu_ms: r.cpu_ms,
            gpu_ms: r.gpu_ms,
            near_triangles: r.near_triangles,
            impostor_quads: r.impostor_quads,
            total_triangles: r.total_triangles,
            cell: r.cell.clone(),
            cell_switch: r.cell_switch,
            stalled: r.stalled,
            cache_bytes: r.cache_bytes,
            fallback: r.fallback,
        }
    }
}

impl From<CsvRow> for FrameRecord {
    fn from(r: CsvRow) -> Self {
        FrameRecord {
            frame: r.frame,
            t: r.t,
            mode: r.mode,
            cpu_ms: r.cpu_ms,
            gpu_ms: r.gpu_ms,
            near_triangles: r.near_triangles,
            impostor_quads: r.impostor_quads,
            total_triangles: r.total_triangles,
            cell: r.cell.filter(|c| !c.is_empty()),
            cell_switch: r.cell_switch,
            stalled: r.stalled,
            cache_bytes: r.cache_bytes,
            fallback: r.fallback,
        }
    }
}

/// `f64` as its shortest round-trip text (`Display`).
mod shortest {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&v.to_string())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        let text = String::deserialize(d)?;
        text.trim().parse().map_err(serde::de::Error::custom)
    }
}

/// `Option<f64>`: the shortest round-trip text, or an empty field.
mod shortest_opt {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&v.map(|v| v.to_string()).unwrap_or_default())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        let text = String::deserialize(d)?;
        let text = text.trim();
        if text.is_empty() {
            return Ok(None);
        }
        text.parse().map(Some).map_err(serde::de::Error::custom)
    }
}

/// `bool` as `0`/`1` (reading also accepts `true`/`false`).
mod bit {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &bool, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(if *v { "1" } else { "0" })
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<bool, D::Error> {
        match String::deserialize(d)?.trim() {
            "1" | "true" => Ok(true),
            "0" | "false" => Ok(false),
            other => Err(serde::de::Error::custom(format!(
                "expected 0 or 1, got `{other}`"
            ))),
        }
    }
}

/// The records as CSV: a header row of [`CSV_COLUMNS`], then one row per record (see
/// [`CsvRow`]); `None` is an empty field; fields with commas, quotes or line breaks are quoted.
pub fn to_csv(records: &[FrameRecord]) -> Result<String, csv::Error> {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    if records.is_empty() {
        w.write_record(CSV_COLUMNS)?;
    }
    for r in records {
        w.serialize(CsvRow::from(r))?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| csv::Error::from(e.into_error()))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// Writes [`to_csv`] to `path` atomically.
pub fn write_csv(path: &Path, records: &[FrameRecord]) -> Result<(), WalkError> {
    let text = to_csv(records).map_err(|source| WalkError::Csv {
        path: path.to_path_buf(),
        source,
    })?;
    lemi_core::container::write_atomic(path, text.as_bytes())
        .map_err(|e| WalkError::io("frame CSV", path, e))
}

/// Reads a `frames.csv` (columns by name, so extra columns are ignored); errors name the file and
/// the line.
pub fn read_csv(path: &Path) -> Result<Vec<FrameRecord>, WalkError> {
    let csv_err = |source| WalkError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let mut r = csv::Reader::from_path(path).map_err(csv_err)?;
    r.deserialize::<CsvRow>()
        .map(|row| row.map(FrameRecord::from).map_err(csv_err))
        .collect()
}

/// The nearest-rank `p`-th percentile (`0 ≤ p ≤ 100`) of sorted values (see the module doc);
/// `None` for no values.
pub fn nearest_rank(sorted: &[f64], p: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let n = sorted.len();
    let rank = (p.clamp(0.0, 100.0) / 100.0 * n as f64).ceil() as usize;
    Some(sorted[rank.clamp(1, n) - 1])
}

/// Frame-time statistics of one mode.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TimeStats {
    pub frames: usize,
    pub median_ms: Option<f64>,
    pub p99_ms: Option<f64>,
    pub mean_ms: Option<f64>,
    pub max_ms: Option<f64>,
    /// Frames per second over the whole replay: `1000 / mean_ms` (frames divided by their total
    /// time, not the mean of per-frame rates).
    pub mean_fps: Option<f64>,
    /// Median GPU time (ms) of the frames that have one.
    pub gpu_median_ms: Option<f64>,
    /// Mean primitives per frame ([`FrameRecord::primitives`]).
    pub mean_primitives: Option<f64>,
}

impl TimeStats {
    pub fn of(records: &[FrameRecord]) -> TimeStats {
        let sorted = |mut v: Vec<f64>| {
            v.retain(|x| x.is_finite());
            v.sort_by(f64::total_cmp);
            v
        };
        let cpu = sorted(records.iter().map(|r| r.cpu_ms).collect());
        let gpu = sorted(records.iter().filter_map(|r| r.gpu_ms).collect());
        let mean = (!cpu.is_empty()).then(|| cpu.iter().sum::<f64>() / cpu.len() as f64);
        TimeStats {
            frames: records.len(),
            median_ms: nearest_rank(&cpu, 50.0),
            p99_ms: nearest_rank(&cpu, 99.0),
            mean_ms: mean,
            max_ms: cpu.last().copied(),
            mean_fps: mean.filter(|&m| m > 0.0).map(|m| 1000.0 / m),
            gpu_median_ms: nearest_rank(&gpu, 50.0),
            mean_primitives: (!records.is_empty()).then(|| {
                records.iter().map(|r| r.primitives() as f64).sum::<f64>() / records.len() as f64
            }),
        }
    }
}

/// The statistics of a replay, the first keys of `summary.json` ([`crate::WalkSummary`] adds
/// what the run knows besides the frames). Counts are of the impostor replay; a statistic with no
/// frames behind it (e.g. no geometry replay) is `null`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameStats {
    /// Frames of the impostor replay.
    pub frames: usize,
    /// Frames of the geometry replay.
    pub geometry_frames: usize,
    /// Impostor frames that waited for a cell.
    pub stalls: usize,
    /// Impostor frames whose cell differs from the previous frame's.
    pub cell_switches: usize,
    /// Impostor frames drawn as all geometry instead.
    pub fallback_frames: usize,
    /// The most cache bytes after any impostor frame.
    pub max_cache_bytes: u64,
    pub impostor_median_ms: Option<f64>,
    pub impostor_p99_ms: Option<f64>,
    pub geometry_median_ms: Option<f64>,
    pub geometry_p99_ms: Option<f64>,
    /// `geometry_median_ms / impostor_median_ms`.
    pub speedup_median: Option<f64>,
    /// Median GPU time (timestamp queries, no readback) of each mode and their ratio, when the
    /// adapter has timestamps and the strategy's frames are GPU work.
    #[serde(default)]
    pub impostor_gpu_median_ms: Option<f64>,
    #[serde(default)]
    pub geometry_gpu_median_ms: Option<f64>,
    #[serde(default)]
    pub speedup_gpu_median: Option<f64>,
    pub impostor_mean_fps: Option<f64>,
    pub geometry_mean_fps: Option<f64>,
    /// Everything about each mode.
    pub impostor: TimeStats,
    pub geometry: TimeStats,
    /// Frames of the geometry-culled replay ([`Mode::Culled`]; `geometry_*` keys are the unculled
    /// replay's).
    #[serde(default)]
    pub culled_frames: usize,
    #[serde(default)]
    pub culled_median_ms: Option<f64>,
    #[serde(default)]
    pub culled_p99_ms: Option<f64>,
    #[serde(default)]
    pub culled_gpu_median_ms: Option<f64>,
    #[serde(default)]
    pub culled_mean_fps: Option<f64>,
    /// Mean triangles a geometry-culled frame submitted.
    #[serde(default)]
    pub culled_mean_triangles: Option<f64>,
    /// `culled_median_ms / impostor_median_ms`: the speed-up against geometry-culled.
    #[serde(default)]
    pub speedup_culled_median: Option<f64>,
    /// `culled_gpu_median_ms / impostor_gpu_median_ms`.
    #[serde(default)]
    pub speedup_culled_gpu_median: Option<f64>,
    #[serde(default)]
    pub culled: TimeStats,
}

fn ratio(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        _ => None,
    }
}

impl FrameStats {
    /// The statistics of the impostor and the unculled geometry replays (no culled replay).
    pub fn of(impostor: &[FrameRecord], geometry: &[FrameRecord]) -> FrameStats {
        FrameStats::of_all(impostor, geometry, &[])
    }

    /// The statistics of the impostor, the unculled and the geometry-culled replays.
    pub fn of_all(
        impostor: &[FrameRecord],
        geometry: &[FrameRecord],
        culled: &[FrameRecord],
    ) -> FrameStats {
        let i = TimeStats::of(impostor);
        let g = TimeStats::of(geometry);
        let c = TimeStats::of(culled);
        let speedup = ratio(g.median_ms, i.median_ms);
        FrameStats {
            frames: impostor.len(),
            geometry_frames: geometry.len(),
            stalls: impostor.iter().filter(|r| r.stalled).count(),
            cell_switches: impostor.iter().filter(|r| r.cell_switch).count(),
            fallback_frames: impostor.iter().filter(|r| r.fallback).count(),
            max_cache_bytes: impostor.iter().map(|r| r.cache_bytes).max().unwrap_or(0),
            impostor_median_ms: i.median_ms,
            impostor_p99_ms: i.p99_ms,
            geometry_median_ms: g.median_ms,
            geometry_p99_ms: g.p99_ms,
            speedup_median: speedup,
            impostor_gpu_median_ms: i.gpu_median_ms,
            geometry_gpu_median_ms: g.gpu_median_ms,
            speedup_gpu_median: ratio(g.gpu_median_ms, i.gpu_median_ms),
            impostor_mean_fps: i.mean_fps,
            geometry_mean_fps: g.mean_fps,
            culled_frames: culled.len(),
            culled_median_ms: c.median_ms,
            culled_p99_ms: c.p99_ms,
            culled_gpu_median_ms: c.gpu_median_ms,
            culled_mean_fps: c.mean_fps,
            culled_mean_triangles: c.mean_primitives,
            speedup_culled_median: ratio(c.median_ms, i.median_ms),
            speedup_culled_gpu_median: ratio(c.gpu_median_ms, i.gpu_median_ms),
            impostor: i,
            geometry: g,
            culled: c,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A record with the given mode and time; the rest plausible.
    pub(crate) fn rec(frame: u64, mode: Mode, cpu_ms: f64) -> FrameRecord {
        FrameRecord {
            frame,
            t: frame as f64 / 30.0,
            mode,
            cpu_ms,
            gpu_ms: None,
            near_triangles: if mode == Mode::Impostor { 1000 } else { 0 },
            impostor_quads: if mode == Mode::Impostor { 200 } else { 0 },
            total_triangles: if mode == Mode::Impostor {
                1400
            } else {
                100_000
            },
            cell: Some("0_0_0".into()),
            cell_switch: false,
            stalled: false,
            cache_bytes: 1 << 20,
            fallback: false,
        }
    }

    #[test]
    fn nearest_rank_definition() {
        let v: Vec<f64> = (1..=10).map(f64::from).collect();
        assert_eq!(nearest_rank(&v, 50.0), Some(5.0)); // ceil(5) = 5th
        assert_eq!(nearest_rank(&v, 99.0), Some(10.0)); // ceil(9.9) = 10th
        assert_eq!(nearest_rank(&v, 90.0), Some(9.0));
        assert_eq!(nearest_rank(&v, 0.0), Some(1.0));
        assert_eq!(nearest_rank(&v, 100.0), Some(10.0));
        assert_eq!(nearest_rank(&[7.0], 50.0), Some(7.0));
        assert_eq!(nearest_rank(&[], 50.0), None);
        let v: Vec<f64> = (1..=200).map(f64::from).collect();
        assert_eq!(nearest_rank(&v, 99.0), Some(198.0)); // ceil(198) = 198th
        assert_eq!(nearest_rank(&v, 50.0), Some(100.0)); // the lower middle
    }

    #[test]
    fn summary_of_known_numbers() {
        // Impostor frames 1..=100 ms (shuffled), geometry frames 3, 6, ..., 300 ms.
        let mut imp: Vec<FrameRecord> = (0..100)
            .map(|i| rec(i, Mode::Impostor, ((i * 37) % 100 + 1) as f64))
            .collect();
        imp[10].stalled = true;
        imp[20].stalled = true;
        imp[30].cell_switch = true;
        imp[40].fallback = true;
        imp[50].cache_bytes = 5 << 20;
        imp[0].gpu_ms = Some(2.0);
        imp[1].gpu_ms = Some(4.0);
        imp[2].cpu_ms = f64::NAN; // left out: 99 finite values remain
        let geo: Vec<FrameRecord> = (0..100)
            .map(|i| rec(i, Mode::Geometry, 3.0 * (i + 1) as f64))
            .collect();
        let s = FrameStats::of(&imp, &geo);
        assert_eq!(s.frames, 100);
        assert_eq!(s.geometry_frames, 100);
        assert_eq!(s.stalls, 2);
        assert_eq!(s.cell_switches, 1);
        assert_eq!(s.fallback_frames, 1);
        assert_eq!(s.max_cache_bytes, 5 << 20);
        // imp[2] had (2·37 % 100) + 1 = 75 ms; the rest 1..=100 without 75: 99 values.
        // Median: 50th of 99 -> 50; p99: ceil(98.01) = 99th -> 100.
        assert_eq!(s.impostor_median_ms, Some(50.0));
        assert_eq!(s.impostor_p99_ms, Some(100.0));
        assert_eq!(s.geometry_median_ms, Some(150.0));
        assert_eq!(s.geometry_p99_ms, Some(297.0));
        assert_eq!(s.speedup_median, Some(3.0));
        let mean_imp = (5050.0 - 75.0) / 99.0;
        assert!((s.impostor.mean_ms.unwrap() - mean_imp).abs() < 1e-12);
        assert!((s.impostor_mean_fps.unwrap() - 1000.0 / mean_imp).abs() < 1e-9);
        assert!((s.geometry_mean_fps.unwrap() - 1000.0 / 151.5).abs() < 1e-9);
        assert_eq!(s.impostor.max_ms, Some(100.0));
        assert_eq!(s.impostor.gpu_median_ms, Some(2.0));
        assert_eq!(s.impostor.mean_primitives, Some(1200.0));
        assert_eq!(s.geometry.mean_primitives, Some(100_000.0));
        // JSON has the promised keys.
        let v: serde_json::Value = serde_json::to_value(&s).unwrap();
        for k in [
            "frames",
            "stalls",
            "cell_switches",
            "impostor_median_ms",
            "impostor_p99_ms",
            "geometry_median_ms",
            "geometry_p99_ms",
            "speedup_median",
            "impostor_mean_fps",
            "geometry_mean_fps",
        ] {
            assert!(v.get(k).is_some_and(|x| !x.is_null()), "{k}");
        }
        // No geometry replay: its numbers are null.
        let s = FrameStats::of(&imp, &[]);
        assert_eq!(s.geometry_median_ms, None);
        assert_eq!(s.speedup_median, None);
        let v: serde_json::Value = serde_json::to_value(&s).unwrap();
        assert!(v["speedup_median"].is_null());
        assert_eq!(s.culled_frames, 0);
        assert_eq!(s.culled_median_ms, None);
        assert!(v["speedup_culled_median"].is_null());
        let empty = FrameStats::of(&[], &[]);
        assert_eq!(empty.frames, 0);
        assert_eq!(empty.impostor_median_ms, None);
    }

    #[test]
    fn culled_replay_has_its_own_keys_and_speed_ups() {
        let imp: Vec<FrameRecord> = (0..10).map(|i| rec(i, Mode::Impostor, 5.0)).collect();
        let geo: Vec<FrameRecord> = (0..10).map(|i| rec(i, Mode::Geometry, 40.0)).collect();
        let culled: Vec<FrameRecord> = (0..10)
            .map(|i| {
                let mut r = rec(i, Mode::Culled, 10.0 + i as f64);
                r.total_triangles = 1000 * (i + 1);
                r.gpu_ms = Some(2.0);
                r
            })
            .collect();
        let s = FrameStats::of_all(&imp, &geo, &culled);
        // the unculled keys keep their meaning
        assert_eq!(s.geometry_median_ms, Some(40.0));
        assert_eq!(s.speedup_median, Some(8.0));
        assert_eq!(s.culled_frames, 10);
        assert_eq!(s.culled_median_ms, Some(14.0));
        assert_eq!(s.culled_p99_ms, Some(19.0));
        assert_eq!(s.culled_gpu_median_ms, Some(2.0));
        assert_eq!(s.culled_mean_triangles, Some(5500.0));
        assert_eq!(s.speedup_culled_median, Some(14.0 / 5.0));
        assert_eq!(s.speedup_culled_gpu_median, None); // no impostor GPU times
        let v = serde_json::to_value(&s).unwrap();
        for k in [
            "culled_frames",
            "culled_median_ms",
            "culled_p99_ms",
            "culled_gpu_median_ms",
            "culled_mean_fps",
            "culled_mean_triangles",
            "speedup_culled_median",
            "culled",
        ] {
            assert!(v.get(k).is_some_and(|x| !x.is_null()), "{k}");
        }
        // summaries written before the culled replay existed still read
        let mut old = v.as_object().unwrap().clone();
        old.retain(|k, _| !k.contains("culled"));
        let back: FrameStats = serde_json::from_value(serde_json::Value::Object(old)).unwrap();
        assert_eq!(back.culled_frames, 0);
        assert_eq!(back.geometry_median_ms, Some(40.0));
        // the mode's CSV name
        let text = to_csv(&culled[..1]).unwrap();
        assert!(
            text.lines().nth(1).unwrap().contains(",geometry-culled,"),
            "{text}"
        );
    }

    #[test]
    fn csv_has_a_header_and_stable_columns() {
        let mut a = rec(0, Mode::Impostor, 12.5);
        a.gpu_ms = Some(3.25);
        a.cell_switch = true;
        let mut b = rec(1, Mode::Geometry, 40.0);
        b.cell = None;
        b.stalled = true;
        b.cell = Some("a,\"b".into());
        let text = to_csv(&[a.clone(), b.clone()]).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[0],
            "frame,t,mode,cpu_ms,gpu_ms,near_triangles,impostor_quads,total_triangles,cell,\
             cell_switch,stalled,cache_bytes,fallback"
        );
        assert_eq!(
            lines[1],
            "0,0,impostor,12.5,3.25,1000,200,1400,0_0_0,1,0,1048576,0"
        );
        assert_eq!(
            lines[2],
            "1,0.03333333333333333,geometry,40,,0,0,100000,\"a,\"\"b\",0,1,1048576,0"
        );
        assert_eq!(lines.len(), 3);
        let dir = std::env::temp_dir().join(format!("lemi-walk-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("frames.csv");
        write_csv(&f, &[rec(0, Mode::Impostor, 1.0)]).unwrap();
        assert!(std::fs::read_to_string(&f).unwrap().starts_with("frame,t,"));
        // The file reads back as the records it was written from.
        write_csv(&f, &[a.clone(), b.clone()]).unwrap();
        assert_eq!(read_csv(&f).unwrap(), vec![a, b]);
        write_csv(&f, &[]).unwrap();
        assert!(std::fs::read_to_string(&f).unwrap().starts_with("frame,t,"));
        assert_eq!(read_csv(&f).unwrap(), vec![]);
        std::fs::write(&f, "frame,t,mode\n0,x,impostor\n").unwrap();
        let e = read_csv(&f).unwrap_err().to_string();
        assert!(e.contains("frames.csv"), "{e}");
        let s = FrameStats::of(&[rec(0, Mode::Impostor, 1.0)], &[]);
        let back: FrameStats = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back, s);
        let e = format!(
            "{}",
            write_csv(&dir.join("no/such/dir/x.csv"), &[]).unwrap_err()
        );
        assert!(e.contains("x.csv"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
