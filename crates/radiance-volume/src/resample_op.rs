//! [`resample_tensor`](crate::resample_tensor) on the CPU: three passes of two-tap lerps (along
//! x, then y, then z) and, for the backward pass, their adjoint. The interpolation matrices the
//! other devices multiply are almost all zeros (two taps per row): at the pyramid's finest step
//! (89^3 to 126^3, 4 channels) they took about ten times as long (docs/performance.md,
//! "Resampling between scales").
//!
//! The forward values are [`Resampled`](crate::Resampled)'s bit for bit: the same lerps in the
//! same order, so a volume generated in training and one streamed to a file agree exactly.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, Layout, Shape, Tensor};
use rayon::prelude::*;

use crate::resample::{axis_lerps, lerp};
use crate::sample::AxisLerp;

/// The lerps of the three axes, `[x, y, z]`, from `from` to `to` cells (each `[D, H, W]`).
fn lerps(from: [usize; 3], to: [usize; 3]) -> [Vec<AxisLerp>; 3] {
    [
        axis_lerps(from[2], to[2], 0..to[2]),
        axis_lerps(from[1], to[1], 0..to[1]),
        axis_lerps(from[0], to[0], 0..to[0]),
    ]
}

/// Resamples the last three axes `(D, H, W)` of an f32 tensor (rank at least 3) to `to`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Resample {
    pub(crate) to: [usize; 3],
}

/// The adjoint of [`Resample`] from `from`: a gradient `(.., D', H', W')` back to `(.., D, H,
/// W)` = `from`.
#[derive(Debug, Clone, Copy)]
struct ResampleAdjoint {
    from: [usize; 3],
}

/// The contiguous f32 values of `storage`, or candle's error naming `op`.
fn f32_values<'a>(
    storage: &'a CpuStorage,
    layout: &Layout,
    op: &'static str,
) -> candle_core::Result<&'a [f32]> {
    let (start, end) = layout
        .contiguous_offsets()
        .ok_or(candle_core::Error::RequiresContiguous { op })?;
    match storage {
        CpuStorage::F32(values) => Ok(&values[start..end]),
        other => Err(candle_core::Error::UnsupportedDTypeForOp(other.dtype(), op)),
    }
}

/// The leading dimensions and the last three of `layout`'s shape.
fn split_dims(layout: &Layout) -> candle_core::Result<(&[usize], [usize; 3])> {
    let dims = layout.dims();
    match dims.len().checked_sub(3) {
        Some(lead) => Ok((&dims[..lead], [dims[lead], dims[lead + 1], dims[lead + 2]])),
        None => Err(candle_core::Error::Msg(format!(
            "resampling needs (.., D, H, W), got {:?}",
            layout.shape()
        ))),
    }
}

/// `lead` followed by `dhw`, as a shape.
fn shape_of(lead: &[usize], dhw: [usize; 3]) -> Shape {
    Shape::from(lead.iter().copied().chain(dhw).collect::<Vec<_>>())
}

impl CustomOp1 for Resample {
    fn name(&self) -> &'static str {
        "resample"
    }

    fn cpu_fwd(
        &self,
        storage: &CpuStorage,
        layout: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let x = f32_values(storage, layout, self.name())?;
        let (lead, from) = split_dims(layout)?;
        Ok((
            CpuStorage::F32(resample(x, from, self.to)),
            shape_of(lead, self.to),
        ))
    }

    fn bwd(
        &self,
        arg: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> candle_core::Result<Option<Tensor>> {
        let rank = arg.rank();
        let from = [arg.dim(rank - 3)?, arg.dim(rank - 2)?, arg.dim(rank - 1)?];
        let grad = grad_res
            .contiguous()?
            .apply_op1_no_bwd(&ResampleAdjoint { from })?;
        Ok(Some(grad))
    }
}

impl CustomOp1 for ResampleAdjoint {
    fn name(&self) -> &'static str {
        "resample-adjoint"
    }

    fn cpu_fwd(
        &self,
        storage: &CpuStorage,
        layout: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let grad = f32_values(storage, layout, self.name())?;
        let (lead, to) = split_dims(layout)?;
        Ok((
            CpuStorage::F32(resample_adjoint(grad, self.from, to)),
            shape_of(lead, self.from),
        ))
    }
}

/// `x`, volumes of `from` cells one after another, resampled to `to`: output plane by output
/// plane, each the lerp along z of two input planes resampled in (y, x), which the worker
/// keeps for the next output plane (consecutive output planes mostly share them). No volume
/// sized temporary, so a call allocates only its result.
fn resample(x: &[f32], from: [usize; 3], to: [usize; 3]) -> Vec<f32> {
    let [lx, ly, lz] = lerps(from, to);
    let ([d, h, w], [td, th, tw]) = (from, to);
    let (volume, plane) = (d * h * w, th * tw);
    let mut out = vec![0f32; x.len() / volume.max(1) * td * plane];
    out.par_chunks_mut(plane.max(1)).enumerate().for_each_init(
        || PlanePair::new(h * tw, plane),
        |pair, (i, dst)| {
            let (item, z) = (i / td, lz[i % td]);
            let input = &x[item * volume..][..volume];
            let xy = |zi: usize| (item, zi, &input[zi * h * w..][..h * w]);
            let (lower, upper) = pair.planes(xy(z.i0), xy(z.i1), [w, h], [&lx, &ly]);
            for ((o, &a), &b) in dst.iter_mut().zip(lower).zip(upper) {
                *o = lerp(a, b, z.t);
            }
        },
    );
    out
}

