//! The differentiable render op on candle: a private `CompositeOp` (candle `CustomOp1`, the
//! volume as its only differentiable input, rays and options captured in the op) and the public
//! [`render`] / [`render_batch`] wrappers.
//!
//! The op's output is a packed `(R, 8)` tensor `[r, g, b, depth, opacity, transmittance, first
//! live sample, end of live samples]` that the wrappers narrow, so gradients from every output
//! flow through the one op; the last three columns are kept for the backward and never exposed.
//!
//! Determinism: the forward writes each ray's outputs independently. The backward splits the
//! rays into at most [`BLOCKS`] blocks (tiles of [`TILE`] consecutive rays dealt round-robin, so
//! the split depends only on the ray count), accumulates each block in order into a private
//! gradient buffer, and sums the buffers in block order. The gradient bits therefore depend on
//! the inputs only, not on the thread count or scheduling.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, DType, Layout, Shape, Tensor, WithDType};
use radiance_volume::GridDims;
use rayon::prelude::*;

use crate::buffer_pool::{self, Pooled};
use crate::config::{RenderConfig, Sampler, MAX_SAMPLES_PER_RAY, MAX_VOLUME_VALUE};
use crate::empty_space::{empty_blocks, CellDistances};
use crate::error::{invalid, Error, Result};
use crate::kernel::{
    softplus_and_slope, GridSpec, Isa, OccView, Params, RayKernel, Real, VolumeView, PACKED,
};
use crate::rays::Rays;
/// The most gradient buffers the backward allocates per volume.
pub(crate) const BLOCKS: usize = 4;
/// Consecutive rays per tile: the unit of parallel work, forward and backward (where tiles are
/// dealt round-robin to the blocks).
const TILE: usize = 64;

/// The outputs of [`render`]: colour `(R, 3)`, and depth `(R)` and opacity `(R)` when asked for.
#[derive(Debug, Clone)]
pub struct RenderOutput {
    /// Composited colour, `(R, 3)`.
    pub rgb: Tensor,
    /// Expected depth (distance along the ray), `(R)`, when `outputs.depth` is set.
    pub depth: Option<Tensor>,
    /// Opacity in [0, 1], `(R)`, when `outputs.opacity` is set.
    pub opacity: Option<Tensor>,
}

/// Renders a physical volume `(C, D, H, W)` (C >= 4: sigma, r, g, b, further channels ignored;
/// f32 or f64, on the CPU) along `rays`. Differentiable with respect to the volume. With
/// [`DensityInterpolation::PostActivated`](crate::DensityInterpolation) channel 0 holds raw
/// density instead, activated at every sample.
///
/// Errors: bad options, a wrong shape, NaN or infinite values, or negative density (unless
/// post-activated; values are checked on every call, fused with the copy the kernel reads
/// from).
///
/// ```
/// use candle_core::{Device, Tensor, Var};
/// use volrender::{render, Rays, RenderConfig};
/// let dev = Device::Cpu;
/// // A constant fog of density 1 and colour (1, 0.5, 0) in [-1, 1]^3.
/// let vol = Var::from_tensor(&Tensor::cat(&[
///     Tensor::ones((1, 4, 4, 4), candle_core::DType::F32, &dev)?,
///     Tensor::ones((1, 4, 4, 4), candle_core::DType::F32, &dev)?,
///     Tensor::full(0.5f32, (1, 4, 4, 4), &dev)?,
///     Tensor::zeros((1, 4, 4, 4), candle_core::DType::F32, &dev)?,
/// ], 0)?)?;
/// let rays = Rays::new(vec![[0.0, 0.0, 3.0]], vec![[0.0, 0.0, -1.0]])?;
/// let out = render(vol.as_tensor(), &rays, &RenderConfig::default().with_opacity(true))?;
/// let opacity = out.opacity.unwrap().to_vec1::<f32>()?[0];
/// assert!((opacity - (1.0 - (-2.0f32).exp())).abs() < 1e-5);
/// let grads = out.rgb.sum_all()?.backward()?;
/// assert_eq!(grads.get(&vol).unwrap().dims(), &[4, 4, 4, 4]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn render(volume: &Tensor, rays: &Rays, cfg: &RenderConfig) -> Result<RenderOutput> {
    if volume.rank() != 4 {
        return Err(invalid(
            "volume",
            format!(
                "expected a (C, D, H, W) tensor, got shape {:?}",
                volume.shape()
            ),
        ));
    }
    let mut outs = render_batch(&volume.unsqueeze(0)?, std::slice::from_ref(rays), cfg)?;
    Ok(outs.remove(0))
}

