//! The eval report: the data model ([`ViewResult`] → [`CellResult`] → [`BundleResult`], sharing the
//! [`Aggregate`] totals), the one-line [`verdict`], the bounded [`WorstSet`] of views to show, and
//! [`write_report`], which writes `report.json` (serde) and a static, self-contained `index.html`
//! (a `maud` template, every text escaped): inline CSS and inline SVG histograms (drawn with
//! `plotters`), images as PNG files beside it, no network access. Every file is written atomically
//! ([`lemi_core::container::write_atomic`]: temporary file in the same directory + rename).
//!
//! Aggregation rules: pixel-error statistics merge exactly ([`PixelErrorStats::merge`]); crack pixels
//! add up; FLIP, SSIM and coverage are means over views (all views of an evaluation have the same
//! size, so this equals the pixel-weighted mean for FLIP); PSNR is that of the mean RGB MSE over the
//! views (the PSNR of all pixels pooled), so one identical view does not make it infinite. In JSON a
//! non-finite number (an infinite PSNR of identical images, an infinite pixel error) is `null`, read
//! back as `+∞`.

use std::cmp::Ordering;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use lemi_gpu::Frame;
use serde::{Deserialize, Serialize};

use crate::image_metrics::{check_frame, mse_from_psnr, psnr_from_mse};
use crate::stats::{Histogram, PixelErrorStats};
use crate::EvalError;

mod html;

/// How many worst views a [`CellResult`] lists.
pub const WORST_PER_CELL: usize = 3;
/// How many worst views a [`BundleResult`] lists.
pub const WORST_PER_BUNDLE: usize = 10;

use lemi_core::serde_inf::{f32_or_inf, f64_or_inf};

/// The pixel-error figures of one view.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorSummary {
    /// Pixels with an applicable (non-NaN) error.
    pub count: u64,
    #[serde(with = "f32_or_inf")]
    pub max: f32,
    /// See [`PixelErrorStats::quantile`] for its precision.
    #[serde(with = "f32_or_inf")]
    pub p99: f32,
    #[serde(with = "f64_or_inf")]
    pub mean: f64,
    /// Share of the counted pixels with an error above 1 px.
    pub above_1px: f64,
}

impl ErrorSummary {
    pub fn of(stats: &PixelErrorStats) -> ErrorSummary {
        ErrorSummary {
            count: stats.count(),
            max: stats.max(),
            p99: stats.p99(),
            mean: stats.mean(),
            above_1px: stats.share_above_1px(),
        }
    }
}

/// The metrics of one viewpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewResult {
    pub cell: String,
    /// Which sample of the cell, e.g. `"corner 3"`.
    pub viewpoint: String,
    pub eye: [f64; 3],
    pub dir: [f64; 3],
    pub error: ErrorSummary,
    pub crack_pixels: u64,
    /// Where the first crack pixels are, `[x, y]` from the top left, row-major, up to
    /// [`crate::MAX_CRACK_SAMPLES`] of them: the pixels `lemi render BUNDLE --compare` marks red
    /// from the same eye and direction. Omitted from the JSON where there are none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub crack_samples: Vec<[u32; 2]>,
    pub mean_flip: f32,
    /// dB over RGB; `+∞` (JSON `null`) for identical images.
    #[serde(with = "f64_or_inf")]
    pub psnr: f64,
    pub ssim: f64,
    /// Share of the reference's covered pixels the impostor covers ([`crate::Coverage::share`]).
    pub coverage: f64,
    /// Distances between the reference's and the impostor's coverage silhouettes, in pixels
    /// ([`crate::image_metrics::silhouettes`]); its `count` is the silhouette pixels of both.
    #[serde(default)]
    pub silhouette: ErrorSummary,
    /// How far the impostor's coverage is displaced from the reference's, in pixels
    /// ([`crate::image_metrics::SilhouetteStats::displacement`]): a slit or a thin feature one
    /// frame closes or drops counts its own pixels' distance, not its outline's distance to the
    /// nearest outline of the other frame.
    #[serde(default)]
    pub displacement: ErrorSummary,
    /// The silhouette distances of the geometry against itself seen turned by a fraction of a
    /// pixel ([`crate::EvalOptions::silhouette_floor_px`]): what the metric gives for a
    /// renderer that moves every point by that much, the floor under the impostor's. `None`
    /// where not asked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub silhouette_floor: Option<ErrorSummary>,
    /// Pixels the impostor covers where the reference shows background.
    #[serde(default)]
    pub false_coverage_pixels: u64,
    /// Pixels of the view (width × height).
    #[serde(default)]
    pub pixels: u64,
}

