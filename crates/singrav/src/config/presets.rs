//! The named presets as data: one table of names and what each is for ([`TABLE`]), and per
//! preset one function that lists its values, built on the paper's model ([`paper`]) or on the
//! CPU recipe ([`cpu`]), each value that is not the paper's with one line saying why. The
//! measurements behind those lines are in docs/journal/ (training quality, training speed,
//! arrangement); tuning a preset is a change to its function alone.

use super::schedule::uniform_schedule;
use super::{
    Ablations, ActiveSet, Critics, Losses, Noise, Pyramid, Rendering, RunPolicy, ScaleSchedule,
    ScaleViews, Schedule, SwdFeatures, TrainConfig, CONFIG_VERSION,
};
use crate::error::{invalid, Result};

/// A named preset.
struct Preset {
    /// What `--preset` takes.
    name: &'static str,
    /// What it is for, in one line (`volgen train --preset`'s help).
    about: &'static str,
    /// Its configuration.
    make: fn() -> TrainConfig,
}

/// Every preset, the paper's first.
const TABLE: [Preset; 6] = [
    Preset {
        name: "paper",
        about: "the paper's model and training parameters (N = 6, final 320^2); needs a GPU",
        make: paper,
    },
    Preset {
        name: "paper-island",
        about: "the paper's Island row: L = 5, renderings from 25^2; needs a GPU",
        make: paper_island,
    },
    Preset {
        name: "hd",
        about: "the paper's sizes (volumes to 126^3, final 320^2) on the CPU recipe",
        make: hd,
    },
    Preset {
        name: "small",
        about: "the CPU recipe at 216^2 (volumes to 57^3); about 11 minutes on 2 cores",
        make: small,
    },
    Preset {
        name: "tiny",
        about: "the demo's: the CPU recipe at 108^2 (volumes to 28^3); about 10 minutes on 2 cores",
        make: tiny,
    },
    Preset {
        name: "micro",
        about: "for tests: 8^3 and 11^3 volumes, 4 iterations per scale; seconds",
        make: micro,
    },
];

impl TrainConfig {
    /// The names [`TrainConfig::preset`] accepts, the paper's first.
    pub const PRESETS: [&'static str; TABLE.len()] = {
        let mut names = [""; TABLE.len()];
        let mut i = 0;
        while i < TABLE.len() {
            names[i] = TABLE[i].name;
            i += 1;
        }
        names
    };

    /// A named preset, one of [`TrainConfig::PRESETS`] ([`TrainConfig::preset_about`] says
    /// what each is for; docs/training.md has their sizes side by side). Every preset but
    /// `micro` runs its finer 3D scales on the active set, shell included.
    ///
    /// ```
    /// let tiny = singrav::TrainConfig::preset("tiny")?;
    /// assert_eq!(tiny.pyramid.volume_sizes, [16, 21, 28]);
    /// assert!(singrav::TrainConfig::preset("huge").is_err());
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn preset(name: &str) -> Result<Self> {
        match TABLE.iter().find(|preset| preset.name == name) {
            Some(preset) => Ok((preset.make)()),
            None => Err(invalid(
                "preset",
                format!(
                    "unknown preset `{name}`; expected one of {}",
                    Self::PRESETS.join(", ")
                ),
            )),
        }
    }

    /// What preset `name` is for, in one line.
    ///
    /// ```
    /// let about = singrav::TrainConfig::preset_about("paper").unwrap();
    /// assert!(about.contains("GPU"));
    /// ```
    pub fn preset_about(name: &str) -> Option<&'static str> {
        TABLE
            .iter()
            .find(|preset| preset.name == name)
            .map(|preset| preset.about)
    }
}

