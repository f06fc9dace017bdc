//! `lemi layers --object-distance D --object-size W …`: the layers of one object impostor seen
//! from a box or shaft view cell, as a table or JSON, optionally with the TR's Fig. 12 for objects
//! (layer count versus object distance for three output widths, and versus view-cell size).
//!
//! This work is based on: S. Jeschke, M. Wimmer, *An Error Metric for Layered Environment Map
//! Impostors*, TR-186-2-02-04, sec. 2.1.1-2.1.2 (the placement, [`lemi_core::placement::object`]),
//! sec. 2.3 (the trends: Fig. 11's dragon at 42, 59, 96, 142, 209 and 563 m from a 10 m cubic
//! cell, Fig. 12's counts versus distance and cell size).
//!
//! The geometry is built as a real view cell and object box and set up by
//! [`ObjectSetup::new`], the function `lemi bake-object` uses, so the numbers are the bake's: a box
//! cell `[−C/2, C/2]³` and an object `W` wide and high (centred on the X axis) and `H` deep whose
//! near side is `D` beyond the cell's `+X` face. A shaft cell (`--shaft-angle β`) has its near
//! border on that face, `C` wide, its axis along X and its apex on the axis `C/(2·tan(β/2))`
//! beyond the near border. The TR puts the apex at the object's centre (its Fig. 2); that holds
//! here when `D + H/2 = C/(2·tan(β/2))`. The placement sees the apex only through the near
//! border's width and the angle (TR eq. 5, eq. 7 from the near border's corners, the check over
//! the whole shaft), so fixing `C` rather than the apex keeps the cell the same while `D` varies.

use anyhow::{anyhow, bail, Context, Result};
use glam::DVec3;
use lemi_core::bundle::{MAX_RESOLUTION, MIN_RESOLUTION};
use lemi_core::object_cell::{ObjectError, ObjectSetup, ObjectViewCell};
use lemi_core::placement::{alpha_from_output_view, Layer, ObjectPlacement};
use lemi_core::Aabb;
use serde::Serialize;
use std::path::Path;

use crate::cmd_layers::{draw_panel, emit, AlphaSource, Args};

/// TR Fig. 11: (distance from the view cell in m, layers) of the dragon seen from a 10 m cell.
pub const TR_FIG11: [(f64, f64); 6] = [
    (42.0, 120.0),
    (59.0, 60.0),
    (96.0, 30.0),
    (142.0, 15.0),
    (209.0, 7.0),
    (563.0, 1.0),
];

/// The output widths of the TR's Fig. 12 (left).
const PLOT_WIDTHS: [u32; 3] = [256, 512, 1024];

/// The object-mode scene: a cell and an object on its +X side.
#[derive(Clone, Copy, Debug)]
struct Geometry {
    /// Box side, or the width of a shaft's near border (m).
    cell: f64,
    /// The shaft's full apex angle (degrees); `None` for a box.
    shaft_angle_deg: Option<f64>,
    /// From the cell's near border to the object's near side (m).
    distance: f64,
    /// Width and height of the object (m).
    size: f64,
    /// Extent of the object along the view axis (m).
    depth: f64,
}

impl Geometry {
    fn with_distance(self, distance: f64) -> Geometry {
        Geometry { distance, ..self }
    }

    fn with_cell(self, cell: f64) -> Geometry {
        Geometry { cell, ..self }
    }

    /// The view cell and the object's box, in world coordinates.
    fn world(&self) -> (ObjectViewCell, Aabb) {
        let h = self.cell / 2.0;
        let w = self.size / 2.0;
        let object = Aabb::new(
            DVec3::new(h + self.distance, -w, -w),
            DVec3::new(h + self.distance + self.depth, w, w),
        );
        let cell = match self.shaft_angle_deg {
            None => ObjectViewCell::Box {
                min: DVec3::splat(-h),
                max: DVec3::splat(h),
            },
            Some(angle) => {
                let apex_distance = h / (angle.to_radians() / 2.0).tan();
                ObjectViewCell::Shaft {
                    apex: DVec3::new(h + apex_distance, 0.0, 0.0),
                    dir: DVec3::NEG_X,
                    angle_deg: angle,
                    min_distance: apex_distance,
                    max_distance: None,
                    within: None,
                }
            }
        };
        (cell, object)
    }

