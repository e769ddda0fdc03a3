//! Scenes outside the unit cube: a dataset moved and scaled in space, told where its scene is,
//! trains on exactly the cameras and depth of the original; `auto` finds the box from the
//! depth maps; boxes that cannot be right are refused.

use std::path::Path;

use candle_core::{Device, Tensor};
use glam::Vec3;
use rgbd_dataset::scenes::SceneKind;
use rgbd_dataset::{write_dataset, Dataset, DatasetSpec, SceneBounds};
use serde_json::Value;

const SPEC: DatasetSpec = DatasetSpec {
    views: 6,
    resolution: 24,
    grid: 32,
    seed: 3,
};
/// The move: world = SCALE * original + SHIFT.
const SCALE: f32 = 2.5;
const SHIFT: Vec3 = Vec3::new(10.0, -4.0, 1.5);

fn values(t: &Tensor) -> Vec<f32> {
    t.flatten_all().unwrap().to_vec1().unwrap()
}

/// The test dataset written to `dir`, and a copy of it in `moved` with every camera moved by
/// the similarity and the depth unit scaled with it.
fn original_and_moved(dir: &Path, moved: &Path) {
    write_dataset(&*SceneKind::Mushrooms.build(1), dir, &SPEC).unwrap();
    for sub in ["images", "depth"] {
        std::fs::create_dir_all(moved.join(sub)).unwrap();
        for entry in std::fs::read_dir(dir.join(sub)).unwrap() {
            let entry = entry.unwrap();
            std::fs::copy(entry.path(), moved.join(sub).join(entry.file_name())).unwrap();
        }
    }
    let text = std::fs::read_to_string(dir.join("transforms.json")).unwrap();
    let mut root: Value = serde_json::from_str(&text).unwrap();
    root["depth_scale"] = (root["depth_scale"].as_f64().unwrap() * f64::from(SCALE)).into();
    for frame in root["frames"].as_array_mut().unwrap() {
        let m = &mut frame["transform_matrix"];
        for (r, shift) in SHIFT.to_array().into_iter().enumerate() {
            let t = m[r][3].as_f64().unwrap() as f32;
            m[r][3] = f64::from(t * SCALE + shift).into();
        }
    }
    std::fs::write(moved.join("transforms.json"), root.to_string()).unwrap();
}

fn moved_box(lo: f32, hi: f32) -> SceneBounds {
    SceneBounds::new(
        (Vec3::splat(lo) * SCALE + SHIFT).to_array(),
        (Vec3::splat(hi) * SCALE + SHIFT).to_array(),
    )
    .unwrap()
}

#[test]
fn a_moved_scene_told_its_bounds_trains_on_the_original_cameras_and_depth() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, moved) = (tmp.path().join("a"), tmp.path().join("b"));
    original_and_moved(&dir, &moved);
    let original = Dataset::load(&dir, [1.0; 3]).unwrap();
    let mapped = Dataset::load(&moved, [1.0; 3])
        .unwrap()
        .in_model_cube(&moved_box(-1.0, 1.0))
        .unwrap();
    for (a, b) in original.cameras().iter().zip(mapped.cameras()) {
        assert!(a.c2w.abs_diff_eq(b.c2w, 1e-5), "{:?} vs {:?}", a.c2w, b.c2w);
    }
    let level = |d: &Dataset| d.level(24, 24, &Device::Cpu).unwrap();
    let (a, b) = (level(&original), level(&mapped));
    for (x, y) in values(&a.depths).iter().zip(&values(&b.depths)) {
        assert!((x - y).abs() < 1e-5, "{x} vs {y}");
    }
    assert_eq!(values(&a.images), values(&b.images));

    // The model's cube lands on the box (a cube here) in the scene.
    let cube = moved_box(-1.0, 1.0).cube();
    assert!((cube.min - (SHIFT - Vec3::splat(SCALE))).length() < 1e-5);
    assert!((cube.max - (SHIFT + Vec3::splat(SCALE))).length() < 1e-5);
}

