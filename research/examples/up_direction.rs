//! Which way is up in a structure-from-motion capture: the cameras' mean up direction
//! (`rgbd_dataset::placement::cameras_up`, nerfstudio's `orientation_method up`) against the normal
//! of the sparse points' dominant plane (`ground_plane`, RANSAC), each measured as the angle to
//! the true up. The truth comes from the dataset the photos were rendered from (its +z is up):
//! the rotation of the similarity (Umeyama on the camera centres, matched by photo name) from
//! the reconstruction's frame onto the true one takes each candidate into the true frame.
//!
//! `cargo run --release -p research --example up_direction -- TRUE_DATASET SPARSE_DIR`

use std::path::Path;

use nalgebra::Vector3;
use research::capture::{poses, umeyama};
use rgbd_dataset::colmap::ColmapModel;
use rgbd_dataset::placement::{cameras_up, ground_plane, up_direction, SparseCapture, UpFrom};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [truth_dir, sparse] = args.as_slice() else {
        eprintln!("usage: up_direction TRUE_DATASET SPARSE_DIR");
        std::process::exit(2);
    };
    let truth = poses(Path::new(truth_dir));
    let model = ColmapModel::read(Path::new(sparse)).expect("the sparse model reads");
    let name = |n: &str| {
        Path::new(n)
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned()
    };
    let matched: Vec<_> = model
        .images
        .iter()
        .filter(|image| truth.contains_key(&name(&image.name)))
        .collect();
    let vector = |v: glam::DVec3| Vector3::new(v.x, v.y, v.z);
    let from: Vec<Vector3<f64>> = matched.iter().map(|i| vector(i.centre())).collect();
    let to: Vec<Vector3<f64>> = matched
        .iter()
        .map(|i| truth[&name(&i.name)].centre)
        .collect();
    let (_, rotation, _) = umeyama(&from, &to);
    let error = |v: glam::DVec3| {
        (rotation * vector(v).normalize())
            .dot(&Vector3::z())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    };
    let capture = SparseCapture::from(&model);
    let cameras = cameras_up(&capture).expect("cameras with an up direction");
    println!(
        "{} cameras ({} matched), {} sparse points",
        model.images.len(),
        matched.len(),
        model.points.len()
    );
    match ground_plane(&capture) {
        Some((normal, share)) => println!(
            "up error: cameras' mean up {:.2} deg, ground plane's normal {:.2} deg ({:.0}% of the \
             points on it)",
            error(cameras),
            error(normal),
            100.0 * share
        ),
        None => println!(
            "up error: cameras' mean up {:.2} deg, no ground plane",
            error(cameras)
        ),
    }
    let (up, used) = up_direction(&capture, UpFrom::Ground).expect("an up direction");
    println!(
        "`volgen import colmap` (--up ground) uses {used}: {:.2} deg",
        error(up)
    );
}
