//! `lemi layers`: the layer placement of a cubic view cell (the error metric of GI 2002 sec. 4.2
//! and TR-186-2-02-04 sec. 2.1), as a table or JSON, optionally with a plot of the layer count
//! versus distance and view-cell size (TR Fig. 12). With `--object-distance` it places the layers
//! of one object seen from a box or shaft view cell instead (TR sec. 2.1.1-2.1.2, the object mode
//! in [`crate::layers_object`]).

use anyhow::{bail, Context, Result};
use lemi_core::placement::{
    alpha_from_output_view, min_face_res_for_output_view, place_env_layers, Dim, EnvParams,
    PixelChoice, Placement, Target, MAX_LAYERS,
};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Default output view when neither `--alpha-deg` nor `--output-fov`/`--output-width` is given.
pub(crate) const DEFAULT_FOV_DEG: f64 = 60.0;
const DEFAULT_WIDTH: u32 = 1280;

/// Compute where the impostor layers and borders of a cubic view cell go, or (with
/// `--object-distance`) of one object seen from a box or shaft view cell.
///
/// α (the allowed parallax angle) is the angle of one output pixel: by default the edge pixel of a
/// 60° wide, 1280 px output view (about 0.0388°).
#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("target").required(true)
    .args(["layers", "near_field", "object_distance"])))]
#[command(group(clap::ArgGroup::new("object").multiple(true)
    .args(["object_distance", "object_size", "object_depth", "shaft_angle"])))]
pub struct Args {
    /// Side length of the cubic view cell in metres (object mode: the box cell's side, or the
    /// width of a shaft cell's near border).
    #[arg(long, value_name = "METRES", value_parser = positive_finite, allow_negative_numbers = true)]
    pub(crate) cell: f64,
    /// Texels per side of each cube face (Res); in object mode texels across the impostor
    /// (default there: Schaufler's rule, as `lemi bake-object`).
    #[arg(long, value_name = "TEXELS", value_parser = clap::value_parser!(u32).range(1..),
          required_unless_present = "object_distance")]
    pub(crate) resolution: Option<u32>,
    /// Number of layers; prints the resulting near field.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=MAX_LAYERS as i64),
          conflicts_with = "object")]
    layers: Option<u32>,
    /// Near-field distance from the cell centre (m); prints the fewest layers that reach it.
    #[arg(long, value_name = "METRES", value_parser = positive_finite, allow_negative_numbers = true,
          conflicts_with = "object")]
    near_field: Option<f64>,
    /// Object mode: distance (m) from the view cell's near border (the side facing the object) to
    /// the object's near side, along the view axis.
    #[arg(long, value_name = "METRES", value_parser = positive_finite, allow_negative_numbers = true,
          requires = "object_size")]
    pub(crate) object_distance: Option<f64>,
    /// Object mode: width and height (m) of the object's near face, centred on the view axis.
    #[arg(long, value_name = "METRES", value_parser = positive_finite, allow_negative_numbers = true,
          requires = "object_distance")]
    pub(crate) object_size: Option<f64>,
    /// Object mode: the object's extent along the view axis (m); default its width.
    #[arg(long, value_name = "METRES", value_parser = positive_finite, allow_negative_numbers = true,
          requires = "object_distance")]
    pub(crate) object_depth: Option<f64>,
    /// Object mode: a shaft view cell with this full apex angle (degrees, 0 < angle < 180) whose
    /// near border is --cell wide, instead of a box.
    #[arg(long, value_name = "DEG", value_parser = shaft_angle, allow_negative_numbers = true,
          requires = "object_distance")]
    pub(crate) shaft_angle: Option<f64>,
    /// Allowed parallax angle α in degrees (0 < α < 90).
    #[arg(long, value_name = "DEG", value_parser = positive_finite, allow_negative_numbers = true,
          conflicts_with_all = ["output_fov", "output_width"])]
    alpha_deg: Option<f64>,
    /// Horizontal field of view of the output view in degrees (α = one output pixel).
    #[arg(long, value_name = "DEG", value_parser = positive_finite, allow_negative_numbers = true)]
    output_fov: Option<f64>,
    /// Width of the output view in pixels.
    #[arg(long, value_name = "PIXELS", value_parser = clap::value_parser!(u32).range(1..))]
    output_width: Option<u32>,
    /// Which output pixel α is the angle of: the edge pixel (smallest, the paper's choice) or
    /// the centre pixel (largest).
    #[arg(long, value_enum, default_value_t = PixelArg::Edge, conflicts_with = "alpha_deg")]
    alpha_pixel: PixelArg,
    /// The 2D case: the viewer moves in a horizontal square (the four horizontal faces).
    #[arg(long = "2d", conflicts_with = "object")]
    two_d: bool,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub(crate) json: bool,
    /// Also draw the layer count versus distance, view-cell size and resolution (SVG); in object
    /// mode versus object distance for 256, 512 and 1024 px output views and versus cell size.
    #[arg(long, value_name = "FILE.svg")]
    pub(crate) plot: Option<PathBuf>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum PixelArg {
    Edge,
    Centre,
}

