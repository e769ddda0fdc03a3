//! The Fréchet distance between Gaussians fitted to feature sets: the "FD" of FID and SIFID,
//! computed in float64 through symmetric eigendecompositions instead of a general matrix square
//! root.

use candle_core::{DType, Tensor};
use nalgebra::{DMatrix, DVector, SymmetricEigen};

use crate::error::{invalid, Result};

/// Iteration cap of the symmetric eigendecomposition: far above what a 64 x 64 covariance needs
/// (nalgebra's own default is unbounded), so a pathological matrix is an error, not a hang.
const MAX_EIGEN_ITERATIONS: usize = 100_000;

/// Largest asymmetry [`FeatureGaussian::new`] accepts in a covariance, relative to its largest
/// entry: what rounding in a `np.cov` or a matrix product leaves, not a different matrix.
const SYMMETRY_TOLERANCE: f64 = 1e-9;

/// A Gaussian fitted to feature vectors: their mean and their covariance, normalised by n - 1
/// like `np.cov(features, rowvar=False)` in SinGAN's and pytorch-fid's code.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use scene_metrics::FeatureGaussian;
/// // Three 2-D samples, one per row.
/// let set = Tensor::new(&[[1f64, 2.], [3., 4.], [5., 0.]], &Device::Cpu)?;
/// let g = FeatureGaussian::fit(&set)?;
/// assert_eq!(g.mean(), &[3.0, 2.0]);
/// assert_eq!(g.covariance(), &[4.0, -2.0, -2.0, 4.0]);
/// // Moving every sample by the same offset moves only the mean: the distance is its length².
/// let moved = FeatureGaussian::fit(&(set + 2.0)?)?;
/// assert!((g.frechet_distance(&moved)? - 8.0).abs() < 1e-9);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureGaussian {
    mean: DVector<f64>,
    covariance: DMatrix<f64>,
}

impl FeatureGaussian {
    /// Fits the rows of `features` `(n, d)`: n >= 2 samples of d >= 1 finite features.
    pub fn fit(features: &Tensor) -> Result<Self> {
        let (n, d) = features.dims2().map_err(|_| {
            invalid(
                "features",
                format!("expected (samples, features), got {:?}", features.dims()),
            )
        })?;
        if n < 2 || d == 0 {
            return Err(invalid(
                "features",
                format!(
                    "a covariance needs at least 2 samples of at least 1 feature, got {n} x {d}"
                ),
            ));
        }
        let values: Vec<f64> = features.to_dtype(DType::F64)?.flatten_all()?.to_vec1()?;
        if values.iter().any(|v| !v.is_finite()) {
            return Err(invalid("features", "holds NaN or infinite values"));
        }
        let samples = DMatrix::from_row_slice(n, d, &values);
        let mean = samples.row_mean().transpose();
        let mut centred = samples;
        for mut row in centred.row_iter_mut() {
            row -= mean.transpose();
        }
        let covariance = centred.transpose() * &centred / (n - 1) as f64;
        Ok(Self {
            mean,
            covariance: symmetrised(covariance),
        })
    }

    /// A Gaussian from its `mean` (d values) and its `covariance` (d x d, row-major), for
    /// statistics computed elsewhere (such as pytorch-fid's `.npz` files). The covariance must be
    /// symmetric up to rounding; eigenvalues below zero count as zero in the distance.
    ///
    /// ```
    /// use scene_metrics::FeatureGaussian;
    /// let a = FeatureGaussian::new(vec![0.0, 0.0], vec![4.0, 0.0, 0.0, 1.0])?;
    /// let b = FeatureGaussian::new(vec![1.0, 0.0], vec![1.0, 0.0, 0.0, 1.0])?;
    /// // Diagonal covariances: |mu1 - mu2|² + sum (sqrt(s1) - sqrt(s2))² = 1 + 1 + 0.
    /// assert!((a.frechet_distance(&b)? - 2.0).abs() < 1e-12);
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    pub fn new(mean: Vec<f64>, covariance: Vec<f64>) -> Result<Self> {
        let d = mean.len();
        if d == 0 || covariance.len() != d * d {
            return Err(invalid(
                "covariance",
                format!(
                    "expected {d} x {d} = {} values for a mean of {d} (at least 1), got {}",
                    d * d,
                    covariance.len()
                ),
            ));
        }
        if mean.iter().chain(&covariance).any(|v| !v.is_finite()) {
            return Err(invalid(
                "mean and covariance",
                "hold NaN or infinite values",
            ));
        }
        let covariance = DMatrix::from_row_slice(d, d, &covariance);
        let asymmetry = (&covariance - covariance.transpose()).amax();
        if asymmetry > SYMMETRY_TOLERANCE * covariance.amax() {
            return Err(invalid(
                "covariance",
                format!(
                    "is not symmetric (entries differ from their transpose by up to {asymmetry})"
                ),
            ));
        }
        Ok(Self {
            mean: DVector::from_vec(mean),
            covariance: symmetrised(covariance),
        })
    }

