//! `volgen scene NAME --out DIR`: render a built-in procedural scene into an RGB-D dataset
//! (NeRF `transforms.json`, colour and depth images) on the paper's camera hemisphere.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::builder::TypedValueParser;
use rgbd_dataset::scenes::SceneKind;
use rgbd_dataset::{write_built_in, DatasetSpec};

/// Arguments of `volgen scene`.
#[derive(Debug, clap::Args)]
pub struct SceneArgs {
    /// The built-in scene.
    #[arg(value_parser = built_in_scenes())]
    name: SceneKind,
    /// Output directory (transforms.json, images/, depth/).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Number of views.
    #[arg(long, default_value_t = 100)]
    views: usize,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 128)]
    resolution: usize,
    /// The scene is baked on a GRID^3 volume before rendering.
    #[arg(long, default_value_t = 128)]
    grid: usize,
    /// Seed of the scene's layout and of the camera placement.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// The built-in scenes as a command line takes them, each with what it is (`--help` lists
/// them).
pub fn built_in_scenes() -> impl clap::builder::TypedValueParser<Value = SceneKind> {
    let names = SceneKind::ALL
        .map(|kind| clap::builder::PossibleValue::new(kind.name()).help(kind.about()));
    clap::builder::PossibleValuesParser::new(names)
        .try_map(|name: String| name.parse::<SceneKind>())
}

/// Bakes, renders and writes the dataset, then says where.
pub fn run(args: &SceneArgs) -> Result<()> {
    let spec = DatasetSpec {
        views: args.views,
        resolution: args.resolution,
        grid: args.grid,
        seed: args.seed,
    };
    let summary = write_built_in(args.name, args.seed, &args.out, &spec)
        .with_context(|| format!("writing the `{}` dataset", args.name))?;
    println!(
        "wrote {} views of `{}` at {}x{} in {:.1} s: {}",
        summary.views,
        args.name,
        summary.resolution,
        summary.resolution,
        summary.seconds,
        summary.transforms.display()
    );
    Ok(())
}
