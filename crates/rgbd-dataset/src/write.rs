//! Writing a dataset: bake a scene, render it from the paper's hemisphere cameras, store colour,
//! depth and cameras.

use std::path::{Path, PathBuf};
use std::time::Instant;

use image::ExtendedColorType;
use radiance_volume::GridDims;
use serde_json::json;
use volrender::{render_image, Camera, Image, RenderConfig, Sampler, PAPER_FOV_DEG, PAPER_RADIUS};

use super::pixels::encode_png;
use crate::error::{invalid, Result};
use crate::io::{create_dir, write_bytes};
use crate::scenes::{Scene, SceneKind};
use crate::source::{SceneSource, SOURCE_FIELD};

/// World units per count of the 16-bit depth PNGs [`write_dataset`] writes (depths up to 6.55).
pub const DEPTH_SCALE: f32 = 1e-4;

/// What [`write_dataset`] makes.
///
/// ```
/// let spec = rgbd_dataset::DatasetSpec { views: 20, ..Default::default() };
/// assert_eq!((spec.views, spec.resolution, spec.grid, spec.seed), (20, 128, 128, 0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DatasetSpec {
    /// Number of cameras (default 100).
    pub views: usize,
    /// Image width and height in pixels (default 128).
    pub resolution: usize,
    /// The scene is baked on a `grid`^3 volume before rendering (default 128).
    pub grid: usize,
    /// Seed of the camera placement on the hemisphere (default 0).
    pub seed: u64,
}

impl Default for DatasetSpec {
    fn default() -> Self {
        Self {
            views: 100,
            resolution: 128,
            grid: 128,
            seed: 0,
        }
    }
}

/// What [`write_dataset`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetSummary {
    /// The dataset's `transforms.json`.
    pub transforms: PathBuf,
    /// Number of frames.
    pub views: usize,
    /// Image width and height in pixels.
    pub resolution: usize,
    /// Wall-clock time of baking, rendering and writing, in seconds.
    pub seconds: f64,
}

/// The renderer settings of [`write_dataset`]: 3 midpoint samples per voxel crossed (the
/// shells of solid matter, 2 voxels wide at 128^3, get about 6 samples), exact (no early
/// termination; empty-space skipping does not change the result), black background so colour
/// stays premultiplied.
///
/// ```
/// let cfg = rgbd_dataset::render_config();
/// assert_eq!(cfg.background, None);
/// assert_eq!(cfg.epsilon, 0.0);
/// ```
#[must_use]
pub fn render_config() -> RenderConfig {
    RenderConfig::default()
        .with_sampler(Sampler::PerVoxel { per_voxel: 3 })
        .with_skip_empty(true)
}

/// Bakes `scene` at `spec.grid`^3, renders `spec.views` cameras placed on the paper's hemisphere
/// (radius [`PAPER_RADIUS`], field of view [`PAPER_FOV_DEG`], seeded by `spec.seed`) with
/// [`render_config`], and writes `images/`, `depth/` and `transforms.json` into `dir` (created
/// if needed; an existing dataset there is overwritten). The format is in the
/// [module docs](super).
///
/// ```
/// use rgbd_dataset::{write_dataset, DatasetSpec};
/// let dir = tempfile::tempdir()?;
/// let spec = DatasetSpec { views: 3, resolution: 8, grid: 16, seed: 2 };
/// let summary = write_dataset(&rgbd_dataset::scenes::Mushrooms::new(0), dir.path(), &spec)?;
/// assert_eq!(summary.transforms, dir.path().join("transforms.json"));
/// assert!(dir.path().join("depth/r_002.png").is_file());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_dataset(scene: &dyn Scene, dir: &Path, spec: &DatasetSpec) -> Result<DatasetSummary> {
    write_recorded(scene, None, dir, spec)
}

/// Writes the built-in scene `kind` laid out from `layout_seed` as [`write_dataset`] does, and
/// records it in `transforms.json` ([`SceneSource`]), so that its other layouts can be rendered
/// from the same cameras ([`Dataset::scene_source`](crate::Dataset::scene_source)); what
/// `volgen scene` writes.
///
/// ```
/// use rgbd_dataset::{write_built_in, Dataset, DatasetSpec};
/// use rgbd_dataset::scenes::SceneKind;
/// let dir = tempfile::tempdir()?;
/// let spec = DatasetSpec { views: 2, resolution: 8, grid: 16, seed: 2 };
/// write_built_in(SceneKind::Mushrooms, 5, dir.path(), &spec)?;
/// let source = Dataset::load(dir.path(), [1.0; 3])?.scene_source().unwrap();
/// assert_eq!((source.kind, source.seed, source.grid), (SceneKind::Mushrooms, 5, 16));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_built_in(
    kind: SceneKind,
    layout_seed: u64,
    dir: &Path,
    spec: &DatasetSpec,
) -> Result<DatasetSummary> {
    let source = SceneSource {
        kind,
        seed: layout_seed,
        grid: spec.grid,
    };
    write_recorded(kind.build(layout_seed).as_ref(), Some(source), dir, spec)
}

