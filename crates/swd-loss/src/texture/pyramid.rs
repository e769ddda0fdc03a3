//! A weights-free feature extractor: square patches of the levels of an image pyramid.

use candle_core::{Tensor, D};

use super::{FeatureExtractor, FeatureMap};
use crate::error::{invalid, Result};

/// Which pyramid the patches are taken from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PyramidKind {
    /// Blurred and halved copies of the image: level l holds detail up to 1 / 2^l of the
    /// full resolution.
    Gaussian,
    /// Band-pass levels `G_l - up(G_{l+1})` and, last, the coarsest Gaussian level (so the
    /// levels together still carry the whole image): each level's patches see one scale of
    /// detail, as in Karras et al.'s sliced Wasserstein metric.
    #[default]
    Laplacian,
}

/// Settings of a [`PatchPyramid`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PatchPyramidConfig {
    /// Number of levels, the full resolution included (default 3).
    pub levels: usize,
    /// Side of the square patches (default 7): a point has `3 * patch^2` dimensions.
    pub patch: usize,
    /// Gaussian or Laplacian levels (default Laplacian).
    pub kind: PyramidKind,
}

impl Default for PatchPyramidConfig {
    fn default() -> Self {
        Self {
            levels: 3,
            patch: 7,
            kind: PyramidKind::Laplacian,
        }
    }
}

impl PatchPyramidConfig {
    /// Sets the number of levels.
    #[must_use]
    pub fn with_levels(self, levels: usize) -> Self {
        Self { levels, ..self }
    }

    /// Sets the patch side.
    #[must_use]
    pub fn with_patch(self, patch: usize) -> Self {
        Self { patch, ..self }
    }

    /// Sets the pyramid kind.
    #[must_use]
    pub fn with_kind(self, kind: PyramidKind) -> Self {
        Self { kind, ..self }
    }
}

/// Patches of every level of a Gaussian or Laplacian pyramid, one layer per level, usable
/// without any pretrained weights.
///
/// Each level is made by blurring with the 5x5 binomial filter (`[1 4 6 4 1] / 16` in each
/// direction, edges replicated) and keeping every other pixel, so a side of n becomes
/// `ceil(n / 2)`. Upsampling (for Laplacian levels) repeats pixels and blurs. Every position
/// where a whole patch fits is a point; the smallest level must hold one patch.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use swd_loss::{FeatureExtractor, PatchPyramid, PatchPyramidConfig};
///
/// let pyramid = PatchPyramid::new(PatchPyramidConfig::default())?;
/// let maps = pyramid.extract(&Tensor::zeros((2, 3, 32, 30), candle_core::DType::F32, &Device::Cpu)?)?;
/// let sizes: Vec<_> = maps.iter().map(|m| m.values.dims().to_vec()).collect();
/// assert_eq!(sizes, vec![vec![2, 3, 32, 30], vec![2, 3, 16, 15], vec![2, 3, 8, 8]]);
/// assert_eq!(maps[0].point_dim()?, 3 * 49);
/// # Ok::<(), swd_loss::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PatchPyramid {
    config: PatchPyramidConfig,
}

impl PatchPyramid {
    /// Builds the extractor; errors if `levels` or `patch` is zero.
    pub fn new(config: PatchPyramidConfig) -> Result<Self> {
        if config.levels == 0 {
            return Err(invalid("levels", "a pyramid needs at least one level"));
        }
        if config.patch == 0 {
            return Err(invalid("patch", "patches must be at least 1x1"));
        }
        Ok(Self { config })
    }

    /// Returns the settings.
    #[must_use]
    pub fn config(&self) -> PatchPyramidConfig {
        self.config
    }

    /// Computes the pyramid levels of `images` `(B, C, H, W)`, finest first.
    pub fn levels(&self, images: &Tensor) -> Result<Vec<Tensor>> {
        let (_, _, h, w) = images.dims4().map_err(|_| {
            invalid(
                "images",
                format!("expected (B, C, H, W), got shape {:?}", images.dims()),
            )
        })?;
        if images.elem_count() == 0 {
            return Err(invalid(
                "images",
                format!("empty images of shape {:?}", images.dims()),
            ));
        }
        let (mut lh, mut lw) = (h, w);
        for _ in 1..self.config.levels {
            (lh, lw) = (lh.div_ceil(2), lw.div_ceil(2));
        }
        let p = self.config.patch;
        if lh < p || lw < p {
            return Err(invalid(
                "images",
                format!(
                    "{h}x{w} images give a {lh}x{lw} level {}, smaller than the {p}x{p} patches: use fewer levels or smaller patches",
                    self.config.levels - 1
                ),
            ));
        }
        let mut gaussian = vec![images.clone()];
        for l in 1..self.config.levels {
            gaussian.push(blur(&gaussian[l - 1], 2)?);
        }
        match self.config.kind {
            PyramidKind::Gaussian => Ok(gaussian),
            PyramidKind::Laplacian => {
                let mut levels = Vec::with_capacity(gaussian.len());
                for pair in gaussian.windows(2) {
                    let (fine, coarse) = (&pair[0], &pair[1]);
                    let (_, _, fh, fw) = fine.dims4()?;
                    let up = blur(&upsample2x(coarse)?, 1)?
                        .narrow(2, 0, fh)?
                        .narrow(3, 0, fw)?;
                    levels.push((fine - up)?);
                }
                levels.extend(gaussian.last().cloned());
                Ok(levels)
            }
        }
    }
}

impl FeatureExtractor for PatchPyramid {
    fn layer_count(&self) -> usize {
        self.config.levels
    }

    fn extract(&self, images: &Tensor) -> Result<Vec<FeatureMap>> {
        Ok(self
            .levels(images)?
            .into_iter()
            .map(|values| FeatureMap {
                values,
                patch: self.config.patch,
            })
            .collect())
    }
}

/// Blurs every channel with the 5x5 binomial filter (edges replicated) and keeps every
/// `stride`-th pixel.
fn blur(x: &Tensor, stride: usize) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    const TAPS: [f64; 5] = [1.0, 4.0, 6.0, 4.0, 1.0];
    let kernel: Vec<f64> = TAPS
        .iter()
        .flat_map(|a| TAPS.iter().map(move |b| a * b / 256.0))
        .collect();
    let kernel = Tensor::from_vec(kernel, (1, 1, 5, 5), x.device())?.to_dtype(x.dtype())?;
    // Channels become batch entries so one single-channel kernel serves them all.
    let padded = x
        .reshape((b * c, 1, h, w))?
        .pad_with_same(D::Minus2, 2, 2)?
        .pad_with_same(D::Minus1, 2, 2)?;
    let out = padded.conv2d(&kernel, 0, stride, 1, 1)?;
    let (_, _, oh, ow) = out.dims4()?;
    Ok(out.reshape((b, c, oh, ow))?)
}

/// Repeats every pixel 2x2.
///
/// Written as a broadcast rather than candle's `upsample_nearest2d`, whose backward in candle
/// 0.11 overwrites (instead of adding to) the gradient its input receives from other uses, and
/// the coarse Gaussian level is used twice here (upsampled, and as the last level).
fn upsample2x(x: &Tensor) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    Ok(x.reshape((b, c, h, 1, w, 1))?
        .broadcast_as((b, c, h, 2, w, 2))?
        .reshape((b, c, 2 * h, 2 * w))?)
}
