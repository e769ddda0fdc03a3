//! volgen's research programs, one example each (`research/examples/`): the measurements that
//! docs/journal/ records, kept runnable so an entry can be re-run
//! (`cargo run --release -p research --example NAME`). Nothing here is a library API: this
//! file holds what several programs share.

/// Grey matter (stone colour: low chroma, not dark soil) by distance from the vertical axis:
/// the share inside the ring (r < 0.4) and on it (0.45 < r < 0.8). The stones scene's own
/// check of the arrangement issue, which the library's metrics need no knowledge of.
pub fn stone_shares(volume: &radiance_volume::RadianceVolume) -> (f64, f64) {
    let n = volume.dims().xyz()[0];
    let voxel = 2.0 / n as f64;
    let values: Vec<f32> = volume.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let cells = n * n * n;
    let (mut inside, mut ring, mut total) = (0.0, 0.0, 0.0);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let i = (z * n + y) * n + x;
                let opacity = 1.0 - (-f64::from(values[i]) * voxel).exp();
                let rgb = [1, 2, 3].map(|c| values[c * cells + i]);
                let chroma = rgb.iter().copied().fold(f32::MIN, f32::max)
                    - rgb.iter().copied().fold(f32::MAX, f32::min);
                let bright = rgb.iter().sum::<f32>() / 3.0;
                if opacity < 1e-3 || chroma > 0.12 || bright < 0.25 {
                    continue;
                }
                let centre = |i: usize| (2.0 * (i as f64 + 0.5) / n as f64) - 1.0;
                let r = centre(x).hypot(centre(y));
                total += opacity;
                if r < 0.4 {
                    inside += opacity;
                } else if (0.45..0.8).contains(&r) {
                    ring += opacity;
                }
            }
        }
    }
    (inside / total.max(1e-12), ring / total.max(1e-12))
}

/// The mean and the (population) standard deviation of `values`.
pub fn mean_and_sd(values: &[f64]) -> (f64, f64) {
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64;
    (mean, var.sqrt())
}
