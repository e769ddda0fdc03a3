//! `volgen eval` on `micro` runs: the reconstruction's fit, the weights-free distribution
//! numbers and Diversity-MV always, SIFID-MV with (generated) InceptionV3 weights, held-out
//! views of a `--holdout` run, the table of several runs, the same numbers for the same seed,
//! and clear errors for bad input.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use rand::{Rng, SeedableRng};
use scene_metrics::InceptionBlock1;

mod common;
use common::{failure, ok, path, train_micro, volgen};

/// Random InceptionV3 first-block weights with torchvision's names (real ones cannot be
/// downloaded here); variances positive, as a BatchNorm's are.
fn write_random_inception(path: &Path) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let tensors: HashMap<String, Tensor> = InceptionBlock1::tensor_shapes()
        .into_iter()
        .map(|(name, shape)| {
            let count = shape.iter().product();
            let values: Vec<f32> = (0..count).map(|_| rng.random_range(0.1..0.5)).collect();
            let tensor = Tensor::from_vec(values, shape, &Device::Cpu).unwrap();
            (name, tensor)
        })
        .collect();
    candle_core::safetensors::save(&tensors, path).unwrap();
}

/// The number after `label` on its line of `text`.
fn number_after(text: &str, label: &str) -> f64 {
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix(label))
        .unwrap_or_else(|| panic!("no `{label}` line in {text}"));
    line.split_whitespace()
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number in `{line}`"))
}

/// The standard error shown after "±" on `label`'s line of `text`.
fn error_after(text: &str, label: &str) -> f64 {
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix(label))
        .unwrap_or_else(|| panic!("no `{label}` line in {text}"));
    line.split_once('±')
        .and_then(|(_, rest)| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no `± error` in `{line}`"))
}

/// The mean over every frame of `data` of the PSNR (f64) of `volume` rendered at the dataset's
/// resolution over white, with the renderer called directly (two samples per voxel crossed,
/// as `volgen fit` scores its volumes; no empty-space skipping).
fn volume_psnr_by_hand(volume: &Path, data: &Path) -> f64 {
    let volume = radiance_volume::RadianceVolume::load_safetensors(volume).unwrap();
    rendered_psnr_by_hand(&volume, volrender::DensityInterpolation::Physical, data)
}

