//! Training configuration: what defines a run, in groups (the pyramid's sizes, the schedule,
//! the loss weights, the critics, the renderer, the active set, the noise, the ablation
//! switches, the run policy), and the named presets (`paper`, `small`, `tiny`, `micro`).
//!
//! A run saves its configuration as `config.json` and in every checkpoint; `--set` names a
//! setting by its dotted path in that JSON (`--set losses.rgb=50`,
//! [`TrainConfig::with_setting`]).

use std::str::FromStr;

use serde::{Deserialize, Serialize};

use rgbd_dataset::SceneBounds;

use crate::error::{invalid, Error, Result};

mod presets;
mod schedule;
mod setting;
mod validate;

pub use schedule::{ScaleSchedule, ScaleViews};
pub use setting::settings_that_differ;

/// The configuration format this version reads and writes ([`TrainConfig::version`](TrainConfig#structfield.version)).
/// Version 1 (before 2026-12) was one flat object of 57 settings; such runs are refused with
/// an explanation ([`TrainConfig::from_json`]).
pub const CONFIG_VERSION: u32 = 2;

/// Everything that defines a training run; saved as `config.json` beside every checkpoint so a
/// run can be resumed and a model sampled without guessing how it was built.
///
/// Scales are numbered from 1 as in the paper. Scales `1..N-1` are 3D generators with volume
/// sizes [`Pyramid::volume_sizes`] and rendering sizes [`Pyramid::image_sizes`] (one entry per
/// 3D scale); scale `N` is the 2D upsampler, whose output is `2 * image_sizes[N - 2]` pixels
/// wide.
///
/// ```
/// use singrav::TrainConfig;
/// let paper = TrainConfig::preset("paper")?;
/// assert_eq!(paper.scales(), 6);
/// assert_eq!(paper.pyramid.volume_sizes, [40, 53, 71, 95, 126]);
/// assert_eq!(paper.final_image_size(), 320);
/// assert_eq!(paper.pyramid.layers, 7);
/// # Ok::<(), singrav::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
// A field this version does not know comes from a newer volgen and may change the model
// (a layer, a normalisation): building the model without it would sample something else.
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// The configuration format, [`CONFIG_VERSION`].
    pub version: u32,
    /// The preset this configuration started from (for the record).
    pub preset: String,
    /// The scales' sizes and the networks' widths.
    pub pyramid: Pyramid,
    /// Iterations, steps, views and learning rates.
    pub schedule: Schedule,
    /// The loss weights.
    pub losses: Losses,
    /// What the critics see and their gradient penalty.
    pub critics: Critics,
    /// How volumes are activated and rendered.
    pub rendering: Rendering,
    /// Where the finer 3D scales' generators may change the volume.
    pub active_set: ActiveSet,
    /// The noise of random draws and of the reconstruction.
    pub noise: Noise,
    /// The paper's ablation switches.
    pub ablations: Ablations,
    /// Seed, held-out views, checkpoint cadence and where the scene is.
    pub run: RunPolicy,
}

/// The pyramid's sizes and the networks' widths.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pyramid {
    /// Volume edge per 3D scale (cubic volumes over `[-1, 1]^3`).
    pub volume_sizes: Vec<usize>,
    /// Rendering edge (square images) per 3D scale.
    pub image_sizes: Vec<usize>,
    /// Uniform samples per ray per 3D scale.
    pub samples: Vec<usize>,
    /// Conv layers L of every generator and discriminator (the receptive field is `2L + 1`).
    pub layers: usize,
    /// Hidden channels of the 3D generators and the discriminators (32 in the paper).
    pub channels: usize,
    /// Feature widths of the upsampler G_N (32, 16, 8, 8 in the paper).
    pub upsampler_widths: [usize; 4],
    /// Edge of the volume fitted to the views before training, when the run compares with one
    /// ([`Losses::fitted`], [`Losses::volume_critic`]); `None`: the finest 3D scale's edge
    /// (twice that without [`Rendering::post_activation`]). A 3D critic that judges only the
    /// coarsest scales needs no finer fit than theirs.
    #[serde(default)]
    pub fit_size: Option<usize>,
}

