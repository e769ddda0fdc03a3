//! Arrangement: how far a volume's matter is from another's, in position and colour.
//!
//! The image metrics compare views patch by patch and colour by colour, so a scene whose stones
//! stand in the middle of the ring scores like one whose stones stand on it. [`layout_distance`]
//! compares where the matter is: each volume becomes a weighted point set, one point
//! `(x, y, z, r, g, b)` per voxel (the voxel's centre in the box normalised to `[-1, 1]^3`, its
//! colour), weighted by the voxel's opacity `1 - exp(-sigma * voxel)`, and the distance is the
//! sliced Wasserstein-1 distance between the two weighted sets: the mean over random directions
//! of the exact 1D W1 distance between the projections. Matter moved by `d` in position costs
//! about `d` (times the directions' share of that axis), so a scene with the same kinds of matter
//! in other places scores far, and one with the same layout and other details near.
//!
//! Weighting by opacity alone counts matter no camera sees: the inside of solid ground, or the
//! fog a fit of views leaves below the surface, outweighs the objects on top.
//! [`LayoutWeighting::SeenFromAbove`] (what `volgen eval` uses) weights each voxel by the light
//! it stops of a ray coming straight down from the top of the box, `opacity x transmittance
//! above it`, so only the matter a camera above the scene sees counts: the ground's surface,
//! the tops and upper sides of what stands on it.

use candle_core::Tensor;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

use crate::error::{invalid, Result};

/// Coordinates of a layout point: position (3) and colour (3).
pub(crate) const DIMS: usize = 6;

/// How [`LayoutPoints::from_volume_weighted`] weights a voxel's point.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum LayoutWeighting {
    /// Its opacity `1 - exp(-sigma * voxel)`: all matter, seen or hidden.
    Opacity,
    /// Its opacity times the transmittance of the voxels above it (the box's z axis is up):
    /// the matter a ray straight down from the top of the box meets.
    #[default]
    SeenFromAbove,
}

/// A volume's matter as weighted points, ready for [`layout_distance`].
#[derive(Debug, Clone, PartialEq)]
pub struct LayoutPoints {
    pub(crate) points: Vec<[f32; DIMS]>,
    /// Each point's share of the volume's matter (they sum to 1).
    pub(crate) weights: Vec<f64>,
}

impl LayoutPoints {
    /// The matter of a physical volume `(4, D, H, W)` (density, then RGB in [0, 1]) over a box
    /// whose voxels are `voxel` world units long, as points in the box normalised to
    /// `[-1, 1]^3`. Voxels of opacity below `1e-4` are left out (empty space); a volume with no
    /// matter gives an empty set, which [`layout_distance`] puts infinitely far from any other.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// // Empty but for one dense red voxel.
    /// let mut values = vec![0f32; 4 * 8];
    /// values[0] = 100.0; // density of voxel (0, 0, 0)
    /// values[8] = 1.0; // its red
    /// let volume = Tensor::from_vec(values, (4, 2, 2, 2), &Device::Cpu)?;
    /// let matter = scene_metrics::LayoutPoints::from_volume(&volume, 0.5)?;
    /// assert_eq!(matter.len(), 1);
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    pub fn from_volume(volume: &Tensor, voxel: f32) -> Result<Self> {
        Self::from_volume_weighted(volume, voxel, LayoutWeighting::Opacity)
    }

