//! `volgen eval` on a `micro` run: Diversity-MV always, SIFID-MV with (generated) InceptionV3
//! weights, the same numbers for the same seed, and clear errors for bad input.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use rand::{Rng, SeedableRng};
use singrav::metrics::InceptionBlock1;

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
    ];

    let text = ok(&volgen(&base));
    let diversity = number_after(&text, "Diversity-MV:");
    assert!(diversity.is_finite() && diversity > 0.0, "{text}");
    assert!(
        text.contains("SIFID-MV:     not computed") && text.contains("--inception"),
        "{text}"
    );
    let report = json(&run.join("eval.json"));
    // The JSON has every digit, the text four decimals.
    let exact = report["diversity_mv"].as_f64().unwrap();
    assert!((exact - diversity).abs() <= 5e-5, "{exact} vs {diversity}");
    assert!(report["sifid_mv"].is_null());
    assert_eq!(report["image_size"], 36, "micro's final images");
    assert_eq!(
        report["views"],
        serde_json::json!(["images/r_000.png", "images/r_003.png"])
    );

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
