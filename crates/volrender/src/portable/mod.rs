//! The renderer on any candle device: the kernel's model (the paper's equation (1) with the
//! uniform samplers, trilinear cell-centred taps, colour, depth, opacity, background, both
//! density rules) written with plain candle ops (`index_select` for the taps, `cumsum` for
//! transmittance), so candle's autograd gives its backward on CUDA and Metal without custom
//! kernels. [`render`](crate::render) and [`render_batch`](crate::render_batch) use it for
//! volumes that are not on the CPU; on the CPU the fused kernel is faster, and this path is
//! tested against it (values and gradients).
//!
//! Only each ray's setup (where it enters and leaves the box, its step) is computed on the host,
//! by the kernel's own code, and uploaded as 9 numbers per ray; sample positions, taps and
//! weights are computed on the device with the kernel's operations in the kernel's order.
//!
//! Memory: rays are rendered in chunks of about `chunk_samples` ray samples (default
//! [`DEFAULT_CHUNK_SAMPLES`]), so the forward's temporaries are bounded by the chunk. Counted
//! from the tensors it builds (not measured): about 0.5 KB per ray sample in f32, most of it the
//! 8 taps' indices and weights and their gathered and weighted values of 4 channels, so about
//! 1 GB per chunk at the default. With gradients, candle keeps the tensors the backward needs
//! for every chunk until the backward runs, so a differentiated render holds a comparable amount
//! per ray sample for all of its samples, not one chunk's.
//!
//! Differences from the kernel: no early termination (`epsilon` is ignored, which is exact) and
//! no skipping (`skip_empty` is ignored: the forward is the same, the backward is the full
//! gradient); the `PerVoxel` sampler is refused. Transmittance is computed in log space,
//! `T_i = exp(-sum_{j<i} tau_j)`, unlike the kernel's running product.

mod composite;
mod geometry;
mod values;

use candle_core::{DType, Tensor, WithDType};
use radiance_volume::GridDims;

use crate::config::{RenderConfig, Sampler};
use crate::error::{invalid, Result};
use crate::kernel::Real;
use crate::op::{checked_grid, grid_spec, unsupported_dtype, RenderOutput};
use crate::rays::Rays;

/// Ray samples per chunk by default (2^21, about 1 GB of forward temporaries in f32).
pub const DEFAULT_CHUNK_SAMPLES: usize = 1 << 21;

/// Renders `(C, D, H, W)` (on any device, f32 or f64) along `rays` with candle ops, in chunks of
/// [`DEFAULT_CHUNK_SAMPLES`] ray samples; see [`render_portable_chunked`].
///
/// ```
/// use candle_core::{Device, Tensor};
/// use volrender::{portable::render_portable, render, Rays, RenderConfig, Sampler};
/// let vol = (Tensor::rand(0f64, 1.0, (4, 3, 3, 3), &Device::Cpu)? * 2.0)?;
/// let rays = Rays::new(vec![[0.2, -3.0, 0.1]], vec![[0.0, 1.0, 0.05]])?;
/// let cfg = RenderConfig::default().with_sampler(Sampler::Uniform { samples: 16 });
/// let fast = render(&vol, &rays, &cfg)?.rgb.to_vec2::<f64>()?;
/// let portable = render_portable(&vol, &rays, &cfg)?.rgb.to_vec2::<f64>()?;
/// assert!((fast[0][0] - portable[0][0]).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn render_portable(volume: &Tensor, rays: &Rays, cfg: &RenderConfig) -> Result<RenderOutput> {
    render_portable_chunked(volume, rays, cfg, DEFAULT_CHUNK_SAMPLES)
}

/// Renders `(C, D, H, W)` (C >= 4; f32 or f64; on the volume's device) along `rays`, rendering
/// `max(1, chunk_samples / samples)` rays at a time; the outputs are those of
/// [`render`](crate::render) (colour, and depth and opacity when `cfg.outputs` asks), on the
/// volume's device, differentiable with respect to the volume.
///
/// Errors as [`render`](crate::render): bad options, a wrong shape, refused values (checked on
/// the device, one reduction per call), and also the `PerVoxel` sampler and a `chunk_samples`
/// of 0.
pub fn render_portable_chunked(
    volume: &Tensor,
    rays: &Rays,
    cfg: &RenderConfig,
    chunk_samples: usize,
) -> Result<RenderOutput> {
    render_volume(volume, 0, rays, cfg, chunk_samples)
}

