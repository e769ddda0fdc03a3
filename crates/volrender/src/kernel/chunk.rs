//! Up to [`LANES`] consecutive samples of one ray, evaluated together.
//!
//! Everything a sample needs that does not depend on the samples before it (its trilinear
//! corners, its interpolated `[sigma, r, g, b]` and its attenuation `exp`) is computed here, lane
//! by lane in fixed-size loops over all lanes, which the compiler turns into SIMD code (the
//! corner arithmetic and the `exp` run 8 samples per instruction in the AVX2 build). Only the
//! compositing, a running product, stays sequential (in `composite`). One sample at a time, the
//! kernels spent most of their time moving corner arrays to and from the stack.
//!
//! Trilinear interpolation is radiance-volume's rule (`radiance_volume::sample::sample_into`):
//! index coordinate `u` puts cell `i`'s centre at `u = i`; inside the box
//! (`-0.5 <= u <= n - 0.5`) values are edge-clamped; outside, the sample does not count. It is
//! computed as nested lerps `a + f (b - a)` (x, then y, then z), which is exact wherever the
//! corners agree; the backward distributes a gradient through the same lerps in reverse.

use super::march::{Marcher, OccView, RayGeom};
use super::{softplus_and_slope, Real, VolumeView};

/// Samples per chunk: one AVX2 register of f32.
pub(crate) const LANES: usize = 8;

/// The samples of one chunk: `len` lanes in use, the rest padding.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Chunk<T> {
    pub(crate) len: usize,
    /// Sample index along the ray.
    pub(crate) index: [usize; LANES],
    /// Distance along the ray.
    pub(crate) t: [T; LANES],
    /// Index-space position per axis (x, y, z).
    u: [[T; LANES]; 3],
    /// The sample counts: inside the grid and, when skipping, not in a corner block of density
    /// exactly 0 everywhere. Padding lanes are not live.
    pub(crate) live: [bool; LANES],
    /// Voxel index of the lowest corner.
    base: [u32; LANES],
    /// Index offset from a corner to its upper neighbour per axis (0 at a clamped far face).
    step: [[u32; LANES]; 3],
    /// Position of the sample between its lower and upper corner per axis, in `[0, 1]`.
    frac: [[T; LANES]; 3],
    /// Interpolated `[sigma, r, g, b]` (zero in lanes that are not live).
    pub(crate) value: [[T; 4]; LANES],
    /// The density of `value` again, lane by lane, so the attenuation loop reads contiguous
    /// lanes (and vectorises).
    sigma: [T; LANES],
    /// `d sigma / d (interpolated channel 0)`: the activation's slope with a post-activated
    /// volume, 1 otherwise (so the backward's chain rule is one multiplication either way).
    slope: [T; LANES],
    /// `1 - exp(-sigma dt)` and `exp(-sigma dt)`.
    pub(crate) alpha: [T; LANES],
    pub(crate) keep: [T; LANES],
}

/// `a + f (b - a)` per channel.
#[inline(always)]
fn lerp<T: Real>(a: [T; 4], b: [T; 4], f: T) -> [T; 4] {
    [0, 1, 2, 3].map(|c| a[c] + f * (b[c] - a[c]))
}

/// Splits `g` into the parts `(g (1 - f), g f)` that flow to a lerp's two ends.
#[inline(always)]
fn split<T: Real>(g: [T; 4], f: T) -> ([T; 4], [T; 4]) {
    let upper = g.map(|x| x * f);
    ([0, 1, 2, 3].map(|c| g[c] - upper[c]), upper)
}

#[inline(always)]
fn add_to<T: Real>(cell: &mut [T; 4], g: [T; 4]) {
    for c in 0..4 {
        cell[c] = cell[c] + g[c];
    }
}

/// Returns `(alpha, 1 - alpha)` = `(1 - exp(-tau), exp(-tau))`, both branches computed and one
/// selected so that a loop over lanes vectorises: below `tau = 1e-3` a 5-term series keeps alpha
/// to full relative precision (its truncation error, `tau^5 / 720`, is below f64's rounding),
/// above it `1 - exp(-tau)` loses at most a few ulp of 1 in absolute terms.
#[inline(always)]
pub(crate) fn attenuation<T: Real>(tau: T) -> (T, T) {
    let one = T::one();
    // tau - tau^2/2 + tau^3/6 - ..., nested; multiplying by rounded reciprocals costs under an
    // ulp and keeps divisions out of the loop.
    let series = tau
        * (one
            - tau
                * T::of(1.0 / 2.0)
                * (one
                    - tau
                        * T::of(1.0 / 3.0)
                        * (one - tau * T::of(1.0 / 4.0) * (one - tau * T::of(1.0 / 5.0)))));
    let e = (-tau).exp_nonpositive();
    if tau < T::of(1e-3) {
        (series, one - series)
    } else {
        (one - e, e)
    }
}

