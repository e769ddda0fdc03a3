//! Reuse of the backward's private gradient buffers across calls.
//!
//! Each backward accumulates into up to `BLOCKS` buffers of the whole grid (16 bytes per voxel
//! in f32: 32 MiB each at 128^3). Freshly allocated, such buffers come from `mmap` and go back
//! to the system on every call, so each call pays a page fault per 4 KiB page touched, twice
//! (accumulate, then sum). With 4096 rays on a 128^3 grid that was 4.8x the rest of the
//! forward+backward (measured with glibc told to keep large blocks, see
//! docs/performance-volrender.md). Here the buffers of the last backward are kept and cleared
//! with a memset instead. What stays allocated between calls is at most `BLOCKS` buffers of the
//! last grid size per float type; [`release_gradient_buffers`] frees them.

use std::sync::{Mutex, MutexGuard};

use crate::kernel::Real;

/// A pool of zero-able gradient buffers for one float type.
pub(crate) type Pool<T> = Mutex<Vec<Vec<[T; 4]>>>;

static POOL_F32: Pool<f32> = Mutex::new(Vec::new());
static POOL_F64: Pool<f64> = Mutex::new(Vec::new());

/// The float types with a buffer pool.
pub(crate) trait Pooled: Real {
    fn pool() -> &'static Pool<Self>;
}

impl Pooled for f32 {
    fn pool() -> &'static Pool<Self> {
        &POOL_F32
    }
}

impl Pooled for f64 {
    fn pool() -> &'static Pool<Self> {
        &POOL_F64
    }
}

/// Locks a pool; a pool poisoned by a panic elsewhere holds whole buffers still (they are only
/// ever pushed or popped whole), so it stays usable.
fn lock<T>(pool: &'static Pool<T>) -> MutexGuard<'static, Vec<Vec<[T; 4]>>> {
    pool.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Returns a buffer of `voxels` zeros: a pooled one cleared, or a new one.
pub(crate) fn take<T: Pooled>(voxels: usize) -> Vec<[T; 4]> {
    let pooled = lock(T::pool()).pop();
    match pooled {
        Some(mut buf) if buf.len() == voxels => {
            buf.fill([T::zero(); 4]);
            buf
        }
        _ => vec![[T::zero(); 4]; voxels],
    }
}

/// Keeps `buffers` for the next backward, dropping whatever the pool held for another size and
/// anything beyond `keep` buffers.
pub(crate) fn give_back<T: Pooled>(buffers: Vec<Vec<[T; 4]>>, keep: usize) {
    let mut pool = lock(T::pool());
    let size = buffers.first().map(Vec::len);
    pool.retain(|b| Some(b.len()) == size);
    pool.extend(buffers);
    pool.truncate(keep);
}

/// Frees the gradient buffers the renderer keeps between backward passes (at most 4 buffers of
/// 16 bytes (f32) or 32 bytes (f64) per voxel of the last grid rendered backward). They are
/// reallocated by the next backward pass; call this when a long-running program is done with
/// large grids.
///
/// ```
/// volrender::release_gradient_buffers();
/// ```
pub fn release_gradient_buffers() {
    lock(&POOL_F32).clear();
    lock(&POOL_F64).clear();
}

#[cfg(test)]
mod tests {
    use super::*;

    // The only test of this crate's unit-test binary that touches the pools, so the counts
    // below are not disturbed by other tests running at the same time.
    #[test]
    fn buffers_come_back_zeroed_and_only_of_the_asked_size() {
        release_gradient_buffers();
        let mut a = take::<f64>(10);
        a[3] = [1.0, 2.0, 3.0, 4.0];
        give_back(vec![a], 4);
        let b = take::<f64>(10);
        assert_eq!(b.len(), 10);
        assert!(b.iter().all(|v| *v == [0.0; 4]));
        give_back(vec![b], 4);
        assert_eq!(take::<f64>(7).len(), 7);
        release_gradient_buffers();
        assert!(lock(&POOL_F64).is_empty());
    }
}
