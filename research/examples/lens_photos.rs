//! Photos as a lens with distortion takes them, for checking undistortion through real
//! structure from motion (tools/colmap/sfm_check.sh with LENS=opencv): every RGBA PNG of a
//! dataset rendered with a pinhole camera is warped so that each pixel shows what the
//! pinhole's ray through its ideal point sees (`rgbd_dataset::lens::photo_through_lens`), as
//! an OPENCV lens with the given coefficients and the dataset's intrinsics would have taken
//! it. Written to OUT with the same file names.
//!
//! `cargo run --release -p research --example lens_photos -- DATASET OUT K1 K2 P1 P2`

use std::path::Path;

use rgbd_dataset::lens::{photo_through_lens, Lens};
use rgbd_dataset::Dataset;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dataset, out, k1, k2, p1, p2] = args.as_slice() else {
        eprintln!("usage: lens_photos DATASET OUT K1 K2 P1 P2");
        std::process::exit(2);
    };
    let number = |s: &String| -> f64 { s.parse().expect("a coefficient is a number") };
    let lens = Lens::BrownConrady {
        radial: [number(k1), number(k2), 0.0, 0.0],
        tangential: [number(p1), number(p2)],
    };
    let dataset_dir = Path::new(dataset);
    let data = Dataset::load(dataset_dir, [1.0; 3]).expect("the dataset loads");
    let base = if dataset_dir.is_dir() {
        dataset_dir
    } else {
        dataset_dir.parent().expect("a file has a directory")
    };
    for (name, camera) in data.frame_names().iter().zip(data.cameras()) {
        let file = if Path::new(name).extension().is_some() {
            base.join(name)
        } else {
            base.join(format!("{name}.png"))
        };
        let pinhole = image::open(&file)
            .unwrap_or_else(|e| panic!("{}: {e}", file.display()))
            .to_rgba8();
        let k = [camera.fx, camera.fy, camera.cx, camera.cy].map(f64::from);
        let photo = photo_through_lens(&pinhole, k, lens);
        let target = Path::new(out).join(file.file_name().expect("a photo has a name"));
        std::fs::create_dir_all(Path::new(out)).expect("OUT can be made");
        photo.save(&target).expect("the photo is written");
    }
    println!(
        "wrote {} photos through {lens:?} to {out}",
        data.frame_names().len()
    );
}
