//! One generator step or one WGAN-GP critic step through patch-gan's public API, as a program
//! that depends on patch-gan would run it, timed the way `../shared/peer/torch_gan_step.py`
//! times the same step in PyTorch, and printed as the same JSON line (plus the step's
//! convolution arithmetic), so `benches/compare_gan_peer.sh` can put the two side by side.
//! It makes no process-wide setting (allocator, thread pools, candle's variables) beyond the
//! thread count; `--join-pool` is there to measure what one would change.
//!
//! ```text
//! cargo run --release -p patch-gan --example gan_step -- generator --size 40 --channels 32 --layers 5 --threads 2
//! cargo run --release -p patch-gan --example gan_step -- critic --size 108 --batch 2 --channels 32 --layers 5 --threads 2
//! cargo run --release -p patch-gan --example gan_step -- active --size 95 --channels 16 --layers 5 --threads 2
//! ```
//!
//! - `generator`: `Generator3d` forward in training mode (BatchNorm on batch statistics) on a
//!   `(1, in_channels, S, S, S)` normal volume, loss `mean(y^2)`, backward to every weight.
//! - `active`: the same generator as a finer scale runs it, on the active sites of an `S^3`
//!   volume (`forward_residual_active`, finding the sites included): a ground and five
//!   spheres, the voxels within two of their surface active (about 7% at 95^3); loss
//!   `mean(V^2)` of the whole residual volume. The peer is the dense generator (PyTorch has no
//!   submanifold convolution), so the ratio includes skipping the inactive voxels.
//! - `critic`: `PatchDiscriminator2d` on `(batch, in_channels, S, S)` uniform images; loss
//!   `D.critic_loss(real, fake) + D.gradient_penalty(...)` (per-pixel norm, weight 0.1);
//!   `--double-backward` takes the generic functions instead (`critic_loss(D(real), D(fake)) +
//!   gradient_penalty(&D, ...)`, candle's double backward), as before the critic had its own.
//!
//! Options: `--threads N` sets `RAYON_NUM_THREADS` (rayon's threads and candle's), as a user
//! would from the shell; `--join-pool` builds rayon's global pool with this thread in it.
//!
//! Inputs and weights are random (candle's CPU generator cannot be seeded; the timing does not
//! depend on the values). `seconds` is the median of `--repeat` steps after one warm-up, `gflop`
//! the convolution arithmetic of one step (2 multiply-adds per weight tap per output voxel,
//! counted at the minimum: see `step_gflop`; for `active`, the dense step's, which the peer
//! does), `gflops` = `gflop / seconds`.

// Setting the environment (`std::env::set_var`) is `unsafe`; nothing else here is.
#![allow(unsafe_code)]

use std::sync::Arc;
use std::time::Instant;

use candle_core::{DType, Device, ModuleT, Tensor};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{
    critic_loss, gradient_penalty, ActiveSites, Generator3d, Generator3dConfig, GradientPenalty,
    PatchDiscriminator2d, PatchDiscriminator2dConfig,
};
use rand::SeedableRng;

#[derive(Debug, Clone, Copy, PartialEq)]
enum What {
    Generator,
    Active,
    Critic,
}

#[derive(Debug, Clone)]
struct Args {
    what: What,
    size: usize,
    channels: usize,
    layers: usize,
    in_channels: usize,
    batch: usize,
    threads: usize,
    repeat: usize,
    join_pool: bool,
    double_backward: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut argv = std::env::args().skip(1);
    let what = match argv.next().as_deref() {
        Some("generator") => What::Generator,
        Some("active") => What::Active,
        Some("critic") => What::Critic,
        other => {
            return Err(format!(
                "first argument: expected generator, active or critic, got {other:?}"
            ))
        }
    };
    let mut args = Args {
        what,
        size: 40,
        channels: 32,
        layers: 5,
        in_channels: 4,
        batch: 1,
        threads: 2,
        repeat: 5,
        join_pool: false,
        double_backward: false,
    };
    while let Some(flag) = argv.next() {
        match flag.as_str() {
            "--join-pool" => {
                args.join_pool = true;
                continue;
            }
            "--double-backward" => {
                args.double_backward = true;
                continue;
            }
            _ => {}
        }
        let value = argv
            .next()
            .ok_or_else(|| format!("{flag}: expected a value after it"))?;
        let number: usize = value
            .parse()
            .map_err(|_| format!("{flag}: expected a whole number, got {value:?}"))?;
        match flag.as_str() {
            "--size" => args.size = number,
            "--channels" => args.channels = number,
            "--layers" => args.layers = number,
            "--in-channels" => args.in_channels = number,
            "--batch" => args.batch = number,
            "--threads" => args.threads = number,
            "--repeat" => args.repeat = number,
            _ => return Err(format!("unknown flag {flag}")),
        }
    }
    if args.size == 0 || args.threads == 0 || args.repeat == 0 || args.batch == 0 {
        return Err("--size, --threads, --repeat and --batch must be at least 1".into());
    }
    Ok(args)
}

