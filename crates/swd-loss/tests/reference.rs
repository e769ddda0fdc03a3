//! The distance against float64 sort-based references and exact 1D Wasserstein distances.

mod common;

use candle_core::{DType, Device, Tensor};
use common::{assert_rel_close, columns, matrix, pseudo_random_rows, sliced_per_projection};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use swd_loss::{sliced_wasserstein, sliced_wasserstein_per_projection, Error, Metric, Projections};

fn per_projection(x: &Tensor, y: &Tensor, p: &Projections, metric: Metric) -> Vec<f64> {
    sliced_wasserstein_per_projection(x, y, p, metric)
        .unwrap()
        .to_dtype(DType::F64)
        .unwrap()
        .to_vec1()
        .unwrap()
}

/// Checks both metrics on f64 and f32 tensors against the reference, for sizes n and m.
fn check_against_reference(n: usize, m: usize, c: usize, k: usize, seed: u64) {
    let x = pseudo_random_rows(n, c, seed, 1.0, 0.0);
    let y = pseudo_random_rows(m, c, seed + 100, 1.7, 0.4);
    let proj =
        Projections::random(c, k, &mut ChaCha8Rng::seed_from_u64(seed), &Device::Cpu).unwrap();
    let dirs = columns(proj.as_tensor());
    for (metric, power) in [(Metric::SquaredW2, 2.0), (Metric::W1, 1.0)] {
        let want = sliced_per_projection(&x, &y, &dirs, power);
        let got64 = per_projection(&matrix(&x), &matrix(&y), &proj, metric);
        let x32 = matrix(&x).to_dtype(DType::F32).unwrap();
        let y32 = matrix(&y).to_dtype(DType::F32).unwrap();
        let got32 = per_projection(&x32, &y32, &proj, metric);
        for kk in 0..k {
            let what = format!("{metric:?} n={n} m={m} slice {kk}");
            assert_rel_close(got64[kk], want[kk], 1e-6, &what);
            assert_rel_close(got32[kk], want[kk], 1e-5, &what);
        }
        let mean = sliced_wasserstein(&matrix(&x), &matrix(&y), &proj, metric)
            .unwrap()
            .to_scalar::<f64>()
            .unwrap();
        assert_rel_close(
            mean,
            want.iter().sum::<f64>() / k as f64,
            1e-6,
            "mean over slices",
        );
    }
}

#[test]
fn equal_sizes_match_float64_reference() {
    check_against_reference(9, 9, 4, 6, 1);
}

#[test]
fn unequal_sizes_match_float64_reference() {
    check_against_reference(5, 8, 3, 5, 2);
    check_against_reference(13, 4, 2, 3, 3);
    check_against_reference(1, 6, 5, 4, 4);
}

fn identity_1d() -> Projections {
    Projections::from_tensor(Tensor::new(&[[1.0f64]], &Device::Cpu).unwrap()).unwrap()
}

fn column(values: &[f64]) -> Tensor {
    Tensor::from_vec(values.to_vec(), (values.len(), 1), &Device::Cpu).unwrap()
}

/// W1 between two empirical measures is the area between their CDFs (independent of sorting).
fn w1_by_cdf(x: &[f64], y: &[f64]) -> f64 {
    let mut points: Vec<f64> = x.iter().chain(y).copied().collect();
    points.sort_by(f64::total_cmp);
    let cdf = |s: &[f64], t: f64| s.iter().filter(|&&v| v <= t).count() as f64 / s.len() as f64;
    points
        .windows(2)
        .map(|w| (cdf(x, w[0]) - cdf(y, w[0])).abs() * (w[1] - w[0]))
        .sum()
}

/// W2^2 for equal sizes as the minimum cost over all matchings.
fn w2sq_by_matchings(x: &[f64], y: &[f64]) -> f64 {
    fn permute(rest: &mut Vec<f64>, chosen: &mut Vec<f64>, x: &[f64], best: &mut f64) {
        if rest.is_empty() {
            let cost = x
                .iter()
                .zip(chosen.iter())
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>();
            *best = best.min(cost / x.len() as f64);
            return;
        }
        for i in 0..rest.len() {
            let v = rest.remove(i);
            chosen.push(v);
            permute(rest, chosen, x, best);
            chosen.pop();
            rest.insert(i, v);
        }
    }
    let mut best = f64::INFINITY;
    permute(&mut y.to_vec(), &mut Vec::new(), x, &mut best);
    best
}