/// Renders a batch of volumes `(N, C, D, H, W)`, volume `n` along `rays[n]` (bundles may differ
/// in length); returns one output per volume. Differentiable with respect to the batch.
pub fn render_batch(
    volumes: &Tensor,
    rays: &[Rays],
    cfg: &RenderConfig,
) -> Result<Vec<RenderOutput>> {
    cfg.validate()?;
    let (n, channels, d, h, w) = volumes.dims5().map_err(|_| {
        invalid(
            "volumes",
            format!(
                "expected an (N, C, D, H, W) tensor, got shape {:?}",
                volumes.shape()
            ),
        )
    })?;
    let dims = checked_grid("volumes", volumes, channels, [d, h, w])?;
    if let Sampler::PerVoxel { per_voxel } = cfg.sampler {
        // A ray is at most the box's diagonal long, and steps are at most the smallest voxel
        // edge over per_voxel.
        let size = cfg.aabb.max - cfg.aabb.min;
        let voxel = (size / glam::Vec3::new(w as f32, h as f32, d as f32)).min_element() as f64;
        let most = (size.length() as f64 / voxel * per_voxel as f64).ceil();
        if most > MAX_SAMPLES_PER_RAY as f64 {
            return Err(invalid(
                "sampler",
                format!(
                    "{per_voxel} samples per voxel give up to {most} samples per ray on this grid; \
                     at most {MAX_SAMPLES_PER_RAY} are supported"
                ),
            ));
        }
    }
    if n != rays.len() {
        return Err(invalid(
            "rays",
            format!("{n} volumes but {} ray bundles", rays.len()),
        ));
    }
    if !volumes.device().is_cpu() {
        // The kernel reads host memory: elsewhere the same model runs as candle ops.
        return rays
            .iter()
            .enumerate()
            .map(|(b, r)| {
                crate::portable::render_volume(
                    &volumes.get(b)?,
                    b,
                    r,
                    cfg,
                    crate::portable::DEFAULT_CHUNK_SAMPLES,
                )
            })
            .collect();
    }
    let packed = match volumes.dtype() {
        DType::F32 => volumes.apply_op1(CompositeOp::<f32>::new(volumes, dims, rays, cfg)?)?,
        DType::F64 => volumes.apply_op1(CompositeOp::<f64>::new(volumes, dims, rays, cfg)?)?,
        other => return Err(unsupported_dtype(other)),
    };
    let mut start = 0;
    rays.iter()
        .map(|r| {
            let block = packed.narrow(0, start, r.len())?;
            start += r.len();
            let column = |c: usize| block.narrow(1, c, 1).and_then(|t| t.squeeze(1));
            Ok(RenderOutput {
                rgb: block.narrow(1, 0, 3)?,
                depth: cfg.outputs.depth.then(|| column(3)).transpose()?,
                opacity: cfg.outputs.opacity.then(|| column(4)).transpose()?,
            })
        })
        .collect()
}

/// The grid of `volume` (named `what` in errors) with `channels` channels of `[d, h, w]` voxels,
/// checked as both renderers need: at least 4 channels, at least one voxel, and voxel indices
/// that fit 32 bits.
pub(crate) fn checked_grid(
    what: &'static str,
    volume: &Tensor,
    channels: usize,
    [d, h, w]: [usize; 3],
) -> Result<GridDims> {
    if channels < 4 || d * h * w == 0 {
        return Err(invalid(
            what,
            format!(
                "expected C >= 4 channels and non-empty grids, got shape {:?}",
                volume.shape()
            ),
        ));
    }
    if u32::try_from(d * h * w).is_err() {
        return Err(Error::Unsupported {
            what,
            why: format!(
                "the renderers index voxels with 32 bits; a {d} x {h} x {w} grid has more than {} voxels",
                u32::MAX
            )
            .into(),
        });
    }
    Ok(GridDims::new(d, h, w))
}

/// The error for volumes of a dtype the renderers do not run in.
pub(crate) fn unsupported_dtype(dtype: DType) -> Error {
    Error::Unsupported {
        what: "dtype",
        why: format!("the renderer takes f32 or f64 volumes, got {dtype:?}").into(),
    }
}

