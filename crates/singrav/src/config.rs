//! Training configuration: the pyramid's sizes, the schedule, the loss weights, the ablation
//! switches, and the named presets (`paper`, `small`, `tiny`, `micro`).

use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::dataset::SceneBounds;
use crate::error::{invalid, Error, Result};

/// Everything that defines a training run; saved as `config.json` beside every checkpoint so a
/// run can be resumed and a model sampled without guessing how it was built.
///
/// Scales are numbered from 1 as in the paper. Scales `1..N-1` are 3D generators with volume
/// sizes `volume_sizes` and rendering sizes `image_sizes` (one entry per 3D scale); scale `N` is
/// the 2D upsampler, whose output is `2 * image_sizes[N - 2]` pixels wide.
///
/// ```
/// use singrav::TrainConfig;
/// let paper = TrainConfig::preset("paper")?;
/// assert_eq!(paper.scales(), 6);
/// assert_eq!(paper.volume_sizes, [40, 53, 71, 95, 126]);
/// assert_eq!(paper.final_image_size(), 320);
/// assert_eq!(paper.layers, 7);
/// # Ok::<(), singrav::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
// A field this version does not know comes from a newer volgen and may change the model
// (a layer, a normalisation): building the model without it would sample something else.
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// The preset this configuration started from (for the record).
    pub preset: String,
    /// Volume edge per 3D scale (cubic volumes over `[-1, 1]^3`).
    pub volume_sizes: Vec<usize>,
    /// Rendering edge (square images) per 3D scale.
    pub image_sizes: Vec<usize>,
    /// Uniform samples per ray per 3D scale.
    pub samples: Vec<usize>,
    /// Conv layers L of every generator and discriminator.
    pub layers: usize,
    /// Hidden channels of the 3D generators and the discriminators (32 in the paper).
    pub channels: usize,
    /// Feature widths of the upsampler G_N (32, 16, 8, 8 in the paper).
    pub upsampler_widths: [usize; 4],
    /// Iterations of each scale, coarsest first, the upsampler last (one entry per scale).
    pub schedule: Vec<ScaleSchedule>,
    /// Critic steps per iteration (3).
    pub d_steps: usize,
    /// Generator steps per iteration (3).
    pub g_steps: usize,
    /// Views rendered per step, for the critic's real and fake batches and the reconstruction
    /// loss: rendering one volume from several views costs little next to generating it.
    pub views_per_step: usize,
    /// Views per step of each scale (coarsest first, the upsampler last) when they are not all
    /// `views_per_step`, as in the paper's table of training parameters (6 generated and 2
    /// reconstruction views at the coarse scales down to 2 and 1 at the finest). Absent
    /// (`None`) in runs made before it existed, which used `views_per_step` everywhere. Written
    /// as `null` rather than left out, so that `--set scale_views=...` finds it.
    #[serde(default)]
    pub scale_views: Option<Vec<ScaleViews>>,
    /// Adam learning rate (5e-4) for generators and critics.
    pub learning_rate: f64,
    /// SinGAN's step decay of the learning rate (its `MultiStepLR`: at 80% of a scale's
    /// iterations, times 0.1), for the generator and critic of every scale. `None` (also runs
    /// made before it existed) keeps the rate constant. Written as `null` rather than left out,
    /// so that `--set lr_decay=...` finds it.
    #[serde(default)]
    pub lr_decay: Option<LrDecay>,
    /// ConSinGAN's concurrent training (Hinz et al. 2021): while a 3D scale trains, the
    /// generators of the scales just below it keep training too, on every loss of the scale, at
    /// smaller learning rates (see [`Concurrent`]). `None` (every preset's default, and runs
    /// made before it existed) is the paper's and SinGAN's training: coarser generators frozen.
    /// Written as `null` rather than left out, so that `--set concurrent=...` finds it.
    #[serde(default)]
    pub concurrent: Option<Concurrent>,
    /// Adam betas (0.9, 0.999).
    pub betas: (f64, f64),
    /// WGAN-GP penalty weight (0.1).
    pub gp_weight: f64,
    /// Colour reconstruction weight lambda_c (10).
    pub lambda_color: f64,
    /// Depth reconstruction weight lambda_d (30).
    pub lambda_depth: f64,
    /// Weight of the sliced Wasserstein texture loss at the last scale.
    pub lambda_swd: f64,
    /// Weight of the 3D comparison of every 3D scale's reconstruction V*_n with a directly
    /// fitted volume (see [`crate::fit`]) resampled to that scale: opacity per voxel (raw
    /// density, with [`TrainConfig::post_activation`]) and opacity-weighted colour. 0 (every
    /// preset's default, and what runs made before it existed used) is the paper's image-only
    /// training. A run with a positive weight and no fitted volume given fits one
    /// first ([`crate::fit::FitConfig::for_training`]).
    #[serde(default)]
    pub lambda_fitted: f64,
    /// Weight of the 3D patch critic's adversarial term at every 3D scale (3inGAN trains with
    /// such a critic beside the 2D ones): a [`patch_gan::PatchDiscriminator3d`] of the 2D
    /// critics' layers and channels judges a generated volume's per-voxel opacity (and with
    /// `volume_critic_colour` its opacity-weighted colour) against the fitted volume's (see
    /// `lambda_fitted`; it needs one too), with WGAN-GP steps of its own beside each 2D critic
    /// step. 0 (every preset's default, and runs made before it existed): no 3D critic.
    #[serde(default)]
    pub lambda_volume_critic: f64,
    /// The 3D critic also sees opacity-weighted colour, not only opacity. Off by default: a
    /// fit's colour is unconstrained wherever no view sees it (inside matter, under the
    /// ground), and a critic that asks for it puts that noise into the samples.
    #[serde(default)]
    pub volume_critic_colour: bool,
    /// Weight of the opacity reconstruction at every 3D scale: `lambda_opacity * mse(opacity,
    /// alpha)` between renderings of V*_n and the dataset's alpha. Colour alone cannot tell a
    /// grey stone from a half-transparent purple one in front of green grass, and the pyramid
    /// learnt the latter; alpha can. 0 (runs made before it existed) leaves it out.
    #[serde(default)]
    pub lambda_opacity: f64,
    /// The 3D scales' critics also see opacity as their last channel (rendered opacity against
    /// the dataset's alpha), so matter in the sky and see-through objects look fake to them.
    /// Off in runs made before it existed.
    #[serde(default)]
    pub critic_opacity: bool,
    /// Weight of the colour-distribution loss of generated scenes at the 3D scales: the squared
    /// sliced W2 distance between the pixel colours of a sample's rendering and of the real
    /// view from the same camera. 0 (runs made before it existed) leaves it out.
    #[serde(default)]
    pub lambda_colour: f64,
    /// Weight of the chroma-distribution loss of generated scenes at the 3D scales: as
    /// [`TrainConfig::lambda_colour`]'s term, on the pixels' chroma (RGB projected onto the
    /// plane orthogonal to grey), so a tint is matched against the real view's tints and not
    /// hidden among its brightnesses. 0 (runs made before it existed) leaves it out.
    #[serde(default)]
    pub lambda_chroma: f64,
    /// The first 3D scale (2 or more, counted from 1) whose generator changes the volume only in
    /// the active set: near matter of the upsampled coarser volume (see [`crate::active_set`]).
    /// `None` (the paper's model, `--dense`, the `micro` preset, and runs made before it
    /// existed): every voxel. The other presets: 2.
    #[serde(default)]
    pub sparse_from_scale: Option<usize>,
    /// Density `sigma` (1/world-length, as [`TrainConfig::density_scale`]'s) above which a voxel
    /// of the upsampled coarser volume is matter, for the active set.
    #[serde(default)]
    pub sparse_threshold: f32,
    /// Voxels around matter that the active set adds (a cube of this half-width).
    #[serde(default)]
    pub sparse_margin: usize,
    /// Leave the inside of matter out of the active set too: active only within
    /// `sparse_margin` voxels of both matter and air (see [`crate::active_set::ActiveSetRule`]).
    /// `false` in runs made before it existed.
    #[serde(default)]
    pub sparse_shell: bool,
    /// Weight of the height-profile loss of generated scenes at the 3D scales: the squared
    /// difference between the mean opacity of each pixel row of a sample's rendering and of the
    /// real view's alpha from the same camera (matter may move sideways, not up into the sky).
    /// Needs opacity in the critics' views (`critic_opacity`). 0 (runs made before it existed)
    /// leaves it out.
    #[serde(default)]
    pub lambda_height_profile: f64,
    /// Weight of the binary-opacity prior of generated scenes at the 3D scales: the mean of
    /// `4 a (1 - a)` over the rendered opacity `a` of a sample's views, so that half-transparent
    /// smudges turn clear or opaque. Needs opacity in the critics' views (`critic_opacity`).
    /// 0 (runs made before it existed) leaves it out.
    #[serde(default)]
    pub lambda_opacity_binary: f64,
    /// The last 3D scale (counted from 1) at which the binary-opacity prior acts; `None`: every
    /// 3D scale. The samples' smudges and stone heights form at the coarse scales, while at
    /// `tiny`'s finest 3D scale the prior alone made the samples' half-transparent,
    /// purple-tinted stones opaque, so their tint showed (docs/training.md, "Opacity priors on
    /// the samples"); with [`TrainConfig::lambda_chroma`] `tiny` keeps it at every 3D scale.
    #[serde(default)]
    pub opacity_binary_until_scale: Option<usize>,
    /// Weight of the opacity-distribution loss of generated scenes at the 3D scales: the squared
    /// W2 distance between the pixel opacities of a sample's rendering and the real view's alpha
    /// from the same camera. Needs opacity in the critics' views (`critic_opacity`). 0 (runs
    /// made before it existed) leaves it out.
    #[serde(default)]
    pub lambda_opacity_distribution: f64,
    /// Learning rate of the reconstruction noise z*_n of the 3D scales n >= 2 (Adam, beside the
    /// generator's). 0 (SinGAN's model, and runs made before it existed): z*_n is zero and the
    /// reconstruction V*_n = up(V*_{n-1}) + G_n(up(V*_{n-1})). Positive: z*_n starts at zero and
    /// is optimised on the reconstruction's losses while scale n trains, then frozen, giving
    /// V*_n per-voxel freedom the shared generator lacks.
    #[serde(default)]
    pub reconstruction_noise_lr: f64,
    /// Adds scale n's noise to its volume as well as to the generator's input:
    /// `x_n = up(x_{n-1}) + z_n + G_n(up(x_{n-1}) + z_n)` at the 3D scales n >= 2. With an
    /// optimised z*_n ([`TrainConfig::reconstruction_noise_lr`]) the reconstruction gets a free
    /// value per voxel, as a direct fit has; random samples get their noise (of SinGAN's
    /// amplitude, far below a voxel's value) once more. `false` (SinGAN's model, and runs made
    /// before it existed): the noise reaches the volume only through G_n.
    #[serde(default)]
    pub noise_skip: bool,
    /// The reconstruction noise's learning rate at the end of each 3D scale: from
    /// [`TrainConfig::reconstruction_noise_lr`] it decays exponentially to this over the
    /// scale's iterations, as `volgen fit` decays its grid's rate. `None` (runs made before it
    /// existed): constant.
    #[serde(default)]
    pub reconstruction_noise_final_lr: Option<f64>,
    /// The fraction of each 3D scale's iterations before which the reconstruction noise stays
    /// as it is (rate 0); the decay to [`TrainConfig::reconstruction_noise_final_lr`] runs over
    /// the rest. 0 (runs made before it existed): z*_n moves from the first iteration.
    #[serde(default)]
    pub reconstruction_noise_from: f64,
    /// The decay of an exponential moving average of each 3D scale's generator weights, updated
    /// after every generator step; when the scale ends its generator keeps the average (Polyak
    /// averaging of GAN weights, StyleGAN's `G_ema`), so the finer scales, V* and the samples
    /// use it. 0 (SinGAN's training, and runs made before it existed): the last step's weights.
    #[serde(default)]
    pub generator_average: f64,
    /// Steps of a direct fit of the finished reconstruction to the training views
    /// ([`crate::fit::fit_volume_from`], at the finest 3D scale's grid, with the fit's rates and
    /// ray batches but training's reconstruction loss and renderer), run after the last scale
    /// with every network frozen. The difference is
    /// kept as [`SinGrav::reconstruction_detail`](crate::SinGrav::reconstruction_detail), which
    /// [`SinGrav::reconstruct`](crate::SinGrav::reconstruct) adds to V*: the reconstruction
    /// gets a direct fit's per-voxel freedom while generated scenes stay exactly what the
    /// generators make. 0 (the paper's V*, and runs made before it existed): no such fit.
    #[serde(default)]
    pub reconstruction_fit_steps: usize,
    /// SinGAN's factor between a scale's reconstruction error and its noise amplitude (0.1).
    pub noise_amp_factor: f64,
    /// Noise amplitude at the coarsest scale (1).
    pub noise_amp_first: f64,
    /// Raw-to-physical density: `sigma = density_scale * softplus(raw + density_shift)`.
    pub density_scale: f32,
    /// See [`TrainConfig::density_scale`]; negative so an untrained generator starts as thin fog.
    pub density_shift: f32,
    /// The colour transparent pixels are composited onto, in data and renderings.
    pub background: [f32; 3],
    /// Render with density-weighted colour ([`volrender::ColourInterpolation::DensityWeighted`]):
    /// a sample's colour is the density-weighted mean of its voxels' colours, so the colours of
    /// clear voxels beside matter never show and matter renders its own voxels' colour. `false`
    /// (the paper's renderer, and runs made before it existed): colour interpolated on its own.
    #[serde(default)]
    pub density_weighted_colour: bool,
    /// Render with post-activated density
    /// ([`volrender::DensityInterpolation::PostActivated`], DVGO's rule): samples interpolate
    /// the raw density and activate it each, so a voxel grid holds edges sharper than its
    /// voxels. `false` (the paper's renderer, and runs made before it existed): the voxels'
    /// physical densities are interpolated. Exported volumes hold physical density either way;
    /// `volgen sample --upsample` writes post-activated runs' on a finer grid
    /// ([`SinGrav::to_physical_upsampled`](crate::SinGrav::to_physical_upsampled)).
    #[serde(default)]
    pub post_activation: bool,
    /// Ablation switch: the SWD loss at the last scale.
    pub use_swd: bool,
    /// The features the SWD loss compares. Recorded so that a resumed run cannot switch them;
    /// absent from checkpoints made before it existed, which used the patch pyramid.
    #[serde(default)]
    pub swd_features: SwdFeatures,
    /// Ablation switch: the CSG grid injected at the coarsest scale.
    pub use_csg: bool,
    /// Ablation switch: depth supervision (depth channel for the critics and the depth term).
    pub use_depth: bool,
    /// Write a checkpoint at least this often within a scale (seconds; 0 = only per scale).
    pub checkpoint_seconds: u64,
    /// Also write a checkpoint every this many iterations (0 = off); deterministic, for tests.
    pub checkpoint_iterations: usize,
    /// Seed of every random draw: weights, noises, views, penalties, projections.
    pub seed: u64,
    /// Every N-th dataset view (0, N, 2N, ...) is kept out of training, for evaluating fit
    /// against 3D consistency (see [`crate::dataset::Dataset::holdout_split`]); `None` trains
    /// on every view. Absent from checkpoints made before it existed, which used every view.
    #[serde(default)]
    pub holdout: Option<usize>,
    /// Where the scene is in the dataset's coordinates, when not in `[-1, 1]^3`: training maps
    /// the box into the model's cube, and generated volumes are placed back on
    /// [`SceneBounds::cube`]. Absent from runs made before it existed (the unit cube). Written
    /// as `null` rather than left out, so that `--set bounds=...` finds it.
    #[serde(default)]
    pub bounds: Option<SceneBounds>,
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

