//! The built-in scene is a valid physical volume, has structure, and depends only on its seed.

use glam::Vec3;
use radiance_volume::GridDims;
use singrav::scenes::{Scene, StandingStones};

#[test]
fn standing_stones_is_physical_partly_occupied_and_seeded() {
    let dims = GridDims::cube(32);
    let a = StandingStones::new(3).to_volume(dims).unwrap();
    let values: Vec<f32> = a.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let n = dims.voxel_count();
    assert!(values[..n].iter().all(|&s| s.is_finite() && s >= 0.0));
    assert!(values[n..].iter().all(|&c| (0.0..=1.0).contains(&c)));
    let occupied = values[..n].iter().filter(|&&s| s > 0.0).count() as f32 / n as f32;
    assert!(
        occupied > 0.05 && occupied < 0.6,
        "occupied fraction {occupied}"
    );

    // Air above the stones, ground below the mound's top.
    let scene = StandingStones::new(3);
    assert_eq!(scene.eval(Vec3::new(0.0, 0.0, 0.9)).0, 0.0);
    assert!(scene.eval(Vec3::new(0.0, 0.0, -0.9)).0 > 0.0);

    let again = StandingStones::new(3).to_volume(dims).unwrap();
    let other = StandingStones::new(4).to_volume(dims).unwrap();
    let again: Vec<f32> = again.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let other: Vec<f32> = other.tensor().flatten_all().unwrap().to_vec1().unwrap();
    assert_eq!(values, again);
    assert_ne!(values, other);
}
