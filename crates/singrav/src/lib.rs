//! SinGRAV: learning a generative radiance volume from multi-view RGB-D images of a single
//! natural scene (Wang, Chen and Chen).
//!
//! The datasets it learns from and the built-in scenes are [`rgbd_dataset`]'s; the metrics it is
//! judged by, [`scene_metrics`]'s; the direct fit it can compare with, [`volume_fit`]'s.
//!
//! - [`export`]: volumes for tools that interpolate physical density, on finer grids.
//! - [`TrainConfig`]: the presets ([`TrainConfig::PRESETS`]) and ablation switches.
//! - [`SinGrav`] ([`model`]): the pyramid of 3D generators and the 2D upsampler.
//! - [`train::train`]: coarse-to-fine training with checkpoints, resume and a loss log.
//! - [`eval::evaluate`]: every quality number of a trained model against its dataset.
//! - [`runtime::init`]: the process-wide settings that make training fast; call it first.
//! - [`sample`]: new scenes from a trained model; [`applications`]: editing, harmonisation and
//!   animation; [`RunDir`]: the files of a training run.
//!
//! ```no_run
//! use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
//! use rgbd_dataset::scenes::StandingStones;
//! use singrav::train::{train, Control, RunOptions, TrainOutcome};
//! use singrav::TrainConfig;
//! let dir = std::path::Path::new("data/stones");
//! write_dataset(&StandingStones::new(0), dir, &DatasetSpec::default())?;
//! let config = TrainConfig::preset("tiny")?;
//! let data = Dataset::load(dir, config.rendering.background)?;
//! let device = candle_core::Device::Cpu;
//! let outcome = train(&config, &data, "runs/stones".as_ref(), &RunOptions::default(), &device, &mut |_| Control::Continue)?;
//! if let TrainOutcome::Finished(model) = outcome {
//!     let cameras = model.showcase_cameras(3)?;
//!     let scene = model.sample(&mut rand::rng(), &cameras)?;
//!     // Physical density per voxel, 3x finer: other tools then render `tiny`'s
//!     // post-activated edges as volgen does (`scene.volume` is the model's own grid).
//!     model.to_physical_upsampled(&scene.raw, 3)?.save_safetensors("scene.safetensors")?;
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod active_set;
pub mod applications;
pub mod checkpoint;
pub mod config;
mod error;
pub mod eval;
pub mod export;
pub mod extent;
mod io;
pub mod model;
pub mod noise;
pub mod optim;
pub mod picture;
pub mod render;
mod run_dir;
pub mod runtime;
pub mod sample;
pub mod train;

pub use config::{ScaleSchedule, ScaleViews, SwdFeatures, TrainConfig};
pub use error::{Error, Result};
pub use model::SinGrav;
pub use run_dir::RunDir;

/// The types most users of this crate need, for `use singrav::prelude::*;`.
pub mod prelude {
    pub use crate::train::{train, RunOptions, Trainer};
    pub use crate::{RunDir, SinGrav, TrainConfig};
}

/// The README's examples, compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