/// A step decay of the learning rate within each scale ([`TrainConfig::lr_decay`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LrDecay {
    /// The fraction of a scale's iterations after which the rate drops, in (0, 1].
    pub at: f64,
    /// What the rate is multiplied by, in (0, 1].
    pub factor: f64,
}

/// Which coarser generators keep training while a 3D scale trains ([`TrainConfig::concurrent`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Concurrent {
    /// 3D scales trained at once, the current one included (ConSinGAN's `train_depth`, 3);
    /// 1 trains the current scale alone.
    pub scales: usize,
    /// The learning rate of the generator k scales below the current one is the scale's rate
    /// times this to the power k (ConSinGAN's `lr_scale`, 0.1), in (0, 1].
    pub learning_rate_scale: f64,
    /// The coarsest scale whose generator keeps training above its own scale: 1 (ConSinGAN,
    /// and when left out) lets every scale train on; 2 keeps G_1, where the scene's layout
    /// forms, frozen once its scale is done.
    #[serde(default = "first_concurrent_scale")]
    pub first_scale: usize,
}

/// [`Concurrent::first_scale`] when a configuration leaves it out: every scale trains on.
fn first_concurrent_scale() -> usize {
    1
}

/// How many views one training step of a scale renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ScaleViews {
    /// Views of the critic's real and fake batches and of the generator's adversarial
    /// renderings.
    pub generated: usize,
    /// Views of the reconstruction loss per generator step.
    pub reconstruction: usize,
}

