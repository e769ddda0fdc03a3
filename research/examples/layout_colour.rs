//! Where the colour share of the layout distance comes from: for a run's generated scenes, its
//! V* and true other layouts of the dataset's built-in scene, each against a fit of the views at
//! the finest 3D scale (as `volgen eval` scores them), the layout distance taken apart, and the
//! colour of the matter seen from above. Used for docs/journal/2026-12-hd.md (issue 82).
//!
//! `cargo run --release -p research --example layout_colour -- RUN DATASET [SCENES] [LAYOUTS]`
//! (defaults 8, 8 and 1; with VARY_FROM K > 1 the scenes keep V*'s noise at the scales before
//! K, as `volgen eval --vary-from K` draws them). Columns:
//!
//! - layout: `volgen eval`'s layout distance (6D, matter seen from above);
//! - by position: the same over `(x, y, z)` directions only;
//! - colour only: the sliced W1 distance over random directions of `(r, g, b)` alone (where the
//!   matter is plays no part);
//! - layout, column colours: the layout distance with every voxel's colour replaced by its
//!   column's colour seen from straight above (the seen-from-above weighted mean down the
//!   column), the colour a top-down camera composites: what remains once colours that vary
//!   down a column, inside a soft surface, are averaged as a picture averages them;
//! - layout, ground coloured as the fit's: the layout distance with the colour of every voxel
//!   of the ground's band (below z = -0.5, the stones scene's mound) taken from the fit at the
//!   same voxel: what remains once the ground's colours are the scene's, where they stand;
//! - ground's slow colours the fit's, ground's fine pattern the fit's: the same with only the
//!   ground's colour averaged over 16 x 16 voxel blocks taken from the fit (the volume keeps its
//!   own finer pattern), or only the finer pattern (the volume keeps its own block means);
//! - mean colour and its standard deviation per channel, and the mean absolute difference
//!   between a voxel's colour and its column's (weighted as the matter seen from above);
//! - under each row, the share of the matter seen from above per height band 0.1 high and the
//!   band's mean colour.

use candle_core::{Device, Tensor};
use radiance_volume::{GridDims, RadianceVolume};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use research::{fit_of_views, mean_and_sd, seen_points};
use rgbd_dataset::Dataset;
use scene_metrics::{layout_distance, layout_distance_by_position, LAYOUT_DIRECTIONS};
use singrav::SinGrav;

/// A volume's seen-from-above matter: per voxel its weight (opacity times transmittance above)
/// and colour, and per voxel its column's composited colour.
struct SeenMatter {
    /// Voxels per horizontal layer (the box's z axis is up, the slowest index).
    layer: usize,
    weights: Vec<f64>,
    colours: Vec<[f64; 3]>,
    column_colours: Vec<[f64; 3]>,
}

fn seen_matter(volume: &RadianceVolume) -> SeenMatter {
    let [w, h, d] = volume.dims().xyz();
    let voxel = f64::from(volume.aabb().size().x) / w as f64;
    let values: Vec<f32> = volume.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let cells = w * h * d;
    let mut matter = SeenMatter {
        layer: h * w,
        weights: vec![0.0; cells],
        colours: vec![[0.0; 3]; cells],
        column_colours: vec![[0.0; 3]; cells],
    };
    for column in 0..h * w {
        let (mut above, mut total, mut sum) = (1.0, 0.0, [0.0; 3]);
        for z in (0..d).rev() {
            let cell = z * h * w + column;
            let opacity = 1.0 - (-f64::from(values[cell]) * voxel).exp();
            let weight = opacity * above;
            above *= 1.0 - opacity;
            let rgb = [1, 2, 3].map(|c| f64::from(values[c * cells + cell]));
            matter.weights[cell] = weight;
            matter.colours[cell] = rgb;
            total += weight;
            for c in 0..3 {
                sum[c] += weight * rgb[c];
            }
        }
        let composite = sum.map(|s| if total > 0.0 { s / total } else { 0.0 });
        for z in 0..d {
            matter.column_colours[z * h * w + column] = composite;
        }
    }
    matter
}

