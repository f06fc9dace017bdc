//! The checks of [`BakeParams`] before any work starts: every value a user controls, each error
//! naming the parameter (its field), so that a front end can name its own flag for it.

use super::{BakeParams, LayerTarget, Layering};

/// A bake parameter out of range. [`ParamsError::parameter`] names the [`BakeParams`] field.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ParamsError {
    #[error("the cell size must be a positive number of metres (got {0})")]
    CellSize(f64),
    #[error("the cell height must be a positive number of metres (got {0})")]
    CellHeight(f64),
    #[error(
        "the resolution must be between {MIN_RESOLUTION} and {MAX_RESOLUTION} texels (got {0})"
    )]
    Resolution(u32),
    #[error("no faces to bake")]
    NoFaces,
    #[error("the parallax angle must be in (0, 0.5) radians (got {0})")]
    Alpha(f64),
    #[error("the number of layers must be between 1 and {MAX_LAYERS} (got {0})")]
    Layers(u32),
    #[error("the near field must be a distance beyond the cell's half size {half} m (got {got})")]
    NearField { got: f64, half: f64 },
    #[error("the micro-texture grid must be 1..={max} texels (got {got})")]
    MicroGrid { got: u32, max: u32 },
    #[error("the micro-texture threshold must be in [0, 1] (got {0})")]
    MicroThreshold(f64),
    #[error("the equidistant layering's overlap must be a fraction of a slab's depth in [0, 1] (got {0})")]
    Overlap(f64),
    #[error("outline copies need a crack-free layering (optimal, single or HLOD), not the equidistant one")]
    OutlineCopies,
    #[error("the outline fringe needs {0}")]
    OutlineFringe(&'static str),
    /// An option of the HLOD layering ([`crate::hlod::HlodError::option`] names it).
    #[error(transparent)]
    Hlod(#[from] crate::hlod::HlodError),
}

/// Texels per face side a bake accepts.
pub const MIN_RESOLUTION: u32 = 16;
pub const MAX_RESOLUTION: u32 = 8192;
/// Layers per face a bake accepts.
pub const MAX_LAYERS: u32 = 4096;

impl ParamsError {
    /// The [`BakeParams`] field at fault (`layering` for the overlap, `target` for layers and
    /// near field).
    pub fn parameter(&self) -> &'static str {
        match self {
            ParamsError::CellSize(_) => "cell_size",
            ParamsError::CellHeight(_) => "cell_height",
            ParamsError::Resolution(_) => "resolution",
            ParamsError::NoFaces => "faces",
            ParamsError::Alpha(_) => "alpha",
            ParamsError::Layers(_) | ParamsError::NearField { .. } => "target",
            ParamsError::MicroGrid { .. } => "micro_grid",
            ParamsError::MicroThreshold(_) => "micro_threshold",
            ParamsError::Overlap(_) | ParamsError::Hlod(_) => "layering",
            ParamsError::OutlineCopies => "outline_copies",
            ParamsError::OutlineFringe(_) => "outline_fringe",
        }
    }
}