/// How long and how each scale trains.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    /// Iterations of each scale, coarsest first, the upsampler last (one entry per scale).
    pub scales: Vec<ScaleSchedule>,
    /// Critic steps per iteration (3).
    pub d_steps: usize,
    /// Generator steps per iteration (3).
    pub g_steps: usize,
    /// Views rendered per step, for the critic's real and fake batches and the reconstruction
    /// loss, where `scale_views` does not say otherwise: rendering one volume from several
    /// views costs little next to generating it.
    pub views_per_step: usize,
    /// Views per step of each scale (coarsest first, the upsampler last) when they are not all
    /// `views_per_step`, as in the paper's table of training parameters (6 generated and 2
    /// reconstruction views at the coarse scales down to 2 and 1 at the finest).
    pub scale_views: Option<Vec<ScaleViews>>,
    /// Adam learning rate for generators and critics (5e-4 in the paper).
    pub learning_rate: f64,
    /// Adam betas (0.9, 0.999).
    pub betas: (f64, f64),
    /// Steps of a direct fit of the finished reconstruction to the training views
    /// ([`volume_fit::fit_volume_from`], at the finest 3D scale's grid, with the fit's rates and
    /// ray batches but training's reconstruction loss and renderer), run after the last scale
    /// with every network frozen. The difference is kept as
    /// [`SinGrav::reconstruction_detail`](crate::SinGrav::reconstruction_detail), which
    /// [`SinGrav::reconstruct`](crate::SinGrav::reconstruct) adds to V*: the reconstruction
    /// gets a direct fit's per-voxel freedom while generated scenes stay exactly what the
    /// generators make. 0 (the paper's V*): no such fit.
    pub reconstruction_fit_steps: usize,
    /// Pixels the reconstruction loss renders per generator step at the 3D scales, drawn at
    /// random over every training view, where its views per step
    /// ([`ScaleViews::reconstruction`]) hold more: the loss then costs what this many rays cost
    /// at the finest scales, and each step sees every view a little rather than a few views
    /// whole. `None`: whole views at every scale.
    #[serde(default)]
    pub reconstruction_pixels: Option<usize>,
}

