//! What the capture tests share: photos as a camera takes them, surface points from a
//! dataset's depth, a dataset's pixels, and the check that imported cameras are the originals
//! up to a similarity.

use glam::{DMat3, DMat4, DQuat, DVec3};
use rgbd_dataset::scenes::StandingStones;
use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};

/// The capture tests' scene: six views at 24^2 of the standing stones of layout `seed`, written
/// to `dir` and loaded.
pub fn stones_dataset(dir: &std::path::Path, seed: u64) -> Dataset {
    let spec = DatasetSpec {
        views: 6,
        resolution: 24,
        grid: 24,
        seed,
    };
    write_dataset(&StandingStones::new(seed), dir, &spec).unwrap();
    Dataset::load(dir, [1.0; 3]).unwrap()
}

/// A pose in f64.
pub fn to_f64(m: glam::Mat4) -> DMat4 {
    DMat4::from_cols_array(&m.to_cols_array().map(f64::from))
}

/// A photo with alpha as a camera takes it, opaque on a grey background, and its alpha as a
/// mask.
pub fn photo_and_mask(photo: &image::RgbaImage) -> (image::RgbImage, image::GrayImage) {
    let rgb = image::RgbImage::from_fn(photo.width(), photo.height(), |x, y| {
        let p = photo.get_pixel(x, y);
        let a = f32::from(p[3]) / 255.0;
        image::Rgb([0, 1, 2].map(|c| (f32::from(p[c]) * a + 128.0 * (1.0 - a)).round() as u8))
    });
    let mask = image::GrayImage::from_fn(photo.width(), photo.height(), |x, y| {
        image::Luma([photo.get_pixel(x, y)[3]])
    });
    (rgb, mask)
}

/// Colour (composited on white) then opacity of every view at `size`^2.
pub fn pixels(d: &Dataset, size: usize) -> Vec<f32> {
    let level = d.level(size, size, &candle_core::Device::Cpu).unwrap();
    let flat =
        |t: &candle_core::Tensor| -> Vec<f32> { t.flatten_all().unwrap().to_vec1().unwrap() };
    let mut v = flat(&level.images);
    v.extend(flat(&level.opacity));
    v
}

/// The surface points the depth maps show at `size`^2, every `step`-th opaque pixel of each
/// view, in the dataset's frame.
pub fn surface_points(data: &Dataset, size: usize, step: usize) -> Vec<DVec3> {
    let level = data.level(size, size, &candle_core::Device::Cpu).unwrap();
    let depths: Vec<f32> = level.depths.flatten_all().unwrap().to_vec1().unwrap();
    let alphas: Vec<f32> = level.opacity.flatten_all().unwrap().to_vec1().unwrap();
    let mut points = Vec::new();
    for (v, cam) in data.cameras().iter().enumerate() {
        for pixel in (0..size * size).step_by(step) {
            let at = v * size * size + pixel;
            if alphas[at] < 0.99 {
                continue;
            }
            let (row, col) = ((pixel / size) as f32 + 0.5, (pixel % size) as f32 + 0.5);
            let (origin, dir) = cam.ray(row, col);
            points.push((origin + dir * depths[at]).as_dvec3());
        }
    }
    points
}

/// Asserts that one rotation takes every camera of `a` to its camera in `b` (within
/// `angle_tolerance` radians) and that distances between camera centres scale by `factor`;
/// returns that rotation.
pub fn assert_similar_cameras(
    a: &[volrender::Camera],
    b: &[volrender::Camera],
    factor: f64,
    angle_tolerance: f64,
) -> DMat3 {
    let map = |i: usize| {
        DMat3::from_mat4(to_f64(b[i].c2w)) * DMat3::from_mat4(to_f64(a[i].c2w)).transpose()
    };
    for i in 1..a.len() {
        let diff = map(i) * map(0).transpose();
        let angle = DQuat::from_mat3(&diff).angle_between(DQuat::IDENTITY);
        assert!(
            angle < angle_tolerance,
            "camera {i}: rotations differ by {angle} rad"
        );
    }
    let centre = |c: &volrender::Camera| c.position().as_dvec3();
    for i in 0..a.len() {
        for j in 0..i {
            let (da, db) = (centre(&a[i]) - centre(&a[j]), centre(&b[i]) - centre(&b[j]));
            assert!((db.length() / da.length() - factor).abs() < 1e-4 * factor);
        }
    }
    map(0)
}

/// Asserts that `placement` puts every one of `points` (the capture's frame) in the model's
/// cube and that the scene fills it: its widest side spans more than half the cube.
pub fn assert_fills_the_cube(placement: &rgbd_dataset::placement::Placement, points: &[DVec3]) {
    let m = placement.matrix();
    let placed: Vec<DVec3> = points.iter().map(|&p| m.transform_point3(p)).collect();
    assert!(
        placed.iter().all(|p| p.abs().max_element() <= 1.0),
        "a point outside the cube"
    );
    let (low, high) = placed
        .iter()
        .fold((DVec3::MAX, DVec3::MIN), |(l, h), &p| (l.min(p), h.max(p)));
    assert!((high - low).max_element() > 1.0, "{low} {high}");
}
