//! How well the layout distance (`scene_metrics::layout_distance`) sees arrangement on the
//! stones scene: the distance from the scene's volume of other true layouts of the scene
//! (`StandingStones::new(1..=N)`), of a trained run's V*, and of its generated scenes, beside
//! the stones-only check of the arrangement issue (the share of grey matter inside the ring).
//! Used for docs/journal/2026-12-arrangement.md.
//!
//! `cargo run --release -p research --example layout_scores -- RUN DATASET [LAYOUTS] [SCENES]
//! [GRID] [PICTURE.png]` (defaults: 32 layouts, 32 scenes, grid 28; with PICTURE, a top-down
//! view of two true layouts, V* and six generated scenes). Each volume is scored against two
//! references, the seed-0 scene baked at GRID^3 and a direct fit of DATASET's views as `volgen
//! eval` makes it, with both weightings of its matter (opacity; seen from above).

use candle_core::Device;
use radiance_volume::GridDims;
use rand::SeedableRng;
use research::{fit_of_views, mean_and_sd, stone_shares};
use rgbd_dataset::scenes::{Scene, StandingStones};
use rgbd_dataset::Dataset;
use scene_metrics::{layout_distance, LayoutPoints, LayoutWeighting, LAYOUT_DIRECTIONS};
use singrav::SinGrav;

/// A straight-down view of `volume` on white, `(3, 96, 96)`.
fn top_down(volume: &radiance_volume::RadianceVolume) -> candle_core::Tensor {
    let size = 96;
    let camera = volrender::Camera::look_at(
        glam::Vec3::new(0.0, 0.0, 3.5),
        glam::Vec3::ZERO,
        glam::Vec3::Y,
        size,
        size,
        0.62,
    )
    .unwrap();
    let config = volrender::RenderConfig::default().with_background([1.0; 3]);
    let image = volrender::render_image(volume, &camera, &config).unwrap();
    let planes: Vec<f32> = (0..3)
        .flat_map(|c| image.rgb.iter().map(move |p| p[c]))
        .collect();
    candle_core::Tensor::from_vec(planes, (3, size, size), &Device::Cpu).unwrap()
}

/// `volume` with every colour 0: its matter by position alone.
fn colourless(volume: &radiance_volume::RadianceVolume) -> radiance_volume::RadianceVolume {
    let density = volume.tensor().narrow(0, 0, 1).unwrap();
    let black = density.zeros_like().unwrap().repeat((3, 1, 1, 1)).unwrap();
    volume
        .with_tensor(candle_core::Tensor::cat(&[&density, &black], 0).unwrap())
        .unwrap()
}

/// The two weightings compared, in column order.
const WEIGHTINGS: [LayoutWeighting; 2] = [LayoutWeighting::Opacity, LayoutWeighting::SeenFromAbove];

