//! Signed-distance building blocks shared by the scenes: primitive shapes, blends, a cheap
//! procedural grain, and culling of constituents that are too far from a point to matter.

use glam::{Vec2, Vec3, Vec3Swizzles};

use super::shade::REACH;

/// Signed distance to a box of half extents `b` with corners rounded by `r`.
pub(super) fn rounded_box(p: Vec3, b: Vec3, r: f32) -> f32 {
    let q = p.abs() - b + Vec3::splat(r);
    q.max(Vec3::ZERO).length() + q.max_element().min(0.0) - r
}

/// Approximate signed distance to an axis-aligned ellipsoid of radii `r` centred at the origin
/// (exact on the axes, a slight underestimate elsewhere; fine for a density shell).
pub(super) fn ellipsoid(p: Vec3, r: Vec3) -> f32 {
    let k0 = (p / r).length();
    if k0 == 0.0 {
        return -r.min_element();
    }
    let k1 = (p / (r * r)).length();
    k0 * (k0 - 1.0) / k1
}

/// Signed distance to a vertical cylinder of radius `r` from `z = z0` to `z = z1`.
pub(super) fn vertical_cylinder(p: Vec3, r: f32, z0: f32, z1: f32) -> f32 {
    let d = Vec2::new(p.xy().length() - r, (z0 - p.z).max(p.z - z1));
    d.max(Vec2::ZERO).length() + d.max_element().min(0.0)
}

/// Polynomial smooth minimum: blends two distances over a width `k`, so joints get fillets.
pub(super) fn smooth_min(a: f32, b: f32, k: f32) -> f32 {
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    b + (a - b) * h - k * h * (1.0 - h)
}

/// Hermite step from 0 at `e0` to 1 at `e1` (`e0 > e1` gives a falling step).
pub(super) fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Turns `p` by `-yaw` about the z axis: world coordinates into a constituent's own frame.
pub(super) fn unyaw(p: Vec3, yaw: f32) -> Vec3 {
    let (sin, cos) = yaw.sin_cos();
    Vec3::new(cos * p.x + sin * p.y, -sin * p.x + cos * p.y, p.z)
}

/// A smooth pseudo-random texture in [-1, 1] with spatial frequencies `freq`.
pub(super) fn grain(p: Vec3, freq: Vec3) -> f32 {
    (freq.x * p.x).sin() * (freq.y * p.y).sin() * (freq.z * p.z).cos()
}

/// Where a constituent can be: within `radius` of `centre` in the xy plane and below `top`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Footprint {
    pub(super) centre: Vec2,
    pub(super) radius: f32,
    pub(super) top: f32,
}

impl Footprint {
    /// Whether `p` may be within [`REACH`] of the constituent; when not, its distance exceeds
    /// `REACH` and it can change neither the density shell nor the shading gradient.
    fn may_reach(&self, p: Vec3) -> bool {
        let reach = self.radius + REACH;
        p.z < self.top + REACH && (p.xy() - self.centre).length_squared() < reach * reach
    }
}

/// The constituent nearest to `p` and its distance, looking only at those whose footprint may
/// reach `p` (so evaluating a scene costs a few constituents per point, not all of them).
pub(super) fn nearest<T>(
    items: &[T],
    p: Vec3,
    footprint: impl Fn(&T) -> Footprint,
    distance: impl Fn(&T, Vec3) -> f32,
) -> Option<(f32, &T)> {
    items
        .iter()
        .filter(|item| footprint(item).may_reach(p))
        .map(|item| (distance(item, p), item))
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_are_zero_on_their_surface() {
        let r = Vec3::new(0.3, 0.2, 0.1);
        for p in [Vec3::X * 0.3, Vec3::Y * 0.2, Vec3::Z * 0.1] {
            assert!(ellipsoid(p, r).abs() < 1e-6);
        }
        assert!(ellipsoid(Vec3::ZERO, r) < 0.0 && ellipsoid(Vec3::ONE, r) > 0.0);
        assert!((vertical_cylinder(Vec3::new(0.5, 0.0, 0.5), 0.5, 0.0, 1.0)).abs() < 1e-6);
        assert!((vertical_cylinder(Vec3::new(0.0, 0.0, 1.5), 0.5, 0.0, 1.0) - 0.5).abs() < 1e-6);
        assert!((rounded_box(Vec3::X, Vec3::ONE, 0.1)).abs() < 1e-6);
        assert!(smooth_min(0.3, 0.3, 0.1) < 0.3 && smooth_min(0.0, 1.0, 0.1) == 0.0);
    }

    #[test]
    fn culling_keeps_every_constituent_within_reach() {
        let spots = [Vec2::new(0.0, 0.0), Vec2::new(0.5, 0.0)];
        let footprint = |c: &Vec2| Footprint {
            centre: *c,
            radius: 0.1,
            top: 0.2,
        };
        let distance = |c: &Vec2, p: Vec3| (p - c.extend(0.0)).length() - 0.1;
        let p = Vec3::new(0.45, 0.0, 0.0);
        let (d, c) = nearest(&spots, p, footprint, distance).unwrap();
        assert_eq!(*c, spots[1]);
        assert!((d + 0.05).abs() < 1e-6);
        // Far from both (sideways and above): nothing can matter there.
        assert!(nearest(&spots, Vec3::new(0.25, 0.5, 0.0), footprint, distance).is_none());
        assert!(nearest(&spots, Vec3::new(0.0, 0.0, 0.5), footprint, distance).is_none());
    }
}
