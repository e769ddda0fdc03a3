//! Matter out of place: the share of a volume's matter that stands where the scene has no
//! matter of its kind anywhere near.
//!
//! A distance from one exemplar ([`layout_distance`](crate::layout_distance),
//! [`kind_layout_distance`](crate::kind_layout_distance)) charges true variation as much as
//! error: a ring of stones turned, or a little wider, is as far from the scene's ring as stones
//! piled in its middle. What the scene does say of every variant is where each kind of its
//! matter may stand: grey stone near where the scene has grey stone, ground where it has ground.
//! [`MatterSupport`] holds that: for each of the scene's [`MatterKinds`], the places within
//! `reach` of the scene's matter of that kind. [`MatterSupport::misplaced`] is the share of a
//! volume's matter that falls outside the places of its kind. Stones moved along their ring by
//! less than `reach` cost nothing; stones moved into its middle cost their whole share.
//!
//! It is one-sided on purpose: a variant need not have matter everywhere the scene has it (a
//! ring with a stone fewer is a true variant), so missing matter is the image metrics' to see
//! (colour SWD sees a scene without stones). Nothing in it knows about a particular scene: the
//! kinds come from the scene's colours, the places from where those colours stand.

use crate::error::{invalid, Result};
use crate::layout::LayoutPoints;
use crate::matter_kinds::MatterKinds;

/// How far from the scene's matter of a kind a volume's matter of that kind may stand before it
/// counts as out of place, in the normalised box `[-1, 1]^3` (so 0.25 is an eighth of the box's
/// edge). Chosen by measurement: docs/metrics.md, "misplaced_matter".
pub const MISPLACED_REACH: f64 = 0.25;

/// Kinds of matter [`MatterSupport`] tells apart unless told otherwise (`volgen eval`'s).
/// Chosen by measurement: docs/metrics.md, "misplaced_matter".
pub const MISPLACED_KINDS: usize = 2;

/// The share of each kind's matter in the scene that makes its places: its heaviest points up to
/// this share, so that faint fog a fit of views leaves (or one stray voxel) does not make a
/// whole neighbourhood a place of that kind.
const SUPPORT_SHARE: f64 = 0.95;

/// Cells per axis of the grid over the normalised box that holds the places (cells of
/// 2/64 = 0.031: finer than any volume the metrics see, so a place's edge is within a cell of
/// `reach`).
const GRID: usize = 64;

/// Where each kind of a scene's matter may stand: within a reach of where the scene has it.
#[derive(Debug, Clone)]
pub struct MatterSupport {
    kinds: MatterKinds,
    reach: f64,
    /// Per kind, per cell of the `GRID^3` grid (x fastest): whether the cell's centre lies
    /// within `reach` of the scene's matter of that kind.
    near: Vec<Vec<bool>>,
}

impl MatterSupport {
    /// The places of `reference`'s matter by kind: for each of `kinds`, the heaviest of the
    /// reference's points of that kind carrying 95% of it (a point counted by its weight times
    /// its share of the kind, [`MatterKinds`]), and everything within `reach` of them (in the
    /// normalised box).
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use scene_metrics::{LayoutPoints, MatterKinds, MatterSupport};
    /// // A row of 8 voxels: green ground everywhere but one grey stone, at x = 1 or x = 6.
    /// let row = |stone: usize| {
    ///     let mut v = vec![0f32; 4 * 8];
    ///     v[..8].fill(50.0);
    ///     for x in 0..8 {
    ///         let rgb = if x == stone { [0.5, 0.5, 0.5] } else { [0.2, 0.7, 0.2] };
    ///         (0..3).for_each(|c| v[(c + 1) * 8 + x] = rgb[c]);
    ///     }
    ///     LayoutPoints::from_volume(&Tensor::from_vec(v, (4, 1, 1, 8), &Device::Cpu)?, 0.25)
    /// };
    /// let scene = row(1)?;
    /// let kinds = MatterKinds::of(&scene, 2, 0)?;
    /// let places = MatterSupport::of(&scene, kinds, 0.3)?;
    /// assert!(places.misplaced(&scene) < 1e-12);
    /// // The stone moved 5 voxels (1.25 of the normalised box) away: its eighth of the matter.
    /// assert!((places.misplaced(&row(6)?) - 1.0 / 8.0).abs() < 1e-9);
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    pub fn of(reference: &LayoutPoints, kinds: MatterKinds, reach: f64) -> Result<Self> {
        if !(reach.is_finite() && reach > 0.0) {
            return Err(invalid(
                "reach",
                format!("expected a distance > 0 in the normalised box, got {reach}"),
            ));
        }
        if kinds.is_empty() {
            return Err(invalid("kinds", "need at least one kind of matter"));
        }
        let shares: Vec<Vec<f64>> = reference.points.iter().map(|p| kinds.shares(p)).collect();
        let near = (0..kinds.len())
            .map(|kind| {
                let mass: Vec<f64> = reference
                    .weights
                    .iter()
                    .zip(&shares)
                    .map(|(w, s)| w * s[kind])
                    .collect();
                let mut near = vec![false; GRID * GRID * GRID];
                for point in heaviest(&mass, SUPPORT_SHARE) {
                    mark_within(&mut near, &reference.points[point], reach);
                }
                near
            })
            .collect();
        Ok(Self { kinds, reach, near })
    }

