//! Kernels' output buffers, made without zeroing them first, and the pointer parallel tasks
//! write their disjoint parts of one through.
//!
//! `vec![0.0; len]` writes every value once before a kernel writes it again: on a reused heap
//! that is a `memset` of every output, on the thread that calls the op while the pool waits
//! (5% of a 28^3 generator step's samples, 8% of its wall time). A kernel that writes every
//! value takes an [`unwritten`] vector instead.

use std::mem::MaybeUninit;

use rayon::prelude::*;

use crate::element::Element;

/// An empty vector with room for `len` values (a recycled one where there is one: see
/// [`crate::buffers`]), for a kernel that writes all of them through its pointer before calling
/// `set_len(len)`. Debug builds (the tests) fill the room with NaN first, so that a value the
/// kernel missed shows up in its results.
pub(crate) fn unwritten<T: Element>(len: usize) -> Vec<T> {
    let mut values = crate::buffers::recycled(len);
    if cfg!(debug_assertions) {
        values.resize(len, T::from_f64(f64::NAN));
        values.clear();
    }
    values
}

/// Appends `len` values to `values`, made `chunk` at a time in parallel: `fill(i, values)`
/// writes chunk `i` (the last may be shorter).
///
/// # Safety
/// `fill` must write every value of the chunk it is given.
pub(crate) unsafe fn extend_par_chunks<T: Element>(
    values: &mut Vec<T>,
    len: usize,
    chunk: usize,
    fill: impl Fn(usize, &mut [MaybeUninit<T>]) + Sync,
) {
    values.reserve(len);
    values.spare_capacity_mut()[..len]
        .par_chunks_mut(chunk)
        .enumerate()
        .for_each(|(i, dst)| fill(i, dst));
    // SAFETY: the chunks cover `len` values and `fill` wrote each (the caller's promise).
    unsafe { values.set_len(values.len() + len) };
}

/// A pointer the forward passes share between rayon tasks that write disjoint outputs.
#[derive(Clone, Copy)]
pub(crate) struct SharedMut<T>(pub(crate) *mut T);
// SAFETY: every task writes a disjoint set of elements (its own output rows or tiles), see
// `im2col::forward` and `winograd`.
unsafe impl<T: Send> Send for SharedMut<T> {}
// SAFETY: as for `Send`: the tasks sharing it write disjoint elements and read none.
unsafe impl<T: Send> Sync for SharedMut<T> {}

impl<T> SharedMut<T> {
    /// A method, not a field access, so closures capture the whole (Sync) wrapper.
    pub(crate) fn ptr(self) -> *mut T {
        self.0
    }
}
