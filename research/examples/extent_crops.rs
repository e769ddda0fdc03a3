//! Scenes twice as wide (`volgen sample --extent 2,1,1`) under each rule for the CSG anchors
//! beyond the learned box, against scenes of the learned size: three crops of the learned size
//! of every wide scene (x in [-2, 0], [-1, 1] and [0, 2]) scored as `volgen eval` scores a
//! scene (patch SWD-MV and colour SWD against the dataset's 4 steepest views, the layout distance and
//! matter out of place against a fit of the views), and seams: how much the volume changes
//! from one x plane to the next at the learned box's borders (x = -1 and 1), against the
//! median plane. Used for docs/applications.md and docs/journal/2026-12-extent.md.
//!
//! `cargo run --release -p research --example extent_crops -- DATASET RUN [SCENES]`
//! (16 scenes by default, drawn from seed 0 as `volgen sample --seed 0` draws them).

use candle_core::{Device, Tensor};
use csg_embed::Outside;
use radiance_volume::RadianceVolume;
use rand::SeedableRng;
use research::{fit_of_views, mean_and_sd, seen_points};
use rgbd_dataset::Dataset;
use scene_metrics::{
    colour_swd_per_scene, layout_distance, patch_swd_per_scene, MatterKinds, MatterSupport,
    LAYOUT_DIRECTIONS, MISPLACED_KINDS, MISPLACED_REACH,
};
use singrav::extent::Extent;
use singrav::SinGrav;

/// Views the crops are seen from.
const VIEWS: usize = 4;

/// What one set of learned-size volumes scores.
struct Row {
    patch: Vec<f64>,
    colour: Vec<f64>,
    layout: Vec<f64>,
    misplaced: Vec<f64>,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: extent_crops DATASET RUN [SCENES]";
    let (dataset, run) = (args.first().expect(usage), args.get(1).expect(usage));
    let scenes: usize = args.get(2).map_or(16, |s| s.parse().expect(usage));
    let device = Device::Cpu;
    let (mut model, _) = SinGrav::load(run.as_ref(), &device).unwrap();
    let data = Dataset::load(dataset.as_ref(), model.config().rendering.background).unwrap();
    let fit = fit_of_views(model.config(), &data);
    let reference = seen_points(&fit);
    let kinds = MatterKinds::of(&reference, MISPLACED_KINDS, 0).unwrap();
    let places = MatterSupport::of(&reference, kinds, MISPLACED_REACH).unwrap();
    // The steepest views: a crop's cut faces show the ground's inside, which no training view
    // saw and any generator fills as it likes; from above they are barely in view.
    let mut frames: Vec<usize> = (0..data.len()).collect();
    let elevation = |i: usize| {
        let p = data.cameras()[i].position();
        p.z / p.length()
    };
    frames.sort_by(|&a, &b| elevation(b).total_cmp(&elevation(a)));
    frames.truncate(VIEWS);
    println!(
        "views {:?}, elevations {:?} degrees",
        frames,
        frames
            .iter()
            .map(|&i| elevation(i).asin().to_degrees().round())
            .collect::<Vec<_>>()
    );
    let chosen = data.subset(&frames).unwrap();
    let size = model.render_size();
    let coarse = chosen.level(size, size, &device).unwrap();
    let real = chosen.level(2 * size, 2 * size, &device).unwrap().images;
    let score = |model: &SinGrav, raws: &[Tensor]| -> Row {
        let mut views = Vec::new();
        let (mut layout, mut misplaced) = (Vec::new(), Vec::new());
        for raw in raws {
            let physical = model.to_physical(raw).unwrap();
            let points = seen_points(&physical);
            layout.push(layout_distance(&reference, &points, LAYOUT_DIRECTIONS, 0).unwrap());
            misplaced.push(places.misplaced(&points));
            let rgb = model.render_maps(raw, &coarse.cameras).unwrap().rgb;
            // Without the upsampler (an unfinished run) the views come out at the 3D size.
            let rgb = if rgb.dim(3).unwrap() == size {
                rgb.upsample_nearest2d(2 * size, 2 * size).unwrap()
            } else {
                rgb
            };
            views.push(rgb);
        }
        Row {
            patch: patch_swd_per_scene(&views, &real).unwrap(),
            colour: colour_swd_per_scene(&views, &real).unwrap(),
            layout,
            misplaced,
        }
    };
    println!(
        "| scenes | patch SWD-MV | colour SWD | layout | misplaced | seam ratio at x = -1 / 1 |"
    );
    println!("|---|---|---|---|---|---|");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let learned: Vec<Tensor> = (0..scenes)
        .map(|_| model.generate_random(&mut rng).unwrap())
        .collect();
    print_row("learned size", &score(&model, &learned), None);
    let finest = model.scale_dims(model.volume_scales()).w;
    for outside in [Outside::Mirror, Outside::Clamp, Outside::Extend] {
        model
            .set_extent(Extent::new([2.0, 1.0, 1.0]).unwrap(), outside)
            .unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        let wide: Vec<Tensor> = (0..scenes)
            .map(|_| model.generate_random(&mut rng).unwrap())
            .collect();
        let seams: Vec<[f64; 2]> = wide
            .iter()
            .map(|raw| seam_ratios(&model.to_physical(raw).unwrap()))
            .collect();
        model.set_extent(Extent::ONE, outside).unwrap();
        for (name, start) in [
            ("x in [-2, 0]", 0),
            ("x in [-1, 1]", finest / 2),
            ("x in [0, 2]", finest),
        ] {
            let crops: Vec<Tensor> = wide
                .iter()
                .map(|raw| raw.narrow(4, start, finest).unwrap().contiguous().unwrap())
                .collect();
            let seam = (start == 0).then_some(seams.as_slice());
            print_row(&format!("{outside}, {name}"), &score(&model, &crops), seam);
        }
    }
}

