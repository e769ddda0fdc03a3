//! The JSON-lines loss log: one object per iteration, appended as training goes.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::StepLosses;
use crate::error::{io_error, Result};

/// The log's file name inside a run directory.
pub const LOG_FILE: &str = "log.jsonl";

/// One line of the log.
#[derive(Serialize)]
struct Line<'a> {
    scale: usize,
    iteration: usize,
    seconds: f64,
    #[serde(flatten)]
    losses: &'a StepLosses,
}

/// An open log.
pub(super) struct LossLog {
    path: PathBuf,
    file: File,
}

impl LossLog {
    /// Opens `run_dir/log.jsonl`. A fresh run starts it empty; a resumed run keeps only the
    /// lines before the checkpoint's position (`scale`, `iteration`), dropping what the killed
    /// run logged after its last checkpoint, so the log reads as one uninterrupted run.
    pub fn open(run_dir: &Path, resume_from: Option<(usize, usize)>) -> Result<Self> {
        let path = run_dir.join(LOG_FILE);
        let kept = match resume_from {
            Some(position) if path.exists() => {
                let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
                text.lines()
                    .filter(|line| line_position(line).is_some_and(|p| p < position))
                    .map(|line| format!("{line}\n"))
                    .collect::<String>()
            }
            _ => String::new(),
        };
        crate::io::write_bytes(&path, kept.as_bytes())?;
        let file = OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(io_error(&path))?;
        Ok(Self { path, file })
    }

    /// Appends the losses of iteration `iteration` (0-based) of `scale`.
    pub fn append(
        &mut self,
        scale: usize,
        iteration: usize,
        seconds: f64,
        losses: &StepLosses,
    ) -> Result<()> {
        let line = Line {
            scale,
            iteration,
            seconds,
            losses,
        };
        let mut text = serde_json::to_string(&line).map_err(|e| crate::error::Error::Io {
            path: self.path.clone(),
            source: e.into(),
        })?;
        text.push('\n');
        self.file
            .write_all(text.as_bytes())
            .map_err(io_error(&self.path))
    }
}

/// The (scale, iteration) of a log line, if it parses.
fn line_position(line: &str) -> Option<(usize, usize)> {
    let value: serde_json::Value = serde_json::from_str(line).ok()?;
    Some((
        value.get("scale")?.as_u64()? as usize,
        value.get("iteration")?.as_u64()? as usize,
    ))
}
