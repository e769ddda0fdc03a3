//! Training with the `micro` preset: finite losses, falling reconstruction, reproducibility,
//! and a killed-then-resumed run ending with the same weights as an uninterrupted one.
//!
//! Longer than the project's ~800 lines on purpose: every training test shares the dataset and
//! run helpers below, and one file is one test binary that links candle once.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use rand::{Rng, SeedableRng};
use rgbd_dataset::scenes::StandingStones;
use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
use singrav::checkpoint::Checkpoint;
use singrav::model::RECONSTRUCTION_DETAIL_TENSOR;
use singrav::train::{
    train, Control, Event, LossTerm, Progress, RunOptions, StepLosses, TrainOutcome,
};
use singrav::{Error, RunDir, ScaleSchedule, SinGrav, SwdFeatures, TrainConfig};
use volume_fit::fit_volume;

/// A small dataset of the stones scene at the micro preset's final resolution.
fn dataset(dir: &Path) -> Dataset {
    let spec = DatasetSpec {
        views: 6,
        resolution: 36,
        grid: 32,
        seed: 3,
    };
    write_dataset(&StandingStones::new(1), dir, &spec).unwrap();
    Dataset::load(dir, [1.0; 3]).unwrap()
}

fn resume() -> RunOptions {
    RunOptions {
        resume: true,
        ..RunOptions::default()
    }
}

fn micro() -> TrainConfig {
    TrainConfig::preset("micro").unwrap()
}

/// Trains to the end, collecting every step's losses.
fn run_to_end(
    config: &TrainConfig,
    data: &Dataset,
    dir: &Path,
) -> (SinGrav, Vec<(usize, StepLosses)>) {
    run_with(config, data, dir, &RunOptions::default())
}

/// [`run_to_end`] with run options.
fn run_with(
    config: &TrainConfig,
    data: &Dataset,
    dir: &Path,
    options: &RunOptions,
) -> (SinGrav, Vec<(usize, StepLosses)>) {
    let mut steps = Vec::new();
    let mut observer = |p: &Progress| {
        if p.event == Event::Step {
            steps.push((p.scale, p.losses));
        }
        Control::Continue
    };
    match train(config, data, dir, options, &Device::Cpu, &mut observer).unwrap() {
        TrainOutcome::Finished(model) => (*model, steps),
        TrainOutcome::Stopped => panic!("nobody asked to stop"),
    }
}

fn checkpoint_tensors(dir: &Path) -> HashMap<String, Tensor> {
    Checkpoint::load(&RunDir::new(dir).checkpoint(), &Device::Cpu)
        .unwrap()
        .tensors
}

fn assert_same_tensors(a: &HashMap<String, Tensor>, b: &HashMap<String, Tensor>) {
    let mut names: Vec<_> = a.keys().collect();
    names.sort();
    let mut other: Vec<_> = b.keys().collect();
    other.sort();
    assert_eq!(names, other);
    for name in names {
        let x: Vec<f32> = a[name].flatten_all().unwrap().to_vec1().unwrap();
        let y: Vec<f32> = b[name].flatten_all().unwrap().to_vec1().unwrap();
        assert!(
            x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits()),
            "tensor {name} differs"
        );
    }
}

/// An observer that stops the run after `iteration` iterations of `scale`, as a kill would.
fn stop_at(scale: usize, iteration: usize) -> impl FnMut(&Progress) -> Control {
    move |p: &Progress| {
        if p.scale == scale && p.iteration == iteration {
            Control::Stop
        } else {
            Control::Continue
        }
    }
}

/// Trains `config` into `dir` until `stop` stops it, as a kill would.
fn run_until_stopped(
    config: &TrainConfig,
    data: &Dataset,
    dir: &Path,
    stop: &mut dyn FnMut(&Progress) -> Control,
) {
    let outcome = train(
        config,
        data,
        dir,
        &RunOptions::default(),
        &Device::Cpu,
        stop,
    )
    .unwrap();
    assert!(matches!(outcome, TrainOutcome::Stopped));
}

/// Trains `config` into `dir` until it is killed in scale 2 after iteration 3 (its checkpoint
/// every 2 iterations then holds iteration 2), asserts that checkpoint holds a tensor named
/// `saved_prefix*`, resumes, and asserts the run ends with the tensors `finished`.
fn killed_in_scale_2_resumes_to(
    config: &TrainConfig,
    data: &Dataset,
    dir: &Path,
    saved_prefix: &str,
    finished: &HashMap<String, Tensor>,
) {
    run_until_stopped(config, data, dir, &mut stop_at(2, 3));
    assert!(checkpoint_tensors(dir)
        .keys()
        .any(|name| name.starts_with(saved_prefix)));
    run_with(config, data, dir, &resume());
    assert_same_tensors(finished, &checkpoint_tensors(dir));
}

/// The error of a training run that must fail.
fn train_failure(config: &TrainConfig, data: &Dataset, run: &Path, options: &RunOptions) -> Error {
    train(config, data, run, options, &Device::Cpu, &mut |_| {
        Control::Continue
    })
    .err()
    .expect("training should have failed")
}

/// The message of a training run that must fail before or during its first step.
fn train_error(config: &TrainConfig, data: &Dataset, run: &Path, options: &RunOptions) -> String {
    train_failure(config, data, run, options).to_string()
}