/// Orders views worst first: more crack pixels, then larger max error, then larger p99, then larger
/// mean FLIP. `Ordering::Less` means `a` is worse than `b`.
pub fn severity_cmp(a: &ViewResult, b: &ViewResult) -> Ordering {
    b.crack_pixels
        .cmp(&a.crack_pixels)
        .then_with(|| b.error.max.total_cmp(&a.error.max))
        .then_with(|| b.error.p99.total_cmp(&a.error.p99))
        .then_with(|| b.mean_flip.total_cmp(&a.mean_flip))
}

fn worst_of<'a>(views: impl Iterator<Item = &'a ViewResult>, n: usize) -> Vec<ViewResult> {
    let mut v: Vec<&ViewResult> = views.collect();
    v.sort_by(|a, b| severity_cmp(a, b));
    v.into_iter().take(n).cloned().collect()
}

/// Totals shared by a cell and the bundle (flattened into their JSON objects).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aggregate {
    /// Number of views evaluated.
    pub views: u64,
    /// Pixels with an applicable geometric error, over all views.
    pub error_pixels: u64,
    #[serde(with = "f32_or_inf")]
    pub max_error_px: f32,
    #[serde(with = "f32_or_inf")]
    pub p99_error_px: f32,
    #[serde(with = "f64_or_inf")]
    pub mean_error_px: f64,
    /// Share of the error pixels above 1 px.
    pub above_1px: f64,
    pub crack_pixels: u64,
    pub views_with_cracks: u64,
    /// Mean over views of the per-view mean FLIP.
    pub mean_flip: f32,
    /// The largest per-view mean FLIP.
    pub max_flip: f32,
    /// Mean over views of the coverage share.
    pub coverage: f64,
    pub min_coverage: f64,
    /// PSNR (dB) of the mean RGB MSE over the views; `+∞` (JSON `null`) if all are identical.
    #[serde(with = "f64_or_inf")]
    pub psnr: f64,
    /// Mean SSIM over views.
    pub ssim: f64,
    pub min_ssim: f64,
    /// Pixel error histogram, 0–4 px in 0.05 px bins.
    pub histogram: Histogram,
    /// The largest silhouette distance of any view (px).
    #[serde(default, with = "f32_or_inf")]
    pub silhouette_max_px: f32,
    /// The largest per-view p99 of the silhouette distances (px): every view's silhouettes are
    /// within it but for 1 % of their pixels.
    #[serde(default, with = "f32_or_inf")]
    pub silhouette_p99_px: f32,
    /// Mean silhouette distance over the silhouette pixels of all views (px).
    #[serde(default, with = "f64_or_inf")]
    pub silhouette_mean_px: f64,
    /// The largest coverage displacement of any view (px): the largest Hausdorff distance between
    /// the reference's and the impostor's coverage.
    #[serde(default, with = "f32_or_inf")]
    pub displacement_max_px: f32,
    /// The largest per-view p99 of the coverage displacement (px).
    #[serde(default, with = "f32_or_inf")]
    pub displacement_p99_px: f32,
    /// The p99 of the silhouette distances of all views pooled (px): all silhouette pixels of
    /// the cell or bundle are within it but for 1 %. 0 where the evaluation did not keep the
    /// distances ([`CellResult::with_outline_stats`]).
    #[serde(default, with = "f32_or_inf")]
    pub silhouette_pooled_p99_px: f32,
    /// The p99 of the coverage displacement of all views pooled (px).
    #[serde(default, with = "f32_or_inf")]
    pub displacement_pooled_p99_px: f32,
    /// The largest silhouette distance of the geometry against itself turned by a fraction of a
    /// pixel in any view ([`ViewResult::silhouette_floor`]); `None` where not asked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub silhouette_floor_max_px: Option<f32>,
    /// Views whose silhouette distance maximum exceeds that of the geometry turned by a fraction
    /// of a pixel (of the views that measured it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub views_above_silhouette_floor: Option<u64>,
    /// Pixels the impostor covers where the reference shows background, over all views.
    #[serde(default)]
    pub false_coverage_pixels: u64,
    /// `false_coverage_pixels` over all evaluated pixels (0 without views).
    #[serde(default)]
    pub false_coverage: f64,
}

