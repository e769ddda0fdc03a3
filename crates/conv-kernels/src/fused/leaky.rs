//! LeakyReLU, its gradient, and bias + LeakyReLU, element-wise in one threaded sweep each.

use std::mem::MaybeUninit;

use super::{slope_at, CHUNK};
use crate::element::Element;
use crate::output::{extend_par_chunks, unwritten};

/// `len` values made [`CHUNK`] at a time in parallel: `fill(start, dst)` writes the values
/// `start..start + dst.len()`. Plain loops over slices, like the other element-wise kernels:
/// rayon's zipped `map` + `collect` wrote one value per call through its consumer.
///
/// # Safety
/// `fill` must write every value of the chunk it is given.
unsafe fn map_chunks<T: Element>(
    len: usize,
    fill: impl Fn(usize, &mut [MaybeUninit<T>]) + Sync,
) -> Vec<T> {
    let mut out = unwritten(len);
    // SAFETY: the caller's promise.
    unsafe { extend_par_chunks(&mut out, len, CHUNK, |i, dst| fill(i * CHUNK, dst)) };
    out
}

/// `LeakyReLU(x) = x` for `x > 0`, else `slope x`, element-wise (as `x * 1` or `x * slope`,
/// `slope` rounded to `T`).
///
/// ```
/// let y = conv_kernels::fused::leaky_relu(&[-2f32, 0., 3.], 0.2);
/// assert_eq!(y, [-0.4, 0., 3.]);
/// ```
pub fn leaky_relu<T: Element>(x: &[T], slope: f64) -> Vec<T> {
    let slope = T::from_f64(slope);
    // SAFETY: each chunk is zipped with the input from its start on, as long as the output.
    unsafe {
        map_chunks(x.len(), |start, dst| {
            for (d, &v) in dst.iter_mut().zip(&x[start..]) {
                d.write(v * slope_at(v, slope));
            }
        })
    }
}

/// `grad` times the slope of the LeakyReLU branch each of `output` lies on (1 where it is
/// positive, else `slope`): the gradient of [`leaky_relu`] (and of [`bias_leaky_relu`]) for a
/// positive `slope`, whose outputs tell the branch.
///
/// # Panics
/// If `grad` and `output` differ in length.
pub fn leaky_relu_grad<T: Element>(grad: &[T], output: &[T], slope: f64) -> Vec<T> {
    assert_eq!(
        grad.len(),
        output.len(),
        "leaky_relu_grad: {} gradients for {} outputs",
        grad.len(),
        output.len()
    );
    let (slope, y) = (T::from_f64(slope), output);
    // SAFETY: each chunk is zipped with both inputs from its start on, as long as the output
    // (they have its length, checked above).
    unsafe {
        map_chunks(grad.len(), |start, dst| {
            for ((d, &g), &y) in dst.iter_mut().zip(&grad[start..]).zip(&y[start..]) {
                d.write(g * slope_at(y, slope));
            }
        })
    }
}

/// `LeakyReLU(x + bias)` for `x` `(N, C, plane)` and `bias` `(C,)` (`C = bias.len()`), one
/// task per `(n, c)` plane: a convolution's bias and activation in one sweep. With `slope` 1
/// it is the bias alone.
///
/// ```
/// // (N, C, plane) = (1, 2, 2)
/// let y = conv_kernels::fused::bias_leaky_relu(&[-1f32, 1., 0., 2.], &[0.5, -1.], 2, 0.2);
/// assert_eq!(y, [-0.1, 1.5, -0.2, 1.]);
/// ```
///
/// # Panics
/// If `plane` is 0, or `bias` is empty while `x` is not.
pub fn bias_leaky_relu<T: Element>(x: &[T], bias: &[T], plane: usize, slope: f64) -> Vec<T> {
    let (slope, channels) = (T::from_f64(slope), bias.len());
    let mut out = unwritten(x.len());
    // SAFETY: every chunk of `out` is written from the chunk of `x` of the same length.
    unsafe {
        extend_par_chunks(&mut out, x.len(), plane, |i, dst| {
            let b = bias[i % channels];
            for (d, &v) in dst.iter_mut().zip(&x[i * plane..]) {
                let v = v + b;
                d.write(v * slope_at(v, slope));
            }
        })
    };
    out
}
