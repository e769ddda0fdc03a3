//! Diversity-MV: how much generated scenes differ from each other, per view, relative to the
//! contrast of the real view.

use candle_core::{Tensor, D};

use crate::error::{invalid, Result};

/// The paper's Diversity-MV: for each view, the per-pixel standard deviation over the generated
/// scenes (mean over pixels and channels), divided by the standard deviation of the real view's
/// pixels; averaged over views. `generated` holds one `(V, 3, H, W)` tensor per scene, all seen
/// from the cameras of `real` `(V, 3, H, W)`.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::rand(0f32, 1., (2, 3, 8, 8), &Device::Cpu)?;
/// // Identical scenes have no diversity.
/// let same = vec![real.clone(), real.clone(), real.clone()];
/// assert_eq!(scene_metrics::diversity_mv(&same, &real)?, 0.0);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn diversity_mv(generated: &[Tensor], real: &Tensor) -> Result<f64> {
    super::check_scenes(generated, real, 2)?;
    let views = real.dim(0)?;
    let stack = Tensor::stack(generated, 0)?.to_dtype(candle_core::DType::F64)?;
    // Population standard deviation over scenes, per view and pixel.
    let mean = stack.mean_keepdim(0)?;
    let spread = stack.broadcast_sub(&mean)?.sqr()?.mean(0)?.sqrt()?;
    let spread = spread.flatten_from(1)?.mean(D::Minus1)?;
    let real = real.to_dtype(candle_core::DType::F64)?.flatten_from(1)?;
    let real_mean = real.mean_keepdim(D::Minus1)?;
    let real_std = real
        .broadcast_sub(&real_mean)?
        .sqr()?
        .mean(D::Minus1)?
        .sqrt()?;
    let spread: Vec<f64> = spread.to_vec1()?;
    let real_std: Vec<f64> = real_std.to_vec1()?;
    if let Some(v) = real_std.iter().position(|s| *s == 0.0) {
        return Err(invalid(
            "real",
            format!("view {v} is constant: its spread is 0"),
        ));
    }
    Ok(spread
        .iter()
        .zip(&real_std)
        .map(|(s, r)| s / r)
        .sum::<f64>()
        / views as f64)
}
