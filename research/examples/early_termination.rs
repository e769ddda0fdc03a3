//! Early ray termination in the training's renderings: run time against error. For each 3D
//! scale of a trained run, renders its reconstruction V* and random volumes from the dataset's
//! cameras at that scale's image size and samples, as the training's generator steps do
//! (colour, depth and opacity, forward and backward through a fixed random probe of the
//! outputs), with the renderer's `epsilon` (a ray stops once its transmittance is at most
//! epsilon) at 0 (exact, the training's renderer) and larger; prints the time relative to 0,
//! the largest change in colour, opacity and depth, and the relative L2 change of the volume's
//! gradient. Used for docs/journal/2026-12-arrangement.md.
//!
//! `cargo run --release -p research --example early_termination -- RUN DATASET [VIEWS]`

use std::time::Instant;

use candle_core::{Device, Tensor, Var};
use rand::SeedableRng;
use rgbd_dataset::Dataset;
use singrav::SinGrav;
use volrender::{render, Rays, RenderConfig, RenderOutput, Sampler};

const EPSILONS: [f32; 4] = [0.0, 1e-4, 1e-3, 1e-2];
const RANDOM_VOLUMES: usize = 3;
const TIMED_RUNS: usize = 4;

/// Forward and backward of one rendering: the outputs and the volume's gradient.
fn render_with_gradient(
    volume: &Tensor,
    rays: &Rays,
    config: &RenderConfig,
    probe: &[Tensor; 3],
) -> (RenderOutput, Tensor) {
    let var = Var::from_tensor(volume).unwrap();
    let out = render(var.as_tensor(), rays, config).unwrap();
    let depth = out.depth.as_ref().unwrap();
    let opacity = out.opacity.as_ref().unwrap();
    let loss = ((&out.rgb * &probe[0]).unwrap().sum_all().unwrap()
        + (depth * &probe[1]).unwrap().sum_all().unwrap()
        + (opacity * &probe[2]).unwrap().sum_all().unwrap())
    .unwrap();
    let grads = loss.backward().unwrap();
    let grad = grads.get(var.as_tensor()).unwrap().clone();
    (out, grad)
}

fn max_abs_diff(a: &Tensor, b: &Tensor) -> f32 {
    let diff = (a - b).and_then(|d| d.abs()?.max_all()).unwrap();
    diff.to_scalar().unwrap()
}

fn norm(t: &Tensor) -> f64 {
    f64::from(
        t.sqr()
            .unwrap()
            .sum_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap(),
    )
    .sqrt()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [run, dataset] = [&args[0], &args[1]];
    let views: usize = args.get(2).map_or(10, |v| v.parse().unwrap());
    let device = Device::Cpu;
    let (model, _) = SinGrav::load(run.as_ref(), &device).unwrap();
    let config = model.config().clone();
    let data = Dataset::load(dataset.as_ref(), config.rendering.background).unwrap();
    let activation = config.activation();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    println!("| scale | image, samples | volume | epsilon | time (x epsilon 0) | max colour change | max opacity change | max depth change | gradient change (rel. L2) |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for n in 1..=model.volume_scales() {
        let (image, samples) = (
            config.pyramid.image_sizes[n - 1],
            config.pyramid.samples[n - 1],
        );
        let level = data.level(image, image, &device).unwrap();
        let (mut origins, mut dirs) = (Vec::new(), Vec::new());
        for camera in level.cameras.iter().take(views) {
            let rays = Rays::from_camera(camera);
            origins.extend_from_slice(rays.origins());
            dirs.extend_from_slice(rays.dirs());
        }
        let count = origins.len();
        let rays = Rays::new(origins, dirs).unwrap();
        let probe = [
            Tensor::randn(0f32, 1.0, (count, 3), &device).unwrap(),
            Tensor::randn(0f32, 1.0, count, &device).unwrap(),
            Tensor::randn(0f32, 1.0, count, &device).unwrap(),
        ];
        let mut volumes = vec![(
            "V*".to_string(),
            model
                .generate(&model.reconstruction_noise(n).unwrap())
                .unwrap(),
        )];
        for k in 0..RANDOM_VOLUMES {
            let noise = model.draw_noise(n, &mut rng).unwrap();
            volumes.push((format!("random {k}"), model.generate(&noise).unwrap()));
        }
        for (name, raw) in volumes {
            let raw = raw.detach().squeeze(0).unwrap();
            let physical = if config.rendering.post_activation {
                activation.apply_colour(&raw).unwrap()
            } else {
                activation.apply(&raw).unwrap()
            };
            let base = RenderConfig::default()
                .with_sampler(Sampler::Uniform { samples })
                .with_background(config.rendering.background)
                .with_depth(true)
                .with_opacity(true)
                .with_density(config.density_interpolation());
            // An untimed render of each epsilon first (its results kept), then the median of
            // timed runs in an order that rotates each round, so neither a slow moment nor
            // coming first (cold caches, fresh allocations) falls on one epsilon alone.
            let results: Vec<_> = EPSILONS
                .iter()
                .map(|&epsilon| {
                    render_with_gradient(&physical, &rays, &base.with_epsilon(epsilon), &probe)
                })
                .collect();
            let mut seconds = vec![Vec::new(); EPSILONS.len()];
            for run in 0..TIMED_RUNS {
                for k in 0..EPSILONS.len() {
                    let e = (k + run) % EPSILONS.len();
                    let config = base.with_epsilon(EPSILONS[e]);
                    let started = Instant::now();
                    render_with_gradient(&physical, &rays, &config, &probe);
                    seconds[e].push(started.elapsed().as_secs_f64());
                }
            }
            let median = |s: &mut Vec<f64>| {
                s.sort_by(f64::total_cmp);
                s[s.len() / 2]
            };
            let exact_seconds = median(&mut seconds[0]);
            let (exact, exact_grad) = &results[0];
            for (e, &epsilon) in EPSILONS.iter().enumerate().skip(1) {
                let (out, grad) = &results[e];
                println!(
                    "| {n} | {image}^2, {samples} | {name} | {epsilon:e} | {:.3} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
                    median(&mut seconds[e]) / exact_seconds,
                    max_abs_diff(&out.rgb, &exact.rgb),
                    max_abs_diff(out.opacity.as_ref().unwrap(), exact.opacity.as_ref().unwrap()),
                    max_abs_diff(out.depth.as_ref().unwrap(), exact.depth.as_ref().unwrap()),
                    norm(&(grad - exact_grad).unwrap()) / norm(exact_grad),
                );
            }
        }
    }
}