impl Aggregate {
    /// Totals of `views`, whose pixel errors `stats` holds (merged).
    pub fn of<'a>(
        views: impl IntoIterator<Item = &'a ViewResult>,
        stats: &PixelErrorStats,
    ) -> Aggregate {
        let mut a = Aggregate {
            views: 0,
            error_pixels: stats.count(),
            max_error_px: stats.max(),
            p99_error_px: stats.p99(),
            mean_error_px: stats.mean(),
            above_1px: stats.share_above_1px(),
            crack_pixels: 0,
            views_with_cracks: 0,
            mean_flip: 0.0,
            max_flip: 0.0,
            coverage: 1.0,
            min_coverage: 1.0,
            psnr: f64::INFINITY,
            ssim: 1.0,
            min_ssim: 1.0,
            histogram: stats.histogram(),
            silhouette_max_px: 0.0,
            silhouette_p99_px: 0.0,
            silhouette_mean_px: 0.0,
            displacement_max_px: 0.0,
            displacement_p99_px: 0.0,
            silhouette_pooled_p99_px: 0.0,
            displacement_pooled_p99_px: 0.0,
            false_coverage_pixels: 0,
            false_coverage: 0.0,
            silhouette_floor_max_px: None,
            views_above_silhouette_floor: None,
        };
        let (mut flip, mut coverage, mut mse, mut ssim) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let (mut outline_sum, mut outline_count, mut pixels) = (0.0f64, 0u64, 0.0f64);
        for v in views {
            let s = &v.silhouette;
            a.silhouette_max_px = a.silhouette_max_px.max(s.max);
            a.silhouette_p99_px = a.silhouette_p99_px.max(s.p99);
            outline_sum += s.mean * s.count as f64;
            outline_count += s.count;
            a.displacement_max_px = a.displacement_max_px.max(v.displacement.max);
            a.displacement_p99_px = a.displacement_p99_px.max(v.displacement.p99);
            a.false_coverage_pixels += v.false_coverage_pixels;
            if let Some(floor) = &v.silhouette_floor {
                let m = a.silhouette_floor_max_px.get_or_insert(0.0);
                *m = m.max(floor.max);
                *a.views_above_silhouette_floor.get_or_insert(0) += u64::from(s.max > floor.max);
            }
            pixels += v.pixels as f64;
            a.views += 1;
            a.crack_pixels += v.crack_pixels;
            a.views_with_cracks += (v.crack_pixels > 0) as u64;
            flip += v.mean_flip as f64;
            a.max_flip = a.max_flip.max(v.mean_flip);
            coverage += v.coverage;
            a.min_coverage = a.min_coverage.min(v.coverage);
            mse += mse_from_psnr(v.psnr);
            ssim += v.ssim;
            a.min_ssim = a.min_ssim.min(v.ssim);
        }
        if a.views > 0 {
            let n = a.views as f64;
            a.mean_flip = (flip / n) as f32;
            a.coverage = coverage / n;
            a.psnr = psnr_from_mse(mse / n);
            a.ssim = ssim / n;
        }
        if outline_count > 0 {
            a.silhouette_mean_px = outline_sum / outline_count as f64;
        }
        if pixels > 0.0 {
            a.false_coverage = a.false_coverage_pixels as f64 / pixels;
        }
        a
    }

    /// Sets the pooled p99s from the merged outline statistics.
    fn set_pooled(&mut self, o: &OutlineStats) {
        self.silhouette_pooled_p99_px = o.silhouette.p99();
        self.displacement_pooled_p99_px = o.displacement.p99();
    }
}

