//! Arrangement by kind of matter: where each kind of the scene's matter stands.
//!
//! [`layout_distance`](crate::layout_distance) compares all of two volumes' matter at once, so
//! the kind that covers most of a scene (its ground) decides it: a ground whose colour or height
//! differs a little from run to run outweighs stones moved from a ring into its middle.
//! [`kind_layout_distance`] gives every kind of matter the same say: the reference's matter is
//! split into [`MatterKinds`] by colour (weighted k-means), each volume's points are shared out
//! among the kinds by how close their colour is to each kind's, and the distance is the mean
//! over kinds of the sliced Wasserstein-1 distance between the two volumes' positions of that
//! kind. Stones that stand elsewhere then cost as much as the whole ground moved by as much.

use rand::{Rng, SeedableRng};

use crate::error::{invalid, Result};
use crate::layout::{sliced_w1, LayoutPoints, Slice, DIMS};

/// Kinds of matter [`kind_layout_distance`] uses unless told otherwise (chosen by measurement:
/// docs/metrics.md, "kind_layout_distance").
pub const MATTER_KINDS: usize = 4;

/// How sharply a point's colour picks its kind: its share of kind `k` falls as
/// `exp(-|colour - kind_k|^2 / (2 KIND_WIDTH^2))`, normalised over the kinds. 0.05 of the colour
/// range is about the spread of one material's shading, so a point between two kinds' colours
/// is shared and one on a kind's colour belongs to it alone.
const KIND_WIDTH: f64 = 0.05;

/// Lloyd iterations of the k-means (it settles within a few on a volume's colours).
const ITERATIONS: usize = 30;

/// The kinds of a scene's matter: the colours of a weighted k-means of its points' colours.
#[derive(Debug, Clone, PartialEq)]
pub struct MatterKinds {
    colours: Vec<[f64; 3]>,
}

impl MatterKinds {
    /// `count` kinds of `reference`'s matter: k-means of its points' colours, each point
    /// weighing its share of the matter, seeded by k-means++ from `seed`. Fewer kinds come back
    /// when the matter has fewer distinct colours.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use scene_metrics::{LayoutPoints, MatterKinds};
    /// // Two red voxels and two green ones.
    /// let mut v = vec![0f32; 4 * 4];
    /// v[..4].fill(50.0);
    /// v[4..6].fill(1.0); // red of voxels 0, 1
    /// v[10..12].fill(1.0); // green of voxels 2, 3
    /// let matter = LayoutPoints::from_volume(&Tensor::from_vec(v, (4, 1, 1, 4), &Device::Cpu)?, 0.5)?;
    /// let kinds = MatterKinds::of(&matter, 2, 0)?;
    /// assert_eq!(kinds.len(), 2);
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    pub fn of(reference: &LayoutPoints, count: usize, seed: u64) -> Result<Self> {
        if count == 0 {
            return Err(invalid("kinds", "need at least one kind of matter"));
        }
        if reference.is_empty() {
            return Err(invalid("reference", "holds no matter to find kinds in"));
        }
        let colours: Vec<[f64; 3]> = reference.points.iter().map(colour_of).collect();
        let weights = &reference.weights;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut centres = plus_plus_centres(&colours, weights, count, &mut rng);
        for _ in 0..ITERATIONS {
            let mut sums = vec![([0.0; 3], 0.0); centres.len()];
            for (colour, &w) in colours.iter().zip(weights) {
                let (sum, total) = &mut sums[nearest(&centres, colour)];
                for c in 0..3 {
                    sum[c] += w * colour[c];
                }
                *total += w;
            }
            // A centre that lost all its points is dropped (fewer kinds than asked).
            centres = sums
                .into_iter()
                .filter(|(_, total)| *total > 0.0)
                .map(|(sum, total)| sum.map(|s| s / total))
                .collect();
        }
        Ok(Self { colours: centres })
    }

    /// The number of kinds.
    pub fn len(&self) -> usize {
        self.colours.len()
    }

    /// Whether there are no kinds (never, for kinds [`MatterKinds::of`] made).
    pub fn is_empty(&self) -> bool {
        self.colours.is_empty()
    }

    /// The kinds' colours, RGB in [0, 1].
    pub fn colours(&self) -> &[[f64; 3]] {
        &self.colours
    }

    /// The kind whose colour is nearest `colour` (RGB).
    pub(crate) fn nearest(&self, colour: &[f64; 3]) -> usize {
        nearest(&self.colours, colour)
    }

    /// `points` shared out among the kinds: one point set per kind, each point weighted by its
    /// weight times its share of that kind, renormalised per kind.
    fn split(&self, points: &LayoutPoints) -> Vec<LayoutPoints> {
        let mut per_kind: Vec<Vec<f64>> = vec![Vec::with_capacity(points.len()); self.len()];
        for (point, &w) in points.points.iter().zip(&points.weights) {
            for (kind, share) in per_kind.iter_mut().zip(self.shares(point)) {
                kind.push(w * share);
            }
        }
        per_kind
            .into_iter()
            .map(|weights| LayoutPoints::reweighted(points, weights))
            .collect()
    }