impl BakeParams {
    /// Checks every parameter a user controls.
    pub fn validate(&self) -> Result<(), ParamsError> {
        let p = self;
        if !(p.cell_size.is_finite() && p.cell_size > 0.0) {
            return Err(ParamsError::CellSize(p.cell_size));
        }
        if let Some(h) = p.cell_height {
            if !(h.is_finite() && h > 0.0) {
                return Err(ParamsError::CellHeight(h));
            }
        }
        if !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&p.resolution) {
            return Err(ParamsError::Resolution(p.resolution));
        }
        if p.faces.is_empty() {
            return Err(ParamsError::NoFaces);
        }
        if !(p.alpha.is_finite() && p.alpha > 0.0 && p.alpha < 0.5) {
            return Err(ParamsError::Alpha(p.alpha));
        }
        match p.target {
            LayerTarget::Layers(n) if n == 0 || n > MAX_LAYERS => {
                return Err(ParamsError::Layers(n));
            }
            LayerTarget::NearField(d) if !(d.is_finite() && d > 0.5 * p.cell_size) => {
                return Err(ParamsError::NearField {
                    got: d,
                    half: 0.5 * p.cell_size,
                });
            }
            _ => {}
        }
        if p.micro_grid == 0 || p.micro_grid > p.resolution {
            return Err(ParamsError::MicroGrid {
                got: p.micro_grid,
                max: p.resolution,
            });
        }
        if !(0.0..=1.0).contains(&p.micro_threshold) {
            return Err(ParamsError::MicroThreshold(p.micro_threshold));
        }
        if let Layering::Hlod {
            error_px,
            band_factor,
        } = p.layering
        {
            crate::hlod::HlodOptions {
                error_px,
                band_factor,
            }
            .validate(p.alpha)?;
        }
        if let Layering::Equidistant { overlap } = p.layering {
            if !(overlap.is_finite() && (0.0..=1.0).contains(&overlap)) {
                return Err(ParamsError::Overlap(overlap));
            }
            if p.outline_copies {
                return Err(ParamsError::OutlineCopies);
            }
            if p.outline_fringe {
                return Err(ParamsError::OutlineFringe(
                    "a crack-free layering (optimal, single or HLOD), not the equidistant one",
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Face;

    fn ok() -> BakeParams {
        BakeParams {
            cell_size: 10.0,
            cell_height: None,
            resolution: 64,
            target: LayerTarget::Layers(8),
            faces: vec![Face::PosX],
            alpha: 0.001,
            output_fov_deg: None,
            output_width: None,
            micro_grid: 8,
            micro_threshold: 0.5,
            layering: Layering::Optimal,
            texture_format: Default::default(),
            outline_copies: false,
            outline_fringe: false,
        }
    }

    #[test]
    fn each_check_fires_and_names_its_parameter() {
        assert_eq!(ok().validate(), Ok(()));
        let cases: Vec<(BakeParams, &str)> = vec![
            (
                BakeParams {
                    cell_size: -3.0,
                    ..ok()
                },
                "cell_size",
            ),
            (
                BakeParams {
                    cell_size: f64::NAN,
                    ..ok()
                },
                "cell_size",
            ),
            (
                BakeParams {
                    cell_height: Some(0.0),
                    ..ok()
                },
                "cell_height",
            ),
            (
                BakeParams {
                    resolution: 3,
                    ..ok()
                },
                "resolution",
            ),
            (
                BakeParams {
                    resolution: 9000,
                    ..ok()
                },
                "resolution",
            ),
            (
                BakeParams {
                    faces: vec![],
                    ..ok()
                },
                "faces",
            ),
            (BakeParams { alpha: 0.0, ..ok() }, "alpha"),
            (
                BakeParams {
                    target: LayerTarget::Layers(0),
                    ..ok()
                },
                "target",
            ),
            (
                BakeParams {
                    target: LayerTarget::NearField(4.0),
                    ..ok()
                },
                "target",
            ),
            (
                BakeParams {
                    micro_grid: 65,
                    ..ok()
                },
                "micro_grid",
            ),
            (
                BakeParams {
                    micro_threshold: 1.5,
                    ..ok()
                },
                "micro_threshold",
            ),
            (
                BakeParams {
                    layering: Layering::Equidistant { overlap: -0.1 },
                    ..ok()
                },
                "layering",
            ),
            (
                BakeParams {
                    layering: Layering::Equidistant { overlap: 0.1 },
                    outline_copies: true,
                    ..ok()
                },
                "outline_copies",
            ),
            (
                BakeParams {
                    layering: Layering::Equidistant { overlap: 0.1 },
                    outline_fringe: true,
                    ..ok()
                },
                "outline_fringe",
            ),
        ];
        for (p, field) in cases {
            let e = p.validate().expect_err(field);
            assert_eq!(e.parameter(), field, "{e}");
            assert!(
                !e.to_string().contains("--"),
                "a library names no flag: {e}"
            );
        }
    }
}