/// The merged per-pixel outline statistics of a cell or bundle: the silhouette distances and the
/// coverage displacement of all its views ([`crate::SilhouetteStats`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OutlineStats {
    pub silhouette: PixelErrorStats,
    pub displacement: PixelErrorStats,
}

impl OutlineStats {
    /// Adds another set (exactly, see [`PixelErrorStats::merge`]).
    pub fn merge(&mut self, other: &OutlineStats) {
        self.silhouette.merge(&other.silhouette);
        self.displacement.merge(&other.displacement);
    }
}

/// The results of one view cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellResult {
    pub cell: String,
    #[serde(flatten)]
    pub summary: Aggregate,
    /// The [`WORST_PER_CELL`] worst views ([`severity_cmp`]).
    pub worst_views: Vec<ViewResult>,
    /// Every view, in evaluation order.
    pub view_results: Vec<ViewResult>,
    /// The merged pixel-error statistics (not serialised: the JSON has the summary and histogram).
    #[serde(skip)]
    stats: PixelErrorStats,
    /// The merged outline statistics (not serialised: the JSON has their pooled p99s).
    #[serde(skip)]
    outlines: OutlineStats,
}

impl CellResult {
    /// A cell's results from its views and their merged pixel-error statistics.
    pub fn new(
        cell: impl Into<String>,
        view_results: Vec<ViewResult>,
        stats: PixelErrorStats,
    ) -> CellResult {
        CellResult {
            cell: cell.into(),
            summary: Aggregate::of(&view_results, &stats),
            worst_views: worst_of(view_results.iter(), WORST_PER_CELL),
            view_results,
            stats,
            outlines: OutlineStats::default(),
        }
    }

    /// The same with the merged outline statistics of its views, whose pooled p99s the summary
    /// then reports.
    pub fn with_outline_stats(mut self, outlines: OutlineStats) -> CellResult {
        self.summary.set_pooled(&outlines);
        self.outlines = outlines;
        self
    }

    /// The merged pixel-error statistics of the cell (empty after deserialisation).
    pub fn error_stats(&self) -> &PixelErrorStats {
        &self.stats
    }
}

/// The results of a whole bundle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BundleResult {
    #[serde(flatten)]
    pub summary: Aggregate,
    pub cells: Vec<CellResult>,
    /// The [`WORST_PER_BUNDLE`] worst views over all cells.
    pub worst_views: Vec<ViewResult>,
    /// Free-form settings shown in the report (bundle path, output size, fov, ppd, …).
    #[serde(default)]
    pub info: BTreeMap<String, String>,
    #[serde(skip)]
    stats: PixelErrorStats,
}

impl BundleResult {
    /// The bundle's results from its cells (their statistics are merged).
    pub fn new(cells: Vec<CellResult>) -> BundleResult {
        let mut stats = PixelErrorStats::new();
        let mut outlines = OutlineStats::default();
        for c in &cells {
            stats.merge(&c.stats);
            outlines.merge(&c.outlines);
        }
        let views = || cells.iter().flat_map(|c| c.view_results.iter());
        let mut summary = Aggregate::of(views(), &stats);
        summary.set_pooled(&outlines);
        BundleResult {
            summary,
            worst_views: worst_of(views(), WORST_PER_BUNDLE),
            cells,
            info: BTreeMap::new(),
            stats,
        }
    }

