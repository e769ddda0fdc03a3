//! EXR slice stacks: one EXR image per z slice (`name.0000.exr`, `name.0001.exr`, ...) with
//! channels `density`, `R`, `G`, `B` and one channel per feature, plus a JSON sidecar `name.json`
//! with the box, the resolution and what each channel means (see `docs/formats.md`).
//!
//! Image columns are x (`w`) from left to right and rows are y (`h`) from the top down starting at
//! the largest y, so a slice looks like the volume seen from above (+z) with +y up. Files are
//! single-part scanline EXRs with ZIP compression, f32 or (optionally) f16 samples.
//!
//! ```
//! use radiance_volume::{Aabb, GridDims, RadianceVolume};
//! let v = RadianceVolume::from_fn(GridDims::new(3, 4, 5), Aabb::CUBE, 4, |p, out| {
//!     out.copy_from_slice(&[p.length(), 0.9, 0.5, 0.1]);
//! })?;
//! let dir = tempfile::tempdir()?;
//! let files = v.write_exr_slices().to_dir(dir.path(), "cloud")?;
//! assert_eq!(files.len(), 3 + 1); // three slices and the sidecar
//! assert!(dir.path().join("cloud.0002.exr").exists());
//! let back = RadianceVolume::read_exr_slices(dir.path(), "cloud")?;
//! let max_diff = back.tensor().sub(v.tensor())?.abs()?.max_all()?.to_scalar::<f32>()?;
//! assert_eq!(max_diff, 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, ReadChannels,
    ReadLayers, SmallVec, WritableImage,
};
use glam::Vec3;
use half::f16;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::atomic::{check_writable, remove_file_if_exists, write_atomic, write_bytes_atomic};
use crate::error::{beyond_half, invalid, io_error, Error, Result};
use crate::grid::{Aabb, GridDims};
use crate::source::VolumeSource;
use crate::volume::RadianceVolume;
use crate::VoxelRange;

/// The value of the sidecar's `format` field.
pub const SIDECAR_FORMAT: &str = "volgen.exr-slices";
/// The sidecar version written; newer ones are refused on reading.
pub const SIDECAR_VERSION: u32 = 1;
/// The EXR channel names of the four physical channels (sigma, r, g, b).
pub const EXR_BASE_CHANNELS: [&str; 4] = ["density", "R", "G", "B"];

const FORMAT: &str = "volgen EXR slice stack";

/// The `name.json` sidecar of a slice stack.
#[derive(Debug, Serialize, Deserialize)]
struct Sidecar {
    format: String,
    format_version: u32,
    /// The world box, Z-up.
    aabb: SidecarAabb,
    /// Cells along x (image width), y (image height) and z (one file per slice).
    resolution: SidecarResolution,
    /// The slice files, a printf pattern over the slice index z.
    files: String,
    /// How image rows map to y.
    rows: String,
    /// `float` or `half`.
    pixel_type: String,
    /// Every channel, in volume order.
    channels: Vec<SidecarChannel>,
}

#[derive(Debug, Serialize, Deserialize)]
struct SidecarAabb {
    min: [f32; 3],
    max: [f32; 3],
}

#[derive(Debug, Serialize, Deserialize)]
struct SidecarResolution {
    w: usize,
    h: usize,
    d: usize,
}

#[derive(Debug, Serialize, Deserialize)]
struct SidecarChannel {
    /// The channel's name in the EXR files.
    exr: String,
    /// The channel's name in the volume.
    volume: String,
    /// What the values are.
    meaning: String,
}

/// Writes a volume as a stack of EXR slices; made by [`RadianceVolume::write_exr_slices`], or
/// by [`ExrSlicesWriter::new`] for any [`VolumeSource`] (read one slice at a time per thread).
/// Defaults: f32 samples, non-finite values refused.
#[derive(Debug, Clone)]
#[must_use = "a writer does nothing until `to_dir` is called"]
pub struct ExrSlicesWriter<'a> {
    volume: &'a dyn VolumeSource,
    half: bool,
    replace_non_finite: Option<f32>,
}

