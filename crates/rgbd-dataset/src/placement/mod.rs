//! Where a capture's scene goes in the model's cube: a reconstruction's frame is arbitrary (any
//! rotation, scale and position), so [`Placement`] turns it upright ([`up_direction`]), centres
//! it and scales it from its sparse points and its photos' foreground. A [`SparseCapture`] is
//! what it reads: camera poses and points, from a COLMAP model ([`crate::colmap::import`]) or a
//! nerfstudio file with its point cloud ([`crate::nerfstudio::import`]).
//!
//! ```
//! use glam::{DMat4, DVec3};
//! use rgbd_dataset::placement::{up_direction, SparseCapture, UpFrom};
//! // Two cameras looking down at a ground of points in the plane y = 0 (y is this frame's up).
//! let look = |eye: DVec3| DMat4::look_at_rh(eye, DVec3::ZERO, DVec3::Y).inverse();
//! let points = (0..100)
//!     .map(|i| DVec3::new(f64::from(i % 10), 0.0, f64::from(i / 10)) * 0.1)
//!     .collect();
//! let capture = SparseCapture {
//!     cameras: vec![look(DVec3::new(2.0, 3.0, 0.0)), look(DVec3::new(-2.0, 3.0, 1.0))],
//!     points,
//! };
//! let (up, from) = up_direction(&capture, UpFrom::Ground).unwrap();
//! assert_eq!(from, UpFrom::Ground);
//! assert!(up.angle_between(DVec3::Y) < 1e-6);
//! ```

mod up;

pub use up::{cameras_up, ground_plane, up_direction, UpFrom};

use glam::{DMat3, DMat4, DVec3};

use crate::error::{invalid, Result};
use up::rotation_between;

/// What placing a capture reads: where its photos were taken and its sparse points, in the
/// capture's own frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SparseCapture {
    /// Camera to world of each photo, in the NeRF convention (x right, y up, looking down -z).
    pub cameras: Vec<DMat4>,
    /// The triangulated points.
    pub points: Vec<DVec3>,
}

/// Where the capture's points go: all but the outermost 1% on each side per axis (between
/// these percentiles) fill this much of the model's half side, as `--bounds auto` places a scene
/// from its depth maps (1st to 99th percentile, 5% margin each side): stray points far out do
/// not shrink the scene, and its edges stay inside the cube. (The 5th to 95th percentiles filling
/// 0.9 cut off the ground of a Blender scene: a fit of its views reached 18.4 dB.)
const POINT_PERCENTILES: (f64, f64) = (0.01, 0.99);
const FILLED_HALF_SIDE: f64 = 1.0 / 1.1;

/// The similarity from a capture's frame to the dataset's: `p' = scale * rotation * (p -
/// centre)`. The rotation turns the up direction to +z (the ground plane's normal or the
/// cameras' mean up, [`up_direction`]); the centre and scale put the middle of the scene's box at the
/// origin and its largest half side at 1 / 1.1 of the cube's, as `--bounds auto` places a scene
/// from its depth maps. The scene's box is the box of the foreground's visual hull when the
/// photos' foreground is known ([`Placement::of_foreground`]) across, the sparse points'
/// central 98% up and down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Turns the capture's up direction to +z.
    pub rotation: DMat3,
    /// The middle of the scene's box, in the capture's frame.
    pub centre: DVec3,
    /// Scale from the capture's lengths to the dataset's.
    pub scale: f64,
    /// Where the up direction the rotation turns to +z came from ([`up_direction`]).
    pub up: UpFrom,
}

