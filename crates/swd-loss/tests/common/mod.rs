//! Float64 references shared by the integration tests, written independently of the crate.

#![allow(dead_code)] // each test binary uses a different subset

use candle_core::{Device, Tensor, Var};

/// `W_p^p` between uniform empirical measures on `x` and `y`, by the common refinement: each
/// x value is repeated m times and each y value n times, so both lists have n m equally
/// weighted points and the sorted pairs give the optimal coupling.
pub fn w_pp_1d(x: &[f64], y: &[f64], p: f64) -> f64 {
    let (n, m) = (x.len(), y.len());
    let mut xs: Vec<f64> = x.iter().flat_map(|&v| std::iter::repeat_n(v, m)).collect();
    let mut ys: Vec<f64> = y.iter().flat_map(|&v| std::iter::repeat_n(v, n)).collect();
    xs.sort_by(f64::total_cmp);
    ys.sort_by(f64::total_cmp);
    xs.iter()
        .zip(&ys)
        .map(|(a, b)| (a - b).abs().powf(p))
        .sum::<f64>()
        / (n * m) as f64
}

/// Projects rows of `points` on direction `theta`.
pub fn project(points: &[Vec<f64>], theta: &[f64]) -> Vec<f64> {
    points
        .iter()
        .map(|r| r.iter().zip(theta).map(|(a, b)| a * b).sum())
        .collect()
}

/// Per-projection `W_p^p`; `directions` holds one direction per entry.
pub fn sliced_per_projection(
    x: &[Vec<f64>],
    y: &[Vec<f64>],
    directions: &[Vec<f64>],
    p: f64,
) -> Vec<f64> {
    directions
        .iter()
        .map(|t| w_pp_1d(&project(x, t), &project(y, t), p))
        .collect()
}

/// Turns rows into an `(N, C)` f64 tensor.
pub fn matrix(rows: &[Vec<f64>]) -> Tensor {
    let (n, c) = (rows.len(), rows[0].len());
    Tensor::from_vec(rows.concat(), (n, c), &Device::Cpu).unwrap()
}

/// Turns a `(C, K)` projection matrix into K direction vectors.
pub fn columns(p: &Tensor) -> Vec<Vec<f64>> {
    let rows = p.to_vec2::<f64>().unwrap();
    (0..rows[0].len())
        .map(|k| rows.iter().map(|r| r[k]).collect())
        .collect()
}

/// Deterministic pseudo-random rows (a small LCG, so references need no RNG crate).
pub fn pseudo_random_rows(n: usize, c: usize, seed: u64, scale: f64, shift: f64) -> Vec<Vec<f64>> {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    (0..n)
        .map(|_| (0..c).map(|_| scale * next() + shift).collect())
        .collect()
}

/// Asserts `|a - b| <= tol * max(|b|, tiny)`.
pub fn assert_rel_close(a: f64, b: f64, tol: f64, what: &str) {
    let scale = b.abs().max(1e-300);
    assert!(
        (a - b).abs() <= tol * scale,
        "{what}: {a} vs {b} (rel {:e})",
        (a - b).abs() / scale
    );
}

/// Compares the autograd gradient of the scalar `f` at the f64 tensor `x0` with central
/// differences (step 1e-6) at every listed flat entry, within `abs_tol + rel_tol * |fd|`.
pub fn check_gradient(
    x0: &Tensor,
    entries: &[usize],
    abs_tol: f64,
    rel_tol: f64,
    f: impl Fn(&Tensor) -> Tensor,
) {
    const EPS: f64 = 1e-6;
    let var = Var::from_tensor(x0).unwrap();
    let grads = f(var.as_tensor()).backward().unwrap();
    let g = grads
        .get(var.as_tensor())
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f64>()
        .unwrap();
    let flat = x0.flatten_all().unwrap().to_vec1::<f64>().unwrap();
    let eval = |i: usize, h: f64| {
        let mut v = flat.clone();
        v[i] += h;
        let t = Tensor::from_vec(v, x0.shape(), &Device::Cpu).unwrap();
        f(&t).to_scalar::<f64>().unwrap()
    };
    for &i in entries {
        let fd = (eval(i, EPS) - eval(i, -EPS)) / (2.0 * EPS);
        assert!(
            (g[i] - fd).abs() <= abs_tol + rel_tol * fd.abs(),
            "entry {i}: autograd {} vs finite difference {fd}",
            g[i]
        );
    }
}
