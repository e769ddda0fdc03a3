//! The training loop as a [`Trainer`] with named steps: [`Trainer::new`] starts a run or
//! resumes one, [`Trainer::train_scale`] trains the next scale (set-up, iterations, checkpoints,
//! picture), [`Trainer::finish`] fits the reconstruction when asked and hands the model over.

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use candle_core::{Device, Tensor};
use radiance_volume::RadianceVolume;
use rgbd_dataset::{Dataset, DatasetLevel};
use swd_loss::Vgg19;

use super::final_scale::FinalScale;
use super::log::LossLog;
use super::losses::StepLosses;
use super::prepare::{prepare, RunInputs};
use super::reconstruction_fit::fit_reconstruction;
use super::stage::{Stage, CRITIC_PREFIX, VOLUME_CRITIC_PREFIX};
use super::volume_scale::{reconstruction_rmse, VolumeScale};
use super::{Control, Event, Progress, RunOptions};
use crate::checkpoint::{write_config_json, Checkpoint, TrainState};
use crate::config::{settings_that_differ, TrainConfig};
use crate::error::{invalid, Error, Result};
use crate::model::{SinGrav, RECONSTRUCTION_DETAIL_TENSOR};
use crate::noise::step_rng;
use crate::render::ViewRenderer;
use crate::run_dir::RunDir;

/// How a call to [`train`] ended.
pub enum TrainOutcome {
    /// Every scale is trained; the model is ready to sample.
    Finished(Box<SinGrav>),
    /// The observer asked to stop; the run directory holds the last checkpoint.
    Stopped,
}

/// Samples shown in each scale's picture.
const PICTURE_SAMPLES: usize = 4;
/// Views used to measure a reconstruction's error for the next noise amplitude.
const AMPLITUDE_VIEWS: usize = 8;
/// Marks the RNG streams of a scale's set-up and picture (iterations use 0..iterations).
const SETUP_STREAM: usize = usize::MAX;
const PICTURE_STREAM: usize = usize::MAX - 1;

/// Trains SinGRAV on `dataset` (without its held-out views when `config.run.holdout` says so),
/// writing checkpoints, the loss log, `config.json` and pictures into `run_dir`, then fits the
/// reconstruction to the views when `config.schedule.reconstruction_fit_steps` asks for it:
/// [`Trainer::new`], [`Trainer::train_scale`] for every scale left, [`Trainer::finish`].
///
/// With `options.resume`, continues from `run_dir`'s checkpoint (which must have been made with
/// the same configuration, but for `schedule.reconstruction_fit_steps` while that fit has not run: a
/// finished run can be given it later) and ends with the same weights as an uninterrupted run.
/// Without it, refuses a directory that already holds a checkpoint rather than overwrite it.
/// VGG-19 weights the configuration needs (`options.vgg19_weights`) are loaded before anything
/// is written, so a missing or broken file fails at once with [`Error::Weights`].
///
/// On the CPU nothing else is needed ([`crate::runtime::init`] makes it faster). On other
/// devices the critics' gradient penalty is candle's double backward, which needs
/// `CANDLE_GRAD_DO_NOT_DETACH=1` in the environment before the first backward pass
/// ([`crate::runtime::init`] sets it with the `cuda` feature); without it this returns an error
/// there. `observer` sees every iteration and may stop the run.
pub fn train(
    config: &TrainConfig,
    dataset: &Dataset,
    run_dir: &Path,
    options: &RunOptions,
    device: &Device,
    observer: &mut dyn FnMut(&Progress) -> Control,
) -> Result<TrainOutcome> {
    Trainer::new(config, dataset, run_dir, options, device)?.run(observer)
}

