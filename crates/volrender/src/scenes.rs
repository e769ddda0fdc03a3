//! The benchmark scenes and camera of the PyTorch peer (`shared/peer/scenes.py`), in volgen's
//! conventions, so benches and the throughput example measure the same workload.
//!
//! - `dense`: smooth random plane waves, sigma = 3 sigmoid(2 f0 - 1) in (0, 3), rgb = sigmoid(2 f_c).
//!   The waves are drawn from ChaCha, so the field is statistically, not bitwise, the peer's.
//! - `sparse`: five solid spheres of density 20 (about 5% of the box), colour of the nearest
//!   sphere everywhere (so interpolation near a surface does not darken it); identical geometry.
//!
//! Both are evaluated at volgen's cell centres over `[-1, 1]^3`. The peer puts its voxels on the
//! corners (`align_corners=True`); [`peer_grid_aabb`] gives the box that puts volgen's cell
//! centres on the peer's lattice, for rendering a volume the peer saved.

use glam::Vec3;
use radiance_volume::{Aabb, GridDims, RadianceVolume};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{invalid, Result};
use crate::rays::Rays;

/// Sphere centres, radii and colours of the sparse scene (the peer's `SPARSE_BLOBS`).
const BLOBS: [([f32; 3], f32, [f32; 3]); 5] = [
    ([-0.45, -0.30, 0.20], 0.31, [0.9, 0.2, 0.2]),
    ([0.40, 0.35, -0.25], 0.29, [0.2, 0.8, 0.3]),
    ([0.10, -0.45, -0.50], 0.24, [0.2, 0.3, 0.9]),
    ([-0.20, 0.50, 0.45], 0.26, [0.9, 0.8, 0.2]),
    ([0.55, -0.20, 0.55], 0.22, [0.8, 0.3, 0.8]),
];
/// Density inside the sparse scene's spheres.
pub const SPARSE_SIGMA: f32 = 20.0;

/// Which scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scene {
    /// Smooth random density everywhere.
    Dense,
    /// Five solid spheres, about 5% of the voxels.
    Sparse,
}

impl std::str::FromStr for Scene {
    type Err = crate::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "dense" => Ok(Self::Dense),
            "sparse" => Ok(Self::Sparse),
            other => Err(invalid(
                "scene",
                format!("expected `dense` or `sparse`, got `{other}`"),
            )),
        }
    }
}

/// Builds scene `scene` on an `n^3` grid over `[-1, 1]^3` (`seed` draws the dense scene's waves).
///
/// ```
/// use volrender::scenes::{make_scene, Scene};
/// let v = make_scene(Scene::Sparse, 32, 0)?;
/// let occupied = v.density()?.gt(0.0)?.to_dtype(candle_core::DType::F32)?.mean_all()?.to_scalar::<f32>()?;
/// assert!((0.03..0.08).contains(&occupied));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn make_scene(scene: Scene, n: usize, seed: u64) -> Result<RadianceVolume> {
    let dims = GridDims::cube(n);
    let volume = match scene {
        Scene::Sparse => RadianceVolume::from_fn(dims, Aabb::CUBE, 4, |p, out| {
            let sd = BLOBS.map(|(c, r, _)| (p - Vec3::from_array(c)).length() - r);
            let nearest =
                (0..BLOBS.len()).fold(0, |best, i| if sd[i] < sd[best] { i } else { best });
            out[0] = if sd[nearest] <= 0.0 {
                SPARSE_SIGMA
            } else {
                0.0
            };
            out[1..4].copy_from_slice(&BLOBS[nearest].2);
        })?,
        Scene::Dense => {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let fields: Vec<Vec<(Vec3, f32)>> = (0..4).map(|_| plane_waves(&mut rng)).collect();
            let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
            RadianceVolume::from_fn(dims, Aabb::CUBE, 4, |p, out| {
                let f: Vec<f32> = fields.iter().map(|waves| smooth_field(waves, p)).collect();
                out[0] = 3.0 * sigmoid(2.0 * f[0] - 1.0);
                for c in 0..3 {
                    out[1 + c] = sigmoid(2.0 * f[1 + c]);
                }
            })?
        }
    };
    Ok(volume)
}

/// Draws 12 plane waves (wave vector with |k| in [1.5, 6], phase), as the peer does.
fn plane_waves(rng: &mut ChaCha8Rng) -> Vec<(Vec3, f32)> {
    (0..12)
        .map(|_| {
            let z: f32 = rng.random_range(-1.0..1.0);
            let phi = rng.random::<f32>() * std::f32::consts::TAU;
            let r = (1.0 - z * z).sqrt();
            let k = Vec3::new(r * phi.cos(), r * phi.sin(), z) * rng.random_range(1.5..6.0);
            (k, rng.random::<f32>() * std::f32::consts::TAU)
        })
        .collect()
}

/// A sum of plane waves of about unit variance.
fn smooth_field(waves: &[(Vec3, f32)], p: Vec3) -> f32 {
    let sum: f32 = waves
        .iter()
        .map(|&(k, phase)| (k.dot(p) + phase).sin())
        .sum();
    sum * (2.0 / waves.len() as f32).sqrt()
}

/// Returns the peer's rays: a pinhole at distance 3.5 looking at the origin from azimuth 30 and
/// elevation 20 degrees with world up +y, FOV 33.4 degrees, a square image of `n_rays` pixels
/// (a perfect square), row-major, unit directions.
pub fn peer_rays(n_rays: usize) -> Result<Rays> {
    let s = (n_rays as f64).sqrt().round() as usize;
    if s * s != n_rays || s == 0 {
        return Err(invalid(
            "rays",
            format!("expected a perfect square number of rays, got {n_rays}"),
        ));
    }
    let (az, el) = (30f64.to_radians(), 20f64.to_radians());
    let pos = [el.cos() * az.sin(), el.sin(), el.cos() * az.cos()].map(|x| 3.5 * x);
    let f = pos.map(|x| -x / 3.5);
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let norm = |a: [f64; 3]| {
        let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        a.map(|x| x / l)
    };
    let r = norm(cross(f, [0.0, 1.0, 0.0]));
    let up = cross(r, f);
    let tan = (33.4f64.to_radians() / 2.0).tan();
    let mut dirs = Vec::with_capacity(n_rays);
    for row in 0..s {
        let v = -((row as f64 + 0.5) / s as f64 * 2.0 - 1.0) * tan;
        for col in 0..s {
            let u = ((col as f64 + 0.5) / s as f64 * 2.0 - 1.0) * tan;
            let d = norm([0, 1, 2].map(|k| f[k] + u * r[k] + v * up[k]));
            dirs.push(d.map(|x| x as f32));
        }
    }
    Rays::new(vec![pos.map(|x| x as f32); n_rays], dirs)
}

/// Returns the box over which an `n`-cell cell-centred grid has its centres at the peer's
/// lattice `-1 + 2 i / (n - 1)`: `[-1 - h, 1 + h]^3` with `h = 1 / (n - 1)` (for `n >= 2`).
pub fn peer_grid_aabb(n: usize) -> Result<Aabb> {
    if n < 2 {
        return Err(invalid(
            "grid",
            format!("the peer's lattice needs n >= 2, got {n}"),
        ));
    }
    let h = 1.0 / (n - 1) as f32;
    Ok(Aabb::try_new(Vec3::splat(-1.0 - h), Vec3::splat(1.0 + h))?)
}
