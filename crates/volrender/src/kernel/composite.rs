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
//!
//! Samples arrive in chunks (`chunk`) with their values and attenuation already computed; the
//! loops here are the sequential part.

use super::chunk::Chunks;
use super::march::{OccView, RayGeom};
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

/// One ray's outputs, and what the backward keeps of the forward: the final transmittance and
/// the span of samples that contributed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RayOut<T> {
    pub(crate) rgb: [T; 3],
    pub(crate) depth: T,
    pub(crate) opacity: T,
    pub(crate) trans: T,
    /// Sample indices `live.0..live.1` hold every live sample the forward composited (empty
    /// when there was none): samples outside add nothing to the forward or the backward, so
    /// the backward walks only these.
    pub(crate) live: (usize, usize),
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
    let (mut first_live, mut end_live) = (None, 0);
    let mut chunks = Chunks::new(vol, occ, g, 0);
    'ray: while let Some(c) = chunks.next_chunk() {
        for l in 0..c.len {
            if !c.live[l] {
                continue;
            }
            first_live.get_or_insert(c.index[l]);
            end_live = c.index[l] + 1;
            let w = trans * c.alpha[l];
            for ch in 0..3 {
                rgb[ch] = rgb[ch] + w * c.value[l][ch + 1];
            }
            if p.depth {
                depth = depth + w * c.t[l];
            }
            if p.opacity {
                opacity = opacity + w;
            }
            trans = trans * c.keep[l];
            if trans <= p.epsilon {
                break 'ray;
            }
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
        live: (first_live.unwrap_or(0), end_live),
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
    // Walk from the forward's first live sample and stop after its last (an empty span walks
    // nothing).
    let (from, to) = out.live;
    let g = &RayGeom { n: to, ..*g };
    let mut chunks = Chunks::new(vol, occ, g, from);
    'ray: while let Some(c) = chunks.next_chunk() {
        for l in 0..c.len {
            if !c.live[l] {
                continue;
            }
            let v = c.value[l];
            let w = trans * c.alpha[l];
            let next = trans * c.keep[l];
            let x = gr * v[1] + gg * v[2] + gb * v[3] + gd * c.t[l];
            upto = upto + w * x;
            let d_tau = next * x - (total - upto) + opacity_term;
            c.scatter(l, buf, [d_tau * g.dt, w * gr, w * gg, w * gb]);
            trans = next;
            if trans <= p.epsilon {
                break 'ray;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Sampler;
    use crate::kernel::chunk::attenuation;
    use crate::kernel::march::{setup_ray, GridSpec, OccView};

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
            post_activation: None,
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
            live: (0, 0),
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

    /// Walking only the forward's live span changes no gradient bit against walking the whole
    /// ray, for rays that miss, graze, start inside or cross empty regions, with and without
    /// an occupancy grid.
    #[test]
    fn the_live_span_holds_every_contribution() {
        let n = [6, 5, 4];
        let voxels = n[0] * n[1] * n[2];
        // Density only in the middle of x, so rays start and end in empty space.
        let data: Vec<[f32; 4]> = (0..voxels)
            .map(|i| {
                let x = i % n[0];
                let density = if (2..4).contains(&x) {
                    0.5 + (i % 7) as f32
                } else {
                    0.0
                };
                [density, (i % 3) as f32 * 0.3, 0.5, (i % 5) as f32 * 0.2]
            })
            .collect();
        let vol = VolumeView {
            data: &data,
            n,
            post_activation: None,
        };
        let grid = GridSpec {
            min: [-1.0; 3],
            max: [1.0; 3],
            n,
        };
        let distance = vec![0u8; 8];
        let empty_block: Vec<bool> = (0..voxels).map(|i| data[i][0] == 0.0).collect();
        let occ = OccView {
            distance: &distance,
            empty_block: &empty_block,
            n: [2, 2, 2],
            k: 3,
        };
        let rays = [
            ([-3.0, 0.1, 0.2], [1.0, 0.05, -0.02]),
            ([-3.0, 2.5, 0.0], [1.0, 0.0, 0.0]),
            ([0.2, -0.3, 0.1], [0.3, 1.0, 0.2]),
            ([-3.0, -1.0, 1.0], [1.0, 0.0, 0.0]),
            ([0.0, 0.0, 3.0], [0.1, 0.0, -1.0]),
        ];
        for occ in [None, Some(&occ)] {
            for epsilon in [0.0f32, 0.05] {
                let p = Params {
                    epsilon,
                    background: [0.2, 0.1, 0.0],
                    depth: true,
                    opacity: true,
                };
                for (origin, dir) in rays {
                    let g = setup_ray(origin, dir, &grid, Sampler::Uniform { samples: 29 });
                    let out = forward_ray(&vol, occ, &g, &p);
                    let backward = |live| {
                        let mut buf = vec![[0f32; 4]; voxels];
                        let grad = [0.3, -1.0, 0.7, 0.25, -0.5];
                        backward_ray(&vol, occ, &g, &p, &RayOut { live, ..out }, grad, &mut buf);
                        buf.as_flattened()
                            .iter()
                            .map(|v| v.to_bits())
                            .collect::<Vec<_>>()
                    };
                    assert!(out.live.1 <= g.n);
                    assert_eq!(backward(out.live), backward((0, g.n)), "{origin:?} {dir:?}");
                }
            }
        }
    }
}
