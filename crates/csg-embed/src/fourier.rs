//! Fourier-feature encodings of a grid: sin and cos of the coordinates at chosen frequencies.

use candle_core::Tensor;

use crate::error::{invalid, Result};

/// Octave frequencies `[1, 2, 4, ..., 2^(n-1)]`, NeRF's positional-encoding choice.
///
/// ```
/// assert_eq!(csg_embed::octave_frequencies(4), [1.0, 2.0, 4.0, 8.0]);
/// ```
pub fn octave_frequencies(n: usize) -> Vec<f64> {
    (0..n).map(|k| (1u64 << k) as f64).collect()
}

/// Fourier features of `grid` along its channel axis `channel_dim`.
///
/// For coordinates `g_0 .. g_{C-1}` (e.g. the x, y, z of [`crate::csg_grid_3d`], in `[-1, 1]`) and
/// frequencies `f_0 .. f_{K-1}`, the output has `2 K C` channels in this order:
///
/// `sin(pi f_0 g_0), ..., sin(pi f_0 g_{C-1}), cos(pi f_0 g_0), ..., cos(pi f_0 g_{C-1}),`
/// then the same for `f_1`, and so on. The factor `pi` makes frequency 1 one half period across the
/// box, so frequency 1 alone is one-to-one on `[-1, 1]`. Every other axis keeps its size, so a
/// `(3, D, H, W)` grid with `channel_dim = 0` gives `(6K, D, H, W)`, and a batched
/// `(N, 3, D, H, W)` grid with `channel_dim = 1` gives `(N, 6K, D, H, W)`.
///
/// ```
/// use candle_core::Device;
/// let grid = csg_embed::csg_grid_2d(4, 4, &Device::Cpu)?;
/// let feats = csg_embed::fourier_features(&grid, 0, &csg_embed::octave_frequencies(3))?;
/// assert_eq!(feats.dims(), &[12, 4, 4]);
/// # Ok::<(), csg_embed::Error>(())
/// ```
pub fn fourier_features(grid: &Tensor, channel_dim: usize, freqs: &[f64]) -> Result<Tensor> {
    if freqs.is_empty() {
        return Err(invalid("frequencies", "at least one frequency is needed"));
    }
    if channel_dim >= grid.rank() {
        return Err(invalid(
            "channel_dim",
            format!(
                "{channel_dim} is not an axis of a rank-{} grid",
                grid.rank()
            ),
        ));
    }
    let mut parts = Vec::with_capacity(2 * freqs.len());
    for &f in freqs {
        let phase = (grid * (std::f64::consts::PI * f))?;
        parts.push(phase.sin()?);
        parts.push(phase.cos()?);
    }
    Ok(Tensor::cat(&parts, channel_dim)?)
}

/// The number of channels [`fourier_features`] produces from `channels` coordinates and
/// `frequencies` frequencies.
///
/// ```
/// assert_eq!(csg_embed::fourier_channels(3, 4), 24);
/// ```
pub fn fourier_channels(channels: usize, frequencies: usize) -> usize {
    2 * channels * frequencies
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::csg_grid_3d;
    use candle_core::{Device, D};

    #[test]
    fn channel_order_and_values() {
        let (d, h, w) = (2, 3, 4);
        let grid = csg_grid_3d(d, h, w, &Device::Cpu).unwrap();
        let freqs = [1.0, 3.0];
        let f = fourier_features(&grid, 0, &freqs).unwrap();
        assert_eq!(f.dims(), &[fourier_channels(3, 2), d, h, w]);
        let g = grid.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let f = f.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let vox = d * h * w;
        for (k, &freq) in freqs.iter().enumerate() {
            for c in 0..3 {
                for v in 0..vox {
                    let phase = std::f64::consts::PI * freq * g[c * vox + v] as f64;
                    let sin = f[((k * 2) * 3 + c) * vox + v] as f64;
                    let cos = f[((k * 2 + 1) * 3 + c) * vox + v] as f64;
                    assert!((sin - phase.sin()).abs() < 1e-6, "sin k={k} c={c} v={v}");
                    assert!((cos - phase.cos()).abs() < 1e-6, "cos k={k} c={c} v={v}");
                }
            }
        }
    }

    #[test]
    fn batched_channel_dim() {
        let grid = crate::csg_grid_3d_batched(2, 2, 2, 2, &Device::Cpu).unwrap();
        let f = fourier_features(&grid, 1, &octave_frequencies(2)).unwrap();
        assert_eq!(f.dims(), &[2, 12, 2, 2, 2]);
        let last = f.narrow(1, 11, 1).unwrap().squeeze(1).unwrap();
        let z = grid.narrow(1, 2, 1).unwrap().squeeze(1).unwrap();
        let expected = (z * (2.0 * std::f64::consts::PI)).unwrap().cos().unwrap();
        let err = (last - expected)
            .unwrap()
            .abs()
            .unwrap()
            .flatten_all()
            .unwrap();
        assert!(err.max(D::Minus1).unwrap().to_scalar::<f32>().unwrap() < 1e-6);
    }

    #[test]
    fn bad_arguments_are_rejected() {
        let grid = crate::csg_grid_2d(2, 2, &Device::Cpu).unwrap();
        assert!(fourier_features(&grid, 0, &[]).is_err());
        assert!(fourier_features(&grid, 3, &[1.0]).is_err());
    }
}
