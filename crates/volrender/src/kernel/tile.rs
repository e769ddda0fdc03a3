//! Rendering a tile of consecutive rays, forward or backward, with the instruction set chosen
//! once per render.
//!
//! The kernels are plain scalar Rust built for the baseline target (x86-64 with SSE2 only, as
//! crates are usually compiled). On CPUs with AVX2 and FMA the same code is compiled again with
//! those features enabled (VEX encodings, SSE4.1 rounding, more freedom in register use); on our
//! machine that made the dense forward about 10% faster (single thread, 0.31 -> 0.28 s for
//! 65,536 rays x 128 samples; docs/performance-volrender.md). A tile is large enough that the
//! dispatch costs nothing. Rust never contracts `a * b + c` into an FMA on its own, so both
//! versions compute bit-identical results (tested below): the choice is invisible except in
//! speed.

// Calling a `#[target_feature]` function is unsafe: the CPU must have the features.
#![allow(unsafe_code)]

use super::composite::{backward_ray, forward_ray, Params, RayOut};
use super::march::{setup_ray, GridSpec, OccView};
use super::{Real, VolumeView};
use crate::config::Sampler;

/// Columns of the packed per-ray output `[r, g, b, depth, opacity, transmittance, first live
/// sample, one past the last live sample]` (sample indices are exact in either float type: a
/// ray has at most 2^24 samples).
pub(crate) const PACKED: usize = 8;

/// The instruction set the kernels run with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Isa {
    /// Whatever the crate was compiled for.
    Baseline,
    /// x86-64 with AVX2 and FMA, detected at run time.
    #[cfg(target_arch = "x86_64")]
    Avx2Fma,
}

impl Isa {
    /// The best instruction set this CPU supports.
    pub(crate) fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return Self::Avx2Fma;
        }
        Self::Baseline
    }
}

/// Everything a tile of rays of one volume needs.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RayKernel<'a, T> {
    pub(crate) volume: VolumeView<'a, T>,
    pub(crate) occupancy: Option<OccView<'a>>,
    pub(crate) grid: GridSpec<T>,
    pub(crate) sampler: Sampler,
    pub(crate) params: Params<T>,
    pub(crate) isa: Isa,
}

