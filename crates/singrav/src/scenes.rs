//! Built-in procedural scenes: analytic density and colour fields with simple baked shading, in
//! the spirit of the paper's natural scenes (many constituents that repeat with variation).
//!
//! A scene is a pure function of the world point and its seed, so a volume of any resolution
//! can be baked from it with [`Scene::to_volume`].

use glam::{Vec2, Vec3};
use radiance_volume::{Aabb, GridDims, RadianceVolume};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Peak density of solid matter, in 1/world-length: opaque over a few hundredths of the box.
const SOLID_SIGMA: f32 = 60.0;
/// Width of the soft shell over which density rises from 0 to [`SOLID_SIGMA`].
const SHELL: f32 = 0.03;
/// The direction light comes from, for the baked shading.
const SUN: Vec3 = Vec3::new(0.45, -0.35, 0.82);

/// A ring of weathered standing stones on a grassy mound.
///
/// ```
/// use singrav::scenes::{Scene, StandingStones};
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

/// A scene: density (>= 0) and colour at every world point of the box `[-1, 1]^3`.
pub trait Scene: Sync {
    /// Returns the density and the shaded colour at `p`.
    fn eval(&self, p: Vec3) -> (f32, [f32; 3]);

    /// Bakes the scene into a physical volume over `[-1, 1]^3` by evaluating it at cell centres.
    fn to_volume(&self, dims: GridDims) -> radiance_volume::Result<RadianceVolume> {
        RadianceVolume::from_fn(dims, Aabb::CUBE, 4, |p, out| {
            let (sigma, rgb) = self.eval(p);
            out[0] = sigma;
            out[1..4].copy_from_slice(&rgb);
        })
    }
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

    /// The ground height: a low mound with gentle ripples.
    fn ground_height(p: Vec2) -> f32 {
        -0.62
            + 0.12 * (-p.length_squared() * 1.6).exp()
            + 0.015 * (7.0 * p.x).sin() * (5.0 * p.y).cos()
    }

    /// Signed distance to the nearest stone and that stone's tint.
    fn stone_distance(&self, p: Vec3) -> (f32, f32) {
        self.stones
            .iter()
            .map(|s| {
                let ground = Self::ground_height(s.base);
                let centre_z = ground + s.half_size.z * 0.9;
                let local = p - Vec3::new(s.base.x, s.base.y, centre_z);
                // Lean: shear x, y with height so the top leans over.
                let h = local.z / s.half_size.z;
                let local = Vec3::new(
                    local.x - s.lean.x * h * s.half_size.z,
                    local.y - s.lean.y * h * s.half_size.z,
                    local.z,
                );
                let (sin, cos) = s.yaw.sin_cos();
                let local = Vec3::new(
                    cos * local.x + sin * local.y,
                    -sin * local.x + cos * local.y,
                    local.z,
                );
                (rounded_box(local, s.half_size, 0.025), s.tint)
            })
            .fold((f32::INFINITY, 1.0), |a, b| if b.0 < a.0 { b } else { a })
    }

    /// Signed distance to the scene (negative inside) and the colour of the nearest surface.
    fn surface(&self, p: Vec3) -> (f32, [f32; 3]) {
        let ground = p.z - Self::ground_height(Vec2::new(p.x, p.y));
        let (stone, tint) = self.stone_distance(p);
        if stone < ground {
            let grain = 0.06 * ((23.0 * p.x).sin() * (19.0 * p.y).sin() * (29.0 * p.z).cos());
            let grey = (0.55 + grain) * tint;
            (stone, [grey, grey * 0.97, grey * 0.9])
        } else {
            let blades = 0.5 + 0.5 * ((41.0 * p.x).sin() * (37.0 * p.y).cos());
            let dry = 0.5 + 0.5 * (3.0 * p.x + 2.0 * p.y).sin();
            (
                ground,
                [0.22 + 0.15 * dry, 0.45 + 0.12 * blades, 0.12 + 0.05 * dry],
            )
        }
    }
}

impl Scene for StandingStones {
    fn eval(&self, p: Vec3) -> (f32, [f32; 3]) {
        let (d, albedo) = self.surface(p);
        if d > SHELL {
            return (0.0, [0.0; 3]);
        }
        let sigma = SOLID_SIGMA * smoothstep(SHELL, -SHELL, d);
        // Baked shading: Lambert from the sun via the distance field's gradient, plus sky light.
        let e = 0.01;
        let grad = Vec3::new(
            self.surface(p + Vec3::X * e).0 - self.surface(p - Vec3::X * e).0,
            self.surface(p + Vec3::Y * e).0 - self.surface(p - Vec3::Y * e).0,
            self.surface(p + Vec3::Z * e).0 - self.surface(p - Vec3::Z * e).0,
        );
        let normal = grad.normalize_or(Vec3::Z);
        let light = 0.35 + 0.65 * normal.dot(SUN.normalize()).max(0.0);
        (sigma, albedo.map(|a| (a * light).clamp(0.0, 1.0)))
    }
}

/// Signed distance to a box of half extents `b` with corners rounded by `r`.
fn rounded_box(p: Vec3, b: Vec3, r: f32) -> f32 {
    let q = p.abs() - b + Vec3::splat(r);
    q.max(Vec3::ZERO).length() + q.max_element().min(0.0) - r
}

/// Hermite step from 0 at `e0` to 1 at `e1`.
fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}