/// A training run in progress: the model so far, where training stands, and what the next
/// scale starts from.
///
/// The configuration is the model's ([`SinGrav::config`]): the one the run was started with,
/// checked against the checkpoint's when resumed; the trainer keeps no copy of its own.
pub struct Trainer<'a> {
    /// The training views in the model's cube (the caller's dataset itself when it has no
    /// held-out views, no bounds to move and no depth from a fit).
    dataset: Cow<'a, Dataset>,
    run: RunDir,
    options: RunOptions,
    device: Device,
    vgg: Option<Vgg19>,
    fitted: Option<RadianceVolume>,
    model: SinGrav,
    state: TrainState,
    /// The configuration of the checkpoint resumed from.
    resumed_config: Option<TrainConfig>,
    log: LossLog,
    /// The critics the next scale starts from (checkpoint names).
    previous_critics: HashMap<String, Tensor>,
    /// What a mid-scale resume restores into the scale it resumes.
    restore: Option<HashMap<String, Tensor>>,
}

impl<'a> Trainer<'a> {
    /// Starts the run in `run_dir`, or resumes it (`options.resume`) from its checkpoint, as
    /// [`train`] describes: settles its inputs ([`prepare`], the fits included, without
    /// progress), then [`Trainer::from_inputs`].
    pub fn new(
        config: &TrainConfig,
        dataset: &'a Dataset,
        run_dir: &Path,
        options: &RunOptions,
        device: &Device,
    ) -> Result<Self> {
        let run = RunDir::new(run_dir);
        let inputs = prepare(config, dataset, &run, options, device, &mut |_, _| {})?;
        Self::from_inputs(config, inputs, run_dir, device)
    }

    /// Starts or resumes the run in `run_dir` on inputs [`prepare`] settled for `config`: writes
    /// `config.json` ([`RunDir::config`]) and opens the loss log.
    pub fn from_inputs(
        config: &TrainConfig,
        inputs: RunInputs<'a>,
        run_dir: &Path,
        device: &Device,
    ) -> Result<Self> {
        config.validate()?;
        let run = RunDir::new(run_dir);
        let RunInputs {
            dataset,
            options,
            vgg,
            fitted,
            ..
        } = inputs;
        let training = match config.run.holdout {
            Some(every) => Cow::Owned(dataset.subset(&dataset.holdout_split(every)?.0)?),
            None => dataset,
        };
        let dataset = match &config.run.bounds {
            Some(bounds) => Cow::Owned(training.in_model_cube(bounds)?),
            None => training,
        };
        crate::io::create_dir(run.root())?;
        // A run killed before its first checkpoint has nothing to resume: it starts over.
        let resume = options.resume && run.has_checkpoint();
        let (model, state, saved, resumed_config) = if resume {
            resume_from(&run.checkpoint(), config, device)?
        } else {
            start(config, &dataset, device)?
        };
        write_config_json(config, &run.config())?;
        let log = LossLog::open(&run, resume.then_some((state.scale, state.iteration)))?;
        let previous_critics = saved
            .iter()
            .filter(|(name, _)| {
                name.starts_with(CRITIC_PREFIX) || name.starts_with(VOLUME_CRITIC_PREFIX)
            })
            .map(|(name, t)| (name.clone(), t.clone()))
            .collect();
        let restore = (state.iteration > 0).then_some(saved);
        Ok(Self {
            dataset,
            run,
            options,
            device: device.clone(),
            vgg,
            fitted,
            model,
            state,
            resumed_config,
            log,
            previous_critics,
            restore,
        })
    }

    /// Trains every scale left ([`Trainer::train_scale`]), then [`Trainer::finish`]; what
    /// [`train`] does after [`Trainer::new`].
    pub fn run(mut self, observer: &mut dyn FnMut(&Progress) -> Control) -> Result<TrainOutcome> {
        while !self.scales_done() {
            if self.train_scale(observer)? == Control::Stop {
                return Ok(TrainOutcome::Stopped);
            }
        }
        self.finish(observer)
    }

    /// Whether every scale is trained (the reconstruction fit may still be due:
    /// [`Trainer::finish`]).
    pub fn scales_done(&self) -> bool {
        self.state.finished(self.model.config())
    }