/// Forward multiply-adds x 2 of one convolution layer: `c_in -> c_out` with `taps` taps onto
/// `outputs` output voxels.
fn conv_flop(c_in: usize, c_out: usize, taps: usize, outputs: usize) -> f64 {
    2.0 * (c_in * c_out * taps * outputs) as f64
}

/// The convolution arithmetic of one step, in GFLOP, as PyTorch's autograd needs it at least:
///
/// - generator (and `active`, counted dense): forward, weight gradient and input gradient of
///   every layer, except the first layer's input gradient (the input is not a leaf that wants
///   one): 3 forwards minus that.
/// - critic: forwards of D(mix), D(real), D(fake) (3), the penalty's input gradient through
///   D(mix) (1), its second-order backward (2 through the input-gradient pass, 2 through D(mix)'s
///   forward) and the first-order backward through D(real) and D(fake) (2 each): 12 forwards,
///   less the input gradients nobody needs at the first layer.
fn step_gflop(a: &Args) -> f64 {
    let c_in = |layer: usize| {
        if layer == 0 {
            a.in_channels
        } else {
            a.channels
        }
    };
    let mut total = 0.0;
    for layer in 0..a.layers {
        let last = layer + 1 == a.layers;
        total += match a.what {
            What::Generator | What::Active => {
                let c_out = if last { 4 } else { a.channels };
                let passes = if layer == 0 { 2.0 } else { 3.0 };
                passes * conv_flop(c_in(layer), c_out, 27, a.size.pow(3))
            }
            What::Critic => {
                let c_out = if last { 1 } else { a.channels };
                let side = a.size - 2 * (layer + 1);
                // The first layer's input gradient is wanted once (the penalty's), not 3 times.
                let passes = if layer == 0 { 9.0 } else { 12.0 };
                passes * conv_flop(c_in(layer), c_out, 9, a.batch * side * side)
            }
        };
    }
    total / 1e9
}

type Step = Box<dyn FnMut() -> patch_gan::Result<()>>;

/// A generator of `a`'s shape, with fresh weights.
fn generator(a: &Args) -> patch_gan::Result<Generator3d> {
    let vb = VarBuilder::from_varmap(&VarMap::new(), DType::F32, &Device::Cpu);
    let config = Generator3dConfig {
        channels: a.channels,
        ..Generator3dConfig::default()
            .with_layers(a.layers)
            .with_in_channels(a.in_channels)
    };
    Generator3d::new(&config, vb)
}

fn generator_step(a: &Args) -> patch_gan::Result<Step> {
    let g = generator(a)?;
    let s = a.size;
    let x = Tensor::randn(0f32, 1., (1, a.in_channels, s, s, s), &Device::Cpu)?;
    Ok(Box::new(move || {
        let y = g.forward_t(&x, true)?;
        drop(y.sqr()?.mean_all()?.backward()?);
        Ok(())
    }))
}

/// The active voxels of [`active_step`]'s scene at `size^3`: within two voxels of the surface
/// of a wavy ground at a quarter of the height and five spheres standing on it.
fn active_mask(size: usize) -> Vec<bool> {
    let spheres = [
        (0.3, 0.3, 0.3, 0.10),
        (0.7, 0.3, 0.28, 0.08),
        (0.5, 0.6, 0.32, 0.12),
        (0.2, 0.75, 0.27, 0.07),
        (0.8, 0.75, 0.3, 0.09),
    ];
    let shell = 2.0 / size as f64;
    let centre = |i: usize| (i as f64 + 0.5) / size as f64;
    let mut mask = Vec::with_capacity(size.pow(3));
    for d in 0..size {
        for h in 0..size {
            for w in 0..size {
                let (x, y, z) = (centre(w), centre(h), centre(d));
                let tau = std::f64::consts::TAU;
                let ground = 0.25 + 0.04 * (tau * x).sin() * (tau * y).cos();
                let mut distance = (z - ground).abs();
                for (cx, cy, cz, r) in spheres {
                    let to_centre = ((x - cx).powi(2) + (y - cy).powi(2) + (z - cz).powi(2)).sqrt();
                    distance = distance.min((to_centre - r).abs());
                }
                mask.push(distance <= shell);
            }
        }
    }
    mask
}

