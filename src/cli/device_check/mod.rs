//! `volgen device-check --device cuda`: does this build compute on this device what it computes
//! on the CPU, and how fast? One JSON line per check on stdout, so `tools/gpu/check.sh` (and a
//! person) can read a GPU machine's answer without building anything there.
//!
//! The agreement checks run each piece training uses in the form the device runs it, against
//! the CPU kernels on the same inputs and weights: the renderer (`volrender::portable`),
//! Conv3d (conv2d over depth slices), a generator step, the active set's dense form, and a
//! critic step with its gradient penalty; then a `micro` training on both devices from the same
//! seed. The timing checks run one or two iterations of every scale of the `paper` preset and
//! a `tiny` training, within what is left of `--budget-seconds`.

mod compare;
mod kernels;
mod training;

use std::io::Write;
use std::panic::AssertUnwindSafe;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use candle_core::Device;
use serde_json::{json, Map, Value};
use singrav::TrainConfig;

/// The checks, in the order they run (the cheapest and most telling first).
const CHECKS: [&str; 8] = [
    "render",
    "conv3d",
    "generator",
    "active-set",
    "critic",
    "micro-training",
    "paper-iterations",
    "tiny-training",
];

/// The options of `volgen device-check`.
#[derive(Debug, clap::Args)]
pub struct DeviceCheckArgs {
    /// The device to check: `cuda` (or `cuda:N`, needs a build with the `cuda` feature) or `cpu`
    /// (the device forms then run on the CPU, against the CPU kernels).
    #[arg(long, default_value = "cuda")]
    device: DeviceName,
    /// The checks to run, comma-separated (default: all, in this order): render, conv3d,
    /// generator, active-set, critic, micro-training, paper-iterations, tiny-training.
    #[arg(long, value_delimiter = ',')]
    checks: Option<Vec<String>>,
    /// Where the checks' datasets and training runs go (default: a temporary directory, removed
    /// at the end).
    #[arg(long, value_name = "DIR")]
    work: Option<PathBuf>,
    /// Seconds for the whole check, looked at between checks and between training iterations:
    /// a training stops at the first iteration past it (and says so), the checks not yet
    /// started are reported as skipped (and count as not passed).
    #[arg(long, default_value_t = 420.0)]
    budget_seconds: f64,
    /// Iterations per scale in `paper-iterations` (the first one is reported apart: it
    /// includes the device's warm-up).
    #[arg(long, default_value_t = 2)]
    paper_iterations: usize,
    /// How many of the `paper` preset's scales `paper-iterations` times (default: all 6).
    #[arg(long)]
    paper_scales: Option<usize>,
}

/// A device as the command line names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DeviceName {
    Cpu,
    Cuda(usize),
}

impl FromStr for DeviceName {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "cpu" => Ok(Self::Cpu),
            "cuda" => Ok(Self::Cuda(0)),
            other => other
                .strip_prefix("cuda:")
                .and_then(|n| n.parse().ok())
                .map(Self::Cuda)
                .ok_or_else(|| format!("expected cpu, cuda or cuda:N, got `{other}`")),
        }
    }
}

impl DeviceName {
    fn open(self) -> Result<Device> {
        match self {
            Self::Cpu => Ok(Device::Cpu),
            Self::Cuda(ordinal) => {
                if !cfg!(feature = "cuda") {
                    bail!(
                        "this volgen was built without the `cuda` feature; tools/gpu/build.sh \
                         builds one with it"
                    );
                }
                Device::new_cuda(ordinal).with_context(|| format!("opening CUDA device {ordinal}"))
            }
        }
    }

    fn label(self) -> String {
        match self {
            Self::Cpu => "cpu".into(),
            Self::Cuda(n) => format!("cuda:{n}"),
        }
    }
}

/// What every check gets: the device, where to write, and the clock.
pub(crate) struct CheckContext {
    device: Device,
    work: PathBuf,
    started: Instant,
    budget_seconds: f64,
    paper_iterations: usize,
    paper_scales: Option<usize>,
}

impl CheckContext {
    /// Seconds of the budget left.
    fn seconds_left(&self) -> f64 {
        self.budget_seconds - self.started.elapsed().as_secs_f64()
    }
}

