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

use std::path::Path;

use nalgebra::Vector3;
use research::capture::{median, poses, umeyama};

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
