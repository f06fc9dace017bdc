//! The PNG plot of a walk, after Jeschke & Wimmer, GI 2002, Figs. 8 and 9: the top
//! panel shows the frame rate of every frame (`1000 / cpu_ms`) of the impostor replay and of the
//! all-geometry replay of the same path, with a vertical line at every cell switch and a red dot
//! on every stalled frame (orange ticks under the frames that fell back to all geometry); the
//! bottom panel shows the primitives per frame (near triangles + impostor quads, the quads alone,
//! and the geometry replay's triangles) on a log scale.
//!
//! Lines and shapes are drawn with `plotters`' bitmap backend into a buffer that is encoded as
//! PNG with `image` and written atomically. `plotters` can only draw text into a bitmap with a
//! font library (`ttf`: font-kit and the system's fontconfig; `ab_glyph`: a font registered for
//! every backend, which would make the crate's SVG plots depend on one too), so the text is
//! rasterized here with `ab_glyph` from the system font [`crate::font::find_font`] finds
//! (DejaVu Sans and other common ones; `LEMI_PLOT_FONT` names another). Without a font the plot
//! is drawn without text, and [`PlotInfo::font`] says so.
//!
//! [`write_frame_times_svg`] draws several walks (one per far-field strategy) into one SVG: frame
//! time and primitives per frame.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use ab_glyph::{Font, FontVec, PxScale, ScaleFont};
use image::RgbImage;
use plotters::prelude::*;

use crate::font::{find_font, FontUse, LoadedFont};
use crate::record::{nearest_rank, FrameRecord, FrameStats};
use crate::WalkError;

/// Size and title of a plot.
#[derive(Clone, Debug, PartialEq)]
pub struct PlotOptions {
    pub width: u32,
    pub height: u32,
    pub title: String,
}

impl Default for PlotOptions {
    fn default() -> Self {
        PlotOptions {
            width: 1200,
            height: 800,
            title: "lemi walk".to_string(),
        }
    }
}

/// What a plot could do.
#[derive(Clone, Debug, PartialEq)]
pub struct PlotInfo {
    /// The font the text was drawn with; `None`: no font was found, the plot has no text.
    pub font: Option<PathBuf>,
}

/// The plot at the default size (1200 × 800) to `path`.
pub fn write_plot(
    path: &Path,
    impostor: &[FrameRecord],
    geometry: &[FrameRecord],
) -> Result<(), WalkError> {
    write_plot_with(path, impostor, geometry, &PlotOptions::default()).map(|_| ())
}

/// The plot with `opts` to `path` (PNG, written atomically).
pub fn write_plot_with(
    path: &Path,
    impostor: &[FrameRecord],
    geometry: &[FrameRecord],
    opts: &PlotOptions,
) -> Result<PlotInfo, WalkError> {
    let plot_err = |message: String| WalkError::Plot {
        path: path.to_path_buf(),
        message,
    };
    let (img, info) = render_plot(impostor, geometry, opts).map_err(plot_err)?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| plot_err(format!("encoding the PNG: {e}")))?;
    lemi_core::container::write_atomic(path, &png)
        .map_err(|e| WalkError::io("walk plot", path, e))?;
    Ok(info)
}

// Colours.
const IMPOSTOR: RGBColor = RGBColor(31, 119, 180);
const QUADS: RGBColor = RGBColor(44, 160, 44);
const GEOMETRY: RGBColor = RGBColor(214, 39, 40);
const SWITCH: RGBColor = RGBColor(175, 175, 175);
const STALL: RGBColor = RGBColor(230, 0, 0);
const FALLBACK: RGBColor = RGBColor(255, 140, 0);
const GRID: RGBColor = RGBColor(228, 228, 228);

#[derive(Clone, Copy, PartialEq)]
enum Anchor {
    Left,
    Centre,
    Right,
}

/// Text to draw after the shapes: `(x, y)` is the anchor point, vertically the text's middle.
struct Label {
    x: i32,
    y: i32,
    text: String,
    px: f32,
    anchor: Anchor,
}

