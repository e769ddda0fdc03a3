//! A weights-free feature extractor: square patches of the levels of an image pyramid.

use candle_core::shape::Dim;
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
/// `stride`-th pixel, starting with the first.
///
/// The filter is separable, so it runs as `[1 4 6 4 1] / 16` along rows, then columns, each a
/// sum of shifted views. Not candle's conv2d: its backward also computes the gradient of the
/// (constant) kernel, a correlation with an image-sized kernel that cost more than the rest of
/// the loss.
fn blur(x: &Tensor, stride: usize) -> Result<Tensor> {
    // Rows dropped after the first pass need no second pass.
    let rows = decimate(&binomial_axis(x, D::Minus2)?, D::Minus2, stride)?;
    decimate(&binomial_axis(&rows, D::Minus1)?, D::Minus1, stride)
}

/// `[1 4 6 4 1] / 16` along `dim`, indices clamped to the axis.
fn binomial_axis(x: &Tensor, dim: D) -> Result<Tensor> {
    const TAPS: [f64; 5] = [1.0, 4.0, 6.0, 4.0, 1.0];
    let n = x.dim(dim)?;
    let padded = x.pad_with_same(dim, 2, 2)?;
    let mut sum = (padded.narrow(dim, 0, n)? * (TAPS[0] / 16.0))?;
    for (shift, tap) in TAPS.iter().enumerate().skip(1) {
        sum = (sum + (padded.narrow(dim, shift, n)? * (tap / 16.0))?)?;
    }
    Ok(sum)
}

/// Every `stride`-th entry along `dim` (indices 0, stride, ...; `ceil(n / stride)` of them).
fn decimate(x: &Tensor, dim: D, stride: usize) -> Result<Tensor> {
    if stride == 1 {
        return Ok(x.clone());
    }
    let axis = dim.to_index(x.shape(), "decimate")?;
    let n = x.dim(axis)?;
    let kept = n.div_ceil(stride);
    // Pad to a multiple of the stride so the axis splits into (kept, stride); the padding is
    // never at a kept index.
    let x = x.pad_with_zeros(axis, 0, kept * stride - n)?;
    let mut split = x.dims().to_vec();
    split.splice(axis..=axis, [kept, stride]);
    let mut out = x.dims().to_vec();
    out[axis] = kept;
    Ok(x.reshape(split)?.narrow(axis + 1, 0, 1)?.reshape(out)?)
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

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    /// The 5x5 binomial kernel in f64 with indices clamped to the image, at every `stride`-th
    /// output, as `(output, source, weight)` terms: the blur gathers along them, its adjoint
    /// scatters.
    fn direct_terms(h: usize, w: usize, stride: usize) -> Vec<(usize, usize, f64)> {
        let taps = [1.0, 4.0, 6.0, 4.0, 1.0];
        let clamp = |i: usize, d: usize, n: usize| (i + d).saturating_sub(2).min(n - 1);
        let (oh, ow) = (h.div_ceil(stride), w.div_ceil(stride));
        let mut terms = Vec::new();
        for i in 0..oh {
            for j in 0..ow {
                for (a, ta) in taps.iter().enumerate() {
                    for (b, tb) in taps.iter().enumerate() {
                        let source = clamp(i * stride, a, h) * w + clamp(j * stride, b, w);
                        terms.push((i * ow + j, source, ta * tb / 256.0));
                    }
                }
            }
        }
        terms
    }

    /// Values from a fixed integer hash, so the test needs no random generator.
    fn values(n: usize, salt: usize) -> Vec<f64> {
        (0..n)
            .map(|i| (((i * 7919 + salt * 104_729) % 1000) as f64) / 500.0 - 1.0)
            .collect()
    }

    /// Forward against the direct kernel, backward against its adjoint, at strides 1 and 2 on
    /// odd and even sizes.
    #[test]
    fn blur_and_its_gradient_equal_the_direct_kernel() {
        for stride in [1, 2] {
            for (h, w) in [(1usize, 1usize), (1, 4), (5, 1), (6, 6), (7, 9)] {
                let (oh, ow) = (h.div_ceil(stride), w.div_ceil(stride));
                let planes = 2 * 3;
                let x = values(planes * h * w, h * 10 + w);
                let u = values(planes * oh * ow, h * 10 + w + 1);
                let xs = Var::from_vec(x.clone(), (2, 3, h, w), &Device::Cpu).unwrap();
                let us = Tensor::from_vec(u.clone(), (2, 3, oh, ow), &Device::Cpu).unwrap();
                let ys = blur(xs.as_tensor(), stride).unwrap();
                assert_eq!(ys.dims(), &[2, 3, oh, ow]);
                let grads = (&ys * &us).unwrap().sum_all().unwrap().backward().unwrap();
                let ours = ys.flatten_all().unwrap().to_vec1::<f64>().unwrap();
                let grad = grads.get(&xs).unwrap().flatten_all().unwrap();
                let grad = grad.to_vec1::<f64>().unwrap();
                for p in 0..planes {
                    let (mut want, mut want_grad) = (vec![0.0; oh * ow], vec![0.0; h * w]);
                    for (o, s, k) in direct_terms(h, w, stride) {
                        want[o] += k * x[p * h * w + s];
                        want_grad[s] += k * u[p * oh * ow + o];
                    }
                    let got = &ours[p * oh * ow..(p + 1) * oh * ow];
                    let got_grad = &grad[p * h * w..(p + 1) * h * w];
                    for (g, w) in got.iter().zip(&want).chain(got_grad.iter().zip(&want_grad)) {
                        assert!((g - w).abs() < 1e-14, "{h}x{w} stride {stride}: {g} vs {w}");
                    }
                }
            }
        }
    }
}
