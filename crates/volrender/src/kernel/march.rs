//! Ray setup (box clipping, sample spacing) and the sample loop with exact empty-space skipping.

use crate::config::Sampler;

use super::Real;

/// The volume's box and cells in kernel precision.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GridSpec<T> {
    pub(crate) min: [T; 3],
    pub(crate) max: [T; 3],
    /// Cells along x, y, z.
    pub(crate) n: [usize; 3],
}

impl<T: Real> GridSpec<T> {
    fn voxel(&self, a: usize) -> T {
        (self.max[a] - self.min[a]) / T::of(self.n[a] as f64)
    }
}

/// One ray's samples: `n` samples at `t_i = t0 + (i + off) dt` (t in world length along the unit
/// direction), at index-space points `a + t b`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RayGeom<T> {
    pub(crate) a: [T; 3],
    pub(crate) b: [T; 3],
    pub(crate) t0: T,
    pub(crate) dt: T,
    pub(crate) off: T,
    pub(crate) n: usize,
}

/// Clips a ray to the box and spaces its samples; a ray that misses gets `n = 0`.
pub(crate) fn setup_ray<T: Real>(
    origin: [f32; 3],
    dir: [f32; 3],
    grid: &GridSpec<T>,
    sampler: Sampler,
) -> RayGeom<T> {
    let o = origin.map(|x| T::of(x as f64));
    let d = dir.map(|x| T::of(x as f64));
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = d.map(|x| x / len);
    let (mut t_near, mut t_far) = (T::neg_infinity(), T::infinity());
    let mut hit = true;
    for a in 0..3 {
        let (lo, hi) = (grid.min[a], grid.max[a]);
        if d[a] == T::zero() {
            // Parallel to this slab: inside it constrains nothing, outside it misses.
            hit &= o[a] >= lo && o[a] <= hi;
        } else {
            let (ta, tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
            t_near = t_near.max(ta.min(tb));
            t_far = t_far.min(ta.max(tb));
        }
    }
    // Rays starting inside the box start at t = 0.
    let t0 = t_near.max(T::zero());
    let voxel = [grid.voxel(0), grid.voxel(1), grid.voxel(2)];
    let a = [0, 1, 2].map(|k| (o[k] - grid.min[k]) / voxel[k] - T::of(0.5));
    let b = [0, 1, 2].map(|k| d[k] / voxel[k]);
    let mut geom = RayGeom {
        a,
        b,
        t0,
        dt: T::zero(),
        off: T::of(sampler.offset()),
        n: 0,
    };
    // A zero-length segment (a ray touching an edge or corner) has dt = 0 and contributes
    // exactly nothing: give it no samples, which also keeps `sigma * dt` free of `inf * 0`.
    if !(hit && t_far > t0 && t_far.is_finite()) {
        return geom;
    }
    let length = t_far - t0;
    geom.n = match sampler {
        Sampler::Uniform { samples } | Sampler::UniformLeft { samples } => samples,
        Sampler::PerVoxel { per_voxel } => {
            let step = voxel[0].min(voxel[1]).min(voxel[2]) / T::of(per_voxel as f64);
            (length / step).ceil().to_usize().unwrap_or(0)
        }
    };
    geom.dt = length / T::of(geom.n.max(1) as f64);
    if geom.dt == T::zero() {
        // The step underflowed: as above, nothing to integrate.
        geom.n = 0;
    }
    geom
}

/// An occupancy grid as the kernel sees it: cell `c` along an axis covers index coordinates
/// `[c k - 0.5, (c + 1) k - 0.5)` (voxels `c k .. (c + 1) k`, radiance-volume's layout), and an
/// empty cell has density exactly 0 everywhere inside it and up to half a voxel beyond.
#[derive(Debug, Clone, Copy)]
pub(crate) struct OccView<'a> {
    /// Per cell: the chessboard distance in cells to the nearest occupied cell (0: occupied).
    /// At distance `d`, the cube of cells within `d - 1` of it is all empty.
    pub(crate) distance: &'a [u8],
    /// Per voxel: the trilinear corner block with this lower corner has density exactly 0 (a
    /// finer, exact test for samples inside occupied cells).
    pub(crate) empty_block: &'a [bool],
    /// Cells along x, y, z.
    pub(crate) n: [usize; 3],
    pub(crate) k: usize,
}

