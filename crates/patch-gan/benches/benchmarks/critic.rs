//! The patch critic's step at the `tiny` preset's last scale (two 6-channel 108^2 images, 16
//! channels, L = 5), on our Conv2d against the same network on candle's conv2d, in one run:
//! a forward pass, forward + backward, and the WGAN-GP penalty with its second-order backward
//! (and, for ours, as the critic's own first-order graph).

use std::time::Duration;

use candle_core::{DType, Device, Module, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use criterion::{BenchmarkId, Criterion};
use patch_gan::{
    gradient_penalty, GradientPenalty, PatchDiscriminator2d, PatchDiscriminator2dConfig,
};
use rand::SeedableRng;

const CONFIG: PatchDiscriminator2dConfig = PatchDiscriminator2dConfig {
    layers: 5,
    channels: 16,
    in_channels: 6,
};
const SIZE: usize = 108;
const BATCH: usize = 2;

/// The same critic with candle's conv2d: built from the weights of ours.
struct CandleCritic {
    layers: Vec<(Tensor, Tensor)>,
}

impl Module for CandleCritic {
    fn forward(&self, xs: &Tensor) -> candle_core::Result<Tensor> {
        let mut x = xs.clone();
        for (i, (w, b)) in self.layers.iter().enumerate() {
            x = x
                .conv2d(w, 0, 1, 1, 1)?
                .broadcast_add(&b.reshape((1, (), 1, 1))?)?;
            if i + 1 < self.layers.len() {
                x = patch_gan::leaky_relu(&x, patch_gan::LEAKY_SLOPE)?;
            }
        }
        Ok(x)
    }
}

fn critics() -> (PatchDiscriminator2d, CandleCritic) {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let ours = PatchDiscriminator2d::new(&CONFIG, vb).unwrap();
    let data = varmap.data().lock().unwrap();
    let get = |name: &str| data[name].as_tensor().clone();
    let mut layers: Vec<_> = (0..CONFIG.layers - 1)
        .map(|i| {
            let w = get(&format!("blocks.{i}.conv.weight"));
            (w, get(&format!("blocks.{i}.conv.bias")))
        })
        .collect();
    layers.push((get("tail.weight"), get("tail.bias")));
    (ours, CandleCritic { layers })
}

fn bench_critic(c: &mut Criterion) {
    // SAFETY: set before any backward pass of this process, read by candle through std::env.
    unsafe { std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1") };
    let dev = Device::Cpu;
    let (ours, theirs) = critics();
    let shape = (BATCH, CONFIG.in_channels, SIZE, SIZE);
    let real = Tensor::randn(0f32, 1., shape, &dev).unwrap();
    let fake = Tensor::randn(0f32, 1., shape, &dev).unwrap();
    let input = Var::from_tensor(&real).unwrap();
    let mut group = c.benchmark_group("gan/critic_108");
    group.sample_size(10).warm_up_time(Duration::from_secs(1));
    let nets: [(&str, &dyn Module); 2] = [("ours", &ours), ("candle", &theirs)];
    for (name, net) in nets {
        group.bench_function(BenchmarkId::new("forward", name), |b| {
            b.iter(|| net.forward(&real).unwrap())
        });
        group.bench_function(BenchmarkId::new("forward_backward", name), |b| {
            b.iter(|| {
                net.forward(input.as_tensor())
                    .unwrap()
                    .mean_all()
                    .unwrap()
                    .backward()
                    .unwrap()
            })
        });
        group.bench_function(BenchmarkId::new("gradient_penalty", name), |b| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
            b.iter(|| {
                let gp = gradient_penalty(net, &real, &fake, GradientPenalty::default(), &mut rng);
                gp.unwrap().backward().unwrap()
            })
        });
    }
    // The same penalty as the critic's own first-order graph (no double backward).
    group.bench_function(
        BenchmarkId::new("gradient_penalty", "ours_first_order"),
        |b| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
            b.iter(|| {
                let gp = ours.gradient_penalty(&real, &fake, GradientPenalty::default(), &mut rng);
                gp.unwrap().backward().unwrap()
            })
        },
    );
    group.finish();
}

criterion::criterion_group!(benches, bench_critic);
