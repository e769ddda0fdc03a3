//! The texture loss with the patch-pyramid extractor.

mod common;

use candle_core::{DType, Device, Tensor};
use common::{assert_rel_close, pseudo_random_rows};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use swd_loss::{
    sliced_wasserstein, Error, FeatureExtractor, Metric, PatchPyramid, PatchPyramidConfig, Points,
    PyramidKind, Slices, TextureLoss, TextureLossConfig,
};

fn image(n: usize, h: usize, w: usize, seed: u64) -> Tensor {
    let rows = pseudo_random_rows(n * 3 * h, w, seed, 0.5, 0.5);
    Tensor::from_vec(rows.concat(), (n, 3, h, w), &Device::Cpu).unwrap()
}

fn pyramid(levels: usize, patch: usize, kind: PyramidKind) -> PatchPyramid {
    PatchPyramid::new(
        PatchPyramidConfig::default()
            .with_levels(levels)
            .with_patch(patch)
            .with_kind(kind),
    )
    .unwrap()
}

fn scalar(t: &Tensor) -> f64 {
    t.to_dtype(DType::F64).unwrap().to_scalar::<f64>().unwrap()
}

/// All p x p patches of image `b` of a `(B, C, H, W)` level, flattened in (c, dy, dx) order.
fn explicit_patches(level: &Tensor, b: usize, p: usize) -> Tensor {
    let data = level.get(b).unwrap().to_vec3::<f64>().unwrap();
    let (c, h, w) = (data.len(), data[0].len(), data[0][0].len());
    let mut rows = Vec::new();
    for y in 0..=h - p {
        for x in 0..=w - p {
            let mut row = Vec::with_capacity(c * p * p);
            for ch in &data {
                for dy in 0..p {
                    for dx in 0..p {
                        row.push(ch[y + dy][x + dx]);
                    }
                }
            }
            rows.push(row);
        }
    }
    common::matrix(&rows)
}

#[test]
fn loss_equals_sliced_distance_of_explicit_patches() {
    for (kind, metric) in [
        (PyramidKind::Gaussian, Metric::SquaredW2),
        (PyramidKind::Laplacian, Metric::W1),
    ] {
        let pyr = pyramid(2, 3, kind);
        let loss = TextureLoss::new(
            pyr,
            TextureLossConfig::default()
                .with_metric(metric)
                .with_slices(Slices::Fixed(5)),
        )
        .unwrap()
        .with_layer_weights(vec![0.7, 1.3])
        .unwrap();
        let (gen, tgt) = (image(2, 8, 9, 1), image(1, 10, 10, 2));
        let target = loss.target(&tgt).unwrap();
        let proj = loss
            .draw_projections(&target, &mut ChaCha8Rng::seed_from_u64(9))
            .unwrap();
        let got = scalar(&loss.loss_with_projections(&gen, &target, &proj).unwrap());

        let (gen_levels, tgt_levels) = (pyr.levels(&gen).unwrap(), pyr.levels(&tgt).unwrap());
        let mut want = 0.0;
        for b in 0..2 {
            for (l, w) in [0.7, 1.3].into_iter().enumerate() {
                let x = explicit_patches(&gen_levels[l], b, 3);
                let y = explicit_patches(&tgt_levels[l], 0, 3);
                want += w * scalar(&sliced_wasserstein(&x, &y, &proj[l], metric).unwrap()) / 2.0;
            }
        }
        assert_rel_close(got, want, 1e-10, &format!("{kind:?} {metric:?}"));
    }
}

