//! One generator step or one WGAN-GP critic step through patch-gan's public API, timed the way
//! `../shared/peer/torch_gan_step.py` times the same step in PyTorch, and printed as the same
//! JSON line (plus the step's convolution arithmetic and its effective GFLOP/s), so
//! `benches/compare_gan_peer.sh` can put the two side by side.
//!
//! ```text
//! cargo run --release -p patch-gan --example gan_step -- generator --size 40 --channels 32 --layers 5 --threads 2
//! cargo run --release -p patch-gan --example gan_step -- critic --size 108 --batch 2 --channels 32 --layers 5 --threads 2
//! cargo run --release -p patch-gan --example gan_step -- gemm --size 2048 --threads 2
//! ```
//!
//! - `generator`: `Generator3d` forward in training mode (BatchNorm on batch statistics) on a
//!   `(1, in_channels, S, S, S)` normal volume, loss `mean(y^2)`, backward to every weight.
//! - `critic`: `PatchDiscriminator2d` on `(batch, in_channels, S, S)` uniform images; loss
//!   `D.critic_loss(real, fake) + D.gradient_penalty(...)` (per-pixel norm, weight 0.1): real
//!   and fake through one forward pass, the penalty's gradient into the critic's weights written
//!   as a first-order graph; `--double-backward` takes the generic functions instead
//!   (`critic_loss(D(real), D(fake)) + gradient_penalty(&D, ...)`, candle's double backward), as
//!   before the critic had its own.
//! - `gemm`: one `S x S x S` f32 product by the `gemm` crate (the kernels' multiplier) on the same
//!   threads: the machine's rate to hold the steps' GFLOP/s against.
//!
//! Inputs and weights are random (candle's CPU generator cannot be seeded; the timing does not
//! depend on the values). `seconds` is the median of `--repeat` steps after one warm-up, `gflop` the convolution
//! arithmetic of one step (2 multiply-adds per weight tap per output voxel, counted at the
//! minimum: see `step_gflop`), `gflops` = `gflop / seconds`.

// Setting the environment (`std::env::set_var`) is `unsafe`; nothing else here is.
#![allow(unsafe_code)]

use std::time::Instant;

use candle_core::{DType, Device, ModuleT, Tensor};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{
    critic_loss, gradient_penalty, Generator3d, Generator3dConfig, GradientPenalty,
    PatchDiscriminator2d, PatchDiscriminator2dConfig,
};
use rand::SeedableRng;