#[test]
fn auto_bounds_follow_the_scene() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, moved) = (tmp.path().join("a"), tmp.path().join("b"));
    original_and_moved(&dir, &moved);
    let here = Dataset::load(&dir, [1.0; 3])
        .unwrap()
        .auto_bounds()
        .unwrap();
    let there = Dataset::load(&moved, [1.0; 3])
        .unwrap()
        .auto_bounds()
        .unwrap();
    for a in 0..3 {
        for (h, t) in [(here.min[a], there.min[a]), (here.max[a], there.max[a])] {
            let want = h * SCALE + SHIFT[a];
            assert!((t - want).abs() < 1e-3 * SCALE, "axis {a}: {t} vs {want}");
        }
    }
    // The mushrooms stand on the ground of [-1, 1]^3 (z near -1), well inside the cube.
    assert!(here.min[2] > -1.2 && here.max[2] < 1.0, "{here}");
    assert!(
        here.min.iter().zip(&here.max).all(|(lo, hi)| hi - lo > 0.3),
        "{here}"
    );
}

#[test]
fn boxes_that_cannot_hold_the_scene_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, moved) = (tmp.path().join("a"), tmp.path().join("b"));
    original_and_moved(&dir, &moved);
    let data = Dataset::load(&moved, [1.0; 3]).unwrap();
    // The cameras are 3.5 from the scene's centre: a box of half side 4 holds them.
    let msg = data
        .in_model_cube(&moved_box(-4.0, 4.0))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("inside the box") && msg.contains("images/r_"),
        "{msg}"
    );
    // The unmoved box is far from every camera's view.
    let msg = data
        .in_model_cube(&SceneBounds::new([-1.0; 3], [1.0; 3]).unwrap())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("no camera sees"), "{msg}");
    for bad in ["1,2,3", "0,0,0,1,1,x", "0,0,0,1,-1,1", "0,0,0,1,1,inf"] {
        let msg = bad.parse::<SceneBounds>().unwrap_err().to_string();
        assert!(msg.contains("bounds"), "{bad}: {msg}");
    }
}

/// The `micro` preset (rendering with post-activated density or not), the moved box, and the
/// preset told that box.
fn micro_and_placed(
    post_activation: bool,
) -> (singrav::TrainConfig, SceneBounds, singrav::TrainConfig) {
    let plain = singrav::TrainConfig::preset("micro").unwrap().with(|c| {
        c.rendering.post_activation = post_activation;
    });
    let bounds = moved_box(-1.0, 0.6);
    let placed = plain.clone().with(|c| {
        c.run.bounds = Some(bounds);
    });
    (plain, bounds, placed)
}

/// A seeded raw volume `(1, 4, 6, 6, 6)` with values on both sides of the activation's knee
/// (raw 4 at the presets' shift -4), where interpolating raw and physical densities differ
/// most.
fn raw_around_the_knee(seed: u64) -> Tensor {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let raw: Vec<f32> = (0..4 * 6 * 6 * 6)
        .map(|_| rng.random_range(-2.0..10.0))
        .collect();
    Tensor::from_vec(raw, (1, 4, 6, 6, 6), &Device::Cpu).unwrap()
}

/// An untrained model of `config` (its volumes come from the tests' raw tensors).
fn model(config: &singrav::TrainConfig) -> singrav::SinGrav {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    singrav::SinGrav::new(config, &Device::Cpu, &mut rng).unwrap()
}

#[test]
fn volumes_of_a_run_with_bounds_sit_on_its_cube_with_density_in_scene_units() {
    let (plain, bounds, placed) = micro_and_placed(false);
    let raw = Tensor::randn(0f32, 2.0, (1, 4, 5, 5, 5), &Device::Cpu).unwrap();
    let a = model(&plain).to_physical(&raw).unwrap();
    let b = model(&placed).to_physical(&raw).unwrap();
    assert_eq!(a.aabb(), radiance_volume::Aabb::CUBE);
    assert_eq!(b.aabb(), bounds.cube());
    // Half side 0.8 x 2.5 = 2: the density halves, colour is unchanged.
    assert_eq!(bounds.half_side(), 2.0);
    let (da, db) = (values(&a.density().unwrap()), values(&b.density().unwrap()));
    for (x, y) in da.iter().zip(&db) {
        assert!((x / 2.0 - y).abs() <= 1e-6 * x.abs(), "{x} vs {y}");
    }
    assert_eq!(values(&a.rgb().unwrap()), values(&b.rgb().unwrap()));
}

