//! Which arrangement distance sees arrangement, on any built-in scene: the layout distance of
//! all matter (`scene_metrics::layout_distance`) beside the distance by kind of matter
//! (`scene_metrics::kind_layout_distance`) for several numbers of kinds, each measured as
//! `volgen eval` measures (seen from above, against a direct fit of the dataset's views), for
//! other true layouts of the dataset's built-in scene, the run's V* and its generated scenes.
//! For the stones, the share of stone matter inside the ring beside them. Used for
//! docs/journal/2026-12-arrangement.md.
//!
//! `cargo run --release -p research --example kind_scores -- RUN DATASET [LAYOUTS] [SCENES]`
//! (defaults: 32 layouts, 32 scenes; the scenes drawn as `volgen eval`'s seed 0 draws them).

use candle_core::Device;
use radiance_volume::{GridDims, RadianceVolume};
use rand::SeedableRng;
use research::{fit_of_views, mean_and_sd, stone_shares};
use rgbd_dataset::Dataset;
use scene_metrics::{
    kind_layout_distance, kind_layout_distances, layout_distance, LayoutPoints, LayoutWeighting,
    MatterKinds, LAYOUT_DIRECTIONS,
};
use singrav::SinGrav;

/// The numbers of kinds compared, in column order.
const KINDS: [usize; 5] = [1, 2, 3, 4, 6];

fn points(volume: &RadianceVolume) -> LayoutPoints {
    let voxel = volume.aabb().size().x / volume.dims().xyz()[0] as f32;
    LayoutPoints::from_volume_weighted(volume.tensor(), voxel, LayoutWeighting::SeenFromAbove)
        .unwrap()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: kind_scores RUN DATASET [LAYOUTS] [SCENES]";
    let (run, dataset) = (args.first().expect(usage), args.get(1).expect(usage));
    let arg = |i: usize, default: usize| args.get(i).map_or(default, |a| a.parse().unwrap());
    let (layouts, scenes) = (arg(2, 32), arg(3, 32));
    let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
    let data = Dataset::load(dataset.as_ref(), model.config().rendering.background).unwrap();
    let source = data
        .scene_source()
        .expect("a dataset of a built-in scene (volgen scene)");
    let fit = fit_of_views(model.config(), &data);
    let reference = points(&fit);
    let kinds: Vec<MatterKinds> = KINDS
        .iter()
        .map(|&k| MatterKinds::of(&reference, k, 0).unwrap())
        .collect();
    for (k, found) in KINDS.iter().zip(&kinds) {
        let colours: Vec<String> = found
            .colours()
            .iter()
            .map(|c| format!("({:.2}, {:.2}, {:.2})", c[0], c[1], c[2]))
            .collect();
        println!("{k} kinds: {}", colours.join(" "));
    }
    let stones = source.kind.name() == "stones";
    // Per volume: the all-matter distance, then one per number of kinds, then inside the ring.
    let score = |volume: &RadianceVolume| {
        let own = points(volume);
        let mut row = vec![layout_distance(&reference, &own, LAYOUT_DIRECTIONS, 0).unwrap()];
        for found in &kinds {
            row.push(kind_layout_distance(&reference, &own, found, LAYOUT_DIRECTIONS, 0).unwrap());
        }
        let (inside, ring) = if stones {
            stone_shares(volume)
        } else {
            (0.0, 0.0)
        };
        row.push(inside);
        row.push(ring);
        // The 2 kinds' own distances.
        row.extend(
            kind_layout_distances(&reference, &own, &kinds[1], LAYOUT_DIRECTIONS, 0).unwrap(),
        );
        row
    };
    // The matter of a set of volumes pooled (each volume weighing alike) against the fit.
    let pooled = |volumes: &[RadianceVolume]| {
        let sets: Vec<LayoutPoints> = volumes.iter().map(points).collect();
        let all = LayoutPoints::pooled(&sets);
        let mut row = vec![layout_distance(&reference, &all, LAYOUT_DIRECTIONS, 0).unwrap()];
        for found in &kinds {
            row.push(kind_layout_distance(&reference, &all, found, LAYOUT_DIRECTIONS, 0).unwrap());
        }
        row.extend([0.0; 4]);
        row
    };
    let mut table: Vec<(String, Vec<Vec<f64>>)> = Vec::new();
    let grid = *model.config().pyramid.volume_sizes.last().unwrap();
    let family_volumes: Vec<RadianceVolume> = source
        .family_seeds(layouts)
        .map(|seed| {
            source
                .kind
                .build(seed)
                .to_volume(GridDims::cube(grid))
                .unwrap()
        })
        .collect();
    let family: Vec<Vec<f64>> = family_volumes.iter().map(score).collect();
    table.push((format!("family: {layouts} other layouts"), family));
    table.push(("family, pooled".into(), vec![pooled(&family_volumes)]));
    let v_star = model.to_physical(&model.reconstruct().unwrap()).unwrap();
    table.push(("V*".into(), vec![score(&v_star)]));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let sample_volumes: Vec<RadianceVolume> = (0..scenes)
        .map(|_| {
            let raw = model.generate_random(&mut rng).unwrap();
            model.to_physical(&raw).unwrap()
        })
        .collect();
    let samples: Vec<Vec<f64>> = sample_volumes.iter().map(score).collect();
    table.push((format!("{scenes} generated scenes"), samples));
    table.push(("generated, pooled".into(), vec![pooled(&sample_volumes)]));
    let kind_columns: Vec<String> = KINDS.iter().map(|k| format!("by kind, {k}")).collect();
    println!(
        "| {} | volumes | all matter | {} | stone matter inside the ring |",
        source.kind.name(),
        kind_columns.join(" | ")
    );
    println!("|---|---|---|{}---|", "---|".repeat(KINDS.len()));
    let columns = KINDS.len() + 1;
    let family_means: Vec<f64> = (0..columns)
        .map(|c| mean_and_sd(&table[0].1.iter().map(|r| r[c]).collect::<Vec<_>>()).0)
        .collect();
    for (name, rows) in &table {
        let cells: Vec<String> = (0..columns)
            .map(|c| {
                let (m, sd) = mean_and_sd(&rows.iter().map(|r| r[c]).collect::<Vec<_>>());
                format!("{m:.4} ± {sd:.4} ({:.2}x)", m / family_means[c])
            })
            .collect();
        let inside = mean_and_sd(&rows.iter().map(|r| r[columns]).collect::<Vec<_>>()).0;
        let mean = |c: usize| mean_and_sd(&rows.iter().map(|r| r[c]).collect::<Vec<_>>()).0;
        let inside = if stones {
            format!(
                "{:.1}% (ring {:.1}%)",
                100.0 * inside,
                100.0 * mean(columns + 1)
            )
        } else {
            String::new()
        };
        let inside = format!(
            "{inside} | 2 kinds apart: {:.4} {:.4}",
            mean(columns + 2),
            mean(columns + 3)
        );
        println!(
            "| {name} | {} | {} | {inside} |",
            rows.len(),
            cells.join(" | ")
        );
    }
}
