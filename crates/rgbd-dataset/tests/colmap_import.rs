//! A COLMAP reconstruction made by hand from a built-in scene's dataset, in a frame of its own
//! (turned, scaled and moved, as structure from motion leaves it), imported back: the cameras
//! come back up to a similarity with the scene upright and the points in the cube, the photos
//! pixel for pixel, masks become alpha, and what cannot be imported is refused by name.

mod common;

use std::path::Path;

use common::capture::{
    assert_fills_the_cube, assert_similar_cameras, photo_and_mask, pixels, stones_dataset,
    surface_points, to_f64,
};
use common::lens_photos;

use glam::{DMat3, DQuat, DVec3};
use rgbd_dataset::colmap::{import, ImportOptions};
use rgbd_dataset::lens::{photo_through_lens, Lens, Undistortion};
use rgbd_dataset::placement::UpFrom;
use rgbd_dataset::{Dataset, DepthKind};

const SIZE: usize = 24;

/// The capture's frame: `p_colmap = SCALE * turn * p + SHIFT`.
const SCALE: f64 = 2.5;
const SHIFT: DVec3 = DVec3::new(3.0, -1.0, 2.0);
fn turn() -> DMat3 {
    DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7)
}

/// Writes a text model of `data` (cameras moved into the capture's frame; points where the
/// depth maps put the surface, every 7th covered pixel of each view) into `dir`, with the
/// camera model line `camera`. Returns the points, in the capture's frame.
fn write_model(data: &Dataset, dir: &Path, camera: &str) -> Vec<DVec3> {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("cameras.txt"), format!("{camera}\n")).unwrap();
    let mut images = String::new();
    for (i, (cam, name)) in data.cameras().iter().zip(data.frame_names()).enumerate() {
        let c2w = to_f64(cam.c2w);
        // NeRF axes (y up, looking down -z) to COLMAP's (y down, z forward), in the capture's
        // frame.
        let rotation =
            turn() * DMat3::from_mat4(c2w) * DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0));
        let centre = SCALE * (turn() * c2w.w_axis.truncate()) + SHIFT;
        let w2c = rotation.transpose();
        let t = -(w2c * centre);
        let q = DQuat::from_mat3(&w2c);
        images += &format!(
            "{} {} {} {} {} {} {} {} 1 {name}\n\n",
            i + 1,
            q.w,
            q.x,
            q.y,
            q.z,
            t.x,
            t.y,
            t.z
        );
    }
    std::fs::write(dir.join("images.txt"), images).unwrap();
    let mut points = String::new();
    let mut placed = Vec::new();
    for (id, p) in surface_points(data, SIZE, 7).into_iter().enumerate() {
        let p = SCALE * (turn() * p) + SHIFT;
        placed.push(p);
        points += &format!(
            "{} {} {} {} 128 128 128 0.5 1 0 2 0\n",
            id + 1,
            p.x,
            p.y,
            p.z
        );
    }
    std::fs::write(dir.join("points3D.txt"), points).unwrap();
    placed
}

fn pinhole(data: &Dataset) -> String {
    let c = &data.cameras()[0];
    format!(
        "1 PINHOLE {SIZE} {SIZE} {} {} {} {}",
        c.fx, c.fy, c.cx, c.cy
    )
}