    /// Where training stands.
    pub fn state(&self) -> &TrainState {
        &self.state
    }

    /// Trains the next scale to its end: builds its generator (unless resuming it), runs its
    /// iterations with checkpoints as the configuration's cadence says, writes its picture and
    /// the checkpoint at its end. Returns [`Control::Stop`] when the observer stopped it (the
    /// last checkpoint stays as it was).
    pub fn train_scale(
        &mut self,
        observer: &mut dyn FnMut(&Progress) -> Control,
    ) -> Result<Control> {
        let n = self.state.scale;
        if n > self.model.config().scales() {
            return Err(invalid("scale", "every scale is trained already"));
        }
        let mut setup = step_rng(self.model.config().run.seed, n, SETUP_STREAM);
        let level = self
            .grow_model(n, &mut setup)
            .map_err(|e| located(e, n, "set-up"))?;
        let restore = self.restore.take();
        let inputs = StageInputs {
            dataset: &self.dataset,
            previous_critics: &self.previous_critics,
            fitted: self.fitted.as_ref(),
            vgg: self.vgg.as_ref(),
            depth_norm: self.state.depth_norm,
            device: &self.device,
        };
        let mut stage = stage(&self.model, n, level, inputs, &mut setup)
            .map_err(|e| located(e, n, "set-up"))?;
        let checkpoint_file = self.run.checkpoint();
        if let Some(tensors) = restore {
            stage.parts().restore(
                &tensors,
                self.state.optimizer_steps,
                &checkpoint_file,
                &self.device,
            )?;
        }
        let schedule = self.model.config().scale_schedule(n);
        let mut last_checkpoint = Instant::now();
        while self.state.iteration < schedule.iterations {
            let it = self.state.iteration;
            let started = Instant::now();
            if self.options.poison == Some((n, it)) {
                poison(&self.model, n)?;
            }
            let losses = stage
                .iteration(
                    it >= schedule.reconstruction_only,
                    &mut step_rng(self.model.config().run.seed, n, it),
                )
                .map_err(|e| located(diverged(e, n, it), n, &format!("iteration {it}")))?;
            check_finite(&losses, n, it)?;
            let state = &mut self.state;
            state.current_seconds += started.elapsed().as_secs_f64();
            state.iteration += 1;
            self.log.append(n, it, total_seconds(state), &losses)?;
            let mut progress = progress(
                self.model.config(),
                &self.state,
                (n, self.state.iteration),
                losses,
                self.state.current_seconds,
                Event::Step,
            );
            if observer(&progress) == Control::Stop {
                return Ok(Control::Stop);
            }
            if self.state.iteration < schedule.iterations
                && checkpoint_due(self.model.config(), &self.state, &last_checkpoint)
            {
                save_mid_scale(
                    &checkpoint_file,
                    self.model.config(),
                    &self.state,
                    &self.model,
                    stage.as_mut(),
                )?;
                last_checkpoint = Instant::now();
                progress.event = Event::Checkpoint(checkpoint_file.clone());
                if observer(&progress) == Control::Stop {
                    return Ok(Control::Stop);
                }
            }
        }
        let picture = self.run.scale_picture(n);
        crate::io::create_dir(&self.run.pictures())?;
        let rows = stage
            .picture_rows(
                &mut step_rng(self.model.config().run.seed, n, PICTURE_STREAM),
                PICTURE_SAMPLES,
            )
            .map_err(|e| located(e, n, "pictures"))?;
        crate::picture::write_grid(&picture, &rows)?;
        self.previous_critics = stage.parts().critic_tensors();
        drop(stage);
        let state = &mut self.state;
        state.scale_seconds.push(state.current_seconds);
        state.scale_peak_mib.push(super::peak_memory_mib());
        state.current_seconds = 0.0;
        state.scale = n + 1;
        state.iteration = 0;
        state.optimizer_steps = (0, 0);
        self.save_boundary()?;
        let seconds = self.state.scale_seconds.last().copied().unwrap_or(0.0);
        let done = Event::ScaleDone(picture);
        let progress = progress(
            self.model.config(),
            &self.state,
            (n, schedule.iterations),
            StepLosses::default(),
            seconds,
            done,
        );
        Ok(observer(&progress))
    }

