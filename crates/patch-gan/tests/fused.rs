//! The fused element-wise ops (LeakyReLU, bias + LeakyReLU, BatchNorm + LeakyReLU) against
//! plain f64 references, and their gradients against central finite differences.
//!
//! Tests that differentiate twice set `CANDLE_GRAD_DO_NOT_DETACH`; candle reads it once per
//! thread and every test runs on its own thread.

// Setting candle's environment switch (`std::env::set_var`) is `unsafe`.
#![allow(unsafe_code)]

use candle_core::{DType, Device, ModuleT, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{batch_norm3d, bias_leaky_relu, leaky_relu, NORM_EPS};
mod common;

use common::{check_finite_differences, random, values};

/// Step of the finite differences (the fused ops are smooth away from the kinks at 0).
const STEP: f64 = 1e-6;

/// `sum(r * y)` for a fixed random `r`: a loss whose gradient with respect to `y` is `r`.
fn weighted_sum(y: &Tensor, seed: u64) -> Tensor {
    (y * random(y.dims(), seed)).unwrap().sum_all().unwrap()
}

#[test]
fn leaky_relu_values_and_gradients_of_both_orders() {
    // SAFETY: tests only read this variable through std::env.
    unsafe { std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1") };
    let x = Var::from_tensor(&random(&[2, 3, 5], 1)).unwrap();
    let y = leaky_relu(x.as_tensor(), 0.2).unwrap();
    let expected: Vec<f64> = values(x.as_tensor())
        .iter()
        .map(|&v| if v > 0.0 { v } else { 0.2 * v })
        .collect();
    assert_eq!(values(&y), expected);
    let loss = || weighted_sum(&leaky_relu(x.as_tensor(), 0.2).unwrap(), 2);
    let grads = loss().backward().unwrap();
    let grad = grads.get(&x).unwrap();
    check_finite_differences(&x, grad, || loss().to_scalar().unwrap(), STEP, "leaky_relu");
    // The gradient is itself differentiable (the penalty needs it): sum(grad^2 * x) has
    // derivative grad^2 along x, the slope's own derivative being zero.
    let grad_sq = (grad.sqr().unwrap() * x.as_tensor())
        .unwrap()
        .sum_all()
        .unwrap();
    let second = grad_sq.backward().unwrap();
    let expected = grad.sqr().unwrap();
    assert_eq!(values(second.get(&x).unwrap()), values(&expected));
}

#[test]
fn bias_leaky_relu_is_leaky_relu_of_the_sum_and_differentiates_like_it() {
    let x = Var::from_tensor(&random(&[2, 3, 4, 5], 3)).unwrap();
    let b = Var::from_tensor(&random(&[3], 4)).unwrap();
    let fused = bias_leaky_relu(x.as_tensor(), b.as_tensor(), 0.2).unwrap();
    let sum = x
        .as_tensor()
        .broadcast_add(&b.as_tensor().reshape((1, 3, 1, 1)).unwrap())
        .unwrap();
    assert_eq!(values(&fused), values(&leaky_relu(&sum, 0.2).unwrap()));
    let loss = || {
        weighted_sum(
            &bias_leaky_relu(x.as_tensor(), b.as_tensor(), 0.2).unwrap(),
            5,
        )
    };
    let grads = loss().backward().unwrap();
    let value = || loss().to_scalar::<f64>().unwrap();
    check_finite_differences(&x, grads.get(&x).unwrap(), value, STEP, "input");
    check_finite_differences(&b, grads.get(&b).unwrap(), value, STEP, "bias");
    // A bias that is not a (C,) vector of the input's channels is refused.
    assert!(bias_leaky_relu(x.as_tensor(), &random(&[4], 6), 0.2).is_err());
}

/// BatchNorm (batch statistics, biased variance) then LeakyReLU, by the definition in f64.
fn batch_norm_reference(x: &Tensor, gamma: &[f64], beta: &[f64], slope: f64) -> Vec<f64> {
    let (n, c, d, h, w) = x.dims5().unwrap();
    let plane = d * h * w;
    let v = values(x);
    let mut out = vec![0.0; v.len()];
    for ch in 0..c {
        let idx = |i: usize| (i / plane * c + ch) * plane + i % plane;
        let count = (n * plane) as f64;
        let mean = (0..n * plane).map(|i| v[idx(i)]).sum::<f64>() / count;
        let var = (0..n * plane)
            .map(|i| (v[idx(i)] - mean).powi(2))
            .sum::<f64>()
            / count;
        for i in 0..n * plane {
            let pre = gamma[ch] * (v[idx(i)] - mean) / (var + NORM_EPS).sqrt() + beta[ch];
            out[idx(i)] = if pre > 0.0 { pre } else { slope * pre };
        }
    }
    out
}

#[test]
fn batch_norm_with_leaky_relu_matches_the_definition_and_finite_differences() {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let bn = batch_norm3d(3, vb.pp("bn")).unwrap();
    let data = varmap.data().lock().unwrap().clone();
    let (gamma, beta) = (&data["bn.weight"], &data["bn.bias"]);
    gamma
        .set(&Tensor::new(&[1.5f64, -0.7, 0.4], &Device::Cpu).unwrap())
        .unwrap();
    beta.set(&Tensor::new(&[0.2f64, -0.1, 0.3], &Device::Cpu).unwrap())
        .unwrap();
    let x = Var::from_tensor(&random(&[2, 3, 2, 3, 2], 7)).unwrap();
    for slope in [0.2, 1.0] {
        let y = bn
            .forward_activated(x.as_tensor(), None, slope, true)
            .unwrap();
        let expected = batch_norm_reference(x.as_tensor(), &values(gamma), &values(beta), slope);
        let err = values(&y)
            .iter()
            .zip(&expected)
            .fold(0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(err < 1e-12, "slope {slope}: {err}");
        for train in [true, false] {
            let loss = || {
                let y = bn
                    .forward_activated(x.as_tensor(), None, slope, train)
                    .unwrap();
                weighted_sum(&y, 8)
            };
            let grads = loss().backward().unwrap();
            let value = || loss().to_scalar::<f64>().unwrap();
            let what = format!("slope {slope}, train {train}");
            check_finite_differences(
                &x,
                grads.get(&x).unwrap(),
                value,
                STEP,
                &format!("{what}: input"),
            );
            for (var, name) in [(gamma, "weight"), (beta, "bias")] {
                let grad = grads.get(var).unwrap();
                check_finite_differences(var, grad, value, STEP, &format!("{what}: {name}"));
            }
        }
    }
}

#[test]
fn a_folded_input_bias_changes_nothing_but_the_running_mean_as_adding_it_would() {
    let make = || {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
        (batch_norm3d(2, vb).unwrap(), varmap)
    };
    let (folded, _a) = make();
    let (added, _b) = make();
    let x = random(&[1, 2, 3, 3, 3], 9);
    let bias = Tensor::new(&[4.0f64, -2.0], &Device::Cpu).unwrap();
    let with_bias = x
        .broadcast_add(&bias.reshape((1, 2, 1, 1, 1)).unwrap())
        .unwrap();
    for train in [true, false] {
        let a = folded
            .forward_activated(&x, Some(&bias), 0.2, train)
            .unwrap();
        let b = added
            .forward_activated(&with_bias, None, 0.2, train)
            .unwrap();
        let err = values(&a)
            .iter()
            .zip(values(&b))
            .fold(0f64, |m, (p, q)| m.max((p - q).abs()));
        assert!(err < 1e-12, "train {train}: {err}");
        for (p, q) in [
            (folded.running_mean(), added.running_mean()),
            (folded.running_var(), added.running_var()),
        ] {
            let err = values(p)
                .iter()
                .zip(values(q))
                .fold(0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(
                err < 1e-12,
                "train {train}: running statistics differ by {err}"
            );
        }
    }
    // Eval mode normalises with the running statistics the train pass left.
    let rm = values(folded.running_mean());
    assert!(
        (rm[0]
            - 0.1
                * (values(&with_bias.narrow(1, 0, 1).unwrap())
                    .iter()
                    .sum::<f64>()
                    / 27.0))
            .abs()
            < 1e-12
    );
}

#[test]
fn the_generator_step_is_bit_identical_on_one_two_and_three_threads() {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let config = patch_gan::Generator3dConfig::default().with_layers(3);
    let g = patch_gan::Generator3d::new(&config, vb).unwrap();
    let x = random(&[1, 3, 12, 12, 12], 10)
        .to_dtype(DType::F32)
        .unwrap();
    let step = || {
        let y = g.forward_t(&x, true).unwrap();
        let grads = y.sqr().unwrap().mean_all().unwrap().backward().unwrap();
        let mut bits = Vec::new();
        for var in varmap.all_vars() {
            if let Some(grad) = grads.get(&var) {
                let v: Vec<f32> = grad.flatten_all().unwrap().to_vec1().unwrap();
                bits.extend(v.iter().map(|f| f.to_bits()));
            }
        }
        bits
    };
    let in_pool = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(step)
    };
    let one = in_pool(1);
    assert!(!one.is_empty());
    for threads in [2, 3] {
        assert_eq!(in_pool(threads), one, "{threads} threads");
    }
}
