//! The CPU kernels, generic over `f32` and `f64`: ray setup and sample marching (`march`), the
//! trilinear gather/scatter (`trilinear`), and per-ray compositing forward and backward
//! (`composite`). Slices in, values out; no tensors here.
//!
//! The volume is read from an interleaved copy, one `[sigma, r, g, b]` per voxel: a trilinear
//! sample then touches 8 runs of 16 (f32) bytes instead of 32 scattered floats.

// Channel and axis loops index several small arrays in step; index loops read clearest.
#![allow(clippy::needless_range_loop)]

mod composite;
mod exp;
mod march;
mod tile;
mod trilinear;

pub(crate) use composite::Params;
pub(crate) use march::{setup_ray, GridSpec, OccView};
pub(crate) use tile::{Isa, RayKernel, PACKED};
pub(crate) use trilinear::corners;

use num_traits::Float;

/// The float types the kernels run in: `f32` for speed, `f64` for references and gradient checks.
pub(crate) trait Real: Float + Send + Sync + std::fmt::Debug + Default + 'static {
    /// Converts from f64 (rounding for f32).
    fn of(x: f64) -> Self;

    /// `e^x` for `x <= 0`: inline arithmetic within 2 ulp for f32 (see `exp`), the standard
    /// library's `exp` for f64 (the reference precision).
    fn exp_nonpositive(self) -> Self;

    /// Truncates a value known to be in `[0, 2^31)` to an index: one conversion instruction
    /// (through `i32`) instead of the range-checked float-to-`usize` sequence.
    fn truncate_index(self) -> usize;
}

impl Real for f32 {
    #[inline]
    fn of(x: f64) -> Self {
        x as f32
    }

    #[inline(always)]
    fn exp_nonpositive(self) -> Self {
        exp::exp_nonpositive(self)
    }

    #[inline(always)]
    fn truncate_index(self) -> usize {
        self as i32 as usize
    }
}

impl Real for f64 {
    #[inline]
    fn of(x: f64) -> Self {
        x
    }

    #[inline(always)]
    fn exp_nonpositive(self) -> Self {
        self.exp()
    }

    #[inline(always)]
    fn truncate_index(self) -> usize {
        self as i32 as usize
    }
}

/// A volume as the kernels see it: interleaved `[sigma, r, g, b]` per voxel, row-major
/// `(z, y, x)`, with `n = [w, h, d]` cells along x, y, z.
#[derive(Debug, Clone, Copy)]
pub(crate) struct VolumeView<'a, T> {
    pub(crate) data: &'a [[T; 4]],
    pub(crate) n: [usize; 3],
}
