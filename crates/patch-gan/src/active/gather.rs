//! Moving features between whole volumes `(B, C, D, H, W)` and active sites `(1, C, M, 1, 1)`:
//! [`gather`] and [`scatter`], each the other's adjoint, so each one's backward is the other.

use std::sync::Arc;

use candle_core::{CpuStorage, CustomOp1, Layout, Shape, Tensor};
use conv_kernels::Element;
use rayon::prelude::*;

use super::ActiveSites;
use crate::error::{invalid, Result};
use crate::storage::{self, Kernel};

/// The values of `volumes` `(B, C, D, H, W)` at the active sites, as `(1, C, M, 1, 1)`.
/// Differentiable (to any order): the gradient is scattered back to the sites' voxels.
pub fn gather(volumes: &Tensor, sites: &Arc<ActiveSites>) -> Result<Tensor> {
    sites.check_volumes("gathered volumes", volumes)?;
    Ok(volumes
        .contiguous()?
        .apply_op1(Move(Arc::clone(sites), Direction::Gather))?)
}

/// Volumes `(B, C, D, H, W)` holding `features` `(1, C, M, 1, 1)` at the active sites and zero
/// elsewhere. Differentiable (to any order): the gradient is gathered from the sites.
pub fn scatter(features: &Tensor, sites: &Arc<ActiveSites>) -> Result<Tensor> {
    let dims = features.dims();
    if dims.len() != 5 || dims[0] != 1 || dims[2] != sites.len() || dims[3] != 1 || dims[4] != 1 {
        return Err(invalid(
            "scattered features",
            format!(
                "expected (1, C, {}, 1, 1) for the active set, got {:?}",
                sites.len(),
                features.shape()
            ),
        ));
    }
    Ok(features
        .contiguous()?
        .apply_op1(Move(Arc::clone(sites), Direction::Scatter))?)
}

/// Which way features move between volumes and sites.
#[derive(Debug, Clone, Copy)]
enum Direction {
    /// Volumes to sites.
    Gather,
    /// Sites to volumes.
    Scatter,
}

/// The op of [`gather`] or [`scatter`]; its backward is the other direction.
struct Move(Arc<ActiveSites>, Direction);

impl CustomOp1 for Move {
    fn name(&self) -> &'static str {
        match self.1 {
            Direction::Gather => "active-gather",
            Direction::Scatter => "active-scatter",
        }
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        // Channels are axis 1 of both `(B, C, D, H, W)` and `(1, C, M, 1, 1)`.
        let c = l.dims().get(1).copied().unwrap_or(0);
        let sites = &self.0;
        Ok(match self.1 {
            Direction::Gather => (
                storage::run_unary(self.name(), (s, l), &GatherKernel(sites, c))?,
                Shape::from((1, c, sites.len(), 1, 1)),
            ),
            Direction::Scatter => {
                let [d, h, w] = sites.dims();
                (
                    storage::run_unary(self.name(), (s, l), &ScatterKernel(sites, c))?,
                    Shape::from((sites.batch(), c, d, h, w)),
                )
            }
        })
    }

    fn bwd(
        &self,
        _arg: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<Option<Tensor>> {
        Ok(Some(match self.1 {
            Direction::Gather => scatter(grad, &self.0)?,
            Direction::Scatter => gather(grad, &self.0)?,
        }))
    }
}

/// `out[c M + j] = x[(b_j C + c) V + v_j]` for site `j` at voxel `v_j` of volume `b_j`.
struct GatherKernel<'a>(&'a ActiveSites, usize);

impl Kernel for GatherKernel<'_> {
    fn run<T: Element>(&self, x: &[T], _: &[T]) -> candle_core::Result<Vec<T>> {
        let (sites, c) = (self.0, self.1);
        let voxels: usize = sites.dims().iter().product();
        let mut out = vec![T::ZERO; c * sites.len()];
        if sites.is_empty() {
            return Ok(out);
        }
        out.par_chunks_mut(sites.len())
            .enumerate()
            .for_each(|(channel, row)| {
                for (v, &site) in row.iter_mut().zip(sites.sites()) {
                    let (item, at) = (site as usize / voxels, site as usize % voxels);
                    *v = x[(item * c + channel) * voxels + at];
                }
            });
        Ok(out)
    }
}

/// The adjoint of [`GatherKernel`]: zeros with the features written at their sites.
struct ScatterKernel<'a>(&'a ActiveSites, usize);

impl Kernel for ScatterKernel<'_> {
    fn run<T: Element>(&self, f: &[T], _: &[T]) -> candle_core::Result<Vec<T>> {
        let (sites, c) = (self.0, self.1);
        let voxels: usize = sites.dims().iter().product();
        let mut out = vec![T::ZERO; sites.batch() * c * voxels];
        if voxels == 0 {
            return Ok(out);
        }
        let m = sites.len();
        out.par_chunks_mut(voxels)
            .enumerate()
            .for_each(|(plane, dst)| {
                let (item, channel) = (plane / c, plane % c);
                // The sites are ascending, so volume `item`'s are one contiguous run.
                let all = sites.sites();
                let lo = all.partition_point(|&s| (s as usize) < item * voxels);
                let hi = all.partition_point(|&s| (s as usize) < (item + 1) * voxels);
                let values = &f[channel * m..(channel + 1) * m];
                for j in lo..hi {
                    dst[all[j] as usize - item * voxels] = values[j];
                }
            });
        Ok(out)
    }
}
