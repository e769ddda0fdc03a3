//! Fused CPU ops for the element-wise work between convolutions: LeakyReLU (and its bias add),
//! and BatchNorm with LeakyReLU, forward and backward each in one threaded sweep (the kernels
//! are `conv_kernels::fused`'s; these are the candle ops around them).
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
pub(crate) mod critic;
mod leaky;

pub(crate) use batch_norm::{batch_norm_act, BatchStats, NormStats};
pub(crate) use conv_leaky::conv_bias_leaky;
pub(crate) use conv_stack::{conv_norm_stack, StackBlock};
pub(crate) use leaky::bias_add;
// The device form of LeakyReLU, which the CPU's tests compare with the fused kernel.
#[cfg(test)]
pub(crate) use leaky::leaky_relu_by_ops;
pub use leaky::{bias_leaky_relu, leaky_relu};

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
