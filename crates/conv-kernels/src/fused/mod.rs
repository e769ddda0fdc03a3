//! Fused CPU kernels for the element-wise work between convolutions: LeakyReLU (and its bias
//! add), BatchNorm with LeakyReLU forward and backward, and per-channel sums, over `(N, C, plane)`
//! values in row-major order.
//!
//! Each is one read and one write of its values (two reads for a backward pass), split over
//! rayon's threads in fixed chunks (per channel where a sum is taken, summed in f64), so
//! results do not depend on the thread count.

mod batch_norm;
mod channel_sum;
mod leaky;

pub use batch_norm::{batch_norm_act, batch_norm_act_backward, channel_stats, NormParams};
pub use channel_sum::channel_sums;
pub use leaky::{bias_leaky_relu, leaky_relu, leaky_relu_grad};

use crate::element::Element;

/// Elements per parallel task of the element-wise kernels: large enough that rayon's overhead
/// vanishes, small enough that two threads share the work evenly.
const CHUNK: usize = 1 << 14;

/// The factor LeakyReLU applies where the value that tells its branch is `v` (its input, or its
/// output for the gradient): 1 for `v > 0`, else `slope`. Callers multiply by it: a select
/// between two constants vectorises, where `if v > 0 { v } else { v * slope }` compiled to a
/// branch per element, mispredicted on random signs (a quarter of the 28^3 generator step's
/// profile was these kernels). `v * 1` is `v`, so the bits are the same.
#[inline(always)]
fn slope_at<T: Element>(v: T, slope: T) -> T {
    if v > T::ZERO {
        T::ONE
    } else {
        slope
    }
}

/// Independent partial sums of [`lane_sums`].
const SUM_LANES: usize = 8;

/// `sum_i f(a_i, b_i)` in f64 over two equally long slices, for `K` sums at once, as eight
/// interleaved partial sums (element `i` goes to lane `i % 8`) added at the end. One chain of
/// f64 additions waits on the adder's latency at every element; eight independent ones do not.
/// The order is fixed, so the bits do not depend on the thread count (nor on the CPU: the AVX2
/// build, 4 f64 lanes instead of 2, gives the same bits).
fn lane_sums<T: Element, const K: usize>(
    a: &[T],
    b: &[T],
    f: impl Fn(T, T) -> [f64; K],
) -> [f64; K] {
    #[cfg(target_arch = "x86_64")]
    if crate::Isa::current() >= crate::Isa::Avx2 {
        // SAFETY: the CPU has AVX2 (`Isa` is never above the CPU's).
        return unsafe { lane_sums_avx2(a, b, f) };
    }
    lane_sums_body(a, b, f)
}

/// [`lane_sums`] compiled for AVX2 (with `f` inlined into it).
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn lane_sums_avx2<T: Element, const K: usize>(
    a: &[T],
    b: &[T],
    f: impl Fn(T, T) -> [f64; K],
) -> [f64; K] {
    lane_sums_body(a, b, f)
}

/// The body of [`lane_sums`], compiled for whichever instruction set its caller is compiled for.
#[inline(always)]
fn lane_sums_body<T: Element, const K: usize>(
    a: &[T],
    b: &[T],
    f: impl Fn(T, T) -> [f64; K],
) -> [f64; K] {
    let mut lanes = [[0f64; SUM_LANES]; K];
    let (blocks_a, blocks_b) = (a.chunks_exact(SUM_LANES), b.chunks_exact(SUM_LANES));
    let tail = blocks_a.remainder().iter().zip(blocks_b.remainder());
    for (xa, xb) in blocks_a.zip(blocks_b) {
        for lane in 0..SUM_LANES {
            let v = f(xa[lane], xb[lane]);
            for k in 0..K {
                lanes[k][lane] += v[k];
            }
        }
    }
    let mut total = lanes.map(|l| l.iter().sum::<f64>());
    for (&x, &y) in tail {
        let v = f(x, y);
        for k in 0..K {
            total[k] += v[k];
        }
    }
    total
}