impl ScaleViews {
    /// `views` views for both.
    pub fn same(views: usize) -> Self {
        Self {
            generated: views,
            reconstruction: views,
        }
    }
}

/// How long one scale trains. One iteration is `d_steps` critic steps, then `g_steps`
/// generator steps; the first `reconstruction_only` iterations skip the critic and train the
/// reconstruction alone (a quarter in the presets, as the paper's 20 of 80 epochs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ScaleSchedule {
    /// Iterations of the scale.
    pub iterations: usize,
    /// The first iterations that train the reconstruction only.
    pub reconstruction_only: usize,
}

impl ScaleSchedule {
    /// `iterations` iterations, the first quarter reconstruction-only.
    pub fn quarter_reconstruction(iterations: usize) -> Self {
        Self {
            iterations,
            reconstruction_only: iterations / 4,
        }
    }
}

/// The same schedule for all `scales` scales.
fn uniform_schedule(iterations: usize, scales: usize) -> Vec<ScaleSchedule> {
    vec![ScaleSchedule::quarter_reconstruction(iterations); scales]
}

/// Iterations per scale of the `tiny` preset. The coarsest scale, which is cheap and forms the
/// scene's layout, trains longest: 720 instead of 240 iterations hold the layouts nearer the
/// scene's (with post-activated density: the stones' floaters -18% and colour drift -8%, at
/// Diversity-MV 0.152; 44 s more in the demo's timing). The two finer 3D scales, where V* and the samples'
/// sharpness gain most, train 480 each (they had 160 and 240: V*'s volume +0.6 and +0.4 dB).
/// docs/training.md has the tables and times.
const TINY_ITERATIONS: [usize; 4] = [720, 480, 480, 80];

/// Iterations per scale of the `small` preset: 240 and 160 at the coarse scales (`tiny`'s of
/// an earlier day; `small` was not measured with `tiny`'s longer ones), then fewer where an
/// iteration costs most (3.6 s at 57^3, 5.9 s for the upsampler at 216^2 on 2 cores), so the
/// preset trains in under 20 minutes (docs/training.md, "`small` in 20 minutes").
const SMALL_ITERATIONS: [usize; 5] = [240, 160, 160, 80, 40];

/// The paper's table of training parameters (`tab:train_params`), first row (Stonehenge and
/// most scenes): views per step of generated scenes and of the reconstruction at its 6 scales.
const PAPER_VIEWS: [(usize, usize); 6] = [(6, 2), (6, 2), (6, 2), (5, 1), (2, 1), (2, 1)];
/// The same table's Island row, which also has L = 5 and 25^2 coarsest renderings.
const ISLAND_VIEWS: [(usize, usize); 6] = [(6, 2), (6, 2), (6, 2), (6, 1), (3, 1), (2, 1)];

/// Per-scale views from `(generated, reconstruction)` pairs.
fn table_views(table: &[(usize, usize)]) -> Vec<ScaleViews> {
    table
        .iter()
        .map(|&(generated, reconstruction)| ScaleViews {
            generated,
            reconstruction,
        })
        .collect()
}

/// Views of the reconstruction loss per generator step at the CPU presets' 3D scales (their
/// critics see 2): cheap next to the generator pass, and V*'s gradient less noisy.
const CPU_RECONSTRUCTION_VIEWS: usize = 8;

/// The CPU presets' reconstruction weights (colour, depth, opacity) are the paper's times this:
/// against the adversarial and colour-distribution terms, the reconstruction V* gained 2.2 dB
/// PSNR over three seeds (docs/training.md, "Why V* stays below a direct fit").
const CPU_RECONSTRUCTION_WEIGHT: f64 = 5.0;

/// Weight of the CPU presets' height-profile loss of samples (see
/// [`TrainConfig::lambda_height_profile`]); it took the matter in the sky that the heavier
/// reconstruction weights let in back out (docs/training.md).
const CPU_HEIGHT_PROFILE: f64 = 50.0;

/// Learning rate of the CPU presets' reconstruction noise z*_n (see
/// [`TrainConfig::reconstruction_noise_lr`]): over three seeds V*'s volume gained 0.5 dB on
/// `tiny` and 3.4 dB on `small`, and the samples' colour SWD fell 11% and 8%
/// (docs/training.md, "Optimised reconstruction noise").
const CPU_RECONSTRUCTION_NOISE_LR: f64 = 0.05;

/// Weight of `tiny`'s binary-opacity prior of samples (see
/// [`TrainConfig::lambda_opacity_binary`]), at every 3D scale: over three seeds the samples'
/// floaters fell 32% (lower at every seed); alone it made their purple-tinted stones opaque at
/// the finest 3D scale (colour SWD +12%), with [`TINY_CHROMA`] they come out grey
/// (docs/training.md, "Opacity priors on the samples" and "The samples' tint in chroma").
const TINY_OPACITY_BINARY: f64 = 3.0;

/// Weight of `tiny`'s chroma-distribution loss of samples (see
/// [`TrainConfig::lambda_chroma`]): with the binary-opacity prior at every 3D scale, over four
/// seeds the samples' colour SWD fell 10% (lower at every seed) and their purple pixels from
/// 4-7% to 0.4-2.9%, the other metrics within the seeds' spread (docs/training.md).
const TINY_CHROMA: f64 = 100.0;

/// Weight of the colour-distribution loss in every preset (see [`TrainConfig::lambda_colour`]).
const LAMBDA_COLOUR: f64 = 20.0;

/// Weight of the opacity reconstruction in every preset (see [`TrainConfig::lambda_opacity`]).
const LAMBDA_OPACITY: f64 = 10.0;

/// Density above which the upsampled coarser volume is matter, for the active set: a voxel of
/// this density at 28^3 in the model's `[-1, 1]^3` cube stops 0.7% of the light crossing it.
const SPARSE_THRESHOLD: f32 = 0.1;

/// Voxels of margin the active set adds around matter.
const SPARSE_MARGIN: usize = 2;

/// The first 3D scale on the active set in the presets: every scale with a coarser volume. On
/// `tiny` (three seeds, docs/training.md) the active set with its shell from scale 2 matched the
/// dense model on every metric within the seeds' spread, and a generator step at the paper's
/// 95^3 and 126^3 is 5.2x and 7.4x faster on it (docs/performance-patch-gan.md).
const SPARSE_FROM_SCALE: usize = 2;

/// The volume grows by 4/3 per scale.
const VOLUME_GROWTH: f64 = 4.0 / 3.0;
/// Renderings grow by 1.5 per scale.
const IMAGE_GROWTH: f64 = 1.5;

/// Errors, naming `field`, unless the loss weight `value` is finite and >= 0.
fn check_weight(field: &str, value: f64) -> Result<()> {
    check_non_negative(field, "weight", value)
}

/// Errors unless `value` (a `what`) is finite and not negative.
fn check_non_negative(field: &str, what: &str, value: f64) -> Result<()> {
    if value >= 0.0 && value.is_finite() {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("expected a finite {what} >= 0, got {value}"),
        ))
    }
}

/// Errors unless `value` (a `what`) lies in [0, 1).
pub(crate) fn check_fraction(field: &str, what: &str, value: f64) -> Result<()> {
    if (0.0..1.0).contains(&value) {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("expected {what} in [0, 1), got {value}"),
        ))
    }
}

