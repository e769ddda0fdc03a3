//! Bench groups, one file per operation.
pub mod render;
