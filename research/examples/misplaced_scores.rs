//! Whether matter out of place (`scene_metrics::MatterSupport`) sees arrangement, on any
//! built-in scene, and at which reach and number of kinds: for other true layouts of the
//! dataset's built-in scene, and for each run's V* and generated scenes, the share of matter
//! standing where the scene (a direct fit of the dataset's views, seen from above, as `volgen
//! eval` measures) has none of its kind within the reach; all matter together, and the mean
//! over kinds of each kind's own share. For the stones, the share of stone matter inside the
//! ring beside them. Used for docs/journal/2026-12-arrangement.md.
//!
//! `cargo run --release -p research --example misplaced_scores -- DATASET RUN [RUN ...]`
//! (32 layouts, 32 scenes drawn as `volgen eval`'s seed 0 draws them; the first run's
//! configuration makes the fit).

use candle_core::Device;
use radiance_volume::{GridDims, RadianceVolume};
use rand::SeedableRng;
use research::{fit_of_views, mean_and_sd, misplaced_by_band, seen_points, stone_shares};
use rgbd_dataset::Dataset;
use scene_metrics::{MatterKinds, MatterSupport};
use singrav::SinGrav;

/// Numbers of kinds compared.
const KINDS: [usize; 3] = [2, 3, 4];
/// Reaches compared, in the normalised box.
const REACHES: [f64; 4] = [0.125, 0.1875, 0.25, 0.375];
const LAYOUTS: usize = 32;
const SCENES: usize = 32;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: misplaced_scores DATASET RUN [RUN ...]";
    let dataset = args.first().expect(usage);
    let runs = &args[1..];
    assert!(!runs.is_empty(), "{usage}");
    let (first, _) = SinGrav::load(runs[0].as_ref(), &Device::Cpu).unwrap();
    let data = Dataset::load(dataset.as_ref(), first.config().rendering.background).unwrap();
    let source = data
        .scene_source()
        .expect("a dataset of a built-in scene (volgen scene)");
    let fit = fit_of_views(first.config(), &data);
    let reference = seen_points(&fit);
    // (kinds, reach) settings in column order.
    let settings: Vec<(usize, f64, MatterSupport)> = KINDS
        .iter()
        .flat_map(|&k| {
            let kinds = MatterKinds::of(&reference, k, 0).unwrap();
            let colours: Vec<String> = kinds
                .colours()
                .iter()
                .map(|c| format!("({:.2}, {:.2}, {:.2})", c[0], c[1], c[2]))
                .collect();
            println!("{k} kinds: {}", colours.join(" "));
            REACHES.map(|reach| {
                (
                    k,
                    reach,
                    MatterSupport::of(&reference, kinds.clone(), reach).unwrap(),
                )
            })
        })
        .collect();
    let stones = source.kind.name() == "stones";
    // Where the matter out of place stands (2 kinds, reach 0.25).
    let chosen = &settings
        .iter()
        .find(|(k, reach, _)| *k == 2 && *reach == 0.25)
        .unwrap()
        .2;
    // Per volume, per setting: (all matter's share out of place, mean over kinds of each
    // kind's share); then the stones' share inside the ring.
    let score = |volume: &RadianceVolume| {
        let own = seen_points(volume);
        let mut row: Vec<f64> = settings
            .iter()
            .flat_map(|(_, _, support)| {
                let per_kind = support.misplaced_per_kind(&own);
                [
                    support.misplaced(&own),
                    per_kind.iter().sum::<f64>() / per_kind.len() as f64,
                ]
            })
            .collect();
        row.push(if stones { stone_shares(volume).0 } else { 0.0 });
        row.extend(misplaced_by_band(chosen, volume));
        row
    };
    let grid = *first.config().pyramid.volume_sizes.last().unwrap();
    let family: Vec<Vec<f64>> = source
        .family_seeds(LAYOUTS)
        .map(|seed| {
            let volume = source
                .kind
                .build(seed)
                .to_volume(GridDims::cube(grid))
                .unwrap();
            score(&volume)
        })
        .collect();
    let mut table: Vec<(String, Vec<Vec<f64>>)> = vec![
        ("fit".into(), vec![score(&fit)]),
        (format!("family: {LAYOUTS} other layouts"), family),
    ];
    for run in runs {
        let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
        let v_star = model.to_physical(&model.reconstruct().unwrap()).unwrap();
        table.push((format!("{run}: V*"), vec![score(&v_star)]));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        let samples: Vec<Vec<f64>> = (0..SCENES)
            .map(|_| {
                let raw = model.generate_random(&mut rng).unwrap();
                score(&model.to_physical(&raw).unwrap())
            })
            .collect();
        table.push((format!("{run}: {SCENES} scenes"), samples));
    }
    let mean =
        |rows: &[Vec<f64>], c: usize| mean_and_sd(&rows.iter().map(|r| r[c]).collect::<Vec<_>>()).0;
    let headers: Vec<String> = settings
        .iter()
        .flat_map(|(k, reach, _)| {
            [
                format!("{k} kinds, reach {reach}: all"),
                format!("{k} kinds, reach {reach}: per kind"),
            ]
        })
        .collect();
    println!(
        "| {} | volumes | {} | stone matter inside the ring | out of place (2 kinds, 0.25) at r < 0.4 | at 0.4 <= r < 0.8 | at r >= 0.8 |",
        source.kind.name(),
        headers.join(" | ")
    );
    println!("|---|---|{}---|---|---|---|", "---|".repeat(headers.len()));
    for (name, rows) in &table {
        let cells: Vec<String> = (0..headers.len() + 4)
            .map(|c| format!("{:.2}%", 100.0 * mean(rows, c)))
            .collect();
        println!("| {name} | {} | {} |", rows.len(), cells.join(" | "));
    }
}
