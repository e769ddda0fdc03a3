//! Objects: separate things standing on the ground, counted and sized.
//!
//! The layout metrics see where matter is, not whether it forms the scene's separate things: a
//! sample whose neighbouring stones have run together into one blob puts its matter in the
//! same places as the scene. [`Objects::of`] finds a volume's objects as the pieces of solid
//! matter that stand above its ground:
//!
//! 1. **Solid matter**: voxels of density at least [`ObjectRule::density`] (per world length).
//! 2. **The ground**: per column (x, y) the height of the top surface, where the light of a ray
//!    straight down from the top of the box falls below one half, then a morphological opening
//!    (a minimum, then a maximum, over a square window of [`ObjectRule::ground_window`] of the
//!    box's width) of that height map: what is narrower than the window (stones, stems, trees)
//!    is taken off, the ground under it (a mound, ripples) stays. Columns the ray crosses
//!    without meeting a surface have no ground and take no part in the window.
//! 3. **Objects**: the face-connected (6-neighbour) pieces of solid matter more than
//!    [`ObjectRule::clearance`] of the box's height (plus one voxel, the height map's step)
//!    above the ground of their column. A sample
//!    whose stones touch counts one object where the scene has two.
//!
//! Each object has its volume (a share of the box) and its mean colour; [`Objects::count`]
//! counts those of at least a given volume (small crumbs of matter are not things), and
//! [`Objects::largest_share`] is the largest object's share of all the volume's object matter.

use candle_core::Tensor;

use crate::error::{invalid, Result};
use crate::matter_kinds::MatterKinds;

/// How [`Objects::of`] tells objects from the ground and from empty space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectRule {
    /// Density (per world length) from which a voxel is solid matter.
    pub density: f32,
    /// Height above the ground (a share of the box's height; one voxel more is added for the
    /// height map's steps) from which solid matter belongs to an object.
    pub clearance: f32,
    /// Width of the window whose opening of the top-surface height map is the ground (a share of
    /// the box's width): wider than the widest object, narrower than the ground's hills.
    pub ground_window: f32,
}

/// Density of solid matter of the default rule: a slab of a stone's thinnest side (0.07 of the
/// box's half-width) at this density stops 75% of the light crossing it; the built-in scenes'
/// solids hold 60.
pub const OBJECT_DENSITY: f32 = 20.0;

/// Clearance of the default rule: 2% of the box's height, a voxel at 50^3.
pub const OBJECT_CLEARANCE: f32 = 0.02;

/// Ground window of the default rule: a fifth of the box's width (0.4 world units in the
/// model's cube), wider than a stone's or a mushroom's footprint (at most 0.3), across which
/// the stones' mound drops by less than the clearance.
pub const OBJECT_GROUND_WINDOW: f32 = 0.2;

impl Default for ObjectRule {
    fn default() -> Self {
        Self {
            density: OBJECT_DENSITY,
            clearance: OBJECT_CLEARANCE,
            ground_window: OBJECT_GROUND_WINDOW,
        }
    }
}

/// One object: a face-connected piece of solid matter above the ground.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// Its voxels.
    pub voxels: usize,
    /// Its volume as a share of the box's.
    pub volume: f64,
    /// Its mean colour (RGB in [0, 1]).
    pub colour: [f64; 3],
    /// The centre of its voxels in the box normalised to `[-1, 1]^3` (x, y, z).
    pub centre: [f64; 3],
}

/// The objects of a volume, largest first.
#[derive(Debug, Clone, PartialEq)]
pub struct Objects {
    objects: Vec<Object>,
}

