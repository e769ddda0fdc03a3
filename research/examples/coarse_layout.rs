//! Where the stones scene's arrangement is lost, one suspect at a time: trains the first SCALES
//! scales of `tiny` (with `--set` changes) at several seeds, then scores random volumes of the
//! last trained scale against the scene baked at that size: the layout distance, the layout
//! distance between samples (their spread of arrangements), the stones-only share of grey
//! matter inside the ring, and the share of all matter out of place (`misplaced_matter`, seen
//! from above against the baked scene, as `volgen eval` takes it against a fit); the other true
//! layouts of the scene are the reference row. Used for docs/journal/2026-12-arrangement.md.
//!
//! `cargo run --release -p research --example coarse_layout -- DATASET OUT SCALES SEEDS
//! [path=value ...]` (SEEDS: comma-separated training seeds; OUT gets a run per seed).

use std::path::Path;

use candle_core::Device;
use radiance_volume::{GridDims, RadianceVolume};
use rand::SeedableRng;
use research::{seen_points, stone_shares};
use rgbd_dataset::scenes::{Scene, StandingStones};
use rgbd_dataset::{Dataset, LoadOptions};
use scene_metrics::{
    layout_distance, LayoutPoints, MatterKinds, MatterSupport, LAYOUT_DIRECTIONS, MISPLACED_KINDS,
    MISPLACED_REACH,
};
use singrav::train::{Control, RunOptions, Trainer};
use singrav::{SinGrav, TrainConfig};

/// Random volumes scored per run, and how many of them enter the pairwise spread.
const SCENES: usize = 32;
const SPREAD_SCENES: usize = 12;

fn points(volume: &RadianceVolume) -> LayoutPoints {
    let voxel = 2.0 / volume.dims().xyz()[0] as f32;
    LayoutPoints::from_volume(volume.tensor(), voxel).unwrap()
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// (layout distance to the scene, pairwise layout distance, share inside the ring, share out of
/// place) of `volumes`.
fn scores(
    reference: &LayoutPoints,
    support: &MatterSupport,
    volumes: &[RadianceVolume],
) -> (f64, f64, f64, f64) {
    let clouds: Vec<LayoutPoints> = volumes.iter().map(points).collect();
    let distance =
        |a: &LayoutPoints, b: &LayoutPoints| layout_distance(a, b, LAYOUT_DIRECTIONS, 0).unwrap();
    let to_scene: Vec<f64> = clouds.iter().map(|c| distance(reference, c)).collect();
    let spread_count = clouds.len().min(SPREAD_SCENES);
    let mut pairs = Vec::new();
    for i in 0..spread_count {
        for j in i + 1..spread_count {
            pairs.push(distance(&clouds[i], &clouds[j]));
        }
    }
    let inside: Vec<f64> = volumes.iter().map(|v| stone_shares(v).0).collect();
    let misplaced: Vec<f64> = volumes
        .iter()
        .map(|v| support.misplaced(&seen_points(v)))
        .collect();
    (
        mean(&to_scene),
        mean(&pairs),
        mean(&inside),
        mean(&misplaced),
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dataset, out, scales, seeds, settings @ ..] = args.as_slice() else {
        panic!("usage: coarse_layout DATASET OUT SCALES SEEDS [path=value ...]");
    };
    singrav::runtime::init(&singrav::runtime::RuntimeOptions::default()).unwrap();
    let scales: usize = scales.parse().unwrap();
    let mut base = TrainConfig::preset("tiny").unwrap();
    for setting in settings {
        let (path, value) = setting.split_once('=').expect("settings are path=value");
        base = base.with_setting(path, value).unwrap();
    }
    let options = LoadOptions {
        background: base.rendering.background,
        depth_kind: None,
    };
    let dataset = Dataset::load_with(Path::new(dataset), &options).unwrap();
    let size = base.pyramid.volume_sizes[scales - 1];
    let dims = GridDims::cube(size);
    let scene = StandingStones::new(0).to_volume(dims).unwrap();
    let reference = points(&scene);
    let seen = seen_points(&scene);
    let kinds = MatterKinds::of(&seen, MISPLACED_KINDS, 0).unwrap();
    let support = MatterSupport::of(&seen, kinds, MISPLACED_REACH).unwrap();
    let family: Vec<RadianceVolume> = (1..=SCENES as u64)
        .map(|seed| StandingStones::new(seed).to_volume(dims).unwrap())
        .collect();
    let (d, spread, inside, misplaced) = scores(&reference, &support, &family);
    println!("settings: {settings:?}, scales {scales} ({size}^3)");
    println!("| run | to the scene | between samples | inside the ring | out of place | V* to the scene | to V* | seconds |");
    println!("|---|---|---|---|---|---|---|---|");
    println!(
        "| true layouts | {d:.4} | {spread:.4} | {:.1}% | {:.2}% | | | |",
        100.0 * inside,
        100.0 * misplaced
    );
    let mut rows = Vec::new();
    for seed in seeds.split(',') {
        let mut config = base.clone();
        config.run.seed = seed.parse().unwrap();
        config.run.checkpoint_seconds = 0;
        let run_dir = Path::new(out).join(format!("seed_{seed}"));
        let _ = std::fs::remove_dir_all(&run_dir);
        let run_options = RunOptions::default();
        let started = std::time::Instant::now();
        let mut trainer =
            Trainer::new(&config, &dataset, &run_dir, &run_options, &Device::Cpu).unwrap();
        for _ in 0..scales {
            assert_eq!(
                trainer.train_scale(&mut |_| Control::Continue).unwrap(),
                Control::Continue
            );
        }
        let seconds = started.elapsed().as_secs_f64();
        drop(trainer);
        let (model, _) = SinGrav::load(&run_dir, &Device::Cpu).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let volumes: Vec<RadianceVolume> = (0..SCENES)
            .map(|_| {
                let raw = model.generate_random(&mut rng).unwrap();
                model.to_physical(&raw).unwrap()
            })
            .collect();
        let v_star = model.to_physical(&model.reconstruct().unwrap()).unwrap();
        let (d, spread, inside, misplaced) = scores(&reference, &support, &volumes);
        let (v, _, v_inside, v_out) = scores(&reference, &support, std::slice::from_ref(&v_star));
        let (to_v, ..) = scores(&points(&v_star), &support, &volumes);
        println!(
            "| seed {seed} | {d:.4} | {spread:.4} | {:.1}% | {:.2}% | {v:.4} ({:.1}% inside, {:.2}% out of place) | {to_v:.4} | {seconds:.0} |",
            100.0 * inside,
            100.0 * misplaced,
            100.0 * v_inside,
            100.0 * v_out
        );
        rows.push((d, spread, inside, misplaced, v, to_v));
    }
    type Row = (f64, f64, f64, f64, f64, f64);
    let column = |f: fn(&Row) -> f64| mean(&rows.iter().map(f).collect::<Vec<_>>());
    println!(
        "| mean | {:.4} | {:.4} | {:.1}% | {:.2}% | {:.4} | {:.4} | |",
        column(|r| r.0),
        column(|r| r.1),
        100.0 * column(|r| r.2),
        100.0 * column(|r| r.3),
        column(|r| r.4),
        column(|r| r.5)
    );
}