/// [`volume_psnr_by_hand`] of a volume in memory, its channel 0 read by `density`.
fn rendered_psnr_by_hand(
    volume: &radiance_volume::RadianceVolume,
    density: volrender::DensityInterpolation,
    data: &Path,
) -> f64 {
    use volrender::{render, Rays, RenderConfig, Sampler};
    let dataset = rgbd_dataset::Dataset::load(data, [1.0; 3]).unwrap();
    let level = dataset
        .level(dataset.width(), dataset.height(), &Device::Cpu)
        .unwrap();
    let config = RenderConfig::default()
        .with_sampler(Sampler::PerVoxel { per_voxel: 2 })
        .with_skip_empty(false)
        .with_background([1.0; 3])
        .with_aabb(volume.aabb())
        .with_density(density);
    let psnr: Vec<f64> = level
        .cameras
        .iter()
        .enumerate()
        .map(|(i, camera)| {
            let rgb: Vec<f32> = render(volume.tensor(), &Rays::from_camera(camera), &config)
                .unwrap()
                .rgb
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap();
            // (3, H, W) -> (H, W, 3), as the renderer lays out its rays' colours.
            let real: Vec<f32> = level
                .images
                .get(i)
                .unwrap()
                .permute((1, 2, 0))
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap();
            let mse = rgb
                .iter()
                .zip(&real)
                .map(|(a, b)| (f64::from(*a) - f64::from(*b)).powi(2))
                .sum::<f64>()
                / rgb.len() as f64;
            -10.0 * mse.log10()
        })
        .collect();
    psnr.iter().sum::<f64>() / psnr.len() as f64
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn eval_reports_diversity_and_with_weights_sifid() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, run) = train_micro(tmp.path());
    let base = [
        "eval",
        path(&run),
        "--dataset",
        path(&data),
        "--scenes",
        "3",
        "--views",
        "2",
        // V* as the layout reference: a fit of the views per evaluation would take a minute
        // here; the fit is checked once below.
        "--layout-reference",
        "vstar",
    ];

    let text = ok(&volgen(&base));
    let diversity = number_after(&text, "Diversity-MV:");
    assert!(diversity.is_finite() && diversity > 0.0, "{text}");
    assert!(
        text.contains("SIFID-MV:                  not computed") && text.contains("--inception"),
        "{text}"
    );
    let report = json(&run.join("eval.json"));
    // The JSON has every digit, the text two or four decimals; every number is labelled.
    for (label, key, within) in [
        ("Diversity-MV:", "diversity_mv", 5e-5),
        ("reconstruction_psnr:", "reconstruction_psnr", 5e-3),
        ("reconstruction_ssim:", "reconstruction_ssim", 5e-5),
        (
            "reconstruction_depth_rmse:",
            "reconstruction_depth_rmse",
            5e-5,
        ),
        ("patch_swd_mv:", "patch_swd_mv", 5e-5),
        ("colour_swd:", "colour_swd", 5e-5),
        ("floaters:", "floaters", 5e-5),
    ] {
        let exact = report[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key}: {report}"));
        let shown = number_after(&text, label);
        assert!((exact - shown).abs() <= within, "{key}: {exact} vs {shown}");
    }
    // The sample metrics carry their standard error over the 3 scenes, shown after "±".
    for (label, key) in [
        ("patch_swd_mv:", "patch_swd_mv_stderr"),
        ("colour_swd:", "colour_swd_stderr"),
        ("floaters:", "floaters_stderr"),
        ("Diversity-MV:", "diversity_mv_stderr"),
    ] {
        let exact = report[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key}: {report}"));
        assert!(exact.is_finite() && exact >= 0.0, "{key}: {exact}");
        let shown = error_after(&text, label);
        assert!((exact - shown).abs() <= 5e-5, "{key}: {exact} vs {shown}");
    }
    // A barely trained micro model: a poor but not absurd fit, some sky filled, all finite.
    let psnr = report["reconstruction_psnr"].as_f64().unwrap();
    assert!(psnr > 5.0 && psnr < 40.0, "{psnr}");
    let ssim = report["reconstruction_ssim"].as_f64().unwrap();
    assert!(ssim > -1.0 && ssim < 1.0, "{ssim}");
    let floaters = report["floaters"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&floaters), "{floaters}");
    assert!(report["patch_swd_mv"].as_f64().unwrap() > 0.0);
    assert!(report["colour_swd"].as_f64().unwrap() > 0.0);
    assert!(report["reconstruction_depth_rmse"].as_f64().unwrap() > 0.0);
    assert!(text.contains("held_out:                  none"), "{text}");
    assert!(report["held_out_psnr"].is_null() && report["holdout"].is_null());
    assert!(report["sifid_mv"].is_null());
    assert_eq!(report["image_size"], 36, "micro's final images");
    assert_eq!(report["depth_size"], 18, "micro's last 3D rendering");
    let first_and_fourth = serde_json::json!(["images/r_000.png", "images/r_003.png"]);
    assert_eq!(report["views"], first_and_fourth);
    assert_eq!(report["reconstruction_views"], first_and_fourth);

    // V*'s own volume, as `volgen sample --reconstruction` writes it, scored independently.
    let v_star = tmp.path().join("v_star");
    ok(&volgen(&[
        "sample",
        path(&run),
        "--count",
        "0",
        "--reconstruction",
        "--out",
        path(&v_star),
    ]));
    let volume_psnr = report["volume_psnr"].as_f64().unwrap();
    let expected = volume_psnr_by_hand(&v_star.join("reconstruction.safetensors"), &data);
    assert!(
        (volume_psnr - expected).abs() < 1e-3,
        "eval {volume_psnr} dB, by hand {expected} dB"
    );
    assert_eq!(report["volume_views"], 6, "every training view");
    assert!((number_after(&text, "volume_psnr:") - volume_psnr).abs() <= 5e-3);
    assert!(report["held_out_volume_psnr"].is_null());

    let weights = tmp.path().join("inception.safetensors");
    write_random_inception(&weights);
    let out = tmp.path().join("metrics.json");
    let mut args = base.to_vec();
    args.extend(["--inception", path(&weights), "--out", path(&out)]);
    let text = ok(&volgen(&args));
    let sifid = number_after(&text, "SIFID-MV:");
    assert!(sifid.is_finite() && sifid >= 0.0, "{text}");
    let report = json(&out);
    assert!((report["sifid_mv"].as_f64().unwrap() - sifid).abs() <= 5e-5);
    // The same seed generates the same scenes.
    assert_eq!(number_after(&text, "Diversity-MV:"), diversity);

    let mut args = base.to_vec();
    let nowhere = tmp.path().join("nowhere.safetensors");
    args.extend(["--inception", path(&nowhere)]);
    let err = failure(&volgen(&args));
    assert!(err.contains("nowhere.safetensors"), "{err}");

    // Against V* no fit is made, and V*'s own distance is not reported; against a fit (the
    // default) it is.
    assert!(text.contains("against V*"), "{text}");
    assert_eq!(report["layout_reference"], "vstar");
    assert!(
        report["reconstruction_layout_distance"].is_null()
            && report["reconstruction_layout_distance_by_position"].is_null()
            && report["reconstruction_misplaced_matter"].is_null(),
        "{report}"
    );
    assert!(number_after(&text, "layout_distance:") > 0.0, "{text}");
    let fitted = ok(&volgen(&base[..base.len() - 2]));
    assert!(
        fitted.contains("a direct fit of the training views"),
        "{fitted}"
    );
    let report = json(&run.join("eval.json"));
    assert_eq!(report["layout_reference"], "fit");
    let v_star = report["reconstruction_layout_distance"].as_f64().unwrap();
    assert!(v_star >= 0.0 && v_star.is_finite(), "{report}");
    let by_position = report["reconstruction_layout_distance_by_position"]
        .as_f64()
        .unwrap();
    assert!(by_position >= 0.0 && by_position.is_finite(), "{report}");
    assert!(
        (number_after(&fitted, "reconstruction_position:") - by_position).abs() <= 5e-5,
        "{fitted}"
    );
    let v_star = report["reconstruction_misplaced_matter"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&v_star), "{report}");
    assert!((number_after(&fitted, "reconstruction_misplaced:") - v_star).abs() <= 5e-5);
    let mut args = base[..base.len() - 2].to_vec();
    args.extend(["--layout-reference", "baked"]);
    let err = failure(&volgen(&args));
    assert!(err.contains("fit or vstar"), "{err}");

    let err = failure(&volgen(&["eval", path(&run)]));
    assert!(err.contains("--dataset"), "{err}");
    let err = failure(&volgen(&[
        "eval",
        path(&run),
        "--dataset",
        path(&data),
        "--views",
        "7",
    ]));
    assert!(err.contains("6 frames"), "{err}");
}

