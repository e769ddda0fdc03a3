//! Shapes, checkpoint names and receptive fields of the paper's networks (tables "generators",
//! "G_N" and "discriminators").

// Loading weights by memory map is `unsafe` (the file must not change meanwhile).
#![allow(unsafe_code)]

use std::collections::HashMap;

use candle_core::{DType, Device, Module, ModuleT, Tensor};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{
    receptive_field, upsample_bilinear2x, Generator3d, Generator3dConfig, PatchDiscriminator2d,
    PatchDiscriminator2dConfig, PatchDiscriminator3d, PatchDiscriminatorConfig, Upsampler2d,
    Upsampler2dConfig,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random(shape: &[usize], seed: u64) -> Tensor {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = shape.iter().product();
    let v: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
}

fn shapes(varmap: &VarMap) -> HashMap<String, Vec<usize>> {
    varmap
        .data()
        .lock()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.clone(), v.dims().to_vec()))
        .collect()
}

/// Indices where `a` and `b` differ by more than rounding: Winograd's F(4, 3) mixes a whole
/// tile of inputs and takes them apart again, so voxels outside the receptive field move by a
/// few ulp (about 1e-16 relative here, against 1e-3 and more inside it).
fn changed(a: &Tensor, b: &Tensor) -> Vec<usize> {
    let a: Vec<f64> = a.flatten_all().unwrap().to_vec1().unwrap();
    let b: Vec<f64> = b.flatten_all().unwrap().to_vec1().unwrap();
    let scale = a.iter().fold(0f64, |m, v| m.max(v.abs()));
    (0..a.len())
        .filter(|&i| (a[i] - b[i]).abs() > 1e-12 * scale)
        .collect()
}

#[test]
fn generator_matches_the_table() {
    for layers in [5, 7] {
        for scale in [1, 2] {
            let varmap = VarMap::new();
            let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
            let cfg = Generator3dConfig::for_scale(scale, layers);
            let g = Generator3d::new(&cfg, vb).unwrap();
            let ic = if scale == 1 { 3 } else { 4 };
            let s = shapes(&varmap);
            assert_eq!(s["blocks.0.conv.weight"], [32, ic, 3, 3, 3]);
            for i in 1..layers - 1 {
                assert_eq!(s[&format!("blocks.{i}.conv.weight")], [32, 32, 3, 3, 3]);
                assert_eq!(s[&format!("blocks.{i}.bn.running_var")], [32]);
            }
            assert_eq!(s["tail.weight"], [4, 32, 3, 3, 3]);
            assert_eq!(s["tail.bias"], [4]);
            // L convs (weight + bias) and L - 1 batch norms (4 tensors each).
            assert_eq!(s.len(), 2 * layers + 4 * (layers - 1));
            let y = g.forward_t(&random(&[2, ic, 5, 6, 7], 1), true).unwrap();
            assert_eq!(y.dims(), &[2, 4, 5, 6, 7]);
        }
    }
}

#[test]
fn generator_receptive_field_is_2l_plus_1() {
    let layers = 5;
    let cfg = Generator3dConfig::for_scale(2, layers);
    assert_eq!(cfg.receptive_field(), 11);
    let varmap = VarMap::new();
    let g = Generator3d::new(
        &cfg,
        VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu),
    )
    .unwrap();
    let size = 15;
    let x = random(&[1, 4, size, size, size], 2);
    let centre = [7, 6, 8];
    let bump = Tensor::zeros((1, 4, size, size, size), DType::F64, &Device::Cpu)
        .unwrap()
        .slice_assign(
            &[
                0..1,
                1..2,
                centre[0]..centre[0] + 1,
                centre[1]..centre[1] + 1,
                centre[2]..centre[2] + 1,
            ],
            &Tensor::ones((1, 1, 1, 1, 1), DType::F64, &Device::Cpu).unwrap(),
        )
        .unwrap();
    // Eval mode: batch statistics would couple every voxel to every other one.
    let y0 = g.forward_t(&x, false).unwrap();
    let y1 = g.forward_t(&(&x + bump).unwrap(), false).unwrap();
    let hits = changed(&y0, &y1);
    let half = layers;
    let expected: Vec<usize> = (0..4 * size.pow(3))
        .filter(|&i| {
            let v = i % size.pow(3);
            let p = [v / (size * size), (v / size) % size, v % size];
            (0..3).all(|a| p[a].abs_diff(centre[a]) <= half)
        })
        .collect();
    assert_eq!(hits, expected);
}