/// What the occupancy grid says about a sample's cell.
enum Cell<T> {
    /// Occupied: no need to look again before `t` reaches `until` (the cell's exit).
    Occupied { until: T },
    /// Empty: continue at sample `next`, the first past the cell.
    Empty { next: usize },
}

/// One ray's walk through an occupancy grid, with the per-ray constants its cell lookups need
/// (so a lookup multiplies instead of dividing).
struct CellWalk<'a, T> {
    occ: &'a OccView<'a>,
    /// Voxels per cell, and its inverse.
    cell: T,
    inv_cell: T,
    /// The last cell's index per axis.
    last: [T; 3],
    /// `1 / b` per axis (unused along axes the ray is parallel to).
    inv_b: [T; 3],
    /// 1 where the ray leaves a cell through its upper face, 0 through its lower one.
    side: [T; 3],
    /// +1 or -1: the direction the ray crosses cells in.
    sign: [T; 3],
    inv_dt: T,
}

impl<'a, T: Real> CellWalk<'a, T> {
    fn new(occ: &'a OccView<'a>, g: &RayGeom<T>) -> Self {
        let cell = T::of(occ.k as f64);
        Self {
            occ,
            cell,
            inv_cell: T::one() / cell,
            last: occ.n.map(|n| T::of((n - 1) as f64)),
            inv_b: g.b.map(|b| T::one() / b),
            side: g
                .b
                .map(|b| if b > T::zero() { T::one() } else { T::zero() }),
            sign: g
                .b
                .map(|b| if b > T::zero() { T::one() } else { -T::one() }),
            inv_dt: T::one() / g.dt,
        }
    }

    /// Classifies the cell of sample `i` (at index point `u`) and finds where the ray leaves
    /// it or, when it is empty, the cube of empty cells around it. Samples before the exit are
    /// in that cell or cube up to rounding far below the half-voxel margin (as are samples that
    /// rounding puts in a neighbouring cell), so skipping them when it is empty is exact, and
    /// not re-checking them when it is occupied is merely conservative.
    #[inline(always)]
    fn classify(&self, g: &RayGeom<T>, u: [T; 3], i: usize) -> Cell<T> {
        let half = T::of(0.5);
        let mut cell = [0; 3];
        let mut flat = 0;
        let mut stride = 1;
        for a in 0..3 {
            // Plain comparisons compile to single min/max instructions (u is not NaN).
            let c = (u[a] + half) * self.inv_cell;
            let c = if c > T::zero() { c } else { T::zero() };
            let c = if c < self.last[a] { c } else { self.last[a] };
            // Truncation of a value >= 0 is floor.
            cell[a] = c.truncate_index();
            flat += cell[a] as usize * stride;
            stride *= self.occ.n[a];
        }
        let distance = self.occ.distance[flat];
        // Cells within `reach` of this one (along every axis) are empty too.
        let reach = T::of_index(u32::from(distance.max(1) - 1));
        let mut t_exit = T::infinity();
        for a in 0..3 {
            if g.b[a] != T::zero() {
                let face = T::of_index(cell[a]) + self.side[a] + reach * self.sign[a];
                let t = (face * self.cell - half - g.a[a]) * self.inv_b[a];
                t_exit = if t < t_exit { t } else { t_exit };
            }
        }
        if distance == 0 {
            return Cell::Occupied { until: t_exit };
        }
        // The first sample index at or past the exit, clamped to [0, n] before converting.
        let x = (t_exit - g.t0) * self.inv_dt - g.off;
        let x = if x > T::zero() { x } else { T::zero() };
        let n = T::of_index(g.n as u32);
        let x = if x < n { x } else { n };
        let mut next = x.truncate_index() as usize;
        if T::of_index(next as u32) < x {
            next += 1; // ceil
        }
        Cell::Empty {
            next: next.clamp(i + 1, g.n),
        }
    }
}

/// The samples of one ray in order, as `(i, t, u)` (index, distance and index-space point), passing over
/// samples in empty cells when an occupancy grid is given.
///
/// A cursor with an inlined `next` rather than a closure-taking loop: the per-sample code must
/// inline into the kernels' AVX2 builds (kernel/tile.rs), and a closure big enough to be worth
/// optimising is one LLVM declines to inline.
pub(crate) struct Marcher<'a, T> {
    g: &'a RayGeom<T>,
    walk: Option<CellWalk<'a, T>>,
    i: usize,
    checked_until: T,
}