    /// The matter of a physical volume as [`LayoutPoints::from_volume`] takes it, each voxel
    /// weighted as `weighting` says; voxels of weight below `1e-4` are left out.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use scene_metrics::{LayoutPoints, LayoutWeighting};
    /// // A column of two opaque voxels (z = 0 below z = 1): seen from above, only the top one.
    /// let mut values = vec![0f32; 4 * 2];
    /// values[0] = 100.0;
    /// values[1] = 100.0;
    /// let column = Tensor::from_vec(values, (4, 2, 1, 1), &Device::Cpu)?;
    /// let seen = LayoutPoints::from_volume_weighted(&column, 1.0, LayoutWeighting::SeenFromAbove)?;
    /// assert_eq!(seen.len(), 1);
    /// assert_eq!(LayoutPoints::from_volume(&column, 1.0)?.len(), 2);
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    pub fn from_volume_weighted(
        volume: &Tensor,
        voxel: f32,
        weighting: LayoutWeighting,
    ) -> Result<Self> {
        let (channels, d, h, w) = volume.dims4()?;
        if channels < 4 {
            return Err(invalid(
                "volume",
                format!("needs density and RGB channels (4), has {channels}"),
            ));
        }
        if !(voxel.is_finite() && voxel > 0.0) {
            return Err(invalid(
                "voxel",
                format!("expected a length > 0, got {voxel}"),
            ));
        }
        let values: Vec<f32> = volume.narrow(0, 0, 4)?.flatten_all()?.to_vec1()?;
        let cells = d * h * w;
        let centre = |i: usize, n: usize| (2.0 * (i as f32 + 0.5) / n as f32) - 1.0;
        let (mut points, mut weights) = (Vec::new(), Vec::new());
        // Per column (x, y), the transmittance from the top of the box down to the current z.
        let mut transmittance = vec![1f64; h * w];
        for z in (0..d).rev() {
            for y in 0..h {
                for x in 0..w {
                    let cell = (z * h + y) * w + x;
                    let sigma = values[cell];
                    if !sigma.is_finite() || sigma < 0.0 {
                        return Err(invalid(
                            "volume",
                            format!("density {sigma} at voxel ({x}, {y}, {z}) (expected >= 0)"),
                        ));
                    }
                    let opacity = 1.0 - (-f64::from(sigma) * f64::from(voxel)).exp();
                    let above = &mut transmittance[y * w + x];
                    let weight = match weighting {
                        LayoutWeighting::Opacity => opacity,
                        LayoutWeighting::SeenFromAbove => opacity * *above,
                    };
                    *above *= 1.0 - opacity;
                    if weight < 1e-4 {
                        continue;
                    }
                    let colour = |c: usize| values[c * cells + cell];
                    points.push([
                        centre(x, w),
                        centre(y, h),
                        centre(z, d),
                        colour(1),
                        colour(2),
                        colour(3),
                    ]);
                    weights.push(weight);
                }
            }
        }
        let total: f64 = weights.iter().sum();
        weights.iter_mut().for_each(|w| *w /= total);
        Ok(Self { points, weights })
    }

    /// Several volumes' matter pooled into one set, each volume weighing `1 / sets.len()`:
    /// where matter stands over a set of scenes. Against one scene's matter this measures the
    /// arrangement a generator keeps on average, not each scene's own variation (a ring turned
    /// is far from the ring, but rings turned every way pool to the ring's annulus); empty sets
    /// are left out, and pooling none gives an empty set.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use scene_metrics::{layout_distance, LayoutPoints};
    /// // One grey voxel at either end of a 4-voxel row, and both halves pooled.
    /// let at = |x: usize| {
    ///     let mut v = vec![0f32; 4 * 4];
    ///     v[x] = 50.0;
    ///     for c in 1..4 { v[c * 4 + x] = 0.5; }
    ///     LayoutPoints::from_volume(&Tensor::from_vec(v, (4, 1, 1, 4), &Device::Cpu)?, 0.5)
    /// };
    /// let pooled = LayoutPoints::pooled(&[at(0)?, at(3)?]);
    /// assert_eq!(pooled.len(), 2);
    /// // Half the matter moves by 1.5 along x: half as far as moving all of it.
    /// let (half, all) = (layout_distance(&at(0)?, &pooled, 64, 0)?, layout_distance(&at(0)?, &at(3)?, 64, 0)?);
    /// assert!((half - all / 2.0).abs() < 1e-9, "{half} {all}");
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    #[must_use]
    pub fn pooled(sets: &[LayoutPoints]) -> Self {
        let kept: Vec<&LayoutPoints> = sets.iter().filter(|set| !set.is_empty()).collect();
        let share = 1.0 / kept.len().max(1) as f64;
        let mut pooled = Self {
            points: Vec::new(),
            weights: Vec::new(),
        };
        for set in kept {
            pooled.points.extend_from_slice(&set.points);
            pooled.weights.extend(set.weights.iter().map(|w| w * share));
        }
        pooled
    }

