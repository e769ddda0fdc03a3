//! Multi-view RGB-D datasets and the built-in scenes they are made from.
//!
//! - [`scenes`]: procedural scenes (standing stones, mushrooms, islands), so a project needs no
//!   download to have a natural scene to learn from.
//! - [`write_dataset`] renders a scene into a NeRF-style RGB-D dataset; [`Dataset::load`] reads
//!   one from disk (any tool's, within the format below); [`Dataset::level`] resizes it to a
//!   training scale; [`SceneBounds`] places a scene that is not in the unit cube.
//! - Captures of your own: [`colmap`] imports a COLMAP reconstruction, [`nerfstudio`] places a
//!   nerfstudio capture; both turn the scene upright and into the model's cube ([`placement`]).
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
//!   down its -Z axis, +Y up), or OpenCV's axes with `"camera_axes": "opencv"`. It must be rigid:
//!   finite, rotation part orthonormal within 1e-3 with determinant +1, last row `[0, 0, 0, 1]`.
//! - `file_path`: the colour image, relative to the `transforms.json` directory; 8- or 16-bit
//!   PNG, RGBA with straight (not premultiplied) alpha, or RGB (opaque), or JPEG. Without an
//!   extension (Blender NeRF style) `.png` is appended when the bare name does not exist.
//! - nerfstudio's capture fields: `mask_path` (per frame, white on the scene; multiplies alpha)
//!   and the lens, `camera_model` (`OPENCV`, the default, `OPENCV_FISHEYE`, `PINHOLE`) with `k1`
//!   to `k4`, `p1`, `p2`: distorted photos are undistorted while loading ([`lens`]) into
//!   pinhole cameras; `ply_file_path`, the sparse points ([`nerfstudio::read_points`]), which
//!   [`Dataset::auto_bounds`] bounds a capture without depth maps by.
//! - `depth_file_path` (required unless `depth_kind` is `"none"`): a 16-bit grey PNG whose counts times the top-level
//!   `depth_scale` (world units per count, required for PNG depth: millimetre PNGs are 0.001)
//!   give the depth, or an `.exr` file (single- or multi-part) whose channel `Z` or ending in `.Z`
//!   (Blender's `ViewLayer.Depth.Z`), or else `Y`, or else `R`, holds depth in world units.
//! - `volgen_scene` (optional): the built-in scene the dataset was rendered from,
//!   `{"name": "stones", "seed": 0, "grid": 128}` ([`write_built_in`] writes it; `volgen eval
//!   --family` renders the scene's other layouts from its cameras); a malformed record is an
//!   error naming the field.
//! - `depth_kind` (required, or `volgen train --depth-kind KIND`, which overrides it; volgen
//!   writes it in every dataset it makes): how the depth maps measure depth.
//!   - `"expected"`: the renderer's expected depth along the ray, `sum_i w_i t_i` (t is the
//!     distance from the camera, not the z coordinate), not divided by opacity, so 0 where nothing
//!     is hit. Read as is; a non-finite value is an error.
//!   - `"z"`: planar depth, the distance along the camera's viewing axis (-Z) to the surface, as
//!     Blender's Z pass and most RGB-D sensors give it. Divided by the cosine between the pixel
//!     centre's ray and the viewing axis, it becomes ray distance, then as `"distance"`.
//!   - `"distance"`: the ray length to the surface. Loading stores `alpha x distance`, the
//!     expected depth of a surface covering the fraction alpha of the pixel.
//!
//!   - `"none"`: no depth maps (photos posed by structure from motion,
//!     [`colmap`]): every pixel is left out of the depth loss, and `volgen train` and `fit` go
//!     without it. A file with no `depth_kind` and no `depth_file_path` in any frame is read
//!     as `"none"`.
//!
//!   Under `"z"` and `"distance"` a value that is infinite, NaN, >= 1e9 (Blender writes 1e10),
//!   65504 (half float's largest) or 0 says "no surface". Where alpha is 0 that is the
//!   background (expected depth 0). Where alpha > 0 and the depth says no surface, the pixel is
//!   left out of the depth loss (a per-pixel weight that resizing averages; the left-out pixels
//!   are counted, and `volgen train` reports them; the critics, which see whole real views,
//!   see 0 there); when more than 5% of a view's foreground
//!   (alpha > 0.5 + 1/255: an 8-bit PNG stores a renderer's exact 0.5 as 128/255) is left out,
//!   loading fails naming the depth file and the count. Negative depth
//!   is an error under every kind. A dataset with depth maps but without `depth_kind` and
//!   without the flag is refused with an error that explains the three kinds: depth read as the wrong kind trains on silently
//!   wrong depth.
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
//! use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
//! use rgbd_dataset::scenes::SceneKind;
//! let spec = DatasetSpec { views: 6, resolution: 32, grid: 48, ..DatasetSpec::default() };
//! let summary = write_dataset(&*SceneKind::Mushrooms.build(0), "data/mushrooms".as_ref(), &spec)?;
//! let data = Dataset::load(&summary.transforms, [1.0, 1.0, 1.0])?;
//! let level = data.level(16, 16, &candle_core::Device::Cpu)?;
//! assert_eq!(level.images.dims(), &[6, 3, 16, 16]);
//! # Ok::<(), rgbd_dataset::Error>(())
//! ```