    /// Ends the run once every scale is trained: fits the reconstruction to the views when the
    /// configuration asks for it and it is not fitted yet (after the last scale's checkpoint,
    /// so a run killed during the fit resumes into it), and returns the model.
    pub fn finish(
        mut self,
        observer: &mut dyn FnMut(&Progress) -> Control,
    ) -> Result<TrainOutcome> {
        if !self.scales_done() {
            return Err(invalid(
                "scale",
                format!("scale {} is not trained yet", self.state.scale),
            ));
        }
        let config = self.model.config().clone();
        let last = config.scales();
        let mut progress = progress(
            &config,
            &self.state,
            (last, config.scale_schedule(last).iterations),
            StepLosses::default(),
            0.0,
            Event::ReconstructionFitting,
        );
        if config.schedule.reconstruction_fit_steps > 0
            && self.model.reconstruction_detail().is_none()
        {
            if observer(&progress) == Control::Stop {
                return Ok(TrainOutcome::Stopped);
            }
            let fit = fit_reconstruction(
                &mut self.model,
                &config,
                &self.dataset,
                self.state.depth_norm,
            )?;
            self.save_boundary()?;
            progress.scale_seconds = fit.seconds;
            progress.event = Event::ReconstructionFitted {
                batch_psnr: fit.batch_psnr,
            };
            if observer(&progress) == Control::Stop {
                return Ok(TrainOutcome::Stopped);
            }
        } else if self
            .resumed_config
            .as_ref()
            .is_some_and(|saved| *saved != config)
        {
            // A finished run resumed with another `schedule.reconstruction_fit_steps` and nothing to fit:
            // the checkpoint records the configuration `config.json` now shows.
            self.save_boundary()?;
        }
        Ok(TrainOutcome::Finished(Box::new(self.model)))
    }

    /// Builds scale `n`'s generator (or the upsampler) when the scale starts afresh, its noise
    /// amplitude from the last scale's reconstruction; returns the dataset at a 3D scale's
    /// rendering size.
    fn grow_model(
        &mut self,
        n: usize,
        setup: &mut rand_chacha::ChaCha8Rng,
    ) -> Result<Option<DatasetLevel>> {
        let fresh = self.restore.is_none();
        if n == self.model.config().scales() {
            if fresh {
                self.model.push_upsampler(setup)?;
                self.state.upsampler = true;
            }
            return Ok(None);
        }
        let size = self.model.config().pyramid.image_sizes[n - 1];
        let level = self.dataset.level(size, size, &self.device)?;
        if fresh {
            let amp = noise_amplitude(&self.model, n, &level, self.state.depth_norm)?;
            self.model.push_generator(amp, setup)?;
            self.state.noise_amps.push(amp);
        }
        Ok(Some(level))
    }

    /// Saves the checkpoint at the end of a scale: weights and the finished critics (by
    /// checkpoint name; the next scale's critics start from them).
    fn save_boundary(&self) -> Result<()> {
        let mut tensors = self.model.tensors();
        tensors.extend(
            self.previous_critics
                .iter()
                .map(|(name, t)| (name.clone(), t.clone())),
        );
        save(
            &self.run.checkpoint(),
            self.model.config(),
            self.state.clone(),
            tensors,
        )
    }
}

/// Whether a mid-scale checkpoint is due, by time or by iteration count.
fn checkpoint_due(config: &TrainConfig, state: &TrainState, last_checkpoint: &Instant) -> bool {
    let run = &config.run;
    let by_time =
        run.checkpoint_seconds > 0 && last_checkpoint.elapsed().as_secs() >= run.checkpoint_seconds;
    let by_count =
        run.checkpoint_iterations > 0 && state.iteration.is_multiple_of(run.checkpoint_iterations);
    by_time || by_count
}