/// `volume` with each voxel's colour replaced by its column's composited colour.
fn with_column_colours(volume: &RadianceVolume, matter: &SeenMatter) -> RadianceVolume {
    let mut values: Vec<f32> = volume.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let cells = matter.weights.len();
    for (cell, rgb) in matter.column_colours.iter().enumerate() {
        for c in 0..3 {
            values[(c + 1) * cells + cell] = rgb[c] as f32;
        }
    }
    let tensor = Tensor::from_vec(values, volume.tensor().dims(), &Device::Cpu).unwrap();
    volume.with_tensor(tensor).unwrap()
}

/// Top of the ground's band in the normalised box: the stones scene's mound stands at
/// -0.62..-0.5 (`StandingStones::ground_height`), its stones above.
const GROUND_TOP: f64 = -0.5;

/// Edge, in voxels, of the square blocks over which [`ground_blocks`] averages: past the ground's
/// finest pattern (the grass blades' period, about 0.15 of the normalised box, 10 voxels at
/// 126^3), short of its slow ones (the dry patches, about 1.7).
const BLOCK: usize = 16;

/// Per voxel of the ground's band, the mean colour over its layer's `BLOCK x BLOCK` block of
/// voxels, weighted by the matter seen from above (the voxel's own colour where the block holds
/// none): the ground's slow colour changes without its fine pattern. `matter` is `volume`'s.
fn ground_blocks(volume: &RadianceVolume, matter: &SeenMatter) -> Vec<[f32; 3]> {
    let [w, h, d] = volume.dims().xyz();
    let mut blocks = vec![[0f32; 3]; w * h * d];
    for z in 0..d {
        for by in (0..h).step_by(BLOCK) {
            for bx in (0..w).step_by(BLOCK) {
                let cells: Vec<usize> = (by..(by + BLOCK).min(h))
                    .flat_map(|y| (bx..(bx + BLOCK).min(w)).map(move |x| (z * h + y) * w + x))
                    .collect();
                let total: f64 = cells.iter().map(|&c| matter.weights[c]).sum();
                for &cell in &cells {
                    blocks[cell] = if total > 0.0 {
                        [0, 1, 2].map(|k| {
                            (cells
                                .iter()
                                .map(|&c| matter.weights[c] * matter.colours[c][k])
                                .sum::<f64>()
                                / total) as f32
                        })
                    } else {
                        matter.colours[cell].map(|v| v as f32)
                    };
                }
            }
        }
    }
    blocks
}

/// `volume` with the colour of every voxel of the ground's band replaced by `colour(cell, own)`
/// (`own` its own colour).
fn with_ground_colour(
    volume: &RadianceVolume,
    colour: impl Fn(usize, [f32; 3]) -> [f32; 3],
) -> RadianceVolume {
    let mut values: Vec<f32> = volume.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let [w, h, d] = volume.dims().xyz();
    let cells = w * h * d;
    for z in 0..d {
        if -1.0 + 2.0 * (z as f64 + 0.5) / d as f64 >= GROUND_TOP {
            continue;
        }
        for cell in z * h * w..(z + 1) * h * w {
            let own = [1, 2, 3].map(|c| values[c * cells + cell]);
            let new = colour(cell, own);
            for c in 0..3 {
                values[(c + 1) * cells + cell] = new[c];
            }
        }
    }
    let tensor = Tensor::from_vec(values, volume.tensor().dims(), &Device::Cpu).unwrap();
    volume.with_tensor(tensor).unwrap()
}

/// Exact W1 distance between two weighted 1D sets (weights each summing to 1).
fn w1(a: &mut [(f64, f64)], b: &mut [(f64, f64)]) -> f64 {
    a.sort_by(|x, y| x.0.total_cmp(&y.0));
    b.sort_by(|x, y| x.0.total_cmp(&y.0));
    let (mut i, mut j) = (0, 0);
    let (mut fa, mut fb, mut distance) = (0f64, 0f64, 0f64);
    let mut at = a
        .first()
        .map_or(0.0, |p| p.0)
        .min(b.first().map_or(0.0, |p| p.0));
    while i < a.len() || j < b.len() {
        let next = match (a.get(i), b.get(j)) {
            (Some(x), Some(y)) => x.0.min(y.0),
            (Some(x), None) => x.0,
            (None, Some(y)) => y.0,
            (None, None) => unreachable!(),
        };
        distance += (fa - fb).abs() * (next - at);
        at = next;
        while i < a.len() && a[i].0 <= at {
            fa += a[i].1;
            i += 1;
        }
        while j < b.len() && b[j].0 <= at {
            fb += b[j].1;
            j += 1;
        }
    }
    distance
}

