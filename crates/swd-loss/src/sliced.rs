//! The sliced Wasserstein distance between two sets of feature vectors.

use std::borrow::Cow;

use candle_core::{DType, Tensor};
use rand::Rng;

use crate::error::{invalid, Error, Result};
use crate::projections::Projections;
use crate::quantile::Coupling;
use crate::sort::sort_last_dim;

/// Which 1D Wasserstein distance each slice contributes.
///
/// Both are averaged over the K projections. POT's `ot.sliced_wasserstein_distance(p=2)` is the
/// square root of [`Metric::SquaredW2`]; with `p=1` it equals [`Metric::W1`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Metric {
    /// `W_2^2` per slice: the mean squared difference of matched quantiles. Smooth almost
    /// everywhere, with gradient `2 (x - y_matched) / n` per point: the usual training loss.
    #[default]
    SquaredW2,
    /// `W_1` per slice: the mean absolute difference of matched quantiles (as ProGAN's metric).
    W1,
}

impl Metric {
    /// Maps differences of matched quantiles to the integrand.
    fn integrand(self, diff: &Tensor) -> Result<Tensor> {
        Ok(match self {
            Self::SquaredW2 => diff.sqr()?,
            Self::W1 => diff.abs()?,
        })
    }
}

/// Computes the sliced Wasserstein distance between the rows of `x` `(N, C)` and `y` `(M, C)`
/// along fixed `projections` `(C, K)`: the mean over the K slices of the 1D distance chosen by
/// `metric`.
///
/// N and M may differ: each slice then integrates the difference of the two empirical quantile
/// step functions exactly (see the crate docs). Gradients flow to `x` and `y` (through the sort,
/// as a gather). `x` and `y` must share dtype and device; the projections are converted to them.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use swd_loss::{sliced_wasserstein, Metric, Projections};
///
/// let x = Tensor::new(&[[0.0f64], [1.0]], &Device::Cpu)?;
/// let y = Tensor::new(&[[3.0f64], [2.0]], &Device::Cpu)?;
/// let p = Projections::from_tensor(Tensor::new(&[[1.0f64]], &Device::Cpu)?)?;
/// // Sorted pairs (0, 2) and (1, 3): W2^2 = (4 + 4) / 2.
/// let d = sliced_wasserstein(&x, &y, &p, Metric::SquaredW2)?;
/// assert_eq!(d.to_scalar::<f64>()?, 4.0);
/// # Ok::<(), swd_loss::Error>(())
/// ```
pub fn sliced_wasserstein(
    x: &Tensor,
    y: &Tensor,
    projections: &Projections,
    metric: Metric,
) -> Result<Tensor> {
    Ok(sliced_wasserstein_per_projection(x, y, projections, metric)?.mean(0)?)
}

/// Computes the 1D distance of every slice, a `(K,)` tensor, whose mean is
/// [`sliced_wasserstein`]. Its spread gives the Monte Carlo error of the mean over random
/// directions: `std / sqrt(K)`.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use swd_loss::{sliced_wasserstein_per_projection, Metric, Projections};
///
/// let x = Tensor::new(&[[0.0f64, 0.0]], &Device::Cpu)?;
/// let y = Tensor::new(&[[1.0f64, 2.0]], &Device::Cpu)?;
/// let axes = Projections::from_tensor(Tensor::new(&[[1.0f64, 0.0], [0.0, 1.0]], &Device::Cpu)?)?;
/// let per = sliced_wasserstein_per_projection(&x, &y, &axes, Metric::W1)?;
/// assert_eq!(per.to_vec1::<f64>()?, vec![1.0, 2.0]);
/// # Ok::<(), swd_loss::Error>(())
/// ```
pub fn sliced_wasserstein_per_projection(
    x: &Tensor,
    y: &Tensor,
    projections: &Projections,
    metric: Metric,
) -> Result<Tensor> {
    let (n, c) = point_set_dims(x, "x")?;
    let (m, c_y) = point_set_dims(y, "y")?;
    if c != c_y {
        return Err(invalid(
            "y",
            format!("x has {c} features per point but y has {c_y}"),
        ));
    }
    if projections.dim() != c {
        return Err(invalid(
            "projections",
            format!(
                "projections are {}-dimensional but the points have {c} features",
                projections.dim()
            ),
        ));
    }
    if x.dtype() != y.dtype() {
        return Err(invalid(
            "y",
            format!("x is {:?} but y is {:?}", x.dtype(), y.dtype()),
        ));
    }
    let rows = projections.rows_as(x.dtype(), x.device())?;
    // (K, C) x (C, N) -> (K, N): each slice is a row, ready to sort along the last dimension.
    let xp = rows.matmul(&x.t()?)?.reshape((1, rows.dim(0)?, n))?;
    let yp = rows.matmul(&y.t()?)?.reshape((1, rows.dim(0)?, m))?;
    Ok(sliced_projected(&xp, &yp, metric, "x", "y")?.squeeze(0)?)
}

