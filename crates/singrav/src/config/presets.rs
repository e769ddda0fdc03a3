//! The named presets: the paper's model and three CPU-sized recipes measured on this project's
//! scenes (each constant's comment names the measurement; the tables are in docs/journal/).

use super::schedule::uniform_schedule;
use super::{
    Ablations, ActiveSet, Critics, Losses, Noise, Pyramid, Rendering, RunPolicy, ScaleSchedule,
    ScaleViews, Schedule, SwdFeatures, TrainConfig, CONFIG_VERSION,
};
use crate::error::{invalid, Result};

/// Iterations per scale of the `tiny` preset. The coarsest scale, which is cheap and forms the
/// scene's layout, trains longest: 720 instead of 240 iterations hold the layouts nearer the
/// scene's (with post-activated density: the stones' floaters -18% and colour drift -8%). The
/// two finer 3D scales, where V* and the samples' sharpness gain most, train 480 each (they had
/// 160 and 240: V*'s volume +0.6 and +0.4 dB).
const TINY_ITERATIONS: [usize; 4] = [720, 480, 480, 80];

/// Iterations per scale of the `small` preset: `tiny`'s 720 at the coarsest scale, where the
/// layout forms (at 16^3 as cheap as `tiny`'s), then fewer where an iteration costs most (1.0 s
/// at 43^3, 2.3-2.5 s at 57^3 and 2.8-2.9 s for the upsampler at 216^2 on 2 Zen 3 cores), to
/// train within 12 minutes on 2 cores.
const SMALL_ITERATIONS: [usize; 5] = [720, 160, 120, 64, 40];

/// Iterations per scale of the `hd` preset: the coarsest scale's 720, where the layout forms
/// (at 16^3 as cheap as `tiny`'s), then fewer as an iteration grows dearer.
const HD_ITERATIONS: [usize; 8] = [720, 240, 200, 160, 100, 60, 40, 40];

/// The `hd` preset's 3D scales: volumes from [`CPU_COARSEST_VOLUME`] to the paper's finest
/// (126^3), renderings from 32^2 to the paper's finest (160^2, so final pictures of 320^2).
const HD_SCALES: usize = 7;
const HD_FINEST_VOLUME: usize = 126;
const HD_IMAGES: (usize, usize) = (32, 160);
const HD_SAMPLES: (usize, usize) = (48, 128);

/// Pixels of `hd`'s reconstruction per generator step, drawn over every view: as many as two
/// of its finest renderings hold (160^2), where its 8 reconstruction views would hold 204,800.
const HD_RECONSTRUCTION_PIXELS: usize = 2 * 160 * 160;

/// The edge `hd` fits its views at for its 3D critic, which judges only the coarsest 16^3
/// volumes: its fourth scale's, where a fit at the finest (126^3) would take several minutes.
const HD_FIT_SIZE: usize = 45;

/// Edge of the coarsest volume of `tiny` and `small`: the networks' 11-voxel fields (L = 5)
/// span 11/16 of it. `small` had 24^3 (11/24): with `tiny`'s 3D critic and 720 coarsest
/// iterations a quarter of the stones' matter still stood inside their ring (26.1%), at 16^3
/// 0.4-0.7% over three seeds, as in `tiny` (docs/journal/2026-12-arrangement.md).
const CPU_COARSEST_VOLUME: usize = 16;

/// The paper's table of training parameters (`tab:train_params`), first row (Stonehenge and
/// most scenes): views per step of generated scenes and of the reconstruction at its 6 scales.
const PAPER_VIEWS: [(usize, usize); 6] = [(6, 2), (6, 2), (6, 2), (5, 1), (2, 1), (2, 1)];
/// The same table's Island row, which also has L = 5 and 25^2 coarsest renderings.
const ISLAND_VIEWS: [(usize, usize); 6] = [(6, 2), (6, 2), (6, 2), (6, 1), (3, 1), (2, 1)];

/// Views of the reconstruction loss per generator step at the CPU presets' 3D scales (their
/// critics see 2): cheap next to the generator pass, and V*'s gradient less noisy.
const CPU_RECONSTRUCTION_VIEWS: usize = 8;

/// The CPU presets' reconstruction weights (colour, depth, opacity) are the paper's times this:
/// against the adversarial and colour-distribution terms, the reconstruction V* gained 2.2 dB
/// PSNR over three seeds.
const CPU_RECONSTRUCTION_WEIGHT: f64 = 5.0;

