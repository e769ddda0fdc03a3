//! WGAN-GP losses as plain functions over critic scores.

use candle_core::{Module, Tensor, Var};
use rand::Rng;

use crate::error::{invalid, Error, Result};

/// The critic's (discriminator's) WGAN loss, to minimise: `mean(fake) - mean(real)`.
///
/// Scores may be patch maps or per-image scores; each side is averaged over all its elements.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::new(&[2f32, 4.], &Device::Cpu)?;
/// let fake = Tensor::new(&[1f32, 1.], &Device::Cpu)?;
/// let loss = patch_gan::critic_loss(&real, &fake)?;
/// assert_eq!(loss.to_scalar::<f32>()?, -2.0);
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn critic_loss(real_scores: &Tensor, fake_scores: &Tensor) -> Result<Tensor> {
    Ok((fake_scores.mean_all()? - real_scores.mean_all()?)?)
}

/// The generator's WGAN loss, to minimise: `-mean(fake)`.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let loss = patch_gan::generator_loss(&Tensor::new(&[1f32, 3.], &Device::Cpu)?)?;
/// assert_eq!(loss.to_scalar::<f32>()?, -2.0);
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn generator_loss(fake_scores: &Tensor) -> Result<Tensor> {
    Ok(fake_scores.mean_all()?.neg()?)
}

/// Over what the norm of the critic's input gradient is taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GradientNorm {
    /// Over channels at each pixel, then `(norm - 1)^2` averaged over pixels and images. This is
    /// what SinGAN's code does (`gradients.norm(2, dim=1)`), whose WGAN-GP setting (weight 0.1)
    /// SinGRAV inherits; it asks each patch of a patch critic to be 1-Lipschitz.
    PerPixel,
    /// Over all of an image's elements, then averaged over images: Gulrajani et al.'s original.
    PerImage,
}

/// Settings of [`gradient_penalty`]; the default is the paper's weight 0.1 with
/// [`GradientNorm::PerPixel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GradientPenalty {
    /// Factor on the penalty (0.1 in the paper).
    pub weight: f64,
    /// How the gradient's norm is taken.
    pub norm: GradientNorm,
}

impl Default for GradientPenalty {
    fn default() -> Self {
        Self {
            weight: 0.1,
            norm: GradientNorm::PerPixel,
        }
    }
}

/// Keeps `sqrt` differentiable where the critic's input gradient vanishes.
pub(crate) const NORM_EPS: f64 = 1e-12;