/// The loss weights. 0 leaves a term out, and [`Default`] leaves every term out. Each weight
/// weighs one [`LossTerm`](crate::train::LossTerm) ([`Losses::weights`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Losses {
    /// Colour reconstruction weight lambda_c (10 in the paper): `mse` between renderings of
    /// V*_n and the real views' colours.
    pub rgb: f64,
    /// Depth reconstruction weight lambda_d (30 in the paper).
    pub depth: f64,
    /// Opacity reconstruction at every 3D scale: `opacity * mse(opacity, alpha)` between
    /// renderings of V*_n and the dataset's alpha. Colour alone cannot tell a grey stone from a
    /// half-transparent purple one in front of green grass, and the pyramid learnt the latter;
    /// alpha can.
    pub opacity: f64,
    /// The sliced Wasserstein texture loss at the last scale.
    pub swd: f64,
    /// The features the SWD loss compares.
    pub swd_features: SwdFeatures,
    /// Colour distribution of generated scenes at the 3D scales: the squared sliced W2 distance
    /// between the pixel colours of a sample's rendering and of the real view from the same
    /// camera.
    pub colour_distribution: f64,
    /// Chroma distribution of generated scenes at the 3D scales: as `colour_distribution`, on
    /// the pixels' chroma (RGB projected onto the plane orthogonal to grey), so a tint is
    /// matched against the real view's tints and not hidden among its brightnesses.
    pub chroma_distribution: f64,
    /// The cells per side of the grid over each view that the colour and chroma distributions
    /// compare cell by cell (the mean over the cells), where `None` compares whole views. A
    /// whole view's colours may stand anywhere in it; with a grid, a sample's colours must stand
    /// in the same part of the view as the real view's, so a scene's colour patches (a dry band
    /// across its ground) keep their places while objects still move within a cell.
    #[serde(default)]
    pub colour_grid: Option<usize>,
    /// Height profile of generated scenes at the 3D scales: the squared difference between the
    /// mean opacity of each pixel row of a sample's rendering and of the real view's alpha from
    /// the same camera (matter may move sideways, not up into the sky). Needs
    /// [`Critics::opacity`].
    pub height_profile: f64,
    /// The binary-opacity prior of generated scenes at the 3D scales: the mean of
    /// `4 a (1 - a)` over the rendered opacity `a` of a sample's views, so that
    /// half-transparent smudges turn clear or opaque. Needs [`Critics::opacity`].
    pub opacity_binary: f64,
    /// The 3D comparison of every 3D scale's reconstruction V*_n with a directly fitted volume
    /// (see [`volume_fit`]) resampled to that scale: opacity per voxel (raw density, with
    /// [`Rendering::post_activation`]) and opacity-weighted colour. 0 is the paper's
    /// image-only training. A run with a positive weight and no fitted volume given fits one
    /// first ([`TrainConfig::fit_config`]).
    pub fitted: f64,
    /// The 3D patch critic's adversarial term at every 3D scale (3inGAN trains with such a
    /// critic beside the 2D ones): a [`patch_gan::PatchDiscriminator3d`] of the 2D critics'
    /// layers and channels judges a generated volume's per-voxel opacity (and with
    /// [`Critics::volume_colour`] its opacity-weighted colour) against the fitted volume's (see
    /// `fitted`; it needs one too), with WGAN-GP steps of its own beside each 2D critic step.
    pub volume_critic: f64,
}

impl Losses {
    /// Every weight with its dotted path (as `--set` takes it), in the order of the fields:
    /// what validation checks. A new field is a compile error here until it is listed.
    ///
    /// ```
    /// let tiny = singrav::TrainConfig::preset("tiny")?;
    /// let weights = tiny.losses.weights();
    /// assert!(weights.contains(&("losses.rgb", 50.0)));
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn weights(&self) -> Vec<(&'static str, f64)> {
        let Self {
            rgb,
            depth,
            opacity,
            swd,
            swd_features: _,
            colour_distribution,
            chroma_distribution,
            colour_grid: _,
            height_profile,
            opacity_binary,
            fitted,
            volume_critic,
        } = *self;
        vec![
            ("losses.rgb", rgb),
            ("losses.depth", depth),
            ("losses.opacity", opacity),
            ("losses.swd", swd),
            ("losses.colour_distribution", colour_distribution),
            ("losses.chroma_distribution", chroma_distribution),
            ("losses.height_profile", height_profile),
            ("losses.opacity_binary", opacity_binary),
            ("losses.fitted", fitted),
            ("losses.volume_critic", volume_critic),
        ]
    }
}