    /// The setup `lemi bake-object` would make for this cell and object box.
    fn setup(&self, res: Option<u32>, alpha: f64) -> Result<ObjectSetup, ObjectError> {
        let (cell, object) = self.world();
        ObjectSetup::new(cell, object, res, alpha)
    }

    /// The number of layers, `None` when the setup or the placement refuses the parameters.
    fn count(&self, res: Option<u32>, alpha: f64) -> Option<usize> {
        let setup = self.setup(res, alpha).ok()?;
        setup.place().ok().map(|p| p.layers.len())
    }

    /// "10 m box view cell" or "shaft view cell (30° apex angle, near border 10 m wide)".
    fn describe_cell(&self) -> String {
        match self.shaft_angle_deg {
            None => format!("{} m box view cell", self.cell),
            Some(a) => format!(
                "shaft view cell ({a}° apex angle, near border {} m wide)",
                self.cell
            ),
        }
    }
}

/// The flag a setup error is about.
fn flag_of(e: &ObjectError, g: &Geometry) -> &'static str {
    match e {
        ObjectError::ViewCell(_) if g.shaft_angle_deg.is_some() => "--cell/--shaft-angle",
        ObjectError::ViewCell(_) => "--cell",
        ObjectError::Object(_) => "--object-size/--object-depth",
        ObjectError::Overlap(_) => "--object-distance",
        ObjectError::Placement(_) => {
            "--object-distance/--object-size/--object-depth/--cell/--resolution"
        }
    }
}

#[derive(Serialize)]
struct CellReport {
    /// `box` or `shaft`.
    kind: &'static str,
    /// Box side, or the shaft's near-border width (m).
    size: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    apex_angle_deg: Option<f64>,
    /// The shaft's apex, this far beyond its near border (m).
    #[serde(skip_serializing_if = "Option::is_none")]
    apex_distance: Option<f64>,
    /// The same cell as `lemi bake-object --view-cell` takes it.
    view_cell: String,
}

#[derive(Serialize)]
struct ObjectReport<'a> {
    mode: &'static str,
    cell: CellReport,
    object: ObjectBox,
    resolution: u32,
    /// `schaufler` (Schaufler's rule) or `explicit` (`--resolution`).
    resolution_source: &'static str,
    alpha: &'a AlphaSource,
    /// Reference viewpoint: this far behind the cell's near border (m).
    s: f64,
    /// The object's near side: this far beyond the cell's near border (m).
    t0: f64,
    /// The object's far side (TR distance, m).
    t_far: f64,
    /// Beyond this TR distance one layer represents everything (`null`: never).
    single_layer_beyond: Option<f64>,
    layer_count: usize,
    /// Near to far; distances are the TR's `t`, from the cell's near border.
    layers: &'a [Layer],
    warnings: Vec<String>,
}

#[derive(Serialize)]
struct ObjectBox {
    distance: f64,
    size: f64,
    depth: f64,
    /// The object's box `x0,y0,z0,x1,y1,z1` (world).
    world_box: [f64; 6],
}

pub fn run(args: &Args, alpha: f64, source: AlphaSource) -> Result<()> {
    let (Some(distance), Some(size)) = (args.object_distance, args.object_size) else {
        bail!("the object mode needs --object-distance and --object-size");
    };
    let g = Geometry {
        cell: args.cell,
        shaft_angle_deg: args.shaft_angle,
        distance,
        size,
        depth: args.object_depth.unwrap_or(size),
    };
    let setup = g
        .setup(args.resolution, alpha)
        .map_err(|e| anyhow!("{}: {e}", flag_of(&e, &g)))?;
    let placement = setup
        .place()
        .map_err(|e| anyhow!("{}: {e}", flag_of(&e, &g)))?;
    let mut warnings = Vec::new();
    let res = setup.params.res;
    if !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&res) {
        warnings.push(format!(
            "an impostor of {res} texels across is outside what `lemi bake-object` bakes \
             ({MIN_RESOLUTION}..={MAX_RESOLUTION}); give --resolution or another output view"
        ));
    }
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    if let Some(path) = &args.plot {
        plot(path, &g, args.resolution, alpha, &source)
            .with_context(|| format!("--plot {}", path.display()))?;
    }
    let (cell, object) = g.world();
    let apex_distance = match cell {
        ObjectViewCell::Shaft { min_distance, .. } => Some(min_distance),
        ObjectViewCell::Box { .. } => None,
    };
    let report = ObjectReport {
        mode: "object",
        cell: CellReport {
            kind: if g.shaft_angle_deg.is_some() {
                "shaft"
            } else {
                "box"
            },
            size: g.cell,
            apex_angle_deg: g.shaft_angle_deg,
            apex_distance,
            view_cell: cell.describe(),
        },
        object: ObjectBox {
            distance: g.distance,
            size: g.size,
            depth: g.depth,
            world_box: [
                object.min.x,
                object.min.y,
                object.min.z,
                object.max.x,
                object.max.y,
                object.max.z,
            ],
        },
        resolution: res,
        resolution_source: if args.resolution.is_some() {
            "explicit"
        } else {
            "schaufler"
        },
        alpha: &source,
        s: setup.params.s,
        t0: setup.params.t0,
        t_far: setup.params.t0 + setup.params.depth,
        single_layer_beyond: Some(placement.single_layer_beyond).filter(|d| d.is_finite()),
        layer_count: placement.layers.len(),
        layers: &placement.layers,
        warnings,
    };
    if args.json {
        return emit(&(serde_json::to_string_pretty(&report)? + "\n"));
    }
    emit(&table(&g, &report, &placement))
}

