//! How well a structure-from-motion reconstruction found the cameras: the poses of a dataset
//! imported from COLMAP (`volgen import colmap`) against the true poses of the dataset its
//! photos came from, after the similarity (rotation, scale, shift; Umeyama's least squares on the
//! camera centres) that best maps one frame onto the other. Frames are matched by the photo's
//! file name (`colmap_name` in the imported `transforms.json`). Prints the per-camera rotation
//! error (degrees) and centre error (relative to the true cameras' spread: their RMS distance
//! from their mean), and exits with status 1 when the median rotation error exceeds
//! `MAX_ROTATION_DEG` or the median centre error `MAX_CENTRE`. Used by tools/colmap/sfm_check.sh.
//!
//! `cargo run --release -p research --example pose_alignment -- TRUE_DATASET IMPORTED_DATASET
//! [MAX_ROTATION_DEG MAX_CENTRE]` (defaults 1 degree and 0.01).

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Matrix3, Vector3};
use serde_json::Value;

/// One camera: rotation (camera to world) and centre.
struct Pose {
    rotation: Matrix3<f64>,
    centre: Vector3<f64>,
}

/// Each frame's pose by the file name of its photo (without directories): `file_path`'s, or
/// `colmap_name`'s where the frame has one.
fn poses(dataset: &Path) -> HashMap<String, Pose> {
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
fn umeyama(from: &[Vector3<f64>], to: &[Vector3<f64>]) -> (f64, Matrix3<f64>, Vector3<f64>) {
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

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: pose_alignment TRUE_DATASET IMPORTED_DATASET [MAX_ROTATION_DEG MAX_CENTRE]";
    let truth = poses(Path::new(args.first().expect(usage)));
    let found = poses(Path::new(args.get(1).expect(usage)));
    let max_rotation: f64 = args.get(2).map_or(1.0, |v| v.parse().expect(usage));
    let max_centre: f64 = args.get(3).map_or(0.01, |v| v.parse().expect(usage));
    let mut names: Vec<&String> = found.keys().filter(|k| truth.contains_key(*k)).collect();
    names.sort();
    assert!(
        names.len() >= 3,
        "only {} photos in both datasets",
        names.len()
    );
    let from: Vec<Vector3<f64>> = names.iter().map(|n| found[*n].centre).collect();
    let to: Vec<Vector3<f64>> = names.iter().map(|n| truth[*n].centre).collect();
    let (scale, rotation, shift) = umeyama(&from, &to);
    let mean = to.iter().sum::<Vector3<f64>>() / to.len() as f64;
    let spread =
        (to.iter().map(|c| (c - mean).norm_squared()).sum::<f64>() / to.len() as f64).sqrt();
    let (mut rotation_errors, mut centre_errors) = (Vec::new(), Vec::new());
    for name in &names {
        let (f, t) = (&found[*name], &truth[*name]);
        let relative = (rotation * f.rotation).transpose() * t.rotation;
        let cos = ((relative.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
        rotation_errors.push(cos.acos().to_degrees());
        centre_errors.push((scale * rotation * f.centre + shift - t.centre).norm() / spread);
    }
    let worst = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let (rot_max, centre_max) = (worst(&rotation_errors), worst(&centre_errors));
    let (rot_median, centre_median) = (median(&mut rotation_errors), median(&mut centre_errors));
    println!(
        "{} of {} true cameras registered; similarity scale {scale:.4}",
        names.len(),
        truth.len()
    );
    println!("rotation error: median {rot_median:.3} deg, max {rot_max:.3} deg");
    println!(
        "centre error: median {centre_median:.5}, max {centre_max:.5} of the cameras' spread ({spread:.3})"
    );
    if rot_median > max_rotation || centre_median > max_centre {
        eprintln!("poses off: median errors above {max_rotation} deg / {max_centre}");
        std::process::exit(1);
    }
}