/// About `target` round tick values (1, 2 or 5 × 10^k apart) within `[lo, hi]`.
fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = hi - lo;
    if !(span > 0.0 && span.is_finite()) {
        return vec![lo];
    }
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

/// `12`, `1.5k`, `20k`, `3M`, ...
fn si(v: f64) -> String {
    let (d, s) = if v >= 1e9 {
        (1e9, "G")
    } else if v >= 1e6 {
        (1e6, "M")
    } else if v >= 1e3 {
        (1e3, "k")
    } else {
        (1.0, "")
    };
    let x = v / d;
    if (x - x.round()).abs() < 1e-9 {
        format!("{}{s}", x.round())
    } else {
        format!("{:.1}{s}", x)
    }
}

fn fps_of(r: &FrameRecord) -> Option<f64> {
    (r.cpu_ms.is_finite() && r.cpu_ms > 0.0).then(|| 1000.0 / r.cpu_ms)
}

/// Renders the plot into an RGB image (see the module doc); the error says what could not be
/// drawn.
pub fn render_plot(
    impostor: &[FrameRecord],
    geometry: &[FrameRecord],
    opts: &PlotOptions,
) -> Result<(RgbImage, PlotInfo), String> {
    let (w, h) = (opts.width, opts.height);
    if !(320..=16384).contains(&w) || !(240..=16384).contains(&h) {
        return Err(format!(
            "plot size must be within 320x240 and 16384x16384, got {w}x{h}"
        ));
    }
    if impostor.is_empty() && geometry.is_empty() {
        return Err("no frames to plot".into());
    }
    let font = font();
    let fpx = (h as f32 / 48.0).clamp(11.0, 22.0);
    let mut labels: Vec<Label> = Vec::new();
    let label = |labels: &mut Vec<Label>, (x, y): (i32, i32), text: String, px: f32, anchor| {
        labels.push(Label {
            x,
            y,
            text,
            px,
            anchor,
        })
    };

    let frames_max = impostor
        .iter()
        .chain(geometry)
        .map(|r| r.frame)
        .max()
        .unwrap_or(0)
        .max(1) as f64;
    // The frame-rate axis ends a little above the 99th percentile of either mode, so a few
    // unusually fast frames do not flatten the rest; faster frames are drawn at the top.
    let mut fps: Vec<f64> = impostor.iter().chain(geometry).filter_map(fps_of).collect();
    fps.sort_by(f64::total_cmp);
    let fps_top = nearest_rank(&fps, 99.0).unwrap_or(1.0).max(1e-3) * 1.15;
    let prims = |r: &FrameRecord| r.primitives().max(1) as f64;
    let (mut pmin, mut pmax) = (f64::INFINITY, 1.0f64);
    for r in impostor.iter().chain(geometry) {
        pmin = pmin.min(prims(r));
        pmax = pmax.max(prims(r));
    }
    for r in impostor {
        pmin = pmin.min(r.impostor_quads.max(1) as f64);
    }
    let plo = 10f64.powf(pmin.max(1.0).log10().floor());
    let phi = 10f64.powf((pmax * 1.01).log10().ceil()).max(plo * 10.0);

    let n = impostor.len().max(geometry.len());
    let stroke = if n <= 1500 { 2 } else { 1 };
    let summary = FrameStats::of(impostor, geometry);

    let mut buf = vec![255u8; w as usize * h as usize * 3];
    {
        let err = |e: DrawingAreaErrorKind<_>| format!("drawing the plot: {e:?}");
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;

        // Title and the headline numbers.
        let title_h = (fpx * 3.6) as i32;
        label(
            &mut labels,
            (12, (fpx * 0.9) as i32),
            format!("{}: frame rate and primitives per frame", opts.title),
            fpx * 1.2,
            Anchor::Left,
        );
        let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2} ms"));
        let mut line = format!(
            "impostors: median {}, p99 {}   geometry: median {}, p99 {}",
            ms(summary.impostor_median_ms),
            ms(summary.impostor_p99_ms),
            ms(summary.geometry_median_ms),
            ms(summary.geometry_p99_ms)
        );
        if let Some(s) = summary.speedup_median {
            line += &format!("   speedup {s:.2}x");
        }
        let plural =
            |n: usize, one: &str, many: &str| format!("{n} {}", if n == 1 { one } else { many });
        line += &format!(
            "   {}, {}",
            plural(summary.cell_switches, "cell switch", "cell switches"),
            plural(summary.stalls, "stall", "stalls")
        );
        label(
            &mut labels,
            (12, (fpx * 2.5) as i32),
            line,
            fpx * 0.9,
            Anchor::Left,
        );

        let body = root.margin(title_h, 0, 0, 0);
        let (top, bottom) = body.split_vertically((h as i32 - title_h) * 55 / 100);
        let (ml, mr, mt, mb) = (
            (fpx * 4.5) as i32,
            (fpx * 1.2) as i32,
            (fpx * 1.8) as i32,
            (fpx * 2.0) as i32,
        );

        // Top: frame rate.
        let mut chart = ChartBuilder::on(&top)
            .margin_left(ml)
            .margin_right(mr)
            .margin_top(mt)
            .margin_bottom(mb)
            .build_cartesian_2d(0.0..frames_max, 0.0..fps_top)
            .map_err(err)?;
        for y in ticks(0.0, fps_top, 6) {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(0.0, y), (frames_max, y)],
                    GRID,
                )))
                .map_err(err)?;
            let (px, py) = chart.backend_coord(&(0.0, y));
            label(&mut labels, (px - 6, py), si(y), fpx * 0.85, Anchor::Right);
        }
        for x in ticks(0.0, frames_max, 10) {
            let (px, py) = chart.backend_coord(&(x, 0.0));
            label(
                &mut labels,
                (px, py + (fpx * 0.8) as i32),
                si(x),
                fpx * 0.85,
                Anchor::Centre,
            );
        }
        let (lx, ly) = chart.backend_coord(&(0.0, fps_top));
        label(
            &mut labels,
            (lx, ly - (fpx * 0.8) as i32),
            "frames per second (1000 / frame time)".into(),
            fpx,
            Anchor::Left,
        );
        // Cell switches behind the series.
        chart
            .draw_series(impostor.iter().filter(|r| r.cell_switch).map(|r| {
                let x = r.frame as f64;
                PathElement::new(vec![(x, 0.0), (x, fps_top)], SWITCH)
            }))
            .map_err(err)?;
        let series = |records: &[FrameRecord]| -> Vec<(f64, f64)> {
            records
                .iter()
                .filter_map(|r| fps_of(r).map(|f| (r.frame as f64, f.min(fps_top))))
                .collect()
        };
        chart
            .draw_series(LineSeries::new(
                series(geometry),
                GEOMETRY.stroke_width(stroke),
            ))
            .map_err(err)?;
        chart
            .draw_series(LineSeries::new(
                series(impostor),
                IMPOSTOR.stroke_width(stroke),
            ))
            .map_err(err)?;
        let tick = fps_top * 0.03;
        chart
            .draw_series(impostor.iter().filter(|r| r.fallback).map(|r| {
                let x = r.frame as f64;
                PathElement::new(vec![(x, 0.0), (x, tick)], FALLBACK.stroke_width(2))
            }))
            .map_err(err)?;
        chart
            .draw_series(impostor.iter().filter(|r| r.stalled).map(|r| {
                let y = fps_of(r).unwrap_or(0.0).min(fps_top);
                Circle::new((r.frame as f64, y), 4, STALL.filled())
            }))
            .map_err(err)?;
        chart
            .plotting_area()
            .draw(&Rectangle::new(
                [(0.0, 0.0), (frames_max, fps_top)],
                BLACK.stroke_width(1),
            ))
            .map_err(err)?;
        let (x1, y0) = chart.backend_coord(&(frames_max, fps_top));
        let mut entries = vec![
            ("impostors", IMPOSTOR, false),
            ("all geometry", GEOMETRY, false),
            ("cell switch", SWITCH, false),
            ("stall", STALL, true),
        ];
        if summary.fallback_frames > 0 {
            entries.push(("fallback", FALLBACK, false));
        }
        legend(&root, &mut labels, (x1, y0), &entries, fpx).map_err(err)?;

        // Bottom: primitives per frame, log scale.
        let mut chart = ChartBuilder::on(&bottom)
            .margin_left(ml)
            .margin_right(mr)
            .margin_top(mt)
            .margin_bottom((fpx * 3.2) as i32)
            .build_cartesian_2d(0.0..frames_max, (plo..phi).log_scale())
            .map_err(err)?;
        let decades = (phi / plo).log10().round() as i32;
        let mut y = plo;
        for _ in 0..=decades {
            for m in [1.0, 2.0, 5.0] {
                let v = y * m;
                if v > phi * 1.0001 || (m != 1.0 && decades > 3) {
                    continue;
                }
                let colour = if m == 1.0 {
                    GRID.mix(1.0)
                } else {
                    GRID.mix(0.5)
                };
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(0.0, v), (frames_max, v)],
                        colour,
                    )))
                    .map_err(err)?;
                let (px, py) = chart.backend_coord(&(0.0, v));
                label(&mut labels, (px - 6, py), si(v), fpx * 0.85, Anchor::Right);
            }
            y *= 10.0;
        }
        for x in ticks(0.0, frames_max, 10) {
            let (px, py) = chart.backend_coord(&(x, plo));
            label(
                &mut labels,
                (px, py + (fpx * 0.8) as i32),
                si(x),
                fpx * 0.85,
                Anchor::Centre,
            );
        }
        let (cx, cy) = chart.backend_coord(&(frames_max / 2.0, plo));
        label(
            &mut labels,
            (cx, cy + (fpx * 2.2) as i32),
            "frame".into(),
            fpx,
            Anchor::Centre,
        );
        let (lx, ly) = chart.backend_coord(&(0.0, phi));
        label(
            &mut labels,
            (lx, ly - (fpx * 0.8) as i32),
            "primitives per frame (log scale)".into(),
            fpx,
            Anchor::Left,
        );
        chart
            .draw_series(impostor.iter().filter(|r| r.cell_switch).map(|r| {
                let x = r.frame as f64;
                PathElement::new(vec![(x, plo), (x, phi)], SWITCH.mix(0.6))
            }))
            .map_err(err)?;
        let clamp = |v: f64| v.clamp(plo, phi);
        chart
            .draw_series(LineSeries::new(
                geometry.iter().map(|r| (r.frame as f64, clamp(prims(r)))),
                GEOMETRY.stroke_width(stroke),
            ))
            .map_err(err)?;
        chart
            .draw_series(LineSeries::new(
                impostor
                    .iter()
                    .map(|r| (r.frame as f64, clamp(r.impostor_quads.max(1) as f64))),
                QUADS.stroke_width(1),
            ))
            .map_err(err)?;
        chart
            .draw_series(LineSeries::new(
                impostor.iter().map(|r| (r.frame as f64, clamp(prims(r)))),
                IMPOSTOR.stroke_width(stroke),
            ))
            .map_err(err)?;
        chart
            .plotting_area()
            .draw(&Rectangle::new([(0.0, plo), (frames_max, phi)], BLACK))
            .map_err(err)?;
        let (x1, y0) = chart.backend_coord(&(frames_max, phi));
        legend(
            &root,
            &mut labels,
            (x1, y0),
            &[
                ("near triangles + impostor quads", IMPOSTOR, false),
                ("impostor quads", QUADS, false),
                ("all geometry: triangles", GEOMETRY, false),
            ],
            fpx,
        )
        .map_err(err)?;
        root.present().map_err(err)?;
    }

    let mut img = RgbImage::from_raw(w, h, buf).ok_or("plot buffer has the wrong size")?;
    if let Some(f) = font {
        for l in &labels {
            draw_text(&mut img, &f.font, l);
        }
    }
    Ok((
        img,
        PlotInfo {
            font: font.map(|f| f.path.clone()),
        },
    ))
}

