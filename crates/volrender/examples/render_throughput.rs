//! Rendering throughput, flag-compatible with the PyTorch peer (`shared/peer/torch_render.py`),
//! printing one JSON line with rays/s and samples/s (median of `--repeats` runs after
//! `--warmup`), forward and, with `--backward`, forward+backward of the peer's loss
//! `mean((colour - 0.5)^2)`.
//!
//! ```text
//! cargo run --release -p volrender --example render_throughput -- \
//!     --grid 64 --samples 128 --rays 65536 --scene sparse --backward --threads 2 [--skip-empty]
//! ```
//! Like the peer, it tunes glibc's malloc first (see `volrender::tune_malloc`; `--no-mallopt` keeps the
//! defaults), so both sides allocate under the same conditions.
//!
//! `--grid-npy DIR/grid.npy` renders the `(4, D, H, W)` volume the peer saved with
//! `torch_render.py --save DIR`, over the box that puts volgen's cell centres on the peer's
//! `align_corners=True` lattice.

use std::time::Instant;

/// Any error, boxed.
type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

use candle_core::{Tensor, Var};
use clap::Parser;
use volrender::scenes::{make_scene, peer_grid_aabb, peer_rays, Scene};
use volrender::{render, RenderConfig, Sampler};

#[derive(Parser, Debug)]
struct Args {
    /// Grid resolution N (the volume is 4 x N^3).
    #[arg(long, default_value_t = 64)]
    grid: usize,
    /// Number of rays (a perfect square: a square image).
    #[arg(long, default_value_t = 65536)]
    rays: usize,
    /// Samples per ray M.
    #[arg(long, default_value_t = 128)]
    samples: usize,
    /// Rayon threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// `dense` or `sparse`.
    #[arg(long, default_value = "dense")]
    scene: String,
    /// Also time forward+backward.
    #[arg(long)]
    backward: bool,
    /// `mid` (volgen's default) or `left` (the peer's default).
    #[arg(long, default_value = "mid")]
    sampling: String,
    /// Skip empty space through an occupancy grid.
    #[arg(long)]
    skip_empty: bool,
    /// Voxels per occupancy cell.
    #[arg(long, default_value_t = 4)]
    cell: usize,
    /// Early-termination threshold.
    #[arg(long, default_value_t = 0.0)]
    epsilon: f32,
    /// Render this `(4, D, H, W)` .npy volume (saved by the peer) instead of a built-in scene.
    #[arg(long)]
    grid_npy: Option<String>,
    /// A directory the peer wrote with `--save`: render its grid along its rays and report the
    /// colour RMSE against its `colour.npy` (implies its grid; use the peer's `--sampling`).
    #[arg(long)]
    peer_dir: Option<String>,
    #[arg(long, default_value_t = 2)]
    warmup: usize,
    #[arg(long, default_value_t = 7)]
    repeats: usize,
    /// Keep glibc's default malloc behaviour (as the peer's `--no-mallopt`).
    #[arg(long)]
    no_mallopt: bool,
    /// Seed of the dense scene.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// Returns the median and all run times in seconds.
fn time(
    warmup: usize,
    repeats: usize,
    mut f: impl FnMut() -> Result<()>,
) -> Result<(f64, Vec<f64>)> {
    for _ in 0..warmup {
        f()?;
    }
    let mut runs = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t = Instant::now();
        f()?;
        runs.push(t.elapsed().as_secs_f64());
    }
    let mut sorted = runs.clone();
    sorted.sort_by(f64::total_cmp);
    Ok((sorted[sorted.len() / 2], runs))
}