/// [`write_dataset`], with the scene's record when it is a built-in one.
fn write_recorded(
    scene: &dyn Scene,
    source: Option<SceneSource>,
    dir: &Path,
    spec: &DatasetSpec,
) -> Result<DatasetSummary> {
    let start = Instant::now();
    if spec.views == 0 || spec.resolution == 0 || spec.grid < 2 {
        return Err(invalid(
            "dataset spec",
            format!(
                "expected views >= 1, resolution >= 1 and grid >= 2, got {} views, resolution {}, grid {}",
                spec.views, spec.resolution, spec.grid
            ),
        ));
    }
    for sub in ["images", "depth"] {
        create_dir(&dir.join(sub))?;
    }
    // Rewriting a dataset: its transforms.json goes first and comes back last, so a run killed
    // in between leaves a directory the loader refuses, not old cameras over new images.
    let transforms_path = dir.join("transforms.json");
    radiance_volume::io::remove_file_if_exists(&transforms_path)?;
    let volume = scene.to_volume(GridDims::cube(spec.grid))?;
    let fov_x = PAPER_FOV_DEG.to_radians();
    let cameras = Camera::hemisphere(
        spec.views,
        PAPER_RADIUS,
        fov_x,
        spec.resolution,
        spec.resolution,
        spec.seed,
    )?;
    let cfg = render_config();
    let frames = cameras
        .iter()
        .enumerate()
        .map(|(i, camera)| {
            let image = render_image(&volume, camera, &cfg)?;
            let (colour, depth) = (
                format!("images/r_{i:03}.png"),
                format!("depth/r_{i:03}.png"),
            );
            write_bytes(&dir.join(&colour), &straight_rgba_png(&image)?)?;
            write_bytes(&dir.join(&depth), &depth_png(&image)?)?;
            Ok(json!({
                "file_path": colour,
                "depth_file_path": depth,
                "transform_matrix": camera.c2w.transpose().to_cols_array_2d(),
            }))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut transforms = json!({
        "camera_angle_x": fov_x,
        "w": spec.resolution,
        "h": spec.resolution,
        "depth_scale": DEPTH_SCALE,
        "depth_kind": "expected",
        "frames": frames,
    });
    if let Some(source) = source {
        transforms[SOURCE_FIELD] = source.to_json();
    }
    let text = serde_json::to_string_pretty(&transforms)
        .map_err(|e| invalid("transforms.json", e.to_string()))?;
    write_bytes(&transforms_path, text.as_bytes())?;
    Ok(DatasetSummary {
        transforms: transforms_path,
        views: spec.views,
        resolution: spec.resolution,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The image as an 8-bit RGBA PNG with straight alpha: rgb = premultiplied colour / opacity.
fn straight_rgba_png(image: &Image) -> Result<Vec<u8>> {
    let to_byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let bytes: Vec<u8> = image
        .rgb
        .iter()
        .zip(&image.opacity)
        .flat_map(|(rgb, &a)| {
            let straight = rgb.map(|c| if a > 0.0 { c / a } else { 0.0 });
            [
                to_byte(straight[0]),
                to_byte(straight[1]),
                to_byte(straight[2]),
                to_byte(a),
            ]
        })
        .collect();
    encode_png(&bytes, image.width, image.height, ExtendedColorType::Rgba8)
        .map_err(|why| invalid("colour image", why))
}

/// The expected depth as a 16-bit grey PNG in counts of [`DEPTH_SCALE`].
fn depth_png(image: &Image) -> Result<Vec<u8>> {
    let bytes: Vec<u8> = image
        .depth
        .iter()
        .flat_map(|&d| {
            let counts = (d / DEPTH_SCALE).round().clamp(0.0, f32::from(u16::MAX)) as u16;
            counts.to_ne_bytes()
        })
        .collect();
    encode_png(&bytes, image.width, image.height, ExtendedColorType::L16)
        .map_err(|why| invalid("depth image", why))
}
