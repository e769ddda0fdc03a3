//! Structural similarity (SSIM) between rendered and real views, as Wang et al. (2004) define it.

use candle_core::{DType, Tensor};

use crate::error::{invalid, Result};

/// Side of the Gaussian window.
const WINDOW: usize = 11;
/// Standard deviation of the Gaussian window, in pixels.
const SIGMA: f64 = 1.5;
/// Wang et al.'s constants for a dynamic range of 1: `C1 = (0.01)^2`, `C2 = (0.03)^2`.
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// SSIM of each view of `rendered` against `real`, both `(V, C, H, W)` with values in [0, 1]
/// (dynamic range 1), computed in f64.
///
/// The standard definition (Wang et al. 2004, their `ssim_index.m`): local means, variances and
/// covariance under an 11 x 11 Gaussian window of sigma 1.5, `K1 = 0.01`, `K2 = 0.03`; the SSIM
/// map is evaluated where the whole window fits (no padding), per channel, and averaged over
/// positions and channels. 1 means identical; views need sides of at least 11 pixels.
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::rand(0f32, 1., (2, 3, 16, 16), &Device::Cpu)?;
/// assert!((scene_metrics::ssim_per_view(&real, &real)?[1] - 1.0).abs() < 1e-12);
/// // Constant images a and b: the structure term is 1, the luminance term
/// // (2ab + C1) / (a^2 + b^2 + C1).
/// let a = Tensor::full(0.2f32, (1, 3, 12, 12), &Device::Cpu)?;
/// let b = Tensor::full(0.6f32, (1, 3, 12, 12), &Device::Cpu)?;
/// let expected = (2.0 * 0.2 * 0.6 + 1e-4) / (0.04 + 0.36 + 1e-4);
/// assert!((scene_metrics::ssim_per_view(&a, &b)?[0] - expected).abs() < 1e-6);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn ssim_per_view(rendered: &Tensor, real: &Tensor) -> Result<Vec<f64>> {
    let (views, channels, h, w) = real.dims4().map_err(|_| {
        invalid(
            "real views",
            format!("expected (V, C, H, W), got {:?}", real.dims()),
        )
    })?;
    if rendered.shape() != real.shape() {
        return Err(invalid(
            "rendered views",
            format!(
                "expected views shaped like the real ones {:?}, got {:?}",
                real.dims(),
                rendered.dims()
            ),
        ));
    }
    if h < WINDOW || w < WINDOW {
        return Err(invalid(
            "views",
            format!("SSIM's {WINDOW} x {WINDOW} window needs views of at least that size, got {h} x {w}"),
        ));
    }
    let flat =
        |t: &Tensor| -> Result<Vec<f64>> { Ok(t.to_dtype(DType::F64)?.flatten_all()?.to_vec1()?) };
    let (x, y) = (flat(rendered)?, flat(real)?);
    let window = gaussian_window();
    let plane = h * w;
    Ok((0..views)
        .map(|v| {
            let total: f64 = (0..channels)
                .map(|c| {
                    let at = (v * channels + c) * plane;
                    plane_ssim(&x[at..at + plane], &y[at..at + plane], h, w, &window)
                })
                .sum();
            total / channels as f64
        })
        .collect())
}

/// The mean over views of [`ssim_per_view`].
///
/// ```
/// use candle_core::{Device, Tensor};
/// let real = Tensor::rand(0f32, 1., (2, 3, 12, 12), &Device::Cpu)?;
/// let noisy = (&real + Tensor::randn(0f32, 0.1, (2, 3, 12, 12), &Device::Cpu)?)?;
/// let ssim = scene_metrics::mean_ssim(&noisy, &real)?;
/// assert!(ssim > 0.0 && ssim < 1.0);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn mean_ssim(rendered: &Tensor, real: &Tensor) -> Result<f64> {
    let per_view = ssim_per_view(rendered, real)?;
    Ok(per_view.iter().sum::<f64>() / per_view.len() as f64)
}

/// The normalised 1D Gaussian weights; the 2D window is their outer product.
fn gaussian_window() -> [f64; WINDOW] {
    let centre = (WINDOW / 2) as f64;
    let mut weights = [0.0; WINDOW];
    for (i, w) in weights.iter_mut().enumerate() {
        let d = i as f64 - centre;
        *w = (-d * d / (2.0 * SIGMA * SIGMA)).exp();
    }
    let sum: f64 = weights.iter().sum();
    weights.map(|w| w / sum)
}

/// The mean SSIM of one channel plane `h x w` over the positions where the window fits.
fn plane_ssim(x: &[f64], y: &[f64], h: usize, w: usize, window: &[f64; WINDOW]) -> f64 {
    let products = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
        x.iter().zip(y).map(|(&a, &b)| f(a, b)).collect()
    };
    let filter = |plane: &[f64]| filter_valid(plane, h, w, window);
    let mu_x = filter(x);
    let mu_y = filter(y);
    let xx = filter(&products(&|a, _| a * a));
    let yy = filter(&products(&|_, b| b * b));
    let xy = filter(&products(&|a, b| a * b));
    let n = mu_x.len();
    let total: f64 = (0..n)
        .map(|i| {
            let (mx, my) = (mu_x[i], mu_y[i]);
            let var_x = xx[i] - mx * mx;
            let var_y = yy[i] - my * my;
            let cov = xy[i] - mx * my;
            ((2.0 * mx * my + C1) * (2.0 * cov + C2))
                / ((mx * mx + my * my + C1) * (var_x + var_y + C2))
        })
        .sum();
    total / n as f64
}

