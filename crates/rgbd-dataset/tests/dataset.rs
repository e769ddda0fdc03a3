//! Datasets round-trip through disk to what the renderer sees, resize faithfully, and broken
//! datasets fail with messages that name the frame and what is wrong.

use std::path::Path;

use candle_core::{Device, Tensor};
use radiance_volume::GridDims;
use rgbd_dataset::scenes::SceneKind;
use rgbd_dataset::{render_config, write_dataset, Dataset, DatasetSpec, DEPTH_SCALE};
use serde_json::Value;
use volrender::{render_image, Camera, PAPER_FOV_DEG, PAPER_RADIUS};

const SPEC: DatasetSpec = DatasetSpec {
    views: 6,
    resolution: 24,
    grid: 32,
    seed: 5,
};
const BACKGROUND: [f32; 3] = [0.2, 0.5, 0.9];

/// Writes the test dataset of `kind` into a fresh directory.
fn written(kind: SceneKind) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let summary = write_dataset(&*kind.build(1), dir.path(), &SPEC).unwrap();
    assert_eq!(summary.transforms, dir.path().join("transforms.json"));
    assert_eq!((summary.views, summary.resolution), (6, 24));
    assert!(summary.seconds > 0.0);
    dir
}

fn values(t: &Tensor) -> Vec<f32> {
    t.flatten_all().unwrap().to_vec1().unwrap()
}

#[test]
fn loaded_frames_equal_a_direct_render_within_quantisation() {
    let scene = SceneKind::Islands.build(1);
    let dir = written(SceneKind::Islands);
    let data = Dataset::load(&dir.path().join("transforms.json"), BACKGROUND).unwrap();
    assert_eq!((data.len(), data.width(), data.height()), (6, 24, 24));
    assert!(!data.is_empty());
    assert_eq!(data.frame_names()[0], "images/r_000.png");

    let fov = PAPER_FOV_DEG.to_radians();
    let cameras = Camera::hemisphere(6, PAPER_RADIUS, fov, 24, 24, SPEC.seed).unwrap();
    for (loaded, expected) in data.cameras().iter().zip(&cameras) {
        assert!(loaded.c2w.abs_diff_eq(expected.c2w, 1e-6));
        assert!((loaded.fx - expected.fx).abs() < 1e-3);
    }

    let volume = scene.to_volume(GridDims::cube(SPEC.grid)).unwrap();
    let cfg = render_config().with_background(BACKGROUND);
    let level = data.level(24, 24, &Device::Cpu).unwrap();
    let (images, depths, opacity) = (
        values(&level.images),
        values(&level.depths),
        values(&level.opacity),
    );
    let plane = 24 * 24;
    let mut covered = 0;
    for (v, camera) in cameras.iter().enumerate() {
        let truth = render_image(&volume, camera, &cfg).unwrap();
        for i in 0..plane {
            for c in 0..3 {
                let got = images[(v * 3 + c) * plane + i];
                let want = truth.rgb[i][c];
                assert!(
                    (got - want).abs() <= 1.0 / 255.0 + 1e-4,
                    "view {v} pixel {i} channel {c}: {got} vs {want}"
                );
            }
            let (got, want) = (depths[v * plane + i], truth.depth[i]);
            assert!(
                (got - want).abs() <= DEPTH_SCALE * 0.5 + 1e-5,
                "view {v} pixel {i} depth {got} vs {want}"
            );
            assert!((opacity[v * plane + i] - truth.opacity[i]).abs() <= 0.5 / 255.0 + 1e-6);
            covered += usize::from(truth.opacity[i] > 0.5);
        }
    }
    // The scene fills a good part of the views, so the comparison is not of empty images.
    assert!(covered > 6 * plane / 4, "covered {covered}");
}

