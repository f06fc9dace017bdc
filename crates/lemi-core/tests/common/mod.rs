//! What the lemi-core test suites share.

pub mod synthetic;