/// Runs the checks `args` asks for, printing one JSON line each; errors when one failed or was
/// skipped.
pub fn run(args: &DeviceCheckArgs) -> Result<()> {
    let checks = match &args.checks {
        Some(names) => {
            for name in names {
                if !CHECKS.contains(&name.as_str()) {
                    bail!(
                        "--checks: unknown check `{name}`; expected some of {}",
                        CHECKS.join(", ")
                    );
                }
            }
            CHECKS
                .iter()
                .filter(|c| names.iter().any(|n| n == *c))
                .copied()
                .collect()
        }
        None => CHECKS.to_vec(),
    };
    if args.paper_iterations == 0 {
        bail!("--paper-iterations: expected at least 1");
    }
    if args.budget_seconds.is_nan() || args.budget_seconds <= 0.0 {
        bail!("--budget-seconds: expected a number of seconds > 0");
    }
    let paper_scales = TrainConfig::preset("paper")?.scales();
    if let Some(n) = args.paper_scales {
        if !(1..=paper_scales).contains(&n) {
            bail!("--paper-scales: expected 1 to {paper_scales}, got {n}");
        }
    }
    let device = args.device.open()?;
    let temporary = match &args.work {
        Some(_) => None,
        None => Some(tempdir()?),
    };
    let work = args
        .work
        .clone()
        .or_else(|| temporary.clone())
        .expect("a work directory");
    std::fs::create_dir_all(&work).with_context(|| format!("creating {}", work.display()))?;
    let cx = CheckContext {
        device,
        work,
        started: Instant::now(),
        budget_seconds: args.budget_seconds,
        paper_iterations: args.paper_iterations,
        paper_scales: args.paper_scales,
    };
    let label = args.device.label();
    let mut failed = 0;
    for check in checks {
        let line = if cx.seconds_left() <= 0.0 {
            let mut details = Map::new();
            details.insert("skipped".into(), json!("the budget is spent"));
            json_line(check, &label, None, 0.0, details)
        } else {
            let started = Instant::now();
            // A panic in a check is a bug; it still gets its line, and the checks after it run.
            let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| run_check(check, &cx)))
                .unwrap_or_else(|_| Err(anyhow::anyhow!("the check panicked (see stderr)")));
            let seconds = started.elapsed().as_secs_f64();
            match outcome {
                Ok(details) => {
                    let ok = details.get("ok").and_then(Value::as_bool).unwrap_or(false);
                    json_line(check, &label, Some(ok), seconds, details)
                }
                Err(e) => {
                    let mut details = Map::new();
                    details.insert("error".into(), json!(without_backtrace(&format!("{e:#}"))));
                    json_line(check, &label, Some(false), seconds, details)
                }
            }
        };
        if line["ok"] != json!(true) {
            failed += 1;
        }
        let mut stdout = std::io::stdout().lock();
        writeln!(stdout, "{line}")?;
        stdout.flush()?;
    }
    if let Some(dir) = temporary {
        // Best effort: a leftover temporary directory is no reason to fail the check.
        let _ = std::fs::remove_dir_all(dir);
    }
    if failed > 0 {
        bail!("{failed} check(s) failed or did not run on {label} (see their JSON lines)");
    }
    Ok(())
}

fn run_check(check: &str, cx: &CheckContext) -> Result<Map<String, Value>> {
    match check {
        "render" => kernels::render(cx),
        "conv3d" => kernels::conv3d(cx),
        "generator" => kernels::generator(cx),
        "active-set" => kernels::active_set(cx),
        "critic" => kernels::critic(cx),
        "micro-training" => training::micro(cx),
        "paper-iterations" => training::paper_iterations(cx),
        "tiny-training" => training::tiny(cx),
        other => unreachable!("check `{other}` was validated"),
    }
}

/// One check's JSON line: its name, the device, `ok` (null when skipped), seconds, and the
/// check's own fields (whose `ok`, if any, is the line's).
fn json_line(
    check: &str,
    device: &str,
    ok: Option<bool>,
    seconds: f64,
    details: Map<String, Value>,
) -> Value {
    let mut fields = Map::new();
    fields.insert("check".into(), json!(check));
    fields.insert("device".into(), json!(device));
    fields.insert("ok".into(), json!(ok));
    fields.insert("seconds".into(), json!(round(seconds, 3)));
    for (key, value) in details {
        if key != "ok" {
            fields.insert(key, value);
        }
    }
    Value::Object(fields)
}

/// An error's text up to the backtrace candle appends under `RUST_BACKTRACE` (a JSON line is
/// read by people and scripts; the frames are not for either).
fn without_backtrace(text: &str) -> String {
    let lines: Vec<&str> = text
        .lines()
        .take_while(|l| !l.trim_start().starts_with("0: "))
        .collect();
    lines.join(" ").trim().to_string()
}

/// `x` to `digits` decimals, for lines people read.
fn round(x: f64, digits: i32) -> f64 {
    let scale = 10f64.powi(digits);
    (x * scale).round() / scale
}

/// A fresh directory under the system's temporary directory.
fn tempdir() -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!(
        "volgen-device-check-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0)
    ));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir)
}