/// What the critics see, and their gradient penalty.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Critics {
    /// WGAN-GP penalty weight (0.1).
    pub gradient_penalty: f64,
    /// The 3D scales' critics also see opacity as their last channel (rendered opacity against
    /// the dataset's alpha), so matter in the sky and see-through objects look fake to them.
    pub opacity: bool,
    /// The 3D critic ([`Losses::volume_critic`]) also sees opacity-weighted colour, not only
    /// opacity. Off by default: a fit's colour is unconstrained wherever no view sees it
    /// (inside matter, under the ground), and a critic that asks for it puts that noise into
    /// the samples.
    pub volume_colour: bool,
    /// The finest 3D scale the 3D critic judges (`None`: every 3D scale). The coarsest scales
    /// make the scene's layout, where a critic of whole volumes sees what renderings' patches
    /// cannot; the finer ones only refine it.
    #[serde(default)]
    pub volume_until_scale: Option<usize>,
    /// The 3D critic sees each voxel weighted by the transmittance of the voxels above it (the
    /// matter a ray straight down from the top of the box meets: the ground's surface and what
    /// stands on it), not all matter. A fit of views leaves fog wherever no view sees (under the
    /// ground, inside objects); a critic that sees it asks the samples for that fog.
    #[serde(default)]
    pub volume_seen_from_above: bool,
    /// The 3D critic also sees where each voxel is: the CSG grid's three coordinates (the
    /// generator's anchors, `csg_embed::csg_grid_3d`) as extra channels, on the fit and on the
    /// samples alike. A patch critic without them judges a patch wherever it stands, so matter
    /// of the scene's kind in a place where the scene has none looks real to it.
    #[serde(default)]
    pub volume_positions: bool,
}

/// How raw volumes are activated and rendered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rendering {
    /// Raw-to-physical density: `sigma = density_scale * softplus(raw + density_shift)`.
    pub density_scale: f32,
    /// See `density_scale`; negative so an untrained generator starts as thin fog.
    pub density_shift: f32,
    /// The colour transparent pixels are composited onto, in data and renderings.
    pub background: [f32; 3],
    /// Render with post-activated density
    /// ([`volrender::DensityInterpolation::PostActivated`], DVGO's rule): samples interpolate
    /// the raw density and activate it each, so a voxel grid holds edges sharper than its
    /// voxels. `false` (the paper's renderer): the voxels' physical densities are
    /// interpolated. Exported volumes hold physical density either way; `volgen sample
    /// --upsample` writes post-activated runs' on a finer grid
    /// ([`SinGrav::to_physical_upsampled`](crate::SinGrav::to_physical_upsampled)).
    pub post_activation: bool,
}

/// Where the finer 3D scales' generators may change the volume (see [`crate::active_set`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActiveSet {
    /// The first 3D scale (2 or more, counted from 1) whose generator changes the volume only
    /// in the active set: near matter of the upsampled coarser volume. `None` (the paper's
    /// model, `--dense`, the `micro` preset): every voxel. The other presets: 2.
    pub from_scale: Option<usize>,
    /// Density `sigma` (1/world-length, as [`Rendering::density_scale`]'s) above which a voxel
    /// of the upsampled coarser volume is matter.
    pub threshold: f32,
    /// Voxels around matter that the active set adds (a cube of this half-width).
    pub margin: usize,
    /// Leave the inside of matter out too: active only within `margin` voxels of both matter
    /// and air (see [`crate::active_set::ActiveSetRule`]).
    pub shell: bool,
}

/// The noise of random draws and of the reconstruction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// SinGAN's factor between a scale's reconstruction error and its noise amplitude (0.1).
    pub amplitude_factor: f64,
    /// Noise amplitude at the coarsest scale (1).
    pub first_amplitude: f64,
    /// Learning rate of the reconstruction noise z*_n of the 3D scales n >= 2 (Adam, beside the
    /// generator's). 0 (SinGAN's model): z*_n is zero and the reconstruction
    /// V*_n = up(V*_{n-1}) + G_n(up(V*_{n-1})). Positive: z*_n starts at zero and is optimised
    /// on the reconstruction's losses while scale n trains, then frozen, giving V*_n per-voxel
    /// freedom the shared generator lacks.
    pub reconstruction_lr: f64,
}

/// The paper's ablation switches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ablations {
    /// The SWD loss at the last scale.
    pub use_swd: bool,
    /// The CSG grid injected at the coarsest scale.
    pub use_csg: bool,
    /// Depth supervision (depth channel for the critics and the depth term).
    pub use_depth: bool,
}

