//! At which scale a run's generated scenes put matter out of place (issue 61: "at which scale do
//! stones first appear off the ring?"): 32 scenes drawn as `volgen eval` draws them, each
//! generated up to every 3D scale in turn from the same noise, scored by `misplaced_matter`
//! (2 kinds, reach 0.25, against a fit of the dataset's views, matter seen from above) and by
//! where that matter stands (inside the stones' ring, on it, beyond it). Used for
//! docs/journal/2026-12-arrangement.md.
//!
//! `cargo run --release -p research --example misplaced_by_scale -- DATASET RUN`

use candle_core::Device;
use rand::SeedableRng;
use research::{fit_of_views, mean_and_sd, misplaced_by_band, seen_points};
use rgbd_dataset::Dataset;
use scene_metrics::{MatterKinds, MatterSupport, MISPLACED_KINDS, MISPLACED_REACH};
use singrav::SinGrav;

const SCENES: usize = 32;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dataset, run] = args.as_slice() else {
        panic!("usage: misplaced_by_scale DATASET RUN");
    };
    let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
    let data = Dataset::load(dataset.as_ref(), model.config().rendering.background).unwrap();
    let fit = fit_of_views(model.config(), &data);
    let reference = seen_points(&fit);
    let kinds = MatterKinds::of(&reference, MISPLACED_KINDS, 0).unwrap();
    let support = MatterSupport::of(&reference, kinds, MISPLACED_REACH).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let scales = model.volume_scales();
    let noises: Vec<_> = (0..SCENES)
        .map(|_| model.draw_noise(scales, &mut rng).unwrap())
        .collect();
    println!("| scale | volume | out of place | at r < 0.4 (inside the ring) | 0.4 <= r < 0.8 (on it) | r >= 0.8 (beyond it) |");
    println!("|---|---|---|---|---|---|");
    for n in 1..=scales {
        let rows: Vec<[f64; 4]> = noises
            .iter()
            .map(|noise| {
                let raw = model.generate(&noise[..n]).unwrap().detach();
                let volume = model.to_physical(&raw).unwrap();
                let [inside, on, beyond] = misplaced_by_band(&support, &volume);
                [support.misplaced(&seen_points(&volume)), inside, on, beyond]
            })
            .collect();
        let mean = |c: usize| 100.0 * mean_and_sd(&rows.iter().map(|r| r[c]).collect::<Vec<_>>()).0;
        let size = model.config().pyramid.volume_sizes[n - 1];
        println!(
            "| {n} | {size}^3 | {:.2}% | {:.2}% | {:.2}% | {:.2}% |",
            mean(0),
            mean(1),
            mean(2),
            mean(3)
        );
    }
}