/// The arguments of a small `volgen eval` of `runs` on `data`: 2 scenes from 2 views.
fn small_eval<'a>(runs: &[&'a Path], data: &'a Path) -> Vec<&'a str> {
    let mut args = vec!["eval"];
    args.extend(runs.iter().map(|run| path(run)));
    args.extend(["--dataset", path(data), "--scenes", "2", "--views", "2"]);
    args.extend(["--layout-reference", "vstar"]);
    args
}

/// A run trained with post-activated density has V*'s volume scored the way it renders: raw
/// density activated per sample, not its per-voxel physical density; its files hold physical
/// density on a grid 3x finer, the nearer to its rendering.
#[test]
fn a_post_activated_run_scores_its_volume_as_it_renders() {
    let tmp = tempfile::tempdir().unwrap();
    let data = common::stones_dataset(tmp.path());
    let run = tmp.path().join("post");
    common::train_micro_with(&data, &run, &["--set", "rendering.post_activation=true"]);
    ok(&volgen(&small_eval(&[&run], &data)));
    let volume_psnr = json(&run.join("eval.json"))["volume_psnr"]
        .as_f64()
        .unwrap();
    let (model, _) = singrav::SinGrav::load(&run, &Device::Cpu).unwrap();
    let (volume, density) = model.to_rendered(&model.reconstruct().unwrap()).unwrap();
    assert!(density.post_activation().is_some());
    let expected = rendered_psnr_by_hand(&volume, density, &data);
    assert!(
        (volume_psnr - expected).abs() < 1e-4,
        "eval {volume_psnr} dB, by hand {expected} dB"
    );
    // The per-voxel physical volume renders otherwise (a barely trained micro V* is a smooth
    // fog, so only a little: by 7e-3 dB when this was written).
    let physical = model.to_physical(&model.reconstruct().unwrap()).unwrap();
    let softer = rendered_psnr_by_hand(&physical, volrender::DensityInterpolation::Physical, &data);
    assert!(
        (volume_psnr - softer).abs() > 1e-3,
        "{volume_psnr} vs {softer}"
    );
    // Its samples are written for other tools on a grid 3x finer unless told otherwise
    // (`--upsample`: what other tools render of them comes closer to volgen's own renders).
    let samples = tmp.path().join("samples");
    ok(&volgen(&[
        "sample",
        path(&run),
        "--count",
        "1",
        "--reconstruction",
        "--out",
        path(&samples),
    ]));
    let written = radiance_volume::RadianceVolume::load_safetensors(
        samples.join("reconstruction.safetensors"),
    )
    .unwrap();
    let want = model
        .to_physical_upsampled(&model.reconstruct().unwrap(), 3)
        .unwrap();
    assert_eq!(written.dims(), want.dims());
    let values = |v: &radiance_volume::RadianceVolume| -> Vec<f32> {
        v.tensor().flatten_all().unwrap().to_vec1().unwrap()
    };
    assert_eq!(values(&written), values(&want));
}

