//! The CPU kernels, generic over `f32` and `f64`: ray setup and sample marching (`march`),
//! chunks of samples interpolated and attenuated together (`chunk`), and per-ray compositing
//! forward and backward (`composite`); `trilinear` (tests only) is the corner-weight form of
//! the interpolation that the lerps are checked against. Slices in, values out; no tensors here.
//!
//! The volume is read from an interleaved copy, one `[sigma, r, g, b]` per voxel: a trilinear
//! sample then touches 8 runs of 16 (f32) bytes instead of 32 scattered floats.

// Channel and axis loops index several small arrays in step; index loops read clearest.
#![allow(clippy::needless_range_loop)]

mod chunk;
mod composite;
mod exp;
mod log;
mod march;
mod tile;
#[cfg(test)]
mod trilinear;

pub(crate) use composite::Params;
pub(crate) use march::{setup_ray, GridSpec, OccView};
pub(crate) use tile::{Isa, RayKernel, PACKED};

use num_traits::Float;

/// The float types the kernels run in: `f32` for speed, `f64` for references and gradient checks.
pub(crate) trait Real: Float + Send + Sync + std::fmt::Debug + Default + 'static {
    /// Converts from f64 (rounding for f32).
    fn of(x: f64) -> Self;

    /// `e^x` for `x <= 0`: inline arithmetic within 2 ulp for f32 (see `exp`), the standard
    /// library's `exp` for f64 (the reference precision).
    fn exp_nonpositive(self) -> Self;

    /// `ln(1 + x)` for `x` in `[0, 1]`: inline arithmetic within 2 ulp for f32 (see `log`), the
    /// standard library's `ln_1p` for f64.
    fn ln_1p_unit(self) -> Self;

    /// Truncates a value known to be in `[0, 2^31)` to an index: one conversion instruction
    /// (through `i32`) instead of the range-checked float-to-integer sequence.
    fn truncate_index(self) -> u32;

    /// Splits a value known to be in `[0, 2^22)` into its floor, as a float and as an index,
    /// without a float-to-int conversion instruction: adding `1.5 * 2^mantissa_bits` rounds
    /// to an integer that then sits in the low mantissa bits, and the floor is that integer or
    /// one less. (Conversions keep LLVM from vectorising the kernels' loops over samples.)
    fn floor_split(self) -> (Self, u32);

    /// Converts an index below `2^31` exactly (below `2^24` for f32): one conversion
    /// instruction (through `i32`), where `of(i as f64)` takes two.
    fn of_index(i: u32) -> Self;
}

/// The index conversions, the same code for both float types up to the magic number
/// `1.5 * 2^mantissa_bits` of `floor_split`.
macro_rules! index_conversions {
    ($float:ty, $magic:expr) => {
        #[inline(always)]
        fn truncate_index(self) -> u32 {
            self as i32 as u32
        }

        #[inline(always)]
        fn floor_split(self) -> (Self, u32) {
            const MAGIC: $float = $magic;
            let shifted = self + MAGIC;
            let nearest = shifted - MAGIC;
            let rounded_up = nearest > self;
            // The integer sits in the low bits, which fit in 32 for values below 2^22.
            let index = (shifted.to_bits() - MAGIC.to_bits()) as u32 - u32::from(rounded_up);
            let floor = if rounded_up { nearest - 1.0 } else { nearest };
            (floor, index)
        }

        #[inline(always)]
        fn of_index(i: u32) -> Self {
            i as i32 as $float
        }
    };
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
    fn ln_1p_unit(self) -> Self {
        log::ln_1p_unit(self)
    }

    index_conversions!(f32, 12_582_912.0); // 1.5 * 2^23
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
    fn ln_1p_unit(self) -> Self {
        self.ln_1p()
    }

    index_conversions!(f64, 6_755_399_441_055_744.0); // 1.5 * 2^52
}

/// A volume as the kernels see it: interleaved `[sigma, r, g, b]` per voxel, row-major
/// `(z, y, x)`, with `n = [w, h, d]` cells along x, y, z. With `post_activation = [scale,
/// shift]` channel 0 is raw density and a sample's density is `scale * softplus(raw + shift)` of
/// its interpolated raw value ([`crate::DensityInterpolation::PostActivated`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct VolumeView<'a, T> {
    pub(crate) data: &'a [[T; 4]],
    pub(crate) n: [usize; 3],
    pub(crate) post_activation: Option<[T; 2]>,
}

/// `(softplus(x), sigmoid(x))` = `(ln(1 + e^x), d softplus / dx)`, without overflow: with
/// `e = exp(-|x|)`, `softplus = max(x, 0) + ln(1 + e)` and the sigmoid is `1 / (1 + e)` for
/// `x >= 0`, `e / (1 + e)` below. Where `e` underflows (x below about -87 in f32) softplus is
/// exactly 0, which is what lets empty-space skipping treat such voxels as empty.
#[inline(always)]
pub(crate) fn softplus_and_slope<T: Real>(x: T) -> (T, T) {
    let e = (-x.abs()).exp_nonpositive();
    let positive = if x > T::zero() { x } else { T::zero() };
    let inverse = (T::one() + e).recip();
    let slope = if x >= T::zero() { inverse } else { e * inverse };
    (positive + e.ln_1p_unit(), slope)
}

/// Distance in units in the last place between an f32 and the exact (f64) value (for the
/// inline `exp` and `ln(1 + x)` tests).
#[cfg(test)]
pub(crate) fn ulps(got: f32, exact: f64) -> f64 {
    let ulp = (exact as f32).abs();
    let spacing = f32::from_bits(ulp.to_bits() + 1) - ulp;
    (got as f64 - exact).abs() / spacing as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_split_is_floor() {
        let mut values: Vec<f64> = vec![0.0, 0.5, 1.0, 1.5, 2.5, 3.0 - 1e-7, 63.5, 4_194_303.75];
        values.extend((0..2000).map(|i| i as f64 * 0.37));
        for x in values {
            let (f, i) = (x as f32).floor_split();
            assert_eq!(
                (f, i),
                ((x as f32).floor(), (x as f32).floor() as u32),
                "{x}"
            );
            let (f, i) = x.floor_split();
            assert_eq!((f, i), (x.floor(), x.floor() as u32), "{x}");
        }
        // The largest f32 below 1 and below each of a few integers.
        for k in [1u32, 2, 64, 1 << 21] {
            let below = f32::from_bits((k as f32).to_bits() - 1);
            assert_eq!(below.floor_split(), ((k - 1) as f32, k - 1));
        }
    }
}
