//! Cropping, pasting, box masks and the paper's edit primitives (removal by filling a mask with
//! an "empty" value; duplicate and move by copying a masked region to another place).
//!
//! Masks are `(D, H, W)` f32 tensors of 0s and 1s (fractional values blend linearly).

use std::ops::Range;

use candle_core::{DType, Tensor};

use crate::error::{invalid, Result};
use crate::grid::{Aabb, GridDims};
use crate::volume::RadianceVolume;

/// A box of cells: half-open index ranges along z (D), y (H) and x (W).
///
/// ```
/// use radiance_volume::VoxelRange;
/// let r = VoxelRange::new(0..2, 1..3, 0..4);
/// assert_eq!(r.dims(), radiance_volume::GridDims::new(2, 2, 4));
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct VoxelRange {
    /// Cells along z.
    pub z: Range<usize>,
    /// Cells along y.
    pub y: Range<usize>,
    /// Cells along x.
    pub x: Range<usize>,
}

impl VoxelRange {
    /// Creates a range of cells.
    #[must_use]
    pub fn new(z: Range<usize>, y: Range<usize>, x: Range<usize>) -> Self {
        Self { z, y, x }
    }

    /// Returns the sizes of the range (0 for empty axes).
    #[must_use]
    pub fn dims(&self) -> GridDims {
        GridDims::new(self.z.len(), self.y.len(), self.x.len())
    }

    /// Returns an error unless the range is non-empty and lies inside a grid of `dims`.
    pub fn validate(&self, dims: GridDims) -> Result<()> {
        let inside = self.z.end <= dims.d && self.y.end <= dims.h && self.x.end <= dims.w;
        if !inside || self.dims().voxel_count() == 0 {
            return Err(invalid(
                "range",
                format!("expected a non-empty range inside the grid {dims:?}, got {self:?}"),
            ));
        }
        Ok(())
    }
}

/// Shifts `x` by `by` cells along `dim`, filling the vacated cells with 0 (no wrap-around).
fn shift_dim(x: &Tensor, dim: usize, by: i64) -> Result<Tensor> {
    let n = x.dim(dim)?;
    let k = by.unsigned_abs() as usize;
    if by == 0 {
        return Ok(x.clone());
    }
    if k >= n {
        return Ok(x.zeros_like()?);
    }
    let mut zero_shape = x.dims().to_vec();
    zero_shape[dim] = k;
    let zeros = Tensor::zeros(zero_shape, x.dtype(), x.device())?;
    let parts = if by > 0 {
        [zeros, x.narrow(dim, 0, n - k)?]
    } else {
        [x.narrow(dim, k, n - k)?, zeros]
    };
    Ok(Tensor::cat(&parts, dim)?)
}

/// Shifts the last three dimensions of `x` by `(dz, dy, dx)` cells.
fn shift_dhw(x: &Tensor, offset: [i64; 3]) -> Result<Tensor> {
    let r = x.rank();
    let x = shift_dim(x, r - 3, offset[0])?;
    let x = shift_dim(&x, r - 2, offset[1])?;
    shift_dim(&x, r - 1, offset[2])
}

impl RadianceVolume {
    /// Returns the cells in `range` as a new volume whose box is exactly those cells.
    pub fn crop(&self, range: &VoxelRange) -> Result<Self> {
        range.validate(self.dims())?;
        let data = self
            .tensor()
            .narrow(1, range.z.start, range.z.len())?
            .narrow(2, range.y.start, range.y.len())?
            .narrow(3, range.x.start, range.x.len())?;
        let grid = self.grid();
        let vs = grid.voxel_size();
        let lo = glam::Vec3::new(
            range.x.start as f32,
            range.y.start as f32,
            range.z.start as f32,
        );
        let hi = glam::Vec3::new(range.x.end as f32, range.y.end as f32, range.z.end as f32);
        let aabb = Aabb::try_new(grid.aabb.min + lo * vs, grid.aabb.min + hi * vs)?;
        Self::new(data, aabb)?.with_channel_names(self.channel_names().to_vec())
    }

    /// Returns a copy with `src`'s voxels written over the cells starting at `at = (z, y, x)`.
    /// `src` must have the same channel count and fit inside; its box is ignored (voxels are
    /// copied one to one).
    pub fn paste(&self, src: &RadianceVolume, at: [usize; 3]) -> Result<Self> {
        if src.channel_count() != self.channel_count() {
            return Err(invalid(
                "src",
                format!(
                    "expected {} channels like the target, got {}",
                    self.channel_count(),
                    src.channel_count()
                ),
            ));
        }
        let s = src.dims();
        let range = VoxelRange::new(at[0]..at[0] + s.d, at[1]..at[1] + s.h, at[2]..at[2] + s.w);
        range.validate(self.dims())?;
        let data = self.tensor().slice_assign(
            &[0..self.channel_count(), range.z, range.y, range.x],
            src.tensor(),
        )?;
        self.with_tensor(data)
    }