#[test]
fn one_dimension_is_exact_wasserstein() {
    let x = [0.3, -1.2, 2.5, 0.0, 0.9, -0.4];
    let y = [1.1, 0.2, -2.0, 3.3, 0.5, 0.6];
    let got = sliced_wasserstein(&column(&x), &column(&y), &identity_1d(), Metric::SquaredW2)
        .unwrap()
        .to_scalar::<f64>()
        .unwrap();
    assert_rel_close(
        got,
        w2sq_by_matchings(&x, &y),
        1e-12,
        "W2^2 vs best matching",
    );

    let y9 = [1.1, 0.2, -2.0, 3.3, 0.5, 0.6, -0.7, 4.0, 0.05];
    for (a, b) in [(&x[..], &y9[..]), (&y9[..], &x[..]), (&x[..], &y[..])] {
        let got = sliced_wasserstein(&column(a), &column(b), &identity_1d(), Metric::W1)
            .unwrap()
            .to_scalar::<f64>()
            .unwrap();
        assert_rel_close(got, w1_by_cdf(a, b), 1e-12, "W1 vs CDF area");
    }
}

#[test]
fn single_points_give_squared_projected_distance() {
    let x = Tensor::new(&[[1.0f64, 2.0]], &Device::Cpu).unwrap();
    let y = Tensor::new(&[[4.0f64, 6.0]], &Device::Cpu).unwrap();
    let p =
        Projections::from_tensor(Tensor::new(&[[0.6f64], [0.8]], &Device::Cpu).unwrap()).unwrap();
    // (3, 4) . (0.6, 0.8) = 5.
    let d = sliced_wasserstein(&x, &y, &p, Metric::SquaredW2).unwrap();
    assert_rel_close(d.to_scalar::<f64>().unwrap(), 25.0, 1e-15, "single points");
}

#[test]
fn bad_inputs_are_errors() {
    let dev = Device::Cpu;
    let p3 = Projections::random(3, 4, &mut ChaCha8Rng::seed_from_u64(0), &dev).unwrap();
    let x = Tensor::zeros((5, 3), DType::F32, &dev).unwrap();
    let invalid = |r: swd_loss::Result<Tensor>| matches!(r, Err(Error::InvalidArgument { .. }));
    let m = Metric::SquaredW2;
    assert!(invalid(sliced_wasserstein(
        &x,
        &Tensor::zeros((5, 2), DType::F32, &dev).unwrap(),
        &p3,
        m
    )));
    assert!(invalid(sliced_wasserstein(
        &x,
        &Tensor::zeros((0, 3), DType::F32, &dev).unwrap(),
        &p3,
        m
    )));
    assert!(invalid(sliced_wasserstein(
        &x,
        &Tensor::zeros((5, 3), DType::F64, &dev).unwrap(),
        &p3,
        m
    )));
    assert!(invalid(sliced_wasserstein(
        &x,
        &Tensor::zeros((2, 5, 3), DType::F32, &dev).unwrap(),
        &p3,
        m
    )));
    let p2 = Projections::random(2, 4, &mut ChaCha8Rng::seed_from_u64(0), &dev).unwrap();
    assert!(invalid(sliced_wasserstein(&x, &x, &p2, m)));
    let nan = Tensor::new(&[[0.0f32, f32::NAN, 1.0]], &dev).unwrap();
    let err = sliced_wasserstein(&x, &nan, &p3, m).unwrap_err();
    assert!(matches!(err, Error::NonFinite { .. }), "{err}");
    assert!(err.to_string().contains('y'), "{err}");
    let inf = Tensor::new(&[[f32::INFINITY, 0.0, 1.0]], &dev).unwrap();
    assert!(matches!(
        sliced_wasserstein(&inf, &x, &p3, m),
        Err(Error::NonFinite { .. })
    ));
}
