//! What the viewer shows: a trained model (scenes drawn as `volgen sample` and `volgen
//! animate` draw them) or volume files (a directory of them, or one). Opening a source loads
//! and checks everything it will serve, so a broken run is refused before the server starts;
//! drawing and exporting run on the generator's thread.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use csg_embed::Outside;
use radiance_volume::{RadianceVolume, VolumeSource};
use rand::SeedableRng;
use serde_json::json;
use singrav::applications::WalkConfig;
use singrav::extent::Extent;
use singrav::SinGrav;
use volrender::{DensityInterpolation, RenderConfig, Sampler, PAPER_FOV_DEG, PAPER_RADIUS};
use volume_mesh::MeshFormat;

use super::params::{Limits, SceneKey, MAX_VIEW_FACTOR, MAX_VOXELS, MAX_WALK};
use super::scene::{Content, Format, Rendering, Scene};
use crate::cli::export::{vdb_bytes, Encoding};
use crate::cli::mesh::{mesh_of, MeshFlags};
use crate::cli::model_io::{load_model, Outputs};

/// Extents the page offers (any other within the bounds can be typed).
const EXTENT_CHOICES: [&str; 6] = ["1,1,1", "2,1,1", "1,2,1", "2,2,1", "3,3,1", "0.5,0.5,1"];

/// A source of scenes.
pub enum Source {
    /// Boxed: a model (its configuration, generators and noise) is far larger than a list of
    /// files.
    Model(Box<ModelSource>),
    Files(FileSource),
}

/// A trained model, with the extent its grids are set to now.
pub struct ModelSource {
    model: SinGrav,
    extent: (Extent, Outside),
}

/// Volume files, checked when opened and read again when drawn (the cache keeps the recent).
pub struct FileSource {
    files: Vec<PathBuf>,
    stems: Vec<String>,
    /// The learned box's centre and largest half side, for the default camera (the first
    /// file's box).
    centre: [f32; 3],
    half: f32,
}