/// Weight of the CPU presets' height-profile loss of samples ([`Losses::height_profile`]); it
/// took the matter in the sky that the heavier reconstruction weights let in back out.
const CPU_HEIGHT_PROFILE: f64 = 50.0;

/// Learning rate of the CPU presets' reconstruction noise z*_n
/// ([`Noise::reconstruction_lr`]): over three seeds V*'s volume gained 0.5 dB on `tiny` and
/// 3.4 dB on `small`, and the samples' colour SWD fell 11% and 8%.
const CPU_RECONSTRUCTION_NOISE_LR: f64 = 0.05;

/// Weight of `tiny`'s binary-opacity prior of samples ([`Losses::opacity_binary`]), at every
/// 3D scale: over three seeds the samples' floaters fell 32% (lower at every seed); alone it
/// made their purple-tinted stones opaque at the finest 3D scale (colour SWD +12%), with
/// [`TINY_CHROMA`] they come out grey.
const TINY_OPACITY_BINARY: f64 = 3.0;

/// Weight of `tiny`'s chroma-distribution loss of samples ([`Losses::chroma_distribution`]):
/// with the binary-opacity prior at every 3D scale, over four seeds the samples' colour SWD
/// fell 10% (lower at every seed) and their purple pixels from 4-7% to 0.4-2.9%, the other
/// metrics within the seeds' spread.
const TINY_CHROMA: f64 = 100.0;

/// Weight of the CPU presets' 3D critic ([`Losses::volume_critic`]), measured on `tiny`, at
/// the coarsest scale only ([`CPU_VOLUME_CRITIC_UNTIL`]) and seeing each voxel as a ray from
/// above meets it ([`Critics::volume_seen_from_above`]). The coarsest scale makes the layout, and 2D critics of
/// 24^2 renderings let it go: without it a fifth to a quarter of the stones' matter stood inside
/// their ring, about 1% with it. Over three seeds of the stones, the islands and the mushrooms,
/// the samples' layout distance came to 0.89-1.47x that of other true layouts of each scene
/// (means 1.21x, 1.31x, 1.00x), with patch SWD-MV, colour SWD and floaters at or below those
/// without it (docs/journal/2026-12-arrangement.md).
const CPU_VOLUME_CRITIC: f64 = 0.3;

/// The last scale the CPU presets' 3D critic judges: the coarsest, where the layout is made.
const CPU_VOLUME_CRITIC_UNTIL: usize = 1;

/// Weight of the colour-distribution loss in every preset ([`Losses::colour_distribution`]).
const LAMBDA_COLOUR: f64 = 20.0;

/// Weight of the opacity reconstruction in every preset ([`Losses::opacity`]).
const LAMBDA_OPACITY: f64 = 10.0;

/// Density above which the upsampled coarser volume is matter, for the active set: a voxel of
/// this density at 28^3 in the model's `[-1, 1]^3` cube stops 0.7% of the light crossing it.
const SPARSE_THRESHOLD: f32 = 0.1;

/// Voxels of margin the active set adds around matter.
const SPARSE_MARGIN: usize = 2;

/// The first 3D scale on the active set in the presets: every scale with a coarser volume. On
/// `tiny` (three seeds) the active set with its shell from scale 2 matched the dense model on
/// every metric within the seeds' spread, and a generator step at the paper's 95^3 and 126^3
/// is 5.2x and 7.4x faster on it (docs/performance-patch-gan.md).
const SPARSE_FROM_SCALE: usize = 2;

/// The volume grows by 4/3 per scale.
const VOLUME_GROWTH: f64 = 4.0 / 3.0;
/// Renderings grow by 1.5 per scale.
const IMAGE_GROWTH: f64 = 1.5;

