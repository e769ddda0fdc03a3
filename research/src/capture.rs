//! Camera poses of datasets and structure-from-motion imports, and the similarity between two
//! sets of camera centres: what the photo programs (`pose_alignment`, `up_direction`) share.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Matrix3, Vector3};
use serde_json::Value;

/// One camera: rotation (camera to world) and centre.
pub struct Pose {
    /// Rotation, camera to world.
    pub rotation: Matrix3<f64>,
    /// The camera's centre in the world.
    pub centre: Vector3<f64>,
}

/// Each frame's pose by the file name of its photo (without directories): `file_path`'s, or
/// `colmap_name`'s where the frame has one.
pub fn poses(dataset: &Path) -> HashMap<String, Pose> {
    let file = if dataset.is_dir() {
        dataset.join("transforms.json")
    } else {
        dataset.to_path_buf()
    };
    let root: Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    root["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .map(|frame| {
            let name = frame
                .get("colmap_name")
                .or_else(|| frame.get("file_path"))
                .and_then(Value::as_str)
                .expect("a file name");
            let base = Path::new(name).file_name().unwrap().to_string_lossy();
            let m = |r: usize, c: usize| frame["transform_matrix"][r][c].as_f64().unwrap();
            let pose = Pose {
                rotation: Matrix3::from_fn(m),
                centre: Vector3::new(m(0, 3), m(1, 3), m(2, 3)),
            };
            (base.into_owned(), pose)
        })
        .collect()
}

/// Umeyama: the similarity `x -> s R x + t` minimising the squared distances from `from` to `to`.
pub fn umeyama(from: &[Vector3<f64>], to: &[Vector3<f64>]) -> (f64, Matrix3<f64>, Vector3<f64>) {
    let n = from.len() as f64;
    let mean = |v: &[Vector3<f64>]| v.iter().sum::<Vector3<f64>>() / n;
    let (mf, mt) = (mean(from), mean(to));
    let var_from = from.iter().map(|x| (x - mf).norm_squared()).sum::<f64>() / n;
    let cov = from
        .iter()
        .zip(to)
        .map(|(x, y)| (y - mt) * (x - mf).transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let svd = cov.svd(true, true);
    let (u, v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rotation = u * d * v_t;
    let scale = (svd.singular_values.component_mul(&d.diagonal())).sum() / var_from;
    let shift = mt - scale * rotation * mf;
    (scale, rotation, shift)
}

/// The middle value (the upper one of an even count); sorts `values`.
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}