    /// `set`'s points with other weights (one per point, renormalised to sum to 1); points
    /// of weight 0 are left out.
    pub(crate) fn reweighted(set: &LayoutPoints, weights: Vec<f64>) -> Self {
        let total: f64 = weights.iter().sum();
        let (points, weights) = set
            .points
            .iter()
            .zip(weights)
            .filter(|(_, w)| *w > 0.0)
            .map(|(p, w)| (*p, w / total))
            .unzip();
        Self { points, weights }
    }

    /// The number of points (voxels holding matter).
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there are no points (the volume held no matter).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The points projected onto `direction`, sorted, with their weights.
    fn projected(&self, direction: &[f64; DIMS]) -> Vec<(f64, f64)> {
        let mut projected: Vec<(f64, f64)> = self
            .points
            .iter()
            .zip(&self.weights)
            .map(|(p, &w)| {
                let along = p
                    .iter()
                    .zip(direction)
                    .map(|(&x, &d)| f64::from(x) * d)
                    .sum::<f64>();
                (along, w)
            })
            .collect();
        projected.sort_by(|a, b| a.0.total_cmp(&b.0));
        projected
    }
}

/// Directions a [`layout_distance`] averages over unless told otherwise.
pub const LAYOUT_DIRECTIONS: usize = 128;

/// The sliced Wasserstein-1 distance between two volumes' matter: the mean over `directions`
/// random unit directions of `(x, y, z, r, g, b)` (drawn from `seed`, the same for every pair
/// so that distances compare) of the exact 1D W1 distance between the weighted projections.
/// 0 for the same matter; symmetric; infinite when one volume holds no matter and the other
/// does (its matter has nowhere to go), 0 when neither does.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use scene_metrics::{layout_distance, LayoutPoints};
/// // One grey voxel, at either end of a 4-voxel row.
/// let row = |x: usize| {
///     let mut v = vec![0f32; 4 * 4];
///     v[x] = 50.0;
///     for c in 1..4 { v[c * 4 + x] = 0.5; }
///     LayoutPoints::from_volume(&Tensor::from_vec(v, (4, 1, 1, 4), &Device::Cpu)?, 0.5)
/// };
/// let (left, right) = (row(0)?, row(3)?);
/// assert_eq!(layout_distance(&left, &left, 64, 0)?, 0.0);
/// let apart = layout_distance(&left, &right, 64, 0)?;
/// assert!(apart > 0.2, "moved 1.5 along x: {apart}");
/// assert_eq!(apart, layout_distance(&right, &left, 64, 0)?);
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn layout_distance(
    a: &LayoutPoints,
    b: &LayoutPoints,
    directions: usize,
    seed: u64,
) -> Result<f64> {
    sliced_w1(a, b, directions, seed, Slice::All)
}

/// [`layout_distance`] by position alone: the same sliced Wasserstein-1 distance over random
/// unit directions of `(x, y, z)`, colours left out. Where it stays as the layout distance
/// grows, two volumes' matter stands in the same places in other colours (a sample's tint, a
/// blurred texture); where it grows too, the matter has moved.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use scene_metrics::{layout_distance, layout_distance_by_position, LayoutPoints};
/// // One dense voxel at either end of a 4-voxel row, red or grey.
/// let voxel = |x: usize, grey: bool| {
///     let mut v = vec![0f32; 4 * 4];
///     v[x] = 50.0;
///     for c in 1..4 { v[c * 4 + x] = if grey || c == 1 { 0.5 } else { 0.0 }; }
///     LayoutPoints::from_volume(&Tensor::from_vec(v, (4, 1, 1, 4), &Device::Cpu)?, 0.5)
/// };
/// let (red, grey, moved) = (voxel(0, false)?, voxel(0, true)?, voxel(3, false)?);
/// assert!(layout_distance(&red, &grey, 64, 0)? > 0.1);
/// assert_eq!(layout_distance_by_position(&red, &grey, 64, 0)?, 0.0);
/// // Moved by 1.5 along x: the mean over 3D directions of |1.5 d_x|, 1.5 / 2.
/// let apart = layout_distance_by_position(&red, &moved, 4096, 0)?;
/// assert!((apart - 0.75).abs() < 0.02, "{apart}");
/// # Ok::<(), scene_metrics::Error>(())
/// ```
pub fn layout_distance_by_position(
    a: &LayoutPoints,
    b: &LayoutPoints,
    directions: usize,
    seed: u64,
) -> Result<f64> {
    sliced_w1(a, b, directions, seed, Slice::Position)
}

