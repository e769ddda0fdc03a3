//! The one activation that maps raw network output to a physical volume.

use candle_core::{Result, Tensor};

use crate::error::invalid;

/// Maps raw (pre-activation) volumes to physical ones: density
/// `sigma = density_scale * softplus(raw_sigma + density_shift)` (>= 0, in 1/world-length), colour
/// `rgb = sigmoid(raw_rgb)` (in [0, 1]); extra feature channels pass through unchanged.
///
/// Softplus rather than ReLU keeps a gradient in empty space, so a generator can grow density
/// where there was none. The default (`shift = 0`, `scale = 1`) maps raw 0 to sigma = ln 2.
///
/// Works on unbatched `(C, D, H, W)` and batched `(N, C, D, H, W)` tensors, on any device, and
/// is differentiable (it is built from candle ops).
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::Activation;
/// let raw = Tensor::zeros((4, 2, 2, 2), candle_core::DType::F32, &Device::Cpu)?;
/// let phys = Activation::default().apply(&raw)?;
/// let v: Vec<f32> = phys.flatten_all()?.to_vec1()?;
/// assert!((v[0] - 2f32.ln()).abs() < 1e-6); // sigma
/// assert_eq!(v[8], 0.5); // red
/// # Ok::<(), candle_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Activation {
    /// Added to the raw density before softplus (negative values make raw 0 emptier).
    pub density_shift: f32,
    /// Multiplies the softplus output, in 1/world-length.
    pub density_scale: f32,
}

impl Default for Activation {
    fn default() -> Self {
        Self {
            density_shift: 0.0,
            density_scale: 1.0,
        }
    }
}

impl Activation {
    /// Returns a copy with another density shift.
    #[must_use]
    pub fn with_density_shift(self, density_shift: f32) -> Self {
        Self {
            density_shift,
            ..self
        }
    }

    /// Returns a copy with another density scale.
    #[must_use]
    pub fn with_density_scale(self, density_scale: f32) -> Self {
        Self {
            density_scale,
            ..self
        }
    }

    /// Returns the raw density that maps to the physical density `sigma`, the inverse of the
    /// density half of [`Activation::apply`]: `softplus^-1(sigma / density_scale) -
    /// density_shift`, with `softplus^-1(y) = ln(e^y - 1)` computed in f64 so that tiny
    /// densities (for example "empty" space for an edit) keep their precision.
    ///
    /// Errors unless `sigma` is finite and positive (softplus never reaches 0, so no raw value
    /// gives exactly empty space) and the result is finite in f32.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use radiance_volume::Activation;
    /// let act = Activation::default().with_density_scale(25.0).with_density_shift(-4.0);
    /// let raw = act.raw_density(1e-4)?;
    /// let voxel = Tensor::new(&[raw, 0.0, 0.0, 0.0], &Device::Cpu)?.reshape((4, 1, 1, 1))?;
    /// let sigma: Vec<f32> = act.apply(&voxel)?.flatten_all()?.to_vec1()?;
    /// // `apply` runs in f32, where ln(1 + 4e-6) keeps about two digits.
    /// assert!((sigma[0] / 1e-4 - 1.0).abs() < 0.02, "{}", sigma[0]);
    /// assert!(act.raw_density(0.0).is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn raw_density(&self, sigma: f32) -> crate::Result<f32> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(invalid(
                "sigma",
                format!("expected a finite density > 0 to invert the activation, got {sigma}"),
            ));
        }
        let y = f64::from(sigma) / f64::from(self.density_scale);
        let raw = (y.exp_m1().ln() - f64::from(self.density_shift)) as f32;
        if !raw.is_finite() {
            return Err(invalid(
                "sigma",
                format!(
                    "density {sigma} has no finite raw value under density scale {} and shift {}",
                    self.density_scale, self.density_shift
                ),
            ));
        }
        Ok(raw)
    }

    /// Applies the activation to a raw `(C, D, H, W)` or `(N, C, D, H, W)` tensor with C >= 4.
    pub fn apply(&self, raw: &Tensor) -> Result<Tensor> {
        self.apply_parts(raw, true)
    }

    /// Applies the colour half only: channel 0 stays raw density, for a renderer that
    /// interpolates raw density and activates it per sample (volrender's
    /// `DensityInterpolation::PostActivated` with this activation's scale and shift).
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use radiance_volume::Activation;
    /// let raw = Tensor::new(&[-3f32, 0.0, 0.0, 0.0], &Device::Cpu)?.reshape((4, 1, 1, 1))?;
    /// let v: Vec<f32> = Activation::default().apply_colour(&raw)?.flatten_all()?.to_vec1()?;
    /// assert_eq!(v, [-3.0, 0.5, 0.5, 0.5]);
    /// # Ok::<(), candle_core::Error>(())
    /// ```
    pub fn apply_colour(&self, raw: &Tensor) -> Result<Tensor> {
        self.apply_parts(raw, false)
    }

    /// Applies the density half alone to a tensor of raw densities of any shape:
    /// `density_scale * softplus(raw + density_shift)`, element-wise.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use radiance_volume::Activation;
    /// let activation = Activation::default().with_density_scale(2.0).with_density_shift(-1.0);
    /// let raw = Tensor::new(&[1f32, -30.0], &Device::Cpu)?;
    /// let sigma: Vec<f32> = activation.apply_density(&raw)?.to_vec1()?;
    /// assert!((sigma[0] - 2.0 * 2f32.ln()).abs() < 1e-6);
    /// assert!(sigma[1] < 1e-12);
    /// # Ok::<(), candle_core::Error>(())
    /// ```
    pub fn apply_density(&self, raw_density: &Tensor) -> Result<Tensor> {
        let sigma = softplus(&(raw_density + f64::from(self.density_shift))?)?;
        sigma * f64::from(self.density_scale)
    }

    /// [`Activation::apply`], with channel 0 left raw unless `density`.
    fn apply_parts(&self, raw: &Tensor, density: bool) -> Result<Tensor> {
        let rank = raw.rank();
        if rank != 4 && rank != 5 {
            candle_core::bail!(
                "activation expects (C, D, H, W) or (N, C, D, H, W), got {:?}",
                raw.shape()
            );
        }
        let channel_dim = rank - 4;
        let channels = raw.dim(channel_dim)?;
        if channels < 4 {
            candle_core::bail!(
                "activation expects at least 4 channels (sigma, r, g, b), got {channels}"
            );
        }
        let raw_density = raw.narrow(channel_dim, 0, 1)?;
        let sigma = if density {
            self.apply_density(&raw_density)?
        } else {
            raw_density
        };
        let rgb = sigmoid(&raw.narrow(channel_dim, 1, 3)?)?;
        let mut parts = vec![sigma, rgb];
        if channels > 4 {
            parts.push(raw.narrow(channel_dim, 4, channels - 4)?);
        }
        Tensor::cat(&parts, channel_dim)
    }
}

/// Computes `ln(1 + e^x)` without overflow: `max(x, 0) + ln(1 + e^-|x|)`.
fn softplus(x: &Tensor) -> Result<Tensor> {
    x.relu()? + (x.abs()?.neg()?.exp()? + 1.0)?.log()?
}

/// Computes `1 / (1 + e^-x)`; for very negative x the exponential overflows to infinity and the
/// result is exactly 0, which is the correct limit.
fn sigmoid(x: &Tensor) -> Result<Tensor> {
    (x.neg()?.exp()? + 1.0)?.recip()
}
