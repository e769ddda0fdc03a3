//! SinGRAV: learning a generative radiance volume from multi-view RGB-D images of a single
//! natural scene (Wang, Chen and Chen).
//!
//! This crate is being built: so far it holds the built-in procedural scenes ([`scenes`]), which
//! give the project training data without any download. The model, training and sampling follow.

pub mod checkpoint;
pub mod config;
pub mod dataset;
mod error;
mod io;
pub mod model;
pub mod noise;
pub mod optim;
pub mod picture;
pub mod render;
pub mod sample;
pub mod scenes;
pub mod train;

pub use config::TrainConfig;
pub use error::{Error, Result};
pub use model::SinGrav;
