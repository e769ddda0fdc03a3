//! `volgen device-check` on the CPU: the device forms (the portable renderer, conv3d over
//! slices, the active set's dense form) against the CPU kernels, a `micro` training on "both"
//! devices, one scale of `paper` timed, the budget stopping a training, and its refusals. On
//! a GPU machine the same command runs with `--device cuda` (tools/gpu/check.sh).

mod common;

use std::path::Path;
use std::process::Output;

use common::{failure, path, volgen};
use serde_json::Value;

/// `volgen device-check --device cpu --work WORK` with `args`.
fn device_check(work: &Path, args: &[&str]) -> Output {
    let mut all = vec!["device-check", "--device", "cpu", "--work", path(work)];
    all.extend_from_slice(args);
    volgen(&all)
}

fn lines(stdout: &[u8]) -> Vec<Value> {
    String::from_utf8_lossy(stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect()
}

#[test]
fn every_check_but_tiny_passes_on_the_cpu_with_one_json_line_each() {
    let work = tempfile::tempdir().unwrap();
    let out = device_check(
        work.path(),
        &[
            "--checks",
            "render,conv3d,generator,active-set,critic,micro-training,paper-iterations",
            "--paper-scales",
            "1",
        ],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let lines = lines(&out.stdout);
    let names: Vec<&str> = lines.iter().map(|l| l["check"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "render",
            "conv3d",
            "generator",
            "active-set",
            "critic",
            "micro-training",
            "paper-iterations"
        ]
    );
    for line in &lines {
        assert_eq!(line["ok"], Value::Bool(true), "{line}");
        assert_eq!(line["device"], "cpu");
        assert!(line["seconds"].as_f64().unwrap() >= 0.0);
    }
    // The device forms really differ from the kernels (other sums), and agree to 1e-5 on
    // the CPU: the checks compare, they do not run one path twice.
    for (line, field, limit) in [
        (&lines[0], "max_error", 1e-5),
        (&lines[1], "max_error", 1e-5),
        (&lines[3], "values_max_error", 1e-4),
        (&lines[3], "gradients_max_error", 1e-4),
    ] {
        let error = line[field].as_f64().unwrap();
        assert!(error > 0.0 && error < limit, "{field}: {line}");
    }
    assert_eq!(lines[5]["iterations"], 12, "micro: 3 scales of 4");
    assert_eq!(lines[5]["first_step_max_relative_difference"], 0.0);
    let scales = lines[6]["scales"].as_array().unwrap();
    assert_eq!(scales.len(), 1);
    assert_eq!(scales[0]["volume"], 40);
    assert!(scales[0]["iteration_s"].as_f64().unwrap() > 0.0);
    // A GPU's memory in use is reported per scale; the CPU has none to report.
    assert!(scales[0]["device_memory_mib"].is_null(), "{}", scales[0]);
}

#[test]
fn the_budget_stops_a_training_and_skips_what_is_left() {
    let work = tempfile::tempdir().unwrap();
    let out = device_check(
        work.path(),
        &[
            "--checks",
            "paper-iterations,tiny-training",
            "--paper-iterations",
            "3",
            "--budget-seconds",
            "1",
        ],
    );
    let err = failure(&out);
    assert!(
        err.contains("2 check(s) failed or did not run on cpu"),
        "{err}"
    );
    let lines = lines(&out.stdout);
    assert_eq!(lines.len(), 2);
    // Paper's dataset takes longer than the budget: its first iteration ends the run.
    assert_eq!(lines[0]["ok"], false);
    assert_eq!(lines[0]["stopped"], "the budget is spent");
    assert_eq!(lines[0]["scales"].as_array().unwrap().len(), 1);
    assert_eq!(lines[1]["ok"], Value::Null);
    assert_eq!(lines[1]["skipped"], "the budget is spent");
}

#[test]
fn bad_arguments_are_refused_by_name() {
    let err = failure(&volgen(&[
        "device-check",
        "--device",
        "cpu",
        "--checks",
        "render,warp",
    ]));
    assert!(
        err.contains("unknown check `warp`") && err.contains("micro-training"),
        "{err}"
    );
    let err = failure(&volgen(&["device-check", "--device", "tpu"]));
    assert!(
        err.contains("expected cpu, cuda or cuda:N, got `tpu`"),
        "{err}"
    );
    let err = failure(&volgen(&[
        "device-check",
        "--device",
        "cpu",
        "--paper-iterations",
        "0",
    ]));
    assert!(
        err.contains("--paper-iterations: expected at least 1"),
        "{err}"
    );
    #[cfg(not(feature = "cuda"))]
    {
        let err = failure(&volgen(&["device-check"]));
        assert!(
            err.contains("built without the `cuda` feature") && err.contains("tools/gpu/build.sh"),
            "{err}"
        );
    }
}
