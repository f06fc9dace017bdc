//! [`PixelErrorStats`]: an accumulator of per-pixel geometric errors (in output pixels) that merges,
//! so statistics aggregate per view → per cell → per bundle without keeping the pixels.
//!
//! It keeps the exact count, sum (f64), maximum and count above 1 px, plus a fine histogram from which
//! quantiles (p99) are read:
//! - below 8 px: linear bins of 1/320 px (0.003125 px; 16 of them make one 0.05 px display bin and
//!   320 make 1 px, so the display histogram and the 1 px threshold fall on bin edges);
//! - from 8 px on: logarithmic bins, 32 per octave (each ≤ 2.2 % wide), up to 8·2⁴⁰ px; larger and
//!   infinite values go to the last bin.
//!
//! **Precision of [`PixelErrorStats::quantile`] (p99)**: it returns the upper edge of the bin holding
//! the nearest-rank quantile, clamped to the exact maximum, so it is never below the exact
//! nearest-rank value and exceeds it by at most one bin: ≤ 1/320 px below 8 px, ≤ 2.2 % above.
//! The histogram grows only up to the largest bin used (a few kB for sub-pixel errors).
//!
//! NaN values (pixels where the error is not applicable) are ignored and counted separately.
//! Errors are expected to be ≥ 0; a negative value is binned as 0 (but enters the mean as it is).
//! The display [`Histogram`] is 0–4 px in 0.05 px bins plus an overflow count.

use serde::{Deserialize, Serialize};

/// Fine linear bins per pixel.
const FINE_PER_PX: f32 = 320.0;
/// Where the linear bins end, in pixels.
const LINEAR_END_PX: f32 = 8.0;
/// Number of linear bins.
const LINEAR_BINS: usize = 2560;
/// Logarithmic bins per octave above `LINEAR_END_PX`.
const LOG_PER_OCTAVE: f32 = 32.0;
/// Number of logarithmic bins (40 octaves).
const LOG_BINS: usize = 32 * 40;
/// Display histogram: bin width in px and number of bins (0–4 px).
pub const DISPLAY_BIN_PX: f32 = 0.05;
pub const DISPLAY_BINS: usize = 80;
const FINE_PER_DISPLAY: usize = 16;

/// A mergeable accumulator of per-pixel errors; see the module documentation for its precision.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PixelErrorStats {
    count: u64,
    nan: u64,
    sum: f64,
    max: f32,
    above_1px: u64,
    /// Fine bins (see the module doc), trimmed after the last one used.
    bins: Vec<u64>,
}

fn bin_of(v: f32) -> usize {
    if v.is_nan() || v <= 0.0 {
        return 0;
    }
    if v < LINEAR_END_PX {
        return ((v * FINE_PER_PX) as usize).min(LINEAR_BINS - 1);
    }
    if !v.is_finite() {
        return LINEAR_BINS + LOG_BINS - 1;
    }
    let k = ((v / LINEAR_END_PX).log2() * LOG_PER_OCTAVE) as usize;
    LINEAR_BINS + k.min(LOG_BINS - 1)
}

fn bin_upper_edge(b: usize) -> f32 {
    if b < LINEAR_BINS {
        (b + 1) as f32 / FINE_PER_PX
    } else if b == LINEAR_BINS + LOG_BINS - 1 {
        f32::INFINITY
    } else {
        LINEAR_END_PX * (((b - LINEAR_BINS + 1) as f32) / LOG_PER_OCTAVE).exp2()
    }
}

impl PixelErrorStats {
    pub fn new() -> PixelErrorStats {
        PixelErrorStats::default()
    }

    /// Statistics of one set of values (NaN ignored).
    pub fn from_values(values: &[f32]) -> PixelErrorStats {
        let mut s = PixelErrorStats::new();
        s.add_all(values);
        s
    }

    /// Adds one value; NaN is ignored (counted in [`Self::ignored_nan`]).
    pub fn add(&mut self, v: f32) {
        if v.is_nan() {
            self.nan += 1;
            return;
        }
        if self.count == 0 || v > self.max {
            self.max = v;
        }
        self.count += 1;
        self.sum += v as f64;
        self.above_1px += (v > 1.0) as u64;
        let b = bin_of(v);
        if self.bins.len() <= b {
            self.bins.resize(b + 1, 0);
        }
        self.bins[b] += 1;
    }

    pub fn add_all(&mut self, values: &[f32]) {
        for &v in values {
            self.add(v);
        }
    }

    /// Adds everything `other` holds: the result equals accumulating the union of both value sets.
    pub fn merge(&mut self, other: &PixelErrorStats) {
        if other.count > 0 && (self.count == 0 || other.max > self.max) {
            self.max = other.max;
        }
        self.count += other.count;
        self.nan += other.nan;
        self.sum += other.sum;
        self.above_1px += other.above_1px;
        if self.bins.len() < other.bins.len() {
            self.bins.resize(other.bins.len(), 0);
        }
        for (a, b) in self.bins.iter_mut().zip(&other.bins) {
            *a += b;
        }
    }