fn print_row(name: &str, row: &Row, seams: Option<&[[f64; 2]]>) {
    let cell = |values: &[f64]| {
        let (mean, sd) = mean_and_sd(values);
        format!("{mean:.4} ± {:.4}", sd / (values.len() as f64).sqrt())
    };
    let seam = seams.map_or(String::new(), |s| {
        let left: Vec<f64> = s.iter().map(|r| r[0]).collect();
        let right: Vec<f64> = s.iter().map(|r| r[1]).collect();
        format!("{} / {}", cell(&left), cell(&right))
    });
    println!(
        "| {name} | {} | {} | {} | {} | {seam} |",
        cell(&row.patch),
        cell(&row.colour),
        cell(&row.layout),
        cell(&row.misplaced)
    );
}

/// How much a wide volume changes across the learned box's borders: the mean absolute
/// difference of opacity and colour (weighted by opacity) between the two x planes either side
/// of x = -1 and of x = 1, each divided by the median of that difference over all neighbouring
/// planes. A seam stands out as a ratio well above 1.
fn seam_ratios(volume: &RadianceVolume) -> [f64; 2] {
    let dims = volume.dims();
    let (d, h, w) = (dims.d, dims.h, dims.w);
    let voxel = f64::from(volume.aabb().size().x) / w as f64;
    let values: Vec<f32> = volume.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let cells = d * h * w;
    let at =
        |c: usize, z: usize, y: usize, x: usize| f64::from(values[c * cells + (z * h + y) * w + x]);
    let opacity = |z, y, x| 1.0 - (-at(0, z, y, x) * voxel).exp();
    let change = |x: usize| -> f64 {
        let mut sum = 0.0;
        for z in 0..d {
            for y in 0..h {
                let (a, b) = (opacity(z, y, x), opacity(z, y, x + 1));
                sum += (a - b).abs();
                for c in 1..4 {
                    sum += (a * at(c, z, y, x) - b * at(c, z, y, x + 1)).abs();
                }
            }
        }
        sum / (d * h) as f64
    };
    let changes: Vec<f64> = (0..w - 1).map(change).collect();
    let mut sorted = changes.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    // The wide grid is `w` voxels over [-2, 2]: x = -1 and 1 fall between planes w/4 - 1 and
    // w/4, and 3w/4 - 1 and 3w/4.
    [changes[w / 4 - 1] / median, changes[3 * w / 4 - 1] / median]
}
