//! The training checks: `micro` on the CPU and on the device from the same seed (agreement),
//! then timings of the `paper` preset's iterations per scale and of a `tiny` training.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use candle_core::Device;
use rgbd_dataset::scenes::SceneKind;
use rgbd_dataset::{write_built_in, Dataset, DatasetSpec};
use serde_json::{json, Map, Value};
use singrav::train::{train, Control, Event, Progress, RunOptions, StepLosses};
use singrav::TrainConfig;

use super::{round, CheckContext};
use crate::cli::train::load_dataset;

/// The first iteration's losses on the device against the CPU's, relative to each loss's size:
/// the same seed gives both the same weights, noise and views, so only the order of sums
/// differs (later iterations drift apart as any two GAN runs do, and are not compared).
const FIRST_STEP_TOLERANCE: f64 = 1e-3;

/// What a training run reported, step by step.
#[derive(Default)]
struct Record {
    /// (scale, seconds of the scale's iterations so far, losses) of every iteration.
    steps: Vec<(usize, f64, StepLosses)>,
    /// (scale, seconds) of every finished scale.
    scales: Vec<(usize, f64)>,
    /// (scale, the device's memory in use in MiB) at the end of every scale and where the run
    /// was stopped (on a GPU).
    memory: Vec<(usize, u64)>,
    /// Iterations of the whole run.
    total_iterations: usize,
    /// Whether the run was stopped before its end, and why.
    stopped: Option<&'static str>,
    seconds: f64,
}

/// Trains `config` on `dataset` into `run_dir` on `device`; `stop` may end it after any step.
fn record_training(
    config: &TrainConfig,
    dataset: &Dataset,
    run_dir: &Path,
    device: &Device,
    stop: &mut dyn FnMut(&Progress) -> Option<&'static str>,
) -> Result<Record> {
    let started = std::time::Instant::now();
    let mut record = Record {
        total_iterations: config.total_iterations(),
        ..Default::default()
    };
    let mut observer = |p: &Progress| {
        match &p.event {
            Event::Step => record.steps.push((p.scale, p.scale_seconds, p.losses)),
            Event::ScaleDone(_) => {
                record.scales.push((p.scale, p.scale_seconds));
                record
                    .memory
                    .extend(device_memory_used_mib(device).map(|m| (p.scale, m)));
            }
            _ => {}
        }
        if matches!(p.event, Event::Step) {
            if let Some(why) = stop(p) {
                record.stopped = Some(why);
                record
                    .memory
                    .extend(device_memory_used_mib(device).map(|m| (p.scale, m)));
                return Control::Stop;
            }
        }
        Control::Continue
    };
    let trained = train(
        config,
        dataset,
        run_dir,
        &RunOptions::default(),
        device,
        &mut observer,
    );
    if let Err(error) = trained {
        // What the device held as the run went on: a driver's error about memory says no more.
        let memory: Vec<String> = record
            .memory
            .iter()
            .map(|(n, mib)| format!("scale {n} {mib} MiB"))
            .collect();
        let held = if memory.is_empty() {
            String::new()
        } else {
            format!(
                " (device memory in use after each finished scale: {})",
                memory.join(", ")
            )
        };
        return Err(anyhow::Error::new(error).context(format!(
            "training `{}` into {}{held}",
            config.preset,
            run_dir.display()
        )));
    }
    record.seconds = started.elapsed().as_secs_f64();
    Ok(record)
}

/// The device's memory in use in MiB as its driver counts it (what candle's CUDA memory pool
/// holds, not only live tensors); `None` on the CPU.
fn device_memory_used_mib(device: &Device) -> Option<u64> {
    #[cfg(feature = "cuda")]
    if let Ok(cuda) = device.as_cuda_device() {
        let (free, total) = cuda.cuda_stream().context().mem_get_info().ok()?;
        return Some(((total - free) >> 20) as u64);
    }
    let _ = device;
    None
}

/// The stones scene's dataset for `config` (at its final image size) in `dir`, loaded as
/// training loads it.
fn stones_dataset(config: &TrainConfig, dir: &Path, views: usize, grid: usize) -> Result<Dataset> {
    let spec = DatasetSpec {
        views,
        resolution: config.final_image_size(),
        grid,
        seed: 0,
    };
    let summary = write_built_in(SceneKind::StandingStones, 0, dir, &spec)
        .with_context(|| format!("writing the stones dataset into {}", dir.display()))?;
    load_dataset(&summary.transforms, config, None)
}

/// The loss terms of one step as a JSON object.
fn losses_json(losses: &StepLosses) -> Value {
    serde_json::to_value(losses).unwrap_or(Value::Null)
}