#[test]
fn micro_run_has_finite_losses_pictures_and_a_sampleable_model() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    // Every optional term and the active set on, so that each runs once.
    let mut config = micro();
    config.losses.chroma_distribution = 1.0;
    config.losses.height_profile = 1.0;
    config.losses.opacity_binary = 1.0;
    config.active_set.from_scale = Some(2);
    config.active_set.shell = true;
    let run = tmp.path().join("run");
    let (model, steps) = run_to_end(&config, &data, &run);
    assert_eq!(steps.len(), config.total_iterations());
    for (scale, l) in &steps {
        let terms = [
            l.get(LossTerm::Critic),
            l.get(LossTerm::Penalty),
            l.get(LossTerm::Adversarial),
            l.get(LossTerm::Rgb),
            l.get(LossTerm::Depth),
            l.get(LossTerm::Swd),
            l.get(LossTerm::Opacity),
            l.get(LossTerm::ColourDistribution),
            l.get(LossTerm::ChromaDistribution),
            l.get(LossTerm::HeightProfile),
            l.get(LossTerm::OpacityBinary),
        ];
        assert!(
            terms.iter().flatten().all(|v| v.is_finite()),
            "scale {scale}: {l:?}"
        );
        // The opacity reconstruction is a term of the 3D scales only.
        assert_eq!(
            l.get(LossTerm::Opacity).is_some(),
            *scale < config.scales(),
            "scale {scale}"
        );
        // The colour distribution of generated scenes: the 3D scales' adversarial iterations.
        let compared = *scale < config.scales()
            && l.get(LossTerm::Adversarial).is_some()
            && config.losses.colour_distribution > 0.0;
        assert_eq!(
            l.get(LossTerm::ColourDistribution).is_some(),
            compared,
            "scale {scale}"
        );
        let on_samples = *scale < config.scales() && l.get(LossTerm::Adversarial).is_some();
        for term in [
            l.get(LossTerm::ChromaDistribution),
            l.get(LossTerm::HeightProfile),
            l.get(LossTerm::OpacityBinary),
        ] {
            assert_eq!(term.is_some(), on_samples, "scale {scale}: {l:?}");
        }
    }
    // Adversarial terms appear after the reconstruction-only iterations; SWD only at the end.
    assert!(steps
        .iter()
        .any(|(s, l)| *s == 3 && l.get(LossTerm::Swd).is_some()));
    assert!(steps
        .iter()
        .all(|(s, l)| *s == 3 || l.get(LossTerm::Swd).is_none()));
    for n in 1..=config.scales() {
        let png = image::open(run.join("samples").join(format!("scale_{n}.png"))).unwrap();
        assert!(png.width() > png.height());
    }
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), steps.len());

    let cams = model.showcase_cameras(2).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let sample = model.sample(&mut rng, &cams).unwrap();
    let size = config.pyramid.volume_sizes[1];
    assert_eq!(sample.volume.tensor().dims(), &[4, size, size, size]);
    assert_eq!(
        sample.views.dims(),
        &[2, 3, config.final_image_size(), config.final_image_size()]
    );
    let (loaded, state) = SinGrav::load(&run, &Device::Cpu).unwrap();
    assert!(state.finished(&config));
    let again = loaded
        .sample(&mut rand_chacha::ChaCha8Rng::seed_from_u64(5), &cams)
        .unwrap();
    let a: Vec<f32> = sample
        .volume
        .tensor()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    let b: Vec<f32> = again
        .volume
        .tensor()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    assert_eq!(a, b, "a loaded model samples what the trained one does");
}

/// Trains `micro`'s first two scales 16 reconstruction-only iterations each (changed by
/// `change`) and checks that scale 1's colour, depth and opacity losses fall by a fifth.
fn assert_reconstruction_falls(change: impl FnOnce(&mut TrainConfig)) {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro()
        .with(|c| {
            c.schedule.g_steps = 2;
        })
        .with_scales(2)
        .unwrap();
    let config = config.with(|c| {
        c.schedule.scales = vec![
            ScaleSchedule {
                iterations: 16,
                reconstruction_only: 16
            };
            2
        ];
        change(c);
    });
    let (_, steps) = run_to_end(&config, &data, &tmp.path().join("run"));
    let colour: Vec<f32> = steps
        .iter()
        .filter(|(s, _)| *s == 1)
        .map(|(_, l)| l.get(LossTerm::Rgb).unwrap())
        .collect();
    let depth: Vec<f32> = steps
        .iter()
        .filter(|(s, _)| *s == 1)
        .map(|(_, l)| l.get(LossTerm::Depth).unwrap())
        .collect();
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    assert!(
        mean(&colour[12..]) < 0.8 * mean(&colour[..4]),
        "colour {colour:?}"
    );
    assert!(
        mean(&depth[12..]) < 0.8 * mean(&depth[..4]),
        "depth {depth:?}"
    );
    let opacity: Vec<f32> = steps
        .iter()
        .filter(|(s, _)| *s == 1)
        .map(|(_, l)| l.get(LossTerm::Opacity).unwrap())
        .collect();
    assert!(
        mean(&opacity[12..]) < 0.8 * mean(&opacity[..4]),
        "opacity {opacity:?}"
    );
}

#[test]
fn reconstruction_loss_falls() {
    assert_reconstruction_falls(|_| {});
}

#[test]
fn reconstruction_loss_falls_on_random_pixels_too() {
    // Micro's 4 views of 12^2 pixels per step: 576; these steps render 150 random ones of
    // all 6 views' pixels.
    assert_reconstruction_falls(|c| c.schedule.reconstruction_pixels = Some(150));
}

#[test]
fn same_seed_same_weights_other_seed_other_weights() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro().with_scales(2).unwrap();
    run_to_end(&config, &data, &tmp.path().join("a"));
    run_to_end(&config, &data, &tmp.path().join("b"));
    let a = checkpoint_tensors(&tmp.path().join("a"));
    assert_same_tensors(&a, &checkpoint_tensors(&tmp.path().join("b")));
    let other = config.with(|c| {
        c.run.seed = 9;
    });
    run_to_end(&other, &data, &tmp.path().join("c"));
    let c = checkpoint_tensors(&tmp.path().join("c"));
    let differs = |name: &str| {
        let x: Vec<f32> = a[name].flatten_all().unwrap().to_vec1().unwrap();
        let y: Vec<f32> = c[name].flatten_all().unwrap().to_vec1().unwrap();
        x != y
    };
    assert!(differs("z_star") && differs("g1.tail.weight"));
}