impl Objects {
    /// The objects of a physical volume `(C >= 4, D, H, W)` (density, then RGB) whose voxels
    /// are `voxel` world units long, as `rule` defines them (z is up: depth index 0 is the
    /// bottom of the box).
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use scene_metrics::{ObjectRule, Objects};
    /// // A 20^3 box: solid ground in the lowest 4 layers, two 2x2x6 posts on it, 4 voxels apart.
    /// let n = 20;
    /// let mut v = vec![0f32; 4 * n * n * n];
    /// for z in 0..n {
    ///     for y in 0..n {
    ///         for x in 0..n {
    ///             let post = (8..10).contains(&y) && ((4..6).contains(&x) || (10..12).contains(&x));
    ///             if z < 4 || (post && z < 10) {
    ///                 v[(z * n + y) * n + x] = 60.0;
    ///             }
    ///         }
    ///     }
    /// }
    /// let volume = Tensor::from_vec(v, (4, n, n, n), &Device::Cpu)?;
    /// let objects = Objects::of(&volume, 2.0 / n as f32, &ObjectRule::default())?;
    /// assert_eq!(objects.count(0.0), 2);
    /// assert!((objects.largest_share() - 0.5).abs() < 1e-9);
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    pub fn of(volume: &Tensor, voxel: f32, rule: &ObjectRule) -> Result<Self> {
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
        check_rule(rule)?;
        let values: Vec<f32> = volume.narrow(0, 0, 4)?.flatten_all()?.to_vec1()?;
        let cells = d * h * w;
        let density = &values[..cells];
        if let Some(bad) = density.iter().position(|s| !s.is_finite() || *s < 0.0) {
            let (x, y, z) = (bad % w, bad / w % h, bad / (w * h));
            return Err(invalid(
                "volume",
                format!(
                    "density {} at voxel ({x}, {y}, {z}) (expected >= 0)",
                    density[bad]
                ),
            ));
        }
        let surface = top_surface(density, [d, h, w], voxel);
        let window = ((rule.ground_window * w.max(h) as f32).round() as usize).max(1);
        let ground = opening(&surface, h, w, window);
        // The height map is whole voxels, so the opened ground steps by one: a voxel more.
        let clearance = rule.clearance * d as f32 + 1.0;
        let above = |cell: usize| -> bool {
            let column = cell % (h * w);
            density[cell] >= rule.density
                && ground[column].is_none_or(|g| (cell / (h * w)) as f32 > g + clearance)
        };
        let pieces = face_connected_pieces(cells, [d, h, w], above);
        let mut objects: Vec<Object> = pieces
            .into_iter()
            .map(|piece| describe(&piece, &values, [d, h, w]))
            .collect();
        objects.sort_by_key(|object| std::cmp::Reverse(object.voxels));
        Ok(Self { objects })
    }

    /// Every object, largest first.
    pub fn all(&self) -> &[Object] {
        &self.objects
    }

    /// How many objects have a volume (share of the box) of at least `min_volume`.
    pub fn count(&self, min_volume: f64) -> usize {
        self.objects
            .iter()
            .filter(|o| o.volume >= min_volume)
            .count()
    }

    /// Per kind of `kinds` (in [`MatterKinds::colours`]' order), how many objects of at least
    /// `min_volume` have their mean colour nearest that kind's.
    pub fn count_by_kind(&self, kinds: &MatterKinds, min_volume: f64) -> Vec<usize> {
        let mut counts = vec![0; kinds.len()];
        for object in self.objects.iter().filter(|o| o.volume >= min_volume) {
            counts[kinds.nearest(&object.colour)] += 1;
        }
        counts
    }

    /// The largest object's share of all the object matter (0 without objects): 1 when all of
    /// it has run together into one piece.
    pub fn largest_share(&self) -> f64 {
        let total: f64 = self.objects.iter().map(|o| o.volume).sum();
        match self.objects.first() {
            Some(largest) if total > 0.0 => largest.volume / total,
            _ => 0.0,
        }
    }

    /// The median volume of the objects of at least `min_volume` (None without any).
    pub fn median_volume(&self, min_volume: f64) -> Option<f64> {
        let volumes: Vec<f64> = self
            .objects
            .iter()
            .map(|o| o.volume)
            .filter(|&v| v >= min_volume)
            .collect();
        // Largest first: the middle one (the upper middle for an even count).
        (!volumes.is_empty()).then(|| volumes[(volumes.len() - 1) / 2])
    }
}

fn check_rule(rule: &ObjectRule) -> Result<()> {
    if !(rule.density.is_finite() && rule.density > 0.0) {
        return Err(invalid(
            "density",
            format!("expected a density > 0, got {}", rule.density),
        ));
    }
    if !(rule.clearance.is_finite() && (0.0..1.0).contains(&rule.clearance)) {
        return Err(invalid(
            "clearance",
            format!(
                "expected a share of the box in [0, 1), got {}",
                rule.clearance
            ),
        ));
    }
    if !(rule.ground_window.is_finite() && rule.ground_window > 0.0 && rule.ground_window <= 1.0) {
        return Err(invalid(
            "ground_window",
            format!(
                "expected a share of the box in (0, 1], got {}",
                rule.ground_window
            ),
        ));
    }
    Ok(())
}

