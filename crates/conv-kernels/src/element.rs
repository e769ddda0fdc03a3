//! The floating-point types the CPU kernels run on: f32 (training) and f64 (exactness tests).

use std::ops::{Add, Mul, Sub};

mod sealed {
    /// Keeps [`super::Element`] to the two types below: the kernels' f32-only SIMD builds cast
    /// pointers on [`super::Element::IS_F32`], which another type could claim falsely.
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// A float the kernels run on: `f32` or `f64` (the ones `gemm` multiplies); sums that must not
/// lose bits go through `f64`. Sealed: no other type can implement it.
pub trait Element:
    sealed::Sealed
    + Copy
    + Send
    + Sync
    + 'static
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
{
    /// `0`.
    const ZERO: Self;
    /// `1`.
    const ONE: Self;
    /// Whether this is `f32`, for kernels with an f32-only build (a pointer cast then keeps the
    /// type).
    const IS_F32: bool;

    /// The value as an `f64` (exact).
    fn to_f64(self) -> f64;

    /// `value` rounded to this type.
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