#[test]
fn a_run_that_compares_with_a_fitted_volume_and_has_none_fits_one_first() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro().with_scales(2).unwrap().with(|c| {
        c.losses.fitted = 1.0;
        c.rendering.post_activation = true;
    });
    let run = tmp.path().join("run");
    let (_, steps) = run_to_end(&config, &data, &run);
    let three_d = config.pyramid.volume_sizes.len();
    assert!(steps
        .iter()
        .all(|(n, losses)| losses.get(LossTerm::Fitted).is_some() == (*n <= three_d)));
    // The run's copy is the fit `TrainConfig::fit_config` describes: post-activated, so on the
    // finest 3D scale's own grid.
    let copy =
        radiance_volume::RadianceVolume::load_safetensors(run.join("fitted.safetensors")).unwrap();
    let fit_config = config.fit_config();
    assert_eq!(
        fit_config.size,
        *config.pyramid.volume_sizes.last().unwrap()
    );
    let all: Vec<usize> = (0..data.len()).collect();
    let direct = fit_volume(&data, &all, &fit_config, &mut |_| {}).unwrap();
    assert_eq!(copy.dims(), direct.volume.dims());
    assert_eq!(
        largest_difference(copy.tensor(), direct.volume.tensor()),
        0.0
    );
}

#[test]
fn a_holdout_run_trains_exactly_as_a_run_on_the_training_views_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let plain = micro().with_scales(2).unwrap();
    let held = plain.clone().with(|c| {
        c.run.holdout = Some(3);
    });
    run_to_end(&held, &data, &tmp.path().join("held"));
    // Frames 0 and 3 are held out: the run sees frames 1, 2, 4 and 5 only.
    let training = data.subset(&[1, 2, 4, 5]).unwrap();
    run_to_end(&plain, &training, &tmp.path().join("subset"));
    assert_same_tensors(
        &checkpoint_tensors(&tmp.path().join("held")),
        &checkpoint_tensors(&tmp.path().join("subset")),
    );
    let recorded = Checkpoint::load(
        &RunDir::new(tmp.path().join("held")).checkpoint(),
        &Device::Cpu,
    )
    .unwrap()
    .config;
    assert_eq!(recorded.run.holdout, Some(3));
    let bad = plain.with(|c| {
        c.run.holdout = Some(1);
    });
    let err = bad.validate().unwrap_err().to_string();
    assert!(err.contains("holdout") && err.contains("got 1"), "{err}");
}

#[test]
fn killed_and_resumed_run_ends_with_the_uninterrupted_weights() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro().with(|c| {
        c.run.checkpoint_iterations = 2;
    });
    run_to_end(&config, &data, &tmp.path().join("whole"));

    // Killed in scale 2 after iteration 3: the last checkpoint is from iteration 2.
    let killed = tmp.path().join("killed");
    let mut stop = stop_at(2, 3);
    let outcome = train(
        &config,
        &data,
        &killed,
        &RunOptions::default(),
        &Device::Cpu,
        &mut stop,
    )
    .unwrap();
    assert!(matches!(outcome, TrainOutcome::Stopped));
    let state = Checkpoint::load(&RunDir::new(&killed).checkpoint(), &Device::Cpu)
        .unwrap()
        .state;
    assert_eq!((state.scale, state.iteration), (2, 2));

    // Without --resume the run directory is refused rather than overwritten.
    let err = train(
        &config,
        &data,
        &killed,
        &RunOptions::default(),
        &Device::Cpu,
        &mut |_| Control::Continue,
    );
    assert!(matches!(err, Err(Error::Checkpoint { .. })));

    let resumed = train(
        &config,
        &data,
        &killed,
        &resume(),
        &Device::Cpu,
        &mut |_| Control::Continue,
    )
    .unwrap();
    assert!(matches!(resumed, TrainOutcome::Finished(_)));
    assert_same_tensors(
        &checkpoint_tensors(&tmp.path().join("whole")),
        &checkpoint_tensors(&killed),
    );
    // The resumed log reads as one run: every (scale, iteration) once.
    let log = std::fs::read_to_string(killed.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), config.total_iterations());
}

#[test]
fn a_nan_stops_the_run_at_once_and_resume_continues_from_the_last_good_checkpoint() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro().with(|c| {
        c.run.checkpoint_iterations = 1;
    });
    run_to_end(&config, &data, &tmp.path().join("whole"));

    // G_2's weights turn NaN before iteration 2 of scale 2.
    let run = tmp.path().join("poisoned");
    let poisoned = RunOptions {
        poison: Some((2, 2)),
        ..RunOptions::default()
    };
    let err = train_failure(&config, &data, &run, &poisoned);
    let Error::Diverged {
        scale, step, what, ..
    } = &err
    else {
        panic!("expected Diverged, got {err}");
    };
    assert_eq!((*scale, *step), (2, 2), "{err}");
    assert!(!what.is_empty(), "{err}");
    let message = err.to_string();
    assert!(
        message.contains("scale 2, iteration 2") && message.contains("last checkpoint"),
        "{message}"
    );
    // Nothing of the bad iteration was saved: the checkpoint is the one after iteration 1,
    // every weight finite, and the log ends before the bad iteration.
    let saved = Checkpoint::load(&RunDir::new(&run).checkpoint(), &Device::Cpu).unwrap();
    assert_eq!((saved.state.scale, saved.state.iteration), (2, 2));
    for (name, tensor) in &saved.tensors {
        let values: Vec<f32> = tensor.flatten_all().unwrap().to_vec1().unwrap();
        assert!(values.iter().all(|v| v.is_finite()), "{name}");
    }
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), config.scale_schedule(1).iterations + 2);

    // Resumed (without the poison), the run ends as the uninterrupted one did.
    run_with(&config, &data, &run, &resume());
    assert_same_tensors(
        &checkpoint_tensors(&tmp.path().join("whole")),
        &checkpoint_tensors(&run),
    );
}

#[test]
fn resume_of_a_run_killed_before_its_first_checkpoint_starts_over() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro();
    run_to_end(&config, &data, &tmp.path().join("whole"));
    // What a kill before the first checkpoint leaves: config.json and part of the log.
    let run = tmp.path().join("early");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(run.join("log.jsonl"), "{\"scale\":1,\"iteration\":0,\"sec").unwrap();
    run_with(&config, &data, &run, &resume());
    assert_same_tensors(
        &checkpoint_tensors(&tmp.path().join("whole")),
        &checkpoint_tensors(&run),
    );
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), config.total_iterations());
}

