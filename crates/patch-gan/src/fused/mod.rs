//! Fused CPU ops for the element-wise work between convolutions: LeakyReLU (and its bias add),
//! and BatchNorm with LeakyReLU, forward and backward each in one threaded sweep.
//!
//! Built from candle's own ops, LeakyReLU is five passes over the tensor (`zeros_like`,
//! `maximum`, `minimum`, `affine`, `add`), each allocating, single-threaded, with a backward of
//! as many again; BatchNorm is a dozen. At the generators' sizes (32 channels x 40^3 voxels =
//! 8 MB per tensor) these passes, not the convolutions, were most of a training step. Here each
//! layer's element-wise work is one read and one write of its tensor in the forward pass and two
//! reads and one write in the backward pass, split over rayon's threads in fixed chunks (per
//! channel where a sum is taken, summed in f64), so results do not depend on the thread count.

mod batch_norm;
mod channel_sum;
mod conv_leaky;
mod conv_stack;
mod leaky;

pub(crate) use batch_norm::{batch_norm_act, BatchStats, NormStats};
pub(crate) use conv_leaky::conv_bias_leaky;
pub(crate) use conv_stack::{conv_norm_stack, StackBlock};
pub(crate) use leaky::{bias_add, leaky_grad};
pub use leaky::{bias_leaky_relu, leaky_relu};

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
    if crate::simd::has_avx2() {
        // SAFETY: the CPU has AVX2 (checked just above).
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

/// The `(channels, plane)` split of an `(N, C, ...)` tensor: `C` and the product of the axes after it.
fn channels_and_plane(dims: &[usize]) -> (usize, usize) {
    let channels = dims.get(1).copied().unwrap_or(1);
    (channels, dims.iter().skip(2).product())
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor, Var};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// An f64 tensor of `shape`, uniform in [-1, 1) from `seed`.
    pub(crate) fn random(shape: &[usize], seed: u64) -> Tensor {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = shape.iter().product();
        let values: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
        Tensor::from_vec(values, shape, &Device::Cpu).unwrap()
    }

    /// Asserts that a fused op's output `fused` and its unfused composition's `plain` have the
    /// same values, and the same gradients of `sum(weights * y)` with respect to `vars`, bit for
    /// bit (f64 values compared with `==`).
    pub(crate) fn assert_same_values_and_gradients(
        (fused, plain): (&Tensor, &Tensor),
        weights: &Tensor,
        vars: &[(&str, &Var)],
        case: &str,
    ) {
        let as_vec = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        assert_eq!(as_vec(fused), as_vec(plain), "{case}: outputs");
        let grads = |y: &Tensor| {
            (y * weights)
                .unwrap()
                .sum_all()
                .unwrap()
                .backward()
                .unwrap()
        };
        let (of_fused, of_plain) = (grads(fused), grads(plain));
        for (name, var) in vars {
            let a = as_vec(of_fused.get(var).unwrap());
            let b = as_vec(of_plain.get(var).unwrap());
            assert_eq!(a, b, "{case}: gradient of {name}");
        }
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
        if !crate::simd::has_avx2() {
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

    #[test]
    fn bias_add_equals_broadcast_add_in_value_and_both_gradients() {
        use candle_core::{Device, Tensor, Var};
        let dev = Device::Cpu;
        let values: Vec<f64> = (0..120).map(|i| (i as f64 * 0.37 - 20.0).sin()).collect();
        let xs = Var::from_tensor(&Tensor::from_vec(values, (2, 3, 4, 5), &dev).unwrap()).unwrap();
        let bias = Var::from_tensor(&Tensor::new(&[0.5f64, -1.25, 2.], &dev).unwrap()).unwrap();
        // A loss that weighs every value differently, so every gradient entry is checked.
        let weights: Vec<f64> = (0..120).map(|i| 1.0 + (i % 7) as f64).collect();
        let weights = Tensor::from_vec(weights, (2, 3, 4, 5), &dev).unwrap();
        let run = |ys: Tensor| -> Vec<Vec<f64>> {
            let grads = (&ys * &weights)
                .unwrap()
                .sum_all()
                .unwrap()
                .backward()
                .unwrap();
            let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f64>().unwrap();
            vec![
                flat(&ys),
                flat(grads.get(&xs).unwrap()),
                flat(grads.get(&bias).unwrap()),
            ]
        };
        let ours = run(bias_add(&xs, &bias).unwrap());
        let reference = run(xs
            .broadcast_add(&bias.reshape((1, 3, 1, 1)).unwrap())
            .unwrap());
        for (a, b) in ours.iter().zip(&reference) {
            assert_eq!(a.len(), b.len());
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() < 1e-12, "{x} vs {y}");
            }
        }
    }
}
