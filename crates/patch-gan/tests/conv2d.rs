//! Conv2d against candle's own conv2d, and its first- and second-order gradients against
//! finite differences (the gradient penalty differentiates an input gradient).
//!
//! The second-order test sets `CANDLE_GRAD_DO_NOT_DETACH`; candle reads it once per thread and
//! every test runs on its own thread.

// Setting candle's environment switch (`std::env::set_var`) is `unsafe`.
#![allow(unsafe_code)]

use candle_core::{DType, Device, Module, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{conv2d, functional, Conv2d, ConvConfig};
mod common;

use common::{check_finite_differences, random, values};

fn max_diff(a: &Tensor, b: &Tensor) -> f64 {
    assert_eq!(a.dims(), b.dims());
    values(a)
        .iter()
        .zip(values(b))
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Input shape, kernel shape, padding and stride.
const CASES: [([usize; 4], [usize; 4], usize, usize); 5] = [
    ([2, 3, 7, 6], [4, 3, 3, 3], 0, 1),
    ([1, 2, 8, 9], [3, 2, 3, 3], 1, 1),
    ([2, 2, 9, 7], [2, 2, 2, 3], 1, 2),
    ([1, 3, 5, 5], [2, 3, 1, 1], 1, 1),
    ([1, 1, 8, 8], [1, 1, 3, 3], 0, 3),
];

/// Every function checked is a polynomial of degree at most 4 in the entries: step 1e-4 leaves a
/// truncation error of order 1e-8 next to the rounding error.
const STEP: f64 = 1e-4;

#[test]
fn values_match_candle_and_gradients_finite_differences() {
    for (i, &(xs, ks, padding, stride)) in CASES.iter().enumerate() {
        let cfg = ConvConfig { padding, stride };
        let x = Var::from_tensor(&random(&xs, 10 + i as u64)).unwrap();
        let k = Var::from_tensor(&random(&ks, 20 + i as u64)).unwrap();
        let ours = functional::conv2d(&x, &k, cfg).unwrap();
        let theirs = x.conv2d(&k, padding, stride, 1, 1).unwrap();
        assert!(max_diff(&ours, &theirs) < 1e-12, "case {i}: values");
        // Gradients against finite differences, not candle's backward: candle 0.11's conv2d
        // backward fails for strided convolutions whose output width needs an output padding
        // other than the height's (case 2).
        let r = random(ours.dims(), 30 + i as u64);
        let loss = || {
            let y = functional::conv2d(&x, &k, cfg).unwrap();
            (y * &r).unwrap().sum_all().unwrap()
        };
        let grads = loss().backward().unwrap();
        for var in [&x, &k] {
            let value = || loss().to_scalar::<f64>().unwrap();
            check_finite_differences(
                var,
                grads.get(var).unwrap(),
                value,
                STEP,
                &format!("case {i}"),
            );
        }
    }
}

/// `h(x, k) = sum(s_x * dL/dx ^ 2) + sum(s_k * dL/dk ^ 2)` with `L = sum(r * conv2d(x, k))`:
/// its gradient needs the backward of all three ops (forward, input and kernel gradient).
fn second_order(x: &Var, k: &Var, cfg: ConvConfig, seed: u64) -> Tensor {
    let y = functional::conv2d(x, k, cfg).unwrap();
    let r = random(y.dims(), seed);
    let grads = (y * r).unwrap().sum_all().unwrap().backward().unwrap();
    let (gx, gk) = (grads.get(x).unwrap(), grads.get(k).unwrap());
    let sx = random(gx.dims(), seed + 1);
    let sk = random(gk.dims(), seed + 2);
    let hx = (gx.sqr().unwrap() * sx).unwrap().sum_all().unwrap();
    let hk = (gk.sqr().unwrap() * sk).unwrap().sum_all().unwrap();
    (hx + hk).unwrap()
}

#[test]
fn second_order_gradients_match_finite_differences() {
    // SAFETY: tests only read this variable through std::env (which locks), never from C code.
    unsafe { std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1") };
    for (i, &(xs, ks, padding, stride)) in CASES.iter().enumerate() {
        let cfg = ConvConfig { padding, stride };
        let x = Var::from_tensor(&random(&xs, 40 + i as u64)).unwrap();
        let k = Var::from_tensor(&random(&ks, 50 + i as u64)).unwrap();
        let seed = 60 + 3 * i as u64;
        let grads = second_order(&x, &k, cfg, seed).backward().unwrap();
        for var in [&x, &k] {
            let value = || second_order(&x, &k, cfg, seed).to_scalar::<f64>().unwrap();
            check_finite_differences(
                var,
                grads.get(var).unwrap(),
                value,
                STEP,
                &format!("case {i}"),
            );
        }
    }
}

#[test]
fn layer_adds_bias_and_rejects_bad_shapes() {
    let dev = Device::Cpu;
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &dev);
    let layer = conv2d(2, 3, 3, ConvConfig::default().with_padding(1), vb.pp("c")).unwrap();
    let x = random(&[1, 2, 5, 4], 1);
    let without = functional::conv2d(&x, layer.weight(), layer.config()).unwrap();
    let with = layer.forward(&x).unwrap();
    let bias = values(layer.bias().unwrap());
    let diff = (with - without).unwrap();
    for (c, b) in bias.iter().enumerate() {
        for v in values(&diff.get(0).unwrap().get(c).unwrap()) {
            assert!((v - b).abs() < 1e-12);
        }
    }
    let w = Tensor::zeros((3, 2, 3, 3), DType::F64, &dev).unwrap();
    let cfg = ConvConfig::default();
    assert!(functional::conv2d(&x.unsqueeze(0).unwrap(), &w, cfg).is_err());
    assert!(functional::conv2d(&x, &w.narrow(1, 0, 1).unwrap(), cfg).is_err());
    assert!(functional::conv2d(&x.narrow(2, 0, 2).unwrap(), &w, cfg).is_err());
    assert!(functional::conv2d(&x, &w, cfg.with_stride(0)).is_err());
    assert!(functional::conv2d(&x, &w.to_dtype(DType::F32).unwrap(), cfg).is_err());
    assert!(Conv2d::new(w.unsqueeze(0).unwrap(), None, cfg).is_err());
    let bad_bias = Some(Tensor::zeros(2, DType::F64, &dev).unwrap());
    assert!(Conv2d::new(w, bad_bias, cfg).is_err());
}