fn table(g: &Geometry, r: &ObjectReport, p: &ObjectPlacement) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "object {} × {} × {} m (deep), {} m beyond the near border of a {}: {} layers",
        g.size,
        g.size,
        g.depth,
        g.distance,
        g.describe_cell(),
        p.layers.len()
    );
    let _ = writeln!(
        o,
        "Res {} ({}), {}",
        r.resolution,
        if r.resolution_source == "schaufler" {
            "Schaufler's rule"
        } else {
            "--resolution"
        },
        r.alpha.describe()
    );
    let _ = writeln!(
        o,
        "s = {:.3} m (reference viewpoint behind the near border), t0 = {:.3} m (object near side), far side {:.3} m",
        r.s, r.t0, r.t_far
    );
    if let Some(apex) = r.cell.apex_distance {
        let _ = writeln!(
            o,
            "shaft apex {apex:.3} m beyond the near border (object centre at {:.3} m)",
            g.distance + g.depth / 2.0
        );
    }
    let _ = writeln!(
        o,
        "view cell (as bake-object --view-cell): {}",
        r.cell.view_cell
    );
    let b = r.object.world_box;
    let _ = writeln!(
        o,
        "object box: {},{},{},{},{},{}",
        b[0], b[1], b[2], b[3], b[4], b[5]
    );
    let _ = writeln!(o, "distances t from the cell's near border, near to far:");
    let _ = writeln!(
        o,
        "{:>6}  {:>14}  {:>14}  {:>14}  bound by",
        "layer", "distance t (m)", "near border", "far border"
    );
    for (i, l) in p.layers.iter().enumerate() {
        let _ = writeln!(
            o,
            "{:>6}  {:>14.3}  {:>14.3}  {:>14.3}  {}",
            i + 1,
            l.distance,
            l.near_border,
            l.far_border,
            l.bound_by
        );
    }
    match r.single_layer_beyond {
        Some(d) => {
            let _ = writeln!(o, "one layer represents everything beyond t = {d:.3} m");
        }
        None => {
            let _ = writeln!(
                o,
                "no distance where one layer represents everything behind it"
            );
        }
    }
    o
}

/// `n` distances spaced evenly on a log scale from `a` to `b`.
fn log_space(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..=n)
        .map(|i| a * (b / a).powf(i as f64 / n as f64))
        .collect()
}