#[test]
fn pyramid_levels_of_a_constant_image() {
    let flat = (Tensor::ones((1, 3, 13, 10), DType::F64, &Device::Cpu).unwrap() * 0.25).unwrap();
    let gauss = pyramid(3, 2, PyramidKind::Gaussian).levels(&flat).unwrap();
    let lap = pyramid(3, 2, PyramidKind::Laplacian).levels(&flat).unwrap();
    let dims: Vec<_> = gauss.iter().map(|t| t.dims().to_vec()).collect();
    assert_eq!(
        dims,
        vec![vec![1, 3, 13, 10], vec![1, 3, 7, 5], vec![1, 3, 4, 3]]
    );
    let range = |t: &Tensor| {
        let v = t.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        v.iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), &a| (lo.min(a), hi.max(a)))
    };
    // The blur's weights sum to one and edges are replicated, so constants stay constant and
    // band-pass levels vanish.
    for g in &gauss {
        let (lo, hi) = range(g);
        assert!((lo - 0.25).abs() < 1e-15 && (hi - 0.25).abs() < 1e-15);
    }
    for l in &lap[..2] {
        let (lo, hi) = range(l);
        assert!(lo.abs() < 1e-15 && hi.abs() < 1e-15);
    }
    assert_eq!(range(&lap[2]), range(&gauss[2]));
}

#[test]
fn batches_average_per_image_losses() {
    let loss = TextureLoss::new(
        pyramid(2, 3, PyramidKind::Laplacian),
        TextureLossConfig::default(),
    )
    .unwrap();
    let gen = image(2, 10, 10, 3);
    let targets = image(2, 12, 11, 4);
    let pair_target = loss.target(&targets).unwrap();
    let proj = loss
        .draw_projections(&pair_target, &mut ChaCha8Rng::seed_from_u64(1))
        .unwrap();
    let value = |g: &Tensor, t: &Tensor| {
        scalar(
            &loss
                .loss_with_projections(g, &loss.target(t).unwrap(), &proj)
                .unwrap(),
        )
    };
    let one = |t: &Tensor, i: usize| t.narrow(0, i, 1).unwrap();

    let paired = value(&gen, &targets);
    let want =
        (value(&one(&gen, 0), &one(&targets, 0)) + value(&one(&gen, 1), &one(&targets, 1))) / 2.0;
    assert_rel_close(paired, want, 1e-12, "paired targets");

    let shared = value(&gen, &one(&targets, 1));
    let want =
        (value(&one(&gen, 0), &one(&targets, 1)) + value(&one(&gen, 1), &one(&targets, 1))) / 2.0;
    assert_rel_close(shared, want, 1e-12, "one target for the batch");

    let three = loss.target(&image(3, 12, 11, 5)).unwrap();
    assert!(matches!(
        loss.loss_with_projections(&gen, &three, &proj),
        Err(Error::InvalidArgument { .. })
    ));
}

#[test]
fn layer_weights_scale_layers_linearly() {
    let make = |w: Vec<f64>| {
        TextureLoss::new(
            pyramid(2, 3, PyramidKind::Laplacian),
            TextureLossConfig::default(),
        )
        .unwrap()
        .with_layer_weights(w)
        .unwrap()
    };
    let (gen, tgt) = (image(1, 12, 12, 6), image(1, 12, 12, 7));
    let base = make(vec![1.0, 1.0]);
    let target = base.target(&tgt).unwrap();
    let proj = base
        .draw_projections(&target, &mut ChaCha8Rng::seed_from_u64(2))
        .unwrap();
    let value = |w: Vec<f64>| scalar(&make(w).loss_with_projections(&gen, &target, &proj).unwrap());
    let (a, b) = (value(vec![1.0, 0.0]), value(vec![0.0, 1.0]));
    assert!(a > 0.0 && b > 0.0);
    assert_rel_close(value(vec![2.0, 3.0]), 2.0 * a + 3.0 * b, 1e-12, "weights");

    let pyr = pyramid(2, 3, PyramidKind::Laplacian);
    let cfg = TextureLossConfig::default();
    assert!(TextureLoss::new(pyr, cfg)
        .unwrap()
        .with_layer_weights(vec![1.0])
        .is_err());
    assert!(TextureLoss::new(pyr, cfg)
        .unwrap()
        .with_layer_weights(vec![1.0, -1.0])
        .is_err());
    assert!(TextureLoss::new(pyr, cfg)
        .unwrap()
        .with_layer_weights(vec![1.0, f64::NAN])
        .is_err());
    assert!(TextureLoss::new(pyr, cfg.with_slices(Slices::Fixed(0))).is_err());
}

