//! Shared by the commands that generate scenes from a trained model (`sample`, `animate`,
//! `edit`): loading the model, and writing one scene's files (physical volume, views, and
//! VDB / EXR slices on request).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use candle_core::Tensor;
use radiance_volume::RadianceVolume;
use singrav::SinGrav;

use super::export::{write_exr_slices, write_vdb, Encoding};

/// Extra formats each generated volume is written in, beside its safetensors file and PNG.
#[derive(Debug, Clone, Copy, clap::Args)]
pub struct Outputs {
    /// Also write each volume as OpenVDB (density and color grids).
    #[arg(long)]
    pub vdb: bool,
    /// Also write each volume as a stack of EXR slices.
    #[arg(long)]
    pub exr_slices: bool,
}

/// Loads a trained model (a run directory or its checkpoint) on the training device, noting
/// on stderr when its training has not finished.
pub fn load_model(path: &Path) -> Result<SinGrav> {
    let (model, state) = SinGrav::load(path, &super::train::device()?)?;
    if !state.finished(model.config()) {
        eprintln!(
            "note: {} is not fully trained (stopped at scale {}); using its trained scales",
            path.display(),
            state.scale
        );
    }
    Ok(model)
}

/// Writes `dir/{stem}.safetensors` (the physical volume), `dir/{stem}.png` (the views
/// `(V, 3, H, W)` side by side) and, as `outputs` asks, `{stem}.vdb` and `{stem}_exr/`.
/// Returns the `dir/{stem}.*` pattern, for messages.
pub fn write_scene(
    dir: &Path,
    stem: &str,
    volume: &RadianceVolume,
    views: &Tensor,
    outputs: Outputs,
) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    volume.save_safetensors(dir.join(format!("{stem}.safetensors")))?;
    let row = (0..views.dim(0)?)
        .map(|v| views.get(v))
        .collect::<candle_core::Result<Vec<_>>>()?;
    singrav::picture::write_grid(&dir.join(format!("{stem}.png")), &[row])?;
    if outputs.vdb {
        write_vdb(
            volume,
            &dir.join(format!("{stem}.vdb")),
            &Encoding::default(),
        )?;
    }
    if outputs.exr_slices {
        write_exr_slices(
            volume,
            &dir.join(format!("{stem}_exr")),
            stem,
            &Encoding::default(),
        )?;
    }
    Ok(dir.join(format!("{stem}.*")))
}
