//! The gradient penalty's gradient against finite differences, for either way of computing it.

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{GradientNorm, GradientPenalty, PatchDiscriminator, PatchDiscriminatorConfig};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::{check_finite_differences_every, random, reseed};

/// Seed of the interpolation weights in every penalty the tests compute.
pub const PENALTY_SEED: u64 = 42;

/// Two layers of three channels: every layer on the im2col kernel.
pub const SMALL_CRITIC: PatchDiscriminatorConfig = PatchDiscriminatorConfig {
    layers: 2,
    channels: 3,
    in_channels: 2,
};

/// Three layers of 32 channels: the middle and last layers (32 input channels) on the Winograd
/// kernel, the first (2 input channels) on im2col.
pub const WIDE_CRITIC: PatchDiscriminatorConfig = PatchDiscriminatorConfig {
    layers: 3,
    channels: 32,
    in_channels: 2,
};

/// A penalty as a function of the critic's weights (interpolation drawn from [`PENALTY_SEED`]).
pub type PenaltyFn<const AXES: usize> =
    fn(&PatchDiscriminator<AXES>, &Tensor, &Tensor, GradientPenalty) -> Tensor;

/// A batch of `n` random inputs of `channels` with `AXES` spatial axes of `side`.
pub fn random_batch<const AXES: usize>(
    n: usize,
    channels: usize,
    side: usize,
    seed: u64,
) -> Tensor {
    let mut shape = vec![n, channels];
    shape.extend([side; AXES]);
    random(&shape, seed)
}

/// The critic's own first-order penalty, a [`PenaltyFn`].
pub fn first_order_penalty<const AXES: usize>(
    critic: &PatchDiscriminator<AXES>,
    real: &Tensor,
    fake: &Tensor,
    cfg: GradientPenalty,
) -> Tensor {
    let mut rng = ChaCha8Rng::seed_from_u64(PENALTY_SEED);
    critic.gradient_penalty(real, fake, cfg, &mut rng).unwrap()
}

/// Checks every `stride`-th entry of every weight and bias of a critic of `cfg` over `AXES`
/// spatial axes (f64), with both norms, and that the penalty reaches every conv weight.
pub fn penalty_gradient_matches_finite_differences<const AXES: usize>(
    cfg: PatchDiscriminatorConfig,
    stride: usize,
    penalty: PenaltyFn<AXES>,
) {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let critic = PatchDiscriminator::<AXES>::new(&cfg, vb).unwrap();
    reseed(&varmap, 11);
    let side = 2 * cfg.layers + 2;
    let real = random_batch::<AXES>(2, cfg.in_channels, side, 5);
    let fake = random_batch::<AXES>(2, cfg.in_channels, side, 6);
    for norm in [GradientNorm::PerPixel, GradientNorm::PerImage] {
        let gp_cfg = GradientPenalty { weight: 0.1, norm };
        let grads = penalty(&critic, &real, &fake, gp_cfg).backward().unwrap();
        let vars = varmap.all_vars();
        let mut checked = 0;
        for var in &vars {
            // Biases only move LeakyReLU's kinks: no gradient, and candle reports None.
            let analytic = match grads.get(var) {
                Some(g) => g.clone(),
                None => var.zeros_like().unwrap(),
            };
            let value = || {
                penalty(&critic, &real, &fake, gp_cfg)
                    .to_scalar::<f64>()
                    .unwrap()
            };
            let what = format!("{norm:?}");
            checked += check_finite_differences_every(var, &analytic, value, 1e-5, stride, &what);
        }
        // Every `stride`-th entry of every weight and bias of every layer.
        let total: usize = vars.iter().map(|v| v.elem_count().div_ceil(stride)).sum();
        assert_eq!(checked, total);
    }
    // The check means something only if the penalty does reach the weights.
    let grads = penalty(&critic, &real, &fake, GradientPenalty::default())
        .backward()
        .unwrap();
    for var in varmap.all_vars().iter().filter(|v| v.rank() == AXES + 2) {
        let g = grads.get(var).expect("every conv weight gets a gradient");
        let total = g
            .abs()
            .unwrap()
            .sum_all()
            .unwrap()
            .to_scalar::<f64>()
            .unwrap();
        assert!(total > 0.0);
    }
}
