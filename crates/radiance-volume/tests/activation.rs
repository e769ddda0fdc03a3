//! The raw -> physical activation against a float64 reference, at extreme inputs too.

use candle_core::{Device, Tensor};
use radiance_volume::{Aabb, Activation, RadianceVolume};

fn softplus64(x: f64) -> f64 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}

#[test]
fn activation_matches_float64_and_stays_in_range() {
    let raw_vals = [
        -1e30f32, -200.0, -20.0, -1.0, -1e-7, 0.0, 1e-7, 1.0, 20.0, 200.0, 1e30,
    ];
    let n = raw_vals.len();
    let mut data = Vec::new();
    for _ in 0..5 {
        data.extend_from_slice(&raw_vals);
    }
    let raw = Tensor::from_vec(data, (5, 1, 1, n), &Device::Cpu).unwrap();
    let act = Activation::default()
        .with_density_shift(-1.0)
        .with_density_scale(3.0);
    let v = RadianceVolume::from_raw(&raw, Aabb::CUBE, &act).unwrap();
    let out: Vec<f32> = v.tensor().flatten_all().unwrap().to_vec1().unwrap();
    for (i, &r) in raw_vals.iter().enumerate() {
        let r64 = f64::from(r);
        let sigma = out[i];
        let want = 3.0 * softplus64(r64 - 1.0);
        assert!(sigma.is_finite() && sigma >= 0.0, "sigma({r}) = {sigma}");
        assert!(
            (f64::from(sigma) - want).abs() <= 1e-6 * want.max(1.0),
            "sigma({r}) = {sigma}, want {want}"
        );
        for c in 1..4 {
            let rgb = out[c * n + i];
            let want = 1.0 / (1.0 + (-r64).exp());
            assert!((0.0..=1.0).contains(&rgb), "rgb({r}) = {rgb}");
            assert!(
                (f64::from(rgb) - want).abs() < 1e-6,
                "rgb({r}) = {rgb}, want {want}"
            );
        }
        // Feature channels pass through.
        assert_eq!(out[4 * n + i], r);
    }
}

#[test]
fn activation_accepts_batches_and_rejects_bad_shapes() {
    let raw = Tensor::zeros((2, 4, 3, 3, 3), candle_core::DType::F32, &Device::Cpu).unwrap();
    let out = Activation::default().apply(&raw).unwrap();
    assert_eq!(out.dims(), &[2, 4, 3, 3, 3]);
    let three = Tensor::zeros((3, 2, 2, 2), candle_core::DType::F32, &Device::Cpu).unwrap();
    assert!(Activation::default().apply(&three).is_err());
    let flat = Tensor::zeros((4, 2), candle_core::DType::F32, &Device::Cpu).unwrap();
    assert!(Activation::default().apply(&flat).is_err());
}
