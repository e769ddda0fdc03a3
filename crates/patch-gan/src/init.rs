//! PyTorch's default initialisation of convolution layers.

use candle_nn::{Conv2d, Conv2dConfig, Init, VarBuilder};

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

/// A 2D convolution with bias, square kernel, stride 1 and the given zero padding, whose tensors
/// are `weight` / `bias` under `vb` (PyTorch's `nn.Conv2d` names) and start from PyTorch's
/// default init. candle-nn's own `conv2d` uses a different default (Kaiming-normal), which would
/// change the networks' behaviour at the start of training relative to the paper's PyTorch code.
pub(crate) fn torch_conv2d(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    padding: usize,
    vb: VarBuilder,
) -> candle_core::Result<Conv2d> {
    let (w_init, b_init) = torch_conv_init(in_channels * kernel * kernel);
    let weight = vb.get_with_hints(
        (out_channels, in_channels, kernel, kernel),
        "weight",
        w_init,
    )?;
    let bias = vb.get_with_hints(out_channels, "bias", b_init)?;
    let config = Conv2dConfig {
        padding,
        ..Default::default()
    };
    Ok(Conv2d::new(weight, Some(bias), config))
}