/// Progress of scale `n` after `iteration` of its iterations.
fn progress(
    config: &TrainConfig,
    state: &TrainState,
    (n, iteration): (usize, usize),
    losses: StepLosses,
    seconds: f64,
    event: Event,
) -> Progress {
    Progress {
        scale: n,
        scales: config.scales(),
        iteration,
        iterations: config.scale_schedule(n).iterations,
        losses,
        scale_seconds: seconds,
        total_seconds: total_seconds(state),
        event,
    }
}

/// Saves a mid-scale checkpoint: weights, the critics, every optimiser.
fn save_mid_scale(
    path: &Path,
    config: &TrainConfig,
    state: &TrainState,
    model: &SinGrav,
    stage: &mut dyn Stage,
) -> Result<()> {
    let mut tensors = model.tensors();
    let (parts, optimizer_steps) = stage.parts().tensors();
    tensors.extend(parts);
    let mut state = state.clone();
    state.optimizer_steps = optimizer_steps;
    save(path, config, state, tensors)
}

fn save(
    path: &Path,
    config: &TrainConfig,
    state: TrainState,
    tensors: HashMap<String, Tensor>,
) -> Result<()> {
    Checkpoint {
        config: config.clone(),
        state,
        tensors,
    }
    .save(path)
}

/// What a scale's stage is built from besides the model.
struct StageInputs<'t> {
    dataset: &'t Dataset,
    previous_critics: &'t HashMap<String, Tensor>,
    fitted: Option<&'t RadianceVolume>,
    vgg: Option<&'t Vgg19>,
    depth_norm: f32,
    device: &'t Device,
}

/// The stage that trains scale `n` of `model` (its generator built): a 3D scale on `level`, or
/// the upsampler. Its critics start from the last scale's.
fn stage<'m>(
    model: &'m SinGrav,
    n: usize,
    level: Option<DatasetLevel>,
    inputs: StageInputs<'_>,
    setup: &mut rand_chacha::ChaCha8Rng,
) -> Result<Box<dyn Stage + 'm>> {
    let previous_critic = prefixed(inputs.previous_critics, CRITIC_PREFIX);
    let previous_volume_critic = prefixed(inputs.previous_critics, VOLUME_CRITIC_PREFIX);
    let previous = (!previous_critic.is_empty()).then_some(&previous_critic);
    let previous_volume = (!previous_volume_critic.is_empty()).then_some(&previous_volume_critic);
    if let Some(level) = level {
        let scale = VolumeScale::new(model, n, level, inputs.depth_norm, previous, setup)?
            .with_fitted(inputs.fitted, previous_volume, setup)?;
        return Ok(Box::new(scale));
    }
    let size = *model.config().pyramid.image_sizes.last().unwrap_or(&0);
    let coarse = inputs.dataset.level(size, size, inputs.device)?;
    let fine = inputs.dataset.level(2 * size, 2 * size, inputs.device)?;
    Ok(Box::new(FinalScale::new(
        model, coarse, fine, previous, inputs.vgg, setup,
    )?))
}

/// Where a run begins: the model, where training stands, the checkpoint's tensors (empty for a
/// new run) and, resumed, the checkpoint's configuration.
type Begun = (
    SinGrav,
    TrainState,
    HashMap<String, Tensor>,
    Option<TrainConfig>,
);

