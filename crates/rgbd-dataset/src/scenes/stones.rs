//! A ring of weathered standing stones on a grassy mound.

use glam::{Vec2, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::sdf::{grain, nearest, rounded_box, unyaw, Footprint};
use super::shade::{solid, Sample};
use super::Scene;

/// A ring of weathered standing stones on a grassy mound.
///
/// ```
/// use rgbd_dataset::scenes::{Scene, StandingStones};
/// use radiance_volume::GridDims;
/// let scene = StandingStones::new(7);
/// let v = scene.to_volume(GridDims::cube(24))?;
/// assert_eq!(v.channel_count(), 4);
/// # Ok::<(), radiance_volume::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct StandingStones {
    stones: Vec<Stone>,
}

/// One stone: a rounded box standing on the ground, turned about z and slightly tilted.
#[derive(Debug, Clone, Copy)]
struct Stone {
    base: Vec2,
    half_size: Vec3,
    yaw: f32,
    lean: Vec2,
    tint: f32,
}

impl StandingStones {
    /// Lays out 9 to 12 stones on a ring with seeded variation of size, spacing and tilt.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let count = rng.random_range(9..=12);
        let stones = (0..count)
            .map(|i| {
                let angle =
                    std::f32::consts::TAU * (i as f32 + rng.random_range(-0.2..0.2)) / count as f32;
                let radius = rng.random_range(0.55..0.68);
                Stone {
                    base: Vec2::new(angle.cos(), angle.sin()) * radius,
                    half_size: Vec3::new(
                        rng.random_range(0.06..0.1),
                        rng.random_range(0.035..0.06),
                        rng.random_range(0.2..0.42),
                    ),
                    yaw: angle + rng.random_range(-0.3..0.3),
                    lean: Vec2::new(rng.random_range(-0.12..0.12), rng.random_range(-0.12..0.12)),
                    tint: rng.random_range(0.85..1.1),
                }
            })
            .collect();
        Self { stones }
    }

    /// How many stones stand in the ring.
    #[must_use]
    pub fn stone_count(&self) -> usize {
        self.stones.len()
    }

    /// The ground height: a low mound with gentle ripples.
    fn ground_height(p: Vec2) -> f32 {
        -0.62
            + 0.12 * (-p.length_squared() * 1.6).exp()
            + 0.015 * (7.0 * p.x).sin() * (5.0 * p.y).cos()
    }

    /// Signed distance to the scene (negative inside) and the colour of the nearest surface.
    fn surface(&self, p: Vec3) -> (f32, [f32; 3]) {
        let ground = p.z - Self::ground_height(Vec2::new(p.x, p.y));
        match nearest(&self.stones, p, Stone::footprint, Stone::distance) {
            Some((d, stone)) if d < ground => {
                let grey = (0.55 + 0.06 * grain(p, Vec3::new(23.0, 19.0, 29.0))) * stone.tint;
                (d, [grey, grey * 0.97, grey * 0.9])
            }
            _ => {
                let blades = 0.5 + 0.5 * ((41.0 * p.x).sin() * (37.0 * p.y).cos());
                let dry = 0.5 + 0.5 * (3.0 * p.x + 2.0 * p.y).sin();
                (
                    ground,
                    [0.22 + 0.15 * dry, 0.45 + 0.12 * blades, 0.12 + 0.05 * dry],
                )
            }
        }
    }
}

impl Stone {
    /// The stone's centre height: sunk a little into the ground under it.
    fn centre_z(&self) -> f32 {
        StandingStones::ground_height(self.base) + self.half_size.z * 0.9
    }

    fn footprint(&self) -> Footprint {
        // The lean shears the top sideways by up to `lean * half height` (a little more with
        // the rounded top), on top of the box's own half diagonal.
        Footprint {
            centre: self.base,
            radius: Vec2::new(self.half_size.x, self.half_size.y).length()
                + 1.2 * self.lean.length() * self.half_size.z,
            top: self.centre_z() + self.half_size.z,
        }
    }

    fn distance(&self, p: Vec3) -> f32 {
        let local = p - self.base.extend(self.centre_z());
        // Lean: shear x, y with height so the top leans over.
        let h = local.z / self.half_size.z;
        let sheared = local - (self.lean * h * self.half_size.z).extend(0.0);
        rounded_box(unyaw(sheared, self.yaw), self.half_size, 0.025)
    }
}

impl Scene for StandingStones {
    fn eval(&self, p: Vec3) -> Sample {
        solid(p, |q| self.surface(q))
    }
}