fn positive_finite(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if !v.is_finite() || v <= 0.0 {
        return Err(format!("must be a finite number > 0, got {s}"));
    }
    Ok(v)
}

fn shaft_angle(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if !(v.is_finite() && v > 0.0 && v < 180.0) {
        return Err(format!(
            "the shaft's apex angle must be more than 0° and less than 180°, got {s}"
        ));
    }
    Ok(v)
}

/// Where α came from, for the report.
#[derive(Serialize)]
pub(crate) struct AlphaSource {
    pub(crate) alpha_deg: f64,
    /// `explicit`, or the output view it was derived from.
    pub(crate) source: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) output_fov_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) output_width: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) pixel: Option<&'static str>,
}

impl AlphaSource {
    /// The output pixel α refers to (edge unless `--alpha-pixel centre`).
    pub(crate) fn pixel_choice(&self) -> PixelChoice {
        match self.pixel {
            Some("centre") => PixelChoice::Centre,
            _ => PixelChoice::Edge,
        }
    }

    /// α as one line of a table.
    pub(crate) fn describe(&self) -> String {
        match (self.output_fov_deg, self.output_width, self.pixel) {
            (Some(f), Some(w), Some(px)) => format!(
                "α = {:.5}° ({px} pixel of a {f}° × {w} px output view, {})",
                self.alpha_deg, self.source
            ),
            _ => format!("α = {:.5}° (explicit)", self.alpha_deg),
        }
    }
}

#[derive(Serialize)]
struct Report<'a> {
    cell: f64,
    resolution: u32,
    dim: &'static str,
    alpha: AlphaSource,
    near_field: f64,
    layer_count: usize,
    layers: &'a [lemi_core::placement::Layer],
    warnings: Vec<String>,
}

pub fn run(args: Args) -> Result<()> {
    let (alpha, source) = alpha_of(&args)?;
    if args.object_distance.is_some() {
        return crate::layers_object::run(&args, alpha, source);
    }
    run_env(args, alpha, source)
}