/// Seed, held-out views, checkpoint cadence and where the scene is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunPolicy {
    /// Seed of every random draw: weights, noises, views, penalties, projections.
    pub seed: u64,
    /// Every N-th dataset view (0, N, 2N, ...) is kept out of training, for evaluating fit
    /// against 3D consistency (see [`rgbd_dataset::Dataset::holdout_split`]); `None` trains
    /// on every view.
    pub holdout: Option<usize>,
    /// Write a checkpoint at least this often within a scale (seconds; 0 = only per scale).
    pub checkpoint_seconds: u64,
    /// Also write a checkpoint every this many iterations (0 = off); deterministic, for tests.
    pub checkpoint_iterations: usize,
    /// Where the scene is in the dataset's coordinates, when not in `[-1, 1]^3`: training maps
    /// the box into the model's cube, and generated volumes are placed back on
    /// [`SceneBounds::cube`].
    pub bounds: Option<SceneBounds>,
    /// The dataset's depth comes from a direct fit of its views (the paper's "NeRF-depth",
    /// for photos without a depth sensor): `volgen train --depth-from-fit` fits the views
    /// without depth, renders the fit's depth from every camera
    /// ([`rgbd_dataset::Dataset::with_depth_from`]) and trains on that dataset. Recorded so
    /// that a resumed run must say the same.
    #[serde(default)]
    pub depth_from_fit: bool,
}

/// The features of the last scale's sliced Wasserstein texture loss.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SwdFeatures {
    /// swd-loss's weights-free Laplacian pyramid of 7x7 patches (up to 3 levels).
    #[default]
    PatchPyramid,
    /// VGG-19 activations `relu1_1` .. `relu4_4` in Heitz et al.'s setting (average pooling,
    /// reflect padding, one slice per channel), as the paper; the weights (torchvision's names,
    /// see docs/swd-loss.md) are given to [`crate::train::train`] in
    /// [`crate::train::RunOptions::vgg19_weights`], not recorded here, so a run can resume
    /// with its weights file moved.
    Vgg19,
}

impl TrainConfig {
    /// The number of scales N (3D scales plus the upsampler).
    pub fn scales(&self) -> usize {
        self.pyramid.volume_sizes.len() + 1
    }

    /// The edge of the final (upsampled) images: twice the last rendering.
    pub fn final_image_size(&self) -> usize {
        2 * self.pyramid.image_sizes.last().copied().unwrap_or(0)
    }

    /// This configuration changed by `change`, for building one from a preset in an expression.
    ///
    /// ```
    /// let config = singrav::TrainConfig::preset("tiny")?.with(|c| {
    ///     c.losses.rgb = 10.0;
    ///     c.run.seed = 3;
    /// });
    /// assert_eq!((config.losses.rgb, config.run.seed), (10.0, 3));
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn with(mut self, change: impl FnOnce(&mut Self)) -> Self {
        change(&mut self);
        self
    }

    /// Reads a configuration from its JSON (`config.json`, or a checkpoint's metadata), naming
    /// `source` in errors. A configuration of another format version is refused with what
    /// wrote it and what to do, rather than misread.
    ///
    /// ```
    /// use singrav::TrainConfig;
    /// let tiny = TrainConfig::preset("tiny")?;
    /// let json = serde_json::to_string(&tiny).unwrap();
    /// assert_eq!(TrainConfig::from_json(&json, "config.json")?, tiny);
    /// let flat = r#"{"preset": "tiny", "volume_sizes": [16, 21, 28]}"#;
    /// let err = TrainConfig::from_json(flat, "config.json").unwrap_err().to_string();
    /// assert!(err.contains("version 1"), "{err}");
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn from_json(json: &str, source: &str) -> Result<Self> {
        let value: serde_json::Value = serde_json::from_str(json)
            .map_err(|e| invalid(source, format!("not a JSON configuration: {e}")))?;
        match value.get("version").and_then(serde_json::Value::as_u64) {
            Some(v) if v == u64::from(CONFIG_VERSION) => {}
            None => {
                return Err(invalid(
                    source,
                    format!(
                        "written by a volgen from before 2026-12 (configuration version 1, one \
                         flat list of settings); this volgen reads version {CONFIG_VERSION} \
                         (settings in groups: pyramid, schedule, losses, ...). Train the run \
                         anew (delete its directory, or give another --out), or sample it with \
                         the volgen that trained it"
                    ),
                ))
            }
            Some(v) => {
                return Err(invalid(
                    source,
                    format!(
                        "configuration version {v}, written by another volgen; this one reads \
                         version {CONFIG_VERSION}: use the volgen that wrote it, or train anew"
                    ),
                ))
            }
        }
        serde_json::from_value(value).map_err(|e| invalid(source, e.to_string()))
    }

