//! Trains a small 3D patch GAN as a program of your own would: a generator that turns noise
//! into a volume of a texture (glowing cells in a dim block, 4 channels: density and RGB), and a
//! 3D patch critic with the WGAN-GP penalty that sees only 11^3 patches of it (3inGAN's setting
//! at one scale), both with Adam. Runs in about half a minute on two cores.
//!
//! ```text
//! cargo run --release -p patch-gan --example train_volume_gan -- [iterations]
//! ```
//!
//! It prints the critic's Wasserstein estimate (how far apart it finds real and generated
//! patches: it falls as the generator learns) and how much of the generated volume is cells
//! against the texture's share.

use candle_core::{DType, Device, ModuleT, Tensor, D};
use candle_nn::{AdamW, Optimizer, ParamsAdamW, VarBuilder, VarMap};
use patch_gan::{
    generator_loss, Generator3d, Generator3dConfig, GradientPenalty, PatchDiscriminator3d,
    PatchDiscriminatorConfig,
};
use rand::SeedableRng;

/// Side of the volumes.
const SIZE: usize = 24;

/// The texture: cells (density 1, warm colour) on a jittered grid of period 8 in a dim block
/// (density -1, blue), as raw values (a network's volumes are raw, before any activation).
fn texture(dev: &Device) -> candle_core::Result<Tensor> {
    let mut values = vec![0f32; 4 * SIZE.pow(3)];
    let plane = SIZE.pow(3);
    for z in 0..SIZE {
        for y in 0..SIZE {
            for x in 0..SIZE {
                let cell = [x, y, z].map(|i| i / 8);
                let jitter =
                    |k: usize| ((cell[0] * 7 + cell[1] * 13 + cell[2] * 29 + k) % 5) as f32;
                let centre = [0, 1, 2].map(|a| (cell[a] * 8) as f32 + 2.0 + jitter(a) * 0.8);
                let d2: f32 = [x, y, z]
                    .iter()
                    .zip(centre)
                    .map(|(&i, c)| (i as f32 + 0.5 - c).powi(2))
                    .sum();
                let inside = d2 < 6.0;
                let at = (z * SIZE + y) * SIZE + x;
                let rgb = if inside {
                    [1.0, 0.6, 0.2]
                } else {
                    [0.1, 0.2, 0.8]
                };
                values[at] = if inside { 1.0 } else { -1.0 };
                for (c, v) in rgb.into_iter().enumerate() {
                    values[(c + 1) * plane + at] = 2.0 * v - 1.0;
                }
            }
        }
    }
    Tensor::from_vec(values, (1, 4, SIZE, SIZE, SIZE), dev)
}

/// The share of a volume's voxels whose density is positive (inside a cell).
fn cell_share(volume: &Tensor) -> candle_core::Result<f32> {
    let density = volume.narrow(1, 0, 1)?;
    density
        .gt(0f32)?
        .to_dtype(DType::F32)?
        .mean_all()?
        .to_scalar()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let iterations: usize = std::env::args().nth(1).map_or(Ok(150), |s| s.parse())?;
    let dev = Device::Cpu;
    let real = texture(&dev)?;

    // The generator: noise (4 channels) to a volume; the critic: 3D patches of 11^3 voxels.
    let g_vars = VarMap::new();
    let g_config = Generator3dConfig {
        channels: 16,
        ..Generator3dConfig::default().with_in_channels(4)
    };
    let g = Generator3d::new(
        &g_config,
        VarBuilder::from_varmap(&g_vars, DType::F32, &dev),
    )?;
    let d_vars = VarMap::new();
    let d_config = PatchDiscriminatorConfig {
        layers: 5,
        channels: 16,
        in_channels: 4,
    };
    let d = PatchDiscriminator3d::new(
        &d_config,
        VarBuilder::from_varmap(&d_vars, DType::F32, &dev),
    )?;
    // The paper's optimiser: Adam, learning rate 5e-4, betas (0.9, 0.999).
    let adam = ParamsAdamW {
        lr: 5e-4,
        weight_decay: 0.0,
        ..ParamsAdamW::default()
    };
    let mut g_opt = AdamW::new(g_vars.all_vars(), adam.clone())?;
    let mut d_opt = AdamW::new(d_vars.all_vars(), adam)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    let noise = || Tensor::randn(0f32, 1., (1, 4, SIZE, SIZE, SIZE), &dev);

    let start = std::time::Instant::now();
    for it in 0..iterations {
        // Three critic steps: WGAN loss on real and generated volumes, plus the penalty.
        let mut wasserstein = 0.0;
        for _ in 0..3 {
            let fake = g.forward_t(&noise()?, true)?.detach();
            let loss = d.critic_loss(&real, &fake)?;
            let penalty = d.gradient_penalty(&real, &fake, GradientPenalty::default(), &mut rng)?;
            wasserstein = -loss.to_scalar::<f32>()?;
            d_opt.backward_step(&(loss + penalty)?)?;
        }
        // Three generator steps: make the critic score generated patches as real.
        for _ in 0..3 {
            let fake = g.forward_t(&noise()?, true)?;
            g_opt.backward_step(&generator_loss(&d.score(&fake)?)?)?;
        }
        if it % 25 == 0 || it + 1 == iterations {
            let sample = g.forward_t(&noise()?, true)?;
            println!(
                "iteration {it:4}: Wasserstein estimate {wasserstein:7.3}, cells {:4.1}% of the volume \
                 (texture {:4.1}%), {:.1} s",
                100.0 * cell_share(&sample)?,
                100.0 * cell_share(&real)?,
                start.elapsed().as_secs_f64()
            );
        }
    }
    // One generated volume's channel means against the texture's.
    let sample = g.forward_t(&noise()?, true)?;
    let means = |v: &Tensor| -> candle_core::Result<Vec<f32>> {
        v.flatten_from(2)?.mean(D::Minus1)?.squeeze(0)?.to_vec1()
    };
    println!("channel means, generated {:?}", means(&sample)?);
    println!("channel means, texture   {:?}", means(&real)?);
    Ok(())
}
