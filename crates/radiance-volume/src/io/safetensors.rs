//! The native format: safetensors with one f32 tensor `volume` of shape `(C, D, H, W)` and
//! optional string metadata (see `docs/formats.md`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use glam::Vec3;
use safetensors::{Dtype, SafeTensors};

use super::atomic::write_bytes_atomic;
use crate::error::{io_error, Error, Result};
use crate::grid::Aabb;
use crate::volume::{default_channel_names, validate_channel_names, RadianceVolume};

/// The name of the tensor that holds the volume.
pub const TENSOR_NAME: &str = "volume";
/// The metadata key naming the format; its value is [`FORMAT_NAME`].
pub const KEY_FORMAT: &str = "format";
/// The metadata key of the format version; its value is [`FORMAT_VERSION`].
pub const KEY_VERSION: &str = "format_version";
/// The metadata key of the world box, a JSON array `[min_x, min_y, min_z, max_x, max_y, max_z]`.
pub const KEY_AABB: &str = "aabb";
/// The metadata key of the channel names, a JSON array of strings.
pub const KEY_CHANNELS: &str = "channels";
/// The value of [`KEY_FORMAT`].
pub const FORMAT_NAME: &str = "volgen.radiance-volume";
/// The version written by this crate; files of a newer version are refused.
pub const FORMAT_VERSION: u32 = 1;

const FORMAT: &str = "volgen safetensors volume";

impl RadianceVolume {
    /// Saves the volume as safetensors, atomically (a temporary file renamed into place).
    pub fn save_safetensors(&self, path: impl AsRef<Path>) -> Result<()> {
        let bytes = self.to_safetensors_bytes()?;
        write_bytes_atomic(path.as_ref(), &bytes)
    }

    /// Serialises the volume to safetensors bytes.
    pub fn to_safetensors_bytes(&self) -> Result<Vec<u8>> {
        let values: Vec<f32> = self.tensor().flatten_all()?.to_vec1()?;
        let bytes: &[u8] = bytemuck::cast_slice(&values);
        let d = self.dims();
        let view = safetensors::tensor::TensorView::new(
            Dtype::F32,
            vec![self.channel_count(), d.d, d.h, d.w],
            bytes,
        )
        .map_err(|e| crate::error::invalid("volume", e.to_string()))?;
        let b = self.aabb();
        let metadata = HashMap::from([
            (KEY_FORMAT.to_string(), FORMAT_NAME.to_string()),
            (KEY_VERSION.to_string(), FORMAT_VERSION.to_string()),
            (
                KEY_AABB.to_string(),
                serde_json::to_string(&[b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z])
                    .expect("floats serialise"),
            ),
            (
                KEY_CHANNELS.to_string(),
                serde_json::to_string(self.channel_names()).expect("strings serialise"),
            ),
        ]);
        safetensors::serialize([(TENSOR_NAME, view)], Some(metadata))
            .map_err(|e| crate::error::invalid("volume", e.to_string()))
    }

    /// Loads a volume saved by [`save_safetensors`](Self::save_safetensors) or written by any
    /// safetensors writer with a single f32 tensor `volume` `(C, D, H, W)`; missing metadata takes
    /// the defaults (box `[-1, 1]^3`, names `sigma, r, g, b, f0, ...`). Errors name the file and
    /// the field at fault; non-finite values are refused.
    pub fn load_safetensors(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(io_error(path))?;
        Self::from_safetensors_bytes(&bytes, path)
    }

    /// Parses safetensors bytes; `path` is only used in error messages.
    pub fn from_safetensors_bytes(bytes: &[u8], path: &Path) -> Result<Self> {
        let bad = |why: String| Error::InvalidFile {
            path: PathBuf::from(path),
            format: FORMAT,
            why,
        };
        let (_, header) = SafeTensors::read_metadata(bytes)
            .map_err(|e| bad(format!("not a readable safetensors file ({e})")))?;
        let tensors = SafeTensors::deserialize(bytes)
            .map_err(|e| bad(format!("not a readable safetensors file ({e})")))?;
        let view = tensors.tensor(TENSOR_NAME).map_err(|_| {
            let mut names = tensors.names();
            names.sort();
            bad(format!("no tensor named `{TENSOR_NAME}` (found {names:?})"))
        })?;
        if view.dtype() != Dtype::F32 {
            return Err(bad(format!(
                "tensor `{TENSOR_NAME}` has dtype {:?}, expected F32 (in numpy: .astype(np.float32))",
                view.dtype()
            )));
        }
        let shape = view.shape().to_vec();
        if shape.len() != 4 || shape[0] < 4 || shape.contains(&0) {
            return Err(bad(format!(
                "tensor `{TENSOR_NAME}` has shape {shape:?}, expected (C, D, H, W) with C >= 4 and all sizes >= 1"
            )));
        }
        let values: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let meta = header.metadata().clone().unwrap_or_default();
        check_version(&meta).map_err(bad)?;
        let aabb = parse_aabb(&meta).map_err(bad)?;
        let names = parse_channels(&meta, shape[0]).map_err(bad)?;
        let data = Tensor::from_vec(values, shape, &Device::Cpu)?;
        let volume = Self::new(data, aabb)?;
        let volume = volume.with_channel_names(names)?;
        volume.check_finite(&format!("{}: tensor `{TENSOR_NAME}`", path.display()))?;
        Ok(volume)
    }
}

fn check_version(meta: &HashMap<String, String>) -> std::result::Result<(), String> {
    if let Some(format) = meta.get(KEY_FORMAT) {
        if format != FORMAT_NAME {
            return Err(format!(
                "metadata `{KEY_FORMAT}` is {format:?}, expected {FORMAT_NAME:?}"
            ));
        }
    }
    match meta.get(KEY_VERSION) {
        None => Ok(()),
        Some(v) => match v.parse::<u32>() {
            Ok(n) if (1..=FORMAT_VERSION).contains(&n) => Ok(()),
            _ => Err(format!(
                "metadata `{KEY_VERSION}` is {v:?}, expected an integer from 1 to {FORMAT_VERSION}"
            )),
        },
    }
}

fn parse_aabb(meta: &HashMap<String, String>) -> std::result::Result<Aabb, String> {
    let Some(text) = meta.get(KEY_AABB) else {
        return Ok(Aabb::default());
    };
    let expected =
        "expected a JSON array [min_x, min_y, min_z, max_x, max_y, max_z] with finite min < max";
    let v: Vec<f32> = serde_json::from_str(text)
        .map_err(|e| format!("metadata `{KEY_AABB}` is {text:?}: {e}; {expected}"))?;
    if v.len() != 6 {
        return Err(format!(
            "metadata `{KEY_AABB}` has {} numbers; {expected}",
            v.len()
        ));
    }
    Aabb::try_new(Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]))
        .map_err(|_| format!("metadata `{KEY_AABB}` is {text}; {expected}"))
}

fn parse_channels(
    meta: &HashMap<String, String>,
    channels: usize,
) -> std::result::Result<Vec<String>, String> {
    let Some(text) = meta.get(KEY_CHANNELS) else {
        return Ok(default_channel_names(channels));
    };
    let names: Vec<String> = serde_json::from_str(text).map_err(|e| {
        format!("metadata `{KEY_CHANNELS}` is {text:?}: {e}; expected a JSON array of strings")
    })?;
    validate_channel_names(&names, channels)
        .map_err(|e| format!("metadata `{KEY_CHANNELS}`: {e}"))?;
    Ok(names)
}
