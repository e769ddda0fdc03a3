//! Texture losses: sliced Wasserstein distances between the feature distributions of images.
//!
//! A [`FeatureExtractor`] turns a batch of images into feature maps, one per layer; every
//! spatial position of a layer (or every `p x p` patch, for patch features) is one point of
//! that layer's distribution. [`TextureLoss`] compares the distribution of each generated
//! image with its target's, layer by layer, and sums the layers with per-layer weights.

mod pyramid;
mod vgg;

pub use pyramid::{PatchPyramid, PatchPyramidConfig, PyramidKind};
pub use vgg::{Padding, Pooling, Vgg19, Vgg19Config, VggLayer};

use candle_core::{Device, Tensor, D};
use rand::Rng;

use crate::error::{invalid, Result};
use crate::projections::Projections;
use crate::sliced::{sliced_projected, Metric};

/// One layer of features: a `(B, C, H, W)` map whose points are its `patch x patch`
/// neighbourhoods (`patch = 1`: each position's C-vector; `patch = 7`: 49 C-vectors flattened
/// in `(c, dy, dx)` order, `C * 49` dimensions).
#[derive(Debug, Clone)]
pub struct FeatureMap {
    /// The `(B, C, H, W)` feature map.
    pub values: Tensor,
    /// The side of the square neighbourhood that forms one point (1 for per-pixel features).
    pub patch: usize,
}

impl FeatureMap {
    /// Returns the dimension of one point, `C * patch^2`.
    pub fn point_dim(&self) -> Result<usize> {
        let (_, c, _, _) = self.values.dims4()?;
        Ok(c * self.patch * self.patch)
    }

    /// Returns the number of points, `(H - patch + 1) (W - patch + 1)`: every position where a
    /// whole patch fits.
    pub fn point_count(&self) -> Result<usize> {
        let (oh, ow) = self.patch_grid()?;
        Ok(oh * ow)
    }

    /// The positions of the patches' top-left corners: `(H - p + 1, W - p + 1)`.
    fn patch_grid(&self) -> Result<(usize, usize)> {
        let (_, _, h, w) = self.values.dims4()?;
        let p = self.patch;
        if p == 0 || h < p || w < p {
            return Err(invalid(
                "feature map",
                format!("a {h}x{w} map has no {p}x{p} patches"),
            ));
        }
        Ok((h - p + 1, w - p + 1))
    }

    /// Projects points onto the directions: `(B, K, P)`, with every point (`positions` `None`)
    /// or the points at `positions` (flat indices `y * (W - p + 1) + x` of patch corners, the
    /// same for every image of the batch).
    ///
    /// Patches are gathered into a `(B, C p^2, P)` matrix (one `index_select`) and multiplied by
    /// the `(K, C p^2)` directions. This is what `conv2d` does inside, but its backward in
    /// candle 0.11 goes through `conv_transpose2d` and a full-image-sized kernel, much slower
    /// (measured in docs/performance-swd.md); an index_select's backward is an index_add.
    fn project(&self, projections: &Projections, positions: Option<&[u32]>) -> Result<Tensor> {
        let (b, c, h, w) = self.values.dims4()?;
        let p = self.patch;
        let (oh, ow) = self.patch_grid()?;
        if projections.dim() != c * p * p {
            return Err(invalid(
                "projections",
                format!(
                    "projections are {}-dimensional but {p}x{p} patches of {c} channels have {} dimensions",
                    projections.dim(),
                    c * p * p
                ),
            ));
        }
        let rows = projections.rows_as(self.values.dtype(), self.values.device())?;
        let pixels = self.values.reshape((b, c, h * w))?;
        let points = match (p, positions) {
            (1, None) => pixels,
            _ => {
                let count = positions.map_or(oh * ow, <[u32]>::len);
                let index = patch_index(w, p, ow, positions, count, self.values.device())?;
                pixels
                    .index_select(&index, 2)?
                    .reshape((b, c * p * p, count))?
            }
        };
        Ok(rows.broadcast_matmul(&points)?)
    }
}

/// Flat pixel indices of `p x p` patches of a `w`-wide image whose corners lie on a grid `ow`
/// wide (all `count` of them in order, or those at `positions`), ordered `(dy, dx, point)` so
/// that selecting them from `(B, C, H W)` and reshaping gives rows in `(c, dy, dx)` order and
/// one column per patch.
fn patch_index(
    w: usize,
    p: usize,
    ow: usize,
    positions: Option<&[u32]>,
    count: usize,
    device: &Device,
) -> Result<Tensor> {
    let corner = |i: u32| (i / ow as u32) * w as u32 + i % ow as u32;
    let corners: Vec<u32> = match positions {
        Some(positions) => positions.iter().map(|&i| corner(i)).collect(),
        None => (0..count as u32).map(corner).collect(),
    };
    let mut index = Vec::with_capacity(p * p * count);
    for dy in 0..p {
        for dx in 0..p {
            let offset = (dy * w + dx) as u32;
            index.extend(corners.iter().map(|&c| c + offset));
        }
    }
    Ok(Tensor::from_vec(index, p * p * count, device)?)
}

