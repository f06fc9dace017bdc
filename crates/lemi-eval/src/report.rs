//! The eval report: the data model ([`ViewResult`] → [`CellResult`] → [`BundleResult`], sharing the
//! [`Aggregate`] totals), the one-line [`verdict`], the bounded [`WorstSet`] of views to show, and
//! [`write_report`], which writes `report.json` (serde) and a static, self-contained `index.html`:
//! inline CSS and inline SVG histograms (hand-written, no plotting dependency), images as PNG files
//! beside it, no network access. Every file is written atomically
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
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use lemi_gpu::Frame;
use serde::{Deserialize, Serialize};

use crate::image_metrics::{check_frame, mse_from_psnr, psnr_from_mse};
use crate::stats::{Histogram, PixelErrorStats};
use crate::EvalError;

/// How many worst views a [`CellResult`] lists.
pub const WORST_PER_CELL: usize = 3;
/// How many worst views a [`BundleResult`] lists.
pub const WORST_PER_BUNDLE: usize = 10;

/// `null` for non-finite numbers in JSON, read back as `+∞`.
mod f64_or_inf {
    use serde::{Deserialize, Deserializer, Serializer};
    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else {
            s.serialize_none()
        }
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

/// As [`f64_or_inf`], for `f32`.
mod f32_or_inf {
    use serde::{Deserialize, Deserializer, Serializer};
    pub fn serialize<S: Serializer>(v: &f32, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f32(*v)
        } else {
            s.serialize_none()
        }
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
        Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::INFINITY))
    }
}

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
    pub mean_flip: f32,
    /// dB over RGB; `+∞` (JSON `null`) for identical images.
    #[serde(with = "f64_or_inf")]
    pub psnr: f64,
    pub ssim: f64,
    /// Share of the reference's covered pixels the impostor covers ([`crate::Coverage::share`]).
    pub coverage: f64,
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
        };
        let (mut flip, mut coverage, mut mse, mut ssim) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for v in views {
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
        a
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
        }
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
        for c in &cells {
            stats.merge(&c.stats);
        }
        let views = || cells.iter().flat_map(|c| c.view_results.iter());
        BundleResult {
            summary: Aggregate::of(views(), &stats),
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

fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// An inline SVG bar chart of `h` (log-scaled counts), with the 1 px threshold marked.
fn histogram_svg(h: &Histogram, title: &str, width: u32, height: u32) -> String {
    let (ml, mr, mt, mb) = (8.0, 8.0, 18.0, 18.0);
    let (w, hh) = (width as f64, height as f64);
    let plot_w = w - ml - mr;
    let plot_h = hh - mt - mb;
    let bars = h.counts.len() + 1; // + overflow
    let bw = plot_w / bars as f64;
    let scale = |c: u64| (1.0 + c as f64).log10();
    let top = h
        .counts
        .iter()
        .chain(std::iter::once(&h.overflow))
        .map(|&c| scale(c))
        .fold(0.0f64, f64::max)
        .max(1e-9);
    let mut s = String::new();
    let _ = write!(
        s,
        r##"<svg xmlns="http://www.w3.org/2000/svg" class="hist" width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img"><title>{t}</title><rect x="0" y="0" width="{width}" height="{height}" fill="#fff"/><text x="{ml}" y="12" font-size="11">{t} (log count, total {total})</text>"##,
        t = esc(title),
        total = h.total()
    );
    for (k, &c) in h
        .counts
        .iter()
        .chain(std::iter::once(&h.overflow))
        .enumerate()
    {
        if c == 0 {
            continue;
        }
        let bh = plot_h * scale(c) / top;
        let x = ml + k as f64 * bw;
        let y = mt + plot_h - bh;
        let lo = k as f32 * h.bin_width_px;
        let fill = if k == h.counts.len() {
            "#b22"
        } else if lo >= 1.0 {
            "#d73"
        } else {
            "#36a"
        };
        let tip = if k == h.counts.len() {
            format!("≥ {:.2} px: {c}", h.range_px())
        } else {
            format!("{:.2}–{:.2} px: {c}", lo, lo + h.bin_width_px)
        };
        let _ = write!(
            s,
            r#"<rect x="{x:.1}" y="{y:.1}" width="{:.1}" height="{bh:.1}" fill="{fill}"><title>{tip}</title></rect>"#,
            (bw - 0.5).max(0.5)
        );
    }
    // 1 px line and axis labels.
    let px_to_x = |px: f32| ml + (px / h.bin_width_px) as f64 * bw;
    let base = mt + plot_h;
    let _ = write!(
        s,
        r##"<line x1="{ml}" y1="{base:.1}" x2="{:.1}" y2="{base:.1}" stroke="#333"/>"##,
        ml + plot_w
    );
    if h.range_px() > 1.0 {
        let x1 = px_to_x(1.0);
        let _ = write!(
            s,
            r##"<line x1="{x1:.1}" y1="{mt}" x2="{x1:.1}" y2="{base:.1}" stroke="#c00" stroke-dasharray="3,2"/>"##
        );
    }
    let mut px = 0.0f32;
    while px < h.range_px() - 1e-3 {
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-size="10" text-anchor="{}">{px}</text>"#,
            px_to_x(px),
            hh - 5.0,
            if px == 0.0 { "start" } else { "middle" }
        );
        px += 1.0;
    }
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" font-size="10" text-anchor="end">≥{}</text></svg>"#,
        w - 2.0,
        hh - 5.0,
        h.range_px()
    );
    s
}