/// The two input planes, resampled in (y, x), that one output plane interpolates, kept by
/// `(volume, z)` for the next output plane.
struct PlanePair {
    /// Along x only: `h x tw`.
    rows: Vec<f32>,
    planes: [Vec<f32>; 2],
    keys: [Option<(usize, usize)>; 2],
}

impl PlanePair {
    fn new(rows: usize, plane: usize) -> Self {
        Self {
            rows: vec![0.0; rows],
            planes: [vec![0.0; plane], vec![0.0; plane]],
            keys: [None; 2],
        }
    }

    /// The resampled planes of `lower` and `upper`, each `(volume, z, input plane)`, computing
    /// those not kept; the one kept for `lower` is never overwritten by `upper`.
    fn planes(
        &mut self,
        lower: (usize, usize, &[f32]),
        upper: (usize, usize, &[f32]),
        [w, h]: [usize; 2],
        [lx, ly]: [&[AxisLerp]; 2],
    ) -> (&[f32], &[f32]) {
        let mut slot_of = |(volume, z, input): (usize, usize, &[f32]), keep: Option<usize>| {
            let key = Some((volume, z));
            if let Some(slot) = self.keys.iter().position(|k| *k == key) {
                return slot;
            }
            let slot = usize::from(keep == Some(0));
            resample_plane(input, w, h, lx, ly, &mut self.rows, &mut self.planes[slot]);
            self.keys[slot] = key;
            slot
        };
        let a = slot_of(lower, None);
        let b = slot_of(upper, Some(a));
        (&self.planes[a], &self.planes[b])
    }
}

/// `input` (`h x w`) resampled to `plane` (`ly.len() x lx.len()`): along x into `rows`, then
/// along y, the order [`Resampled`](crate::Resampled) lerps a cell in.
fn resample_plane(
    input: &[f32],
    w: usize,
    h: usize,
    lx: &[AxisLerp],
    ly: &[AxisLerp],
    rows: &mut [f32],
    plane: &mut [f32],
) {
    let tw = lx.len();
    for (row, out) in input.chunks_exact(w).take(h).zip(rows.chunks_exact_mut(tw)) {
        for (o, l) in out.iter_mut().zip(lx) {
            *o = lerp(row[l.i0], row[l.i1], l.t);
        }
    }
    for (out, l) in plane.chunks_exact_mut(tw).zip(ly) {
        let (a, b) = (&rows[l.i0 * tw..][..tw], &rows[l.i1 * tw..][..tw]);
        for ((o, &a), &b) in out.iter_mut().zip(a).zip(b) {
            *o = lerp(a, b, l.t);
        }
    }
}

/// Per input cell of an axis, the output cells it feeds and their weights, in output order:
/// the lower neighbour with `1 - t`, the upper one with `t` (not at all at `t = 0`, where
/// [`lerp`] copies the lower one).
fn feeds(n_in: usize, lerps: &[AxisLerp]) -> Vec<Vec<(usize, f32)>> {
    let mut feeds = vec![Vec::new(); n_in];
    for (o, l) in lerps.iter().enumerate() {
        feeds[l.i0].push((o, 1.0 - l.t));
        if l.t != 0.0 {
            feeds[l.i1].push((o, l.t));
        }
    }
    feeds
}

