//! `Conv2d` as shifted views and one matrix product (stride 1, zero padding).
//!
//! candle 0.11's CPU conv2d computes its input gradient with a direct transposed convolution
//! (a dot product per output element) and its weight gradient as a convolution with an
//! image-sized kernel; on the critics' 50-110 pixel images those passes dominate training, and
//! the gradient penalty runs them twice. Built from `narrow`, `stack` and `matmul`, every pass
//! here, second-order ones included, is a matrix product or a copy.

use candle_core::{Module, Tensor};

/// A 2D convolution with square kernel, stride 1, zero padding and a bias: weight
/// `(C_out, C_in, k, k)` (PyTorch's layout and names), `(N, C_in, H, W)` to
/// `(N, C_out, H + 2 padding - k + 1, W + 2 padding - k + 1)`.
#[derive(Debug, Clone)]
pub struct Conv2d {
    weight: Tensor,
    bias: Tensor,
    padding: usize,
}

impl Conv2d {
    /// A layer from its tensors.
    pub fn new(weight: Tensor, bias: Tensor, padding: usize) -> Self {
        Self {
            weight,
            bias,
            padding,
        }
    }
}

impl Module for Conv2d {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let xs = if self.padding > 0 {
            xs.pad_with_zeros(2, self.padding, self.padding)?
                .pad_with_zeros(3, self.padding, self.padding)?
        } else {
            xs.clone()
        };
        let (n, c, h, w) = xs.dims4()?;
        let (c_out, c_in, k, _) = self.weight.dims4()?;
        if c != c_in || h < k || w < k {
            candle_core::bail!(
                "conv2d: input {:?} does not fit weight {:?}",
                xs.shape(),
                self.weight.shape()
            );
        }
        let (h_out, w_out) = (h - k + 1, w - k + 1);
        let mut shifted = Vec::with_capacity(k * k);
        for dy in 0..k {
            for dx in 0..k {
                shifted.push(xs.narrow(2, dy, h_out)?.narrow(3, dx, w_out)?);
            }
        }
        // (N, C, k*k, H', W'): channel-major then (dy, dx), the order of the weight's rows.
        let columns = Tensor::stack(&shifted, 2)?.reshape((n, c * k * k, h_out * w_out))?;
        let weight = self.weight.reshape((1, c_out, c_in * k * k))?;
        let out = weight.broadcast_matmul(&columns)?;
        out.reshape((n, c_out, h_out, w_out))?
            .broadcast_add(&self.bias.reshape((1, c_out, 1, 1))?)
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Module, Tensor, Var};

    use super::Conv2d;

    /// Values and both gradients equal candle's own conv2d (f64, padding 0 and 1).
    #[test]
    fn matches_candle_conv2d_values_and_gradients() {
        let dev = Device::Cpu;
        for padding in [0, 1] {
            let x =
                Var::from_tensor(&Tensor::randn(0f64, 1., (2, 3, 7, 6), &dev).unwrap()).unwrap();
            let w =
                Var::from_tensor(&Tensor::randn(0f64, 1., (4, 3, 3, 3), &dev).unwrap()).unwrap();
            let b = Var::from_tensor(&Tensor::randn(0f64, 1., 4, &dev).unwrap()).unwrap();
            let ours = Conv2d::new(w.as_tensor().clone(), b.as_tensor().clone(), padding)
                .forward(x.as_tensor())
                .unwrap();
            let theirs = x
                .as_tensor()
                .conv2d(w.as_tensor(), padding, 1, 1, 1)
                .unwrap()
                .broadcast_add(&b.as_tensor().reshape((1, 4, 1, 1)).unwrap())
                .unwrap();
            assert_eq!(ours.dims(), theirs.dims());
            let r = Tensor::randn(0f64, 1., ours.shape(), &dev).unwrap();
            let g1 = (&ours * &r).unwrap().sum_all().unwrap().backward().unwrap();
            let g2 = (&theirs * &r)
                .unwrap()
                .sum_all()
                .unwrap()
                .backward()
                .unwrap();
            let diff = |a: &Tensor, b: &Tensor| -> f64 {
                (a - b)
                    .unwrap()
                    .abs()
                    .unwrap()
                    .flatten_all()
                    .unwrap()
                    .max(0)
                    .unwrap()
                    .to_dtype(DType::F64)
                    .unwrap()
                    .to_scalar()
                    .unwrap()
            };
            assert!(diff(&ours, &theirs) < 1e-12);
            for v in [&x, &w, &b] {
                let (a, c) = (g1.get(v).unwrap(), g2.get(v).unwrap());
                assert!(
                    diff(a, c) < 1e-10,
                    "padding {padding}: gradient differs by {}",
                    diff(a, c)
                );
            }
        }
    }
}
