//! The static `index.html` of the eval report: a `maud` template (checked at compile time, every
//! interpolated string HTML-escaped: cell ids, viewpoint labels, info keys and values such as
//! scene names), inline CSS, and the pixel-error histograms drawn with `plotters` as inline SVG.
//! The page references nothing but the files beside it (`report.json`, `worst-NN.png`).

use maud::{html, Markup, PreEscaped, DOCTYPE};

use super::{fmt_num, verdict, Aggregate, BundleResult, ViewResult};
use crate::stats::Histogram;
use crate::EvalError;

/// One worst view of the page: its image file (`None` for an empty frame), label and size.
pub(super) struct Figure<'a> {
    pub(super) file: Option<String>,
    pub(super) label: &'a str,
    pub(super) width: u32,
    pub(super) height: u32,
}

const CSS: &str = "body{font-family:system-ui,sans-serif;margin:1.5em;color:#222}\
h1{font-size:1.4em}h2{font-size:1.15em;margin-top:1.6em}\
.verdict{font-size:1.15em;font-weight:600;padding:.6em .8em;background:#eef3fb;border-left:4px solid #36a}\
.verdict.bad{background:#fbeeee;border-color:#b22}\
table{border-collapse:collapse;font-size:.9em}td,th{border:1px solid #ccc;padding:.2em .5em;text-align:right}\
th{background:#f4f4f4}td.l,th.l{text-align:left}tr.bad td{background:#fdecec}\
figure{margin:1em 0}figure img{max-width:100%;image-rendering:pixelated;border:1px solid #ccc}\
.cellhist{display:inline-block;margin:.3em}.note{color:#666;font-size:.85em}";

/// Whether a row is marked bad: cracks, or an error above one pixel.
fn is_bad(a: &Aggregate) -> bool {
    a.crack_pixels > 0 || a.max_error_px > 1.0
}

fn bad_class(bad: bool) -> Option<&'static str> {
    bad.then_some("bad")
}

fn aggregate_header() -> Markup {
    html! {
        th { "views" } th { "max px" } th { "p99 px" } th { "mean px" } th { ">1 px %" }
        th { "crack px" } th { "views w/ cracks" } th { "mean FLIP" } th { "max FLIP" }
        th { "coverage" } th { "min cov." } th { "PSNR dB" } th { "SSIM" }
        th { "silhouette max px (with --silhouette-floor: the geometry's own, turned)" } th { "silhouette p99 px (all / worst view)" }
        th { "displacement max px" } th { "displacement p99 px (all / worst view)" }
        th { "false cov. %" }
    }
}

fn aggregate_cells(a: &Aggregate) -> Markup {
    html! {
        td { (a.views) }
        td { (fmt_num(a.max_error_px as f64, 3)) }
        td { (fmt_num(a.p99_error_px as f64, 3)) }
        td { (fmt_num(a.mean_error_px, 3)) }
        td { (fmt_num(100.0 * a.above_1px, 3)) }
        td { (a.crack_pixels) }
        td { (a.views_with_cracks) }
        td { (fmt_num(a.mean_flip as f64, 4)) }
        td { (fmt_num(a.max_flip as f64, 4)) }
        td { (fmt_num(a.coverage, 4)) }
        td { (fmt_num(a.min_coverage, 4)) }
        td { (fmt_num(a.psnr, 2)) }
        td { (fmt_num(a.ssim, 4)) }
        td {
            (fmt_num(a.silhouette_max_px as f64, 2))
            @if let Some(floor) = a.silhouette_floor_max_px {
                " (the geometry's own: " (fmt_num(floor as f64, 2)) ")"
            }
        }
        td { (fmt_num(a.silhouette_pooled_p99_px as f64, 2)) " / " (fmt_num(a.silhouette_p99_px as f64, 2)) }
        td { (fmt_num(a.displacement_max_px as f64, 2)) }
        td { (fmt_num(a.displacement_pooled_p99_px as f64, 2)) " / " (fmt_num(a.displacement_p99_px as f64, 2)) }
        td { (fmt_num(100.0 * a.false_coverage, 3)) }
    }
}