impl TrainConfig {
    /// The names [`TrainConfig::preset`] accepts.
    pub const PRESETS: [&'static str; 6] =
        ["paper", "paper-island", "hd", "small", "tiny", "micro"];

    /// A named preset:
    ///
    /// - `paper`: the paper's N = 6 (volumes 40..126, renderings 32..160, final 320^2), and its
    ///   table of training parameters for Stonehenge and most scenes: L = 7, 6, 6, 6, 5, 2, 2
    ///   generated and 2, 2, 2, 1, 1, 1 reconstruction views per step; 32 channels, 64 to 128
    ///   samples. Needs a GPU (see docs/training.md).
    /// - `paper-island`: the table's Island row: L = 5, renderings 25..160, 6, 6, 6, 6, 3, 2
    ///   generated views.
    /// - `hd`: the paper's resolution on a CPU: N = 8, volumes ramping from 16^3 to 126^3,
    ///   renderings from 32^2 to 160^2 (final 320^2), `small`'s recipe (16 channels, L = 5,
    ///   `tiny`'s training recipe, 3D critic of the coarsest volumes and post-activated
    ///   density) with a schedule of its own and its fit at 45^3.
    /// - `small`: N = 5, volumes 16, 32, 43, 57, renderings 32..108 (final 216^2), 16 channels,
    ///   `tiny`'s training recipe, 3D critic and post-activated density without its
    ///   binary-opacity prior, and a schedule of its own (fewest iterations at the costly fine
    ///   scales); 10 to 11 minutes of training on 2 CPU cores (an AMD EPYC Zen 3,
    ///   2026-12-04).
    /// - `tiny`: N = 4, volumes 16..28, renderings 24..54 (final 108^2), 16 channels, learning
    ///   rate 1e-3 (fewer iterations than the paper, so larger steps), reconstruction weights
    ///   5x the paper's, the samples' height profile, optimised reconstruction noise z*_n, the
    ///   binary-opacity prior with the chroma-distribution loss on its samples, and
    ///   post-activated density, and a 3D critic of the coarsest volumes as seen from above
    ///   (which needs a fit of the dataset's views, made first); 10 to 14 minutes of training
    ///   on 2 CPU cores (an Intel Xeon with AVX-512, 2026-12-02).
    /// - `micro`: N = 3, 8^3 and 11^3 volumes, for tests (seconds); dense finer scale.
    ///
    /// Every preset but `micro` runs its finer 3D scales on the active set, shell included
    /// (`active_set.from_scale` 2, `active_set.shell`; `--dense` for the paper's dense model).
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => Ok(paper()),
            "paper-island" => {
                let mut island = paper();
                island.preset = "paper-island".into();
                island.pyramid.layers = 5;
                island.pyramid.image_sizes = geometric(25, (160.0f64 / 25.0).powf(0.25), 5);
                island.schedule.scale_views = Some(table_views(&ISLAND_VIEWS));
                Ok(island)
            }
            "hd" => {
                let sizes = ramped(
                    "hd",
                    HD_SCALES,
                    (CPU_COARSEST_VOLUME, HD_FINEST_VOLUME),
                    HD_IMAGES,
                    HD_SAMPLES,
                );
                let mut hd = cpu_recipe(sizes, &HD_ITERATIONS);
                hd.pyramid.fit_size = Some(HD_FIT_SIZE);
                hd.schedule.reconstruction_pixels = Some(HD_RECONSTRUCTION_PIXELS);
                Ok(arranged_and_sharp(hd))
            }
            "small" => {
                let mut small = cpu_recipe(scaled("small", 5, 24, 32), &SMALL_ITERATIONS);
                small.pyramid.volume_sizes[0] = CPU_COARSEST_VOLUME;
                Ok(arranged_and_sharp(small))
            }
            "tiny" => {
                let tiny = cpu_recipe(scaled("tiny", 4, CPU_COARSEST_VOLUME, 24), &TINY_ITERATIONS);
                Ok(arranged_and_sharp(with_binary_opacity(tiny)))
            }
            "micro" => {
                let mut micro = scaled("micro", 3, 8, 12);
                micro.pyramid.layers = 3;
                micro.pyramid.channels = 4;
                micro.pyramid.upsampler_widths = [4, 4, 4, 4];
                micro.pyramid.samples = vec![16, 16];
                micro.schedule.scales = uniform_schedule(4, 3);
                micro.schedule.d_steps = 1;
                micro.schedule.g_steps = 1;
                micro.run.checkpoint_seconds = 0;
                // The paper's dense finer scale, so the tests that train `micro` cover it;
                // the active set has tests of its own.
                micro.active_set.from_scale = None;
                Ok(micro)
            }
            other => Err(invalid(
                "preset",
                format!(
                    "unknown preset `{other}`; expected one of {}",
                    Self::PRESETS.join(", ")
                ),
            )),
        }
    }
}