/// What skipping needs of one volume's `density` (channel 0): the occupancy distances and the
/// empty corner blocks of its physical density. Post-activated raw density is activated first,
/// once, with the kernel's own function, so that what they call empty the kernel renders as
/// exactly 0.
fn skipping<T: Real>(
    density: &[T],
    post_activation: Option<[f32; 2]>,
    dims: GridDims,
    cfg: &RenderConfig,
) -> Result<(CellDistances, Vec<bool>)> {
    let activated: Option<Vec<T>> = post_activation.map(|[scale, shift]| {
        let (scale, shift) = (T::of(f64::from(scale)), T::of(f64::from(shift)));
        density
            .par_iter()
            .map(|&x| scale * softplus_and_slope(x + shift).0)
            .collect()
    });
    let sigma = activated.as_deref().unwrap_or(density);
    // The occupancy grid reads f32: an f64 density too small for f32 is kept above 0 so that no
    // voxel the kernel renders counts as empty.
    let smallest = f64::from(f32::MIN_POSITIVE);
    let sigma_f32: Vec<f32> = sigma
        .par_iter()
        .map(|&s| {
            let s = s.to_f64().unwrap_or(f64::NAN);
            if s > 0.0 && s < smallest {
                f32::MIN_POSITIVE
            } else {
                s as f32
            }
        })
        .collect();
    let cells = CellDistances::from_density(&sigma_f32, dims, cfg)?;
    let blocks = empty_blocks(sigma, dims, &cells);
    Ok((cells, blocks))
}

/// The render op: interleaved copies of the volumes (validated), rays and options.
struct CompositeOp<T: Pooled> {
    volumes: Vec<Vec<[T; 4]>>,
    dims: GridDims,
    channels: usize,
    rays: Vec<Rays>,
    occupancy: Vec<CellDistances>,
    /// Per volume when skipping: is the 2x2x2 corner block with this lower corner all empty?
    empty_blocks: Vec<Vec<bool>>,
    grid: GridSpec<T>,
    params: Params<T>,
    cfg: RenderConfig,
    isa: Isa,
}

impl<T: Pooled + WithDType> CompositeOp<T> {
    /// The op for `volumes` (validated and copied here, with what skipping needs of each).
    fn new(volumes: &Tensor, dims: GridDims, rays: &[Rays], cfg: &RenderConfig) -> Result<Self> {
        let channels = volumes.dim(1)?;
        let planar = volumes.contiguous()?;
        let (storage, layout) = planar.storage_and_layout();
        let candle_core::Storage::Cpu(cpu) = &*storage else {
            return Err(Error::Unsupported {
                what: "device",
                why: "the render kernel runs on the CPU".into(),
            });
        };
        let (start, end) = layout
            .contiguous_offsets()
            .ok_or_else(|| invalid("volumes", "expected a contiguous tensor"))?;
        let values = &T::cpu_storage_as_slice(cpu)?[start..end];
        let post_activation = cfg.density.post_activation();
        let volumes = interleave(
            values,
            rays.len(),
            channels,
            dims,
            post_activation.is_some(),
        )?;
        let voxels = dims.voxel_count();
        let (occupancy, empty_blocks) = if cfg.skip_empty {
            (0..rays.len())
                .map(|b| {
                    let density = &values[b * channels * voxels..][..voxels];
                    skipping(density, post_activation, dims, cfg)
                })
                .collect::<Result<Vec<_>>>()?
                .into_iter()
                .unzip()
        } else {
            (Vec::new(), Vec::new())
        };
        Ok(Self {
            volumes,
            empty_blocks,
            dims,
            channels,
            rays: rays.to_vec(),
            occupancy,
            grid: grid_spec(cfg, dims),
            params: Params {
                epsilon: T::of(cfg.epsilon as f64),
                background: cfg.background.unwrap_or([0.0; 3]).map(|c| T::of(c as f64)),
                depth: cfg.outputs.depth,
                opacity: cfg.outputs.opacity,
            },
            cfg: *cfg,
            isa: Isa::detect(),
        })
    }

