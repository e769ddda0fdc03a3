//! How close depth from a fit of the views (`volgen train --depth-from-fit`, the paper's
//! "NeRF-depth") comes to a dataset's true depth: the fit in `RUN/depth_fit.safetensors` rendered
//! from every camera as `Dataset::with_depth_from` does, against the dataset's own depth maps,
//! over the foreground pixels (alpha above 0.5) where both are known. Prints the holes (pixels
//! the fit leaves thin), the mean and median absolute error and the RMSE of the ray distance
//! (depth / alpha), in world units and relative to the true distance.
//!
//! `cargo run --release -p research --example fit_depth_error -- DATASET FIT.safetensors`

use candle_core::Device;
use radiance_volume::RadianceVolume;
use rgbd_dataset::Dataset;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// A dataset's planes at full size: expected depth, opacity, and the depth mask where some
/// depth is left out.
struct Planes {
    depth: Vec<f32>,
    opacity: Vec<f32>,
    mask: Option<Vec<f32>>,
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dataset, fit] = args.as_slice() else {
        return Err("usage: fit_depth_error DATASET FIT.safetensors".into());
    };
    let truth = Dataset::load(dataset.as_ref(), [1.0; 3])?;
    let volume = RadianceVolume::load_safetensors(fit)?;
    let (fitted, coverage) = truth.with_depth_from(&volume)?;
    let (w, h) = (truth.width(), truth.height());
    let planes = |d: &Dataset| -> Result<Planes> {
        let level = d.level(w, h, &Device::Cpu)?;
        let mask = match &level.depth_mask {
            Some(m) => Some(m.flatten_all()?.to_vec1()?),
            None => None,
        };
        Ok(Planes {
            depth: level.depths.flatten_all()?.to_vec1()?,
            opacity: level.opacity.flatten_all()?.to_vec1()?,
            mask,
        })
    };
    let Planes {
        depth: true_depth,
        opacity: alpha,
        mask: true_mask,
    } = planes(&truth)?;
    let Planes {
        depth: fit_depth,
        mask: fit_mask,
        ..
    } = planes(&fitted)?;
    let known = |mask: &Option<Vec<f32>>, i: usize| mask.as_ref().is_none_or(|m| m[i] > 0.0);
    let mut errors = Vec::new();
    let mut relative = Vec::new();
    for i in 0..alpha.len() {
        if alpha[i] > 0.5 && known(&true_mask, i) && known(&fit_mask, i) {
            let (t, f) = (true_depth[i] / alpha[i], fit_depth[i] / alpha[i]);
            errors.push((f - t).abs());
            relative.push((f - t).abs() / t);
        }
    }
    let median = |v: &mut Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let mean = errors.iter().sum::<f32>() / errors.len() as f32;
    let rmse = (errors.iter().map(|e| e * e).sum::<f32>() / errors.len() as f32).sqrt();
    println!(
        "holes: {} of {} foreground pixels ({:.2}%)",
        coverage.holes,
        coverage.foreground,
        100.0 * coverage.holes as f64 / coverage.foreground as f64
    );
    println!(
        "ray distance over {} pixels: mean abs error {mean:.4}, median {:.4}, RMSE {rmse:.4} world \
         units; median relative error {:.2}%",
        errors.len(),
        median(&mut errors),
        100.0 * median(&mut relative)
    );
    Ok(())
}
