//! Shared by the commands that generate scenes from a trained model (`sample`, `animate`,
//! `edit`, `compose`): loading the model, and writing one scene's files (physical volume,
//! views, and VDB / EXR slices and meshes on request).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use candle_core::Tensor;
use radiance_volume::{Resampled, VolumeSource};
use singrav::SinGrav;

use super::export::{write_exr_slices, write_vdb, Encoding};

/// Extra formats each generated volume is written in, beside its safetensors file and PNG.
/// The default is the flags' defaults: no extra format, the default upsampling.
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub struct Outputs {
    /// Also write each volume as OpenVDB (density and color grids).
    #[arg(long)]
    pub vdb: bool,
    /// Also write each volume as a stack of EXR slices.
    #[arg(long)]
    pub exr_slices: bool,
    /// Also write each volume's surface as a coloured mesh: glb, gltf, ply or obj (`{stem}.glb`, ...;
    /// docs/formats.md, "Meshes").
    #[arg(long, value_name = "FORMAT", value_parser = super::mesh::mesh_format)]
    pub mesh: Option<volume_mesh::MeshFormat>,
    #[command(flatten)]
    pub mesh_flags: super::mesh::MeshFlags,
    /// Write the volumes (safetensors, VDB, EXR) on a grid K times finer per axis, K odd.
    /// Tools that interpolate physical density (Blender, OpenVDB) render a run trained with
    /// post-activated density (`tiny`'s default) as volgen does only on a finer grid: at 1 its
    /// sharp edges are smeared over a voxel. Default: 3 for such runs (27x the voxels), 1 for
    /// the others. See docs/formats.md.
    #[arg(long, value_name = "K", value_parser = odd_factor)]
    pub upsample: Option<usize>,
}

/// `--upsample`'s default: 3 for volumes rendered with post-activated density (their edges
/// then survive other tools' interpolation of physical density), 1 for the others.
pub fn default_upsample(post_activation: bool) -> usize {
    if post_activation {
        3
    } else {
        1
    }
}

impl Outputs {
    /// The upsampling factor for `model`'s volumes: `--upsample`, or its default.
    pub fn upsample(&self, model: &SinGrav) -> usize {
        self.upsample
            .unwrap_or_else(|| default_upsample(model.config().rendering.post_activation))
    }

    /// The physical volume written for a raw volume `(1, 4, s, s, s)` of `model`, at
    /// [`Outputs::upsample`]'s resolution, computed block by block as the writers stream it.
    pub fn volume(&self, model: &SinGrav, raw: &Tensor) -> Result<Resampled> {
        Ok(model.physical_source(raw, self.upsample(model))?)
    }
}

/// Parses `--upsample`: an odd factor from 1 to 9 (the finer grid keeps the model's voxel
/// centres; 9 already makes a 71^3 grid 639^3).
pub fn odd_factor(text: &str) -> std::result::Result<usize, String> {
    match text.parse::<usize>() {
        Ok(k) if k % 2 == 1 && k <= 9 => Ok(k),
        _ => Err(format!("expected an odd factor from 1 to 9, got {text:?}")),
    }
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
    volume: &dyn VolumeSource,
    views: &Tensor,
    outputs: Outputs,
) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    radiance_volume::io::write_safetensors(volume, dir.join(format!("{stem}.safetensors")))?;
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
    if let Some(format) = outputs.mesh {
        let file = dir.join(format!("{stem}.{}", format.extension()));
        super::mesh::write_mesh(volume, &file, outputs.mesh_flags.shape())
            .with_context(|| format!("writing the mesh {}", file.display()))?;
    }
    Ok(dir.join(format!("{stem}.*")))
}

/// Writes the scenes of a command that changes a generated scene (`edit`, `compose`): each raw
/// volume rendered from the same cameras and written with the same outputs, and named on
/// standard output with what was done.
pub struct SceneWriter<'a> {
    pub model: &'a SinGrav,
    pub cameras: Vec<volrender::Camera>,
    pub dir: &'a Path,
    pub outputs: Outputs,
}

impl<'a> SceneWriter<'a> {
    /// A writer of `model`'s scenes into `dir`, rendered from `views` showcase cameras.
    pub fn new(model: &'a SinGrav, views: usize, dir: &'a Path, outputs: Outputs) -> Result<Self> {
        Ok(Self {
            model,
            cameras: model.showcase_cameras(views)?,
            dir,
            outputs,
        })
    }

    /// Writes `raw` as `stem` ([`write_scene`]) and prints `stem: what -> files`.
    pub fn write(&self, stem: &str, raw: &Tensor, what: String) -> Result<()> {
        let volume = self.outputs.volume(self.model, raw)?;
        let views = self.model.render_raw(raw, &self.cameras)?;
        let files = write_scene(self.dir, stem, &volume, &views, self.outputs)?;
        println!("{stem}: {what} -> {}", files.display());
        Ok(())
    }
}
