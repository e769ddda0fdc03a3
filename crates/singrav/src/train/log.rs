//! The JSON-lines loss log: one object per iteration, appended as training goes
//! ([`LossLog`]), and read back ([`read_log`]).

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::PathBuf;

use serde::Serialize;

use super::{LossTerm, StepLosses};
use crate::error::{invalid, io_error, Result};
use crate::run_dir::RunDir;

/// One line of a run's loss log: an iteration and its losses ([`LossTerm::key`]s, `null`
/// where not computed).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LogLine {
    /// The scale (1-based).
    pub scale: usize,
    /// The iteration within the scale (0-based).
    pub iteration: usize,
    /// Seconds of training when it ended, over all scales.
    pub seconds: f64,
    /// Its losses.
    #[serde(flatten)]
    pub losses: StepLosses,
}

/// Reads a run's loss log ([`RunDir::log`]), as this volgen writes it or an earlier one did:
/// keys earlier volgens wrote for a term are read as the term ([`LossTerm::from_key`]), keys of
/// terms since removed (`opacity_distribution`) are passed over.
///
/// ```no_run
/// let log = singrav::train::read_log(&singrav::RunDir::new("runs/stones"))?;
/// let last = log.last().expect("a line per iteration");
/// println!("scale {}: {:?}", last.scale, last.losses.get(singrav::train::LossTerm::Rgb));
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn read_log(run: &RunDir) -> Result<Vec<LogLine>> {
    let path = run.log();
    let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
    text.lines()
        .enumerate()
        .filter(|(_, line)| !line.trim().is_empty())
        .map(|(i, line)| {
            parse_line(line).ok_or_else(|| {
                invalid(
                    format!("{} line {}", path.display(), i + 1),
                    "expected a JSON object with scale, iteration, seconds and losses",
                )
            })
        })
        .collect()
}

/// A log line, if it is one.
fn parse_line(line: &str) -> Option<LogLine> {
    let value: serde_json::Value = serde_json::from_str(line).ok()?;
    let fields = value.as_object()?;
    let mut losses = StepLosses::default();
    for (key, value) in fields {
        if let (Some(term), Some(value)) = (LossTerm::from_key(key), value.as_f64()) {
            losses.set(term, value as f32);
        }
    }
    Some(LogLine {
        scale: usize::try_from(fields.get("scale")?.as_u64()?).ok()?,
        iteration: usize::try_from(fields.get("iteration")?.as_u64()?).ok()?,
        seconds: fields.get("seconds")?.as_f64()?,
        losses,
    })
}

/// An open log.
pub(super) struct LossLog {
    path: PathBuf,
    file: File,
}

impl LossLog {
    /// Opens the run's log ([`RunDir::log`]). A fresh run starts it empty; a resumed run keeps
    /// only the lines before the checkpoint's position (`scale`, `iteration`), dropping what the
    /// killed run logged after its last checkpoint, so the log reads as one uninterrupted run.
    pub fn open(run: &RunDir, resume_from: Option<(usize, usize)>) -> Result<Self> {
        let path = run.log();
        let kept = match resume_from {
            Some(position) if path.exists() => {
                let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
                text.lines()
                    .filter(|line| {
                        parse_line(line).is_some_and(|l| (l.scale, l.iteration) < position)
                    })
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
        let line = LogLine {
            scale,
            iteration,
            seconds,
            losses: *losses,
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

#[cfg(test)]
mod tests {
    use super::{parse_line, LogLine, LossTerm, StepLosses};

    #[test]
    fn a_line_reads_back_as_written_and_old_keys_as_their_terms() {
        let mut losses = StepLosses::default();
        losses.set(LossTerm::Rgb, 0.25);
        losses.set(LossTerm::VolumeAdversarial, -2.0);
        let line = LogLine {
            scale: 2,
            iteration: 7,
            seconds: 1.5,
            losses,
        };
        let text = serde_json::to_string(&line).unwrap();
        assert_eq!(parse_line(&text), Some(line.clone()));
        // A line of a volgen before the names agreed: `color`, and a removed term's key.
        let old = r#"{"scale":2,"iteration":7,"seconds":1.5,"critic":null,"color":0.25,
            "volume_adversarial":-2.0,"opacity_distribution":0.5}"#;
        assert_eq!(parse_line(old), Some(line));
        assert_eq!(parse_line(r#"{"scale":1}"#), None);
    }
}