impl Placement {
    /// The placement with the box of the foreground's visual hull: the points of space that
    /// every photo seeing them shows as foreground (`foreground[i]`, one per registered image,
    /// in order). Sparse points miss the parts of a scene where few features are found (a plain
    /// ground's far edges, seen obliquely); the masks do not. The hull bounds the scene across
    /// (x and y after turning it upright), searched on a grid around the points' box (a square
    /// twice its diagonal across, between their lowest and highest up and down) among the grid
    /// points at least half the photos frame; up and down the points' box bounds it (photos from
    /// around and above carve neither under the ground nor far above it). The scene is turned
    /// about +z so that the hull's box is narrowest (`narrowest_azimuth`).
    pub fn of_foreground(
        capture: &SparseCapture,
        foreground: &[Foreground],
        up: UpFrom,
    ) -> Result<Self> {
        let (upright, up) = upright(capture, up)?;
        let (low, high) = points_box(capture, upright);
        let (centre, reach) = (
            0.5 * (low + high),
            (high - low).truncate().length().max(1e-9),
        );
        let search = (
            DVec3::new(centre.x - reach, centre.y - reach, low.z),
            DVec3::new(centre.x + reach, centre.y + reach, high.z),
        );
        let (hull, cell) = hull_points(capture, foreground, upright, search);
        if hull.is_empty() {
            let turned: Vec<DVec3> = capture.points.iter().map(|&p| upright * p).collect();
            let rotation = spin(narrowest_azimuth(&turned, central_box)) * upright;
            return Self::around((rotation, up), points_box(capture, rotation));
        }
        let rotation = spin(narrowest_azimuth(&hull, exact_box)) * upright;
        let (hull_low, hull_high) = exact_box(
            &hull
                .iter()
                .map(|&p| spin_of(rotation, upright) * p)
                .collect::<Vec<_>>(),
        );
        let (low, high) = points_box(capture, rotation);
        let margin = 0.5 * cell;
        let low = DVec3::new(hull_low.x - margin, hull_low.y - margin, low.z);
        let high = DVec3::new(hull_high.x + margin, hull_high.y + margin, high.z);
        Self::around((rotation, up), (low, high))
    }

    /// Centres and scales the box `(low, high)` of the turned frame.
    fn around((rotation, up): (DMat3, UpFrom), (low, high): (DVec3, DVec3)) -> Result<Self> {
        let half = 0.5 * (high - low);
        if half.max_element() <= 0.0 {
            return Err(invalid(
                "capture",
                "the scene's box has no extent: too few or identical points",
            ));
        }
        Ok(Self {
            rotation,
            centre: rotation.transpose() * (0.5 * (low + high)),
            scale: FILLED_HALF_SIDE / half.max_element(),
            up,
        })
    }

    /// The capture's direction that became +z (unit).
    #[must_use]
    pub fn up_in_capture(&self) -> DVec3 {
        self.rotation.transpose() * DVec3::Z
    }

    /// The placement as a 4x4 matrix acting on points.
    pub fn matrix(&self) -> DMat4 {
        DMat4::from_scale(DVec3::splat(self.scale))
            * DMat4::from_mat3(self.rotation)
            * DMat4::from_translation(-self.centre)
    }

    /// A camera-to-world matrix (rigid) of the capture as one of the dataset: rotated, its
    /// centre placed; still rigid (the scale moves centres only).
    pub fn place_camera(&self, c2w: DMat4) -> DMat4 {
        let rotation = self.rotation * DMat3::from_mat4(c2w);
        let centre = self.matrix().transform_point3(c2w.w_axis.truncate());
        let mut placed = DMat4::from_mat3(rotation);
        placed.w_axis = centre.extend(1.0);
        placed
    }
}

/// The rotation turning the up direction `up` asks for to +z (the shortest one), and where up
/// came from; errors without images or points.
fn upright(capture: &SparseCapture, up: UpFrom) -> Result<(DMat3, UpFrom)> {
    if capture.cameras.is_empty() || capture.points.is_empty() {
        return Err(invalid(
            "capture",
            format!(
                "needs posed photos and 3D points to place the scene, has {} photos and {} \
                 points",
                capture.cameras.len(),
                capture.points.len()
            ),
        ));
    }
    Ok(match up_direction(capture, up) {
        Some((direction, used)) => (rotation_between(direction, DVec3::Z), used),
        None => (DMat3::IDENTITY, UpFrom::Cameras),
    })
}

/// Azimuths tried by [`narrowest_azimuth`]: steps over a quarter turn (a box turned by a
/// quarter turn is the same box).
const AZIMUTH_STEPS: usize = 180;

