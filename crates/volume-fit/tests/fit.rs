//! Direct fits: a scene rendered from known cameras is fitted back to a stated PSNR on the
//! views it saw and on views it did not, reproducibly from its seed.

use candle_core::{DType, Device, Tensor};
use rgbd_dataset::scenes::StandingStones;
use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
use volume_fit::{fit_volume, fit_volume_from, view_psnr, FitBudget, FitConfig};

fn stones(views: usize) -> (tempfile::TempDir, Dataset) {
    let dir = tempfile::tempdir().unwrap();
    let spec = DatasetSpec {
        views,
        resolution: 32,
        grid: 32,
        seed: 3,
    };
    write_dataset(&StandingStones::new(3), dir.path(), &spec).unwrap();
    let data = Dataset::load(dir.path(), [1.0; 3]).unwrap();
    (dir, data)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn a_rendered_scene_is_fitted_back_on_seen_and_held_out_views() {
    let (_dir, data) = stones(24);
    let (training, held_out) = data.holdout_split(6).unwrap();
    let config = FitConfig {
        size: 24,
        start_size: 12,
        budget: FitBudget::Steps(300),
        rays_per_step: 2048,
        ..FitConfig::default()
    };
    let mut last_size = 0;
    let fitted = fit_volume(&data, &training, &config, &mut |p| last_size = p.size).unwrap();
    assert_eq!((fitted.steps, last_size), (300, 24));
    let seen = mean(&view_psnr(&fitted.volume, &data, &training, &config).unwrap());
    let unseen = mean(&view_psnr(&fitted.volume, &data, &held_out, &config).unwrap());
    println!(
        "seen {seen:.2} dB, held out {unseen:.2} dB, live {}",
        fitted.live_fraction
    );
    // Measured 2026-11-24: 30.6 dB seen and 27.3 dB held out; a grey fog scores about 9.
    assert!(seen > 27.0, "training views {seen:.2} dB");
    assert!(unseen > 24.0, "held-out views {unseen:.2} dB");
    // The occupancy mask found the sky empty: density exactly 0 in most voxels.
    assert!(fitted.live_fraction < 0.8, "{}", fitted.live_fraction);
    let density: Vec<f32> = fitted
        .volume
        .density()
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    let empty = density.iter().filter(|&&d| d == 0.0).count() as f32 / density.len() as f32;
    assert!(empty > 0.2, "{empty}");
}

/// A grid too coarse for the stones' edges holds them better when its samples activate the
/// interpolated raw density (DVGO's post-activation) than when they interpolate the voxels'
/// physical densities; the fit renders raw density and saves physical density.
#[test]
fn post_activated_density_fits_a_coarse_grid_closer() {
    let (_dir, data) = stones(12);
    let all: Vec<usize> = (0..data.len()).collect();
    let config = FitConfig {
        size: 16,
        start_size: 16,
        budget: FitBudget::Steps(300),
        rays_per_step: 2048,
        ..FitConfig::default()
    };
    let post = FitConfig {
        post_activation: true,
        ..config.clone()
    };
    let psnr = |c: &FitConfig| {
        let fitted = fit_volume(&data, &all, c, &mut |_| {}).unwrap();
        let psnr = mean(&view_psnr(&fitted.rendered, &data, &all, c).unwrap());
        let density = |v: &radiance_volume::RadianceVolume| -> Vec<f32> {
            let flat = v.density().and_then(|d| Ok(d.flatten_all()?));
            flat.unwrap().to_vec1().unwrap()
        };
        (psnr, density(&fitted.volume), density(&fitted.rendered))
    };
    let (physical_psnr, _, _) = psnr(&config);
    let (post_psnr, saved, rendered) = psnr(&post);
    println!("16^3: physical {physical_psnr:.2} dB, post-activated {post_psnr:.2} dB");
    // Measured 2026-11-28: 24.98 dB physical, 26.79 dB post-activated.
    assert!(
        post_psnr > physical_psnr + 1.0,
        "post-activated {post_psnr:.2} dB vs physical {physical_psnr:.2} dB"
    );
    assert!(saved.iter().all(|&d| d >= 0.0));
    assert!(rendered.iter().any(|&d| d < 0.0), "raw density is rendered");
    // The saved volume is the raw one activated per voxel.
    let activation = post.activation;
    for (&raw, &sigma) in rendered.iter().zip(&saved) {
        let want = if raw <= -1.0e3 {
            0.0
        } else {
            activation.density_scale * (raw + activation.density_shift).exp().ln_1p()
        };
        assert!(
            (sigma - want).abs() <= 1e-4 * want.max(1.0),
            "{sigma} vs {want}"
        );
    }
}

/// A fit continued from raw values starts where they are: from a converged fit's values a few
/// small steps keep its PSNR, from a grey start the same steps stay far below; the values come
/// back in the planar layout they went in.
#[test]
fn a_fit_continues_from_the_raw_values_it_is_given() {
    let (_dir, data) = stones(12);
    let all: Vec<usize> = (0..data.len()).collect();
    let first = FitConfig {
        size: 16,
        start_size: 16,
        budget: FitBudget::Steps(300),
        rays_per_step: 2048,
        post_activation: true,
        // Every voxel live, so the raw values render as the fit rendered them.
        occupancy_every: 0,
        ..FitConfig::default()
    };
    let fitted = fit_volume(&data, &all, &first, &mut |_| {}).unwrap();
    let fitted_psnr = mean(&view_psnr(&fitted.rendered, &data, &all, &first).unwrap());
    let short = FitConfig {
        budget: FitBudget::Steps(20),
        learning_rate: 0.01,
        final_learning_rate: 0.01,
        ..first.clone()
    };
    let continued = fit_volume_from(&data, &all, &short, &fitted.raw, &mut |_| {}).unwrap();
    let continued_psnr = mean(&view_psnr(&continued.rendered, &data, &all, &short).unwrap());
    let grey = Tensor::zeros((4, 16, 16, 16), DType::F32, &Device::Cpu).unwrap();
    let from_grey = fit_volume_from(&data, &all, &short, &grey, &mut |_| {}).unwrap();
    let grey_psnr = mean(&view_psnr(&from_grey.rendered, &data, &all, &short).unwrap());
    println!(
        "fit {fitted_psnr:.2} dB, continued {continued_psnr:.2} dB, from grey {grey_psnr:.2} dB"
    );
    assert_eq!(continued.steps, 20);
    assert!(
        continued_psnr > fitted_psnr - 0.5,
        "{continued_psnr:.2} vs {fitted_psnr:.2} dB"
    );
    assert!(
        grey_psnr < fitted_psnr - 5.0,
        "{grey_psnr:.2} vs {fitted_psnr:.2} dB"
    );
    // Adam's bias-corrected step stays near the rate (about 1.2 times it at most over 20 steps
    // with these betas), so 20 steps stay well within 0.7 of the start: a value read from
    // another voxel would not.
    let before: Vec<f32> = fitted.raw.flatten_all().unwrap().to_vec1().unwrap();
    let after: Vec<f32> = continued.raw.flatten_all().unwrap().to_vec1().unwrap();
    let largest = before
        .iter()
        .zip(&after)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(largest <= 20.0 * 0.01 * 3.5, "{largest}");
    // A start of another size is refused, naming it.
    let wrong = Tensor::zeros((4, 8, 8, 8), DType::F32, &Device::Cpu).unwrap();
    let err = fit_volume_from(&data, &all, &short, &wrong, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("initial volume") && err.contains("[4, 16, 16, 16]"),
        "{err}"
    );
}

#[test]
fn the_same_seed_fits_the_same_bits() {
    let (_dir, data) = stones(4);
    let config = FitConfig {
        size: 10,
        start_size: 6,
        budget: FitBudget::Steps(30),
        rays_per_step: 512,
        seed: 7,
        ..FitConfig::default()
    };
    let all = [0, 1, 2, 3];
    let values = |c: &FitConfig| -> Vec<f32> {
        let fitted = fit_volume(&data, &all, c, &mut |_| {}).unwrap();
        fitted
            .volume
            .tensor()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap()
    };
    let first = values(&config);
    assert_eq!(first, values(&config));
    assert_ne!(first, values(&FitConfig { seed: 8, ..config }));
}

#[test]
fn bad_settings_and_views_are_named() {
    let (_dir, data) = stones(2);
    let fit = |config: FitConfig, views: &[usize]| {
        fit_volume(&data, views, &config, &mut |_| {})
            .unwrap_err()
            .to_string()
    };
    let err = fit(
        FitConfig {
            size: 1,
            ..FitConfig::default()
        },
        &[0],
    );
    assert!(err.contains("size"), "{err}");
    let err = fit(
        FitConfig {
            start_size: 1,
            ..FitConfig::default()
        },
        &[0],
    );
    assert!(err.contains("start_size"), "{err}");
    let err = fit(
        FitConfig {
            budget: FitBudget::Seconds(f64::NAN),
            ..FitConfig::default()
        },
        &[0],
    );
    assert!(err.contains("budget"), "{err}");
    let err = fit(FitConfig::default(), &[5]);
    assert!(err.contains("frame 5 does not exist"), "{err}");
    let err = fit(FitConfig::default(), &[]);
    assert!(err.contains("at least one frame"), "{err}");
}