#[test]
fn residual_form_adds_the_upsampled_volume() {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let g = Generator3d::new(&Generator3dConfig::for_scale(3, 5), vb).unwrap();
    let z = random(&[1, 4, 4, 4, 4], 3);
    let prev = random(&[1, 4, 4, 4, 4], 4);
    let v = g.forward_residual(&z, &prev, false).unwrap();
    let expected = (&prev + g.forward_t(&(&z + &prev).unwrap(), false).unwrap()).unwrap();
    assert!(changed(&v, &expected).is_empty());
    let g1 = Generator3d::new(
        &Generator3dConfig::for_scale(1, 5),
        VarBuilder::from_varmap(&VarMap::new(), DType::F64, &Device::Cpu),
    )
    .unwrap();
    assert!(g1.forward_residual(&z, &prev, false).is_err());
    assert!(Generator3d::new(
        &Generator3dConfig::default().with_layers(1),
        VarBuilder::from_varmap(&VarMap::new(), DType::F64, &Device::Cpu)
    )
    .is_err());
}

#[test]
fn generator_checkpoint_round_trips_through_safetensors() {
    let dev = Device::Cpu;
    let varmap = VarMap::new();
    let cfg = Generator3dConfig::for_scale(2, 5);
    let g = Generator3d::new(
        &cfg,
        VarBuilder::from_varmap(&varmap, DType::F32, &dev).pp("g2"),
    )
    .unwrap();
    let x = random(&[1, 4, 5, 5, 5], 5).to_dtype(DType::F32).unwrap();
    g.forward_t(&x, true).unwrap(); // moves the running stats away from their init
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.safetensors");
    varmap.save(&path).unwrap();
    // SAFETY: the file is ours and not modified while mapped.
    let vb = unsafe { VarBuilder::from_mmaped_safetensors(&[&path], DType::F32, &dev) }.unwrap();
    let loaded = Generator3d::new(&cfg, vb.pp("g2")).unwrap();
    let a = g.forward_t(&x, false).unwrap();
    let b = loaded.forward_t(&x, false).unwrap();
    assert!(changed(
        &a.to_dtype(DType::F64).unwrap(),
        &b.to_dtype(DType::F64).unwrap()
    )
    .is_empty());
}

