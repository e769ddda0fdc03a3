//! RGB-D datasets: a transforms.json (fields from the fuzzer, or its whole text), one colour
//! image (8- or 16-bit PNG, grey to RGBA, any size) and one depth map (16-bit PNG, or an EXR
//! with a depth channel under one of the names volgen reads), each possibly damaged, loaded
//! as `volgen train` loads them and resampled to a training level. The loader must return a
//! dataset of finite values or an error naming the file.
#![no_main]

use std::io::Cursor;

use arbitrary::Arbitrary;
use candle_core::Device;
use image::{DynamicImage, ImageBuffer, ImageFormat};
use libfuzzer_sys::fuzz_target;
use rgbd_dataset::{Dataset, LoadOptions};
use volgen_fuzz::{all_finite, Damage};

#[derive(Arbitrary, Debug)]
struct Frame {
    matrix: [[f32; 4]; 4],
    depth_exr: bool,
}

#[derive(Arbitrary, Debug)]
struct Input {
    camera_angle_x: f32,
    size: (u8, u8),
    depth_scale: Option<f32>,
    depth_kind: u8,
    frame: Frame,
    /// Replaces the whole transforms.json when given.
    raw_json: Option<String>,
    colour_type: u8,
    pixels: Vec<u8>,
    colour_damage: Damage,
    depth_values: Vec<f32>,
    depth_channel: u8,
    depth_damage: Damage,
}

const DEPTH_KINDS: [&str; 4] = ["expected", "z", "distance", "furlongs"];
const DEPTH_CHANNELS: [&str; 4] = ["ViewLayer.Depth.Z", "Z", "Y", "R"];

fn png(width: u32, height: u32, colour_type: u8, pixels: &[u8]) -> Vec<u8> {
    let bytes = |n: usize| -> Vec<u8> { pixels.iter().copied().cycle().take(n).collect() };
    let n = (width * height) as usize;
    let image = match colour_type % 4 {
        0 => DynamicImage::ImageLuma8(ImageBuffer::from_raw(width, height, bytes(n)).unwrap()),
        1 => DynamicImage::ImageRgb8(ImageBuffer::from_raw(width, height, bytes(3 * n)).unwrap()),
        2 => DynamicImage::ImageRgba8(ImageBuffer::from_raw(width, height, bytes(4 * n)).unwrap()),
        _ => {
            let wide: Vec<u16> = bytes(8 * n)
                .chunks(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect();
            DynamicImage::ImageRgba16(ImageBuffer::from_raw(width, height, wide).unwrap())
        }
    };
    let mut out = Cursor::new(Vec::new());
    image.write_to(&mut out, ImageFormat::Png).unwrap();
    out.into_inner()
}

fn depth_png(width: u32, height: u32, values: &[f32]) -> Vec<u8> {
    let n = (width * height) as usize;
    let wide: Vec<u16> = values
        .iter()
        .map(|v| (v.abs() * 1000.0) as u16)
        .cycle()
        .take(n)
        .collect();
    let image = DynamicImage::ImageLuma16(ImageBuffer::from_raw(width, height, wide).unwrap());
    let mut out = Cursor::new(Vec::new());
    image.write_to(&mut out, ImageFormat::Png).unwrap();
    out.into_inner()
}

fn depth_exr(width: usize, height: usize, values: &[f32], channel: &str) -> Vec<u8> {
    use exr::prelude::*;
    let n = width * height;
    let values: Vec<f32> = values.iter().copied().cycle().take(n).collect();
    let channels = AnyChannels::sort(smallvec::smallvec![AnyChannel::new(
        channel,
        FlatSamples::F32(values)
    )]);
    let image = Image::from_layer(Layer::new(
        (width, height),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        channels,
    ));
    let mut out = Cursor::new(Vec::new());
    // Without a thread pool: a pool thread's reused compression buffer (thread-local) reads
    // as a leak to LeakSanitizer (found 2026-11-25; volgen's own EXR code is non-parallel too).
    image.write().non_parallel().to_buffered(&mut out).unwrap();
    out.into_inner()
}

fuzz_target!(|input: Input| {
    let (w, h) = (
        u32::from(input.size.0 % 12) + 1,
        u32::from(input.size.1 % 12) + 1,
    );
    if input.pixels.is_empty() || input.depth_values.is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("images")).unwrap();
    std::fs::create_dir_all(dir.path().join("depth")).unwrap();
    let colour = input
        .colour_damage
        .apply(png(w, h, input.colour_type, &input.pixels));
    std::fs::write(dir.path().join("images/r_000.png"), colour).unwrap();
    let depth_file = if input.frame.depth_exr {
        let channel = DEPTH_CHANNELS[usize::from(input.depth_channel) % DEPTH_CHANNELS.len()];
        let bytes = depth_exr(w as usize, h as usize, &input.depth_values, channel);
        std::fs::write(
            dir.path().join("depth/r_000.exr"),
            input.depth_damage.apply(bytes),
        )
        .unwrap();
        "depth/r_000.exr"
    } else {
        let bytes = depth_png(w, h, &input.depth_values);
        std::fs::write(
            dir.path().join("depth/r_000.png"),
            input.depth_damage.apply(bytes),
        )
        .unwrap();
        "depth/r_000.png"
    };
    let json = match &input.raw_json {
        Some(text) => text.clone(),
        None => {
            let mut json = serde_json::json!({
                "camera_angle_x": input.camera_angle_x,
                "w": w,
                "h": h,
                "depth_kind": DEPTH_KINDS[usize::from(input.depth_kind) % DEPTH_KINDS.len()],
                "frames": [{
                    "file_path": "images/r_000.png",
                    "depth_file_path": depth_file,
                    "transform_matrix": input.frame.matrix,
                }],
            });
            if let Some(scale) = input.depth_scale {
                json["depth_scale"] = scale.into();
            }
            json.to_string()
        }
    };
    std::fs::write(dir.path().join("transforms.json"), json).unwrap();
    let Ok(dataset) = Dataset::load_with(dir.path(), &LoadOptions::default()) else {
        return;
    };
    let level = dataset
        .level(4, 4, &Device::Cpu)
        .expect("a loaded dataset resamples");
    for tensor in [&level.images, &level.depths, &level.opacity] {
        assert!(all_finite(tensor), "the loader accepted non-finite values");
    }
});
