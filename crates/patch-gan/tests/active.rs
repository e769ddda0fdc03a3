//! The active-set (submanifold) generator, and the library's dense form of it, against its dense
//! definition: the same generator with its input and every layer's output masked and BatchNorm
//! statistics taken over the mask's voxels, written here with plain candle ops and the dense
//! convolution, in f64. Values,
//! gradients (weights and noise) and the running statistics must agree, on random volumes and
//! masks, including empty and full masks and masks that touch the box's faces.

mod common;

use std::collections::HashMap;
use std::sync::Arc;

use candle_core::{DType, Device, Tensor, Var, D};
use candle_nn::{VarBuilder, VarMap};
use common::{random, values};
use patch_gan::{
    active, functional, ActiveSites, ConvConfig, Generator3d, Generator3dConfig, LEAKY_SLOPE,
    NORM_EPS,
};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Largest difference relative to the largest magnitude of `expected` (plus 1e-12 absolute).
fn max_rel_diff(actual: &[f64], expected: &[f64]) -> f64 {
    assert_eq!(actual.len(), expected.len());
    let scale = expected.iter().fold(0f64, |m, v| m.max(v.abs())) + 1e-12;
    actual
        .iter()
        .zip(expected)
        .fold(0f64, |m, (a, e)| m.max((a - e).abs()))
        / scale
}

/// Sums over the batch and the three spatial axes, keeping `(1, C, 1, 1, 1)`.
fn channel_sum(t: &Tensor) -> Tensor {
    t.sum_keepdim(0)
        .and_then(|t| t.sum_keepdim(2))
        .and_then(|t| t.sum_keepdim(3))
        .and_then(|t| t.sum_keepdim(D::Minus1))
        .unwrap()
}

/// The dense definition of `forward_residual_active` (train mode), and each BatchNorm's batch
/// mean and unbiased variance (conv bias included) per layer.
fn dense_reference(
    tensors: &HashMap<String, Tensor>,
    layers: usize,
    z: &Tensor,
    prev: &Tensor,
    mask: &Tensor,
) -> (Tensor, Vec<(Tensor, Tensor)>) {
    let cfg = ConvConfig::default().with_padding(1);
    let count = mask.sum_all().unwrap().to_scalar::<f64>().unwrap();
    let masked = |t: &Tensor| t.broadcast_mul(mask).unwrap();
    let conv = |x: &Tensor, name: &str| {
        let y = functional::conv3d(x, &tensors[&format!("{name}.weight")], cfg).unwrap();
        let bias = tensors[&format!("{name}.bias")]
            .reshape((1, (), 1, 1, 1))
            .unwrap();
        masked(&y.broadcast_add(&bias).unwrap())
    };
    let mut h = masked(&(z + prev).unwrap());
    let mut stats = Vec::new();
    for i in 0..layers - 1 {
        let c = conv(&h, &format!("blocks.{i}.conv"));
        let mean = (channel_sum(&c) / count).unwrap();
        let centred = masked(&c.broadcast_sub(&mean).unwrap());
        let sq = channel_sum(&centred.sqr().unwrap());
        let var = (&sq / count).unwrap();
        stats.push((
            mean.flatten_all().unwrap(),
            (sq / (count - 1.0)).unwrap().flatten_all().unwrap(),
        ));
        let gamma = tensors[&format!("blocks.{i}.bn.weight")]
            .reshape((1, (), 1, 1, 1))
            .unwrap();
        let beta = tensors[&format!("blocks.{i}.bn.bias")]
            .reshape((1, (), 1, 1, 1))
            .unwrap();
        let normed = centred
            .broadcast_div(&(var + NORM_EPS).unwrap().sqrt().unwrap())
            .unwrap()
            .broadcast_mul(&gamma)
            .unwrap()
            .broadcast_add(&beta)
            .unwrap();
        let activated = normed.maximum(&(&normed * LEAKY_SLOPE).unwrap()).unwrap();
        h = masked(&activated);
    }
    ((prev + conv(&h, "tail")).unwrap(), stats)
}

/// A generator with random weights (and BatchNorm affine parameters away from 1 and 0) in f64.
fn generator(channels: usize, layers: usize, seed: u64) -> (Generator3d, VarMap) {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let config = Generator3dConfig {
        layers,
        channels,
        in_channels: 4,
        out_channels: 4,
        kernel: 3,
    };
    let g = Generator3d::new(&config, vb).unwrap();
    for (i, (name, var)) in varmap.data().lock().unwrap().iter().enumerate() {
        if name.contains("running") {
            continue;
        }
        let r = random(var.dims(), seed + i as u64);
        let r = if name.ends_with("bn.weight") {
            r.affine(0.5, 1.0).unwrap()
        } else {
            r
        };
        var.set(&r).unwrap();
    }
    (g, varmap)
}

