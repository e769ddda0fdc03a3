//! One resampling step as training runs it between pyramid scales, timed the way
//! `benches/resample_peer.py` times PyTorch's `F.interpolate(mode="trilinear")` on the same
//! sizes, and printed as the same JSON line, so `benches/compare_resample_peer.sh` can put the
//! two side by side: a `(1, C, S, S, S)` normal volume to `(1, C, T, T, T)` with
//! [`radiance_volume::resample_tensor`], forward alone and forward + backward of `sum(y * p)`
//! for a fixed random `p`.
//!
//! ```text
//! cargo run --release -p radiance-volume --example resample_step -- --from 89 --to 126 --channels 4 --threads 2
//! ```
//!
//! `--threads N` sets `RAYON_NUM_THREADS` before the first parallel call, as a user would from
//! the shell. `forward_seconds` and `backward_seconds` (forward + backward) are medians of
//! `--repeat` runs after one warm-up.

// Setting the environment (`std::env::set_var`) is `unsafe`; nothing else here is.
#![allow(unsafe_code)]

use std::time::Instant;

use candle_core::{DType, Device, Tensor, Var};
use radiance_volume::{resample_tensor, GridDims};

/// Any error, boxed.
type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// The value after `--name` in `args`, parsed, or `default`.
fn flag(args: &[String], name: &str, default: usize) -> Result<usize> {
    match args.iter().position(|a| a == name) {
        Some(i) => {
            let value = args
                .get(i + 1)
                .ok_or_else(|| format!("{name} needs a value"))?;
            Ok(value
                .parse()
                .map_err(|e| format!("{name} {value}: expected a whole number ({e})"))?)
        }
        None => Ok(default),
    }
}

/// The median of `repeat` timings of `step`, after one warm-up run.
fn median_seconds(repeat: usize, mut step: impl FnMut() -> Result<()>) -> Result<f64> {
    step()?;
    let mut times = Vec::with_capacity(repeat);
    for _ in 0..repeat {
        let started = Instant::now();
        step()?;
        times.push(started.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok(times[times.len() / 2])
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let from = flag(&args, "--from", 89)?;
    let to = flag(&args, "--to", 126)?;
    let channels = flag(&args, "--channels", 4)?;
    let threads = flag(&args, "--threads", 2)?;
    let repeat = flag(&args, "--repeat", 10)?.max(1);
    // SAFETY: no other thread runs yet.
    unsafe { std::env::set_var("RAYON_NUM_THREADS", threads.to_string()) };
    let device = Device::Cpu;
    let x = Var::from_tensor(&Tensor::randn(
        0f32,
        1.0,
        (1, channels, from, from, from),
        &device,
    )?)?;
    let probe = Tensor::rand(0f32, 1.0, (1, channels, to, to, to), &device)?;
    let dims = GridDims::cube(to);
    let forward = median_seconds(repeat, || {
        resample_tensor(x.as_tensor(), dims)?;
        Ok(())
    })?;
    let backward = median_seconds(repeat, || {
        let y = resample_tensor(x.as_tensor(), dims)?;
        let grads = (y * &probe)?.sum_all()?.backward()?;
        grads.get(x.as_tensor()).ok_or("no gradient")?;
        Ok(())
    })?;
    let dtype = DType::F32;
    println!(
        "{{\"what\": \"resample\", \"from\": {from}, \"to\": {to}, \"channels\": {channels}, \
         \"threads\": {threads}, \"dtype\": \"{dtype:?}\", \"forward_seconds\": {forward:.6}, \
         \"backward_seconds\": {backward:.6}}}"
    );
    Ok(())
}
