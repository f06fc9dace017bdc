//! Cameras and views: eye, orientation, projection (owned by the renderer work).