/// `sum_i f(x_i)` over one slice, as [`lane_sums`].
fn lane_sum<T: Element>(xs: &[T], f: impl Fn(T) -> f64) -> f64 {
    lane_sums(xs, xs, |x, _| [f(x)])[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values in [-1, 1) of both signs, and zeros.
    fn values(len: usize, k: f32) -> Vec<f32> {
        (0..len)
            .map(|i| {
                if i % 17 == 0 {
                    0.0
                } else {
                    (i as f32 * k).sin()
                }
            })
            .collect()
    }

    /// The element-wise kernels against one scalar loop each, bit for bit, on lengths around
    /// the parallel chunks' size and planes that do not divide it.
    #[test]
    fn element_kernels_equal_scalar_loops() {
        let leaky = |v: f32, slope: f32| if v > 0.0 { v } else { v * slope };
        for len in [0, 1, 7, CHUNK - 1, CHUNK, 3 * CHUNK + 5] {
            let (x, y) = (values(len, 0.37), values(len, 0.11));
            let expected: Vec<f32> = x.iter().map(|&v| leaky(v, 0.2)).collect();
            assert_eq!(leaky_relu(&x, 0.2), expected, "len {len}");
            let expected: Vec<f32> = x
                .iter()
                .zip(&y)
                .map(|(&g, &y)| if y > 0.0 { g } else { g * 0.2 })
                .collect();
            assert_eq!(leaky_relu_grad(&x, &y, 0.2), expected, "len {len}");
        }
        let (bias, plane) = ([0.5f32, -0.25, 0.0], 1001);
        let x = values(2 * 3 * plane, 0.37);
        let expected: Vec<f32> = x
            .iter()
            .enumerate()
            .map(|(i, &v)| leaky(v + bias[(i / plane) % 3], 0.2))
            .collect();
        assert_eq!(bias_leaky_relu(&x, &bias, plane, 0.2), expected);
        let sums = channel_sums(&x, 3, plane);
        for (c, sum) in sums.iter().enumerate() {
            let plain: f64 = (0..2)
                .flat_map(|n| &x[(n * 3 + c) * plane..][..plane])
                .map(|&v| f64::from(v))
                .sum();
            assert!((f64::from(*sum) - plain).abs() < 1e-4, "channel {c}");
        }
    }

    #[test]
    #[should_panic(expected = "3 gradients for 4 outputs")]
    fn gradients_and_outputs_of_different_lengths_are_refused() {
        leaky_relu_grad(&[1f32; 3], &[1f32; 4], 0.2);
    }

    #[test]
    fn lane_sums_equal_plain_sums_for_every_tail_length() {
        for len in 0..27 {
            let a: Vec<f32> = (0..len).map(|i| (i as f32 * 0.37).sin()).collect();
            let b: Vec<f32> = (0..len).map(|i| 1.0 + i as f32 / 8.0).collect();
            let [s, sp] = lane_sums(&a, &b, |x, y| [x.to_f64(), x.to_f64() * y.to_f64()]);
            let plain: f64 = a.iter().map(|&x| f64::from(x)).sum();
            let products: f64 = a
                .iter()
                .zip(&b)
                .map(|(&x, &y)| f64::from(x) * f64::from(y))
                .sum();
            assert!((s - plain).abs() < 1e-12, "len {len}: {s} vs {plain}");
            assert!(
                (sp - products).abs() < 1e-12,
                "len {len}: {sp} vs {products}"
            );
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_build_of_lane_sums_gives_the_same_bits() {
        if crate::Isa::detected() < crate::Isa::Avx2 {
            return;
        }
        let a: Vec<f32> = (0..1003).map(|i| (i as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..1003).map(|i| 1.0 + (i as f32 * 0.11).cos()).collect();
        let f = |x: f32, y: f32| {
            let g = (y * slope_at(x, 0.2f32)).to_f64();
            [g, g * (x.to_f64() - 0.3) * 1.7]
        };
        // SAFETY: the CPU has AVX2 (checked above).
        let avx2 = unsafe { lane_sums_avx2(&a, &b, f) };
        let body = lane_sums_body(&a, &b, f);
        assert_eq!(avx2.map(f64::to_bits), body.map(f64::to_bits));
    }
}