#[test]
fn a_holdout_run_reports_held_out_views_and_several_runs_make_one_table() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, run) = train_micro(tmp.path());
    let held = tmp.path().join("held");
    let text = ok(&volgen(&[
        "train",
        path(&data),
        "--out",
        path(&held),
        "--preset",
        "micro",
        "--holdout",
        "3",
        // 24-pixel final views: too small for patch_swd_mv's pyramid.
        "--scales",
        "2",
    ]));
    assert!(text.contains("trained model"), "{text}");
    assert_eq!(json(&held.join("config.json"))["run"]["holdout"], 3);

    // Both runs in one evaluation, with `extra` flags.
    let eval_both = |extra: &[&str]| {
        let mut args = small_eval(&[&run, &held], &data);
        args.extend_from_slice(extra);
        ok(&volgen(&args))
    };
    let text = eval_both(&[]);
    // Frames 0 and 3 of 6 are held out; the reconstruction is seen from 2 of frames 1, 2, 4, 5.
    let report = json(&held.join("eval.json"));
    assert_eq!(report["holdout"], 3);
    assert_eq!(
        report["held_out_views"],
        serde_json::json!(["images/r_000.png", "images/r_003.png"])
    );
    assert_eq!(
        report["reconstruction_views"],
        serde_json::json!(["images/r_001.png", "images/r_004.png"])
    );
    let held_psnr = report["held_out_psnr"].as_f64().unwrap();
    assert!(held_psnr > 5.0 && held_psnr < 40.0, "{held_psnr}");
    assert_eq!(report["image_size"], 24);
    assert!(report["patch_swd_mv"].is_null(), "{report}");
    assert!(report["colour_swd"].as_f64().unwrap() > 0.0);

    // One Markdown table: a header, a rule and a row per run, in the order given.
    let lines: Vec<&str> = text.lines().filter(|l| l.starts_with('|')).collect();
    assert_eq!(lines.len(), 4, "{text}");
    assert!(lines[0].contains("| run | PSNR (dB) | SSIM |") && lines[0].contains("floaters"));
    let cells = |line: &str| -> Vec<String> {
        line.trim_matches('|')
            .split('|')
            .map(|c| c.trim().to_string())
            .collect()
    };
    let (plain, holdout) = (cells(lines[2]), cells(lines[3]));
    assert_eq!(plain.len(), 17, "{text}");
    assert_eq!(plain[0], path(&run));
    assert_eq!(holdout[0], path(&held));
    // No held-out views and no SIFID-MV in the plain run: dashes.
    assert_eq!(
        (plain[5].as_str(), plain[6].as_str(), plain[16].as_str()),
        ("-", "-", "-")
    );
    assert_eq!(holdout[5], format!("{held_psnr:.2}"));
    // The sample metrics with their standard errors over scenes.
    let colour = report["colour_swd"].as_f64().unwrap();
    let colour_error = report["colour_swd_stderr"].as_f64().unwrap();
    assert_eq!(holdout[8], format!("{colour:.4} ± {colour_error:.4}"));
    // Two scenes leave too few for Diversity-MV's jackknife: its value alone.
    assert!(report["diversity_mv_stderr"].is_null(), "{report}");
    let diversity = report["diversity_mv"].as_f64().unwrap();
    assert_eq!(holdout[15], format!("{diversity:.4}"));
    // The layout distance, with its standard error.
    assert_eq!(report["layout_reference"], "vstar");
    let layout = report["layout_distance"].as_f64().unwrap();
    let layout_error = report["layout_distance_stderr"].as_f64().unwrap();
    assert!(layout > 0.0 && layout.is_finite(), "{report}");
    assert_eq!(holdout[10], format!("{layout:.4} ± {layout_error:.4}"));
    // The same by position alone, beside it.
    let by_position = report["layout_distance_by_position"].as_f64().unwrap();
    let by_position_error = report["layout_distance_by_position_stderr"]
        .as_f64()
        .unwrap();
    assert!(by_position > 0.0 && by_position.is_finite(), "{report}");
    assert_eq!(
        holdout[11],
        format!("{by_position:.4} ± {by_position_error:.4}")
    );
    // The share of matter out of place, a share of the volumes' matter, with its error.
    let misplaced = report["misplaced_matter"].as_f64().unwrap();
    let misplaced_error = report["misplaced_matter_stderr"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&misplaced), "{report}");
    assert_eq!(
        holdout[12],
        format!("{misplaced:.4} ± {misplaced_error:.4}")
    );
    // V*'s volume over the 4 training and, separately, the 2 held-out frames.
    let volume_psnr = report["volume_psnr"].as_f64().unwrap();
    assert_eq!(holdout[4], format!("{volume_psnr:.2}"));
    assert_eq!(report["volume_views"], 4);
    let held_volume = report["held_out_volume_psnr"].as_f64().unwrap();
    assert!(held_volume > 5.0 && held_volume < 40.0, "{held_volume}");
    assert_eq!(
        (holdout[7].as_str(), plain[7] != "-"),
        ("-", true),
        "{text}"
    );
    let plain_report = json(&run.join("eval.json"));
    assert_eq!(
        plain[1],
        format!(
            "{:.2}",
            plain_report["reconstruction_psnr"].as_f64().unwrap()
        )
    );

    // --mean ends the table with each number's mean over the runs and its standard error
    // over them: for two values a and b, (a + b) / 2 and |a - b| / 2.
    let text = eval_both(&["--mean"]);
    let lines: Vec<&str> = text.lines().filter(|l| l.starts_with('|')).collect();
    assert_eq!(lines.len(), 5, "{text}");
    let mean_row = cells(lines[4]);
    assert_eq!(mean_row[0], "mean ± s.e. of 2 runs");
    let (a, b) = (
        json(&run.join("eval.json"))["colour_swd"].as_f64().unwrap(),
        json(&held.join("eval.json"))["colour_swd"]
            .as_f64()
            .unwrap(),
    );
    assert_eq!(
        mean_row[8],
        format!("{:.4} ± {:.4}", (a + b) / 2.0, (a - b).abs() / 2.0)
    );
    // Only the held-out run has held-out views: no mean.
    assert_eq!(mean_row[5], "-");
    let err = failure(&volgen(&[
        "eval",
        path(&run),
        "--dataset",
        path(&data),
        "--mean",
    ]));
    assert!(err.contains("--mean needs at least 2 runs"), "{err}");

    // --out is for one run.
    let out = tmp.path().join("both.json");
    let err = failure(&volgen(&[
        "eval",
        path(&run),
        path(&held),
        "--dataset",
        path(&data),
        "--out",
        path(&out),
    ]));
    assert!(err.contains("--out"), "{err}");
    let err = failure(&volgen(&[
        "train",
        path(&data),
        "--out",
        path(&tmp.path().join("bad")),
        "--preset",
        "micro",
        "--holdout",
        "1",
    ]));
    assert!(err.contains("holdout") && err.contains(">= 2"), "{err}");
}