/// A new run: the model's fixed parts (seeded), nothing trained ([`prepare`] has refused a
/// directory that holds a checkpoint).
fn start(config: &TrainConfig, dataset: &Dataset, device: &Device) -> Result<Begun> {
    let model = SinGrav::new(
        config,
        device,
        &mut step_rng(config.run.seed, 0, SETUP_STREAM),
    )?;
    let state = TrainState {
        scale: 1,
        iteration: 0,
        noise_amps: Vec::new(),
        upsampler: false,
        depth_norm: depth_norm(dataset),
        optimizer_steps: (0, 0),
        scale_seconds: Vec::new(),
        current_seconds: 0.0,
        scale_peak_mib: Vec::new(),
    };
    Ok((model, state, HashMap::new(), None))
}

/// A resumed run: the checkpoint's model, state and tensors, after checking that it was made
/// with `config`.
fn resume_from(checkpoint_file: &Path, config: &TrainConfig, device: &Device) -> Result<Begun> {
    let checkpoint = Checkpoint::load(checkpoint_file, device)?;
    check_same_config(
        &resumable_config(&checkpoint, config),
        config,
        checkpoint_file,
    )?;
    let model = SinGrav::from_tensors(
        config,
        &checkpoint.tensors,
        &checkpoint.state.noise_amps,
        checkpoint.state.upsampler,
        device,
    )
    .map_err(|why| Error::Checkpoint {
        path: checkpoint_file.to_path_buf(),
        why,
    })?;
    Ok((
        model,
        checkpoint.state,
        checkpoint.tensors,
        Some(checkpoint.config),
    ))
}

/// Seconds of training over all scales, including before a resume.
fn total_seconds(state: &TrainState) -> f64 {
    state.scale_seconds.iter().sum::<f64>() + state.current_seconds
}

/// Depth is divided by the farthest a camera can see into the box: its distance from the
/// centre plus the box's half diagonal, so normalised depth stays within [0, 1].
fn depth_norm(dataset: &Dataset) -> f32 {
    let farthest = dataset
        .cameras()
        .iter()
        .map(|c| c.position().length())
        .fold(0.0f32, f32::max);
    farthest + 3f32.sqrt()
}

/// The noise amplitude of a new scale n: the first scale's is fixed; above, SinGAN's rule
/// `factor * RMSE(render(up(V*_{n-1})), x_n)` with `V*_{n-1}` the reconstruction as the last
/// scale left it.
fn noise_amplitude(
    model: &SinGrav,
    n: usize,
    level: &rgbd_dataset::DatasetLevel,
    depth_norm: f32,
) -> Result<f64> {
    let config = model.config();
    if n < 2 {
        return Ok(config.noise.first_amplitude);
    }
    let prev = model
        .generate(&model.reconstruction_noise(n - 1)?)?
        .detach();
    let up = model.upsample_to_scale(&prev, n)?;
    let renderer = ViewRenderer::new(config, config.pyramid.samples[n - 1], depth_norm, false);
    let rmse = reconstruction_rmse(&renderer, &up, level, AMPLITUDE_VIEWS)?;
    Ok(config.noise.amplitude_factor * rmse)
}

/// Errors with [`Error::Diverged`] when a loss of the iteration is not finite.
fn check_finite(losses: &StepLosses, scale: usize, step: usize) -> Result<()> {
    match losses.iter().find(|(_, value)| !value.is_finite()) {
        Some((term, value)) => Err(Error::Diverged {
            scale,
            step,
            what: format!("the {} is {value}", term.describe()),
        }),
        None => Ok(()),
    }
}

/// An iteration's error as [`Error::Diverged`] at scale `n`, iteration `it` when it says that
/// something went non-finite (a gradient, a generated volume the renderer refuses).
fn diverged(error: Error, n: usize, it: usize) -> Error {
    let what = match error {
        Error::NonFiniteGradient { parameter, value } => {
            format!("the gradient of {parameter} is not finite (its sum is {value})")
        }
        Error::Render(volrender::Error::InvalidVolume { count, first, why }) => {
            format!("a generated volume has {count} invalid values, first at {first} ({why})")
        }
        other => return other,
    };
    Error::Diverged {
        scale: n,
        step: it,
        what,
    }
}