    /// The kernel for volume `b`.
    fn kernel(&self, b: usize) -> RayKernel<'_, T> {
        RayKernel {
            volume: VolumeView {
                data: &self.volumes[b],
                n: self.grid.n,
                post_activation: self
                    .cfg
                    .density
                    .post_activation()
                    .map(|a| a.map(|x| T::of(f64::from(x)))),
            },
            occupancy: self.occupancy.get(b).map(|o| OccView {
                distance: &o.distance,
                empty_block: &self.empty_blocks[b],
                n: o.n,
                k: o.k,
            }),
            grid: self.grid,
            sampler: self.cfg.sampler,
            params: self.params,
            isa: self.isa,
        }
    }

    /// Renders every ray of every volume into the packed `(R, PACKED)` layout.
    fn forward(&self) -> Vec<T> {
        let total: usize = self.rays.iter().map(Rays::len).sum();
        let mut out = vec![T::zero(); total * PACKED];
        let mut rest = out.as_mut_slice();
        for (b, rays) in self.rays.iter().enumerate() {
            let (mine, tail) = rest.split_at_mut(rays.len() * PACKED);
            rest = tail;
            let kernel = self.kernel(b);
            mine.par_chunks_mut(TILE * PACKED)
                .zip(
                    rays.origins()
                        .par_chunks(TILE)
                        .zip(rays.dirs().par_chunks(TILE)),
                )
                .for_each(|(out, (origins, dirs))| kernel.forward_tile(origins, dirs, out));
        }
        out
    }

    /// Returns the gradient `(N, C, D, H, W)` (planar, channels >= 4 zero) given the forward's
    /// packed output and its gradient.
    fn backward(&self, res: &[T], grad: &[T]) -> Vec<T> {
        let voxels = self.dims.voxel_count();
        let mut out = vec![T::zero(); self.rays.len() * self.channels * voxels];
        let mut first_ray = 0;
        for (b, rays) in self.rays.iter().enumerate() {
            let kernel = self.kernel(b);
            let tiles = rays.len().div_ceil(TILE);
            let blocks = tiles.min(BLOCKS);
            let buffers: Vec<Vec<[T; 4]>> = (0..blocks)
                .into_par_iter()
                .map(|block| {
                    let mut buf = buffer_pool::take_zeroed::<T>(voxels);
                    for tile in (block..tiles).step_by(blocks) {
                        let rays_in_tile = tile * TILE..((tile + 1) * TILE).min(rays.len());
                        let rows = (first_ray + rays_in_tile.start) * PACKED
                            ..(first_ray + rays_in_tile.end) * PACKED;
                        kernel.backward_tile(
                            &rays.origins()[rays_in_tile.clone()],
                            &rays.dirs()[rays_in_tile],
                            &res[rows.clone()],
                            &grad[rows],
                            &mut buf,
                        );
                    }
                    buf
                })
                .collect();
            first_ray += rays.len();
            // Sum the block buffers in block order, straight into the planar layout.
            let volume_grad =
                &mut out[b * self.channels * voxels..(b * self.channels + 4) * voxels];
            let (sigma, rest) = volume_grad.split_at_mut(voxels);
            let (red, rest) = rest.split_at_mut(voxels);
            let (green, blue) = rest.split_at_mut(voxels);
            const CHUNK: usize = 4096;
            sigma
                .par_chunks_mut(CHUNK)
                .zip(red.par_chunks_mut(CHUNK))
                .zip(green.par_chunks_mut(CHUNK).zip(blue.par_chunks_mut(CHUNK)))
                .enumerate()
                .for_each(|(chunk, ((s, r), (g, bl)))| {
                    for j in 0..s.len() {
                        let v = chunk * CHUNK + j;
                        let mut acc = [T::zero(); 4];
                        for buf in &buffers {
                            for c in 0..4 {
                                acc[c] += buf[v][c];
                            }
                        }
                        (s[j], r[j], g[j], bl[j]) = (acc[0], acc[1], acc[2], acc[3]);
                    }
                });
            buffer_pool::give_back(buffers);
        }
        out
    }
}

impl<T: Pooled> Drop for CompositeOp<T> {
    /// Hands the volume copies to the buffer pool for the next render.
    fn drop(&mut self) {
        buffer_pool::give_back(std::mem::take(&mut self.volumes));
    }
}