#[test]
fn resume_refuses_another_configuration_and_names_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro().with_scales(2).unwrap();
    let run = tmp.path().join("run");
    run_to_end(&config, &data, &run);
    let other = config.with(|c| {
        c.losses.depth = 1.0;
    });
    let err = train_error(&other, &data, &run, &resume());
    assert!(
        err.contains("losses.depth") && err.contains("checkpoint.safetensors"),
        "{err}"
    );

    let missing = train_error(&other, &data, &tmp.path().join("empty"), &resume());
    assert!(missing.contains("no checkpoint"), "{missing}");
}

#[test]
fn broken_checkpoint_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let path = RunDir::new(tmp.path()).checkpoint();
    std::fs::write(&path, b"not a checkpoint").unwrap();
    let err = SinGrav::load(tmp.path(), &Device::Cpu)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("checkpoint.safetensors") && err.contains("safetensors"),
        "{err}"
    );
}

#[test]
fn presets_validate_and_unknown_names_are_listed() {
    for name in TrainConfig::PRESETS {
        TrainConfig::preset(name).unwrap().validate().unwrap();
    }
    let err = TrainConfig::preset("huge").unwrap_err().to_string();
    assert!(err.contains("huge") && err.contains("tiny"), "{err}");
    assert!(TrainConfig::preset("tiny").unwrap().with_scales(9).is_err());
}

#[test]
fn diversity_mv_matches_a_hand_computation() {
    let dev = Device::Cpu;
    // One view, 1 x 2 pixels, 3 channels. Real: channel values 0, 1 per pixel -> std 0.5.
    let real = Tensor::new(&[[[[0f32, 1.]], [[0., 1.]], [[0., 1.]]]], &dev).unwrap();
    // Two scenes differing by 0.2 everywhere: per-pixel population std 0.1.
    let a = Tensor::new(&[[[[0.3f32, 0.6]], [[0.3, 0.6]], [[0.3, 0.6]]]], &dev).unwrap();
    let b = (&a + 0.2).unwrap();
    let d = scene_metrics::diversity_mv(&[a.clone(), b], &real).unwrap();
    assert!((d - 0.1 / 0.5).abs() < 1e-6, "{d}");
    assert!(scene_metrics::diversity_mv(std::slice::from_ref(&a), &real).is_err());
    let flat = Tensor::full(0.5f32, (1, 3, 1, 2), &dev).unwrap();
    assert!(scene_metrics::diversity_mv(&[a.clone(), a], &flat).is_err());
}

#[test]
fn animation_walks_smoothly_and_harmonisation_runs_the_finer_scales() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro().with(|c| {
        c.schedule.scales = vec![
            ScaleSchedule {
                iterations: 2,
                reconstruction_only: 1
            };
            4
        ];
        c.pyramid.volume_sizes = vec![8, 11, 14];
        c.pyramid.image_sizes = vec![12, 18, 24];
        c.pyramid.samples = vec![16, 16, 16];
    });
    let (model, _) = run_to_end(&config, &data, &tmp.path().join("run"));
    let walk = singrav::applications::WalkConfig::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let frames = model.animate(6, walk, &mut rng).unwrap();
    assert_eq!(frames.len(), 6);
    let dist = |a: &Tensor, b: &Tensor| -> f32 {
        (a - b)
            .unwrap()
            .sqr()
            .unwrap()
            .mean_all()
            .unwrap()
            .to_scalar()
            .unwrap()
    };
    let independent = model
        .generate(&model.draw_noise(3, &mut rng).unwrap())
        .unwrap();
    let step = dist(&frames[0], &frames[1]);
    assert!(
        step > 0.0 && step < dist(&frames[0], &independent),
        "{step}"
    );
    // Fully anchored to the first frame's noise, the animation stands still.
    let frozen = singrav::applications::WalkConfig {
        anchor: 1.0,
        ..walk
    };
    let still = model.animate(3, frozen, &mut rng).unwrap();
    assert_eq!(dist(&still[0], &still[2]), 0.0);
    // Frame by frame, the animation is what `animate` returns at once.
    let mut one_by_one = model
        .animation(walk, rand_chacha::ChaCha8Rng::seed_from_u64(4))
        .unwrap();
    for frame in &frames {
        assert_eq!(dist(frame, &one_by_one.next_frame().unwrap()), 0.0);
    }
    for bad in [
        singrav::applications::WalkConfig {
            first_moving_scale: 4,
            ..walk
        },
        singrav::applications::WalkConfig {
            momentum: -0.1,
            ..walk
        },
    ] {
        assert!(model.animate(2, bad, &mut rng).is_err());
    }

    // Varying from scale 3: scales 1 and 2 take V*'s noise, scale 3 the seed's own draw.
    let seeded = || rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let draw = |vary_from| model.draw_noise_from(3, vary_from, &mut seeded()).unwrap();
    let (all, kept) = (draw(1), draw(3));
    let v_star_noise = model.reconstruction_noise(3).unwrap();
    assert_eq!(dist(&kept[0], &v_star_noise[0]), 0.0);
    assert_eq!(dist(&kept[1], &v_star_noise[1]), 0.0);
    assert_eq!(dist(&kept[2], &all[2]), 0.0);
    assert!(dist(&all[0], &v_star_noise[0]) > 0.0);
    let plain = model.draw_noise(3, &mut seeded()).unwrap();
    assert!(all.iter().zip(&plain).all(|(a, b)| dist(a, b) == 0.0));
    for bad in [0, 4] {
        assert!(model.draw_noise_from(3, bad, &mut seeded()).is_err());
    }
    // The animation from scale 3 starts from that noise and moves only scale 3.
    let from_three = singrav::applications::WalkConfig {
        vary_from: 3,
        ..walk
    };
    let kept_frames = model.animate(2, from_three, &mut seeded()).unwrap();
    assert_eq!(dist(&kept_frames[0], &model.generate(&kept).unwrap()), 0.0);
    assert!(dist(&kept_frames[0], &kept_frames[1]) > 0.0);
    let bad = singrav::applications::WalkConfig {
        vary_from: 4,
        ..walk
    };
    assert!(model.animate(2, bad, &mut seeded()).is_err());

    // Harmonising from scale 2 re-runs G_2 and G_3, from scale 3 only G_3 (on the edit itself).
    let edited = frames[0].clone();
    for from in [2, 3] {
        let out = model
            .harmonize(
                &edited,
                from,
                &mut rand_chacha::ChaCha8Rng::seed_from_u64(1),
            )
            .unwrap();
        assert_eq!(out.dims(), edited.dims());
        let again = model
            .harmonize(
                &edited,
                from,
                &mut rand_chacha::ChaCha8Rng::seed_from_u64(1),
            )
            .unwrap();
        assert_eq!(dist(&out, &again), 0.0);
    }
    for bad in [0, 1, 4] {
        assert!(model.harmonize(&edited, bad, &mut rng).is_err());
    }
}

