//! Multi-view RGB-D datasets: writing one from a scene, loading one from disk, and resizing it to
//! each training scale.
//!
//! # Format
//!
//! A dataset is a directory with a NeRF `transforms.json` (as Blender NeRF data and nerfstudio
//! use), images and depth maps:
//!
//! ```json
//! {
//!   "camera_angle_x": 0.5829,
//!   "w": 128, "h": 128,
//!   "depth_scale": 0.0001,
//!   "depth_kind": "expected",
//!   "frames": [
//!     { "file_path": "images/r_000.png", "depth_file_path": "depth/r_000.png",
//!       "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3.5], [0, 0, 0, 1]] }
//!   ]
//! }
//! ```
//!
//! - Intrinsics: `camera_angle_x` (horizontal field of view, radians) or `fl_x` / `fl_y` / `cx` /
//!   `cy` in pixels, as [`volrender::load_transforms`] reads them. `w` and `h` are optional; when
//!   given, every image must have that size, otherwise all images must share the first one's.
//! - `transform_matrix`: camera-to-world, row-major 4x4, NeRF/Blender convention (the camera looks
//!   down its -Z axis, +Y up). It must be rigid: finite, rotation part orthonormal within 1e-3
//!   with determinant +1, last row `[0, 0, 0, 1]`.
//! - `file_path`: the colour image, relative to the `transforms.json` directory; 8- or 16-bit
//!   PNG, RGBA with straight (not premultiplied) alpha, or RGB (opaque). Without an extension
//!   (Blender NeRF style) `.png` is appended when the bare name does not exist.
//! - `depth_file_path` (required): a 16-bit grey PNG whose counts times the top-level
//!   `depth_scale` (world units per count; required for PNG depth) give the depth, or an `.exr`
//!   file whose channel `Z` (or `Y`, or `R` when there is no `Z`) holds depth in world units.
//! - `depth_kind`: optional; when present it must be `"expected"`. Depth is the renderer's
//!   expected depth along the ray, `sum_i w_i t_i` (t is the distance from the camera, not the
//!   z coordinate), not divided by opacity, so 0 where nothing is hit.
//!
//! Pixels relate to the renderer's premultiplied colour `C` and opacity `a` by `alpha = a` and
//! stored `rgb = C / a`. Loading composites onto a background `bg`: `rgb * a + bg * (1 - a)`,
//! which is `C + bg (1 - a)`, what the renderer gives with that background.
//!
//! [`write_dataset`] writes 8-bit RGBA images and 16-bit depth PNGs with `depth_scale` 1e-4
//! (depths up to 6.55 world units; the paper's cameras see at most 5.3), named `r_000.png`, ...
//! under `images/` and `depth/`; every file is written atomically and `transforms.json` last, so
//! a directory with `transforms.json` is complete.
//!
//! ```no_run
//! use singrav::dataset::{write_dataset, Dataset, DatasetSpec};
//! use singrav::scenes::SceneKind;
//! let spec = DatasetSpec { views: 6, resolution: 32, grid: 48, ..DatasetSpec::default() };
//! let summary = write_dataset(&*SceneKind::Mushrooms.build(0), "data/mushrooms".as_ref(), &spec)?;
//! let data = Dataset::load(&summary.transforms, [1.0, 1.0, 1.0])?;
//! let level = data.level(16, 16, &candle_core::Device::Cpu)?;
//! assert_eq!(level.images.dims(), &[6, 3, 16, 16]);
//! # Ok::<(), singrav::Error>(())
//! ```

use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use volrender::Camera;

use crate::error::{invalid, Result};

mod load;
mod pixels;
mod resize;
mod write;

pub use write::{render_config, write_dataset, DatasetSpec, DatasetSummary, DEPTH_SCALE};

use resize::resize_plane;