const CSS: &str = "body{font-family:system-ui,sans-serif;margin:1.5em;color:#222}\
h1{font-size:1.4em}h2{font-size:1.15em;margin-top:1.6em}\
.verdict{font-size:1.15em;font-weight:600;padding:.6em .8em;background:#eef3fb;border-left:4px solid #36a}\
.verdict.bad{background:#fbeeee;border-color:#b22}\
table{border-collapse:collapse;font-size:.9em}td,th{border:1px solid #ccc;padding:.2em .5em;text-align:right}\
th{background:#f4f4f4}td.l,th.l{text-align:left}tr.bad td{background:#fdecec}\
figure{margin:1em 0}figure img{max-width:100%;image-rendering:pixelated;border:1px solid #ccc}\
.cellhist{display:inline-block;margin:.3em}.note{color:#666;font-size:.85em}";

fn aggregate_cells(a: &Aggregate) -> String {
    format!(
        "<td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
        a.views,
        fmt_num(a.max_error_px as f64, 3),
        fmt_num(a.p99_error_px as f64, 3),
        fmt_num(a.mean_error_px, 3),
        fmt_num(100.0 * a.above_1px, 3),
        a.crack_pixels,
        a.views_with_cracks,
        fmt_num(a.mean_flip as f64, 4),
        fmt_num(a.max_flip as f64, 4),
        fmt_num(a.coverage, 4),
        fmt_num(a.min_coverage, 4),
        fmt_num(a.psnr, 2),
        fmt_num(a.ssim, 4),
    )
}

const AGGREGATE_HEADER: &str = "<th>views</th><th>max px</th><th>p99 px</th><th>mean px</th><th>&gt;1 px %</th><th>crack px</th><th>views w/ cracks</th><th>mean FLIP</th><th>max FLIP</th><th>coverage</th><th>min cov.</th><th>PSNR dB</th><th>SSIM</th>";

fn is_bad(a: &Aggregate) -> bool {
    a.crack_pixels > 0 || a.max_error_px > 1.0
}