/// A model of `config` with two fresh 3D scales, the coarser one's reconstruction, what scale 2
/// makes of it with noise of its shape, and the rng that drew them.
struct TwoScales {
    model: SinGrav,
    coarse: Tensor,
    refined: Tensor,
    rng: rand_chacha::ChaCha8Rng,
}

fn two_fresh_scales(config: &TrainConfig) -> TwoScales {
    let device = Device::Cpu;
    let mut rng = singrav::noise::step_rng(0, 0, 0);
    let mut model = SinGrav::new(config, &device, &mut rng).unwrap();
    model.push_generator(1.0, &mut rng).unwrap();
    let coarse = model.coarsest(model.z_star()).unwrap();
    model.push_generator(0.1, &mut rng).unwrap();
    let size = config.pyramid.volume_sizes[1];
    let z = singrav::noise::gaussian_volume(&mut rng, 4, size, 0.1, &device).unwrap();
    let refined = model.refine(2, &z, &coarse).unwrap();
    TwoScales {
        model,
        coarse,
        refined,
        rng,
    }
}

/// The largest absolute difference between two tensors of one shape.
fn largest_difference(a: &Tensor, b: &Tensor) -> f32 {
    let diff = (a - b).unwrap().abs().unwrap().flatten_all().unwrap();
    diff.max(0).unwrap().to_scalar::<f32>().unwrap()
}

#[test]
fn new_finer_scales_start_as_the_identity_on_the_coarser_output() {
    let TwoScales {
        mut model,
        coarse,
        refined,
        mut rng,
        ..
    } = two_fresh_scales(&micro());
    let upsampled = model.upsample_to_scale(&coarse, 2).unwrap();
    assert_eq!(largest_difference(&refined, &upsampled), 0.0);
    model.push_upsampler(&mut rng).unwrap();
    let images = Tensor::rand(0f32, 1., (2, 3, 6, 5), &Device::Cpu).unwrap();
    let doubled = model.upsample_images(&images).unwrap();
    let bilinear = patch_gan::upsample_bilinear2x(&images).unwrap();
    assert_eq!(largest_difference(&doubled, &bilinear), 0.0);
}

#[test]
fn active_set_scales_change_the_volume_only_near_matter() {
    let mut config = micro();
    config.active_set.from_scale = Some(2);
    config.active_set.threshold = 0.1;
    config.active_set.margin = 1;
    let device = Device::Cpu;
    let mut rng = singrav::noise::step_rng(0, 0, 0);
    let mut model = SinGrav::new(&config, &device, &mut rng).unwrap();
    model.push_generator(1.0, &mut rng).unwrap();
    let vars = model.push_generator(0.1, &mut rng).unwrap();
    // A generator that changes every voxel (new ones start as the identity).
    for var in vars.all_vars() {
        let noise = Tensor::randn(0f32, 0.5, var.as_tensor().shape(), &device).unwrap();
        var.set(&noise).unwrap();
    }
    // Matter in one slab of the coarser volume (raw density 10: sigma ~ 25 * 6), air elsewhere.
    let coarse_size = config.pyramid.volume_sizes[0];
    let slab = coarse_size / 2;
    let raw: Vec<f32> = (0..4 * coarse_size.pow(3))
        .map(|i| {
            let (channel, z) = (
                i / coarse_size.pow(3),
                (i / coarse_size.pow(2)) % coarse_size,
            );
            match (channel, z) {
                (0, z) if z == slab => 10.0,
                (0, _) => -30.0,
                _ => 0.0,
            }
        })
        .collect();
    let coarse =
        Tensor::from_vec(raw, (1, 4, coarse_size, coarse_size, coarse_size), &device).unwrap();
    let size = config.pyramid.volume_sizes[1];
    let z = singrav::noise::gaussian_volume(&mut rng, 4, size, 0.1, &device).unwrap();
    let values = |t: Tensor| -> Vec<f32> { t.flatten_all().unwrap().to_vec1().unwrap() };
    let refined = values(model.refine(2, &z, &coarse).unwrap());
    let up = model.upsample_to_scale(&coarse, 2).unwrap();
    let mask = values(
        singrav::active_set::active_mask(&up, &config.activation(), &config.active_set_rule())
            .unwrap(),
    );
    let up = values(up);
    let voxels = size.pow(3);
    let active = mask.iter().filter(|&&m| m == 1.0).count();
    assert!(active > 0 && active < voxels, "{active} of {voxels} active");
    for (i, (&r, &u)) in refined.iter().zip(&up).enumerate() {
        if mask[i % voxels] == 0.0 {
            assert_eq!(r, u, "inactive voxel {i} changed");
        }
    }
    let changed = (0..refined.len()).filter(|&i| refined[i] != up[i]).count();
    assert!(
        changed >= active,
        "{changed} values changed, {active} voxels active"
    );
    // The paper's dense model, same weights, changes the inactive voxels too.
    config.active_set.from_scale = None;
    let dense = SinGrav::from_tensors(
        &config,
        &model.tensors(),
        model.noise_amps(),
        false,
        &device,
    )
    .unwrap();
    let dense = values(dense.refine(2, &z, &coarse).unwrap());
    let changed_outside = (0..dense.len())
        .filter(|&i| mask[i % voxels] == 0.0 && dense[i] != up[i])
        .count();
    assert!(changed_outside > 0);
}

