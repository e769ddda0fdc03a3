//! CPU kernels of volgen's convolutions, on plain slices: the chunked im2col + `gemm`
//! convolution ([`im2col`]), Winograd's F(2, 3) and F(4, 3) for 3-tap kernels with AVX2 + FMA
//! products of its own and 16-lane AVX-512 transforms ([`winograd`]), and the fused element
//! loops between convolutions (BatchNorm, LeakyReLU, per-channel sums: [`fused`]). patch-gan
//! wraps them in candle ops. Large outputs come from, and can be handed back to, a pool of
//! buffers ([`recycle`]), so that a training loop does not fault its temporaries in anew each
//! step.
//!
//! Tensors are contiguous row-major slices of `f32` or `f64` ([`Element`]): a convolution's
//! input `(N, C_in, D, H, W)`, kernel `(C_out, C_in, kd, kh, kw)` and output
//! `(N, C_out, D_out, H_out, W_out)`, with the shape in a [`Geometry`] (a 2D convolution is a 3D
//! one of depth 1). Results are deterministic: they do not depend on the thread count (work is
//! split and summed in fixed orders), only on the instruction set the CPU runs (see below).
//!
//! ```
//! use conv_kernels::{im2col, winograd, Geometry};
//! // 2 images of 3 channels, 9 x 10, to 4 channels, a 3 x 3 kernel (one tap deep), padding 1.
//! let g = Geometry {
//!     batch: 2,
//!     c_in: 3,
//!     c_out: 4,
//!     input: [1, 9, 10],
//!     kernel: [1, 3, 3],
//!     padding: [0, 1, 1],
//!     stride: 1,
//! };
//! assert!(g.is_valid() && winograd::supports(&g));
//! let x: Vec<f64> = (0..g.input_len()).map(|i| (i as f64 * 0.37).sin()).collect();
//! let w: Vec<f64> = (0..g.kernel_len()).map(|i| (i as f64 * 0.11).cos()).collect();
//! let direct = im2col::forward(&x, &w, &g);
//! let tiled = winograd::forward(&x, &w, &g);
//! assert_eq!(g.output(), [1, 9, 10]);
//! assert_eq!(direct.len(), g.output_len());
//! assert!(direct.iter().zip(&tiled).all(|(a, b)| (a - b).abs() < 1e-12));
//! // The bias and activation after it, in one sweep.
//! let bias = [0.5, -0.5, 0.25, 0.];
//! let y = conv_kernels::fused::bias_leaky_relu(&direct, &bias, 9 * 10, 0.2);
//! let pre = direct[0] + bias[0];
//! assert_eq!(y[0], if pre > 0. { pre } else { 0.2 * pre });
//! ```
//!
//! # Unsafe code
//!
//! This crate holds all of the `unsafe` code of the workspace's convolutions, so that
//! patch-gan, their only user, is `#![forbid(unsafe_code)]`; no other crate of the workspace
//! holds convolution kernels. Every public function is safe: it checks the slices' lengths
//! against the geometry (and a [`Columns`] implementation's chunks against its sizes) and panics
//! on a mismatch, so no argument a safe caller can pass reaches undefined behaviour. `unsafe`
//! is used for three things only:
//!
//! - **SIMD behind run-time feature detection** ([`Isa`]). Functions compiled with
//!   `#[target_feature(enable = "avx2,fma")]` or `"avx512f"` run only after
//!   `is_x86_feature_detected!` found those features (cached per process; a kernel asks once
//!   per call and hands the answer to its tasks), with the portable build (`gemm` for the
//!   products) on every other CPU, all always compiled. The Winograd products use AVX2 + FMA
//!   intrinsics on f32 for CPUs without AVX-512 (with AVX-512, `gemm`'s 16-lane kernels are
//!   faster), and the Winograd transforms AVX-512 intrinsics on f32 (16 lanes, masked tails,
//!   permutes for the rows' phases) where the CPU has them, both reading and writing through
//!   raw pointers whose extents they check or the callers derive from the tiling; the f32-only
//!   kernels cast pointers after checking [`Element::IS_F32`], which is why [`Element`] is
//!   sealed. The 16-lane vectors are a private type that only those `avx512f` functions make,
//!   so its operators, which call the intrinsics, run only where AVX-512 was found. The other
//!   AVX2 builds are the same Rust code as their portable build, compiled for wider vectors,
//!   and the 16-lane transforms do the portable transforms' operations in the same order: Rust
//!   neither fuses multiplies and adds nor reorders sums, so they give the same bits.
//! - **Matrix products through `gemm`**, whose API takes raw pointers and strides: each call
//!   reads and writes inside the slices its dimensions and strides imply.
//! - **Output buffers filled in parallel without zeroing them first.** A kernel that writes
//!   every value takes a vector with capacity only, has rayon tasks write disjoint parts of it
//!   (disjoint chunks of `spare_capacity_mut`, or rows and tiles through a shared raw pointer),
//!   and sets its length once all are written. Debug builds fill that capacity with NaN first,
//!   so a value a kernel missed shows up in the tests' results.
//!
//! The invariants these rely on: a raw-pointer access stays inside the allocation it was
//! derived from; parallel tasks write disjoint elements and read none another task writes; a
//! vector's length is set only after every value below it was written; a `target_feature`
//! function runs only on a CPU that has its features. Every `unsafe` block and `unsafe impl`
//! states, in a `// SAFETY:` comment above it, why these hold there (enforced by
//! `clippy::undocumented_unsafe_blocks`), and every `unsafe fn` states its contract under
//! `# Safety`.
//!
//! Every SIMD path is tested against a reference on the CPU running the tests, each
//! instruction set the CPU has forced in turn (a per-thread limit on [`Isa`] that only the
//! tests set), so a CPU with AVX-512 tests the AVX2 and portable paths too: the products
//! against sums in f64 (every block shape, tails and accumulation), the AVX2 builds of the
//! per-channel sums and the 16-lane transforms against their portable builds bit for bit, and
//! the Winograd passes against the im2col kernel in f64, and in f32 within a stated factor of
//! its rounding against sums in f64. A CPU without AVX2 runs the portable paths in the same
//! tests.

// The workspace denies `unsafe` code; this crate is where the convolutions' lives (above).
#![allow(unsafe_code)]
#![deny(unsafe_op_in_unsafe_fn)]
#![warn(missing_docs, clippy::undocumented_unsafe_blocks)]

mod buffers;
mod element;
pub mod fused;
mod geometry;
pub mod im2col;
mod isa;
mod output;
mod scratch;
pub mod winograd;

pub use buffers::{recycle, recycled};
pub use element::Element;
pub use geometry::Geometry;
pub use im2col::{Chunk, Columns};
pub use isa::Isa;

/// The README's example, run as a doctest.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
struct ReadmeExample;