    /// A point's share of each kind (summing to 1): falling as
    /// `exp(-|colour - kind_k|^2 / (2 KIND_WIDTH^2))` with the distance of its colour from the
    /// kind's, normalised over the kinds.
    pub(crate) fn shares(&self, point: &[f32; DIMS]) -> Vec<f64> {
        let colour = colour_of(point);
        let mut closeness: Vec<f64> = self
            .colours
            .iter()
            .map(|kind| (-squared_distance(&colour, kind) / (2.0 * KIND_WIDTH * KIND_WIDTH)).exp())
            .collect();
        let total: f64 = closeness.iter().sum();
        if total > 0.0 {
            closeness.iter_mut().for_each(|c| *c /= total);
        } else {
            // A colour far from every kind (every closeness underflowing to 0) is shared equally.
            closeness.fill(1.0 / self.len() as f64);
        }
        closeness
    }
}

/// The arrangement distance by kind of matter: the mean over `kinds` of
/// [`kind_layout_distances`], the sliced Wasserstein-1 distance between the positions of that
/// kind's matter in `a` and in `b`. 0 for the same matter; symmetric; infinite when one volume
/// holds no matter and the other does, 0 when neither does.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use scene_metrics::{kind_layout_distance, LayoutPoints, MatterKinds};
/// // A row of 8 voxels: green ground everywhere but one grey stone, at x = 1 or at x = 6.
/// let row = |stone: usize| {
///     let mut v = vec![0f32; 4 * 8];
///     v[..8].fill(50.0);
///     for x in 0..8 {
///         let rgb = if x == stone { [0.5, 0.5, 0.5] } else { [0.2, 0.7, 0.2] };
///         (0..3).for_each(|c| v[(c + 1) * 8 + x] = rgb[c]);
///     }
///     LayoutPoints::from_volume(&Tensor::from_vec(v, (4, 1, 1, 8), &Device::Cpu)?, 0.25)
/// };
/// let (here, there) = (row(1)?, row(6)?);
/// let kinds = MatterKinds::of(&here, 2, 0)?;
/// assert_eq!(kind_layout_distance(&here, &here, &kinds, 64, 0)?, 0.0);
/// // The stone kind moved by 5/8 of the box's width: half of that (one of two kinds) and more.
/// assert!(kind_layout_distance(&here, &there, &kinds, 64, 0)? > 0.1);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn kind_layout_distance(
    a: &LayoutPoints,
    b: &LayoutPoints,
    kinds: &MatterKinds,
    directions: usize,
    seed: u64,
) -> Result<f64> {
    let per_kind = kind_layout_distances(a, b, kinds, directions, seed)?;
    Ok(per_kind.iter().sum::<f64>() / per_kind.len() as f64)
}

/// Per kind of `kinds` (in [`MatterKinds::colours`]' order), the sliced Wasserstein-1 distance
/// between the positions of that kind's matter in `a` and in `b` (`directions` random 3D
/// directions drawn from `seed`): each volume's points shared out among the kinds by colour,
/// a point's share of kind `k` falling as `exp(-|colour - kind_k|^2 / (2 * 0.05^2))`.
pub fn kind_layout_distances(
    a: &LayoutPoints,
    b: &LayoutPoints,
    kinds: &MatterKinds,
    directions: usize,
    seed: u64,
) -> Result<Vec<f64>> {
    if kinds.is_empty() {
        return Err(invalid("kinds", "need at least one kind of matter"));
    }
    let (a_kinds, b_kinds) = (kinds.split(a), kinds.split(b));
    a_kinds
        .iter()
        .zip(&b_kinds)
        .map(|(a_kind, b_kind)| sliced_w1(a_kind, b_kind, directions, seed, Slice::Position))
        .collect()
}

fn colour_of(point: &[f32; DIMS]) -> [f64; 3] {
    [3, 4, 5].map(|c| f64::from(point[c]))
}

fn squared_distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// The index of the centre nearest `colour`.
fn nearest(centres: &[[f64; 3]], colour: &[f64; 3]) -> usize {
    centres
        .iter()
        .map(|c| squared_distance(c, colour))
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(i, _)| i)
}

/// k-means++ seeding: the first centre drawn by weight, each next one by weight times the
/// squared distance to the nearest centre so far; stops early when every colour is a centre.
fn plus_plus_centres(
    colours: &[[f64; 3]],
    weights: &[f64],
    count: usize,
    rng: &mut impl Rng,
) -> Vec<[f64; 3]> {
    let mut centres: Vec<[f64; 3]> = Vec::with_capacity(count);
    // Each colour's squared distance to its nearest centre so far (none yet: all alike).
    let mut nearest_d2 = vec![1.0; colours.len()];
    while centres.len() < count {
        let reach: Vec<f64> = weights
            .iter()
            .zip(&nearest_d2)
            .map(|(w, d)| w * d)
            .collect();
        let total: f64 = reach.iter().sum();
        if total <= 0.0 {
            break;
        }
        let mut target = rng.random::<f64>() * total;
        let mut pick = reach.len() - 1;
        for (i, &r) in reach.iter().enumerate() {
            if target < r {
                pick = i;
                break;
            }
            target -= r;
        }
        let centre = colours[pick];
        centres.push(centre);
        for (d2, colour) in nearest_d2.iter_mut().zip(colours) {
            *d2 = d2.min(squared_distance(colour, &centre));
        }
    }
    centres
}

