//! Contact sheets: grids of rendered images written as one PNG.

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
            if cell.dims() != [3, h, w] {
                return Err(invalid(
                    "picture",
                    format!("cell {r},{c} is {:?}, expected [3, {h}, {w}]", cell.dims()),
                ));
            }
            let values: Vec<f32> = cell.flatten_all()?.to_vec1()?;
            let (x0, y0) = (GAP + c * (w + GAP), GAP + r * (h + GAP));
            for y in 0..h {
                for x in 0..w {
                    let channel = |k: usize| {
                        (values[(k * h + y) * w + x].clamp(0.0, 1.0) * 255.0).round() as u8
                    };
                    canvas.put_pixel(
                        (x0 + x) as u32,
                        (y0 + y) as u32,
                        image::Rgb([channel(0), channel(1), channel(2)]),
                    );
                }
            }
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