/// The transpose of [`resample`]: `grad`, volumes of `to` cells, summed back onto volumes of
/// `from` cells, input plane by input plane (z, then y, then x transposed), each value a sum
/// in a fixed order, so the gradient does not depend on threads.
fn resample_adjoint(grad: &[f32], from: [usize; 3], to: [usize; 3]) -> Vec<f32> {
    let [lx, ly, lz] = lerps(from, to);
    let [fx, fy, fz] = [
        feeds(from[2], &lx),
        feeds(from[1], &ly),
        feeds(from[0], &lz),
    ];
    let ([d, h, w], [td, th, tw]) = (from, to);
    let (volume, plane) = (td * th * tw, th * tw);
    let mut out = vec![0f32; grad.len() / volume.max(1) * d * h * w];
    out.par_chunks_mut((h * w).max(1))
        .enumerate()
        .for_each_init(
            || (vec![0f32; plane], vec![0f32; h * tw]),
            |(along_z, along_y), (i, dst)| {
                let (item, z) = (i / d, i % d);
                let g = &grad[item * volume..][..volume];
                along_z.fill(0.0);
                for &(o, weight) in &fz[z] {
                    for (a, &v) in along_z.iter_mut().zip(&g[o * plane..][..plane]) {
                        *a += v * weight;
                    }
                }
                along_y.fill(0.0);
                for (row, feed) in along_y.chunks_exact_mut(tw).zip(&fy) {
                    for &(o, weight) in feed {
                        for (a, &v) in row.iter_mut().zip(&along_z[o * tw..][..tw]) {
                            *a += v * weight;
                        }
                    }
                }
                for (out, row) in dst.chunks_exact_mut(w).zip(along_y.chunks_exact(tw)) {
                    for (o, feed) in out.iter_mut().zip(&fx) {
                        *o = feed
                            .iter()
                            .fold(0.0, |sum, &(x, weight)| sum + row[x] * weight);
                    }
                }
            },
        );
    out
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Tensor, Var};

    use crate::{resample_tensor, Aabb, GridDims, RadianceVolume, Resampled};

    /// A `(2, 4, d, h, w)` tensor (two volumes) of distinct, irregular values.
    fn batch(dims: [usize; 3]) -> Tensor {
        let n = 8 * dims.iter().product::<usize>();
        let values: Vec<f32> = (0..n)
            .map(|i| ((i * 7919) % 1009) as f32 / 97.0 - 5.0)
            .collect();
        Tensor::from_vec(values, (2, 4, dims[0], dims[1], dims[2]), &Device::Cpu).unwrap()
    }

    fn values(t: &Tensor) -> Vec<f64> {
        t.to_dtype(DType::F64)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap()
    }

    /// Size changes up, down, mixed and kept, with odd sizes and single cells.
    const CASES: [([usize; 3], [usize; 3]); 4] = [
        ([5, 7, 6], [7, 9, 8]),
        ([9, 6, 11], [6, 4, 8]),
        ([4, 1, 5], [4, 3, 2]),
        ([1, 2, 3], [2, 2, 3]),
    ];

    #[test]
    fn lerps_equal_the_streamed_cells_bit_for_bit() {
        for (from, to) in CASES {
            let x = batch(from);
            let got = resample_tensor(&x, GridDims::new(to[0], to[1], to[2])).unwrap();
            assert_eq!(got.dims(), &[2, 4, to[0], to[1], to[2]]);
            for item in 0..2 {
                let volume = RadianceVolume::new(x.get(item).unwrap(), Aabb::CUBE).unwrap();
                let streamed = Resampled::new(volume, GridDims::new(to[0], to[1], to[2]))
                    .unwrap()
                    .to_volume()
                    .unwrap();
                let want: Vec<f32> = streamed.tensor().flatten_all().unwrap().to_vec1().unwrap();
                let got: Vec<f32> = got
                    .get(item)
                    .unwrap()
                    .flatten_all()
                    .unwrap()
                    .to_vec1()
                    .unwrap();
                assert_eq!(got, want, "{from:?} -> {to:?}");
            }
        }
    }

    #[test]
    fn values_and_gradients_equal_the_interpolation_matrices_in_f64() {
        for (from, to) in CASES {
            let dims = GridDims::new(to[0], to[1], to[2]);
            let x = Var::from_tensor(&batch(from)).unwrap();
            let probe = batch(to).sin().unwrap();
            let y = resample_tensor(x.as_tensor(), dims).unwrap();
            let grads = (&y * &probe)
                .unwrap()
                .sum_all()
                .unwrap()
                .backward()
                .unwrap();
            let grad = grads.get(x.as_tensor()).unwrap();

            // The f64 reference: the matrices, through candle's autograd.
            let x64 = Var::from_tensor(&x.as_tensor().to_dtype(DType::F64).unwrap()).unwrap();
            let y64 = resample_tensor(x64.as_tensor(), dims).unwrap();
            let p64 = probe.to_dtype(DType::F64).unwrap();
            let grads64 = (&y64 * &p64)
                .unwrap()
                .sum_all()
                .unwrap()
                .backward()
                .unwrap();
            let grad64 = grads64.get(x64.as_tensor()).unwrap();

            for (got, want) in [(&y, &y64), (grad, grad64)] {
                assert_eq!(got.dims(), want.dims());
                for (a, b) in values(got).iter().zip(values(want)) {
                    assert!(
                        (a - b).abs() <= 1e-5 * b.abs().max(1.0),
                        "{from:?} -> {to:?}: {a} vs {b}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_strided_tensor_is_resampled_as_its_contiguous_copy() {
        let x = batch([4, 5, 6]).transpose(3, 4).unwrap();
        let dims = GridDims::new(6, 7, 5);
        let strided = resample_tensor(&x, dims).unwrap();
        let contiguous = resample_tensor(&x.contiguous().unwrap(), dims).unwrap();
        assert_eq!(values(&strided), values(&contiguous));
    }

    #[test]
    fn fewer_than_three_dimensions_are_refused() {
        let x = Tensor::zeros((4, 4), DType::F32, &Device::Cpu).unwrap();
        assert!(resample_tensor(&x, GridDims::cube(2)).is_err());
    }
}
