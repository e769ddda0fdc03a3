//! Peak signal-to-noise ratio between rendered and real views.

use candle_core::{DType, Tensor};

use crate::error::{invalid, Result};

/// PSNR in dB of each view of `rendered` against `real`, both `(V, C, H, W)` with values in
/// [0, 1]: `10 log10(1 / mse)` per view, computed in f64. A view that matches exactly gives
/// `f64::INFINITY`.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::zeros((2, 3, 4, 4), candle_core::DType::F32, &Device::Cpu)?;
/// // A constant error of 0.1 is an mse of 0.01: 20 dB.
/// let off = (real.clone() + 0.1)?;
/// let psnr = scene_metrics::psnr_per_view(&off, &real)?;
/// assert!((psnr[0] - 20.0).abs() < 1e-5 && (psnr[1] - 20.0).abs() < 1e-5);
/// assert_eq!(scene_metrics::psnr_per_view(&real, &real)?[0], f64::INFINITY);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn psnr_per_view(rendered: &Tensor, real: &Tensor) -> Result<Vec<f64>> {
    if rendered.shape() != real.shape() || rendered.rank() != 4 {
        return Err(invalid(
            "rendered views",
            format!(
                "expected (V, C, H, W) views shaped like the real ones {:?}, got {:?}",
                real.dims(),
                rendered.dims()
            ),
        ));
    }
    let diff = (rendered.to_dtype(DType::F64)? - real.to_dtype(DType::F64)?)?;
    let mse: Vec<f64> = diff.sqr()?.flatten_from(1)?.mean(1)?.to_vec1()?;
    Ok(mse.into_iter().map(|m| -10.0 * m.log10()).collect())
}

/// The mean over views of [`psnr_per_view`] (the NeRF convention: average the views' dB, not
/// their errors).
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::zeros((1, 3, 4, 4), candle_core::DType::F32, &Device::Cpu)?;
/// let off = (real.clone() + 0.01)?;
/// assert!((scene_metrics::mean_psnr(&off, &real)? - 40.0).abs() < 1e-4);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn mean_psnr(rendered: &Tensor, real: &Tensor) -> Result<f64> {
    let per_view = psnr_per_view(rendered, real)?;
    Ok(per_view.iter().sum::<f64>() / per_view.len() as f64)
}
