//! Where a dataset's scene is: a box in the scene's own coordinates, found from the depth maps
//! or given, and the similarity that maps it into the model's cube `[-1, 1]^3`.

use glam::{Mat4, Vec3};
use radiance_volume::Aabb;
use serde::{Deserialize, Serialize};
use volrender::Camera;

use super::{Dataset, DepthKind, FramePixels};
use crate::error::{invalid, Result};

/// The box a scene occupies, in the dataset's world coordinates.
///
/// The model always works in `[-1, 1]^3`; a scene elsewhere is mapped there by the similarity
/// `x -> (x - centre) / half_side`, uniform so that rays stay rays and distances scale by one
/// factor. The model's cube lands on [`SceneBounds::cube`] (the box's centre plus or minus its
/// largest half side), which holds the whole box.
///
/// ```
/// use rgbd_dataset::SceneBounds;
/// let bounds: SceneBounds = "0,0,0,4,2,2".parse()?;
/// assert_eq!(bounds.half_side(), 2.0);
/// assert_eq!(bounds.to_model(glam::Vec3::new(4.0, 1.0, 1.0)), glam::Vec3::new(1.0, 0.0, 0.0));
/// assert_eq!(bounds.cube().min, glam::Vec3::new(0.0, -1.0, -1.0));
/// # Ok::<(), rgbd_dataset::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SceneBounds {
    /// The lower corner.
    pub min: [f32; 3],
    /// The upper corner.
    pub max: [f32; 3],
}

/// Back-projected depth points below this percentile (and above 100 minus it) along an axis
/// are outliers that `auto` bounds ignore.
const AUTO_PERCENTILE: f64 = 1.0;
/// `auto` bounds grow by this fraction of their size on every side.
const AUTO_MARGIN: f32 = 0.05;

impl SceneBounds {
    /// A box from its corners; errors unless they are finite and `min < max` on every axis.
    pub fn new(min: [f32; 3], max: [f32; 3]) -> Result<Self> {
        let finite = min.iter().chain(&max).all(|v| v.is_finite());
        if !finite || (0..3).any(|i| min[i] >= max[i]) {
            return Err(invalid(
                "bounds",
                format!(
                    "expected finite corners with min < max on every axis, got min {min:?}, \
                     max {max:?}"
                ),
            ));
        }
        Ok(Self { min, max })
    }

    /// The box's centre.
    #[must_use]
    pub fn centre(&self) -> Vec3 {
        (Vec3::from(self.min) + Vec3::from(self.max)) * 0.5
    }

    /// Half the box's largest side: the world length the model's unit stands for.
    #[must_use]
    pub fn half_side(&self) -> f32 {
        ((Vec3::from(self.max) - Vec3::from(self.min)) * 0.5).max_element()
    }

    /// Where the model's cube `[-1, 1]^3` lies in the scene: a cube around the box.
    #[must_use]
    pub fn cube(&self) -> Aabb {
        let (c, s) = (self.centre(), self.half_side());
        Aabb {
            min: c - Vec3::splat(s),
            max: c + Vec3::splat(s),
        }
    }

    /// A scene point in the model's coordinates.
    #[must_use]
    pub fn to_model(&self, p: Vec3) -> Vec3 {
        (p - self.centre()) / self.half_side()
    }

    /// Whether `p` is inside the box (boundary included).
    fn contains(&self, p: Vec3) -> bool {
        p.cmpge(Vec3::from(self.min)).all() && p.cmple(Vec3::from(self.max)).all()
    }

    /// The box's corners and centre.
    fn landmarks(&self) -> Vec<Vec3> {
        let (lo, hi) = (Vec3::from(self.min), Vec3::from(self.max));
        let mut points: Vec<Vec3> = (0..8)
            .map(|i| {
                Vec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                )
            })
            .collect();
        points.push(self.centre());
        points
    }
}

impl std::fmt::Display for SceneBounds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [a, b, c] = self.min;
        let [d, e, g] = self.max;
        write!(f, "{a:.4},{b:.4},{c:.4},{d:.4},{e:.4},{g:.4}")
    }
}

impl std::str::FromStr for SceneBounds {
    type Err = crate::Error;

    /// Parses `xmin,ymin,zmin,xmax,ymax,zmax`.
    fn from_str(s: &str) -> Result<Self> {
        let values: Vec<f32> = s
            .split(',')
            .map(|v| v.trim().parse::<f32>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| invalid("bounds", format!("`{s}`: {e}")))?;
        let [a, b, c, d, e, g] = values[..] else {
            return Err(invalid(
                "bounds",
                format!("expected xmin,ymin,zmin,xmax,ymax,zmax (6 numbers), got `{s}`"),
            ));
        };
        Self::new([a, b, c], [d, e, g])
    }
}

