//! The harmonisation options of `volgen edit` and `volgen compose`: from which 3D scale the
//! generators re-run on the changed scene (the paper: 3), or not at all.

use std::time::Instant;

use anyhow::{bail, Context, Result};
use candle_core::Tensor;
use singrav::SinGrav;

use super::model_io::SceneWriter;

/// The scale the paper's harmonisation re-runs the generators from.
const PAPER_HARMONIZE_FROM: usize = 3;

/// `--harmonize-from N` and `--no-harmonize`.
#[derive(Debug, clap::Args)]
pub struct HarmonizeArgs {
    /// Re-run the generators from this 3D scale on the downscaled scene (the paper: 3; at most
    /// the model's finest 3D scale, which is also the default for models with fewer scales).
    #[arg(long, value_name = "N", conflicts_with = "no_harmonize")]
    harmonize_from: Option<usize>,
    /// Skip the harmonisation; write only the scenes before it.
    #[arg(long)]
    no_harmonize: bool,
}

impl HarmonizeArgs {
    /// The scale harmonisation re-runs the generators from, or `None` to skip it.
    pub fn start_scale(&self, model: &SinGrav) -> Result<Option<usize>> {
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

/// Harmonises the changed scene `changed` from scale `from` with fresh noise from `rng` and
/// writes it as `harmonized`.
pub fn harmonize_and_write(
    changed: &Tensor,
    from: usize,
    rng: &mut impl rand::Rng,
    writer: &SceneWriter<'_>,
) -> Result<()> {
    let model = writer.model;
    let started = Instant::now();
    let harmonized = model
        .harmonize(changed, from, rng)
        .with_context(|| format!("harmonising from scale {from}"))?;
    writer.write(
        "harmonized",
        &harmonized,
        format!(
            "re-ran {} in {:.3} s",
            generators(from, model.volume_scales()),
            started.elapsed().as_secs_f64()
        ),
    )
}

/// Names the generators G_from .. G_to for messages.
fn generators(from: usize, to: usize) -> String {
    if from == to {
        format!("G_{from}")
    } else {
        format!("G_{from}..G_{to}")
    }
}
