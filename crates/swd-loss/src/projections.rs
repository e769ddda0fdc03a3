//! Projection directions: a `(C, K)` matrix whose K columns are directions in feature space.

use candle_core::{DType, Device, Tensor};
use rand::Rng;
use rand_distr::StandardNormal;

use crate::error::{invalid, Result};

/// K projection directions in a C-dimensional feature space, stored as a `(C, K)` matrix
/// (one direction per column, the layout POT uses).
///
/// [`Projections::random`] draws unit directions uniformly on the sphere from a caller's RNG, so
/// the same seed gives the same directions; [`Projections::from_tensor`] takes any fixed matrix.
///
/// ```
/// use candle_core::Device;
/// use rand::SeedableRng;
/// use swd_loss::Projections;
///
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
/// let p = Projections::random(3, 16, &mut rng, &Device::Cpu)?;
/// assert_eq!((p.dim(), p.count()), (3, 16));
/// # Ok::<(), swd_loss::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Projections {
    matrix: Tensor,
}

impl Projections {
    /// Draws `count` directions uniformly on the unit sphere of dimension `dim` (normalised
    /// standard normal vectors), as an `f64` matrix on `device`.
    ///
    /// Errors if `dim` or `count` is zero.
    pub fn random<R: Rng + ?Sized>(
        dim: usize,
        count: usize,
        rng: &mut R,
        device: &Device,
    ) -> Result<Self> {
        check_sizes(dim, count)?;
        // Draw column by column so that the directions do not depend on how many are drawn
        // after them; store row-major (C, K) at the end.
        let mut columns = Vec::with_capacity(count);
        for _ in 0..count {
            columns.push(unit_vector(dim, rng));
        }
        let data: Vec<f64> = (0..dim)
            .flat_map(|c| columns.iter().map(move |col| col[c]))
            .collect();
        Ok(Self {
            matrix: Tensor::from_vec(data, (dim, count), device)?,
        })
    }

    /// Uses a caller's `(C, K)` matrix as it is (columns are not normalised: pass unit columns
    /// for a Wasserstein distance; other scales multiply each slice's distance).
    ///
    /// Errors if the tensor is not rank 2, has a zero dimension, is not a float tensor or holds
    /// non-finite values.
    pub fn from_tensor(matrix: Tensor) -> Result<Self> {
        let (dim, count) = matrix.dims2().map_err(|_| {
            invalid(
                "projections",
                format!("expected a (C, K) matrix, got shape {:?}", matrix.dims()),
            )
        })?;
        check_sizes(dim, count)?;
        if !matrix.dtype().is_float() {
            return Err(invalid(
                "projections",
                format!("expected a float matrix, got {:?}", matrix.dtype()),
            ));
        }
        crate::sliced::ensure_finite(&matrix, "projections")?;
        Ok(Self { matrix })
    }

    /// Returns the feature dimension C.
    #[must_use]
    pub fn dim(&self) -> usize {
        self.matrix.dims()[0]
    }

    /// Returns the number of directions K.
    #[must_use]
    pub fn count(&self) -> usize {
        self.matrix.dims()[1]
    }

    /// Returns the `(C, K)` matrix.
    #[must_use]
    pub fn as_tensor(&self) -> &Tensor {
        &self.matrix
    }

    /// Returns the `(K, C)` matrix (one direction per row) in `dtype` on `device`, the form the
    /// projection kernels multiply with.
    pub(crate) fn rows_as(&self, dtype: DType, device: &Device) -> Result<Tensor> {
        Ok(self
            .matrix
            .to_device(device)?
            .to_dtype(dtype)?
            .t()?
            .contiguous()?)
    }
}

fn check_sizes(dim: usize, count: usize) -> Result<()> {
    if dim == 0 {
        return Err(invalid(
            "projections",
            "feature dimension C must be at least 1",
        ));
    }
    if count == 0 {
        return Err(invalid(
            "projections",
            "the number of projections K must be at least 1",
        ));
    }
    Ok(())
}

/// Draws a standard normal vector and normalises it; redraws in the (probability zero, but
/// possible in floating point) case of a zero vector.
fn unit_vector<R: Rng + ?Sized>(dim: usize, rng: &mut R) -> Vec<f64> {
    loop {
        let v: Vec<f64> = (0..dim).map(|_| rng.sample(StandardNormal)).collect();
        let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        if norm > 0.0 {
            return v.into_iter().map(|a| a / norm).collect();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn random_columns_are_unit_and_seeded() -> Result<()> {
        let a = Projections::random(5, 9, &mut ChaCha8Rng::seed_from_u64(1), &Device::Cpu)?;
        let b = Projections::random(5, 9, &mut ChaCha8Rng::seed_from_u64(1), &Device::Cpu)?;
        let norms = a.as_tensor().sqr()?.sum(0)?.to_vec1::<f64>()?;
        assert!(norms.iter().all(|n| (n - 1.0).abs() < 1e-12), "{norms:?}");
        assert_eq!(
            a.as_tensor().to_vec2::<f64>()?,
            b.as_tensor().to_vec2::<f64>()?
        );
        Ok(())
    }

    #[test]
    fn rejects_empty_and_non_finite() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        assert!(Projections::random(0, 3, &mut rng, &Device::Cpu).is_err());
        assert!(Projections::random(3, 0, &mut rng, &Device::Cpu).is_err());
        let nan = Tensor::new(&[[1.0f32, f32::NAN]], &Device::Cpu).unwrap();
        assert!(matches!(
            Projections::from_tensor(nan),
            Err(crate::Error::NonFinite { .. })
        ));
        let vector = Tensor::new(&[1.0f32, 2.0], &Device::Cpu).unwrap();
        assert!(matches!(
            Projections::from_tensor(vector),
            Err(crate::Error::InvalidArgument { .. })
        ));
    }
}
