//! The VGG-19 extractor: loading torchvision-named safetensors and the forward pass, checked
//! against a float64 hand-written network on random weights we generate.

mod common;

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
use common::check_gradient;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use swd_loss::{
    Error, FeatureExtractor, Padding, Pooling, TextureLoss, TextureLossConfig, Vgg19, Vgg19Config,
    VggLayer,
};

/// torchvision indices and shapes of the first three convolutions (conv1_1, conv1_2, conv2_1).
const CONVS: [(usize, usize, usize); 3] = [(0, 3, 64), (2, 64, 64), (5, 64, 128)];

/// Random weights (uniform, He-like scale), as row-major f64 vectors per tensor name.
fn random_weights(seed: u64) -> Vec<(String, Vec<usize>, Vec<f64>)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    for (idx, cin, cout) in CONVS {
        let a = (6.0 / (9 * cin) as f64).sqrt();
        let w: Vec<f64> = (0..cout * cin * 9)
            .map(|_| rng.random_range(-a..a))
            .collect();
        let b: Vec<f64> = (0..cout).map(|_| rng.random_range(-0.1..0.1)).collect();
        out.push((format!("features.{idx}.weight"), vec![cout, cin, 3, 3], w));
        out.push((format!("features.{idx}.bias"), vec![cout], b));
    }
    out
}

fn save(weights: &[(String, Vec<usize>, Vec<f64>)], path: &std::path::Path) {
    let map: HashMap<String, Tensor> = weights
        .iter()
        .map(|(name, shape, v)| {
            let t = Tensor::from_vec(v.clone(), shape.as_slice(), &Device::Cpu).unwrap();
            (name.clone(), t.to_dtype(DType::F32).unwrap())
        })
        .collect();
    candle_core::safetensors::save(&map, path).unwrap();
}

/// A `(C, H, W)` image in f64.
type Image = Vec<Vec<Vec<f64>>>;

fn conv3x3_relu(x: &Image, w: &[f64], b: &[f64], padding: Padding) -> Image {
    let (cin, h, wd) = (x.len(), x[0].len(), x[0][0].len());
    let at = |c: usize, y: isize, xx: isize| -> f64 {
        let inside = |v: isize, n: usize| (0..n as isize).contains(&v);
        match padding {
            Padding::Zeros if !inside(y, h) || !inside(xx, wd) => 0.0,
            Padding::Zeros => x[c][y as usize][xx as usize],
            _ => {
                let reflect = |v: isize, n: usize| -> usize {
                    if n == 1 {
                        0
                    } else if v < 0 {
                        1
                    } else if v >= n as isize {
                        n - 2
                    } else {
                        v as usize
                    }
                };
                x[c][reflect(y, h)][reflect(xx, wd)]
            }
        }
    };
    (0..b.len())
        .map(|o| {
            (0..h)
                .map(|y| {
                    (0..wd)
                        .map(|xx| {
                            let mut s = b[o];
                            for c in 0..cin {
                                for dy in 0..3 {
                                    for dx in 0..3 {
                                        let wv = w[((o * cin + c) * 3 + dy) * 3 + dx];
                                        s += wv
                                            * at(
                                                c,
                                                y as isize + dy as isize - 1,
                                                xx as isize + dx as isize - 1,
                                            );
                                    }
                                }
                            }
                            s.max(0.0)
                        })
                        .collect()
                })
                .collect()
        })
        .collect()
}

fn pool2(x: &Image, pooling: Pooling) -> Image {
    x.iter()
        .map(|ch| {
            (0..ch.len() / 2)
                .map(|y| {
                    (0..ch[0].len() / 2)
                        .map(|xx| {
                            let v = [
                                ch[2 * y][2 * xx],
                                ch[2 * y][2 * xx + 1],
                                ch[2 * y + 1][2 * xx],
                                ch[2 * y + 1][2 * xx + 1],
                            ];
                            match pooling {
                                Pooling::Max => v.iter().copied().fold(f64::MIN, f64::max),
                                _ => v.iter().sum::<f64>() / 4.0,
                            }
                        })
                        .collect()
                })
                .collect()
        })
        .collect()
}

