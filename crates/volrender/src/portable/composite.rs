//! Equation (1) over a chunk's taps with candle ops: blend the taps, activate post-activated
//! density, then weights `w_i = T_i (1 - exp(-tau_i))` with `T_i = exp(-sum_{j<i} tau_j)`
//! (an exclusive cumulative sum, so no cancellation), and the weighted sums.

use candle_core::Tensor;

use super::geometry::Taps;
use crate::config::RenderConfig;
use crate::error::Result;
use crate::op::RenderOutput;

/// Composites the `(4, V)` flat volume `flat` at `taps`, with per-ray steps `dt` `(R, 1)`.
pub(super) fn composite(
    flat: &Tensor,
    taps: &Taps,
    dt: &Tensor,
    cfg: &RenderConfig,
) -> Result<RenderOutput> {
    let (r, m) = taps.t.dims2()?;
    let samples = flat
        .index_select(&taps.index, 1)?
        .broadcast_mul(&taps.weight.unsqueeze(0)?)?
        .reshape((4, r * m, 8))?
        .sum(2)?
        .reshape((4, r, m))?;
    let mut sigma = samples.get(0)?;
    if let Some([scale, shift]) = cfg.density.post_activation() {
        // Samples outside the box hold no matter, activated or not.
        let x = (sigma + f64::from(shift))?;
        let softplus = (x.relu()? + (x.abs()?.neg()?.exp()? + 1.0)?.log()?)?;
        sigma = ((softplus * f64::from(scale))? * &taps.inside)?;
    }
    let tau = sigma.broadcast_mul(dt)?;
    let before = if m > 1 {
        let earlier = Tensor::cat(
            &[tau.zeros_like()?.narrow(1, 0, 1)?, tau.narrow(1, 0, m - 1)?],
            1,
        )?;
        earlier.cumsum(1)?
    } else {
        tau.zeros_like()?
    };
    let transmittance = before.neg()?.exp()?;
    let alpha = (1.0 - tau.neg()?.exp()?)?;
    let weights = (transmittance * alpha)?;
    let rgb = samples.narrow(0, 1, 3)?;
    let mut colour = rgb.broadcast_mul(&weights.unsqueeze(0)?)?.sum(2)?.t()?;
    if let Some(background) = cfg.background {
        let last = (before.narrow(1, m - 1, 1)? + tau.narrow(1, m - 1, 1)?)?;
        let background =
            Tensor::from_vec(background.to_vec(), (1, 3), flat.device())?.to_dtype(flat.dtype())?;
        colour = (colour + last.neg()?.exp()?.broadcast_mul(&background)?)?;
    }
    Ok(RenderOutput {
        rgb: colour,
        depth: cfg
            .outputs
            .depth
            .then(|| (&weights * &taps.t)?.sum(1))
            .transpose()?,
        opacity: cfg.outputs.opacity.then(|| weights.sum(1)).transpose()?,
    })
}