use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use volrender::Camera;

use crate::error::invalid;

mod bounds;
mod capture;
pub mod colmap;
mod depth;
mod error;
mod io;
pub mod lens;
mod load;
pub mod nerfstudio;
mod pixels;
pub mod placement;
mod rendered;
mod resize;
pub mod scenes;
mod source;
mod write;

pub use bounds::{Bounds, SceneBounds};
pub use depth::DepthKind;
pub use error::{Error, Result};
pub use rendered::{DepthCoverage, MIN_COVERED_SHARE};
pub use source::SceneSource;
pub use write::{
    render_config, write_built_in, write_dataset, DatasetSpec, DatasetSummary, DEPTH_SCALE,
};

use resize::resize_plane;

/// A loaded dataset: per frame its camera, colour composited on a background, opacity and
/// expected depth, at the files' resolution.
///
/// ```
/// use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
/// use rgbd_dataset::scenes::StandingStones;
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
    depth_kind: DepthKind,
    source: Option<SceneSource>,
    /// The capture's sparse points (nerfstudio's `ply_file_path`, resolved), if it names them.
    points_file: Option<PathBuf>,
}

/// How [`Dataset::load_with`] reads a dataset.
///
/// ```
/// use rgbd_dataset::{DepthKind, LoadOptions};
/// let options = LoadOptions { depth_kind: Some(DepthKind::Z), ..LoadOptions::default() };
/// assert_eq!(options.background, [1.0; 3]);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadOptions {
    /// What transparent pixels are composited onto (default white).
    pub background: [f32; 3],
    /// How the depth maps measure depth; overrides the file's `depth_kind` when given (default
    /// `None`: the file must say).
    pub depth_kind: Option<DepthKind>,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            background: [1.0; 3],
            depth_kind: None,
        }
    }
}

/// One frame's planes, row-major at the dataset's resolution.
#[derive(Debug, Clone)]
struct FramePixels {
    /// Colour composited on the background, channel-major `(3, h, w)`.
    rgb: Vec<f32>,
    /// Opacity `(h, w)`.
    opacity: Vec<f32>,
    /// Expected depth in world units `(h, w)`, 0 where left out.
    depth: Vec<f32>,
    /// 1 where the depth is known, 0 where it is left out of the depth loss `(h, w)`; `None`
    /// when every pixel's depth is known.
    depth_mask: Option<Vec<f32>>,
    /// How many pixels the mask leaves out.
    depth_left_out: usize,
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
    /// How much each pixel's depth counts in the depth loss, `(V, 1, h, w)` in [0, 1]: the
    /// fraction of the source pixels under it whose depth is known. `None` when every source
    /// pixel's depth is known (then every pixel counts fully).
    pub depth_mask: Option<Tensor>,
    /// The cameras at this resolution (same field of view as the files').
    pub cameras: Vec<Camera>,
}

impl Dataset {
    /// Loads a dataset and checks every frame (see the [module docs](self) for the format and
    /// the checks). `transforms` is the `transforms.json` file or its directory; `background` is
    /// what transparent pixels are composited onto.
    pub fn load(transforms: &Path, background: [f32; 3]) -> Result<Self> {
        Self::load_with(
            transforms,
            &LoadOptions {
                background,
                depth_kind: None,
            },
        )
    }

