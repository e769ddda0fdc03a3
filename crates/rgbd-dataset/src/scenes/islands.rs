//! Rocky, grassy islands and scattered boulders in calm water.

use glam::{Vec2, Vec3, Vec3Swizzles};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::sdf::{ellipsoid, grain, nearest, smoothstep, unyaw, Footprint};
use super::shade::{lit, mix, solid, Sample, SHELL};
use super::Scene;

/// Height of the sea floor.
const SEABED: f32 = -0.62;
/// Height of the water's surface.
const WATER_LEVEL: f32 = -0.48;
/// Water density, in 1/world-length: the layer down to the sea floor is ~98% opaque, so a
/// camera's depth lands within a few hundredths below the surface.
const WATER_SIGMA: f32 = 30.0;
/// Islands are centred within this distance of the z axis.
const ARCHIPELAGO_RADIUS: f32 = 0.6;
/// Finite-difference step of the terrain's slope.
const SLOPE_STEP: f32 = 0.004;

/// Four to seven islands of varied size and outline, with grass on top, bare rock on the flanks
/// and sand at the waterline, plus boulders along their shores, in a flat, fairly dense layer of
/// blue-green water.
///
/// ```
/// use rgbd_dataset::scenes::{Islands, Scene};
/// use glam::Vec3;
/// let scene = Islands::new(2);
/// assert_eq!(scene.eval(Vec3::new(0.0, 0.0, 0.9)).0, 0.0);
/// // Just under the water's surface, far out at sea: water, blue-green.
/// let (sigma, [r, _, b]) = scene.eval(Vec3::new(0.95, 0.95, -0.5));
/// assert!(sigma > 0.0 && b > r);
/// ```
#[derive(Debug, Clone)]
pub struct Islands {
    islands: Vec<Island>,
    boulders: Vec<Boulder>,
}

/// One island: a plateau-shaped bump of the sea floor with a wobbly elliptical outline.
#[derive(Debug, Clone, Copy)]
struct Island {
    centre: Vec2,
    radius: f32,
    /// Outline ratio of the long to the short axis.
    stretch: f32,
    yaw: f32,
    /// Rise of the top above the sea floor.
    rise: f32,
    /// Phase of the outline's wobble.
    phase: f32,
}

/// A boulder: a turned ellipsoid half sunk at an island's shore.
#[derive(Debug, Clone, Copy)]
struct Boulder {
    centre: Vec3,
    radii: Vec3,
    yaw: f32,
    tint: f32,
}

impl Islands {
    /// Scatters 4 to 7 non-overlapping islands and 2 to 4 boulders per island.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let count = rng.random_range(4..=7);
        let mut islands: Vec<Island> = Vec::with_capacity(count);
        for _ in 0..count * 40 {
            if islands.len() == count {
                break;
            }
            let candidate = Island::random(&mut rng);
            let clear = islands.iter().all(|i| {
                (i.centre - candidate.centre).length() > 0.75 * (i.reach() + candidate.reach())
            });
            if clear {
                islands.push(candidate);
            }
        }
        let boulders = islands
            .iter()
            .flat_map(|island| {
                let n = rng.random_range(2..=4);
                (0..n)
                    .map(|_| Boulder::at_shore(island, &mut rng))
                    .collect::<Vec<_>>()
            })
            .collect();
        Self { islands, boulders }
    }

    /// The islands whose outline may contain `p` (the others leave the sea floor flat there).
    fn islands_at(&self, p: Vec2) -> impl Iterator<Item = &Island> {
        self.islands
            .iter()
            .filter(move |island| (p - island.centre).length_squared() < island.reach().powi(2))
    }

    /// The terrain height: the sea floor's ripples and the tallest island at `p`.
    fn terrain_height(&self, p: Vec2) -> f32 {
        let floor = SEABED + 0.02 * (5.0 * p.x).sin() * (6.0 * p.y + 0.5).cos();
        self.islands_at(p)
            .map(|island| island.height(p))
            .fold(floor, f32::max)
    }

    /// Signed distance to land (negative inside) and the colour of the nearest surface.
    fn land(&self, p: Vec3) -> (f32, [f32; 3]) {
        let height = self.terrain_height(p.xy());
        // The height above the terrain, divided by the slope's secant, is the distance to the
        // terrain's tangent plane: close to the true distance even on the steep flanks, where
        // the plain height difference would make the density shell far too thin.
        let slope = Vec2::new(
            self.terrain_height(p.xy() + Vec2::X * SLOPE_STEP) - height,
            self.terrain_height(p.xy() + Vec2::Y * SLOPE_STEP) - height,
        ) / SLOPE_STEP;
        let ground = (p.z - height) / (1.0 + slope.length_squared()).sqrt();
        match nearest(&self.boulders, p, Boulder::footprint, Boulder::distance) {
            Some((d, boulder)) if d < ground => (d, rock(p, boulder.tint)),
            _ => (ground, self.terrain_albedo(p, height)),
        }
    }

    /// Sand at the waterline, grass where the land is flat enough, bare rock on the flanks.
    fn terrain_albedo(&self, p: Vec3, height: f32) -> [f32; 3] {
        let above_water = height - WATER_LEVEL;
        if above_water < 0.02 + 0.01 * grain(p, Vec3::new(17.0, 19.0, 0.0)) {
            return [0.78, 0.7, 0.5];
        }
        let flatness = self
            .islands_at(p.xy())
            .map(|island| island.flatness(p.xy()))
            .fold(0.0, f32::max);
        if flatness > 0.5 + 0.15 * grain(p, Vec3::new(9.0, 11.0, 0.0)) {
            let blades = 0.5 + 0.5 * grain(p, Vec3::new(43.0, 39.0, 0.0));
            [0.2 + 0.08 * blades, 0.42 + 0.12 * blades, 0.12]
        } else {
            rock(p, 1.0)
        }
    }

    /// The water layer's density and colour at `p`: turquoise in the shallows, deep blue-green
    /// over the sea floor, lit as a flat surface.
    fn water(&self, p: Vec3) -> Sample {
        let density = WATER_SIGMA * smoothstep(WATER_LEVEL + SHELL, WATER_LEVEL - SHELL, p.z);
        if density == 0.0 {
            return (0.0, [0.0; 3]);
        }
        let depth = WATER_LEVEL - self.terrain_height(p.xy());
        let deep = smoothstep(0.0, 0.1, depth);
        let shallow_colour = [0.25, 0.6, 0.58];
        let deep_colour = [0.07, 0.26, 0.4];
        let albedo = std::array::from_fn(|i| {
            shallow_colour[i] + (deep_colour[i] - shallow_colour[i]) * deep
        });
        (density, lit(albedo, Vec3::Z))
    }
}

