//! Compositing along one ray (equation (1)) and its closed-form O(N) backward.
//!
//! With `tau_i = sigma_i delta_i`, `alpha_i = 1 - exp(-tau_i)`, `T_i = prod_{j<i} exp(-tau_j)`,
//! `w_i = T_i alpha_i`:
//! `C = sum_i w_i c_i + T_N bg`, `D = sum_i w_i t_i`, `A = sum_i w_i = 1 - T_N`.
//!
//! Backward (DVGO's closed form, derived here with the background term). `T_k` for `k > i`
//! depends on `tau_i` through `dT_k/dtau_i = -T_k`, and `dalpha_i/dtau_i = 1 - alpha_i`, so for a
//! per-sample value `x_i` (a colour channel, or `t_i` for depth, with `x_bg` = bg or 0):
//! `d(sum_k w_k x_k + T_N x_bg)/dtau_i = T_{i+1} x_i - (sum_{k>i} w_k x_k + T_N x_bg)`,
//! and the bracket is `total - sum_{k<=i} w_k x_k`, which the forward's output gives us.
//! For opacity `dA/dtau_i = T_N`. Finally `dL/dsigma_i = delta_i dL/dtau_i` and
//! `dL/dc_i = w_i dL/dC`. One pass, in sample order, with no per-sample storage.

use super::march::{Marcher, OccView, RayGeom};
use super::trilinear::{corners, gather, scatter, Corners};
use super::{Real, VolumeView};

/// Per-render constants of the compositing.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Params<T> {
    /// Stop once `T <= epsilon`.
    pub(crate) epsilon: T,
    pub(crate) background: [T; 3],
    pub(crate) depth: bool,
    pub(crate) opacity: bool,
}

/// One ray's outputs; `trans` is the final transmittance, kept for the backward.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RayOut<T> {
    pub(crate) rgb: [T; 3],
    pub(crate) depth: T,
    pub(crate) opacity: T,
    pub(crate) trans: T,
}

/// Returns `(alpha, 1 - alpha)` = `(1 - exp(-tau), exp(-tau))` with one cheap call per sample:
/// below `tau = 1e-3` a 5-term series keeps alpha to full relative precision (its truncation
/// error, `tau^5 / 720`, is below f64's rounding), above it `1 - exp(-tau)` loses at most a few
/// ulp of 1 in absolute terms. (`expm1` would do both but costs a quarter of the f32 forward.)
#[inline(always)]
fn attenuation<T: Real>(tau: T) -> (T, T) {
    if tau < T::of(1e-3) {
        let one = T::one();
        let series = one
            - tau / T::of(2.0)
                * (one - tau / T::of(3.0) * (one - tau / T::of(4.0) * (one - tau / T::of(5.0))));
        let alpha = tau * series;
        (alpha, one - alpha)
    } else {
        let e = (-tau).exp_nonpositive();
        (T::one() - e, e)
    }
}

/// One ray's samples with their trilinear corners and interpolated `[sigma, r, g, b]`, in order.
/// Samples outside the grid and samples in blocks the occupancy grid marks empty (density
/// exactly 0 there, so they add nothing to the forward or the backward) are passed over.
struct Samples<'a, T> {
    vol: &'a VolumeView<'a, T>,
    occ: Option<&'a OccView<'a>>,
    marcher: Marcher<'a, T>,
}

impl<'a, T: Real> Samples<'a, T> {
    #[inline(always)]
    fn new(vol: &'a VolumeView<'a, T>, occ: Option<&'a OccView<'a>>, g: &'a RayGeom<T>) -> Self {
        Self {
            vol,
            occ,
            marcher: Marcher::new(g, occ),
        }
    }

    #[inline(always)]
    fn next_sample(&mut self) -> Option<(T, Corners<T>, [T; 4])> {
        while let Some((t, u)) = self.marcher.next_sample() {
            let Some(c) = corners(self.vol.n, u) else {
                continue;
            };
            if self.occ.is_some_and(|o| o.empty_block[c.idx[0]]) {
                // Density exactly 0 at this sample: it adds nothing (skipping is on).
                continue;
            }
            return Some((t, c, gather(self.vol, &c)));
        }
        None
    }
}

