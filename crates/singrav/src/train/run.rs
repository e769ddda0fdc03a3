//! The training loop over scales: set-up of each scale, iterations, checkpoints, resume.

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use candle_core::{Device, Tensor};
use radiance_volume::RadianceVolume;

use super::concurrent::CoarserGenerator;
use super::critic::{Critic, VolumeCritic};
use super::final_scale::FinalScale;
use super::fitted::load_fitted;
use super::log::LossLog;
use super::reconstruction_fit::fit_reconstruction;
use super::texture::load_vgg19;
use super::volume_scale::{picture_path, reconstruction_rmse, VolumeScale};
use super::{Control, Event, Progress, RunOptions, StepLosses};
use crate::checkpoint::{write_config_json, Checkpoint, TrainState, CHECKPOINT_FILE, CONFIG_FILE};
use crate::config::TrainConfig;
use crate::dataset::Dataset;
use crate::error::{invalid, Error, Result};
use crate::fit::{fit_volume, FitConfig};
use crate::model::{load_into, var_tensors, SinGrav, RECONSTRUCTION_DETAIL_TENSOR};
use crate::noise::step_rng;
use crate::optim::{Adam, WeightAverage};
use crate::render::ViewRenderer;

/// One scale's training, as the loop drives it.
pub(super) trait Stage {
    /// Runs one iteration (`d_steps` critic steps when `adversarial`, then `g_steps` generator
    /// steps) drawing all randomness from `rng`.
    fn iteration(
        &mut self,
        adversarial: bool,
        rng: &mut rand_chacha::ChaCha8Rng,
    ) -> Result<StepLosses>;
    /// Rows of the scale's picture: real view, reconstruction, then `count` samples.
    fn picture_rows(
        &self,
        rng: &mut rand_chacha::ChaCha8Rng,
        count: usize,
    ) -> Result<Vec<Vec<Tensor>>>;
    /// Ends the scale's training before its picture and checkpoint: generators that keep a
    /// weight average take it.
    fn finish(&mut self) -> Result<()> {
        Ok(())
    }
    /// The critics and the generator's optimiser (for checkpoints).
    fn parts(&mut self) -> StageParts<'_>;
}

/// What a stage trains beside its generator's weights, as a checkpoint saves it.
pub(super) struct StageParts<'a> {
    /// The 2D critic (checkpoint names `d.*`, its optimiser `opt_d.*`).
    pub critic: &'a mut Critic,
    /// The 3D critic, when the run has one (`d3.*`, `opt_d3.*`).
    pub volume_critic: Option<&'a mut VolumeCritic>,
    /// The generator's optimiser (`opt_g.*`).
    pub generator_opt: &'a mut Adam,
    /// The coarser generators training with it (`opt_g{scale}.*`; concurrent training).
    pub coarser_generators: &'a mut [CoarserGenerator],
    /// The optimiser of the scale's reconstruction noise z*_n (`opt_z.*`), when the run
    /// optimises it.
    pub reconstruction_noise_opt: Option<&'a mut Adam>,
    /// The moving average of the training generators' weights (`avg_g.*`), when the run keeps
    /// one.
    pub generator_average: Option<&'a mut WeightAverage>,
}

impl StageParts<'_> {
    /// Sets every optimiser's learning rate: `rate` for the networks, `noise_rate` for the
    /// reconstruction noise.
    fn set_learning_rate(&mut self, rate: f64, noise_rate: f64) {
        self.critic.opt.set_learning_rate(rate);
        if let Some(critic) = self.volume_critic.as_mut() {
            critic.opt.set_learning_rate(rate);
        }
        self.generator_opt.set_learning_rate(rate);
        for coarser in self.coarser_generators.iter_mut() {
            coarser.opt.set_learning_rate(rate * coarser.rate_factor);
        }
        if let Some(opt) = self.reconstruction_noise_opt.as_mut() {
            opt.set_learning_rate(noise_rate);
        }
    }

    /// The critics' weights by checkpoint name (`d.*`, `d3.*`).
    fn critic_tensors(&self) -> HashMap<String, Tensor> {
        let named = |prefix: &str, vars: &candle_nn::VarMap| {
            var_tensors(vars)
                .into_iter()
                .map(|(name, t)| (format!("{prefix}{name}"), t))
                .collect::<Vec<_>>()
        };
        let mut tensors: HashMap<_, _> = named(CRITIC_PREFIX, &self.critic.vars)
            .into_iter()
            .collect();
        if let Some(critic) = &self.volume_critic {
            tensors.extend(named(VOLUME_CRITIC_PREFIX, &critic.vars));
        }
        tensors
    }
}

