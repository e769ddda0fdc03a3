//! Datasets rendered in memory: another volume seen from a dataset's cameras, as
//! [`write_dataset`](crate::write_dataset) would have rendered it, without files; or only its
//! depth, for a dataset without depth maps ([`Dataset::with_depth_from`]).

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

/// A pixel's depth from a reconstruction is a hole where the reconstruction's opacity is below
/// this share of the view's own: too little matter along the ray to say where the surface is
/// (as a depth sensor's missing returns).
pub const MIN_COVERED_SHARE: f32 = 0.5;

impl Dataset {
    /// This dataset with its depth taken from a reconstruction of its views (the paper's
    /// "NeRF-depth": photos without a depth sensor), `volume` rendered from every camera with
    /// [`render_config`]: where a view's pixel shows something (alpha above 1/255) and the
    /// reconstruction's opacity there is at least [`MIN_COVERED_SHARE`] of the pixel's, its ray
    /// distance `depth / opacity` times the pixel's alpha (the expected depth the view's own
    /// coverage implies); where the reconstruction is thinner, a hole left out of the depth
    /// loss, as missing depth in files is; where the view is empty, 0. Colour and opacity are
    /// the dataset's. Returns the dataset (`depth_kind` expected) and its foreground pixels
    /// with and without depth.
    ///
    /// ```
    /// use rgbd_dataset::{write_dataset, Dataset, DatasetSpec};
    /// use rgbd_dataset::scenes::{Scene, StandingStones};
    /// let dir = tempfile::tempdir()?;
    /// let spec = DatasetSpec { views: 2, resolution: 16, grid: 24, seed: 1 };
    /// write_dataset(&StandingStones::new(1), dir.path(), &spec)?;
    /// let data = Dataset::load(dir.path(), [1.0; 3])?;
    /// // The scene itself as the reconstruction: its depth comes back, with no holes.
    /// let scene = StandingStones::new(1).to_volume(radiance_volume::GridDims::cube(24))?;
    /// let (with_depth, coverage) = data.with_depth_from(&scene)?;
    /// assert_eq!(coverage.holes, 0);
    /// assert_eq!(with_depth.depth_left_out(), 0);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn with_depth_from(&self, volume: &RadianceVolume) -> Result<(Self, DepthCoverage)> {
        let config = render_config();
        let mut coverage = DepthCoverage::default();
        let mut frames = Vec::with_capacity(self.frames.len());
        for (camera, frame) in self.cameras.iter().zip(&self.frames) {
            let image = render_image(volume, camera, &config)?;
            let mut depth = vec![0f32; frame.opacity.len()];
            let mut mask = vec![1f32; frame.opacity.len()];
            let mut left_out = 0;
            for (i, &alpha) in frame.opacity.iter().enumerate() {
                if alpha <= 1.0 / 255.0 {
                    continue;
                }
                let reconstructed = image.opacity[i];
                let covered = reconstructed >= MIN_COVERED_SHARE * alpha;
                if covered {
                    depth[i] = alpha * image.depth[i] / reconstructed;
                } else {
                    mask[i] = 0.0;
                    left_out += 1;
                }
                if alpha > 0.5 {
                    coverage.foreground += 1;
                    coverage.holes += usize::from(!covered);
                }
            }
            frames.push(FramePixels {
                rgb: frame.rgb.clone(),
                opacity: frame.opacity.clone(),
                depth,
                depth_mask: (left_out > 0).then_some(mask),
                depth_left_out: left_out,
            });
        }
        Ok((
            Self {
                frames,
                depth_kind: DepthKind::Expected,
                ..self.clone()
            },
            coverage,
        ))
    }
}

/// How much of a dataset's foreground [`Dataset::with_depth_from`] gave depth.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DepthCoverage {
    /// Pixels with alpha above 0.5, over all views.
    pub foreground: usize,
    /// Those where the reconstruction was too thin to give depth.
    pub holes: usize,
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