/// The turn about +z (radians, in half-degree steps) that makes the box `box_of` gives the
/// points narrowest: its largest horizontal side smallest. Turning a capture upright by the
/// shortest turn to +z leaves its azimuth where the capture's frame had it, and the scene's box
/// is axis-aligned in the turned frame: one COLMAP reconstruction imported as COLMAP wrote it and
/// as nerfstudio rewrote it (axes swapped) got boxes whose largest sides differed by 13% (scales
/// 0.585 and 0.511). The narrowest box is the scene's own whatever the frame, and it fills the
/// cube best (on that reconstruction, scales 0.587 and 0.590 from the two files).
fn narrowest_azimuth(points: &[DVec3], box_of: fn(&[DVec3]) -> (DVec3, DVec3)) -> f64 {
    let widest_side = |azimuth: f64| {
        let spun: Vec<DVec3> = points.iter().map(|&p| spin(azimuth) * p).collect();
        let (low, high) = box_of(&spun);
        (high - low).truncate().max_element()
    };
    let quarter = std::f64::consts::FRAC_PI_2;
    (0..AZIMUTH_STEPS)
        .map(|k| quarter * k as f64 / AZIMUTH_STEPS as f64)
        .min_by(|&a, &b| widest_side(a).total_cmp(&widest_side(b)))
        .unwrap_or(0.0)
}

/// The turn by `azimuth` radians about +z.
fn spin(azimuth: f64) -> DMat3 {
    DMat3::from_rotation_z(azimuth)
}

/// The turn about +z that `rotation` adds to `upright`.
fn spin_of(rotation: DMat3, upright: DMat3) -> DMat3 {
    rotation * upright.transpose()
}

/// The smallest box holding `points`.
fn exact_box(points: &[DVec3]) -> (DVec3, DVec3) {
    points
        .iter()
        .fold((DVec3::MAX, DVec3::MIN), |(low, high), &p| {
            (low.min(p), high.max(p))
        })
}

/// The box of the points turned by `rotation`, between the [`POINT_PERCENTILES`].
fn points_box(capture: &SparseCapture, rotation: DMat3) -> (DVec3, DVec3) {
    let turned: Vec<DVec3> = capture.points.iter().map(|&p| rotation * p).collect();
    central_box(&turned)
}

/// Cells across (x and y) and up (z) of the grid the visual hull is searched on.
const HULL_CELLS_ACROSS: usize = 128;
const HULL_CELLS_UP: usize = 64;

/// The centres (in the turned frame) of the cells of the grid over `search` that every photo
/// framing them shows as foreground, and that at least half the photos (and two) frame; and
/// the cells' side across.
fn hull_points(
    capture: &SparseCapture,
    foreground: &[Foreground],
    rotation: DMat3,
    (low, high): (DVec3, DVec3),
) -> (Vec<DVec3>, f64) {
    let views: Vec<MaskedView<'_>> = capture
        .cameras
        .iter()
        .zip(foreground)
        .map(|(c2w, photo)| MaskedView::new(c2w, photo))
        .collect();
    // A point of the scene is in most photos' frame; points that few photos frame are not
    // carved by the others and would otherwise stay.
    let min_framed = (views.len() / 2).max(2);
    let cells = DVec3::new(
        HULL_CELLS_ACROSS as f64,
        HULL_CELLS_ACROSS as f64,
        HULL_CELLS_UP as f64,
    );
    let step = (high - low) / cells;
    let mut kept = Vec::new();
    for k in 0..HULL_CELLS_UP {
        for j in 0..HULL_CELLS_ACROSS {
            for i in 0..HULL_CELLS_ACROSS {
                let turned =
                    low + step * DVec3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5);
                let world = rotation.transpose() * turned;
                let mut framed = 0;
                let inside = views.iter().all(|view| match view.shows(world) {
                    None => true,
                    Some(foreground) => {
                        framed += 1;
                        foreground
                    }
                });
                if inside && framed >= min_framed {
                    kept.push(turned);
                }
            }
        }
    }
    (kept, step.x)
}

/// A registered photo's foreground, as [`Placement::of_foreground`] reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct Foreground {
    /// `fx, fy, cx, cy` of the photo's pinhole camera (after undistortion), in pixels.
    pub intrinsics: [f64; 4],
    /// Width and height of the photo, pixels.
    pub size: (usize, usize),
    /// Opacity bytes, row-major at `size`; above half is foreground.
    pub alpha: Vec<u8>,
}

/// A registered photo as the visual hull sees it: its pose (world to camera in OpenCV's axes,
/// x right, y down, z forward), pinhole intrinsics and foreground.
struct MaskedView<'a> {
    rotation: DMat3,
    translation: DVec3,
    intrinsics: [f64; 4],
    size: (usize, usize),
    /// Opacity bytes, row-major.
    alpha: &'a [u8],
}