/// Random VGG-19 weights with torchvision's names for the convolutions Heitz et al.'s layers
/// read (up to `relu4_4`), He-scaled so activations neither vanish nor explode, written as
/// safetensors as swd-loss's tests do.
fn write_random_vgg19(path: &Path) {
    const CONVS: [(usize, usize, usize); 12] = [
        (0, 3, 64),
        (2, 64, 64),
        (5, 64, 128),
        (7, 128, 128),
        (10, 128, 256),
        (12, 256, 256),
        (14, 256, 256),
        (16, 256, 256),
        (19, 256, 512),
        (21, 512, 512),
        (23, 512, 512),
        (25, 512, 512),
    ];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(19);
    let mut tensors = HashMap::new();
    for (index, cin, cout) in CONVS {
        let bound = (6.0 / (9 * cin) as f32).sqrt();
        let weights: Vec<f32> = (0..cout * cin * 9)
            .map(|_| rng.random_range(-bound..bound))
            .collect();
        let weight = Tensor::from_vec(weights, (cout, cin, 3, 3), &Device::Cpu).unwrap();
        let bias = Tensor::zeros(cout, candle_core::DType::F32, &Device::Cpu).unwrap();
        tensors.insert(format!("features.{index}.weight"), weight);
        tensors.insert(format!("features.{index}.bias"), bias);
    }
    candle_core::safetensors::save(&tensors, path).unwrap();
}

#[test]
fn vgg19_features_drive_the_last_scales_swd_when_weights_are_given() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let weights = tmp.path().join("vgg19.safetensors");
    write_random_vgg19(&weights);
    let config = micro().with_scales(2).unwrap().with(|c| {
        c.losses.swd_features = SwdFeatures::Vgg19;
    });
    let with_weights = RunOptions {
        vgg19_weights: Some(weights.clone()),
        ..RunOptions::default()
    };
    let run = tmp.path().join("run");
    let (_, steps) = run_with(&config, &data, &run, &with_weights);
    let last = config.scales();
    for (scale, l) in &steps {
        let terms = [
            l.get(LossTerm::Critic),
            l.get(LossTerm::Penalty),
            l.get(LossTerm::Adversarial),
            l.get(LossTerm::Rgb),
            l.get(LossTerm::Swd),
        ];
        assert!(
            terms.iter().flatten().all(|v| v.is_finite()),
            "scale {scale}: {l:?}"
        );
    }
    assert!(steps
        .iter()
        .any(|(s, l)| *s == last && l.get(LossTerm::Swd).is_some()));
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    let logged_swd = log.lines().any(|line| {
        let entry: serde_json::Value = serde_json::from_str(line).unwrap();
        entry["scale"] == last && entry["swd"].as_f64().is_some_and(f64::is_finite)
    });
    assert!(logged_swd, "{log}");
    let recorded = std::fs::read_to_string(run.join("config.json")).unwrap();
    assert!(
        recorded.contains(r#""swd_features": "vgg19""#),
        "{recorded}"
    );

    // A resume cannot silently switch to the patch pyramid (the configuration records VGG-19)
    // nor run VGG-19 without its weights.
    let switched = train_error(
        &config.clone().with(|c| {
            c.losses.swd_features = SwdFeatures::PatchPyramid;
        }),
        &data,
        &run,
        &resume(),
    );
    assert!(switched.contains("swd_features"), "{switched}");
    let no_weights = train_error(&config, &data, &run, &resume());
    assert!(no_weights.contains("vgg19_weights"), "{no_weights}");
}

#[test]
fn missing_or_broken_vgg19_weights_fail_before_training_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro().with(|c| {
        c.losses.swd_features = SwdFeatures::Vgg19;
    });
    let broken = tmp.path().join("broken.safetensors");
    std::fs::write(&broken, b"not safetensors").unwrap();
    let truncated = tmp.path().join("truncated.safetensors");
    let conv1 = HashMap::from([(
        "features.0.weight".to_string(),
        Tensor::zeros((64, 3, 3, 3), candle_core::DType::F32, &Device::Cpu).unwrap(),
    )]);
    candle_core::safetensors::save(&conv1, &truncated).unwrap();
    for file in [
        "missing.safetensors",
        "broken.safetensors",
        "truncated.safetensors",
    ] {
        let path = tmp.path().join(file);
        let run = tmp.path().join(format!("run_{file}"));
        let options = RunOptions {
            vgg19_weights: Some(path.clone()),
            ..RunOptions::default()
        };
        let mut steps = 0;
        let err = train(&config, &data, &run, &options, &Device::Cpu, &mut |_| {
            steps += 1;
            Control::Continue
        })
        .err()
        .unwrap();
        assert!(matches!(err, Error::Weights { .. }), "{err:?}");
        assert!(err.to_string().contains(file), "{err}");
        assert_eq!(steps, 0, "{file}: training started");
        assert!(!run.exists(), "{file}: the run directory was created");
    }
    // Weights given to a run whose SWD loss does not use them are refused, not ignored.
    let unused = train_error(
        &micro(),
        &data,
        &tmp.path().join("run_unused"),
        &RunOptions {
            vgg19_weights: Some(broken),
            ..RunOptions::default()
        },
    );
    assert!(unused.contains("vgg19_weights"), "{unused}");
    assert!(config
        .with(|c| {
            c.ablations.use_swd = false;
        })
        .validate()
        .is_err());
}

