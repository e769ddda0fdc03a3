//! SinGRAV: learning a generative radiance volume from multi-view RGB-D images of a single
//! natural scene (Wang, Chen and Chen).
//!
//! - [`scenes`]: built-in procedural scenes (stones, mushrooms, islands), so the project needs
//!   no download; [`dataset`] renders them into, and loads, NeRF-style RGB-D datasets.
//! - [`export`]: volumes for tools that interpolate physical density, on finer grids.
//! - [`fit`]: a direct fit of one radiance volume to a dataset (no networks), in about a minute.
//! - [`TrainConfig`]: presets (`paper`, `small`, `tiny`, `micro`) and ablation switches.
//! - [`SinGrav`] ([`model`]): the pyramid of 3D generators and the 2D upsampler.
//! - [`train::train`]: coarse-to-fine training with checkpoints, resume and a loss log.
//! - [`sample`]: new scenes from a trained model; [`applications`]: editing, harmonisation and
//!   animation; [`metrics`]: Diversity-MV, SIFID-MV and weights-free quality numbers (PSNR, SSIM,
//!   depth RMSE, patch and colour SWD, floaters).
//!
//! ```no_run
//! use singrav::dataset::{write_dataset, Dataset, DatasetSpec};
//! use singrav::scenes::StandingStones;
//! use singrav::train::{train, Control, RunOptions, TrainOutcome};
//! use singrav::TrainConfig;
//! let dir = std::path::Path::new("data/stones");
//! write_dataset(&StandingStones::new(0), dir, &DatasetSpec::default())?;
//! let config = TrainConfig::preset("tiny")?;
//! let data = Dataset::load(dir, config.background)?;
//! let device = candle_core::Device::Cpu;
//! let outcome = train(&config, &data, "runs/stones".as_ref(), &RunOptions::default(), &device, &mut |_| Control::Continue)?;
//! if let TrainOutcome::Finished(model) = outcome {
//!     let cameras = singrav::sample::showcase_cameras(3, model.render_size())?;
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
pub mod dataset;
mod dilate;
mod error;
pub mod export;
pub mod fit;
mod io;
pub mod metrics;
pub mod model;
pub mod noise;
pub mod optim;
pub mod picture;
pub mod render;
pub mod sample;
pub mod scenes;
pub mod train;

pub use config::{ScaleSchedule, ScaleViews, SwdFeatures, TrainConfig};
pub use error::{Error, Result};
pub use model::SinGrav;
