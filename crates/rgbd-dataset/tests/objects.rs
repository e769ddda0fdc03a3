//! scene-metrics' objects (separate solid things above the ground) of the built-in scenes,
//! baked at the grids of the presets' finest volumes: the things each scene laid out (but those
//! that touch), which is what makes the metric's count of generated scenes comparable with the
//! scene's.

use radiance_volume::GridDims;
use rgbd_dataset::scenes::{Mushrooms, Scene, StandingStones};
use scene_metrics::{ObjectRule, Objects};

fn objects(scene: &dyn Scene, grid: usize) -> Objects {
    let volume = scene.to_volume(GridDims::cube(grid)).unwrap();
    Objects::of(volume.tensor(), 2.0 / grid as f32, &ObjectRule::default()).unwrap()
}

#[test]
fn every_standing_stone_is_one_object_at_every_presets_finest_grid() {
    for seed in 0..4 {
        let scene = StandingStones::new(seed);
        for grid in [57, 126] {
            let found = objects(&scene, grid);
            assert_eq!(
                found.count(0.0),
                scene.stone_count(),
                "seed {seed}, {grid}^3"
            );
            // No stone holds more than a quarter of the ring's stone matter.
            assert!(found.largest_share() < 0.25, "seed {seed}, {grid}^3");
        }
    }
}

#[test]
fn mushrooms_are_objects_but_for_those_whose_caps_touch() {
    // The field lets neighbouring caps overlap by a fifth of their radii, so some caps touch
    // and two mushrooms are one piece of matter: the metric counts what the volume holds.
    for seed in 0..2 {
        let scene = Mushrooms::new(seed);
        let found = objects(&scene, 126);
        let sizes: Vec<(usize, [f64; 3])> =
            found.all().iter().map(|o| (o.voxels, o.centre)).collect();
        let (count, mushrooms) = (found.count(0.0), scene.mushroom_count());
        assert!(
            count <= mushrooms && 5 * count >= 4 * mushrooms,
            "seed {seed}: {count} objects of {mushrooms} mushrooms: {sizes:?}"
        );
        // A merged pair is at most about twice a mushroom: none holds a fifth of the field.
        assert!(found.largest_share() < 0.2, "seed {seed}: {sizes:?}");
    }
}
