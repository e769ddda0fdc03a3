//! A capture as nerfstudio's `ns-process-data` writes one (JPEG photos without alpha, a mask per
//! frame in `mask_path`, an OPENCV lens with distortion, intrinsics in pixels, no depth) read
//! by `Dataset::load` as the pinhole views it was made from; also with the cameras in OpenCV's
//! axes (`"camera_axes": "opencv"`). What cannot be read is refused by frame and field.

mod common;

use std::path::Path;

use common::capture::photo_and_mask;
use common::lens_photos;
use rgbd_dataset::lens::{photo_through_lens, Lens, Undistortion};
use rgbd_dataset::scenes::StandingStones;
use rgbd_dataset::{write_dataset, Dataset, DatasetSpec, DepthKind};
use serde_json::{json, Value};

const SIZE: usize = 48;

fn lens() -> Lens {
    Lens::BrownConrady {
        radial: [-0.3, 0.08, 0.0, 0.0],
        tangential: [0.002, -0.001],
    }
}

/// Writes the capture of `data` (in `data_dir`) into `dir` and returns its transforms.json.
fn write_capture(data: &Dataset, data_dir: &Path, dir: &Path, axes: &str) -> Value {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    std::fs::create_dir_all(dir.join("masks")).unwrap();
    let c = &data.cameras()[0];
    let k = [c.fx, c.fy, c.cx, c.cy].map(f64::from);
    let mut frames = Vec::new();
    for (i, (name, camera)) in data.frame_names().iter().zip(data.cameras()).enumerate() {
        let pinhole = image::open(data_dir.join(name)).unwrap().to_rgba8();
        let photo = photo_through_lens(&pinhole, k, lens());
        // A camera's photo has a background (grey here) and no alpha; the mask has the alpha.
        let (rgb, mask) = photo_and_mask(&photo);
        let (file, mask_file) = (
            format!("images/frame_{:05}.jpg", i + 1),
            format!("masks/mask_{:05}.png", i + 1),
        );
        rgb.save(dir.join(&file)).unwrap();
        mask.save(dir.join(&mask_file)).unwrap();
        let mut c2w = camera.c2w;
        if axes == "opencv" {
            c2w *= glam::Mat4::from_scale(glam::Vec3::new(1.0, -1.0, -1.0));
        }
        let rows: Vec<[f32; 4]> = (0..4).map(|r| c2w.row(r).to_array()).collect();
        frames.push(json!({"file_path": file, "mask_path": mask_file, "transform_matrix": rows}));
    }
    let mut root = json!({
        "camera_model": "OPENCV",
        "fl_x": k[0], "fl_y": k[1], "cx": k[2], "cy": k[3], "w": SIZE, "h": SIZE,
        "k1": -0.3, "k2": 0.08, "p1": 0.002, "p2": -0.001,
        "frames": frames,
    });
    if axes == "opencv" {
        root["camera_axes"] = "opencv".into();
    }
    std::fs::write(dir.join("transforms.json"), root.to_string()).unwrap();
    root
}

/// Opacity and colour (composited on white, planar per view) of every view at full size.
fn pixels(d: &Dataset) -> (Vec<f32>, Vec<f32>) {
    let level = d.level(SIZE, SIZE, &candle_core::Device::Cpu).unwrap();
    let flat = |t: &candle_core::Tensor| t.flatten_all().unwrap().to_vec1().unwrap();
    (flat(&level.opacity), flat(&level.images))
}

/// A dataset of the stones (layout 2) at SIZE^2 written to `dir` and loaded.
fn stones(dir: &Path, views: usize, grid: usize) -> Dataset {
    let spec = DatasetSpec {
        views,
        resolution: SIZE,
        grid,
        seed: 1,
    };
    write_dataset(&StandingStones::new(2), dir, &spec).unwrap();
    Dataset::load(dir, [1.0; 3]).unwrap()
}