fn main() -> Result<()> {
    let a = Args::parse();
    let mallopt = !a.no_mallopt && volrender::tune_malloc();
    // As the `volgen` binary does: this thread is one of the pool's.
    volrender::join_global_pool(Some(a.threads))?;
    let grid_npy = a
        .peer_dir
        .as_ref()
        .map(|d| format!("{d}/grid.npy"))
        .or(a.grid_npy.clone());
    let (volume, aabb) = match &grid_npy {
        Some(path) => {
            let t = Tensor::read_npy(path)?;
            let n = t.dim(3)?;
            (t, peer_grid_aabb(n)?)
        }
        None => {
            let v = make_scene(a.scene.parse::<Scene>()?, a.grid, a.seed)?;
            let aabb = v.aabb();
            (v.into_tensor(), aabb)
        }
    };
    let rays = match &a.peer_dir {
        Some(dir) => {
            let read = |name: &str| -> Result<Vec<[f32; 3]>> {
                let t: Vec<Vec<f32>> = Tensor::read_npy(format!("{dir}/{name}"))?.to_vec2()?;
                Ok(t.into_iter().map(|v| [v[0], v[1], v[2]]).collect())
            };
            volrender::Rays::new(read("rays_o.npy")?, read("rays_d.npy")?)?
        }
        None => peer_rays(a.rays)?,
    };
    let r = rays.len() as f64;
    let sampler = match a.sampling.as_str() {
        "mid" => Sampler::Uniform { samples: a.samples },
        "left" => Sampler::UniformLeft { samples: a.samples },
        other => return Err(format!("--sampling must be mid or left, got {other}").into()),
    };
    let cfg = RenderConfig {
        occupancy_cell: a.cell,
        ..RenderConfig::default()
    }
    .with_sampler(sampler)
    .with_aabb(aabb)
    .with_epsilon(a.epsilon)
    .with_skip_empty(a.skip_empty);

    let (fwd_s, fwd_runs) = time(a.warmup, a.repeats, || {
        render(&volume, &rays, &cfg)?;
        Ok(())
    })?;
    let hit = {
        let out = render(&volume, &rays, &cfg.with_opacity(true))?;
        let hits: f32 = out
            .opacity
            .unwrap_or(out.rgb)
            .gt(0.0)?
            .to_dtype(candle_core::DType::F32)?
            .mean_all()?
            .to_scalar()?;
        hits
    };
    let m = a.samples as f64;
    let mut res = serde_json::json!({
        "impl": "volrender-cpu", "scene": grid_npy.clone().unwrap_or(a.scene.clone()), "grid": volume.dim(3)?,
        "rays": rays.len(), "samples": a.samples, "threads": a.threads, "sampling": a.sampling,
        "skip_empty": a.skip_empty, "cell": a.cell, "epsilon": a.epsilon, "mallopt": mallopt,
        "hit_opacity_fraction": hit,
        "fwd_s": fwd_s, "fwd_rays_per_s": r / fwd_s, "fwd_samples_per_s": r * m / fwd_s,
        "fwd_runs_s": fwd_runs,
    });
    if let Some(dir) = &a.peer_dir {
        let theirs: Vec<f32> = Tensor::read_npy(format!("{dir}/colour.npy"))?
            .flatten_all()?
            .to_vec1()?;
        let ours: Vec<f32> = render(&volume, &rays, &cfg)?.rgb.flatten_all()?.to_vec1()?;
        let se: f64 = ours
            .iter()
            .zip(&theirs)
            .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
            .sum();
        res["colour_rmse_vs_peer"] = (se / ours.len() as f64).sqrt().into();
    }
    if a.backward {
        let var = Var::from_tensor(&volume)?;
        let (s, runs) = time(a.warmup, a.repeats, || {
            let out = render(var.as_tensor(), &rays, &cfg)?;
            let loss = (out.rgb - 0.5)?.sqr()?.mean_all()?;
            loss.backward()?;
            Ok(())
        })?;
        res["fwdbwd_s"] = s.into();
        res["fwdbwd_rays_per_s"] = (r / s).into();
        res["fwdbwd_samples_per_s"] = (r * m / s).into();
        res["fwdbwd_runs_s"] = runs.into();
    }
    println!("{res}");
    Ok(())
}