#[test]
fn zero_for_same_image_and_growing_with_offset() {
    let loss = TextureLoss::new(
        pyramid(3, 3, PyramidKind::Gaussian),
        TextureLossConfig::default(),
    )
    .unwrap();
    let img = image(1, 16, 16, 8);
    let target = loss.target(&img).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    assert_eq!(scalar(&loss.loss(&img, &target, &mut rng).unwrap()), 0.0);
    let proj = loss.draw_projections(&target, &mut rng).unwrap();
    let at = |s: f64| {
        scalar(
            &loss
                .loss_with_projections(&(&img + s).unwrap(), &target, &proj)
                .unwrap(),
        )
    };
    let values: Vec<f64> = [0.01, 0.05, 0.2, 1.0].into_iter().map(at).collect();
    assert!(values.windows(2).all(|w| w[1] > w[0]), "{values:?}");
}

#[test]
fn resampling_is_seeded_and_slice_counts_follow_config() {
    let pyr = pyramid(2, 3, PyramidKind::Laplacian);
    let loss = TextureLoss::new(
        pyr,
        TextureLossConfig::default().with_slices(Slices::MatchDim),
    )
    .unwrap();
    let (gen, tgt) = (image(1, 10, 10, 9), image(1, 10, 10, 10));
    let target = loss.target(&tgt).unwrap();
    let draw = |seed| {
        loss.draw_projections(&target, &mut ChaCha8Rng::seed_from_u64(seed))
            .unwrap()
    };
    assert!(draw(0).iter().all(|p| p.count() == 27 && p.dim() == 27));
    let value = |seed| {
        scalar(
            &loss
                .loss(&gen, &target, &mut ChaCha8Rng::seed_from_u64(seed))
                .unwrap(),
        )
    };
    assert_eq!(value(1), value(1));
    assert_ne!(value(1), value(2));
    let fixed = TextureLoss::new(pyr, TextureLossConfig::default()).unwrap();
    assert!(fixed
        .draw_projections(&target, &mut ChaCha8Rng::seed_from_u64(0))
        .unwrap()
        .iter()
        .all(|p| p.count() == 64));
}

#[test]
fn bad_images_are_errors() {
    let pyr = pyramid(3, 7, PyramidKind::Laplacian);
    // 3 levels of 20 px: 20, 10, 5 < 7.
    let small = Tensor::zeros((1, 3, 20, 20), DType::F32, &Device::Cpu).unwrap();
    let err = pyr.extract(&small).unwrap_err();
    assert!(
        matches!(err, Error::InvalidArgument { .. }) && err.to_string().contains("5x5"),
        "{err}"
    );
    let rank3 = Tensor::zeros((3, 20, 20), DType::F32, &Device::Cpu).unwrap();
    assert!(matches!(
        pyr.extract(&rank3),
        Err(Error::InvalidArgument { .. })
    ));
    assert!(PatchPyramid::new(PatchPyramidConfig::default().with_levels(0)).is_err());
    let loss = TextureLoss::new(pyr, TextureLossConfig::default()).unwrap();
    let target = loss
        .target(&Tensor::ones((1, 3, 32, 32), DType::F32, &Device::Cpu).unwrap())
        .unwrap();
    let nan = Tensor::full(f32::NAN, (1, 3, 32, 32), &Device::Cpu).unwrap();
    let err = loss
        .loss(&nan, &target, &mut ChaCha8Rng::seed_from_u64(0))
        .unwrap_err();
    assert!(matches!(err, Error::NonFinite { .. }), "{err}");
}

/// Rows `positions` of an `(N, C)` point set.
fn rows(points: &Tensor, positions: &[usize]) -> Tensor {
    let index: Vec<u32> = positions.iter().map(|&i| i as u32).collect();
    let index = Tensor::from_vec(index, positions.len(), &Device::Cpu).unwrap();
    points.index_select(&index, 0).unwrap()
}

