//! Scenes of any size: a trained pyramid generating a scene that is a multiple of the learned
//! box along each axis (SinGAN's retargeting). The generators are fully convolutional, so only
//! the noise, the CSG grid and the sizes of the scales change; what the CSG anchors hold beyond
//! the learned box is [`csg_embed::Outside`].

use std::fmt;
use std::str::FromStr;

use candle_core::Tensor;
use csg_embed::Outside;
use glam::Vec3;
use radiance_volume::{Aabb, GridDims};

use crate::error::{invalid, Result};
use crate::model::SinGrav;

/// How many times the learned box a generated scene is along x, y and z.
///
/// ```
/// use singrav::extent::Extent;
/// let wide: Extent = "2,1,1".parse()?;
/// assert_eq!(wide.factors(), [2.0, 1.0, 1.0]);
/// assert!(Extent::ONE.is_one() && !wide.is_one());
/// assert!("0,1,1".parse::<Extent>().is_err());
/// # Ok::<(), String>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    factors: [f64; 3],
}

impl Extent {
    /// The learned box itself.
    pub const ONE: Self = Self { factors: [1.0; 3] };

    /// The smallest factor accepted: a quarter of the learned box.
    pub const MIN_FACTOR: f64 = 0.25;

    /// The largest factor accepted: memory grows with the product of the factors (a 16 x 16 x 1
    /// scene of a 40^3 model is 26 million voxels at the finest scale).
    pub const MAX_FACTOR: f64 = 16.0;

    /// An extent of `[x, y, z]` times the learned box; errors unless every factor lies in
    /// [`Extent::MIN_FACTOR`] ..= [`Extent::MAX_FACTOR`].
    pub fn new(factors: [f64; 3]) -> Result<Self> {
        if factors
            .iter()
            .all(|f| (Self::MIN_FACTOR..=Self::MAX_FACTOR).contains(f))
        {
            return Ok(Self { factors });
        }
        Err(invalid(
            "extent",
            format!(
                "expected factors between {} and {} of the learned box along x, y and z, got {factors:?}",
                Self::MIN_FACTOR,
                Self::MAX_FACTOR
            ),
        ))
    }

    /// The factors along x, y and z.
    pub fn factors(&self) -> [f64; 3] {
        self.factors
    }

    /// Whether this is the learned box.
    pub fn is_one(&self) -> bool {
        *self == Self::ONE
    }

    /// The grid of a scale whose learned grid is `size`^3: `size` times each factor, rounded to
    /// whole voxels (at least one), so voxels keep their learned size.
    pub fn dims(&self, size: usize) -> GridDims {
        let [x, y, z] = self
            .factors
            .map(|f| ((size as f64 * f).round() as usize).max(1));
        GridDims::new(z, y, x)
    }
}

impl fmt::Display for Extent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.factors;
        write!(f, "{x},{y},{z}")
    }
}

impl FromStr for Extent {
    type Err = String;

    /// Parses `X,Y,Z`.
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let expected = || format!("expected three comma-separated factors X,Y,Z, got \"{text}\"");
        let factors: Vec<f64> = text
            .split(',')
            .map(|part| part.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| expected())?;
        let factors: [f64; 3] = factors.try_into().map_err(|_| expected())?;
        Self::new(factors).map_err(|e| e.to_string())
    }
}

/// A pyramid's grids at an extent other than one: every 3D scale's dims and the coarsest
/// scale's CSG grid.
#[derive(Debug, Clone)]
pub(crate) struct Extended {
    pub(crate) extent: Extent,
    pub(crate) outside: Outside,
    /// Per 3D scale (index n - 1).
    pub(crate) dims: Vec<GridDims>,
    /// `(1, 3, D, H, W)` over the coarsest grid, when the model has the CSG grid.
    pub(crate) csg: Option<Tensor>,
}

/// The half sides of the box a `dims` grid of a `size`^3-learned scale covers, in the model's
/// units (the learned box is `[-1, 1]^3`), as `(x, y, z)`.
fn half_sides(dims: GridDims, size: usize) -> [f64; 3] {
    [dims.w, dims.h, dims.d].map(|n| n as f64 / size as f64)
}

