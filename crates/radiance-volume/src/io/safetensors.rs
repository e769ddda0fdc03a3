//! The native format: safetensors with one f32 tensor `volume` of shape `(C, D, H, W)` and
//! optional string metadata (see `docs/formats.md`).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Cursor, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use glam::Vec3;
use safetensors::tensor::Metadata;
use safetensors::Dtype;

use super::atomic::write_sized_atomic;
use crate::error::{io_error, Error, Result};
use crate::grid::Aabb;
use crate::source::{z_slabs, VolumeSource};
use crate::volume::{default_channel_names, validate_channel_names, RadianceVolume};
use crate::VoxelRange;

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

/// The largest header read (as the safetensors crate's own limit): a damaged length field must
/// not make the reader allocate gigabytes.
const MAX_HEADER: u64 = 100_000_000;

impl RadianceVolume {
    /// Saves the volume as safetensors, atomically (a temporary file renamed into place).
    pub fn save_safetensors(&self, path: impl AsRef<Path>) -> Result<()> {
        write_safetensors(self, path)
    }

    /// Serialises the volume to safetensors bytes.
    pub fn to_safetensors_bytes(&self) -> Result<Vec<u8>> {
        safetensors_bytes(self)
    }

    /// Loads a volume saved by [`save_safetensors`](Self::save_safetensors) or written by any
    /// safetensors writer with a single f32 tensor `volume` `(C, D, H, W)`; missing metadata takes
    /// the defaults (box `[-1, 1]^3`, names `sigma, r, g, b, f0, ...`). Errors name the file and
    /// the field at fault; non-finite values are refused. The values are read straight into the
    /// volume's memory (no second copy of the file).
    pub fn load_safetensors(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let mut file = File::open(path).map_err(io_error(path))?;
        let len = file.metadata().map_err(io_error(path))?.len();
        read_safetensors(&mut file, len, path)
    }

    /// Parses safetensors bytes; `path` is only used in error messages.
    pub fn from_safetensors_bytes(bytes: &[u8], path: &Path) -> Result<Self> {
        read_safetensors(&mut Cursor::new(bytes), bytes.len() as u64, path)
    }
}

/// Writes any [`VolumeSource`] as a volgen safetensors file, atomically, one slab of one channel
/// at a time: a volume computed block by block (e.g. [`crate::Resampled`]) is never whole in
/// memory.
///
/// ```
/// use radiance_volume::{Aabb, GridDims, RadianceVolume, Resampled};
/// let v = RadianceVolume::from_fn(GridDims::cube(4), Aabb::CUBE, 4, |p, out| out[0] = p.x)?;
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("fine.safetensors");
/// radiance_volume::io::write_safetensors(&Resampled::finer(v, 3)?, &path)?;
/// assert_eq!(RadianceVolume::load_safetensors(&path)?.dims(), GridDims::cube(12));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_safetensors(source: &dyn VolumeSource, path: impl AsRef<Path>) -> Result<()> {
    let path = path.as_ref();
    let header = header(source)?;
    let bytes = 8 + header.len() as u64 + data_len(source) as u64;
    write_sized_atomic(path, bytes, |w| {
        write_safetensors_to(source, &header, w, path)
    })
}

/// The bytes [`write_safetensors`] writes for `source`, in memory (a server's download, say).
///
/// ```
/// use radiance_volume::{Aabb, GridDims, RadianceVolume, Resampled};
/// let v = RadianceVolume::from_fn(GridDims::cube(4), Aabb::CUBE, 4, |p, out| out[0] = p.x)?;
/// let bytes = radiance_volume::io::safetensors_bytes(&Resampled::finer(v, 3)?)?;
/// let path = std::path::Path::new("fine.safetensors");
/// let fine = RadianceVolume::from_safetensors_bytes(&bytes, path)?;
/// assert_eq!(fine.dims(), GridDims::cube(12));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn safetensors_bytes(source: &dyn VolumeSource) -> Result<Vec<u8>> {
    let header = header(source)?;
    let mut bytes = Vec::with_capacity(8 + header.len() + data_len(source));
    write_safetensors_to(source, &header, &mut bytes, Path::new("<memory>"))?;
    Ok(bytes)
}

/// The bytes of the `volume` tensor's values.
fn data_len(source: &dyn VolumeSource) -> usize {
    source.channel_count() * source.dims().voxel_count() * 4
}

/// The safetensors header of `source`: its JSON, padded with spaces to a multiple of 8 bytes
/// as the safetensors crate writes it. The keys are in a fixed order (the crate's own writer
/// follows a `HashMap`'s), so a volume's file has the same bytes at every write.
fn header(source: &dyn VolumeSource) -> Result<Vec<u8>> {
    let d = source.dims();
    let b = source.grid().aabb;
    let metadata = BTreeMap::from([
        (KEY_FORMAT, FORMAT_NAME.to_string()),
        (KEY_VERSION, FORMAT_VERSION.to_string()),
        (
            KEY_AABB,
            serde_json::to_string(&[b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z])
                .expect("floats serialise"),
        ),
        (
            KEY_CHANNELS,
            serde_json::to_string(source.channel_names()).expect("strings serialise"),
        ),
    ]);
    let info = serde_json::json!({
        "dtype": "F32",
        "shape": [source.channel_count(), d.d, d.h, d.w],
        "data_offsets": [0, data_len(source)],
    });
    let header = BTreeMap::from([
        (
            "__metadata__",
            serde_json::to_value(metadata).expect("strings serialise"),
        ),
        (TENSOR_NAME, info),
    ]);
    let mut header = serde_json::to_vec(&header).expect("a safetensors header serialises");
    header.resize(header.len().next_multiple_of(8), b' ');
    Ok(header)
}

