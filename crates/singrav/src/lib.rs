//! SinGRAV: learning a generative radiance volume from multi-view RGB-D images of a single
//! natural scene (Wang, Chen and Chen).
//!
//! This crate is being built: so far it holds the built-in procedural scenes ([`scenes`]), which
//! give the project training data without any download. The model, training and sampling follow.

pub mod scenes;
