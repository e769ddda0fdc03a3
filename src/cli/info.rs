//! `volgen info VOLUME`: what a volume file holds.

use std::path::PathBuf;

use anyhow::Result;
use radiance_volume::RadianceVolume;

/// Arguments of `volgen info`.
#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// A volume in volgen's safetensors format.
    volume: PathBuf,
}

/// Loads the volume and prints its summary.
pub fn run(args: &InfoArgs) -> Result<()> {
    let v = RadianceVolume::load_safetensors(&args.volume)?;
    let d = v.dims();
    let b = v.aabb();
    println!("{}", args.volume.display());
    println!(
        "  grid     {} x {} x {} (D x H x W), {} voxels",
        d.d,
        d.h,
        d.w,
        d.voxel_count()
    );
    println!("  box      {} .. {}", b.min, b.max);
    let per_channel = v.tensor().flatten_from(1)?;
    let mins: Vec<f32> = per_channel.min(1)?.to_vec1()?;
    let maxs: Vec<f32> = per_channel.max(1)?.to_vec1()?;
    for (c, name) in v.channel_names().iter().enumerate() {
        println!("  {c:>2} {name:<8} min {:<12} max {}", mins[c], maxs[c]);
    }
    let sigma = v.density()?.flatten_all()?;
    let occupied = sigma
        .gt(0f32)?
        .to_dtype(candle_core::DType::F32)?
        .mean_all()?;
    println!(
        "  occupied {:.2}% of voxels (sigma > 0)",
        100.0 * occupied.to_scalar::<f32>()?
    );
    Ok(())
}