#[test]
fn discriminator_matches_the_table_and_its_receptive_field() {
    for layers in [5, 7] {
        for in_channels in [4, 6] {
            let varmap = VarMap::new();
            let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
            let cfg = PatchDiscriminator2dConfig::default()
                .with_layers(layers)
                .with_in_channels(in_channels);
            let d = PatchDiscriminator2d::new(&cfg, vb).unwrap();
            let s = shapes(&varmap);
            assert_eq!(s["blocks.0.conv.weight"], [32, in_channels, 3, 3]);
            for i in 1..layers - 1 {
                assert_eq!(s[&format!("blocks.{i}.conv.weight")], [32, 32, 3, 3]);
            }
            assert_eq!(s["tail.weight"], [1, 32, 3, 3]);
            assert_eq!(s.len(), 2 * layers);

            let (h, w) = (2 * layers + 9, 2 * layers + 6);
            let x = random(&[1, in_channels, h, w], 6);
            let map = d.forward(&x).unwrap();
            assert_eq!(map.dims(), &[1, 1, h - 2 * layers, w - 2 * layers]);
            assert_eq!(d.score(&x).unwrap().dims(), &[1]);

            // Perturb one pixel: exactly the outputs whose window covers it change.
            let field = receptive_field(layers);
            let (py, px) = (layers + 3, layers + 1);
            let bump = Tensor::zeros((1, in_channels, h, w), DType::F64, &Device::Cpu)
                .unwrap()
                .slice_assign(
                    &[0..1, 0..1, py..py + 1, px..px + 1],
                    &Tensor::ones((1, 1, 1, 1), DType::F64, &Device::Cpu).unwrap(),
                )
                .unwrap();
            let hits = changed(&map, &d.forward(&(&x + bump).unwrap()).unwrap());
            let ow = w - 2 * layers;
            let expected: Vec<usize> = (0..(h - 2 * layers) * ow)
                .filter(|&i| {
                    let (oy, ox) = (i / ow, i % ow);
                    (oy..oy + field).contains(&py) && (ox..ox + field).contains(&px)
                })
                .collect();
            assert_eq!(hits, expected, "L = {layers}");
            // A pixel in the middle of a large enough image reaches a field x field square.
            assert_eq!(hits.len(), field.min(h - 2 * layers) * field.min(ow));
        }
    }
}

#[test]
fn discriminator_rejects_images_smaller_than_its_field() {
    let d = PatchDiscriminator2d::new(
        &PatchDiscriminator2dConfig::default(),
        VarBuilder::from_varmap(&VarMap::new(), DType::F64, &Device::Cpu),
    )
    .unwrap();
    assert!(d.forward(&random(&[1, 4, 10, 20], 7)).is_err());
}

/// The critic of volumes: PyTorch's Conv3d shapes under the 2D critic's names, a patch map
/// `2 L` smaller along each axis whose values each see one field^3 cube, and with kernels that
/// are zero outside their middle depth slice it is the 2D critic of those slices, run on every
/// depth slice of the volume.
#[test]
fn volume_discriminator_is_the_image_critic_along_a_third_axis() {
    let cfg = PatchDiscriminatorConfig {
        layers: 3,
        channels: 5,
        in_channels: 4,
    };
    let varmap = VarMap::new();
    let d3 = PatchDiscriminator3d::new(
        &cfg,
        VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu),
    )
    .unwrap();
    let s = shapes(&varmap);
    assert_eq!(s["blocks.0.conv.weight"], [5, 4, 3, 3, 3]);
    assert_eq!(s["blocks.1.conv.weight"], [5, 5, 3, 3, 3]);
    assert_eq!(s["tail.weight"], [1, 5, 3, 3, 3]);
    assert_eq!(s.len(), 6);
    let (d, h, w) = (9, 10, 8);
    let x = random(&[2, 4, d, h, w], 9);
    let map = d3.forward(&x).unwrap();
    assert_eq!(map.dims(), &[2, 1, d - 6, h - 6, w - 6]);

    // One voxel reaches exactly the outputs whose field^3 window covers it.
    let field = receptive_field(cfg.layers);
    let (pz, py, px) = (4, 5, 3);
    let bump = Tensor::zeros((2, 4, d, h, w), DType::F64, &Device::Cpu)
        .unwrap()
        .slice_assign(
            &[1..2, 2..3, pz..pz + 1, py..py + 1, px..px + 1],
            &Tensor::ones((1, 1, 1, 1, 1), DType::F64, &Device::Cpu).unwrap(),
        )
        .unwrap();
    let hits = changed(&map, &d3.forward(&(&x + bump).unwrap()).unwrap());
    let (od, oh, ow) = (d - 6, h - 6, w - 6);
    let expected: Vec<usize> = (0..2 * od * oh * ow)
        .filter(|&i| {
            let (b, z, y, x) = (i / (od * oh * ow), i / (oh * ow) % od, i / ow % oh, i % ow);
            b == 1
                && (z..z + field).contains(&pz)
                && (y..y + field).contains(&py)
                && (x..x + field).contains(&px)
        })
        .collect();
    assert_eq!(hits, expected);

    // Kernels flat in depth: the 2D critic of each depth slice.
    let flat_varmap = VarMap::new();
    let d2 = PatchDiscriminator2d::new(
        &cfg,
        VarBuilder::from_varmap(&flat_varmap, DType::F64, &Device::Cpu),
    )
    .unwrap();
    let volume_vars = varmap.data().lock().unwrap();
    for (name, var2) in flat_varmap.data().lock().unwrap().iter() {
        let var3 = &volume_vars[name];
        if var3.rank() == 1 {
            var3.set(var2.as_tensor()).unwrap();
            continue;
        }
        let middle = var3.as_tensor().narrow(2, 1, 1).unwrap();
        var2.set(&middle.squeeze(2).unwrap()).unwrap();
        let flat = middle.pad_with_zeros(2, 1, 1).unwrap();
        var3.set(&flat).unwrap();
    }
    let map = d3.forward(&x).unwrap();
    for z in 0..od {
        let slice = x.narrow(2, z + cfg.layers, 1).unwrap().squeeze(2).unwrap();
        let want = d2.forward(&slice).unwrap();
        let got = map.narrow(2, z, 1).unwrap().squeeze(2).unwrap();
        let diff = (got - want)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar::<f64>()
            .unwrap();
        assert!(diff < 1e-12, "depth slice {z}: {diff}");
    }

    // Images, or volumes smaller than the field, are refused.
    assert!(d3.forward(&random(&[1, 4, 9, 9], 10)).is_err());
    assert!(d3.forward(&random(&[1, 4, 9, 6, 9], 10)).is_err());
}

