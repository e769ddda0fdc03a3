//! Run time against error of the patch-pyramid texture loss when it compares a random subset of
//! each level's patches ([`Points::Random`]) instead of all of them, and with more or fewer
//! directions. Prints a Markdown table.
//!
//! Each call draws its directions (and its patches) afresh, as training does, so even the full
//! loss is a random estimate: the reference is the mean value and gradient (with respect to the
//! generated image's pixels) of `--reference-draws` full calls of 64 directions, and each setting
//! is scored over `--draws` calls with other seeds: the mean value against the reference's
//! (bias), the spread of the values, the mean relative distance of its gradient from the
//! reference gradient, and their mean cosine. Time is the median of the calls, forward and
//! backward, one thread pool of `--threads`.
//!
//! The images are two views of a dataset (`volgen scene stones --resolution 320 --out DIR`):
//! the target `--target`, and as the generated image either another view (`--generated`) or the
//! target blurred (`--blur`: a generator that is nearly right, but soft).
//!
//! ```text
//! cargo run --release -p swd-loss --example texture_error_table -- --images data/stones320/images
//! ```

use std::path::PathBuf;
use std::time::Instant;

use candle_core::{DType, Device, Tensor, Var};
use clap::Parser;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use swd_loss::{
    PatchPyramid, PatchPyramidConfig, Points, Slices, TextureLoss, TextureLossConfig, TextureTarget,
};

/// Any error, boxed.
type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Parser, Debug)]
struct Args {
    /// The dataset's images (`r_000.png`, ...).
    #[arg(long)]
    images: PathBuf,
    /// The target view.
    #[arg(long, default_value_t = 0)]
    target: usize,
    /// The view compared with it.
    #[arg(long, default_value_t = 7)]
    generated: usize,
    /// Compare the target blurred (binomial 5x5, twice) instead of another view.
    #[arg(long)]
    blur: bool,
    /// Pyramid levels (training takes 3 when the coarsest still holds a patch).
    #[arg(long, default_value_t = 3)]
    levels: usize,
    /// Full calls averaged into the reference.
    #[arg(long, default_value_t = 32)]
    reference_draws: usize,
    /// Calls per setting.
    #[arg(long, default_value_t = 12)]
    draws: usize,
    /// Rayon threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
}

/// One call: the loss and its gradient with respect to the generated image, and its time.
struct Call {
    value: f64,
    grad: Vec<f64>,
    seconds: f64,
}

fn call(
    loss: &TextureLoss<PatchPyramid>,
    generated: &Var,
    target: &TextureTarget,
    seed: u64,
) -> Result<Call> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let started = Instant::now();
    let value = loss.loss(generated.as_tensor(), target, &mut rng)?;
    let grads = value.backward()?;
    let seconds = started.elapsed().as_secs_f64();
    let grad = grads
        .get(generated.as_tensor())
        .ok_or("no gradient")?
        .flatten_all()?
        .to_dtype(DType::F64)?
        .to_vec1()?;
    Ok(Call {
        value: value.to_dtype(DType::F64)?.to_scalar()?,
        grad,
        seconds,
    })
}

/// A dataset image composited on white (as training loads it), `(1, 3, H, W)` f32 in [0, 1].
fn load(dir: &std::path::Path, view: usize) -> Result<Tensor> {
    let image = image::open(dir.join(format!("r_{view:03}.png")))?.to_rgba32f();
    let (w, h) = image.dimensions();
    let mut planes = vec![0f32; 3 * (w * h) as usize];
    for (i, p) in image.pixels().enumerate() {
        for c in 0..3 {
            planes[c * (w * h) as usize + i] = p[c] * p[3] + (1.0 - p[3]);
        }
    }
    Ok(Tensor::from_vec(
        planes,
        (1, 3, h as usize, w as usize),
        &Device::Cpu,
    )?)
}

/// The 5x5 binomial filter (`[1 4 6 4 1] / 16` per axis, edges replicated) applied twice.
fn blurred(image: &Tensor) -> Result<Tensor> {
    let mut x = image.clone();
    for _ in 0..2 {
        for dim in [2, 3] {
            let n = x.dim(dim)?;
            let padded = x.pad_with_same(dim, 2, 2)?;
            let mut sum = padded.narrow(dim, 0, n)?.zeros_like()?;
            for (shift, tap) in [1.0, 4.0, 6.0, 4.0, 1.0].into_iter().enumerate() {
                sum = (sum + (padded.narrow(dim, shift, n)? * (tap / 16.0))?)?;
            }
            x = sum;
        }
    }
    Ok(x)
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|a| a * a).sum::<f64>().sqrt()
}