fn active_step(a: &Args) -> patch_gan::Result<Step> {
    let g = generator(a)?;
    let (s, c) = (a.size, a.in_channels);
    let dev = Device::Cpu;
    let z = Tensor::randn(0f32, 1., (1, c, s, s, s), &dev)?;
    let prev_up = Tensor::randn(0f32, 1., (1, c, s, s, s), &dev)?;
    let mask = active_mask(s);
    Ok(Box::new(move || {
        let sites = Arc::new(ActiveSites::new(1, [s, s, s], 3, &mask)?);
        let v = g.forward_residual_active(&z, &prev_up, &sites, true)?;
        drop(v.sqr()?.mean_all()?.backward()?);
        Ok(())
    }))
}

fn critic_step(a: &Args) -> patch_gan::Result<Step> {
    let double_backward = a.double_backward;
    if double_backward {
        // The generic penalty differentiates the critic's input gradient: candle must keep
        // that graph. Set before any backward pass, while this program runs no other threads.
        std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1");
    }
    let dev = Device::Cpu;
    let vb = VarBuilder::from_varmap(&VarMap::new(), DType::F32, &dev);
    let config = PatchDiscriminator2dConfig {
        layers: a.layers,
        channels: a.channels,
        in_channels: a.in_channels,
    };
    let d = PatchDiscriminator2d::new(&config, vb)?;
    let shape = (a.batch, a.in_channels, a.size, a.size);
    let real = Tensor::rand(0f32, 1., shape, &dev)?;
    let fake = Tensor::rand(0f32, 1., shape, &dev)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(0);
    Ok(Box::new(move || {
        let cfg = GradientPenalty::default();
        let (penalty, adversarial) = if double_backward {
            let scores = (d.forward_t(&real, true)?, d.forward_t(&fake, true)?);
            (
                gradient_penalty(&d, &real, &fake, cfg, &mut rng)?,
                critic_loss(&scores.0, &scores.1)?,
            )
        } else {
            (
                d.gradient_penalty(&real, &fake, cfg, &mut rng)?,
                d.critic_loss(&real, &fake)?,
            )
        };
        drop((adversarial + penalty)?.backward()?);
        Ok(())
    }))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a = parse_args()?;
    // candle sizes its own parallel loops from the variable rayon reads. Set before any thread
    // of this program exists.
    std::env::set_var("RAYON_NUM_THREADS", a.threads.to_string());
    if a.join_pool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(a.threads)
            .use_current_thread()
            .build_global()?;
    }
    let mut step = match a.what {
        What::Generator => generator_step(&a)?,
        What::Active => active_step(&a)?,
        What::Critic => critic_step(&a)?,
    };
    step()?;
    let mut times = Vec::with_capacity(a.repeat);
    for _ in 0..a.repeat {
        let start = Instant::now();
        step()?;
        times.push(start.elapsed().as_secs_f64());
    }
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    let gflop = step_gflop(&a);
    let what = match a.what {
        What::Generator => "generator",
        What::Active => "active",
        What::Critic => "critic",
    };
    let active = match a.what {
        What::Active => {
            let mask = active_mask(a.size);
            let fraction = mask.iter().filter(|&&m| m).count() as f64 / mask.len() as f64;
            format!("{fraction:.4}")
        }
        _ => "null".into(),
    };
    println!(
        "{{\"what\": \"{what}\", \"size\": {}, \"channels\": {}, \"layers\": {}, \"in_channels\": {}, \
         \"batch\": {}, \"threads\": {}, \"volgen\": \"{}\", \"seconds\": {median:.5}, \
         \"min_seconds\": {min:.5}, \"gflop\": {gflop:.3}, \"gflops\": {:.1}, \"active\": {active}, \
         \"join_pool\": {}, \"double_backward\": {}}}",
        a.size,
        a.channels,
        a.layers,
        a.in_channels,
        a.batch,
        a.threads,
        env!("CARGO_PKG_VERSION"),
        gflop / median,
        a.join_pool,
        a.double_backward,
    );
    Ok(())
}