/// Writes the header's length and `header`, then each channel's values slab by slab,
/// little-endian.
fn write_safetensors_to(
    source: &dyn VolumeSource,
    header: &[u8],
    w: &mut dyn Write,
    path: &Path,
) -> Result<()> {
    let d = source.dims();
    let put = |w: &mut dyn Write, bytes: &[u8]| w.write_all(bytes).map_err(io_error(path));
    put(w, &(header.len() as u64).to_le_bytes())?;
    put(w, header)?;
    for c in 0..source.channel_count() {
        for z in z_slabs(d, 1, source.slab_values()) {
            let mut values = source.read_block(c..c + 1, &VoxelRange::z_slab(d, z))?;
            if cfg!(target_endian = "big") {
                values
                    .iter_mut()
                    .for_each(|v| *v = f32::from_bits(v.to_bits().swap_bytes()));
            }
            put(w, bytemuck::cast_slice(&values))?;
        }
    }
    Ok(())
}

/// Reads a volume from a safetensors stream of `len` bytes: the header, then the `volume`
/// tensor's values straight into an f32 buffer. The header is checked as the safetensors crate
/// checks it (its parser), plus the sizes this reader relies on: the file holds exactly the
/// header and the tensors' bytes, and the volume's bytes match its shape.
fn read_safetensors<R: Read + Seek>(r: &mut R, len: u64, path: &Path) -> Result<RadianceVolume> {
    let bad = |why: String| Error::InvalidFile {
        path: PathBuf::from(path),
        format: FORMAT,
        why,
    };
    let unreadable =
        |e: &dyn std::fmt::Display| bad(format!("not a readable safetensors file ({e})"));
    let mut n = [0u8; 8];
    r.read_exact(&mut n).map_err(|e| unreadable(&e))?;
    let n = u64::from_le_bytes(n);
    if n > MAX_HEADER || 8 + n > len {
        return Err(unreadable(&format!(
            "a header of {n} bytes in a file of {len}"
        )));
    }
    let mut header = vec![0u8; n as usize];
    r.read_exact(&mut header).map_err(|e| unreadable(&e))?;
    let header: Metadata = serde_json::from_slice(&header).map_err(|e| unreadable(&e))?;
    let tensors = header.tensors();
    let data_len = tensors
        .values()
        .map(|t| t.data_offsets.1)
        .max()
        .unwrap_or(0) as u64;
    if 8 + n + data_len != len {
        return Err(unreadable(&format!(
            "the header describes {data_len} bytes of tensors, the file holds {}",
            len - 8 - n
        )));
    }
    let Some(info) = tensors.get(TENSOR_NAME) else {
        let mut names: Vec<&String> = tensors.keys().collect();
        names.sort();
        return Err(bad(format!(
            "no tensor named `{TENSOR_NAME}` (found {names:?})"
        )));
    };
    if info.dtype != Dtype::F32 {
        return Err(bad(format!(
            "tensor `{TENSOR_NAME}` has dtype {:?}, expected F32 (in numpy: .astype(np.float32))",
            info.dtype
        )));
    }
    let shape = info.shape.clone();
    if shape.len() != 4 || shape[0] < 4 || shape.contains(&0) {
        return Err(bad(format!(
            "tensor `{TENSOR_NAME}` has shape {shape:?}, expected (C, D, H, W) with C >= 4 and all sizes >= 1"
        )));
    }
    let (start, end) = info.data_offsets;
    let count: usize = shape.iter().product();
    if end < start || end - start != count * 4 {
        return Err(unreadable(&format!(
            "tensor `{TENSOR_NAME}` of shape {shape:?} has {} bytes",
            end.saturating_sub(start)
        )));
    }
    let meta = header.metadata().clone().unwrap_or_default();
    check_version(&meta).map_err(bad)?;
    let aabb = parse_aabb(&meta).map_err(bad)?;
    let names = parse_channels(&meta, shape[0]).map_err(bad)?;
    let mut values = vec![0f32; count];
    r.seek(SeekFrom::Start(8 + n + start as u64))
        .and_then(|_| r.read_exact(bytemuck::cast_slice_mut(&mut values)))
        .map_err(|e| unreadable(&e))?;
    // The file is little-endian; on a big-endian host swap what was read.
    if cfg!(target_endian = "big") {
        values
            .iter_mut()
            .for_each(|v| *v = f32::from_bits(v.to_bits().swap_bytes()));
    }
    let data = Tensor::from_vec(values, shape, &Device::Cpu)?;
    let volume = RadianceVolume::new(data, aabb)?.with_channel_names(names)?;
    volume.check_finite(&format!("{}: tensor `{TENSOR_NAME}`", path.display()))?;
    Ok(volume)
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