/// The subsampled loss is the sliced distance between the explicitly unfolded patches at the
/// drawn positions: directions first (as `draw_projections`), then per level a sorted uniform
/// subset of the generated batch's positions and one of the target's, from the same generator.
/// With at least as many points as a level holds, every point is used and the loss is the full
/// one along the same directions.
#[test]
fn random_points_are_a_uniform_subset_per_level() {
    let pyr = pyramid(2, 3, PyramidKind::Laplacian);
    let (gen, tgt) = (image(2, 9, 10, 41), image(1, 11, 9, 42));
    let n = 13;
    let loss = TextureLoss::new(
        pyr,
        TextureLossConfig::default()
            .with_slices(Slices::Fixed(6))
            .with_points(Points::Random(n)),
    )
    .unwrap();
    let target = loss.target(&tgt).unwrap();
    let got = scalar(
        &loss
            .loss(&gen, &target, &mut ChaCha8Rng::seed_from_u64(3))
            .unwrap(),
    );

    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let proj = loss.draw_projections(&target, &mut rng).unwrap();
    let (gen_levels, tgt_levels) = (pyr.levels(&gen).unwrap(), pyr.levels(&tgt).unwrap());
    let mut draw = |total: usize| -> Vec<usize> {
        if n >= total {
            return (0..total).collect();
        }
        let mut picked = rand::seq::index::sample(&mut rng, total, n).into_vec();
        picked.sort_unstable();
        picked
    };
    let mut want = 0.0;
    let mut subsets = Vec::new();
    for l in 0..2 {
        let all_gen: Vec<Tensor> = (0..2)
            .map(|b| explicit_patches(&gen_levels[l], b, 3))
            .collect();
        let all_tgt = explicit_patches(&tgt_levels[l], 0, 3);
        let g = draw(all_gen[0].dim(0).unwrap());
        let t = draw(all_tgt.dim(0).unwrap());
        subsets.push((g.len(), t.len()));
        for x in &all_gen {
            let d = sliced_wasserstein(
                &rows(x, &g),
                &rows(&all_tgt, &t),
                &proj[l],
                Metric::SquaredW2,
            );
            want += scalar(&d.unwrap()) / 2.0;
        }
    }
    // Level 0 (9x10 and 11x9 images: 56 and 63 patches) is subsampled, level 1 (9 and 12
    // patches) is not.
    assert_eq!(subsets, vec![(n, n), (9, 12)]);
    assert_rel_close(got, want, 1e-10, "subsampled loss");

    let everything = TextureLoss::new(
        pyr,
        TextureLossConfig::default()
            .with_slices(Slices::Fixed(6))
            .with_points(Points::Random(1000)),
    )
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let proj = everything.draw_projections(&target, &mut rng).unwrap();
    let full = scalar(
        &everything
            .loss_with_projections(&gen, &target, &proj)
            .unwrap(),
    );
    let sampled = everything
        .loss(&gen, &target, &mut ChaCha8Rng::seed_from_u64(3))
        .unwrap();
    assert_eq!(scalar(&sampled), full);
}

/// A target of many images, selected per step, gives the loss of the target made of the
/// selected images.
#[test]
fn selected_targets_equal_targets_of_the_selection() {
    let loss = TextureLoss::new(
        pyramid(2, 3, PyramidKind::Laplacian),
        TextureLossConfig::default(),
    )
    .unwrap();
    let views = image(4, 12, 12, 43);
    let all = loss.target(&views).unwrap();
    let gen = image(2, 12, 12, 44);
    let picked = [3usize, 1];
    let index = Tensor::new(&[3u32, 1], &Device::Cpu).unwrap();
    let direct = loss
        .target(&views.index_select(&index, 0).unwrap())
        .unwrap();
    let proj = loss
        .draw_projections(&direct, &mut ChaCha8Rng::seed_from_u64(1))
        .unwrap();
    let a = scalar(
        &loss
            .loss_with_projections(&gen, &all.select(&picked).unwrap(), &proj)
            .unwrap(),
    );
    let b = scalar(&loss.loss_with_projections(&gen, &direct, &proj).unwrap());
    assert_eq!(a, b);
    assert!(all.select(&[4]).is_err());
    assert!(all.select(&[]).is_err());
    let none = TextureLossConfig::default().with_points(Points::Random(0));
    assert!(TextureLoss::new(pyramid(2, 3, PyramidKind::Laplacian), none).is_err());
}
