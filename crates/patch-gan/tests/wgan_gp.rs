//! WGAN-GP: loss values, the penalty's second-order gradient against finite differences, and
//! the critic's first-order penalty against it.
//!
//! Every test sets `CANDLE_GRAD_DO_NOT_DETACH` first: candle reads it once per thread, and each
//! test runs on its own thread.

// Setting candle's environment switch (`std::env::set_var`) is `unsafe`.
#![allow(unsafe_code)]

use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{
    critic_loss, generator_loss, gradient_penalty, GradientNorm, GradientPenalty,
    PatchDiscriminator, PatchDiscriminator2d, PatchDiscriminatorConfig,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn enable_second_order() {
    // SAFETY: tests only read this variable through std::env (which locks), never from C code.
    unsafe { std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1") };
}

mod common;
use common::penalty as support;
use common::{max_abs, max_abs_diff, random};

#[test]
fn losses_are_wasserstein_estimates() {
    let real = random(&[2, 1, 3, 3], 1);
    let fake = random(&[2, 1, 3, 3], 2);
    let mean = |t: &Tensor| t.mean_all().unwrap().to_scalar::<f64>().unwrap();
    let c = critic_loss(&real, &fake)
        .unwrap()
        .to_scalar::<f64>()
        .unwrap();
    assert!((c - (mean(&fake) - mean(&real))).abs() < 1e-15);
    let g = generator_loss(&fake).unwrap().to_scalar::<f64>().unwrap();
    assert_eq!(g, -mean(&fake));
}

#[test]
fn penalty_of_a_linear_critic_is_known() {
    enable_second_order();
    // A 1x1 conv has input gradient w at every pixel, whatever the input.
    let w = Tensor::new(&[[[[0.6f64]], [[0.8]], [[2.0]]]], &Device::Cpu).unwrap();
    let critic = |x: &Tensor| x.conv2d(&w, 0, 1, 1, 1);
    let real = random(&[2, 3, 4, 5], 3);
    let fake = random(&[2, 3, 4, 5], 4);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let per_pixel = GradientPenalty {
        weight: 0.1,
        norm: GradientNorm::PerPixel,
    };
    let gp = gradient_penalty(&critic, &real, &fake, per_pixel, &mut rng).unwrap();
    let norm = (0.36f64 + 0.64 + 4.0).sqrt();
    assert!((gp.to_scalar::<f64>().unwrap() - 0.1 * (norm - 1.0).powi(2)).abs() < 1e-9);
    let per_image = GradientPenalty {
        weight: 2.0,
        norm: GradientNorm::PerImage,
    };
    let gp = gradient_penalty(&critic, &real, &fake, per_image, &mut rng).unwrap();
    let norm = (20.0 * 5.0f64).sqrt();
    assert!((gp.to_scalar::<f64>().unwrap() - 2.0 * (norm - 1.0).powi(2)).abs() < 1e-9);
}

/// The generic penalty as a function of the critic's weights, with the interpolation drawn
/// from a fixed seed.
fn penalty<const AXES: usize>(
    critic: &PatchDiscriminator<AXES>,
    real: &Tensor,
    fake: &Tensor,
    cfg: GradientPenalty,
) -> Tensor {
    enable_second_order();
    let mut rng = ChaCha8Rng::seed_from_u64(support::PENALTY_SEED);
    gradient_penalty(critic, real, fake, cfg, &mut rng).unwrap()
}

#[test]
fn penalty_gradient_matches_finite_differences() {
    // Three channels run every layer on the im2col kernel; every weight is checked.
    support::penalty_gradient_matches_finite_differences::<2>(support::SMALL_CRITIC, 1, penalty);
}

#[test]
fn penalty_gradient_matches_finite_differences_through_winograd() {
    // 32 input channels send the middle and last layers through the Winograd kernel; every 97th
    // weight is checked (all 10k would take minutes).
    support::penalty_gradient_matches_finite_differences::<2>(support::WIDE_CRITIC, 97, penalty);
}

/// The first-order penalty against the double backward: the same value and the same gradient
/// for every weight (to rounding, in f64), and no bias gradient from either, with the im2col
/// and the Winograd kernels and both norms.
#[test]
fn first_order_penalty_equals_the_double_backward() {
    for cfg in [support::SMALL_CRITIC, support::WIDE_CRITIC] {
        let side = 2 * cfg.layers + 3;
        assert_first_order_equals_double_backward::<2>(cfg, &[side, side + 1]);
    }
}

/// As above for the critic of volumes, on the im2col kernel (3 channels) and the Winograd
/// kernel (32).
#[test]
fn first_order_penalty_of_a_volume_critic_equals_the_double_backward() {
    let narrow = PatchDiscriminatorConfig {
        layers: 3,
        ..support::SMALL_CRITIC
    };
    for cfg in [narrow, support::WIDE_CRITIC] {
        let side = 2 * cfg.layers + 2;
        assert_first_order_equals_double_backward::<3>(cfg, &[side, side + 1, side]);
    }
}

fn assert_first_order_equals_double_backward<const AXES: usize>(
    cfg: PatchDiscriminatorConfig,
    sides: &[usize],
) {
    enable_second_order();
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let critic = PatchDiscriminator::<AXES>::new(&cfg, vb).unwrap();
    let shape: Vec<usize> = [3, cfg.in_channels].iter().chain(sides).copied().collect();
    let (real, fake) = (random(&shape, 7), random(&shape, 8));
    for norm in [GradientNorm::PerPixel, GradientNorm::PerImage] {
        let gp_cfg = GradientPenalty { weight: 0.3, norm };
        let generic = penalty(&critic, &real, &fake, gp_cfg);
        let first = support::first_order_penalty(&critic, &real, &fake, gp_cfg);
        let (a, b) = (
            generic.to_scalar::<f64>().unwrap(),
            first.to_scalar::<f64>().unwrap(),
        );
        assert!((a - b).abs() <= 1e-12 * a.abs(), "{norm:?}: {a} vs {b}");
        let (ga, gb) = (generic.backward().unwrap(), first.backward().unwrap());
        for var in varmap.all_vars() {
            match (ga.get(&var), gb.get(&var)) {
                (None, None) => assert_eq!(var.rank(), 1, "only biases get no gradient"),
                (Some(x), Some(y)) => {
                    let (scale, diff) = (max_abs(x), max_abs_diff(x, y));
                    assert!(
                        scale > 0.0 && diff <= 1e-10 * scale,
                        "{:?}: {diff} of {scale}",
                        var.shape()
                    );
                }
                (x, y) => panic!(
                    "{:?}: gradient {} vs {}",
                    var.shape(),
                    x.is_some(),
                    y.is_some()
                ),
            }
        }
    }
}

/// The critic's one-pass WGAN loss against the two-pass definition: value and every gradient,
/// with batches of different sizes; channels that differ are an error.
#[test]
fn one_pass_critic_loss_equals_two_passes() {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let critic = PatchDiscriminator2d::new(&support::SMALL_CRITIC, vb).unwrap();
    let real = random(&[2, 2, 9, 8], 11);
    let fake = random(&[3, 2, 9, 8], 12);
    let joint = critic.critic_loss(&real, &fake).unwrap();
    let apart = critic_loss(
        &critic.forward(&real).unwrap(),
        &critic.forward(&fake).unwrap(),
    )
    .unwrap();
    let (a, b) = (
        joint.to_scalar::<f64>().unwrap(),
        apart.to_scalar::<f64>().unwrap(),
    );
    assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-3), "{a} vs {b}");
    let (ga, gb) = (joint.backward().unwrap(), apart.backward().unwrap());
    for var in varmap.all_vars() {
        let diff = max_abs_diff(ga.get(&var).unwrap(), gb.get(&var).unwrap());
        assert!(diff <= 1e-12, "{:?}: {diff}", var.shape());
    }
    assert!(critic
        .critic_loss(&real, &random(&[2, 3, 9, 8], 13))
        .is_err());
}

#[test]
fn penalty_rejects_mismatched_inputs() {
    enable_second_order();
    let critic = |x: &Tensor| Ok(x.clone());
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let r = gradient_penalty(
        &critic,
        &random(&[1, 2, 3, 3], 1),
        &random(&[1, 2, 3, 4], 2),
        GradientPenalty::default(),
        &mut rng,
    );
    assert!(r.is_err());
}