/// A legend box in the top right corner `(x1, y0)` of a panel: a swatch (line or dot) and a name
/// per entry.
fn legend<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    labels: &mut Vec<Label>,
    (x1, y0): (i32, i32),
    entries: &[(&str, RGBColor, bool)],
    fpx: f32,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let px = fpx * 0.85;
    let row = (fpx * 1.3) as i32;
    // Text width is estimated (0.55 em per character) so the box fits without a font, too.
    let text_w = entries
        .iter()
        .map(|e| e.0.chars().count())
        .max()
        .unwrap_or(0) as f32
        * px
        * 0.55;
    let sw = (fpx * 2.0) as i32;
    let bw = sw + 18 + text_w as i32;
    let bh = row * entries.len() as i32 + 8;
    let (bx, by) = (x1 - bw - 8, y0 + 8);
    root.draw(&Rectangle::new(
        [(bx, by), (bx + bw, by + bh)],
        WHITE.mix(0.85).filled(),
    ))?;
    root.draw(&Rectangle::new(
        [(bx, by), (bx + bw, by + bh)],
        RGBColor(120, 120, 120),
    ))?;
    for (i, (name, colour, dot)) in entries.iter().enumerate() {
        let cy = by + 4 + row * i as i32 + row / 2;
        if *dot {
            root.draw(&Circle::new((bx + 6 + sw / 2, cy), 4, colour.filled()))?;
        } else {
            root.draw(&PathElement::new(
                vec![(bx + 6, cy), (bx + 6 + sw, cy)],
                colour.stroke_width(3),
            ))?;
        }
        labels.push(Label {
            x: bx + sw + 12,
            y: cy,
            text: name.to_string(),
            px,
            anchor: Anchor::Left,
        });
    }
    Ok(())
}