/// relu1_1 and relu2_1 of the hand-written network.
fn reference(
    img: &Image,
    weights: &[(String, Vec<usize>, Vec<f64>)],
    pooling: Pooling,
    padding: Padding,
) -> (Image, Image) {
    let mean = [0.485, 0.456, 0.406];
    let std = [0.229, 0.224, 0.225];
    let x: Image = img
        .iter()
        .enumerate()
        .map(|(c, ch)| {
            ch.iter()
                .map(|r| r.iter().map(|v| (v - mean[c]) / std[c]).collect())
                .collect()
        })
        .collect();
    let r11 = conv3x3_relu(&x, &weights[0].2, &weights[1].2, padding);
    let r12 = conv3x3_relu(&r11, &weights[2].2, &weights[3].2, padding);
    let r21 = conv3x3_relu(&pool2(&r12, pooling), &weights[4].2, &weights[5].2, padding);
    (r11, r21)
}

fn assert_close(got: &Tensor, want: &Image, what: &str) {
    let got = got
        .squeeze(0)
        .unwrap()
        .to_dtype(DType::F64)
        .unwrap()
        .to_vec3::<f64>()
        .unwrap();
    assert_eq!(
        (got.len(), got[0].len(), got[0][0].len()),
        (want.len(), want[0].len(), want[0][0].len()),
        "{what}: shape"
    );
    for (c, (g, w)) in got.iter().zip(want).enumerate() {
        for (gr, wr) in g.iter().zip(w) {
            for (a, b) in gr.iter().zip(wr) {
                assert!(
                    (a - b).abs() <= 1e-4 * (1.0 + b.abs()),
                    "{what} channel {c}: {a} vs {b}"
                );
            }
        }
    }
}

#[test]
fn forward_matches_hand_written_network() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg19-part.safetensors");
    let weights = random_weights(1);
    save(&weights, &path);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let img: Image = (0..3)
        .map(|_| {
            (0..6)
                .map(|_| (0..5).map(|_| rng.random::<f64>()).collect())
                .collect()
        })
        .collect();
    let input = Tensor::from_vec(img.concat().concat(), (1, 3, 6, 5), &Device::Cpu).unwrap();
    for (pooling, padding) in [
        (Pooling::Max, Padding::Zeros),
        (Pooling::Average, Padding::Reflect),
    ] {
        let config = Vgg19Config {
            layers: vec![VggLayer::relu(2, 1).unwrap(), VggLayer::relu(1, 1).unwrap()],
            pooling,
            padding,
            imagenet_normalize: true,
        };
        let vgg = Vgg19::from_safetensors(&path, config, &Device::Cpu).unwrap();
        assert_eq!(
            vgg.layers()
                .iter()
                .map(|l| l.to_string())
                .collect::<Vec<_>>(),
            ["relu1_1", "relu2_1"]
        );
        let maps = vgg.extract(&input).unwrap();
        assert_eq!(maps.len(), 2);
        assert!(maps.iter().all(|m| m.patch == 1));
        let (r11, r21) = reference(&img, &weights, pooling, padding);
        assert_close(
            &maps[0].values,
            &r11,
            &format!("relu1_1 {pooling:?} {padding:?}"),
        );
        assert_close(
            &maps[1].values,
            &r21,
            &format!("relu2_1 {pooling:?} {padding:?}"),
        );
    }
}

#[test]
fn missing_or_misshapen_weights_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut weights = random_weights(3);
    let deep = Vgg19Config {
        layers: vec![VggLayer::relu(2, 1).unwrap()],
        ..Vgg19Config::default()
    };

    let truncated = dir.path().join("truncated.safetensors");
    save(&weights[..4], &truncated);
    let err = Vgg19::from_safetensors(&truncated, deep.clone(), &Device::Cpu).unwrap_err();
    assert!(err.to_string().contains("features.5"), "{err}");
    // The same file serves a shallower network: only needed convolutions are read.
    let shallow = Vgg19Config {
        layers: vec![VggLayer::relu(1, 2).unwrap()],
        ..Vgg19Config::default()
    };
    assert!(Vgg19::from_safetensors(&truncated, shallow, &Device::Cpu).is_ok());

    weights[0].1 = vec![64, 3, 1, 9];
    let misshapen = dir.path().join("misshapen.safetensors");
    save(&weights, &misshapen);
    assert!(matches!(
        Vgg19::from_safetensors(&misshapen, deep.clone(), &Device::Cpu),
        Err(Error::Candle(_))
    ));

    let missing = dir.path().join("nothing-here.safetensors");
    assert!(matches!(
        Vgg19::from_safetensors(&missing, deep, &Device::Cpu),
        Err(Error::Io { .. })
    ));
}

