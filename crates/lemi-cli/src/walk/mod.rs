//! `lemi walk`: headless replay of a camera path, per-frame records and the plot after GI 2002
//! Figs. 8–9. [`path`] is the camera path format (`--path`, the viewer's recordings) and the
//! automatic walkthrough + flyover (`--auto`); [`record`] the per-frame records, their CSV and the
//! summary JSON; [`plot`] the PNG plot.

// Parts of the modules' API (other plot sizes, statistics helpers) serve the tests and the
// viewer's path recording; the binary does not use all of them yet.
#![allow(dead_code)]

pub mod path;
pub mod plot;
pub mod record;

pub use path::{auto_path, CameraPath, Pose};
pub use plot::write_plot;
pub use record::{write_csv, FrameRecord, Mode, Summary, CSV_COLUMNS};
