//! The Cartesian spatial grid (CSG) of SinGRAV: e_csg(x, y, z) = 2 [x/W - 1/2, y/H - 1/2, z/U - 1/2].

use candle_core::{Device, Tensor};

use crate::error::{invalid, Result};
use crate::extended::{csg_grid_3d_over, Outside};

/// The CSG coordinate of cell `i` on an axis of `n` cells: `2 ((i + 0.5) / n - 1/2) = (2i + 1)/n - 1`.
///
/// Cells are cell-centred (docs/architecture.md: cell `i` has its centre at `min + (i + 0.5) (max - min) / n`),
/// so the grid is the position of each voxel centre in the box `[-1, 1]`: symmetric about 0, first
/// value `1/n - 1`, last value `1 - 1/n`. The paper's formula with the integer index `x` instead of
/// `x + 0.5` would shift every value by `-1/n` and never reach the upper half symmetrically.
///
/// ```
/// assert_eq!(csg_embed::csg_coordinate(0, 4), -0.75);
/// assert_eq!(csg_embed::csg_coordinate(3, 4), 0.75);
/// ```
pub fn csg_coordinate(i: usize, n: usize) -> f64 {
    // One rounding of an exact integer ratio: values are correctly rounded and exactly
    // antisymmetric, coordinate(i) == -coordinate(n - 1 - i).
    (2 * i as i64 + 1 - n as i64) as f64 / n as f64
}

/// The CSG values of one axis of `n` cells, as an f32 tensor of shape `(n,)`.
fn axis(n: usize, what: &'static str, device: &Device) -> Result<Tensor> {
    if n == 0 {
        return Err(invalid(what, "a grid axis needs at least one cell"));
    }
    let values: Vec<f32> = (0..n).map(|i| csg_coordinate(i, n) as f32).collect();
    Ok(Tensor::from_vec(values, n, device)?)
}

/// The 3D CSG grid as an f32 tensor of shape `(3, D, H, W)` in the workspace's volume layout (D along z,
/// H along y, W along x; docs/architecture.md).
///
/// Channel 0 is x (varies along W), channel 1 is y (along H), channel 2 is z (along D); the value at
/// `[c, k, j, i]` is [`csg_coordinate`] of the index along that channel's axis.
///
/// ```
/// let g = csg_embed::csg_grid_3d(2, 3, 4, &candle_core::Device::Cpu)?;
/// assert_eq!(g.dims(), &[3, 2, 3, 4]);
/// // x of the voxel (z=0, y=0, x=3) is the centre of the last of 4 cells in [-1, 1].
/// assert_eq!(g.get(0)?.get(0)?.get(0)?.get(3)?.to_scalar::<f32>()?, 0.75);
/// # Ok::<(), csg_embed::Error>(())
/// ```
pub fn csg_grid_3d(d: usize, h: usize, w: usize, device: &Device) -> Result<Tensor> {
    // The learned box itself: every rule for the outside gives the same grid.
    csg_grid_3d_over((d, h, w), [1.0; 3], Outside::Extend, device)
}

/// The 3D CSG grid repeated over a batch: shape `(N, 3, D, H, W)`, every item equal to
/// [`csg_grid_3d`].
///
/// ```
/// let g = csg_embed::csg_grid_3d_batched(2, 4, 4, 4, &candle_core::Device::Cpu)?;
/// assert_eq!(g.dims(), &[2, 3, 4, 4, 4]);
/// # Ok::<(), csg_embed::Error>(())
/// ```
pub fn csg_grid_3d_batched(
    n: usize,
    d: usize,
    h: usize,
    w: usize,
    device: &Device,
) -> Result<Tensor> {
    if n == 0 {
        return Err(invalid("batch size", "a batch needs at least one item"));
    }
    let grid = csg_grid_3d(d, h, w, device)?.unsqueeze(0)?;
    Ok(grid.broadcast_as((n, 3, d, h, w))?.contiguous()?)
}

