//! Root-mean-square error of rendered depth against the dataset's depth maps.

use candle_core::{DType, Tensor};

use crate::error::{invalid, Result};

/// The RMSE in world units between rendered and real expected depth, both `(V, 1, H, W)` (or
/// any equal shapes), over every pixel of every view, computed in f64.
///
/// Both are expected depth as the renderer and the dataset format define it (the sum of the
/// weights times the distance, 0 where nothing is hit), so empty sky compares as 0 against 0
/// and matter in the sky counts as an error.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::new(&[[[[2.0f32, 3.0], [0.0, 4.0]]]], &Device::Cpu)?;
/// let rendered = Tensor::new(&[[[[2.0f32, 3.0], [1.0, 2.0]]]], &Device::Cpu)?;
/// // Errors 0, 0, 1, -2: sqrt(5 / 4).
/// let rmse = scene_metrics::depth_rmse(&rendered, &real)?;
/// assert!((rmse - 1.25f64.sqrt()).abs() < 1e-12);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn depth_rmse(rendered: &Tensor, real: &Tensor) -> Result<f64> {
    if rendered.shape() != real.shape() || real.elem_count() == 0 {
        return Err(invalid(
            "rendered depth",
            format!(
                "expected depth maps shaped like the real ones {:?}, got {:?}",
                real.dims(),
                rendered.dims()
            ),
        ));
    }
    let diff = (rendered.to_dtype(DType::F64)? - real.to_dtype(DType::F64)?)?;
    Ok(diff.sqr()?.mean_all()?.to_scalar::<f64>()?.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn identical_depth_is_zero_and_a_constant_offset_is_its_size() {
        let real = Tensor::rand(0f32, 5., (3, 1, 6, 7), &Device::Cpu).unwrap();
        assert_eq!(depth_rmse(&real, &real).unwrap(), 0.0);
        let off = (&real - 0.25).unwrap();
        assert!((depth_rmse(&off, &real).unwrap() - 0.25).abs() < 1e-6);
        let other = Tensor::zeros((3, 1, 6, 6), DType::F32, &Device::Cpu).unwrap();
        let err = depth_rmse(&other, &real).unwrap_err().to_string();
        assert!(err.contains("[3, 1, 6, 7]"), "{err}");
    }
}