#[test]
fn upsampler_matches_the_table() {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let g = Upsampler2d::new(&Upsampler2dConfig::default(), vb).unwrap();
    let s = shapes(&varmap);
    assert_eq!(s["up.weight"], [4 * 32, 3, 3, 3]);
    assert_eq!(s["blocks.0.conv.weight"], [16, 32, 3, 3]);
    assert_eq!(s["blocks.1.conv.weight"], [8, 16, 3, 3]);
    assert_eq!(s["blocks.2.conv.weight"], [8, 8, 3, 3]);
    assert_eq!(s["tail.weight"], [3, 8, 3, 3]);
    assert_eq!(s.len(), 10);
    let x = random(&[2, 3, 10, 12], 8);
    assert_eq!(g.forward(&x).unwrap().dims(), &[2, 3, 20, 24]);
}

#[test]
fn upsampler_with_zero_weights_is_the_naive_upsample() {
    let vb = VarBuilder::zeros(DType::F64, &Device::Cpu);
    let g = Upsampler2d::new(&Upsampler2dConfig::default(), vb).unwrap();
    let x = random(&[1, 3, 5, 4], 9);
    assert!(changed(&g.forward(&x).unwrap(), &upsample_bilinear2x(&x).unwrap()).is_empty());
}

#[test]
fn bilinear2x_matches_candle_and_is_differentiable() {
    let x = random(&[2, 3, 5, 7], 10);
    let ours = upsample_bilinear2x(&x).unwrap();
    let candle = x.upsample_bilinear2d(10, 14, false).unwrap();
    let err = (ours - candle)
        .unwrap()
        .abs()
        .unwrap()
        .flatten_all()
        .unwrap()
        .max(0)
        .unwrap();
    assert!(err.to_scalar::<f64>().unwrap() < 1e-12);
    // Each input pixel spreads weights summing to 4 (it is one of 4 neighbours of 4 outputs).
    let v = candle_core::Var::from_tensor(&x).unwrap();
    let grads = upsample_bilinear2x(v.as_tensor())
        .unwrap()
        .sum_all()
        .unwrap()
        .backward()
        .unwrap();
    let g: Vec<f64> = grads
        .get(&v)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    assert!(g.iter().all(|g| (g - 4.0).abs() < 1e-12));
}
