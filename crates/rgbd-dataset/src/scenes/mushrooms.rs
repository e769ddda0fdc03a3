//! A field of mushrooms of varied size and cap colour on mossy ground.

use glam::{Vec2, Vec3, Vec3Swizzles};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::sdf::{ellipsoid, grain, nearest, smooth_min, vertical_cylinder, Footprint};
use super::shade::{solid, Sample};
use super::Scene;

/// Cap colours to draw from: fly agaric red, brown, tan, orange and ivory.
const CAP_COLOURS: [[f32; 3]; 5] = [
    [0.72, 0.1, 0.07],
    [0.45, 0.27, 0.13],
    [0.76, 0.6, 0.38],
    [0.85, 0.45, 0.1],
    [0.88, 0.85, 0.76],
];
/// The stems' pale cream.
const STEM_COLOUR: [f32; 3] = [0.86, 0.82, 0.7];
/// Mushrooms stand within this distance of the z axis (so every camera sees them whole).
const FIELD_RADIUS: f32 = 0.7;

/// A field of 15 to 25 mushrooms of varied size, lean and cap colour on mossy ground.
///
/// ```
/// use rgbd_dataset::scenes::{Mushrooms, Scene};
/// use glam::Vec3;
/// let scene = Mushrooms::new(1);
/// // Air high above the field, moss and soil deep below it.
/// assert_eq!(scene.eval(Vec3::new(0.0, 0.0, 0.9)).0, 0.0);
/// assert!(scene.eval(Vec3::new(0.0, 0.0, -0.9)).0 > 0.0);
/// ```
#[derive(Debug, Clone)]
pub struct Mushrooms {
    mushrooms: Vec<Mushroom>,
}

/// One mushroom: a tapered stem that bends with `lean`, under a domed cap.
#[derive(Debug, Clone, Copy)]
struct Mushroom {
    base: Vec3,
    stem_height: f32,
    stem_radius: f32,
    cap_radius: f32,
    cap_thickness: f32,
    lean: Vec2,
    cap_colour: [f32; 3],
    spotted: bool,
}

impl Mushrooms {
    /// Scatters 15 to 25 non-overlapping mushrooms with seeded size, lean and colour.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let count = rng.random_range(15..=25);
        let mut mushrooms: Vec<Mushroom> = Vec::with_capacity(count);
        // Rejection sampling of positions; a crowded draw simply ends with fewer mushrooms.
        for _ in 0..count * 40 {
            if mushrooms.len() == count {
                break;
            }
            let candidate = Mushroom::random(&mut rng);
            let clear = mushrooms.iter().all(|m| {
                let gap = (m.base.xy() - candidate.base.xy()).length();
                gap > 0.8 * (m.cap_radius + candidate.cap_radius) + 0.02
            });
            if clear {
                mushrooms.push(candidate);
            }
        }
        Self { mushrooms }
    }

    /// How many mushrooms stand in the field.
    #[must_use]
    pub fn mushroom_count(&self) -> usize {
        self.mushrooms.len()
    }

    /// The ground height: gentle hummocks of moss.
    fn ground_height(p: Vec2) -> f32 {
        -0.55 + 0.03 * (4.0 * p.x + 1.0).sin() * (3.0 * p.y).cos() - 0.05 * p.length_squared()
    }

    /// Signed distance to the scene (negative inside) and the colour of the nearest surface.
    fn surface(&self, p: Vec3) -> (f32, [f32; 3]) {
        let ground = p.z - Self::ground_height(p.xy());
        match nearest(&self.mushrooms, p, Mushroom::footprint, Mushroom::distance) {
            Some((d, mushroom)) if d < ground => (d, mushroom.albedo(p)),
            _ => {
                let patches = 0.5 + 0.5 * grain(p, Vec3::new(13.0, 11.0, 0.0));
                let fuzz = 0.5 + 0.5 * grain(p, Vec3::new(57.0, 61.0, 0.0));
                (
                    ground,
                    [
                        0.16 + 0.08 * patches,
                        0.34 + 0.14 * patches + 0.06 * fuzz,
                        0.08 + 0.04 * fuzz,
                    ],
                )
            }
        }
    }
}

impl Mushroom {
    fn random(rng: &mut impl Rng) -> Self {
        let at = Vec2::from_angle(rng.random_range(0.0..std::f32::consts::TAU))
            * FIELD_RADIUS
            * rng.random::<f32>().sqrt();
        let stem_height = rng.random_range(0.07..0.32);
        let cap_radius = rng.random_range(0.05..0.13) * (0.6 + stem_height * 2.0);
        let colour = CAP_COLOURS[rng.random_range(0..CAP_COLOURS.len())];
        let tint = rng.random_range(0.85..1.1);
        Self {
            base: at.extend(Mushrooms::ground_height(at)),
            stem_height,
            stem_radius: cap_radius * rng.random_range(0.18..0.3),
            cap_radius,
            cap_thickness: cap_radius * rng.random_range(0.35..0.7),
            lean: Vec2::new(rng.random_range(-0.4..0.4), rng.random_range(-0.4..0.4)) * stem_height,
            cap_colour: colour.map(|c| (c * tint).min(1.0)),
            spotted: colour == CAP_COLOURS[0],
        }
    }

    fn footprint(&self) -> Footprint {
        Footprint {
            centre: self.base.xy() + self.lean,
            radius: self.cap_radius + self.lean.length(),
            top: self.base.z + self.stem_height + self.cap_thickness,
        }
    }

    /// `p` in the mushroom's frame: origin at the foot, and the stem's bend taken out, so the
    /// stem is straight up the z axis and the cap is centred on it.
    fn local(&self, p: Vec3) -> Vec3 {
        let q = p - self.base;
        let t = (q.z / self.stem_height).clamp(0.0, 1.0);
        q - (self.lean * t * t).extend(0.0)
    }

    fn stem_distance(&self, q: Vec3) -> f32 {
        let taper = 1.15 - 0.3 * (q.z / self.stem_height).clamp(0.0, 1.0);
        // The stem starts below the ground so no gap shows on a slope.
        vertical_cylinder(q, self.stem_radius * taper, -0.05, self.stem_height)
    }

    fn cap_distance(&self, q: Vec3) -> f32 {
        let centre = Vec3::Z * self.stem_height;
        let dome = ellipsoid(
            q - centre,
            Vec3::new(self.cap_radius, self.cap_radius, self.cap_thickness),
        );
        // Cut the dome's lower part off, leaving a flattish underside.
        let underside = self.stem_height - 0.25 * self.cap_thickness - q.z;
        dome.max(underside)
    }

    fn distance(&self, p: Vec3) -> f32 {
        let q = self.local(p);
        smooth_min(self.stem_distance(q), self.cap_distance(q), 0.015)
    }

    fn albedo(&self, p: Vec3) -> [f32; 3] {
        let q = self.local(p);
        if self.stem_distance(q) < self.cap_distance(q) {
            return STEM_COLOUR;
        }
        let spot = grain(q, Vec3::new(45.0, 45.0, 0.0)) > 0.75;
        if self.spotted && spot {
            [0.95, 0.93, 0.88]
        } else {
            let speckle = 1.0 + 0.06 * grain(p, Vec3::new(31.0, 29.0, 37.0));
            self.cap_colour.map(|c| (c * speckle).min(1.0))
        }
    }
}

impl Scene for Mushrooms {
    fn eval(&self, p: Vec3) -> Sample {
        solid(p, |q| self.surface(q))
    }
}