/// The paper's model and training, with the opacity and colour-distribution terms every preset
/// has and the active set.
fn paper() -> TrainConfig {
    TrainConfig {
        version: CONFIG_VERSION,
        preset: "paper".into(),
        pyramid: Pyramid {
            volume_sizes: vec![40, 53, 71, 95, 126],
            image_sizes: vec![32, 48, 72, 108, 160],
            samples: sample_ramp(64, 128, 5),
            layers: 7,
            channels: 32,
            upsampler_widths: [32, 16, 8, 8],
            fit_size: None,
        },
        schedule: Schedule {
            scales: uniform_schedule(2000, 6),
            d_steps: 3,
            g_steps: 3,
            views_per_step: 1,
            scale_views: Some(table_views(&PAPER_VIEWS)),
            learning_rate: 5e-4,
            betas: (0.9, 0.999),
            reconstruction_fit_steps: 0,
            reconstruction_pixels: None,
        },
        losses: Losses {
            rgb: 10.0,
            depth: 30.0,
            opacity: LAMBDA_OPACITY,
            swd: 1.0,
            swd_features: SwdFeatures::PatchPyramid,
            colour_distribution: LAMBDA_COLOUR,
            chroma_distribution: 0.0,
            height_profile: 0.0,
            opacity_binary: 0.0,
            fitted: 0.0,
            volume_critic: 0.0,
        },
        critics: Critics {
            gradient_penalty: 0.1,
            opacity: true,
            volume_colour: false,
            volume_until_scale: None,
            volume_seen_from_above: false,
            volume_positions: false,
        },
        rendering: Rendering {
            density_scale: 25.0,
            density_shift: -4.0,
            background: [1.0, 1.0, 1.0],
            post_activation: false,
        },
        active_set: ActiveSet {
            from_scale: Some(SPARSE_FROM_SCALE),
            threshold: SPARSE_THRESHOLD,
            margin: SPARSE_MARGIN,
            shell: true,
        },
        noise: Noise {
            amplitude_factor: 0.1,
            first_amplitude: 1.0,
            reconstruction_lr: 0.0,
        },
        ablations: Ablations {
            use_swd: true,
            use_csg: true,
            use_depth: true,
        },
        run: RunPolicy {
            seed: 0,
            holdout: None,
            checkpoint_seconds: 300,
            checkpoint_iterations: 0,
            bounds: None,
            depth_from_fit: false,
        },
    }
}

/// The paper's model at `scales` scales from a `volume`^3 volume and `image`^2 renderings, with
/// 5 layers, 16 channels and 4 views per step.
fn scaled(preset: &str, scales: usize, volume: usize, image: usize) -> TrainConfig {
    let mut config = paper();
    config.preset = preset.into();
    config.pyramid = Pyramid {
        volume_sizes: geometric(volume, VOLUME_GROWTH, scales - 1),
        image_sizes: geometric(image, IMAGE_GROWTH, scales - 1),
        samples: sample_ramp(48, 96, scales - 1),
        layers: 5,
        channels: 16,
        upsampler_widths: [16, 16, 8, 8],
        fit_size: None,
    };
    config.schedule.views_per_step = 4;
    config.schedule.scale_views = None;
    config
}

/// The paper's model as [`scaled`] makes it, at `scales` 3D scales whose volumes, renderings
/// and samples per ray run from the first to the last of each pair: volumes and renderings
/// geometrically ([`ramp`]), samples linearly.
fn ramped(
    preset: &str,
    scales: usize,
    volumes: (usize, usize),
    images: (usize, usize),
    samples: (usize, usize),
) -> TrainConfig {
    let mut config = scaled(preset, scales + 1, volumes.0, images.0);
    config.pyramid.volume_sizes = ramp(volumes.0, volumes.1, scales);
    config.pyramid.image_sizes = ramp(images.0, images.1, scales);
    config.pyramid.samples = sample_ramp(samples.0, samples.1, scales);
    config
}