#[test]
fn an_imported_capture_has_the_cameras_up_to_a_similarity_upright_in_the_cube() {
    let tmp = tempfile::tempdir().unwrap();
    let data = stones_dataset(&tmp.path().join("data"), 3);
    let model = tmp.path().join("sparse");
    let points = write_model(&data, &model, &pinhole(&data));
    let options = ImportOptions {
        images: tmp.path().join("data"),
        masks: None,
        up: UpFrom::default(),
    };
    let out = tmp.path().join("imported");
    let summary = import(&model, &options, &out).unwrap();
    assert_eq!(summary.frames, data.len());
    let imported = Dataset::load(&out, [1.0; 3]).unwrap();
    assert_eq!(imported.depth_kind(), DepthKind::None);

    let (a, b) = (data.cameras(), imported.cameras());
    // One rotation takes every original camera to its imported one, distances between camera
    // centres scale by one factor (the capture's times the import's), and +z stays up.
    let factor = SCALE * summary.placement.scale;
    let turned = assert_similar_cameras(a, b, factor, 1e-4);
    let up = turned * DVec3::Z;
    // Up from the ground plane the surface points find (the scene's flat ground): within 2
    // degrees; from the cameras' mean up (six cameras, not spread evenly), within 15.
    assert_eq!(summary.placement.up, UpFrom::Ground);
    assert!(up.angle_between(DVec3::Z).to_degrees() < 2.0, "{up}");
    let by_cameras = ImportOptions {
        up: UpFrom::Cameras,
        ..options.clone()
    };
    let cameras_summary = import(&model, &by_cameras, &tmp.path().join("by_cameras")).unwrap();
    assert_eq!(cameras_summary.placement.up, UpFrom::Cameras);
    let cameras_up = cameras_summary.placement.up_in_capture();
    let truth_up = summary.placement.up_in_capture();
    assert!(cameras_up.angle_between(truth_up).to_degrees() < 15.0);
    // The intrinsics and the photos come back as they were.
    for (ca, cb) in a.iter().zip(b) {
        assert!((ca.fx - cb.fx).abs() < 1e-3 && (ca.cx - cb.cx).abs() < 1e-4);
    }
    assert_eq!(pixels(&data, SIZE), pixels(&imported, SIZE));
    // Every surface point lands in the cube, the scene fills it, its middle near the origin.
    assert_fills_the_cube(&summary.placement, &points);
    let m = summary.placement.matrix();
    let placed_centre = m.transform_point3(SHIFT);
    assert!(placed_centre.length() < 0.5, "{placed_centre}");
}

#[test]
fn masks_become_alpha_and_unusable_captures_are_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let data = stones_dataset(&tmp.path().join("data"), 3);
    let model = tmp.path().join("sparse");
    write_model(&data, &model, &pinhole(&data));
    // The photos as a camera takes them: RGB, opaque; their alpha as separate masks.
    let photos = tmp.path().join("photos");
    let masks = tmp.path().join("masks");
    for name in data.frame_names() {
        let rgba = image::open(tmp.path().join("data").join(name))
            .unwrap()
            .to_rgba8();
        let (rgb, mask) = photo_and_mask(&rgba);
        for (dir, save) in [(&photos, 0), (&masks, 1)] {
            let file = dir.join(name);
            std::fs::create_dir_all(file.parent().unwrap()).unwrap();
            match save {
                0 => rgb.save(&file).unwrap(),
                _ => mask.save(&file).unwrap(),
            }
        }
    }
    let out = tmp.path().join("imported");
    let without = ImportOptions {
        images: photos.clone(),
        masks: None,
        up: UpFrom::default(),
    };
    let err = import(&model, &without, &out).unwrap_err().to_string();
    assert!(err.contains("opaque") && err.contains("masks"), "{err}");
    let with = ImportOptions {
        images: photos,
        masks: Some(masks),
        up: UpFrom::default(),
    };
    import(&model, &with, &out).unwrap();
    let opacity = |d: &Dataset| -> Vec<f32> {
        let level = d.level(SIZE, SIZE, &candle_core::Device::Cpu).unwrap();
        level.opacity.flatten_all().unwrap().to_vec1().unwrap()
    };
    assert_eq!(
        opacity(&data),
        opacity(&Dataset::load(&out, [1.0; 3]).unwrap())
    );

    // A lens model volgen does not undistort: refused, naming the model and the way out.
    write_model(
        &data,
        &model,
        &format!("1 FULL_OPENCV {SIZE} {SIZE} 20 20 12 12 0.1 0 0 0 0 0 0 0"),
    );
    let err = import(&model, &with, &out).unwrap_err().to_string();
    assert!(
        err.contains("FULL_OPENCV") && err.contains("image_undistorter"),
        "{err}"
    );
    // ... but only where a registered image uses it: a camera no image refers to (of an
    // image the mapper dropped), of another size and model, is not looked at.
    write_model(
        &data,
        &model,
        &format!(
            "{}\n2 FULL_OPENCV 99 77 20 20 12 12 0.1 0 0 0 0 0 0 0",
            pinhole(&data)
        ),
    );
    let summary = import(&model, &with, &out).unwrap();
    assert_eq!((summary.width, summary.height), (SIZE as u32, SIZE as u32));
    assert!(summary.undistorted.is_empty());
    // A missing photo names its file.
    let elsewhere = ImportOptions {
        images: tmp.path().join("nowhere"),
        masks: None,
        up: UpFrom::default(),
    };
    write_model(&data, &model, &pinhole(&data));
    let err = import(&model, &elsewhere, &out).unwrap_err().to_string();
    assert!(err.contains("nowhere"), "{err}");
}

