//! A nerfstudio capture made by hand from a built-in scene's dataset, in a frame of its own
//! (turned, scaled and moved, as structure from motion leaves it; photos without alpha, masks
//! in `mask_path`, the sparse points in `sparse_pc.ply` as `ns-process-data` writes it),
//! imported: the cameras come back up to a similarity with the scene upright
//! and its points in the cube, the photos pixel for pixel; `--bounds auto` bounds the capture by
//! its points; what cannot be placed is refused by name.

use std::path::Path;

mod common;

use common::capture::{
    assert_fills_the_cube, assert_similar_cameras, photo_and_mask, pixels, stones_dataset,
    surface_points, to_f64,
};
use glam::{DMat3, DMat4, DVec3};
use rgbd_dataset::nerfstudio::{import, read_points, ImportOptions};
use rgbd_dataset::placement::{recorded_placement, UpFrom};
use rgbd_dataset::{Dataset, DepthKind};
use serde_json::{json, Value};

const SIZE: usize = 24;

/// The capture's frame: `p_capture = SCALE * turn * p + SHIFT`.
const SCALE: f64 = 0.4;
const SHIFT: DVec3 = DVec3::new(-2.0, 5.0, 1.0);
fn turn() -> DMat3 {
    DMat3::from_axis_angle(DVec3::new(-2.0, 1.0, 0.5).normalize(), 2.1)
}

/// Writes `points` as nerfstudio's `create_ply_from_colmap` does: ASCII, float x y z with six
/// decimals (Python's `{x:8f}`), uint8 colours.
fn write_ply(path: &Path, points: &[DVec3]) {
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nproperty uint8 red\nproperty uint8 green\nproperty uint8 blue\n\
         end_header\n",
        points.len()
    );
    for p in points {
        text += &format!("{:8.6} {:8.6} {:8.6} 90 120 60\n", p.x, p.y, p.z);
    }
    std::fs::write(path, text).unwrap();
}

/// Writes the capture of `data` (in `data_dir`) into `dir`, in the capture's frame: opaque
/// photos (composited on grey), masks, OpenCV camera axes, and `sparse_pc.ply`. Returns the
/// points in the capture's frame.
fn write_capture(data: &Dataset, data_dir: &Path, dir: &Path) -> Vec<DVec3> {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    std::fs::create_dir_all(dir.join("masks")).unwrap();
    let c = &data.cameras()[0];
    let mut frames = Vec::new();
    for (i, (name, camera)) in data.frame_names().iter().zip(data.cameras()).enumerate() {
        let photo = image::open(data_dir.join(name)).unwrap().to_rgba8();
        let (rgb, mask) = photo_and_mask(&photo);
        let (file, mask_file) = (
            format!("images/frame_{:05}.png", i + 1),
            format!("masks/mask_{:05}.png", i + 1),
        );
        rgb.save(dir.join(&file)).unwrap();
        mask.save(dir.join(&mask_file)).unwrap();
        // Moved into the capture's frame, with OpenCV's camera axes.
        let c2w = to_f64(camera.c2w);
        let rotation =
            turn() * DMat3::from_mat4(c2w) * DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0));
        let mut moved = DMat4::from_mat3(rotation);
        moved.w_axis = (SCALE * (turn() * c2w.w_axis.truncate()) + SHIFT).extend(1.0);
        let rows: Vec<[f64; 4]> = (0..4).map(|r| moved.row(r).to_array()).collect();
        frames.push(json!({"file_path": file, "mask_path": mask_file, "transform_matrix": rows}));
    }
    let points: Vec<DVec3> = surface_points(data, SIZE, 5)
        .into_iter()
        .map(|p| SCALE * (turn() * p) + SHIFT)
        .collect();
    write_ply(&dir.join("sparse_pc.ply"), &points);
    let root = json!({
        "camera_model": "PINHOLE",
        "camera_axes": "opencv",
        "fl_x": c.fx, "fl_y": c.fy, "cx": c.cx, "cy": c.cy, "w": SIZE, "h": SIZE,
        "applied_transform": [[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0]],
        "ply_file_path": "sparse_pc.ply",
        "frames": frames,
    });
    std::fs::write(dir.join("transforms.json"), root.to_string()).unwrap();
    points
}

#[test]
fn an_imported_capture_has_the_cameras_up_to_a_similarity_upright_in_the_cube() {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    let data = stones_dataset(&data_dir, 5);
    let capture = tmp.path().join("capture");
    let points = write_capture(&data, &data_dir, &capture);
    let read = read_points(&capture.join("sparse_pc.ply")).unwrap();
    assert_eq!(read.len(), points.len());
    assert!(read
        .iter()
        .zip(&points)
        .all(|(r, p)| (*r - *p).abs().max_element() <= 5e-7));
    let out = tmp.path().join("imported");
    let summary = import(&capture, &ImportOptions::default(), &out).unwrap();
    assert_eq!(summary.frames, data.len());
    assert_eq!(summary.points.1, points.len());
    let imported = Dataset::load(&out, [1.0; 3]).unwrap();
    assert_eq!(imported.depth_kind(), DepthKind::None);
    let written: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("transforms.json")).unwrap())
            .unwrap();
    assert!(written.get("ply_file_path").is_none() && written.get("applied_transform").is_none());
    assert_eq!(written["volgen_import"]["from"], "nerfstudio");
    let recorded = recorded_placement(&out).unwrap();
    assert!(recorded.abs_diff_eq(summary.placement.matrix(), 1e-12));

    // One rotation takes every original camera to its imported one (within f32's rounding of
    // the files: the angle is an acos near 1, the square root of 1e-8), distances between
    // camera centres scale by the capture's factor times the import's, and the scene's ground
    // becomes level (the ground plane's normal is its up).
    let factor = SCALE * summary.placement.scale;
    let turned = assert_similar_cameras(data.cameras(), imported.cameras(), factor, 5e-4);
    assert_eq!(summary.placement.up, UpFrom::Ground);
    let up = turned * DVec3::Z;
    assert!(up.angle_between(DVec3::Z).to_degrees() < 2.0, "{up}");
    // The photos come back as the capture's: colour and opacity (mask) as they were.
    let capture_data = Dataset::load(&capture, [1.0; 3]).unwrap();
    assert_eq!(pixels(&capture_data, SIZE), pixels(&imported, SIZE));
    assert_fills_the_cube(&summary.placement, &points);
}