/// The training recipe measured on `tiny` (docs/training.md), for a CPU preset with the sizes
/// of `sized` and `iterations` per scale (a quarter of them reconstruction-only): learning rate
/// 1e-3 (far fewer iterations than the paper, so larger steps), reconstruction weights
/// [`CPU_RECONSTRUCTION_WEIGHT`] times the paper's with [`CPU_RECONSTRUCTION_VIEWS`] views per
/// generator step, 2 views for the critics, the samples' height profile, and optimised
/// reconstruction noise.
fn cpu_recipe(sized: TrainConfig, iterations: &[usize]) -> TrainConfig {
    TrainConfig {
        schedule: iterations
            .iter()
            .map(|&n| ScaleSchedule::quarter_reconstruction(n))
            .collect(),
        views_per_step: 2,
        learning_rate: 1e-3,
        checkpoint_seconds: 60,
        lambda_color: sized.lambda_color * CPU_RECONSTRUCTION_WEIGHT,
        lambda_depth: sized.lambda_depth * CPU_RECONSTRUCTION_WEIGHT,
        lambda_opacity: sized.lambda_opacity * CPU_RECONSTRUCTION_WEIGHT,
        lambda_height_profile: CPU_HEIGHT_PROFILE,
        reconstruction_noise_lr: CPU_RECONSTRUCTION_NOISE_LR,
        ..sized
    }
    .with_reconstruction_views(CPU_RECONSTRUCTION_VIEWS)
}

/// `count` sizes starting at `first`, each `growth` times the previous, rounded.
fn geometric(first: usize, growth: f64, count: usize) -> Vec<usize> {
    (0..count)
        .map(|i| (first as f64 * growth.powi(i as i32)).round() as usize)
        .collect()
}

/// Samples per ray rising linearly from `first` at the coarsest scale to `last` at the finest.
fn sample_ramp(first: usize, last: usize, count: usize) -> Vec<usize> {
    (0..count)
        .map(|i| {
            if count == 1 {
                last
            } else {
                first + (last - first) * i / (count - 1)
            }
        })
        .collect()
}

impl TrainConfig {
    /// The names [`TrainConfig::preset`] accepts.
    pub const PRESETS: [&'static str; 5] = ["paper", "paper-island", "small", "tiny", "micro"];

    /// A named preset:
    ///
    /// - `paper`: the paper's N = 6 (volumes 40..126, renderings 32..160, final 320^2), and its
    ///   table of training parameters for Stonehenge and most scenes: L = 7, 6, 6, 6, 5, 2, 2
    ///   generated and 2, 2, 2, 1, 1, 1 reconstruction views per step; 32 channels, 64 to 128
    ///   samples. Needs a GPU (see docs/training.md).
    /// - `paper-island`: the table's Island row: L = 5, renderings 25..160, 6, 6, 6, 6, 3, 2
    ///   generated views.
    /// - `small`: N = 5, volumes 24..57, renderings 32..108 (final 216^2), 16 channels,
    ///   `tiny`'s training recipe with a shorter schedule of its own (fewest iterations at
    ///   the costly fine scales); under 20
    ///   minutes on 2 CPU cores.
    /// - `tiny`: N = 4, volumes 16..28, renderings 24..54 (final 108^2), 16 channels, learning
    ///   rate 1e-3 (fewer iterations than the paper, so larger steps), reconstruction weights
    ///   5x the paper's, the samples' height profile, optimised reconstruction noise z*_n, and
    ///   the binary-opacity prior with the chroma-distribution loss on its samples (all
    ///   measured in docs/training.md); about five and a half minutes of training on 2 CPU
    ///   cores.
    /// - `micro`: N = 3, 8^3 and 11^3 volumes, for tests (seconds); dense finer scale.
    ///
    /// Every preset but `micro` runs its finer 3D scales on the active set, shell included
    /// (`sparse_from_scale` 2, `sparse_shell`; `--dense` for the paper's dense model).
    pub fn preset(name: &str) -> Result<Self> {
        let paper = Self {
            preset: "paper".into(),
            volume_sizes: vec![40, 53, 71, 95, 126],
            image_sizes: vec![32, 48, 72, 108, 160],
            samples: sample_ramp(64, 128, 5),
            layers: 7,
            channels: 32,
            upsampler_widths: [32, 16, 8, 8],
            schedule: uniform_schedule(2000, 6),
            d_steps: 3,
            g_steps: 3,
            views_per_step: 1,
            scale_views: Some(table_views(&PAPER_VIEWS)),
            learning_rate: 5e-4,
            lr_decay: None,
            concurrent: None,
            betas: (0.9, 0.999),
            gp_weight: 0.1,
            lambda_color: 10.0,
            lambda_depth: 30.0,
            lambda_swd: 1.0,
            lambda_fitted: 0.0,
            lambda_volume_critic: 0.0,
            volume_critic_colour: false,
            lambda_opacity: LAMBDA_OPACITY,
            critic_opacity: true,
            lambda_colour: LAMBDA_COLOUR,
            lambda_chroma: 0.0,
            lambda_height_profile: 0.0,
            lambda_opacity_binary: 0.0,
            opacity_binary_until_scale: None,
            lambda_opacity_distribution: 0.0,
            reconstruction_noise_lr: 0.0,
            noise_skip: false,
            reconstruction_noise_final_lr: None,
            reconstruction_noise_from: 0.0,
            generator_average: 0.0,
            reconstruction_fit_steps: 0,
            sparse_from_scale: Some(SPARSE_FROM_SCALE),
            sparse_threshold: SPARSE_THRESHOLD,
            sparse_margin: SPARSE_MARGIN,
            sparse_shell: true,
            noise_amp_factor: 0.1,
            noise_amp_first: 1.0,
            density_scale: 25.0,
            density_shift: -4.0,
            background: [1.0, 1.0, 1.0],
            density_weighted_colour: false,
            post_activation: false,
            use_swd: true,
            swd_features: SwdFeatures::PatchPyramid,
            use_csg: true,
            use_depth: true,
            checkpoint_seconds: 300,
            checkpoint_iterations: 0,
            seed: 0,
            holdout: None,
            bounds: None,
        };
        let scaled = |preset: &str, scales: usize, volume: usize, image: usize| Self {
            preset: preset.into(),
            layers: 5,
            views_per_step: 4,
            scale_views: None,
            volume_sizes: geometric(volume, VOLUME_GROWTH, scales - 1),
            image_sizes: geometric(image, IMAGE_GROWTH, scales - 1),
            samples: sample_ramp(48, 96, scales - 1),
            channels: 16,
            upsampler_widths: [16, 16, 8, 8],
            ..paper.clone()
        };
        match name {
            "paper-island" => Ok(Self {
                preset: "paper-island".into(),
                layers: 5,
                image_sizes: geometric(25, (160.0f64 / 25.0).powf(0.25), 5),
                scale_views: Some(table_views(&ISLAND_VIEWS)),
                ..paper
            }),
            "paper" => Ok(paper),
            "small" => Ok(cpu_recipe(scaled("small", 5, 24, 32), &SMALL_ITERATIONS)),
            "tiny" => Ok(Self {
                // `tiny` only: on `small` the prior cost colour, V* and diversity
                // (docs/training.md, "Opacity priors on the samples").
                lambda_opacity_binary: TINY_OPACITY_BINARY,
                lambda_chroma: TINY_CHROMA,
                // Sharper edges than a voxel: V* +2.8 dB, the samples' patches and colours
                // closer on both scenes measured (docs/training.md, "Post-activated density").
                post_activation: true,
                ..cpu_recipe(scaled("tiny", 4, 16, 24), &TINY_ITERATIONS)
            }),
            "micro" => Ok(Self {
                layers: 3,
                channels: 4,
                upsampler_widths: [4, 4, 4, 4],
                samples: vec![16, 16],
                schedule: uniform_schedule(4, 3),
                d_steps: 1,
                g_steps: 1,
                checkpoint_seconds: 0,
                // The paper's dense finer scale, so the tests that train `micro` cover it;
                // the active set has tests of its own.
                sparse_from_scale: None,
                ..scaled("micro", 3, 8, 12)
            }),
            other => Err(invalid(
                "preset",
                format!(
                    "unknown preset `{other}`; expected one of {}",
                    Self::PRESETS.join(", ")
                ),
            )),
        }
    }

    /// The views per step of scale `n` (1-based).
    ///
    /// # Panics
    /// If `n` is not a scale of this configuration (see [`TrainConfig::validate`]).
    pub fn views(&self, n: usize) -> ScaleViews {
        match &self.scale_views {
            Some(views) => views[n - 1],
            None => ScaleViews::same(self.views_per_step),
        }
    }

    /// Sets the reconstruction loss's views per generator step at every 3D scale to `views`,
    /// keeping each scale's generated views (and the upsampler's views).
    pub fn with_reconstruction_views(mut self, views: usize) -> Self {
        let mut all: Vec<ScaleViews> = (1..=self.scales()).map(|n| self.views(n)).collect();
        let upsampler = all.len() - 1;
        for scale in &mut all[..upsampler] {
            scale.reconstruction = views;
        }
        self.scale_views = Some(all);
        self
    }

    /// The weight of the binary-opacity prior at 3D scale `n` (1-based):
    /// [`TrainConfig::lambda_opacity_binary`] up to
    /// [`TrainConfig::opacity_binary_until_scale`], 0 above it.
    ///
    /// ```
    /// use singrav::TrainConfig;
    ///
    /// let config = TrainConfig::preset("micro")?
    ///     .with_setting("lambda_opacity_binary", "3")?
    ///     .with_setting("opacity_binary_until_scale", "1")?;
    /// assert_eq!(config.opacity_binary_weight(1), 3.0);
    /// assert_eq!(config.opacity_binary_weight(2), 0.0);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn opacity_binary_weight(&self, n: usize) -> f64 {
        match self.opacity_binary_until_scale {
            Some(last) if n > last => 0.0,
            _ => self.lambda_opacity_binary,
        }
    }

