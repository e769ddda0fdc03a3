//! Depth as datasets made elsewhere carry it: planar (`z`) and ray-length (`distance`) depth
//! become expected depth, every background convention reads as "nothing hit", holes in the
//! foreground are left out (and refused above 5%), and a dataset that does not say how it
//! measures depth is refused. Each test writes a one-view 8 x 6 dataset by hand.

use std::path::Path;

use candle_core::{Device, Tensor};
use exr::prelude::WritableImage;
use rgbd_dataset::{write_dataset, Dataset, DatasetSpec, DepthKind, LoadOptions};
use serde_json::{json, Value};

const W: usize = 8;
const H: usize = 6;
/// Horizontal field of view of the test camera, radians.
const FOV_X: f64 = 0.9;
/// The test camera: 3 units up +Z, looking down -Z, rotated 30 degrees about Z (so the
/// conversion cannot rely on an axis-aligned camera).
fn c2w() -> [[f64; 4]; 4] {
    let (s, c) = 30f64.to_radians().sin_cos();
    [
        [c, -s, 0.0, 0.5],
        [s, c, 0.0, -0.2],
        [0.0, 0.0, 1.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// Opacity bytes: the first row's first four pixels are background, the rest foreground but
/// for the edge pixels 5 (partly covered) and 6 (a renderer's exact 0.5, stored as 128/255).
fn alpha_byte(i: usize) -> u8 {
    match i {
        0..=3 => 0,
        5 => 100,
        6 => 128,
        _ => 255,
    }
}

/// A smooth positive depth, in world units.
fn surface(i: usize) -> f32 {
    2.0 + 0.05 * (i % W) as f32 + 0.03 * (i / W) as f32
}

/// `1 / cos` of the angle between pixel `i`'s ray and the viewing axis, in float64 from the
/// pinhole model (square pixels, principal point at the centre).
fn secant(i: usize) -> f64 {
    let f = 0.5 * W as f64 / (0.5 * FOV_X).tan();
    let u = ((i % W) as f64 + 0.5 - 0.5 * W as f64) / f;
    let v = ((i / W) as f64 + 0.5 - 0.5 * H as f64) / f;
    (1.0 + u * u + v * v).sqrt()
}

/// Writes a one-view dataset: RGBA image, depth `values` as an EXR channel `Z` (Blender's
/// name), and `transforms.json` with `depth_kind` when given.
fn write_exr_dataset(dir: &Path, kind: Option<&str>, values: &[f32]) {
    std::fs::create_dir_all(dir.join("depth")).unwrap();
    let image = image::RgbaImage::from_fn(W as u32, H as u32, |x, y| {
        image::Rgba([200, 120, 40, alpha_byte(y as usize * W + x as usize)])
    });
    image.save(dir.join("r_0.png")).unwrap();
    let channel = exr::prelude::AnyChannel::new(
        "View Layer.Depth.Z",
        exr::prelude::FlatSamples::F32(values.to_vec()),
    );
    exr::prelude::Image::from_channels(
        (W, H),
        exr::prelude::AnyChannels::sort(vec![channel].into()),
    )
    .write()
    .to_file(dir.join("depth/r_0.exr"))
    .unwrap();
    write_transforms(dir, kind, "depth/r_0.exr", None);
}

fn write_transforms(dir: &Path, kind: Option<&str>, depth: &str, scale: Option<f64>) {
    let mut root = json!({
        "camera_angle_x": FOV_X,
        "frames": [{ "file_path": "r_0", "depth_file_path": depth, "transform_matrix": c2w() }],
    });
    if let Some(kind) = kind {
        root["depth_kind"] = kind.into();
    }
    if let Some(scale) = scale {
        root["depth_scale"] = scale.into();
    }
    std::fs::write(dir.join("transforms.json"), root.to_string()).unwrap();
}

fn load(dir: &Path, kind: Option<DepthKind>) -> rgbd_dataset::Result<Dataset> {
    Dataset::load_with(
        dir,
        &LoadOptions {
            background: [0.0; 3],
            depth_kind: kind,
        },
    )
}

fn values(t: &Tensor) -> Vec<f32> {
    t.flatten_all().unwrap().to_vec1().unwrap()
}

fn depths(data: &Dataset) -> Vec<f32> {
    values(&data.level(W, H, &Device::Cpu).unwrap().depths)
}

fn error(result: rgbd_dataset::Result<Dataset>) -> String {
    match result {
        Ok(_) => panic!("loading should fail"),
        Err(e) => e.to_string(),
    }
}

fn alpha(i: usize) -> f64 {
    f64::from(alpha_byte(i)) / 255.0
}

#[test]
fn planar_depth_becomes_opacity_times_ray_distance() {
    let dir = tempfile::tempdir().unwrap();
    let raw: Vec<f32> = (0..W * H).map(surface).collect();
    write_exr_dataset(dir.path(), Some("z"), &raw);
    let data = load(dir.path(), None).unwrap();
    assert_eq!(
        (data.depth_kind(), data.depth_left_out()),
        (DepthKind::Z, 0)
    );
    for (i, got) in depths(&data).into_iter().enumerate() {
        let want = alpha(i) * f64::from(surface(i)) * secant(i);
        assert!(
            (f64::from(got) - want).abs() < 1e-5,
            "pixel {i}: {got} vs {want}"
        );
    }
    // The corner rays are clearly longer than the axis distance, so the test sees the cosine.
    assert!(secant(W * H - 1) > 1.1);
}

#[test]
fn ray_distance_becomes_opacity_times_distance() {
    let dir = tempfile::tempdir().unwrap();
    let raw: Vec<f32> = (0..W * H).map(surface).collect();
    write_exr_dataset(dir.path(), Some("distance"), &raw);
    let got = depths(&load(dir.path(), None).unwrap());
    for (i, got) in got.into_iter().enumerate() {
        let want = alpha(i) * f64::from(surface(i));
        assert!(
            (f64::from(got) - want).abs() < 1e-5,
            "pixel {i}: {got} vs {want}"
        );
    }
}

#[test]
fn every_background_convention_reads_as_nothing_hit() {
    for marker in [f32::INFINITY, f32::NAN, 1e10, 1e9, 65504.0, 0.0] {
        for kind in ["z", "distance"] {
            let dir = tempfile::tempdir().unwrap();
            // The background pixels (opacity 0) carry the marker.
            let raw: Vec<f32> = (0..W * H)
                .map(|i| {
                    if alpha_byte(i) == 0 {
                        marker
                    } else {
                        surface(i)
                    }
                })
                .collect();
            write_exr_dataset(dir.path(), Some(kind), &raw);
            let data = load(dir.path(), None).unwrap();
            assert_eq!(data.depth_left_out(), 0, "{kind} {marker}");
            let got = depths(&data);
            assert_eq!(got[..4], [0.0; 4], "{kind} {marker}");
            assert!(got[4..].iter().all(|d| *d > 0.7), "{kind} {marker}");
            assert!(data.level(W, H, &Device::Cpu).unwrap().depth_mask.is_none());
        }
    }
}

#[test]
fn foreground_without_depth_is_left_out_and_refused_above_five_percent() {
    // 42 pixels are foreground; one hole among them is 2.4%. The edge pixels 5 and 6 are
    // left out too, but do not count against the foreground.
    let dir = tempfile::tempdir().unwrap();
    let mut raw: Vec<f32> = (0..W * H).map(surface).collect();
    raw[5] = 1e10;
    raw[6] = 1e10;
    raw[20] = f32::INFINITY;
    write_exr_dataset(dir.path(), Some("z"), &raw);
    let data = load(dir.path(), None).unwrap();
    assert_eq!(data.depth_left_out(), 3);
    let level = data.level(W, H, &Device::Cpu).unwrap();
    let mask = values(level.depth_mask.as_ref().unwrap());
    for (i, m) in mask.iter().enumerate() {
        let left_out = [5, 6, 20].contains(&i);
        assert_eq!(*m, if left_out { 0.0 } else { 1.0 }, "pixel {i}");
    }
    assert_eq!(values(&level.depths)[20], 0.0);

    // Halving the resolution: the 2 x 2 block holding pixel 20 (row 2, column 4) keeps 3/4 of
    // its weight and the mean depth of its three known pixels.
    let half = data.level(W / 2, H / 2, &Device::Cpu).unwrap();
    let block = W / 2 + 2;
    assert_eq!(values(half.depth_mask.as_ref().unwrap())[block], 0.75);
    let known = [21, 28, 29].map(|i| f64::from(surface(i)) * secant(i));
    let want = known.iter().sum::<f64>() / 3.0;
    let got = f64::from(values(&half.depths)[block]);
    assert!((got - want).abs() < 1e-5, "{got} vs {want}");

    // Three holes in the foreground: 3 / 42 = 7.1% > 5%.
    raw[30] = 0.0;
    raw[40] = 65504.0;
    write_exr_dataset(dir.path(), Some("z"), &raw);
    let msg = error(load(dir.path(), None));
    assert!(
        msg.contains("depth/r_0.exr") && msg.contains("3 of the 42") && msg.contains("5%"),
        "{msg}"
    );
}

#[test]
fn a_dataset_that_does_not_say_its_depth_kind_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let raw: Vec<f32> = (0..W * H).map(surface).collect();
    write_exr_dataset(dir.path(), None, &raw);
    let msg = error(load(dir.path(), None));
    for word in [
        "transforms.json",
        "`depth_kind` is missing",
        "--depth-kind",
        "\"expected\"",
        "\"z\"",
        "\"distance\"",
    ] {
        assert!(msg.contains(word), "{word} not in {msg}");
    }
    // The option says it instead.
    let data = load(dir.path(), Some(DepthKind::Distance)).unwrap();
    assert_eq!(data.depth_kind(), DepthKind::Distance);

    // An unknown kind in the file.
    write_exr_dataset(dir.path(), Some("planar"), &raw);
    let msg = error(load(dir.path(), None));
    assert!(
        msg.contains("transforms.json") && msg.contains("depth_kind") && msg.contains("\"planar\""),
        "{msg}"
    );
    // A kind that is not a string.
    let path = dir.path().join("transforms.json");
    let mut root: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    root["depth_kind"] = 3.into();
    std::fs::write(&path, root.to_string()).unwrap();
    let msg = error(load(dir.path(), None));
    assert!(msg.contains("`depth_kind` must be a string"), "{msg}");
}

#[test]
fn the_option_overrides_the_files_kind() {
    let dir = tempfile::tempdir().unwrap();
    let raw: Vec<f32> = (0..W * H).map(surface).collect();
    write_exr_dataset(dir.path(), Some("expected"), &raw);
    let as_file = depths(&load(dir.path(), None).unwrap());
    assert_eq!(as_file[10], surface(10));
    let as_z = depths(&load(dir.path(), Some(DepthKind::Z)).unwrap());
    let want = alpha(10) * f64::from(surface(10)) * secant(10);
    assert!((f64::from(as_z[10]) - want).abs() < 1e-5);
}

#[test]
fn values_no_kind_allows_are_refused_with_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut raw: Vec<f32> = (0..W * H).map(surface).collect();
    raw[12] = f32::INFINITY;
    write_exr_dataset(dir.path(), Some("expected"), &raw);
    let msg = error(load(dir.path(), None));
    assert!(
        msg.contains("depth/r_0.exr") && msg.contains("finite") && msg.contains("r_0"),
        "{msg}"
    );
    raw[12] = -1.0;
    write_exr_dataset(dir.path(), Some("z"), &raw);
    let msg = error(load(dir.path(), None));
    assert!(
        msg.contains("depth/r_0.exr") && msg.contains("negative"),
        "{msg}"
    );
}

#[test]
fn millimetre_png_depth_keeps_its_scale() {
    let dir = tempfile::tempdir().unwrap();
    write_exr_dataset(dir.path(), Some("z"), &[1.0; W * H]);
    // Millimetres: 2000 counts are 2 world units; 0 counts are "no surface" (background here).
    let counts = |i: usize| {
        if alpha_byte(i) == 0 {
            0
        } else {
            2000 + i as u16
        }
    };
    let png = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(W as u32, H as u32, |x, y| {
        image::Luma([counts(y as usize * W + x as usize)])
    });
    png.save(dir.path().join("depth/r_0.png")).unwrap();
    write_transforms(dir.path(), Some("z"), "depth/r_0.png", Some(0.001));
    let got = depths(&load(dir.path(), None).unwrap());
    for (i, got) in got.into_iter().enumerate() {
        let want = alpha(i) * f64::from(counts(i)) * 0.001 * secant(i);
        assert!(
            (f64::from(got) - want).abs() < 1e-5,
            "pixel {i}: {got} vs {want}"
        );
    }
}

#[test]
fn volgen_datasets_say_they_hold_expected_depth() {
    let dir = tempfile::tempdir().unwrap();
    let spec = DatasetSpec {
        views: 1,
        resolution: 8,
        grid: 8,
        seed: 0,
    };
    write_dataset(&rgbd_dataset::scenes::Islands::new(1), dir.path(), &spec).unwrap();
    let text = std::fs::read_to_string(dir.path().join("transforms.json")).unwrap();
    let root: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(root["depth_kind"], "expected");
    let data = Dataset::load(dir.path(), [1.0; 3]).unwrap();
    assert_eq!(data.depth_kind(), DepthKind::Expected);
}

/// Photos without depth maps (`depth_kind` none): frames need no depth file, every covered
/// pixel is left out of the depth loss, colour and opacity load as usual; another kind still
/// needs its files.
#[test]
fn a_dataset_without_depth_maps_loads_with_every_pixel_left_out() {
    let dir = tempfile::tempdir().unwrap();
    write_exr_dataset(dir.path(), Some("none"), &[2.0; W * H]);
    // No depth file at all: the frame's `depth_file_path` names a file that is not there.
    std::fs::remove_file(dir.path().join("depth/r_0.exr")).unwrap();
    let root = json!({
        "camera_angle_x": FOV_X,
        "depth_kind": "none",
        "frames": [{ "file_path": "r_0", "transform_matrix": c2w() }],
    });
    std::fs::write(dir.path().join("transforms.json"), root.to_string()).unwrap();
    let data = load(dir.path(), None).unwrap();
    assert_eq!(data.depth_kind(), DepthKind::None);
    let covered = (0..W * H).filter(|&i| alpha_byte(i) > 0).count();
    assert_eq!(data.depth_left_out(), covered);
    let level = data.level(W, H, &Device::Cpu).unwrap();
    assert!(values(&level.depths).iter().all(|&d| d == 0.0));
    let mask = level.depth_mask.expect("every pixel is left out");
    assert!(values(&mask).iter().all(|&m| m == 0.0));
    let opacity = values(&level.opacity);
    for (i, &a) in opacity.iter().enumerate() {
        assert!((f64::from(a) - alpha(i)).abs() < 1e-6);
    }
    // Read as any kind with depth, the missing field is an error naming it.
    let err = error(load(dir.path(), Some(DepthKind::Z)));
    assert!(err.contains("depth_file_path"), "{err}");
    assert_eq!("none".parse::<DepthKind>().unwrap(), DepthKind::None);
}

/// Depth from a reconstruction (`Dataset::with_depth_from`): the scene itself gives back the
/// depth maps the files hold (to their 16-bit steps of 1e-4, and their 8-bit alpha: the depth
/// is the ray distance times the file's alpha, which is the rendering's to half of 1/255); an
/// empty reconstruction gives
/// none, every foreground pixel left out, colour and opacity untouched either way.
#[test]
fn depth_from_a_reconstruction_is_the_scene_s_where_it_covers_the_views() {
    use rgbd_dataset::scenes::{Scene, StandingStones};
    let dir = tempfile::tempdir().unwrap();
    let spec = DatasetSpec {
        views: 3,
        resolution: 20,
        grid: 24,
        seed: 4,
    };
    write_dataset(&StandingStones::new(4), dir.path(), &spec).unwrap();
    let data = Dataset::load(dir.path(), [1.0; 3]).unwrap();
    let scene = StandingStones::new(4)
        .to_volume(radiance_volume::GridDims::cube(24))
        .unwrap();
    let level = |d: &Dataset| d.level(20, 20, &Device::Cpu).unwrap();
    let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let (from_scene, coverage) = data.with_depth_from(&scene).unwrap();
    assert_eq!(coverage.holes, 0);
    assert!(coverage.foreground > 100, "{coverage:?}");
    assert_eq!(from_scene.depth_kind(), DepthKind::Expected);
    let (truth, got) = (level(&data), level(&from_scene));
    let alpha = flat(&truth.opacity);
    for ((want, got), a) in flat(&truth.depths)
        .iter()
        .zip(flat(&got.depths))
        .zip(&alpha)
    {
        // Where the view shows (next to) nothing, the depth is 0, the file's at most the
        // farthest ray distance (5.3) times an opacity that rounds to 1/255 or less.
        let allowed = 2e-4
            + if *a > 1.0 / 255.0 {
                want * (0.5 / 255.0) / a
            } else {
                0.03
            };
        assert!(
            (want - got).abs() <= allowed,
            "{got} against {want} at alpha {a}"
        );
    }
    assert_eq!(flat(&truth.images), flat(&got.images));
    assert_eq!(flat(&truth.opacity), flat(&got.opacity));

    let empty = radiance_volume::RadianceVolume::new(
        Tensor::zeros((4, 8, 8, 8), candle_core::DType::F32, &Device::Cpu).unwrap(),
        scene.aabb(),
    )
    .unwrap();
    let (from_nothing, coverage) = data.with_depth_from(&empty).unwrap();
    assert_eq!(coverage.holes, coverage.foreground);
    let shown = flat(&truth.opacity)
        .iter()
        .filter(|&&a| a > 1.0 / 255.0)
        .count();
    assert_eq!(from_nothing.depth_left_out(), shown);
    assert!(flat(&level(&from_nothing).depths).iter().all(|&d| d == 0.0));
}
