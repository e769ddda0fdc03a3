//! What a run trains on besides its configuration, settled before its first scale: the VGG-19
//! weights its texture loss may need, the views' depth rendered from a fit of them without
//! depth (`run.depth_from_fit`), and the volume its 3D comparisons train against
//! ([`TrainConfig::compares_with_fit`]). Each fit is made once and kept in the run's directory,
//! where a resumed run finds it. [`prepare`] is what [`Trainer::new`](super::Trainer::new)
//! runs first; a caller that shows the fits' progress runs it itself and hands the result to
//! [`Trainer::from_inputs`](super::Trainer::from_inputs).

use std::borrow::Cow;
use std::path::PathBuf;

use candle_core::Device;
use radiance_volume::{Aabb, RadianceVolume};
use rgbd_dataset::{Dataset, DepthCoverage, DepthKind, SceneBounds};
use swd_loss::Vgg19;
use volume_fit::{fit_volume, FitBudget, FitProgress, FittedVolume};

use super::fitted::{fit_training_target, load_fitted};
use super::texture::load_vgg19;
use super::RunOptions;
use crate::config::TrainConfig;
use crate::error::{invalid, Error, Result};
use crate::run_dir::RunDir;

/// A fit a run makes of its views before training.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum RunFit {
    /// The fit without depth whose rendered depth a run with `run.depth_from_fit` trains on
    /// ([`TrainConfig::depth_fit_config`]).
    DepthSource,
    /// The volume the 3D comparisons train against ([`TrainConfig::fit_config`]).
    Target,
}

/// A fit [`prepare`] made (rather than found in the run's directory or was given).
#[derive(Debug, Clone, PartialEq)]
pub struct FitMade {
    /// Which fit.
    pub fit: RunFit,
    /// Its grid's edge in voxels.
    pub size: usize,
    /// Seconds it took.
    pub seconds: f64,
    /// Where the run keeps it.
    pub path: PathBuf,
}

/// A run's inputs, settled ([`prepare`]).
pub struct RunInputs<'a> {
    /// The dataset the run trains on: the caller's, or with `run.depth_from_fit` the same views
    /// with depth from the fit.
    pub dataset: Cow<'a, Dataset>,
    /// The options, with the fits the run uses named.
    pub options: RunOptions,
    /// The VGG-19 weights, when the configuration's texture loss compares their features.
    pub vgg: Option<Vgg19>,
    /// The volume the 3D comparisons train against, when the configuration has any.
    pub fitted: Option<RadianceVolume>,
    /// With `run.depth_from_fit`: the foreground pixels, and those the fit leaves too thin to
    /// give depth (left out of the depth loss).
    pub depth_coverage: Option<DepthCoverage>,
    /// The fits made now, in the order they were made.
    pub made: Vec<FitMade>,
}

/// Settles what a run of `config` in `run` trains on, before anything is written but the fits:
/// loads the VGG-19 weights the configuration needs (a missing or broken file fails here, with
/// nothing written), then makes the fits it needs, each unless `options` names one or a
/// resumed run has its copy: with `run.depth_from_fit` a fit of the training views without
/// depth, whose depth the dataset takes ([`Dataset::with_depth_from`]); when the configuration
/// compares with a fitted volume, that fit ([`fit_training_target`]). Fits are written into the
/// run's directory. `observer` sees their progress.
///
/// Errors as [`Trainer::new`](super::Trainer::new) does before training: an invalid
/// configuration, depth supervision on a dataset without depth maps, a resumed run without a
/// directory, a new run into a directory that holds a checkpoint, and a fitted volume given to
/// a configuration that compares with none.
///
/// ```no_run
/// use singrav::train::{prepare, Trainer, RunOptions};
/// use singrav::{RunDir, TrainConfig};
/// let config = TrainConfig::preset("tiny")?.with(|c| c.run.depth_from_fit = true);
/// let data = rgbd_dataset::Dataset::load("data/photos".as_ref(), config.rendering.background)?;
/// let run = RunDir::new("runs/photos");
/// let device = candle_core::Device::Cpu;
/// let inputs = prepare(&config, &data, &run, &RunOptions::default(), &device, &mut |fit, p| {
///     eprintln!("{fit:?}: step {}, {:.0}% of the budget", p.step, 100.0 * p.fraction);
/// })?;
/// let trainer = Trainer::from_inputs(&config, inputs, run.root(), &device)?;
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn prepare<'a>(
    config: &TrainConfig,
    dataset: &'a Dataset,
    run: &RunDir,
    options: &RunOptions,
    device: &Device,
    observer: &mut dyn FnMut(RunFit, &FitProgress),
) -> Result<RunInputs<'a>> {
    config.validate()?;
    if config.reads_depth_maps() && dataset.depth_kind() == DepthKind::None {
        return Err(invalid(
            "ablations.use_depth",
            "the dataset has no depth maps (depth_kind none): train without depth \
             (ablations.use_depth false) or with depth from a fit of the views \
             (run.depth_from_fit)",
        ));
    }
    check_directory(run, options)?;
    let vgg = load_vgg19(config, options.vgg19_weights.as_deref(), device)?;
    let mut options = options.clone();
    let mut made = Vec::new();
    let (dataset, depth_coverage) = if config.run.depth_from_fit {
        let source = match settled_fit(RunFit::DepthSource, config, run, &mut options)? {
            Some(volume) => volume,
            None => {
                let mut fit_config = config.depth_fit_config();
                if let Some(steps) = options.depth_fit_steps {
                    fit_config.budget = FitBudget::Steps(steps);
                }
                let views = training_views(config, dataset)?;
                let fitted = fit_volume(dataset, &views, &fit_config, &mut |p| {
                    observer(RunFit::DepthSource, p);
                })?;
                keep(RunFit::DepthSource, fitted, run, &mut made)?
            }
        };
        let (with_depth, coverage) = dataset.with_depth_from(&source)?;
        (Cow::Owned(with_depth), Some(coverage))
    } else {
        (Cow::Borrowed(dataset), None)
    };
    let fitted = if config.compares_with_fit() {
        Some(
            match settled_fit(RunFit::Target, config, run, &mut options)? {
                Some(volume) => volume,
                None => {
                    let steps = options.fit_steps;
                    let fitted = fit_training_target(config, &dataset, steps, &mut |p| {
                        observer(RunFit::Target, p);
                    })?;
                    keep(RunFit::Target, fitted, run, &mut made)?
                }
            },
        )
    } else if let Some(path) = &options.fitted_volume {
        return Err(invalid(
            "fitted volume",
            format!(
                "{} was given but the configuration's losses.fitted and losses.volume_critic \
                 are 0; set a positive weight to train against it",
                path.display()
            ),
        ));
    } else {
        None
    };
    Ok(RunInputs {
        dataset,
        options,
        vgg,
        fitted,
        depth_coverage,
        made,
    })
}