/// Where a scene is, as a user says it: its box, or `auto`, the box its depth maps (or sparse
/// points) show ([`Dataset::auto_bounds`]).
///
/// ```
/// use rgbd_dataset::{Bounds, SceneBounds};
/// assert_eq!("auto".parse::<Bounds>()?, Bounds::Auto);
/// let given: Bounds = "0,0,0,4,2,2".parse()?;
/// assert_eq!(given, Bounds::Box("0,0,0,4,2,2".parse::<SceneBounds>()?));
/// assert!("0,0,0,1,1".parse::<Bounds>().unwrap_err().to_string().contains("or auto"));
/// # Ok::<(), rgbd_dataset::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bounds {
    /// This box.
    Box(SceneBounds),
    /// The box the dataset shows.
    Auto,
}

impl Bounds {
    /// The box itself, or `auto`'s for `dataset`.
    pub fn resolve(&self, dataset: &Dataset) -> Result<SceneBounds> {
        match self {
            Self::Box(bounds) => Ok(*bounds),
            Self::Auto => dataset.auto_bounds(),
        }
    }
}

impl std::fmt::Display for Bounds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Box(bounds) => bounds.fmt(f),
            Self::Auto => f.write_str("auto"),
        }
    }
}

impl std::str::FromStr for Bounds {
    type Err = crate::Error;

    /// Parses `auto` or `xmin,ymin,zmin,xmax,ymax,zmax`.
    fn from_str(s: &str) -> Result<Self> {
        if s.trim() == "auto" {
            return Ok(Self::Auto);
        }
        s.parse().map(Self::Box).map_err(|e| match e {
            crate::Error::Invalid { what, why } => invalid(what, format!("{why}, or auto")),
            other => other,
        })
    }
}

/// Whether `camera` sees `p`: in front of it and inside its image.
fn sees(camera: &Camera, p: Vec3) -> bool {
    let q = camera.c2w.inverse().transform_point3(p);
    if q.z >= 0.0 {
        return false;
    }
    let col = camera.cx + camera.fx * q.x / -q.z;
    let row = camera.cy - camera.fy * q.y / -q.z;
    (0.0..camera.width as f32).contains(&col) && (0.0..camera.height as f32).contains(&row)
}

/// The `pct`-th percentile of `values` (sorted in place), nearest rank.
fn percentile(values: &mut [f32], pct: f64) -> f32 {
    values.sort_by(f32::total_cmp);
    let rank = ((pct / 100.0) * (values.len() - 1) as f64).round() as usize;
    values[rank]
}