    /// The direct fit a training run compares with ([`Losses::fitted`]) when it is given none:
    /// the run's activation, density rule, background, depth and seed, over the model's cube
    /// (in the scene's coordinates under the run's `bounds`), with volume-fit's default budget.
    /// The grid is [`Pyramid::fit_size`] when set, else the finest 3D scale's own edge for
    /// post-activated runs, which compare raw density (resampling a finer grid would average it
    /// away from the direct fit of that grid), and twice it otherwise (per-voxel opacity
    /// resampled from a finer grid is a smoother target).
    ///
    /// ```
    /// let tiny = singrav::TrainConfig::preset("tiny")?;
    /// let fit = tiny.fit_config();
    /// assert_eq!(fit.size, 28);
    /// assert!(fit.post_activation);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn fit_config(&self) -> volume_fit::FitConfig {
        let finest = self.pyramid.volume_sizes.last().copied().unwrap_or(16);
        let post_activation = self.rendering.post_activation;
        let finest_rule = if post_activation { finest } else { 2 * finest };
        volume_fit::FitConfig {
            size: self.pyramid.fit_size.unwrap_or(finest_rule),
            activation: self.activation(),
            background: self.rendering.background,
            use_depth: self.ablations.use_depth,
            seed: self.run.seed,
            post_activation,
            aabb: self
                .run
                .bounds
                .map_or(radiance_volume::Aabb::CUBE, |bounds| bounds.cube()),
            ..volume_fit::FitConfig::default()
        }
    }

    /// Whether a run compares with a volume fitted to its views ([`Losses::fitted`], the 3D
    /// critic of [`Losses::volume_critic`]): it then fits one before its first scale
    /// ([`TrainConfig::fit_config`]), unless given one.
    ///
    /// ```
    /// let tiny = singrav::TrainConfig::preset("tiny")?;
    /// assert!(tiny.compares_with_fit());
    /// assert!(!singrav::TrainConfig::preset("micro")?.compares_with_fit());
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn compares_with_fit(&self) -> bool {
        self.losses.fitted > 0.0 || self.losses.volume_critic > 0.0
    }

    /// Whether a run reads its dataset's depth maps: it supervises depth
    /// ([`Ablations::use_depth`]) and does not take it from a fit
    /// ([`RunPolicy::depth_from_fit`]). Otherwise a dataset may be loaded without them
    /// ([`rgbd_dataset::DepthKind::None`]), and need not say how they measure depth.
    ///
    /// ```
    /// let tiny = singrav::TrainConfig::preset("tiny")?;
    /// assert!(tiny.reads_depth_maps());
    /// assert!(!tiny.clone().with(|c| c.ablations.use_depth = false).reads_depth_maps());
    /// assert!(!tiny.with(|c| c.run.depth_from_fit = true).reads_depth_maps());
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn reads_depth_maps(&self) -> bool {
        self.ablations.use_depth && !self.run.depth_from_fit
    }

    /// The fit of the training views without depth whose rendered depth a run with
    /// [`RunPolicy::depth_from_fit`] trains on: volume-fit's defaults (64^3), colour and
    /// opacity only, over the model's cube (in the scene's coordinates under the run's
    /// `bounds`).
    ///
    /// ```
    /// let config = singrav::TrainConfig::preset("tiny")?.with(|c| c.run.depth_from_fit = true);
    /// let fit = config.depth_fit_config();
    /// assert!(!fit.use_depth);
    /// assert_eq!(fit.size, volume_fit::FitConfig::default().size);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn depth_fit_config(&self) -> volume_fit::FitConfig {
        volume_fit::FitConfig {
            use_depth: false,
            aabb: self
                .run
                .bounds
                .map_or(radiance_volume::Aabb::CUBE, |bounds| bounds.cube()),
            ..volume_fit::FitConfig::default()
        }
    }

    /// The activation mapping the generators' raw volumes to physical ones.
    pub fn activation(&self) -> radiance_volume::Activation {
        radiance_volume::Activation::default()
            .with_density_scale(self.rendering.density_scale)
            .with_density_shift(self.rendering.density_shift)
    }

    /// The renderer's density rule for [`Rendering::post_activation`], with this run's
    /// activation.
    pub fn density_interpolation(&self) -> volrender::DensityInterpolation {
        volrender::DensityInterpolation::post_activated_if(
            self.rendering.post_activation,
            self.rendering.density_scale,
            self.rendering.density_shift,
        )
    }

    /// The rule of the finer scales' active sets.
    pub fn active_set_rule(&self) -> crate::active_set::ActiveSetRule {
        crate::active_set::ActiveSetRule {
            threshold: self.active_set.threshold,
            margin: self.active_set.margin,
            shell: self.active_set.shell,
        }
    }
}

