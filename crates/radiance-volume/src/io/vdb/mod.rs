//! OpenVDB export (our own writer: no Rust crate writes VDB) and import (through vdb-rs).
//!
//! A volume becomes a `.vdb` file with
//! - `density`: a FloatGrid of grid class fog volume, from channel 0;
//! - `color`: a Vec3SGrid (`vector_type` invariant), from channels 1..4, which Blender's
//!   Principled Volume reads as its colour attribute;
//! - optionally one FloatGrid per feature channel, named like the channel.
//!
//! All grids share one sparse topology: only the 8^3 leaves holding a voxel with density above the
//! threshold are stored, and a voxel is active exactly when its density is above it. Inactive
//! voxels hold the background 0 in every grid. Index `(i, j, k)` is `(x, y, z)` = `(w, h, d)`
//! and `world = index * voxel_size + translation` with `translation = aabb.min + voxel_size / 2`,
//! so voxel centres land on the cell centres of the volume and the grid fills its world box in
//! Blender (Z-up). The byte layout is documented in `docs/formats.md`.
//!
//! ```
//! use radiance_volume::{Aabb, GridDims, RadianceVolume};
//! let v = RadianceVolume::from_fn(GridDims::cube(32), Aabb::CUBE, 4, |p, out| {
//!     out[0] = if p.length() < 0.3 { 4.0 } else { 0.0 };
//!     out[1..4].copy_from_slice(&[0.9, 0.5, 0.2]);
//! })?;
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("ball.vdb");
//! let stats = v.write_vdb().zlib(true).to_file(&path)?;
//! // The ball occupies 8 of the 64 blocks of 8^3 voxels; only those are stored.
//! assert_eq!(stats.leaves, 8);
//! let back = RadianceVolume::read_vdb(&path, v.grid())?;
//! assert_eq!(back.dims(), v.dims());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod bytes;
mod meta;
mod read;
mod tree;

use std::io::{Cursor, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use glam::DMat4;

use self::bytes::PutBytes;
use self::meta::{ContentHash, MetaValue, Transform, COMPRESS_ACTIVE_MASK, COMPRESS_ZIP};
use self::tree::{Encoding, GridValues, Topology};
use super::atomic::{check_writable, write_atomic};
use crate::error::{invalid, io_error, Error, Result};
use crate::source::VolumeSource;
use crate::volume::RadianceVolume;

pub use self::read::{COLOR_GRID_NAMES, COLOR_RGB_GRID_NAMES, DEFAULT_IMPORT_COLOR};

/// The name of the density grid.
pub const DENSITY_GRID: &str = "density";
/// The name of the colour grid.
pub const COLOR_GRID: &str = "color";

/// What an export wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VdbStats {
    /// Leaves (8^3 blocks) stored per grid.
    pub leaves: usize,
    /// Active voxels per grid.
    pub active_voxels: u64,
    /// Size of the file in bytes.
    pub bytes: u64,
}

/// Writes a volume as an OpenVDB file; made by [`RadianceVolume::write_vdb`], or by
/// [`VdbWriter::new`] for any [`VolumeSource`] (such as a [`crate::Resampled`] volume, computed
/// block by block as it is written).
///
/// Defaults: full floats, no zlib, threshold 0, no feature grids, non-finite values refused.
#[derive(Debug, Clone)]
#[must_use = "a writer does nothing until `to_file` or `to_writer` is called"]
pub struct VdbWriter<'a> {
    volume: &'a dyn VolumeSource,
    half: bool,
    zlib: bool,
    threshold: f32,
    feature_grids: bool,
    replace_non_finite: Option<f32>,
    placed: Option<DMat4>,
}

impl RadianceVolume {
    /// Starts an OpenVDB export of this volume (see [`VdbWriter`] and the module docs of
    /// [`crate::io::vdb`]).
    pub fn write_vdb(&self) -> VdbWriter<'_> {
        VdbWriter::new(self)
    }
}

impl<'a> VdbWriter<'a> {
    /// Starts an OpenVDB export of `volume`, with the defaults above.
    pub fn new(volume: &'a dyn VolumeSource) -> Self {
        Self {
            volume,
            half: false,
            zlib: false,
            threshold: 0.0,
            feature_grids: false,
            replace_non_finite: None,
            placed: None,
        }
    }

    /// Stores values as IEEE half floats (`_HalfFloat` grids): half the size, about 3 decimal
    /// digits. Values beyond ±65504 make the export fail.
    pub fn half(self, half: bool) -> Self {
        Self { half, ..self }
    }

    /// Compresses value arrays with zlib (OpenVDB's `zip` codec). Active-mask compression (only
    /// active values are stored) is always on, as in OpenVDB's own default.
    pub fn zlib(self, zlib: bool) -> Self {
        Self { zlib, ..self }
    }

    /// Sets the density threshold: voxels with density `> threshold` are active, and a leaf is
    /// stored when it holds an active voxel. Default 0.
    pub fn threshold(self, threshold: f32) -> Self {
        Self { threshold, ..self }
    }