/// How many points of each layer one evaluation of [`TextureLoss::loss`] compares.
///
/// At 320^2 the finest level of the patch pyramid holds 98,596 patches of 147 dimensions, and
/// projecting, sorting and back-propagating all of them is most of a last-scale training step.
/// A random subset of a few thousand gives nearly the same gradient: the directions, also
/// random, are the larger part of its noise (docs/swd-loss.md has the measured error against
/// run time).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Points {
    /// Every point of every layer (exact along the drawn directions).
    #[default]
    All,
    /// At most this many points per layer and image batch: positions drawn uniformly without
    /// replacement at every call, separately for the generated and the target images (each
    /// draw shared by the images of its batch). Layers with fewer points use them all. Each
    /// slice then compares two empirical distributions of the subsets (exact 1D distance
    /// between them, [`crate::sliced_wasserstein`]'s).
    Random(usize),
}

impl Points {
    /// Draws the positions of one layer with `total` points: `None` for all of them, else a
    /// sorted random subset (sorted so that the gather reads memory in order).
    fn draw<R: Rng + ?Sized>(self, total: usize, rng: &mut R) -> Option<Vec<u32>> {
        match self {
            Self::Random(n) if n < total => {
                let mut picked: Vec<u32> = rand::seq::index::sample(rng, total, n)
                    .into_iter()
                    .map(|i| i as u32)
                    .collect();
                picked.sort_unstable();
                Some(picked)
            }
            _ => None,
        }
    }
}

/// Turns a batch of images into feature maps, one per layer.
pub trait FeatureExtractor {
    /// Returns how many feature maps [`FeatureExtractor::extract`] returns.
    fn layer_count(&self) -> usize;

    /// Extracts the feature maps of `images` `(B, 3, H, W)`, in a fixed layer order.
    fn extract(&self, images: &Tensor) -> Result<Vec<FeatureMap>>;
}

/// How many random directions each layer is sliced along.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slices {
    /// The same number for every layer.
    Fixed(usize),
    /// As many as the layer's point dimension (Heitz et al.: one per VGG channel).
    MatchDim,
}

/// Settings of a [`TextureLoss`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TextureLossConfig {
    /// Directions per layer (default: 64).
    pub slices: Slices,
    /// The 1D distance per slice (default: squared W2, as Heitz et al.).
    pub metric: Metric,
    /// The points of each layer [`TextureLoss::loss`] compares (default: all).
    pub points: Points,
}

impl Default for TextureLossConfig {
    fn default() -> Self {
        Self {
            slices: Slices::Fixed(64),
            metric: Metric::SquaredW2,
            points: Points::All,
        }
    }
}

impl TextureLossConfig {
    /// Sets the directions per layer.
    #[must_use]
    pub fn with_slices(self, slices: Slices) -> Self {
        Self { slices, ..self }
    }

    /// Sets the 1D distance per slice.
    #[must_use]
    pub fn with_metric(self, metric: Metric) -> Self {
        Self { metric, ..self }
    }

    /// Sets the points compared per layer.
    #[must_use]
    pub fn with_points(self, points: Points) -> Self {
        Self { points, ..self }
    }
}

/// The feature maps of target images, computed once and reused by every loss evaluation.
#[derive(Debug, Clone)]
pub struct TextureTarget {
    maps: Vec<FeatureMap>,
}

impl TextureTarget {
    /// Returns the target's feature maps (detached from any graph).
    #[must_use]
    pub fn maps(&self) -> &[FeatureMap] {
        &self.maps
    }