/// The 2D CSG grid as an f32 tensor of shape `(2, H, W)`: channel 0 is x (along W), channel 1 is y
/// (along H), with the same cell-centred values as [`csg_grid_3d`].
///
/// ```
/// let g = csg_embed::csg_grid_2d(2, 2, &candle_core::Device::Cpu)?;
/// assert_eq!(g.flatten_all()?.to_vec1::<f32>()?, [-0.5, 0.5, -0.5, 0.5, -0.5, -0.5, 0.5, 0.5]);
/// # Ok::<(), csg_embed::Error>(())
/// ```
pub fn csg_grid_2d(h: usize, w: usize, device: &Device) -> Result<Tensor> {
    let shape = (h, w);
    let x = axis(w, "width", device)?.reshape((1, w))?;
    let y = axis(h, "height", device)?.reshape((h, 1))?;
    Ok(Tensor::stack(
        &[x.broadcast_as(shape)?, y.broadcast_as(shape)?],
        0,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_3d_matches_formula_exactly() {
        let (d, h, w) = (3, 5, 7);
        let g = csg_grid_3d(d, h, w, &Device::Cpu).unwrap();
        assert_eq!(g.dims(), &[3, d, h, w]);
        let flat = g.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        for c in 0..3 {
            for k in 0..d {
                for j in 0..h {
                    for i in 0..w {
                        let (idx, n) = [(i, w), (j, h), (k, d)][c];
                        // The exact rational (2 idx + 1 - n) / n, rounded once to f32...
                        let exact = ((2 * idx as i64 + 1 - n as i64) as f64 / n as f64) as f32;
                        let got = flat[((c * d + k) * h + j) * w + i];
                        assert_eq!(got, exact, "c={c} k={k} j={j} i={i}");
                        // ...which is the paper's 2 (x/W - 1/2) at the cell centre x = idx + 0.5.
                        let paper = 2.0 * ((idx as f64 + 0.5) / n as f64 - 0.5);
                        assert!((got as f64 - paper).abs() < 1e-7);
                    }
                }
            }
        }
    }

    #[test]
    fn grid_is_symmetric_about_zero() {
        for n in 1..9 {
            for i in 0..n {
                assert_eq!(csg_coordinate(i, n), -csg_coordinate(n - 1 - i, n));
            }
        }
        assert_eq!(csg_coordinate(0, 1), 0.0);
    }

    #[test]
    fn grid_2d_matches_formula_exactly() {
        let (h, w) = (4, 3);
        let g = csg_grid_2d(h, w, &Device::Cpu)
            .unwrap()
            .to_vec3::<f32>()
            .unwrap();
        assert_eq!((g[0].len(), g[0][0].len()), (h, w));
        let exact = |i: usize, n: usize| ((2 * i as i64 + 1 - n as i64) as f64 / n as f64) as f32;
        for (j, (xs, ys)) in g[0].iter().zip(&g[1]).enumerate() {
            for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
                assert_eq!(x, exact(i, w));
                assert_eq!(y, exact(j, h));
            }
        }
    }

    #[test]
    fn batched_repeats_the_grid() {
        let g = csg_grid_3d(2, 3, 4, &Device::Cpu).unwrap();
        let b = csg_grid_3d_batched(3, 2, 3, 4, &Device::Cpu).unwrap();
        for n in 0..3 {
            let diff = (b.get(n).unwrap() - &g).unwrap().abs().unwrap();
            assert_eq!(diff.max_all().unwrap().to_scalar::<f32>().unwrap(), 0.0);
        }
    }

    #[test]
    fn zero_sizes_are_rejected() {
        assert!(csg_grid_3d(0, 2, 2, &Device::Cpu).is_err());
        assert!(csg_grid_2d(2, 0, &Device::Cpu).is_err());
        assert!(csg_grid_3d_batched(0, 2, 2, 2, &Device::Cpu).is_err());
    }
}