/// The font for labels, found once ([`find_font`]).
fn font() -> Option<&'static LoadedFont> {
    static FONT: OnceLock<Option<LoadedFont>> = OnceLock::new();
    FONT.get_or_init(|| find_font(FontUse::Plot)).as_ref()
}

/// Blends `l` into `img` (black text, anti-aliased).
fn draw_text(img: &mut RgbImage, font: &FontVec, l: &Label) {
    let sf = font.as_scaled(PxScale::from(l.px));
    let mut width = 0.0f32;
    let mut prev = None;
    for c in l.text.chars() {
        let id = sf.glyph_id(c);
        if let Some(p) = prev {
            width += sf.kern(p, id);
        }
        width += sf.h_advance(id);
        prev = Some(id);
    }
    let x0 = match l.anchor {
        Anchor::Left => l.x as f32,
        Anchor::Centre => l.x as f32 - width / 2.0,
        Anchor::Right => l.x as f32 - width,
    };
    let baseline = l.y as f32 + (sf.ascent() + sf.descent()) / 2.0;
    let (w, h) = img.dimensions();
    let mut caret = x0;
    let mut prev = None;
    for c in l.text.chars() {
        let id = sf.glyph_id(c);
        if let Some(p) = prev {
            caret += sf.kern(p, id);
        }
        let glyph = id.with_scale_and_position(sf.scale(), ab_glyph::point(caret, baseline));
        if let Some(o) = font.outline_glyph(glyph) {
            let b = o.px_bounds();
            o.draw(|gx, gy, cov| {
                let x = b.min.x as i64 + gx as i64;
                let y = b.min.y as i64 + gy as i64;
                if x >= 0 && y >= 0 && (x as u32) < w && (y as u32) < h {
                    let px = img.get_pixel_mut(x as u32, y as u32);
                    let a = cov.clamp(0.0, 1.0);
                    for ch in px.0.iter_mut() {
                        *ch = (*ch as f32 * (1.0 - a)).round() as u8;
                    }
                }
            });
        }
        caret += sf.h_advance(id);
        prev = Some(id);
    }
}