/// A run trained with post-activated density hands out its volumes (`to_rendered`) so that
/// volrender, told the density rule that comes with them, renders them as the model's own
/// renderer does: in the model's cube, and in the scene's coordinates of a run with bounds
/// (where the rule's scale is divided by the half side, as `to_physical` divides density).
/// What `volgen eval` scores as V*'s volume is therefore what the model renders.
#[test]
fn post_activated_volumes_render_outside_the_model_as_inside() {
    use singrav::render::ViewRenderer;
    use volrender::{render, Camera, Rays, RenderConfig, Sampler};
    let (plain, bounds, placed) = micro_and_placed(true);
    // Raw densities around the activation's knee (shift -4), where interpolating raw and
    // physical values differ most.
    let raw = raw_around_the_knee(3);
    let samples = 48;
    let camera =
        |eye: Vec3, target: Vec3| Camera::look_at(eye, target, Vec3::Z, 8, 8, 0.7).unwrap();
    let (eye, target) = (Vec3::new(0.4, -3.2, 1.1), Vec3::new(0.0, 0.1, -0.2));
    let inside = ViewRenderer::new(&plain, samples, 1.0, false)
        .with_opacity(true)
        .render_all(&raw, &[&camera(eye, target)])
        .unwrap();
    let (inside_rgb, inside_opacity) = (values(&inside.rgb), values(&inside.opacity.unwrap()));
    assert!(inside_opacity.iter().any(|&a| a > 0.1 && a < 0.9));
    let cube = bounds.cube();
    let centre = (cube.min + cube.max) / 2.0;
    let half = bounds.half_side();
    for (config, cam) in [
        (&plain, camera(eye, target)),
        (&placed, camera(centre + half * eye, centre + half * target)),
    ] {
        let (volume, density) = model(config).to_rendered(&raw).unwrap();
        let cfg = RenderConfig::default()
            .with_sampler(Sampler::Uniform { samples })
            .with_background(config.rendering.background)
            .with_opacity(true)
            .with_aabb(volume.aabb())
            .with_density(density);
        let out = render(volume.tensor(), &Rays::from_camera(&cam), &cfg).unwrap();
        // (V, 3, h, w) against (R, 3): compare channel by channel.
        let rgb = values(&out.rgb.t().unwrap().contiguous().unwrap());
        for (a, b) in rgb.iter().zip(&inside_rgb) {
            assert!((a - b).abs() < 1e-4, "colour {a} vs {b}");
        }
        for (a, b) in values(&out.opacity.unwrap()).iter().zip(&inside_opacity) {
            assert!((a - b).abs() < 1e-4, "opacity {a} vs {b}");
        }
    }
    // A run rendering physical density hands out its physical volume.
    let physical = plain.clone().with(|c| {
        c.rendering.post_activation = false;
    });
    let (volume, density) = model(&physical).to_rendered(&raw).unwrap();
    assert_eq!(density, volrender::DensityInterpolation::Physical);
    let want = model(&physical).to_physical(&raw).unwrap();
    assert_eq!(values(volume.tensor()), values(want.tensor()));
}