/// Renders one ray.
#[inline(always)]
pub(crate) fn forward_ray<T: Real>(
    vol: &VolumeView<'_, T>,
    occ: Option<&OccView<'_>>,
    g: &RayGeom<T>,
    p: &Params<T>,
) -> RayOut<T> {
    let mut trans = T::one();
    let mut rgb = [T::zero(); 3];
    let (mut depth, mut opacity) = (T::zero(), T::zero());
    let mut samples = Samples::new(vol, occ, g);
    while let Some((t, _, v)) = samples.next_sample() {
        let (alpha, keep) = attenuation(v[0] * g.dt);
        let w = trans * alpha;
        for ch in 0..3 {
            rgb[ch] = rgb[ch] + w * v[ch + 1];
        }
        if p.depth {
            depth = depth + w * t;
        }
        if p.opacity {
            opacity = opacity + w;
        }
        trans = trans * keep;
        if trans <= p.epsilon {
            break;
        }
    }
    for ch in 0..3 {
        rgb[ch] = rgb[ch] + trans * p.background[ch];
    }
    RayOut {
        rgb,
        depth,
        // Rounding can push the sum of weights a few ulp past 1.
        opacity: opacity.min(T::one()),
        trans,
    }
}

/// Adds one ray's gradient with respect to the voxels to `buf`, given the forward's output
/// `out` and the output gradient `[d_r, d_g, d_b, d_depth, d_opacity]`.
#[inline(always)]
pub(crate) fn backward_ray<T: Real>(
    vol: &VolumeView<'_, T>,
    occ: Option<&OccView<'_>>,
    g: &RayGeom<T>,
    p: &Params<T>,
    out: &RayOut<T>,
    grad: [T; 5],
    buf: &mut [[T; 4]],
) {
    let [gr, gg, gb, gd, ga] = grad;
    let total = gr * out.rgb[0] + gg * out.rgb[1] + gb * out.rgb[2] + gd * out.depth;
    let opacity_term = ga * out.trans;
    let mut upto = T::zero();
    let mut trans = T::one();
    let mut samples = Samples::new(vol, occ, g);
    while let Some((t, c, v)) = samples.next_sample() {
        let (alpha, keep) = attenuation(v[0] * g.dt);
        let w = trans * alpha;
        let next = trans * keep;
        let x = gr * v[1] + gg * v[2] + gb * v[3] + gd * t;
        upto = upto + w * x;
        let d_tau = next * x - (total - upto) + opacity_term;
        scatter(buf, &c, [d_tau * g.dt, w * gr, w * gg, w * gb]);
        trans = next;
        if trans <= p.epsilon {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Sampler;
    use crate::kernel::march::{setup_ray, GridSpec};

    #[test]
    fn attenuation_is_a_split_of_one() {
        for tau in [
            0.0,
            1e-300,
            1e-30,
            1e-12,
            9.99e-4,
            1e-3,
            0.25,
            1.0,
            30.0,
            1e6,
            1e30,
            f64::MAX,
            f64::INFINITY,
        ] {
            let (alpha, keep) = attenuation(tau);
            assert!(
                (0.0..=1.0).contains(&alpha) && (0.0..=1.0).contains(&keep),
                "{tau}"
            );
            assert!((alpha + keep - 1.0).abs() < 1e-15, "{tau}");
            // Small tau keeps full relative precision: alpha ~ tau.
            if tau > 0.0 && tau < 1e-3 {
                assert!((alpha / -(-tau).exp_m1() - 1.0).abs() < 1e-15, "{tau}");
            }
        }
    }

    /// Transmittance never increases and opacity never decreases along a ray: render growing
    /// prefixes of the same samples.
    #[test]
    fn transmittance_never_increases() {
        let data: Vec<[f32; 4]> = (0..27)
            .map(|i| [[0.0, 1e-12, 3.0, 1e6, 1e30][i % 5], 0.5, 0.5, 0.5])
            .collect();
        let vol = VolumeView {
            data: &data,
            n: [3, 3, 3],
        };
        let grid = GridSpec {
            min: [-1.0; 3],
            max: [1.0; 3],
            n: [3, 3, 3],
        };
        let full = setup_ray(
            [-3.0, -0.2, 0.1],
            [1.0, 0.1, 0.05],
            &grid,
            Sampler::Uniform { samples: 50 },
        );
        let p = Params {
            epsilon: 0.0,
            background: [0.0; 3],
            depth: true,
            opacity: true,
        };
        let mut last = RayOut {
            rgb: [0.0; 3],
            depth: 0.0,
            opacity: 0.0,
            trans: 1.0,
        };
        for n in 1..=full.n {
            let out = forward_ray(&vol, None, &RayGeom { n, ..full }, &p);
            assert!(
                out.trans <= last.trans && out.opacity >= last.opacity,
                "sample {n}"
            );
            assert!(out.rgb.iter().all(|c| c.is_finite()) && (0.0..=1.0).contains(&out.opacity));
            last = out;
        }
    }
}