    /// The number of scales N (3D scales plus the upsampler).
    pub fn scales(&self) -> usize {
        self.volume_sizes.len() + 1
    }

    /// The edge of the final (upsampled) images: twice the last rendering.
    pub fn final_image_size(&self) -> usize {
        2 * self.image_sizes.last().copied().unwrap_or(0)
    }

    /// The schedule of scale `n` (1-based).
    ///
    /// # Panics
    /// If `n` is not a scale of this configuration (see [`TrainConfig::validate`]).
    pub fn scale_schedule(&self, n: usize) -> ScaleSchedule {
        self.schedule[n - 1]
    }

    /// The learning rate of scale `n` (1-based) at its 0-based `iteration`: `learning_rate`,
    /// times [`LrDecay::factor`] from [`LrDecay::at`] of the scale's iterations on.
    ///
    /// ```
    /// use singrav::config::{LrDecay, TrainConfig};
    /// let config = TrainConfig {
    ///     lr_decay: Some(LrDecay { at: 0.75, factor: 0.1 }),
    ///     ..TrainConfig::preset("tiny")?
    /// };
    /// // tiny's scale 3 runs 480 iterations: the rate drops from iteration 360.
    /// assert_eq!(config.learning_rate_at(3, 359), 1e-3);
    /// assert!((config.learning_rate_at(3, 360) - 1e-4).abs() < 1e-12);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn learning_rate_at(&self, n: usize, iteration: usize) -> f64 {
        self.learning_rate * self.decay_at(n, iteration)
    }

    /// The reconstruction noise's learning rate at `iteration` of scale `n`: decayed
    /// exponentially towards [`TrainConfig::reconstruction_noise_final_lr`] when that is set,
    /// and with the networks' ([`TrainConfig::learning_rate_at`]).
    ///
    /// ```
    /// use singrav::config::TrainConfig;
    /// let config = TrainConfig {
    ///     reconstruction_noise_lr: 0.1,
    ///     reconstruction_noise_final_lr: Some(0.01),
    ///     ..TrainConfig::preset("tiny")?
    /// };
    /// // tiny's scale 3 runs 480 iterations: a tenth at the end, a third of the way at half.
    /// assert!((config.reconstruction_noise_lr_at(3, 0) - 0.1).abs() < 1e-12);
    /// assert!((config.reconstruction_noise_lr_at(3, 240) - 0.1 * 0.1f64.sqrt()).abs() < 1e-12);
    /// // From half-way on only: still until then, the same decay over the second half.
    /// let late = TrainConfig { reconstruction_noise_from: 0.5, ..config };
    /// assert_eq!(late.reconstruction_noise_lr_at(3, 239), 0.0);
    /// assert!((late.reconstruction_noise_lr_at(3, 240) - 0.1).abs() < 1e-12);
    /// assert!((late.reconstruction_noise_lr_at(3, 360) - 0.1 * 0.1f64.sqrt()).abs() < 1e-12);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn reconstruction_noise_lr_at(&self, n: usize, iteration: usize) -> f64 {
        let fraction = iteration as f64 / self.scale_schedule(n).iterations.max(1) as f64;
        if fraction < self.reconstruction_noise_from {
            return 0.0;
        }
        let along = match self.reconstruction_noise_final_lr {
            Some(last) if self.reconstruction_noise_lr > 0.0 => {
                let window = (fraction - self.reconstruction_noise_from)
                    / (1.0 - self.reconstruction_noise_from);
                (last / self.reconstruction_noise_lr).powf(window)
            }
            _ => 1.0,
        };
        self.reconstruction_noise_lr * along * self.decay_at(n, iteration)
    }

    /// The factor `lr_decay` puts on the learning rates at `iteration` of scale `n` (1 before
    /// the decay, and without one).
    fn decay_at(&self, n: usize, iteration: usize) -> f64 {
        match self.lr_decay {
            Some(decay)
                if iteration as f64 >= decay.at * self.scale_schedule(n).iterations as f64 =>
            {
                decay.factor
            }
            _ => 1.0,
        }
    }

    /// The coarser 3D scales whose generators train while 3D scale `n` (1-based) trains, coarsest
    /// first, each with the factor its learning rate is the scale's times
    /// ([`TrainConfig::concurrent`]); empty without concurrent training and for the upsampler.
    ///
    /// ```
    /// use singrav::config::{Concurrent, TrainConfig};
    /// let config = TrainConfig {
    ///     concurrent: Some(Concurrent { scales: 3, learning_rate_scale: 0.1, first_scale: 1 }),
    ///     ..TrainConfig::preset("tiny")?
    /// };
    /// assert_eq!(config.concurrent_scales(1), []);
    /// assert_eq!(config.concurrent_scales(2), [(1, 0.1)]);
    /// let scale_3 = config.concurrent_scales(3);
    /// assert_eq!(scale_3.iter().map(|s| s.0).collect::<Vec<_>>(), [1, 2]);
    /// assert!((scale_3[0].1 - 0.01).abs() < 1e-12);
    /// // tiny's scale 4 is the 2D upsampler: it trains alone.
    /// assert_eq!(config.concurrent_scales(4), []);
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn concurrent_scales(&self, n: usize) -> Vec<(usize, f64)> {
        match self.concurrent {
            Some(Concurrent {
                scales,
                learning_rate_scale,
                first_scale,
            }) if n < self.scales() => {
                let first = n.saturating_sub(scales.saturating_sub(1)).max(first_scale);
                (first..n)
                    .map(|m| (m, learning_rate_scale.powi((n - m) as i32)))
                    .collect()
            }
            _ => Vec::new(),
        }
    }

    /// Iterations of all scales before scale `n` (1-based).
    pub fn iterations_before(&self, n: usize) -> usize {
        self.schedule[..n - 1].iter().map(|s| s.iterations).sum()
    }

    /// Iterations of the whole run.
    pub fn total_iterations(&self) -> usize {
        self.iterations_before(self.schedule.len() + 1)
    }

    /// The same `iterations` at every scale, the first quarter reconstruction-only.
    pub fn with_iterations(mut self, iterations: usize) -> Self {
        self.schedule = uniform_schedule(iterations, self.scales());
        self
    }

    /// The ablation "number of scales": keeps the `scales - 1` coarsest 3D scales and the
    /// upsampler, so the final images shrink with the pyramid.
    pub fn with_scales(mut self, scales: usize) -> Result<Self> {
        if scales < 2 || scales > self.scales() {
            return Err(invalid(
                "scales",
                format!(
                    "the `{}` preset has {} scales; choose 2 to {}",
                    self.preset,
                    self.scales(),
                    self.scales()
                ),
            ));
        }
        self.volume_sizes.truncate(scales - 1);
        self.image_sizes.truncate(scales - 1);
        self.samples.truncate(scales - 1);
        if let Some(&upsampler) = self.schedule.last() {
            self.schedule.truncate(scales - 1);
            self.schedule.push(upsampler);
        }
        if let Some(views) = &mut self.scale_views {
            if let Some(&upsampler) = views.last() {
                views.truncate(scales - 1);
                views.push(upsampler);
            }
        }
        Ok(self)
    }

    /// Sets one field by name to a JSON value, as `volgen train --set FIELD=VALUE` does: for
    /// the settings without a flag of their own (a loss weight, the channels, the schedule).
    /// `value` is read as JSON (`50`, `true`, `[240, 160]`), and as a string where it is not
    /// JSON. Call [`TrainConfig::validate`] after the last change.
    ///
    /// ```
    /// use singrav::TrainConfig;
    /// let config = TrainConfig::preset("tiny")?.with_setting("lambda_color", "50")?;
    /// assert_eq!(config.lambda_color, 50.0);
    /// assert!(TrainConfig::preset("tiny")?.with_setting("lambda_colr", "1").is_err());
    /// # Ok::<(), singrav::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::Invalid`] naming the field when it does not exist or the value is not of its
    /// type.
    pub fn with_setting(self, field: &str, value: &str) -> Result<Self> {
        let mut fields = match serde_json::to_value(&self) {
            Ok(serde_json::Value::Object(fields)) => fields,
            other => {
                return Err(invalid(
                    field,
                    format!("cannot list the settings: {other:?}"),
                ))
            }
        };
        let Some(slot) = fields.get_mut(field) else {
            let known: Vec<&str> = fields.keys().map(String::as_str).collect();
            return Err(invalid(
                field,
                format!("no such setting; the settings are {}", known.join(", ")),
            ));
        };
        let parsed = serde_json::from_str(value)
            .unwrap_or_else(|_| serde_json::Value::String(value.to_string()));
        let was = std::mem::replace(slot, parsed);
        serde_json::from_value(serde_json::Value::Object(fields)).map_err(|e| {
            invalid(
                field,
                format!("`{value}` is not a value of this setting (it was {was}): {e}"),
            )
        })
    }

    /// The renderer's colour rule for [`TrainConfig::density_weighted_colour`].
    pub fn colour_interpolation(&self) -> volrender::ColourInterpolation {
        volrender::ColourInterpolation::density_weighted_if(self.density_weighted_colour)
    }

    /// The renderer's density rule for [`TrainConfig::post_activation`], with this run's
    /// activation.
    pub fn density_interpolation(&self) -> volrender::DensityInterpolation {
        volrender::DensityInterpolation::post_activated_if(
            self.post_activation,
            self.density_scale,
            self.density_shift,
        )
    }

    /// Checks that the sizes agree and every setting is in range.
    pub fn validate(&self) -> Result<()> {
        check_weight("lambda_fitted", self.lambda_fitted)?;
        check_weight("lambda_volume_critic", self.lambda_volume_critic)?;
        check_non_negative(
            "reconstruction_noise_lr",
            "learning rate",
            self.reconstruction_noise_lr,
        )?;
        check_fraction(
            "reconstruction_noise_from",
            "a fraction of a scale's iterations",
            self.reconstruction_noise_from,
        )?;
        check_fraction(
            "generator_average",
            "the weight average's decay (0: off)",
            self.generator_average,
        )?;
        if let Some(last) = self.reconstruction_noise_final_lr {
            if !(last > 0.0 && last.is_finite()) {
                return Err(invalid(
                    "reconstruction_noise_final_lr",
                    format!("expected a finite learning rate > 0, got {last}"),
                ));
            }
        }
        if let Some(bounds) = self.bounds {
            SceneBounds::new(bounds.min, bounds.max)?;
        }
        if self.post_activation && self.density_weighted_colour {
            return Err(invalid(
                "post_activation",
                "cannot be combined with density_weighted_colour (its weights are the voxels' \
                 physical densities); set one of them to false",
            ));
        }
        // The terms on the samples' rendered opacity read it from the critics' views.
        for (field, weight) in [
            ("lambda_height_profile", self.lambda_height_profile),
            ("lambda_opacity_binary", self.lambda_opacity_binary),
            (
                "lambda_opacity_distribution",
                self.lambda_opacity_distribution,
            ),
        ] {
            check_weight(field, weight)?;
            if weight > 0.0 && !self.critic_opacity {
                return Err(invalid(
                    field,
                    format!(
                        "compares the samples' rendered opacity, which the critics' views hold \
                         only with critic_opacity on (--no-opacity turns it off); set \
                         {field}=0 or critic_opacity=true"
                    ),
                ));
            }
        }
        if let Some(last) = self.opacity_binary_until_scale {
            let scales_3d = self.volume_sizes.len();
            if !(1..=scales_3d).contains(&last) {
                return Err(invalid(
                    "opacity_binary_until_scale",
                    format!("expected a 3D scale from 1 to {scales_3d}, got {last}"),
                ));
            }
        }
        if let Some(from) = self.sparse_from_scale {
            if from < 2 {
                return Err(invalid(
                    "sparse_from_scale",
                    format!(
                        "expected a 3D scale >= 2 (the coarsest, 1, has no coarser volume to \
                         take the active set from), got {from}"
                    ),
                ));
            }
            if !(self.sparse_threshold.is_finite() && self.sparse_threshold > 0.0) {
                return Err(invalid(
                    "sparse_threshold",
                    format!(
                        "expected a finite density > 0, got {}",
                        self.sparse_threshold
                    ),
                ));
            }
        }
        let n = self.volume_sizes.len();
        if n == 0 {
            return Err(invalid("volume_sizes", "need at least one 3D scale"));
        }
        if self.image_sizes.len() != n || self.samples.len() != n {
            return Err(invalid(
                "config",
                format!(
                    "volume_sizes, image_sizes and samples need one entry per 3D scale; have {}, {} and {}",
                    n,
                    self.image_sizes.len(),
                    self.samples.len()
                ),
            ));
        }
        if let Some(every) = self.holdout.filter(|&every| every < 2) {
            return Err(invalid(
                "holdout",
                format!("expected every N-th view held out with N >= 2, got {every}"),
            ));
        }
        let field = 2 * self.layers + 1;
        if let Some(size) = self.image_sizes.iter().find(|&&s| s <= field) {
            return Err(invalid(
                "image_sizes",
                format!("{size} is not larger than the critics' receptive field {field}"),
            ));
        }
        if self.volume_sizes.contains(&0) || self.samples.contains(&0) {
            return Err(invalid("volume_sizes / samples", "must be positive"));
        }
        if self.layers < 2 || self.channels == 0 || self.upsampler_widths.contains(&0) {
            return Err(invalid(
                "layers / channels",
                "need at least 2 layers and positive widths",
            ));
        }
        if self.schedule.len() != n + 1 {
            return Err(invalid(
                "schedule",
                format!(
                    "needs one entry per scale ({}), has {}",
                    n + 1,
                    self.schedule.len()
                ),
            ));
        }
        if self.d_steps == 0 || self.g_steps == 0 {
            return Err(invalid("d_steps / g_steps", "must be positive"));
        }
        if self.views_per_step == 0 {
            return Err(invalid("views_per_step", "must be positive"));
        }
        if let Some(views) = &self.scale_views {
            if views.len() != n + 1
                || views
                    .iter()
                    .any(|v| v.generated == 0 || v.reconstruction == 0)
            {
                return Err(invalid(
                    "scale_views",
                    format!(
                        "needs one entry per scale ({}) with positive generated and \
                         reconstruction views, has {views:?}",
                        n + 1
                    ),
                ));
            }
        }
        for (i, s) in self.schedule.iter().enumerate() {
            if s.iterations == 0 || s.reconstruction_only > s.iterations {
                return Err(invalid(
                    "schedule",
                    format!(
                        "scale {}: needs at least one iteration and no more reconstruction-only \
                         iterations than iterations, has {} of {}",
                        i + 1,
                        s.reconstruction_only,
                        s.iterations
                    ),
                ));
            }
        }
        if !self.use_swd && self.swd_features != SwdFeatures::PatchPyramid {
            return Err(invalid(
                "swd_features",
                "VGG-19 features need the SWD loss (use_swd); without it they would go unused",
            ));
        }
        let weights = [
            self.learning_rate,
            self.gp_weight,
            self.lambda_color,
            self.lambda_depth,
            self.lambda_swd,
            self.lambda_opacity,
            self.lambda_colour,
            self.lambda_chroma,
            self.noise_amp_factor,
            self.noise_amp_first,
        ];
        if weights.iter().any(|w| !(w.is_finite() && *w >= 0.0)) || self.learning_rate == 0.0 {
            return Err(invalid(
                "learning rate / loss weights / noise amplitudes",
                "must be finite and non-negative (learning rate positive)",
            ));
        }
        if let Some(LrDecay { at, factor }) = self.lr_decay {
            if !(at > 0.0 && at <= 1.0 && factor > 0.0 && factor <= 1.0) {
                return Err(invalid(
                    "lr_decay",
                    format!("`at` and `factor` must lie in (0, 1], got at {at}, factor {factor}"),
                ));
            }
        }
        if let Some(Concurrent {
            scales,
            learning_rate_scale,
            first_scale,
        }) = self.concurrent
        {
            if scales == 0
                || first_scale == 0
                || !(learning_rate_scale > 0.0 && learning_rate_scale <= 1.0)
            {
                return Err(invalid(
                    "concurrent",
                    format!(
                        "`scales` and `first_scale` must be at least 1 and `learning_rate_scale` \
                         lie in (0, 1], got scales {scales}, first_scale {first_scale}, \
                         learning_rate_scale {learning_rate_scale}"
                    ),
                ));
            }
        }
        let density_ok = self.density_scale.is_finite()
            && self.density_scale > 0.0
            && self.density_shift.is_finite();
        if !density_ok || self.background.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return Err(invalid(
                "density_scale / density_shift / background",
                "need a positive density scale, a finite shift and a background in [0, 1]",
            ));
        }
        Ok(())
    }

    /// The rule of the finer scales' active sets: `sparse_threshold`, `sparse_margin`,
    /// `sparse_shell`.
    pub fn active_set_rule(&self) -> crate::active_set::ActiveSetRule {
        crate::active_set::ActiveSetRule {
            threshold: self.sparse_threshold,
            margin: self.sparse_margin,
            shell: self.sparse_shell,
        }
    }

    /// The activation mapping the generators' raw volumes to physical ones.
    pub fn activation(&self) -> radiance_volume::Activation {
        radiance_volume::Activation::default()
            .with_density_scale(self.density_scale)
            .with_density_shift(self.density_shift)
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
    use super::{Concurrent, LrDecay, ScaleViews, TrainConfig};

    /// Asserts that `config` fails validation with an error naming `field`.
    fn assert_refused_naming(config: &TrainConfig, field: &str) {
        let message = config.validate().unwrap_err().to_string();
        assert!(message.contains(field), "{message}");
    }

    #[test]
    fn runs_saved_before_opacity_supervision_read_as_trained_without_it() {
        let mut json = serde_json::to_value(TrainConfig::preset("tiny").unwrap()).unwrap();
        let fields = json.as_object_mut().unwrap();
        for field in [
            "lambda_opacity",
            "critic_opacity",
            "lambda_colour",
            "lambda_chroma",
            "scale_views",
            "lambda_height_profile",
            "reconstruction_noise_lr",
            "noise_skip",
            "reconstruction_noise_final_lr",
            "reconstruction_noise_from",
            "generator_average",
            "reconstruction_fit_steps",
            "lambda_opacity_binary",
            "opacity_binary_until_scale",
            "lambda_opacity_distribution",
            "density_weighted_colour",
            "post_activation",
            "sparse_from_scale",
            "sparse_threshold",
            "sparse_margin",
            "sparse_shell",
        ] {
            fields.remove(field);
        }
        let old: TrainConfig = serde_json::from_value(json).unwrap();
        assert_eq!(old.lambda_opacity, 0.0);
        assert!(!old.critic_opacity);
        assert_eq!(old.lambda_colour, 0.0);
        assert_eq!(old.lambda_chroma, 0.0);
        assert_eq!(old.scale_views, None);
        assert_eq!(old.lambda_height_profile, 0.0);
        assert_eq!(old.reconstruction_noise_lr, 0.0);
        assert!(!old.noise_skip);
        assert_eq!(old.reconstruction_noise_final_lr, None);
        assert_eq!(old.reconstruction_noise_from, 0.0);
        assert_eq!(old.generator_average, 0.0);
        assert_eq!(old.reconstruction_fit_steps, 0);
        assert_eq!(old.lambda_opacity_binary, 0.0);
        assert_eq!(old.opacity_binary_until_scale, None);
        assert_eq!(old.lambda_opacity_distribution, 0.0);
        assert!(!old.density_weighted_colour);
        assert!(!old.post_activation);
        assert_eq!(old.sparse_from_scale, None);
        assert!(!old.sparse_shell);
        assert_eq!(old.views(1), ScaleViews::same(old.views_per_step));
        old.validate().unwrap();
    }

    #[test]
    fn post_activation_with_density_weighted_colour_is_refused_by_name() {
        let mut config = TrainConfig::preset("micro").unwrap();
        config.post_activation = true;
        config.validate().unwrap();
        assert_eq!(
            config.density_interpolation(),
            volrender::DensityInterpolation::PostActivated {
                scale: config.density_scale,
                shift: config.density_shift,
            }
        );
        config.density_weighted_colour = true;
        assert_refused_naming(&config, "post_activation");
    }

    #[test]
    fn active_set_and_sample_opacity_settings_out_of_range_are_refused_by_name() {
        let micro = TrainConfig::preset("micro").unwrap();
        let refused = |setting: &str, value: &str| {
            let err = micro
                .clone()
                .with_setting(setting, value)
                .and_then(|c| c.validate())
                .unwrap_err()
                .to_string();
            assert!(err.contains(setting), "{setting}={value}: {err}");
        };
        refused("sparse_from_scale", "1");
        refused("sparse_from_scale", "0");
        let sparse = micro
            .clone()
            .with_setting("sparse_from_scale", "2")
            .unwrap();
        sparse.validate().unwrap();
        for bad in ["0", "-0.1"] {
            let err = sparse
                .clone()
                .with_setting("sparse_threshold", bad)
                .unwrap()
                .validate()
                .unwrap_err()
                .to_string();
            assert!(err.contains("sparse_threshold"), "{err}");
        }
        refused("reconstruction_noise_lr", "-0.01");
        refused("reconstruction_noise_final_lr", "0");
        refused("reconstruction_noise_from", "1");
        refused("reconstruction_noise_from", "-0.5");
        // micro has two 3D scales.
        refused("opacity_binary_until_scale", "0");
        refused("opacity_binary_until_scale", "3");
        for field in [
            "lambda_height_profile",
            "lambda_opacity_binary",
            "lambda_opacity_distribution",
        ] {
            refused(field, "-1");
            let mut blind = micro.clone().with_setting(field, "1").unwrap();
            blind.critic_opacity = false;
            assert_refused_naming(&blind, "critic_opacity");
            assert_refused_naming(&blind, field);
        }
    }

    #[test]
    fn a_field_from_a_newer_version_is_refused_by_name() {
        let mut json = serde_json::to_value(TrainConfig::preset("micro").unwrap()).unwrap();
        json.as_object_mut()
            .unwrap()
            .insert("upsampler_norm".into(), false.into());
        let err = serde_json::from_value::<TrainConfig>(json).unwrap_err();
        assert!(err.to_string().contains("upsampler_norm"), "{err}");
    }

    #[test]
    fn reconstruction_views_change_the_3d_scales_only_and_follow_the_scales_ablation() {
        let micro = TrainConfig::preset("micro").unwrap();
        let config = micro.clone().with_reconstruction_views(7);
        let upsampler = config.scales();
        assert_eq!(
            config.views(1),
            ScaleViews {
                generated: micro.views_per_step,
                reconstruction: 7
            }
        );
        assert_eq!(
            config.views(upsampler),
            ScaleViews::same(micro.views_per_step)
        );
        let fewer = config.with_scales(2).unwrap();
        fewer.validate().unwrap();
        assert_eq!(fewer.views(1).reconstruction, 7);
        assert_eq!(fewer.views(2), ScaleViews::same(micro.views_per_step));
    }

    #[test]
    fn paper_presets_follow_the_papers_table_of_training_parameters() {
        let paper = TrainConfig::preset("paper").unwrap();
        let island = TrainConfig::preset("paper-island").unwrap();
        let views = |config: &TrainConfig| -> Vec<(usize, usize)> {
            (1..=config.scales())
                .map(|n| (config.views(n).generated, config.views(n).reconstruction))
                .collect()
        };
        // L, first volume / rendering, last volume / rendering, final, views per step.
        let rows = [
            (
                &paper,
                7,
                (40, 32),
                [(6, 2), (6, 2), (6, 2), (5, 1), (2, 1), (2, 1)],
            ),
            (
                &island,
                5,
                (40, 25),
                [(6, 2), (6, 2), (6, 2), (6, 1), (3, 1), (2, 1)],
            ),
        ];
        for (config, layers, first, per_scale_views) in rows {
            assert_eq!(config.layers, layers, "{}", config.preset);
            assert_eq!((config.volume_sizes[0], config.image_sizes[0]), first);
            assert_eq!((config.volume_sizes[4], config.image_sizes[4]), (126, 160));
            assert_eq!(config.final_image_size(), 320);
            assert_eq!(views(config), per_scale_views, "{}", config.preset);
        }
        // The smaller presets keep their own layers and views.
        let tiny = TrainConfig::preset("tiny").unwrap();
        assert_eq!(tiny.layers, 5);
        assert_eq!(
            tiny.views(1),
            ScaleViews {
                generated: 2,
                reconstruction: 8
            }
        );
        assert_eq!(tiny.views(tiny.scales()), ScaleViews::same(2));
    }

    #[test]
    fn views_missing_a_scale_or_zero_are_refused() {
        let micro = TrainConfig::preset("micro").unwrap();
        let short = TrainConfig {
            scale_views: Some(vec![ScaleViews::same(2)]),
            ..micro.clone()
        };
        let zero = micro.with_reconstruction_views(0);
        for config in [short, zero] {
            assert_refused_naming(&config, "scale_views");
        }
    }

    #[test]
    fn the_learning_rate_decays_where_set_and_bad_decays_are_refused() {
        let tiny = TrainConfig::preset("tiny").unwrap();
        assert_eq!(tiny.lr_decay, None);
        // Runs made before the field existed have none.
        let mut json = serde_json::to_value(&tiny).unwrap();
        json.as_object_mut().unwrap().remove("lr_decay");
        assert_eq!(serde_json::from_value::<TrainConfig>(json).unwrap(), tiny);
        // Settable by name although absent: written as null.
        let decayed = tiny
            .with_setting("lr_decay", r#"{"at": 0.5, "factor": 0.25}"#)
            .unwrap();
        decayed.validate().unwrap();
        // Scale 1 runs 720 iterations, scale 4 80: each decays at its own half.
        for (n, last_full) in [(1, 359), (4, 39)] {
            assert_eq!(decayed.learning_rate_at(n, last_full), 1e-3);
            assert_eq!(decayed.learning_rate_at(n, last_full + 1), 2.5e-4);
        }
        for (at, factor) in [
            (0.0, 0.1),
            (1.5, 0.1),
            (0.8, 0.0),
            (0.8, 2.0),
            (f64::NAN, 0.1),
        ] {
            let bad = TrainConfig {
                lr_decay: Some(LrDecay { at, factor }),
                ..decayed.clone()
            };
            assert_refused_naming(&bad, "lr_decay");
        }
    }

    #[test]
    fn concurrent_training_is_off_by_default_settable_and_checked() {
        let tiny = TrainConfig::preset("tiny").unwrap();
        assert_eq!(tiny.concurrent, None);
        assert!((1..=tiny.scales()).all(|n| tiny.concurrent_scales(n).is_empty()));
        // Runs made before the field existed have none.
        let mut json = serde_json::to_value(&tiny).unwrap();
        json.as_object_mut().unwrap().remove("concurrent");
        assert_eq!(serde_json::from_value::<TrainConfig>(json).unwrap(), tiny);
        let concurrent = tiny
            .clone()
            .with_setting("concurrent", r#"{"scales": 2, "learning_rate_scale": 0.5}"#)
            .unwrap();
        concurrent.validate().unwrap();
        assert_eq!(concurrent.concurrent_scales(1), []);
        assert_eq!(concurrent.concurrent_scales(2), [(1, 0.5)]);
        assert_eq!(concurrent.concurrent_scales(3), [(2, 0.5)]);
        let layout_frozen = tiny
            .clone()
            .with_setting(
                "concurrent",
                r#"{"scales": 3, "learning_rate_scale": 0.5, "first_scale": 2}"#,
            )
            .unwrap();
        assert_eq!(layout_frozen.concurrent_scales(2), []);
        assert_eq!(layout_frozen.concurrent_scales(3), [(2, 0.5)]);
        for (scales, learning_rate_scale, first_scale) in [
            (0, 0.1, 1),
            (3, 0.0, 1),
            (3, 1.5, 1),
            (3, f64::NAN, 1),
            (3, 0.1, 0),
        ] {
            let bad = TrainConfig {
                concurrent: Some(Concurrent {
                    scales,
                    learning_rate_scale,
                    first_scale,
                }),
                ..tiny.clone()
            };
            assert_refused_naming(&bad, "concurrent");
        }
    }

    #[test]
    fn per_scale_views_and_bounds_are_settable_on_presets_without_them() {
        // `micro` has neither, so the fields must be listed for `--set` to find them.
        let micro = TrainConfig::preset("micro").unwrap();
        assert_eq!((micro.scale_views.clone(), micro.bounds), (None, None));
        let views = r#"[{"generated": 2, "reconstruction": 8}, {"generated": 2, "reconstruction": 8},
            {"generated": 1, "reconstruction": 2}]"#;
        let set = micro
            .clone()
            .with_setting("scale_views", views)
            .unwrap()
            .with_setting("bounds", r#"{"min": [-2, -2, 0], "max": [2, 2, 1]}"#)
            .unwrap();
        set.validate().unwrap();
        assert_eq!(
            set.views(1),
            ScaleViews {
                generated: 2,
                reconstruction: 8
            }
        );
        assert_eq!(
            set.views(3),
            ScaleViews {
                generated: 1,
                reconstruction: 2
            }
        );
        assert_eq!(set.bounds.unwrap().max, [2.0, 2.0, 1.0]);
        // Runs written before the fields were listed as `null` read as before.
        let mut json = serde_json::to_value(&micro).unwrap();
        let fields = json.as_object_mut().unwrap();
        assert_eq!(fields.remove("scale_views"), Some(serde_json::Value::Null));
        assert_eq!(fields.remove("bounds"), Some(serde_json::Value::Null));
        assert_eq!(serde_json::from_value::<TrainConfig>(json).unwrap(), micro);
    }

    #[test]
    fn small_is_tinys_recipe_at_its_own_sizes_without_the_binary_opacity_prior() {
        let (tiny, small) = (
            TrainConfig::preset("tiny").unwrap(),
            TrainConfig::preset("small").unwrap(),
        );
        small.validate().unwrap();
        assert_eq!(small.volume_sizes, [24, 32, 43, 57]);
        assert_eq!(small.image_sizes, [32, 48, 72, 108]);
        assert_eq!(small.final_image_size(), 216);
        let iterations: Vec<_> = small.schedule.iter().map(|s| s.iterations).collect();
        assert_eq!(iterations, [240, 160, 160, 80, 40]);
        assert!(small
            .schedule
            .iter()
            .all(|s| s.reconstruction_only * 4 == s.iterations));
        // Everything but the sizes, the schedule, the binary-opacity prior (which cost small
        // colour, V* and diversity), the chroma loss that goes with it and the post-activated
        // density (measured on tiny only) is tiny's.
        assert_eq!(small.lambda_opacity_binary, 0.0);
        assert_eq!(small.lambda_chroma, 0.0);
        assert!(!small.post_activation);
        let resized = TrainConfig {
            lambda_opacity_binary: tiny.lambda_opacity_binary,
            lambda_chroma: tiny.lambda_chroma,
            post_activation: tiny.post_activation,
            preset: tiny.preset.clone(),
            volume_sizes: tiny.volume_sizes.clone(),
            image_sizes: tiny.image_sizes.clone(),
            samples: tiny.samples.clone(),
            schedule: tiny.schedule.clone(),
            scale_views: tiny.scale_views.clone(),
            ..small.clone()
        };
        assert_eq!(resized, tiny);
        assert!((1..small.scales()).all(|n| small.views(n).reconstruction == 8));
        assert_eq!(
            small.views(5),
            ScaleViews {
                generated: 2,
                reconstruction: 2
            }
        );
    }
}