fn views_table(views: &[ViewResult]) -> String {
    let mut s = String::from(
        "<table><tr><th class=\"l\">cell</th><th class=\"l\">viewpoint</th><th class=\"l\">eye</th><th class=\"l\">dir</th><th>max px</th><th>p99 px</th><th>mean px</th><th>crack px</th><th>FLIP</th><th>PSNR dB</th><th>SSIM</th><th>coverage</th></tr>",
    );
    let v3 = |v: &[f64; 3]| format!("{:.3}, {:.3}, {:.3}", v[0], v[1], v[2]);
    for v in views {
        let bad = v.crack_pixels > 0 || v.error.max > 1.0;
        let _ = write!(
            s,
            "<tr{}><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            if bad { " class=\"bad\"" } else { "" },
            esc(&v.cell),
            esc(&v.viewpoint),
            v3(&v.eye),
            v3(&v.dir),
            fmt_num(v.error.max as f64, 3),
            fmt_num(v.error.p99 as f64, 3),
            fmt_num(v.error.mean, 3),
            v.crack_pixels,
            fmt_num(v.mean_flip as f64, 4),
            fmt_num(v.psnr, 2),
            fmt_num(v.ssim, 4),
            fmt_num(v.coverage, 4),
        );
    }
    s.push_str("</table>");
    s
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

    let mut figures = String::new();
    for (k, w) in worst.iter().enumerate() {
        let name = format!("worst-{k:02}.png");
        match worst_view_png(w)? {
            Some(png) => {
                write_file(&dir.join(&name), &png)?;
                let _ = write!(
                    figures,
                    "<figure><img src=\"{name}\" alt=\"{l}: reference, impostor, FLIP\" loading=\"lazy\"><figcaption>{l} — reference | impostor | FLIP heat map ({}×{})</figcaption></figure>",
                    w.reference.width,
                    w.reference.height,
                    l = esc(&w.label),
                );
            }
            None => {
                let _ = write!(figures, "<p>{} — empty frame</p>", esc(&w.label));
            }
        }
    }

    let s = &result.summary;
    let mut html = String::new();
    let _ = write!(
        html,
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>lemi eval report</title><style>{CSS}</style></head><body><h1>lemi eval report</h1><p class=\"verdict{}\" id=\"verdict\">{}</p>",
        if is_bad(s) { " bad" } else { "" },
        esc(&verdict(result))
    );
    if !result.info.is_empty() {
        html.push_str("<table>");
        for (k, v) in &result.info {
            let _ = write!(
                html,
                "<tr><th class=\"l\">{}</th><td class=\"l\">{}</td></tr>",
                esc(k),
                esc(v)
            );
        }
        html.push_str("</table>");
    }
    let _ = write!(
        html,
        "<h2>Bundle</h2><table><tr><th class=\"l\">scope</th>{AGGREGATE_HEADER}</tr><tr{}><td class=\"l\">bundle ({} cells)</td>{}</tr></table>",
        if is_bad(s) { " class=\"bad\"" } else { "" },
        result.cells.len(),
        aggregate_cells(s)
    );
    let _ = write!(
        html,
        "<h2>Pixel error, bundle</h2>{}<p class=\"note\">Geometric error per pixel in output pixels, 0.05 px bins, last bar ≥ {} px; dashed line: 1 px. p99 is an upper bound, at most 1/320 px above the exact value (below 8 px).</p>",
        histogram_svg(&s.histogram, "pixel error, bundle", 720, 220),
        s.histogram.range_px()
    );
    let _ = write!(
        html,
        "<h2>Cells</h2><table id=\"cells\"><tr><th class=\"l\">cell</th>{AGGREGATE_HEADER}</tr>"
    );
    for (k, c) in result.cells.iter().enumerate() {
        let _ = write!(
            html,
            "<tr id=\"cell-{k}\"{}><td class=\"l\">{}</td>{}</tr>",
            if is_bad(&c.summary) {
                " class=\"bad\""
            } else {
                ""
            },
            esc(&c.cell),
            aggregate_cells(&c.summary)
        );
    }
    html.push_str("</table>");
    if !result.worst_views.is_empty() {
        let _ = write!(
            html,
            "<h2>Worst views</h2><p class=\"note\">Ordered by crack pixels, then max error, then p99, then FLIP.</p>{}",
            views_table(&result.worst_views)
        );
    }
    if !figures.is_empty() {
        let _ = write!(html, "<h2>Worst views: images</h2>{figures}");
    }
    if !result.cells.is_empty() {
        html.push_str("<h2>Pixel error per cell</h2><details open><summary>histograms</summary>");
        for c in &result.cells {
            let _ = write!(
                html,
                "<div class=\"cellhist\">{}</div>",
                histogram_svg(&c.summary.histogram, &c.cell, 360, 130)
            );
        }
        html.push_str("</details>");
    }
    html.push_str(
        "<p class=\"note\">All numbers: <a href=\"report.json\">report.json</a>.</p></body></html>\n",
    );
    let index = dir.join("index.html");
    write_file(&index, html.as_bytes())?;
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
            mean_flip: flip,
            psnr: 30.0,
            ssim: 0.9,
            coverage: 1.0,
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

    #[test]
    fn aggregate_pools_psnr_by_mse() {
        let mut a = view("c", "a", 0, 0.1, 0.0);
        a.psnr = f64::INFINITY;
        let mut b = a.clone();
        b.psnr = psnr_from_mse(2.0);
        let agg = Aggregate::of([&a, &b], &PixelErrorStats::new());
        assert!((agg.psnr - psnr_from_mse(1.0)).abs() < 1e-9);
    }

    #[test]
    fn html_escapes() {
        assert_eq!(esc("<a&\"'>"), "&lt;a&amp;&quot;&#39;&gt;");
    }
}
