//! One generator step of the finer 3D scales, dense against the active set, on the stones
//! scene: time and peak memory side by side in one run. Used for docs/performance-patch-gan.md
//! ("Generators on the active set").
//!
//! `cargo run --release -p research --example sparse_step -- small paper [--reps 3]`
//!
//! For 3D scale `n` of a preset, `up(V_{n-1})` is the stones scene (layout 0) baked at scale
//! `n - 1`'s size, as raw values under the preset's activation, upsampled to scale `n` as
//! training upsamples; the active set is the preset's rule on it (`sparse_threshold`,
//! `sparse_margin`), once as it is and once with `sparse_shell` (the inside of matter left out). A trained model's `up(V_{n-1})` is blurrier than the baked scene, so real
//! active sets are somewhat larger. A step is the generator's forward pass in training mode
//! plus the backward pass of `mean(V_n^2)`; the sparse step includes finding the active set.
//! Peak memory is the heap's high-water mark above what was allocated before the step, counted
//! by this program's allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{Generator3d, Generator3dConfig};
use radiance_volume::{resample_tensor, GridDims};
use rgbd_dataset::scenes::SceneKind;
use singrav::active_set::{active_sites, ActiveSetRule};
use singrav::noise::{gaussian_volume, step_rng};
use singrav::TrainConfig;

/// The system allocator, counting the bytes in use and their high-water mark.
struct Counting;

static IN_USE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

#[allow(unsafe_code)] // A measuring allocator, this program's only `unsafe`.
                      // SAFETY: forwards every call to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            let now = IN_USE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        IN_USE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(layout);
        if !p.is_null() {
            let now = IN_USE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = System.realloc(ptr, layout, new_size);
        if !p.is_null() {
            IN_USE.fetch_sub(layout.size(), Ordering::Relaxed);
            let now = IN_USE.fetch_add(new_size, Ordering::Relaxed) + new_size;
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Seconds and peak extra MiB of `step`.
fn measure(step: impl FnOnce() -> Result<(), BoxError>) -> Result<(f64, f64), BoxError> {
    let base = IN_USE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let started = Instant::now();
    step()?;
    let seconds = started.elapsed().as_secs_f64();
    let peak = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    Ok((seconds, peak as f64 / (1024.0 * 1024.0)))
}

type BoxError = Box<dyn std::error::Error>;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The stones scene baked at `size`^3 as a raw volume `(1, 4, s, s, s)` under `config`'s activation.
fn stones_raw(config: &TrainConfig, size: usize, device: &Device) -> Result<Tensor, BoxError> {
    let volume = SceneKind::StandingStones
        .build(0)
        .to_volume(GridDims::cube(size))?;
    let activation = config.activation();
    let mut values: Vec<f32> = volume.tensor().flatten_all()?.to_vec1()?;
    let voxels = size.pow(3);
    // Empty space gets the raw value of a negligible density (softplus never reaches 0).
    for v in &mut values[..voxels] {
        *v = activation.raw_density(v.max(1e-6))?;
    }
    Ok(Tensor::from_vec(values, (1, 4, size, size, size), device)?)
}

fn main() -> Result<(), BoxError> {
    volrender::tune_malloc();
    let mut presets = Vec::new();
    let mut reps = 3usize;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--reps" => reps = args.next().ok_or("--reps needs a count")?.parse()?,
            name => presets.push(name.to_string()),
        }
    }
    if reps == 0 {
        return Err("--reps needs at least 1 timed repetition".into());
    }
    if presets.is_empty() {
        presets = vec!["small".into(), "paper".into()];
    }
    let device = Device::Cpu;
    println!(
        "one generator step (forward in training mode + backward), dense vs active set (the \
         preset's rule, then with sparse_shell), stones scene; median of {reps} after a warm-up; \
         {} threads",
        rayon::current_num_threads()
    );
    println!("| preset | scale | volume | channels, layers | dense s | dense peak MiB | rule | active | sparse s | peak MiB | speed-up | memory ratio |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for preset in &presets {
        let config = TrainConfig::preset(preset)?;
        let rules = [
            (
                "margin",
                ActiveSetRule {
                    shell: false,
                    ..config.active_set_rule()
                },
            ),
            (
                "shell",
                ActiveSetRule {
                    shell: true,
                    ..config.active_set_rule()
                },
            ),
        ];
        for n in 2..=config.pyramid.volume_sizes.len() {
            let size = config.pyramid.volume_sizes[n - 1];
            let coarse = stones_raw(&config, config.pyramid.volume_sizes[n - 2], &device)?;
            let up = resample_tensor(&coarse, GridDims::cube(size))?;
            let varmap = VarMap::new();
            let vb = VarBuilder::from_varmap(&varmap, DType::F32, &device);
            let g_config = Generator3dConfig {
                channels: config.pyramid.channels,
                ..Generator3dConfig::for_scale(n, config.pyramid.layers)
            };
            let generator = Generator3d::new(&g_config, vb)?;
            let z = gaussian_volume(&mut step_rng(0, n, 0), 4, size, 0.1, &device)?;
            let dense_step = || -> Result<(), BoxError> {
                let v = generator.forward_residual(&z, &up, true)?;
                v.sqr()?.mean_all()?.backward()?;
                Ok(())
            };
            let mut fractions = [0.0; 2];
            let mut sparse_step = |rule: usize| -> Result<(), BoxError> {
                let sites = Arc::new(active_sites(
                    &up,
                    &config.activation(),
                    &rules[rule].1,
                    g_config.kernel,
                )?);
                fractions[rule] = sites.fraction();
                let v = generator.forward_residual_active(&z, &up, &sites, true)?;
                v.sqr()?.mean_all()?.backward()?;
                Ok(())
            };
            let mut dense = Vec::new();
            let mut sparse = [Vec::new(), Vec::new()];
            // Interleaved, warm-up first, so all see the same machine.
            for rep in 0..=reps {
                let d = measure(dense_step)?;
                let s = [measure(|| sparse_step(0))?, measure(|| sparse_step(1))?];
                if rep > 0 {
                    dense.push(d);
                    sparse[0].push(s[0]);
                    sparse[1].push(s[1]);
                }
            }
            let time = |v: &[(f64, f64)]| median(v.iter().map(|m| m.0).collect());
            let peak = |v: &[(f64, f64)]| v.iter().map(|m| m.1).fold(0f64, f64::max);
            let (dt, dm) = (time(&dense), peak(&dense));
            for (rule, measured) in sparse.iter().enumerate() {
                let (st, sm) = (time(measured), peak(measured));
                println!(
                    "| {preset} | {n} | {size}^3 | {}, {} | {dt:.3} | {dm:.0} | {} | {:.0}% | {st:.3} | {sm:.0} | {:.2}x | {:.2}x |",
                    config.pyramid.channels,
                    config.pyramid.layers,
                    rules[rule].0,
                    100.0 * fractions[rule],
                    dt / st,
                    dm / sm,
                );
            }
        }
    }
    Ok(())
}