#[test]
fn a_nerfstudio_capture_loads_as_the_pinhole_views_it_was_made_from() {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    let data = stones(&data_dir, 4, 32);
    let c = &data.cameras()[0];
    let k = [c.fx, c.fy, c.cx, c.cy].map(f64::from);
    let expected = Undistortion::new(lens(), k, (SIZE as u32, SIZE as u32))
        .unwrap()
        .pinhole();
    for axes in ["opengl", "opencv"] {
        let capture = tmp.path().join(axes);
        write_capture(&data, &data_dir, &capture, axes);
        let loaded = Dataset::load(&capture, [1.0; 3]).unwrap();
        // No depth maps and no `depth_kind`: a depth-less capture.
        assert_eq!(loaded.depth_kind(), DepthKind::None);
        for (a, b) in data.cameras().iter().zip(loaded.cameras()) {
            assert!(
                a.c2w.abs_diff_eq(b.c2w, 1e-5),
                "{axes}: {} against {}",
                a.c2w,
                b.c2w
            );
            for (got, want) in [b.fx, b.fy, b.cx, b.cy].iter().zip(expected) {
                assert!(
                    (f64::from(*got) - want).abs() < 1e-3,
                    "{got} against {want}"
                );
            }
        }
        // The mask is the opacity and the JPEG the colour, undistorted: each pixel's as the
        // pinhole view has it along the same ray, far closer than the distorted photo read as it
        // is.
        let (mut undistorted_error, mut ignored_error) = (0.0, 0.0);
        let (mut colour_error, mut colour_ignored) = (0.0, 0.0);
        let (got, got_colour) = pixels(&loaded);
        for (v, name) in data.frame_names().iter().enumerate() {
            let pinhole = image::open(data_dir.join(name)).unwrap().to_rgba8();
            let photo = photo_through_lens(&pinhole, k, lens());
            for j in 0..SIZE {
                for i in 0..SIZE {
                    let x = (i as f64 + 0.5 - expected[2]) / expected[0];
                    let y = (j as f64 + 0.5 - expected[3]) / expected[1];
                    let truth = lens_photos::sample(&pinhole, k[0] * x + k[2], k[1] * y + k[3]);
                    let alpha = truth[3] / 255.0;
                    let at = v * SIZE * SIZE + j * SIZE + i;
                    undistorted_error += (f64::from(got[at]) - alpha).abs();
                    let naive = photo.get_pixel(i as u32, j as u32);
                    let naive_alpha = f64::from(naive[3]) / 255.0;
                    ignored_error += (naive_alpha - alpha).abs();
                    for c in 0..3 {
                        let on_white = (truth[c] + 255.0 * (1.0 - alpha)) / 255.0;
                        let plane = (3 * v + c) * SIZE * SIZE + j * SIZE + i;
                        colour_error += (f64::from(got_colour[plane]) - on_white).abs();
                        let naive_on_white = (f64::from(naive[c]) * naive_alpha
                            + 255.0 * (1.0 - naive_alpha))
                            / 255.0;
                        colour_ignored += (naive_on_white - on_white).abs();
                    }
                }
            }
        }
        assert!(
            undistorted_error < 0.5 * ignored_error,
            "{axes}: opacity off by {undistorted_error:.1} in all undistorted, {ignored_error:.1} \
             ignoring the lens"
        );
        // JPEG's own error (about 3 levels of 255 on average at its default quality) is in
        // both.
        let values = (3 * SIZE * SIZE * data.len()) as f64;
        assert!(
            colour_error < 0.75 * colour_ignored && colour_error / values < 0.015,
            "{axes}: colour off by {colour_error:.1} in all undistorted, {colour_ignored:.1} \
             ignoring the lens"
        );
    }
}

#[test]
fn what_a_capture_cannot_say_is_refused_by_frame_and_field() {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    let data = stones(&data_dir, 2, 16);
    let capture = tmp.path().join("capture");
    let root = write_capture(&data, &data_dir, &capture, "opengl");
    let refused = |edit: &dyn Fn(&mut Value)| {
        let mut changed = root.clone();
        edit(&mut changed);
        std::fs::write(capture.join("transforms.json"), changed.to_string()).unwrap();
        Dataset::load(&capture, [1.0; 3]).unwrap_err().to_string()
    };
    let err = refused(&|r| r["frames"][1]["camera_model"] = "EQUIRECTANGULAR".into());
    assert!(
        err.contains("frame_00002")
            && err.contains("camera_model")
            && err.contains("EQUIRECTANGULAR"),
        "{err}"
    );
    let err = refused(&|r| r["camera_axes"] = "left-handed".into());
    assert!(err.contains("camera_axes"), "{err}");
    image::GrayImage::new(8, 8)
        .save(capture.join("masks/small.png"))
        .unwrap();
    let err = refused(&|r| r["frames"][0]["mask_path"] = "masks/small.png".into());
    assert!(err.contains("small.png") && err.contains("8 x 8"), "{err}");
    let err = refused(&|r| r["frames"][0]["mask_path"] = "masks/gone.png".into());
    assert!(err.contains("gone.png") && err.contains("missing"), "{err}");
    // Depth maps with a distorting lens: volgen undistorts photos, not depth.
    let err = refused(&|r| {
        r["depth_kind"] = "z".into();
        r["frames"][0]["depth_file_path"] = "depth.png".into();
    });
    assert!(err.contains("distortion") && err.contains("depth"), "{err}");
}
