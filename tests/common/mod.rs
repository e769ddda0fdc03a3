//! Helpers shared by the CLI tests: run the `volgen` binary and check how it ended.

// Each test binary compiles this module and uses a different part of it.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

pub mod view;

/// Runs the `volgen` binary built for these tests.
pub fn volgen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volgen"))
        .args(args)
        .output()
        .expect("volgen runs")
}

/// The stdout of a run that must succeed (both streams shown if it did not).
pub fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The stderr of a run that must fail without panicking.
pub fn failure(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "should have failed: {err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// A path as a command-line argument.
pub fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Renders a tiny stones dataset (6 views at 36^2) into `root/data`; returns its directory.
pub fn stones_dataset(root: &Path) -> std::path::PathBuf {
    let data = root.join("data");
    ok(&volgen(&[
        "scene",
        "stones",
        "--out",
        path(&data),
        "--views",
        "6",
        "--resolution",
        "36",
        "--grid",
        "32",
    ]));
    data
}

/// Renders a tiny stones dataset (6 views at 36^2) into `root/data` and trains the `micro`
/// preset on it into `root/run`; returns `(data, run)`.
pub fn train_micro(root: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let (data, run) = (stones_dataset(root), root.join("run"));
    train_micro_with(&data, &run, &[]);
    (data, run)
}

/// Trains the `micro` preset on `data` into `run` with `extra` arguments; returns stdout.
pub fn train_micro_with(data: &Path, run: &Path, extra: &[&str]) -> String {
    let mut args = vec!["train", path(data), "--out", path(run), "--preset", "micro"];
    args.extend_from_slice(extra);
    ok(&volgen(&args))
}

/// Asserts that the VDB file `vdb` holds the density of `volume` (read back through vdb-rs, an
/// independent reader), to 1e-5 of its largest value.
pub fn assert_vdb_matches(volume: &radiance_volume::RadianceVolume, vdb: &Path) {
    let from_vdb = radiance_volume::RadianceVolume::read_vdb(vdb, volume.grid()).unwrap();
    let density = |v: &radiance_volume::RadianceVolume| -> Vec<f32> {
        v.density()
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap()
    };
    let (written, read) = (density(volume), density(&from_vdb));
    let worst = written
        .iter()
        .zip(&read)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(
        worst <= 1e-5 * written.iter().fold(1f32, |m, v| m.max(*v)),
        "{}: density differs by {worst}",
        vdb.display()
    );
}
