//! Separable image resampling for the per-scale training images: an area (box) filter when
//! shrinking, so every source pixel counts in proportion to its overlap with the target pixel
//! (antialiased at any ratio, integer or not), and linear interpolation between pixel centres
//! when enlarging.

/// For each target sample, the first source index and the weights of consecutive source samples.
type Taps = Vec<(usize, Vec<f32>)>;

/// The taps that resample `src` samples to `dst` samples along one axis.
fn taps(src: usize, dst: usize) -> Taps {
    let scale = src as f64 / dst as f64;
    (0..dst)
        .map(|j| {
            if scale >= 1.0 {
                // Target pixel j covers [j, j + 1) * scale of the source.
                let (lo, hi) = (j as f64 * scale, (j + 1) as f64 * scale);
                let first = lo.floor() as usize;
                let last = (hi.ceil() as usize).min(src);
                let weights = (first..last)
                    .map(|i| ((hi.min(i as f64 + 1.0) - lo.max(i as f64)) / scale) as f32)
                    .collect();
                (first, weights)
            } else {
                // Linear between source centres, edge-clamped.
                let x = ((j as f64 + 0.5) * scale - 0.5).clamp(0.0, (src - 1) as f64);
                let first = (x.floor() as usize).min(src.saturating_sub(2));
                let frac = (x - first as f64) as f32;
                if src == 1 {
                    (0, vec![1.0])
                } else {
                    (first, vec![1.0 - frac, frac])
                }
            }
        })
        .collect()
}

/// Resamples a row-major `(height, width)` plane to `(new_height, new_width)`. All sizes are
/// at least 1.
pub(super) fn resize_plane(
    plane: &[f32],
    (height, width): (usize, usize),
    (new_height, new_width): (usize, usize),
) -> Vec<f32> {
    let (along_x, along_y) = (taps(width, new_width), taps(height, new_height));
    let rows: Vec<f32> = plane
        .chunks_exact(width)
        .flat_map(|row| {
            along_x
                .iter()
                .map(|(first, weights)| dot(&row[*first..], weights, 1))
        })
        .collect();
    along_y
        .iter()
        .flat_map(|(first, weights)| {
            let rows = &rows;
            (0..new_width).map(move |x| dot(&rows[first * new_width + x..], weights, new_width))
        })
        .collect()
}

/// `sum_k weights[k] * values[k * stride]`.
fn dot(values: &[f32], weights: &[f32], stride: usize) -> f32 {
    weights
        .iter()
        .enumerate()
        .map(|(k, w)| w * values[k * stride])
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_planes_stay_constant_at_any_ratio() {
        let plane = vec![0.3f32; 7 * 11];
        for size in [(1, 1), (3, 5), (7, 11), (10, 17), (20, 4)] {
            let out = resize_plane(&plane, (7, 11), size);
            assert_eq!(out.len(), size.0 * size.1);
            assert!(
                out.iter().all(|v| (v - 0.3).abs() < 1e-6),
                "{size:?}: {out:?}"
            );
        }
    }

    #[test]
    fn halving_is_the_two_by_two_mean_and_equal_size_is_identity() {
        let plane: Vec<f32> = (0..16).map(|i| i as f32).collect();
        assert_eq!(resize_plane(&plane, (4, 4), (4, 4)), plane);
        let half = resize_plane(&plane, (4, 4), (2, 2));
        assert_eq!(half, vec![2.5, 4.5, 10.5, 12.5]);
        // Non-integer shrink keeps the mean of a linear ramp along x.
        let ramp: Vec<f32> = (0..9).map(|i| i as f32).collect();
        let out = resize_plane(&ramp, (1, 9), (1, 4));
        assert!(
            (out.iter().sum::<f32>() / 4.0 - 4.0).abs() < 1e-5,
            "{out:?}"
        );
        // Enlarging interpolates between centres.
        assert_eq!(
            resize_plane(&[0.0, 1.0], (1, 2), (1, 4)),
            vec![0.0, 0.25, 0.75, 1.0]
        );
    }
}