/// The training recipe measured on `tiny`, for a CPU preset with the sizes of `sized` and
/// `iterations` per scale (a quarter of them reconstruction-only): learning rate 1e-3 (far
/// fewer iterations than the paper, so larger steps), reconstruction weights
/// [`CPU_RECONSTRUCTION_WEIGHT`] times the paper's with [`CPU_RECONSTRUCTION_VIEWS`] views per
/// generator step, 2 views for the critics, the samples' height profile, and optimised
/// reconstruction noise.
fn cpu_recipe(mut config: TrainConfig, iterations: &[usize]) -> TrainConfig {
    config.schedule.scales = iterations
        .iter()
        .map(|&n| ScaleSchedule::quarter_reconstruction(n))
        .collect();
    config.schedule.views_per_step = 2;
    config.schedule.learning_rate = 1e-3;
    config.run.checkpoint_seconds = 60;
    let losses = &mut config.losses;
    losses.rgb *= CPU_RECONSTRUCTION_WEIGHT;
    losses.depth *= CPU_RECONSTRUCTION_WEIGHT;
    losses.opacity *= CPU_RECONSTRUCTION_WEIGHT;
    losses.height_profile = CPU_HEIGHT_PROFILE;
    config.noise.reconstruction_lr = CPU_RECONSTRUCTION_NOISE_LR;
    config.with_reconstruction_views(CPU_RECONSTRUCTION_VIEWS)
}

/// `tiny`'s binary-opacity prior of samples with the chroma-distribution loss that keeps their
/// stones grey under it (`tiny` only: on `small` the prior cost colour, V* and diversity).
fn with_binary_opacity(mut config: TrainConfig) -> TrainConfig {
    config.losses.opacity_binary = TINY_OPACITY_BINARY;
    config.losses.chroma_distribution = TINY_CHROMA;
    config
}

/// The CPU presets' arrangement and sharpness: the 3D critic of the coarsest volumes as seen
/// from above (see [`CPU_VOLUME_CRITIC`]), and post-activated density, sharper edges than a
/// voxel (on `tiny` V* +2.8 dB, the samples' patches and colours closer on both scenes
/// measured).
fn arranged_and_sharp(mut config: TrainConfig) -> TrainConfig {
    config.rendering.post_activation = true;
    config.losses.volume_critic = CPU_VOLUME_CRITIC;
    config.critics.volume_until_scale = Some(CPU_VOLUME_CRITIC_UNTIL);
    config.critics.volume_seen_from_above = true;
    config
}

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

/// `count` sizes starting at `first`, each `growth` times the previous, rounded.
fn geometric(first: usize, growth: f64, count: usize) -> Vec<usize> {
    (0..count)
        .map(|i| (first as f64 * growth.powi(i as i32)).round() as usize)
        .collect()
}

