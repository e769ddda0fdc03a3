//! Run time against error: for each sampler setting, early-termination threshold and skipping,
//! the median forward time (f32) and the colour / opacity RMSE against a float64 reference
//! rendered with the per-voxel sampler at k = 64 (a very fine midpoint step), on the dense and
//! sparse scenes and the peer's camera. Prints a Markdown table.
//!
//! ```text
//! cargo run --release -p volrender --example render_error_table -- --grid 32 --rays 4096 --threads 2
//! ```

use std::time::Instant;

use candle_core::{DType, Tensor};
use clap::Parser;
use volrender::scenes::{make_scene, peer_rays, Scene};
use volrender::{render, Rays, RenderConfig, Sampler};

/// Any error, boxed.
type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Parser, Debug)]
struct Args {
    /// Grid resolution N.
    #[arg(long, default_value_t = 32)]
    grid: usize,
    /// Number of rays (a perfect square).
    #[arg(long, default_value_t = 4096)]
    rays: usize,
    /// Rayon threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Timed runs per setting (median reported).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
}

/// Renders and returns (colour, opacity) as f64.
fn run(volume: &Tensor, rays: &Rays, cfg: &RenderConfig) -> Result<(Vec<f64>, Vec<f64>)> {
    let out = render(volume, rays, &cfg.with_opacity(true))?;
    let flat =
        |t: &Tensor| -> Result<Vec<f64>> { Ok(t.flatten_all()?.to_dtype(DType::F64)?.to_vec1()?) };
    Ok((
        flat(&out.rgb)?,
        flat(out.opacity.as_ref().ok_or("no opacity")?)?,
    ))
}

fn rmse(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

fn main() -> Result<()> {
    let a = Args::parse();
    volrender::join_global_pool(Some(a.threads))?;
    let rays = peer_rays(a.rays)?;
    println!("| scene | sampler | epsilon | skip | forward ms | colour RMSE | opacity RMSE |");
    println!("|---|---|---|---|---|---|---|");
    for (scene, name) in [(Scene::Dense, "dense"), (Scene::Sparse, "sparse")] {
        let v32 = make_scene(scene, a.grid, 0)?.into_tensor();
        let v64 = v32.to_dtype(DType::F64)?;
        let fine = RenderConfig::default().with_sampler(Sampler::PerVoxel { per_voxel: 64 });
        let (ref_rgb, ref_opacity) = run(&v64, &rays, &fine)?;
        let mut settings: Vec<(Sampler, f32, bool)> = Vec::new();
        for m in [32, 64, 128, 256] {
            settings.push((Sampler::UniformLeft { samples: m }, 0.0, false));
            settings.push((Sampler::Uniform { samples: m }, 0.0, false));
        }
        for k in [1, 2, 4] {
            settings.push((Sampler::PerVoxel { per_voxel: k }, 0.0, false));
        }
        for eps in [1e-4, 1e-3, 1e-2] {
            settings.push((Sampler::Uniform { samples: 128 }, eps, false));
            settings.push((Sampler::PerVoxel { per_voxel: 2 }, eps, false));
        }
        settings.push((Sampler::Uniform { samples: 128 }, 0.0, true));
        settings.push((Sampler::PerVoxel { per_voxel: 2 }, 0.0, true));
        settings.push((Sampler::PerVoxel { per_voxel: 2 }, 1e-3, true));
        for (sampler, eps, skip) in settings {
            let cfg = RenderConfig::default()
                .with_sampler(sampler)
                .with_epsilon(eps)
                .with_skip_empty(skip);
            let mut times = Vec::new();
            let mut result = None;
            for _ in 0..a.repeats.max(1) {
                let t = Instant::now();
                result = Some(run(&v32, &rays, &cfg)?);
                times.push(t.elapsed().as_secs_f64() * 1e3);
            }
            times.sort_by(f64::total_cmp);
            let (rgb, opacity) = result.ok_or("no run")?;
            println!(
                "| {name} | {sampler:?} | {eps} | {skip} | {:.1} | {:.2e} | {:.2e} |",
                times[times.len() / 2],
                rmse(&rgb, &ref_rgb),
                rmse(&opacity, &ref_opacity)
            );
        }
    }
    Ok(())
}