    /// Returns the target of images `indices` of this target's batch, in that order: extract
    /// the features of a fixed set of images once, then pick the ones each step compares.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use swd_loss::{PatchPyramid, PatchPyramidConfig, TextureLoss, TextureLossConfig};
    ///
    /// let loss = TextureLoss::new(PatchPyramid::new(PatchPyramidConfig::default())?, TextureLossConfig::default())?;
    /// let views = Tensor::rand(0f32, 1.0, (5, 3, 32, 32), &Device::Cpu)?;
    /// let all = loss.target(&views)?;
    /// let two = all.select(&[4, 1])?;
    /// assert_eq!(two.maps()[0].values.dims(), &[2, 3, 32, 32]);
    /// # Ok::<(), swd_loss::Error>(())
    /// ```
    pub fn select(&self, indices: &[usize]) -> Result<Self> {
        let batch = self.maps.first().map_or(Ok(0), |m| m.values.dim(0))?;
        if indices.is_empty() || indices.iter().any(|&i| i >= batch) {
            return Err(invalid(
                "indices",
                format!("expected 1 or more image indices below {batch}, got {indices:?}"),
            ));
        }
        let device = self.maps[0].values.device();
        let index = Tensor::from_vec(
            indices.iter().map(|&i| i as u32).collect::<Vec<_>>(),
            indices.len(),
            device,
        )?;
        let maps = self
            .maps
            .iter()
            .map(|m| {
                Ok(FeatureMap {
                    values: m.values.index_select(&index, 0)?,
                    patch: m.patch,
                })
            })
            .collect::<Result<_>>()?;
        Ok(Self { maps })
    }
}

/// A sliced Wasserstein texture loss over the layers of a feature extractor.
///
/// For each generated image b and layer l, the points of l (pixels or patches) of image b are
/// compared with those of its target (the single target image, or target b of a batch of the
/// same size): `loss = mean_b sum_l w_l * mean_k SW_k(gen_b, target_b)`. Image sizes may differ
/// between generated and target images (their quantile functions are compared exactly).
///
/// ```
/// use candle_core::{Device, Tensor};
/// use rand::SeedableRng;
/// use swd_loss::{PatchPyramid, PatchPyramidConfig, TextureLoss, TextureLossConfig};
///
/// let dev = Device::Cpu;
/// let pyramid = PatchPyramid::new(PatchPyramidConfig::default().with_levels(2))?;
/// let loss = TextureLoss::new(pyramid, TextureLossConfig::default())?;
/// let target = loss.target(&Tensor::rand(0f32, 1.0, (1, 3, 24, 24), &dev)?)?;
/// let generated = Tensor::rand(0f32, 1.0, (2, 3, 20, 20), &dev)?;
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
/// let value = loss.loss(&generated, &target, &mut rng)?;
/// assert!(value.to_scalar::<f32>()? > 0.0);
/// # Ok::<(), swd_loss::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct TextureLoss<E> {
    extractor: E,
    config: TextureLossConfig,
    layer_weights: Vec<f64>,
}

impl<E: FeatureExtractor> TextureLoss<E> {
    /// Builds the loss with weight 1 for every layer.
    ///
    /// Errors on `Slices::Fixed(0)`, `Points::Random(0)` or an extractor without layers.
    pub fn new(extractor: E, config: TextureLossConfig) -> Result<Self> {
        if config.slices == Slices::Fixed(0) {
            return Err(invalid(
                "slices",
                "at least one projection per layer is needed",
            ));
        }
        if config.points == Points::Random(0) {
            return Err(invalid("points", "at least one point per layer is needed"));
        }
        let layers = extractor.layer_count();
        if layers == 0 {
            return Err(invalid("extractor", "the feature extractor has no layers"));
        }
        Ok(Self {
            extractor,
            config,
            layer_weights: vec![1.0; layers],
        })
    }

