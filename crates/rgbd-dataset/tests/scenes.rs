//! The built-in scenes are valid physical volumes, have structure, depend only on their seed,
//! and are found by name.

use glam::Vec3;
use radiance_volume::GridDims;
use rgbd_dataset::scenes::{Scene, SceneKind, StandingStones};

const DIMS: GridDims = GridDims {
    d: 32,
    h: 32,
    w: 32,
};

fn bake(kind: SceneKind, seed: u64) -> Vec<f32> {
    kind.build(seed)
        .to_volume(DIMS)
        .unwrap()
        .tensor()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap()
}

#[test]
fn every_scene_is_physical_partly_occupied_and_seeded() {
    let n = DIMS.voxel_count();
    for kind in SceneKind::ALL {
        let values = bake(kind, 3);
        assert!(
            values[..n].iter().all(|&s| s.is_finite() && s >= 0.0),
            "{kind}: density must be finite and >= 0"
        );
        assert!(
            values[n..].iter().all(|&c| (0.0..=1.0).contains(&c)),
            "{kind}: colour must be in [0, 1]"
        );
        let occupied = values[..n].iter().filter(|&&s| s > 0.0).count() as f32 / n as f32;
        assert!(
            occupied > 0.02 && occupied < 0.4,
            "{kind}: occupied fraction {occupied}"
        );
        assert_eq!(values, bake(kind, 3), "{kind}: same seed, same volume");
        assert_ne!(
            values,
            bake(kind, 4),
            "{kind}: another seed, another volume"
        );

        // Air above the content, solid ground below it.
        let scene = kind.build(3);
        assert_eq!(scene.eval(Vec3::new(0.0, 0.0, 0.9)).0, 0.0, "{kind}");
        assert!(scene.eval(Vec3::new(0.0, 0.0, -0.9)).0 > 0.0, "{kind}");
    }
}

#[test]
fn content_stays_where_the_hemisphere_cameras_see_it() {
    // Above the ground, matter only near the axis and below z = 0.5; the sides of the box are
    // empty above the ground (so nothing is cut off at an image's edge).
    for kind in SceneKind::ALL {
        let scene = kind.build(11);
        for i in 0..40 {
            let angle = i as f32 * std::f32::consts::TAU / 40.0;
            for z in [-0.3, 0.0, 0.3, 0.6] {
                let p = Vec3::new(0.9 * angle.cos(), 0.9 * angle.sin(), z);
                assert_eq!(scene.eval(p).0, 0.0, "{kind} at {p}");
            }
            for r in [0.0, 0.3, 0.6] {
                let p = Vec3::new(r * angle.cos(), r * angle.sin(), 0.55);
                assert_eq!(scene.eval(p).0, 0.0, "{kind} at {p}");
            }
        }
    }
}

#[test]
fn the_scenes_differ_from_each_other() {
    let volumes: Vec<Vec<f32>> = SceneKind::ALL.iter().map(|&k| bake(k, 0)).collect();
    assert_ne!(volumes[0], volumes[1]);
    assert_ne!(volumes[1], volumes[2]);
    assert_ne!(volumes[0], volumes[2]);
}

#[test]
fn scene_names_round_trip_and_junk_is_refused() {
    for kind in SceneKind::ALL {
        assert_eq!(kind.name().parse::<SceneKind>().unwrap(), kind);
        assert_eq!(kind.to_string(), kind.name());
    }
    for junk in ["", "Stones", "forest", "stones "] {
        let err = junk.parse::<SceneKind>().unwrap_err().to_string();
        assert!(
            err.contains("stones") && err.contains("mushrooms") && err.contains("islands"),
            "{err}"
        );
    }
}

#[test]
fn standing_stones_is_the_stones_kind() {
    let dims = GridDims::cube(16);
    let direct = StandingStones::new(5).to_volume(dims).unwrap();
    let by_kind = SceneKind::StandingStones.build(5).to_volume(dims).unwrap();
    let direct: Vec<f32> = direct.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let by_kind: Vec<f32> = by_kind.tensor().flatten_all().unwrap().to_vec1().unwrap();
    assert_eq!(direct, by_kind);
}
