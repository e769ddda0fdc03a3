//! Reuse of the renderer's whole-grid buffers across calls: the backward's private gradient
//! buffers and the forward's interleaved volume copy.
//!
//! Each backward accumulates into up to `BLOCKS` buffers of the whole grid (16 bytes per voxel
//! in f32: 32 MiB each at 128^3), and each render copies its volume into one more of the same
//! size. Freshly allocated, such buffers come from `mmap` and go back to the system on every
//! call, so each call pays a page fault per 4 KiB page touched. With 4096 rays on a 128^3 grid
//! that was 4.8x the rest of the forward+backward (measured with glibc told to keep large
//! blocks, see docs/performance-volrender.md). Here the buffers of the last calls are kept (at
//! most [`KEEP`] of the last grid size per float type) and reused; gradient buffers are cleared
//! with a memset, volume copies are overwritten. [`release_gradient_buffers`] frees them.

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

/// The most buffers kept per float type: the backward's gradient blocks and one volume copy.
pub(crate) const KEEP: usize = crate::op::BLOCKS + 1;

/// Returns a buffer of `voxels` elements with unspecified (old) contents, for a caller that
/// overwrites all of it: a pooled one, or a new one.
pub(crate) fn take<T: Pooled>(voxels: usize) -> Vec<[T; 4]> {
    let pooled = lock(T::pool()).pop();
    match pooled {
        Some(buf) if buf.len() == voxels => buf,
        _ => vec![[T::zero(); 4]; voxels],
    }
}

/// Returns a buffer of `voxels` zeros: a pooled one cleared, or a new one.
pub(crate) fn take_zeroed<T: Pooled>(voxels: usize) -> Vec<[T; 4]> {
    let mut buf = take(voxels);
    buf.fill([T::zero(); 4]);
    buf
}

/// Keeps `buffers` for later calls, dropping whatever the pool held for another size and
/// anything beyond [`KEEP`] buffers.
pub(crate) fn give_back<T: Pooled>(buffers: Vec<Vec<[T; 4]>>) {
    let mut pool = lock(T::pool());
    let size = buffers.first().map(Vec::len);
    pool.retain(|b| Some(b.len()) == size);
    pool.extend(buffers);
    pool.truncate(KEEP);
}

/// Frees the buffers the renderer keeps between calls (gradient buffers and volume copies: at
/// most 5 buffers of 16 bytes (f32) or 32 bytes (f64) per voxel of the last grid rendered, per
/// float type). They are reallocated by the next render; call this when a long-running program
/// is done with large grids.
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
        let mut a = take_zeroed::<f64>(10);
        a[3] = [1.0, 2.0, 3.0, 4.0];
        give_back(vec![a]);
        let b = take_zeroed::<f64>(10);
        assert_eq!(b.len(), 10);
        assert!(b.iter().all(|v| *v == [0.0; 4]));
        give_back(vec![
            b.clone(),
            b.clone(),
            b.clone(),
            b.clone(),
            b.clone(),
            b,
        ]);
        assert_eq!(lock(&POOL_F64).len(), KEEP);
        assert_eq!(take::<f64>(7).len(), 7);
        release_gradient_buffers();
        assert!(lock(&POOL_F64).is_empty());
    }
}
