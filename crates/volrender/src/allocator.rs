//! Process-wide tuning of glibc's allocator for programs that allocate large buffers in a loop.
//!
//! `mallopt` is a C call, hence the one `unsafe` block of this module.
#![allow(unsafe_code)]

/// Keeps freed memory in glibc's heap instead of returning it to the system
/// (`M_MMAP_MAX = 0`, `M_TRIM_THRESHOLD = 2^30`), as PyTorch-style training loops want.
///
/// By default glibc maps every allocation above 128 KiB (up to 32 MiB) afresh and unmaps it when
/// freed, so each multi-megabyte tensor of a render, a generator step or their autograd is
/// page-faulted in anew on every iteration: measured with `examples/gan_step` of patch-gan, that
/// made a generator step 1.7x slower. Call it once, first thing in `main`, before other threads
/// exist; the `volgen` binary does. Returns whether it was applied (glibc on Linux only).
///
/// ```
/// // A program's first line:
/// let tuned = volrender::tune_malloc();
/// assert_eq!(tuned, cfg!(all(target_os = "linux", target_env = "gnu")));
/// ```
pub fn tune_malloc() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only sets allocator parameters; callers call it before spawning
        // threads, as documented.
        unsafe {
            libc::mallopt(libc::M_MMAP_MAX, 0) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30) == 1
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    false
}
