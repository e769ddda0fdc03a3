//! Helpers shared by the integration tests.

// Each test file uses a part of the modules.
#[allow(dead_code)]
pub mod capture;
#[allow(dead_code)]
pub mod lens_photos;
