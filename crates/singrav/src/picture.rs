//! Pictures of renderings: contact sheets (grids of images in one PNG) and animated GIFs.

use std::path::Path;

use candle_core::Tensor;

use crate::error::{invalid, Result};

/// Pixels of white between cells.
const GAP: usize = 2;

/// Writes a grid of `(3, h, w)` images (colour in [0, 1], clamped), one `Vec` per row, all of
/// one size, to a PNG at `path` atomically.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let dir = tempfile::tempdir()?;
/// let grey = Tensor::full(0.5f32, (3, 4, 6), &Device::Cpu)?;
/// let path = dir.path().join("grid.png");
/// singrav::picture::write_grid(&path, &[vec![grey.clone(), grey.clone()], vec![grey]])?;
/// let png = image::open(&path)?;
/// assert_eq!((png.width(), png.height()), (2 * 6 + 3 * 2, 2 * 4 + 3 * 2));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_grid(path: &Path, rows: &[Vec<Tensor>]) -> Result<()> {
    let first = rows
        .iter()
        .flatten()
        .next()
        .ok_or_else(|| invalid("picture", "no images to write"))?;
    let (_, h, w) = first.dims3()?;
    let columns = rows.iter().map(Vec::len).max().unwrap_or(0);
    let width = columns * (w + GAP) + GAP;
    let height = rows.len() * (h + GAP) + GAP;
    let mut canvas = image::RgbImage::from_pixel(width as u32, height as u32, image::Rgb([255; 3]));
    for (r, row) in rows.iter().enumerate() {
        for (c, cell) in row.iter().enumerate() {
            let (x0, y0) = (GAP + c * (w + GAP), GAP + r * (h + GAP));
            let cell = rgb8(cell, [h, w], &format!("cell {r},{c}"))?;
            image::imageops::replace(&mut canvas, &cell, x0 as i64, y0 as i64);
        }
    }
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgb8(canvas)
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| invalid("picture", format!("{}: {e}", path.display())))?;
    crate::io::write_bytes(path, &bytes)
}

/// Writes `frames` `(3, h, w)` (colour in [0, 1], clamped; all of one size) as an animated GIF
/// at `path` atomically, each frame shown `frame_ms` milliseconds, looping forever. GIF frames
/// hold at most 256 colours each (the encoder quantises them), so colours are close, not exact.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use image::AnimationDecoder;
/// let dir = tempfile::tempdir()?;
/// let frames: Vec<Tensor> = (0..3)
///     .map(|i| Tensor::full(i as f32 / 2.0, (3, 4, 6), &Device::Cpu))
///     .collect::<candle_core::Result<_>>()?;
/// let path = dir.path().join("fade.gif");
/// singrav::picture::write_gif(&path, &frames, 80)?;
/// let file = std::io::BufReader::new(std::fs::File::open(&path)?);
/// let decoded = image::codecs::gif::GifDecoder::new(file)?.into_frames().collect_frames()?;
/// assert_eq!(decoded.len(), 3);
/// assert_eq!(decoded[1].buffer().dimensions(), (6, 4));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_gif(path: &Path, frames: &[Tensor], frame_ms: u32) -> Result<()> {
    let first = frames
        .first()
        .ok_or_else(|| invalid("animation", "no frames to write"))?;
    let (_, h, w) = first.dims3()?;
    let mut bytes = Vec::new();
    {
        let mut encoder = image::codecs::gif::GifEncoder::new_with_speed(&mut bytes, 10);
        let fail = |e: image::ImageError| invalid("animation", format!("{}: {e}", path.display()));
        encoder
            .set_repeat(image::codecs::gif::Repeat::Infinite)
            .map_err(fail)?;
        for (i, frame) in frames.iter().enumerate() {
            let rgb = rgb8(frame, [h, w], &format!("frame {i}"))?;
            let rgba = image::DynamicImage::ImageRgb8(rgb).into_rgba8();
            let delay = image::Delay::from_numer_denom_ms(frame_ms, 1);
            encoder
                .encode_frame(image::Frame::from_parts(rgba, 0, 0, delay))
                .map_err(fail)?;
        }
    }
    crate::io::write_bytes(path, &bytes)
}

/// A `(3, h, w)` tensor as an 8-bit image (colour clamped to [0, 1]); `what` names it in the
/// error when its shape is not `[3, h, w]`.
fn rgb8(tensor: &Tensor, [h, w]: [usize; 2], what: &str) -> Result<image::RgbImage> {
    if tensor.dims() != [3, h, w] {
        return Err(invalid(
            "picture",
            format!("{what} is {:?}, expected [3, {h}, {w}]", tensor.dims()),
        ));
    }
    let values: Vec<f32> = tensor.flatten_all()?.to_vec1()?;
    let channel = |k: usize, y: usize, x: usize| {
        (values[(k * h + y) * w + x].clamp(0.0, 1.0) * 255.0).round() as u8
    };
    Ok(image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let (x, y) = (x as usize, y as usize);
        image::Rgb([channel(0, y, x), channel(1, y, x), channel(2, y, x)])
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use image::AnimationDecoder;

    #[test]
    fn gif_frames_keep_their_colours_and_delay_and_mismatches_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("two.gif");
        let colour = |rgb: [f32; 3]| {
            Tensor::new(&rgb, &Device::Cpu)
                .unwrap()
                .reshape((3, 1, 1))
                .unwrap()
                .repeat((1, 5, 7))
                .unwrap()
        };
        write_gif(
            &path,
            &[colour([1.0, 0.0, 0.0]), colour([0.0, 0.5, 1.0])],
            120,
        )
        .unwrap();
        let reader = std::io::BufReader::new(std::fs::File::open(&path).unwrap());
        let frames = image::codecs::gif::GifDecoder::new(reader)
            .unwrap()
            .into_frames()
            .collect_frames()
            .unwrap();
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[0].delay().numer_denom_ms(), (120, 1));
        // A one-colour frame survives quantisation to within a step or two of 255.
        let pixel = frames[1].buffer().get_pixel(3, 2).0;
        for (got, want) in pixel.iter().zip([0u8, 128, 255, 255]) {
            assert!(got.abs_diff(want) <= 2, "{pixel:?}");
        }
        let small = Tensor::zeros((3, 4, 4), candle_core::DType::F32, &Device::Cpu).unwrap();
        let err = write_gif(&path, &[colour([0.0; 3]), small], 80)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("frame 1") && err.contains("[3, 5, 7]"),
            "{err}"
        );
        assert!(write_gif(&path, &[], 80).is_err());
    }
}