    /// Loads a dataset as [`Dataset::load`] does, with the depth kind overridable (a dataset
    /// made elsewhere may not say how its depth is measured).
    ///
    /// ```
    /// use rgbd_dataset::{write_dataset, Dataset, DatasetSpec, DepthKind, LoadOptions};
    /// let dir = tempfile::tempdir()?;
    /// let spec = DatasetSpec { views: 1, resolution: 8, grid: 8, seed: 1 };
    /// write_dataset(&rgbd_dataset::scenes::Islands::new(1), dir.path(), &spec)?;
    /// let options = LoadOptions { depth_kind: Some(DepthKind::Expected), ..Default::default() };
    /// let data = Dataset::load_with(dir.path(), &options)?;
    /// assert_eq!((data.depth_kind(), data.depth_left_out()), (DepthKind::Expected, 0));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn load_with(transforms: &Path, options: &LoadOptions) -> Result<Self> {
        load::load(transforms, options)
    }

    /// How the files measured depth (the loaded depth is always expected depth).
    #[must_use]
    pub fn depth_kind(&self) -> DepthKind {
        self.depth_kind
    }

    /// How many pixels, over all frames, have colour but no depth (the depth map says "no
    /// surface" where the opacity is above 0) and are left out of the depth loss.
    #[must_use]
    pub fn depth_left_out(&self) -> usize {
        self.frames.iter().map(|f| f.depth_left_out).sum()
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

    /// The built-in scene the dataset shows, when `transforms.json` records one
    /// ([`write_built_in`] does; `None` for every other dataset).
    #[must_use]
    pub fn scene_source(&self) -> Option<SceneSource> {
        self.source
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
    /// # use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
    /// # let dir = tempfile::tempdir()?;
    /// # let spec = DatasetSpec { views: 3, resolution: 12, grid: 16, seed: 1 };
    /// # write_dataset(&rgbd_dataset::scenes::Islands::new(1), dir.path(), &spec)?;
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
            depth_kind: self.depth_kind,
            source: self.source,
            points_file: self.points_file.clone(),
        })
    }

    /// Splits the frames for a held-out evaluation, as NeRF's LLFF convention does: with
    /// `every = N`, frames 0, N, 2N, ... are held out and the rest train. Returns
    /// `(training, held_out)` frame indices. Errors when `every < 2` (nothing would train or
    /// every frame would) or when fewer than one frame would remain for either side.
    ///
    /// ```
    /// # use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
    /// # let dir = tempfile::tempdir()?;
    /// # let spec = DatasetSpec { views: 5, resolution: 8, grid: 8, seed: 1 };
    /// # write_dataset(&rgbd_dataset::scenes::Islands::new(1), dir.path(), &spec)?;
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
    /// # use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
    /// # let dir = tempfile::tempdir()?;
    /// # let spec = DatasetSpec { views: 2, resolution: 12, grid: 16, seed: 1 };
    /// # write_dataset(&rgbd_dataset::scenes::Islands::new(1), dir.path(), &spec)?;
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
        let mut depths = resize_all(&|f| vec![&f.depth]);
        let opacity = resize_all(&|f| vec![&f.opacity]);
        let n = self.len();
        let depth_mask = if self.frames.iter().any(|f| f.depth_mask.is_some()) {
            let mask: Vec<f32> = self
                .frames
                .iter()
                .flat_map(|f| match &f.depth_mask {
                    Some(mask) => resize_plane(mask, from, to),
                    None => vec![1.0; width * height],
                })
                .collect();
            // Left-out pixels hold 0, so the resized depth is the mean over the known ones
            // times their fraction: divide it back out.
            for (d, &m) in depths.iter_mut().zip(&mask) {
                *d = if m > 0.0 { *d / m } else { 0.0 };
            }
            Some(Tensor::from_vec(mask, (n, 1, height, width), device)?)
        } else {
            None
        };
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
            depth_mask,
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

/// The types most users of this crate need, for `use rgbd_dataset::prelude::*;`.
pub mod prelude {
    pub use crate::scenes::{Scene, SceneKind};
    pub use crate::{
        write_dataset, Bounds, Dataset, DatasetSpec, DepthKind, LoadOptions, SceneBounds,
    };
}

/// The README's examples, compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