    /// Adds a line to [`Self::info`].
    pub fn with_info(mut self, key: impl Into<String>, value: impl Into<String>) -> BundleResult {
        self.info.insert(key.into(), value.into());
        self
    }

    /// The merged pixel-error statistics of the bundle (empty after deserialisation).
    pub fn error_stats(&self) -> &PixelErrorStats {
        &self.stats
    }
}

fn fmt_num(v: f64, decimals: usize) -> String {
    if v.is_nan() {
        "n/a".into()
    } else if v.is_infinite() {
        if v > 0.0 { "∞" } else { "-∞" }.into()
    } else {
        format!("{v:.decimals$}")
    }
}

/// The one-line summary, e.g.
/// `max error 0.93 px (p99 0.41 px), 0 crack pixels, mean FLIP 0.031 over 540 views`.
pub fn verdict(result: &BundleResult) -> String {
    let s = &result.summary;
    let error = if s.error_pixels == 0 {
        "max error n/a (no pixel errors measured)".to_string()
    } else {
        format!(
            "max error {} px (p99 {} px)",
            fmt_num(s.max_error_px as f64, 2),
            fmt_num(s.p99_error_px as f64, 2)
        )
    };
    format!(
        "{error}, {} crack pixels, mean FLIP {:.3} over {} views",
        s.crack_pixels, s.mean_flip, s.views
    )
}

/// A view shown with images in the report: reference | impostor | FLIP heat map.
#[derive(Clone, Debug)]
pub struct WorstView {
    pub label: String,
    pub reference: Frame,
    pub impostor: Frame,
    /// RGBA8, same size as the frames ([`crate::FlipResult::heatmap_rgba`]).
    pub flip_heatmap: Vec<u8>,
}

/// Keeps the `capacity` worst views ([`severity_cmp`]) seen so far with their images, building a
/// [`WorstView`] only for views it keeps, so an evaluation holds at most `capacity` frame triples.
pub struct WorstSet {
    capacity: usize,
    entries: Vec<(ViewResult, WorstView)>,
}

impl WorstSet {
    pub fn new(capacity: usize) -> WorstSet {
        WorstSet {
            capacity,
            entries: Vec::new(),
        }
    }

    /// Whether [`Self::offer`] would keep `view`.
    pub fn would_keep(&self, view: &ViewResult) -> bool {
        self.capacity > 0
            && (self.entries.len() < self.capacity
                || self
                    .entries
                    .last()
                    .is_some_and(|(w, _)| severity_cmp(view, w) == Ordering::Less))
    }

    /// Keeps `view` (building its images with `make`) if it is among the worst; returns whether it
    /// was kept. Ties keep the earlier view.
    pub fn offer(&mut self, view: &ViewResult, make: impl FnOnce() -> WorstView) -> bool {
        if !self.would_keep(view) {
            return false;
        }
        let at = self
            .entries
            .partition_point(|(w, _)| severity_cmp(w, view) != Ordering::Greater);
        self.entries.insert(at, (view.clone(), make()));
        self.entries.truncate(self.capacity);
        true
    }

