//! WGAN-GP: loss values, and the penalty's second-order gradient against finite differences.
//!
//! Every test sets `CANDLE_GRAD_DO_NOT_DETACH` first: candle reads it once per thread, and each
//! test runs on its own thread.

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{
    critic_loss, generator_loss, gradient_penalty, GradientNorm, GradientPenalty,
    PatchDiscriminator2d, PatchDiscriminator2dConfig,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn enable_second_order() {
    // SAFETY: tests only read this variable through std::env (which locks), never from C code.
    unsafe { std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1") };
}

fn random(shape: &[usize], seed: u64) -> Tensor {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = shape.iter().product();
    let v: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
}

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

/// Penalty as a function of the critic's weights, with the interpolation drawn from a fixed seed.
fn penalty(
    critic: &PatchDiscriminator2d,
    real: &Tensor,
    fake: &Tensor,
    cfg: GradientPenalty,
) -> Tensor {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    gradient_penalty(critic, real, fake, cfg, &mut rng).unwrap()
}

#[test]
fn penalty_gradient_matches_finite_differences() {
    // Three channels run every layer on the im2col kernel; every weight is checked.
    penalty_gradient_matches_finite_differences_for(
        PatchDiscriminator2dConfig {
            layers: 2,
            channels: 3,
            in_channels: 2,
        },
        1,
    );
}

#[test]
fn penalty_gradient_matches_finite_differences_through_winograd() {
    // 32 channels in and out send the middle layer through the Winograd kernel; every 97th
    // weight is checked (all 10k would take minutes).
    penalty_gradient_matches_finite_differences_for(
        PatchDiscriminator2dConfig {
            layers: 3,
            channels: 32,
            in_channels: 2,
        },
        97,
    );
}

/// Checks every `stride`-th entry of every weight and bias.
fn penalty_gradient_matches_finite_differences_for(cfg: PatchDiscriminator2dConfig, stride: usize) {
    enable_second_order();
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let critic = PatchDiscriminator2d::new(&cfg, vb).unwrap();
    let side = 2 * cfg.layers + 2;
    let real = random(&[2, 2, side, side], 5);
    let fake = random(&[2, 2, side, side], 6);
    for norm in [GradientNorm::PerPixel, GradientNorm::PerImage] {
        let gp_cfg = GradientPenalty { weight: 0.1, norm };
        let grads = penalty(&critic, &real, &fake, gp_cfg).backward().unwrap();
        let vars: Vec<Var> = varmap.all_vars();
        let h = 1e-5;
        let mut checked = 0;
        for var in &vars {
            // The last bias shifts every score equally and so has no gradient: candle reports None.
            let analytic: Vec<f64> = match grads.get(var) {
                Some(g) => g.flatten_all().unwrap().to_vec1().unwrap(),
                None => vec![0.0; var.elem_count()],
            };
            let base: Vec<f64> = var.flatten_all().unwrap().to_vec1().unwrap();
            for (j, &g) in analytic.iter().enumerate().step_by(stride) {
                let eval = |delta: f64| {
                    let mut v = base.clone();
                    v[j] += delta;
                    var.set(&Tensor::from_vec(v, var.shape(), &Device::Cpu).unwrap())
                        .unwrap();
                    penalty(&critic, &real, &fake, gp_cfg)
                        .to_scalar::<f64>()
                        .unwrap()
                };
                let fd = (eval(h) - eval(-h)) / (2.0 * h);
                eval(0.0);
                assert!(
                    (fd - g).abs() < 1e-6 * (1.0 + g.abs()),
                    "{norm:?} weight {j} of {:?}: fd {fd} vs {g}",
                    var.shape()
                );
                checked += 1;
            }
        }
        // Every `stride`-th entry of every weight and bias of every layer.
        let total: usize = vars.iter().map(|v| v.elem_count().div_ceil(stride)).sum();
        assert_eq!(checked, total);
    }
    // The check means something only if the penalty does reach the weights.
    let grads = penalty(&critic, &real, &fake, GradientPenalty::default())
        .backward()
        .unwrap();
    for var in varmap.all_vars().iter().filter(|v| v.rank() == 4) {
        let g = grads.get(var).expect("every conv weight gets a gradient");
        assert!(
            g.abs()
                .unwrap()
                .sum_all()
                .unwrap()
                .to_scalar::<f64>()
                .unwrap()
                > 0.0
        );
    }
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
