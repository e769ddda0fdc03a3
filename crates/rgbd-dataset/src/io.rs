//! File helpers shared by checkpoints, pictures and logs.

use std::path::Path;

use crate::error::{io_error, Result};

/// Writes `bytes` to `path` atomically (temporary file in the same directory, then rename), so
/// an interrupted write never leaves a partial file under the user's name.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(radiance_volume::io::write_bytes_atomic(path, bytes)?)
}

/// Creates `dir` and its parents, naming it on failure.
pub fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(io_error(dir))
}
