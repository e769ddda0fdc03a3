//! Datasets rendered in memory: another volume seen from a dataset's cameras, as
//! [`write_dataset`](crate::write_dataset) would have rendered it, without files.

use radiance_volume::RadianceVolume;
use volrender::{render_image, Image};

use crate::depth::DepthKind;
use crate::error::Result;
use crate::render_config;
use crate::{Dataset, FramePixels};

impl Dataset {
    /// `volume` rendered from this dataset's cameras at its resolution with [`render_config`]
    /// (what [`write_dataset`](crate::write_dataset) renders scenes with), composited onto
    /// `background` as loading composites files: the same views of another scene, for
    /// example another layout of a built-in one ([`Dataset::scene_source`]). Frames keep
    /// their names; depth is exact expected depth (no 8-bit or 16-bit rounding, as files
    /// have), known everywhere; the result records no scene source.
    ///
    /// ```
    /// use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
    /// use rgbd_dataset::scenes::{Scene, StandingStones};
    /// let dir = tempfile::tempdir()?;
    /// let spec = DatasetSpec { views: 2, resolution: 16, grid: 24, seed: 1 };
    /// write_dataset(&StandingStones::new(1), dir.path(), &spec)?;
    /// let data = Dataset::load(dir.path(), [1.0; 3])?;
    /// let same = StandingStones::new(1).to_volume(radiance_volume::GridDims::cube(24))?;
    /// let again = data.rendered(&same, [1.0; 3])?;
    /// let (a, b) = (data.level(16, 16, &candle_core::Device::Cpu)?, again.level(16, 16, &candle_core::Device::Cpu)?);
    /// let worst = (a.images - b.images)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
    /// // The files round colour and alpha to 8 bits: at most 1/255 after compositing.
    /// assert!(worst <= 1.0 / 255.0 + 1e-4, "{worst}");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn rendered(&self, volume: &RadianceVolume, background: [f32; 3]) -> Result<Self> {
        let config = render_config();
        let frames = self
            .cameras
            .iter()
            .map(|camera| {
                Ok(composite(
                    &render_image(volume, camera, &config)?,
                    background,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            frames,
            depth_kind: DepthKind::Expected,
            source: None,
            ..self.clone()
        })
    }
}

/// A premultiplied rendering (no background) composited onto `background`, as loading
/// composites straight-alpha files: `C + bg (1 - a)`.
fn composite(image: &Image, background: [f32; 3]) -> FramePixels {
    let plane = image.opacity.len();
    let mut rgb = vec![0f32; 3 * plane];
    for (i, (colour, &alpha)) in image.rgb.iter().zip(&image.opacity).enumerate() {
        for c in 0..3 {
            rgb[c * plane + i] = colour[c] + background[c] * (1.0 - alpha);
        }
    }
    FramePixels {
        rgb,
        opacity: image.opacity.clone(),
        depth: image.depth.clone(),
        depth_mask: None,
        depth_left_out: 0,
    }
}
