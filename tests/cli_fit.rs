//! `volgen fit` and `volgen train --fitted / --fit` end to end: the files they promise, read
//! back (the VDB through vdb-rs), the PSNR report, the run's record of the fitted volume, and
//! clear errors.

use radiance_volume::RadianceVolume;

mod common;
use common::{assert_vdb_matches, failure, ok, path, stones_dataset, train_micro_with, volgen};

#[test]
fn fit_writes_the_volume_its_views_and_a_psnr_report() {
    let tmp = tempfile::tempdir().unwrap();
    let data = stones_dataset(tmp.path());
    let out = tmp.path().join("fit/stones.safetensors");
    let text = ok(&volgen(&[
        "fit",
        path(&data),
        "--size",
        "16",
        "--steps",
        "80",
        "--rays",
        "2048",
        "--holdout",
        "3",
        "--out",
        path(&out),
        "--vdb",
        path(&tmp.path().join("fit/stones.vdb")),
        "--exr-slices",
        path(&tmp.path().join("fit/exr")),
    ]));
    assert!(
        text.contains("over 4 training views") && text.contains("over 2 held-out views"),
        "{text}"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("fit/stones.fit.json")).unwrap())
            .unwrap();
    assert_eq!(report["steps"], 80);
    assert_eq!(report["size"], 16);
    // Measured: about 22 dB after 80 steps; an untrained grey fog scores about 9.
    let psnr = report["training_psnr"].as_f64().unwrap();
    assert!(psnr > 16.0, "{report}");
    assert!(report["held_out_psnr"].as_f64().unwrap() > 12.0, "{report}");
    let views = report["views"].as_array().unwrap();
    assert_eq!(views.len(), 6);
    assert_eq!(views[4]["file_path"], "images/r_000.png");
    assert_eq!(views[4]["held_out"], true);
    let volume = RadianceVolume::load_safetensors(&out).unwrap();
    assert_eq!(volume.dims().xyz(), [16, 16, 16]);
    assert_vdb_matches(&volume, &tmp.path().join("fit/stones.vdb"));
    assert!(tmp.path().join("fit/exr/stones.json").is_file());
    let picture = image::open(tmp.path().join("fit/stones.png")).unwrap();
    // Two rows (real, fitted) of three 36-pixel views, with 2-pixel gaps around each.
    assert_eq!(
        (picture.width(), picture.height()),
        (3 * 36 + 4 * 2, 2 * 36 + 3 * 2)
    );

    // A post-activated fit writes its files on a grid 3x finer unless told otherwise
    // (docs/formats.md: other tools then render it as the fit does); even factors are refused.
    let fit_post = |name: &str, extra: &[&str]| {
        let out = tmp.path().join(format!("post/{name}.safetensors"));
        let vdb = tmp.path().join(format!("post/{name}.vdb"));
        let mut args = vec![
            "fit",
            path(&data),
            "--size",
            "8",
            "--steps",
            "5",
            "--post-activation",
            "--out",
            path(&out),
            "--vdb",
            path(&vdb),
        ];
        args.extend_from_slice(extra);
        let result = volgen(&args);
        (result, out, vdb)
    };
    let (result, out3, vdb3) = fit_post("default", &[]);
    ok(&result);
    let fine = RadianceVolume::load_safetensors(&out3).unwrap();
    assert_eq!(fine.dims().xyz(), [24, 24, 24]);
    assert_vdb_matches(&fine, &vdb3);
    let (result, out1, _) = fit_post("coarse", &["--upsample", "1"]);
    ok(&result);
    let coarse = RadianceVolume::load_safetensors(&out1).unwrap();
    assert_eq!(coarse.dims().xyz(), [8, 8, 8]);
    // The same seeded fit: every third fine voxel sits on a coarse centre and holds its
    // physical value (density activated from the raw grid, colour as it is).
    let values =
        |v: &RadianceVolume| -> Vec<f32> { v.tensor().flatten_all().unwrap().to_vec1().unwrap() };
    let (fine_values, coarse_values) = (values(&fine), values(&coarse));
    for (i, &want) in coarse_values.iter().enumerate() {
        let (c, z, y, x) = (i / 512, i / 64 % 8, i / 8 % 8, i % 8);
        let got = fine_values[((c * 24 + 3 * z + 1) * 24 + 3 * y + 1) * 24 + 3 * x + 1];
        assert!(
            (got - want).abs() <= 1e-5 * (1.0 + want.abs()),
            "channel {c} voxel ({z}, {y}, {x}): {got} vs {want}"
        );
    }
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out3.with_extension("fit.json")).unwrap()).unwrap();
    assert_eq!(
        (report["size"].clone(), report["upsample"].clone()),
        (8.into(), 3.into())
    );
    let err = failure(&fit_post("even", &["--upsample", "4"]).0);
    assert!(err.contains("--upsample") && err.contains("odd"), "{err}");

    // Train against it: the log has the 3D term, the run keeps a copy and records the weight.
    let run = tmp.path().join("run");
    train_micro_with(
        &data,
        &run,
        &["--fitted", path(&out), "--lambda-fitted", "5"],
    );
    let config: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["losses"]["fitted"], 5.0);
    assert!(run.join("fitted.safetensors").is_file());
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    let first: serde_json::Value = serde_json::from_str(log.lines().next().unwrap()).unwrap();
    assert!(first.to_string().contains("\"fitted\":"), "{first}");
    assert!(
        log.lines()
            .filter(|l| l.contains("\"fitted\":null"))
            .count()
            < log.lines().count()
    );
    // A resume uses the run's own copy: the original file may be gone, and --fit does not
    // fit again.
    std::fs::rename(&out, tmp.path().join("moved.safetensors")).unwrap();
    train_micro_with(&data, &run, &["--fit", "--lambda-fitted", "5", "--resume"]);
    let kept = RadianceVolume::load_safetensors(run.join("fitted.safetensors")).unwrap();
    assert_eq!(
        kept.dims().xyz(),
        [16, 16, 16],
        "the copy of the 16^3 fit, not a new fit"
    );

    // --fit fits first, into the run.
    let run2 = tmp.path().join("run2");
    train_micro_with(&data, &run2, &["--fit", "--fit-steps", "5"]);
    let fitted = RadianceVolume::load_safetensors(run2.join("fitted.safetensors")).unwrap();
    assert_eq!(
        fitted.dims().xyz(),
        [22, 22, 22],
        "twice micro's finest 11^3"
    );
    // A post-activated run compares raw density, which resampling a finer grid would average:
    // its fit is the finest scale's own grid, and the log has the 3D term.
    let run5 = tmp.path().join("run5");
    let post = [
        "--fit",
        "--fit-steps",
        "5",
        "--set",
        "rendering.post_activation=true",
    ];
    train_micro_with(&data, &run5, &post);
    let fitted = RadianceVolume::load_safetensors(run5.join("fitted.safetensors")).unwrap();
    assert_eq!(fitted.dims().xyz(), [11, 11, 11], "micro's finest 11^3");
    let log = std::fs::read_to_string(run5.join("log.jsonl")).unwrap();
    assert!(log.lines().any(|l| !l.contains("\"fitted\":null")), "{log}");

    // A 3D critic judges the samples against the fitted volume, here without the 3D
    // comparison of the reconstruction: recorded in the run, logged at the 3D scales.
    let run3 = tmp.path().join("run3");
    let moved = tmp.path().join("moved.safetensors");
    let args = [
        "--fitted",
        path(&moved),
        "--lambda-fitted",
        "0",
        "--lambda-volume-critic",
        "0.5",
    ];
    train_micro_with(&data, &run3, &args);
    let config: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run3.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["losses"]["volume_critic"], 0.5);
    assert_eq!(config["critics"]["volume_colour"], false);
    let log = std::fs::read_to_string(run3.join("log.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(lines.iter().all(|l| l["fitted"].is_null()));
    assert!(lines.iter().any(|l| l["volume_critic"].is_f64()));
    // A configuration that compares with a fitted volume and is given none fits one first,
    // as `tiny` does.
    let run4 = tmp.path().join("run4");
    train_micro_with(&data, &run4, &["--set", "losses.fitted=2"]);
    let fitted = RadianceVolume::load_safetensors(run4.join("fitted.safetensors")).unwrap();
    assert_eq!(fitted.dims().xyz(), [22, 22, 22]);
}

#[test]
fn fit_names_bad_input() {
    let tmp = tempfile::tempdir().unwrap();
    let err = failure(&volgen(&[
        "fit",
        path(&tmp.path().join("nowhere")),
        "--out",
        path(&tmp.path().join("v.safetensors")),
    ]));
    assert!(err.contains("nowhere"), "{err}");
    let data = stones_dataset(tmp.path());
    let run = |extra: &[&str]| {
        let mut args = vec!["fit", path(&data), "--steps", "2", "--size", "8"];
        args.extend_from_slice(extra);
        failure(&volgen(&args))
    };
    let out = tmp.path().join("v.safetensors");
    let err = run(&["--out", path(&out), "--holdout", "1"]);
    assert!(err.contains("holdout") && err.contains("N >= 2"), "{err}");
    let err = run(&["--out", path(&tmp.path().join("v.vdb"))]);
    assert!(
        err.contains("v.vdb") && err.contains(".safetensors"),
        "{err}"
    );
    let err = run(&["--out", path(&out), "--start-size", "1"]);
    assert!(err.contains("start_size"), "{err}");
    let err = run(&["--out", path(&out), "--seconds", "3"]);
    assert!(
        err.contains("--seconds") && err.contains("--steps"),
        "{err}"
    );
    // A fitted volume must be [-1, 1]^3 and cubic, and --fitted needs a file that exists.
    let err = failure(&volgen(&[
        "train",
        path(&data),
        "--out",
        path(&tmp.path().join("r")),
        "--preset",
        "micro",
        "--fitted",
        path(&tmp.path().join("missing.safetensors")),
    ]));
    assert!(err.contains("missing.safetensors"), "{err}");
}

/// A dataset that does not say how its depth maps measure depth (as Blender's exporters write
/// them): the kind is asked for only where the depth is used, so `--no-depth` needs none, for
/// `fit` as for `train`.
#[test]
fn without_depth_no_depth_kind_is_asked_for() {
    let tmp = tempfile::tempdir().unwrap();
    let data = stones_dataset(tmp.path());
    let transforms = data.join("transforms.json");
    let mut root: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&transforms).unwrap()).unwrap();
    root.as_object_mut().unwrap().remove("depth_kind");
    std::fs::write(&transforms, root.to_string()).unwrap();
    let out = tmp.path().join("v.safetensors");
    let fit = |extra: &[&str]| {
        let mut args = vec!["fit", path(&data), "--steps", "2", "--size", "8"];
        args.extend_from_slice(&["--out", path(&out)]);
        args.extend_from_slice(extra);
        volgen(&args)
    };
    let err = failure(&fit(&[]));
    assert!(err.contains("--depth-kind"), "{err}");
    ok(&fit(&["--no-depth"]));
    let train = |extra: &[&str]| {
        let mut args = vec![
            "train",
            path(&data),
            "--preset",
            "micro",
            "--iterations",
            "1",
        ];
        args.extend_from_slice(extra);
        volgen(&args)
    };
    let run = tmp.path().join("run");
    let err = failure(&train(&["--out", path(&run)]));
    assert!(err.contains("--depth-kind"), "{err}");
    ok(&train(&["--out", path(&run), "--no-depth"]));
}