/// The paper's model and training, the first row of its table of training parameters
/// (supplementary, `tab:train_params`: Stonehenge and most scenes), with the opacity and
/// colour-distribution terms every preset has and the active set.
fn paper() -> TrainConfig {
    TrainConfig {
        version: CONFIG_VERSION,
        preset: "paper".into(),
        pyramid: Pyramid {
            volume_sizes: vec![40, 53, 71, 95, 126],
            image_sizes: vec![32, 48, 72, 108, 160],
            samples: vec![64, 80, 96, 112, 128],
            layers: 7,
            channels: 32,
            upsampler_widths: [32, 16, 8, 8],
            fit_size: None,
        },
        schedule: Schedule {
            // The paper trains 80 epochs per scale; a guess at the same order of updates.
            scales: uniform_schedule(2000, 6),
            d_steps: 3,
            g_steps: 3,
            views_per_step: 1,
            scale_views: Some(table_views(&[
                (6, 2),
                (6, 2),
                (6, 2),
                (5, 1),
                (2, 1),
                (2, 1),
            ])),
            learning_rate: 5e-4,
            betas: (0.9, 0.999),
            reconstruction_fit_steps: 0,
            reconstruction_pixels: None,
        },
        losses: Losses {
            rgb: 10.0,
            depth: 30.0,
            // Alpha tells a grey stone from a see-through purple one; colour alone cannot.
            opacity: 10.0,
            swd: 1.0,
            swd_features: SwdFeatures::PatchPyramid,
            // The critics' small fields learnt the samples' colours slowly.
            colour_distribution: 20.0,
            ..Losses::default()
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
        // Finer scales only near matter (and its shell): the dense model's metrics on `tiny`,
        // 5-7x faster steps at the paper's sizes.
        active_set: ActiveSet {
            from_scale: Some(2),
            // A 28^3 voxel of this density stops 0.7% of the light crossing it.
            threshold: 0.1,
            margin: 2,
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

/// The paper's table's Island row.
fn paper_island() -> TrainConfig {
    let mut island = paper();
    island.preset = "paper-island".into();
    island.pyramid.layers = 5;
    island.pyramid.image_sizes = vec![25, 40, 63, 101, 160];
    island.schedule.scale_views = Some(table_views(&[
        (6, 2),
        (6, 2),
        (6, 2),
        (6, 1),
        (3, 1),
        (2, 1),
    ]));
    island
}

/// The paper's sizes on the CPU recipe: volumes 16^3 (where the layout forms) to 126^3,
/// renderings 32^2 to 160^2, each a constant factor times the last.
fn hd() -> TrainConfig {
    let mut hd = cpu(
        "hd",
        Sizes {
            volumes: &[16, 23, 32, 45, 63, 89, 126],
            images: &[32, 42, 55, 72, 94, 122, 160],
            samples: &[48, 61, 74, 88, 101, 114, 128],
        },
        // The coarsest scale's 720, then fewer as an iteration grows dearer.
        &[720, 240, 200, 160, 100, 60, 40, 40],
    );
    // The 3D critic judges the 16^3 volumes only: no need to fit the views at 126^3.
    hd.pyramid.fit_size = Some(45);
    // As many pixels as two of its finest renderings: 8 views of them would hold 204,800.
    hd.schedule.reconstruction_pixels = Some(2 * 160 * 160);
    // Matches the samples' tints to the views': greyer stones, and so a layout distance 0.83x
    // hd's without it over three seeds (the binary-opacity prior stays off: at this size it
    // joins neighbouring stones).
    hd.losses.chroma_distribution = 100.0;
    // The colour and chroma distributions compared per cell of a 2 x 2 grid over each view keep
    // the ground's colour patches in their places: the layout distance 1.12x the true layouts'
    // where it was 1.31x (seed 0, the stones' first layout), 1.25x where it was 1.47x (seed 2),
    // the matter where it stood and every other goal held.
    hd.losses.colour_grid = Some(2);
    hd
}

/// The CPU recipe at 216^2.
fn small() -> TrainConfig {
    cpu(
        "small",
        Sizes {
            // 16^3 as `tiny`'s, where the layout forms (at 24^3 it was lost), then 4/3 per
            // scale from 24^3.
            volumes: &[16, 32, 43, 57],
            images: &[32, 48, 72, 108],
            samples: &[48, 64, 80, 96],
        },
        // `tiny`'s 720 where the layout forms, fewer where an iteration costs most.
        &[720, 160, 120, 64, 40],
    )
}

/// The CPU recipe at 108^2, with the binary-opacity prior and the chroma loss that keeps its
/// stones grey under it (on `small` the prior cost colour, V* and diversity).
fn tiny() -> TrainConfig {
    let mut tiny = cpu(
        "tiny",
        Sizes {
            volumes: &[16, 21, 28],
            images: &[24, 36, 54],
            samples: &[48, 72, 96],
        },
        // The coarsest scale, cheap, forms the layout; the finer 3D ones sharpen V* most.
        &[720, 480, 480, 80],
    );
    // Half-transparent smudges of the samples turn clear or opaque: fewer floaters.
    tiny.losses.opacity_binary = 3.0;
    // Matches the samples' tints to the views': no purple stones under the prior.
    tiny.losses.chroma_distribution = 100.0;
    tiny
}

/// The paper's model at 8^3 and 11^3 for tests: seconds; its dense finer scale keeps the dense
/// path tested (the active set has tests of its own).
fn micro() -> TrainConfig {
    let mut micro = paper();
    micro.preset = "micro".into();
    micro.pyramid = Pyramid {
        volume_sizes: vec![8, 11],
        image_sizes: vec![12, 18],
        samples: vec![16, 16],
        layers: 3,
        channels: 4,
        upsampler_widths: [4, 4, 4, 4],
        fit_size: None,
    };
    micro.schedule.scales = uniform_schedule(4, 3);
    micro.schedule.views_per_step = 4;
    micro.schedule.scale_views = None;
    micro.schedule.d_steps = 1;
    micro.schedule.g_steps = 1;
    micro.run.checkpoint_seconds = 0;
    micro.active_set.from_scale = None;
    micro
}

/// A CPU preset's sizes per 3D scale, coarsest first.
struct Sizes {
    volumes: &'static [usize],
    images: &'static [usize],
    samples: &'static [usize],
}

/// The CPU recipe, measured on `tiny` and kept by `small` and `hd`: the paper's model at
/// `sizes` with 5 layers and 16 channels, `iterations` per scale (a quarter of them
/// reconstruction-only), and these changes.
fn cpu(preset: &str, sizes: Sizes, iterations: &[usize]) -> TrainConfig {
    let mut c = paper();
    c.preset = preset.into();
    c.pyramid = Pyramid {
        volume_sizes: sizes.volumes.to_vec(),
        image_sizes: sizes.images.to_vec(),
        samples: sizes.samples.to_vec(),
        // An 11-voxel field: 11/16 of the coarsest volume.
        layers: 5,
        channels: 16,
        upsampler_widths: [16, 16, 8, 8],
        fit_size: None,
    };
    c.schedule.scales = iterations
        .iter()
        .map(|&n| ScaleSchedule::quarter_reconstruction(n))
        .collect();
    // Far fewer iterations than the paper: larger steps.
    c.schedule.learning_rate = 1e-3;
    // Critics see 2 views per step, the reconstruction 8 (set below): cheap next to the
    // generator pass, and V*'s gradient less noisy.
    c.schedule.views_per_step = 2;
    c.schedule.scale_views = None;
    c.run.checkpoint_seconds = 60;
    let losses = &mut c.losses;
    // 5x the paper's reconstruction weights: V* +2.2 dB against the adversarial terms.
    losses.rgb = 50.0;
    losses.depth = 150.0;
    losses.opacity = 50.0;
    // Takes back out of the sky the matter the heavier reconstruction lets in.
    losses.height_profile = 50.0;
    // The 3D critic of the coarsest volumes as a ray from above meets them keeps the scene's
    // layout (the stones' ring), which the 2D critics let go.
    losses.volume_critic = 0.3;
    c.critics.volume_until_scale = Some(1);
    c.critics.volume_seen_from_above = true;
    // Optimised reconstruction noise z*_n: V* +0.5 dB on `tiny`, +3.4 dB on `small`.
    c.noise.reconstruction_lr = 0.05;
    // Post-activated density, edges sharper than a voxel: V* +2.8 dB on `tiny`.
    c.rendering.post_activation = true;
    c.with_reconstruction_views(8)
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

#[cfg(test)]
mod tests {
    use super::TrainConfig;
    use crate::config::ScaleViews;

    /// `count` sizes from `first`, each `growth` times the last, rounded.
    fn geometric(first: f64, growth: f64, count: usize) -> Vec<usize> {
        (0..count)
            .map(|i| (first * growth.powi(i as i32)).round() as usize)
            .collect()
    }

    /// The sizes are the ramps the presets' lines say: volumes 4/3 and renderings 1.5 times
    /// the last (the paper's theta and its rendering growth), samples per ray linear.
    #[test]
    fn every_presets_sizes_are_the_ramps_it_says() {
        for name in ["paper", "tiny", "micro"] {
            let pyramid = TrainConfig::preset(name).unwrap().pyramid;
            let n = pyramid.volume_sizes.len();
            let (volume, image) = (pyramid.volume_sizes[0], pyramid.image_sizes[0]);
            assert_eq!(
                pyramid.volume_sizes,
                geometric(volume as f64, 4.0 / 3.0, n),
                "{name}"
            );
            // The paper's table ends its renderings at 160^2, where the ramp reaches 162.
            let mut ramp = geometric(image as f64, 1.5, n);
            if name == "paper" {
                ramp[n - 1] = 160;
            }
            assert_eq!(pyramid.image_sizes, ramp, "{name}");
        }
        // `small`: `tiny`'s 16^3 first, then the 4/3 ramp from 24^3.
        let small = TrainConfig::preset("small").unwrap().pyramid;
        assert_eq!(small.volume_sizes[0], 16);
        assert_eq!(small.volume_sizes[1..], geometric(24.0, 4.0 / 3.0, 4)[1..]);
        assert_eq!(small.image_sizes, geometric(32.0, 1.5, 4));
        // The Island row: 25^2 to the paper's 160^2 by a constant factor.
        let island = TrainConfig::preset("paper-island").unwrap().pyramid;
        assert_eq!(
            island.image_sizes,
            geometric(25.0, (160.0f64 / 25.0).powf(0.25), 5)
        );
        for name in TrainConfig::PRESETS {
            let samples = TrainConfig::preset(name).unwrap().pyramid.samples;
            let (first, last, n) = (samples[0], samples[samples.len() - 1], samples.len());
            let linear: Vec<usize> = (0..n)
                .map(|i| first + (last - first) * i / (n - 1).max(1))
                .collect();
            assert_eq!(samples, linear, "{name}");
            assert!(TrainConfig::preset_about(name).is_some_and(|a| !a.is_empty()));
        }
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
        assert_eq!(hd.losses.chroma_distribution, 100.0);
        assert_eq!(hd.losses.opacity_binary, 0.0);
        assert_eq!(hd.losses.colour_grid, Some(2));
        // hd as it was before the grid, as docs/training.md compares it.
        let whole_views = hd
            .clone()
            .with_setting("losses.colour_grid", "null")
            .unwrap();
        assert_eq!(whole_views.losses.colour_grid, None);
        // small's recipe: everything but the sizes, the schedule, the fit's size, the
        // reconstruction's pixels, the chroma loss and the colour grid.
        let mut resized = hd.clone();
        resized.preset = small.preset.clone();
        resized.pyramid = small.pyramid.clone();
        resized.schedule.scales = small.schedule.scales.clone();
        resized.schedule.scale_views = small.schedule.scale_views.clone();
        resized.schedule.reconstruction_pixels = None;
        resized.losses.chroma_distribution = small.losses.chroma_distribution;
        resized.losses.colour_grid = small.losses.colour_grid;
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