impl SinGrav {
    /// Makes the pyramid generate scenes `extent` times the learned box (SinGAN's retargeting):
    /// every 3D scale's noise and volume at its size times the factors (rounded to whole
    /// voxels), the CSG grid over the larger box, anchored by `outside` beyond the learned one.
    /// [`Extent::ONE`] restores the learned size. Volumes, renderings and exports then cover
    /// [`SinGrav::model_box`]. The reconstruction V* keeps the learned size: with another
    /// extent [`SinGrav::reconstruct`] and varying from a scale above 1 are refused.
    ///
    /// ```
    /// use candle_core::Device;
    /// use rand::SeedableRng;
    /// use singrav::extent::Extent;
    /// let config = singrav::TrainConfig::preset("micro")?;
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    /// let mut model = singrav::SinGrav::new(&config, &Device::Cpu, &mut rng)?;
    /// model.push_generator(1.0, &mut rng)?;
    /// let size = config.pyramid.volume_sizes[0];
    /// model.set_extent("2,1,1".parse()?, csg_embed::Outside::Mirror)?;
    /// let raw = model.generate_random(&mut rng)?;
    /// assert_eq!(raw.dims(), &[1, 4, size, size, 2 * size]);
    /// assert_eq!(model.model_box().max.x, 2.0);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn set_extent(&mut self, extent: Extent, outside: Outside) -> Result<()> {
        if extent.is_one() {
            self.extended = None;
            return Ok(());
        }
        let sizes = &self.config().pyramid.volume_sizes;
        let dims: Vec<GridDims> = sizes.iter().map(|&s| extent.dims(s)).collect();
        let coarsest = dims[0];
        let csg = if self.config().ablations.use_csg {
            let grid = csg_embed::csg_grid_3d_over(
                (coarsest.d, coarsest.h, coarsest.w),
                half_sides(coarsest, sizes[0]),
                outside,
                self.device(),
            )?;
            Some(grid.unsqueeze(0)?)
        } else {
            None
        };
        self.extended = Some(Extended {
            extent,
            outside,
            dims,
            csg,
        });
        Ok(())
    }

    /// The extent scenes are generated at ([`SinGrav::set_extent`]; [`Extent::ONE`] unless set).
    pub fn extent(&self) -> Extent {
        self.extended.as_ref().map_or(Extent::ONE, |e| e.extent)
    }

    /// What the CSG anchors hold beyond the learned box, when the extent is not one.
    pub fn csg_outside(&self) -> Option<Outside> {
        self.extended.as_ref().map(|e| e.outside)
    }

    /// The grid of 3D scale `n` (1-based) at the current extent.
    pub fn scale_dims(&self, n: usize) -> GridDims {
        match &self.extended {
            Some(e) => e.dims[n - 1],
            None => GridDims::cube(self.config().pyramid.volume_sizes[n - 1]),
        }
    }

    /// The box the finest 3D scale's volume covers in the model's units: `[-1, 1]^3`, or at
    /// another extent the finest grid's whole voxels around the same centre.
    pub fn model_box(&self) -> Aabb {
        let Some(e) = &self.extended else {
            return Aabb::CUBE;
        };
        let sizes = &self.config().pyramid.volume_sizes;
        let last = sizes.len().min(e.dims.len()).max(1);
        let half = half_sides(e.dims[last - 1], sizes[last - 1]).map(|h| h as f32);
        Aabb {
            min: -Vec3::from(half),
            max: Vec3::from(half),
        }
    }

    /// Errors when the extent is not one: what V*, fixed at the learned size, refuses.
    pub(crate) fn check_learned_size(&self, what: &str) -> Result<()> {
        match &self.extended {
            None => Ok(()),
            Some(e) => Err(invalid(
                "extent",
                format!(
                    "{what} has the learned scene's size; it cannot be made at extent {}",
                    e.extent
                ),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use rand::SeedableRng;

    /// `micro` with its 3D scales built from seeded weights (untrained: the shapes and the
    /// bookkeeping are under test, not the scenes).
    fn built_micro() -> SinGrav {
        let config = crate::TrainConfig::preset("micro").unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut model = SinGrav::new(&config, &Device::Cpu, &mut rng).unwrap();
        for _ in 0..config.pyramid.volume_sizes.len() {
            model.push_generator(0.1, &mut rng).unwrap();
        }
        model
    }

    fn values(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1().unwrap()
    }

    #[test]
    fn every_scale_grows_and_the_learned_size_comes_back_unchanged() {
        let mut model = built_micro();
        let sizes = model.config().pyramid.volume_sizes.clone();
        let draw = |model: &SinGrav| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
            model.generate_random(&mut rng).unwrap()
        };
        let before = values(&draw(&model));
        let wide = Extent::new([2.0, 1.0, 1.5]).unwrap();
        for outside in [Outside::Mirror, Outside::Clamp, Outside::Extend] {
            model.set_extent(wide, outside).unwrap();
            let last = *sizes.last().unwrap();
            let dims = wide.dims(last);
            assert_eq!(draw(&model).dims(), &[1, 4, dims.d, dims.h, dims.w]);
            for (n, &s) in sizes.iter().enumerate() {
                assert_eq!(model.scale_dims(n + 1), wide.dims(s));
            }
            let half = Vec3::new(2.0, 1.0, dims.d as f32 / last as f32);
            assert_eq!(
                model.model_box(),
                Aabb {
                    min: -half,
                    max: half
                }
            );
            let physical = model.to_physical(&draw(&model)).unwrap();
            assert_eq!(physical.aabb(), model.model_box());
            // V*'s noise has the learned size: refused by name, before any work.
            for err in [
                model.reconstruct().unwrap_err(),
                model.check_vary_from(2).unwrap_err(),
            ] {
                assert!(err.to_string().contains("extent 2,1,1.5"), "{err}");
            }
            model.check_vary_from(1).unwrap();
            // Harmonisation re-runs the finer scales at the grown size.
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
            let harmonized = model.harmonize(&draw(&model), 2, &mut rng).unwrap();
            assert_eq!(harmonized.dims(), &[1, 4, dims.d, dims.h, dims.w]);
        }
        model.set_extent(Extent::ONE, Outside::Mirror).unwrap();
        assert_eq!(model.extent(), Extent::ONE);
        assert_eq!(model.model_box(), Aabb::CUBE);
        assert_eq!(values(&draw(&model)), before);
    }

    /// The coarsest scale's CSG grid over a box three times as wide, by the mirror rule: the
    /// learned grid in the middle third, its mirror images in the outer thirds.
    #[test]
    fn mirror_anchors_repeat_the_learned_grid_mirrored() {
        let mut model = built_micro();
        let size = model.config().pyramid.volume_sizes[0];
        model
            .set_extent(Extent::new([3.0, 1.0, 1.0]).unwrap(), Outside::Mirror)
            .unwrap();
        let dims = model.scale_dims(1);
        let csg = model.extended.as_ref().unwrap().csg.clone().unwrap();
        let x: Vec<f32> = values(
            &csg.narrow(1, 0, 1)
                .unwrap()
                .narrow(2, 0, 1)
                .unwrap()
                .narrow(3, 0, 1)
                .unwrap(),
        );
        assert_eq!(x.len(), dims.w);
        assert_eq!(dims.w, 3 * size);
        // The middle third is the learned grid; the outer thirds are its mirror images.
        let learned: Vec<f32> = (0..size)
            .map(|i| csg_embed::csg_coordinate(i, size) as f32)
            .collect();
        assert_eq!(&x[size..2 * size], learned.as_slice());
        let mirrored: Vec<f32> = learned.iter().rev().copied().collect();
        assert_eq!(&x[..size], mirrored.as_slice());
        assert_eq!(&x[2 * size..], mirrored.as_slice());
    }

    #[test]
    fn dims_round_to_whole_voxels() {
        let e = Extent::new([2.0, 1.5, 1.0]).unwrap();
        assert_eq!(e.dims(16), GridDims::new(16, 24, 32));
        assert_eq!(e.dims(21), GridDims::new(21, 32, 42)); // 31.5 rounds up
        assert_eq!(Extent::ONE.dims(28), GridDims::cube(28));
    }

    #[test]
    fn bad_extents_are_refused_by_name() {
        for text in [
            "2,1", "2,1,1,1", "a,1,1", "0.1,1,1", "17,1,1", "NaN,1,1", "inf,1,1",
        ] {
            let err = text.parse::<Extent>().unwrap_err();
            assert!(
                err.contains(text) || err.contains("between"),
                "{text}: {err}"
            );
        }
        assert_eq!(
            "1.5, 2 ,1".parse::<Extent>().unwrap().factors(),
            [1.5, 2.0, 1.0]
        );
    }
}