impl RadianceVolume {
    /// Starts an EXR slice export of this volume (see [`ExrSlicesWriter`] and the module docs of
    /// [`crate::io::exr_slices`]).
    pub fn write_exr_slices(&self) -> ExrSlicesWriter<'_> {
        ExrSlicesWriter::new(self)
    }

    /// Reads a stack written by [`write_exr_slices`](Self::write_exr_slices) (or any stack with a
    /// matching sidecar): `dir/name.json` and its slice files. Errors name the file at fault;
    /// non-finite samples are refused.
    pub fn read_exr_slices(dir: impl AsRef<Path>, name: &str) -> Result<Self> {
        let dir = dir.as_ref();
        let sidecar_path = dir.join(format!("{name}.json"));
        let text = std::fs::read_to_string(&sidecar_path).map_err(io_error(&sidecar_path))?;
        let bad = |why: String| Error::InvalidFile {
            path: sidecar_path.clone(),
            format: FORMAT,
            why,
        };
        let sidecar: Sidecar = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
        if sidecar.format != SIDECAR_FORMAT {
            return Err(bad(format!(
                "`format` is {:?}, expected {SIDECAR_FORMAT:?}",
                sidecar.format
            )));
        }
        if sidecar.format_version > SIDECAR_VERSION {
            return Err(bad(format!(
                "`format_version` {} is newer than this reader ({SIDECAR_VERSION})",
                sidecar.format_version
            )));
        }
        let r = &sidecar.resolution;
        let dims = GridDims::new(r.d, r.h, r.w);
        dims.validate().map_err(|e| bad(e.to_string()))?;
        let aabb = Aabb::try_new(Vec3::from(sidecar.aabb.min), Vec3::from(sidecar.aabb.max))
            .map_err(|e| bad(e.to_string()))?;
        let channels = sidecar.channels.len();
        if channels < 4 {
            return Err(bad(format!("expected at least 4 channels, got {channels}")));
        }

        let slices: Vec<Vec<Vec<f32>>> = (0..dims.d)
            .into_par_iter()
            .map(|z| read_slice(&slice_path(dir, name, z, dims.d), dims, &sidecar.channels))
            .collect::<Result<_>>()?;
        let plane = dims.h * dims.w;
        let mut planar = vec![0f32; channels * dims.voxel_count()];
        for (z, slice) in slices.iter().enumerate() {
            for (c, samples) in slice.iter().enumerate() {
                let dst = &mut planar[c * dims.voxel_count() + z * plane..][..plane];
                // Rows run from the largest y down.
                for (row, line) in samples.chunks_exact(dims.w).enumerate() {
                    dst[(dims.h - 1 - row) * dims.w..][..dims.w].copy_from_slice(line);
                }
            }
        }
        let data = Tensor::from_vec(planar, (channels, dims.d, dims.h, dims.w), &Device::Cpu)?;
        let volume = Self::new(data, aabb)?
            .with_channel_names(sidecar.channels.iter().map(|c| c.volume.clone()))
            .map_err(|e| bad(e.to_string()))?;
        volume.check_finite(&format!("{}", sidecar_path.display()))?;
        Ok(volume)
    }
}

impl<'a> ExrSlicesWriter<'a> {
    /// Starts an EXR slice export of `volume`, with the defaults above.
    pub fn new(volume: &'a dyn VolumeSource) -> Self {
        Self {
            volume,
            half: false,
            replace_non_finite: None,
        }
    }

    /// Stores f16 samples instead of f32; values beyond ±65504 make the export fail.
    pub fn half(self, half: bool) -> Self {
        Self { half, ..self }
    }

    /// Replaces NaN and infinite values by `value` instead of failing with
    /// [`Error::NonFinite`].
    pub fn replace_non_finite(self, value: Option<f32>) -> Self {
        Self {
            replace_non_finite: value,
            ..self
        }
    }

