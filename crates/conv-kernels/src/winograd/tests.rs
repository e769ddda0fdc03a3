//! The Winograd passes against the im2col kernel, in f64 and in f32.

use super::*;
use crate::isa::{available, with_isa};

/// Deterministic values in [-1, 1).
pub(super) fn values(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        })
        .collect()
}

fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(1e-30f64, |m, v| m.max(v.abs()));
    a.iter().zip(b).fold(0f64, |m, (x, y)| m.max((x - y).abs())) / scale
}

fn geometries() -> Vec<Geometry> {
    let mut out = Vec::new();
    for (kernel, padding) in [
        ([3, 3, 3], [1, 1, 1]),
        ([3, 3, 3], [0, 0, 0]),
        ([1, 3, 3], [0, 0, 0]),
        ([1, 3, 3], [0, 1, 1]),
        ([3, 1, 3], [2, 0, 1]),
    ] {
        // Rows of 37 voxels take the (de)interleaving's blocks of 8 tiles with both tiles,
        // rows of 29 its blocks of 4 (F(2, 3) after a block of 8), the others only its
        // single tiles.
        for input in [[5, 6, 7], [4, 4, 4], [3, 8, 5], [4, 3, 37], [3, 4, 29]] {
            let input = [0, 1, 2].map(|a| {
                if kernel[a] == 1 {
                    input[a].min(2)
                } else {
                    input[a]
                }
            });
            out.push(Geometry {
                batch: 2,
                c_in: 3,
                c_out: 5,
                input,
                kernel,
                padding,
                stride: 1,
            });
        }
    }
    out
}

/// The three passes with `tile`; the input gradient as [`grad_input`] computes it.
fn passes<T: Element>(x: &[T], w: &[T], go: &[T], g: &Geometry, tile: Tile) -> [Vec<T>; 3] {
    let transposed = g.transposed().unwrap();
    let flipped = im2col::flipped_transposed(w, g);
    [
        forward_tiled(x, w, g, tile),
        forward_tiled(go, &flipped, &transposed, tile),
        grad_weight_tiled(x, go, g, tile),
    ]
}

/// Asserts that the three passes with `tile` equal the im2col kernel's to 1e-13 relative on
/// values drawn from `seed`.
fn assert_passes_match_im2col(g: &Geometry, tile: Tile, seed: u64) {
    let in_len = g.batch * g.c_in * g.input.iter().product::<usize>();
    let out_len = g.batch * g.c_out * g.output().iter().product::<usize>();
    let w_len = g.c_out * g.c_in * g.kernel.iter().product::<usize>();
    let x = values(in_len, 3 * seed);
    let w = values(w_len, 3 * seed + 1);
    let go = values(out_len, 3 * seed + 2);
    let references = [
        im2col::forward(&x, &w, g),
        im2col::grad_input(&go, &w, g),
        im2col::grad_weight(&x, &go, g),
    ];
    let ours = passes(&x, &w, &go, g, tile);
    for (pass, (ours, reference)) in ours.iter().zip(&references).enumerate() {
        let err = max_rel_diff(ours, reference);
        assert!(
            err < 1e-13,
            "{tile:?} {g:?} pass {pass}: relative error {err}"
        );
    }
}

#[test]
fn all_three_passes_match_the_im2col_kernel_in_f64() {
    for isa in available() {
        with_isa(isa, || {
            for tile in [Tile::F2, Tile::F4] {
                for (i, g) in geometries().into_iter().enumerate() {
                    assert!(supports(&g), "{g:?}");
                    assert_passes_match_im2col(&g, tile, i as u64);
                }
            }
        });
    }
}

#[test]
fn passes_split_into_several_chunks_match_im2col() {
    // 256 rows of tiles per batch item, 3 -> 5 channels: with `gemm`'s chunk target at most
    // 110 rows a chunk, so three chunks, made four (an even number) of 64 rows; with our
    // own products' a quarter of that, so ten of 25 or 26 rows.
    let g = Geometry {
        input: [62, 61, 37],
        ..geometries()[0]
    };
    for isa in available() {
        let plan = Plan::new(&g, 4, isa);
        let rows: Vec<usize> = plan.chunks(1).iter().map(|&(_, _, rows)| rows).collect();
        let expected = if chunk_target(isa) == CHUNK_TARGET_ELEMS {
            vec![64; 4]
        } else {
            (0..10).map(|i| (i + 1) * 256 / 10 - i * 256 / 10).collect()
        };
        assert_eq!(rows, expected, "{isa:?} {plan:?}");
        with_isa(isa, || assert_passes_match_im2col(&g, Tile::F4, 14));
    }
}

#[test]
fn weight_gradient_blocks_of_several_chunks_match_im2col() {
    // One chunk per batch item, more chunks than partial sums: a block's first chunk
    // writes its partial sum, the next adds to it.
    let g = Geometry {
        batch: WEIGHT_GRAD_BLOCKS + 1,
        ..geometries()[0]
    };
    let plan = Plan::new(&g, 2, Isa::current());
    assert_eq!(plan.chunks(1).len(), 1, "{plan:?}");
    assert_passes_match_im2col(&g, Tile::F2, 15);
}

