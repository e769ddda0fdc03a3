//! From a surface (signed distance plus albedo) to density and baked colour: a soft density shell
//! around the zero set, and Lambert light from a fixed sun plus sky light, using the distance
//! field's gradient as the normal. Every scene shares these, so all look lit the same way.

use glam::Vec3;

use super::sdf::smoothstep;

/// Peak density of solid matter, in 1/world-length: opaque over a few hundredths of the box.
pub(super) const SOLID_SIGMA: f32 = 60.0;
/// Half width of the soft shell over which density rises from 0 to [`SOLID_SIGMA`].
pub(super) const SHELL: f32 = 0.03;
/// Central-difference step of the normal estimate.
const GRADIENT_STEP: f32 = 0.01;
/// The farthest a surface can be from a point and still change its density or shading.
pub(super) const REACH: f32 = SHELL + GRADIENT_STEP;
/// The direction light comes from (normalised on use).
const SUN: Vec3 = Vec3::new(0.45, -0.35, 0.82);

/// Density and colour at a point: what [`Scene::eval`](super::Scene::eval) returns.
pub(super) type Sample = (f32, [f32; 3]);

/// The density and lit colour of a solid bounded by `surface` (signed distance, negative inside,
/// and the albedo of the nearest surface) at `p`; empty beyond the shell.
pub(super) fn solid(p: Vec3, surface: impl Fn(Vec3) -> (f32, [f32; 3])) -> Sample {
    let (d, albedo) = surface(p);
    if d > SHELL {
        return (0.0, [0.0; 3]);
    }
    let sigma = SOLID_SIGMA * smoothstep(SHELL, -SHELL, d);
    let e = GRADIENT_STEP;
    let difference = |axis: Vec3| surface(p + axis * e).0 - surface(p - axis * e).0;
    let normal = Vec3::new(
        difference(Vec3::X),
        difference(Vec3::Y),
        difference(Vec3::Z),
    );
    (sigma, lit(albedo, normal.normalize_or(Vec3::Z)))
}

/// `albedo` lit by the sun (Lambert) and a uniform sky, for a surface facing `normal`.
pub(super) fn lit(albedo: [f32; 3], normal: Vec3) -> [f32; 3] {
    let light = 0.35 + 0.65 * normal.dot(SUN.normalize()).max(0.0);
    albedo.map(|a| (a * light).clamp(0.0, 1.0))
}

/// Two media sharing a point: densities add and the colour is their density-weighted mean
/// (what the renderer would see from two thin interleaved layers).
pub(super) fn mix((sa, ca): Sample, (sb, cb): Sample) -> Sample {
    let sigma = sa + sb;
    if sigma <= 0.0 {
        return (0.0, [0.0; 3]);
    }
    (
        sigma,
        std::array::from_fn(|i| (sa * ca[i] + sb * cb[i]) / sigma),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_is_solid_below_empty_above_and_lit_from_above() {
        let plane = |p: Vec3| (p.z, [0.5, 0.5, 0.5]);
        assert_eq!(solid(Vec3::Z * 0.1, plane), (0.0, [0.0; 3]));
        let (sigma, rgb) = solid(Vec3::Z * -0.1, plane);
        assert_eq!(sigma, SOLID_SIGMA);
        let expected = 0.5 * (0.35 + 0.65 * SUN.normalize().z);
        assert!(rgb.iter().all(|&c| (c - expected).abs() < 1e-5), "{rgb:?}");
        // Facing away from the sun: sky light only.
        assert!((lit([1.0; 3], -SUN)[0] - 0.35).abs() < 1e-6);
    }

    #[test]
    fn mixing_weighs_colour_by_density() {
        let (sigma, rgb) = mix((3.0, [1.0, 0.0, 0.0]), (1.0, [0.0, 0.0, 1.0]));
        assert_eq!((sigma, rgb), (4.0, [0.75, 0.0, 0.25]));
        assert_eq!(mix((0.0, [1.0; 3]), (0.0, [1.0; 3])), (0.0, [0.0; 3]));
    }
}