#[derive(Debug, Clone, Copy, PartialEq)]
enum What {
    Generator,
    Critic,
    Gemm,
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
    mallopt: bool,
    double_backward: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut argv = std::env::args().skip(1);
    let what = match argv.next().as_deref() {
        Some("generator") => What::Generator,
        Some("critic") => What::Critic,
        Some("gemm") => What::Gemm,
        other => {
            return Err(format!(
                "first argument: expected generator, critic or gemm, got {other:?}"
            ))
        }
    };
    let mut args = Args {
        what,
        size: if what == What::Gemm { 2048 } else { 40 },
        channels: 32,
        layers: 5,
        in_channels: 4,
        batch: 1,
        threads: 2,
        repeat: 5,
        mallopt: true,
        double_backward: false,
    };
    while let Some(flag) = argv.next() {
        if flag == "--no-mallopt" {
            args.mallopt = false;
            continue;
        }
        if flag == "--double-backward" {
            args.double_backward = true;
            continue;
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
/// - generator: forward, weight gradient and input gradient of every layer, except the first
///   layer's input gradient (the input is not a leaf that wants one): 3 forwards minus that.
/// - critic: forwards of D(mix), D(real), D(fake) (3), the penalty's input gradient through
///   D(mix) (1), its second-order backward (2 through the input-gradient pass, 2 through D(mix)'s
///   forward) and the first-order backward through D(real) and D(fake) (2 each): 12 forwards,
///   less the input gradients nobody needs at the first layer.
fn step_gflop(a: &Args) -> f64 {
    match a.what {
        What::Generator => {
            let vox = a.size.pow(3);
            let mut total = 0.0;
            for layer in 0..a.layers {
                let c_in = if layer == 0 {
                    a.in_channels
                } else {
                    a.channels
                };
                let c_out = if layer + 1 == a.layers { 4 } else { a.channels };
                let passes = if layer == 0 { 2.0 } else { 3.0 };
                total += passes * conv_flop(c_in, c_out, 27, vox);
            }
            total / 1e9
        }
        What::Critic => {
            let mut total = 0.0;
            for layer in 0..a.layers {
                let c_in = if layer == 0 {
                    a.in_channels
                } else {
                    a.channels
                };
                let c_out = if layer + 1 == a.layers { 1 } else { a.channels };
                let side = a.size - 2 * (layer + 1);
                // The first layer's input gradient is wanted once (the penalty's), not 3 times.
                let passes = if layer == 0 { 9.0 } else { 12.0 };
                total += passes * conv_flop(c_in, c_out, 9, a.batch * side * side);
            }
            total / 1e9
        }
        What::Gemm => 2.0 * (a.size as f64).powi(3) / 1e9,
    }
}

fn generator_step(a: &Args) -> candle_core::Result<Box<dyn FnMut() -> candle_core::Result<()>>> {
    let dev = Device::Cpu;
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
    let config = Generator3dConfig::default()
        .with_layers(a.layers)
        .with_in_channels(a.in_channels);
    let config = Generator3dConfig {
        channels: a.channels,
        ..config
    };
    let g = Generator3d::new(&config, vb).map_err(candle_core::Error::wrap)?;
    let s = a.size;
    let x = Tensor::randn(0f32, 1., (1, a.in_channels, s, s, s), &dev)?;
    Ok(Box::new(move || {
        let y = g.forward_t(&x, true)?;
        let grads = y.sqr()?.mean_all()?.backward()?;
        drop(grads);
        Ok(())
    }))
}

fn critic_step(a: &Args) -> candle_core::Result<Box<dyn FnMut() -> candle_core::Result<()>>> {
    let double_backward = a.double_backward;
    if double_backward {
        // The generic penalty differentiates the critic's input gradient: candle must keep
        // that graph.
        // SAFETY: set before any backward pass, while this program runs no other threads.
        unsafe { std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1") };
    }
    let dev = Device::Cpu;
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
    let config = PatchDiscriminator2dConfig {
        layers: a.layers,
        channels: a.channels,
        in_channels: a.in_channels,
    };
    let d = PatchDiscriminator2d::new(&config, vb).map_err(candle_core::Error::wrap)?;
    let shape = (a.batch, a.in_channels, a.size, a.size);
    let real = Tensor::rand(0f32, 1., shape, &dev)?;
    let fake = Tensor::rand(0f32, 1., shape, &dev)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    Ok(Box::new(move || {
        let wrap = candle_core::Error::wrap;
        let cfg = GradientPenalty::default();
        let penalty = if double_backward {
            gradient_penalty(&d, &real, &fake, cfg, &mut rng)
        } else {
            d.gradient_penalty(&real, &fake, cfg, &mut rng)
        }
        .map_err(wrap)?;
        let adversarial = if double_backward {
            critic_loss(&d.forward_t(&real, true)?, &d.forward_t(&fake, true)?)
        } else {
            d.critic_loss(&real, &fake)
        }
        .map_err(wrap)?;
        drop((adversarial + penalty)?.backward()?);
        Ok(())
    }))
}

fn gemm_step(a: &Args) -> Box<dyn FnMut() -> candle_core::Result<()>> {
    let n = a.size;
    let lhs: Vec<f32> = (0..n * n)
        .map(|i| ((i * 7919) % 1000) as f32 / 1000.0)
        .collect();
    let rhs: Vec<f32> = (0..n * n)
        .map(|i| ((i * 104729) % 1000) as f32 / 1000.0)
        .collect();
    let mut dst = vec![0f32; n * n];
    let threads = a.threads;
    Box::new(move || {
        // SAFETY: the three buffers are n x n, row-major, with the strides given.
        unsafe {
            gemm::gemm(
                n,
                n,
                n,
                dst.as_mut_ptr(),
                1,
                n as isize,
                false,
                lhs.as_ptr(),
                1,
                n as isize,
                rhs.as_ptr(),
                1,
                n as isize,
                0f32,
                1f32,
                false,
                false,
                false,
                gemm::Parallelism::Rayon(threads),
            )
        };
        Ok(())
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a = parse_args()?;
    // As the `volgen` binary does (see its doc).
    let mallopt = a.mallopt && volrender::tune_malloc();
    // As the `volgen` binary does: candle's pool worker parks right after each element-wise op
    // instead of spinning on a core the convolutions need (unless the caller set a limit).
    // SAFETY: set before any thread of this program exists.
    if std::env::var_os("CANDLE_BARRIER_POOL_SPIN_LIMIT").is_none() {
        unsafe { std::env::set_var("CANDLE_BARRIER_POOL_SPIN_LIMIT", "1") };
    }
    // candle sizes its own parallel loops from the variable rayon reads.
    // SAFETY: set before any thread of this program exists.
    unsafe { std::env::set_var("RAYON_NUM_THREADS", a.threads.to_string()) };
    // As the `volgen` binary does: this thread is one of the pool's (see the function).
    volrender::join_global_pool(Some(a.threads))?;
    let mut step = match a.what {
        What::Generator => generator_step(&a)?,
        What::Critic => critic_step(&a)?,
        What::Gemm => gemm_step(&a),
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
        What::Critic => "critic",
        What::Gemm => "gemm",
    };
    println!(
        "{{\"what\": \"{what}\", \"size\": {}, \"channels\": {}, \"layers\": {}, \"in_channels\": {}, \
         \"batch\": {}, \"threads\": {}, \"volgen\": \"{}\", \"seconds\": {median:.5}, \
         \"min_seconds\": {min:.5}, \"gflop\": {gflop:.3}, \"gflops\": {:.1}, \"mallopt\": {mallopt}, \
         \"double_backward\": {}}}",
        a.size,
        a.channels,
        a.layers,
        a.in_channels,
        a.batch,
        a.threads,
        env!("CARGO_PKG_VERSION"),
        gflop / median,
        a.double_backward,
    );
    Ok(())
}