impl<'a, T: Real> Marcher<'a, T> {
    /// Walks the samples from index `start` on.
    #[inline(always)]
    pub(crate) fn new(g: &'a RayGeom<T>, occ: Option<&'a OccView<'a>>, start: usize) -> Self {
        Self {
            g,
            walk: occ.filter(|_| g.n > 0).map(|o| CellWalk::new(o, g)),
            i: start,
            checked_until: T::neg_infinity(),
        }
    }

    /// Returns the next sample to evaluate as `(index, t, u)`, or `None` past the last one.
    #[inline(always)]
    pub(crate) fn next_sample(&mut self) -> Option<(usize, T, [T; 3])> {
        let g = self.g;
        while self.i < g.n {
            let i = self.i;
            let t = g.t0 + (T::of_index(i as u32) + g.off) * g.dt;
            let u = [
                g.a[0] + t * g.b[0],
                g.a[1] + t * g.b[1],
                g.a[2] + t * g.b[2],
            ];
            if let Some(walk) = &self.walk {
                if t >= self.checked_until {
                    match walk.classify(g, u, i) {
                        Cell::Occupied { until } => self.checked_until = until,
                        Cell::Empty { next } => {
                            self.i = next;
                            continue;
                        }
                    }
                }
            }
            self.i = i + 1;
            return Some((i, t, u));
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CUBE: GridSpec<f64> = GridSpec {
        min: [-1.0; 3],
        max: [1.0; 3],
        n: [4, 4, 4],
    };

    #[test]
    fn clipping_cases() {
        let s = Sampler::Uniform { samples: 4 };
        // From outside along -z: enters at t = 2, leaves at t = 4.
        let g = setup_ray([0.0, 0.0, 3.0], [0.0, 0.0, -2.0], &CUBE, s);
        assert_eq!((g.t0, g.dt, g.n), (2.0, 0.5, 4));
        // Starting inside: t starts at 0.
        let g = setup_ray([0.0, 0.0, 0.5], [0.0, 0.0, 1.0], &CUBE, s);
        assert_eq!((g.t0, g.dt), (0.0, 0.125));
        // Missing, and pointing away.
        assert_eq!(setup_ray([0.0, 2.0, 3.0], [0.0, 0.0, -1.0], &CUBE, s).n, 0);
        assert_eq!(setup_ray([0.0, 0.0, 3.0], [0.0, 0.0, 1.0], &CUBE, s).n, 0);
        // Grazing along a face is inside the closed box.
        assert_eq!(setup_ray([-3.0, 1.0, 0.0], [1.0, 0.0, 0.0], &CUBE, s).n, 4);
        // Per-voxel: 2 per voxel of 0.5 over a length of 2 gives 8 samples.
        let g = setup_ray(
            [0.0, 0.0, 3.0],
            [0.0, 0.0, -1.0],
            &CUBE,
            Sampler::PerVoxel { per_voxel: 2 },
        );
        assert_eq!((g.n, g.dt), (8, 0.25));
    }

    #[test]
    fn skipping_visits_exactly_the_occupied_samples() {
        // 4 voxels per axis, 2 per cell: 2x2x2 cells, only cell (x=1, y=0, z=0) occupied.
        let mut distance = vec![1; 8];
        distance[1] = 0;
        let blocks = vec![false; 64];
        let occ = OccView {
            distance: &distance,
            empty_block: &blocks,
            n: [2, 2, 2],
            k: 2,
        };
        let g = setup_ray::<f64>(
            [-3.0, -0.5, -0.5],
            [1.0, 0.0, 0.0],
            &CUBE,
            Sampler::Uniform { samples: 40 },
        );
        let collect = |occ: Option<&OccView<'_>>| {
            let mut marcher = Marcher::new(&g, occ, 0);
            std::iter::from_fn(|| marcher.next_sample().map(|(_, t, _)| t)).collect::<Vec<f64>>()
        };
        let (all, kept) = (collect(None), collect(Some(&occ)));
        let expected: Vec<f64> = all.iter().copied().filter(|&t| t - 3.0 >= 0.0).collect();
        assert_eq!(kept, expected);
    }
}