    /// Returns the number of features d.
    #[must_use]
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Returns the mean (d values).
    #[must_use]
    pub fn mean(&self) -> &[f64] {
        self.mean.as_slice()
    }

    /// Returns the covariance, d x d (symmetric, so row- and column-major alike).
    #[must_use]
    pub fn covariance(&self) -> &[f64] {
        self.covariance.as_slice()
    }

    /// The squared Fréchet distance `|mu1 - mu2|² + tr(S1 + S2 - 2 (S1 S2)^(1/2))` to `other`,
    /// the quantity FID and SIFID report (not its square root).
    ///
    /// `tr((S1 S2)^(1/2))` is computed as the sum of the square roots of the eigenvalues of the
    /// symmetric positive semi-definite `S1^(1/2) S2 S1^(1/2)`, which has the eigenvalues of
    /// `S1 S2`: two symmetric eigendecompositions in float64, stable where `scipy.linalg.sqrtm`
    /// of the non-symmetric `S1 S2` (SinGAN's code) needs an epsilon fallback and drops imaginary
    /// parts. Eigenvalues that rounding pushes below zero count as zero, and so does a distance
    /// that rounding pushes below zero.
    pub fn frechet_distance(&self, other: &Self) -> Result<f64> {
        if self.dim() != other.dim() {
            return Err(invalid(
                "Gaussians",
                format!(
                    "cannot compare {} features with {}",
                    self.dim(),
                    other.dim()
                ),
            ));
        }
        let mean_term = (&self.mean - &other.mean).norm_squared();
        let root = psd_sqrt(&self.covariance)?;
        let inner = symmetrised(&root * &other.covariance * &root);
        let cross: f64 = eigen(inner)?
            .eigenvalues
            .iter()
            .map(|l| l.max(0.0).sqrt())
            .sum();
        let distance = mean_term + self.covariance.trace() + other.covariance.trace() - 2.0 * cross;
        Ok(distance.max(0.0))
    }
}

/// `(m + m^T) / 2`: removes the rounding asymmetry of products, so eigensolvers see an exactly
/// symmetric matrix.
fn symmetrised(m: DMatrix<f64>) -> DMatrix<f64> {
    (&m + m.transpose()) * 0.5
}

/// The symmetric eigendecomposition of `m`, or an error if it does not converge.
fn eigen(m: DMatrix<f64>) -> Result<SymmetricEigen<f64, nalgebra::Dyn>> {
    SymmetricEigen::try_new(m, f64::EPSILON, MAX_EIGEN_ITERATIONS).ok_or_else(|| {
        invalid(
            "covariance",
            "its symmetric eigendecomposition did not converge",
        )
    })
}