    /// Returns a `(D, H, W)` mask with 1 at the cells whose centre lies in `aabb` (closed box).
    pub fn box_mask(&self, aabb: Aabb) -> Result<Tensor> {
        let grid = *self.grid();
        let dims = grid.dims;
        let mask: Vec<f32> = (0..dims.voxel_count())
            .map(|i| {
                let (z, y, x) = (i / (dims.h * dims.w), (i / dims.w) % dims.h, i % dims.w);
                f32::from(u8::from(aabb.contains(grid.cell_center(z, y, x))))
            })
            .collect();
        Ok(Tensor::from_vec(
            mask,
            (dims.d, dims.h, dims.w),
            self.tensor().device(),
        )?)
    }

    /// Returns a copy where masked cells take `value` (one number per channel), blending
    /// `v * (1 - m) + value * m`: the paper's removal, with `value` the "empty" (air) voxel.
    pub fn fill_masked(&self, mask: &Tensor, value: &[f32]) -> Result<Self> {
        let mask = self.check_mask(mask)?;
        let value = self.check_value(value)?;
        let keep = mask.affine(-1.0, 1.0)?;
        let data = (self.tensor().broadcast_mul(&keep)? + mask.broadcast_mul(&value)?)?;
        self.with_tensor(data)
    }

    /// Copies the masked region to a place `offset = (dz, dy, dx)` cells away, over whatever is
    /// there (the paper's duplicate). With `fill_source = Some(empty)`, the source region is
    /// first filled with `empty` (the paper's move). Parts shifted beyond the grid are dropped.
    pub fn translate_masked(
        &self,
        mask: &Tensor,
        offset: [i64; 3],
        fill_source: Option<&[f32]>,
    ) -> Result<Self> {
        let base = match fill_source {
            Some(empty) => self.fill_masked(mask, empty)?,
            None => self.clone(),
        };
        base.paste_masked(self, mask, offset)
    }

    /// Returns a copy where the masked region of `source` (a volume on the same grid, with the
    /// same channels), moved `offset = (dz, dy, dx)` cells, replaces what is there: an object
    /// of another scene put into this one (the paper's composition). Parts moved beyond the
    /// grid are dropped; [`RadianceVolume::translate_masked`] is this with `source = self`.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use radiance_volume::{Aabb, RadianceVolume};
    /// let zeros = Tensor::zeros((4, 1, 1, 4), candle_core::DType::F32, &Device::Cpu)?;
    /// let base = RadianceVolume::new(zeros, Aabb::CUBE)?;
    /// let source = RadianceVolume::new(Tensor::ones((4, 1, 1, 4), candle_core::DType::F32, &Device::Cpu)?, Aabb::CUBE)?;
    /// let first = Tensor::new(&[[[1f32, 0.0, 0.0, 0.0]]], &Device::Cpu)?;
    /// // The source's first cell, put two cells along x.
    /// let pasted = base.paste_masked(&source, &first, [0, 0, 2])?;
    /// let density: Vec<f32> = pasted.tensor().get(0)?.flatten_all()?.to_vec1()?;
    /// assert_eq!(density, [0.0, 0.0, 1.0, 0.0]);
    /// # Ok::<(), radiance_volume::Error>(())
    /// ```
    pub fn paste_masked(
        &self,
        source: &RadianceVolume,
        mask: &Tensor,
        offset: [i64; 3],
    ) -> Result<Self> {
        if source.tensor().dims() != self.tensor().dims() {
            return Err(invalid(
                "source",
                format!(
                    "expected a volume of the same shape {:?}, got {:?}",
                    self.tensor().dims(),
                    source.tensor().dims()
                ),
            ));
        }
        let mask = self.check_mask(mask)?;
        let moved = shift_dhw(source.tensor(), offset)?;
        let moved_mask = shift_dhw(&mask, offset)?;
        let keep = moved_mask.affine(-1.0, 1.0)?;
        let data = (self.tensor().broadcast_mul(&keep)? + moved.broadcast_mul(&moved_mask)?)?;
        self.with_tensor(data)
    }

    /// Checks a `(D, H, W)` mask against the grid and returns it as `(1, D, H, W)` f32.
    fn check_mask(&self, mask: &Tensor) -> Result<Tensor> {
        let d = self.dims();
        if mask.dims() != [d.d, d.h, d.w] {
            return Err(invalid(
                "mask",
                format!(
                    "expected shape [{}, {}, {}], got {:?}",
                    d.d,
                    d.h,
                    d.w,
                    mask.dims()
                ),
            ));
        }
        Ok(mask.to_dtype(DType::F32)?.unsqueeze(0)?)
    }

    /// Checks a per-channel value and returns it as a `(C, 1, 1, 1)` tensor.
    fn check_value(&self, value: &[f32]) -> Result<Tensor> {
        let c = self.channel_count();
        if value.len() != c {
            return Err(invalid(
                "value",
                format!("expected one value per channel ({c}), got {}", value.len()),
            ));
        }
        Ok(Tensor::from_slice(
            value,
            (c, 1, 1, 1),
            self.tensor().device(),
        )?)
    }
}