#[test]
fn levels_resize_by_area_and_keep_the_field_of_view() {
    let dir = written(SceneKind::Mushrooms);
    let data = Dataset::load(dir.path(), [1.0; 3]).unwrap();
    let full = data.level(24, 24, &Device::Cpu).unwrap();
    let half = data.level(12, 12, &Device::Cpu).unwrap();
    for (full, half) in [
        (&full.images, &half.images),
        (&full.depths, &half.depths),
        (&full.opacity, &half.opacity),
    ] {
        let pooled = values(&full.avg_pool2d(2).unwrap());
        let half = values(half);
        assert_eq!(pooled.len(), half.len());
        for (a, b) in pooled.iter().zip(&half) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }
    let odd = data.level(17, 10, &Device::Cpu).unwrap();
    assert_eq!(odd.images.dims(), &[6, 3, 10, 17]);
    for (camera, original) in odd.cameras.iter().zip(data.cameras()) {
        let fov = |c: &Camera| {
            (
                2.0 * (0.5 * c.width as f32 / c.fx).atan(),
                2.0 * (0.5 * c.height as f32 / c.fy).atan(),
            )
        };
        let (a, b) = (fov(camera), fov(original));
        assert!((a.0 - b.0).abs() < 1e-5 && (a.1 - b.1).abs() < 1e-5);
        assert_eq!((camera.width, camera.height), (17, 10));
        assert_eq!(camera.c2w, original.c2w);
        // The image centre still looks along the same ray.
        let (_, d_new) = camera.ray(5.0, 8.5);
        let (_, d_old) = original.ray(12.0, 12.0);
        assert!((d_new - d_old).length() < 1e-5);
    }
}

#[test]
fn a_constant_dataset_stays_constant_at_every_level() {
    let dir = written(SceneKind::StandingStones);
    // Overwrite every image with one colour at half opacity.
    let data = Dataset::load(dir.path(), [0.0; 3]).unwrap();
    for name in data.frame_names() {
        let pixels = image::RgbaImage::from_pixel(24, 24, image::Rgba([200, 100, 50, 128]));
        pixels.save(dir.path().join(name)).unwrap();
    }
    let data = Dataset::load(dir.path(), [1.0, 1.0, 1.0]).unwrap();
    let a = 128.0 / 255.0;
    let want = [200.0, 100.0, 50.0].map(|c: f32| c / 255.0 * a + (1.0 - a));
    for (w, h) in [(24, 24), (12, 12), (7, 5), (30, 40)] {
        let level = data.level(w, h, &Device::Cpu).unwrap();
        let images = values(&level.images);
        for (i, v) in images.iter().enumerate() {
            let c = (i / (w * h)) % 3;
            assert!((v - want[c]).abs() < 1e-5, "{w}x{h}: {v} vs {}", want[c]);
        }
        assert!(values(&level.opacity).iter().all(|o| (o - a).abs() < 1e-5));
    }
    assert!(data.level(0, 4, &Device::Cpu).is_err());
}

fn load_error(dir: &Path) -> String {
    match Dataset::load(dir, [0.0; 3]) {
        Ok(_) => panic!("loading {} should fail", dir.display()),
        Err(e) => e.to_string(),
    }
}

/// Rewrites `transforms.json` in `dir` through `edit`.
fn edit_transforms(dir: &Path, edit: impl FnOnce(&mut Value)) {
    let path = dir.join("transforms.json");
    let mut json: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut json);
    std::fs::write(&path, serde_json::to_string_pretty(&json).unwrap()).unwrap();
}

#[test]
fn a_missing_image_is_named() {
    let dir = written(SceneKind::StandingStones);
    std::fs::remove_file(dir.path().join("images/r_002.png")).unwrap();
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_002.png") && msg.contains("missing"),
        "{msg}"
    );

    let dir = written(SceneKind::StandingStones);
    std::fs::remove_file(dir.path().join("depth/r_004.png")).unwrap();
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_004.png")
            && msg.contains("depth/r_004.png")
            && msg.contains("missing"),
        "{msg}"
    );
}

#[test]
fn a_wrong_image_size_names_the_frame_and_both_sizes() {
    let dir = written(SceneKind::StandingStones);
    image::RgbaImage::new(10, 12)
        .save(dir.path().join("images/r_001.png"))
        .unwrap();
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_001.png") && msg.contains("10 x 12") && msg.contains("24 x 24"),
        "{msg}"
    );

    // Without `w` and `h` the first frame's size is the reference.
    edit_transforms(dir.path(), |json| {
        let root = json.as_object_mut().unwrap();
        root.remove("w");
        root.remove("h");
    });
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_001.png") && msg.contains("10 x 12") && msg.contains("24 x 24"),
        "{msg}"
    );

    // A depth map of another size than its image.
    let dir = written(SceneKind::StandingStones);
    image::ImageBuffer::<image::Luma<u16>, _>::new(24, 20)
        .save(dir.path().join("depth/r_003.png"))
        .unwrap();
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_003.png") && msg.contains("24 x 20"),
        "{msg}"
    );
}