/// `micro` (3 scales, 4 iterations each) trained on the CPU and on the device from seed 0:
/// the first iteration's losses must agree, every loss on the device must be finite.
pub fn micro(cx: &CheckContext) -> Result<Map<String, Value>> {
    let config = TrainConfig::preset("micro")?;
    let dataset = stones_dataset(&config, &cx.work.join("micro-data"), 8, 32)?;
    let run = |device: &Device, name: &str| {
        record_training(
            &config,
            &dataset,
            &fresh(&cx.work, name)?,
            device,
            &mut |_| None,
        )
    };
    let cpu = run(&Device::Cpu, "micro-cpu")?;
    let ours = run(&cx.device, "micro-device")?;
    let (first_cpu, first_device) = match (cpu.steps.first(), ours.steps.first()) {
        (Some(c), Some(d)) => (&c.2, &d.2),
        _ => anyhow::bail!("micro training ran no iteration"),
    };
    let mut worst = 0f64;
    for (term, reference) in first_cpu.iter() {
        let value = first_device
            .get(term)
            .with_context(|| format!("the device's first step has no `{}` loss", term.key()))?;
        let scale = f64::from(reference.abs()).max(1e-6);
        worst = worst.max((f64::from(value) - f64::from(reference)).abs() / scale);
    }
    let finite = ours
        .steps
        .iter()
        .all(|(_, _, l)| l.iter().all(|(_, v)| v.is_finite()));
    let mut fields = Map::new();
    fields.insert(
        "ok".into(),
        json!(finite && worst <= FIRST_STEP_TOLERANCE && ours.steps.len() == cpu.steps.len()),
    );
    fields.insert("first_step_max_relative_difference".into(), json!(worst));
    fields.insert("tolerance".into(), json!(FIRST_STEP_TOLERANCE));
    fields.insert("losses_finite".into(), json!(finite));
    fields.insert("iterations".into(), json!(ours.steps.len()));
    fields.insert("seconds_cpu".into(), json!(round(cpu.seconds, 2)));
    fields.insert("seconds_device".into(), json!(round(ours.seconds, 2)));
    if let (Some(c), Some(d)) = (cpu.steps.last(), ours.steps.last()) {
        fields.insert("last_losses_cpu".into(), losses_json(&c.2));
        fields.insert("last_losses_device".into(), losses_json(&d.2));
    }
    Ok(fields)
}

/// The `paper` preset (volumes 40^3 to 126^3, images to 320^2) for `--paper-iterations`
/// iterations at each of its first `--paper-scales` scales: the seconds of the first iteration
/// (which includes the device's warm-up for the scale's shapes; the scale's set-up is not
/// counted) and of the fastest later one.
pub fn paper_iterations(cx: &CheckContext) -> Result<Map<String, Value>> {
    let preset = TrainConfig::preset("paper")?;
    // `run` checked it against the preset's scales.
    let last_scale = cx.paper_scales.unwrap_or(preset.scales());
    let iterations = cx.paper_iterations;
    let config = preset.with_iterations(iterations);
    let dataset = stones_dataset(&config, &cx.work.join("paper-data"), 16, 128)?;
    let record = record_training(
        &config,
        &dataset,
        &fresh(&cx.work, "paper-run")?,
        &cx.device,
        &mut |p| {
            if p.scale == last_scale && p.iteration == iterations {
                Some("the last scale asked for is timed")
            } else if cx.seconds_left() <= 0.0 {
                Some("the budget is spent")
            } else {
                None
            }
        },
    )?;
    let mut scales = Vec::new();
    for n in 1..=last_scale {
        let times: Vec<f64> = record
            .steps
            .iter()
            .filter(|s| s.0 == n)
            .map(|s| s.1)
            .collect();
        let Some(&first) = times.first() else { break };
        let later: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
        let size = |sizes: &[usize]| sizes.get(n - 1).copied();
        let memory = record.memory.iter().find(|m| m.0 == n).map(|m| m.1);
        scales.push(json!({
            "scale": n,
            "volume": size(&config.pyramid.volume_sizes),
            "image": size(&config.pyramid.image_sizes).unwrap_or(config.final_image_size()),
            "first_iteration_s": round(first, 3),
            "iteration_s": later.iter().cloned().reduce(f64::min).map(|s| round(s, 3)),
            "device_memory_mib": memory,
        }));
    }
    let mut fields = Map::new();
    let complete = scales.len() == last_scale;
    fields.insert("ok".into(), json!(complete));
    fields.insert("iterations_per_scale".into(), json!(iterations));
    fields.insert("scales".into(), Value::Array(scales));
    if !complete {
        fields.insert("stopped".into(), json!(record.stopped));
    }
    Ok(fields)
}

/// A `tiny` training (the demo's preset, with its volume fit) on the device, for as long as
/// the budget allows: seconds per scale, and for a run the budget stopped, the iterations done
/// and the whole run's projected seconds.
pub fn tiny(cx: &CheckContext) -> Result<Map<String, Value>> {
    let config = TrainConfig::preset("tiny")?;
    let dataset = stones_dataset(&config, &cx.work.join("tiny-data"), 40, 128)?;
    let record = record_training(
        &config,
        &dataset,
        &fresh(&cx.work, "tiny-run")?,
        &cx.device,
        &mut |_| (cx.seconds_left() <= 0.0).then_some("the budget is spent"),
    )?;
    let done = record.steps.len();
    let mut fields = Map::new();
    fields.insert("ok".into(), json!(done > 0));
    fields.insert("finished".into(), json!(record.stopped.is_none()));
    fields.insert("iterations".into(), json!(done));
    fields.insert("iterations_total".into(), json!(record.total_iterations));
    fields.insert(
        "scale_seconds".into(),
        json!(record
            .scales
            .iter()
            .map(|(n, s)| {
                let mut scale = json!({"scale": n, "seconds": round(*s, 1)});
                if let Some((_, mib)) = record.memory.iter().find(|m| m.0 == *n) {
                    scale["device_memory_mib"] = json!(mib);
                }
                scale
            })
            .collect::<Vec<_>>()),
    );
    fields.insert("training_seconds".into(), json!(round(record.seconds, 1)));
    if let Some(why) = record.stopped {
        fields.insert("stopped".into(), json!(why));
        if done > 0 {
            // Iterations differ in cost by scale, so this is a rough figure.
            let projected = record.seconds * record.total_iterations as f64 / done as f64;
            fields.insert(
                "projected_seconds_at_this_rate".into(),
                json!(round(projected, 0)),
            );
        }
    }
    Ok(fields)
}

/// `work/name`, emptied: a run directory training may start in.
fn fresh(work: &Path, name: &str) -> Result<PathBuf> {
    let dir = work.join(name);
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("emptying {}", dir.display()))?;
    }
    Ok(dir)
}