/// `count` sizes from `first` to `last` (both included), each the same factor times the
/// previous, rounded.
fn ramp(first: usize, last: usize, count: usize) -> Vec<usize> {
    if count == 1 {
        return vec![last];
    }
    let growth = (last as f64 / first as f64).powf(1.0 / (count - 1) as f64);
    geometric(first, growth, count)
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

#[cfg(test)]
mod tests {
    use super::TrainConfig;
    use crate::config::ScaleViews;

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
            let pyramid = &config.pyramid;
            assert_eq!(pyramid.layers, layers, "{}", config.preset);
            assert_eq!((pyramid.volume_sizes[0], pyramid.image_sizes[0]), first);
            assert_eq!(
                (pyramid.volume_sizes[4], pyramid.image_sizes[4]),
                (126, 160)
            );
            assert_eq!(config.final_image_size(), 320);
            assert_eq!(views(config), per_scale_views, "{}", config.preset);
        }
        // The smaller presets keep their own layers and views.
        let tiny = TrainConfig::preset("tiny").unwrap();
        assert_eq!(tiny.pyramid.layers, 5);
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
    fn tinys_3d_critic_judges_only_the_coarsest_volumes_as_seen_from_above() {
        let tiny = TrainConfig::preset("tiny").unwrap();
        tiny.validate().unwrap();
        assert_eq!(tiny.losses.volume_critic, 0.3);
        assert_eq!(tiny.critics.volume_until_scale, Some(1));
        assert!(tiny.critics.volume_seen_from_above && !tiny.critics.volume_colour);
        // The paper has 2D critics only, and the tests' `micro` trains without a fit.
        for name in ["paper", "paper-island", "micro"] {
            let config = TrainConfig::preset(name).unwrap();
            assert_eq!(config.losses.volume_critic, 0.0, "{name}");
        }
    }

    #[test]
    fn hd_has_the_papers_finest_sizes_on_ramps_and_smalls_recipe() {
        let (hd, small) = (
            TrainConfig::preset("hd").unwrap(),
            TrainConfig::preset("small").unwrap(),
        );
        hd.validate().unwrap();
        assert_eq!(hd.pyramid.volume_sizes, [16, 23, 32, 45, 63, 89, 126]);
        assert_eq!(hd.pyramid.image_sizes, [32, 42, 55, 72, 94, 122, 160]);
        assert_eq!(hd.pyramid.samples, [48, 61, 74, 88, 101, 114, 128]);
        assert_eq!(hd.final_image_size(), 320);
        assert_eq!(hd.scales(), 8);
        // Each size the previous one times a constant factor, rounded.
        for sizes in [&hd.pyramid.volume_sizes, &hd.pyramid.image_sizes] {
            let growth = (*sizes.last().unwrap() as f64 / sizes[0] as f64).powf(1.0 / 6.0);
            for (i, &size) in sizes.iter().enumerate() {
                let exact = sizes[0] as f64 * growth.powi(i as i32);
                assert!((size as f64 - exact).abs() <= 0.5, "{sizes:?}");
            }
        }
        let iterations: Vec<_> = hd.schedule.scales.iter().map(|s| s.iterations).collect();
        assert_eq!(iterations, [720, 240, 200, 160, 100, 60, 40, 40]);
        assert!(hd
            .schedule
            .scales
            .iter()
            .all(|s| s.reconstruction_only * 4 == s.iterations));
        assert_eq!(hd.pyramid.fit_size, Some(45));
        assert_eq!(hd.fit_config().size, 45);
        assert_eq!(hd.schedule.reconstruction_pixels, Some(51_200));
        // small's recipe: everything but the sizes, the schedule, the fit's size and the
        // reconstruction's pixels.
        let mut resized = hd.clone();
        resized.preset = small.preset.clone();
        resized.pyramid = small.pyramid.clone();
        resized.schedule.scales = small.schedule.scales.clone();
        resized.schedule.scale_views = small.schedule.scale_views.clone();
        resized.schedule.reconstruction_pixels = None;
        assert_eq!(resized, small);
    }

    #[test]
    fn small_is_tinys_recipe_at_its_own_sizes_without_the_binary_opacity_prior() {
        let (tiny, small) = (
            TrainConfig::preset("tiny").unwrap(),
            TrainConfig::preset("small").unwrap(),
        );
        small.validate().unwrap();
        // The coarsest volume at tiny's 16^3, where the layout forms, then the 4/3 ramp to 57^3.
        assert_eq!(small.pyramid.volume_sizes, [16, 32, 43, 57]);
        assert_eq!(small.pyramid.image_sizes, [32, 48, 72, 108]);
        assert_eq!(small.final_image_size(), 216);
        let iterations: Vec<_> = small.schedule.scales.iter().map(|s| s.iterations).collect();
        assert_eq!(iterations, [720, 160, 120, 64, 40]);
        assert!(small
            .schedule
            .scales
            .iter()
            .all(|s| s.reconstruction_only * 4 == s.iterations));
        // Everything but the sizes, the schedule and the binary-opacity prior with its chroma
        // loss (which cost small colour, V* and diversity) is tiny's: the 3D critic of the
        // layout and the post-activated density included.
        assert_eq!(small.losses.opacity_binary, 0.0);
        assert_eq!(small.losses.chroma_distribution, 0.0);
        assert!(small.rendering.post_activation);
        assert_eq!(small.losses.volume_critic, 0.3);
        let mut resized = small.clone();
        resized.losses.opacity_binary = tiny.losses.opacity_binary;
        resized.losses.chroma_distribution = tiny.losses.chroma_distribution;
        resized.preset = tiny.preset.clone();
        resized.pyramid.volume_sizes = tiny.pyramid.volume_sizes.clone();
        resized.pyramid.image_sizes = tiny.pyramid.image_sizes.clone();
        resized.pyramid.samples = tiny.pyramid.samples.clone();
        resized.schedule.scales = tiny.schedule.scales.clone();
        resized.schedule.scale_views = tiny.schedule.scale_views.clone();
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