fn points(volume: &radiance_volume::RadianceVolume, weighting: LayoutWeighting) -> LayoutPoints {
    let voxel = 2.0 / volume.dims().xyz()[0] as f32;
    LayoutPoints::from_volume_weighted(volume.tensor(), voxel, weighting).unwrap()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: layout_scores RUN DATASET [LAYOUTS] [SCENES] [GRID]";
    let (run, dataset) = (args.first().expect(usage), args.get(1).expect(usage));
    let arg = |i: usize, default: usize| args.get(i).map_or(default, |a| a.parse().unwrap());
    let (layouts, scenes, grid) = (arg(2, 32), arg(3, 32), arg(4, 28));
    let dims = GridDims::cube(grid);
    let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
    let data = Dataset::load(dataset.as_ref(), model.config().rendering.background).unwrap();
    let fit = fit_of_views(model.config(), &data);
    let scene = StandingStones::new(0).to_volume(dims).unwrap();
    // (reference, weighting) pairs in column order, then the fit seen from above by position
    // alone (every colour set to 0).
    let mut references: Vec<(LayoutPoints, LayoutWeighting)> = [&scene, &fit]
        .iter()
        .flat_map(|volume| WEIGHTINGS.map(|w| (points(volume, w), w)))
        .collect();
    references.push((
        points(&colourless(&fit), LayoutWeighting::SeenFromAbove),
        LayoutWeighting::SeenFromAbove,
    ));
    let score = |volume: &radiance_volume::RadianceVolume| {
        let last = references.len() - 1;
        let distances: Vec<f64> = references
            .iter()
            .enumerate()
            .map(|(i, (reference, w))| {
                let own = if i == last {
                    points(&colourless(volume), *w)
                } else {
                    points(volume, *w)
                };
                layout_distance(reference, &own, LAYOUT_DIRECTIONS, 0).unwrap()
            })
            .collect();
        (distances, stone_shares(volume))
    };
    // The pooled matter of a set of volumes against each reference.
    let pooled_row = |name: &str, volumes: &[radiance_volume::RadianceVolume]| {
        let last = references.len() - 1;
        let cells: Vec<String> = references
            .iter()
            .enumerate()
            .map(|(i, (reference, w))| {
                let sets: Vec<LayoutPoints> = volumes
                    .iter()
                    .map(|v| {
                        if i == last {
                            points(&colourless(v), *w)
                        } else {
                            points(v, *w)
                        }
                    })
                    .collect();
                let pooled = LayoutPoints::pooled(&sets);
                format!(
                    "{:.4}",
                    layout_distance(reference, &pooled, LAYOUT_DIRECTIONS, 0).unwrap()
                )
            })
            .collect();
        println!(
            "| {name}, pooled | {} | {} | |",
            volumes.len(),
            cells.join(" | ")
        );
    };
    let row = |name: &str, scores: &[(Vec<f64>, (f64, f64))]| {
        let cells: Vec<String> = (0..references.len())
            .map(|c| {
                let (m, sd) = mean_and_sd(&scores.iter().map(|s| s.0[c]).collect::<Vec<_>>());
                format!("{m:.4} ± {sd:.4}")
            })
            .collect();
        let inside: Vec<f64> = scores.iter().map(|s| s.1 .0).collect();
        println!(
            "| {name} | {} | {} | {:.1}% |",
            scores.len(),
            cells.join(" | "),
            100.0 * mean_and_sd(&inside).0
        );
    };
    println!("| volumes | count | to the scene, opacity | to the scene, seen from above | to the fit, opacity | to the fit, seen from above | to the fit, seen from above, position only | stone matter inside the ring |");
    println!("|---|---|---|---|---|---|---|---|");
    row("the scene (seed 0)", &[score(&scene)]);
    row("its fit", &[score(&fit)]);
    let truth_volumes: Vec<_> = (1..=layouts as u64)
        .map(|seed| StandingStones::new(seed).to_volume(dims).unwrap())
        .collect();
    let truth: Vec<_> = truth_volumes.iter().map(score).collect();
    row("other layouts of the scene", &truth);
    pooled_row("other layouts of the scene", &truth_volumes);
    let v_star = model.to_physical(&model.reconstruct().unwrap()).unwrap();
    row("V*", &[score(&v_star)]);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let sample_volumes: Vec<_> = (0..scenes)
        .map(|_| {
            let raw = model.generate_random(&mut rng).unwrap();
            model.to_physical(&raw).unwrap()
        })
        .collect();
    let samples: Vec<_> = sample_volumes.iter().map(score).collect();
    row("generated scenes", &samples);
    pooled_row("generated scenes", &sample_volumes);
    if let Some(picture) = args.get(5) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut views: Vec<_> = [1, 2]
            .iter()
            .map(|&seed| top_down(&StandingStones::new(seed).to_volume(dims).unwrap()))
            .collect();
        views.push(top_down(&v_star));
        for _ in 0..6 {
            let raw = model.generate_random(&mut rng).unwrap();
            views.push(top_down(&model.to_physical(&raw).unwrap()));
        }
        singrav::picture::write_grid(picture.as_ref(), &[views]).unwrap();
        println!("top-down views (layouts 1 and 2, V*, six scenes) -> {picture}");
    }
}