impl Dataset {
    /// The box of the scene the depth maps show: every pixel with opacity > 0.5 and known
    /// depth is back-projected (ray distance = expected depth / opacity), the 1st and 99th
    /// percentiles of the points along each axis bound it, and it grows by 5% of its size on
    /// every side. A capture without depth maps that names its sparse points (nerfstudio's
    /// `ply_file_path`) is bounded by those points the same way. Errors when there is neither.
    ///
    /// ```
    /// use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
    /// let dir = tempfile::tempdir()?;
    /// let spec = DatasetSpec { views: 4, resolution: 16, grid: 24, seed: 1 };
    /// write_dataset(&rgbd_dataset::scenes::StandingStones::new(1), dir.path(), &spec)?;
    /// let bounds = Dataset::load(dir.path(), [1.0; 3])?.auto_bounds()?;
    /// // The built-in scenes lie in [-1, 1]^3.
    /// assert!(bounds.min.iter().all(|v| *v > -1.2) && bounds.max.iter().all(|v| *v < 1.2));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn auto_bounds(&self) -> Result<SceneBounds> {
        let mut axes = if self.depth_kind == DepthKind::None {
            self.sparse_points_by_axis()?
        } else {
            self.depth_points_by_axis()
        };
        if axes[0].is_empty() {
            return Err(invalid(
                "bounds",
                "`auto` found no point of the scene: no pixel has opacity > 0.5 and a known \
                 depth (or the sparse point cloud is empty)",
            ));
        }
        let (mut min, mut max) = ([0f32; 3], [0f32; 3]);
        for (a, values) in axes.iter_mut().enumerate() {
            let (lo, hi) = (
                percentile(values, AUTO_PERCENTILE),
                percentile(values, 100.0 - AUTO_PERCENTILE),
            );
            // A flat scene (a plane) still gets a box of some thickness.
            let margin = (AUTO_MARGIN * (hi - lo)).max(1e-3 * (1.0 + lo.abs().max(hi.abs())));
            (min[a], max[a]) = (lo - margin, hi + margin);
        }
        SceneBounds::new(min, max)
    }

    /// The x, y and z of every foreground pixel's surface point where its depth is known.
    fn depth_points_by_axis(&self) -> [Vec<f32>; 3] {
        let mut axes: [Vec<f32>; 3] = Default::default();
        for (camera, frame) in self.cameras.iter().zip(&self.frames) {
            for (i, (&a, &d)) in frame.opacity.iter().zip(&frame.depth).enumerate() {
                let known = frame.depth_mask.as_ref().is_none_or(|m| m[i] > 0.0);
                if a <= 0.5 || !known {
                    continue;
                }
                let (row, col) = ((i / self.width) as f32 + 0.5, (i % self.width) as f32 + 0.5);
                let (origin, dir) = camera.ray(row, col);
                let p = origin + dir * (d / a);
                for (axis, v) in axes.iter_mut().zip(p.to_array()) {
                    axis.push(v);
                }
            }
        }
        axes
    }

    /// The x, y and z of the capture's sparse points; errors without them.
    fn sparse_points_by_axis(&self) -> Result<[Vec<f32>; 3]> {
        let Some(file) = &self.points_file else {
            return Err(invalid(
                "bounds",
                "`auto` needs depth maps or sparse points, and this dataset has neither                  (`depth_kind` \"none\", no `ply_file_path`): give the scene's box                  xmin,ymin,zmin,xmax,ymax,zmax in the dataset's coordinates, or import the                  capture (`volgen import colmap` or `volgen import nerfstudio`), which turns it                  upright and places it in the model's cube from its sparse points and the photos'                  foreground",
            ));
        };
        let mut axes: [Vec<f32>; 3] = Default::default();
        for p in crate::nerfstudio::read_points(file)? {
            for (axis, v) in axes.iter_mut().zip(p.to_array()) {
                axis.push(v as f32);
            }
        }
        Ok(axes)
    }

    /// The dataset with its scene moved from `bounds` into the model's cube: cameras mapped by
    /// [`SceneBounds::to_model`] (rotations kept), depth divided by the half side. Errors when
    /// a camera is inside the box or no camera sees any of its corners or its centre.
    ///
    /// ```
    /// use rgbd_dataset::{write_dataset, Dataset, DatasetSpec, SceneBounds};
    /// let dir = tempfile::tempdir()?;
    /// let spec = DatasetSpec { views: 2, resolution: 8, grid: 8, seed: 1 };
    /// write_dataset(&rgbd_dataset::scenes::Islands::new(1), dir.path(), &spec)?;
    /// let data = Dataset::load(dir.path(), [1.0; 3])?;
    /// let moved = data.in_model_cube(&"-2,-2,-2,2,2,2".parse()?)?;
    /// let (a, b) = (data.cameras()[0].position(), moved.cameras()[0].position());
    /// assert!((a * 0.5 - b).length() < 1e-6);
    /// assert!(data.in_model_cube(&"-9,-9,-9,9,9,9".parse()?).is_err()); // cameras inside
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn in_model_cube(&self, bounds: &SceneBounds) -> Result<Self> {
        if let Some((i, camera)) = self
            .cameras
            .iter()
            .enumerate()
            .find(|(_, c)| bounds.contains(c.position()))
        {
            return Err(invalid(
                "bounds",
                format!(
                    "camera of frame {} at {:?} is inside the box {bounds}: the box must hold \
                     the scene, not the cameras",
                    self.names[i],
                    camera.position().to_array()
                ),
            ));
        }
        let landmarks = bounds.landmarks();
        if !self
            .cameras
            .iter()
            .any(|c| landmarks.iter().any(|&p| sees(c, p)))
        {
            return Err(invalid(
                "bounds",
                format!("no camera sees the box {bounds} (neither its corners nor its centre)"),
            ));
        }
        let s = bounds.half_side();
        let map = Mat4::from_scale(Vec3::splat(1.0 / s)) * Mat4::from_translation(-bounds.centre());
        let cameras = self
            .cameras
            .iter()
            .map(|c| {
                let mut c2w = c.c2w;
                c2w.w_axis = map.transform_point3(c.position()).extend(1.0);
                Camera::from_intrinsics(c2w, c.width, c.height, [c.fx, c.fy, c.cx, c.cy])
            })
            .collect::<volrender::Result<Vec<_>>>()?;
        let frames = self
            .frames
            .iter()
            .map(|f| FramePixels {
                depth: f.depth.iter().map(|d| d / s).collect(),
                ..f.clone()
            })
            .collect();
        Ok(Self {
            cameras,
            frames,
            // The points are in the scene's frame, not the model's.
            points_file: None,
            ..self.clone()
        })
    }
}