    /// The share of `volume`'s matter (by its weights) standing outside the places of its
    /// kind: 0 when all of it stands near the scene's matter of the same kind, 1 when none
    /// does. A point's weight is shared among the kinds by colour, as the places were made.
    /// An empty volume has no matter out of place (0).
    pub fn misplaced(&self, volume: &LayoutPoints) -> f64 {
        self.misplaced_by_kind(volume)
            .iter()
            .map(|(out, _)| out)
            .sum()
    }

    /// Per kind (in [`MatterKinds::colours`]' order), the share of `volume`'s matter of that
    /// kind standing outside its places: 0 for a kind `volume` has none of.
    pub fn misplaced_per_kind(&self, volume: &LayoutPoints) -> Vec<f64> {
        self.misplaced_by_kind(volume)
            .into_iter()
            .map(|(out, all)| if all > 0.0 { out / all } else { 0.0 })
            .collect()
    }

    /// The kinds the places are of.
    pub fn kinds(&self) -> &MatterKinds {
        &self.kinds
    }

    /// How far from the scene's matter a kind's places reach.
    pub fn reach(&self) -> f64 {
        self.reach
    }

    /// Per kind: (`volume`'s matter of the kind outside its places, all its matter of the kind),
    /// as shares of `volume`'s whole matter.
    fn misplaced_by_kind(&self, volume: &LayoutPoints) -> Vec<(f64, f64)> {
        let mut by_kind = vec![(0.0, 0.0); self.kinds.len()];
        for (point, &w) in volume.points.iter().zip(&volume.weights) {
            let cell = cell_of(point);
            for (kind, share) in self.kinds.shares(point).into_iter().enumerate() {
                let (out, all) = &mut by_kind[kind];
                *all += w * share;
                if !self.near[kind][cell] {
                    *out += w * share;
                }
            }
        }
        by_kind
    }
}

/// The indices of the heaviest entries of `mass` that together carry `share` of its total
/// (none when the total is 0).
fn heaviest(mass: &[f64], share: f64) -> Vec<usize> {
    let total: f64 = mass.iter().sum();
    if total <= 0.0 {
        return Vec::new();
    }
    let mut order: Vec<usize> = (0..mass.len()).filter(|&i| mass[i] > 0.0).collect();
    order.sort_by(|&a, &b| mass[b].total_cmp(&mass[a]));
    let mut carried = 0.0;
    let mut kept = Vec::new();
    for i in order {
        if carried >= share * total {
            break;
        }
        carried += mass[i];
        kept.push(i);
    }
    kept
}

/// The centre of grid cell `i` along an axis, in the normalised box.
fn cell_centre(i: usize) -> f64 {
    (2.0 * (i as f64 + 0.5) / GRID as f64) - 1.0
}

/// The cell index along an axis of coordinate `x` in the normalised box (clamped to the grid).
fn cell_index(x: f64) -> usize {
    (((x + 1.0) / 2.0 * GRID as f64).floor().max(0.0) as usize).min(GRID - 1)
}

/// The grid cell holding a point's position.
fn cell_of(point: &[f32; crate::layout::DIMS]) -> usize {
    let [x, y, z] = [0, 1, 2].map(|c| cell_index(f64::from(point[c])));
    (z * GRID + y) * GRID + x
}

