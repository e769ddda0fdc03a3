//! Metric properties of the sliced distance, on random small sets (proptest).

mod common;

use candle_core::Device;
use common::{columns, matrix, project};
use proptest::prelude::*;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use swd_loss::{sliced_wasserstein, Metric, Projections};

fn sw(x: &[Vec<f64>], y: &[Vec<f64>], p: &Projections, metric: Metric) -> f64 {
    sliced_wasserstein(&matrix(x), &matrix(y), p, metric)
        .unwrap()
        .to_scalar::<f64>()
        .unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-10 * (1.0 + a.abs().max(b.abs()))
}

/// Two point sets of the same dimension (sizes 1..8), a seed and a metric.
fn case() -> impl Strategy<Value = (Vec<Vec<f64>>, Vec<Vec<f64>>, u64, Metric)> {
    (1usize..4).prop_flat_map(|c| {
        let set = prop::collection::vec(prop::collection::vec(-5.0f64..5.0, c), 1..8);
        let metric = prop_oneof![Just(Metric::SquaredW2), Just(Metric::W1)];
        (set.clone(), set, any::<u64>(), metric)
    })
}

fn directions(c: usize, seed: u64) -> Projections {
    Projections::random(c, 6, &mut ChaCha8Rng::seed_from_u64(seed), &Device::Cpu).unwrap()
}

fn shifted(x: &[Vec<f64>], v: &[f64], t: f64) -> Vec<Vec<f64>> {
    x.iter()
        .map(|r| r.iter().zip(v).map(|(a, b)| a + t * b).collect())
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn zero_for_identical_sets((x, _y, seed, metric) in case()) {
        let p = directions(x[0].len(), seed);
        prop_assert_eq!(sw(&x, &x, &p, metric), 0.0);
    }

    #[test]
    fn symmetric_and_non_negative((x, y, seed, metric) in case()) {
        let p = directions(x[0].len(), seed);
        let (a, b) = (sw(&x, &y, &p, metric), sw(&y, &x, &p, metric));
        prop_assert!(a >= 0.0);
        prop_assert!(close(a, b), "{} vs {}", a, b);
    }

    #[test]
    fn invariant_to_permuting_points((x, y, seed, metric) in case()) {
        let p = directions(x[0].len(), seed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
        let (mut xp, mut yp) = (x.clone(), y.clone());
        xp.shuffle(&mut rng);
        yp.shuffle(&mut rng);
        let (a, b) = (sw(&x, &y, &p, metric), sw(&xp, &yp, &p, metric));
        prop_assert!(close(a, b), "{} vs {}", a, b);
    }

    /// Shifting a copy of X by t v gives exactly t^2 mean_k (θ_k·v)^2 (squared W2) or
    /// t mean_k |θ_k·v| (W1): strictly growing with t.
    #[test]
    fn grows_with_shift_of_one_set((x, _y, seed, metric) in case(), t1 in 0.01f64..2.0, dt in 0.01f64..2.0) {
        let c = x[0].len();
        let p = directions(c, seed);
        let v: Vec<f64> = (0..c).map(|i| 1.0 + i as f64).collect();
        let along: Vec<f64> = columns(p.as_tensor()).iter().map(|t| project(std::slice::from_ref(&v), t)[0]).collect();
        let (t2, k) = (t1 + dt, along.len() as f64);
        let expected = |t: f64| match metric {
            Metric::SquaredW2 => along.iter().map(|a| (t * a).powi(2)).sum::<f64>() / k,
            _ => along.iter().map(|a| (t * a).abs()).sum::<f64>() / k,
        };
        let (d1, d2) = (sw(&x, &shifted(&x, &v, t1), &p, metric), sw(&x, &shifted(&x, &v, t2), &p, metric));
        prop_assert!(close(d1, expected(t1)), "{} vs {}", d1, expected(t1));
        prop_assert!(close(d2, expected(t2)), "{} vs {}", d2, expected(t2));
        prop_assert!(d2 > d1);
    }

    /// For any two sets, squared W2 under a shift t v of Y is the quadratic
    /// SW(X, Y) + 2 t mean_k (θ_k·v)(mean Yθ_k - mean Xθ_k) + t^2 mean_k (θ_k·v)^2: it grows
    /// without bound once t passes the vertex.
    #[test]
    fn squared_w2_is_quadratic_in_shift((x, y, seed, _m) in case(), t in -3.0f64..3.0) {
        let c = x[0].len();
        let p = directions(c, seed);
        let v: Vec<f64> = (0..c).map(|i| 0.5 - i as f64).collect();
        let dirs = columns(p.as_tensor());
        let k = dirs.len() as f64;
        let mean = |s: &[Vec<f64>], d: &[f64]| project(s, d).iter().sum::<f64>() / s.len() as f64;
        let (mut lin, mut quad) = (0.0, 0.0);
        for d in &dirs {
            let a = project(std::slice::from_ref(&v), d)[0];
            lin += 2.0 * a * (mean(&y, d) - mean(&x, d)) / k;
            quad += a * a / k;
        }
        let base = sw(&x, &y, &p, Metric::SquaredW2);
        let got = sw(&x, &shifted(&y, &v, t), &p, Metric::SquaredW2);
        let want = base + t * lin + t * t * quad;
        prop_assert!((got - want).abs() <= 1e-9 * (1.0 + want.abs()), "{} vs {}", got, want);
    }
}
