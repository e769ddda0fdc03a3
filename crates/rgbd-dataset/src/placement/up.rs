//! Which way is up in a reconstruction: its frame is arbitrary, and the model learns scenes
//! with +z up. Two estimates: the cameras' mean up direction (nerfstudio's `orientation_method
//! up`), and the normal of the plane most sparse points lie on (the ground). On four COLMAP
//! reconstructions of a Blender scene photographed from a hemisphere above it, the ground's
//! normal was 0.6-1.1 degrees from the true up, the cameras' mean 7.4-12.9 degrees (the
//! registered cameras are not spread evenly around; docs/journal/2026-12-photos.md), so the
//! ground is tried first and the cameras' up is the fallback where no credible ground plane is
//! found (a floating object, points on many surfaces).

use glam::{DMat3, DVec3};
use rand::{Rng, SeedableRng};

use super::SparseCapture;

/// How up was decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpFrom {
    /// The normal of the sparse points' dominant plane, when credible, else the cameras'.
    #[default]
    Ground,
    /// The mean of the cameras' up directions.
    Cameras,
}

impl std::str::FromStr for UpFrom {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "ground" => Ok(Self::Ground),
            "cameras" => Ok(Self::Cameras),
            other => Err(format!("expected ground or cameras, got {other:?}")),
        }
    }
}

impl std::fmt::Display for UpFrom {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Ground => "ground",
            Self::Cameras => "cameras",
        })
    }
}

/// RANSAC draws of three points for the ground plane.
const DRAWS: usize = 2000;
/// A point is on a plane within this share of the diagonal of the points' central box (1st to
/// 99th percentile per axis). Measured against the whole box's diagonal first: 1% and 0.5% let
/// the plane tilt onto the objects' bases (15-19 degrees off) on three and two of the four
/// reconstructions, 0.2% found the ground on all four.
const PLANE_TOLERANCE: f64 = 0.002;
/// A ground plane holds at least this share of the points (22-25% on the reconstructions
/// measured) ...
const MIN_GROUND_SHARE: f64 = 0.15;
/// ... and its normal is within this angle of the cameras' mean up (degrees): photos are taken
/// from above the ground, not from within it.
const MAX_TILT_FROM_CAMERAS_DEG: f64 = 30.0;

/// The cameras' mean up direction (unit; their y axes in the NeRF convention), `None` when
/// they cancel out or there are no cameras.
pub fn cameras_up(capture: &SparseCapture) -> Option<DVec3> {
    let up = capture
        .cameras
        .iter()
        .map(|c2w| c2w.y_axis.truncate())
        .sum::<DVec3>()
        .normalize_or_zero();
    (up != DVec3::ZERO).then_some(up)
}

/// The dominant plane of the sparse points: its unit normal, turned towards the cameras'
/// mean centre, and the share of points on it. Found by RANSAC (seeded, so the same capture
/// gives the same plane) within `PLANE_TOLERANCE`, then refitted by least squares to its
/// points. `None` with fewer than three points or no plane.
pub fn ground_plane(capture: &SparseCapture) -> Option<(DVec3, f64)> {
    let points = &capture.points;
    if points.len() < 3 || capture.cameras.is_empty() {
        return None;
    }
    let (low, high) = super::central_box(points);
    let tolerance = PLANE_TOLERANCE * (high - low).length();
    let on_plane =
        |normal: DVec3, at: DVec3| move |p: &&DVec3| (**p - at).dot(normal).abs() <= tolerance;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let mut best: Option<(usize, DVec3, DVec3)> = None;
    for _ in 0..DRAWS {
        let [a, b, c] = [(); 3].map(|_| points[rng.random_range(0..points.len())]);
        let normal = (b - a).cross(c - a).normalize_or_zero();
        if normal == DVec3::ZERO {
            continue;
        }
        let count = points.iter().filter(on_plane(normal, a)).count();
        if best.is_none_or(|(most, ..)| count > most) {
            best = Some((count, normal, a));
        }
    }
    let (_, normal, at) = best?;
    let inliers: Vec<DVec3> = points
        .iter()
        .filter(on_plane(normal, at))
        .copied()
        .collect();
    let mean = inliers.iter().sum::<DVec3>() / inliers.len() as f64;
    let mut refined = least_squares_normal(&inliers, mean).unwrap_or(normal);
    let cameras = capture
        .cameras
        .iter()
        .map(|c2w| c2w.w_axis.truncate())
        .sum::<DVec3>()
        / capture.cameras.len() as f64;
    if refined.dot(cameras - mean) < 0.0 {
        refined = -refined;
    }
    Some((refined, inliers.len() as f64 / points.len() as f64))
}

/// The direction of least spread of `points` about `mean`: the eigenvector of the smallest
/// eigenvalue of their scatter matrix, by power iteration on `trace * I - scatter` (whose
/// largest eigenvalue it is).
fn least_squares_normal(points: &[DVec3], mean: DVec3) -> Option<DVec3> {
    let scatter = points.iter().fold(DMat3::ZERO, |sum, p| {
        let d = *p - mean;
        sum + DMat3::from_cols(d * d.x, d * d.y, d * d.z)
    });
    let trace = scatter.x_axis.x + scatter.y_axis.y + scatter.z_axis.z;
    let shifted = DMat3::from_diagonal(DVec3::splat(trace)) - scatter;
    let mut v = DVec3::new(0.3, 0.5, 0.8).normalize();
    for _ in 0..200 {
        v = (shifted * v).normalize_or_zero();
        if v == DVec3::ZERO {
            return None;
        }
    }
    Some(v)
}

/// The up direction `from` asks for, and what was used: the ground plane's normal when it is
/// credible (at least `MIN_GROUND_SHARE` of the points, within `MAX_TILT_FROM_CAMERAS_DEG`
/// of the cameras' up), else the cameras' up. `None` when the cameras' up is undefined.
pub fn up_direction(capture: &SparseCapture, from: UpFrom) -> Option<(DVec3, UpFrom)> {
    let cameras = cameras_up(capture)?;
    if from == UpFrom::Ground {
        if let Some((normal, share)) = ground_plane(capture) {
            let tilt = normal.angle_between(cameras).to_degrees();
            if share >= MIN_GROUND_SHARE && tilt <= MAX_TILT_FROM_CAMERAS_DEG {
                return Some((normal, UpFrom::Ground));
            }
        }
    }
    Some((cameras, UpFrom::Cameras))
}

/// The rotation taking unit vector `from` to unit vector `to` (the shortest one; a half turn
/// about x when they are opposite).
pub(super) fn rotation_between(from: DVec3, to: DVec3) -> DMat3 {
    let axis = from.cross(to);
    let cos = from.dot(to).clamp(-1.0, 1.0);
    if axis.length() < 1e-12 {
        return if cos > 0.0 {
            DMat3::IDENTITY
        } else {
            DMat3::from_axis_angle(DVec3::X, std::f64::consts::PI)
        };
    }
    DMat3::from_axis_angle(axis.normalize(), cos.acos())
}
