//! Whole-image rendering for tools, and the image writers (EXR with float R, G, B, A = opacity,
//! Z = depth; 8-bit PNG preview). Writers are atomic: a temporary file in the target's
//! directory, renamed over the target once complete.

use std::path::{Path, PathBuf};

use radiance_volume::RadianceVolume;

use crate::camera::Camera;
use crate::config::RenderConfig;
use crate::error::{Error, Result};
use crate::op::render;
use crate::rays::Rays;

/// A rendered image, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Colour per pixel (including the background, if any).
    pub rgb: Vec<[f32; 3]>,
    /// Expected depth per pixel (distance along the ray; 0 where nothing is hit).
    pub depth: Vec<f32>,
    /// Opacity per pixel, in [0, 1].
    pub opacity: Vec<f32>,
}

/// Renders every pixel of `camera` (with depth and opacity, in the volume's own box).
///
/// ```
/// use volrender::{render_image, Camera, RenderConfig};
/// use radiance_volume::{Aabb, GridDims, RadianceVolume};
/// use glam::Vec3;
/// let fog = RadianceVolume::from_fn(GridDims::cube(4), Aabb::CUBE, 4, |_, out| {
///     out.copy_from_slice(&[1.0, 0.2, 0.4, 0.6]);
/// })?;
/// let cam = Camera::look_at(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, Vec3::Y, 8, 6, 0.3)?;
/// let img = render_image(&fog, &cam, &RenderConfig::default())?;
/// assert_eq!((img.width, img.height, img.rgb.len()), (8, 6, 48));
/// let dir = tempfile::tempdir()?;
/// img.write_png(dir.path().join("fog.png"))?;
/// img.write_exr(dir.path().join("fog.exr"))?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn render_image(volume: &RadianceVolume, camera: &Camera, cfg: &RenderConfig) -> Result<Image> {
    let cfg = cfg
        .with_aabb(volume.aabb())
        .with_depth(true)
        .with_opacity(true);
    let out = render(volume.tensor(), &Rays::from_camera(camera), &cfg)?;
    let rgb: Vec<f32> = out.rgb.flatten_all()?.to_vec1()?;
    let column = |t: Option<candle_core::Tensor>| -> Result<Vec<f32>> {
        match t {
            Some(t) => Ok(t.to_vec1()?),
            None => Err(crate::error::invalid(
                "outputs",
                "renderer returned no depth/opacity",
            )),
        }
    };
    Ok(Image {
        width: camera.width,
        height: camera.height,
        rgb: rgb.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        depth: column(out.depth)?,
        opacity: column(out.opacity)?,
    })
}

impl Image {
    /// Writes an 8-bit RGB PNG preview (colour clamped to [0, 1]).
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<()> {
        let bytes: Vec<u8> = self
            .rgb
            .iter()
            .flat_map(|c| c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
            .collect();
        let (w, h) = (self.width as u32, self.height as u32);
        write_atomic(path.as_ref(), "png", |tmp| {
            image::save_buffer_with_format(
                tmp,
                &bytes,
                w,
                h,
                image::ExtendedColorType::Rgb8,
                image::ImageFormat::Png,
            )
            .map_err(|e| e.to_string())
        })
    }

    /// Writes an OpenEXR file with float channels R, G, B, A (opacity) and Z (depth).
    pub fn write_exr(&self, path: impl AsRef<Path>) -> Result<()> {
        use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2, WritableImage};
        let pixels = SpecificChannels::build()
            .with_channel("R")
            .with_channel("G")
            .with_channel("B")
            .with_channel("A")
            .with_channel("Z")
            .with_pixel_fn(|Vec2(x, y)| {
                let i = y * self.width + x;
                let [r, g, b] = self.rgb[i];
                (r, g, b, self.opacity[i], self.depth[i])
            });
        let image = ExrImage::from_channels((self.width, self.height), pixels);
        write_atomic(path.as_ref(), "exr", |tmp| {
            image.write().to_file(tmp).map_err(|e| e.to_string())
        })
    }
}

/// Runs `write(tmp)` on a temporary path beside `path`, then renames it over `path`; removes the
/// temporary file when writing fails.
fn write_atomic(
    path: &Path,
    format: &'static str,
    write: impl FnOnce(&Path) -> std::result::Result<(), String>,
) -> Result<()> {
    let name = path
        .file_name()
        .map_or_else(|| "image".into(), |n| n.to_string_lossy().into_owned());
    let tmp: PathBuf = path.with_file_name(format!(".{name}.{}.tmp.{format}", std::process::id()));
    if let Err(why) = write(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::Encode {
            path: path.to_path_buf(),
            format,
            why,
        });
    }
    std::fs::rename(&tmp, path).map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn exr_round_trip_keeps_every_channel() {
        use exr::prelude::*;
        let img = super::Image {
            width: 3,
            height: 2,
            rgb: (0..6).map(|i| [i as f32, 0.5, -1.0]).collect(),
            depth: (0..6).map(|i| i as f32 * 0.25).collect(),
            opacity: vec![0.0, 0.1, 0.2, 0.3, 0.4, 1.0],
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.exr");
        img.write_exr(&path).unwrap();
        let read = read_all_flat_layers_from_file(&path).unwrap();
        let layer = &read.layer_data[0];
        let channel = |name: &str| -> Vec<f32> {
            let c = layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name == *name)
                .unwrap();
            c.sample_data.values_as_f32().collect()
        };
        assert_eq!(channel("Z"), img.depth);
        assert_eq!(channel("A"), img.opacity);
        assert_eq!(channel("R"), vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        // Only the final file is left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        assert!(img.write_png(dir.path().join("no/such/dir.png")).is_err());
    }
}
