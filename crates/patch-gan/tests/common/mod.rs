//! Helpers the test files share: seeded random tensors and finite-difference checks.

// Each test binary compiles this module and uses a different part of it.
#![allow(dead_code)]

use candle_core::{Device, Tensor, Var};
use candle_nn::VarMap;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub mod penalty;

/// An f64 tensor of `shape` with values uniform in [-1, 1) from `seed`.
pub fn random(shape: &[usize], seed: u64) -> Tensor {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = shape.iter().product();
    let v: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
}

/// Redraws every randomly initialised variable of `varmap` (f64) from `seed`, uniform within
/// +-1/sqrt(fan-in) of its layer (a bias takes its weight's, named alike); constants are left
/// alone.
///
/// candle's initialisers draw from an unseeded generator, so without this each run checks a
/// different network; and the gradient penalty jumps where a LeakyReLU input crosses zero, so a
/// network with an input within the finite-difference step of its kink fails the check, at
/// random, about one run in five for the wide critic. The bound comes from the shapes, not from
/// the values drawn, so every run checks the very same network.
pub fn reseed(varmap: &VarMap, seed: u64) {
    let data = varmap.data().lock().unwrap();
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for (k, name) in names.into_iter().enumerate() {
        let var = &data[name];
        let current = values(var.as_tensor());
        if current.iter().all(|&v| v == current[0]) {
            continue;
        }
        let weight = match name.strip_suffix("bias") {
            Some(layer) => &data[&format!("{layer}weight")],
            None => var,
        };
        let fan_in: usize = weight.dims()[1..].iter().product();
        let bound = 1.0 / (fan_in as f64).sqrt();
        let redrawn = (random(var.dims(), seed + k as u64) * bound).unwrap();
        var.set(&redrawn).unwrap();
    }
}

/// The largest absolute value of an f64 tensor.
pub fn max_abs(t: &Tensor) -> f64 {
    t.abs().unwrap().max_all().unwrap().to_scalar().unwrap()
}

/// The largest absolute difference between two f64 tensors of one shape.
pub fn max_abs_diff(a: &Tensor, b: &Tensor) -> f64 {
    max_abs(&(a - b).unwrap())
}

/// The values of an f64 tensor, flattened.
pub fn values(t: &Tensor) -> Vec<f64> {
    t.flatten_all().unwrap().to_vec1().unwrap()
}

/// Central finite differences of `f` with `step` along every entry of `var`, checked against
/// `analytic` to 1e-6 relative (plus 1e-6 absolute).
pub fn check_finite_differences(
    var: &Var,
    analytic: &Tensor,
    f: impl Fn() -> f64,
    step: f64,
    what: &str,
) {
    check_finite_differences_every(var, analytic, f, step, 1, what);
}

/// [`check_finite_differences`] along every `stride`-th entry of `var`; returns how many were
/// checked.
pub fn check_finite_differences_every(
    var: &Var,
    analytic: &Tensor,
    f: impl Fn() -> f64,
    step: f64,
    stride: usize,
    what: &str,
) -> usize {
    let base = values(var.as_tensor());
    let analytic = values(analytic);
    assert_eq!(analytic.len(), base.len(), "{what}");
    let mut checked = 0;
    for (j, &g) in analytic.iter().enumerate().step_by(stride) {
        let eval = |delta: f64| {
            let mut v = base.clone();
            v[j] += delta;
            var.set(&Tensor::from_vec(v, var.shape(), &Device::Cpu).unwrap())
                .unwrap();
            f()
        };
        let fd = (eval(step) - eval(-step)) / (2.0 * step);
        eval(0.0);
        assert!(
            (fd - g).abs() < 1e-6 * (1.0 + g.abs()),
            "{what}, entry {j} of {:?}: finite difference {fd} vs {g}",
            var.shape()
        );
        checked += 1;
    }
    checked
}