/// A computation's error at scale `n` as [`Error::Training`], naming where it happened (a
/// device error says nothing of that itself); errors that name their cause already (a file, a
/// setting, a divergence) pass unchanged.
fn located(error: Error, n: usize, at: &str) -> Error {
    match error {
        Error::Candle(_)
        | Error::Render(_)
        | Error::Gan(_)
        | Error::Swd(_)
        | Error::Volume(_)
        | Error::Metrics(_)
        | Error::Csg(_) => Error::Training {
            scale: n,
            at: at.into(),
            source: Box::new(error),
        },
        other => other,
    }
}

/// The test hook [`RunOptions::poison`]: sets every weight of scale `n`'s generator (or the
/// upsampler) to NaN, as a divergence would.
fn poison(model: &SinGrav, n: usize) -> Result<()> {
    let vars = match model.generator_vars(n) {
        Some(vars) => vars,
        None => model
            .upsampler_vars()
            .ok_or_else(|| invalid("poison", format!("scale {n} has no generator yet")))?,
    };
    for var in vars.all_vars() {
        var.set(&(var.as_tensor() * f64::NAN)?)?;
    }
    Ok(())
}

/// The tensors under `prefix`, with the prefix removed.
fn prefixed(tensors: &HashMap<String, Tensor>, prefix: &str) -> HashMap<String, Tensor> {
    tensors
        .iter()
        .filter_map(|(k, v)| Some((k.strip_prefix(prefix)?.to_string(), v.clone())))
        .collect()
}

/// The configuration a resume must match: the checkpoint's, except that a run whose
/// reconstruction was not fitted to the views yet may be given any `schedule.reconstruction_fit_steps`
/// (the fit runs after every scale, so it can be added to a finished run, or dropped).
fn resumable_config(checkpoint: &Checkpoint, wanted: &TrainConfig) -> TrainConfig {
    let mut config = checkpoint.config.clone();
    if !checkpoint
        .tensors
        .contains_key(RECONSTRUCTION_DETAIL_TENSOR)
    {
        config.schedule.reconstruction_fit_steps = wanted.schedule.reconstruction_fit_steps;
    }
    config
}

/// Errors unless a checkpoint's configuration equals the requested one, naming the settings
/// that differ.
fn check_same_config(saved: &TrainConfig, wanted: &TrainConfig, path: &Path) -> Result<()> {
    if saved == wanted {
        return Ok(());
    }
    Err(Error::Checkpoint {
        path: path.to_path_buf(),
        why: format!(
            "it was made with another configuration; differing (checkpoint against \
             requested): {}",
            settings_that_differ(saved, wanted).join(", ")
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::{diverged, located};
    use crate::error::{invalid, Error};

    /// A device's error (candle's, as a driver's reaches training) names the scale and the
    /// place; errors that name their cause already pass through.
    #[test]
    fn computation_errors_say_where_in_the_run_they_happened() {
        let driver = Error::Candle(candle_core::Error::Msg(
            "DriverError(CUDA_ERROR_INVALID_VALUE, \"invalid argument\")".into(),
        ));
        let err = located(diverged(driver, 4, 0), 4, "iteration 0");
        assert!(matches!(err, Error::Training { scale: 4, .. }), "{err:?}");
        assert!(
            err.to_string()
                .starts_with("scale 4, iteration 0: DriverError(CUDA_ERROR_INVALID_VALUE"),
            "{err}"
        );
        let setting = located(invalid("losses.rgb", "expected >= 0"), 2, "set-up");
        assert!(matches!(setting, Error::Invalid { .. }), "{setting:?}");
        let nan = Error::NonFiniteGradient {
            parameter: "g2.w".into(),
            value: f32::NAN,
        };
        let err = located(diverged(nan, 2, 7), 2, "iteration 7");
        assert!(
            matches!(
                err,
                Error::Diverged {
                    scale: 2,
                    step: 7,
                    ..
                }
            ),
            "{err:?}"
        );
    }
}
