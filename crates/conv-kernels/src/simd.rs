//! Run-time CPU feature checks for the kernels that have an AVX2 build.
//!
//! The crate is compiled for baseline x86-64 (SSE2), so its vectorised loops run 4 f32 or 2 f64
//! lanes wide unless a function is compiled with `#[target_feature(enable = "avx2")]` and called
//! after this check. Such builds give the same bits as the baseline ones: Rust does not fuse
//! multiplies and adds, and the vectorised loops do not reorder sums.

/// Whether this CPU runs the AVX2 builds.
pub(crate) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}
