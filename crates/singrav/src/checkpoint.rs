//! Checkpoints: one safetensors file holding every weight, the fixed noise, the optimiser
//! moments, and (in its metadata) the configuration and the progress, written atomically so a
//! killed run always leaves the last complete checkpoint behind.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use safetensors::tensor::{Dtype, TensorView};
use serde::{Deserialize, Serialize};

use crate::config::TrainConfig;
use crate::error::{Error, Result};

/// Where training stands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// The scale in training (1-based); `scales + 1` once training is complete.
    pub scale: usize,
    /// The next iteration to run within `scale`.
    pub iteration: usize,
    /// Noise amplitude of every 3D scale built so far.
    pub noise_amps: Vec<f64>,
    /// Whether the upsampler G_N is built.
    pub upsampler: bool,
    /// Depth is divided by this before the critics and the loss see it.
    pub depth_norm: f32,
    /// Adam steps taken by the current scale's generator and critic optimisers.
    pub optimizer_steps: (usize, usize),
    /// Training seconds spent per completed scale.
    pub scale_seconds: Vec<f64>,
    /// Training seconds spent in the current scale so far.
    pub current_seconds: f64,
    /// Peak resident memory (MiB) at the end of each completed scale, where the OS reports it.
    pub scale_peak_mib: Vec<Option<f64>>,
}

impl TrainState {
    /// Whether every scale is trained.
    pub fn finished(&self, config: &TrainConfig) -> bool {
        self.scale > config.scales()
    }
}

/// A checkpoint in memory.
#[derive(Debug, Clone)]
pub struct Checkpoint {
    /// How the run was configured.
    pub config: TrainConfig,
    /// Where it stands.
    pub state: TrainState,
    /// Weights (`g{n}.*`, `up.*`, `d.*`), `z_star` (and the optimised `z_star.{n}` of runs with
    /// `noise.reconstruction_lr > 0`), optimiser moments (`opt_g.*`, `opt_d.*`, `opt_z.*`), and
    /// V*'s `reconstruction_detail` once a run with `reconstruction_fit_steps > 0` has fitted it.
    pub tensors: HashMap<String, Tensor>,
}

fn checkpoint_error(path: &Path, why: impl Into<String>) -> Error {
    Error::Checkpoint {
        path: path.to_path_buf(),
        why: why.into(),
    }
}

impl Checkpoint {
    /// Writes the checkpoint to `path` atomically (temporary file, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        let mut names: Vec<&String> = self.tensors.keys().collect();
        names.sort();
        let mut buffers = Vec::with_capacity(names.len());
        for name in &names {
            let t = &self.tensors[*name];
            let values: Vec<f32> = t
                .to_dtype(candle_core::DType::F32)?
                .flatten_all()?
                .to_vec1()?;
            buffers.push((t.dims().to_vec(), le_bytes(&values)));
        }
        let views = names
            .iter()
            .zip(&buffers)
            .map(|(name, (shape, bytes))| {
                TensorView::new(Dtype::F32, shape.clone(), bytes)
                    .map(|v| (name.as_str(), v))
                    .map_err(|e| checkpoint_error(path, e.to_string()))
            })
            .collect::<Result<Vec<_>>>()?;
        let metadata = HashMap::from([
            ("config".to_string(), to_json(&self.config, path)?),
            ("state".to_string(), to_json(&self.state, path)?),
        ]);
        let bytes = safetensors::serialize(views, Some(metadata))
            .map_err(|e| checkpoint_error(path, e.to_string()))?;
        crate::io::write_bytes(path, &bytes)
    }

    /// Reads a checkpoint written by [`Checkpoint::save`], putting tensors on `device`.
    pub fn load(path: &Path, device: &Device) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|source| {
            if source.kind() == std::io::ErrorKind::NotFound {
                checkpoint_error(path, "no checkpoint here (train a model first)")
            } else {
                Error::Io {
                    path: path.to_path_buf(),
                    source,
                }
            }
        })?;
        let (_, header) = safetensors::SafeTensors::read_metadata(&bytes)
            .map_err(|e| checkpoint_error(path, format!("not a safetensors file: {e}")))?;
        let meta = header
            .metadata()
            .as_ref()
            .ok_or_else(|| checkpoint_error(path, "no metadata (not a volgen checkpoint)"))?;
        let field = |key: &str| {
            meta.get(key)
                .ok_or_else(|| checkpoint_error(path, format!("metadata field `{key}` is missing")))
        };
        let config = TrainConfig::from_json(field("config")?, "metadata `config`")
            .map_err(|e| checkpoint_error(path, e.to_string()))?;
        let state: TrainState = serde_json::from_str(field("state")?)
            .map_err(|e| checkpoint_error(path, format!("metadata `state`: {e}")))?;
        config
            .validate()
            .map_err(|e| checkpoint_error(path, format!("metadata `config`: {e}")))?;
        let file = safetensors::SafeTensors::deserialize(&bytes)
            .map_err(|e| checkpoint_error(path, format!("not a safetensors file: {e}")))?;
        let mut tensors = HashMap::new();
        for (name, view) in file.tensors() {
            if view.dtype() != Dtype::F32 {
                return Err(checkpoint_error(
                    path,
                    format!("tensor `{name}` is {:?}, expected F32", view.dtype()),
                ));
            }
            let values: Vec<f32> = view
                .data()
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
                return Err(checkpoint_error(
                    path,
                    format!("tensor `{name}` holds the non-finite value {bad}"),
                ));
            }
            tensors.insert(name, Tensor::from_vec(values, view.shape(), device)?);
        }
        Ok(Self {
            config,
            state,
            tensors,
        })
    }
}

fn to_json<T: Serialize>(value: &T, path: &Path) -> Result<String> {
    serde_json::to_string(value).map_err(|e| checkpoint_error(path, e.to_string()))
}

/// Little-endian bytes of `values` (safetensors' layout).
fn le_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Writes `config` as pretty JSON to `path` atomically.
pub fn write_config_json(config: &TrainConfig, path: &Path) -> Result<()> {
    let text =
        serde_json::to_string_pretty(config).map_err(|e| checkpoint_error(path, e.to_string()))?;
    crate::io::write_bytes(path, text.as_bytes())
}
