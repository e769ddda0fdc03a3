//! How well the layout distance (`scene_metrics::layout_distance`) sees arrangement on the
//! stones scene: the distance from the scene's volume of other true layouts of the scene
//! (`StandingStones::new(1..=N)`), of a trained run's V*, and of its generated scenes, beside
//! the stones-only check of the arrangement issue (the share of grey matter inside the ring).
//! Used for docs/journal/2026-12-arrangement.md.
//!
//! `cargo run --release -p research --example layout_scores -- RUN [LAYOUTS] [SCENES] [GRID]`
//! (defaults: 32 layouts, 32 scenes, grid 28; the reference is the seed-0 scene baked at GRID^3,
//! as a fit of its views would see it at the model's resolution).

use candle_core::Device;
use radiance_volume::GridDims;
use rand::SeedableRng;
use rgbd_dataset::scenes::{Scene, StandingStones};
use scene_metrics::{layout_distance, LayoutPoints, LAYOUT_DIRECTIONS};
use singrav::SinGrav;

/// Grey matter (stone colour: low chroma, not dark soil) by distance from the vertical axis:
/// the share inside the ring (r < 0.4) and on it (0.45 < r < 0.8).
fn stone_shares(volume: &radiance_volume::RadianceVolume) -> (f64, f64) {
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

fn points(volume: &radiance_volume::RadianceVolume) -> LayoutPoints {
    let voxel = 2.0 / volume.dims().xyz()[0] as f32;
    LayoutPoints::from_volume(volume.tensor(), voxel).unwrap()
}

/// Mean and standard deviation.
fn stats(values: &[f64]) -> (f64, f64) {
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64;
    (mean, var.sqrt())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let run = args
        .first()
        .expect("usage: layout_scores RUN [LAYOUTS] [SCENES] [GRID]");
    let arg = |i: usize, default: usize| args.get(i).map_or(default, |a| a.parse().unwrap());
    let (layouts, scenes, grid) = (arg(1, 32), arg(2, 32), arg(3, 28));
    let dims = GridDims::cube(grid);
    let scene = StandingStones::new(0).to_volume(dims).unwrap();
    let reference = points(&scene);
    let score = |volume: &radiance_volume::RadianceVolume| {
        let distance = layout_distance(&reference, &points(volume), LAYOUT_DIRECTIONS, 0).unwrap();
        let (inside, ring) = stone_shares(volume);
        (distance, inside, ring)
    };
    let row = |name: &str, scores: &[(f64, f64, f64)]| {
        let d: Vec<f64> = scores.iter().map(|s| s.0).collect();
        let inside: Vec<f64> = scores.iter().map(|s| s.1).collect();
        let ring: Vec<f64> = scores.iter().map(|s| s.2).collect();
        let (dm, ds) = stats(&d);
        println!(
            "| {name} | {} | {dm:.4} ± {ds:.4} | {:.1}% | {:.1}% |",
            scores.len(),
            100.0 * stats(&ring).0,
            100.0 * stats(&inside).0
        );
    };
    println!("| volumes | count | layout distance (mean ± s.d.) | stone matter on the ring | inside the ring |");
    println!("|---|---|---|---|---|");
    row("the scene (seed 0)", &[score(&scene)]);
    let truth: Vec<_> = (1..=layouts as u64)
        .map(|seed| score(&StandingStones::new(seed).to_volume(dims).unwrap()))
        .collect();
    row("other layouts of the scene", &truth);
    let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
    let v_star = model.to_physical(&model.reconstruct().unwrap()).unwrap();
    row("V*", &[score(&v_star)]);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let samples: Vec<_> = (0..scenes)
        .map(|_| {
            let raw = model.generate_random(&mut rng).unwrap();
            score(&model.to_physical(&raw).unwrap())
        })
        .collect();
    row("generated scenes", &samples);
}
