//! Autograd gradients against central finite differences, in float64.

mod common;

use candle_core::{Device, Tensor};
use common::{check_gradient, matrix, pseudo_random_rows};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use swd_loss::{
    sliced_wasserstein, Metric, PatchPyramid, PatchPyramidConfig, Points, Projections, PyramidKind,
    TextureLoss, TextureLossConfig,
};

/// The losses are piecewise smooth (the sort order changes only on ties), so with distinct
/// projected values and a small step the differences are accurate to ~1e-8.
fn check_gradient_loss(x0: &Tensor, entries: &[usize], f: impl Fn(&Tensor) -> Tensor) {
    check_gradient(x0, entries, 1e-6, 1e-5, f);
}

fn point_sets(n: usize, m: usize) -> (Tensor, Tensor) {
    (
        matrix(&pseudo_random_rows(n, 3, 11, 1.0, 0.0)),
        matrix(&pseudo_random_rows(m, 3, 12, 1.3, 0.2)),
    )
}

#[test]
fn point_set_gradients_match_finite_differences() {
    let p = Projections::random(3, 5, &mut ChaCha8Rng::seed_from_u64(3), &Device::Cpu).unwrap();
    for (n, m) in [(6, 6), (6, 9), (7, 4)] {
        let (x, y) = point_sets(n, m);
        let all_x: Vec<usize> = (0..n * 3).collect();
        let all_y: Vec<usize> = (0..m * 3).collect();
        for metric in [Metric::SquaredW2, Metric::W1] {
            check_gradient_loss(&x, &all_x, |x| {
                sliced_wasserstein(x, &y, &p, metric).unwrap()
            });
            check_gradient_loss(&y, &all_y, |y| {
                sliced_wasserstein(&x, y, &p, metric).unwrap()
            });
        }
    }
}

#[test]
fn texture_loss_gradient_matches_finite_differences() {
    let dev = Device::Cpu;
    let image = |n: usize, s: usize, seed: u64| {
        let rows = pseudo_random_rows(n * 3 * s, s, seed, 0.5, 0.5);
        Tensor::from_vec(rows.concat(), (n, 3, s, s), &dev).unwrap()
    };
    let generated = image(2, 9, 21);
    let target = image(1, 11, 22);
    let entries: Vec<usize> = (0..generated.elem_count()).step_by(7).collect();
    for kind in [PyramidKind::Laplacian, PyramidKind::Gaussian] {
        let config = PatchPyramidConfig::default()
            .with_levels(2)
            .with_patch(3)
            .with_kind(kind);
        let loss = TextureLoss::new(
            PatchPyramid::new(config).unwrap(),
            TextureLossConfig::default(),
        )
        .unwrap()
        .with_layer_weights(vec![1.0, 0.5])
        .unwrap();
        let tgt = loss.target(&target).unwrap();
        let proj = loss
            .draw_projections(&tgt, &mut ChaCha8Rng::seed_from_u64(5))
            .unwrap();
        check_gradient_loss(&generated, &entries, |g| {
            loss.loss_with_projections(g, &tgt, &proj).unwrap()
        });
    }
}

/// With a seeded generator the random patch subsets are fixed (they never depend on the
/// values), so the subsampled loss is a function of the pixels whose gradient must match.
#[test]
fn subsampled_texture_loss_gradient_matches_finite_differences() {
    let dev = Device::Cpu;
    let image = |n: usize, s: usize, seed: u64| {
        let rows = pseudo_random_rows(n * 3 * s, s, seed, 0.5, 0.5);
        Tensor::from_vec(rows.concat(), (n, 3, s, s), &dev).unwrap()
    };
    let generated = image(2, 10, 31);
    let target = image(2, 12, 32);
    let entries: Vec<usize> = (0..generated.elem_count()).step_by(5).collect();
    let config = PatchPyramidConfig::default().with_levels(2).with_patch(3);
    let loss = TextureLoss::new(
        PatchPyramid::new(config).unwrap(),
        TextureLossConfig::default().with_points(Points::Random(20)),
    )
    .unwrap();
    let tgt = loss.target(&target).unwrap();
    check_gradient_loss(&generated, &entries, |g| {
        loss.loss(g, &tgt, &mut ChaCha8Rng::seed_from_u64(8))
            .unwrap()
    });
}