/// α and where it came from: `--alpha-deg`, or one pixel of the output view.
fn alpha_of(args: &Args) -> Result<(f64, AlphaSource)> {
    let pixel = match args.alpha_pixel {
        PixelArg::Edge => PixelChoice::Edge,
        PixelArg::Centre => PixelChoice::Centre,
    };
    let (alpha, source) = match args.alpha_deg {
        Some(a) => {
            if a >= 90.0 {
                bail!("--alpha-deg must be below 90°, got {a}");
            }
            (
                a.to_radians(),
                AlphaSource {
                    alpha_deg: a,
                    source: "explicit",
                    output_fov_deg: None,
                    output_width: None,
                    pixel: None,
                },
            )
        }
        None => {
            let fov = args.output_fov.unwrap_or(DEFAULT_FOV_DEG);
            let width = args.output_width.unwrap_or(DEFAULT_WIDTH);
            if fov >= 180.0 {
                bail!("--output-fov must be below 180°, got {fov}");
            }
            let a = alpha_from_output_view(fov.to_radians(), width, pixel)
                .context("--output-fov/--output-width")?;
            let explicit = args.output_fov.is_some() || args.output_width.is_some();
            (
                a,
                AlphaSource {
                    alpha_deg: a.to_degrees(),
                    source: if explicit {
                        "output view"
                    } else {
                        "default output view"
                    },
                    output_fov_deg: Some(fov),
                    output_width: Some(width),
                    pixel: Some(match pixel {
                        PixelChoice::Edge => "edge",
                        PixelChoice::Centre => "centre",
                    }),
                },
            )
        }
    };
    Ok((alpha, source))
}

/// The environment-map placement of a cubic cell (GI 2002 sec. 4.2).
fn run_env(args: Args, alpha: f64, source: AlphaSource) -> Result<()> {
    let dim = if args.two_d { Dim::Two } else { Dim::Three };
    let Some(resolution) = args.resolution else {
        bail!("--resolution is required for the environment-map placement (without --object-distance)");
    };
    let mut warnings = Vec::new();
    if let (Some(fov), Some(width)) = (source.output_fov_deg, source.output_width) {
        let need = min_face_res_for_output_view(fov.to_radians(), width)
            .context("--output-fov/--output-width")?;
        if resolution < need {
            warnings.push(format!(
                "--resolution {} is too low for a {fov}° × {width} px output view: layer texels \
                 are magnified on screen (a face needs ≥ {need} texels for one texel ≤ one pixel), \
                 so the one-pixel guarantee is only nominal",
                resolution
            ));
        }
    }

    let half = args.cell / 2.0;
    let params = EnvParams::cube(half, resolution, alpha, dim);
    let target = match (args.layers, args.near_field) {
        (Some(n), None) => Target::Layers(n as usize),
        (None, Some(d)) => {
            if d <= half {
                bail!(
                    "--near-field {d} lies inside the view cell (half side {half} m): it must be \
                     farther than {half} m from the centre"
                );
            }
            Target::NearField(d)
        }
        _ => bail!("give exactly one of --layers and --near-field"),
    };
    let placement = place_env_layers(&params, target).context("layer placement")?;

    for w in &warnings {
        eprintln!("warning: {w}");
    }
    if let Some(path) = &args.plot {
        plot(path, &params, &placement, &source)
            .with_context(|| format!("--plot {}", path.display()))?;
    }

    let dim_name = match dim {
        Dim::Two => "2d",
        Dim::Three => "3d",
    };
    if args.json {
        let report = Report {
            cell: args.cell,
            resolution,
            dim: dim_name,
            alpha: source,
            near_field: placement.near_field,
            layer_count: placement.layers.len(),
            layers: &placement.layers,
            warnings,
        };
        return emit(&(serde_json::to_string_pretty(&report)? + "\n"));
    }
    emit(&table(&args, resolution, dim_name, &source, &placement))
}

/// Writes to stdout; a closed pipe (`lemi layers … | head`) is not an error.
pub(crate) fn emit(text: &str) -> Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r.context("writing to stdout"),
    }
}

fn table(args: &Args, resolution: u32, dim: &str, source: &AlphaSource, p: &Placement) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "view cell {} m, Res {}, {}, {dim}: {} layers",
        args.cell,
        resolution,
        source.describe(),
        p.layers.len()
    );
    let _ = writeln!(
        o,
        "{:>6}  {:>14}  {:>14}  {:>14}  bound by",
        "layer", "distance (m)", "near border", "far border"
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
    let _ = writeln!(
        o,
        "near field: {:.3} m from the centre (near-field cube side {:.3} m)",
        p.near_field,
        2.0 * p.near_field
    );
    o
}