#[test]
fn auto_bounds_of_a_capture_without_depth_come_from_its_points() {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    let data = stones_dataset(&data_dir, 5);
    let capture = tmp.path().join("capture");
    let points = write_capture(&data, &data_dir, &capture);
    let loaded = Dataset::load(&capture, [1.0; 3]).unwrap();
    assert_eq!(loaded.depth_kind(), DepthKind::None);
    let bounds = loaded.auto_bounds().unwrap();
    // All but the outermost 1% per axis are inside, and the box is no more than 10% (its
    // margins) larger than the points' full extent on any axis.
    let (lo, hi) = (
        DVec3::from(bounds.min.map(f64::from)),
        DVec3::from(bounds.max.map(f64::from)),
    );
    let inside = points
        .iter()
        .filter(|p| p.cmpge(lo - 1e-5).all() && p.cmple(hi + 1e-5).all())
        .count();
    assert!(
        inside as f64 >= 0.94 * points.len() as f64,
        "{inside} of {}",
        points.len()
    );
    let (low, high) = points
        .iter()
        .fold((DVec3::MAX, DVec3::MIN), |(l, h), &p| (l.min(p), h.max(p)));
    assert!(
        ((hi - lo) - (high - low) * 1.1).max_element() < 1e-4,
        "{bounds} {low} {high}"
    );
    // The capture's cameras see it and none is inside: it trains with these bounds.
    loaded.in_model_cube(&bounds).unwrap();
}

#[test]
fn captures_that_cannot_be_placed_are_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    let data = stones_dataset(&data_dir, 5);
    let capture = tmp.path().join("capture");
    write_capture(&data, &data_dir, &capture);
    let file = capture.join("transforms.json");
    let root: Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    let out = tmp.path().join("out");
    let refused = |root: &Value, options: &ImportOptions| {
        std::fs::write(&file, root.to_string()).unwrap();
        import(&capture, options, &out).unwrap_err().to_string()
    };
    // No points: named, with the way out.
    let mut no_points = root.clone();
    no_points.as_object_mut().unwrap().remove("ply_file_path");
    let err = refused(&no_points, &ImportOptions::default());
    assert!(
        err.contains("transforms.json")
            && err.contains("ply_file_path")
            && err.contains("--points"),
        "{err}"
    );
    // Given separately instead, they place it.
    let given = ImportOptions {
        points: Some(capture.join("sparse_pc.ply")),
        ..ImportOptions::default()
    };
    std::fs::write(&file, no_points.to_string()).unwrap();
    import(&capture, &given, &out).unwrap();
    // A point cloud that is not one.
    let mut bad_points = root.clone();
    bad_points["ply_file_path"] = "images/frame_00001.png".into();
    let err = refused(&bad_points, &ImportOptions::default());
    assert!(
        err.contains("frame_00001.png") && err.contains("PLY"),
        "{err}"
    );
    // Opaque photos without masks.
    let mut opaque = root.clone();
    for frame in opaque["frames"].as_array_mut().unwrap() {
        frame.as_object_mut().unwrap().remove("mask_path");
    }
    let err = refused(&opaque, &ImportOptions::default());
    assert!(err.contains("opaque") && err.contains("mask_path"), "{err}");
    // A recorded placement that is not a similarity (sheared) is refused by field.
    let sheared = json!({"frames": [], "volgen_import": {"capture_to_dataset":
        [[1.0, 0.5, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]}});
    std::fs::write(out.join("transforms.json"), sheared.to_string()).unwrap();
    let err = recorded_placement(&out).unwrap_err().to_string();
    assert!(
        err.contains("capture_to_dataset") && err.contains("not a similarity"),
        "{err}"
    );
    // The capture's own directory as the output: refused, the capture untouched.
    std::fs::write(&file, root.to_string()).unwrap();
    let err = import(&capture, &ImportOptions::default(), &capture)
        .unwrap_err()
        .to_string();
    assert!(err.contains("capture's own"), "{err}");
    assert_eq!(std::fs::read_to_string(&file).unwrap(), root.to_string());
    // A capture with depth maps places itself (--bounds auto).
    let err = import(&data_dir, &ImportOptions::default(), &out)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("depth maps") && err.contains("--bounds auto"),
        "{err}"
    );
}