#[test]
fn photos_through_a_distorting_lens_come_back_as_the_pinhole_saw_them() {
    let tmp = tempfile::tempdir().unwrap();
    let data = stones_dataset(&tmp.path().join("data"), 3);
    let c = &data.cameras()[0];
    let k = [c.fx, c.fy, c.cx, c.cy].map(f64::from);
    // An OPENCV lens with strong barrel distortion (about two pixels at the corners).
    let (k1, k2, p1, p2) = (-0.45, 0.1, 0.004, -0.003);
    let lens = Lens::BrownConrady {
        radial: [k1, k2, 0.0, 0.0],
        tangential: [p1, p2],
    };
    let model = tmp.path().join("sparse");
    write_model(
        &data,
        &model,
        &format!(
            "1 OPENCV {SIZE} {SIZE} {} {} {} {} {k1} {k2} {p1} {p2}",
            k[0], k[1], k[2], k[3]
        ),
    );
    // The photos as that lens takes them: each pixel shows what the pinhole's ray through its
    // ideal point sees.
    let photos = tmp.path().join("photos");
    let mut pinhole_photos = Vec::new();
    let mut distorted_photos = Vec::new();
    for name in data.frame_names() {
        let pinhole = image::open(tmp.path().join("data").join(name))
            .unwrap()
            .to_rgba8();
        let distorted = photo_through_lens(&pinhole, k, lens);
        let file = photos.join(name);
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        distorted.save(&file).unwrap();
        pinhole_photos.push(pinhole);
        distorted_photos.push(distorted);
    }
    let out = tmp.path().join("imported");
    let options = ImportOptions {
        images: photos,
        masks: None,
        up: UpFrom::default(),
    };
    import(&model, &options, &out).unwrap();
    let imported = Dataset::load(&out, [1.0; 3]).unwrap();
    // The imported cameras are the undistortion's pinhole: wider than the photo's focal length
    // (barrel distortion squeezed more into the frame), the principal point kept.
    let expected = Undistortion::new(lens, k, (SIZE as u32, SIZE as u32))
        .unwrap()
        .pinhole();
    let b = &imported.cameras()[0];
    assert!(expected[0] < k[0] * 0.99, "{expected:?} against {k:?}");
    for (got, want) in [b.fx, b.fy, b.cx, b.cy].iter().zip(expected) {
        assert!(
            (f64::from(*got) - want).abs() < 1e-3,
            "{got} against {want}"
        );
    }
    // Each imported pixel shows what the pinhole photo shows along the same ray, far closer
    // than the distorted photo read as if it were a pinhole one.
    let mut undistorted_error = 0.0;
    let mut ignored_error = 0.0;
    for (v, name) in imported.frame_names().iter().enumerate() {
        let got = image::open(out.join(name)).unwrap().to_rgba8();
        for (i, j, pixel) in got.enumerate_pixels() {
            let x = (f64::from(i) + 0.5 - expected[2]) / expected[0];
            let y = (f64::from(j) + 0.5 - expected[3]) / expected[1];
            let truth = lens_photos::sample(&pinhole_photos[v], k[0] * x + k[2], k[1] * y + k[3]);
            let naive = distorted_photos[v].get_pixel(i, j);
            let alpha = f64::from(pixel[3]) / 255.0;
            let naive_alpha = f64::from(naive[3]) / 255.0;
            for c in 0..3 {
                undistorted_error += (f64::from(pixel[c]) * alpha - truth[c]).abs();
                ignored_error += (f64::from(naive[c]) * naive_alpha - truth[c]).abs();
            }
            undistorted_error += (f64::from(pixel[3]) - truth[3]).abs();
            ignored_error += (f64::from(naive[3]) - truth[3]).abs();
        }
    }
    let values = (4 * SIZE * SIZE * imported.len()) as f64;
    let (undistorted_error, ignored_error) = (undistorted_error / values, ignored_error / values);
    assert!(
        undistorted_error < 0.5 * ignored_error,
        "mean error {undistorted_error:.2} levels undistorted, {ignored_error:.2} ignoring the lens"
    );
}