#[test]
fn the_public_passes_pick_f4_from_eight_outputs_and_match_im2col() {
    let mut g = geometries()[0];
    g.input = [9, 8, 12];
    assert_eq!(Tile::for_geometry(&g), Tile::F4);
    let small = Geometry {
        input: [7, 8, 12],
        ..g
    };
    assert_eq!(Tile::for_geometry(&small), Tile::F2);
    let x = values(g.batch * g.c_in * 9 * 8 * 12, 1);
    let w = values(g.c_out * g.c_in * 27, 2);
    let go = values(g.batch * g.c_out * 9 * 8 * 12, 3);
    let pairs = [
        (forward(&x, &w, &g), im2col::forward(&x, &w, &g)),
        (grad_input(&go, &w, &g), im2col::grad_input(&go, &w, &g)),
        (grad_weight(&x, &go, &g), im2col::grad_weight(&x, &go, &g)),
    ];
    for (pass, (ours, reference)) in pairs.iter().enumerate() {
        let err = max_rel_diff(ours, reference);
        assert!(err < 1e-13, "pass {pass}: relative error {err}");
    }
}

/// The f32 passes on every instruction set this CPU runs against sums in f64 (the im2col kernel
/// in f64), within a stated factor of the f32 im2col kernel's own error.
#[test]
fn f32_rounding_stays_near_the_direct_sums_level() {
    for isa in available() {
        with_isa(isa, f32_rounding_on);
    }
}

fn f32_rounding_on() {
    let g = Geometry {
        batch: 1,
        c_in: 32,
        c_out: 32,
        input: [9, 10, 11],
        kernel: [3, 3, 3],
        padding: [1, 1, 1],
        stride: 1,
    };
    let vox = 990;
    let x = values(32 * vox, 7);
    let w: Vec<f64> = values(32 * 32 * 27, 8).iter().map(|v| v * 0.05).collect();
    let go = values(32 * vox, 9);
    let exact = [
        im2col::forward(&x, &w, &g),
        im2col::grad_input(&go, &w, &g),
        im2col::grad_weight(&x, &go, &g),
    ];
    let as_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let widen = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
    let (x, w, go) = (as_f32(&x), as_f32(&w), as_f32(&go));
    let direct = [
        im2col::forward(&x, &w, &g),
        im2col::grad_input(&go, &w, &g),
        im2col::grad_weight(&x, &go, &g),
    ];
    // F(2, 3) rounds like the direct sums; F(4, 3)'s larger entries cost a bounded factor
    // (measured: 15x the im2col kernel's error forward and for the input gradient, 27x for
    // the weight gradient, whose im2col sums are unusually exact; all below 2e-5 relative).
    for (tile, factor) in [(Tile::F2, 4.0), (Tile::F4, 40.0)] {
        let ours = passes(&x, &w, &go, &g, tile);
        for pass in 0..3 {
            let ours_err = max_rel_diff(&widen(&ours[pass]), &exact[pass]);
            let direct_err = max_rel_diff(&widen(&direct[pass]), &exact[pass]);
            assert!(
                ours_err < factor * direct_err.max(1e-7),
                "{:?} {tile:?} pass {pass}: {ours_err} vs im2col {direct_err}",
                Isa::current()
            );
        }
    }
}

#[test]
fn unsupported_geometries_are_left_to_im2col() {
    let base = geometries()[0];
    assert!(!supports(&Geometry { stride: 2, ..base }));
    assert!(!supports(&Geometry {
        kernel: [5, 5, 5],
        ..base
    }));
    assert!(!supports(&Geometry {
        kernel: [1, 1, 1],
        padding: [0; 3],
        ..base
    }));
    assert!(!supports(&Geometry {
        padding: [3, 1, 1],
        ..base
    }));
}

/// The 16-lane transforms compute what the portable ones do, in the same order: with the same
/// products (`gemm`'s, which both take) and chunks, the f32 passes give the same bits, on
/// rows with padding, short rows and several chunks. Skipped on a CPU without AVX-512.
#[test]
fn the_avx512_transforms_give_the_portable_bits() {
    if Isa::detected() < Isa::Avx512 {
        return;
    }
    let as_f32 = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect::<Vec<f32>>();
    let mut cases = geometries();
    cases.push(Geometry {
        c_in: 16,
        c_out: 8,
        input: [30, 29, 37],
        ..geometries()[0]
    });
    for (i, g) in cases.iter().enumerate() {
        let in_len = g.batch * g.c_in * g.input.iter().product::<usize>();
        let out_len = g.batch * g.c_out * g.output().iter().product::<usize>();
        let x = as_f32(values(in_len, 40 + i as u64));
        let w = as_f32(values(g.kernel_len(), 60 + i as u64));
        let go = as_f32(values(out_len, 80 + i as u64));
        for tile in [Tile::F2, Tile::F4] {
            let wide = with_isa(Isa::Avx512, || passes(&x, &w, &go, g, tile));
            let portable = with_isa(Isa::Portable, || passes(&x, &w, &go, g, tile));
            for pass in 0..3 {
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&wide[pass]),
                    bits(&portable[pass]),
                    "{tile:?} {g:?} pass {pass}"
                );
            }
        }
    }
}