/// Volumes written for other tools (`volgen sample --upsample K`) are physical per voxel, and
/// such tools interpolate physical density. On a grid K times finer (K odd), a post-activated
/// run's volume renders that way ever closer to what the model itself renders (the sharp edges
/// between its voxels come back), in the scene's coordinates too; a physical run's renders as
/// the model does at every K; K = 1 is `to_physical`, even K are refused.
#[test]
fn finer_physical_volumes_render_as_the_model_does() {
    use singrav::render::ViewRenderer;
    use volrender::{render, Camera, Rays, RenderConfig, Sampler};
    let raw = raw_around_the_knee(7);
    let samples = 64;
    // The model renders in its cube; the volumes it hands out sit in the scene's box.
    let (eye, target) = (Vec3::new(0.4, -3.2, 1.1), Vec3::new(0.0, 0.1, -0.2));
    let camera =
        |eye: Vec3, target: Vec3| Camera::look_at(eye, target, Vec3::Z, 16, 16, 0.7).unwrap();
    let rms_errors = |post_activation: bool, factors: &[usize]| -> Vec<f32> {
        let (plain, bounds, placed) = micro_and_placed(post_activation);
        let own = ViewRenderer::new(&plain, samples, 1.0, false)
            .render_all(&raw, &[&camera(eye, target)])
            .unwrap();
        // (1, 3, h, w) as (R, 3), the layout of volrender's output.
        let own = own.rgb.flatten_from(2).unwrap().squeeze(0).unwrap();
        let own = values(&own.t().unwrap().contiguous().unwrap());
        let cube = bounds.cube();
        let (centre, half) = ((cube.min + cube.max) / 2.0, bounds.half_side());
        let rays = Rays::from_camera(&camera(centre + half * eye, centre + half * target));
        let model = model(&placed);
        let coarse = model.to_physical(&raw).unwrap();
        let same = model.to_physical_upsampled(&raw, 1).unwrap();
        assert_eq!(values(coarse.tensor()), values(same.tensor()));
        let msg = model
            .to_physical_upsampled(&raw, 2)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("odd factor") && msg.contains("got 2"), "{msg}");
        let error = |&factor: &usize| {
            let volume = model.to_physical_upsampled(&raw, factor).unwrap();
            assert_eq!(volume.dims(), radiance_volume::GridDims::cube(6 * factor));
            assert_eq!(volume.aabb(), cube);
            let cfg = RenderConfig::default()
                .with_sampler(Sampler::Uniform { samples })
                .with_background(placed.rendering.background)
                .with_aabb(volume.aabb());
            let rgb = values(&render(volume.tensor(), &rays, &cfg).unwrap().rgb);
            let sum: f32 = rgb.iter().zip(&own).map(|(a, b)| (a - b).powi(2)).sum();
            (sum / rgb.len() as f32).sqrt()
        };
        factors.iter().map(error).collect()
    };
    let post = rms_errors(true, &[1, 3, 5, 7]);
    assert!(
        post[0] > 0.01,
        "the test volume has no sub-voxel edges: {post:?}"
    );
    assert!(
        post.windows(2).all(|w| w[1] < 0.7 * w[0])
            && post[1] < 0.3 * post[0]
            && post[3] < 0.1 * post[0],
        "{post:?}"
    );
    let physical = rms_errors(false, &[1, 3]);
    assert!(physical.iter().all(|&e| e < 1e-5), "{physical:?}");
}

/// Automatic bounds from the library alone (no CLI): a scene beyond the model's cube is
/// reported, `auto` resolves to the box its depth maps show, and a run placed by it trains.
#[test]
fn auto_bounds_place_a_moved_scene_from_the_library() {
    use rgbd_dataset::Bounds;
    use singrav::train::{beyond_the_cube, Control, RunOptions, Trainer};

    let tmp = tempfile::tempdir().unwrap();
    let (dir, moved) = (tmp.path().join("a"), tmp.path().join("b"));
    original_and_moved(&dir, &moved);
    let here = Dataset::load(&dir, [1.0; 3]).unwrap();
    let there = Dataset::load(&moved, [1.0; 3]).unwrap();
    assert!(beyond_the_cube(&here).is_none());
    let seen = beyond_the_cube(&there).expect("the moved scene is beyond the cube");
    let auto = Bounds::Auto.resolve(&there).unwrap();
    assert_eq!(auto, seen);
    assert_eq!(auto, there.auto_bounds().unwrap());
    let given = Bounds::Box(moved_box(-1.0, 1.0));
    assert_eq!(given.resolve(&there).unwrap(), moved_box(-1.0, 1.0));

    let config = singrav::TrainConfig::preset("micro")
        .unwrap()
        .with(|c| c.run.bounds = Some(auto));
    // The coarsest scale trains on the scene moved into the model's cube.
    let mut trainer = Trainer::new(
        &config,
        &there,
        &tmp.path().join("run"),
        &RunOptions::default(),
        &Device::Cpu,
    )
    .unwrap();
    let control = trainer.train_scale(&mut |_| Control::Continue).unwrap();
    assert_eq!(control, Control::Continue);
    assert_eq!(trainer.state().scale, 2);
}