    /// Writes `dir/name.0000.exr` ... (one file per z slice, numbered with at least 4 digits)
    /// and then `dir/name.json`, creating `dir` if needed, and returns the paths written. The
    /// directory is checked first, so an unwritable one fails before any work; each file is
    /// written atomically, and on error the files of this call are removed.
    pub fn to_dir(&self, dir: impl AsRef<Path>, name: &str) -> Result<Vec<PathBuf>> {
        let dir = dir.as_ref();
        if name.is_empty() || name.contains(['/', '\\']) {
            return Err(invalid(
                "name",
                format!("expected a non-empty file name stem without separators, got {name:?}"),
            ));
        }
        std::fs::create_dir_all(dir).map_err(io_error(dir))?;
        let sidecar_path = dir.join(format!("{name}.json"));
        check_writable(&sidecar_path)?;
        let volume = self.volume;
        if let Some(r) = self.replace_non_finite.filter(|r| !r.is_finite()) {
            return Err(invalid(
                "replace_non_finite",
                format!("the replacement must be finite, got {r}"),
            ));
        }
        if self.replace_non_finite.is_none() {
            volume.check_finite_channels("volume to export", 0..volume.channel_count())?;
        }
        let channels = self.channels()?;
        let dims = volume.dims();
        let paths: Vec<PathBuf> = (0..dims.d)
            .map(|z| slice_path(dir, name, z, dims.d))
            .collect();
        // Over an earlier export the old sidecar goes first; the new one comes last.
        remove_file_if_exists(&sidecar_path)?;

        let written = paths
            .par_iter()
            .enumerate()
            .map(|(z, path)| {
                let slice = VoxelRange::z_slab(dims, z..z + 1);
                let values = volume.read_block(0..channels.len(), &slice)?;
                let layer = self.slice_layer(&values, z, &channels)?;
                write_atomic(path, |w| {
                    Image::from_layer(layer)
                        .write()
                        .non_parallel()
                        .to_buffered(w)
                        .map_err(|e| exr_write_error(path, e))
                })
            })
            .collect::<Vec<Result<()>>>();
        let result = written.into_iter().collect::<Result<()>>().and_then(|()| {
            let b = volume.grid().aabb;
            let sidecar = Sidecar {
                format: SIDECAR_FORMAT.into(),
                format_version: SIDECAR_VERSION,
                aabb: SidecarAabb {
                    min: b.min.to_array(),
                    max: b.max.to_array(),
                },
                resolution: SidecarResolution {
                    w: dims.w,
                    h: dims.h,
                    d: dims.d,
                },
                files: format!("{name}.%0{}d.exr", digits(dims.d)),
                rows: "x left to right; the top row is the largest y".into(),
                pixel_type: if self.half { "half" } else { "float" }.into(),
                channels,
            };
            let json = serde_json::to_vec_pretty(&sidecar).expect("the sidecar serialises");
            write_bytes_atomic(&sidecar_path, &json)
        });
        if let Err(e) = result {
            paths.iter().for_each(|p| {
                let _ = std::fs::remove_file(p);
            });
            return Err(e);
        }
        Ok(paths.into_iter().chain([sidecar_path]).collect())
    }

    /// Names and describes the channels: `density, R, G, B`, then the feature channels under
    /// their own names.
    fn channels(&self) -> Result<Vec<SidecarChannel>> {
        let names = self.volume.channel_names();
        let meanings = [
            "density sigma in 1/world-length",
            "red, linear, in [0, 1]",
            "green, linear, in [0, 1]",
            "blue, linear, in [0, 1]",
        ];
        names
            .iter()
            .enumerate()
            .map(|(c, volume_name)| {
                let (exr, meaning) = match (EXR_BASE_CHANNELS.get(c), meanings.get(c)) {
                    (Some(e), Some(m)) => (e.to_string(), m.to_string()),
                    _ if EXR_BASE_CHANNELS.contains(&volume_name.as_str()) => {
                        return Err(invalid(
                            "channel_names",
                            format!(
                                "feature channel `{volume_name}` collides with an EXR base channel"
                            ),
                        ))
                    }
                    _ => (volume_name.clone(), "feature channel".to_string()),
                };
                Ok(SidecarChannel {
                    exr,
                    volume: volume_name.clone(),
                    meaning,
                })
            })
            .collect()
    }