    /// Also writes each feature channel (channel 4 on) as a FloatGrid named like the channel.
    pub fn feature_grids(self, feature_grids: bool) -> Self {
        Self {
            feature_grids,
            ..self
        }
    }

    /// Replaces NaN and infinite values by `value` instead of failing with
    /// [`Error::NonFinite`].
    pub fn replace_non_finite(self, value: Option<f32>) -> Self {
        Self {
            replace_non_finite: value,
            ..self
        }
    }

    /// Places the grid in another frame: the file's world is the volume's coordinates mapped by
    /// the affine `placed` (OpenVDB's `AffineMap`), e.g. the similarity back to a capture's
    /// frame. Density is written as it is: scale it by the inverse of a similarity's length
    /// factor first (per unit length, opacity must stay the same along longer rays).
    /// [`RadianceVolume::read_vdb`] (through vdb-rs) does not read such files; OpenVDB and
    /// Blender do. Errors at writing when `placed` is not finite, its last row is not
    /// `[0, 0, 0, 1]` or it is singular.
    ///
    /// ```
    /// use radiance_volume::{Aabb, GridDims, RadianceVolume};
    /// let v = RadianceVolume::from_fn(GridDims::cube(8), Aabb::CUBE, 4, |_, out| out[0] = 1.0)?;
    /// let turn = glam::DMat4::from_rotation_z(0.5);
    /// let mut file = Vec::new();
    /// v.write_vdb().placed(turn).to_writer(&mut file)?;
    /// assert!(file.windows(9).any(|w| w == b"AffineMap"));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn placed(self, placed: DMat4) -> Self {
        Self {
            placed: Some(placed),
            ..self
        }
    }

    /// Writes the file atomically, streaming it: the volume is read one slab (for the tree's
    /// shape) and then one 128^3 brick per grid at a time, and nothing larger is held. The
    /// destination is checked first, so an unwritable path fails before any work, and no
    /// partial file is ever left under `path`.
    pub fn to_file(&self, path: impl AsRef<Path>) -> Result<VdbStats> {
        let path = path.as_ref();
        check_writable(path)?;
        let mut stats = None;
        write_atomic(path, |w| {
            stats = Some(self.write_to(w, path)?);
            Ok(())
        })?;
        Ok(stats.expect("written above"))
    }

    /// Writes the file to `w`. The file is assembled in memory first (its header and grid
    /// offsets are filled in last); for large volumes use [`VdbWriter::to_file`].
    pub fn to_writer(&self, mut w: impl Write) -> Result<VdbStats> {
        let name = PathBuf::from("<vdb writer>");
        let mut file = Cursor::new(Vec::new());
        let stats = self.write_to(&mut file, &name)?;
        w.write_all(file.get_ref()).map_err(io_error(name))?;
        Ok(stats)
    }

    /// Validates the options and the values, then writes the header, and each grid's
    /// descriptor and body, streaming the leaf buffers; the UUID (a hash of the grid bodies) and
    /// each grid's end offset are written last, over placeholders. `path` names `w` in errors.
    fn write_to<W: Write + Seek>(&self, w: &mut W, path: &Path) -> Result<VdbStats> {
        let volume = self.volume;
        if !self.threshold.is_finite() {
            return Err(invalid(
                "threshold",
                format!("must be finite, got {}", self.threshold),
            ));
        }
        if let Some(m) = self.placed {
            let affine = m.row(3) == glam::DVec4::W;
            if !m.is_finite() || !affine || m.determinant().abs() < 1e-12 {
                return Err(invalid(
                    "placed",
                    format!(
                        "expected a finite, invertible affine map (last row [0, 0, 0, 1]), got \
                         {m:?}"
                    ),
                ));
            }
        }
        if let Some(r) = self.replace_non_finite.filter(|r| !r.is_finite()) {
            return Err(invalid(
                "replace_non_finite",
                format!("the replacement must be finite, got {r}"),
            ));
        }
        let names = volume.channel_names();
        let features = if self.feature_grids {
            4..names.len()
        } else {
            4..4
        };
        if let Some(bad) = names[features.clone()]
            .iter()
            .find(|n| *n == DENSITY_GRID || *n == COLOR_GRID)
        {
            return Err(invalid(
                "channel_names",
                format!("feature channel `{bad}` would collide with the grid of that name"),
            ));
        }
        if self.replace_non_finite.is_none() {
            // Only the exported channels: NaNs elsewhere do not fail the export.
            volume.check_finite_channels("volume to export", 0..features.end.max(4))?;
        }

        let enc = Encoding {
            half: self.half,
            zlib: self.zlib,
        };
        let transform = Transform {
            placed: self.placed,
            ..Transform::for_grid(&volume.grid())
        };
        let grid = |name: &'a str, channels: std::ops::Range<usize>| GridValues {
            name,
            channels,
            replace_non_finite: self.replace_non_finite,
        };
        let mut grids = vec![
            (grid(DENSITY_GRID, 0..1), "fog volume"),
            (grid(COLOR_GRID, 1..4), "unknown"),
        ];
        grids.extend(features.map(|c| (grid(names[c].as_str(), c..c + 1), "unknown")));
        let topology = Topology::build(volume, &grids[0].0, self.threshold)?;

        let mut out = Output {
            w,
            path,
            hash: ContentHash::new(),
        };
        let mut header = Vec::new();
        meta::put_header_start(&mut header);
        let uuid_at = header.len() as u64;
        header.extend_from_slice(ContentHash::new().uuid().as_bytes());
        meta::put_header_end(&mut header, grids.len() as u32);
        out.put(&header, false)?;
        for (g, class) in &grids {
            out.put(&grid_head(g, enc), false)?;
            let body = grid_body_head(&topology, g, class, &transform, enc);
            let grid_pos = out.position()? + 24;
            let end_at = grid_pos - 8;
            let mut offsets = Vec::new();
            offsets.put_i64(grid_pos as i64);
            offsets.put_i64((grid_pos + body.len() as u64) as i64);
            offsets.put_i64(0); // the end, filled in below
            out.put(&offsets, false)?;
            out.put(&body, true)?;
            topology.write_buffers(&mut |bytes| out.put(bytes, true), volume, g, enc)?;
            out.hash.end_part();
            let end_pos = out.position()?;
            out.put_at(end_at, &(end_pos as i64).to_le_bytes())?;
        }
        let bytes = out.position()?;
        let uuid = out.hash.uuid();
        out.put_at(uuid_at, uuid.as_bytes())?;
        Ok(VdbStats {
            leaves: topology.leaves().len(),
            active_voxels: topology.active_voxels(),
            bytes,
        })
    }
}