/// Frame time and primitives per frame (near triangles + far-field primitives) of several walks
/// along the same path, one line each (`walks`: a name and its impostor records), plus the
/// all-geometry replay's frame times; an SVG of 1200 × 800 written atomically to `path`.
pub fn write_frame_times_svg(
    path: &Path,
    walks: &[(&str, &[FrameRecord])],
    geometry: &[FrameRecord],
) -> Result<(), WalkError> {
    let plot_err = |message: String| WalkError::Plot {
        path: path.to_path_buf(),
        message,
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1200, 800)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_err(e.to_string()))?;
        let (top, bottom) = root.split_vertically(450);
        let walks: Vec<_> = walks.iter().filter(|(_, f)| !f.is_empty()).collect();
        let line = |frames: &[FrameRecord], y: &dyn Fn(&FrameRecord) -> f64| -> Vec<(f64, f64)> {
            frames.iter().map(|f| (f.frame as f64, y(f))).collect()
        };
        let mut times: Vec<(String, Vec<(f64, f64)>)> = walks
            .iter()
            .map(|(name, f)| (name.to_string(), line(f, &|r| r.cpu_ms)))
            .collect();
        if !geometry.is_empty() {
            times.push(("all geometry".into(), line(geometry, &|r| r.cpu_ms)));
        }
        let prims: Vec<(String, Vec<(f64, f64)>)> = walks
            .iter()
            .map(|(name, f)| {
                let p = |r: &FrameRecord| (r.near_triangles + r.impostor_quads) as f64;
                (name.to_string(), line(f, &p))
            })
            .collect();
        svg_panel(&top, "frame time per frame", "ms", &times).map_err(plot_err)?;
        svg_panel(
            &bottom,
            "primitives per frame (near triangles + far-field primitives)",
            "primitives",
            &prims,
        )
        .map_err(plot_err)?;
        root.present().map_err(|e| plot_err(e.to_string()))?;
    }
    lemi_core::container::write_atomic(path, svg.as_bytes())
        .map_err(|e| WalkError::io("frame-time plot", path, e))
}