/// A loaded dataset: per frame its camera, colour composited on a background, opacity and
/// expected depth, at the files' resolution.
///
/// ```
/// use singrav::dataset::{write_dataset, Dataset, DatasetSpec};
/// use singrav::scenes::StandingStones;
/// let dir = tempfile::tempdir()?;
/// let spec = DatasetSpec { views: 2, resolution: 12, grid: 16, seed: 1 };
/// write_dataset(&StandingStones::new(1), dir.path(), &spec)?;
/// let data = Dataset::load(dir.path(), [0.0; 3])?;
/// assert_eq!((data.len(), data.width(), data.height()), (2, 12, 12));
/// assert_eq!(data.frame_names()[1], "images/r_001.png");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct Dataset {
    width: usize,
    height: usize,
    cameras: Vec<Camera>,
    names: Vec<String>,
    frames: Vec<FramePixels>,
}

/// One frame's planes, row-major at the dataset's resolution.
#[derive(Debug, Clone)]
struct FramePixels {
    /// Colour composited on the background, channel-major `(3, h, w)`.
    rgb: Vec<f32>,
    /// Opacity `(h, w)`.
    opacity: Vec<f32>,
    /// Expected depth in world units `(h, w)`.
    depth: Vec<f32>,
}

/// A dataset at one training resolution.
#[derive(Debug, Clone)]
pub struct DatasetLevel {
    /// Colour composited on the background, `(V, 3, h, w)` in [0, 1].
    pub images: Tensor,
    /// Expected depth in world units, `(V, 1, h, w)`.
    pub depths: Tensor,
    /// Opacity, `(V, 1, h, w)` in [0, 1].
    pub opacity: Tensor,
    /// The cameras at this resolution (same field of view as the files').
    pub cameras: Vec<Camera>,
}

impl Dataset {
    /// Loads a dataset and checks every frame (see the [module docs](self) for the format and
    /// the checks). `transforms` is the `transforms.json` file or its directory; `background` is
    /// what transparent pixels are composited onto.
    pub fn load(transforms: &Path, background: [f32; 3]) -> Result<Self> {
        load::load(transforms, background)
    }

    /// The number of frames.
    #[must_use]
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether there are no frames (never true for a loaded dataset).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The images' width in pixels.
    #[must_use]
    pub fn width(&self) -> usize {
        self.width
    }

    /// The images' height in pixels.
    #[must_use]
    pub fn height(&self) -> usize {
        self.height
    }

    /// The frames' cameras, at the files' resolution.
    #[must_use]
    pub fn cameras(&self) -> &[Camera] {
        &self.cameras
    }

    /// The frames' names: their `file_path` as written in `transforms.json`.
    #[must_use]
    pub fn frame_names(&self) -> &[String] {
        &self.names
    }