/// A seekable destination that hashes the grid bodies as they pass.
struct Output<'w, W> {
    w: &'w mut W,
    path: &'w Path,
    hash: ContentHash,
}

impl<W: Write + Seek> Output<'_, W> {
    /// Writes `bytes` at the end, feeding them to the hash when `hashed`.
    fn put(&mut self, bytes: &[u8], hashed: bool) -> Result<()> {
        if hashed {
            self.hash.update(bytes);
        }
        self.w.write_all(bytes).map_err(io_error(self.path))
    }

    /// Overwrites bytes at `at`, then returns to the end.
    fn put_at(&mut self, at: u64, bytes: &[u8]) -> Result<()> {
        (|| {
            let end = self.w.stream_position()?;
            self.w.seek(SeekFrom::Start(at))?;
            self.w.write_all(bytes)?;
            self.w.seek(SeekFrom::Start(end)).map(|_| ())
        })()
        .map_err(io_error(self.path))
    }

    fn position(&mut self) -> Result<u64> {
        self.w.stream_position().map_err(io_error(self.path))
    }
}

/// A grid descriptor's head: name, tree type, parent (none).
fn grid_head(grid: &GridValues<'_>, enc: Encoding) -> Vec<u8> {
    let mut type_name = String::from(if grid.channels.len() == 3 {
        "Tree_vec3s_5_4_3"
    } else {
        "Tree_float_5_4_3"
    });
    if enc.half {
        type_name.push_str("_HalfFloat");
    }
    let mut head = Vec::new();
    head.put_str(grid.name);
    head.put_str(&type_name);
    head.put_str(""); // not an instance of another grid
    head
}

/// A grid body up to its leaf buffers: compression, metadata, transform and topology.
fn grid_body_head(
    topology: &Topology,
    grid: &GridValues<'_>,
    class: &str,
    transform: &Transform,
    enc: Encoding,
) -> Vec<u8> {
    let vector = grid.channels.len() == 3;
    let compression = COMPRESS_ACTIVE_MASK | if enc.zlib { COMPRESS_ZIP } else { 0 };
    let (bbox_min, bbox_max) = topology.active_bbox();
    let mut metadata = vec![
        ("class", MetaValue::Str(class)),
        ("file_bbox_max", MetaValue::Vec3i(bbox_max)),
        ("file_bbox_min", MetaValue::Vec3i(bbox_min)),
        (
            "file_compression",
            MetaValue::Str(if enc.zlib {
                "zip + active values"
            } else {
                "active values"
            }),
        ),
        (
            "file_voxel_count",
            MetaValue::I64(topology.active_voxels() as i64),
        ),
        ("is_local_space", MetaValue::Bool(false)),
        ("is_saved_as_half_float", MetaValue::Bool(enc.half)),
        ("name", MetaValue::Str(grid.name)),
    ];
    if vector {
        metadata.push(("vector_type", MetaValue::Str("invariant")));
    }
    let mut body = Vec::new();
    body.put_u32(compression);
    meta::put_metadata(&mut body, &metadata);
    transform.put(&mut body);
    topology.put_topology(&mut body, grid.channels.len(), enc);
    body
}

/// Maps an error from vdb-rs to [`Error::InvalidFile`].
fn vdb_error(path: &Path, why: impl std::fmt::Display) -> Error {
    Error::InvalidFile {
        path: path.to_path_buf(),
        format: "OpenVDB",
        why: why.to_string(),
    }
}