    /// Adds the entries of `other` (e.g. from another thread).
    pub fn merge(&mut self, other: WorstSet) {
        for (v, w) in other.entries {
            self.offer(&v, || w);
        }
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The kept views, worst first.
    pub fn views(&self) -> impl Iterator<Item = &ViewResult> {
        self.entries.iter().map(|(v, _)| v)
    }

    /// The kept images, worst first.
    pub fn into_worst_views(self) -> Vec<WorstView> {
        self.entries.into_iter().map(|(_, w)| w).collect()
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), EvalError> {
    lemi_core::container::write_atomic(path, bytes)
        .map_err(|e| EvalError::io(format!("writing {}", path.display()), e))
}

/// Gap between the three panels of a worst-view PNG, in pixels.
const PANEL_GAP: u32 = 4;

/// reference | impostor | heat map as one RGB8 PNG (alpha dropped: background shows its clear
/// colour), panels separated by a grey gap. `None` for 0-pixel frames.
fn worst_view_png(w: &WorstView) -> Result<Option<Vec<u8>>, EvalError> {
    use image::ImageEncoder as _;
    let r = &w.reference;
    let i = &w.impostor;
    if (r.width, r.height) != (i.width, i.height) {
        return Err(EvalError::SizeMismatch {
            what_a: "worst-view reference",
            a_width: r.width,
            a_height: r.height,
            what_b: "worst-view impostor",
            b_width: i.width,
            b_height: i.height,
        });
    }
    let n = check_frame(r, "worst-view reference")?;
    check_frame(i, "worst-view impostor")?;
    if w.flip_heatmap.len() != 4 * n {
        return Err(EvalError::BufferLength {
            what: "worst-view FLIP heat map",
            width: r.width,
            height: r.height,
            expected: 4 * n,
            actual: w.flip_heatmap.len(),
            unit: "RGBA bytes",
        });
    }
    if n == 0 {
        return Ok(None);
    }
    let (fw, fh) = (r.width as usize, r.height as usize);
    let gap = PANEL_GAP as usize;
    let out_w = 3 * fw + 2 * gap;
    let mut rgb = vec![128u8; out_w * fh * 3];
    for (panel, src) in [&r.rgba, &i.rgba, &w.flip_heatmap].into_iter().enumerate() {
        let x0 = panel * (fw + gap);
        for y in 0..fh {
            for x in 0..fw {
                let s = 4 * (y * fw + x);
                let d = 3 * (y * out_w + x0 + x);
                rgb[d..d + 3].copy_from_slice(&src[s..s + 3]);
            }
        }
    }
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(
            &rgb,
            out_w as u32,
            fh as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| EvalError::Encode {
            what: format!("the PNG of {}", w.label),
            message: e.to_string(),
        })?;
    Ok(Some(png))
}

/// Writes `report.json`, one `worst-NN.png` per entry of `worst` (reference | impostor | FLIP heat
/// map) and `index.html` into `dir` (created if missing), each atomically; returns the path of
/// `index.html`. The HTML references only those files, by relative name.
pub fn write_report(
    dir: &Path,
    result: &BundleResult,
    worst: &[WorstView],
) -> Result<PathBuf, EvalError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| EvalError::io(format!("creating {}", dir.display()), e))?;
    let json = serde_json::to_vec_pretty(result).map_err(|e| EvalError::Encode {
        what: "report.json".into(),
        message: e.to_string(),
    })?;
    write_file(&dir.join("report.json"), &json)?;

    let mut figures = Vec::with_capacity(worst.len());
    for (k, w) in worst.iter().enumerate() {
        let file = match worst_view_png(w)? {
            Some(png) => {
                let name = format!("worst-{k:02}.png");
                write_file(&dir.join(&name), &png)?;
                Some(name)
            }
            None => None,
        };
        figures.push(html::Figure {
            file,
            label: &w.label,
            width: w.reference.width,
            height: w.reference.height,
        });
    }
    let page = html::index_html(result, &figures)?;
    let index = dir.join("index.html");
    write_file(&index, page.as_bytes())?;
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(cell: &str, name: &str, cracks: u64, max: f32, flip: f32) -> ViewResult {
        ViewResult {
            cell: cell.into(),
            viewpoint: name.into(),
            eye: [0.0; 3],
            dir: [1.0, 0.0, 0.0],
            error: ErrorSummary {
                count: 1,
                max,
                p99: max,
                mean: max as f64,
                above_1px: 0.0,
            },
            crack_pixels: cracks,
            crack_samples: Vec::new(),
            mean_flip: flip,
            psnr: 30.0,
            ssim: 0.9,
            coverage: 1.0,
            silhouette: ErrorSummary::default(),
            displacement: ErrorSummary::default(),
            false_coverage_pixels: 0,
            pixels: 1,
            silhouette_floor: None,
        }
    }