/// Draws `count` fresh random directions from `rng` and computes [`sliced_wasserstein`]: the
/// entry point for losses that resample their slices at every call.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use rand::SeedableRng;
/// use swd_loss::{sliced_wasserstein_resampled, Metric};
///
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
/// let x = Tensor::randn(0f32, 1.0, (64, 4), &Device::Cpu)?;
/// let d = sliced_wasserstein_resampled(&x, &x, 32, Metric::SquaredW2, &mut rng)?;
/// assert_eq!(d.to_scalar::<f32>()?, 0.0);
/// # Ok::<(), swd_loss::Error>(())
/// ```
pub fn sliced_wasserstein_resampled<R: Rng + ?Sized>(
    x: &Tensor,
    y: &Tensor,
    count: usize,
    metric: Metric,
    rng: &mut R,
) -> Result<Tensor> {
    let (_, c) = point_set_dims(x, "x")?;
    let projections = Projections::random(c, count, rng, x.device())?;
    sliced_wasserstein(x, y, &projections, metric)
}

/// The shared kernel: `xp` `(B, K, N)` and `yp` `(B or 1, K, M)` hold projected values, one
/// slice per row; returns the `(B, K)` per-slice distances. `x_name`/`y_name` label errors.
pub(crate) fn sliced_projected(
    xp: &Tensor,
    yp: &Tensor,
    metric: Metric,
    x_name: &'static str,
    y_name: &'static str,
) -> Result<Tensor> {
    let (_, _, n) = xp.dims3()?;
    let (_, _, m) = yp.dims3()?;
    // Sorting NaNs gives an arbitrary order (and may panic in the standard sort), so refuse them.
    ensure_finite(xp, x_name)?;
    ensure_finite(yp, y_name)?;
    let xs = sort_last_dim(xp)?;
    let ys = sort_last_dim(yp)?;
    let coupling = Coupling::new(n, m, xp.dtype(), xp.device())?;
    let (a, b) = coupling.align(&xs, &ys)?;
    coupling.integrate(&metric.integrand(&a.broadcast_sub(&b)?)?)
}

/// Returns the `(N, C)` sizes of a point set, refusing other ranks and empty sets.
fn point_set_dims(t: &Tensor, what: &'static str) -> Result<(usize, usize)> {
    let (n, c) = t.dims2().map_err(|_| {
        invalid(
            what,
            format!(
                "expected an (N, C) matrix of points, got shape {:?}",
                t.dims()
            ),
        )
    })?;
    if n == 0 || c == 0 {
        return Err(invalid(
            what,
            format!("the point set is empty (shape {:?})", t.dims()),
        ));
    }
    Ok((n, c))
}

/// Fails with [`Error::NonFinite`] if `t` holds a NaN or an infinity.
///
/// `t - t` is 0 for every finite value and NaN otherwise, so its sum is 0 exactly when all
/// values are finite (no overflow is possible, unlike summing `t` itself).
pub(crate) fn ensure_finite(t: &Tensor, what: impl Into<Cow<'static, str>>) -> Result<()> {
    let t = t.detach();
    let probe = t
        .sub(&t)?
        .sum_all()?
        .to_dtype(DType::F64)?
        .to_scalar::<f64>()?;
    if probe == 0.0 {
        Ok(())
    } else {
        Err(Error::NonFinite { what: what.into() })
    }
}
