//! Where a sample's objects join: for chosen samples of a run (drawn as `object_counts` and
//! `volgen eval`'s seed 0 draw them), the objects (`scene_metrics::Objects`) of the volume
//! after every 3D scale, beside the built-in scene's own layout baked at that scale's grid.
//! Two stones that one scale joins show as one object fewer and a larger largest share from
//! that scale on. Used for docs/journal/2026-12-hd.md.
//!
//! `cargo run --release -p research --example objects_by_scale -- RUN DATASET SAMPLE[,SAMPLE..]`

use candle_core::Device;
use radiance_volume::GridDims;
use rand::SeedableRng;
use research::{crumb_volume, largest_volumes, objects};
use rgbd_dataset::Dataset;
use scene_metrics::Objects;
use singrav::SinGrav;

/// Objects at least `min_volume`, the largest share and the three largest volumes (1e-3 box).
fn describe(found: &Objects, min_volume: f64) -> String {
    format!(
        "{:>2} objects, largest share {:.3} (largest {})",
        found.count(min_volume),
        found.largest_share(),
        largest_volumes(found, 3)
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: objects_by_scale RUN DATASET SAMPLE[,SAMPLE..]";
    let (run, dataset) = (args.first().expect(usage), args.get(1).expect(usage));
    let chosen: Vec<usize> = args
        .get(2)
        .expect(usage)
        .split(',')
        .map(|s| s.parse().expect("a sample index"))
        .collect();
    let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
    let data = Dataset::load(dataset.as_ref(), model.config().rendering.background).unwrap();
    let scene = data
        .scene_source()
        .map(|source| source.kind.build(source.seed));
    let sizes = model.config().pyramid.volume_sizes.clone();
    // Crumbs as `object_counts` counts them, against the truth at the finest grid.
    let truth = scene.as_ref().map(|scene| {
        objects(
            &scene
                .to_volume(GridDims::cube(*sizes.last().unwrap()))
                .unwrap(),
        )
    });
    let min_volume = crumb_volume(truth.as_ref());
    if let Some(scene) = &scene {
        for &size in &sizes {
            let baked = scene.to_volume(GridDims::cube(size)).unwrap();
            println!(
                "truth {size:>3}^3: {}",
                describe(&objects(&baked), min_volume)
            );
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let last = *chosen.iter().max().expect(usage);
    for i in 0..=last {
        let noise = model.draw_noise(sizes.len(), &mut rng).unwrap();
        if !chosen.contains(&i) {
            continue;
        }
        for (k, size) in sizes.iter().enumerate() {
            let raw = model.generate(&noise[..=k]).unwrap().detach();
            let volume = model.to_physical(&raw).unwrap();
            println!(
                "sample {i} scale {} ({size:>3}^3): {}",
                k + 1,
                describe(&objects(&volume), min_volume)
            );
        }
    }
}
