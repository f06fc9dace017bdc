//! lemi-core: the GPU-free heart of lemi.
//!
//! Geometry and math (cells, faces, cameras), layer placement (the error metric of Jeschke & Wimmer),
//! the image operations of the compression stages and the bundle format. Nothing here touches a GPU,
//! so its tests are fast and run anywhere.

pub mod bundle;
pub mod camera;
pub mod cell;
pub mod classify;
pub mod clip;
pub mod clip_border;
pub mod compress;
pub mod container;
pub mod culling;
pub mod enclosure;
pub mod face;
pub mod frustum;
pub mod hlod;
pub mod layering;
pub mod object_cell;
pub mod parallax_error;
pub mod placement;
pub mod scene;
pub mod serde_inf;
pub mod texel_scale;

pub use face::Face;
pub use scene::{Aabb, Material, Mesh, Scene, SceneBuilder, SceneStats, Texture, UpAxis, Vertex};
