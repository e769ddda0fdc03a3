//! Atomic file writes: write to a temporary file beside the target, then rename over it, so a
//! crash or an error never leaves a partial file under the user's name.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::error::{io_error, Error, Result};

/// Writes a file atomically: `write` fills a buffered temporary file in the target's directory,
/// which is flushed, synced and renamed to `path`. On any error the temporary file is removed and
/// an existing file at `path` is left untouched.
///
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("hello.txt");
/// radiance_volume::io::write_atomic(&path, |w| {
///     w.write_all(b"hi").map_err(|source| radiance_volume::Error::Io { path: path.clone(), source })
/// })?;
/// assert_eq!(std::fs::read(&path)?, b"hi");
/// # use std::io::Write;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<()>,
) -> Result<()> {
    let tmp = temp_path_for(path)?;
    let result = (|| {
        let file = File::create(&tmp).map_err(io_error(&tmp))?;
        let mut w = BufWriter::new(file);
        write(&mut w)?;
        w.flush().map_err(io_error(&tmp))?;
        let file = w.into_inner().map_err(|e| Error::Io {
            path: tmp.clone(),
            source: e.into_error(),
        })?;
        file.sync_all().map_err(io_error(&tmp))?;
        std::fs::rename(&tmp, path).map_err(io_error(path))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically (see [`write_atomic`]).
///
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("hello.txt");
/// radiance_volume::io::write_bytes_atomic(&path, b"hi")?;
/// assert_eq!(std::fs::read(&path)?, b"hi");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// [`Error::Write`] naming `path` and the size when the bytes do not fit (a full disk, a
/// file-size limit); [`Error::Io`] for other failures.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_sized_atomic(path, bytes.len() as u64, |w| {
        w.write_all(bytes).map_err(io_error(path))
    })
}

/// [`write_atomic`] of a file whose size, `bytes`, is known before it is written: a write that
/// fails for want of space becomes [`Error::Write`], naming that size.
pub(crate) fn write_sized_atomic(
    path: &Path,
    bytes: u64,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<()>,
) -> Result<()> {
    write_atomic(path, write).map_err(|e| match e {
        Error::Io { source, .. } if out_of_space(&source) => Error::Write {
            path: path.to_path_buf(),
            bytes,
            source,
        },
        other => other,
    })
}

/// Whether a write failed for want of space: a full disk or quota, or a file-size limit.
fn out_of_space(error: &std::io::Error) -> bool {
    matches!(
        error.kind(),
        std::io::ErrorKind::StorageFull
            | std::io::ErrorKind::QuotaExceeded
            | std::io::ErrorKind::FileTooLarge
    )
}

/// Removes `path` if it exists (a missing file is not an error). Rewriters of a directory of
/// files use it to take away the index file first (a dataset's transforms.json, an EXR stack's
/// sidecar) and write it last, so a rewrite killed part-way never leaves an old index over a mix
/// of old and new files.
///
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("index.json");
/// radiance_volume::io::remove_file_if_exists(&path)?;
/// std::fs::write(&path, "{}")?;
/// radiance_volume::io::remove_file_if_exists(&path)?;
/// assert!(!path.exists());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn remove_file_if_exists(path: &Path) -> Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(io_error(path)(e)),
        _ => Ok(()),
    }
}

/// Checks, before any expensive work, that a file can be created in `path`'s directory (the
/// directory exists and is writable), by creating and removing a temporary file there.
pub fn check_writable(path: &Path) -> Result<()> {
    let tmp = temp_path_for(path)?;
    File::create(&tmp).map_err(io_error(path))?;
    std::fs::remove_file(&tmp).map_err(io_error(&tmp))
}

/// Returns `dir/.name.tmp-<pid>` for `dir/name`.
fn temp_path_for(path: &Path) -> Result<PathBuf> {
    let name = path.file_name().ok_or_else(|| Error::Io {
        path: path.to_path_buf(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name"),
    })?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp-{}", std::process::id()));
    Ok(path.with_file_name(tmp_name))
}