/// Per column (row-major y, x), the depth index of the top surface: the voxel where a ray
/// straight down from the top of the box has lost half its light (None where it keeps more).
fn top_surface(density: &[f32], [d, h, w]: [usize; 3], voxel: f32) -> Vec<Option<f32>> {
    (0..h * w)
        .map(|column| {
            let mut optical_depth = 0.0f64;
            for z in (0..d).rev() {
                optical_depth += f64::from(density[z * h * w + column]) * f64::from(voxel);
                if optical_depth >= std::f64::consts::LN_2 {
                    return Some(z as f32);
                }
            }
            None
        })
        .collect()
}

/// The morphological opening of a height map (row-major `h x w`, None for columns without a
/// surface) with a `window x window` square: the minimum over each window, then the maximum of
/// those minima, each over the columns that have a value. A column keeps None only where no
/// column of its windows has a surface.
fn opening(heights: &[Option<f32>], h: usize, w: usize, window: usize) -> Vec<Option<f32>> {
    let eroded = filter(heights, h, w, window, f32::min);
    let opened = filter(&eroded, h, w, window, f32::max);
    // Where the eroded map had nothing to give (no surface near), the column keeps its own.
    opened
        .into_iter()
        .zip(heights)
        .map(|(o, &own)| o.or(own))
        .collect()
}

/// `pick` (min or max) over the `window x window` square centred on each column, skipping
/// columns without a value; separable (rows, then columns).
fn filter(
    values: &[Option<f32>],
    h: usize,
    w: usize,
    window: usize,
    pick: fn(f32, f32) -> f32,
) -> Vec<Option<f32>> {
    let (before, after) = (window / 2, window - 1 - window / 2);
    let reduce = |items: &mut dyn Iterator<Item = Option<f32>>| -> Option<f32> {
        items.flatten().reduce(pick)
    };
    let mut rows = vec![None; h * w];
    for y in 0..h {
        for x in 0..w {
            let (from, to) = (x.saturating_sub(before), (x + after).min(w - 1));
            rows[y * w + x] = reduce(&mut (from..=to).map(|i| values[y * w + i]));
        }
    }
    let mut out = vec![None; h * w];
    for y in 0..h {
        let (from, to) = (y.saturating_sub(before), (y + after).min(h - 1));
        for x in 0..w {
            out[y * w + x] = reduce(&mut (from..=to).map(|j| rows[j * w + x]));
        }
    }
    out
}