/// Which coordinates of the points a sliced distance projects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Slice {
    /// Position and colour.
    All,
    /// Position alone.
    Position,
}

/// The sliced Wasserstein-1 distance between two weighted point sets over the coordinates
/// `slice` names: [`layout_distance`]'s definition.
pub(crate) fn sliced_w1(
    a: &LayoutPoints,
    b: &LayoutPoints,
    directions: usize,
    seed: u64,
    slice: Slice,
) -> Result<f64> {
    if directions == 0 {
        return Err(invalid("directions", "need at least one"));
    }
    match (a.is_empty(), b.is_empty()) {
        (true, true) => return Ok(0.0),
        (true, false) | (false, true) => return Ok(f64::INFINITY),
        (false, false) => {}
    }
    let used = match slice {
        Slice::All => DIMS,
        Slice::Position => 3,
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut total = 0.0;
    for _ in 0..directions {
        let direction = random_direction(&mut rng, used);
        total += wasserstein_1d(&a.projected(&direction), &b.projected(&direction));
    }
    Ok(total / directions as f64)
}

/// A uniformly random unit vector in the first `used` of `DIMS` coordinates (the rest 0).
fn random_direction(rng: &mut impl rand::Rng, used: usize) -> [f64; DIMS] {
    loop {
        let mut d = [0.0; DIMS];
        for x in &mut d[..used] {
            *x = StandardNormal.sample(rng);
        }
        let norm = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-12 {
            return d.map(|x| x / norm);
        }
    }
}

/// The exact W1 distance between two weighted 1D distributions, each sorted by value with
/// weights summing to 1: the integral over q in (0, 1) of the distance between their quantile
/// functions, summed over the pieces on which both are constant.
fn wasserstein_1d(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    let (mut i, mut j) = (0, 0);
    let (mut left_a, mut left_b) = (a[0].1, b[0].1);
    let mut distance = 0.0;
    loop {
        let step = left_a.min(left_b);
        distance += step * (a[i].0 - b[j].0).abs();
        left_a -= step;
        left_b -= step;
        // The piece that ran out moves on; the last piece of each ends both (rounding aside).
        if left_a <= 1e-15 {
            i += 1;
            if i == a.len() {
                break;
            }
            left_a = a[i].1;
        }
        if left_b <= 1e-15 {
            j += 1;
            if j == b.len() {
                break;
            }
            left_b = b[j].1;
        }
    }
    distance
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};
    use rand::SeedableRng;

    use super::{
        layout_distance, random_direction, wasserstein_1d, LayoutPoints, LayoutWeighting, DIMS,
    };

    /// A physical `(4, n, n, n)` volume with grey matter of density 40 in the cells `solid`
    /// says, colour `rgb` there.
    fn volume(n: usize, rgb: [f32; 3], solid: impl Fn(usize, usize, usize) -> bool) -> Tensor {
        let cells = n * n * n;
        let mut v = vec![0f32; 4 * cells];
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    if solid(x, y, z) {
                        let i = (z * n + y) * n + x;
                        v[i] = 40.0;
                        for c in 0..3 {
                            v[(c + 1) * cells + i] = rgb[c];
                        }
                    }
                }
            }
        }
        Tensor::from_vec(v, (4, n, n, n), &Device::Cpu).unwrap()
    }

    #[test]
    fn a_translation_costs_its_length_along_each_direction() {
        // A 2 x 2 x 2 block moved by one voxel (2/8 of the normalised box) along x: every
        // direction's projections are the same distribution shifted by 0.25 * |theta_x|.
        let n = 8;
        let block = |dx: usize| {
            volume(n, [0.5; 3], move |x, y, z| {
                (2 + dx..4 + dx).contains(&x) && (2..4).contains(&y) && (2..4).contains(&z)
            })
        };
        let (a, b) = (
            LayoutPoints::from_volume(&block(0), 0.25).unwrap(),
            LayoutPoints::from_volume(&block(1), 0.25).unwrap(),
        );
        let (directions, seed) = (64, 7);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let expected = (0..directions)
            .map(|_| 0.25 * random_direction(&mut rng, DIMS)[0].abs())
            .sum::<f64>()
            / directions as f64;
        let got = layout_distance(&a, &b, directions, seed).unwrap();
        assert!((got - expected).abs() < 1e-6, "{got} against {expected}");
    }

    #[test]
    fn matter_in_the_middle_is_farther_from_a_ring_than_the_ring_turned() {
        // A ring of blocks, the same ring turned by a quarter of its spacing, and the ring's
        // matter piled in the middle: the arrangement issue's case in miniature.
        let n = 24;
        let ring = |turn: f32| {
            move |x: usize, y: usize, z: usize| {
                let (px, py) = (x as f32 - 11.5, y as f32 - 11.5);
                let angle = py.atan2(px) + turn;
                let radius = (px * px + py * py).sqrt();
                let on_stone = (angle * 8.0 / std::f32::consts::TAU).rem_euclid(1.0) < 0.3;
                (7.0..10.0).contains(&radius) && on_stone && z < 6
            }
        };
        let scene = LayoutPoints::from_volume(&volume(n, [0.5; 3], ring(0.0)), 0.1).unwrap();
        let turned = LayoutPoints::from_volume(&volume(n, [0.5; 3], ring(0.2)), 0.1).unwrap();
        let heap = LayoutPoints::from_volume(
            &volume(n, [0.5; 3], |x, y, z| {
                (9..15).contains(&x) && (9..15).contains(&y) && z < 6
            }),
            0.1,
        )
        .unwrap();
        let near = layout_distance(&scene, &turned, 128, 0).unwrap();
        let far = layout_distance(&scene, &heap, 128, 0).unwrap();
        assert!(far > 3.0 * near, "heap {far}, turned ring {near}");
    }

    #[test]
    fn seen_from_above_weighs_opacity_by_the_transmittance_above() {
        // One column of two voxels of opacity 1/2 each (sigma ln 2 per unit voxel): from above
        // the top one weighs 1/2, the lower 1/2 x 1/2, normalised 2/3 and 1/3.
        let sigma = std::f32::consts::LN_2;
        let v = vec![sigma, sigma, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5];
        let column = Tensor::from_vec(v, (4, 2, 1, 1), &Device::Cpu).unwrap();
        let seen = LayoutPoints::from_volume_weighted(&column, 1.0, LayoutWeighting::SeenFromAbove)
            .unwrap();
        let mut pairs: Vec<(f32, f64)> = seen
            .points
            .iter()
            .zip(&seen.weights)
            .map(|(p, &w)| (p[2], w))
            .collect();
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(pairs.len(), 2);
        assert!(
            (pairs[0].1 - 1.0 / 3.0).abs() < 1e-6 && pairs[0].0 < 0.0,
            "{pairs:?}"
        );
        assert!(
            (pairs[1].1 - 2.0 / 3.0).abs() < 1e-6 && pairs[1].0 > 0.0,
            "{pairs:?}"
        );
        let all = LayoutPoints::from_volume(&column, 1.0).unwrap();
        assert!(all.weights.iter().all(|&w| (w - 0.5).abs() < 1e-6));
    }

    #[test]
    fn hidden_matter_does_not_count_seen_from_above() {
        // The same opaque top layer; below it solid ground in one volume, empty in the other.
        let n = 6;
        let top = volume(n, [0.3, 0.6, 0.2], |_, _, z| z == 4);
        let solid = volume(n, [0.3, 0.6, 0.2], |_, _, z| z <= 4);
        let weighted =
            |v: &Tensor, weighting| LayoutPoints::from_volume_weighted(v, 1.0, weighting).unwrap();
        let seen = LayoutWeighting::SeenFromAbove;
        let d = layout_distance(&weighted(&top, seen), &weighted(&solid, seen), 64, 0).unwrap();
        assert!(d < 1e-9, "{d}");
        let all = LayoutWeighting::Opacity;
        let d = layout_distance(&weighted(&top, all), &weighted(&solid, all), 64, 0).unwrap();
        assert!(d > 0.1, "{d}");
    }

    #[test]
    fn colour_counts_beside_position() {
        let cube = |x: usize, y: usize, z: usize| x < 2 && y < 2 && z < 2;
        let grey = LayoutPoints::from_volume(&volume(4, [0.5; 3], cube), 0.5).unwrap();
        let green = LayoutPoints::from_volume(&volume(4, [0.2, 0.8, 0.2], cube), 0.5).unwrap();
        assert!(layout_distance(&grey, &green, 64, 0).unwrap() > 0.05);
    }

    #[test]
    fn empty_volumes_are_infinitely_far_and_bad_input_is_refused() {
        let empty = volume(4, [0.5; 3], |_, _, _| false);
        let nothing = LayoutPoints::from_volume(&empty, 0.5).unwrap();
        assert!(nothing.is_empty());
        let row = LayoutPoints::from_volume(&volume(4, [0.5; 3], |x, _, _| x == 1), 0.5).unwrap();
        assert_eq!(
            layout_distance(&nothing, &row, 8, 0).unwrap(),
            f64::INFINITY
        );
        assert_eq!(
            layout_distance(&row, &nothing, 8, 0).unwrap(),
            f64::INFINITY
        );
        assert_eq!(layout_distance(&nothing, &nothing, 8, 0).unwrap(), 0.0);
        let three = Tensor::zeros((3, 2, 2, 2), candle_core::DType::F32, &Device::Cpu).unwrap();
        assert!(LayoutPoints::from_volume(&three, 0.5).is_err());
        let some = volume(4, [0.5; 3], |x, _, _| x == 0);
        assert!(LayoutPoints::from_volume(&some, 0.0).is_err());
        let points = LayoutPoints::from_volume(&some, 0.5).unwrap();
        assert!(layout_distance(&points, &points, 0, 0).is_err());
    }

    #[test]
    fn one_dimensional_w1_matches_hand_derived_values() {
        // Two points of equal weight against one point: (|0 - 1| + |2 - 1|) / 2 = 1.
        assert!((wasserstein_1d(&[(0.0, 0.5), (2.0, 0.5)], &[(1.0, 1.0)]) - 1.0).abs() < 1e-12);
        // A shift by 3 of any distribution costs 3.
        let a = [(0.0, 0.25), (1.0, 0.25), (4.0, 0.5)];
        let b: Vec<_> = a.iter().map(|&(x, w)| (x + 3.0, w)).collect();
        assert!((wasserstein_1d(&a, &b) - 3.0).abs() < 1e-12);
        // Weights 0.75 / 0.25 at 0 and 1 against 0.25 / 0.75: half the mass moves by 1.
        let c = [(0.0, 0.75), (1.0, 0.25)];
        let d = [(0.0, 0.25), (1.0, 0.75)];
        assert!((wasserstein_1d(&c, &d) - 0.5).abs() < 1e-12);
        assert_eq!(wasserstein_1d(&c, &c), 0.0);
    }

    #[test]
    fn directions_are_unit_vectors() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
        for _ in 0..10 {
            let d = super::random_direction(&mut rng, DIMS);
            assert_eq!(d.len(), DIMS);
            assert!((d.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }
}
