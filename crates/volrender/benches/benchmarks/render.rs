//! `volrender/composite_fwd` and `volrender/composite_fwdbwd`: grids 32/64/128, 64 and 128
//! samples, dense and sparse scenes, skipping off and on, 1 and 2 threads, on the peer's camera
//! with 4096 rays; and with density-weighted colour (`-weighted`) on both scenes at grid 64, 128
//! samples, 2 threads, skipping off and on. Throughput is samples (rays x samples per ray), so criterion reports
//! samples/s; rays/s is that divided by the samples per ray.

use candle_core::{Tensor, Var};
use criterion::{BenchmarkId, Criterion, Throughput};
use volrender::scenes::{make_scene, peer_rays, Scene};
use volrender::{render, ColourInterpolation, Rays, RenderConfig, Sampler};

const RAYS: usize = 4096;

struct Case {
    scene: Scene,
    grid: usize,
    samples: usize,
    skip: bool,
    threads: usize,
    weighted: bool,
}

impl Case {
    fn id(&self) -> String {
        let scene = match self.scene {
            Scene::Dense => "dense",
            Scene::Sparse => "sparse",
        };
        let skip = if self.skip { "skip" } else { "noskip" };
        let colour = if self.weighted { "-weighted" } else { "" };
        format!(
            "{scene}-g{}-m{}-{skip}-t{}{colour}",
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
                            weighted: false,
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
                weighted: true,
            });
        }
    }
    out
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
        let var = Var::from_tensor(&volume).expect("var");
        let cfg = RenderConfig::default()
            .with_sampler(Sampler::Uniform {
                samples: case.samples,
            })
            .with_skip_empty(case.skip)
            .with_colour_interpolation(ColourInterpolation::density_weighted_if(case.weighted));
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
