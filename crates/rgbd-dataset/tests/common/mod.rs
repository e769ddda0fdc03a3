//! Helpers shared by the integration tests.

pub mod lens_photos;
