//! `lemi-walk`: walking a camera path through a baked bundle, after Jeschke, Wimmer & Schumann,
//! "Layered Environment-Map Impostors for Arbitrary Scenes" (Graphics Interface 2002), sec. 3 and
//! 6, Figs. 8–9: the viewer moves through the view cells, the far field comes from the current
//! cell's impostors, and the same path is replayed drawing all the geometry for comparison.
//!
//! - [`path`]: the camera path file (`lemi-path` JSON) and the automatic walkthrough + flyover of
//!   the baked cells ([`auto_path`]);
//! - [`record`]: per-frame records, `frames.csv`, and the frame-time statistics;
//! - [`run`]: [`walk`], the real-time paced replay through a [`lemi_strategy::Strategy`] and with
//!   the reference renderer, giving a [`WalkRun`] with its typed [`WalkSummary`];
//! - [`plot`]: the PNG plot of one walk and the SVG of several strategies' frame times;
//! - [`controls`]: the interactive viewer's fly/walk camera and its path recording;
//! - [`hud`]: the viewer's on-screen text and layer legend, drawn into a frame's pixels;
//! - [`layer_tint`]: the viewer's layer colouring (every impostor pixel tinted by its layer);
//! - [`font`]: the system font the plots and the viewer's HUD draw their text with.
//!
//! Nothing here panics on bad input: files, paths and options that cannot be used are
//! [`WalkError`]s naming the file or the field.

pub mod controls;
pub mod error;
pub mod font;
pub mod hud;
pub mod layer_tint;
pub mod path;
pub mod plot;
pub mod record;
pub mod run;

pub use error::WalkError;
pub use path::{auto_path, CameraPath, Key, PathError, Pose};
pub use plot::{
    render_plot, write_frame_times_svg, write_plot, write_plot_with, PlotInfo, PlotOptions,
};
pub use record::{
    nearest_rank, read_csv, to_csv, write_csv, FrameRecord, FrameStats, Mode, TimeStats,
    CSV_COLUMNS,
};
pub use run::{walk, WalkEvent, WalkOptions, WalkRun, WalkSummary, CLEAR};