/// Copies channels 0..4 of `n` planar `(C, D, H, W)` volumes into interleaved `[sigma, r, g, b]`
/// per voxel, checking in the same pass that every value is finite and every density >= 0
/// (with `raw_density`, at most [`MAX_VOLUME_VALUE`] in magnitude instead).
fn interleave<T: Pooled>(
    values: &[T],
    n: usize,
    channels: usize,
    dims: GridDims,
    raw_density: bool,
) -> Result<Vec<Vec<[T; 4]>>> {
    /// Voxels per parallel task.
    const CHUNK: usize = 4096;
    let voxels = dims.voxel_count();
    let limit = T::of(f64::from(MAX_VOLUME_VALUE));
    // Density may be any finite value >= 0 (the kernel is exact up to f32::MAX); colours, and
    // raw densities whose activation is linear above its knee, are bounded so that their
    // products with segment lengths stay finite in the backward pass.
    let value_ok = |c: usize, x: T| {
        if c == 0 && !raw_density {
            x.is_finite() && x >= T::zero()
        } else {
            x.abs() <= limit
        }
    };
    // The first channel refused in voxel `v`.
    let refused = |v: &[T; 4]| (0..4).find(|&c| !value_ok(c, v[c]));
    (0..n)
        .map(|b| {
            let vol = &values[b * channels * voxels..(b * channels + 4) * voxels];
            let voxel = |i: usize| [0, 1, 2, 3].map(|c| vol[c * voxels + i]);
            let mut data = buffer_pool::take::<T>(voxels);
            let count: usize = data
                .par_chunks_mut(CHUNK)
                .enumerate()
                .map(|(chunk, out)| {
                    let start = chunk * CHUNK;
                    let planes = [0, 1, 2, 3].map(|c| {
                        let plane = c * voxels + start;
                        &vol[plane..plane + out.len()]
                    });
                    let mut count = 0;
                    for (i, cell) in out.iter_mut().enumerate() {
                        *cell = planes.map(|p| p[i]);
                        count += usize::from(refused(cell).is_some());
                    }
                    count
                })
                .sum();
            if count > 0 {
                // (The buffer is not given back: errors are not the path to optimise.)
                let (i, c) = (0..voxels)
                    .find_map(|i| refused(&voxel(i)).map(|c| (i, c)))
                    .unwrap_or((0, 0));
                return Err(invalid_volume(
                    count,
                    b,
                    c,
                    i,
                    dims,
                    voxel(i)[c],
                    raw_density,
                ));
            }
            Ok(data)
        })
        .collect()
}

/// The error for a volume holding `count` values the renderer refuses, the first in channel `c`
/// of voxel `i` (flat, x fastest) of volume `b` (shared with the portable path, which checks
/// the same rules with tensor ops).
pub(crate) fn invalid_volume(
    count: usize,
    b: usize,
    c: usize,
    i: usize,
    dims: GridDims,
    value: impl std::fmt::Debug,
    raw_density: bool,
) -> Error {
    let (z, y, x) = (i / (dims.h * dims.w), (i / dims.w) % dims.h, i % dims.w);
    Error::InvalidVolume {
        count,
        first: format!(
            "volume {b}, channel {c} ({}), voxel (d={z}, h={y}, w={x}) = {value:?}",
            radiance_volume::BASE_CHANNELS[c],
        ),
        why: if raw_density {
            "raw density (channel 0, post-activated) and colours must be finite \
             and at most 1e10 in magnitude"
        } else {
            "density (channel 0) must be finite and >= 0, colours finite and at \
             most 1e10 in magnitude"
        },
    }
}

impl<T: Pooled + WithDType> CustomOp1 for CompositeOp<T> {
    fn name(&self) -> &'static str {
        "volrender-composite"
    }

    fn cpu_fwd(
        &self,
        storage: &CpuStorage,
        _layout: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        // The kernel reads the interleaved copy made (and validated) when the op was built from
        // this very tensor; only the dtype needs to agree.
        if storage.dtype() != T::DTYPE {
            candle_core::bail!(
                "{}: op built for {:?}, called on {:?}",
                self.name(),
                T::DTYPE,
                storage.dtype()
            );
        }
        let out = self.forward();
        let rows = out.len() / PACKED;
        Ok((T::to_cpu_storage_owned(out), Shape::from((rows, PACKED))))
    }

    fn bwd(
        &self,
        arg: &Tensor,
        res: &Tensor,
        grad_res: &Tensor,
    ) -> candle_core::Result<Option<Tensor>> {
        let res: Vec<T> = res.flatten_all()?.to_vec1()?;
        let grad: Vec<T> = grad_res.flatten_all()?.to_vec1()?;
        let g = self.backward(&res, &grad);
        Ok(Some(Tensor::from_vec(g, arg.shape(), arg.device())?))
    }
}

/// Returns the volume's box and cells in kernel precision.
pub(crate) fn grid_spec<T: Real>(cfg: &RenderConfig, dims: GridDims) -> GridSpec<T> {
    let of = |v: glam::Vec3| v.to_array().map(|x| T::of(x as f64));
    GridSpec {
        min: of(cfg.aabb.min),
        max: of(cfg.aabb.max),
        n: [dims.w, dims.h, dims.d],
    }
}