fn views_table(views: &[ViewResult]) -> Markup {
    let v3 = |v: &[f64; 3]| format!("{:.3}, {:.3}, {:.3}", v[0], v[1], v[2]);
    html! {
        table {
            tr {
                th.l { "cell" } th.l { "viewpoint" } th.l { "eye" } th.l { "dir" }
                th { "max px" } th { "p99 px" } th { "mean px" } th { "crack px" } th { "FLIP" }
                th { "PSNR dB" } th { "SSIM" } th { "coverage" }
            }
            @for v in views {
                tr class=[bad_class(v.crack_pixels > 0 || v.error.max > 1.0)] {
                    td.l { (v.cell) }
                    td.l { (v.viewpoint) }
                    td.l { (v3(&v.eye)) }
                    td.l { (v3(&v.dir)) }
                    td { (fmt_num(v.error.max as f64, 3)) }
                    td { (fmt_num(v.error.p99 as f64, 3)) }
                    td { (fmt_num(v.error.mean, 3)) }
                    td { (v.crack_pixels) (crack_places(v)) }
                    td { (fmt_num(v.mean_flip as f64, 4)) }
                    td { (fmt_num(v.psnr, 2)) }
                    td { (fmt_num(v.ssim, 4)) }
                    td { (fmt_num(v.coverage, 4)) }
                }
            }
        }
    }
}

/// Where a view's first crack pixels are, e.g. ` at (576, 353), (576, 354), …`; empty without.
fn crack_places(v: &ViewResult) -> String {
    const SHOWN: usize = 3;
    if v.crack_samples.is_empty() {
        return String::new();
    }
    let places: Vec<String> = v
        .crack_samples
        .iter()
        .take(SHOWN)
        .map(|[x, y]| format!("({x}, {y})"))
        .collect();
    let more = v.crack_pixels > places.len() as u64;
    format!(" at {}{}", places.join(", "), if more { ", …" } else { "" })
}

/// An SVG bar chart of `h`, `width × height` pixels, drawn with `plotters`: counts on a log axis,
/// bars below 1 px blue, from 1 px orange, the overflow bar (≥ the histogram's range) red, the
/// 1 px threshold dashed. Text goes through the SVG backend, which escapes it.
pub(super) fn histogram_svg(
    h: &Histogram,
    title: &str,
    width: u32,
    height: u32,
) -> Result<String, EvalError> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Debug| EvalError::Encode {
        what: format!("the histogram `{title}`"),
        message: format!("{e:?}"),
    };
    let bin = h.bin_width_px as f64;
    let bin = if bin.is_finite() && bin > 0.0 {
        bin
    } else {
        1.0
    };
    let range = h.counts.len() as f64 * bin;
    let x_max = range + bin; // + the overflow bar
    let top = h
        .counts
        .iter()
        .chain(std::iter::once(&h.overflow))
        .copied()
        .max()
        .unwrap_or(0)
        .max(1) as f64;
    let (y0, y1) = (0.8, 1.6 * top);
    let small = width < 500;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{title} (log count, total {})", h.total()),
                ("sans-serif", if small { 11 } else { 13 }),
            )
            .margin(4)
            .x_label_area_size(16)
            .y_label_area_size(if small { 30 } else { 40 })
            .build_cartesian_2d(0.0..x_max, (y0..y1).log_scale())
            .map_err(|e| err(&e))?;
        // the overflow bar starts at the range: its tick reads "≥ range" (as an f32, `≥4`)
        let x_label = |v: &f64| {
            if (v - range).abs() < 1e-6 * range.max(1.0) {
                format!("≥{}", h.range_px())
            } else {
                format!("{v}")
            }
        };
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(range.ceil() as usize + 1)
            .x_label_formatter(&x_label)
            .y_labels(3)
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(("sans-serif", 10))
            .draw()
            .map_err(|e| err(&e))?;
        let bars = h
            .counts
            .iter()
            .chain(std::iter::once(&h.overflow))
            .enumerate()
            .filter(|&(_, &c)| c > 0)
            .map(|(k, &c)| {
                let lo = k as f64 * bin;
                let colour = if k == h.counts.len() {
                    RGBColor(0xbb, 0x22, 0x22)
                } else if lo >= 1.0 {
                    RGBColor(0xdd, 0x77, 0x33)
                } else {
                    RGBColor(0x33, 0x66, 0xaa)
                };
                Rectangle::new([(lo, y0), (lo + 0.9 * bin, c as f64)], colour.filled())
            });
        chart.draw_series(bars).map_err(|e| err(&e))?;
        if range > 1.0 {
            chart
                .draw_series(DashedLineSeries::new(
                    [(1.0, y0), (1.0, y1)],
                    3,
                    2,
                    RGBColor(0xcc, 0, 0).into(),
                ))
                .map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    Ok(svg)
}