/// One panel of [`write_frame_times_svg`]: a line per series, a legend.
fn svg_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    ylabel: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("{e:?}");
    let x1 = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.0))
        .fold(1.0f64, f64::max);
    let y1 = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.1))
        .filter(|y| y.is_finite())
        .fold(1.0f64, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..x1, 0.0..y1 * 1.05)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("frame")
        .y_desc(ylabel)
        .draw()
        .map_err(err)?;
    let colors = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(214, 39, 40),
    ];
    for (i, (name, pts)) in series.iter().enumerate() {
        let c = colors[i % colors.len()];
        chart
            .draw_series(LineSeries::new(
                pts.iter().copied().filter(|p| p.1.is_finite()),
                c.stroke_width(2),
            ))
            .map_err(err)?
            .label(name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::tests::rec;
    use crate::record::Mode;

    fn records() -> (Vec<FrameRecord>, Vec<FrameRecord>) {
        let imp: Vec<FrameRecord> = (0..300)
            .map(|i| {
                let mut r = rec(i, Mode::Impostor, 8.0 + (i % 17) as f64 * 0.3);
                r.cell_switch = i % 60 == 0 && i > 0;
                r.stalled = i == 120;
                r.fallback = i == 200;
                if r.stalled {
                    r.cpu_ms = 60.0;
                }
                r.near_triangles = 500 + (i % 50) * 20;
                r
            })
            .collect();
        let geo: Vec<FrameRecord> = (0..300)
            .map(|i| rec(i, Mode::Geometry, 40.0 + (i % 23) as f64))
            .collect();
        (imp, geo)
    }

    #[test]
    fn png_decodes_at_the_requested_size() {
        let (imp, geo) = records();
        let dir = std::env::temp_dir().join(format!("lemi-walk-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("walk.png");
        let opts = PlotOptions {
            width: 900,
            height: 600,
            title: "test".into(),
        };
        let info = write_plot_with(&f, &imp, &geo, &opts).unwrap();
        if let Some(keep) = std::env::var_os("LEMI_WALK_PLOT_OUT") {
            std::fs::copy(&f, keep).unwrap(); // set it to look at the plot
        }
        let img = image::open(&f).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (900, 600));
        let count = |c: RGBColor| img.pixels().filter(|p| p.0 == [c.0, c.1, c.2]).count();
        assert!(count(IMPOSTOR) > 500, "impostor series");
        assert!(count(GEOMETRY) > 500, "geometry series");
        assert!(count(STALL) > 10, "stall marker");
        assert!(count(SWITCH) > 100, "cell switch lines");
        // Text: dark grey pixels (anti-aliased glyph edges) appear only when a font was found.
        let text = img
            .pixels()
            .filter(|p| {
                let [r, g, b] = p.0;
                r == g && g == b && r > 20 && r < 200
            })
            .count();
        match &info.font {
            Some(path) => {
                eprintln!("plot font: {}", path.display());
                assert!(text > 200, "text pixels: {text}");
            }
            None => eprintln!("no font found: the plot has no text"),
        }
        // Only one mode, and the default size.
        write_plot(&f, &imp, &[]).unwrap();
        let img = image::open(&f).unwrap();
        assert_eq!((img.width(), img.height()), (1200, 800));
        write_plot(&f, &[], &geo).unwrap();
        // Errors name the file.
        let e = write_plot(&f, &[], &[]).unwrap_err().to_string();
        assert!(e.contains("walk.png") && e.contains("no frames"), "{e}");
        let tiny = PlotOptions {
            width: 10,
            ..PlotOptions::default()
        };
        assert!(write_plot_with(&f, &imp, &geo, &tiny).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn frame_times_svg_has_every_walk() {
        let (imp, geo) = records();
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("frame_times.svg");
        write_frame_times_svg(
            &f,
            &[("lemi", &imp), ("warp", &imp[..10]), ("none", &[])],
            &geo,
        )
        .unwrap();
        let svg = std::fs::read_to_string(&f).unwrap();
        assert!(svg.contains("<svg") && svg.contains("frame time"));
        assert!(svg.contains("lemi") && svg.contains("warp") && svg.contains("all geometry"));
        let e = write_frame_times_svg(&dir.path().join("no/dir/x.svg"), &[], &[]).unwrap_err();
        assert!(e.to_string().contains("x.svg"), "{e}");
    }

    #[test]
    fn degenerate_records_do_not_panic() {
        let mut imp = vec![
            rec(0, Mode::Impostor, 0.0),
            rec(1, Mode::Impostor, f64::NAN),
        ];
        imp[1].near_triangles = 0;
        imp[1].impostor_quads = 0;
        let geo = vec![rec(0, Mode::Geometry, f64::INFINITY)];
        let (img, _) = render_plot(&imp, &geo, &PlotOptions::default()).unwrap();
        assert_eq!(img.dimensions(), (1200, 800));
    }

    #[test]
    fn tick_values_are_round() {
        assert_eq!(
            ticks(0.0, 100.0, 5),
            vec![0.0, 20.0, 40.0, 60.0, 80.0, 100.0]
        );
        assert_eq!(ticks(0.0, 7.0, 6), vec![0.0, 2.0, 4.0, 6.0]);
        assert_eq!(si(1500.0), "1.5k");
        assert_eq!(si(2e6), "2M");
        assert_eq!(si(20.0), "20");
    }
}
