//! Objects (`scene_metrics::Objects`) of a run's scene, reconstruction and samples: the built-in
//! scene's own layout baked at several grids (the truth), a fit of the views (the run's fitted
//! volume when it has one), V* and generated scenes; per volume the number of objects, their
//! volumes and the largest one's share of all object matter. For the stones, the samples' share
//! of stone matter inside the ring too (`research::stone_shares`, without the fit `layout_scores`
//! makes). Used for docs/journal/2026-12-hd.md.
//!
//! `cargo run --release -p research --example object_counts -- RUN DATASET [SCENES]`
//! (default 32 scenes, drawn as `volgen eval`'s seed 0 draws them)

use candle_core::Device;
use radiance_volume::{GridDims, RadianceVolume};
use rand::SeedableRng;
use research::{crumb_volume, largest_volumes, objects};
use rgbd_dataset::Dataset;
use scene_metrics::Objects;
use singrav::SinGrav;

fn describe(name: &str, found: &Objects, min_volume: f64) {
    println!(
        "{name:>14}: {:>3} objects ({:>3} with crumbs), largest share {:.3}; volumes (1e-3 box) {}",
        found.count(min_volume),
        found.count(0.0),
        found.largest_share(),
        largest_volumes(found, 14)
    );
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: object_counts RUN DATASET [SCENES]";
    let (run, dataset) = (args.first().expect(usage), args.get(1).expect(usage));
    let scenes: usize = args.get(2).map_or(32, |a| a.parse().unwrap());
    let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
    let data = Dataset::load(dataset.as_ref(), model.config().rendering.background).unwrap();
    let finest = *model.config().pyramid.volume_sizes.last().unwrap();
    let source = data.scene_source();
    let mut grids = vec![finest];
    for grid in [28, 57, 126] {
        if !grids.contains(&grid) {
            grids.push(grid);
        }
    }
    let truth = source.map(|source| {
        let scene = source.kind.build(source.seed);
        for &grid in &grids {
            let baked = scene.to_volume(GridDims::cube(grid)).unwrap();
            describe(&format!("truth {grid}^3"), &objects(&baked), 0.0);
        }
        objects(&scene.to_volume(GridDims::cube(finest)).unwrap())
    });
    let min_volume = crumb_volume(truth.as_ref());
    println!("min volume {:.3}e-3 of the box", min_volume * 1e3);
    let fitted = std::path::Path::new(run).join("fitted.safetensors");
    if fitted.exists() {
        let fit = RadianceVolume::load_safetensors(&fitted).unwrap();
        let fit = fit.resample(GridDims::cube(finest)).unwrap();
        describe("fit", &objects(&fit), min_volume);
    }
    let v_star = model.to_physical(&model.reconstruct().unwrap()).unwrap();
    describe("V*", &objects(&v_star), min_volume);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let stones = source.is_some_and(|s| s.kind.name() == "stones");
    let (mut counts, mut shares, mut inside) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..scenes {
        let raw = model.generate_random_from(&mut rng, 1).unwrap();
        let volume = model.to_physical(&raw).unwrap();
        let found = objects(&volume);
        describe(&format!("sample {i}"), &found, min_volume);
        counts.push(found.count(min_volume) as f64);
        shares.push(found.largest_share());
        if stones {
            inside.push(research::stone_shares(&volume).0);
        }
    }
    if stones {
        let (mean, sd) = research::mean_and_sd(&inside);
        println!(
            "stone matter inside the ring: {:.2}% (sd {:.2}%)",
            100.0 * mean,
            100.0 * sd
        );
    }
    let (count, count_sd) = research::mean_and_sd(&counts);
    let (share, _) = research::mean_and_sd(&shares);
    let most = shares.iter().copied().fold(0.0, f64::max);
    println!(
        "samples: {count:.2} objects (sd {count_sd:.2}), largest share {share:.3} (at most {most:.3}){}",
        truth.map_or(String::new(), |t| format!(
            "; truth {} objects, largest share {:.3}",
            t.count(0.0),
            t.largest_share()
        ))
    );
}