/// A 3D critic judges the generated volumes against a fitted volume: its losses are logged at
/// the 3D scales' adversarial iterations (and nowhere else), it changes what the generators
/// learn, its weights and optimiser are in mid-scale checkpoints, and a killed run resumes to
/// the uninterrupted weights. Without a fitted volume it is refused by name.
#[test]
fn a_volume_critic_trains_against_the_fitted_volume_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let fitted = tmp.path().join("fitted.safetensors");
    let raw = Tensor::randn(0f32, 1.0, (4, 8, 8, 8), &Device::Cpu).unwrap();
    let activation = micro().activation();
    radiance_volume::RadianceVolume::from_raw(&raw, radiance_volume::Aabb::CUBE, &activation)
        .unwrap()
        .save_safetensors(&fitted)
        .unwrap();
    let options = RunOptions {
        fitted_volume: Some(fitted.clone()),
        ..RunOptions::default()
    };
    // The critic alone, without the 3D comparison of the reconstruction.
    let config = micro().with(|c| {
        c.losses.volume_critic = 1.0;
        c.run.checkpoint_iterations = 2;
    });
    let whole = tmp.path().join("whole");
    let (_, steps) = run_with(&config, &data, &whole, &options);
    let volume_scales = config.pyramid.volume_sizes.len();
    for (scale, losses) in &steps {
        let judged = *scale <= volume_scales && losses.get(LossTerm::Critic).is_some();
        assert_eq!(
            losses.get(LossTerm::VolumeCritic).is_some(),
            judged,
            "scale {scale}"
        );
        assert_eq!(
            losses.get(LossTerm::VolumePenalty).is_some(),
            judged,
            "scale {scale}"
        );
        assert_eq!(
            losses.get(LossTerm::VolumeAdversarial).is_some(),
            judged,
            "scale {scale}"
        );
        assert!(losses.get(LossTerm::Fitted).is_none());
        for value in [
            losses.get(LossTerm::VolumeCritic),
            losses.get(LossTerm::VolumePenalty),
            losses.get(LossTerm::VolumeAdversarial),
        ] {
            assert!(value.is_none_or(f32::is_finite));
        }
    }
    assert!(steps
        .iter()
        .any(|(_, l)| l.get(LossTerm::VolumeCritic).is_some()));
    // Up to scale 1 only, seeing what a ray from above meets: judged there, not at scale 2.
    let coarsest_only = config.clone().with(|c| {
        c.critics.volume_until_scale = Some(1);
        c.critics.volume_seen_from_above = true;
    });
    let (_, steps) = run_with(
        &coarsest_only,
        &data,
        &tmp.path().join("coarsest"),
        &options,
    );
    for (scale, losses) in &steps {
        let judged = *scale == 1 && losses.get(LossTerm::Critic).is_some();
        assert_eq!(
            losses.get(LossTerm::VolumeCritic).is_some(),
            judged,
            "scale {scale}"
        );
        assert!(losses
            .get(LossTerm::VolumeAdversarial)
            .is_none_or(f32::is_finite));
    }

    let without = tmp.path().join("without");
    run_to_end(&micro(), &data, &without);
    let (a, b) = (checkpoint_tensors(&whole), checkpoint_tensors(&without));
    let values = |t: &Tensor| -> Vec<f32> { t.flatten_all().unwrap().to_vec1().unwrap() };
    let changed = a
        .keys()
        .filter(|name| name.starts_with("g1."))
        .any(|name| values(&a[name]) != values(&b[name]));
    assert!(changed, "the 3D critic changed nothing in G_1");

    // Killed in scale 2 after iteration 3: the checkpoint of iteration 2 holds the 3D critic.
    let killed = tmp.path().join("killed");
    let mut stop = stop_at(2, 3);
    let outcome = train(&config, &data, &killed, &options, &Device::Cpu, &mut stop).unwrap();
    assert!(matches!(outcome, TrainOutcome::Stopped));
    let saved = checkpoint_tensors(&killed);
    assert!(saved.contains_key("d3.tail.weight"));
    assert!(saved.keys().any(|name| name.starts_with("opt_d3.")));
    let resumed = RunOptions {
        resume: true,
        ..options.clone()
    };
    run_with(&config, &data, &killed, &resumed);
    assert_same_tensors(&checkpoint_tensors(&whole), &checkpoint_tensors(&killed));
    // Without a fitted volume the run fits one itself
    // (`a_run_that_compares_with_a_fitted_volume_and_has_none_fits_one_first`).
}

#[test]
fn optimised_reconstruction_noise_trains_is_saved_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let config = micro().with(|c| {
        c.noise.reconstruction_lr = 0.05;
        c.run.checkpoint_iterations = 2;
    });
    let whole = tmp.path().join("whole");
    let (model, _) = run_to_end(&config, &data, &whole);
    let finished = checkpoint_tensors(&whole);
    let values = |t: &Tensor| -> Vec<f32> { t.flatten_all().unwrap().to_vec1().unwrap() };
    let z2 = values(&finished["z_star.2"]);
    // Micro's scale 2 takes 4 generator steps of Adam at 0.05 from zero: every voxel moved
    // (the dense generator's input gradient reaches all of them), and by about that much.
    assert!(z2.iter().all(|&v| v != 0.0 && v.abs() < 0.5));
    let noise = model.reconstruction_noise(2).unwrap();
    assert_eq!(values(&noise[1]), z2);

    killed_in_scale_2_resumes_to(
        &config,
        &data,
        &tmp.path().join("killed"),
        "opt_z.",
        &finished,
    );

    let mut without_z2 = finished.clone();
    without_z2.remove("z_star.2");
    let state = Checkpoint::load(&RunDir::new(&whole).checkpoint(), &Device::Cpu)
        .unwrap()
        .state;
    let err = SinGrav::from_tensors(
        &config,
        &without_z2,
        &state.noise_amps,
        state.upsampler,
        &Device::Cpu,
    )
    .err()
    .expect("a checkpoint without z*_2 must be refused");
    assert!(err.contains("z_star.2"), "{err}");

    let plain = tmp.path().join("plain");
    run_to_end(&micro(), &data, &plain);
    assert!(checkpoint_tensors(&plain)
        .keys()
        .all(|name| name == "z_star" || !name.starts_with("z_star") && !name.starts_with("opt_z")));
}

fn reconstruction_volume_psnr(model: &SinGrav, data: &Dataset) -> f64 {
    let all: Vec<usize> = (0..data.len()).collect();
    let v_star = model.reconstruct().unwrap();
    model.volume_psnr(&v_star, data, &all).unwrap()
}

