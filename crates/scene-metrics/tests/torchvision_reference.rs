//! SIFID against SinGAN's `sifid_score.py` running on torchvision's own InceptionV3 (random
//! weights, random BatchNorm statistics): the block's features and the SIFID values, to 1e-4
//! relative. The file and the values come from `data/torchvision_reference.py`.

use std::collections::HashMap;
use std::path::PathBuf;

use candle_core::{DType, Device, Tensor};
use scene_metrics::{sifid, sifid_mv, InceptionBlock1};

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// `|got - want| <= tol * |want|`.
fn assert_rel(got: f64, want: f64, tol: f64, what: &str) {
    assert!(
        (got - want).abs() <= tol * want.abs(),
        "{what}: {got} vs {want} (relative {:.2e})",
        (got - want).abs() / want.abs()
    );
}

/// 8-bit images of the reference file as `sifid_score.py` feeds them: divided by 255.
fn unit(tensors: &HashMap<String, Tensor>, name: &str) -> Tensor {
    (tensors[name].to_dtype(DType::F32).unwrap() / 255.0).unwrap()
}

#[test]
fn inception_features_and_sifid_match_torchvision_and_scipy() {
    let path = data("sifid_reference.safetensors");
    let block = InceptionBlock1::from_safetensors(&path, &Device::Cpu).unwrap();
    let tensors = candle_core::safetensors::load(&path, &Device::Cpu).unwrap();
    let (real, fake) = (
        unit(&tensors, "test.real_u8"),
        unit(&tensors, "test.fake_u8"),
    );
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("sifid_reference.json")).unwrap())
            .unwrap();

    for v in 0..2 {
        // Every feature within 1e-4 of the largest (float32 here, float64 in the reference).
        let got: Vec<f32> = block
            .features(&real.narrow(0, v, 1).unwrap())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let want: Vec<f32> = tensors[&format!("test.features_real_{v}")]
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        assert_eq!(got.len(), 64 * 14 * 14, "64 x 64 images give 14 x 14 maps");
        let scale = want.iter().fold(0f32, |m, w| m.max(w.abs()));
        let worst = got
            .iter()
            .zip(&want)
            .map(|(g, w)| (g - w).abs())
            .fold(0f32, f32::max);
        assert!(worst <= 1e-4 * scale, "view {v}: {worst} against {scale}");

        let d = sifid(&real.get(v).unwrap(), &fake.get(v).unwrap(), &block).unwrap();
        let want = reference["sifid_per_view"][v].as_f64().unwrap();
        assert_rel(d, want, 1e-4, &format!("SIFID of view {v}"));
    }
    let mv = sifid_mv(&[fake], &real, &block).unwrap();
    assert_rel(
        mv,
        reference["sifid_mv"].as_f64().unwrap(),
        1e-4,
        "SIFID-MV",
    );
}
