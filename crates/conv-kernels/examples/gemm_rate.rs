//! The machine's rate for the kernels' multiplier: one `S x S x S` f32 product by the `gemm`
//! crate (conv-kernels' dependency, with its AVX-512 kernels where the CPU has them) on `T`
//! threads, median of `R` after a warm-up, printed as one JSON line. `benches/compare_gan_peer.sh`
//! holds the steps' GFLOP/s against it.
//!
//! ```text
//! cargo run --release -p conv-kernels --example gemm_rate -- 2048 2 5    # S, T, R
//! ```

// The `gemm` crate's entry point is `unsafe` (raw pointers and strides); nothing else here is.
#![allow(unsafe_code)]

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize, default: usize| -> Result<usize, Box<dyn std::error::Error>> {
        Ok(std::env::args().nth(i).map_or(Ok(default), |v| v.parse())?)
    };
    let (n, threads, repeat) = (arg(1, 2048)?, arg(2, 2)?, arg(3, 5)?.max(1));
    let lhs: Vec<f32> = (0..n * n)
        .map(|i| ((i * 7919) % 1000) as f32 / 1000.0)
        .collect();
    let rhs: Vec<f32> = (0..n * n)
        .map(|i| ((i * 104729) % 1000) as f32 / 1000.0)
        .collect();
    let mut dst = vec![0f32; n * n];
    let mut product = || {
        // SAFETY: the three buffers are n x n, row-major, with the strides given.
        unsafe {
            gemm::gemm(
                n,
                n,
                n,
                dst.as_mut_ptr(),
                1,
                n as isize,
                false,
                lhs.as_ptr(),
                1,
                n as isize,
                rhs.as_ptr(),
                1,
                n as isize,
                0f32,
                1f32,
                false,
                false,
                false,
                gemm::Parallelism::Rayon(threads),
            )
        }
    };
    product();
    let mut times: Vec<f64> = (0..repeat)
        .map(|_| {
            let start = Instant::now();
            product();
            start.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let seconds = times[times.len() / 2];
    let gflop = 2.0 * (n as f64).powi(3) / 1e9;
    println!(
        "{{\"what\": \"gemm\", \"size\": {n}, \"threads\": {threads}, \"seconds\": {seconds:.5}, \
         \"gflop\": {gflop:.3}, \"gflops\": {:.1}}}",
        gflop / seconds
    );
    Ok(())
}