fn main() -> Result<()> {
    let a = Args::parse();
    rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads)
        .build_global()?;
    let target_image = load(&a.images, a.target)?;
    let generated_image = if a.blur {
        blurred(&target_image)?
    } else {
        load(&a.images, a.generated)?
    };
    let generated = Var::from_tensor(&generated_image)?;
    let pyramid = PatchPyramid::new(PatchPyramidConfig::default().with_levels(a.levels))?;
    let make = |points: Points, slices: usize| {
        TextureLoss::new(
            pyramid,
            TextureLossConfig::default()
                .with_points(points)
                .with_slices(Slices::Fixed(slices)),
        )
    };
    let full = make(Points::All, 64)?;
    let target = full.target(&target_image)?;
    let sizes: Vec<usize> = target
        .maps()
        .iter()
        .map(|m| m.point_count())
        .collect::<swd_loss::Result<_>>()?;

    let reference: Vec<Call> = (0..a.reference_draws as u64)
        .map(|s| call(&full, &generated, &target, 1_000_000 + s))
        .collect::<Result<_>>()?;
    let ref_value = reference.iter().map(|c| c.value).sum::<f64>() / reference.len() as f64;
    let mut ref_grad = vec![0f64; reference[0].grad.len()];
    for c in &reference {
        ref_grad.iter_mut().zip(&c.grad).for_each(|(r, g)| *r += g);
    }
    ref_grad
        .iter_mut()
        .for_each(|r| *r /= reference.len() as f64);
    let ref_norm = norm(&ref_grad);

    let case = if a.blur {
        format!("view {} blurred against itself", a.target)
    } else {
        format!("view {} against view {}", a.generated, a.target)
    };
    println!(
        "{case}, {}x{} pixels, {} levels of 7x7 patches ({:?} points); reference: {} full calls \
         of 64 directions, value {ref_value:.6}",
        target_image.dim(3)?,
        target_image.dim(2)?,
        a.levels,
        sizes,
        a.reference_draws
    );
    println!();
    println!("| points per level | directions | ms per call | value bias | value spread | gradient error | cosine |");
    println!("|---|---|---|---|---|---|---|");
    let mut settings = vec![(Points::All, 64), (Points::All, 128)];
    for n in [1024, 2048, 4096, 8192, 16384] {
        for k in [64, 128] {
            settings.push((Points::Random(n), k));
        }
    }
    for (points, slices) in settings {
        let loss = make(points, slices)?;
        let calls: Vec<Call> = (0..a.draws as u64)
            .map(|s| call(&loss, &generated, &target, s))
            .collect::<Result<_>>()?;
        let count = calls.len() as f64;
        let mean = calls.iter().map(|c| c.value).sum::<f64>() / count;
        let spread = (calls.iter().map(|c| (c.value - mean).powi(2)).sum::<f64>() / count).sqrt();
        let error = calls
            .iter()
            .map(|c| {
                let diff: Vec<f64> = c.grad.iter().zip(&ref_grad).map(|(g, r)| g - r).collect();
                norm(&diff) / ref_norm
            })
            .sum::<f64>()
            / count;
        let cosine = calls
            .iter()
            .map(|c| {
                let dot: f64 = c.grad.iter().zip(&ref_grad).map(|(g, r)| g * r).sum();
                dot / (norm(&c.grad) * ref_norm)
            })
            .sum::<f64>()
            / count;
        let mut times: Vec<f64> = calls.iter().map(|c| c.seconds).collect();
        times.sort_by(f64::total_cmp);
        let label = match points {
            Points::All => "all".to_string(),
            Points::Random(n) => n.to_string(),
        };
        println!(
            "| {label} | {slices} | {:.1} | {:+.3} | {:.3} | {:.3} | {:.3} |",
            1e3 * times[times.len() / 2],
            (mean - ref_value) / ref_value,
            spread / ref_value,
            error,
            cosine
        );
    }
    Ok(())
}
