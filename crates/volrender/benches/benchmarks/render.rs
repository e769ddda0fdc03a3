//! `volrender/composite_fwd` and `volrender/composite_fwdbwd`: grids 32/64/128, 64 and 128
//! samples, dense and sparse scenes, skipping off and on, 1 and 2 threads, on the peer's camera
//! with 4096 rays; and with post-activated density (`-post`: the same scene's densities as raw
//! values under `25 softplus(raw - 4)`, empty voxels far below the knee) on both scenes at grid
//! 64, 128 samples, 2 threads, skipping off and on.
//! Throughput is samples (rays x samples per ray), so criterion reports samples/s; rays/s is
//! that divided by the samples per ray.

use candle_core::{Tensor, Var};
use criterion::{BenchmarkId, Criterion, Throughput};
use radiance_volume::Activation;
use volrender::scenes::{make_scene, peer_rays, Scene};
use volrender::{render, DensityInterpolation, Rays, RenderConfig, Sampler};

const RAYS: usize = 4096;
/// The post-activated cases' activation: the training presets'.
const SCALE: f32 = 25.0;
const SHIFT: f32 = -4.0;

/// How samples get density.
#[derive(Clone, Copy, PartialEq)]
enum Rule {
    /// Interpolated as it is, like colour (the paper's renderer).
    Paper,
    /// Raw density, activated per sample.
    PostActivated,
}

struct Case {
    scene: Scene,
    grid: usize,
    samples: usize,
    skip: bool,
    threads: usize,
    rule: Rule,
}

impl Case {
    fn id(&self) -> String {
        let scene = match self.scene {
            Scene::Dense => "dense",
            Scene::Sparse => "sparse",
        };
        let skip = if self.skip { "skip" } else { "noskip" };
        let rule = match self.rule {
            Rule::Paper => "",
            Rule::PostActivated => "-post",
        };
        format!(
            "{scene}-g{}-m{}-{skip}-t{}{rule}",
            self.grid, self.samples, self.threads
        )
    }
}

fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    for scene in [Scene::Sparse, Scene::Dense] {
        for grid in [32, 64, 128] {
            for samples in [64, 128] {
                for skip in [false, true] {
                    for threads in [1, 2] {
                        out.push(Case {
                            scene,
                            grid,
                            samples,
                            skip,
                            threads,
                            rule: Rule::Paper,
                        });
                    }
                }
            }
        }
        for skip in [false, true] {
            out.push(Case {
                scene,
                grid: 64,
                samples: 128,
                skip,
                threads: 2,
                rule: Rule::PostActivated,
            });
        }
    }
    out
}

/// The scene with each voxel's density replaced by the raw value the post-activated cases'
/// activation maps to it (empty voxels: far below the knee, where it gives exactly 0).
fn raw_density(volume: &Tensor) -> Tensor {
    let activation = Activation::default()
        .with_density_scale(SCALE)
        .with_density_shift(SHIFT);
    let density: Vec<f32> = volume
        .get(0)
        .and_then(|d| d.flatten_all())
        .and_then(|d| d.to_vec1())
        .expect("density");
    let raw: Vec<f32> = density
        .iter()
        .map(|&sigma| activation.raw_density(sigma).unwrap_or(-1.0e4))
        .collect();
    let raw = Tensor::from_vec(
        raw,
        volume.get(0).expect("density").shape(),
        volume.device(),
    )
    .and_then(|r| r.unsqueeze(0))
    .expect("raw density");
    let channels = volume.dim(0).expect("channels");
    Tensor::cat(
        &[&raw, &volume.narrow(0, 1, channels - 1).expect("colour")],
        0,
    )
    .expect("volume")
}

fn bench(c: &mut Criterion, backward: bool) {
    let name = if backward {
        "volrender/composite_fwdbwd"
    } else {
        "volrender/composite_fwd"
    };
    let mut group = c.benchmark_group(name);
    group.sample_size(10);
    let rays: Rays = peer_rays(RAYS).expect("square ray count");
    for case in cases() {
        let volume: Tensor = make_scene(case.scene, case.grid, 0)
            .expect("scene")
            .into_tensor();
        let volume = if case.rule == Rule::PostActivated {
            raw_density(&volume)
        } else {
            volume
        };
        let var = Var::from_tensor(&volume).expect("var");
        let cfg = RenderConfig::default()
            .with_sampler(Sampler::Uniform {
                samples: case.samples,
            })
            .with_skip_empty(case.skip)
            .with_density(if case.rule == Rule::PostActivated {
                DensityInterpolation::PostActivated {
                    scale: SCALE,
                    shift: SHIFT,
                }
            } else {
                DensityInterpolation::Physical
            });
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(case.threads)
            .build()
            .expect("pool");
        group.throughput(Throughput::Elements((RAYS * case.samples) as u64));
        group.bench_function(BenchmarkId::from_parameter(case.id()), |b| {
            b.iter(|| {
                pool.install(|| {
                    let out = render(var.as_tensor(), &rays, &cfg).expect("render");
                    if backward {
                        let loss = (out.rgb - 0.5)
                            .and_then(|d| d.sqr())
                            .and_then(|d| d.mean_all())
                            .expect("loss");
                        loss.backward().expect("backward");
                    }
                })
            })
        });
    }
    group.finish();
}

fn forward(c: &mut Criterion) {
    bench(c, false);
}

fn forward_backward(c: &mut Criterion) {
    bench(c, true);
}

criterion::criterion_group!(benches, forward, forward_backward);
