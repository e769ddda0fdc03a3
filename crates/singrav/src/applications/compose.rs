//! The paper's composition: objects of several generated scenes put into one base scene, which
//! [`crate::SinGrav::harmonize`] then blends as it blends an edit. A [`Placement`] copies a box
//! of another scene's finest raw volume to a place in the base; [`ground`] gives a base that
//! holds a scene's ground alone, its objects cleared.

use std::fmt;

use candle_core::Tensor;
use glam::Vec3;
use radiance_volume::{Aabb, Activation};

use super::edit::{box_mask, check_placement, raw_volume, voxel_shift};
use crate::error::{invalid, Result};

/// One object of a composition: the content of `region` (world coordinates inside the volume
/// box `[-1, 1]^3`, Z-up) of a source scene, put `offset` away (world units, rounded to whole
/// voxels; 0 keeps it where it stood) over what the base holds there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The box taken from the source scene.
    pub region: Aabb,
    /// Where it goes in the composed scene, relative to the box.
    pub offset: Vec3,
}

impl fmt::Display for Placement {
    /// The placement as `volgen compose` names it: `x0,y0,z0,x1,y1,z1 at dx,dy,dz`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (r, o) = (self.region, self.offset);
        write!(
            f,
            "{},{},{},{},{},{} at {},{},{}",
            r.min.x, r.min.y, r.min.z, r.max.x, r.max.y, r.max.z, o.x, o.y, o.z
        )
    }
}

impl Placement {
    /// Errors, naming the placement, unless its box and the box moved by the offset lie inside
    /// the volume box. [`Placement::apply`] checks this too; calling it first lets a caller
    /// refuse a bad composition before generating anything.
    ///
    /// ```
    /// use glam::Vec3;
    /// use radiance_volume::Aabb;
    /// use singrav::applications::Placement;
    /// let region = Aabb::try_new(Vec3::splat(0.0), Vec3::splat(0.5))?;
    /// assert!(Placement { region, offset: Vec3::ZERO }.validate().is_ok());
    /// let far = Placement { region, offset: Vec3::new(0.0, 0.7, 0.0) };
    /// assert!(far.validate().unwrap_err().to_string().contains("destination"));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn validate(&self) -> Result<()> {
        check_placement(self.region, Some(self.offset), Aabb::CUBE)
            .map_err(|why| invalid(format!("placement `{self}`"), why))
    }

    /// `base` with the placement's box of `source` put in: both raw volumes `(1, 4, s, s, s)` of
    /// the same model's finest 3D scale. Voxels outside the destination keep the base's exact
    /// values; inside it they are the source's exactly.
    ///
    /// ```
    /// use candle_core::{DType, Device, Tensor};
    /// use glam::Vec3;
    /// use radiance_volume::Aabb;
    /// use singrav::applications::Placement;
    /// let base = Tensor::zeros((1, 4, 8, 8, 8), DType::F32, &Device::Cpu)?;
    /// let source = Tensor::ones((1, 4, 8, 8, 8), DType::F32, &Device::Cpu)?;
    /// // The source's corner octant, put into the opposite corner.
    /// let region = Aabb::try_new(Vec3::splat(-1.0), Vec3::splat(0.0))?;
    /// let composed = Placement { region, offset: Vec3::splat(1.0) }.apply(&base, &source)?;
    /// let values: Vec<f32> = composed.flatten_all()?.to_vec1()?;
    /// assert_eq!((values[0], values[511]), (0.0, 1.0));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn apply(&self, base: &Tensor, source: &Tensor) -> Result<Tensor> {
        let fail = |why: String| invalid(format!("placement `{self}`"), why);
        let base = raw_volume(base, Aabb::CUBE).map_err(fail)?;
        let source = raw_volume(source, Aabb::CUBE).map_err(fail)?;
        self.validate()?;
        let mask = box_mask(&source, self.region).map_err(fail)?;
        let shift = voxel_shift(&source, self.offset);
        Ok(base
            .paste_masked(&source, &mask, shift)?
            .tensor()
            .unsqueeze(0)?)
    }
}

/// Edge of the window, as a share of the volume's edge, over which [`ground`] takes the
/// ground's height: objects narrower than this are cleared, ground that rises over a wider
/// span is kept. A quarter of the box holds a standing stone or a mushroom of the built-in
/// scenes several times over, and the stones' mound many times less.
pub const GROUND_WINDOW: f32 = 0.25;

/// Opacity across one voxel above which a voxel counts as the surface [`ground`] looks for.
const SURFACE_OPACITY: f32 = 0.5;