fn tensors(varmap: &VarMap) -> HashMap<String, Tensor> {
    let data = varmap.data().lock().unwrap();
    data.iter()
        .map(|(k, v)| (k.clone(), v.as_tensor().clone()))
        .collect()
}

/// Which voxels of the mask are active.
#[derive(Debug, Clone, Copy)]
enum MaskKind {
    Empty,
    Full,
    /// Each voxel active with this probability.
    Random(f64),
}

fn mask_tensor(batch: usize, dims: [usize; 3], kind: MaskKind, seed: u64) -> Tensor {
    let n = batch * dims.iter().product::<usize>();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let v: Vec<f64> = (0..n)
        .map(|_| match kind {
            MaskKind::Empty => 0.0,
            MaskKind::Full => 1.0,
            MaskKind::Random(p) => f64::from(u8::from(rng.random_bool(p))),
        })
        .collect();
    let [d, h, w] = dims;
    Tensor::from_vec(v, (batch, 1, d, h, w), &Device::Cpu).unwrap()
}

fn check_against_dense(
    batch: usize,
    dims: [usize; 3],
    channels: usize,
    layers: usize,
    kind: MaskKind,
    seed: u64,
) {
    let [d, h, w] = dims;
    let shape = [batch, 4, d, h, w];
    let (g, varmap) = generator(channels, layers, seed);
    let before = tensors(&varmap);
    let z = Var::from_tensor(&random(&shape, seed + 100)).unwrap();
    let prev = random(&shape, seed + 101);
    let weights = random(&shape, seed + 102);
    let mask = mask_tensor(batch, dims, kind, seed + 103);
    let sites = Arc::new(ActiveSites::from_mask(&mask, 3).unwrap());
    let sparse = g
        .forward_residual_active(z.as_tensor(), &prev, &sites, true)
        .unwrap();
    let after = tensors(&varmap);
    let sparse_grads = (&sparse * &weights)
        .unwrap()
        .sum_all()
        .unwrap()
        .backward()
        .unwrap();

    if sites.is_empty() {
        // Nothing active: the volume is the coarser one and the generator gets no gradient.
        assert_eq!(values(&sparse), values(&prev));
        for name in before.keys().filter(|n| !n.contains("running")) {
            assert!(sparse_grads.get(&before[name]).is_none(), "{name}");
        }
        return;
    }
    let (dense, stats) = dense_reference(&before, layers, z.as_tensor(), &prev, &mask);
    let diff = max_rel_diff(&values(&sparse), &values(&dense));
    assert!(
        diff < 1e-10,
        "values differ by {diff:e} ({kind:?}, {dims:?})"
    );

    // The library's own dense form (what GPUs run) is the same math.
    let library_dense = g
        .forward_residual_active_dense(z.as_tensor(), &prev, &sites, true)
        .unwrap();
    let diff = max_rel_diff(&values(&library_dense), &values(&dense));
    assert!(
        diff < 1e-10,
        "dense form differs by {diff:e} ({kind:?}, {dims:?})"
    );
    let library_grads = (&library_dense * &weights)
        .unwrap()
        .sum_all()
        .unwrap()
        .backward()
        .unwrap();
    let dense_grads = (&dense * &weights)
        .unwrap()
        .sum_all()
        .unwrap()
        .backward()
        .unwrap();
    let mut wrt: Vec<(String, &Tensor)> = before
        .iter()
        .filter(|(n, _)| !n.contains("running"))
        .map(|(n, t)| (n.clone(), t))
        .collect();
    wrt.push(("z".into(), z.as_tensor()));
    for (name, t) in wrt {
        let expected = dense_grads.get(t);
        let actual = sparse_grads.get(t);
        // The blocks' conv biases cancel in BatchNorm: the dense graph gives them a zero
        // gradient (up to rounding), the active path none at all.
        let expected_values = expected.map(values).unwrap_or_default();
        let actual_values = match actual {
            Some(a) => values(a),
            None => vec![0.0; expected_values.len()],
        };
        if name.starts_with("blocks") && name.ends_with("conv.bias") {
            assert!(expected_values.iter().all(|v| v.abs() < 1e-9), "{name}");
            assert!(actual_values.iter().all(|v| v.abs() < 1e-9), "{name}");
            continue;
        }
        let diff = max_rel_diff(&actual_values, &expected_values);
        // 1e-9, not the values' 1e-10: BatchNorm over one or two active sites divides by a
        // near-zero spread, which amplifies f64 rounding in the gradients (found by proptest:
        // 1.1e-10 on a 1 x 5 x 1 volume with a random mask, seed 835).
        assert!(
            diff < 1e-9,
            "gradient of {name} differs by {diff:e} ({kind:?}, {dims:?})"
        );
        let library = values(library_grads.get(t).unwrap());
        let diff = max_rel_diff(&library, &expected_values);
        assert!(diff < 1e-10, "dense form's gradient of {name}: {diff:e}");
    }

    // Running statistics: momentum 0.1 from (0, 1), over the active voxels only.
    for (i, (mean, unbiased)) in stats.iter().enumerate() {
        let running_mean = values(&after[&format!("blocks.{i}.bn.running_mean")]);
        let running_var = values(&after[&format!("blocks.{i}.bn.running_var")]);
        let expected_mean: Vec<f64> = values(mean).iter().map(|m| 0.1 * m).collect();
        let expected_var: Vec<f64> = values(unbiased).iter().map(|v| 0.9 + 0.1 * v).collect();
        if sites.len() > 1 {
            assert!(
                max_rel_diff(&running_mean, &expected_mean) < 1e-10,
                "running mean {i}"
            );
            assert!(
                max_rel_diff(&running_var, &expected_var) < 1e-10,
                "running var {i}"
            );
        }
    }
}