#[test]
fn broken_camera_matrices_name_the_frame() {
    let dir = written(SceneKind::StandingStones);
    let original = std::fs::read_to_string(dir.path().join("transforms.json")).unwrap();

    // A scaled rotation is not rigid.
    edit_transforms(dir.path(), |json| {
        let m = &mut json["frames"][3]["transform_matrix"];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] = (m[r][c].as_f64().unwrap() * 1.1).into();
            }
        }
    });
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_003.png") && msg.contains("rigid"),
        "{msg}"
    );

    // NaN as Python's json module writes it: put a marker where the NaN goes, then swap it in.
    let path = dir.path().join("transforms.json");
    std::fs::write(&path, &original).unwrap();
    edit_transforms(dir.path(), |json| {
        json["frames"][5]["transform_matrix"][0][0] = 12345.5.into();
    });
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.matches("12345.5").count(), 1);
    std::fs::write(&path, text.replace("12345.5", "NaN")).unwrap();
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_005.png") && msg.contains("finite"),
        "{msg}"
    );

    // A last row other than [0, 0, 0, 1].
    std::fs::write(&path, &original).unwrap();
    edit_transforms(dir.path(), |json| {
        json["frames"][0]["transform_matrix"][3][1] = 0.5.into();
    });
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_000.png") && msg.contains("last row"),
        "{msg}"
    );
}

#[test]
fn missing_fields_are_named() {
    let dir = written(SceneKind::StandingStones);
    edit_transforms(dir.path(), |json| {
        json.as_object_mut().unwrap().remove("depth_scale");
    });
    let msg = load_error(dir.path());
    assert!(msg.contains("depth_scale") && msg.contains("unit"), "{msg}");

    let dir = written(SceneKind::StandingStones);
    edit_transforms(dir.path(), |json| {
        json["frames"][2]
            .as_object_mut()
            .unwrap()
            .remove("depth_file_path");
    });
    let msg = load_error(dir.path());
    assert!(
        msg.contains("images/r_002.png") && msg.contains("depth_file_path"),
        "{msg}"
    );

    edit_transforms(dir.path(), |json| json["frames"] = Value::Array(vec![]));
    assert!(load_error(dir.path()).contains("no frames"));
}

#[test]
fn blender_style_names_and_exr_depth_load() {
    let dir = written(SceneKind::Mushrooms);
    let reference = Dataset::load(dir.path(), [0.0; 3]).unwrap();
    let want = values(&reference.level(24, 24, &Device::Cpu).unwrap().depths);

    // Frame 0: image named without extension, depth as an EXR in world units.
    let depth: Vec<f32> = want[..24 * 24].to_vec();
    let exr_path = dir.path().join("depth/r_000.exr");
    exr::prelude::write_rgba_file(&exr_path, 24, 24, |x, y| {
        let d = depth[y * 24 + x];
        (d, d, d, 1.0)
    })
    .unwrap();
    edit_transforms(dir.path(), |json| {
        json["frames"][0]["file_path"] = "images/r_000".into();
        json["frames"][0]["depth_file_path"] = "depth/r_000.exr".into();
    });
    let data = Dataset::load(dir.path(), [0.0; 3]).unwrap();
    assert_eq!(data.frame_names()[0], "images/r_000");
    let got = values(&data.level(24, 24, &Device::Cpu).unwrap().depths);
    assert_eq!(got[..24 * 24], want[..24 * 24]);
}

#[test]
fn a_rewrite_that_fails_part_way_leaves_no_dataset_the_loader_accepts() {
    let dir = written(SceneKind::StandingStones);
    assert!(Dataset::load(dir.path(), BACKGROUND).is_ok());
    // Rewriting with other cameras fails at view 2 (its depth map's name is taken by a
    // directory): the old transforms.json must not survive to describe the new images.
    let blocked = dir.path().join("depth/r_002.png");
    std::fs::remove_file(&blocked).unwrap();
    std::fs::create_dir(&blocked).unwrap();
    let other = DatasetSpec { seed: 6, ..SPEC };
    assert!(write_dataset(&*SceneKind::StandingStones.build(1), dir.path(), &other).is_err());
    assert!(!dir.path().join("transforms.json").exists());
    let err = Dataset::load(dir.path(), BACKGROUND)
        .unwrap_err()
        .to_string();
    assert!(err.contains("transforms.json"), "{err}");
}