/// [`render_portable_chunked`] of volume `batch_index` of a batch (named in value errors).
pub(crate) fn render_volume(
    volume: &Tensor,
    batch_index: usize,
    rays: &Rays,
    cfg: &RenderConfig,
    chunk_samples: usize,
) -> Result<RenderOutput> {
    cfg.validate()?;
    let samples =
        match cfg.sampler {
            Sampler::Uniform { samples } | Sampler::UniformLeft { samples } => samples,
            Sampler::PerVoxel { .. } => return Err(invalid(
                "sampler",
                "the portable renderer supports the uniform samplers only (Uniform, UniformLeft)",
            )),
        };
    if chunk_samples == 0 {
        return Err(invalid(
            "chunk_samples",
            "expected at least 1 ray sample per chunk",
        ));
    }
    let (channels, d, h, w) = volume.dims4().map_err(|_| {
        invalid(
            "volume",
            format!("expected (C, D, H, W), got {:?}", volume.shape()),
        )
    })?;
    let dims = checked_grid("volume", volume, channels, [d, h, w])?;
    let raw_density = cfg.density.post_activation().is_some();
    values::check(volume, batch_index, dims, raw_density)?;
    let rays_per_chunk = (chunk_samples / samples).max(1);
    match volume.dtype() {
        DType::F32 => render_chunks::<f32>(volume, rays, cfg, dims, samples, rays_per_chunk),
        DType::F64 => render_chunks::<f64>(volume, rays, cfg, dims, samples, rays_per_chunk),
        other => Err(unsupported_dtype(other)),
    }
}

/// Renders the rays chunk by chunk in `T` (the volume's dtype) and joins the outputs.
fn render_chunks<T: Real + WithDType>(
    volume: &Tensor,
    rays: &Rays,
    cfg: &RenderConfig,
    dims: GridDims,
    samples: usize,
    rays_per_chunk: usize,
) -> Result<RenderOutput> {
    let grid = grid_spec::<T>(cfg, dims);
    let device = volume.device();
    let flat = volume.narrow(0, 0, 4)?.reshape((4, dims.voxel_count()))?;
    let steps = geometry::sample_steps::<T>(samples, cfg.sampler, device)?;
    let mut parts = Vec::new();
    for start in (0..rays.len()).step_by(rays_per_chunk) {
        let end = (start + rays_per_chunk).min(rays.len());
        let bundle = geometry::RayBundle::new(
            &rays.origins()[start..end],
            &rays.dirs()[start..end],
            &grid,
            cfg.sampler,
            device,
        )?;
        let taps = bundle.taps(&steps, grid.n)?;
        parts.push(composite::composite(&flat, &taps, bundle.dt(), cfg)?);
    }
    join(parts, cfg, volume)
}

/// Concatenates the chunks' outputs along the rays (empty outputs for no rays).
fn join(parts: Vec<RenderOutput>, cfg: &RenderConfig, volume: &Tensor) -> Result<RenderOutput> {
    if parts.is_empty() {
        let empty = |shape: &[usize]| Tensor::zeros(shape, volume.dtype(), volume.device());
        return Ok(RenderOutput {
            rgb: empty(&[0, 3])?,
            depth: cfg.outputs.depth.then(|| empty(&[0])).transpose()?,
            opacity: cfg.outputs.opacity.then(|| empty(&[0])).transpose()?,
        });
    }
    let cat = |pick: fn(&RenderOutput) -> Option<&Tensor>| -> Result<Option<Tensor>> {
        let picked: Option<Vec<&Tensor>> = parts.iter().map(pick).collect();
        Ok(picked.map(|p| Tensor::cat(&p, 0)).transpose()?)
    };
    let colours: Vec<&Tensor> = parts.iter().map(|p| &p.rgb).collect();
    Ok(RenderOutput {
        rgb: Tensor::cat(&colours, 0)?,
        depth: cat(|p| p.depth.as_ref())?,
        opacity: cat(|p| p.opacity.as_ref())?,
    })
}