/// The whole page.
pub(super) fn index_html(result: &BundleResult, figures: &[Figure]) -> Result<String, EvalError> {
    let s = &result.summary;
    let bundle_histogram = histogram_svg(&s.histogram, "pixel error, bundle", 720, 220)?;
    let cell_histograms = result
        .cells
        .iter()
        .map(|c| histogram_svg(&c.summary.histogram, &c.cell, 360, 130))
        .collect::<Result<Vec<_>, _>>()?;
    let page = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { "lemi eval report" }
                style { (PreEscaped(CSS)) }
            }
            body {
                h1 { "lemi eval report" }
                p.verdict.bad[is_bad(s)] id="verdict" { (verdict(result)) }
                @if !result.info.is_empty() {
                    table {
                        @for (k, v) in &result.info {
                            tr { th.l { (k) } td.l { (v) } }
                        }
                    }
                }
                h2 { "Bundle" }
                table {
                    tr { th.l { "scope" } (aggregate_header()) }
                    tr class=[bad_class(is_bad(s))] {
                        td.l { "bundle (" (result.cells.len()) " cells)" }
                        (aggregate_cells(s))
                    }
                }
                h2 { "Pixel error, bundle" }
                (PreEscaped(bundle_histogram))
                p.note {
                    "Geometric error per pixel in output pixels, 0.05 px bins, last bar ≥ "
                    (s.histogram.range_px())
                    " px; dashed line: 1 px. p99 is an upper bound, at most 1/320 px above the exact value (below 8 px)."
                }
                h2 { "Cells" }
                table id="cells" {
                    tr { th.l { "cell" } (aggregate_header()) }
                    @for (k, c) in result.cells.iter().enumerate() {
                        tr id=(format!("cell-{k}")) class=[bad_class(is_bad(&c.summary))] {
                            td.l { (c.cell) }
                            (aggregate_cells(&c.summary))
                        }
                    }
                }
                @if !result.worst_views.is_empty() {
                    h2 { "Worst views" }
                    p.note { "Ordered by crack pixels, then max error, then p99, then FLIP." }
                    (views_table(&result.worst_views))
                }
                @if !figures.is_empty() {
                    h2 { "Worst views: images" }
                    @for f in figures {
                        @if let Some(file) = &f.file {
                            figure {
                                img src=(file) alt={ (f.label) ": reference, impostor, FLIP" } loading="lazy";
                                figcaption {
                                    (f.label) " — reference | impostor | FLIP heat map ("
                                    (f.width) "×" (f.height) ")"
                                }
                            }
                        } @else {
                            p { (f.label) " — empty frame" }
                        }
                    }
                }
                @if !result.cells.is_empty() {
                    h2 { "Pixel error per cell" }
                    details open {
                        summary { "histograms" }
                        @for svg in cell_histograms {
                            div.cellhist { (PreEscaped(svg)) }
                        }
                    }
                }
                p.note { "All numbers: " a href="report.json" { "report.json" } "." }
            }
        }
    };
    let mut out = page.into_string();
    out.push('\n');
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::PixelErrorStats;

    #[test]
    fn text_is_escaped() {
        let s = "<a&\"'>";
        assert_eq!(html! { (s) }.into_string(), "&lt;a&amp;&quot;'&gt;");
        assert_eq!(
            html! { td title=(s) {} }.into_string(),
            "<td title=\"&lt;a&amp;&quot;'&gt;\"></td>"
        );
    }

    #[test]
    fn histograms_are_svg_with_escaped_titles() {
        let stats = PixelErrorStats::from_values(&[0.1, 0.2, 0.2, 1.5, 9.0]);
        let svg = histogram_svg(&stats.histogram(), "cell <x&y>", 360, 130).expect("svg");
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(
            svg.contains("cell &lt;x&amp;y&gt; (log count, total 5)"),
            "{svg}"
        );
        assert!(!svg.contains("<x&y>"));
        // one bar per non-empty bin (3 bins + the overflow) over the white background
        assert!(svg.matches("<rect").count() >= 4);
        // an empty histogram still draws
        let empty = histogram_svg(&PixelErrorStats::new().histogram(), "empty", 360, 130);
        assert!(empty.expect("svg").contains("total 0"));
    }
}