impl FromStr for TrainConfig {
    type Err = Error;

    fn from_str(name: &str) -> Result<Self> {
        Self::preset(name)
    }
}

#[cfg(test)]
mod tests {
    use super::TrainConfig;

    #[test]
    fn a_field_from_a_newer_version_is_refused_by_name() {
        let mut json = serde_json::to_value(TrainConfig::preset("micro").unwrap()).unwrap();
        json["pyramid"]
            .as_object_mut()
            .unwrap()
            .insert("upsampler_norm".into(), false.into());
        let err = TrainConfig::from_json(&json.to_string(), "config.json").unwrap_err();
        assert!(err.to_string().contains("upsampler_norm"), "{err}");
    }

    #[test]
    fn runs_of_the_flat_format_and_of_other_versions_are_refused_with_what_to_do() {
        // A version-1 configuration as volgen wrote it before the groups (abridged: the check
        // is on the version, before any field is read).
        let flat = r#"{"preset": "tiny", "volume_sizes": [16, 21, 28], "lambda_color": 50.0}"#;
        let err = TrainConfig::from_json(flat, "run/config.json")
            .unwrap_err()
            .to_string();
        for words in ["run/config.json", "version 1", "before 2026-12", "anew"] {
            assert!(err.contains(words), "{words}: {err}");
        }
        let mut future = serde_json::to_value(TrainConfig::preset("micro").unwrap()).unwrap();
        future["version"] = 3.into();
        let err = TrainConfig::from_json(&future.to_string(), "c.json")
            .unwrap_err()
            .to_string();
        assert!(err.contains("version 3"), "{err}");
        let err = TrainConfig::from_json("{", "c.json")
            .unwrap_err()
            .to_string();
        assert!(err.contains("c.json") && err.contains("JSON"), "{err}");
    }

    #[test]
    fn every_preset_round_trips_through_its_json() {
        for name in TrainConfig::PRESETS {
            let config = TrainConfig::preset(name).unwrap();
            let json = serde_json::to_string_pretty(&config).unwrap();
            assert_eq!(
                TrainConfig::from_json(&json, name).unwrap(),
                config,
                "{name}"
            );
        }
    }
}