impl<T: Real> Chunk<T> {
    fn new() -> Self {
        let zeros = [T::zero(); LANES];
        Self {
            len: 0,
            index: [0; LANES],
            t: zeros,
            u: [zeros; 3],
            live: [false; LANES],
            base: [0; LANES],
            step: [[0; LANES]; 3],
            frac: [zeros; 3],
            value: [[T::zero(); 4]; LANES],
            sigma: zeros,
            slope: [T::one(); LANES],
            alpha: zeros,
            keep: zeros,
        }
    }

    /// Finds each lane's corners; lanes past `len` and lanes outside the box (or NaN) are not
    /// live, and their (clamped, in-range) corners are never used.
    #[inline(always)]
    fn locate(&mut self, n: [usize; 3]) {
        let half = T::of(0.5);
        for l in 0..LANES {
            self.live[l] = l < self.len;
        }
        let mut stride = 1u32;
        self.base = [0; LANES];
        for a in 0..3 {
            let last = n[a] as u32 - 1;
            let top = T::of(last as f64);
            let far = T::of(n[a] as f64) - half;
            for l in 0..LANES {
                let u = self.u[a][l];
                // `!(..)` is false for NaN too.
                self.live[l] &= u >= -half && u <= far;
                // Plain comparisons, not `max`/`min`: NaN lanes are dead anyway, and these
                // compile to single min/max instructions.
                let uc = if u > T::zero() { u } else { T::zero() };
                let uc = if uc < top { uc } else { top };
                let (floor, lower) = uc.floor_split();
                let upper_step = u32::from(lower < last);
                self.base[l] += lower * stride;
                self.step[a][l] = upper_step * stride;
                self.frac[a][l] = uc - floor;
            }
            stride *= n[a] as u32;
        }
    }

    /// Interpolates the live lanes' values (and zeroes the rest); with a post-activated volume
    /// the density is then activated. With an occupancy view, lanes whose corner block is empty
    /// are first marked dead.
    #[inline(always)]
    fn gather(&mut self, vol: &VolumeView<'_, T>, occ: Option<&OccView<'_>>) {
        if let Some(o) = occ {
            for l in 0..self.len {
                self.live[l] &= !o.empty_block[self.base[l] as usize];
            }
        }
        self.value = [[T::zero(); 4]; LANES];
        self.sigma = [T::zero(); LANES];
        for l in 0..self.len {
            if !self.live[l] {
                continue;
            }
            let b = self.base[l] as usize;
            let [sx, sy, sz] = self.step.map(|s| s[l] as usize);
            let [fx, fy, fz] = self.frac.map(|f| f[l]);
            let row = |r: usize| lerp(vol.data[r], vol.data[r + sx], fx);
            let near = lerp(row(b), row(b + sy), fy);
            let far = lerp(row(b + sz), row(b + sz + sy), fy);
            self.value[l] = lerp(near, far, fz);
            self.sigma[l] = self.value[l][0];
        }
        if let Some([scale, shift]) = vol.post_activation {
            // Every lane computed and the live ones selected, so the loop runs in SIMD; lanes
            // that are not live keep density 0 (outside the box there is no matter).
            for l in 0..LANES {
                let (softplus, slope) = softplus_and_slope(self.sigma[l] + shift);
                self.sigma[l] = if self.live[l] {
                    scale * softplus
                } else {
                    T::zero()
                };
                self.slope[l] = scale * slope;
            }
            for l in 0..self.len {
                self.value[l][0] = self.sigma[l];
            }
        }
    }

    /// Computes every lane's attenuation over a step `dt`.
    #[inline(always)]
    fn attenuate(&mut self, dt: T) {
        for l in 0..LANES {
            (self.alpha[l], self.keep[l]) = attenuation(self.sigma[l] * dt);
        }
    }

    /// Adds `g` (per channel) to the corners of live lane `l` in `buf`, through the adjoint of
    /// the lerps that interpolated it, its density part first through the activation's slope
    /// (1 unless post-activated).
    #[inline(always)]
    pub(crate) fn scatter(&self, l: usize, buf: &mut [[T; 4]], g: [T; 4]) {
        let g = [g[0] * self.slope[l], g[1], g[2], g[3]];
        let b = self.base[l] as usize;
        let [sx, sy, sz] = self.step.map(|s| s[l] as usize);
        let [fx, fy, fz] = self.frac.map(|f| f[l]);
        let (near, far) = split(g, fz);
        for (z_row, gz) in [(b, near), (b + sz, far)] {
            let (front, back) = split(gz, fy);
            for (row, gy) in [(z_row, front), (z_row + sy, back)] {
                let (left, right) = split(gy, fx);
                add_to(&mut buf[row], left);
                add_to(&mut buf[row + sx], right);
            }
        }
    }
}