#[test]
fn full_network_shapes_and_input_checks() {
    let vb = VarBuilder::zeros(DType::F32, &Device::Cpu);
    let vgg = Vgg19::new(Vgg19Config::default(), vb.clone()).unwrap();
    let maps = vgg
        .extract(&Tensor::zeros((2, 3, 16, 17), DType::F32, &Device::Cpu).unwrap())
        .unwrap();
    let dims: Vec<_> = maps.iter().map(|m| m.values.dims().to_vec()).collect();
    assert_eq!(
        dims,
        vec![
            vec![2, 64, 16, 17],
            vec![2, 128, 8, 8],
            vec![2, 256, 4, 4],
            vec![2, 512, 2, 2],
            vec![2, 512, 1, 1]
        ]
    );
    let small = Tensor::zeros((1, 3, 8, 32), DType::F32, &Device::Cpu).unwrap();
    assert!(matches!(
        vgg.extract(&small),
        Err(Error::InvalidArgument { .. })
    ));
    let gray = Tensor::zeros((1, 1, 32, 32), DType::F32, &Device::Cpu).unwrap();
    assert!(matches!(
        vgg.extract(&gray),
        Err(Error::InvalidArgument { .. })
    ));

    let heitz = Vgg19::new(Vgg19Config::heitz(), vb.clone()).unwrap();
    assert_eq!(heitz.layer_count(), 12);
    assert_eq!(heitz.layers().last().unwrap().to_string(), "relu4_4");
    let empty = Vgg19Config {
        layers: vec![],
        ..Vgg19Config::default()
    };
    assert!(Vgg19::new(empty, vb).is_err());
}

#[test]
fn texture_loss_runs_on_vgg_features() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg.safetensors");
    save(&random_weights(4), &path);
    let config = Vgg19Config {
        layers: vec![VggLayer::relu(1, 1).unwrap(), VggLayer::relu(2, 1).unwrap()],
        ..Vgg19Config::default()
    };
    let vgg = Vgg19::from_safetensors(&path, config, &Device::Cpu).unwrap();
    let loss = TextureLoss::new(vgg, TextureLossConfig::default())
        .unwrap()
        .with_layer_weights(vec![1.0, 0.5])
        .unwrap();
    let a = Tensor::rand(0f32, 1.0, (2, 3, 8, 8), &Device::Cpu).unwrap();
    let b = Tensor::rand(0f32, 1.0, (1, 3, 10, 10), &Device::Cpu).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let same = loss
        .loss(&a, &loss.target(&a).unwrap(), &mut rng)
        .unwrap()
        .to_scalar::<f32>()
        .unwrap();
    assert_eq!(same, 0.0);
    let differ = loss
        .loss(&a, &loss.target(&b).unwrap(), &mut rng)
        .unwrap()
        .to_scalar::<f32>()
        .unwrap();
    assert!(differ > 0.0);
}

/// Float64 weights for the first three convolutions, as a VarBuilder.
fn f64_builder(seed: u64) -> VarBuilder<'static> {
    let map: HashMap<String, Tensor> = random_weights(seed)
        .into_iter()
        .map(|(name, shape, v)| {
            (
                name,
                Tensor::from_vec(v, shape.as_slice(), &Device::Cpu).unwrap(),
            )
        })
        .collect();
    VarBuilder::from_tensors(map, DType::F64, &Device::Cpu)
}

#[test]
fn gradients_through_vgg_match_finite_differences() {
    // Odd sides make pooling drop a row and a column, the case candle's pooling backward gets
    // wrong unless the input is cropped first.
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let data: Vec<f64> = (0..3 * 5 * 7).map(|_| rng.random::<f64>()).collect();
    let x0 = Tensor::from_vec(data.clone(), (1, 3, 5, 7), &Device::Cpu).unwrap();
    let weights = Tensor::from_vec(
        (0..128 * 2 * 3)
            .map(|_| rng.random::<f64>())
            .collect::<Vec<_>>(),
        (1, 128, 2, 3),
        &Device::Cpu,
    )
    .unwrap();
    for (pooling, padding) in [
        (Pooling::Max, Padding::Zeros),
        (Pooling::Average, Padding::Reflect),
    ] {
        let config = Vgg19Config {
            layers: vec![VggLayer::relu(2, 1).unwrap()],
            pooling,
            padding,
            imagenet_normalize: true,
        };
        let vgg = Vgg19::new(config, f64_builder(9)).unwrap();
        let f = |x: &Tensor| {
            let maps = vgg.extract(x).unwrap();
            maps[0].values.mul(&weights).unwrap().sum_all().unwrap()
        };
        let entries: Vec<usize> = (0..data.len()).collect();
        check_gradient(&x0, &entries, 1e-5, 1e-5, f);
    }
}
