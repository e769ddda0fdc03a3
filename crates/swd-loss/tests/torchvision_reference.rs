//! VGG-19 features against torchvision's own `vgg19(weights=None)` (random weights, stored as
//! float16, biases made random), run in float64 in Heitz et al.'s setting (ImageNet
//! normalisation, reflect padding, average pooling): relu1_1, relu1_2 and relu2_1 to 1e-4
//! relative. The file comes from `crates/singrav/tests/data/torchvision_reference.py`.

use candle_core::{DType, Device, Tensor};
use swd_loss::{FeatureExtractor, Vgg19, Vgg19Config, VggLayer};

#[test]
fn heitz_features_match_torchvision() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/vgg19_torchvision.safetensors"
    );
    let config = Vgg19Config {
        layers: vec![
            VggLayer::relu(1, 1).unwrap(),
            VggLayer::relu(1, 2).unwrap(),
            VggLayer::relu(2, 1).unwrap(),
        ],
        ..Vgg19Config::heitz()
    };
    let vgg = Vgg19::from_safetensors(path, config, &Device::Cpu).unwrap();
    let tensors = candle_core::safetensors::load(path, &Device::Cpu).unwrap();
    let image: Tensor = (tensors["test.image_u8"].to_dtype(DType::F32).unwrap() / 255.0).unwrap();
    let maps = vgg.extract(&image).unwrap();
    for (map, name) in maps.iter().zip(["relu1_1", "relu1_2", "relu2_1"]) {
        let want = &tensors[&format!("test.{name}")];
        assert_eq!(map.values.dims(), want.dims(), "{name}");
        let got: Vec<f32> = map.values.flatten_all().unwrap().to_vec1().unwrap();
        let want: Vec<f32> = want.flatten_all().unwrap().to_vec1().unwrap();
        // Every feature within 1e-4 of the largest (float32 here, float64 in the reference).
        let scale = want.iter().fold(0f32, |m, w| m.max(w.abs()));
        let worst = got
            .iter()
            .zip(&want)
            .map(|(g, w)| (g - w).abs())
            .fold(0f32, f32::max);
        assert!(worst <= 1e-4 * scale, "{name}: {worst} against {scale}");
        assert!(scale > 0.1, "{name}: features too small to test ({scale})");
    }
}