/// One ray's samples, chunk by chunk. Samples the marcher passes over (outside the grid or in
/// empty occupancy cells) never enter a chunk.
pub(crate) struct Chunks<'a, T> {
    vol: &'a VolumeView<'a, T>,
    occ: Option<&'a OccView<'a>>,
    dt: T,
    marcher: Marcher<'a, T>,
    chunk: Chunk<T>,
}

impl<'a, T: Real> Chunks<'a, T> {
    /// The chunks of samples `start..g.n`.
    #[inline(always)]
    pub(crate) fn new(
        vol: &'a VolumeView<'a, T>,
        occ: Option<&'a OccView<'a>>,
        g: &'a RayGeom<T>,
        start: usize,
    ) -> Self {
        Self {
            vol,
            occ,
            dt: g.dt,
            marcher: Marcher::new(g, occ, start),
            chunk: Chunk::new(),
        }
    }

    /// Evaluates the next chunk of samples, or returns `None` past the last one.
    #[inline(always)]
    pub(crate) fn next_chunk(&mut self) -> Option<&Chunk<T>> {
        let c = &mut self.chunk;
        c.len = 0;
        while c.len < LANES {
            let Some((i, t, u)) = self.marcher.next_sample() else {
                break;
            };
            c.index[c.len] = i;
            c.t[c.len] = t;
            for a in 0..3 {
                c.u[a][c.len] = u[a];
            }
            c.len += 1;
        }
        if c.len == 0 {
            return None;
        }
        c.locate(self.vol.n);
        c.gather(self.vol, self.occ);
        c.attenuate(self.dt);
        Some(&self.chunk)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::trilinear::corners;

    /// Fills a chunk with the given index-space points.
    fn chunk_at(points: &[[f64; 3]], vol: &VolumeView<'_, f64>) -> Chunk<f64> {
        let mut c = Chunk::new();
        c.len = points.len();
        for (l, p) in points.iter().enumerate() {
            for a in 0..3 {
                c.u[a][l] = p[a];
            }
        }
        c.locate(vol.n);
        c.gather(vol, None);
        c
    }

    fn test_volume(n: [usize; 3]) -> Vec<[f64; 4]> {
        (0..n[0] * n[1] * n[2])
            .map(|i| [(i * 37 % 11) as f64 * 0.1, 1.0, 2.0 * i as f64, -1.0])
            .collect()
    }

    /// The lerps equal the weighted sum of the 8 corners (the reference path's form), including
    /// clamped far faces, and points outside the box (or NaN) are not live.
    #[test]
    fn lerps_match_the_weighted_corners() {
        let n = [3, 1, 4];
        let data = test_volume(n);
        let vol = VolumeView {
            data: &data,
            n,
            post_activation: None,
        };
        let points = [
            [1.3, 0.0, 0.25],
            [-0.5, 0.2, 3.5],
            [2.0, -0.4, 2.999],
            [0.0, 0.0, 0.0],
            [2.6, 0.0, 0.0],
            [1.0, f64::NAN, 1.0],
        ];
        let c = chunk_at(&points, &vol);
        for (l, p) in points.iter().enumerate() {
            match corners(n, *p) {
                Some(w) => {
                    assert!(c.live[l], "{p:?}");
                    for ch in 0..4 {
                        let expected: f64 = (0..8).map(|k| w.w[k] * data[w.idx[k]][ch]).sum();
                        assert!((c.value[l][ch] - expected).abs() < 1e-12, "{p:?} {ch}");
                    }
                }
                None => assert!(!c.live[l] && c.value[l] == [0.0; 4], "{p:?}"),
            }
        }
        assert!(!c.live[points.len()..].iter().any(|&x| x));
    }

    /// `<gather(x), g> == <x, scatter(g)>` for every lane.
    #[test]
    fn scatter_is_the_adjoint_of_gather() {
        let n = [3, 2, 2];
        let data = test_volume(n);
        let vol = VolumeView {
            data: &data,
            n,
            post_activation: None,
        };
        let points = [[1.3, 0.0, 0.25], [2.0, 1.4, 0.5], [0.2, 0.7, 1.0]];
        let c = chunk_at(&points, &vol);
        let g = [0.5, -1.0, 2.0, 3.0];
        for l in 0..points.len() {
            let mut buf = vec![[0.0; 4]; data.len()];
            c.scatter(l, &mut buf, g);
            let lhs: f64 = (0..4).map(|k| c.value[l][k] * g[k]).sum();
            let rhs: f64 = data
                .iter()
                .zip(&buf)
                .map(|(x, s)| (0..4).map(|k| x[k] * s[k]).sum::<f64>())
                .sum();
            assert!((lhs - rhs).abs() < 1e-12 * lhs.abs().max(1.0), "lane {l}");
        }
    }
}