/// The WGAN-GP gradient penalty `weight * mean((||grad_x critic(x_hat)|| - 1)^2)` at
/// `x_hat = a real + (1 - a) fake`, with one `a ~ U[0, 1)` per image drawn from `rng`.
///
/// `critic` maps `(N, C, H, W)` images to scores or patch maps; the gradient is that of the sum of
/// its output, so each image's own scores drive its gradient. `real` and `fake` are treated as
/// constants (the generator gets no gradient through the penalty, as in a critic step).
///
/// The returned scalar is differentiable with respect to the critic's weights: it contains the
/// critic's backward pass, so calling `.backward()` on a loss that includes it gives
/// second-order gradients. candle keeps backward graphs only when the environment variable
/// `CANDLE_GRAD_DO_NOT_DETACH` is set (non-empty, not `0`) before the thread's first backward
/// pass; this function returns [`Error::SecondOrderDisabled`] when it is not set rather than a
/// silently wrong gradient. Set it at program start. For the crate's own critic,
/// [`PatchDiscriminator::gradient_penalty`](crate::PatchDiscriminator::gradient_penalty)
/// gives the same penalty as a first-order graph: faster, and without the variable.
///
/// ```
/// use candle_core::{DType, Device, Tensor};
/// use candle_nn::{VarBuilder, VarMap};
/// use patch_gan::{gradient_penalty, GradientPenalty, PatchDiscriminator2d, PatchDiscriminator2dConfig};
/// use rand::SeedableRng;
/// // Normally done once in main(), before any backward pass.
/// unsafe { std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1") };
/// let varmap = VarMap::new();
/// let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
/// let cfg = PatchDiscriminator2dConfig::default().with_layers(3);
/// let critic = PatchDiscriminator2d::new(&cfg, vb)?;
/// let real = Tensor::rand(0f32, 1., (2, 4, 12, 12), &Device::Cpu)?;
/// let fake = Tensor::rand(0f32, 1., (2, 4, 12, 12), &Device::Cpu)?;
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
/// let gp = gradient_penalty(&critic, &real, &fake, GradientPenalty::default(), &mut rng)?;
/// let grads = gp.backward()?;
/// // The penalty reaches every conv weight (biases only move LeakyReLU's kinks, so their
/// // gradient is zero almost everywhere and candle records none).
/// let data = varmap.data().lock().unwrap();
/// let weights: Vec<_> = data.iter().filter(|(name, _)| name.ends_with("weight")).collect();
/// assert_eq!(weights.len(), 3);
/// assert!(weights.iter().all(|(_, v)| grads.get(v).is_some()));
/// # Ok::<(), patch_gan::Error>(())
/// ```
pub fn gradient_penalty<C: Module + ?Sized, R: Rng + ?Sized>(
    critic: &C,
    real: &Tensor,
    fake: &Tensor,
    penalty: GradientPenalty,
    rng: &mut R,
) -> Result<Tensor> {
    if !second_order_enabled() {
        return Err(Error::SecondOrderDisabled);
    }
    // A fresh leaf, so the backward pass below reports the gradient with respect to it.
    let mixed = Var::from_tensor(&mixed_images(real, fake, rng)?)?;
    let grads = critic.forward(mixed.as_tensor())?.sum_all()?.backward()?;
    let grad = match grads.get(mixed.as_tensor()) {
        Some(g) => g.clone(),
        None => mixed.as_tensor().zeros_like()?,
    };
    penalty_of_gradient(&grad, penalty)
}

/// `a real + (1 - a) fake` with one `a ~ U[0, 1)` per image drawn from `rng`, detached; errors
/// unless `real` and `fake` are equal batched shapes.
fn mixed_images<R: Rng + ?Sized>(real: &Tensor, fake: &Tensor, rng: &mut R) -> Result<Tensor> {
    let alphas = draw_alphas(real, fake, rng)?;
    let mut alpha_shape = vec![1; real.rank()];
    alpha_shape[0] = alphas.len();
    let alpha = Tensor::from_vec(alphas, alpha_shape, real.device())?.to_dtype(real.dtype())?;
    let mixed = (real.broadcast_mul(&alpha)? + fake.broadcast_mul(&alpha.affine(-1.0, 1.0)?)?)?;
    Ok(mixed.detach())
}

/// The mixing weights of [`gradient_penalty`]: one `a ~ U[0, 1)` per image drawn from `rng`;
/// errors unless `real` and `fake` are equal batched shapes.
pub(crate) fn draw_alphas<R: Rng + ?Sized>(
    real: &Tensor,
    fake: &Tensor,
    rng: &mut R,
) -> Result<Vec<f64>> {
    if real.shape() != fake.shape() || real.rank() < 2 {
        return Err(invalid(
            "gradient penalty inputs",
            format!(
                "real {:?} and fake {:?} must be equal batched shapes",
                real.shape(),
                fake.shape()
            ),
        ));
    }
    Ok((0..real.dim(0)?).map(|_| rng.random::<f64>()).collect())
}

/// `weight * mean((||grad|| - 1)^2)` of the critic's input gradient `grad`, the norm taken as
/// `penalty.norm` says.
fn penalty_of_gradient(grad: &Tensor, penalty: GradientPenalty) -> Result<Tensor> {
    let sq = grad.sqr()?;
    let norms = match penalty.norm {
        GradientNorm::PerPixel => sq.sum_keepdim(1)?,
        GradientNorm::PerImage => sq.flatten_from(1)?.sum(1)?,
    };
    let norms = (norms + NORM_EPS)?.sqrt()?;
    Ok(((norms - 1.0)?.sqr()?.mean_all()? * penalty.weight)?)
}

/// Whether candle keeps the graph of backward passes (the same test candle applies).
fn second_order_enabled() -> bool {
    std::env::var("CANDLE_GRAD_DO_NOT_DETACH").is_ok_and(|s| !s.is_empty() && s != "0")
}