/// Layers needed for a near field at `d` (None when unreachable or inside the cell).
fn count(params: &EnvParams, d: f64) -> Option<usize> {
    place_env_layers(params, Target::NearField(d))
        .ok()
        .map(|p| p.layers.len())
}

/// TR Fig. 12: layer count versus near-field distance for three resolutions (left) and versus
/// view-cell size for three distances (right). When α comes from the output view, the output
/// width scales with the resolution (as in the TR, which varied the output resolution).
fn plot(path: &Path, params: &EnvParams, placement: &Placement, src: &AlphaSource) -> Result<()> {
    use plotters::prelude::*;

    let base_d = placement.near_field.max(params.along * 1.5);
    let m = params.along;
    let dim = if params.across[1] == 0.0 {
        Dim::Two
    } else {
        Dim::Three
    };
    let alpha_for = |res: u32| -> f64 {
        match (src.output_fov_deg, src.output_width, src.pixel) {
            (Some(fov), Some(w), Some(px)) => {
                let scale = f64::from(res) / f64::from(params.res);
                let width = ((f64::from(w) * scale).round() as u32).max(1);
                let pixel = if px == "edge" {
                    PixelChoice::Edge
                } else {
                    PixelChoice::Centre
                };
                alpha_from_output_view(fov.to_radians(), width, pixel).unwrap_or(params.alpha)
            }
            _ => params.alpha,
        }
    };

    // Left: count versus distance, Res/2, Res, 2·Res.
    let d_min = (m * 1.2).max(base_d / 4.0);
    let d_max = base_d * 8.0;
    let ds: Vec<f64> = (0..=60)
        .map(|i| d_min * (d_max / d_min).powf(f64::from(i) / 60.0))
        .collect();
    let mut left = Vec::new();
    for res in [params.res / 2, params.res, params.res.saturating_mul(2)] {
        if res == 0 {
            continue;
        }
        let p = EnvParams::cube(m, res, alpha_for(res), dim);
        let pts: Vec<(f64, f64)> = ds
            .iter()
            .filter_map(|&d| count(&p, d).map(|n| (d, n as f64)))
            .collect();
        left.push((format!("Res {res}"), pts));
    }
    // Right: count versus cell side for three near-field distances.
    let distances = [base_d, 2.0 * base_d, 4.0 * base_d];
    let sides: Vec<f64> = (1..=40).map(|i| 2.0 * m * f64::from(i) / 20.0).collect();
    let mut right = Vec::new();
    for &d in &distances {
        let pts: Vec<(f64, f64)> = sides
            .iter()
            .filter_map(|&side| {
                let p = EnvParams::cube(side / 2.0, params.res, params.alpha, dim);
                count(&p, d).map(|n| (side, n as f64))
            })
            .collect();
        right.push((format!("near field {d:.0} m"), pts));
    }

    let root = SVGBackend::new(path, (1200, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
    let (a, b) = root.split_horizontally(600);
    draw_panel(
        &a,
        "layers vs near-field distance",
        "near-field distance from the centre (m)",
        &left,
    )?;
    draw_panel(&b, "layers vs view-cell size", "view-cell side (m)", &right)?;
    root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(())
}

pub(crate) fn draw_panel<DB: plotters::prelude::DrawingBackend>(
    area: &plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    xlabel: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e:?}");
    let xs = series.iter().flat_map(|s| s.1.iter().map(|p| p.0));
    let (x0, x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    let y1 = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.1))
        .fold(1.0f64, f64::max);
    if !x0.is_finite() || !x1.is_finite() || x0 >= x1 {
        bail!("nothing to plot");
    }
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(x0..x1, 0.0..y1 * 1.05)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(xlabel)
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
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}