/// Separable Gaussian filtering of an `h x w` plane, keeping only positions where the whole
/// window fits: an `(h - 10) x (w - 10)` plane, row-major.
fn filter_valid(plane: &[f64], h: usize, w: usize, window: &[f64; WINDOW]) -> Vec<f64> {
    let (oh, ow) = (h - WINDOW + 1, w - WINDOW + 1);
    let mut rows = vec![0.0; h * ow];
    for r in 0..h {
        for c in 0..ow {
            rows[r * ow + c] = (0..WINDOW).map(|k| window[k] * plane[r * w + c + k]).sum();
        }
    }
    let mut out = vec![0.0; oh * ow];
    for r in 0..oh {
        for c in 0..ow {
            out[r * ow + c] = (0..WINDOW)
                .map(|k| window[k] * rows[(r + k) * ow + c])
                .sum();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    /// The SSIM of one window position computed directly from the definition (the full 2D
    /// weights, two-pass variances), for the top-left position of one channel.
    fn direct_first_position(x: &[f64], y: &[f64], w: usize) -> f64 {
        let g = gaussian_window();
        let mut weights = Vec::new();
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for r in 0..WINDOW {
            for c in 0..WINDOW {
                weights.push(g[r] * g[c]);
                xs.push(x[r * w + c]);
                ys.push(y[r * w + c]);
            }
        }
        let mean = |v: &[f64]| weights.iter().zip(v).map(|(w, a)| w * a).sum::<f64>();
        let (mx, my) = (mean(&xs), mean(&ys));
        let dx: Vec<f64> = xs.iter().map(|a| a - mx).collect();
        let dy: Vec<f64> = ys.iter().map(|b| b - my).collect();
        let var_x = mean(&dx.iter().map(|a| a * a).collect::<Vec<_>>());
        let var_y = mean(&dy.iter().map(|b| b * b).collect::<Vec<_>>());
        let cov = mean(&dx.iter().zip(&dy).map(|(a, b)| a * b).collect::<Vec<_>>());
        ((2.0 * mx * my + C1) * (2.0 * cov + C2))
            / ((mx * mx + my * my + C1) * (var_x + var_y + C2))
    }

    #[test]
    fn the_window_is_a_normalised_gaussian_of_sigma_one_and_a_half() {
        let g = gaussian_window();
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // Ratio of neighbouring weights from the centre: exp(-1 / (2 * 1.5^2)).
        assert!((g[6] / g[5] - (-1.0 / 4.5f64).exp()).abs() < 1e-15);
        assert_eq!(g[0], g[10]);
    }

    #[test]
    fn an_11_by_11_view_is_one_window_and_matches_the_definition() {
        let dev = Device::Cpu;
        let real = Tensor::rand(0f64, 1., (1, 1, 11, 11), &dev).unwrap();
        let rendered =
            (&real * 0.5 + Tensor::rand(0f64, 0.5, (1, 1, 11, 11), &dev).unwrap()).unwrap();
        let got = ssim_per_view(&rendered, &real).unwrap()[0];
        let x: Vec<f64> = rendered.flatten_all().unwrap().to_vec1().unwrap();
        let y: Vec<f64> = real.flatten_all().unwrap().to_vec1().unwrap();
        let want = direct_first_position(&x, &y, 11);
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
        assert!(got > 0.0 && got < 0.99, "{got}");
    }

    #[test]
    fn ssim_is_symmetric_falls_with_noise_and_averages_channels_and_views() {
        let dev = Device::Cpu;
        let real = Tensor::rand(0f32, 1., (2, 3, 20, 24), &dev).unwrap();
        let noise = Tensor::randn(0f32, 1., (2, 3, 20, 24), &dev).unwrap();
        let noisy = |amount: f64| (&real + (&noise * amount).unwrap()).unwrap();
        let a = ssim_per_view(&noisy(0.05), &real).unwrap();
        let b = ssim_per_view(&real, &noisy(0.05)).unwrap();
        assert!((a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12);
        let more = ssim_per_view(&noisy(0.3), &real).unwrap();
        assert!(more[0] < a[0] && more[1] < a[1], "{a:?} then {more:?}");
        // Channel 0 identical, channels 1 and 2 constant 0 against constant 1: per channel
        // 1, (C1) / (1 + C1), (C1) / (1 + C1).
        let zeros = Tensor::zeros((1, 2, 12, 12), DType::F32, &dev).unwrap();
        let ones = Tensor::ones((1, 2, 12, 12), DType::F32, &dev).unwrap();
        let shared = real
            .get(0)
            .unwrap()
            .narrow(0, 0, 1)
            .unwrap()
            .narrow(1, 0, 12)
            .unwrap();
        let shared = shared.narrow(2, 0, 12).unwrap().unsqueeze(0).unwrap();
        let x = Tensor::cat(&[&shared, &zeros], 1).unwrap();
        let y = Tensor::cat(&[&shared, &ones], 1).unwrap();
        let want = (1.0 + 2.0 * C1 / (1.0 + C1)) / 3.0;
        let got = mean_ssim(&x, &y).unwrap();
        assert!((got - want).abs() < 1e-9, "{got} vs {want}");
    }

    #[test]
    fn small_or_mismatched_views_are_errors() {
        let dev = Device::Cpu;
        let small = Tensor::zeros((1, 3, 10, 16), DType::F32, &dev).unwrap();
        let err = ssim_per_view(&small, &small).unwrap_err().to_string();
        assert!(err.contains("10 x 16"), "{err}");
        let a = Tensor::zeros((1, 3, 12, 12), DType::F32, &dev).unwrap();
        let b = Tensor::zeros((2, 3, 12, 12), DType::F32, &dev).unwrap();
        assert!(ssim_per_view(&a, &b).is_err());
    }
}