/// Sliced W1 distance between the seen-from-above colours of two volumes (positions left out).
fn colour_distance(a: &SeenMatter, b: &SeenMatter, directions: &[[f64; 3]]) -> f64 {
    let project = |m: &SeenMatter, dir: &[f64; 3]| -> Vec<(f64, f64)> {
        m.weights
            .iter()
            .zip(&m.colours)
            .filter(|(w, _)| **w >= 1e-4)
            .map(|(w, c)| (c[0] * dir[0] + c[1] * dir[1] + c[2] * dir[2], *w))
            .collect()
    };
    let normalise = |mut set: Vec<(f64, f64)>| {
        let total: f64 = set.iter().map(|p| p.1).sum();
        set.iter_mut().for_each(|p| p.1 /= total);
        set
    };
    directions
        .iter()
        .map(|dir| {
            w1(
                &mut normalise(project(a, dir)),
                &mut normalise(project(b, dir)),
            )
        })
        .sum::<f64>()
        / directions.len() as f64
}

/// Mean colour, per-channel standard deviation, and mean |colour - column colour| (summed over
/// channels), all weighted by the matter seen from above.
fn colour_stats(m: &SeenMatter) -> ([f64; 3], [f64; 3], f64) {
    let total: f64 = m.weights.iter().sum();
    let mut mean = [0.0; 3];
    for (w, c) in m.weights.iter().zip(&m.colours) {
        for k in 0..3 {
            mean[k] += w * c[k] / total;
        }
    }
    let (mut var, mut spread) = ([0.0; 3], 0.0);
    for ((w, c), col) in m.weights.iter().zip(&m.colours).zip(&m.column_colours) {
        for k in 0..3 {
            var[k] += w * (c[k] - mean[k]).powi(2) / total;
            spread += w * (c[k] - col[k]).abs() / total;
        }
    }
    (mean, var.map(f64::sqrt), spread)
}

/// Height bands of the normalised box, 0.1 high, from the bottom.
const BANDS: usize = 20;

