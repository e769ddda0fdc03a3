//! The CPU kernels, generic over `f32` and `f64`: ray setup and sample marching (`march`), the
//! trilinear gather/scatter (`trilinear`), and per-ray compositing forward and backward
//! (`composite`). Slices in, values out; no tensors here.
//!
//! The volume is read from an interleaved copy, one `[sigma, r, g, b]` per voxel: a trilinear
//! sample then touches 8 runs of 16 (f32) bytes instead of 32 scattered floats.

// Channel and axis loops index several small arrays in step; index loops read clearest.
#![allow(clippy::needless_range_loop)]

mod composite;
mod march;
mod trilinear;

pub(crate) use composite::{backward_ray, forward_ray, Params, RayOut};
pub(crate) use march::{setup_ray, GridSpec, OccView};
pub(crate) use trilinear::corners;

use num_traits::Float;

/// The float types the kernels run in: `f32` for speed, `f64` for references and gradient checks.
pub(crate) trait Real: Float + Send + Sync + std::fmt::Debug + Default + 'static {
    /// Converts from f64 (rounding for f32).
    fn of(x: f64) -> Self;
}

impl Real for f32 {
    #[inline]
    fn of(x: f64) -> Self {
        x as f32
    }
}

impl Real for f64 {
    #[inline]
    fn of(x: f64) -> Self {
        x
    }
}

/// A volume as the kernels see it: interleaved `[sigma, r, g, b]` per voxel, row-major
/// `(z, y, x)`, with `n = [w, h, d]` cells along x, y, z.
#[derive(Debug, Clone, Copy)]
pub(crate) struct VolumeView<'a, T> {
    pub(crate) data: &'a [[T; 4]],
    pub(crate) n: [usize; 3],
}
