//! `volgen demo`, `train` and `sample` end to end with the `micro` preset: the files they promise
//! exist and load, VDB files read back through vdb-rs, a killed-free resume is a no-op, and bad
//! input is a clear error.

use std::path::Path;
use std::process::{Command, Output};

use radiance_volume::RadianceVolume;

fn volgen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volgen"))
        .args(args)
        .output()
        .expect("volgen runs")
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn demo_writes_dataset_model_samples_pictures_and_summary() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let args = [
        "demo",
        "--out",
        path(&out),
        "--preset",
        "micro",
        "--views",
        "6",
        "--resolution",
        "36",
        "--count",
        "2",
    ];
    let text = ok(&volgen(&args));
    assert!(
        text.contains("overview.png") && text.contains("summary.md"),
        "{text}"
    );
    assert!(text.contains("generated in"), "{text}");
    for file in [
        "dataset/transforms.json",
        "run/checkpoint.safetensors",
        "run/config.json",
        "run/log.jsonl",
        "run/samples/scale_3.png",
        "samples/scene_0.safetensors",
        "samples/scene_1.png",
        "summary.md",
        "summary.json",
    ] {
        assert!(out.join(file).is_file(), "missing {file}");
    }
    // The overview: one row of input views and one per scene, three views each.
    let overview = image::open(out.join("overview.png")).unwrap();
    assert!(overview.height() > overview.width() / 3 * 2 / 3);
    // The VDB export reads back through an independent reader and matches the volume.
    let volume = RadianceVolume::load_safetensors(out.join("samples/scene_0.safetensors")).unwrap();
    let from_vdb =
        RadianceVolume::read_vdb(out.join("samples/scene_0.vdb"), volume.grid()).unwrap();
    let density = |v: &RadianceVolume| -> Vec<f32> {
        v.density()
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap()
    };
    let (written, read) = (density(&volume), density(&from_vdb));
    let worst = written
        .iter()
        .zip(&read)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(
        worst <= 1e-5 * written.iter().fold(1f32, |m, v| m.max(*v)),
        "density differs by {worst}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["scale_seconds"].as_array().unwrap().len(), 3);

    // Sampling the trained run again with the same seed gives the same scenes.
    let again = tmp.path().join("again");
    let text = ok(&volgen(&[
        "sample",
        path(&out.join("run")),
        "--count",
        "2",
        "--out",
        path(&again),
        "--exr-slices",
    ]));
    assert!(text.contains("scene 1: generated in"), "{text}");
    let a = RadianceVolume::load_safetensors(again.join("scene_0.safetensors")).unwrap();
    assert!(again.join("scene_0_exr").is_dir());
    let values =
        |v: &RadianceVolume| -> Vec<f32> { v.tensor().flatten_all().unwrap().to_vec1().unwrap() };
    assert_eq!(
        values(&a),
        values(&volume),
        "same model, same seed, same scene"
    );

    // A finished run resumes as a no-op; training it afresh is refused rather than overwritten.
    let dataset = out.join("dataset");
    let run = out.join("run");
    ok(&volgen(&[
        "train",
        path(&dataset),
        "--out",
        path(&run),
        "--preset",
        "micro",
        "--resume",
    ]));
    let refused = volgen(&[
        "train",
        path(&dataset),
        "--out",
        path(&run),
        "--preset",
        "micro",
    ]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--resume"));
}

#[test]
fn train_and_sample_report_bad_input_clearly() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = volgen(&[
        "train",
        path(&tmp.path().join("nowhere")),
        "--out",
        path(tmp.path()),
    ]);
    assert!(!missing.status.success());
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(
        err.contains("nowhere") && !err.contains("panicked"),
        "{err}"
    );

    let preset = volgen(&[
        "train",
        path(tmp.path()),
        "--out",
        path(tmp.path()),
        "--preset",
        "huge",
    ]);
    let err = String::from_utf8_lossy(&preset.stderr);
    assert!(err.contains("huge") && err.contains("tiny"), "{err}");

    let no_model = volgen(&[
        "sample",
        path(tmp.path()),
        "--out",
        path(&tmp.path().join("s")),
    ]);
    let err = String::from_utf8_lossy(&no_model.stderr);
    assert!(
        !no_model.status.success() && err.contains("checkpoint"),
        "{err}"
    );
}

#[test]
fn scene_writes_a_loadable_dataset_and_rejects_unknown_names() {
    let tmp = tempfile::tempdir().unwrap();
    for name in ["stones", "mushrooms", "islands"] {
        let dir = tmp.path().join(name);
        let text = ok(&volgen(&[
            "scene",
            name,
            "--out",
            path(&dir),
            "--views",
            "4",
            "--resolution",
            "16",
            "--grid",
            "24",
        ]));
        assert!(
            text.contains("wrote 4 views") && text.contains("transforms.json"),
            "{text}"
        );
        let data = singrav::dataset::Dataset::load(&dir, [1.0; 3]).unwrap();
        assert_eq!((data.len(), data.width(), data.height()), (4, 16, 16));
    }
    let bad = volgen(&["scene", "volcano", "--out", path(tmp.path())]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("volcano") && err.contains("mushrooms") && err.contains("islands"),
        "{err}"
    );
}