    /// Builds the EXR layer of slice `z` from its values (every channel of the slice).
    fn slice_layer(
        &self,
        values: &[f32],
        z: usize,
        channels: &[SidecarChannel],
    ) -> Result<Layer<AnyChannels<FlatSamples>>> {
        let dims = self.volume.dims();
        let list = channels
            .iter()
            .enumerate()
            .map(|(c, ch)| {
                let plane = &values[c * dims.h * dims.w..][..dims.h * dims.w];
                let fixed = (0..dims.h)
                    .rev()
                    .flat_map(|y| &plane[y * dims.w..][..dims.w])
                    .map(|&v| match self.replace_non_finite {
                        Some(r) if !v.is_finite() => r,
                        _ => v,
                    });
                let samples = if self.half {
                    let halves: Vec<f16> = fixed.map(f16::from_f32).collect();
                    if let Some(i) = halves.iter().position(|h| h.is_infinite()) {
                        let (row, x) = (i / dims.w, i % dims.w);
                        let v = plane[(dims.h - 1 - row) * dims.w + x];
                        return Err(beyond_half(
                            &format!("channel `{}`", ch.volume),
                            v,
                            &format!("voxel (d={z}, h={}, w={x})", dims.h - 1 - row),
                        ));
                    }
                    FlatSamples::F16(halves)
                } else {
                    FlatSamples::F32(fixed.collect())
                };
                Ok(AnyChannel::new(ch.exr.as_str(), samples))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Layer::new(
            (dims.w, dims.h),
            LayerAttributes::default(),
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(SmallVec::from_vec(list)),
        ))
    }
}

/// Digits in slice numbers: at least 4, more for stacks of 10000 slices or more.
fn digits(slices: usize) -> usize {
    slices.saturating_sub(1).to_string().len().max(4)
}

fn slice_path(dir: &Path, name: &str, z: usize, slices: usize) -> PathBuf {
    dir.join(format!("{name}.{z:0width$}.exr", width = digits(slices)))
}

fn exr_write_error(path: &Path, e: exr::error::Error) -> Error {
    match e {
        exr::error::Error::Io(source) => Error::Io {
            path: path.to_path_buf(),
            source,
        },
        other => invalid("exr", format!("{}: {other}", path.display())),
    }
}

/// Reads one slice file: every channel of the sidecar, as f32 in file row order.
fn read_slice(path: &Path, dims: GridDims, channels: &[SidecarChannel]) -> Result<Vec<Vec<f32>>> {
    let bad = |why: String| Error::InvalidFile {
        path: path.to_path_buf(),
        format: FORMAT,
        why,
    };
    // The header first: a damaged one can claim any size, and the pixel reader would allocate
    // it before finding the data missing (found by fuzzing: 6.6 GB for a 16-voxel slice).
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| match e {
        exr::error::Error::Io(source) => Error::Io {
            path: path.to_path_buf(),
            source,
        },
        other => bad(other.to_string()),
    })?;
    for header in &meta.headers {
        let size = header.layer_size;
        if size.width() != dims.w || size.height() != dims.h {
            return Err(bad(format!(
                "slice is {}x{}, the sidecar says {}x{}",
                size.width(),
                size.height(),
                dims.w,
                dims.h
            )));
        }
    }
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        // Slices are already read in parallel; exr's own pool per file would only add threads.
        .non_parallel()
        .from_file(path)
        .map_err(|e| match e {
            exr::error::Error::Io(source) => Error::Io {
                path: path.to_path_buf(),
                source,
            },
            other => bad(other.to_string()),
        })?;
    // Its size was checked with the headers above.
    let layer = image.layer_data;
    channels
        .iter()
        .map(|ch| {
            let found = layer
                .channel_data
                .list
                .iter()
                .find(|a| a.name.to_string() == ch.exr);
            let found = found.ok_or_else(|| bad(format!("no channel `{}`", ch.exr)))?;
            Ok(found.sample_data.values_as_f32().collect())
        })
        .collect()
}
