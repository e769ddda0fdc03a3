//! `--to-capture DATASET` of `export` and `mesh`: a volume made in an imported dataset's frame
//! (a sample of a model trained on it, a fit of it) taken back to the frame of the capture it
//! was imported from, by the inverse of the similarity `volgen import` recorded
//! (`volgen_import.capture_to_dataset`).

use std::path::Path;

use anyhow::{Context, Result};
use glam::{DMat3, DMat4};
use radiance_volume::RadianceVolume;

/// The map from a dataset's frame to its capture's.
#[derive(Debug, Clone, Copy)]
pub struct CaptureFrame {
    /// Dataset coordinates to capture coordinates (a similarity).
    pub map: DMat4,
    /// The capture's length of one unit of the dataset's.
    pub length: f64,
}

impl CaptureFrame {
    /// The frame recorded in `dataset` (its directory or `transforms.json`).
    pub fn of(dataset: &Path) -> Result<Self> {
        let to_dataset =
            rgbd_dataset::placement::recorded_placement(dataset).with_context(|| {
                format!(
                    "--to-capture {}: reading the capture's frame",
                    dataset.display()
                )
            })?;
        let map = to_dataset.inverse();
        Ok(Self {
            map,
            length: DMat3::from_mat4(map).determinant().cbrt(),
        })
    }

    /// `volume` with its density per unit length of the capture's frame: divided by
    /// [`CaptureFrame::length`], so that rays through it keep their opacity.
    pub fn density_for(&self, volume: &RadianceVolume) -> Result<RadianceVolume> {
        let data = volume.tensor();
        let density = (data.narrow(0, 0, 1)? / self.length)?;
        let rest = data.narrow(0, 1, data.dim(0)? - 1)?;
        Ok(volume.with_tensor(candle_core::Tensor::cat(&[&density, &rest], 0)?)?)
    }

    /// Says what was done, for the commands' messages.
    pub fn describe(&self, dataset: &Path) -> String {
        format!(
            "in the frame of the capture {} was imported from (a unit of the dataset is {:.4} \
             there)",
            dataset.display(),
            self.length
        )
    }
}