#[test]
fn a_full_mask_is_the_dense_generator() {
    let (g, _) = generator(3, 3, 7);
    let shape = [1, 4, 4, 3, 5];
    let (z, prev) = (random(&shape, 1), random(&shape, 2));
    let mask = Tensor::ones((1, 1, 4, 3, 5), DType::F64, &Device::Cpu).unwrap();
    let sites = Arc::new(ActiveSites::from_mask(&mask, 3).unwrap());
    let sparse = g.forward_residual_active(&z, &prev, &sites, true).unwrap();
    let dense = g.forward_residual(&z, &prev, true).unwrap();
    assert!(max_rel_diff(&values(&sparse), &values(&dense)) < 1e-12);
}

#[test]
fn faces_and_two_volumes_match_the_dense_definition() {
    // Masks of random voxels reach every face of these small boxes; two volumes share the
    // BatchNorm statistics.
    check_against_dense(2, [3, 4, 5], 3, 3, MaskKind::Random(0.5), 11);
    check_against_dense(1, [5, 5, 5], 2, 2, MaskKind::Full, 12);
    check_against_dense(1, [2, 3, 2], 2, 2, MaskKind::Empty, 13);
}

#[test]
fn gather_and_scatter_are_adjoint() {
    let x = random(&[2, 3, 3, 4, 2], 21);
    let mask = mask_tensor(2, [3, 4, 2], MaskKind::Random(0.4), 22);
    let sites = Arc::new(ActiveSites::from_mask(&mask, 3).unwrap());
    let f = random(&[1, 3, sites.len(), 1, 1], 23);
    // <gather(x), f> = <x, scatter(f)>, and scatter(gather(x)) = x masked.
    let lhs = (active::gather(&x, &sites).unwrap() * &f)
        .unwrap()
        .sum_all()
        .unwrap();
    let rhs = (&x * active::scatter(&f, &sites).unwrap())
        .unwrap()
        .sum_all()
        .unwrap();
    let (lhs, rhs) = (
        lhs.to_scalar::<f64>().unwrap(),
        rhs.to_scalar::<f64>().unwrap(),
    );
    assert!(
        (lhs - rhs).abs() < 1e-12 * (1.0 + lhs.abs()),
        "{lhs} vs {rhs}"
    );
    let round = active::scatter(&active::gather(&x, &sites).unwrap(), &sites).unwrap();
    assert_eq!(values(&round), values(&x.broadcast_mul(&mask).unwrap()));
    // Shapes that do not fit the set are refused, naming both.
    let err = active::gather(&random(&[1, 3, 3, 4, 2], 1), &sites)
        .unwrap_err()
        .to_string();
    assert!(err.contains("2 volumes of [3, 4, 2]"), "{err}");
    let err = active::scatter(&x, &sites).unwrap_err().to_string();
    assert!(
        err.contains(&format!("(1, C, {}, 1, 1)", sites.len())),
        "{err}"
    );
}