    /// The frames at `indices`, in that order, as a dataset of their own (so [`Dataset::level`]
    /// resizes only them). Errors on an empty list or an index past the last frame.
    ///
    /// ```
    /// # use singrav::dataset::{write_dataset, Dataset, DatasetSpec};
    /// # let dir = tempfile::tempdir()?;
    /// # let spec = DatasetSpec { views: 3, resolution: 12, grid: 16, seed: 1 };
    /// # write_dataset(&singrav::scenes::Islands::new(1), dir.path(), &spec)?;
    /// let data = Dataset::load(dir.path(), [1.0; 3])?;
    /// let picked = data.subset(&[2, 0])?;
    /// assert_eq!(picked.frame_names(), ["images/r_002.png", "images/r_000.png"]);
    /// assert_eq!(picked.cameras()[1].c2w, data.cameras()[0].c2w);
    /// assert!(data.subset(&[3]).is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn subset(&self, indices: &[usize]) -> Result<Self> {
        if indices.is_empty() {
            return Err(invalid("frames", "choose at least one frame"));
        }
        if let Some(bad) = indices.iter().find(|&&i| i >= self.len()) {
            return Err(invalid(
                "frames",
                format!(
                    "frame {bad} does not exist: the dataset has {} (0 to {})",
                    self.len(),
                    self.len() - 1
                ),
            ));
        }
        Ok(Self {
            width: self.width,
            height: self.height,
            cameras: indices.iter().map(|&i| self.cameras[i]).collect(),
            names: indices.iter().map(|&i| self.names[i].clone()).collect(),
            frames: indices.iter().map(|&i| self.frames[i].clone()).collect(),
        })
    }

    /// Splits the frames for a held-out evaluation, as NeRF's LLFF convention does: with
    /// `every = N`, frames 0, N, 2N, ... are held out and the rest train. Returns
    /// `(training, held_out)` frame indices. Errors when `every < 2` (nothing would train or
    /// every frame would) or when fewer than one frame would remain for either side.
    ///
    /// ```
    /// # use singrav::dataset::{write_dataset, Dataset, DatasetSpec};
    /// # let dir = tempfile::tempdir()?;
    /// # let spec = DatasetSpec { views: 5, resolution: 8, grid: 8, seed: 1 };
    /// # write_dataset(&singrav::scenes::Islands::new(1), dir.path(), &spec)?;
    /// let data = Dataset::load(dir.path(), [1.0; 3])?;
    /// let (train, held_out) = data.holdout_split(2)?;
    /// assert_eq!((train, held_out), (vec![1, 3], vec![0, 2, 4]));
    /// assert!(data.holdout_split(1).is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn holdout_split(&self, every: usize) -> Result<(Vec<usize>, Vec<usize>)> {
        if every < 2 {
            return Err(invalid(
                "holdout",
                format!("expected every N-th view held out with N >= 2, got {every}"),
            ));
        }
        let (held_out, training): (Vec<usize>, Vec<usize>) =
            (0..self.len()).partition(|i| i % every == 0);
        if training.is_empty() {
            return Err(invalid(
                "holdout",
                format!(
                    "holding out every {every}-th of {} views leaves none to train on",
                    self.len()
                ),
            ));
        }
        Ok((training, held_out))
    }

    /// The dataset resized to `width` x `height` (area filter when shrinking, linear when
    /// enlarging, separately along each axis; any ratio), as tensors on `device`, with the
    /// cameras rescaled to match (same field of view, focal lengths and principal point scaled).
    ///
    /// ```
    /// # use singrav::dataset::{write_dataset, Dataset, DatasetSpec};
    /// # let dir = tempfile::tempdir()?;
    /// # let spec = DatasetSpec { views: 2, resolution: 12, grid: 16, seed: 1 };
    /// # write_dataset(&singrav::scenes::Islands::new(1), dir.path(), &spec)?;
    /// let data = Dataset::load(dir.path(), [1.0; 3])?;
    /// let level = data.level(8, 6, &candle_core::Device::Cpu)?;
    /// assert_eq!(level.images.dims(), &[2, 3, 6, 8]);
    /// assert_eq!(level.depths.dims(), &[2, 1, 6, 8]);
    /// assert_eq!((level.cameras[0].width, level.cameras[0].height), (8, 6));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn level(&self, width: usize, height: usize, device: &Device) -> Result<DatasetLevel> {
        if width == 0 || height == 0 {
            return Err(invalid(
                "level size",
                format!("expected width and height >= 1, got {width} x {height}"),
            ));
        }
        let (from, to) = ((self.height, self.width), (height, width));
        let plane = from.0 * from.1;
        let resize_all = |planes: &dyn Fn(&FramePixels) -> Vec<&[f32]>| -> Vec<f32> {
            self.frames
                .iter()
                .flat_map(planes)
                .flat_map(|p| resize_plane(p, from, to))
                .collect()
        };
        let images = resize_all(&|f| f.rgb.chunks_exact(plane).collect());
        let depths = resize_all(&|f| vec![&f.depth]);
        let opacity = resize_all(&|f| vec![&f.opacity]);
        let n = self.len();
        let (sx, sy) = (
            width as f32 / self.width as f32,
            height as f32 / self.height as f32,
        );
        let cameras = self
            .cameras
            .iter()
            .map(|c| {
                Camera::from_intrinsics(
                    c.c2w,
                    width,
                    height,
                    [c.fx * sx, c.fy * sy, c.cx * sx, c.cy * sy],
                )
            })
            .collect::<volrender::Result<Vec<_>>>()?;
        Ok(DatasetLevel {
            images: Tensor::from_vec(images, (n, 3, height, width), device)?,
            depths: Tensor::from_vec(depths, (n, 1, height, width), device)?,
            opacity: Tensor::from_vec(opacity, (n, 1, height, width), device)?,
            cameras,
        })
    }
}

/// The `transforms.json` a dataset path names: the path itself, or `transforms.json` inside it
/// when it is a directory.
fn transforms_file(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join("transforms.json")
    } else {
        path.to_path_buf()
    }
}
