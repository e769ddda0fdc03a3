//! `volgen edit MODEL --seed S --out DIR --remove BOX --duplicate BOX --to OFFSET --move BOX
//! --by OFFSET`: the paper's scene editing. Generates the scene of the seed (the same as
//! `volgen sample --seed S` makes first), applies the edits to its finest raw volume, and
//! harmonises the result by re-running the finer generators; writes `original`, `edited` and
//! `harmonized` volumes with PNG views.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use glam::Vec3;
use radiance_volume::Aabb;
use rand::SeedableRng;
use rgbd_dataset::SceneBounds;
use singrav::applications::{empty_voxel, Edit};
use singrav::sample::showcase_cameras;
use singrav::SinGrav;

use super::model_io::{load_model, write_scene, Outputs};

/// The scale the paper's harmonisation re-runs the generators from.
const PAPER_HARMONIZE_FROM: usize = 3;

/// Arguments of `volgen edit`.
#[derive(Debug, clap::Args)]
pub struct EditArgs {
    /// A trained model: a run directory or its checkpoint.safetensors.
    model: PathBuf,
    /// Seed of the scene to edit (the scene `volgen sample --seed S` writes first).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Empty a box (scene coordinates, Z up: inside [-1, 1]^3, or the cube of the run's
    /// --bounds). Repeatable. Edits apply in the
    /// order: removals, duplicates, moves.
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
    /// Re-run the generators from this 3D scale on the downscaled edit (the paper: 3; at most
    /// the model's finest 3D scale, which is also the default for models with fewer scales).
    #[arg(long, value_name = "N", conflicts_with = "no_harmonize")]
    harmonize_from: Option<usize>,
    /// Skip the harmonisation; write only the original and the edited scene.
    #[arg(long)]
    no_harmonize: bool,
    /// Views rendered per volume.
    #[arg(long, default_value_t = 3)]
    views: usize,
    #[command(flatten)]
    outputs: Outputs,
}

/// `N` comma-separated finite numbers, or a message naming the expected `format`.
fn parse_numbers<const N: usize>(text: &str, format: &str) -> Result<[f32; N], String> {
    let expected = || format!("expected {format}, got \"{text}\"");
    let numbers: Vec<f32> = text
        .split(',')
        .map(|part| part.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| expected())?;
    let numbers: [f32; N] = numbers.try_into().map_err(|_| expected())?;
    if numbers.iter().any(|v| !v.is_finite()) {
        return Err(expected());
    }
    Ok(numbers)
}

/// Parses `x0,y0,z0,x1,y1,z1` into a non-empty box.
fn parse_box(text: &str) -> Result<Aabb, String> {
    let [x0, y0, z0, x1, y1, z1] =
        parse_numbers(text, "six comma-separated numbers x0,y0,z0,x1,y1,z1")?;
    let (min, max) = (Vec3::new(x0, y0, z0), Vec3::new(x1, y1, z1));
    if min.cmpge(max).any() {
        return Err(format!(
            "the box \"{text}\" is empty: expected x0 < x1, y0 < y1 and z0 < z1"
        ));
    }
    Aabb::try_new(min, max).map_err(|e| e.to_string())
}

/// Parses `dx,dy,dz`.
fn parse_offset(text: &str) -> Result<Vec3, String> {
    let [dx, dy, dz] = parse_numbers(text, "three comma-separated numbers dx,dy,dz")?;
    Ok(Vec3::new(dx, dy, dz))
}

impl EditArgs {
    /// The edits in the order they apply, each checked against the volume box; boxes and
    /// offsets are in the scene's coordinates, mapped into the model's cube when the run was
    /// trained with `bounds`.
    fn edits(&self, bounds: Option<&SceneBounds>) -> Result<Vec<Edit>> {
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
        let place = |region: &Aabb| match bounds {
            Some(b) => Aabb {
                min: b.to_model(region.min),
                max: b.to_model(region.max),
            },
            None => *region,
        };
        let shift = |offset: &Vec3| bounds.map_or(*offset, |b| *offset / b.half_side());
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
            edit.validate()?;
        }
        Ok(edits)
    }

    /// The scale harmonisation re-runs the generators from, or `None` to skip it.
    fn harmonize_from(&self, model: &SinGrav) -> Result<Option<usize>> {
        let finest = model.volume_scales();
        match self.harmonize_from {
            _ if self.no_harmonize => Ok(None),
            Some(from) if (2..=finest).contains(&from) => Ok(Some(from)),
            Some(from) => bail!(
                "--harmonize-from: expected a 3D scale of this model from 2 to {finest}, got {from}"
            ),
            None if finest < 2 => {
                eprintln!("note: the model has one 3D scale, nothing to harmonise with");
                Ok(None)
            }
            None => {
                let from = PAPER_HARMONIZE_FROM.min(finest);
                if from < PAPER_HARMONIZE_FROM {
                    eprintln!(
                        "note: the model's finest 3D scale is {finest}; harmonising from scale \
                         {from} rather than the paper's {PAPER_HARMONIZE_FROM}"
                    );
                }
                Ok(Some(from))
            }
        }
    }
}

/// Names the generators G_from .. G_to for messages.
fn generators(from: usize, to: usize) -> String {
    if from == to {
        format!("G_{from}")
    } else {
        format!("G_{from}..G_{to}")
    }
}

/// Generates the scene, edits it, harmonises it, and writes the three.
pub fn run(args: &EditArgs) -> Result<()> {
    let model = load_model(&args.model)?;
    let edits = args.edits(model.config().run.bounds.as_ref())?;
    let harmonize_from = args.harmonize_from(&model)?;
    let cameras = showcase_cameras(args.views, model.render_size())?;
    let write = |stem: &str, raw: &candle_core::Tensor, what: String| -> Result<()> {
        let volume = args.outputs.volume(&model, raw)?;
        let views = model.render_raw(raw, &cameras)?;
        let files = write_scene(&args.out, stem, &volume, &views, args.outputs)?;
        println!("{stem}: {what} -> {}", files.display());
        Ok(())
    };

    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let started = Instant::now();
    let original = model.generate_random(&mut rng)?;
    write(
        "original",
        &original,
        format!("generated in {:.3} s", started.elapsed().as_secs_f64()),
    )?;

    let started = Instant::now();
    let empty = empty_voxel(&original, &model.config().activation())?;
    let mut edited = original;
    for edit in &edits {
        edited = edit.apply(&edited, &empty)?;
    }
    let summary: Vec<String> = edits.iter().map(ToString::to_string).collect();
    write(
        "edited",
        &edited,
        format!(
            "{} in {:.3} s",
            summary.join("; "),
            started.elapsed().as_secs_f64()
        ),
    )?;

    if let Some(from) = harmonize_from {
        let started = Instant::now();
        let harmonized = model
            .harmonize(&edited, from, &mut rng)
            .with_context(|| format!("harmonising from scale {from}"))?;
        write(
            "harmonized",
            &harmonized,
            format!(
                "re-ran {} in {:.3} s",
                generators(from, model.volume_scales()),
                started.elapsed().as_secs_f64()
            ),
        )?;
    }
    Ok(())
}