/// Checkpoint names of the 2D and 3D critics' weights.
const CRITIC_PREFIX: &str = "d.";
const VOLUME_CRITIC_PREFIX: &str = "d3.";
/// Checkpoint name prefix of the reconstruction noise's optimiser.
const NOISE_OPT_PREFIX: &str = "opt_z.";
/// Checkpoint name prefix of the generators' weight average.
const AVERAGE_PREFIX: &str = "avg_g.";

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

/// Trains SinGRAV on `dataset` (without its held-out views when `config.holdout` says so),
/// writing checkpoints, the loss log, `config.json` and pictures into `run_dir`, then fits the
/// reconstruction to the views when `config.reconstruction_fit_steps` asks for it. With
/// `options.resume`, continues from `run_dir`'s checkpoint (which must have been made with the
/// same configuration, but for `reconstruction_fit_steps` while that fit has not run: a finished
/// run can be given it later) and ends with the same weights as an uninterrupted
/// run. Without it, refuses a directory that already holds a checkpoint rather than overwrite
/// it. VGG-19 weights the configuration needs (`options.vgg19_weights`) are loaded before
/// anything is written, so a missing or broken file fails at once with [`Error::Weights`].
///
/// On the CPU nothing else is needed. On other devices the critics' gradient penalty is
/// candle's double backward, which needs `CANDLE_GRAD_DO_NOT_DETACH=1` in the environment
/// before the first backward pass; without it this returns an error there.
/// `observer` sees every iteration and may stop the run.
pub fn train(
    config: &TrainConfig,
    dataset: &Dataset,
    run_dir: &Path,
    options: &RunOptions,
    device: &Device,
    observer: &mut dyn FnMut(&Progress) -> Control,
) -> Result<TrainOutcome> {
    config.validate()?;
    let training_views;
    let dataset = match config.holdout {
        Some(every) => {
            training_views = dataset.subset(&dataset.holdout_split(every)?.0)?;
            &training_views
        }
        None => dataset,
    };
    let checkpoint_file = run_dir.join(CHECKPOINT_FILE);
    if options.resume && !run_dir.exists() {
        return Err(Error::Checkpoint {
            path: checkpoint_file,
            why: "no checkpoint here, nor a run directory (train a model first)".into(),
        });
    }
    let vgg = load_vgg19(config, options.vgg19_weights.as_deref(), device)?;
    let fitted = load_fitted_target(config, options, run_dir, dataset)?;
    let moved;
    let dataset = match &config.bounds {
        Some(bounds) => {
            moved = dataset.in_model_cube(bounds)?;
            &moved
        }
        None => dataset,
    };
    crate::io::create_dir(run_dir)?;
    if let Some((volume, true)) = &fitted {
        volume.save_safetensors(run_dir.join(FITTED_FILE))?;
    }
    let fitted = fitted.map(|(volume, _)| volume);
    // A run killed before its first checkpoint has nothing to resume: it starts over.
    let resume = options.resume && checkpoint_file.exists();
    let mut resumed_config = None;
    let (mut model, mut state, saved) = if resume {
        let checkpoint = Checkpoint::load(&checkpoint_file, device)?;
        check_same_config(
            &resumable_config(&checkpoint, config),
            config,
            &checkpoint_file,
        )?;
        resumed_config = Some(checkpoint.config.clone());
        let model = SinGrav::from_tensors(
            config,
            &checkpoint.tensors,
            &checkpoint.state.noise_amps,
            checkpoint.state.upsampler,
            device,
        )
        .map_err(|why| Error::Checkpoint {
            path: checkpoint_file.clone(),
            why,
        })?;
        (model, checkpoint.state, checkpoint.tensors)
    } else {
        if checkpoint_file.exists() {
            return Err(Error::Checkpoint {
                path: checkpoint_file,
                why: "this run directory already holds a checkpoint; resume it (--resume) or \
                      choose another directory"
                    .into(),
            });
        }
        let model = SinGrav::new(config, device, &mut step_rng(config.seed, 0, SETUP_STREAM))?;
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
        (model, state, HashMap::new())
    };
    write_config_json(config, &run_dir.join(CONFIG_FILE))?;
    let mut log = LossLog::open(run_dir, resume.then_some((state.scale, state.iteration)))?;
    // The critics the next scale starts from (checkpoint names), and the tensors a mid-scale
    // resume restores.
    let mut previous_critics: HashMap<String, Tensor> = saved
        .iter()
        .filter(|(name, _)| {
            name.starts_with(CRITIC_PREFIX) || name.starts_with(VOLUME_CRITIC_PREFIX)
        })
        .map(|(name, t)| (name.clone(), t.clone()))
        .collect();
    let mut restore = (state.iteration > 0).then_some(&saved);
    for n in state.scale..=config.scales() {
        let mut setup = step_rng(config.seed, n, SETUP_STREAM);
        let fresh = restore.is_none();
        let previous_critic = prefixed(&previous_critics, CRITIC_PREFIX);
        let previous_volume_critic = prefixed(&previous_critics, VOLUME_CRITIC_PREFIX);
        let previous = (!previous_critic.is_empty()).then_some(&previous_critic);
        let previous_volume =
            (!previous_volume_critic.is_empty()).then_some(&previous_volume_critic);
        let mut stage: Box<dyn Stage + '_> = if n < config.scales() {
            let size = config.image_sizes[n - 1];
            let level = dataset.level(size, size, device)?;
            if fresh {
                // The reconstruction V*_{n-1} as the last scale left it sets the noise amplitude.
                let prev_reconstruction = if n >= 2 {
                    Some(
                        model
                            .generate(&model.reconstruction_noise(n - 1)?)?
                            .detach(),
                    )
                } else {
                    None
                };
                let amp = noise_amplitude(
                    &model,
                    n,
                    &level,
                    state.depth_norm,
                    prev_reconstruction.as_ref(),
                )?;
                model.push_generator(amp, &mut setup)?;
                state.noise_amps.push(amp);
            }
            Box::new(
                VolumeScale::new(&model, n, level, state.depth_norm, previous, &mut setup)?
                    .with_fitted(fitted.as_ref(), previous_volume, &mut setup)?,
            )
        } else {
            if fresh {
                model.push_upsampler(&mut setup)?;
                state.upsampler = true;
            }
            let size = *config.image_sizes.last().unwrap_or(&0);
            let coarse = dataset.level(size, size, device)?;
            let fine = dataset.level(2 * size, 2 * size, device)?;
            Box::new(FinalScale::new(
                &model,
                coarse,
                fine,
                previous,
                vgg.as_ref(),
                &mut setup,
            )?)
        };
        if let Some(tensors) = restore.take() {
            restore_stage(stage.as_mut(), tensors, &state, &checkpoint_file, device)?;
        }
        let mut last_checkpoint = Instant::now();
        let schedule = config.scale_schedule(n);
        while state.iteration < schedule.iterations {
            let it = state.iteration;
            let started = Instant::now();
            if options.poison == Some((n, it)) {
                poison(&model, n)?;
            }
            // A function of the iteration alone, so a resumed run decays where it would have.
            let learning_rate = config.learning_rate_at(n, it);
            let noise_rate = config.reconstruction_noise_lr_at(n, it);
            stage.parts().set_learning_rate(learning_rate, noise_rate);
            let losses = stage
                .iteration(
                    it >= schedule.reconstruction_only,
                    &mut step_rng(config.seed, n, it),
                )
                .map_err(|e| diverged(e, n, it))?;
            check_finite(&losses, n, it)?;
            state.current_seconds += started.elapsed().as_secs_f64();
            state.iteration += 1;
            log.append(n, it, total_seconds(&state), &losses)?;
            let mut progress = Progress {
                scale: n,
                scales: config.scales(),
                iteration: state.iteration,
                iterations: schedule.iterations,
                losses,
                scale_seconds: state.current_seconds,
                total_seconds: total_seconds(&state),
                event: Event::Step,
            };
            if observer(&progress) == Control::Stop {
                return Ok(TrainOutcome::Stopped);
            }
            let due_by_time = config.checkpoint_seconds > 0
                && last_checkpoint.elapsed().as_secs() >= config.checkpoint_seconds;
            let due_by_count = config.checkpoint_iterations > 0
                && state.iteration % config.checkpoint_iterations == 0;
            if state.iteration < schedule.iterations && (due_by_time || due_by_count) {
                save(
                    &checkpoint_file,
                    config,
                    &state,
                    &model,
                    Some(stage.as_mut()),
                )?;
                last_checkpoint = Instant::now();
                progress.event = Event::Checkpoint(checkpoint_file.clone());
                if observer(&progress) == Control::Stop {
                    return Ok(TrainOutcome::Stopped);
                }
            }
        }
        stage.finish()?;
        let picture = picture_path(run_dir, n);
        crate::io::create_dir(picture.parent().unwrap_or(run_dir))?;
        let rows = stage.picture_rows(
            &mut step_rng(config.seed, n, PICTURE_STREAM),
            PICTURE_SAMPLES,
        )?;
        crate::picture::write_grid(&picture, &rows)?;
        previous_critics = stage.parts().critic_tensors();
        drop(stage);
        state.scale_seconds.push(state.current_seconds);
        state.scale_peak_mib.push(super::peak_memory_mib());
        state.current_seconds = 0.0;
        state.scale = n + 1;
        state.iteration = 0;
        state.optimizer_steps = (0, 0);
        save_boundary(&checkpoint_file, config, &state, &model, &previous_critics)?;
        let progress = Progress {
            scale: n,
            scales: config.scales(),
            iteration: schedule.iterations,
            iterations: schedule.iterations,
            losses: StepLosses::default(),
            scale_seconds: *state.scale_seconds.last().unwrap_or(&0.0),
            total_seconds: total_seconds(&state),
            event: Event::ScaleDone(picture),
        };
        if observer(&progress) == Control::Stop {
            return Ok(TrainOutcome::Stopped);
        }
    }
    // After the last scale's checkpoint, so a run killed during the fit resumes into it.
    let last = config.scales();
    let iterations = config.scale_schedule(last).iterations;
    let mut progress = Progress {
        scale: last,
        scales: last,
        iteration: iterations,
        iterations,
        losses: StepLosses::default(),
        scale_seconds: 0.0,
        total_seconds: total_seconds(&state),
        event: Event::ReconstructionFitting,
    };
    if config.reconstruction_fit_steps > 0 && model.reconstruction_detail().is_none() {
        if observer(&progress) == Control::Stop {
            return Ok(TrainOutcome::Stopped);
        }
        let fit = fit_reconstruction(&mut model, config, dataset, state.depth_norm)?;
        save_boundary(&checkpoint_file, config, &state, &model, &previous_critics)?;
        progress.scale_seconds = fit.seconds;
        progress.event = Event::ReconstructionFitted {
            batch_psnr: fit.batch_psnr,
        };
        if observer(&progress) == Control::Stop {
            return Ok(TrainOutcome::Stopped);
        }
    } else if resumed_config.is_some_and(|saved| saved != *config) {
        // A finished run resumed with another `reconstruction_fit_steps` and nothing to fit:
        // the checkpoint records the configuration `config.json` now shows.
        save_boundary(&checkpoint_file, config, &state, &model, &previous_critics)?;
    }
    Ok(TrainOutcome::Finished(Box::new(model)))
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
/// `factor * RMSE(render(up(V*_{n-1})), x_n)` with `prev` the reconstruction `V*_{n-1}`.
fn noise_amplitude(
    model: &SinGrav,
    n: usize,
    level: &crate::dataset::DatasetLevel,
    depth_norm: f32,
    prev: Option<&Tensor>,
) -> Result<f64> {
    let config = model.config();
    let Some(prev) = prev else {
        return Ok(config.noise_amp_first);
    };
    let up = model.upsample_to_scale(prev, n)?;
    let renderer = ViewRenderer::new(config, config.samples[n - 1], depth_norm, false);
    Ok(config.noise_amp_factor * reconstruction_rmse(&renderer, &up, level, AMPLITUDE_VIEWS)?)
}