    /// Sets one weight per layer (finite, non-negative), in the extractor's layer order.
    pub fn with_layer_weights(self, weights: Vec<f64>) -> Result<Self> {
        if weights.len() != self.layer_weights.len() {
            return Err(invalid(
                "layer weights",
                format!(
                    "the extractor has {} layers but {} weights were given",
                    self.layer_weights.len(),
                    weights.len()
                ),
            ));
        }
        if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
            return Err(invalid(
                "layer weights",
                format!("weights must be finite and non-negative, got {w}"),
            ));
        }
        Ok(Self {
            layer_weights: weights,
            ..self
        })
    }

    /// Returns the feature extractor.
    #[must_use]
    pub fn extractor(&self) -> &E {
        &self.extractor
    }

    /// Returns the per-layer weights.
    #[must_use]
    pub fn layer_weights(&self) -> &[f64] {
        &self.layer_weights
    }

    /// Extracts (and detaches) the feature maps of target images `(1 or B, 3, H, W)`.
    pub fn target(&self, images: &Tensor) -> Result<TextureTarget> {
        let maps = self.extract_checked(images)?;
        Ok(TextureTarget {
            maps: maps
                .into_iter()
                .map(|m| FeatureMap {
                    values: m.values.detach(),
                    patch: m.patch,
                })
                .collect(),
        })
    }

    /// Draws fresh directions for every layer of `target` from `rng`, as many as
    /// [`TextureLossConfig::slices`] says.
    pub fn draw_projections<R: Rng + ?Sized>(
        &self,
        target: &TextureTarget,
        rng: &mut R,
    ) -> Result<Vec<Projections>> {
        target
            .maps
            .iter()
            .map(|map| {
                let dim = map.point_dim()?;
                let count = match self.config.slices {
                    Slices::Fixed(k) => k,
                    Slices::MatchDim => dim,
                };
                Projections::random(dim, count, rng, map.values.device())
            })
            .collect()
    }

    /// Computes the loss of `generated` `(B, 3, H, W)` against `target` along directions drawn
    /// afresh from `rng` (the resampling Heitz et al. recommend), over the points
    /// [`TextureLossConfig::points`] says (their positions drawn from `rng` too, after the
    /// directions); a scalar tensor.
    pub fn loss<R: Rng + ?Sized>(
        &self,
        generated: &Tensor,
        target: &TextureTarget,
        rng: &mut R,
    ) -> Result<Tensor> {
        let projections = self.draw_projections(target, rng)?;
        let points = self.config.points;
        self.evaluate(generated, target, &projections, &mut |total| {
            points.draw(total, rng)
        })
    }

    /// Computes the loss along fixed directions, one [`Projections`] per layer, over every point
    /// whatever [`TextureLossConfig::points`] says (a deterministic evaluation, as metrics
    /// want); a scalar tensor.
    pub fn loss_with_projections(
        &self,
        generated: &Tensor,
        target: &TextureTarget,
        projections: &[Projections],
    ) -> Result<Tensor> {
        self.evaluate(generated, target, projections, &mut |_| None)
    }

    /// The loss along `projections`; `positions(points)` picks the points of a layer of the
    /// generated or the target batch with that many (`None`: all).
    fn evaluate(
        &self,
        generated: &Tensor,
        target: &TextureTarget,
        projections: &[Projections],
        positions: &mut dyn FnMut(usize) -> Option<Vec<u32>>,
    ) -> Result<Tensor> {
        let maps = self.extract_checked(generated)?;
        if projections.len() != maps.len() || target.maps.len() != maps.len() {
            return Err(invalid(
                "projections",
                format!(
                    "the extractor gives {} layers, the target {} and the projections {}",
                    maps.len(),
                    target.maps.len(),
                    projections.len()
                ),
            ));
        }
        let mut total: Option<Tensor> = None;
        for (l, ((gen, tgt), proj)) in maps.iter().zip(&target.maps).zip(projections).enumerate() {
            check_layer_pair(l, gen, tgt)?;
            let gen_points = positions(gen.point_count()?);
            let tgt_points = positions(tgt.point_count()?);
            let per_slice = sliced_projected(
                &gen.project(proj, gen_points.as_deref())?,
                &tgt.project(proj, tgt_points.as_deref())?,
                self.config.metric,
                "generated features",
                "target features",
            )?;
            let layer = (per_slice.mean(D::Minus1)? * self.layer_weights[l])?;
            total = Some(match total {
                None => layer,
                Some(t) => (t + layer)?,
            });
        }
        let per_image = total.ok_or_else(|| invalid("extractor", "no feature maps"))?;
        Ok(per_image.mean(0)?)
    }

    fn extract_checked(&self, images: &Tensor) -> Result<Vec<FeatureMap>> {
        if images.rank() != 4 || images.elem_count() == 0 {
            return Err(invalid(
                "images",
                format!(
                    "expected non-empty (B, 3, H, W) images, got shape {:?}",
                    images.dims()
                ),
            ));
        }
        let maps = self.extractor.extract(images)?;
        if maps.len() != self.layer_weights.len() {
            return Err(invalid(
                "extractor",
                format!(
                    "the extractor promised {} layers but returned {}",
                    self.layer_weights.len(),
                    maps.len()
                ),
            ));
        }
        Ok(maps)
    }
}

/// Checks that a generated layer and its target layer can be compared.
fn check_layer_pair(layer: usize, gen: &FeatureMap, tgt: &FeatureMap) -> Result<()> {
    let (b, c, _, _) = gen.values.dims4()?;
    let (bt, ct, _, _) = tgt.values.dims4()?;
    if c != ct || gen.patch != tgt.patch {
        return Err(invalid(
            "target",
            format!(
                "layer {layer}: generated points are {c} channels x {p}^2, target points {ct} x {pt}^2",
                p = gen.patch,
                pt = tgt.patch
            ),
        ));
    }
    if bt != 1 && bt != b {
        return Err(invalid(
            "target",
            format!("layer {layer}: {bt} target images for {b} generated images (need 1 or {b})"),
        ));
    }
    Ok(())
}