/// Per height band: its share of the matter seen from above, and that matter's mean colour
/// (printed where the band holds more than 0.3% of the matter).
fn band_stats(m: &SeenMatter) -> Vec<[f64; 4]> {
    let layers = m.weights.len() / m.layer;
    let total: f64 = m.weights.iter().sum();
    let mut bands = vec![[0.0; 4]; BANDS];
    for (cell, (w, c)) in m.weights.iter().zip(&m.colours).enumerate() {
        let z = cell / m.layer;
        let band = (z * BANDS / layers).min(BANDS - 1);
        bands[band][0] += w / total;
        for k in 0..3 {
            bands[band][k + 1] += w * c[k] / total;
        }
    }
    for band in &mut bands {
        if band[0] > 0.0 {
            for k in 1..4 {
                band[k] /= band[0];
            }
        }
    }
    bands
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: layout_colour RUN DATASET [SCENES] [LAYOUTS] [VARY_FROM]";
    let (run, dataset) = (args.first().expect(usage), args.get(1).expect(usage));
    let arg = |i: usize, default: usize| args.get(i).map_or(default, |a| a.parse().unwrap());
    let (scenes, layouts, vary_from) = (arg(2, 8), arg(3, 8), arg(4, 1));
    let (model, _) = SinGrav::load(run.as_ref(), &Device::Cpu).unwrap();
    let data = Dataset::load(dataset.as_ref(), model.config().rendering.background).unwrap();
    let config = model.config().clone().with(|c| c.pyramid.fit_size = None);
    let fit = fit_of_views(&config, &data);
    let grid = fit.dims().xyz()[0];
    let reference = seen_points(&fit);
    let reference_matter = seen_matter(&fit);
    let reference_columns = seen_points(&with_column_colours(&fit, &reference_matter));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let directions: Vec<[f64; 3]> = (0..LAYOUT_DIRECTIONS)
        .map(|_| {
            let v: [f64; 3] = [0; 3].map(|_| StandardNormal.sample(&mut rng));
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|x| x / n)
        })
        .collect();
    let fit_blocks = ground_blocks(&fit, &reference_matter);
    let fit_colours: Vec<[f32; 3]> = reference_matter
        .colours
        .iter()
        .map(|c| c.map(|v| v as f32))
        .collect();
    let score = |volume: &RadianceVolume| -> Vec<f64> {
        let points = seen_points(volume);
        let matter = seen_matter(volume);
        let columns = seen_points(&with_column_colours(volume, &matter));
        let (mean, sd, spread) = colour_stats(&matter);
        let mut row = vec![
            layout_distance(&reference, &points, LAYOUT_DIRECTIONS, 0).unwrap(),
            layout_distance_by_position(&reference, &points, LAYOUT_DIRECTIONS, 0).unwrap(),
            colour_distance(&reference_matter, &matter, &directions),
            layout_distance(&reference_columns, &columns, LAYOUT_DIRECTIONS, 0).unwrap(),
            layout_distance(
                &reference,
                &seen_points(&with_ground_colour(volume, |cell, _| fit_colours[cell])),
                LAYOUT_DIRECTIONS,
                0,
            )
            .unwrap(),
        ];
        // The fit's slow ground colours with the volume's own fine pattern, and the volume's
        // slow colours with the fit's fine pattern.
        let own_blocks = ground_blocks(volume, &matter);
        let slow_from_fit = with_ground_colour(volume, |cell, own| {
            [0, 1, 2].map(|k| own[k] - own_blocks[cell][k] + fit_blocks[cell][k])
        });
        let fine_from_fit = with_ground_colour(volume, |cell, _| {
            [0, 1, 2].map(|k| own_blocks[cell][k] + fit_colours[cell][k] - fit_blocks[cell][k])
        });
        for other in [slow_from_fit, fine_from_fit] {
            row.push(
                layout_distance(&reference, &seen_points(&other), LAYOUT_DIRECTIONS, 0).unwrap(),
            );
        }
        row.extend(mean);
        row.extend(sd);
        row.push(spread);
        row.extend(band_stats(&matter).iter().flatten());
        row
    };
    println!("| volumes | count | layout | by position | colour only | layout, column colours | layout, ground coloured as the fit's | ground's slow colours the fit's | ground's fine pattern the fit's | mean r, g, b | sd r, g, b | voxel vs column colour |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let print = |name: &str, rows: &[Vec<f64>]| {
        let m = |c: usize| mean_and_sd(&rows.iter().map(|r| r[c]).collect::<Vec<_>>());
        let pm = |c: usize| format!("{:.4} ± {:.4}", m(c).0, m(c).1);
        println!(
            "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {:.3}, {:.3}, {:.3} | {:.3}, {:.3}, {:.3} | {:.4} |",
            rows.len(),
            pm(0),
            pm(1),
            pm(2),
            pm(3),
            pm(4),
            pm(5),
            pm(6),
            m(7).0,
            m(8).0,
            m(9).0,
            m(10).0,
            m(11).0,
            m(12).0,
            m(13).0
        );
        let bands: Vec<String> = (0..BANDS)
            .filter(|b| m(14 + 4 * b).0 > 0.003)
            .map(|b| {
                let c = 14 + 4 * b;
                format!(
                    "z {:+.1}: {:.1}% ({:.2}, {:.2}, {:.2})",
                    -1.0 + 0.1 * b as f64,
                    100.0 * m(c).0,
                    m(c + 1).0,
                    m(c + 2).0,
                    m(c + 3).0
                )
            })
            .collect();
        println!("|   bands of {name} | {} |", bands.join("; "));
    };
    print("the fit", &[score(&fit)]);
    let v_star = model.to_physical(&model.reconstruct().unwrap()).unwrap();
    print("V*", &[score(&v_star)]);
    if let Some(source) = data.scene_source() {
        let truth: Vec<Vec<f64>> = source
            .family_seeds(layouts)
            .map(|seed| {
                score(
                    &source
                        .kind
                        .build(seed)
                        .to_volume(GridDims::cube(grid))
                        .unwrap(),
                )
            })
            .collect();
        print("true other layouts", &truth);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let samples: Vec<Vec<f64>> = (0..scenes)
        .map(|_| {
            let raw = model.generate_random_from(&mut rng, vary_from).unwrap();
            score(&model.to_physical(&raw).unwrap())
        })
        .collect();
    print("generated scenes", &samples);
}
