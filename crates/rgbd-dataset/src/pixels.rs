//! Image files of a dataset: 8-bit RGBA colour PNGs, 16-bit grey depth PNGs and float depth
//! EXRs. Decoding reports what is wrong as a sentence; the caller adds the file and frame.

use std::path::Path;

use image::{codecs::png::PngEncoder, DynamicImage, ExtendedColorType, ImageEncoder};

/// A decoded image: row-major pixels with their size.
pub(super) struct Pixels<T> {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) data: Vec<T>,
}

/// Encodes row-major `bytes` of the given colour type as a PNG file's contents.
pub(super) fn encode_png(
    bytes: &[u8],
    width: usize,
    height: usize,
    colour: ExtendedColorType,
) -> Result<Vec<u8>, String> {
    let (w, h) = (to_u32(width)?, to_u32(height)?);
    let mut png = Vec::new();
    PngEncoder::new(&mut png)
        .write_image(bytes, w, h, colour)
        .map_err(|e| e.to_string())?;
    Ok(png)
}

fn to_u32(n: usize) -> Result<u32, String> {
    u32::try_from(n).map_err(|_| format!("image side {n} is too large for PNG"))
}

/// Decodes a colour image to straight (not premultiplied) RGBA in [0, 1]; images without alpha
/// are opaque.
pub(super) fn read_rgba(path: &Path) -> Result<Pixels<[f32; 4]>, String> {
    let image = decode(path)?;
    let (width, height) = (image.width() as usize, image.height() as usize);
    let data = image
        .to_rgba32f()
        .pixels()
        .map(|p| p.0.map(|v| v.clamp(0.0, 1.0)))
        .collect();
    Ok(Pixels {
        width,
        height,
        data,
    })
}

/// Decodes a mask to grey in [0, 1] (colour masks by their luma).
pub(super) fn read_grey(path: &Path) -> Result<Pixels<f32>, String> {
    let image = decode(path)?;
    let (width, height) = (image.width() as usize, image.height() as usize);
    let data = image
        .to_luma32f()
        .pixels()
        .map(|p| p.0[0].clamp(0.0, 1.0))
        .collect();
    Ok(Pixels {
        width,
        height,
        data,
    })
}

/// Decodes a 16-bit grey PNG depth map to its raw counts.
pub(super) fn read_depth_png(path: &Path) -> Result<Pixels<u16>, String> {
    let (width, height, data) = match decode(path)? {
        DynamicImage::ImageLuma16(img) => (img.width(), img.height(), img.into_raw()),
        DynamicImage::ImageLumaA16(img) => {
            let (w, h) = (img.width(), img.height());
            (w, h, img.pixels().map(|p| p.0[0]).collect())
        }
        other => {
            return Err(format!(
                "a PNG depth map must be 16-bit grey, this one is {:?}",
                other.color()
            ))
        }
    };
    Ok(Pixels {
        width: width as usize,
        height: height as usize,
        data,
    })
}

/// Reads depth in world units from an EXR file: the first channel named `Z` (or ending in
/// `.Z`, as in Blender's `View Layer.Depth.Z`), else `Y`, else `R`.
pub(super) fn read_depth_exr(path: &Path) -> Result<Pixels<f32>, String> {
    let image = exr::prelude::read_all_flat_layers_from_file(path).map_err(|e| e.to_string())?;
    let channels = || {
        image.layer_data.iter().flat_map(|layer| {
            layer
                .channel_data
                .list
                .iter()
                .map(move |channel| (layer.size, channel))
        })
    };
    let named = |wanted: &str| {
        channels().find(|(_, channel)| {
            let name = channel.name.to_string();
            name == wanted || name.ends_with(&format!(".{wanted}"))
        })
    };
    let (size, channel) = named("Z")
        .or_else(|| named("Y"))
        .or_else(|| named("R"))
        .ok_or("the EXR depth map has no channel `Z`, `Y` or `R`")?;
    // Non-finite values are "no surface" markers or errors depending on the depth kind; the
    // conversion decides.
    let data: Vec<f32> = channel.sample_data.values_as_f32().collect();
    Ok(Pixels {
        width: size.0,
        height: size.1,
        data,
    })
}

fn decode(path: &Path) -> Result<DynamicImage, String> {
    image::ImageReader::open(path)
        .map_err(|e| e.to_string())?
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .decode()
        .map_err(|e| format!("cannot decode: {e}"))
}
