//! The plain-tensor reference path: the uniform samplers of [`render`](crate::render) written
//! with ordinary candle ops (`index_select`, `cumsum`, `exp`, sums), differentiable through
//! candle's autograd. Slow and memory-hungry (it materialises `8 R M` corner values per
//! channel); it exists so tests can cross-check the fast kernel's values and gradients.
//!
//! Only the geometry (where the samples go and which voxels they blend) comes from the kernel's
//! ray setup and trilinear rule; it does not depend on the volume. Transmittance is computed in
//! log space, `T_i = exp(-(cumsum(tau)_i - tau_i))`, unlike the kernel's running product.

use candle_core::{Device, Tensor};
use radiance_volume::GridDims;

use crate::config::{RenderConfig, Sampler};
use crate::error::{invalid, Result};
use crate::kernel::{corners, setup_ray};
use crate::op::{grid_spec, RenderOutput};
use crate::rays::Rays;

/// Renders `(C, D, H, W)` along `rays` with candle ops; supports the `Uniform` and `UniformLeft`
/// samplers, both density rules, the background and both extra outputs (always returned), but
/// neither early termination nor skipping (they do not change its result when `epsilon` is 0).
///
/// ```
/// use candle_core::{Device, Tensor, DType};
/// use volrender::{reference::render_reference, render, Rays, RenderConfig, Sampler};
/// let vol = (Tensor::rand(0f64, 1.0, (4, 3, 3, 3), &Device::Cpu)? * 2.0)?;
/// let rays = Rays::new(vec![[0.2, -3.0, 0.1]], vec![[0.0, 1.0, 0.05]])?;
/// let cfg = RenderConfig::default().with_sampler(Sampler::Uniform { samples: 16 });
/// let fast = render(&vol, &rays, &cfg)?.rgb.to_vec2::<f64>()?;
/// let slow = render_reference(&vol, &rays, &cfg)?.rgb.to_vec2::<f64>()?;
/// assert!((fast[0][0] - slow[0][0]).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn render_reference(volume: &Tensor, rays: &Rays, cfg: &RenderConfig) -> Result<RenderOutput> {
    cfg.validate()?;
    let samples = match cfg.sampler {
        Sampler::Uniform { samples } | Sampler::UniformLeft { samples } => samples,
        Sampler::PerVoxel { .. } => {
            return Err(invalid(
                "sampler",
                "the reference path supports the uniform samplers only",
            ))
        }
    };
    let (_, d, h, w) = volume.dims4().map_err(|_| {
        invalid(
            "volume",
            format!("expected (C, D, H, W), got {:?}", volume.shape()),
        )
    })?;
    let dims = GridDims::new(d, h, w);
    let grid = grid_spec::<f64>(cfg, dims);
    let (r, m) = (rays.len(), samples);
    let mut idx = Vec::with_capacity(r * m * 8);
    let mut weights = Vec::with_capacity(r * m * 8);
    let mut ts = Vec::with_capacity(r * m);
    let mut dts = Vec::with_capacity(r);
    for (&o, &dir) in rays.origins().iter().zip(rays.dirs()) {
        let g = setup_ray(o, dir, &grid, cfg.sampler);
        dts.push(g.dt);
        for i in 0..m {
            let t = g.t0 + (i as f64 + g.off) * g.dt;
            ts.push(t);
            let u = [0, 1, 2].map(|k| g.a[k] + t * g.b[k]);
            // Rays that miss have dt = 0 (no attenuation); their corners are zeroed too.
            match corners(grid.n, u).filter(|_| g.n > 0) {
                Some(c) => {
                    idx.extend(c.idx.map(|i| i as u32));
                    weights.extend(c.w);
                }
                None => {
                    idx.extend([0u32; 8]);
                    weights.extend([0.0; 8]);
                }
            }
        }
    }
    let dev = &Device::Cpu;
    let dtype = volume.dtype();
    let idx = Tensor::from_vec(idx, r * m * 8, dev)?;
    let weights = Tensor::from_vec(weights, (1, r * m * 8), dev)?.to_dtype(dtype)?;
    let t = Tensor::from_vec(ts, (r, m), dev)?.to_dtype(dtype)?;
    let dt = Tensor::from_vec(dts, (r, 1), dev)?.to_dtype(dtype)?;

    let flat = volume.narrow(0, 0, 4)?.reshape((4, dims.voxel_count()))?;
    let values = flat
        .index_select(&idx, 1)?
        .broadcast_mul(&weights)?
        .reshape((4, r * m, 8))?
        .sum(2)?
        .reshape((4, r, m))?;
    let mut sigma = values.get(0)?;
    if let Some([scale, shift]) = cfg.density.post_activation() {
        // Samples outside the box have all-zero corner weights and hold no matter, activated
        // or not.
        let inside = weights
            .reshape((r * m, 8))?
            .sum(1)?
            .gt(0.5)?
            .to_dtype(dtype)?
            .reshape((r, m))?;
        let x = (sigma + f64::from(shift))?;
        let softplus = (x.relu()? + (x.abs()?.neg()?.exp()? + 1.0)?.log()?)?;
        sigma = ((softplus * f64::from(scale))? * inside)?;
    }
    let rgb = values.narrow(0, 1, 3)?;
    let tau = sigma.broadcast_mul(&dt)?;
    let cum = tau.cumsum(1)?;
    let trans = (cum.clone() - &tau)?.neg()?.exp()?;
    let alpha = (1.0 - tau.neg()?.exp()?)?;
    let wts = (trans * alpha)?;
    let mut colour = rgb.broadcast_mul(&wts.unsqueeze(0)?)?.sum(2)?.t()?;
    if let Some(bg) = cfg.background {
        let t_final = cum.narrow(1, m - 1, 1)?.neg()?.exp()?;
        let bg = Tensor::from_vec(bg.to_vec(), (1, 3), dev)?.to_dtype(dtype)?;
        colour = (colour + t_final.broadcast_mul(&bg)?)?;
    }
    Ok(RenderOutput {
        rgb: colour,
        depth: Some((&wts * t)?.sum(1)?),
        opacity: Some(wts.sum(1)?),
    })
}
