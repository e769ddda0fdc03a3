//! The floating-point types the CPU kernels run on: f32 (training) and f64 (exactness tests).

use std::ops::{Add, Mul, Sub};

/// A float the kernels run on (the ones `gemm` multiplies); sums that must not lose bits go
/// through `f64`.
pub(crate) trait Element:
    Copy
    + Send
    + Sync
    + 'static
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
{
    const ZERO: Self;
    const ONE: Self;
    /// Whether this is `f32`, for kernels with an f32-only build (a pointer cast then keeps the type).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    const IS_F32: bool;

    fn to_f64(self) -> f64;

    fn from_f64(value: f64) -> Self;
}

impl Element for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const IS_F32: bool = true;

    fn to_f64(self) -> f64 {
        f64::from(self)
    }

    fn from_f64(value: f64) -> Self {
        value as f32
    }
}

impl Element for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const IS_F32: bool = false;

    fn to_f64(self) -> f64 {
        self
    }

    fn from_f64(value: f64) -> Self {
        value
    }
}