/// The face-connected pieces of the cells where `inside` holds (cell = `(z * h + y) * w + x`),
/// each as its list of cells.
fn face_connected_pieces(
    cells: usize,
    [d, h, w]: [usize; 3],
    inside: impl Fn(usize) -> bool,
) -> Vec<Vec<usize>> {
    let mut seen = vec![false; cells];
    let mut pieces = Vec::new();
    let mut stack = Vec::new();
    for start in 0..cells {
        if seen[start] || !inside(start) {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let mut piece = Vec::new();
        while let Some(cell) = stack.pop() {
            piece.push(cell);
            let (x, y, z) = (cell % w, cell / w % h, cell / (w * h));
            let neighbours = [
                (x > 0).then(|| cell - 1),
                (x + 1 < w).then(|| cell + 1),
                (y > 0).then(|| cell - w),
                (y + 1 < h).then(|| cell + w),
                (z > 0).then(|| cell - w * h),
                (z + 1 < d).then(|| cell + w * h),
            ];
            for next in neighbours.into_iter().flatten() {
                if !seen[next] && inside(next) {
                    seen[next] = true;
                    stack.push(next);
                }
            }
        }
        pieces.push(piece);
    }
    pieces
}

/// A piece's size, mean colour and centre.
fn describe(piece: &[usize], values: &[f32], [d, h, w]: [usize; 3]) -> Object {
    let cells = d * h * w;
    let (mut colour, mut centre) = ([0.0f64; 3], [0.0f64; 3]);
    let normalised = |i: usize, n: usize| 2.0 * (i as f64 + 0.5) / n as f64 - 1.0;
    for &cell in piece {
        for (c, sum) in colour.iter_mut().enumerate() {
            *sum += f64::from(values[(c + 1) * cells + cell]);
        }
        centre[0] += normalised(cell % w, w);
        centre[1] += normalised(cell / w % h, h);
        centre[2] += normalised(cell / (w * h), d);
    }
    let count = piece.len() as f64;
    Object {
        voxels: piece.len(),
        volume: count / cells as f64,
        colour: colour.map(|c| c / count),
        centre: centre.map(|c| c / count),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    /// A grey `n^3` volume with density `density(x, y, z)` (z up).
    fn volume_of(n: usize, density: impl Fn(usize, usize, usize) -> f32) -> Tensor {
        let mut v = vec![0.5f32; 4 * n * n * n];
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    v[(z * n + y) * n + x] = density(x, y, z);
                }
            }
        }
        Tensor::from_vec(v, (4, n, n, n), &Device::Cpu).unwrap()
    }

    /// Density `solid` where `inside(x, y, z)`, 0 elsewhere.
    fn volume(n: usize, solid: f32, inside: impl Fn(usize, usize, usize) -> bool) -> Tensor {
        volume_of(n, |x, y, z| if inside(x, y, z) { solid } else { 0.0 })
    }

    fn objects(v: &Tensor) -> Objects {
        let n = v.dim(1).unwrap();
        Objects::of(v, 2.0 / n as f32, &ObjectRule::default()).unwrap()
    }

    #[test]
    fn posts_on_a_mound_are_objects_and_the_mound_is_ground() {
        // A dome of ground rising 3 voxels at the middle of a 40^3 box (at most 0.13 voxels
        // per voxel across, as steep as the stones' mound), with three posts of 2x2 voxels
        // standing on it: one on the top, two on its flanks.
        let n = 40;
        let ground = |x: usize, y: usize| {
            let (dx, dy) = (x as f32 - 20.0, y as f32 - 20.0);
            10.0 + 3.0 * (-(dx * dx + dy * dy) / 400.0).exp()
        };
        let posts = [(19, 19), (8, 20), (30, 12)];
        let v = volume(n, 60.0, |x, y, z| {
            let post = posts
                .iter()
                .any(|&(px, py)| (px..px + 2).contains(&x) && (py..py + 2).contains(&y));
            (z as f32) < ground(x, y) || (post && (z as f32) < ground(x, y) + 8.0)
        });
        let found = objects(&v);
        assert_eq!(found.count(0.0), 3, "{:?}", found.all());
        // Each about 2 x 2 x 8 voxels; no ground among them.
        assert!(found.all().iter().all(|o| (24..=36).contains(&o.voxels)));
        assert!(found.largest_share() < 0.4);
    }

    #[test]
    fn touching_posts_are_one_object_and_a_gap_of_one_voxel_keeps_them_apart() {
        let n = 32;
        let with_gap = |gap: usize| {
            volume(n, 60.0, move |x, y, z| {
                let post = (14..16).contains(&y)
                    && ((10..13).contains(&x) || (13 + gap..16 + gap).contains(&x));
                z < 6 || (post && z < 14)
            })
        };
        assert_eq!(objects(&with_gap(0)).count(0.0), 1);
        assert!((objects(&with_gap(0)).largest_share() - 1.0).abs() < 1e-12);
        assert_eq!(objects(&with_gap(1)).count(0.0), 2);
    }

    #[test]
    fn thin_fog_and_crumbs_are_not_objects_and_an_empty_box_has_none() {
        let n = 24;
        // Fog of density 5 everywhere above solid ground: below the solid density.
        let fog = volume_of(n, |_, _, z| if z < 5 { 60.0 } else { 5.0 });
        assert_eq!(objects(&fog).count(0.0), 0);
        // One voxel above the ground is a crumb: counted with no minimum, not with one.
        let crumb = volume(n, 60.0, |x, y, z| z < 5 || (x, y, z) == (12, 12, 9));
        let found = objects(&crumb);
        assert_eq!(found.count(0.0), 1);
        assert_eq!(found.count(2.0 / (n * n * n) as f64), 0);
        assert_eq!(objects(&volume(n, 0.0, |_, _, _| false)).count(0.0), 0);
        assert_eq!(
            objects(&volume(n, 0.0, |_, _, _| false)).largest_share(),
            0.0
        );
    }

    #[test]
    fn bad_input_is_refused() {
        let v = volume(4, 60.0, |_, _, z| z < 1);
        for voxel in [0.0, -1.0, f32::NAN] {
            assert!(Objects::of(&v, voxel, &ObjectRule::default()).is_err());
        }
        let rule = ObjectRule {
            ground_window: 0.0,
            ..ObjectRule::default()
        };
        assert!(Objects::of(&v, 0.5, &rule).is_err());
        let negative = (v.clone() * -1.0).unwrap();
        let err = Objects::of(&negative, 0.5, &ObjectRule::default()).unwrap_err();
        assert!(err.to_string().contains("voxel (0, 0, 0)"), "{err}");
    }
}
