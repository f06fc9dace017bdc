//! lemi-runtime: the runtime job's cell streaming (GI 2002 sec. 3, runtime steps 1–2): locate the
//! observer's view cell, prefetch the cells it may reach soon in the background, keep them in a
//! bounded cache, spread their texture uploads over frames, and count every frame that had to
//! wait (a stall).
//!
//! - [`predict()`](predict::predict): which cells to have ready, soonest reachable first (pure).
//! - [`Loader`]: background reading, verification and decoding of cell files.
//! - [`Cache`]: byte-bounded LRU of cells; the current cell is never evicted.
//! - [`Streamer`]: the per-frame driver; [`Streamer::frame`] returns a [`FrameState`] whose
//!   `ready` cell is drawn with [`lemi_gpu::ImpostorRenderer`], or a `fallback` reason to draw all
//!   geometry instead.
//!
//! ```no_run
//! # use std::sync::Arc;
//! # use lemi_runtime::{Streamer, StreamerOptions};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! # let scene = Arc::new(lemi_core::SceneBuilder::new().finish());
//! let gpu = Arc::new(lemi_gpu::Gpu::new(lemi_gpu::BackendChoice::Auto)?);
//! let materials = Arc::new(lemi_gpu::GpuMaterials::upload(&gpu, &scene.materials, &scene.textures)?);
//! let bundle = std::path::Path::new("out/demo/bundle");
//! let manifest = lemi_core::bundle::Manifest::read(bundle)?;
//! let mut streamer =
//!     Streamer::new(gpu, manifest, bundle, scene, materials, StreamerOptions::default())?;
//! let (position, velocity) = (glam::DVec3::new(0.0, 1.7, 0.0), glam::DVec3::X);
//! let frame = streamer.frame(position, velocity, 1.0 / 60.0);
//! match (frame.ready, &frame.fallback) {
//!     (Some(_cell), _) => { /* draw _cell with ImpostorRenderer */ }
//!     (None, reason) => eprintln!("drawing geometry: {reason:?}"),
//! }
//! # Ok(()) }
//! ```

pub mod cache;
mod error;
pub mod loader;
pub mod predict;
pub mod streamer;

pub use cache::{Cache, Evicted};
pub use error::RuntimeError;
pub use loader::{DecodedCell, Loaded, Loader, LoaderOptions};
pub use predict::{earliest_arrival, predict, PredictOptions, Prediction};
pub use streamer::{CellState, FrameState, StallPolicy, StreamStats, Streamer, StreamerOptions};