/// Marks every cell whose centre lies within `reach` of `point`'s position.
fn mark_within(near: &mut [bool], point: &[f32; crate::layout::DIMS], reach: f64) {
    let centre = [0, 1, 2].map(|c| f64::from(point[c]));
    let range = |c: usize| cell_index(centre[c] - reach)..=cell_index(centre[c] + reach);
    for z in range(2) {
        let dz = cell_centre(z) - centre[2];
        for y in range(1) {
            let dy = cell_centre(y) - centre[1];
            for x in range(0) {
                let dx = cell_centre(x) - centre[0];
                if dx * dx + dy * dy + dz * dz <= reach * reach {
                    near[(z * GRID + y) * GRID + x] = true;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};

    use super::MatterSupport;
    use crate::test_slabs::slab;
    use crate::{LayoutPoints, MatterKinds};

    const GROUND: [f32; 3] = [0.2, 0.6, 0.2];
    const STONE: [f32; 3] = [0.55, 0.55, 0.55];

    /// Ground everywhere on a 16 x 16 slab, stone on the cells listed.
    fn with_stones(stones: &'static [(usize, usize)]) -> LayoutPoints {
        slab(16, move |x, y| {
            Some(if stones.contains(&(x, y)) {
                STONE
            } else {
                GROUND
            })
        })
    }

    /// Four stones near the corners: the "ring".
    const RING: &[(usize, usize)] = &[(1, 1), (14, 1), (1, 14), (14, 14)];

    fn places(scene: &LayoutPoints, reach: f64) -> MatterSupport {
        MatterSupport::of(scene, MatterKinds::of(scene, 2, 0).unwrap(), reach).unwrap()
    }

    #[test]
    fn the_scene_and_stones_moved_within_reach_have_nothing_out_of_place() {
        let scene = with_stones(RING);
        // Cells are 2/16 = 0.125 of the normalised box: stones moved by two cells (0.25)
        // stay within a reach of 0.3.
        let variant = with_stones(&[(3, 1), (14, 3), (1, 12), (12, 14)]);
        let support = places(&scene, 0.3);
        // Nothing but the e^-44 share of the stone kind that ground colours carry.
        assert!(support.misplaced(&scene) < 1e-15);
        assert!(support.misplaced(&variant) < 1e-15);
        // A reach shorter than the move: every moved stone is out of place, 4 of 256 cells.
        let tight = places(&scene, 0.2);
        assert!((tight.misplaced(&variant) - 4.0 / 256.0).abs() < 1e-9);
    }

    #[test]
    fn stones_in_the_middle_cost_their_share_of_the_matter() {
        let scene = with_stones(RING);
        let middle = with_stones(&[(7, 7), (8, 7), (7, 8), (8, 8)]);
        let support = places(&scene, 0.3);
        // The 4 stone cells of 256 stand far from every stone of the scene; the ground cells
        // where the scene's stones were are within reach of its ground.
        assert!((support.misplaced(&middle) - 4.0 / 256.0).abs() < 1e-9);
        // By kind: all of the stone kind, none of the ground.
        let per_kind = support.misplaced_per_kind(&middle);
        let stone = support
            .kinds()
            .colours()
            .iter()
            .position(|c| (c[0] - c[1]).abs() < 1e-3)
            .unwrap();
        assert!((per_kind[stone] - 1.0).abs() < 1e-9, "{per_kind:?}");
        assert!(per_kind[1 - stone].abs() < 1e-9, "{per_kind:?}");
        // Half the stones moved in, half kept: half the stone kind.
        let half = with_stones(&[(1, 1), (14, 14), (7, 7), (8, 8)]);
        let per_kind = support.misplaced_per_kind(&half);
        assert!((per_kind[stone] - 0.5).abs() < 1e-9, "{per_kind:?}");
    }

    #[test]
    fn faint_matter_of_a_kind_makes_no_place_for_it() {
        // The scene's stone kind: four solid stones and one faint stone-coloured voxel in the
        // middle, below 5% of the kind's matter: stones in the middle are still out of place.
        let n = 16;
        let mut v = vec![0f32; 4 * n * n];
        for y in 0..n {
            for x in 0..n {
                let i = y * n + x;
                let (density, rgb) = if RING.contains(&(x, y)) {
                    (40.0, STONE)
                } else if (x, y) == (8, 8) {
                    (0.05, STONE)
                } else {
                    (40.0, GROUND)
                };
                v[i] = density;
                (0..3).for_each(|c| v[(c + 1) * n * n + i] = rgb[c]);
            }
        }
        let scene = Tensor::from_vec(v, (4, 1, n, n), &Device::Cpu).unwrap();
        let scene = LayoutPoints::from_volume(&scene, 0.1).unwrap();
        let middle = with_stones(&[(7, 7), (8, 7), (7, 8), (8, 8)]);
        let support = places(&scene, 0.3);
        assert!((support.misplaced(&middle) - 4.0 / 256.0).abs() < 1e-9);
    }

    #[test]
    fn empty_volumes_and_bad_arguments() {
        let scene = with_stones(RING);
        let nothing = slab(4, |_, _| None);
        let support = places(&scene, 0.3);
        assert_eq!(support.misplaced(&nothing), 0.0);
        assert_eq!(support.misplaced_per_kind(&nothing), vec![0.0, 0.0]);
        let kinds = || MatterKinds::of(&scene, 2, 0).unwrap();
        for reach in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let error = MatterSupport::of(&scene, kinds(), reach).unwrap_err();
            assert!(error.to_string().contains("reach"), "{error}");
        }
        // A scene with no matter gives no places: everything is out of place.
        let empty = MatterSupport::of(&nothing, kinds(), 0.3).unwrap();
        assert!((empty.misplaced(&scene) - 1.0).abs() < 1e-9);
    }
}
