//! The strip of training views: the dataset's images (composited on the model's background,
//! as training sees them) as PNG, each with its camera, so the page can show a scene from the
//! camera of a training view beside that view.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use axum::body::Bytes;
use image::ImageEncoder;
use rgbd_dataset::Dataset;
use serde_json::json;
use volrender::Camera;

/// One training view: its image as PNG and its camera.
pub struct TrainingView {
    pub png: Bytes,
    pub camera: Camera,
}

/// The training views of the dataset `dir` (composited on `background`), as PNG.
pub fn load(dir: &Path, background: [f32; 3]) -> Result<Vec<TrainingView>> {
    let data = Dataset::load(dir, background)
        .with_context(|| format!("loading the training views of {}", dir.display()))?;
    let level = data.level(data.width(), data.height(), &candle_core::Device::Cpu)?;
    let (width, height) = (data.width(), data.height());
    let pixels: Vec<f32> = level.images.flatten_all()?.to_vec1()?;
    let plane = width * height;
    level
        .cameras
        .iter()
        .enumerate()
        .map(|(v, camera)| {
            // Channel-major (3, h, w) to interleaved 8-bit RGB, as volgen writes its PNGs.
            let image = &pixels[v * 3 * plane..(v + 1) * 3 * plane];
            let rgb: Vec<u8> = (0..plane)
                .flat_map(|p| (0..3).map(move |c| image[c * plane + p]))
                .map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect();
            let mut png = Vec::new();
            image::codecs::png::PngEncoder::new(&mut png).write_image(
                &rgb,
                width as u32,
                height as u32,
                image::ExtendedColorType::Rgb8,
            )?;
            Ok(TrainingView {
                png: Bytes::from(png),
                camera: *camera,
            })
        })
        .collect()
}

/// The dataset beside a model at `run` (its directory or checkpoint): the `dataset` directory
/// beside the run directory, where `volgen demo` writes it, when it has a `transforms.json`.
pub fn dataset_beside(run: &Path) -> Option<PathBuf> {
    let run_dir = if run.is_dir() { run } else { run.parent()? };
    let beside = run_dir.canonicalize().ok()?.parent()?.join("dataset");
    beside.join("transforms.json").is_file().then_some(beside)
}

/// The views as the page's JSON: image URL and camera (camera-to-world matrix column-major,
/// intrinsics in pixels of the image).
pub fn describe(views: &[TrainingView]) -> serde_json::Value {
    json!(views
        .iter()
        .enumerate()
        .map(|(i, view)| {
            let c = &view.camera;
            json!({
                "image": format!("/views/{i}.png"),
                "c2w": c.c2w.to_cols_array(),
                "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy,
                "width": c.width, "height": c.height,
            })
        })
        .collect::<Vec<_>>())
}