    /// Number of (non-NaN) values.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Number of NaN values ignored.
    pub fn ignored_nan(&self) -> u64 {
        self.nan
    }

    /// Largest value; 0 when empty.
    pub fn max(&self) -> f32 {
        if self.count == 0 {
            0.0
        } else {
            self.max
        }
    }

    /// Mean value; 0 when empty.
    pub fn mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum / self.count as f64
        }
    }

    /// Number of values strictly above 1 px.
    pub fn count_above_1px(&self) -> u64 {
        self.above_1px
    }

    /// Share of values strictly above 1 px; 0 when empty.
    pub fn share_above_1px(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.above_1px as f64 / self.count as f64
        }
    }

    /// The nearest-rank `q`-quantile (`q` in `[0, 1]`), as an upper bound within one fine bin (see
    /// the module doc); 0 when empty.
    pub fn quantile(&self, q: f64) -> f32 {
        if self.count == 0 {
            return 0.0;
        }
        let q = if q.is_nan() { 1.0 } else { q.clamp(0.0, 1.0) };
        let rank = ((q * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut cumulative = 0u64;
        for (b, &c) in self.bins.iter().enumerate() {
            cumulative += c;
            if cumulative >= rank {
                return bin_upper_edge(b).min(self.max);
            }
        }
        self.max
    }

    /// The 99th percentile; see [`Self::quantile`].
    pub fn p99(&self) -> f32 {
        self.quantile(0.99)
    }

    /// The display histogram: 0–4 px in 0.05 px bins, values ≥ 4 px in `overflow`.
    pub fn histogram(&self) -> Histogram {
        let mut counts = vec![0u64; DISPLAY_BINS];
        let mut overflow = 0u64;
        for (b, &c) in self.bins.iter().enumerate() {
            match counts.get_mut(b / FINE_PER_DISPLAY) {
                Some(slot) => *slot += c,
                None => overflow += c,
            }
        }
        Histogram {
            bin_width_px: DISPLAY_BIN_PX,
            counts,
            overflow,
        }
    }
}

/// A display histogram of pixel errors: `counts[i]` holds values in
/// `[i·bin_width_px, (i+1)·bin_width_px)`, `overflow` those at or above `counts.len()·bin_width_px`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Histogram {
    pub bin_width_px: f32,
    pub counts: Vec<u64>,
    pub overflow: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        PixelErrorStats::new().histogram()
    }
}

impl Histogram {
    /// Upper end of the binned range in pixels.
    pub fn range_px(&self) -> f32 {
        self.bin_width_px * self.counts.len() as f32
    }

    /// Total number of values.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum::<u64>() + self.overflow
    }

    /// Adds `other` (which must have the same bins; extra bins of `other` count as overflow).
    pub fn merge(&mut self, other: &Histogram) {
        for (i, &c) in other.counts.iter().enumerate() {
            match self.counts.get_mut(i) {
                Some(slot) => *slot += c,
                None => self.overflow += c,
            }
        }
        self.overflow += other.overflow;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_are_monotonic_and_edges_consistent() {
        let mut last = 0;
        let mut v = 0.0001f32;
        while v < 1e9 {
            let b = bin_of(v);
            assert!(b >= last, "bin of {v}");
            assert!(bin_upper_edge(b) > v, "upper edge of bin of {v}");
            if b > 0 {
                assert!(
                    bin_upper_edge(b - 1) <= v * 1.0001,
                    "lower edge of bin of {v}"
                );
            }
            last = b;
            v *= 1.01;
        }
        assert_eq!(bin_of(f32::INFINITY), LINEAR_BINS + LOG_BINS - 1);
        assert_eq!(bin_of(1.0), 320);
        assert_eq!(bin_of(0.05), 16);
    }

    #[test]
    fn empty_stats_are_zero() {
        let s = PixelErrorStats::from_values(&[f32::NAN, f32::NAN]);
        assert_eq!(s.count(), 0);
        assert_eq!(s.ignored_nan(), 2);
        assert_eq!((s.max(), s.mean(), s.p99()), (0.0, 0.0, 0.0));
        assert_eq!(s.histogram().total(), 0);
    }

    #[test]
    fn large_and_infinite_values() {
        let s = PixelErrorStats::from_values(&[0.5, 100.0, f32::INFINITY]);
        assert_eq!(s.max(), f32::INFINITY);
        assert_eq!(s.quantile(0.5), bin_upper_edge(bin_of(100.0)));
        assert!(s.quantile(0.5) >= 100.0 && s.quantile(0.5) < 100.0 * 1.022);
        assert_eq!(s.histogram().overflow, 2);
    }
}