    fn dummy(label: &str) -> WorstView {
        let f = Frame {
            width: 1,
            height: 1,
            rgba: vec![0; 4],
            depth: vec![1.0],
        };
        WorstView {
            label: label.into(),
            reference: f.clone(),
            impostor: f,
            flip_heatmap: vec![0; 4],
        }
    }

    #[test]
    fn severity_orders_cracks_then_error_then_flip() {
        let a = view("c", "a", 1, 0.1, 0.0);
        let b = view("c", "b", 0, 5.0, 0.9);
        let c = view("c", "c", 0, 5.0, 0.1);
        let mut v = [c.clone(), b.clone(), a.clone()];
        v.sort_by(severity_cmp);
        assert_eq!(v.map(|x| x.viewpoint), ["a", "b", "c"].map(String::from));
    }

    #[test]
    fn worst_set_keeps_the_worst_and_builds_only_kept() {
        let mut set = WorstSet::new(2);
        let mut built = 0;
        for (i, max) in [0.1f32, 0.5, 0.3, 0.05, 0.9].into_iter().enumerate() {
            let v = view("c", &format!("v{i}"), 0, max, 0.0);
            set.offer(&v, || {
                built += 1;
                dummy(&v.viewpoint)
            });
        }
        // v0, v1 built (filling), v2 (0.3 > 0.1) built, v3 rejected, v4 built.
        assert_eq!(built, 4);
        let labels: Vec<_> = set
            .into_worst_views()
            .into_iter()
            .map(|w| w.label)
            .collect();
        assert_eq!(labels, ["v4", "v1"]);
    }

    /// The floor's maximum is the largest of the views that measured it, and a view counts as
    /// above it only when its own silhouette maximum is larger; without any, both stay `None`,
    /// and the report's table shows the floor beside the maximum.
    #[test]
    fn the_silhouette_floor_aggregates_over_the_views_that_measured_it() {
        let with = |own: f32, floor: Option<f32>| {
            let mut v = view("c", "v", 0, 0.1, 0.0);
            v.silhouette.max = own;
            v.silhouette_floor = floor.map(|max| ErrorSummary {
                max,
                ..Default::default()
            });
            v
        };
        let views = [
            with(3.0, Some(1.4)),
            with(2.0, Some(40.0)),
            with(5.0, None),
            with(1.0, Some(1.0)),
        ];
        let a = Aggregate::of(&views, &PixelErrorStats::new());
        assert_eq!(a.silhouette_floor_max_px, Some(40.0));
        assert_eq!(a.views_above_silhouette_floor, Some(1));
        assert_eq!(a.silhouette_max_px, 5.0);
        let none = Aggregate::of(&views[2..3], &PixelErrorStats::new());
        assert_eq!(none.silhouette_floor_max_px, None);
        assert_eq!(none.views_above_silhouette_floor, None);
        let cell = CellResult::new("c", views.to_vec(), PixelErrorStats::new());
        let page = html::index_html(&BundleResult::new(vec![cell]), &[]).expect("html");
        assert!(page.contains("5.00 (the geometry's own: 40.00)"), "{page}");
    }

    #[test]
    fn aggregate_pools_psnr_by_mse() {
        let mut a = view("c", "a", 0, 0.1, 0.0);
        a.psnr = f64::INFINITY;
        let mut b = a.clone();
        b.psnr = psnr_from_mse(2.0);
        let agg = Aggregate::of([&a, &b], &PixelErrorStats::new());
        assert!((agg.psnr - psnr_from_mse(1.0)).abs() < 1e-9);
    }
}