/// A finished run resumed with `reconstruction_fit_steps` fits its reconstruction to the views
/// with every network frozen: V*'s volume comes nearer the views, every other tensor (and so
/// every generated scene) stays bit for bit, the detail is saved and loads with the run, and
/// a fitted run refuses another step count naming the field.
#[test]
fn a_finished_run_fits_its_reconstruction_to_the_views_with_the_networks_frozen() {
    let tmp = tempfile::tempdir().unwrap();
    let data = dataset(&tmp.path().join("data"));
    let plain_dir = tmp.path().join("plain");
    let (plain, _) = run_to_end(&micro(), &data, &plain_dir);
    let fitted_dir = tmp.path().join("fitted");
    std::fs::create_dir(&fitted_dir).unwrap();
    std::fs::copy(
        RunDir::new(&plain_dir).checkpoint(),
        RunDir::new(&fitted_dir).checkpoint(),
    )
    .unwrap();
    let config = micro().with(|c| {
        c.schedule.reconstruction_fit_steps = 60;
    });
    let mut fit_events = 0;
    let mut observer = |p: &Progress| {
        if let Event::ReconstructionFitted { batch_psnr } = p.event {
            assert!(batch_psnr.is_finite() && p.scale_seconds > 0.0);
            fit_events += 1;
        }
        Control::Continue
    };
    let outcome = train(
        &config,
        &data,
        &fitted_dir,
        &resume(),
        &Device::Cpu,
        &mut observer,
    );
    let TrainOutcome::Finished(fitted) = outcome.unwrap() else {
        panic!("nobody asked to stop")
    };
    assert_eq!(fit_events, 1);

    let before = reconstruction_volume_psnr(&plain, &data);
    let after = reconstruction_volume_psnr(&fitted, &data);
    println!("V*'s volume: {before:.2} dB trained, {after:.2} dB fitted after training");
    assert!(after > before + 1.0, "{after:.2} vs {before:.2} dB");

    let mut saved = checkpoint_tensors(&fitted_dir);
    let detail = saved.remove(RECONSTRUCTION_DETAIL_TENSOR).unwrap();
    let s = *micro().pyramid.volume_sizes.last().unwrap();
    assert_eq!(detail.dims(), &[1, 4, s, s, s]);
    assert_same_tensors(&saved, &checkpoint_tensors(&plain_dir));
    let scene = |model: &SinGrav| -> Vec<f32> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let raw = model.generate_random(&mut rng).unwrap();
        raw.flatten_all().unwrap().to_vec1().unwrap()
    };
    assert_eq!(scene(&plain), scene(&fitted));
    let (loaded, _) = SinGrav::load(&fitted_dir, &Device::Cpu).unwrap();
    let values = |t: Tensor| -> Vec<f32> { t.flatten_all().unwrap().to_vec1().unwrap() };
    assert_eq!(
        values(loaded.reconstruct().unwrap()),
        values(fitted.reconstruct().unwrap())
    );

    // A run with the fit from the start ends where the finished run given it later does.
    let direct = tmp.path().join("direct");
    run_to_end(&config, &data, &direct);
    assert_same_tensors(
        &checkpoint_tensors(&direct),
        &checkpoint_tensors(&fitted_dir),
    );

    let other = micro().with(|c| {
        c.schedule.reconstruction_fit_steps = 30;
    });
    let err = train_error(&other, &data, &fitted_dir, &resume());
    assert!(err.contains("reconstruction_fit_steps"), "{err}");
    let wrong = Tensor::zeros((1, 4, 3, 3, 3), candle_core::DType::F32, &Device::Cpu).unwrap();
    let mut model = loaded;
    let err = model
        .set_reconstruction_detail(wrong)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("reconstruction detail") && err.contains(&format!("{s}, {s}, {s}]")),
        "{err}"
    );
}

/// Depth from a fit of the views, from the library alone (no CLI): `prepare` fits the views
/// without depth into the run's directory, the run trains on the depth that fit renders, and a
/// resumed run finds the fit rather than making it again.
#[test]
fn depth_from_a_fit_is_made_kept_and_reused_by_the_library() {
    use rgbd_dataset::{DepthKind, LoadOptions};
    use singrav::train::{prepare, RunFit, Trainer};

    let tmp = tempfile::tempdir().unwrap();
    dataset(&tmp.path().join("data"));
    // Photos without depth maps, as a capture of one's own has them.
    let options = LoadOptions {
        depth_kind: Some(DepthKind::None),
        ..LoadOptions::default()
    };
    let photos = Dataset::load_with(&tmp.path().join("data"), &options).unwrap();
    assert_eq!(photos.depth_kind(), DepthKind::None);
    let config = micro().with(|c| c.run.depth_from_fit = true);
    assert!(!config.reads_depth_maps());
    let run = RunDir::new(tmp.path().join("run"));
    let options = RunOptions {
        depth_fit_steps: Some(4),
        ..RunOptions::default()
    };
    let mut fits = Vec::new();
    let inputs = prepare(
        &config,
        &photos,
        &run,
        &options,
        &Device::Cpu,
        &mut |fit, _| {
            fits.push(fit);
        },
    )
    .unwrap();
    assert!(!fits.is_empty() && fits.iter().all(|&fit| fit == RunFit::DepthSource));
    assert_eq!(inputs.made.len(), 1);
    assert_eq!(inputs.made[0].fit, RunFit::DepthSource);
    assert_eq!(inputs.made[0].path, run.depth_fit());
    assert!(run.depth_fit().is_file());
    assert_ne!(inputs.dataset.depth_kind(), DepthKind::None);
    let coverage = inputs.depth_coverage.unwrap();
    assert!(coverage.foreground > 0);
    let trainer = Trainer::from_inputs(&config, inputs, run.root(), &Device::Cpu).unwrap();
    let outcome = trainer.run(&mut |_| Control::Continue).unwrap();
    assert!(matches!(outcome, TrainOutcome::Finished(_)));
    assert!(run.log().is_file() && run.scale_picture(1).is_file());

    // Resumed, the run's own fit is used: nothing is fitted again.
    let resumed = RunOptions {
        resume: true,
        ..options
    };
    let again = prepare(
        &config,
        &photos,
        &run,
        &resumed,
        &Device::Cpu,
        &mut |_, _| panic!("fitted again"),
    )
    .unwrap();
    assert!(again.made.is_empty());
    assert_eq!(again.options.depth_fit, Some(run.depth_fit()));
}