impl<'a> MaskedView<'a> {
    /// The view of a camera-to-world pose in the NeRF convention and its photo's foreground.
    fn new(c2w: &DMat4, photo: &'a Foreground) -> Self {
        let to_world = DMat3::from_mat4(*c2w) * DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0));
        let rotation = to_world.transpose();
        Self {
            rotation,
            translation: -(rotation * c2w.w_axis.truncate()),
            intrinsics: photo.intrinsics,
            size: photo.size,
            alpha: &photo.alpha,
        }
    }

    /// Whether the photo shows the world point as foreground (opacity above half), or `None`
    /// when the point is behind the camera or outside the frame.
    fn shows(&self, world: DVec3) -> Option<bool> {
        let c = self.rotation * world + self.translation;
        let [fx, fy, cx, cy] = self.intrinsics;
        let (w, h) = self.size;
        let (u, v) = (fx * c.x / c.z + cx, fy * c.y / c.z + cy);
        let framed = c.z > 0.0 && u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64;
        framed.then(|| self.alpha[v as usize * w + u as usize] > u8::MAX / 2)
    }
}

/// Per axis the [`POINT_PERCENTILES`] of `points`.
fn central_box(points: &[DVec3]) -> (DVec3, DVec3) {
    let mut low = DVec3::ZERO;
    let mut high = DVec3::ZERO;
    for axis in 0..3 {
        let mut values: Vec<f64> = points.iter().map(|p| p[axis]).collect();
        values.sort_by(f64::total_cmp);
        let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
        low[axis] = at(POINT_PERCENTILES.0);
        high[axis] = at(POINT_PERCENTILES.1);
    }
    (low, high)
}

/// The placement an import recorded in a dataset (`volgen_import.capture_to_dataset` of its
/// `transforms.json`, or of the directory's): the similarity from the capture's frame to the
/// dataset's, the inverse of which takes what is made in the dataset's frame (volumes, meshes)
/// back to the capture's. Errors name the file and the field: no record, not a 4x4 of finite
/// numbers, last row not `[0, 0, 0, 1]`, or not a similarity (a turn and one positive scale,
/// within 1e-6).
///
/// ```
/// use rgbd_dataset::placement::recorded_placement;
/// let dir = tempfile::tempdir()?;
/// let record = r#"{"frames": [], "volgen_import": {"capture_to_dataset":
///     [[0, -2, 0, 1], [2, 0, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]}}"#;
/// std::fs::write(dir.path().join("transforms.json"), record)?;
/// let m = recorded_placement(dir.path())?;
/// assert_eq!(m.transform_point3(glam::DVec3::X), glam::DVec3::new(1.0, 2.0, 0.0));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn recorded_placement(transforms: &std::path::Path) -> Result<DMat4> {
    let path = crate::transforms_file(transforms);
    let error = |why: String| crate::Error::Dataset {
        path: path.clone(),
        frame: None,
        why,
    };
    let text = std::fs::read_to_string(&path).map_err(crate::error::io_error(&path))?;
    let root: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| error(format!("not valid JSON: {e}")))?;
    let Some(record) = root.pointer("/volgen_import/capture_to_dataset") else {
        return Err(error(
            "has no `volgen_import.capture_to_dataset`: only datasets written by `volgen import` \
             record the capture's frame"
                .into(),
        ));
    };
    let field = "`volgen_import.capture_to_dataset`";
    let mut rows = [[0f64; 4]; 4];
    for (r, row) in rows.iter_mut().enumerate() {
        for (c, value) in row.iter_mut().enumerate() {
            *value = record
                .get(r)
                .and_then(|row| row.get(c))
                .and_then(serde_json::Value::as_f64)
                .filter(|v| v.is_finite())
                .ok_or_else(|| error(format!("{field} must be 4 rows of 4 finite numbers")))?;
        }
    }
    if rows[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(error(format!(
            "{field}'s last row must be [0, 0, 0, 1], got {:?}",
            rows[3]
        )));
    }
    let m = DMat4::from_cols_array_2d(&rows).transpose();
    let linear = DMat3::from_mat4(m);
    let scale = linear.determinant().cbrt();
    let turn = linear * (1.0 / scale);
    let off = (turn.transpose() * turn - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0f64, |worst, v| worst.max(v.abs()));
    if scale <= 0.0 || off > 1e-6 {
        return Err(error(format!(
            "{field} is not a similarity (a turn and one positive scale): {rows:?}"
        )));
    }
    Ok(m)
}