fn check_finite(losses: &StepLosses, scale: usize, step: usize) -> Result<()> {
    let terms = [
        ("critic loss", losses.critic),
        ("gradient penalty", losses.penalty),
        ("adversarial loss", losses.adversarial),
        ("colour reconstruction", Some(losses.color)),
        ("depth reconstruction", losses.depth),
        ("SWD loss", losses.swd),
        ("fitted-volume comparison", losses.fitted),
        ("opacity reconstruction", losses.opacity),
        ("colour distribution", losses.colour_distribution),
        ("chroma distribution", losses.chroma_distribution),
        ("height profile", losses.height_profile),
        ("binary-opacity prior", losses.opacity_binary),
        ("opacity distribution", losses.opacity_distribution),
        ("3D critic loss", losses.volume_critic),
        ("3D critic's gradient penalty", losses.volume_penalty),
        ("3D adversarial loss", losses.volume_adversarial),
    ];
    for (what, value) in terms {
        if let Some(value) = value.filter(|v| !v.is_finite()) {
            return Err(Error::Diverged {
                scale,
                step,
                what: format!("the {what} is {value}"),
            });
        }
    }
    Ok(())
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

/// The run's copy of the fitted volume, so that a resumed run compares with what it started with.
const FITTED_FILE: &str = "fitted.safetensors";

/// The fitted volume a configuration with `lambda_fitted > 0` trains against, and whether it is
/// new to the run (to be copied into it): the one `options` names, else on resume the run's
/// copy, else a fit of `dataset` (the training views, in the scene's coordinates) made now as
/// [`FitConfig::for_training`] says. Errors when one is given and not needed.
fn load_fitted_target(
    config: &TrainConfig,
    options: &RunOptions,
    run_dir: &Path,
    dataset: &Dataset,
) -> Result<Option<(RadianceVolume, bool)>> {
    let copy = run_dir.join(FITTED_FILE);
    if config.lambda_fitted == 0.0 && config.lambda_volume_critic == 0.0 {
        return match &options.fitted_volume {
            Some(path) => Err(invalid(
                "fitted volume",
                format!(
                    "{} was given but the configuration's lambda_fitted and \
                     lambda_volume_critic are 0; set a positive weight to train against it",
                    path.display()
                ),
            )),
            None => Ok(None),
        };
    }
    let (path, new) = match &options.fitted_volume {
        Some(path) => (path.clone(), *path != copy),
        None if options.resume && copy.exists() => (copy, false),
        None => {
            let all: Vec<usize> = (0..dataset.len()).collect();
            let fitted = fit_volume(dataset, &all, &FitConfig::for_training(config), &mut |_| {})?;
            return Ok(Some((fitted.volume, true)));
        }
    };
    let cube = config
        .bounds
        .map_or(radiance_volume::Aabb::CUBE, |bounds| bounds.cube());
    Ok(Some((load_fitted(&path, cube)?, new)))
}

/// The tensors under `prefix`, with the prefix removed.
fn prefixed(tensors: &HashMap<String, Tensor>, prefix: &str) -> HashMap<String, Tensor> {
    tensors
        .iter()
        .filter_map(|(k, v)| Some((k.strip_prefix(prefix)?.to_string(), v.clone())))
        .collect()
}

/// Saves a mid-scale checkpoint: weights, the critic, both optimisers.
fn save(
    path: &Path,
    config: &TrainConfig,
    state: &TrainState,
    model: &SinGrav,
    stage: Option<&mut dyn Stage>,
) -> Result<()> {
    let mut tensors = model.tensors();
    let mut state = state.clone();
    if let Some(stage) = stage {
        let parts = stage.parts();
        tensors.extend(parts.critic_tensors());
        let (g_state, g_steps) = parts.generator_opt.state("opt_g.");
        let (d_state, d_steps) = parts.critic.opt.state("opt_d.");
        tensors.extend(g_state);
        tensors.extend(d_state);
        for coarser in parts.coarser_generators.iter() {
            // It steps with the scale's generator, so `g_steps` counts its steps too.
            tensors.extend(coarser.opt.state(&coarser.checkpoint_prefix()).0);
        }
        if let Some(opt) = &parts.reconstruction_noise_opt {
            // It steps with the scale's generator too.
            tensors.extend(opt.state(NOISE_OPT_PREFIX).0);
        }
        if let Some(average) = &parts.generator_average {
            tensors.extend(average.state(AVERAGE_PREFIX));
        }
        if let Some(critic) = &parts.volume_critic {
            // It steps with the 2D critic, so `d_steps` counts its steps too.
            tensors.extend(critic.opt.state("opt_d3.").0);
        }
        state.optimizer_steps = (g_steps, d_steps);
    }
    Checkpoint {
        config: config.clone(),
        state,
        tensors,
    }
    .save(path)
}

/// Saves the checkpoint at the end of a scale: weights and the finished critics (by checkpoint
/// name; the next scale's critics start from them).
fn save_boundary(
    path: &Path,
    config: &TrainConfig,
    state: &TrainState,
    model: &SinGrav,
    critics: &HashMap<String, Tensor>,
) -> Result<()> {
    let mut tensors = model.tensors();
    tensors.extend(critics.iter().map(|(name, t)| (name.clone(), t.clone())));
    Checkpoint {
        config: config.clone(),
        state: state.clone(),
        tensors,
    }
    .save(path)
}

/// Restores a mid-scale stage's critic and optimisers from a checkpoint.
fn restore_stage(
    stage: &mut dyn Stage,
    tensors: &HashMap<String, Tensor>,
    state: &TrainState,
    path: &Path,
    device: &Device,
) -> Result<()> {
    let fail = |why: String| Error::Checkpoint {
        path: path.to_path_buf(),
        why,
    };
    let parts = stage.parts();
    load_into(&parts.critic.vars, tensors, CRITIC_PREFIX, device).map_err(fail)?;
    let (g_steps, d_steps) = state.optimizer_steps;
    parts
        .generator_opt
        .restore(tensors, "opt_g.", g_steps)
        .map_err(fail)?;
    for coarser in parts.coarser_generators.iter_mut() {
        let prefix = coarser.checkpoint_prefix();
        coarser
            .opt
            .restore(tensors, &prefix, g_steps)
            .map_err(fail)?;
    }
    if let Some(opt) = parts.reconstruction_noise_opt {
        opt.restore(tensors, NOISE_OPT_PREFIX, g_steps)
            .map_err(fail)?;
    }
    if let Some(average) = parts.generator_average {
        average.restore(tensors, AVERAGE_PREFIX).map_err(fail)?;
    }
    parts
        .critic
        .opt
        .restore(tensors, "opt_d.", d_steps)
        .map_err(fail)?;
    if let Some(critic) = parts.volume_critic {
        load_into(&critic.vars, tensors, VOLUME_CRITIC_PREFIX, device).map_err(fail)?;
        critic
            .opt
            .restore(tensors, "opt_d3.", d_steps)
            .map_err(fail)?;
    }
    Ok(())
}

/// The configuration a resume must match: the checkpoint's, except that a run whose
/// reconstruction was not fitted to the views yet may be given any `reconstruction_fit_steps`
/// (the fit runs after every scale, so it can be added to a finished run, or dropped).
fn resumable_config(checkpoint: &Checkpoint, wanted: &TrainConfig) -> TrainConfig {
    if checkpoint
        .tensors
        .contains_key(RECONSTRUCTION_DETAIL_TENSOR)
    {
        checkpoint.config.clone()
    } else {
        TrainConfig {
            reconstruction_fit_steps: wanted.reconstruction_fit_steps,
            ..checkpoint.config.clone()
        }
    }
}

/// Errors unless a checkpoint's configuration equals the requested one, naming the fields that
/// differ.
fn check_same_config(saved: &TrainConfig, wanted: &TrainConfig, path: &Path) -> Result<()> {
    if saved == wanted {
        return Ok(());
    }
    let as_map = |c: &TrainConfig| match serde_json::to_value(c) {
        Ok(serde_json::Value::Object(fields)) => fields,
        _ => serde_json::Map::new(),
    };
    let (a, b) = (as_map(saved), as_map(wanted));
    // Over the fields of both: an optional field left out of one of them differs too.
    let names: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let value = |fields: &serde_json::Map<String, serde_json::Value>, k: &str| {
        fields.get(k).cloned().unwrap_or_default()
    };
    let differing: Vec<String> = names
        .into_iter()
        .filter(|k| a.get(k.as_str()) != b.get(k.as_str()))
        .map(|k| {
            format!(
                "{k} (checkpoint {}, requested {})",
                value(&a, k),
                value(&b, k)
            )
        })
        .collect();
    Err(Error::Checkpoint {
        path: path.to_path_buf(),
        why: format!(
            "it was made with another configuration; differing: {}",
            differing.join(", ")
        ),
    })
}
