//! At which scale a run's generated scenes leave the scene's layout: 16 scenes drawn as `volgen
//! eval` draws them, each generated up to every 3D scale in turn from the same noise, scored by
//! the layout distance and the layout distance by position (matter seen from above, against a
//! fit of the dataset's views, as `volgen eval` scores them), beside the reconstruction V* up to
//! the same scale. Used for docs/journal/2026-12-hd.md (issue 82: seed 2's layout).
//!
//! `cargo run --release -p research --example layout_by_scale -- DATASET RUN [FIT]`: the fit at
//! FIT^3 (default: the finest 3D scale's size, as `volgen eval` fits it; at `hd`'s 126^3 its
//! matter makes every distance several times slower than at the run's own fit size, 45).

use candle_core::Device;
use rand::SeedableRng;
use research::{fit_of_views, mean_and_sd, seen_points};
use rgbd_dataset::Dataset;
use scene_metrics::{layout_distance, layout_distance_by_position, LAYOUT_DIRECTIONS};
use singrav::SinGrav;

const SCENES: usize = 16;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (dataset, run, fit_size) = match args.as_slice() {
        [dataset, run] => (dataset, run, None),
        [dataset, run, size] => (
            dataset,
            run,
            Some(size.parse().expect("FIT: a volume edge")),
        ),
        _ => panic!("usage: layout_by_scale DATASET RUN [FIT]"),
    };
    let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
    let data = Dataset::load(dataset.as_ref(), model.config().rendering.background).unwrap();
    // `fit_of_views` fits at the run's own fit size; without FIT at the finest 3D scale instead,
    // as `volgen eval` fits it.
    let config = model
        .config()
        .clone()
        .with(|c| c.pyramid.fit_size = fit_size);
    let reference = seen_points(&fit_of_views(&config, &data));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let scales = model.volume_scales();
    let noises: Vec<_> = (0..SCENES)
        .map(|_| model.draw_noise(scales, &mut rng).unwrap())
        .collect();
    let scores = |noise: &[candle_core::Tensor]| {
        let raw = model.generate(noise).unwrap().detach();
        let points = seen_points(&model.to_physical(&raw).unwrap());
        [
            layout_distance(&reference, &points, LAYOUT_DIRECTIONS, 0).unwrap(),
            layout_distance_by_position(&reference, &points, LAYOUT_DIRECTIONS, 0).unwrap(),
        ]
    };
    let reconstruction = model.reconstruction_noise(scales).unwrap();
    println!("| scale | volume | layout distance | by position | V* layout | V* by position |");
    println!("|---|---|---|---|---|---|");
    for n in 1..=scales {
        let rows: Vec<[f64; 2]> = noises.iter().map(|noise| scores(&noise[..n])).collect();
        let mean = |c: usize| mean_and_sd(&rows.iter().map(|r| r[c]).collect::<Vec<_>>()).0;
        let vstar = scores(&reconstruction[..n]);
        let size = model.config().pyramid.volume_sizes[n - 1];
        println!(
            "| {n} | {size}^3 | {:.4} | {:.4} | {:.4} | {:.4} |",
            mean(0),
            mean(1),
            vstar[0],
            vstar[1]
        );
    }
}
