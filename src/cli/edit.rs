//! `volgen edit MODEL --seed S --out DIR --remove BOX --duplicate BOX --to OFFSET --move BOX
//! --by OFFSET`: the paper's scene editing. Generates the scene of the seed (the same as
//! `volgen sample --seed S` makes first), applies the edits to its finest raw volume, and
//! harmonises the result by re-running the finer generators; writes `original`, `edited` and
//! `harmonized` volumes with PNG views.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{ensure, Result};
use glam::Vec3;
use radiance_volume::Aabb;
use rand::SeedableRng;
use singrav::applications::{empty_voxel, Edit};

use super::extent::ExtentArgs;
use super::harmonize::{harmonize_and_write, HarmonizeArgs};
use super::model_io::{load_model, Outputs, SceneWriter};
use super::scene_boxes::{parse_box, parse_offset, ModelFrame};

/// Arguments of `volgen edit`.
#[derive(Debug, clap::Args)]
pub struct EditArgs {
    /// A trained model: a run directory or its checkpoint.
    model: PathBuf,
    /// Seed of the scene to edit (the scene `volgen sample --seed S` writes first).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Empty a box (scene coordinates, Z up: inside [-1, 1]^3, or the cube of the run's
    /// --bounds, grown by --extent). Repeatable. Edits apply in the order: removals,
    /// duplicates, moves.
    #[arg(
        long,
        value_name = "X0,Y0,Z0,X1,Y1,Z1",
        value_parser = parse_box,
        allow_hyphen_values = true
    )]
    remove: Vec<Aabb>,
    /// Copy a box's content to the place given by the matching --to. Repeatable.
    #[arg(
        long,
        value_name = "X0,Y0,Z0,X1,Y1,Z1",
        value_parser = parse_box,
        requires = "to",
        allow_hyphen_values = true
    )]
    duplicate: Vec<Aabb>,
    /// Offset of the copy of the matching --duplicate (world units, rounded to whole voxels).
    #[arg(
        long,
        value_name = "DX,DY,DZ",
        value_parser = parse_offset,
        requires = "duplicate",
        allow_hyphen_values = true
    )]
    to: Vec<Vec3>,
    /// Move a box's content by the matching --by (the box is emptied). Repeatable.
    #[arg(
        long = "move",
        value_name = "X0,Y0,Z0,X1,Y1,Z1",
        value_parser = parse_box,
        requires = "by",
        allow_hyphen_values = true
    )]
    move_box: Vec<Aabb>,
    /// Offset of the matching --move (world units, rounded to whole voxels).
    #[arg(
        long,
        value_name = "DX,DY,DZ",
        value_parser = parse_offset,
        requires = "move_box",
        allow_hyphen_values = true
    )]
    by: Vec<Vec3>,
    #[command(flatten)]
    harmonize: HarmonizeArgs,
    #[command(flatten)]
    extent: ExtentArgs,
    /// Views rendered per volume.
    #[arg(long, default_value_t = 3)]
    views: usize,
    #[command(flatten)]
    outputs: Outputs,
}

impl EditArgs {
    /// The edits in the order they apply, each checked against the volume box; boxes and
    /// offsets are in the scene's coordinates, mapped into the model's cube when the run was
    /// trained with `bounds`.
    fn edits(&self, frame: ModelFrame<'_>, model_box: Aabb) -> Result<Vec<Edit>> {
        ensure!(
            self.duplicate.len() == self.to.len(),
            "--duplicate: each needs its --to (got {} --duplicate and {} --to)",
            self.duplicate.len(),
            self.to.len()
        );
        ensure!(
            self.move_box.len() == self.by.len(),
            "--move: each needs its --by (got {} --move and {} --by)",
            self.move_box.len(),
            self.by.len()
        );
        let (place, shift) = (|r: &Aabb| frame.place(r), |o: &Vec3| frame.shift(o));
        let removals = self.remove.iter().map(|region| Edit::Remove {
            region: place(region),
        });
        let duplicates =
            (self.duplicate.iter().zip(&self.to)).map(|(region, offset)| Edit::Duplicate {
                region: place(region),
                offset: shift(offset),
            });
        let moves = (self.move_box.iter().zip(&self.by)).map(|(region, offset)| Edit::Move {
            region: place(region),
            offset: shift(offset),
        });
        let edits: Vec<Edit> = removals.chain(duplicates).chain(moves).collect();
        ensure!(
            !edits.is_empty(),
            "nothing to edit: give --remove BOX, --duplicate BOX --to OFFSET or --move BOX --by OFFSET"
        );
        for edit in &edits {
            edit.validate_in(model_box)?;
        }
        Ok(edits)
    }
}

/// Generates the scene, edits it, harmonises it, and writes the three.
pub fn run(args: &EditArgs) -> Result<()> {
    let mut model = load_model(&args.model)?;
    args.extent.apply(&mut model)?;
    let model_box = model.model_box();
    let edits = args.edits(
        ModelFrame {
            bounds: model.config().run.bounds.as_ref(),
        },
        model_box,
    )?;
    let harmonize_from = args.harmonize.start_scale(&model)?;
    let writer = SceneWriter::new(&model, args.views, &args.out, args.outputs)?;

    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let started = Instant::now();
    let original = model.generate_random(&mut rng)?;
    writer.write(
        "original",
        &original,
        format!("generated in {:.3} s", started.elapsed().as_secs_f64()),
    )?;

    let started = Instant::now();
    let empty = empty_voxel(&original, &model.config().activation())?;
    let mut edited = original;
    for edit in &edits {
        edited = edit.apply_in(&edited, model_box, &empty)?;
    }
    let summary: Vec<String> = edits.iter().map(ToString::to_string).collect();
    writer.write(
        "edited",
        &edited,
        format!(
            "{} in {:.3} s",
            summary.join("; "),
            started.elapsed().as_secs_f64()
        ),
    )?;

    if let Some(from) = harmonize_from {
        harmonize_and_write(&edited, from, &mut rng, &writer)?;
    }
    Ok(())
}
