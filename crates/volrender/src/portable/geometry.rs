//! Where a chunk of rays samples the grid: each ray's setup from the kernel's own code on the
//! host (9 numbers per ray), then sample positions, the 8 trilinear taps and their weights on
//! the device, with the kernel's operations in the kernel's order (`kernel::march`,
//! `kernel::trilinear`), so both paths sample the same points and blend the same voxels.

use candle_core::{DType, Device, Tensor, WithDType};

use crate::config::Sampler;
use crate::error::Result;
use crate::kernel::{setup_ray, GridSpec, Real};

/// The per-ray columns uploaded to the device: `a`, `b`, `t0`, `dt`, `live`.
const COLUMNS: usize = 9;

/// The offsets `i + off` of a ray's `samples` samples along its step (`off` is the sampler's:
/// 0.5 for midpoints), `(1, M)`, as the kernel computes them in `T`.
pub(super) fn sample_steps<T: Real + WithDType>(
    samples: usize,
    sampler: Sampler,
    device: &Device,
) -> Result<Tensor> {
    let off = T::of(sampler.offset());
    let steps: Vec<T> = (0..samples).map(|i| T::of_index(i as u32) + off).collect();
    Ok(Tensor::from_vec(steps, (1, samples), device)?)
}

/// A chunk of rays on the device: `(R, 1)` columns of index-space origins `a` and steps `b` per
/// axis (sample `t` is at `a + t b`), entry `t0` and step `dt` (0 for rays that miss, which
/// then add nothing), and `live` (1 for rays with samples, 0 otherwise).
pub(super) struct RayBundle {
    a: [Tensor; 3],
    b: [Tensor; 3],
    t0: Tensor,
    dt: Tensor,
    live: Tensor,
}

/// The taps of every sample of a chunk: `t` `(R, M)`, flat voxel indices `(R M 8)` (u32) and
/// weights `(R M 8)` (0 for samples outside the box), and `inside` `(R, M)`.
pub(super) struct Taps {
    pub(super) t: Tensor,
    pub(super) index: Tensor,
    pub(super) weight: Tensor,
    pub(super) inside: Tensor,
}

impl RayBundle {
    /// Sets up every ray of `origins`/`dirs` with the kernel's `setup_ray` and uploads them.
    pub(super) fn new<T: Real + WithDType>(
        origins: &[[f32; 3]],
        dirs: &[[f32; 3]],
        grid: &GridSpec<T>,
        sampler: Sampler,
        device: &Device,
    ) -> Result<Self> {
        let mut rows = Vec::with_capacity(origins.len() * COLUMNS);
        for (&o, &d) in origins.iter().zip(dirs) {
            let g = setup_ray(o, d, grid, sampler);
            // A ray without samples may have an infinite entry: keep its numbers finite.
            let (t0, dt) = if g.n > 0 {
                (g.t0, g.dt)
            } else {
                (T::zero(), T::zero())
            };
            let live = if g.n > 0 { T::one() } else { T::zero() };
            rows.extend([g.a[0], g.a[1], g.a[2], g.b[0], g.b[1], g.b[2], t0, dt, live]);
        }
        let r = origins.len();
        let table = Tensor::from_vec(rows, (r, COLUMNS), device)?;
        let column = |c: usize| table.narrow(1, c, 1);
        Ok(Self {
            a: [column(0)?, column(1)?, column(2)?],
            b: [column(3)?, column(4)?, column(5)?],
            t0: column(6)?,
            dt: column(7)?,
            live: column(8)?,
        })
    }

    /// The step length of each ray, `(R, 1)`.
    pub(super) fn dt(&self) -> &Tensor {
        &self.dt
    }

    /// The taps of every sample at `t = t0 + steps dt` on a grid of `n` cells along x, y, z.
    pub(super) fn taps(&self, steps: &Tensor, n: [usize; 3]) -> Result<Taps> {
        let t = steps.broadcast_mul(&self.dt)?.broadcast_add(&self.t0)?;
        let axes = [0, 1, 2].map(|k| Axis::new(&t, &self.a[k], &self.b[k], n[k]));
        let [x, y, z] = axes;
        let (x, y, z) = (x?, y?, z?);
        let inside = ((&x.inside * &y.inside)? * &z.inside)?
            .to_dtype(t.dtype())?
            .broadcast_mul(&self.live)?;
        // Corner order (z, y, x) with x fastest, weights as the kernel multiplies them.
        let (w00, w01) = (
            (&z.lower_weight * &y.lower_weight)?,
            (&z.lower_weight * &y.upper_weight)?,
        );
        let (w10, w11) = (
            (&z.upper_weight * &y.lower_weight)?,
            (&z.upper_weight * &y.upper_weight)?,
        );
        let row = |zi: &Tensor, yi: &Tensor| -> Result<Tensor> {
            Ok((zi.affine(n[1] as f64, 0.0)? + yi)?.affine(n[0] as f64, 0.0)?)
        };
        let (row00, row01) = (row(&z.lower, &y.lower)?, row(&z.lower, &y.upper)?);
        let (row10, row11) = (row(&z.upper, &y.lower)?, row(&z.upper, &y.upper)?);
        let mut index = Vec::with_capacity(8);
        let mut weight = Vec::with_capacity(8);
        for (row, w_zy) in [
            (&row00, &w00),
            (&row01, &w01),
            (&row10, &w10),
            (&row11, &w11),
        ] {
            index.push((row + &x.lower)?);
            index.push((row + &x.upper)?);
            weight.push(((w_zy * &x.lower_weight)? * &inside)?);
            weight.push(((w_zy * &x.upper_weight)? * &inside)?);
        }
        Ok(Taps {
            index: Tensor::stack(&index, 2)?.flatten_all()?,
            weight: Tensor::stack(&weight, 2)?.flatten_all()?,
            t,
            inside,
        })
    }
}

/// One axis of every sample: whether it is inside the box, its lower and upper neighbours
/// (u32) and their weights.
struct Axis {
    inside: Tensor,
    lower: Tensor,
    upper: Tensor,
    lower_weight: Tensor,
    upper_weight: Tensor,
}

impl Axis {
    /// The axis of `n` cells at index coordinate `u = a + t b`: inside is
    /// `-0.5 <= u <= n - 0.5`; the coordinate is clamped to `[0, n - 1]` (edge clamping), its
    /// floor is the lower neighbour and `min(floor + 1, n - 1)` the upper.
    fn new(t: &Tensor, a: &Tensor, b: &Tensor, n: usize) -> Result<Self> {
        let u = t.broadcast_mul(b)?.broadcast_add(a)?;
        let top = (n - 1) as f64;
        let inside = (u.ge(-0.5)? * u.le(n as f64 - 0.5)?)?;
        let clamped = u.clamp(0.0, top)?;
        let floor = clamped.floor()?;
        let upper_weight = (&clamped - &floor)?;
        let lower_weight = (1.0 - &upper_weight)?;
        let upper = (&floor + 1.0)?.minimum(top)?;
        Ok(Self {
            inside,
            lower: floor.to_dtype(DType::U32)?,
            upper: upper.to_dtype(DType::U32)?,
            lower_weight,
            upper_weight,
        })
    }
}