/// Weathered grey-brown rock.
fn rock(p: Vec3, tint: f32) -> [f32; 3] {
    let grey = (0.5 + 0.07 * grain(p, Vec3::new(27.0, 23.0, 31.0))) * tint;
    [grey, grey * 0.94, grey * 0.86]
}

impl Island {
    fn random(rng: &mut impl Rng) -> Self {
        Self {
            centre: Vec2::from_angle(rng.random_range(0.0..std::f32::consts::TAU))
                * ARCHIPELAGO_RADIUS
                * rng.random::<f32>().sqrt(),
            radius: rng.random_range(0.12..0.26),
            stretch: rng.random_range(1.0..1.6),
            yaw: rng.random_range(0.0..std::f32::consts::PI),
            rise: rng.random_range(0.22..0.5),
            phase: rng.random_range(0.0..std::f32::consts::TAU),
        }
    }

    /// The farthest the island's outline reaches from its centre (stretch and wobble included).
    fn reach(&self) -> f32 {
        self.radius * self.stretch * 1.2
    }

    /// Distance from the centre relative to the wobbly outline: 0 at the centre, 1 on the shore
    /// of the sea floor.
    fn relative_radius(&self, p: Vec2) -> f32 {
        let local = unyaw((p - self.centre).extend(0.0), self.yaw).xy();
        let local = Vec2::new(local.x / self.stretch, local.y);
        let angle = local.y.atan2(local.x);
        let wobble = 1.0 + 0.1 * (3.0 * angle + self.phase).sin() + 0.06 * (5.0 * angle).cos();
        local.length() / (self.radius * wobble)
    }

    /// The island's height at `p`: a plateau with steep flanks, on the sea floor.
    fn height(&self, p: Vec2) -> f32 {
        let r = self.relative_radius(p);
        let hummocks = 0.025 * (17.0 * p.x + self.phase).sin() * (13.0 * p.y).cos();
        SEABED + self.rise * smoothstep(1.0, 0.45, r) + hummocks * smoothstep(0.6, 0.2, r)
    }

    /// 1 on the plateau, 0 on the flanks and beyond.
    fn flatness(&self, p: Vec2) -> f32 {
        smoothstep(0.62, 0.5, self.relative_radius(p))
    }
}

impl Boulder {
    fn at_shore(island: &Island, rng: &mut impl Rng) -> Self {
        let angle = rng.random_range(0.0..std::f32::consts::TAU);
        let along = unyaw(
            (Vec2::from_angle(angle) * Vec2::new(island.stretch, 1.0)).extend(0.0),
            -island.yaw,
        );
        let distance = island.radius * rng.random_range(0.8..1.15);
        let size = rng.random_range(0.025..0.06);
        Self {
            centre: (island.centre + along.xy() * distance).extend(WATER_LEVEL),
            radii: Vec3::new(
                size * rng.random_range(1.0..1.6),
                size,
                size * rng.random_range(0.8..1.5),
            ),
            yaw: rng.random_range(0.0..std::f32::consts::PI),
            tint: rng.random_range(0.8..1.05),
        }
    }

    fn footprint(&self) -> Footprint {
        Footprint {
            centre: self.centre.xy(),
            radius: self.radii.max_element(),
            top: self.centre.z + self.radii.z,
        }
    }

    fn distance(&self, p: Vec3) -> f32 {
        ellipsoid(unyaw(p - self.centre, self.yaw), self.radii)
    }
}

impl Scene for Islands {
    fn eval(&self, p: Vec3) -> Sample {
        mix(solid(p, |q| self.land(q)), self.water(p))
    }
}
