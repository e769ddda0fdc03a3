//! Agreement with POT (the peer reference), on vectors it generated (see `data/README.md`).

mod common;

use candle_core::{Device, Tensor, Var};
use common::assert_rel_close;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use swd_loss::{sliced_wasserstein, sliced_wasserstein_per_projection, Metric, Projections};

fn load(name: &str) -> Tensor {
    let path = format!("{}/tests/data/{name}.npy", env!("CARGO_MANIFEST_DIR"));
    Tensor::read_npy(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn assert_all_close(got: &Tensor, want: &Tensor, tol: f64, what: &str) {
    let got = got.flatten_all().unwrap().to_vec1::<f64>().unwrap();
    let want = want.flatten_all().unwrap().to_vec1::<f64>().unwrap();
    assert_eq!(got.len(), want.len(), "{what}");
    for (i, (a, b)) in got.iter().zip(&want).enumerate() {
        assert_rel_close(*a, *b, tol, &format!("{what}[{i}]"));
    }
}

/// Runs one saved case with POT's projections: per-slice W2^2 and POT's sqrt(mean).
fn check_case(case: &str, pot_swd: f64) {
    let (x, y) = (load(&format!("{case}_X")), load(&format!("{case}_Y")));
    let p = Projections::from_tensor(load(&format!("{case}_P"))).unwrap();
    let per = sliced_wasserstein_per_projection(&x, &y, &p, Metric::SquaredW2).unwrap();
    assert_all_close(&per, &load(&format!("{case}_per_projection")), 1e-10, case);
    let swd2 = sliced_wasserstein(&x, &y, &p, Metric::SquaredW2).unwrap();
    assert_rel_close(
        swd2.to_scalar::<f64>().unwrap().sqrt(),
        pot_swd,
        1e-10,
        case,
    );
}

#[test]
fn equal_sizes_match_pot() {
    check_case("tiny", 0.9973773032416002);
}

#[test]
fn unequal_sizes_match_pot() {
    check_case("unequal", 0.5758763804708162);
}

#[test]
fn gradient_matches_pot_case() {
    let x = Var::from_tensor(&load("tiny_X")).unwrap();
    let p = Projections::from_tensor(load("tiny_P")).unwrap();
    let loss = sliced_wasserstein(x.as_tensor(), &load("tiny_Y"), &p, Metric::SquaredW2).unwrap();
    let grads = loss.backward().unwrap();
    let g = grads.get(x.as_tensor()).unwrap();
    assert_all_close(g, &load("tiny_grad"), 1e-10, "d swd2 / dX");
}

/// POT with 20000 random directions (seed 12345) on the `unequal` sets: mean W2^2 and its
/// standard error (per-slice std / sqrt(20000)), from the one-off run in `data/README.md`.
const POT_MC_SWD2: f64 = 0.324_694_570_189_500_76;
const POT_MC_STDERR: f64 = 0.000_388_912_122_784_581_8;

#[test]
fn random_directions_agree_with_pot_within_monte_carlo_error() {
    let (x, y) = (load("unequal_X"), load("unequal_Y"));
    let k = 4096;
    let p = Projections::random(3, k, &mut ChaCha8Rng::seed_from_u64(2024), &Device::Cpu).unwrap();
    let per = sliced_wasserstein_per_projection(&x, &y, &p, Metric::SquaredW2)
        .unwrap()
        .to_vec1::<f64>()
        .unwrap();
    let mean = per.iter().sum::<f64>() / k as f64;
    let var = per.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (k - 1) as f64;
    let stderr = (var / k as f64).sqrt();
    // Both are unbiased estimates of the same expectation over uniform directions; their
    // difference has standard deviation sqrt(se1^2 + se2^2). Four of those: a false failure
    // rate below 1e-4.
    let sigma = (stderr * stderr + POT_MC_STDERR * POT_MC_STDERR).sqrt();
    assert!(
        (mean - POT_MC_SWD2).abs() < 4.0 * sigma,
        "ours {mean} (se {stderr}) vs POT {POT_MC_SWD2} (se {POT_MC_STDERR})"
    );
}