impl<T: Real> RayKernel<'_, T> {
    /// Renders rays `(origins[i], dirs[i])` into `out[i * PACKED..(i + 1) * PACKED]`.
    pub(crate) fn forward_tile(&self, origins: &[[f32; 3]], dirs: &[[f32; 3]], out: &mut [T]) {
        match self.isa {
            Isa::Baseline => self.forward_tile_inline(origins, dirs, out),
            // SAFETY: `Isa::Avx2Fma` is only ever produced by `detect` on a CPU with both.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma => unsafe { self.forward_tile_avx2(origins, dirs, out) },
        }
    }

    /// Adds the gradient of rays `(origins[i], dirs[i])` to `buf`, given their packed forward
    /// outputs `res` and output gradients `grad` (same layout).
    pub(crate) fn backward_tile(
        &self,
        origins: &[[f32; 3]],
        dirs: &[[f32; 3]],
        res: &[T],
        grad: &[T],
        buf: &mut [[T; 4]],
    ) {
        match self.isa {
            Isa::Baseline => self.backward_tile_inline(origins, dirs, res, grad, buf),
            // SAFETY: as in `forward_tile`.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma => unsafe { self.backward_tile_avx2(origins, dirs, res, grad, buf) },
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn forward_tile_avx2(&self, origins: &[[f32; 3]], dirs: &[[f32; 3]], out: &mut [T]) {
        self.forward_tile_inline(origins, dirs, out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn backward_tile_avx2(
        &self,
        origins: &[[f32; 3]],
        dirs: &[[f32; 3]],
        res: &[T],
        grad: &[T],
        buf: &mut [[T; 4]],
    ) {
        self.backward_tile_inline(origins, dirs, res, grad, buf);
    }

    #[inline(always)]
    fn forward_tile_inline(&self, origins: &[[f32; 3]], dirs: &[[f32; 3]], out: &mut [T]) {
        for ((&origin, &dir), o) in origins.iter().zip(dirs).zip(out.chunks_exact_mut(PACKED)) {
            let g = setup_ray(origin, dir, &self.grid, self.sampler);
            let r = forward_ray(&self.volume, self.occupancy.as_ref(), &g, &self.params);
            let (from, to) = r.live;
            o.copy_from_slice(&[
                r.rgb[0],
                r.rgb[1],
                r.rgb[2],
                r.depth,
                r.opacity,
                r.trans,
                T::of_index(from as u32),
                T::of_index(to as u32),
            ]);
        }
    }

    #[inline(always)]
    fn backward_tile_inline(
        &self,
        origins: &[[f32; 3]],
        dirs: &[[f32; 3]],
        res: &[T],
        grad: &[T],
        buf: &mut [[T; 4]],
    ) {
        let rows = res.chunks_exact(PACKED).zip(grad.chunks_exact(PACKED));
        for ((&origin, &dir), (p, gr)) in origins.iter().zip(dirs).zip(rows) {
            let live = (
                p[6].truncate_index() as usize,
                p[7].truncate_index() as usize,
            );
            if live.0 >= live.1 {
                continue; // nothing contributed, nothing to differentiate
            }
            let g = setup_ray(origin, dir, &self.grid, self.sampler);
            let out = RayOut {
                rgb: [p[0], p[1], p[2]],
                depth: p[3],
                opacity: p[4],
                trans: p[5],
                live,
            };
            let g_out = [gr[0], gr[1], gr[2], gr[3], gr[4]];
            backward_ray(
                &self.volume,
                self.occupancy.as_ref(),
                &g,
                &self.params,
                &out,
                g_out,
                buf,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Sampler;

    /// The AVX2+FMA build (where the CPU has it) gives the same bits as the baseline build,
    /// forward and backward, with skipping on and off, physical and post-activated density.
    #[test]
    fn instruction_sets_agree_bit_for_bit() {
        let n = [5, 4, 6];
        let voxels = n[0] * n[1] * n[2];
        let data: Vec<[f32; 4]> = (0..voxels)
            .map(|i| {
                let density = if i % 3 == 0 {
                    0.0
                } else {
                    (i * 37 % 17) as f32 * 0.7
                };
                [density, (i % 5) as f32 * 0.2, (i % 7) as f32 / 7.0, 0.5]
            })
            .collect();
        let distance = vec![0; 8];
        let empty_block: Vec<bool> = (0..voxels).map(|i| i % 11 == 0).collect();
        let occ = OccView {
            distance: &distance,
            empty_block: &empty_block,
            n: [2, 2, 2],
            k: 3,
        };
        let origins: Vec<[f32; 3]> = (0..40)
            .map(|i| [-3.0, (i as f32 * 0.05) - 1.0, 0.3 - i as f32 * 0.01])
            .collect();
        let dirs: Vec<[f32; 3]> = (0..40)
            .map(|i| [1.0, 0.02 * (i % 3) as f32, -0.1 + 0.01 * i as f32])
            .collect();
        let rules = [None, Some([25.0, -4.0])];
        for (occupancy, post_activation) in [None, Some(occ)]
            .into_iter()
            .flat_map(|o| rules.map(|r| (o, r)))
        {
            let kernel = |isa| RayKernel {
                volume: VolumeView {
                    data: &data,
                    n,
                    post_activation,
                },
                occupancy,
                grid: GridSpec {
                    min: [-1.0, -1.2, -0.8],
                    max: [1.0, 0.9, 1.1],
                    n,
                },
                sampler: Sampler::Uniform { samples: 37 },
                params: Params {
                    epsilon: 1e-3,
                    background: [0.1, 0.2, 0.3],
                    depth: true,
                    opacity: true,
                },
                isa,
            };
            let run = |isa| {
                let k = kernel(isa);
                let mut out = vec![0f32; origins.len() * PACKED];
                k.forward_tile(&origins, &dirs, &mut out);
                let grad: Vec<f32> = (0..out.len()).map(|i| (i % 7) as f32 - 3.0).collect();
                let mut buf = vec![[0f32; 4]; voxels];
                k.backward_tile(&origins, &dirs, &out, &grad, &mut buf);
                (out, buf)
            };
            let (base_out, base_buf) = run(Isa::Baseline);
            let (out, buf) = run(Isa::detect());
            assert!(base_out.iter().any(|&v| v != 0.0));
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&base_out), bits(&out));
            assert_eq!(bits(base_buf.as_flattened()), bits(buf.as_flattened()));
        }
    }
}