impl Source {
    /// Opens `path`: a run directory or a `checkpoint.safetensors` is a model; another
    /// directory, the `.safetensors` volumes in it; another file, one volume. Every volume is
    /// read and checked; a model is loaded.
    pub fn open(path: &Path) -> Result<Self> {
        ensure!(
            path.exists(),
            "{}: no such run, directory or volume",
            path.display()
        );
        // A run directory, or the checkpoint file of one (not any `.safetensors`).
        let run = singrav::RunDir::of_model(path);
        let is_run = if path.is_dir() {
            run.has_checkpoint()
        } else {
            run.checkpoint() == path
        };
        if is_run {
            let model = load_model(path)?;
            let extent = (model.extent(), Outside::default());
            return Ok(Source::Model(Box::new(ModelSource { model, extent })));
        }
        let files = if path.is_dir() {
            volume_files(path)?
        } else {
            vec![path.to_path_buf()]
        };
        let mut first = None;
        for file in &files {
            let volume = check_volume(file)?;
            first.get_or_insert(volume.aabb());
        }
        let aabb = first.context("no volume")?;
        let half = ((aabb.max - aabb.min) * 0.5).max_element();
        let stems = files
            .iter()
            .map(|f| {
                f.file_stem()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        Ok(Source::Files(FileSource {
            files,
            stems,
            centre: aabb.center().to_array(),
            half,
        }))
    }

    /// What requests may ask of this source.
    pub fn limits(&self) -> Limits {
        match self {
            Source::Model(m) => Limits::Model {
                scales: m.model.volume_scales(),
                finest: m.model.config().pyramid.volume_sizes[m.model.volume_scales() - 1],
            },
            Source::Files(f) => Limits::Files {
                count: f.files.len(),
            },
        }
    }

    /// The background training views are composited on: the model's, or volgen render's
    /// default for volumes.
    pub fn background(&self) -> [f32; 3] {
        match self {
            Source::Model(m) => m.model.config().rendering.background,
            Source::Files(_) => files_rendering().background,
        }
    }

    /// What the page needs to know before drawing anything, as JSON (views added by the
    /// caller).
    pub fn describe(&self, title: &str) -> serde_json::Value {
        let (centre, half) = match self {
            Source::Model(m) => match m.model.config().run.bounds {
                Some(bounds) => (bounds.cube().center().to_array(), bounds.half_side()),
                None => ([0.0; 3], 1.0),
            },
            Source::Files(f) => (f.centre, f.half),
        };
        let mut info = json!({
            "title": title,
            "camera": {
                // volgen sample's showcase camera: the paper's field of view and radius, 35
                // degrees up, 45 degrees round.
                "fov_x": PAPER_FOV_DEG.to_radians(),
                "radius": PAPER_RADIUS,
                "elevation": 35f32.to_radians(),
                "azimuth": 45f32.to_radians(),
                "centre": centre,
                "half": half,
            },
        });
        match self {
            Source::Model(m) => {
                let scales = m.model.volume_scales();
                info["kind"] = json!("model");
                info["scales"] = json!(scales);
                info["walk_max"] = json!(if scales >= 2 { MAX_WALK } else { 0 });
                info["extent"] = json!({
                    "max": MAX_VIEW_FACTOR,
                    "min": Extent::MIN_FACTOR,
                    "max_voxels": MAX_VOXELS,
                    "choices": EXTENT_CHOICES,
                    "outside": Outside::NAMES,
                });
            }
            Source::Files(f) => {
                info["kind"] = json!("files");
                info["files"] = json!(f.stems);
            }
        }
        info
    }

    /// Draws the scene `key` asks for (checked by [`super::params::scene_key`] against
    /// [`Source::limits`]).
    pub fn draw(&mut self, key: &SceneKey) -> Result<Scene> {
        match (self, key) {
            (Source::Model(m), key @ SceneKey::Drawn { .. }) => m.draw(key),
            (Source::Files(f), SceneKey::File { index }) => {
                let volume = RadianceVolume::load_safetensors(&f.files[*index])?;
                Scene::new(
                    key.clone(),
                    key.stem(&f.stems),
                    &volume,
                    files_rendering(),
                    0.0,
                    Content::Volume(volume.clone()),
                )
            }
            _ => bail!("this source draws no such scene"),
        }
    }

    /// The bytes of `scene`'s download in `format`: the file `volgen sample --vdb --mesh glb`
    /// writes for a model's scene (the volume at `--upsample`'s default), and for a volume
    /// file the file itself, `volgen export --vdb`'s and `volgen mesh`'s.
    pub fn export(&mut self, scene: &Scene, format: Format) -> Result<Vec<u8>> {
        // A model's scene is streamed from its raw volume at `--upsample`'s size (never whole).
        let volume: Box<dyn VolumeSource> = match (&mut *self, &scene.content) {
            (Source::Model(m), Content::Raw(raw)) => {
                m.set_extent(&scene.key)?;
                Box::new(Outputs::default().volume(&m.model, raw)?)
            }
            (Source::Files(f), Content::Volume(volume)) => {
                if let (Format::Safetensors, SceneKey::File { index }) = (format, &scene.key) {
                    let file = &f.files[*index];
                    return std::fs::read(file)
                        .with_context(|| format!("reading {}", file.display()));
                }
                Box::new(volume.clone())
            }
            _ => bail!("the scene is not this source's"),
        };
        match format {
            Format::Safetensors => Ok(radiance_volume::io::safetensors_bytes(&*volume)?),
            Format::Vdb => vdb_bytes(&*volume, &Encoding::default()),
            Format::Glb => {
                Ok(mesh_of(&*volume, MeshFlags::default().shape())?.to_bytes(MeshFormat::Glb)?)
            }
        }
    }
}

impl ModelSource {
    /// The scene of a [`SceneKey::Drawn`]: the seed's noise, drawn as `volgen sample` draws
    /// scene 0 of that seed, walked `walk` frames as `volgen animate` walks it.
    fn draw(&mut self, key: &SceneKey) -> Result<Scene> {
        let SceneKey::Drawn {
            seed, vary, walk, ..
        } = *key
        else {
            bail!("a model draws scenes from seeds");
        };
        self.set_extent(key)?;
        let model = &self.model;
        let started = Instant::now();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let raw = if walk == 0 {
            model.generate_random_from(&mut rng, vary)?
        } else {
            let walk_config = WalkConfig {
                vary_from: vary,
                ..WalkConfig::default()
            };
            let mut animation = model.animation(walk_config, rng)?;
            animation.skip_frames(walk)?;
            animation.next_frame()?
        };
        let seconds = started.elapsed().as_secs_f64();
        let (volume, density) = model.to_rendered(&raw)?;
        let settings = model.render_config();
        let Sampler::Uniform { samples } = settings.sampler else {
            bail!(
                "the model renders with {:?}, not uniform samples",
                settings.sampler
            );
        };
        let rendering = Rendering {
            density,
            samples,
            background: model.config().rendering.background,
        };
        Scene::new(
            key.clone(),
            key.stem(&[]),
            &volume,
            rendering,
            seconds,
            Content::Raw(raw),
        )
    }

    /// Sets the model's grids to `key`'s extent, unless they are.
    fn set_extent(&mut self, key: &SceneKey) -> Result<()> {
        let SceneKey::Drawn {
            extent, outside, ..
        } = *key
        else {
            bail!("a file has no extent");
        };
        if self.extent != (extent, outside) {
            self.model.set_extent(extent, outside).context("extent")?;
            self.extent = (extent, outside);
        }
        Ok(())
    }
}

/// How volume files render: `volgen render`'s defaults (its samples per ray, black behind).
fn files_rendering() -> Rendering {
    let defaults = RenderConfig::default();
    let samples = match defaults.sampler {
        Sampler::Uniform { samples } => samples,
        _ => 128,
    };
    Rendering {
        density: DensityInterpolation::Physical,
        samples,
        background: defaults.background.unwrap_or([0.0; 3]),
    }
}

/// The `.safetensors` files of `dir`, sorted by name.
fn volume_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("reading the directory {}", dir.display()))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("reading the directory {}", dir.display()))?
            .path();
        if path.is_file() && path.extension().is_some_and(|e| e == "safetensors") {
            files.push(path);
        }
    }
    files.sort();
    ensure!(
        !files.is_empty(),
        "{}: neither a run (no checkpoint.safetensors) nor a directory of volumes (no \
         .safetensors files)",
        dir.display()
    );
    Ok(files)
}

/// Reads a volume file and checks that the viewer can draw it.
fn check_volume(file: &Path) -> Result<RadianceVolume> {
    let volume = RadianceVolume::load_safetensors(file)?;
    ensure!(
        volume.channel_count() >= 4,
        "{}: expected a volume of density and colour (4 channels or more), got {} channels",
        file.display(),
        volume.channel_count()
    );
    let voxels = volume.dims().voxel_count();
    ensure!(
        voxels <= MAX_VOXELS,
        "{}: {voxels} voxels; the viewer draws at most {MAX_VOXELS}",
        file.display()
    );
    Ok(volume)
}
