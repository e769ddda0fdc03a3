//! The sum over every axis but the channel axis, as a bias's gradient needs it.

use rayon::prelude::*;

use super::lane_sum;
use crate::element::Element;

/// `x` `(N, C, plane)` (`C = channels`) summed to `(C,)`: f64 accumulation in a fixed order,
/// one task per channel.
///
/// ```
/// // (N, C, plane) = (2, 2, 1)
/// let sums = conv_kernels::fused::channel_sums(&[1f32, 2., 3., 4.], 2, 1);
/// assert_eq!(sums, [4., 6.]);
/// ```
///
/// # Panics
/// If `channels` or `plane` is 0.
pub fn channel_sums<T: Element>(x: &[T], channels: usize, plane: usize) -> Vec<T> {
    let batch = x.len() / (channels * plane);
    (0..channels)
        .into_par_iter()
        .map(|c| {
            let total: f64 = (0..batch)
                .map(|n| {
                    let p = &x[(n * channels + c) * plane..][..plane];
                    lane_sum(p, |v| v.to_f64())
                })
                .sum();
            T::from_f64(total)
        })
        .collect()
}