/// The symmetric square root `V diag(sqrt(max(l, 0))) V^T` of a symmetric positive
/// semi-definite matrix.
fn psd_sqrt(m: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    let e = eigen(m.clone())?;
    let mut scaled = e.eigenvectors.clone();
    for (mut column, l) in scaled.column_iter_mut().zip(e.eigenvalues.iter()) {
        column *= l.max(0.0).sqrt();
    }
    Ok(scaled * e.eigenvectors.transpose())
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// `n` samples of `d` features: correlated (each feature mixes the previous one in) and
    /// shifted by `offset`, so covariances are full and not diagonal.
    fn sample_set(seed: u64, n: usize, d: usize, offset: f64) -> Tensor {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut values = Vec::with_capacity(n * d);
        for _ in 0..n {
            let mut previous = 0.0;
            for j in 0..d {
                let v: f64 = rng.random_range(-1.0..1.0) + 0.6 * previous + offset + j as f64;
                values.push(v);
                previous = v;
            }
        }
        Tensor::from_vec(values, (n, d), &Device::Cpu).unwrap()
    }

    fn fit(set: &Tensor) -> FeatureGaussian {
        FeatureGaussian::fit(set).unwrap()
    }

    #[test]
    fn fit_matches_np_cov_with_n_minus_1() {
        // np.cov([[1, 2], [3, 4], [5, 0]], rowvar=False) = [[4, -2], [-2, 4]]; mean (3, 2).
        let set = Tensor::new(&[[1f32, 2.], [3., 4.], [5., 0.]], &Device::Cpu).unwrap();
        let g = fit(&set);
        assert_eq!(g.dim(), 2);
        assert_eq!(g.mean(), &[3.0, 2.0]);
        assert_eq!(g.covariance(), &[4.0, -2.0, -2.0, 4.0]);
    }

    #[test]
    fn identical_sets_are_at_distance_zero() {
        let set = sample_set(1, 200, 16, 0.0);
        let d = fit(&set).frechet_distance(&fit(&set)).unwrap();
        assert!(d.abs() < 1e-9, "{d}");
    }

    #[test]
    fn diagonal_covariances_match_the_closed_form() {
        let (s1, s2) = ([4.0, 0.25, 9.0, 1e-6], [1.0, 1.0, 2.0, 3.0]);
        let (m1, m2) = ([0.5, -1.0, 2.0, 0.0], [0.0, 1.0, 2.0, -3.0]);
        let diag = |s: &[f64; 4]| -> Vec<f64> {
            let mut c = vec![0.0; 16];
            for (i, v) in s.iter().enumerate() {
                c[i * 4 + i] = *v;
            }
            c
        };
        let a = FeatureGaussian::new(m1.to_vec(), diag(&s1)).unwrap();
        let b = FeatureGaussian::new(m2.to_vec(), diag(&s2)).unwrap();
        let expected: f64 = (0..4)
            .map(|i| (m1[i] - m2[i]).powi(2) + s1[i] + s2[i] - 2.0 * (s1[i] * s2[i]).sqrt())
            .sum();
        let d = a.frechet_distance(&b).unwrap();
        assert!((d - expected).abs() < 1e-12 * expected, "{d} vs {expected}");
    }

    #[test]
    fn full_2x2_covariances_match_the_closed_form_of_sqrtm() {
        // For a 2 x 2 matrix A with eigenvalues a, b >= 0, tr sqrtm(A) = sqrt(a) + sqrt(b)
        // = sqrt(tr A + 2 sqrt(det A)); with A = S1 S2 (which do not commute here) that gives
        // the distance without any eigendecomposition.
        let (s1, s2) = ([2.0, 0.8, 0.8, 1.0], [1.5, -0.6, -0.6, 0.7]);
        let a = FeatureGaussian::new(vec![1.0, 2.0], s1.to_vec()).unwrap();
        let b = FeatureGaussian::new(vec![-0.5, 2.5], s2.to_vec()).unwrap();
        let product = [
            s1[0] * s2[0] + s1[1] * s2[2],
            s1[0] * s2[1] + s1[1] * s2[3],
            s1[2] * s2[0] + s1[3] * s2[2],
            s1[2] * s2[1] + s1[3] * s2[3],
        ];
        assert!(
            (product[1] - product[2]).abs() > 0.1,
            "S1 S2 is not symmetric"
        );
        let det = |m: &[f64; 4]| m[0] * m[3] - m[1] * m[2];
        let tr_sqrt = (product[0] + product[3] + 2.0 * det(&product).sqrt()).sqrt();
        let expected =
            1.5f64.powi(2) + 0.5f64.powi(2) + s1[0] + s1[3] + s2[0] + s2[3] - 2.0 * tr_sqrt;
        let d = a.frechet_distance(&b).unwrap();
        assert!((d - expected).abs() < 1e-12, "{d} vs {expected}");
    }

    #[test]
    fn distance_is_symmetric() {
        let a = fit(&sample_set(2, 300, 12, 0.0));
        let b = fit(&(sample_set(3, 150, 12, 0.3) * 1.7).unwrap());
        let (ab, ba) = (
            a.frechet_distance(&b).unwrap(),
            b.frechet_distance(&a).unwrap(),
        );
        assert!(ab > 1.0, "{ab}");
        assert!((ab - ba).abs() < 1e-9 * ab, "{ab} vs {ba}");
    }

    #[test]
    fn translating_both_sets_changes_nothing() {
        let (x, y) = (sample_set(4, 120, 8, 0.0), sample_set(5, 90, 8, 0.5));
        let d = fit(&x).frechet_distance(&fit(&y)).unwrap();
        let shift = Tensor::from_vec(
            (0..8).map(|i| 100.0 - 30.0 * i as f64).collect::<Vec<_>>(),
            (1, 8),
            &Device::Cpu,
        )
        .unwrap();
        let moved = |t: &Tensor| fit(&t.broadcast_add(&shift).unwrap());
        let d_moved = moved(&x).frechet_distance(&moved(&y)).unwrap();
        assert!(d > 0.1, "{d}");
        assert!((d - d_moved).abs() < 1e-9 * d, "{d} vs {d_moved}");
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let one = Tensor::new(&[[1f32, 2.]], &Device::Cpu).unwrap();
        assert!(FeatureGaussian::fit(&one).is_err());
        let nan = Tensor::new(&[[1f32, f32::NAN], [0., 0.]], &Device::Cpu).unwrap();
        assert!(FeatureGaussian::fit(&nan).is_err());
        assert!(FeatureGaussian::fit(&Tensor::new(&[1f32, 2.], &Device::Cpu).unwrap()).is_err());
        assert!(FeatureGaussian::new(vec![0.0, 0.0], vec![1.0, 0.0, 0.0]).is_err());
        assert!(FeatureGaussian::new(vec![0.0, 0.0], vec![1.0, 0.5, 0.0, 1.0]).is_err());
        assert!(FeatureGaussian::new(vec![], vec![]).is_err());
        let a = fit(&sample_set(6, 10, 3, 0.0));
        let b = fit(&sample_set(6, 10, 4, 0.0));
        let err = a.frechet_distance(&b).unwrap_err().to_string();
        assert!(err.contains('3') && err.contains('4'), "{err}");
    }
}
