//! `volgen compose MODEL --out DIR [--base SEED] --take SEED:X0,Y0,Z0,X1,Y1,Z1 --at DX,DY,DZ
//! ...`: the paper's composition. Objects (boxes) of several generated scenes, each the scene
//! `volgen sample --seed SEED` makes first, are put into one base scene (another seed's, or
//! V*'s ground with its objects cleared), and the result is harmonised by re-running the finer
//! generators; writes `base`, `composed` and `harmonized` volumes with PNG views, as `volgen
//! edit` writes its scenes.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{ensure, Result};
use candle_core::Tensor;
use glam::Vec3;
use radiance_volume::Aabb;
use rand::SeedableRng;
use singrav::applications::{empty_voxel, ground, Placement};
use singrav::SinGrav;

use super::harmonize::{harmonize_and_write, HarmonizeArgs};
use super::model_io::{load_model, Outputs, SceneWriter};
use super::scene_boxes::{parse_box, parse_offset, ModelFrame};

/// Arguments of `volgen compose`.
#[derive(Debug, clap::Args)]
pub struct ComposeArgs {
    /// A trained model: a run directory or its checkpoint.
    model: PathBuf,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// The scene the objects go into: the scene of this seed (as `volgen sample --seed SEED`
    /// makes first). Without it, empty ground: the reconstruction V* with every object
    /// narrower than a quarter of the scene cleared down to its ground.
    #[arg(long, value_name = "SEED")]
    base: Option<u64>,
    /// An object to take: a box (scene coordinates, Z up) of the scene of SEED. Repeatable;
    /// each needs its --at.
    #[arg(
        long,
        value_name = "SEED:X0,Y0,Z0,X1,Y1,Z1",
        value_parser = parse_take,
        requires = "at",
        allow_hyphen_values = true
    )]
    take: Vec<(u64, Aabb)>,
    /// Where the matching --take goes: its offset from where it stood (world units, rounded to
    /// whole voxels; 0,0,0 keeps its place).
    #[arg(
        long,
        value_name = "DX,DY,DZ",
        value_parser = parse_offset,
        requires = "take",
        allow_hyphen_values = true
    )]
    at: Vec<Vec3>,
    /// Seed of the harmonisation's noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    harmonize: HarmonizeArgs,
    /// Views rendered per volume.
    #[arg(long, default_value_t = 3)]
    views: usize,
    #[command(flatten)]
    outputs: Outputs,
}

/// Parses `SEED:x0,y0,z0,x1,y1,z1`.
fn parse_take(text: &str) -> Result<(u64, Aabb), String> {
    let (seed, region) = text.split_once(':').ok_or_else(|| {
        format!("expected SEED:x0,y0,z0,x1,y1,z1 (a scene's seed, a colon, a box), got \"{text}\"")
    })?;
    let seed = seed.trim().parse().map_err(|_| {
        format!("expected a seed (a whole number >= 0) before the colon, got \"{seed}\"")
    })?;
    Ok((seed, parse_box(region)?))
}

impl ComposeArgs {
    /// The placements with their source seeds, in the order given, each checked against the
    /// volume box; boxes and offsets in the scene's coordinates, mapped into the model's cube.
    fn placements(&self, frame: ModelFrame<'_>) -> Result<Vec<(u64, Placement)>> {
        ensure!(
            !self.take.is_empty(),
            "nothing to compose: give --take SEED:X0,Y0,Z0,X1,Y1,Z1 --at DX,DY,DZ"
        );
        ensure!(
            self.take.len() == self.at.len(),
            "--take: each needs its --at (got {} --take and {} --at)",
            self.take.len(),
            self.at.len()
        );
        let placements: Vec<(u64, Placement)> = self
            .take
            .iter()
            .zip(&self.at)
            .map(|((seed, region), offset)| {
                let placement = Placement {
                    region: frame.place(region),
                    offset: frame.shift(offset),
                };
                (*seed, placement)
            })
            .collect();
        for (_, placement) in &placements {
            placement.validate()?;
        }
        Ok(placements)
    }
}

/// The scene `volgen sample --seed seed` makes first.
fn scene_of(model: &SinGrav, seed: u64) -> Result<Tensor> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    Ok(model.generate_random(&mut rng)?)
}

/// Generates the base and the sources, composes, harmonises, and writes the three.
pub fn run(args: &ComposeArgs) -> Result<()> {
    let model = load_model(&args.model)?;
    let placements = args.placements(ModelFrame {
        bounds: model.config().run.bounds.as_ref(),
    })?;
    let harmonize_from = args.harmonize.start_scale(&model)?;
    let writer = SceneWriter::new(&model, args.views, &args.out, args.outputs)?;

    let started = Instant::now();
    let (base, what) = match args.base {
        Some(seed) => (scene_of(&model, seed)?, format!("the scene of seed {seed}")),
        None => {
            let v_star = model.reconstruct()?;
            let empty = empty_voxel(&v_star, &model.config().activation())?;
            let finest = model.config().pyramid.volume_sizes[model.volume_scales() - 1];
            let voxel = 2.0 / finest as f32;
            let cleared = ground(&v_star, &model.config().activation(), voxel, &empty)?;
            (cleared, "the ground of V*".to_string())
        }
    };
    writer.write(
        "base",
        &base,
        format!("{what}, made in {:.3} s", started.elapsed().as_secs_f64()),
    )?;

    let started = Instant::now();
    let mut sources: BTreeMap<u64, Tensor> = BTreeMap::new();
    let mut composed = base;
    for (seed, placement) in &placements {
        if !sources.contains_key(seed) {
            sources.insert(*seed, scene_of(&model, *seed)?);
        }
        composed = placement.apply(&composed, &sources[seed])?;
    }
    let summary: Vec<String> = placements
        .iter()
        .map(|(seed, placement)| format!("seed {seed}: {placement}"))
        .collect();
    writer.write(
        "composed",
        &composed,
        format!(
            "{} in {:.3} s",
            summary.join("; "),
            started.elapsed().as_secs_f64()
        ),
    )?;

    if let Some(from) = harmonize_from {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
        harmonize_and_write(&composed, from, &mut rng, &writer)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::parse_take;

    #[test]
    fn takes_parse_a_seed_and_a_box_and_name_what_is_wrong() {
        let (seed, region) = parse_take("7:-0.5,-0.5,-1,0,0,0").unwrap();
        assert_eq!(seed, 7);
        assert_eq!(region.min.to_array(), [-0.5, -0.5, -1.0]);
        assert_eq!(region.max.to_array(), [0.0, 0.0, 0.0]);
        assert!(parse_take("-0.5,-0.5,-1,0,0,0")
            .unwrap_err()
            .contains("SEED:"));
        assert!(parse_take("x:0,0,0,1,1,1").unwrap_err().contains("seed"));
        assert!(parse_take("3:0,0,0,1,1").unwrap_err().contains("six"));
        assert!(parse_take("3:1,0,0,0,1,1").unwrap_err().contains("empty"));
    }
}