/// Errors where a run cannot start in `run`: resumed without a directory, or new where a
/// checkpoint is (it would be overwritten).
fn check_directory(run: &RunDir, options: &RunOptions) -> Result<()> {
    if options.resume && !run.root().exists() {
        return Err(Error::Checkpoint {
            path: run.checkpoint(),
            why: "no checkpoint here, nor a run directory (train a model first)".into(),
        });
    }
    if !options.resume && run.has_checkpoint() {
        return Err(Error::Checkpoint {
            path: run.checkpoint(),
            why: "this run directory already holds a checkpoint; resume it (--resume) or \
                  choose another directory"
                .into(),
        });
    }
    Ok(())
}

/// The fit `fit` when there is one already: the one `options` names (copied into the run's
/// directory, so that a resumed run finds it), else a resumed run's copy (then named in
/// `options`); `None` when it is still to be made.
fn settled_fit(
    fit: RunFit,
    config: &TrainConfig,
    run: &RunDir,
    options: &mut RunOptions,
) -> Result<Option<RadianceVolume>> {
    let copy = kept_at(fit, run);
    let given = match fit {
        RunFit::DepthSource => &mut options.depth_fit,
        RunFit::Target => &mut options.fitted_volume,
    };
    if given.is_none() && options.resume && copy.is_file() {
        *given = Some(copy.clone());
    }
    let Some(path) = given.clone() else {
        return Ok(None);
    };
    let volume = match fit {
        RunFit::DepthSource => RadianceVolume::load_safetensors(&path)?,
        RunFit::Target => load_fitted(&path, model_cube(config))?,
    };
    if path != copy {
        crate::io::create_dir(run.root())?;
        volume.save_safetensors(&copy)?;
    }
    Ok(Some(volume))
}

/// Where the run keeps fit `fit`.
fn kept_at(fit: RunFit, run: &RunDir) -> PathBuf {
    match fit {
        RunFit::DepthSource => run.depth_fit(),
        RunFit::Target => run.fitted(),
    }
}

/// Writes a fit just made into the run's directory and records it.
fn keep(
    fit: RunFit,
    fitted: FittedVolume,
    run: &RunDir,
    made: &mut Vec<FitMade>,
) -> Result<RadianceVolume> {
    let path = kept_at(fit, run);
    crate::io::create_dir(run.root())?;
    fitted.volume.save_safetensors(&path)?;
    made.push(FitMade {
        fit,
        size: fitted.volume.dims().w,
        seconds: fitted.seconds,
        path,
    });
    Ok(fitted.volume)
}

/// The views of `dataset` a run of `config` trains on: all but those `run.holdout` keeps out.
pub(super) fn training_views(config: &TrainConfig, dataset: &Dataset) -> Result<Vec<usize>> {
    Ok(match config.run.holdout {
        Some(every) => dataset.holdout_split(every)?.0,
        None => (0..dataset.len()).collect(),
    })
}

/// The model's cube in the scene's coordinates: `[-1, 1]^3`, or the cube of `run.bounds`.
fn model_cube(config: &TrainConfig) -> Aabb {
    config.run.bounds.map_or(Aabb::CUBE, |bounds| bounds.cube())
}

/// How far past the model's cube `[-1, 1]^3` a scene may reach before [`beyond_the_cube`]
/// reports it (the depth maps' box has a 5% margin; the built-in scenes' reach 1.09).
const CUBE_SLACK: f32 = 1.25;

/// The box the depth maps show ([`Dataset::auto_bounds`]) when it reaches beyond the model's
/// cube `[-1, 1]^3` on some axis (with a little slack): trained without `run.bounds`, such a
/// scene would be cut off or squeezed. `None` when it lies inside, or the dataset has nothing to
/// measure it by.
///
/// ```no_run
/// let data = rgbd_dataset::Dataset::load("data/mine".as_ref(), [1.0; 3])?;
/// if let Some(seen) = singrav::train::beyond_the_cube(&data) {
///     eprintln!("the scene spans {seen}: give run.bounds (data.auto_bounds()?)");
/// }
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn beyond_the_cube(dataset: &Dataset) -> Option<SceneBounds> {
    let seen = dataset.auto_bounds().ok()?;
    seen.min
        .iter()
        .chain(&seen.max)
        .any(|v| v.abs() > CUBE_SLACK)
        .then_some(seen)
}