#[test]
fn active_convolution_matches_the_masked_dense_one_in_f32() {
    let dev = Device::Cpu;
    let x = random(&[1, 5, 6, 7, 8], 31).to_dtype(DType::F32).unwrap();
    let k = random(&[6, 5, 3, 3, 3], 32).to_dtype(DType::F32).unwrap();
    let mask = mask_tensor(1, [6, 7, 8], MaskKind::Random(0.3), 33)
        .to_dtype(DType::F32)
        .unwrap();
    let sites = Arc::new(ActiveSites::from_mask(&mask, 3).unwrap());
    let sparse =
        functional::conv3d_active(&active::gather(&x, &sites).unwrap(), &k, &sites).unwrap();
    let dense = functional::conv3d(
        &x.broadcast_mul(&mask).unwrap(),
        &k,
        ConvConfig::default().with_padding(1),
    )
    .unwrap();
    let dense = active::gather(&dense, &sites).unwrap();
    let as_f64 = |t: &Tensor| values(&t.to_dtype(DType::F64).unwrap());
    assert!(max_rel_diff(&as_f64(&sparse), &as_f64(&dense)) < 1e-5);
    // A kernel of another size than the set's, and features of another count, are refused.
    let k5 = Tensor::zeros((6, 5, 5, 5, 5), DType::F32, &dev).unwrap();
    let f = active::gather(&x, &sites).unwrap();
    let err = functional::conv3d_active(&f, &k5, &sites)
        .unwrap_err()
        .to_string();
    assert!(err.contains("(C_out, 5, 3, 3, 3)"), "{err}");
    let err = functional::conv3d_active(&x, &k, &sites)
        .unwrap_err()
        .to_string();
    assert!(err.contains("active-site features"), "{err}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn random_volumes_and_masks_match_the_dense_definition(
        batch in 1usize..=2,
        d in 1usize..=5, h in 1usize..=5, w in 1usize..=5,
        channels in 2usize..=3,
        layers in 2usize..=3,
        kind in prop_oneof![
            Just(MaskKind::Empty),
            Just(MaskKind::Full),
            (0.05f64..0.95).prop_map(MaskKind::Random),
        ],
        seed in 0u64..1000,
    ) {
        check_against_dense(batch, [d, h, w], channels, layers, kind, seed);
    }
}

#[test]
fn wide_convolutions_span_several_chunks_and_match_the_masked_dense_one() {
    // 64 channels each way: an im2col column of 1728 values, so a chunk holds 144 sites and the
    // ~500 sites here take several chunks in every pass (forward, input and weight gradients).
    let x = Var::from_tensor(&random(&[1, 64, 10, 10, 10], 41)).unwrap();
    let k = Var::from_tensor(&random(&[64, 64, 3, 3, 3], 42)).unwrap();
    let mask = mask_tensor(1, [10, 10, 10], MaskKind::Random(0.5), 43);
    let sites = Arc::new(ActiveSites::from_mask(&mask, 3).unwrap());
    assert!(sites.len() > 3 * 144, "{} sites", sites.len());
    let weights = random(&[1, 64, sites.len(), 1, 1], 44);
    let gathered = active::gather(x.as_tensor(), &sites).unwrap();
    let sparse = functional::conv3d_active(&gathered, k.as_tensor(), &sites).unwrap();
    let masked = x.as_tensor().broadcast_mul(&mask).unwrap();
    let dense = functional::conv3d(
        &masked,
        k.as_tensor(),
        ConvConfig::default().with_padding(1),
    );
    let dense = active::gather(&dense.unwrap(), &sites).unwrap();
    assert!(max_rel_diff(&values(&sparse), &values(&dense)) < 1e-12);
    let loss = |y: &Tensor| {
        (y * &weights)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap()
    };
    let (sparse_grads, dense_grads) = (loss(&sparse), loss(&dense));
    for (name, var) in [("input", &x), ("kernel", &k)] {
        let a = values(sparse_grads.get(var.as_tensor()).unwrap());
        let e = values(dense_grads.get(var.as_tensor()).unwrap());
        let diff = max_rel_diff(&a, &e);
        assert!(diff < 1e-12, "{name} gradient differs by {diff:e}");
    }
}