/// TR Fig. 12 for objects: (a) layer count versus object distance for output widths 256, 512
/// and 1024 px (α = one pixel of each, Schaufler's resolution per distance unless
/// `--resolution`), with the TR's Fig. 11 counts as markers; (b) layer count versus view-cell size
/// (1-32 m) at the distances D, 2D and 4D for the given α.
fn plot(path: &Path, g: &Geometry, res: Option<u32>, alpha: f64, src: &AlphaSource) -> Result<()> {
    use plotters::prelude::*;

    let fov = src
        .output_fov_deg
        .unwrap_or(crate::cmd_layers::DEFAULT_FOV_DEG);
    let pixel = src.pixel_choice();
    let d0 = 20f64.min(g.distance / 1.5);
    let d1 = 1000f64.max(g.distance * 1.5);
    let ds = log_space(d0, d1, 120);
    let res_note = match res {
        Some(r) => format!("Res {r}"),
        None => "Schaufler's Res".to_string(),
    };
    let mut left = Vec::new();
    for w in PLOT_WIDTHS {
        let a = alpha_from_output_view(fov.to_radians(), w, pixel).context("--output-fov")?;
        let pts: Vec<(f64, f64)> = ds
            .iter()
            .filter_map(|&d| g.with_distance(d).count(res, a).map(|n| (d, n as f64)))
            .collect();
        left.push((format!("{w} px"), pts));
    }
    if src.output_fov_deg.is_none() {
        // An explicit α: its own curve beside the output widths.
        let pts: Vec<(f64, f64)> = ds
            .iter()
            .filter_map(|&d| g.with_distance(d).count(res, alpha).map(|n| (d, n as f64)))
            .collect();
        left.push((format!("α = {:.4}°", src.alpha_deg), pts));
    }
    let distances = [g.distance, 2.0 * g.distance, 4.0 * g.distance];
    let sides: Vec<f64> = (0..=62).map(|i| 1.0 + 0.5 * f64::from(i)).collect();
    let mut right = Vec::new();
    for &d in &distances {
        let pts: Vec<(f64, f64)> = sides
            .iter()
            .filter_map(|&c| {
                g.with_distance(d)
                    .with_cell(c)
                    .count(res, alpha)
                    .map(|n| (c, n as f64))
            })
            .collect();
        right.push((format!("{d:.0} m"), pts));
    }

    let root = SVGBackend::new(path, (1200, 540)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<std::io::Error>| anyhow!("{e}");
    root.fill(&WHITE).map_err(err)?;
    let cell = match g.shaft_angle_deg {
        None => format!("{} m box cell", g.cell),
        Some(a) => format!("{a}° shaft, near border {} m", g.cell),
    };
    let title = format!(
        "Object impostor layers (TR-186-2-02-04 Fig. 12): object {}×{}×{} m, {cell}, {fov}° output view, {res_note}",
        g.size, g.size, g.depth
    );
    let root = root.titled(&title, ("sans-serif", 18)).map_err(err)?;
    let (a, b) = root.split_horizontally(600);
    let alpha_note = match (src.output_fov_deg, src.output_width) {
        (Some(_), Some(w)) => format!("{w} px"),
        _ => format!("α = {:.4}°", src.alpha_deg),
    };
    draw_distance_panel(&a, &left, &TR_FIG11)?;
    let xlabel = match g.shaft_angle_deg {
        None => "view-cell side (m)",
        Some(_) => "shaft near-border width (m)",
    };
    draw_panel(
        &b,
        &format!("(b) layers vs view-cell size ({alpha_note})"),
        xlabel,
        &right,
    )?;
    root.present().map_err(err)?;
    Ok(())
}

/// Panel (a): the layer count against a log distance axis, the TR's counts as markers.
fn draw_distance_panel<DB: plotters::prelude::DrawingBackend>(
    area: &plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    series: &[(String, Vec<(f64, f64)>)],
    markers: &[(f64, f64)],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("{e:?}");
    let xs = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.0))
        .chain(markers.iter().map(|p| p.0));
    let (x0, x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if !x0.is_finite() || !x1.is_finite() || x0 <= 0.0 || x0 >= x1 {
        bail!("nothing to plot");
    }
    let y1 = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.1))
        .chain(markers.iter().map(|p| p.1))
        .fold(1.0f64, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption("(a) layers vs object distance", ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d((x0..x1).log_scale(), 0.0..y1 * 1.05)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_labels(12)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .light_line_style(WHITE.mix(0.0))
        .x_desc("distance from the view cell to the object (m, log scale)")
        .y_desc("layers")
        .draw()
        .map_err(err)?;
    let colors = [RED, BLUE, GREEN, MAGENTA];
    for (i, (name, pts)) in series.iter().enumerate() {
        let c = colors[i % colors.len()];
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
            .map_err(err)?
            .label(name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
    }
    chart
        .draw_series(
            markers
                .iter()
                .map(|&p| Circle::new(p, 5, BLACK.stroke_width(2))),
        )
        .map_err(err)?
        .label("TR Fig. 11 (dragon, 10 m cell)")
        .legend(|(x, y)| Circle::new((x + 10, y), 5, BLACK.stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}
