//! PyTorch's default initialisation of convolution layers.

use candle_nn::Init;

/// The weight and bias initialisers PyTorch's `ConvNd.reset_parameters` uses for a layer whose
/// weight has `fan_in = in_channels * kernel volume` inputs per output.
///
/// Weights: `kaiming_uniform_(a = sqrt(5))`, i.e. bound `gain * sqrt(3 / fan_in)` with
/// `gain = sqrt(2 / (1 + a^2)) = sqrt(1/3)`, which is `1 / sqrt(fan_in)`. Bias: uniform in
/// `±1 / sqrt(fan_in)`. Both therefore draw from `U(-1/sqrt(fan_in), 1/sqrt(fan_in))`.
pub(crate) fn torch_conv_init(fan_in: usize) -> (Init, Init) {
    let bound = 1.0 / (fan_in as f64).sqrt();
    let uniform = Init::Uniform {
        lo: -bound,
        up: bound,
    };
    (uniform, uniform)
}
