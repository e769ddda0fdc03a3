//! Per-thread pools of the convolution kernels' scratch buffers.
//!
//! Every rayon task of a convolution needs buffers of a size fixed by its geometry (im2col
//! columns, Winograd's transformed tiles); made and zeroed afresh per task they cost a few MiB
//! of `memset` per convolution, as much as a small layer's arithmetic. The kernels write every
//! value of a scratch before they read it, so a buffer can be reused as it is, stale values and
//! all: a task takes one from its thread's pool and gives it back when done.

use std::any::Any;
use std::cell::RefCell;
use std::ops::{Deref, DerefMut};

use crate::element::Element;

thread_local! {
    /// Scratches of earlier tasks on this thread, of any type (found by type).
    static POOL: RefCell<Vec<Box<dyn Any>>> = const { RefCell::new(Vec::new()) };
}

/// A scratch of type `S` taken from this thread's pool (or made with `S::default()`), put back
/// when dropped.
pub(crate) struct Pooled<S: 'static>(Option<S>);

impl<S: Default + 'static> Pooled<S> {
    /// A pooled `S` (with whatever its last user left in it), or a default one.
    pub(crate) fn take() -> Self {
        let pooled = POOL.with(|pool| {
            let mut pool = pool.borrow_mut();
            let at = pool.iter().position(|s| s.is::<S>())?;
            pool.swap_remove(at).downcast::<S>().ok()
        });
        Self(Some(pooled.map(|b| *b).unwrap_or_default()))
    }
}

impl<S: 'static> Deref for Pooled<S> {
    type Target = S;

    fn deref(&self) -> &S {
        self.0.as_ref().expect("present until dropped")
    }
}

impl<S: 'static> DerefMut for Pooled<S> {
    fn deref_mut(&mut self) -> &mut S {
        self.0.as_mut().expect("present until dropped")
    }
}

impl<S: 'static> Drop for Pooled<S> {
    fn drop(&mut self) {
        if let Some(scratch) = self.0.take() {
            // Thread-local storage may already be gone while a thread exits: then the
            // scratch is simply freed.
            let _ = POOL.try_with(|pool| pool.borrow_mut().push(Box::new(scratch)));
        }
    }
}

/// Grows `buf` to at least `len` values (zeros at the end); never shrinks it.
pub(crate) fn at_least<T: Element>(buf: &mut Vec<T>, len: usize) {
    if buf.len() < len {
        buf.resize(len, T::ZERO);
    }
}

/// A pooled `Vec<T>` of at least `len` values.
pub(crate) fn pooled_vec<T: Element>(len: usize) -> Pooled<Vec<T>> {
    let mut buf = Pooled::<Vec<T>>::take();
    at_least(&mut buf, len);
    buf
}