/// `--family N` scores N other layouts of the dataset's built-in scene with the same functions
/// (its own layout, put in the family by hand, scores as the real views do), and `--vary-from`
/// keeps V*'s noise below the given scale, in `eval` as in `sample`.
#[test]
fn the_family_row_scores_other_layouts_and_vary_from_is_checked() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, run) = train_micro(tmp.path());
    let mut args = small_eval(&[&run], &data);
    args.extend(["--family", "2"]);
    let text = ok(&volgen(&args));
    assert!(
        text.contains("family: 2 other layouts of the built-in `stones` scene (seeds 1..=2)"),
        "{text}"
    );
    let family = json(&run.join("eval.json"))["family"].clone();
    assert_eq!(family["scene"], "stones");
    assert_eq!(family["seeds"], serde_json::json!([1, 2]));
    for key in [
        "colour_swd",
        "floaters",
        "layout_distance",
        "layout_distance_by_position",
        "misplaced_matter",
        "diversity_mv",
    ] {
        let value = family[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key}: {family}"));
        assert!(value.is_finite() && value >= 0.0, "{key}: {family}");
    }

    // A record whose seed comes just before the dataset's own (0): the family's one layout is
    // the dataset's scene, seen as its files show it but for their 8-bit rounding.
    let transforms = data.join("transforms.json");
    let mut record = json(&transforms);
    assert_eq!(record["volgen_scene"]["seed"], 0);
    record["volgen_scene"]["seed"] = serde_json::json!(u64::MAX);
    std::fs::write(&transforms, record.to_string()).unwrap();
    let mut args = small_eval(&[&run], &data);
    args.extend(["--family", "1"]);
    ok(&volgen(&args));
    let family = json(&run.join("eval.json"))["family"].clone();
    assert_eq!(family["seeds"], serde_json::json!([0]));
    let colour = family["colour_swd"].as_f64().unwrap();
    let floaters = family["floaters"].as_f64().unwrap();
    assert!(colour < 2e-3 && floaters < 1e-3, "{family}");

    // Two runs: one table, the family's row last, dashes where V*'s numbers stand.
    let mut args = small_eval(&[&run, &run], &data);
    args.extend(["--family", "1"]);
    let text = ok(&volgen(&args));
    let lines: Vec<&str> = text.lines().filter(|l| l.starts_with('|')).collect();
    assert_eq!(lines.len(), 5, "{text}");
    assert!(
        lines[4].starts_with("| family: 1 other layouts of `stones` | - |"),
        "{text}"
    );
    assert_eq!(lines[4].matches('|').count(), 18, "{text}");

    // A dataset that records no built-in scene has no family.
    record.as_object_mut().unwrap().remove("volgen_scene");
    std::fs::write(&transforms, record.to_string()).unwrap();
    let err = failure(&volgen(&args));
    assert!(err.contains("volgen_scene"), "{err}");
    // A malformed record names the file and the field.
    record["volgen_scene"] = serde_json::json!({"name": "forest", "seed": 1, "grid": 8});
    std::fs::write(&transforms, record.to_string()).unwrap();
    let err = failure(&volgen(&small_eval(&[&run], &data)));
    assert!(
        err.contains("transforms.json") && err.contains("volgen_scene"),
        "{err}"
    );
    record.as_object_mut().unwrap().remove("volgen_scene");
    std::fs::write(&transforms, record.to_string()).unwrap();

    // --vary-from: recorded in eval.json, and refused beyond the model's 3D scales (micro: 2).
    let mut args = small_eval(&[&run], &data);
    args.extend(["--vary-from", "2"]);
    let text = ok(&volgen(&args));
    assert!(text.contains("scenes vary from 3D scale 2"), "{text}");
    assert_eq!(json(&run.join("eval.json"))["vary_from"], 2);
    let mut args = small_eval(&[&run], &data);
    args.extend(["--vary-from", "3"]);
    let err = failure(&volgen(&args));
    assert!(err.contains("vary_from") && err.contains("1 to 2"), "{err}");
    let out = tmp.path().join("kept");
    let sample = |vary_from: &str| {
        volgen(&[
            "sample",
            path(&run),
            "--count",
            "2",
            "--vary-from",
            vary_from,
            "--out",
            path(&out),
        ])
    };
    ok(&sample("2"));
    assert!(out.join("scene_1.safetensors").is_file());
    let err = failure(&sample("0"));
    assert!(
        err.contains("--vary-from") && err.contains("1 to 2"),
        "{err}"
    );
}
