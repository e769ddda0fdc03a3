//! volgen's research programs, one example each (`research/examples/`): the measurements that
//! docs/journal/ records, kept runnable so an entry can be re-run
//! (`cargo run --release -p research --example NAME`). Nothing here is a library API: this
//! file holds what several programs share.

pub mod capture;

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

/// The objects (`scene_metrics::Objects`, the default rule) of a physical volume, with its
/// voxel edge in box units: what `object_counts` and `objects_by_scale` count.
pub fn objects(volume: &radiance_volume::RadianceVolume) -> scene_metrics::Objects {
    let voxel = volume.aabb().size().x / volume.dims().xyz()[0] as f32;
    scene_metrics::Objects::of(
        volume.tensor(),
        voxel,
        &scene_metrics::ObjectRule::default(),
    )
    .unwrap()
}

/// The crumb threshold of `object_counts` and `objects_by_scale`: objects below a fifth of the
/// truth's median object are not counted (0 without a truth: every object counts).
pub fn crumb_volume(truth: Option<&scene_metrics::Objects>) -> f64 {
    truth
        .and_then(|t| t.median_volume(0.0))
        .map_or(0.0, |median| 0.2 * median)
}

/// The `count` largest objects' volumes in thousandths of the box, as both programs print them.
pub fn largest_volumes(found: &scene_metrics::Objects, count: usize) -> String {
    let volumes: Vec<String> = found
        .all()
        .iter()
        .take(count)
        .map(|o| format!("{:.2}", o.volume * 1e3))
        .collect();
    volumes.join(" ")
}

/// The mean and the (population) standard deviation of `values`.
pub fn mean_and_sd(values: &[f64]) -> (f64, f64) {
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64;
    (mean, var.sqrt())
}

/// A volume's matter as `volgen eval` weighs it for the layout distance and
/// `misplaced_matter`: each voxel's opacity times the transmittance above it.
pub fn seen_points(volume: &radiance_volume::RadianceVolume) -> scene_metrics::LayoutPoints {
    let voxel = volume.aabb().size().x / volume.dims().xyz()[0] as f32;
    scene_metrics::LayoutPoints::from_volume_weighted(
        volume.tensor(),
        voxel,
        scene_metrics::LayoutWeighting::SeenFromAbove,
    )
    .unwrap()
}

/// Where a volume's matter out of place stands: its share of all the volume's matter in the
/// columns inside the stones' ring (r < 0.4, r the distance from the box's vertical axis,
/// normalised box), on it (0.4 <= r < 0.8) and beyond it (r >= 0.8).
pub fn misplaced_by_band(
    support: &scene_metrics::MatterSupport,
    volume: &radiance_volume::RadianceVolume,
) -> [f64; 3] {
    let total = seen_weight(volume);
    [(0.0, 0.4), (0.4, 0.8), (0.8, 9.0)].map(|(from, to)| {
        let band = columns_between(volume, from, to);
        let weight = seen_weight(&band);
        if weight > 0.0 {
            support.misplaced(&seen_points(&band)) * weight / total
        } else {
            0.0
        }
    })
}

/// The total seen-from-above weight (opacity times the transmittance above) of a volume's
/// voxels, before `LayoutPoints` normalises it.
fn seen_weight(volume: &radiance_volume::RadianceVolume) -> f64 {
    let [w, h, d] = volume.dims().xyz();
    let voxel = f64::from(volume.aabb().size().x) / w as f64;
    let sigma: Vec<f32> = volume
        .tensor()
        .get(0)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    let mut total = 0.0;
    for column in 0..h * w {
        let mut above = 1.0;
        for z in (0..d).rev() {
            let opacity = 1.0 - (-f64::from(sigma[z * h * w + column]) * voxel).exp();
            total += opacity * above;
            above *= 1.0 - opacity;
        }
    }
    total
}

/// `volume` with the density of every column whose axis lies outside `from <= r < to` (r the
/// distance from the box's vertical axis, normalised box) set to 0: whole columns, so the
/// weights seen from above of the columns kept are unchanged.
fn columns_between(
    volume: &radiance_volume::RadianceVolume,
    from: f64,
    to: f64,
) -> radiance_volume::RadianceVolume {
    let [w, h, d] = volume.dims().xyz();
    let mut values: Vec<f32> = volume.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let centre = |i: usize, n: usize| 2.0 * (i as f64 + 0.5) / n as f64 - 1.0;
    for z in 0..d {
        for y in 0..h {
            for x in 0..w {
                let r = centre(x, w).hypot(centre(y, h));
                if !(from..to).contains(&r) {
                    values[(z * h + y) * w + x] = 0.0;
                }
            }
        }
    }
    let tensor =
        candle_core::Tensor::from_vec(values, volume.tensor().dims(), &candle_core::Device::Cpu)
            .unwrap();
    volume.with_tensor(tensor).unwrap()
}

/// A direct fit of the dataset's views, made as training makes the 3D critic's, with `config`.
/// `volgen eval` scores layouts against this fit at the finest 3D scale's size: the same volume
/// for a run whose `pyramid.fit_size` is unset, a coarser one for `hd` (45^3) unless the caller
/// clears it (as `layout_by_scale` does by default).
pub fn fit_of_views(
    config: &singrav::TrainConfig,
    data: &rgbd_dataset::Dataset,
) -> radiance_volume::RadianceVolume {
    singrav::train::fit_training_target(config, data, None, &mut |_| {})
        .unwrap()
        .volume
}