/// A scene's ground alone: its raw volume `(1, 4, s, s, s)` with every voxel standing above the
/// ground filled with `empty` (the raw "air" voxel, see [`super::empty_voxel`]).
///
/// The ground's height is found as a terrain map's ground is found under its buildings (a
/// morphological opening of the surface heights): per column, the height of the highest voxel
/// whose opacity across the voxel reaches 1/2; then the lowest of these heights within a
/// square window of [`GROUND_WINDOW`] of the box (which lowers every object narrower than the
/// window to the ground around it), then the highest of those within the window again (which
/// gives wide rises back their height). Every voxel above that height is emptied. Columns with
/// no surface have no ground there.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::Activation;
/// // An 8^3 scene: a solid floor two voxels deep, one column of stone on it.
/// let n = 8;
/// let mut raw = vec![-20f32; 4 * n * n * n];
/// for z in 0..n {
///     for y in 0..n {
///         for x in 0..n {
///             if z < 2 || (x, y) == (4, 4) {
///                 raw[(z * n + y) * n + x] = 20.0;
///             }
///         }
///     }
/// }
/// let raw = Tensor::from_vec(raw, (1, 4, n, n, n), &Device::Cpu)?;
/// let activation = Activation::default().with_density_scale(25.0).with_density_shift(-4.0);
/// let cleared = singrav::applications::ground(&raw, &activation, 2.0 / n as f32, &[-20.0, 0.0, 0.0, 0.0])?;
/// let density: Vec<f32> = cleared.flatten_all()?.to_vec1()?;
/// let at = |z: usize, y: usize, x: usize| density[(z * n + y) * n + x];
/// assert_eq!((at(1, 4, 4), at(2, 4, 4), at(7, 4, 4)), (20.0, -20.0, -20.0)); // the floor kept
/// assert_eq!(at(1, 0, 0), 20.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn ground(
    raw: &Tensor,
    activation: &Activation,
    voxel: f32,
    empty: &[f32; 4],
) -> Result<Tensor> {
    let volume = raw_volume(raw, Aabb::CUBE).map_err(|why| invalid("raw", why))?;
    if !(voxel.is_finite() && voxel > 0.0) {
        return Err(invalid(
            "voxel",
            format!("expected a length > 0, got {voxel}"),
        ));
    }
    let [w, h, d] = volume.dims().xyz();
    let sigma: Vec<f32> = activation
        .apply_density(&raw.narrow(1, 0, 1)?)?
        .flatten_all()?
        .to_vec1()?;
    // Per column, one past the highest surface voxel (0: no surface).
    let opaque = -(1.0 - SURFACE_OPACITY).ln() / voxel;
    let surface: Vec<usize> = (0..h * w)
        .map(|column| {
            (0..d)
                .rev()
                .find(|&z| sigma[z * h * w + column] >= opaque)
                .map_or(0, |z| z + 1)
        })
        .collect();
    let radius = ((GROUND_WINDOW * w.max(h) as f32) / 2.0).floor() as usize;
    let lowest = window_extreme(&surface, h, w, radius, Iterator::min);
    let height = window_extreme(&lowest, h, w, radius, Iterator::max);
    let mask: Vec<f32> = (0..d * h * w)
        .map(|i| {
            let (z, column) = (i / (h * w), i % (h * w));
            // Kept: up to the ground's top voxel, height[column] - 1.
            f32::from(u8::from(z >= height[column]))
        })
        .collect();
    let mask = Tensor::from_vec(mask, (d, h, w), raw.device())?;
    Ok(volume.fill_masked(&mask, empty)?.tensor().unsqueeze(0)?)
}