#[cfg(test)]
mod tests {
    use super::{kind_layout_distance, MatterKinds};
    use crate::layout_distance;
    use crate::test_slabs::slab;

    const GROUND: [f32; 3] = [0.2, 0.6, 0.2];
    const STONE: [f32; 3] = [0.55, 0.55, 0.55];

    #[test]
    fn k_means_finds_the_colours_of_the_matter() {
        let scene = slab(10, |x, _| Some(if x < 3 { STONE } else { GROUND }));
        let kinds = MatterKinds::of(&scene, 2, 3).unwrap();
        let mut found: Vec<[f64; 3]> = kinds.colours().to_vec();
        found.sort_by(|a, b| a[0].total_cmp(&b[0]));
        for (got, want) in found.iter().zip([GROUND, STONE]) {
            for c in 0..3 {
                assert!((got[c] - f64::from(want[c])).abs() < 1e-6, "{found:?}");
            }
        }
        // Two colours only: a third kind is not invented.
        assert_eq!(MatterKinds::of(&scene, 3, 3).unwrap().len(), 2);
    }

    #[test]
    fn stones_moved_off_their_place_are_seen_where_the_whole_layout_barely_moves() {
        // Ground everywhere; 4 stone cells at the border (the "ring") in the scene, the same 4
        // cells at other border places in a true variant, and in the middle in a bad sample.
        let n = 16;
        let with_stones = |stones: &'static [(usize, usize)]| {
            slab(n, move |x, y| {
                Some(if stones.contains(&(x, y)) {
                    STONE
                } else {
                    GROUND
                })
            })
        };
        let scene = with_stones(&[(1, 1), (14, 1), (1, 14), (14, 14)]);
        let variant = with_stones(&[(3, 1), (14, 3), (1, 12), (12, 14)]);
        let middle = with_stones(&[(7, 7), (8, 7), (7, 8), (8, 8)]);
        let kinds = MatterKinds::of(&scene, 2, 0).unwrap();
        let by_kind = |other| kind_layout_distance(&scene, other, &kinds, 128, 0).unwrap();
        let (near, far) = (by_kind(&variant), by_kind(&middle));
        assert!(far > 2.0 * near, "middle {far}, variant {near}");
        // All matter at once: 4 cells of 256 move, and the distance hardly sees either.
        let whole = layout_distance(&scene, &middle, 128, 0).unwrap();
        assert!(whole < 0.25 * far, "whole {whole}, by kind {far}");
        // Symmetric, and 0 for itself.
        let back = kind_layout_distance(&middle, &scene, &kinds, 128, 0).unwrap();
        assert!((back - far).abs() < 1e-12);
        assert_eq!(by_kind(&scene), 0.0);
    }

    #[test]
    fn a_kind_moved_costs_its_displacement_over_the_number_of_kinds() {
        // A stone column moved by 4 cells (0.5 of the normalised box) along x through ground:
        // the stone kind's positions shift by 0.5 along x, a W1 of 0.5 |theta_x| along each
        // direction, whose mean over 3D unit directions is 1/2; the ground's gap moves by as
        // much, which moves 1/15 of its matter by 0.5: 0.5 / 15 |theta_x|. Two kinds:
        // (0.25 + 0.5 / 30) / 2.
        let n = 16;
        let column = |at: usize| slab(n, move |x, _| Some(if x == at { STONE } else { GROUND }));
        let (a, b) = (column(2), column(6));
        let kinds = MatterKinds::of(&a, 2, 0).unwrap();
        let d = kind_layout_distance(&a, &b, &kinds, 2048, 0).unwrap();
        let expected = (0.25 + 0.5 / 30.0) / 2.0;
        assert!(
            (d - expected).abs() < 0.03 * expected,
            "{d} against {expected}"
        );
    }

    #[test]
    fn empty_volumes_and_bad_arguments() {
        let scene = slab(4, |_, _| Some(GROUND));
        let nothing = slab(4, |_, _| None);
        assert!(MatterKinds::of(&nothing, 2, 0).is_err());
        assert!(MatterKinds::of(&scene, 0, 0).is_err());
        let kinds = MatterKinds::of(&scene, 2, 0).unwrap();
        assert_eq!(kinds.len(), 1);
        assert_eq!(
            kind_layout_distance(&scene, &nothing, &kinds, 8, 0).unwrap(),
            f64::INFINITY
        );
        assert_eq!(
            kind_layout_distance(&nothing, &nothing, &kinds, 8, 0).unwrap(),
            0.0
        );
        assert!(kind_layout_distance(&scene, &scene, &kinds, 0, 0).is_err());
    }
}