/// Per cell of an `h x w` map, `pick` (min or max) of the values within `radius` cells along
/// both axes (the window clipped at the map's edges).
fn window_extreme(
    map: &[usize],
    h: usize,
    w: usize,
    radius: usize,
    pick: fn(std::vec::IntoIter<usize>) -> Option<usize>,
) -> Vec<usize> {
    (0..h * w)
        .map(|cell| {
            let (y, x) = (cell / w, cell % w);
            let ys = y.saturating_sub(radius)..(y + radius + 1).min(h);
            let values: Vec<usize> = ys
                .flat_map(|y| {
                    let xs = x.saturating_sub(radius)..(x + radius + 1).min(w);
                    xs.map(move |x| map[y * w + x])
                })
                .collect();
            pick(values.into_iter()).unwrap_or(0)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};
    use glam::Vec3;
    use radiance_volume::{Aabb, Activation};

    use super::{ground, Placement};

    const SOLID: f32 = 20.0;
    const AIR: f32 = -20.0;

    fn activation() -> Activation {
        Activation::default()
            .with_density_scale(25.0)
            .with_density_shift(-4.0)
    }

    /// A raw `(1, 4, n, n, n)` volume, solid where `solid(x, y, z)` says, colour `rgb` there.
    fn scene(n: usize, rgb: f32, solid: impl Fn(usize, usize, usize) -> bool) -> Tensor {
        let cells = n * n * n;
        let mut v = vec![0f32; 4 * cells];
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let i = (z * n + y) * n + x;
                    v[i] = if solid(x, y, z) { SOLID } else { AIR };
                    (1..4).for_each(|c| v[c * cells + i] = rgb);
                }
            }
        }
        Tensor::from_vec(v, (1, 4, n, n, n), &Device::Cpu).unwrap()
    }

    fn density(raw: &Tensor, n: usize) -> Vec<f32> {
        raw.narrow(1, 0, 1)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap()[..n * n * n]
            .to_vec()
    }

    #[test]
    fn ground_clears_narrow_objects_and_keeps_wide_rises() {
        // 16^3: a floor 3 voxels deep, a wide mound (8 x 8 cells, 2 more voxels) and two
        // stones (2 x 2 cells, 6 voxels tall), one on the floor, one on the mound.
        let n = 16;
        let mound = |x: usize, y: usize| (4..12).contains(&x) && (4..12).contains(&y);
        let stone = |x: usize, y: usize| {
            ((1..3).contains(&x) && (1..3).contains(&y))
                || ((7..9).contains(&x) && (7..9).contains(&y))
        };
        let raw = scene(n, 0.5, |x, y, z| {
            z < 3 || (mound(x, y) && z < 5) || (stone(x, y) && z < 11)
        });
        let cleared = ground(&raw, &activation(), 2.0 / n as f32, &[AIR, 0.0, 0.0, 0.0]).unwrap();
        let (before, after) = (density(&raw, n), density(&cleared, n));
        let at = |v: &[f32], x: usize, y: usize, z: usize| v[(z * n + y) * n + x];
        // The floor and the mound stay; the stones above them go.
        assert_eq!(at(&after, 0, 0, 2), SOLID);
        assert_eq!(at(&after, 5, 5, 4), SOLID);
        assert_eq!(at(&after, 1, 1, 2), SOLID);
        assert_eq!(at(&after, 1, 1, 3), AIR);
        assert_eq!(at(&after, 7, 7, 4), SOLID);
        assert_eq!(at(&after, 7, 7, 5), AIR);
        assert_eq!(at(&after, 8, 8, 10), AIR);
        // Nothing but air above the ground was there before: only stone voxels changed.
        let changed = before.iter().zip(&after).filter(|(a, b)| a != b).count();
        assert_eq!(changed, 4 * (11 - 3) + 4 * (11 - 5));
    }

    #[test]
    fn a_placement_puts_the_sources_box_at_its_place() {
        let n = 8;
        let base = scene(n, 0.2, |_, _, z| z < 2);
        let source = scene(n, 0.9, |x, y, z| x < 2 && y < 2 && z < 5);
        // The source's pillar (cells x, y < 2, i.e. world x, y < -0.5) moved to x, y in 4..6.
        let region =
            Aabb::try_new(Vec3::new(-1.0, -1.0, -1.0), Vec3::new(-0.5, -0.5, 0.5)).unwrap();
        let placement = Placement {
            region,
            offset: Vec3::new(1.0, 1.0, 0.0),
        };
        let composed = placement.apply(&base, &source).unwrap();
        let (b, s, c) = (
            density(&base, n),
            density(&source, n),
            density(&composed, n),
        );
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let i = (z * n + y) * n + x;
                    let inside = (4..6).contains(&x) && (4..6).contains(&y) && z < 6;
                    let want = if inside {
                        s[(z * n + y - 4) * n + x - 4]
                    } else {
                        b[i]
                    };
                    assert_eq!(c[i], want, "({x}, {y}, {z})");
                }
            }
        }
        // The colour came along.
        let colour: Vec<f32> = composed.flatten_all().unwrap().to_vec1().unwrap();
        assert_eq!(colour[n * n * n + (4 * n + 4) * n + 4], 0.9);
    }

    #[test]
    fn bad_placements_and_volumes_are_refused_by_name() {
        let n = 8;
        let base = scene(n, 0.2, |_, _, z| z < 2);
        let region = Aabb::try_new(Vec3::splat(0.0), Vec3::splat(0.5)).unwrap();
        let outside = Placement {
            region,
            offset: Vec3::new(0.0, 0.0, 0.8),
        };
        let err = outside.apply(&base, &base).unwrap_err().to_string();
        assert!(
            err.contains("placement `0,0,0,0.5,0.5,0.5 at 0,0,0.8`"),
            "{err}"
        );
        assert!(err.contains("destination"), "{err}");
        let tiny = Aabb::try_new(Vec3::splat(0.01), Vec3::splat(0.02)).unwrap();
        let err = Placement {
            region: tiny,
            offset: Vec3::ZERO,
        }
        .apply(&base, &base)
        .unwrap_err()
        .to_string();
        assert!(err.contains("no voxel centre"), "{err}");
        let other = scene(4, 0.2, |_, _, _| true);
        let fine = Placement {
            region,
            offset: Vec3::ZERO,
        };
        assert!(fine.apply(&base, &other).is_err());
        let flat = base.squeeze(0).unwrap();
        assert!(fine.apply(&flat, &base).is_err());
        assert!(ground(&flat, &activation(), 0.25, &[AIR, 0.0, 0.0, 0.0]).is_err());
        assert!(ground(&base, &activation(), 0.0, &[AIR, 0.0, 0.0, 0.0]).is_err());
    }
}
